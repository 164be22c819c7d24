"""The robot interface: contract, command validation and clamping, lifecycle."""

import numpy as np
import pytest

from wbc.errors import CommandError, RobotNotConnectedError
from wbc.hardware import Robot, RobotContractError, check_robot
from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
from wbc.robots import get_robot, joint_table
from wbc.types import MotorCommand, RobotState


@pytest.mark.parametrize(("robot", "arm"), [("a1-wx200", "actuated"), ("a1-wx200", "none"), ("go1-arm", "locked")])
def test_mujoco_robot_passes_the_contract(robot, arm):
    check_robot(lambda: MujocoRobot(MujocoRobotConfig(robot=robot, arm_mode=arm)))


class _LeakyRobot(MujocoRobot):
    """A broken backend: it skips clamping and never advances its tick."""

    def write(self, cmd):
        self._require_connected("write")
        self._send(cmd)
        return cmd

    def _read(self):
        s = super()._read()
        return RobotState(**{**s.__dict__, "tick": 0})


def test_contract_checker_catches_a_broken_backend():
    with pytest.raises(RobotContractError) as err:
        check_robot(lambda: _LeakyRobot(MujocoRobotConfig(arm_mode="none")))
    text = str(err.value)
    assert "tick did not advance" in text
    assert "unclamped" in text
    assert "joints" in text


@pytest.mark.parametrize(
    "fields",
    [
        {"q": [0.0, np.nan]},
        {"tau": [np.inf, 0.0]},
        {"kp": [-1.0, 0.0]},
        {"kd": [[0.0, 0.0]]},
        {"dq": [0.0]},
        {"q": ["a", "b"]},
    ],
)
@pytest.mark.parametrize("as_array", [False, True], ids=["lists", "float arrays"])
def test_bad_motor_commands_are_rejected_at_construction(fields, as_array):
    # float arrays take the fast path of every control tick, lists the slow one: both must refuse
    base = {k: [0.0, 0.0] for k in ("q", "dq", "kp", "kd", "tau")}
    base.update(fields)
    if as_array:
        base = {k: np.asarray(v) for k, v in base.items()}
    with pytest.raises(CommandError) as err:
        MotorCommand(**base)
    assert "MotorCommand." in str(err.value)


@pytest.mark.parametrize(
    "fields",
    [{"q": [0.0, np.nan]}, {"tau": [np.inf, 0.0]}, {"kp": [-1.0, 0.0]}, {"kd": [0.0, -np.inf]}],
)
def test_commands_from_rows_are_checked_as_the_constructor_checks(fields):
    base = {k: [0.0, 0.0] for k in ("q", "dq", "kp", "kd", "tau")}
    base.update(fields)
    rows = np.array([base[k] for k in ("q", "dq", "kp", "kd", "tau")])
    with pytest.raises(CommandError, match=f"MotorCommand.{next(iter(fields))}"):
        MotorCommand.from_rows(rows)
    with pytest.raises(CommandError, match="expected a .5, n. array"):
        MotorCommand.from_rows(rows[:4])


def test_a_command_from_rows_owns_them_read_only():
    rows = np.arange(10.0).reshape(5, 2)
    cmd = MotorCommand.from_rows(rows)
    assert np.array_equal(cmd.kp, [4.0, 5.0]) and np.array_equal(cmd.stacked(), rows)
    with pytest.raises(ValueError):
        rows[0, 0] = 1.0  # the command's storage: nobody writes it after the command is made


@pytest.mark.filterwarnings("error")
def test_huge_finite_commands_are_accepted_without_warnings():
    huge = np.array([1e308, 1e308])
    cmd = MotorCommand(q=huge, dq=huge, kp=np.zeros(2), kd=np.zeros(2), tau=huge)
    assert np.array_equal(cmd.q, huge) and not cmd.q.flags.writeable


def test_commands_are_read_only():
    cmd = MotorCommand.hold(np.zeros(3), 1.0, 0.1)
    with pytest.raises(ValueError):
        cmd.q[0] = 1.0


def test_write_clamps_to_motor_limits_and_returns_what_was_sent():
    desc = get_robot("a1-wx200", "actuated")
    lim = joint_table(desc)
    with MujocoRobot(MujocoRobotConfig()) as robot:
        n = robot.num_joints
        cmd = MotorCommand(q=lim.lower - 1.0, dq=np.full(n, 1e3), kp=np.full(n, 5e3), kd=np.full(n, 3.0),
                           tau=lim.torque_limit * 3)
        sent = robot.write(cmd)
        np.testing.assert_array_equal(sent.q, lim.lower)
        np.testing.assert_array_equal(sent.dq, lim.velocity_limit)
        np.testing.assert_array_equal(sent.tau, lim.torque_limit)
        assert np.all(sent.kp <= 1000.0) and np.all(sent.kd == 3.0)
        # the arm's limits are the servos', the legs' the A1's
        assert lim.torque_limit[0] == 33.5 and lim.torque_limit[13] == pytest.approx(8.2)
        robot.advance(0.01)
        # the motors never exceed their torque limit, whatever the command asked
        assert np.all(np.abs(robot.data.actuator_force) <= lim.torque_limit + 1e-9)
        with pytest.raises(CommandError, match="15"):
            robot.write(MotorCommand.hold(np.zeros(12), 1.0, 0.1))


def test_a_command_within_the_limits_is_sent_as_it_is_and_one_value_outside_clamps_only_that_value():
    from wbc.hardware.robot import command_bounds, within_bounds

    lim = joint_table(get_robot("a1-wx200", "actuated"))
    lower, upper = command_bounds(lim)
    with MujocoRobot(MujocoRobotConfig()) as robot:
        n = robot.num_joints
        mid = 0.5 * (lim.lower + lim.upper)
        inside = MotorCommand(q=mid, dq=np.zeros(n), kp=np.full(n, 20.0), kd=np.full(n, 0.5), tau=np.zeros(n))
        assert within_bounds(inside.rows, lower, upper)
        assert robot.write(inside) is inside  # nothing to clamp: no copy
        # a bound itself is within; one value past it, in any row, is not, and only that value moves
        for row, col, value in ((0, 3, lim.upper[3]), (4, 13, -lim.torque_limit[13])):
            rows = inside.stacked()
            rows[row, col] = value
            edge = MotorCommand.from_rows(rows.copy())  # the array becomes the command's, read-only
            assert within_bounds(edge.rows, lower, upper) and robot.write(edge) is edge
            rows[row, col] = value + np.sign(value) * 1e-9
            past = MotorCommand.from_rows(rows)
            assert not within_bounds(past.rows, lower, upper)
            sent = robot.write(past)
            assert sent is not past and sent.rows[row, col] == value
            changed = sent.rows != past.rows
            assert changed.sum() == 1 and changed[row, col]
    rows = np.zeros((5, 2))
    rows[1, 1] = np.nan  # no command holds one, but the check must not call it within
    assert not within_bounds(rows, np.full((5, 2), -1.0), np.ones((5, 2)))


def test_lifecycle():
    robot = MujocoRobot(MujocoRobotConfig(arm_mode="none"))
    assert isinstance(robot, Robot)
    with pytest.raises(RobotNotConnectedError, match=r"connect\(\)"):
        robot.read()
    robot.connect()
    robot.connect()  # idempotent
    a = robot.read()
    b = robot.read()
    assert a.tick == b.tick  # no new frame without time passing: a caller can see it is stale
    robot.advance(0.004)
    assert robot.read().tick == a.tick + 2
    robot.close()
    robot.close()
    assert not robot.is_connected
