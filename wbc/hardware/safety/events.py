"""`SafetyEvent`: one transition of the safety layer, the record a runner writes into an episode.

Every change of `SafetyState` is one event with its time, both states and a reason from `REASONS`; a trip's reason
names the check that fired (`TRIP_REASONS`), and ``detail`` says what was measured against which limit.
"""

from __future__ import annotations

from dataclasses import dataclass

from wbc.hardware.safety.state import SafetyState

__all__ = ["REASONS", "TRIP_REASONS", "SafetyEvent"]

TRIP_REASONS = (
    "bad_state",  # the state holds a non-finite value or a quaternion that is not unit length
    "stale_state",  # the robot's state tick did not advance for longer than the timeout
    "joint_range",  # a measured joint beyond its range by more than the margin
    "over_power",  # measured sum |tau_est dq| above the limit for too many consecutive frames
    "motor_temperature",  # a motor hotter than the limit
    "motor_mode",  # a motor reports a mode that is neither servo nor damping (a motor error code)
    "tilt",  # IMU roll or pitch beyond the limit (a fall)
    "remote_estop",  # L2 + B held on the wireless remote (Unitree's "passive")
    "software_estop",  # `SafeRobot.estop()` was called
)
"""Why the layer went to ``damped``; each is latched until `SafeRobot.reset`."""

REASONS = ("fresh_state", "ramp_done", "reset", "connect", *TRIP_REASONS)
"""Every reason an event can carry: a live stream started the ramp, the ramp finished, an explicit reset, a
reconnection (back to waiting), a trip."""


@dataclass(frozen=True, kw_only=True)
class SafetyEvent:
    """One transition of the safety layer.

    Attributes:
        time: when it happened, on the safety layer's clock [s] (robot time unless a wall clock was given).
        from_state: the state left.
        to_state: the state entered.
        reason: one of `REASONS`.
        detail: what was measured, against which limit (empty when there is nothing to add).
    """

    time: float
    from_state: SafetyState
    to_state: SafetyState
    reason: str
    detail: str = ""

    def to_dict(self) -> dict[str, float | str]:
        """The event as plain JSON-ready values (states by name)."""
        return {"time": self.time, "from_state": str(self.from_state), "to_state": str(self.to_state),
                "reason": self.reason, "detail": self.detail}

    def __str__(self) -> str:
        tail = f": {self.detail}" if self.detail else ""
        return f"safety t={self.time:.3f} s {self.from_state} -> {self.to_state} ({self.reason}){tail}"
