"""`SafetyEvent`: one transition of the safety layer, the record a runner writes into an episode.

Every change of `SafetyState` is one event with its time, both states and a reason from `REASONS`; a trip's reason
names the check that fired (`TRIP_REASONS`), ``detail`` says what was measured against which limit, and ``remedy``
what the operator does about that reason (`REMEDIES`).
"""

from __future__ import annotations

from dataclasses import dataclass

from wbc.hardware.safety.state import SafetyState

__all__ = ["REASONS", "REMEDIES", "TRIP_REASONS", "SafetyEvent"]

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

REMEDIES: dict[str, str] = {
    "bad_state": "The robot reported a state that is not a state (NaN, or an IMU quaternion off unit length): check "
                 "that --robot names this robot and that the link's rejected-frame counts are 0 (`wbc hw check`), "
                 "then power-cycle the robot's low-level board if it persists.",
    "stale_state": "The state went stale, and the detail says whose: the legs' stream (the robot stopped answering "
                   "or its board froze: check the cable or network, the robot's power and the link's counters with "
                   "`wbc hw check`), the arm's state (a servo stopped answering: check the arm's cable and power, "
                   "then its servos with `wbc hw check`), or the host's control loop (this computer stalled the "
                   "controller: close other programs, keep the I/O process on, the default, and ask for real-time "
                   "scheduling).",
    "joint_range": "Put the robot in a pose inside its joint ranges (hung in its harness) and check it with "
                   "`wbc hw check`.",
    "over_power": "The motors drew more power than the limit: let the robot come to rest, look for a joint that "
                  "fights the controller or a leg caught on something, and lower the gains before trying again.",
    "motor_temperature": "A motor is too hot: power the robot off and let its motors cool (`wbc hw check` shows each "
                         "motor's temperature) before running again.",
    "motor_mode": "A motor reported a fault code (a Unitree motor's 0x08 is overheat; an arm servo's 0x80 + bits is "
                  "its Hardware Error Status, 0x41 no answer, 0x42 corrupt answers, 0x43 the serial port lost): "
                  "power-cycle the robot (a servo's hardware error clears only by a reboot), let it cool, check its "
                  "cables, and read the motor's status with `wbc hw check`.",
    "tilt": "The trunk rolled or pitched beyond the limit (a fall): set the robot upright in its harness and check "
            "it with `wbc hw check`.",
    "remote_estop": "The remote's L2 + B (passive) was pressed: release the buttons, make sure the robot is safe, "
                    "and start again.",
    "software_estop": "The e-stop was pressed on this computer: make sure the robot is safe, and start again.",
}
"""What the operator does about each trip reason, in words (a trip's `SafetyEvent.remedy`)."""

REASONS = ("fresh_state", "ramp_done", "reset", "connect", "write_deadline", *TRIP_REASONS)
"""Every reason an event can carry: a live stream started the ramp, the ramp finished, an explicit reset, a
reconnection (back to waiting), a device that damped itself when the control loop stalled past its write deadline
(back to a ramp from the measured pose), a trip."""


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

    @property
    def remedy(self) -> str:
        """What to do about this event's reason (`REMEDIES`); empty for a transition that is not a trip."""
        return REMEDIES.get(self.reason, "")

    def to_dict(self) -> dict[str, float | str]:
        """The event as plain JSON-ready values (states by name)."""
        return {"time": self.time, "from_state": str(self.from_state), "to_state": str(self.to_state),
                "reason": self.reason, "detail": self.detail}

    def __str__(self) -> str:
        tail = f": {self.detail}" if self.detail else ""
        return f"safety t={self.time:.3f} s {self.from_state} -> {self.to_state} ({self.reason}){tail}"
