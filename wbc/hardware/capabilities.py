"""Capabilities a `Robot` backend may offer beyond the interface, as protocols the runner asks for by name.

A real robot offers none of these by default; the simulator offers all three. A runner or tool checks
``isinstance(robot, Pushable)`` instead of testing for a backend class, so a backend that can do the same (motion
capture as a `TruthSource`, a push rig as `Pushable`) takes the same path.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from wbc.scenario.push import Push
from wbc.types import BaseTruth

__all__ = ["FallDetector", "Pushable", "TruthSource"]


@runtime_checkable
class TruthSource(Protocol):
    """A backend that knows the base's true state (the simulator; motion capture on a real robot)."""

    def base_truth(self) -> BaseTruth:
        """The trunk's true pose and velocity now."""


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
