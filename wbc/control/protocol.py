"""What the runner drives (`Controller`) and the optional capabilities a controller may have, as protocols.

A controller sees only what a real robot gives it (`RobotState`) and the operator's `VelocityCommand`. Tools that need
more from a controller ask for a capability by its protocol (``isinstance(ctrl, HasDebugPlan)``) instead of probing
attribute names, so a capability is a documented, checked promise: the viewer draws a `HasDebugPlan`'s plan, the
arena throws a `TruthSwitch` for ``--debug-truth``, the MPC bench reads a `HasTickTimings`' breakdown.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Protocol, runtime_checkable

import numpy as np

from wbc.types import BaseTruth, MotorCommand, RobotState, VelocityCommand

__all__ = ["Controller", "HasDebugPlan", "HasSettings", "HasTickTimings", "TruthSwitch"]


@runtime_checkable
class Controller(Protocol):
    """What the runner drives at `rate_hz`.

    A controller that draws from numpy's global generator or Python's `random` finds them seeded before each trial
    from the trial's identity (`wbc.arena.sim_trial.seed_global_rngs`); a generator of its own is better still.
    """

    rate_hz: float
    """Control rate [Hz]; the runner calls `act` every 1 / rate_hz seconds of robot time."""

    def reset(self) -> None:
        """Forget everything from the previous episode."""

    def act(self, state: RobotState, command: VelocityCommand) -> MotorCommand:
        """One control tick: the motor command for this state and command."""

    def counters(self) -> dict[str, int]:
        """Event counts of the episode so far (e.g. ``fallbacks``: solves that failed and fell back)."""


@runtime_checkable
class TruthSwitch(Protocol):
    """A controller with a ground-truth debug switch: it may read the true base state instead of estimating it."""

    def use_ground_truth(self, truth: Callable[[], BaseTruth]) -> None:
        """From now on, take the base position and velocity from `truth` (called once per tick)."""


@runtime_checkable
class HasDebugPlan(Protocol):
    """A controller that can show what it plans (drawn by the viewer)."""

    def debug_plan(self) -> dict[str, np.ndarray] | None:
        """The current plan as named arrays (world frame), or None before the first plan."""


@runtime_checkable
class HasTickTimings(Protocol):
    """A controller that reports where the time of its last tick went."""

    def tick_timings(self) -> Mapping[str, float]:
        """Seconds spent in named parts of the last `act` call; a part that did not run in that tick is absent."""


@runtime_checkable
class HasSettings(Protocol):
    """A controller that can say the settings it runs with, as a run records them (``run.json``)."""

    def settings(self) -> dict[str, object]:
        """Every setting it runs with, resolved (defaults and computed values filled in), JSON-ready."""
