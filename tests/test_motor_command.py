"""`MotorCommand` stored as rows: built unchecked for a caller that vouches for them (`trusted`), its fields made when
first read, the same command in every way as one built field by field."""

import copy
import pickle
import warnings

import numpy as np
import pytest

from wbc.errors import CommandError
from wbc.types import MotorCommand


def _rows(n=4):
    rows = np.arange(5.0 * n).reshape(5, n)
    rows[2:4] = np.abs(rows[2:4])
    return rows


def test_a_trusted_command_owns_its_rows_read_only_and_reads_as_a_constructed_one():
    rows = _rows()
    cmd = MotorCommand.trusted(rows)
    built = MotorCommand(*_rows())
    assert cmd.rows is rows and not rows.flags.writeable
    assert cmd.num_joints == 4
    for name in ("q", "dq", "kp", "kd", "tau"):
        field = getattr(cmd, name)
        np.testing.assert_array_equal(field, getattr(built, name))
        assert np.shares_memory(field, rows) and getattr(cmd, name) is field  # a view of its row, made once
        with pytest.raises(ValueError):
            field[0] = 1.0
    assert repr(cmd) == repr(built)
    np.testing.assert_array_equal(cmd.stacked(), built.stacked())


def test_a_constructed_command_keeps_views_of_its_stack_not_the_callers_arrays():
    q = np.zeros(3)
    cmd = MotorCommand(q=q, dq=np.zeros(3), kp=np.ones(3), kd=np.ones(3), tau=np.zeros(3))
    q[0] = 5.0  # the caller's array changes; the command does not
    assert cmd.q[0] == 0.0 and np.shares_memory(cmd.q, cmd.rows) and not cmd.q.flags.writeable


def test_a_command_stored_as_rows_copies_and_pickles_whole():
    cmd = MotorCommand.trusted(_rows())
    _ = cmd.q  # one field made, the others not yet
    for other in (copy.copy(cmd), copy.deepcopy(cmd), pickle.loads(pickle.dumps(cmd))):
        np.testing.assert_array_equal(other.stacked(), cmd.stacked())
        np.testing.assert_array_equal(other.tau, cmd.tau)
    with pytest.raises(AttributeError, match="no attribute 'speed'"):
        cmd.speed  # noqa: B018


def _hold(q):
    return MotorCommand.hold(np.asarray(q, dtype=float), 20.0, 0.5)


def test_commands_compare_by_value():
    # the dataclass's comparison asked an array for its truth value and raised
    a, b = _hold([0.1, 0.2, 0.3]), _hold([0.1, 0.2, 0.3])
    assert a == b and not a != b
    assert a != _hold([0.1, 0.2, 0.4])
    assert a != _hold([0.1, 0.2])
    assert a != "not a command"
    assert a in [_hold([0.0, 0.0, 0.0]), b]
    assert MotorCommand.from_rows(a.stacked()) == a


@pytest.mark.parametrize("name", ["q", "dq", "kp", "kd", "tau"])
def test_a_complex_field_is_refused_naming_it(name):
    fields = {f: np.zeros(3) for f in ("q", "dq", "kp", "kd", "tau")}
    fields[name] = np.zeros(3, dtype=complex)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no ComplexWarning on the way: refused before any cast
        with pytest.raises(CommandError, match=rf"MotorCommand.{name}: complex values"):
            MotorCommand(**fields)
        with pytest.raises(CommandError, match=r"MotorCommand\.\w+: complex values"):  # the rows: all complex
            MotorCommand.from_rows(np.stack([fields[f] for f in ("q", "dq", "kp", "kd", "tau")]))
