"""`MotorCommand` stored as rows: built unchecked for a caller that vouches for them (`trusted`), its fields made when
first read, the same command in every way as one built field by field."""

import copy
import pickle

import numpy as np
import pytest

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
