"""`QuadrupedArmRobot`: two devices as one robot (joints, commands split, one frame, freshness, capabilities).

The devices here are in-memory fakes with a clock the test moves, so every rule is checked exactly; the same class
over the real links (Unitree UDP legs + Dynamixel arm) against the emulators is in the hardware tests.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from wbc.errors import ConfigError, RobotLinkError
from wbc.hardware.quadruped_arm_robot import QuadrupedArmConfig, QuadrupedArmRobot
from wbc.hardware.robot import Robot
from wbc.hardware.robot_contract import check_robot
from wbc.hardware.safety import SafeRobot, SafetyConfig, SafetyState
from wbc.robots.joint_table import JointTable
from wbc.robots.wx200 import WX200_NOMINAL_Q
from wbc.types import MotorCommand, RobotState


class Clock:
    def __init__(self) -> None:
        self.now = 0.0


@dataclasses.dataclass
class Status:
    motor_mode: np.ndarray
    motor_temperature: np.ndarray


class Device(Robot):
    """A fake device of `n` joints: its tick advances on `advance` unless `stalled`; it records what it was sent."""

    def __init__(self, n: int, clock: Clock, *, prefix: str, q0: float = 0.1, fail_connect: bool = False) -> None:
        super().__init__()
        self.n, self.clock, self.prefix, self.q0, self.fail_connect = n, clock, prefix, q0, fail_connect
        self.sent: list[MotorCommand] = []
        self.ticks = 0
        self.stalled = False
        self.mode = np.full(n, 0x0A)
        self.closed_count = 0

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(f"{self.prefix}{i}" for i in range(self.n))

    @property
    def limits(self) -> JointTable:
        n = self.n
        return JointTable(names=self.joint_names, lower=np.full(n, -2.0), upper=np.full(n, 2.0),
                          torque_limit=np.full(n, 10.0 if self.n == 3 else 30.0), velocity_limit=np.full(n, 20.0),
                          armature=np.zeros(n), damping=np.zeros(n), frictionloss=np.zeros(n))

    def _connect(self) -> None:
        if self.fail_connect:
            raise RobotLinkError(f"{self.prefix}: no state")
        self.ticks = 1

    def _close(self) -> None:
        self.closed_count += 1

    def _read(self) -> RobotState:
        n = self.n
        return RobotState(tick=self.ticks, time=self.clock.now, q=np.full(n, self.q0), dq=np.zeros(n),
                          tau_est=np.zeros(n), imu_quat=np.array([1.0, 0, 0, 0]), gyro_in_body=np.zeros(3),
                          accel_in_body=np.array([0, 0, 9.81]), foot_force=np.zeros(4))

    def _send(self, cmd: MotorCommand) -> None:
        self.sent.append(cmd)

    def _advance(self, dt: float) -> None:
        self.clock.now += dt
        if not self.stalled:
            self.ticks += 1

    def motor_status(self) -> Status:
        return Status(motor_mode=self.mode, motor_temperature=np.full(self.n, 40))


class Legs(Device):
    def wall_time(self) -> float:
        return self.clock.now


class Arm(Device):
    """Free-running, as a bus thread is: a new state every 2 ms of the shared clock, unless `stalled`."""

    def _read(self) -> RobotState:
        if not self.stalled:
            self.ticks = 1 + int(round(self.clock.now / 0.002))
        return super()._read()


def _pair(mode: str = "actuated", **kw: object) -> tuple[QuadrupedArmRobot, Legs, Device, Clock]:
    clock = Clock()
    legs, arm = Legs(12, clock, prefix="leg"), Arm(3, clock, prefix="arm", q0=-0.3)
    return QuadrupedArmRobot(legs, arm, QuadrupedArmConfig(arm_mode=mode, **kw)), legs, arm, clock


def test_actuated_joins_joints_limits_states_and_splits_commands() -> None:
    robot, legs, arm, _ = _pair()
    assert robot.joint_names == legs.joint_names + arm.joint_names and robot.num_joints == 15
    np.testing.assert_array_equal(robot.limits.torque_limit, [30.0] * 12 + [10.0] * 3)
    with robot:
        state = robot.read()
        np.testing.assert_array_equal(state.q, [0.1] * 12 + [-0.3] * 3)
        cmd = MotorCommand(q=np.linspace(-1, 1, 15), dq=np.zeros(15), kp=np.arange(15.0), kd=np.ones(15),
                           tau=np.full(15, 50.0))
        robot.write(cmd)
    np.testing.assert_array_equal(legs.sent[-1].kp, np.arange(12.0))
    np.testing.assert_array_equal(arm.sent[-1].kp, [12.0, 13.0, 14.0])
    np.testing.assert_array_equal(arm.sent[-1].tau, 10.0)  # clamped to the arm's own limit on the way
    assert legs.closed_count == arm.closed_count == 1


def test_the_legs_close_first_then_the_arm() -> None:
    """The legs' close damps them from their next frame on; the arm's takes its damping and its park (0.2 s and more),
    during which legs closed after it would hold their last command until their write deadline."""
    robot, legs, arm, _ = _pair()
    order: list[str] = []
    legs._close = lambda: order.append("legs")
    arm._close = lambda: order.append("arm")
    robot.connect()
    robot.close()
    assert order == ["legs", "arm"]


def test_locked_holds_the_arm_at_its_stowed_pose_whatever_the_controller_sends() -> None:
    robot, legs, arm, _ = _pair("locked")
    assert robot.num_joints == 12 and robot.joint_names == legs.joint_names
    with robot:
        assert robot.read().num_joints == 12
        robot.write(MotorCommand.hold(np.zeros(12), 40.0, 1.0))
        robot.write(MotorCommand.damping(12, 3.0))
    for sent in arm.sent:
        np.testing.assert_array_equal(sent.q, WX200_NOMINAL_Q)
        np.testing.assert_array_equal(sent.kp, robot.config.hold_kp)
    assert (legs.sent[-1].kp == 0).all()


def test_the_modes_need_the_devices_they_name() -> None:
    clock = Clock()
    legs, arm = Legs(12, clock, prefix="leg"), Arm(3, clock, prefix="arm")
    assert QuadrupedArmRobot(legs, None, QuadrupedArmConfig(arm_mode="none")).num_joints == 12
    with pytest.raises(ConfigError, match="needs an arm device"):
        QuadrupedArmRobot(legs, None, QuadrupedArmConfig(arm_mode="actuated"))
    with pytest.raises(ConfigError, match="has no arm device"):
        QuadrupedArmRobot(legs, arm, QuadrupedArmConfig(arm_mode="none"))
    with pytest.raises(ConfigError, match="expected 3"):
        QuadrupedArmRobot(legs, Device(5, clock, prefix="x"))
    with pytest.raises(ConfigError, match="expected 12"):
        QuadrupedArmRobot(Device(15, clock, prefix="x"), arm)
    with pytest.raises(ConfigError, match="stowed_q"):
        QuadrupedArmConfig(stowed_q=np.zeros(2))


def test_a_stale_arm_makes_the_joined_frame_stale_and_it_recovers() -> None:
    robot, legs, arm, clock = _pair(arm_stale_s=0.05)
    with robot:
        ticks = []
        for k in range(60):
            arm.stalled = 10 <= k < 40
            robot.advance(0.002)
            ticks.append(robot.read().tick)
    steps = np.diff(ticks)
    assert (steps[:9] == 1).all()  # both fresh: every frame is news
    assert (steps[9 + 26:39] == 0).all()  # the arm silent for longer than 50 ms: no frame is news
    assert steps[9:9 + 24].all()  # ... but not before its 50 ms were up
    assert (steps[41:] == 1).all()  # the arm back: news again


def test_the_safety_layer_trips_on_a_dead_arm_and_damps_both_devices() -> None:
    for mode in ("actuated", "locked"):
        robot, legs, arm, clock = _pair(mode)
        events = []
        safe = SafeRobot(robot, SafetyConfig(on_event=events.append, ramp_time_s=0.02))
        with safe:
            hold = MotorCommand.hold(safe.read().q, 30.0, 1.0)
            for _ in range(50):
                safe.read()
                safe.write(hold)
                safe.advance(0.002)
            assert safe.safety_state is SafetyState.RUN, events
            arm.stalled = True
            for _ in range(100):
                safe.read()
                safe.write(hold)
                safe.advance(0.002)
            assert safe.safety_state is SafetyState.DAMPED and events[-1].reason == "stale_state", (mode, events)
        assert (legs.sent[-1].kp == 0).all() and (legs.sent[-1].kd > 0).all()
        # the arm damped too, a locked one as well: a trip damps every motor, as an e-stop does
        assert (arm.sent[-1].kp == 0).all() and (arm.sent[-1].kd > 0).all(), mode


def test_an_arm_servo_alarm_trips_the_layer_by_motor_status() -> None:
    robot, legs, arm, _ = _pair()
    events = []
    safe = SafeRobot(robot, SafetyConfig(on_event=events.append, ramp_time_s=0.02))
    with safe:
        hold = MotorCommand.hold(safe.read().q, 30.0, 1.0)
        for k in range(60):
            if k == 40:
                arm.mode = np.array([0x0A, 0x20, 0x0A])  # the shoulder reports an error code
            safe.read()
            safe.write(hold)
            safe.advance(0.002)
    assert events[-1].reason == "motor_mode" and "(motor 13) reports mode 0x20" in events[-1].detail
    assert events[-1].detail.startswith(robot.joint_names[13])  # the arm's joint by name: its device names none


def test_connect_is_both_or_neither() -> None:
    clock = Clock()
    legs = Legs(12, clock, prefix="leg")
    robot = QuadrupedArmRobot(legs, Arm(3, clock, prefix="arm", fail_connect=True))
    with pytest.raises(RobotLinkError):
        robot.connect()
    assert not robot.is_connected and not legs.is_connected and legs.closed_count == 1


@pytest.mark.parametrize("mode", ["actuated", "locked"])
def test_contract(mode: str) -> None:
    check_robot(lambda: _pair(mode)[0])


@dataclasses.dataclass
class Counters:
    late_advances: int
    worst_lateness: float
    frames_sent: int

    def as_dict(self, prefix: str = "link/") -> dict[str, float]:
        return {f"{prefix}{k}": v for k, v in dataclasses.asdict(self).items()}


def test_link_stats_join_the_legs_pacing_and_the_arm_bus_counters() -> None:
    """A hardware trial reads the robot's lateness and link counters through `link_stats` (`HasLinkStats`): the legs'
    link paces the loop, so its lateness is the robot's; the arm bus's counters come beside it, under their own keys."""
    from wbc.hardware.capabilities import HasLinkStats

    robot, legs, arm, _ = _pair()
    assert isinstance(robot, HasLinkStats)
    assert robot.link_stats().late_advances == 0 and robot.link_stats().as_dict() == {}  # fakes without counters
    legs.link_stats = lambda: Counters(late_advances=3, worst_lateness=0.004, frames_sent=500)  # type: ignore[attr-defined]
    arm.bus_stats = lambda: Counters(late_advances=0, worst_lateness=0.0, frames_sent=200)  # type: ignore[attr-defined]
    stats = robot.link_stats()
    assert (stats.late_advances, stats.worst_lateness) == (3, 0.004)
    flat = stats.as_dict(prefix="")
    assert flat["frames_sent"] == 500 and flat["arm_bus/frames_sent"] == 200 and flat["late_advances"] == 3


@pytest.mark.parametrize(("cls", "protocols"), [
    ("wbc.hardware.unitree.UnitreeRobot", ("RemoteEstopLatch", "WriteDeadlineTrips", "RemoteSource")),
    ("wbc.hardware.quadruped_arm_robot.QuadrupedArmRobot", ("RemoteEstopLatch", "WriteDeadlineTrips", "RemoteSource",
                                                            "HeldJoints")),
    ("wbc.hardware.io_process.process_robot.ProcessRobot", ("RemoteEstopLatch", "WriteDeadlineTrips", "RemoteSource",
                                                            "HeldJoints")),
    ("wbc.hardware.dynamixel.DynamixelArm", ("WriteDeadlineTrips",)),
])
def test_each_real_robot_class_has_every_member_of_its_capabilities(cls: str, protocols: tuple[str, ...]) -> None:
    """A member left out drops the whole capability, silently: the safety layer then neither trips on the link's L2 + B
    latch nor releases it (a robot class without `remote_estop_latched` did so). Checked on the class, statically."""
    import importlib

    from wbc.hardware import capabilities

    module, name = cls.rsplit(".", 1)
    robot_class = getattr(importlib.import_module(module), name)
    for protocol in protocols:
        missing = sorted(member for member in capabilities.protocol_members(getattr(capabilities, protocol))
                         if not hasattr(robot_class, member))
        assert not missing, f"{name} lacks {missing} of {protocol}"
        assert capabilities.provides(robot_class, getattr(capabilities, protocol))


class CountingLegs(Legs):
    """Legs that count their write-deadline trips, and how often the count is read."""

    reads_of_trips = 0

    @property
    def deadline_trips(self) -> int:
        self.reads_of_trips += 1
        return 2


class CountingArm(Arm):
    reads_of_trips = 0

    @property
    def deadline_trips(self) -> int:
        self.reads_of_trips += 1
        return 1


def test_the_trip_counters_are_read_once_a_call_the_devices_that_count_them_resolved_once() -> None:
    # the I/O process publishes both with every state: a check against the runtime-checkable protocol per call read
    # each counter (under its device's lock) once more to see that it is there
    clock = Clock()
    legs, arm = CountingLegs(12, clock, prefix="leg"), CountingArm(3, clock, prefix="arm", q0=-0.3)
    robot = QuadrupedArmRobot(legs, arm, QuadrupedArmConfig(arm_mode="actuated"))
    legs.reads_of_trips = arm.reads_of_trips = 0
    assert robot.deadline_trips == 3 and robot.deadline_trips_by_device() == {"legs": 2, "arm": 1}
    assert (legs.reads_of_trips, arm.reads_of_trips) == (2, 2)
    plain = QuadrupedArmRobot(Legs(12, clock, prefix="leg"), Arm(3, clock, prefix="arm", q0=-0.3),
                              QuadrupedArmConfig(arm_mode="actuated"))
    assert plain.deadline_trips == 0 and plain.deadline_trips_by_device() == {}
