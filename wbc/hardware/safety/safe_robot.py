"""`SafeRobot`: the safety layer, a `Robot` that wraps any other and decides what reaches its motors.

States (`SafetyState`): ``waiting`` until the state stream is live (its tick advances), damping only; ``ramp`` from
the measured pose into the controller's command (`CommandRamp`); ``run``, where the controller's commands pass,
clamped to the motor limits and the position table; ``damped``, damping only, latched until `reset`.

Trips, each into ``damped`` on the spot (damping is sent to the robot at once, not only on the next write): a stale
state stream, a state with non-finite values or a non-unit quaternion, a measured joint beyond its range plus a
margin, sustained over-power (Unitree's PowerProtect rule, latched), a hot motor or a motor error mode (robots that
are a `MotorStatusSource`), a trunk roll or pitch beyond the limit (a fall, from the IMU), the remote's L2 + B
(robots that are a `RemoteSource`; a robot whose link checks the remote on every state frame, a `RemoteEstopLatch`,
damps on that frame itself and the layer latches it at its next read, however short the press) or `estop`. Every
transition is a `SafetyEvent`, kept in `events` (offered to a runner as `safety_events`, so the episode logs them)
and handed to `SafetyConfig.on_event` (by default printed to standard error, one line per transition).

A robot whose devices damp on their own when `write` stops for their write deadline (`WriteDeadlineTrips`: the legs'
link, the arm's bus) tells the layer how often that happened: a control loop that stalled past that deadline but
not past the stale timeout finds, at its next read or write, the layer back in ``ramp`` (event ``write_deadline``),
starting again from the measured pose, never its command at full gain after the damping.

The layer's clock is the one the motors live on: a robot that is a `WallClock` (a real robot over its wire, or an
emulator behind one) is timed on its monotonic clock, which also sees a control loop that stalls between calls; a
simulator on the robot time that `advance` lets pass, so a simulated run is deterministic. A `clock` handed in
overrides both.

The wrapped robot's own capabilities (a simulator's `TruthSource`, `FallDetector`, `Pushable`) are not forwarded: a
runner reaches them through `SafeRobot.robot`, e.g. ``run_episode(safe, ctrl, ..., truth=safe.robot.base_truth)``.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from typing import cast

import numpy as np

from wbc.errors import SafetyResetError
from wbc.hardware.capabilities import (
    HeldJoints,
    JoinedDevices,
    MotorNames,
    MotorStatusSource,
    RemoteButtons,
    RemoteEstopLatch,
    RemoteSource,
    WallClock,
    WriteDeadlineTrips,
    provides,
)
from wbc.hardware.dynamixel.arm_fault import MODE_CORRUPT, MODE_HARDWARE_ERROR, MODE_NO_ANSWER, MODE_PORT_LOST
from wbc.hardware.dynamixel.control_table import HARDWARE_ERROR_BITS
from wbc.hardware.robot import Robot
from wbc.hardware.safety.config import SafetyConfig
from wbc.hardware.safety.events import SafetyEvent
from wbc.hardware.safety.limits import position_range
from wbc.hardware.safety.ramp import CommandRamp
from wbc.hardware.safety.state import SafetyState
from wbc.hardware.unitree.layout import MOTOR_STATE_MODES
from wbc.robots.conventions import quat_to_matrix
from wbc.robots.euler import rpy_of
from wbc.robots.joint_table import JointTable
from wbc.types import MotorCommand, RobotState

__all__ = ["SafeRobot"]

_ARM_START = 12  # joints from this index on are the arm's (house order)
_QUAT_NORM_TOLERANCE = 0.05  # an IMU quaternion further from unit length than this is not an orientation


class SafeRobot(Robot):
    """A robot behind the safety layer; use it wherever a `Robot` is used.

    ``write`` returns what was actually sent to the wrapped robot (damping, a ramp step or the clamped command).
    A frame is fresh when its tick differs from the previous read's; the first frame after `connect` alone proves
    nothing (a backend may hand out a default frame before the first datagram), so ``waiting`` lasts at least until
    the second read. The state checks run on fresh frames only; a repeated frame carries no news, only age.
    Not thread-safe: call `estop` from the control thread.

    Args:
        robot: the robot to protect (it is connected and closed with this one).
        config: thresholds, gains and timings.
        clock: returns now [s]; default: the robot's `wall_time` if it is a `WallClock`, else the robot time passed
            through `advance`.
    """

    def __init__(self, robot: Robot, config: SafetyConfig | None = None, *,
                 clock: Callable[[], float] | None = None) -> None:
        super().__init__()
        self.robot = robot
        self.gain_limits = robot.gain_limits  # what the robot passes on is what this layer says it sent
        self.config = config if config is not None else SafetyConfig()
        self._clock = clock if clock is not None else (robot.wall_time if isinstance(robot, WallClock) else None)
        self._time = 0.0
        self._state = SafetyState.WAITING
        self._events: list[SafetyEvent] = []
        self._latest: RobotState | None = None
        self._last_tick: int | None = None
        self._fresh = False
        self._last_fresh_time = -math.inf
        self._over_power_frames = 0
        self._deadline_trips: int | None = None  # the robot's write-deadline trips as last seen (`WriteDeadlineTrips`)
        self._device_trips: dict[str, int] = {}  # the same by device, as last seen (`JoinedDevices`)
        self._last_read_time = -math.inf  # when `read` last ran, on the layer's clock [s]
        self._remote_estops = 0  # the robot's own L2 + B latches as last seen (`RemoteEstopLatch`)
        # The robot's capabilities, resolved once: isinstance against a runtime-checkable protocol runs the protocol's
        # properties (a device's lock, the I/O process's state block) on every call, too dear for every read and write.
        self._latch: RemoteEstopLatch | None = robot if provides(robot, RemoteEstopLatch) else None
        self._trips: WriteDeadlineTrips | None = robot if provides(robot, WriteDeadlineTrips) else None
        self._joined: JoinedDevices | None = robot if provides(robot, JoinedDevices) else None
        self._held: HeldJoints | None = robot if provides(robot, HeldJoints) else None
        self._remote_of = robot.remote if provides(robot, RemoteSource) else None
        self._ramp: CommandRamp | None = None
        self._sent: MotorCommand | None = None
        self._lower = self._upper = np.zeros(0)
        self._damping: MotorCommand | None = None

    # -- what the layer reports -----------------------------------------------------------------------------------
    @property
    def safety_state(self) -> SafetyState:
        """The layer's state now."""
        return self._state

    @property
    def events(self) -> tuple[SafetyEvent, ...]:
        """Every transition so far, oldest first."""
        return tuple(self._events)

    def safety_events(self) -> tuple[SafetyEvent, ...]:
        """Every transition so far, oldest first (the `HasSafetyEvents` capability: an episode logs them)."""
        return tuple(self._events)

    @property
    def position_lower(self) -> np.ndarray:
        """Lower end of each joint's allowed range (the position table), shape (n,) [rad]; set by `connect`."""
        return self._lower.copy()

    @property
    def position_upper(self) -> np.ndarray:
        """Upper end of each joint's allowed range, shape (n,) [rad]; set by `connect`."""
        return self._upper.copy()

    def now(self) -> float:
        """The layer's clock [s]."""
        return self._clock() if self._clock is not None else self._time

    @property
    def last_fresh_time(self) -> float:
        """When `read` last returned a fresh state (its tick advanced), on the layer's clock [s]; -inf before one.

        It moves in every state, ``damped`` included: a runner that goes on reading a tripped robot learns from it
        whether the state stream came back (a control loop that stalled) or not (a robot that stopped answering).
        """
        return self._last_fresh_time

    # -- operator actions -----------------------------------------------------------------------------------------
    def estop(self, detail: str = "estop() called") -> None:
        """Software e-stop: go to ``damped`` (latched) and send damping now, if connected.

        `detail` says who stopped it, in the event (a hardware trial's interrupted command says so).
        """
        self._trip("software_estop", detail)

    def reset(self) -> None:
        """Release a latched ``damped`` state into a new ramp from the measured pose; nothing to do otherwise.

        Accepted only when the latest state is fresh (its tick advanced, within the stale timeout), no remote
        button is held, none of the state checks (joint range, tilt, motor status) fails on it, and its power
        is within the limit (a reset into a ramp while the motors still report over-power would only trip again).

        Raises:
            SafetyResetError: refused; the message lists why and what to do.
        """
        if self._state is not SafetyState.DAMPED:
            return
        why = []
        age = self.now() - self._last_fresh_time
        if self._latest is None or not self._fresh or age > self.config.stale_timeout_s:
            tick = None if self._latest is None else self._latest.tick
            why.append(f"the state stream is stale (tick {tick} did not advance at the last read); read() fresh "
                       "frames first")
        remote = self._remote()
        if remote is not None and remote.held:
            why.append(f"remote buttons held ({', '.join(remote.held)}); release them")
        if self._latest is not None:
            fault = self._state_fault(self._latest)
            if fault is not None:
                why.append(f"{fault[0]}: {fault[1]}")
            power = _power(self._latest)
            if power > self.config.power_limit_w:
                why.append(f"over_power: {power:.0f} W measured (limit {self.config.power_limit_w} W); wait until "
                           "the motors are quiet")
        if not why and self._latch is not None and not self._latch.release_remote_estop():
            why.append("the robot's link still sees L2 + B held; release them")
        if why:
            raise SafetyResetError("SafeRobot.reset refused: " + "; ".join(why))
        self._over_power_frames = 0
        self._ramp = None
        self._transition(SafetyState.RAMP, "reset", "operator reset")

    # -- Robot ----------------------------------------------------------------------------------------------------
    @property
    def joint_names(self) -> tuple[str, ...]:
        """The wrapped robot's joints."""
        return self.robot.joint_names

    @property
    def limits(self) -> JointTable:
        """The wrapped robot's motor limits."""
        return self.robot.limits

    def write(self, cmd: MotorCommand) -> MotorCommand:
        """Validate and clamp the controller's command, then send what the safety state allows; return what was sent.

        Raises:
            CommandError: the command has the wrong number of joints.
            RobotNotConnectedError: not connected.
        """
        super().write(cmd)  # validates and clamps, then calls _send, which records what went out in _sent
        return cast(MotorCommand, self._sent)

    def _connect(self) -> None:
        self.robot.connect()
        n = self.robot.num_joints
        self._lower, self._upper = position_range(self.config.position_table, self.robot.limits)
        kd = np.full(n, self.config.damping_kd)
        kd[_ARM_START:] = self.config.arm_damping_kd
        self._damping = MotorCommand(q=np.zeros(n), dq=np.zeros(n), kp=np.zeros(n), kd=kd, tau=np.zeros(n))
        self._damp_held()  # a locked arm too, until the ramp lets the controller in
        self._latest, self._last_tick, self._fresh = None, None, False
        self._last_fresh_time = -math.inf
        self._over_power_frames = 0
        self._ramp = None
        self._deadline_trips = self._robot_deadline_trips()
        self._device_trips = self._joined.deadline_trips_by_device() if self._joined is not None else {}
        self._last_read_time = self.now()
        self._remote_estops = 0  # the robot was connected just now: a press its link saw already counts
        if self._state is not SafetyState.DAMPED and self._state is not SafetyState.WAITING:
            self._transition(SafetyState.WAITING, "connect", "connected again: waiting for a live state stream")

    def _close(self) -> None:
        if self.robot.is_connected and self._damping is not None:
            self._damp_held()
            self._sent = self.robot.write(self._damping)
        self.robot.close()

    def _read(self) -> RobotState:
        state = self.robot.read()
        now = self.now()
        # Before this frame counts as news: a control loop that stalled between two reads (seen with a wall clock)
        # left the robot unwatched for that long, and the backend damped it meanwhile; passing the controller's
        # command straight on would be a jump from wherever it sagged to.
        self._check_stale(now, state)
        self._check_deadline()
        fresh = self._last_tick is not None and state.tick != self._last_tick
        self._last_tick, self._latest, self._fresh = state.tick, state, fresh
        self._last_read_time = now
        if fresh:
            self._last_fresh_time = now
        if self._latch is not None:
            presses = self._latch.remote_estops
            if presses > self._remote_estops:
                self._remote_estops = presses
                # the link damped on the very frame that showed the press; the layer latches it
                self._trip("remote_estop", "L2 + B pressed on the remote (the link damped on the frame that showed "
                                           "it)")
        if self._state is SafetyState.DAMPED:
            return state
        remote = self._remote()
        if remote is not None and remote.l2_b:
            self._trip("remote_estop", "L2 + B held on the remote")
            return state
        if fresh:
            fault = self._state_fault(state) or self._power_fault(state)
            if fault is not None:
                self._trip(*fault)
            elif self._state is SafetyState.WAITING:
                self._ramp = None
                self._transition(SafetyState.RAMP, "fresh_state", f"tick advanced to {state.tick}")
        else:
            self._check_stale(now)
        return state

    def _send(self, cmd: MotorCommand) -> None:
        now = self.now()
        self._check_stale(now)
        self._check_deadline()
        if self._state is SafetyState.RAMP:
            target = self._limit_positions(cmd)
            if self._ramp is None:
                self._ramp = self._new_ramp()
                out = self._ramp.start(np.clip(self._latest.q, self._lower, self._upper), now)
                if self._held is not None:  # a locked arm ramps into its hold beside the legs
                    self._held.ramp_held(self._new_ramp())
            else:
                out, done = self._ramp.step(target, now)
                out = self._limit_positions(out)  # the controller's target plus the closing gap may leave the table
                if done:
                    self._ramp = None
                    self._transition(SafetyState.RUN, "ramp_done",
                                     "the ramp reached the controller's own command (its targets and gains)")
        elif self._state is SafetyState.RUN:
            out = self._limit_positions(cmd)
        else:
            out = self._damping
        self._sent = self.robot.write(out)

    def _new_ramp(self) -> CommandRamp:
        cfg = self.config
        return CommandRamp(duration_s=cfg.ramp_time_s, slew=cfg.ramp_slew, kp=cfg.ramp_kp, kd=cfg.ramp_kd,
                           hold_s=cfg.ramp_hold_s)

    def _damp_held(self) -> None:
        """Damp the joints the wrapped robot drives for no controller (a locked arm; `HeldJoints`), if any."""
        if self._held is not None:
            self._held.damp_held(self.config.arm_damping_kd)

    def _advance(self, dt: float) -> None:
        self.robot.advance(dt)
        self._time += dt

    # -- checks ---------------------------------------------------------------------------------------------------
    def _remote(self) -> RemoteButtons | None:
        return self._remote_of() if self._remote_of is not None else None

    def _check_stale(self, now: float, state: RobotState | None = None) -> None:
        """Trip when no fresh state was taken for the stale timeout; `state`: the frame `read` just got, if any."""
        if self._state not in (SafetyState.RAMP, SafetyState.RUN):
            return
        age = now - self._last_fresh_time
        if age > self.config.stale_timeout_s:
            self._trip("stale_state", self._stale_source(now, age, state))

    def _stale_source(self, now: float, age: float, state: RobotState | None) -> str:
        """What went stale, in words: the host's loop (late since its last read), the arm's state, or the legs'.

        The host loop when the layer was not called for longer than the timeout and the robot answered meanwhile (the
        frame just read advanced, or a write came late after its read); the arm's state when the robot tells its
        devices apart (`JoinedDevices`) and the legs' stream was fresh; else the legs' (the robot's) stream.
        """
        limit = self.config.stale_timeout_s
        gap = now - self._last_read_time
        answered = state is None or (self._last_tick is not None and state.tick != self._last_tick)
        if gap > limit and answered:
            return (f"the host's control loop was late: {gap * 1e3:.0f} ms since its last read (limit "
                    f"{limit * 1e3:g} ms), while the robot's state stream went on")
        ages = self._joined.state_ages() if self._joined is not None else {}
        legs, arm = ages.get("legs"), ages.get("arm")
        if arm is not None and legs is not None and legs <= limit < arm:
            return (f"the arm's state: {arm:.3f} s old, its bus's servos not answering (the legs' state stream fresh, "
                    f"{legs * 1e3:.0f} ms old; limit {limit} s)")
        tick = None if self._latest is None else self._latest.tick
        stream = "the legs' state stream" if "legs" in ages else "the robot's state stream"
        return f"{stream}: tick {tick} unchanged for {age:.3f} s (limit {limit} s)"

    def _robot_deadline_trips(self) -> int | None:
        return self._trips.deadline_trips if self._trips is not None else None

    def _check_deadline(self) -> None:
        """A device damped on its own since the last look (its write deadline expired: the loop stalled): ramp again.

        The stall was too short for the stale timeout, but the motors were damped meanwhile and the robot sagged;
        the controller's command at full gain would be a jump from wherever it is now. A new ramp starts from the
        measured pose at the next write (the ramp's own steps, if one was running, start over too).
        """
        trips = self._robot_deadline_trips()
        seen, self._deadline_trips = self._deadline_trips, trips
        if trips is None or seen is None or trips <= seen:
            return
        by_device = self._joined.deadline_trips_by_device() if self._joined is not None else {}
        seen_by_device, self._device_trips = self._device_trips, by_device
        if self._state not in (SafetyState.RAMP, SafetyState.RUN):
            return
        self._ramp = None
        damped = {d: n - seen_by_device.get(d, 0) for d, n in by_device.items() if n > seen_by_device.get(d, 0)}
        self._transition(SafetyState.RAMP, "write_deadline",
                         f"{_who_damped(damped, trips - seen)} since the last look: no write within the write "
                         "deadline (the control loop stalled); ramping again from the measured pose")

    def _state_fault(self, state: RobotState) -> tuple[str, str] | None:
        """The first check that fails on `state` (values, motor status, joint range, tilt), as (reason, detail)."""
        cfg = self.config
        for name in ("q", "dq", "tau_est", "imu_quat"):
            if not np.all(np.isfinite(getattr(state, name))):
                return "bad_state", f"RobotState.{name} holds a non-finite value"
        norm = float(np.linalg.norm(state.imu_quat))
        if abs(norm - 1.0) > _QUAT_NORM_TOLERANCE:
            return "bad_state", f"RobotState.imu_quat has norm {norm:.3f}, not 1"
        status = self.robot.motor_status() if isinstance(self.robot, MotorStatusSource) else None
        if status is not None:
            modes = np.asarray(status.motor_mode).astype(int)
            bad = ~np.isin(modes, cfg.ok_motor_modes)
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                ok = ", ".join(f"{m:#04x}" for m in cfg.ok_motor_modes)
                return "motor_mode", (f"{self._motor_label(i)} reports mode {modes[i]:#04x}"
                                      f"{_mode_name(int(modes[i]), arm=i >= _ARM_START)} (ok: {ok})")
            temps = np.asarray(status.motor_temperature, dtype=np.float64)
            if temps.size and temps.max() > cfg.max_motor_temperature_c:
                i = int(np.argmax(temps))
                return "motor_temperature", (f"{self._motor_label(i)} at {temps[i]:.0f} degC (limit "
                                             f"{cfg.max_motor_temperature_c} degC)")
        q = state.q
        outside = (q < self._lower - cfg.joint_margin) | (q > self._upper + cfg.joint_margin)
        if outside.any():
            i = int(np.flatnonzero(outside)[0])
            return "joint_range", (f"{self.joint_names[i]} at {q[i]:.3f} rad, range [{self._lower[i]:.3f}, "
                                   f"{self._upper[i]:.3f}] + {cfg.joint_margin} rad")
        roll, pitch, _ = rpy_of(quat_to_matrix(np.asarray(state.imu_quat))).tolist()
        if max(abs(roll), abs(pitch)) > cfg.max_tilt:
            return "tilt", f"roll {roll:.2f} rad, pitch {pitch:.2f} rad (limit {cfg.max_tilt} rad)"
        return None

    def _motor_label(self, i: int) -> str:
        """Entry `i` of the motor status by name: the robot's (`MotorNames`), else a leg joint's, else its index."""
        names = self.robot.motor_names if isinstance(self.robot, MotorNames) else ()
        if i < len(names):
            return names[i]
        if i < min(_ARM_START, self.robot.num_joints):  # legs come first, one motor per joint
            return f"{self.joint_names[i]} (motor {i})"
        return f"motor {i}"

    def _power_fault(self, state: RobotState) -> tuple[str, str] | None:
        """PowerProtect's rule on a fresh frame: above the limit on more than `power_frames` frames in a row."""
        power = _power(state)
        self._over_power_frames = self._over_power_frames + 1 if power > self.config.power_limit_w else 0
        if self._over_power_frames > self.config.power_frames:
            return "over_power", (f"{power:.0f} W for {self._over_power_frames} frames in a row (limit "
                                  f"{self.config.power_limit_w} W on more than {self.config.power_frames})")
        return None

    def _limit_positions(self, cmd: MotorCommand) -> MotorCommand:
        """`cmd` with its targets clipped into the position table (Unitree's PositionLimit)."""
        rows = cmd.stacked()
        np.clip(rows[0], self._lower, self._upper, out=rows[0])
        return MotorCommand._trusted(rows)

    # -- transitions ----------------------------------------------------------------------------------------------
    def _trip(self, reason: str, detail: str) -> None:
        if self._state is SafetyState.DAMPED:
            return
        self._ramp = None
        self._over_power_frames = 0
        # the damping first, then the word of it: a print to a stderr whose reader stalled (a paused pager) or a
        # caller's callback must not hold the damping back
        event = self._transition(SafetyState.DAMPED, reason, detail, announce=False)
        try:
            self._damp_held()
            if self.is_connected and self.robot.is_connected and self._damping is not None:
                self._sent = self.robot.write(self._damping)
        finally:
            self._announce(event)

    def _transition(self, to: SafetyState, reason: str, detail: str, *, announce: bool = True) -> SafetyEvent:
        event = SafetyEvent(time=self.now(), from_state=self._state, to_state=to, reason=reason, detail=detail)
        self._state = to
        self._events.append(event)
        if announce:
            self._announce(event)
        return event

    def _announce(self, event: SafetyEvent) -> None:
        """Tell `config.on_event` of `event`, or print it on stderr."""
        if self.config.on_event is not None:
            self.config.on_event(event)
        else:
            try:
                print(event, file=sys.stderr)
            except OSError:
                pass  # the terminal was closed (SIGHUP): the event is kept in `events`, and the trip must go on


_ARM_MODES = {MODE_NO_ANSWER: "no answer", MODE_CORRUPT: "corrupt answers", MODE_PORT_LOST: "serial port lost"}
"""The arm's status codes (`wbc.hardware.dynamixel.arm_fault`), by name; 0x80 + bits is its Hardware Error Status."""


def _mode_name(mode: int, *, arm: bool) -> str:
    """``: overheat`` for a mode the motor's documentation names (a leg motor's, an arm servo's), else empty."""
    if not arm:
        name = MOTOR_STATE_MODES.get(mode)
    elif mode & MODE_HARDWARE_ERROR:
        bits = [text for bit, text in HARDWARE_ERROR_BITS.items() if mode & bit]
        name = f"hardware error: {', '.join(bits)}" if bits else "hardware error"
    else:
        name = _ARM_MODES.get(mode)
    return f" ({name})" if name else ""


def _who_damped(by_device: dict[str, int], total: int) -> str:
    """``the legs and the arm each damped once``, ``the legs damped twice``; ``the robot damped itself 3 times``."""
    def times(n: int) -> str:
        return {1: "once", 2: "twice"}.get(n, f"{n} times")

    if not by_device:
        return f"the robot damped itself {times(total)}"
    names = [f"the {device}" for device in by_device]
    counts = set(by_device.values())
    if len(by_device) > 1 and len(counts) == 1:
        return f"{' and '.join(names)} each damped {times(counts.pop())}"
    return " and ".join(f"{name} damped {times(n)}" for name, n in zip(names, by_device.values(), strict=True))


def _power(state: RobotState) -> float:
    """Measured mechanical power sum |tau_est dq| over all joints [W]."""
    return float(np.abs(state.tau_est * state.dq).sum())
