"""The hardware-safety cases: SafeRobot(UnitreeRobot) against UnitreeEmulator, each fault injected, each reaction
checked on the wire.

Every case injects its fault in the emulator and reads what reached the emulated robot from the emulator's log of
decoded command frames (`UnitreeEmulator.commands`), not from what the layers meant to send. The safety layer runs on
the link's wall clock, as on a robot (`UnitreeRobot` is a `WallClock`), with no clock handed in. Every socket binds
127.0.0.1 on a port the kernel picks; every loop is bounded in iterations and in time.
"""

from __future__ import annotations

import gc
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
import pytest

from wbc.control.stand import StandController, stand_command
from wbc.errors import RobotLinkError, SafetyResetError
from wbc.hardware.emulators import Fault, LoggedCommand, UnitreeEmulator, UnitreeEmulatorConfig
from wbc.hardware.interpreter import freeze_heap
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.hardware.safety import MotorStatusSource, RemoteSource, SafeRobot, SafetyConfig, SafetyEvent, SafetyState
from wbc.hardware.unitree import DESCRIPTIONS, UnitreeRobot, UnitreeRobotConfig
from wbc.types import MotorCommand

ROBOTS = ("go1", "a1")
LOOPBACK = "127.0.0.1"
PERIOD = 0.004  # [s] the control loop's period in these tests (the link runs at 500 Hz, 0.002 s)
LINK_PERIOD = 0.002  # [s]
Q_QUANTUM = 1e-6  # [rad] a joint target goes out as float32: |q| < 5 rad rounds by less than 5e-7
FAST = dict(ramp_time_s=0.2)  # a short ramp, so that a case reaches ``run`` quickly


@contextmanager
def _rig(robot: str = "go1", *, mode: str = "lockstep", qpos: np.ndarray | None = None,
         **safety: object) -> Iterator[tuple[UnitreeEmulator, SafeRobot, list[SafetyEvent]]]:
    """An emulator (optionally reset to `qpos` first) and a connected SafeRobot(UnitreeRobot) talking to it."""
    events: list[SafetyEvent] = []
    with UnitreeEmulator(UnitreeEmulatorConfig(robot=robot, mode=mode)) as emu:
        if qpos is not None:
            emu.reset(qpos)
        host, port = emu.address
        assert host == LOOPBACK
        link = UnitreeRobot(UnitreeRobotConfig(robot=robot, target_host=host, target_port=port))
        safe = SafeRobot(link, SafetyConfig(on_event=events.append, **safety))
        with safe:
            yield emu, safe, events
        assert emu.failure is None, emu.failure
    assert not [t.name for t in threading.enumerate() if t.name.startswith("unitree-")]  # every thread stopped


def _loop(safe: SafeRobot, cmd: MotorCommand, seconds: float,
          until: Callable[[], bool] | None = None) -> list[tuple[np.ndarray, MotorCommand]]:
    """Read, write `cmd`, advance PERIOD, for `seconds` of wall time (or until `until()`); (measured q, sent)."""
    log = []
    end = time.monotonic() + seconds
    for _ in range(int(seconds / PERIOD) + 2):
        if time.monotonic() >= end:
            break
        state = safe.read()
        log.append((state.q.copy(), safe.write(cmd)))
        safe.advance(PERIOD)
        if until is not None and until():
            break
    return log


def _run_to(safe: SafeRobot, cmd: MotorCommand, state: SafetyState, seconds: float = 2.0) -> None:
    _loop(safe, cmd, seconds, until=lambda: safe.safety_state is state)
    assert safe.safety_state is state, safe.events


def _stand(safe: SafeRobot) -> MotorCommand:
    return stand_command(safe.robot.desc)


def _after(emu: UnitreeEmulator, t: float) -> list[LoggedCommand]:
    return [c for c in emu.commands() if c.time > t]


def _first_damping(emu: UnitreeEmulator, since: float, timeout: float = 0.2) -> LoggedCommand:
    """The first damping frame the emulator decoded after `since`, waiting up to `timeout` for it to arrive (the trip
    hands damping to the link thread, which sends it at its next period; a loaded machine may run that late)."""
    end = time.monotonic() + timeout
    while True:
        found = next((c for c in _after(emu, since) if c.damping), None)
        if found is not None or time.monotonic() >= end:
            assert found is not None, f"no damping frame on the wire within {timeout} s"
            return found
        time.sleep(LINK_PERIOD / 2)


def _inject_until_damped(emu: UnitreeEmulator, safe: SafeRobot, cmd: MotorCommand, fault: Fault, value: object = None,
                         *, reason: str, seconds: float = 0.3) -> tuple[float, LoggedCommand]:
    """Inject `fault`, keep the loop going until the layer is damped for `reason`; (injection time, first damping frame
    on the wire after it)."""
    if value is None:
        emu.inject(fault)
    else:
        emu.inject(fault, value)
    injected = time.monotonic()
    _loop(safe, cmd, seconds, until=lambda: safe.safety_state is SafetyState.DAMPED)
    assert safe.safety_state is SafetyState.DAMPED and safe.events[-1].reason == reason, safe.events[-1]
    return injected, _first_damping(emu, injected)


def _first_servo(frames: list[LoggedCommand]) -> LoggedCommand:
    return next(c for c in frames if not c.damping)


def _assert_latched(emu: UnitreeEmulator, safe: SafeRobot, cmd: MotorCommand, since: float, seconds: float) -> None:
    """The layer stays ``damped`` for `seconds` of writes, and every frame on the wire from `since` on is damping."""
    _loop(safe, cmd, seconds)
    assert safe.safety_state is SafetyState.DAMPED
    frames = _after(emu, since)
    assert len(frames) > seconds / LINK_PERIOD / 2 and all(c.damping for c in frames)


def _timed_writes(safe: SafeRobot, cmd: MotorCommand, seconds: float) -> list[tuple[float, float, np.ndarray,
                                                                                       MotorCommand]]:
    """Read, write `cmd`, advance PERIOD, for `seconds`; per write (wall time before it, after it, measured q, sent)."""
    writes = []
    end = time.monotonic() + seconds
    for _ in range(int(seconds / PERIOD) + 2):
        if time.monotonic() >= end:
            break
        q = safe.read().q.copy()
        before = time.monotonic()
        sent = safe.write(cmd)
        writes.append((before, time.monotonic(), q, sent))
        safe.advance(PERIOD)
    return writes


def _check_ramp_slew(safe: SafeRobot, writes: list, frames: list[LoggedCommand]) -> float:
    """The layer's targets close on the controller's no faster than the slew over the wall time between its writes
    (it reads its clock between the two stamps of a write, so the bound needs no slack), and the servo frames on the
    wire carry exactly those targets, in their order; returns the largest step's share of its bound."""
    targets = np.array([w[3].q for w in writes])
    steps = np.abs(np.diff(targets, axis=0)).max(axis=1)
    bounds = safe.config.ramp_slew * np.array([b[1] - a[0] for a, b in zip(writes, writes[1:], strict=False)])
    assert (steps <= bounds + Q_QUANTUM).all()
    k = 0
    for frame in (c for c in frames if not c.damping):
        while k < len(targets) and not np.allclose(frame.wire.q, targets[k], atol=Q_QUANTUM):
            k += 1
        assert k < len(targets), "a target reached the wire that the layer never sent"
    return float((steps / (bounds + Q_QUANTUM)).max()) if steps.size else 0.0


def _reset_and_check_ramp(emu: UnitreeEmulator, safe: SafeRobot, cmd: MotorCommand) -> np.ndarray:
    """Reset the latch; the first servo frame on the wire holds the measured pose with the ramp's start gains, and
    the targets after it move no faster than the ramp's slew over wall time.

    Returns the measured pose the ramp started from."""
    safe.read()
    reset_at = time.monotonic()
    safe.reset()
    assert safe.safety_state is SafetyState.RAMP
    writes = _timed_writes(safe, cmd, 0.05)
    measured = writes[0][2]  # what the layer read just before the ramp's first write
    servo = [c for c in _after(emu, reset_at) if not c.damping]
    first = servo[0]
    np.testing.assert_allclose(first.wire.q, measured, atol=Q_QUANTUM)
    np.testing.assert_allclose(first.wire.q, writes[0][3].q, atol=Q_QUANTUM)
    np.testing.assert_array_equal(first.wire.kp, safe.config.ramp_kp)
    assert np.all(first.wire.tau == 0)
    assert len(servo) > 10 and safe.safety_state is SafetyState.RAMP
    _check_ramp_slew(safe, writes, servo)
    return measured


def test_unitree_robot_reports_remote_and_motor_status_to_the_safety_layer() -> None:
    robot = UnitreeRobot(UnitreeRobotConfig(robot="go1", target_host=LOOPBACK, target_port=9))
    assert isinstance(robot, RemoteSource) and isinstance(robot, MotorStatusSource)
    with pytest.raises(RobotLinkError, match="no valid state"):
        robot.remote()  # nothing to report before a state arrived
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1")) as emu:
        emu.inject(Fault.OVER_TEMPERATURE, 80)
        emu.inject(Fault.REMOTE_L2_B)
        with UnitreeRobot(UnitreeRobotConfig(robot="go1", target_host=LOOPBACK, target_port=emu.address[1])) as robot:
            assert robot.remote().l2_b and (robot.motor_status().motor_temperature == 80).all()


# -- 1: the state stream stops ------------------------------------------------------------------------------------
@pytest.mark.parametrize("robot", ROBOTS)
def test_silence_damps_within_the_stale_timeout_latches_and_ramps_after_reset(robot: str) -> None:
    with _rig(robot, **FAST) as (emu, safe, events):
        cmd = _stand(safe)
        _run_to(safe, cmd, SafetyState.RUN)
        silenced, first = _inject_until_damped(emu, safe, cmd, Fault.SILENCE, reason="stale_state", seconds=0.5)
        frames = _after(emu, silenced)
        latency = first.time - silenced
        print(f"\n{robot}: state stream stopped -> damping on the wire after {latency * 1e3:.1f} ms "
              f"(stale timeout {safe.config.stale_timeout_s * 1e3:.0f} ms)")
        assert latency <= safe.config.stale_timeout_s + 5 * PERIOD
        assert all(c.damping for c in frames if c.time >= first.time)
        safe.read()
        with pytest.raises(SafetyResetError, match="stale"):
            safe.reset()  # nothing fresh to ramp from while the stream is silent
        emu.clear()  # the stream resumes: the latch holds
        resumed, states = time.monotonic(), safe.robot.link_stats().valid_states
        _assert_latched(emu, safe, cmd, first.time, 0.1)
        # the stream really is back (at least half the link's rate over the window, and fresh by the layer's own
        # timeout), so what holds the damping is the latch, not a stale state
        stats, window = safe.robot.link_stats(), time.monotonic() - resumed
        assert window > 0.05 and stats.valid_states - states >= 0.5 * window / LINK_PERIOD
        assert stats.state_age < safe.config.stale_timeout_s
        q0 = _reset_and_check_ramp(emu, safe, cmd)
        print(f"{robot}: ramp after reset starts {np.abs(q0 - cmd.q).max():.3f} rad from the stand target")


# -- 3: the control loop stalls -----------------------------------------------------------------------------------
@pytest.mark.parametrize("robot", ROBOTS)
def test_loop_stall_damps_on_the_wire_and_resumes_without_a_jump(robot: str) -> None:
    with _rig(robot, **FAST) as (emu, safe, events):
        cmd = _stand(safe)
        _run_to(safe, cmd, SafetyState.RUN)
        # A few writes in run, so that a frame the link thread composed before the last write (and sends just after
        # it) already carries the controller's command rather than the ramp's last step.
        _loop(safe, cmd, 5 * PERIOD)
        assert safe.safety_state is SafetyState.RUN, safe.events
        deadline = safe.robot.config.write_deadline
        stalled_at = time.monotonic()  # the last write was just before this
        time.sleep(3 * deadline)  # a stall longer than both the link's write deadline and the stale timeout
        resumed_at = time.monotonic()
        stall = [c for c in _after(emu, stalled_at) if c.time < resumed_at]
        first = next(c for c in stall if c.damping)
        latency = first.time - stalled_at
        print(f"\n{robot}: loop stalled -> the link's damping on the wire after {latency * 1e3:.1f} ms "
              f"(write deadline {deadline * 1e3:.0f} ms)")
        assert latency <= deadline + 5 * LINK_PERIOD
        assert all(c.damping for c in stall if c.time >= first.time)
        assert all(not c.damping and (c.wire.kp == cmd.kp).all() for c in stall if c.time < first.time)
        assert safe.robot.link_stats().deadline_trips == 1
        # The loop resumes: the layer saw the stall on its wall clock, so the stand command must not pass.
        _loop(safe, cmd, 0.05)
        assert safe.safety_state is SafetyState.DAMPED and events[-1].reason == "stale_state"
        assert all(c.damping for c in _after(emu, resumed_at))
        q0 = _reset_and_check_ramp(emu, safe, cmd)
        print(f"{robot}: after the stall the ramp starts {np.abs(q0 - cmd.q).max():.3f} rad from the stand target")


# -- 5, 6, 7: state faults ----------------------------------------------------------------------------------------
STATE_CASES = [
    (Fault.JOINT_OUT_OF_RANGE, (2, 0.5), "joint_range"),  # calf 0 reports +0.5 rad (its range ends below -0.8)
    (Fault.OVER_TEMPERATURE, 95, "motor_temperature"),
    (Fault.MOTOR_ERROR, 0x05, "motor_mode"),  # neither servo 0x0A nor off 0x00: a motor error code
    (Fault.FALL, np.pi / 2, "tilt"),  # the IMU reads the trunk rolled onto its side
]


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize(("fault", "value", "reason"), STATE_CASES, ids=[c[0].value for c in STATE_CASES])
def test_state_fault_damps_on_the_wire_and_latches(robot: str, fault: Fault, value: object, reason: str) -> None:
    with _rig(robot, **FAST) as (emu, safe, events):
        assert isinstance(safe.robot, MotorStatusSource) and isinstance(safe.robot, RemoteSource)
        cmd = _stand(safe)
        _run_to(safe, cmd, SafetyState.RUN)
        injected, first = _inject_until_damped(emu, safe, cmd, fault, value, reason=reason)
        frames = _after(emu, injected)
        assert first.time - injected <= 10 * LINK_PERIOD
        assert all(c.damping for c in frames if c.time >= first.time)
        with pytest.raises(SafetyResetError, match=reason):
            safe.reset()  # refused while the fault is still reported
        emu.clear(fault)
        _assert_latched(emu, safe, cmd, first.time, 0.06)  # the fault has gone; the latch holds
        _reset_and_check_ramp(emu, safe, cmd)


def _power(state) -> float:
    return float(np.abs(state.tau_est * state.dq).sum())


def _over_power_frames(safe: SafeRobot, cmd: MotorCommand, count: int, last_tick: list[int]) -> int:
    """Loop until `count` fresh frames in a row report power above the limit (as the layer counts them: a frame is
    fresh when its tick differs from the previous read's), or the layer damps; return the run counted."""
    run = 0
    for _ in range(500):
        state = safe.read()
        if state.tick != last_tick[0]:
            run = run + 1 if _power(state) > safe.config.power_limit_w else 0
        last_tick[0] = state.tick
        if run >= count or safe.safety_state is SafetyState.DAMPED:
            return run
        safe.write(cmd)
        safe.advance(PERIOD)
    return run


def _until_quiet(safe: SafeRobot, cmd: MotorCommand, last_tick: list[int]) -> None:
    """Loop until a fresh frame reports power within the limit (the layer's count starts again)."""
    for _ in range(500):
        safe.write(cmd)
        safe.advance(PERIOD)
        state = safe.read()
        fresh = state.tick != last_tick[0]
        last_tick[0] = state.tick
        if fresh and _power(state) <= safe.config.power_limit_w:
            return
    raise AssertionError("the reported power never came back under the limit")


# -- 6: over-power ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("robot", ROBOTS)
def test_over_power_damps_only_after_more_than_the_configured_frames_and_latches(robot: str) -> None:
    with _rig(robot, **FAST) as (emu, safe, events):
        cmd = _stand(safe)
        n = safe.config.power_frames
        _run_to(safe, cmd, SafetyState.RUN)
        start = time.monotonic()
        last_tick = [safe.read().tick]
        for _ in range(3):  # bursts of exactly n over-power frames: PowerProtect lets them pass
            emu.inject(Fault.OVER_POWER)
            assert _over_power_frames(safe, cmd, n, last_tick) == n
            assert safe.safety_state is SafetyState.RUN, events[-1]
            emu.clear(Fault.OVER_POWER)
            time.sleep(5 * LINK_PERIOD)  # replies already on their way carry the fault; the next read is after it
            _until_quiet(safe, cmd, last_tick)
            assert safe.safety_state is SafetyState.RUN
        assert not any(c.damping for c in _after(emu, start))
        emu.inject(Fault.OVER_POWER)
        assert _over_power_frames(safe, cmd, n, last_tick) == n
        before_trip = time.monotonic()
        assert safe.safety_state is SafetyState.RUN
        safe.write(cmd)
        safe.advance(PERIOD)
        assert _over_power_frames(safe, cmd, 1, last_tick) == 1  # the (n + 1)-th frame in a row trips
        tripped = time.monotonic()
        assert safe.safety_state is SafetyState.DAMPED and events[-1].reason == "over_power", events[-1]
        assert f"for {n + 1} frames" in events[-1].detail
        first = _first_damping(emu, start)  # the trip itself put damping on the link
        time.sleep(3 * LINK_PERIOD)
        frames = _after(emu, start)
        print(f"\n{robot}: over-power on {n + 1} frames in a row -> damping on the wire "
              f"{(first.time - tripped) * 1e3:+.1f} ms after the tripping read (bursts of {n} passed)")
        assert before_trip <= first.time <= tripped + 10 * LINK_PERIOD
        assert all(c.damping for c in frames if c.time >= first.time)
        _loop(safe, cmd, 0.02)
        with pytest.raises(SafetyResetError, match="over_power"):
            safe.reset()  # refused while the motors still report over-power
        emu.clear(Fault.OVER_POWER)
        _assert_latched(emu, safe, cmd, first.time, 0.06)  # quiet again; the latch holds
        _reset_and_check_ramp(emu, safe, cmd)


# -- 8: unsafe start ----------------------------------------------------------------------------------------------
FOLDED = np.tile([0.0, 1.1, -2.2], 4)  # crouched low, legs folded (feet 1 cm above the ground at 0.26 m) [rad]


@pytest.mark.parametrize("robot", ROBOTS)
def test_unsafe_start_first_command_is_the_measured_pose_then_a_bounded_slew(robot: str) -> None:
    qpos = np.concatenate([[0.0, 0.0, 0.26, 1.0, 0.0, 0.0, 0.0], FOLDED])
    with _rig(robot, qpos=qpos) as (emu, safe, events):
        cmd = _stand(safe)
        writes = _timed_writes(safe, cmd, 0.4)
        trips = [e for e in events if e.to_state is SafetyState.DAMPED]
        assert safe.safety_state is SafetyState.RAMP and not trips, events
    frames = emu.commands()
    start = next(i for i, c in enumerate(frames) if not c.damping)
    k0 = next(k for k, w in enumerate(writes) if not (w[3].kp == 0).all())
    measured = writes[k0][2]
    np.testing.assert_allclose(frames[start].wire.q, measured, atol=Q_QUANTUM)  # the first servo frame
    np.testing.assert_array_equal(frames[start].wire.kp, safe.config.ramp_kp)
    assert np.abs(measured - cmd.q).max() > 0.5  # the start really was far from the stand pose
    share = _check_ramp_slew(safe, writes[k0:], frames[start:])
    steps = np.abs(np.diff([w[3].q for w in writes[k0:]], axis=0)).max()
    print(f"\n{robot}: start {np.abs(measured - cmd.q).max():.3f} rad from the stand pose; largest step between "
          f"two writes {steps * 1e3:.2f} mrad, {share:.0%} of its wall-time bound")
    assert steps > 0  # it does move


# -- 9: e-stop ----------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("robot", ROBOTS)
def test_software_estop_damps_at_once_and_latches_until_reset(robot: str) -> None:
    with _rig(robot, **FAST) as (emu, safe, events):
        cmd = _stand(safe)
        _run_to(safe, cmd, SafetyState.RUN)
        stopped = time.monotonic()
        safe.estop()
        assert safe.safety_state is SafetyState.DAMPED and events[-1].reason == "software_estop"
        first = _first_damping(emu, stopped)  # no write, no advance: estop() itself put damping on the link
        time.sleep(3 * LINK_PERIOD)
        frames = _after(emu, stopped)
        print(f"\n{robot}: estop() -> damping on the wire after {(first.time - stopped) * 1e3:.1f} ms")
        assert first.time - stopped <= 2 * LINK_PERIOD + 0.002
        assert all(c.damping for c in frames if c.time >= first.time)
        _assert_latched(emu, safe, cmd, first.time, 0.1)
        _reset_and_check_ramp(emu, safe, cmd)


@pytest.mark.parametrize("robot", ROBOTS)
def test_remote_l2_b_damps_and_reset_is_refused_while_held(robot: str) -> None:
    with _rig(robot, **FAST) as (emu, safe, events):
        cmd = _stand(safe)
        _run_to(safe, cmd, SafetyState.RUN)
        pressed, first = _inject_until_damped(emu, safe, cmd, Fault.REMOTE_L2_B, reason="remote_estop")
        assert first.time - pressed <= 10 * LINK_PERIOD
        for _ in range(3):  # held: every reset is refused, and nothing but damping goes out
            _loop(safe, cmd, 0.02)
            with pytest.raises(SafetyResetError, match="remote buttons held"):
                safe.reset()
        assert safe.safety_state is SafetyState.DAMPED
        assert all(c.damping for c in _after(emu, first.time))
        emu.clear(Fault.REMOTE_L2_B)  # released: still latched until the explicit reset
        _assert_latched(emu, safe, cmd, first.time, 0.06)
        _reset_and_check_ramp(emu, safe, cmd)


# -- done means: stand through the whole stack, in real time --------------------------------------------------------
def _stand_height_in_sim(robot: str, seconds: float) -> float:
    with MujocoRobot(MujocoRobotConfig(robot=DESCRIPTIONS[robot], arm_mode="none")) as sim:
        ctrl = StandController(sim.desc)
        for _ in range(int(round(seconds * ctrl.rate_hz))):
            sim.write(ctrl.act(sim.read(), None))
            sim.advance(1.0 / ctrl.rate_hz)
        return float(sim.base_truth().base_position_in_world[2])


def _stand_over_the_wire(robot: str, seconds: float) -> None:
    # As `wbc hw run` does once all is built: a full collection of a test session's heap stalls the in-process link
    # and emulator threads for 0.1-0.2 s, past the stale timeout.
    freeze_heap()
    try:
        _stand_frozen(robot, seconds)
    finally:
        gc.unfreeze()


def _stand_frozen(robot: str, seconds: float) -> None:
    with _rig(robot, mode="realtime") as (emu, safe, events):
        ctrl = StandController(safe.robot.desc)
        for _ in range(int(round(seconds * ctrl.rate_hz))):
            safe.write(ctrl.act(safe.read(), None))
            safe.advance(1.0 / ctrl.rate_hz)
        wire = float(emu.base_truth().base_position_in_world[2])  # before close() damps it down
        sim_time = emu.sim_time
        assert safe.safety_state is SafetyState.RUN, events  # which trip, with its detail, when it fails
        assert [e.reason for e in events] == ["fresh_state", "ramp_done"]
        stats = safe.robot.link_stats()
    sim = _stand_height_in_sim(robot, seconds)
    print(f"\n{robot}: {seconds:.0f} s stand through SafeRobot(UnitreeRobot), real-time emulator: trunk height "
          f"{wire:.4f} m (emulated {sim_time:.2f} s), in simulation {sim:.4f} m, difference "
          f"{(wire - sim) * 1e3:+.2f} mm; link deadline trips {stats.deadline_trips}, rejected {stats.rejected_states}")
    assert abs(wire - sim) < 0.01
    assert sim_time > 0.95 * seconds
    assert stats.deadline_trips == 0 and stats.rejected_states == 0


@pytest.mark.parametrize("robot", ROBOTS)
def test_stand_ten_seconds_through_the_safety_layer_over_the_wire(robot: str) -> None:
    # the acceptance run, in the default suite (about 10 s of wall time per robot, real time by design)
    _stand_over_the_wire(robot, 10.0)
