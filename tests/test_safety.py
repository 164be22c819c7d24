"""The safety layer `SafeRobot`: its contract, its states, and every trip injected and checked on what went out.

Most tests wrap `MujocoRobot` in `Faulty`, a robot that records each command it receives (what would reach the
wire) and reports the faults a test injects (a frozen tick, a bad joint, a tilted IMU, power, motor status, the
remote), then wrap that in `SafeRobot`.
"""

import dataclasses
import math

import numpy as np
import pytest

from wbc.arena.episode import Episode
from wbc.arena.runner import run_episode
from wbc.control.stand import StandController, stand_command
from wbc.errors import ConfigError, EpisodeFileError, SafetyResetError, UnknownNameError
from wbc.hardware import Robot, check_robot
from wbc.hardware.capabilities import HasSafetyEvents, MotorStatusSource, RemoteSource
from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
from wbc.hardware.safety import (
    REASONS,
    REMEDIES,
    TRIP_REASONS,
    UNITREE_POSITION_LIMITS,
    SafeRobot,
    SafetyConfig,
    SafetyEvent,
    SafetyState,
    position_range,
)
from wbc.hardware.unitree import LowStateExtras, Remote
from wbc.hardware.unitree.layout import MOTOR_STATE_MODES
from wbc.scenario import Push
from wbc.scenario.trial import CommandSchedule
from wbc.types import MotorCommand

DT = 0.02  # [s] control period (the stand controller's 50 Hz)
FAST = dict(ramp_time_s=0.2)  # a short ramp, so the trip tests reach ``run`` quickly


class Faulty(Robot):
    """Wraps a robot: records every command it is sent and reports the faults set on it."""

    def __init__(self, inner: Robot) -> None:
        super().__init__()
        self.inner = inner
        self.sent: list = []
        self.freeze = False
        self.q = None  # reported joint positions instead of the measured ones
        self.quat = None  # reported IMU quaternion
        self.power = None  # (tau_est, dq) reported
        self.buttons: tuple[str, ...] = ()
        self.modes = 0x0A
        self.temperature = 35
        self._frozen = None

    @property
    def joint_names(self):
        return self.inner.joint_names

    @property
    def limits(self):
        return self.inner.limits

    def _connect(self):
        self.inner.connect()

    def _close(self):
        self.inner.close()

    def _read(self):
        state = self.inner.read()
        if self.freeze:
            self._frozen = self._frozen or state
            return self._frozen
        self._frozen = None
        if self.q is not None:
            state = dataclasses.replace(state, q=np.asarray(self.q, dtype=float))
        if self.quat is not None:
            state = dataclasses.replace(state, imu_quat=np.asarray(self.quat, dtype=float))
        if self.power is not None:
            n = state.num_joints
            state = dataclasses.replace(state, tau_est=np.full(n, self.power[0]), dq=np.full(n, self.power[1]))
        return state

    def _send(self, cmd):
        self.sent.append(cmd)
        self.inner.write(cmd)

    def _advance(self, dt):
        self.inner.advance(dt)

    def remote(self):
        return Remote.build(buttons=self.buttons)

    def motor_status(self):
        return LowStateExtras(motor_mode=np.full(12, self.modes, dtype=np.uint8),
                              motor_temperature=np.full(12, self.temperature, dtype=np.int8))


def _make(arm="none", robot="a1-wx200", **cfg):
    events = []
    faulty = Faulty(MujocoRobot(MujocoRobotConfig(robot=robot, arm_mode=arm)))
    safe = SafeRobot(faulty, SafetyConfig(on_event=events.append, **cfg))
    return safe, faulty, events


def _drive(safe, cmd, ticks, until=None):
    """Read, write `cmd`, advance, `ticks` times (or until the state is `until`); (measured q, sent) per tick."""
    log = []
    for _ in range(ticks):
        state = safe.read()
        log.append((state.q.copy(), safe.write(cmd)))
        safe.advance(DT)
        if until is not None and safe.safety_state is until:
            break
    return log


def _is_damping(cmd, cfg):
    kd = np.full(cmd.num_joints, cfg.damping_kd)
    kd[12:] = cfg.arm_damping_kd
    return bool(np.all(cmd.kp == 0) and np.allclose(cmd.kd, kd) and np.all(cmd.tau == 0) and np.all(cmd.dq == 0))


def _check_ramp(log, safe, target):
    """The first non-damping command holds the measured pose (inside the position table); every later target moves
    at most slew x dt, and the last command is the controller's."""
    cfg = safe.config
    start = next(i for i, (_, sent) in enumerate(log) if not _is_damping(sent, cfg))
    measured, first = log[start]
    np.testing.assert_allclose(first.q, np.clip(measured, safe.position_lower, safe.position_upper))
    np.testing.assert_allclose(first.kp, cfg.ramp_kp)
    assert np.all(first.tau == 0)
    held = int(np.ceil(cfg.ramp_hold_s / DT - 1e-9))  # the hold stays on for ramp_hold_s before anything moves
    assert held >= 1
    for _, sent in log[start:start + held]:
        np.testing.assert_array_equal(sent.stacked(), first.stacked())
    assert not np.array_equal(log[start + held + 1][1].q, first.q)
    qs = np.array([sent.q for _, sent in log[start:]])
    assert np.abs(np.diff(qs, axis=0)).max() <= cfg.ramp_slew * DT + 1e-9
    last = log[-1][1]
    np.testing.assert_allclose(last.stacked(), target.stacked())


# -- contract and states ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("arm", ["none", "actuated"])
def test_safe_robot_passes_the_robot_contract(arm):
    check_robot(lambda: SafeRobot(MujocoRobot(MujocoRobotConfig(arm_mode=arm)), SafetyConfig(on_event=print)))
    check_robot(lambda: _make(arm)[0])


@pytest.mark.parametrize("arm", ["none", "actuated"])
def test_waiting_sends_only_damping_until_the_tick_advances(arm):
    safe, faulty, events = _make(arm)
    faulty.freeze = True  # no live stream: the tick never advances
    with safe:
        cmd = stand_command(faulty.inner.desc)
        log = _drive(safe, cmd, 20)
        assert safe.safety_state is SafetyState.WAITING
        assert all(_is_damping(sent, safe.config) for _, sent in log)
        assert all(_is_damping(c, safe.config) for c in faulty.sent)
        assert events == []
        faulty.freeze = False
        _drive(safe, cmd, 1)
        assert safe.safety_state is SafetyState.RAMP
        assert [(e.from_state, e.to_state, e.reason) for e in events] == [("waiting", "ramp", "fresh_state")]


def test_unsafe_start_begins_at_the_measured_pose_and_ramps_without_a_jump():
    safe, faulty, events = _make("actuated")
    with safe:
        robot = faulty.inner
        qpos = robot.data.qpos.copy()
        qpos[2] = 0.12  # lying on its belly, legs folded: far from the stand pose
        qpos[7:19] = np.tile([0.3, 1.9, -2.6], 4)
        qpos[19:] = [0.8, 0.5, -0.5]
        robot.reset(qpos=qpos)
        cmd = stand_command(robot.desc)
        log = _drive(safe, cmd, 250, until=SafetyState.RUN)
        assert safe.safety_state is SafetyState.RUN
        assert np.abs(log[1][0] - cmd.q).max() > 0.9  # it really started far away
        _check_ramp(log, safe, cmd)
        # what the inner robot received is what write returned
        for (_, sent), got in zip(log, faulty.sent, strict=True):
            np.testing.assert_array_equal(sent.stacked(), got.stacked())
        kps = np.array([sent.kp[0] for _, sent in log[1:]])
        assert np.all(np.diff(kps) >= -1e-12) and kps[0] == safe.config.ramp_kp and kps[-1] == cmd.kp[0]
        # the ramp lasted as long as the slowest joint needed at the slew rate
        distance = np.abs(log[1][0] - cmd.q).max()
        assert len(log) * DT >= distance / safe.config.ramp_slew
        assert [e.reason for e in events] == ["fresh_state", "ramp_done"]
        # the printed line says what was reached, in a whole sentence
        assert events[-1].detail == "the ramp reached the controller's own command (its targets and gains)"
        _drive(safe, cmd, 50)
        truth = robot.sim_truth()
        assert truth.base_position_in_world[2] > 0.2 and truth.ground_contact_bodies == ()  # it stood up


def test_the_ramp_lets_a_moving_controller_in_in_bounded_time():
    # A gait moves its swing legs' targets faster than any safe slew; the ramp closes the gap to them instead of
    # chasing them, so it ends (a chasing ramp never caught up and the controller ran under low gains).
    safe, faulty, events = _make("none", ramp_time_s=0.2)
    with safe:
        nominal = faulty.inner.desc.nominal_q
        hold = MotorCommand.hold(nominal, 30.0, 1.0)
        _drive(safe, hold, 400, until=SafetyState.RUN)  # standing, in run
        safe.estop()
        safe.read()
        safe.reset()  # a new ramp, from the measured pose, into a controller that swings the calves at 3 rad/s
        log, gaps = [], []
        for k in range(400):
            target = nominal.copy()
            target[2::3] += 0.3 * np.sin(10.0 * k * DT)
            cmd = MotorCommand.hold(target, 30.0, 1.0)
            safe.read()
            sent = safe.write(cmd)
            log.append(sent)
            gaps.append(np.abs(sent.q - target).max())
            safe.advance(DT)
            if safe.safety_state is SafetyState.RUN:
                break
        assert safe.safety_state is SafetyState.RUN and events[-1].reason == "ramp_done", events
        steps = np.diff(gaps[1:])  # from the first step on, the gap to the moving target
        assert steps.max() <= 1e-12 and (-steps).max() <= safe.config.ramp_slew * DT + 1e-9  # closes, no faster
        assert len(log) * DT <= 0.2 + gaps[1] / safe.config.ramp_slew + 2 * DT
        np.testing.assert_array_equal(log[-1].q, target)  # the last command is the controller's own


@pytest.mark.parametrize("robot", ["a1-wx200", "go1-arm"])
def test_standing_through_the_safety_layer_keeps_standing_and_ends_in_run(robot):
    inner = MujocoRobot(MujocoRobotConfig(robot=robot, arm_mode="actuated"))
    table = robot.split("-")[0]
    safe = SafeRobot(inner, SafetyConfig(position_table=table, on_event=lambda e: None))
    with safe:
        episode = run_episode(safe, StandController(inner.desc), CommandSchedule(), 2.0, truth=inner.base_truth,
                              fallen=inner.fallen)
        assert not episode.fell
        assert inner.sim_truth().base_position_in_world[2] > 0.2
        assert safe.safety_state is SafetyState.RUN
        assert [(e.to_state, e.reason) for e in safe.events] == [("ramp", "fresh_state"), ("run", "ramp_done")]


def test_targets_are_clipped_into_a_position_table_narrower_than_the_robots_own():
    """Go1's URDF lets the thigh reach 4.5 rad; Unitree's PositionLimit stops it at 2.966: with that table, a target
    beyond it reaches the robot at the table's bound, in the ramp and in run, whatever the robot would accept."""
    safe, faulty, _ = _make(robot="go1-arm", position_table="go1", **FAST)
    with safe:
        robot_upper = faulty.limits.upper
        table_lower, table_upper = position_range("go1", faulty.limits)
        thighs = [1, 4, 7, 10]
        assert (robot_upper[thighs] > table_upper[thighs] + 1.0).all()  # the robot alone would take 3.5 rad
        target = faulty.inner.desc.nominal_q.copy()
        target[thighs] = 3.5
        cmd = MotorCommand.hold(target, 20.0, 1.0)
        _drive(safe, cmd, 500, until=SafetyState.RUN)
        assert safe.safety_state is SafetyState.RUN
        _drive(safe, cmd, 3)
    sent = [c for c in faulty.sent if not _is_damping(c, safe.config)]
    assert sent and all((c.q >= table_lower).all() and (c.q <= table_upper).all() for c in sent)
    np.testing.assert_array_equal(sent[-1].q[thighs], table_upper[thighs])  # in run: the bound itself
    np.testing.assert_array_equal(np.delete(sent[-1].q, thighs), np.delete(target, thighs))


# -- trips ------------------------------------------------------------------------------------------------------
def _tilted(angle):
    return np.array([math.cos(angle / 2), math.sin(angle / 2), 0.0, 0.0])  # roll about x


def _bad_q(faulty):
    q = faulty.inner.desc.nominal_q.copy()
    q[2] = faulty.inner.limits.lower[2] - 0.2  # FR calf folded far past its range
    return q


TRIPS = {
    # reason: (inject, clear, does the fault alone refuse a reset)
    "stale_state": (lambda f: setattr(f, "freeze", True), lambda f: setattr(f, "freeze", False), True),
    "bad_state": (lambda f: setattr(f, "q", np.full(f.num_joints, np.nan)), lambda f: setattr(f, "q", None), True),
    "joint_range": (lambda f: setattr(f, "q", _bad_q(f)), lambda f: setattr(f, "q", None), True),
    "over_power": (lambda f: setattr(f, "power", (20.0, 5.0)), lambda f: setattr(f, "power", None), True),
    "motor_temperature": (lambda f: setattr(f, "temperature", 90), lambda f: setattr(f, "temperature", 35), True),
    "motor_mode": (lambda f: setattr(f, "modes", 0x07), lambda f: setattr(f, "modes", 0x0A), True),
    "tilt": (lambda f: setattr(f, "quat", _tilted(1.3)), lambda f: setattr(f, "quat", None), True),
    "remote_estop": (lambda f: setattr(f, "buttons", ("L2", "B")), lambda f: setattr(f, "buttons", ()), True),
    "software_estop": (lambda f: None, lambda f: None, False),
}


def test_each_trip_reason_has_a_remedy_of_its_own() -> None:
    assert set(REMEDIES) == set(TRIP_REASONS)
    assert len(set(REMEDIES.values())) == len(REMEDIES)  # no reason borrows another's words
    joint_pose = "pose inside its joint ranges"
    assert [r for r, text in REMEDIES.items() if joint_pose in text] == ["joint_range"]
    for reason, words in (("remote_estop", "L2 + B"), ("motor_temperature", "cool"), ("over_power", "power"),
                          ("stale_state", "stopped answering"), ("tilt", "upright"), ("motor_mode", "0x08")):
        assert words in SafetyEvent(time=0.0, from_state=SafetyState.RUN, to_state=SafetyState.DAMPED,
                                    reason=reason).remedy
    assert SafetyEvent(time=0.0, from_state=SafetyState.WAITING, to_state=SafetyState.RAMP,
                       reason="fresh_state").remedy == ""


@pytest.mark.parametrize(("mode", "trips"), [(0x0A, False), (0x00, False), (0x08, True), (0x05, True)])
def test_motor_modes_the_vendor_documents(mode, trips):
    """Servo and damping are normal; overheat (0x08, Go1 SDK 3.8) and any other code trip, naming the joint."""
    safe, faulty, events = _make("actuated", **FAST)
    with safe:
        cmd = stand_command(faulty.inner.desc)
        _drive(safe, cmd, 100, until=SafetyState.RUN)
        faulty.modes = mode
        _drive(safe, cmd, 10, until=SafetyState.DAMPED)
        assert (safe.safety_state is SafetyState.DAMPED) == trips
        if trips:
            named = f" ({MOTOR_STATE_MODES[mode]})" if mode in MOTOR_STATE_MODES else ""  # 0x08 (overheat)
            assert events[-1].detail == f"FR_hip_joint (motor 0) reports mode {mode:#04x}{named} (ok: 0x00, 0x0a)"


@pytest.mark.parametrize("reason", list(TRIPS))
def test_each_trip_damps_at_once_latches_and_resets_only_when_safe_into_a_ramp(reason):
    inject, clear, refuses = TRIPS[reason]
    safe, faulty, events = _make("actuated", **FAST)
    cfg = safe.config
    with safe:
        cmd = stand_command(faulty.inner.desc)
        _drive(safe, cmd, 100, until=SafetyState.RUN)
        assert safe.safety_state is SafetyState.RUN
        safe.reset()  # nothing latched: a no-op
        assert safe.safety_state is SafetyState.RUN
        n_before = len(faulty.sent)
        inject(faulty)
        if reason == "software_estop":
            safe.estop()
        log = _drive(safe, cmd, 30, until=SafetyState.DAMPED)
        assert safe.safety_state is SafetyState.DAMPED
        assert events[-1].reason == reason and events[-1].from_state == "run"
        # damping went out at the trip itself, one command more than the controller wrote, before its next one
        assert len(faulty.sent) == n_before + len(log) + 1
        trip = n_before + len(log) - 1
        assert _is_damping(faulty.sent[trip], cfg) and _is_damping(faulty.sent[trip + 1], cfg)
        assert reason == "software_estop" or not _is_damping(faulty.sent[trip - 1], cfg)
        assert _is_damping(safe.write(cmd), cfg)
        assert _is_damping(faulty.sent[-1], cfg)
        if refuses:
            with pytest.raises(SafetyResetError):
                safe.reset()
            assert safe.safety_state is SafetyState.DAMPED
        clear(faulty)
        # latched: the fault is gone, yet every command for the next second is damping
        latched = _drive(safe, cmd, 50)
        assert all(_is_damping(sent, cfg) for _, sent in latched)
        assert safe.safety_state is SafetyState.DAMPED
        safe.reset()
        assert safe.safety_state is SafetyState.RAMP and events[-1].reason == "reset"
        log = _drive(safe, cmd, 200, until=SafetyState.RUN)
        assert safe.safety_state is SafetyState.RUN
        _check_ramp(log, safe, cmd)
        assert [e.reason for e in events][-3:] == [reason, "reset", "ramp_done"]


def test_reset_is_refused_while_stale_or_any_remote_button_is_held():
    safe, faulty, events = _make("none", **FAST)
    with safe:
        cmd = stand_command(faulty.inner.desc)
        _drive(safe, cmd, 100, until=SafetyState.RUN)
        faulty.buttons = ("L2", "B")
        _drive(safe, cmd, 1)
        assert events[-1].reason == "remote_estop"
        faulty.buttons = ("L2",)  # B released, L2 still held
        _drive(safe, cmd, 5)
        with pytest.raises(SafetyResetError, match="remote buttons held"):
            safe.reset()
        faulty.buttons = ()
        faulty.freeze = True
        _drive(safe, cmd, 5)
        with pytest.raises(SafetyResetError, match="stale"):
            safe.reset()
        faulty.freeze = False
        safe.read()
        safe.reset()
        assert safe.safety_state is SafetyState.RAMP


def test_over_power_trips_only_after_more_than_n_consecutive_frames():
    safe, faulty, events = _make("none", **FAST)
    n = safe.config.power_frames
    with safe:
        cmd = stand_command(faulty.inner.desc)
        _drive(safe, cmd, 100, until=SafetyState.RUN)
        for _ in range(3):  # n frames over the limit, then one under: the count starts again
            faulty.power = (20.0, 5.0)  # 12 x 100 W
            _drive(safe, cmd, n)
            faulty.power = None
            _drive(safe, cmd, 1)
        assert safe.safety_state is SafetyState.RUN
        faulty.power = (20.0, 5.0)
        _drive(safe, cmd, n)
        assert safe.safety_state is SafetyState.RUN
        _drive(safe, cmd, 1)
        assert safe.safety_state is SafetyState.DAMPED and events[-1].reason == "over_power"


def test_a_real_fall_from_a_push_trips_on_tilt():
    safe, faulty, events = _make("none", **FAST)
    with safe:
        cmd = stand_command(faulty.inner.desc)
        _drive(safe, cmd, 100, until=SafetyState.RUN)
        t = faulty.inner.time
        faulty.inner.apply_push(Push(force_in_world=np.array([0.0, 600.0, 0.0]),
                                     offset_in_base=np.array([0.0, 0.0, 0.1]), start=t, duration=0.15))
        _drive(safe, cmd, 100, until=SafetyState.DAMPED)
        assert safe.safety_state is SafetyState.DAMPED and events[-1].reason == "tilt"
        assert _is_damping(faulty.sent[-1], safe.config)


def test_a_stalled_control_loop_trips_at_the_next_write_with_a_wall_clock():
    now = [0.0]
    faulty = Faulty(MujocoRobot(MujocoRobotConfig(arm_mode="none")))
    safe = SafeRobot(faulty, SafetyConfig(on_event=lambda e: None, **FAST), clock=lambda: now[0])
    with safe:
        cmd = stand_command(faulty.inner.desc)
        for _ in range(100):
            safe.read()
            safe.write(cmd)
            safe.advance(DT)
            now[0] += DT
            if safe.safety_state is SafetyState.RUN:
                break
        safe.read()
        now[0] += 0.5  # the controller took half a second
        sent = safe.write(cmd)
        assert _is_damping(sent, safe.config) and _is_damping(faulty.sent[-1], safe.config)
        assert safe.events[-1].reason == "stale_state"


def test_estop_before_connect_latches_and_the_stream_must_start_before_a_reset():
    safe, faulty, events = _make("none")
    safe.estop()
    assert safe.safety_state is SafetyState.DAMPED
    with safe:
        cmd = stand_command(faulty.inner.desc)
        assert _is_damping(safe.write(cmd), safe.config)
        safe.read()
        with pytest.raises(SafetyResetError, match="stale"):
            safe.reset()
        log = _drive(safe, cmd, 10)
        assert all(_is_damping(sent, safe.config) for _, sent in log)
        safe.reset()
        assert safe.safety_state is SafetyState.RAMP


# -- records, config, tables ------------------------------------------------------------------------------------
def test_events_are_records_handed_to_the_callback_in_order():
    safe, faulty, events = _make("none", **FAST)
    with safe:
        _drive(safe, stand_command(faulty.inner.desc), 100, until=SafetyState.RUN)
        safe.estop()
    assert list(safe.events) == events
    assert [e.reason for e in events] == ["fresh_state", "ramp_done", "software_estop"]
    assert all(e.reason in REASONS for e in events)
    times = [e.time for e in events]
    assert times == sorted(times) and times[0] > 0
    d = events[-1].to_dict()
    assert d == {"time": events[-1].time, "from_state": "run", "to_state": "damped", "reason": "software_estop",
                 "detail": "estop() called"}
    assert "run -> damped (software_estop)" in str(events[-1])


def test_the_fake_robot_offers_the_capabilities_and_the_simulator_none():
    faulty = Faulty(MujocoRobot(MujocoRobotConfig(arm_mode="none")))
    assert isinstance(faulty, RemoteSource) and isinstance(faulty, MotorStatusSource)
    assert not isinstance(faulty.inner, RemoteSource) and not isinstance(faulty.inner, MotorStatusSource)


@pytest.mark.parametrize("field,value", [("stale_timeout_s", 0.0), ("power_limit_w", -1.0), ("damping_kd", -3.0),
                                         ("ramp_slew", math.nan), ("max_tilt", 4.0), ("power_frames", -1)])
def test_config_rejects_bad_values(field, value):
    with pytest.raises(ConfigError, match=field):
        SafetyConfig(**{field: value})


def test_an_unknown_position_table_lists_the_valid_ones():
    with pytest.raises(UnknownNameError, match="a1, go1, robot"):
        SafetyConfig(position_table="b2")


def test_unitree_tables_replace_the_leg_ranges_and_keep_the_arm_s():
    robot = MujocoRobot(MujocoRobotConfig(robot="go1-arm", arm_mode="actuated"))
    lower, upper = position_range("go1", robot.limits)
    table = np.tile(np.array(UNITREE_POSITION_LIMITS["go1"]), (4, 1))
    np.testing.assert_array_equal(lower[:12], table[:, 0])
    np.testing.assert_array_equal(upper[:12], table[:, 1])
    np.testing.assert_array_equal(lower[12:], robot.limits.lower[12:])
    lower, upper = position_range("robot", robot.limits)
    np.testing.assert_array_equal(lower, robot.limits.lower)
    assert np.all((robot.desc.nominal_q > lower) & (robot.desc.nominal_q < upper))


def test_close_leaves_damping_and_a_reconnection_waits_for_the_stream_again():
    safe, faulty, events = _make("none", **FAST)
    cmd = stand_command(faulty.inner.desc)
    with safe:
        _drive(safe, cmd, 100, until=SafetyState.RUN)
    assert _is_damping(faulty.sent[-1], safe.config)
    with safe:
        assert safe.safety_state is SafetyState.WAITING and events[-1].reason == "connect"
        log = _drive(safe, cmd, 100, until=SafetyState.RUN)
        assert _is_damping(log[0][1], safe.config)
        _check_ramp(log, safe, cmd)


def test_a_zero_quaternion_is_a_bad_state_not_an_upright_robot():
    safe, faulty, events = _make("none", **FAST)
    with safe:
        _drive(safe, stand_command(faulty.inner.desc), 100, until=SafetyState.RUN)
        faulty.quat = np.zeros(4)
        _drive(safe, stand_command(faulty.inner.desc), 1)
        assert safe.safety_state is SafetyState.DAMPED and "norm 0.000" in events[-1].detail


# -- the episode logs the layer's transitions -------------------------------------------------------------------
def test_an_episode_through_the_safety_layer_logs_its_transitions_and_keeps_them_on_disk(tmp_path):
    inner = MujocoRobot(MujocoRobotConfig(arm_mode="none"))
    safe = SafeRobot(inner, SafetyConfig(on_event=lambda e: None, **FAST))
    assert isinstance(safe, HasSafetyEvents) and not isinstance(inner, HasSafetyEvents)

    def estop_after_half_a_second(t, robot, controller, command):
        if t >= 0.5 and robot.safety_state is not SafetyState.DAMPED:
            robot.estop()

    with safe:
        episode = run_episode(safe, StandController(inner.desc), CommandSchedule(), 1.0, truth=inner.base_truth,
                              fallen=inner.fallen, observer=estop_after_half_a_second)
    log = episode.safety_events
    assert [(a, b, r) for _, a, b, r, _ in log.rows()] == [
        ("waiting", "ramp", "fresh_state"), ("ramp", "run", "ramp_done"), ("run", "damped", "software_estop")]
    assert [e.to_dict() for e in safe.events] == [
        dict(time=t, from_state=a, to_state=b, reason=r, detail=d) for t, a, b, r, d in log.rows()]
    times = log.time
    assert times[0] == pytest.approx(DT)  # the second read is the first fresh one
    assert times[0] < times[1] < 0.5 <= times[2] < 0.5 + DT + 1e-9  # the ramp is 0.2 s; the e-stop on its tick
    assert log.detail[2] == "estop() called"
    path = tmp_path / "episode.npz"
    episode.save(str(path))
    loaded = Episode.load(str(path))
    assert loaded.safety_events.rows() == log.rows()
    assert loaded.safety_events.reason.dtype.kind == "U"
    with np.load(path, allow_pickle=False) as z:  # plain arrays, no pickles
        assert z["safety_reason"].tolist() == ["fresh_state", "ramp_done", "software_estop"]
        old = {k: z[k] for k in z.files if not k.startswith("safety_")}
    np.savez_compressed(tmp_path / "old.npz", **old)  # a file written before episodes kept safety events
    with pytest.raises(EpisodeFileError, match="field safety_time missing .* another version of wbc"):
        Episode.load(str(tmp_path / "old.npz"))

    with MujocoRobot(MujocoRobotConfig(arm_mode="none")) as plain:
        bare = run_episode(plain, StandController(plain.desc), CommandSchedule(), 0.2)
    assert len(bare.safety_events) == 0 and bare.safety_events.rows() == []
    bare.save(str(tmp_path / "bare.npz"))
    assert len(Episode.load(str(tmp_path / "bare.npz")).safety_events) == 0


def test_the_safety_layer_prints_each_transition_by_default(capsys):
    safe = SafeRobot(MujocoRobot(MujocoRobotConfig(arm_mode="none")), SafetyConfig(**FAST))
    with safe:
        _drive(safe, stand_command(safe.robot.desc), 2)
        safe.estop()
    err = capsys.readouterr().err.splitlines()
    assert [line for line in err if line.startswith("safety t=")] == [str(e) for e in safe.events]
    assert [e.reason for e in safe.events] == ["fresh_state", "software_estop"]


def test_a_trip_sends_its_damping_before_it_reports_the_trip():
    """The layer printed a trip's event (or called `on_event`) before it wrote the damping: a reader of standard error
    that stalled (a paused pager) held the damping back. The damping goes out first, then the word of it."""
    seen = []
    faulty = Faulty(MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none")))

    def on_event(event):  # what had reached the robot when the layer told of the event
        seen.append((event.to_state, len(faulty.sent), faulty.sent[-1] if faulty.sent else None))

    safe = SafeRobot(faulty, SafetyConfig(on_event=on_event, **FAST))
    with safe:
        _drive(safe, stand_command(faulty.inner.desc), 200, until=SafetyState.RUN)
        safe.estop()
    (damped,) = [s for s in seen if s[0] is SafetyState.DAMPED]
    assert damped[2] is not None and _is_damping(damped[2], safe.config)


class _CountedLatch(Faulty):
    """A robot with an L2 + B latch and write-deadline trips whose properties count how often they are read."""

    def __init__(self, inner: Robot) -> None:
        super().__init__(inner)
        self.reads = {"remote_estops": 0, "remote_estop_latched": 0, "deadline_trips": 0}

    @property
    def remote_estops(self) -> int:
        self.reads["remote_estops"] += 1
        return 0

    @property
    def remote_estop_latched(self) -> bool:
        self.reads["remote_estop_latched"] += 1
        return False

    def release_remote_estop(self) -> bool:
        return True

    @property
    def deadline_trips(self) -> int:
        self.reads["deadline_trips"] += 1
        return 0


def test_the_layer_looks_its_robots_capabilities_up_once_not_on_every_tick() -> None:
    """isinstance against a runtime-checkable protocol runs every property of it (a device's lock, the I/O process's
    state block): the layer reads only what it needs on a tick, and `remote_estop_latched` never."""
    robot = _CountedLatch(MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none")))
    safe = SafeRobot(robot, SafetyConfig())
    assert robot.reads == {"remote_estops": 0, "remote_estop_latched": 0, "deadline_trips": 0}
    with safe:
        robot.reads = dict.fromkeys(robot.reads, 0)
        _drive(safe, MotorCommand.damping(12, 1.0), 50)
    assert robot.reads["remote_estop_latched"] == 0, robot.reads
    assert robot.reads["remote_estops"] == 50, robot.reads  # one look per read
    assert robot.reads["deadline_trips"] == 100, robot.reads  # one per read and one per write
