"""`SafetyState`: the four states of the safety layer `SafeRobot`.

``waiting`` (no live state stream yet: damping only) -> ``ramp`` (from the measured pose towards the controller's
command, bounded slew, gains blended in) -> ``run`` (the controller's commands pass, clamped) -> ``damped`` (damping
only, latched: only `SafeRobot.reset` leaves it, into ``ramp``).
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["SafetyState"]


class SafetyState(StrEnum):
    """Where the safety layer is; the value is the name written into logs and events."""

    WAITING = "waiting"
    RAMP = "ramp"
    RUN = "run"
    DAMPED = "damped"
