"""Capabilities a `Robot` backend may offer beyond the interface, as protocols the runner asks for by name.

A real robot offers none of these by default; the simulator offers the first three and `SimulatorHealth`. A runner
or tool checks ``isinstance(robot, Pushable)`` instead of testing for a backend class, so a backend that can do the
same (motion capture as a `TruthSource`, a push rig as `Pushable`) takes the same path. A safety layer that records its
transitions is a `HasSafetyEvents` (`wbc.hardware.safety.SafeRobot` is one); the protocol is structural, so the
runner logs the events without importing the safety layer. A robot that paces `advance` on a wall clock over a link
reports its lateness as a `HasLinkStats` (`wbc.hardware.unitree.UnitreeRobot` is one); a device whose link or bus
runs as a `wbc.hardware.device_thread.DeviceThread` reports that loop's period, late cycles and overruns as a
`HasThreadStats`. A device that latches its own faults (an arm's bus) offers them as a `HasLatchedFaults`, and so
does a robot that joins it, so that a runner records them apart from the safety layer's trips. A robot whose devices
run in a process that asked for real-time scheduling says what it got as a `HasRealtimeGrant` (`ProcessRobot`). A
robot that knows its own configuration only from its sensors (joint encoders, IMU, a base state estimator) offers it
as a `ConfigurationEstimate`, which is what a viewer draws of a real robot. A simulator that reports its own integration
failures is a `SimulatorHealth`. A robot that lives in wall-clock time (a real robot, or an emulator over a wire) is
a `WallClock`, so a safety layer times its checks on the clock the motors live on.

What the safety layer reads beyond `RobotState`: a wireless remote (`RemoteSource`: its L2 + B is an e-stop, and a
reset needs it idle) and the motors' own status (`MotorStatusSource`: temperatures and modes, named by a
`MotorNames`). The Unitree backend's `Remote` and `LowStateExtras` have exactly the attributes asked for
(`RemoteButtons`, `MotorStatus`), so it offers both by returning them; the simulator offers neither, and the checks
that need them are then skipped.

A check made on every control tick or link period resolves its capability once with `provides` (at construction),
never with ``isinstance``: against a runtime-checkable protocol with properties, ``isinstance`` runs each property
(taking a device's lock, reading the I/O process's state block), and raises where one does (a robot not connected).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from wbc.hardware.device_thread import DeviceThreadStats
from wbc.hardware.realtime import RealtimeGrant
from wbc.robots.description import RobotDescription
from wbc.scenario.push import Push
from wbc.types import BaseTruth, MotorCommand

if TYPE_CHECKING:
    from wbc.hardware.dynamixel.arm_fault import ArmFault

__all__ = ["ConfigurationEstimate", "DampsWhile", "FallDetector", "HasLatchedFaults", "HasLinkStats",
           "HasRealtimeGrant", "HasSafetyEvents", "HasThreadStats", "HeldJoints", "HeldRamp", "JoinedDevices",
           "LinkStatsLike", "MotorNames", "MotorStatus", "MotorStatusSource", "Pushable", "RemoteButtons",
           "RemoteEstopLatch", "RemoteSource", "SafetyEventLike", "SimulatorHealth", "TruthSource", "WallClock",
           "WriteDeadlineTrips"]


@runtime_checkable
class TruthSource(Protocol):
    """A backend that knows the base's true state (the simulator; motion capture on a real robot)."""

    def base_truth(self) -> BaseTruth:
        """The trunk's true pose and velocity now."""


@runtime_checkable
class SimulatorHealth(Protocol):
    """A simulator that reports when its own integration failed.

    MuJoCo resets its state after a bad position, velocity or acceleration and carries on: the state after such a
    reset looks like a robot standing still.
    """

    def instability(self) -> str | None:
        """What the simulator reported as unstable since the last reset, or None."""


@runtime_checkable
class Pushable(Protocol):
    """A backend that can apply a scenario's pushes."""

    def apply_push(self, push: Push) -> None:
        """Schedule `push` (its start time is on the robot's clock)."""


@runtime_checkable
class FallDetector(Protocol):
    """A backend that can tell when the robot has fallen."""

    def fallen(self) -> bool:
        """True when the trunk or a non-foot link touches the ground."""


class SafetyEventLike(Protocol):
    """One transition of a safety layer (`wbc.hardware.safety.SafetyEvent` is one)."""

    @property
    def time(self) -> float:
        """When it happened, on the safety layer's clock [s]."""

    @property
    def from_state(self) -> str:
        """The state left, by name."""

    @property
    def to_state(self) -> str:
        """The state entered, by name."""

    @property
    def reason(self) -> str:
        """Why (a trip's reason names the check that fired)."""

    @property
    def detail(self) -> str:
        """What was measured, against which limit (may be empty)."""


@runtime_checkable
class HasSafetyEvents(Protocol):
    """A robot behind a safety layer that records every transition of its state."""

    def safety_events(self) -> Sequence[SafetyEventLike]:
        """Every transition so far, oldest first (a runner logs those that happened during its episode)."""


@runtime_checkable
class WallClock(Protocol):
    """A backend whose robot lives in wall-clock time, whatever its caller does (a real robot over a wire).

    Its motors keep acting while the caller is late, so whoever watches over them (`wbc.hardware.safety.SafeRobot`)
    must time stale streams, stalls and ramps on this clock, not on the time the caller says has passed.
    """

    def wall_time(self) -> float:
        """Now, on a monotonic clock [s] (an arbitrary origin; only differences mean anything)."""


@runtime_checkable
class RemoteEstopLatch(Protocol):
    """A backend whose device loop checks the remote's L2 + B on every state frame and damps at once, latched.

    The safety layer trips when `remote_estops` rose since its last look, and releases the device's latch in its
    `reset` (which it refuses while a button is held).
    """

    @property
    def remote_estops(self) -> int:
        """How many times since `connect` the device saw L2 + B pressed and latched damping."""

    @property
    def remote_estop_latched(self) -> bool:
        """Whether the device damps now on its L2 + B latch (until `release_remote_estop`)."""

    def release_remote_estop(self) -> bool:
        """Release the device's latch; False (the latch kept) while L2 + B is still held."""


@runtime_checkable
class DampsWhile(Protocol):
    """A device whose loop damps its motors on every cycle where a condition holds (another device's e-stop latch)."""

    def damp_while(self, condition: Callable[[], bool] | None) -> None:
        """Damp on every cycle where `condition()` is true (called from the device's loop; short, never raising)."""


@runtime_checkable
class WriteDeadlineTrips(Protocol):
    """A backend whose device loops damp on their own once `write` has not been called for their write deadline.

    A control loop that stalls past that deadline leaves the robot damped for a while; whoever watches over the
    motors (`wbc.hardware.safety.SafeRobot`) must not then hand the controller's command straight back at full gain.
    """

    @property
    def deadline_trips(self) -> int:
        """How many times since `connect` a write deadline expired and the device switched to damping."""


@runtime_checkable
class JoinedDevices(Protocol):
    """A robot whose frame joins several devices' states (the legs' link, the arm's bus), each told apart.

    The joined frame goes stale when any device's state does, and each device damps on its own write deadline; whoever
    watches over the motors (`wbc.hardware.safety.SafeRobot`) names which one in what it reports.
    """

    def state_ages(self) -> dict[str, float]:
        """By device (``legs``, ``arm``): how long its state's tick had stood still at the last `read` [s]."""

    def deadline_trips_by_device(self) -> dict[str, int]:
        """By device (``legs``, ``arm``): its write-deadline trips since `connect` (their sum is `deadline_trips`)."""


class LinkStatsLike(Protocol):
    """Counters of a robot's link (`wbc.hardware.unitree.LinkStats` is one); the pacing ones are read by name."""

    @property
    def late_advances(self) -> int:
        """`advance` calls that found their wall-clock deadline already past (the control loop was late)."""

    @property
    def worst_lateness(self) -> float:
        """By how much the latest such call was late [s]."""

    @property
    def state_age(self) -> float | None:
        """How long before the snapshot the link brought its newest valid state [s]; inf before the first.

        None for a robot whose link keeps no such figure. The link is the robot's own (a quadruped's legs' link, which
        paces it), not a device beside it (an arm's bus): this alone tells a robot that stopped answering from one
        whose joined state went stale on another device.
        """

    def as_dict(self, prefix: str = "link/") -> dict[str, float]:
        """Every counter as a flat dict, keys namespaced with `prefix`."""


@runtime_checkable
class HasLinkStats(Protocol):
    """A robot behind a link whose `advance` waits for the wall clock, and which counts how late its caller was."""

    def link_stats(self) -> LinkStatsLike:
        """A snapshot of the link's counters since `connect`."""


@runtime_checkable
class HasLatchedFaults(Protocol):
    """A robot, or a device of one, that latches its faults until it is closed.

    `DynamixelArm` does (a silent servo, corrupt answers, a servo's hardware error, its port lost); `QuadrupedArmRobot`
    and `ProcessRobot` pass their arm's on.
    """

    @property
    def faults(self) -> tuple[ArmFault, ...]:
        """The faults latched since `connect`, oldest first (empty while all is well)."""


@runtime_checkable
class HasThreadStats(Protocol):
    """A device whose link or bus runs as a `DeviceThread` (`UnitreeRobot`, `DynamixelArm`)."""

    def thread_stats(self) -> DeviceThreadStats:
        """The loop's statistics since `connect`: cycles, period, busy time, late cycles, overruns."""


@runtime_checkable
class HasRealtimeGrant(Protocol):
    """A robot whose devices run in a process that asked the OS for real-time scheduling (the I/O process)."""

    @property
    def realtime_grant(self) -> RealtimeGrant | None:
        """What that process asked for and was granted (`wbc.hardware.realtime`); None before `connect`."""


@runtime_checkable
class ConfigurationEstimate(Protocol):
    """A robot that can say what it looks like now from its own sensors alone.

    The joints are as measured, the base pose as a state estimator puts it (there is no simulator to ask); a viewer
    draws a real robot from this, without contacts or pushes.
    """

    @property
    def description(self) -> RobotDescription:
        """The robot as built (quadruped, arm and arm mode): what to draw."""

    def estimated_configuration(self) -> np.ndarray:
        """Base position [m], base quaternion (w, x, y, z) and joints in house order [rad], shape (7 + n,)."""


# -- what the safety layer reads beyond RobotState ---------------------------------------------------------------------

class RemoteButtons(Protocol):
    """The buttons of a wireless remote at one instant (`wbc.hardware.unitree.Remote` is one)."""

    @property
    def l2_b(self) -> bool:
        """L2 and B held together: Unitree's "go passive" request."""

    @property
    def held(self) -> tuple[str, ...]:
        """Names of the buttons held (empty when the remote is idle)."""


@runtime_checkable
class RemoteSource(Protocol):
    """A robot that reports its wireless remote."""

    def remote(self) -> RemoteButtons | None:
        """The remote's buttons as of the latest state; None if the robot has no remote after all.

        (A composite robot offers the method whether or not its part that would carry a remote has one.)
        """


class MotorStatus(Protocol):
    """The motors' own status at one instant (`wbc.hardware.unitree.LowStateExtras` is one)."""

    @property
    def motor_mode(self) -> np.ndarray:
        """Each motor's reported mode (0x0A servo, 0 damping/off, anything else an error code)."""

    @property
    def motor_temperature(self) -> np.ndarray:
        """Each motor's temperature [degC]."""


@runtime_checkable
class MotorNames(Protocol):
    """A robot that names the motors of its `MotorStatus`, so that a trip names the motor (``elbow (ID 4)``)."""

    @property
    def motor_names(self) -> tuple[str, ...]:
        """One name per entry of `MotorStatusSource.motor_status`, in its order."""


@runtime_checkable
class MotorStatusSource(Protocol):
    """A robot that reports its motors' temperatures and modes."""

    def motor_status(self) -> MotorStatus | None:
        """The motors' status as of the latest state; None if none of its motors report one."""


class HeldRamp(Protocol):
    """A bounded move into a command (`wbc.hardware.safety.ramp.CommandRamp`).

    It starts at the measured pose (`start`), then steps towards the target until it says it is done (`step`).
    """

    @property
    def settings(self) -> dict[str, float]:
        """What it was built with, as plain numbers (a robot whose devices run in another process sends them)."""

    @property
    def started(self) -> bool:
        """True once `start` was called."""

    def start(self, q_measured: np.ndarray, time: float) -> MotorCommand:
        """The first command: hold `q_measured` with the ramp's start gains."""

    def step(self, target: MotorCommand, time: float) -> tuple[MotorCommand, bool]:
        """The command at `time` towards `target`, and whether the ramp is done."""


@runtime_checkable
class HeldJoints(Protocol):
    """A robot that drives joints no controller commands: a locked arm, held at its stowed pose.

    A safety layer above it (`wbc.hardware.safety.SafeRobot`) decides what those joints get, as it does for the
    controller's: damping while it waits for a live state or after a trip (`damp_held`), and a ramp from where they
    are into their hold when it lets the controller in (`ramp_held`). Without a safety layer they are held.
    """

    def damp_held(self, kd: float) -> None:
        """From the next write on, damp the held joints (kp 0, kd `kd`), until `ramp_held`."""

    def ramp_held(self, ramp: HeldRamp) -> None:
        """From the next write on, move the held joints from their measured pose into their hold through `ramp`.

        `ramp` is not yet started: the robot starts it at the pose it measures at its next write.
        """


_ABSENT = object()


def protocol_members(protocol: type) -> frozenset[str]:
    """The public members (methods and properties) that `protocol` and the protocols it extends declare."""
    return frozenset(name for base in protocol.__mro__ if base not in (object, Protocol) and base.__name__ != "Generic"
                     for name in vars(base) if not name.startswith("_"))


def provides(obj: Any, protocol: type) -> bool:
    """Whether `obj` (an instance or a class) has every member of `protocol`, looked up statically.

    Unlike ``isinstance``, no property runs: the answer is the class's, the same before `connect` as after, and cheap
    enough to take once and keep (the safety layer, the I/O process).
    """
    return all(inspect.getattr_static(obj, name, _ABSENT) is not _ABSENT for name in protocol_members(protocol))
