"""`QuadrupedArmRobot`: a quadruped's legs and its arm, two devices on two links, as one robot in the house order.

On a real robot the legs (a Unitree low-level link, 12 motors) and the arm (a Dynamixel bus, 3 servos the model
moves) are separate devices, each with its own thread, rate and faults. This class makes them one `Robot`:

- Joints: the 12 legs, then (arm mode ``actuated``) the arm's 3: waist, shoulder, elbow. In mode ``locked`` the arm
  is still driven, but not by the controller: it is held at its stowed pose (`QuadrupedArmConfig`), as a welded arm
  is held in simulation, and the robot has 12 joints. A safety layer above (`HeldJoints`) decides when: the arm is
  damped while the layer waits or after a trip, and ramped from where it is into its hold when the layer lets the
  controller in, as the legs are; without a layer every write holds it. In mode ``none`` there is no arm device.
- One frame: `read` joins the newest leg and arm states under the legs' timestamp. Its tick (a freshness counter)
  advances when the legs' tick did, and only while the arm's did too within `arm_stale_s`: a stale arm makes the whole
  frame stale, so a safety layer above (`wbc.hardware.safety.SafeRobot`) trips on a dead arm bus as on a dead leg
  link, even in ``locked`` mode where the controller never sees the arm. Whether the robot itself still answers is
  the legs' link's to say (`link_stats().state_age`), and what the arm's bus latched is the arm's (`faults`): a runner
  tells a robot that stopped answering from an arm that did by those two, not by the joined tick.
- Time: both devices run their own loops on one clock, the wall clock on a robot (each device on a thread of its
  own), or a `ManualClock` in a deterministic test (each device's loop a task of that clock, moved by whoever
  advances it); `advance` paces on the legs' link (which waits for a fresh leg state) and never calls the arm's,
  which would wait a second time: on a shared `ManualClock` the legs' advance moves the arm's bus cycles too. The
  robot is a `WallClock` on the legs' clock.
- What the safety layer reads: the legs' remote (`RemoteSource`), and the motor status of both devices joined
  (`MotorStatusSource`: legs then arm), so an arm servo's alarm or heat trips the layer like a leg motor's.
- `close` closes both (each leaves its motors damped), the legs first, which are damped from their next frame on,
  then the arm (its close damping, then its park); `connect` connects both or neither.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from wbc.errors import ConfigError, UnknownNameError
from wbc.hardware.capabilities import (
    DampsWhile,
    HasLatchedFaults,
    HasLinkStats,
    HasThreadStats,
    HeldRamp,
    LinkStatsLike,
    MotorNames,
    MotorStatusSource,
    RemoteButtons,
    RemoteEstopLatch,
    RemoteSource,
    WallClock,
    WriteDeadlineTrips,
)
from wbc.hardware.device_thread import DeviceThreadStats
from wbc.hardware.dynamixel.arm_fault import ArmFault
from wbc.hardware.robot import Robot
from wbc.robots.description import ARM_MODES
from wbc.robots.joint_table import JointTable
from wbc.robots.wx200 import WX200_NOMINAL_Q
from wbc.types import MotorCommand, RobotState

__all__ = ["JointMotorStatus", "JoinedLinkStats", "QuadrupedArmConfig", "QuadrupedArmRobot"]

_LEGS = 12
_ARM = 3


@dataclass(frozen=True, kw_only=True)
class QuadrupedArmConfig:
    """How the two devices make one robot.

    Attributes:
        arm_mode: ``none`` (no arm device), ``locked`` (the arm held at `stowed_q`, 12 joints) or ``actuated``
            (15 joints).
        stowed_q: the arm's pose in ``locked`` mode (waist, shoulder, elbow) [rad]; the model's locked pose.
        hold_kp: position gain of the ``locked`` hold [N m / rad].
        hold_kd: velocity gain of the ``locked`` hold [N m s / rad].
        arm_stale_s: longest time the arm's tick may stand still before the joined frame counts as stale [s].
    """

    arm_mode: str = "actuated"
    stowed_q: np.ndarray = field(default_factory=lambda: WX200_NOMINAL_Q.copy())
    hold_kp: float = 20.0
    hold_kd: float = 0.5
    arm_stale_s: float = 0.05

    def __post_init__(self) -> None:
        if self.arm_mode not in ARM_MODES:
            raise UnknownNameError("arm mode", self.arm_mode, ARM_MODES)
        stowed = np.array(self.stowed_q, dtype=np.float64)
        if stowed.shape != (_ARM,) or not np.all(np.isfinite(stowed)):
            raise ConfigError(f"QuadrupedArmConfig.stowed_q must be 3 finite angles [rad], got {self.stowed_q!r}")
        stowed.setflags(write=False)
        object.__setattr__(self, "stowed_q", stowed)
        for name in ("hold_kp", "hold_kd", "arm_stale_s"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ConfigError(f"QuadrupedArmConfig.{name} must be a positive number, got {value!r}")


@dataclass(frozen=True)
class JointMotorStatus:
    """Motor modes and temperatures of every motor the joined robot drives, legs first, then the arm's.

    Attributes:
        motor_mode: each motor's mode (0x0A servo, 0 damping/off, anything else an error code).
        motor_temperature: each motor's temperature [degC].
    """

    motor_mode: np.ndarray
    motor_temperature: np.ndarray


@dataclass(frozen=True)
class JoinedLinkStats:
    """Both devices' counters: the legs' link (which paces the loop, so its lateness is the robot's) and the arm's bus.

    Attributes:
        legs: the leg link's counters (`wbc.hardware.unitree.LinkStats`), None when the leg device keeps none.
        arm: the arm bus's counters (`wbc.hardware.dynamixel.ArmBusStats`), None without an arm device or counters.
        threads: each device's loop statistics (`DeviceThreadStats`) by device, ``legs`` and ``arm``; a device that
            runs no `DeviceThread` has none.
    """

    legs: LinkStatsLike | None
    arm: object | None
    threads: Mapping[str, DeviceThreadStats] = field(default_factory=dict)

    @property
    def late_advances(self) -> int:
        """`advance` calls that found the legs' deadline already past (the arm's bus is never paced on)."""
        return self.legs.late_advances if self.legs is not None else 0

    @property
    def worst_lateness(self) -> float:
        """By how much the latest late `advance` was late [s]."""
        return self.legs.worst_lateness if self.legs is not None else 0.0

    @property
    def state_age(self) -> float | None:
        """How old the legs' newest valid state was [s]: the robot's own link, whatever the arm's bus does."""
        return self.legs.state_age if self.legs is not None else None

    def as_dict(self, prefix: str = "link/") -> dict[str, float]:
        """Every counter as a flat dict, keys namespaced with `prefix`.

        The legs' counters directly under `prefix`, the arm bus's under ``arm_bus/``, each device's loop statistics
        under ``legs_thread/`` and ``arm_thread/``.
        """
        out = dict(self.legs.as_dict(prefix)) if self.legs is not None else {}
        as_dict = getattr(self.arm, "as_dict", None)
        if as_dict is not None:
            out.update(as_dict(f"{prefix}arm_bus/"))
        for device, stats in self.threads.items():
            out.update(stats.as_dict(f"{prefix}{device}_thread/"))
        return out


class QuadrupedArmRobot(Robot):
    """Legs and arm as one robot.

    Args:
        legs: the leg device, 12 joints in the house order (e.g. `wbc.hardware.unitree.UnitreeRobot`).
        arm: the arm device, 3 joints (waist, shoulder, elbow), running its own bus thread; None in mode ``none``.
        config: the arm mode and the locked hold.

    Raises:
        ConfigError: a device with the wrong number of joints, or an arm given (or missing) for the mode.
    """

    def __init__(self, legs: Robot, arm: Robot | None, config: QuadrupedArmConfig | None = None) -> None:
        super().__init__()
        self.config = config if config is not None else QuadrupedArmConfig()
        mode = self.config.arm_mode
        if legs.num_joints != _LEGS:
            raise ConfigError(f"QuadrupedArmRobot: the legs device has {legs.num_joints} joints, expected {_LEGS}")
        if (arm is None) != (mode == "none"):
            raise ConfigError(f"QuadrupedArmRobot: arm mode {mode!r} " + ("needs an arm device" if arm is None else
                              "has no arm device; pass arm=None or choose locked / actuated"))
        if arm is not None and arm.num_joints != _ARM:
            raise ConfigError(f"QuadrupedArmRobot: the arm device has {arm.num_joints} joints, expected {_ARM} "
                              "(waist, shoulder, elbow)")
        self.legs = legs
        self.arm = arm
        self._actuated = mode == "actuated"
        parts = (legs, arm) if self._actuated else (legs,)
        self._names = tuple(n for p in parts for n in p.joint_names)
        tables = [p.limits for p in parts]
        self._limits = JointTable(names=self._names, **{
            f: np.concatenate([getattr(t, f) for t in tables])
            for f in ("lower", "upper", "torque_limit", "velocity_limit", "armature", "damping", "frictionloss")})
        # each joint's gains bounded as its own device bounds them (the arm's current loop far below the legs')
        self.gain_limits = tuple(np.concatenate([np.broadcast_to(np.asarray(p.gain_limits[k], dtype=float),
                                                                  (p.num_joints,)) for p in parts]) for k in (0, 1))
        # the devices that count write-deadline trips, resolved once: a check against the runtime-checkable protocol
        # reads its properties, under the device's lock, which the I/O process's every published state would pay
        self._trip_counters: tuple[tuple[str, Robot], ...] = tuple(
            (name, part) for name, part in (("legs", legs), ("arm", arm)) if isinstance(part, WriteDeadlineTrips))
        if isinstance(legs, RemoteEstopLatch) and isinstance(arm, DampsWhile):
            # the remote's L2 + B, latched by the legs' link on the frame that shows it, damps the arm's bus too
            arm.damp_while(lambda: legs.remote_estop_latched)
        self._hold = MotorCommand.hold(self.config.stowed_q, self.config.hold_kp, self.config.hold_kd)
        self._held: MotorCommand | HeldRamp = self._hold  # what a locked arm gets: its hold, damping, or a ramp
        self._reset_frames()

    def _reset_frames(self) -> None:
        self._tick = 0
        self._legs_tick: int | None = None
        self._arm_tick: int | None = None
        self._legs_fresh_at = self._arm_fresh_at = -np.inf
        self._read_at = -np.inf  # when `read` last ran, on `wall_time` [s]
        self._arm_state: RobotState | None = None

    # -- Robot ----------------------------------------------------------------------------------------------------
    @property
    def joint_names(self) -> tuple[str, ...]:
        """The legs' joints, then the arm's in mode ``actuated``."""
        return self._names

    @property
    def limits(self) -> JointTable:
        """The two devices' tables, joined."""
        return self._limits

    def _connect(self) -> None:
        self._reset_frames()
        self.legs.connect()
        if self.arm is not None:
            try:
                self.arm.connect()
            except BaseException:
                self.legs.close()  # connect both or neither
                raise

    def _close(self) -> None:
        # the legs first: their close damps them from their next frame on, while the arm's takes its close damping and
        # its park (0.2 s and more), during which the legs would hold their last command until their write deadline
        try:
            self.legs.close()
        finally:
            if self.arm is not None:
                self.arm.close()

    def _read(self) -> RobotState:
        legs = self.legs.read()
        fresh = self._legs_tick is not None and legs.tick != self._legs_tick
        self._legs_tick = legs.tick
        now = self._read_at = self.wall_time()
        if fresh:
            self._legs_fresh_at = now
        if self.arm is not None:
            arm = self.arm.read()
            if arm.tick != self._arm_tick:
                self._arm_tick, self._arm_fresh_at = arm.tick, now
            self._arm_state = arm
            fresh = fresh and now - self._arm_fresh_at <= self.config.arm_stale_s
        if fresh or self._tick == 0:
            self._tick += 1
        if not self._actuated:
            return RobotState(tick=self._tick, time=legs.time, q=legs.q, dq=legs.dq, tau_est=legs.tau_est,
                              imu_quat=legs.imu_quat, gyro_in_body=legs.gyro_in_body,
                              accel_in_body=legs.accel_in_body, foot_force=legs.foot_force)
        arm = self._arm_state
        return RobotState(tick=self._tick, time=legs.time, q=np.concatenate((legs.q, arm.q)),
                          dq=np.concatenate((legs.dq, arm.dq)), tau_est=np.concatenate((legs.tau_est, arm.tau_est)),
                          imu_quat=legs.imu_quat, gyro_in_body=legs.gyro_in_body, accel_in_body=legs.accel_in_body,
                          foot_force=legs.foot_force)

    def _send(self, cmd: MotorCommand) -> None:
        rows = cmd.stacked()
        self.legs.write(MotorCommand._trusted(rows[:, :_LEGS].copy()))
        if self.arm is not None:
            self.arm.write(MotorCommand._trusted(rows[:, _LEGS:].copy()) if self._actuated else self._held_command())

    def _held_command(self) -> MotorCommand:
        """A locked arm's command: its hold, damping, or the next step of the ramp into its hold."""
        held = self._held
        if isinstance(held, MotorCommand):
            return held
        now = self.wall_time()
        if not held.started:
            state = self._arm_state if self._arm_state is not None else self.arm.read()
            limits = self.arm.limits
            return held.start(np.clip(state.q, limits.lower, limits.upper), now)
        out, done = held.step(self._hold, now)
        if done:
            self._held = self._hold
        return out

    # -- HeldJoints -----------------------------------------------------------------------------------------------
    def damp_held(self, kd: float) -> None:
        """In mode ``locked``, damp the arm (kp 0, kd `kd`) from the next write on (`HeldJoints`); else nothing."""
        if self.arm is not None and not self._actuated:
            self._held = MotorCommand.damping(_ARM, kd)

    def ramp_held(self, ramp: HeldRamp) -> None:
        """In mode ``locked``, move the arm from where it is into its hold through `ramp` (`HeldJoints`)."""
        if self.arm is not None and not self._actuated:
            self._held = ramp

    def _advance(self, dt: float) -> None:
        self.legs.advance(dt)

    # -- capabilities ---------------------------------------------------------------------------------------------
    def wall_time(self) -> float:
        """Now on the legs' clock if they offer one, else the monotonic clock [s] (both devices live in wall time)."""
        return self.legs.wall_time() if isinstance(self.legs, WallClock) else time.monotonic()

    def link_stats(self) -> JoinedLinkStats:
        """The legs' link counters (pacing, lateness), the arm bus's and both loops' (`HasLinkStats`): one snapshot."""
        legs = self.legs.link_stats() if isinstance(self.legs, HasLinkStats) else None
        bus_stats = getattr(self.arm, "bus_stats", None)
        threads = {device: robot.thread_stats() for device, robot in (("legs", self.legs), ("arm", self.arm))
                   if isinstance(robot, HasThreadStats)}
        return JoinedLinkStats(legs=legs, arm=bus_stats() if bus_stats is not None else None, threads=threads)

    @property
    def remote_estops(self) -> int:
        """The legs' link's L2 + B latches (`RemoteEstopLatch`; the remote is the legs'); 0 without one."""
        return self.legs.remote_estops if isinstance(self.legs, RemoteEstopLatch) else 0

    @property
    def remote_estop_latched(self) -> bool:
        """Whether the legs' link damps now on its L2 + B latch (and so the arm's bus with it); False without one."""
        return self.legs.remote_estop_latched if isinstance(self.legs, RemoteEstopLatch) else False

    def release_remote_estop(self) -> bool:
        """Release the legs' link's L2 + B latch; False while the buttons are still held."""
        return self.legs.release_remote_estop() if isinstance(self.legs, RemoteEstopLatch) else True

    @property
    def deadline_trips(self) -> int:
        """The legs' write-deadline trips plus the arm's (`WriteDeadlineTrips`); a device without one counts none."""
        return sum(part.deadline_trips for _, part in self._trip_counters)

    # -- JoinedDevices --------------------------------------------------------------------------------------------
    def state_ages(self) -> dict[str, float]:
        """How long the legs' tick, and the arm's, had stood still at the last `read` [s] (`JoinedDevices`)."""
        ages = {"legs": self._read_at - self._legs_fresh_at}
        if self.arm is not None:
            ages["arm"] = self._read_at - self._arm_fresh_at
        return ages

    def deadline_trips_by_device(self) -> dict[str, int]:
        """The legs' write-deadline trips and the arm's, apart (`JoinedDevices`); a device without one is left out."""
        return {name: part.deadline_trips for name, part in self._trip_counters}

    @property
    def faults(self) -> tuple[ArmFault, ...]:
        """The faults the arm's bus latched since `connect`, oldest first (`HasLatchedFaults`); empty without one."""
        return self.arm.faults if isinstance(self.arm, HasLatchedFaults) else ()

    def remote(self) -> RemoteButtons | None:
        """The legs' wireless remote (the arm has none), or None when the legs device offers no remote."""
        return self.legs.remote() if isinstance(self.legs, RemoteSource) else None

    @property
    def motor_names(self) -> tuple[str, ...]:
        """One name per entry of `motor_status` (`MotorNames`): the legs' joints, then the arm's servos.

        A device that names its motors (the arm: ``elbow (ID 4)``) gives its names; one that does not is taken to
        drive one motor per joint, named after the joint and the motor's index in the status (``FR_hip_joint (motor
        0)``).
        """
        names: list[str] = []
        for part in (self.legs, self.arm):
            if not isinstance(part, MotorStatusSource):
                continue
            if isinstance(part, MotorNames):
                names += part.motor_names
            else:
                names += [f"{joint} (motor {len(names) + k})" for k, joint in enumerate(part.joint_names)]
        return tuple(names)

    def motor_status(self) -> JointMotorStatus | None:
        """Modes and temperatures of the legs' motors, then the arm's servos (those that report them).

        None when neither device reports a status.
        """
        parts = [p.motor_status() for p in (self.legs, self.arm) if isinstance(p, MotorStatusSource)]
        if not parts:
            return None
        return JointMotorStatus(motor_mode=np.concatenate([np.asarray(s.motor_mode) for s in parts]),
                                motor_temperature=np.concatenate([np.asarray(s.motor_temperature) for s in parts]))
