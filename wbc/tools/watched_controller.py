"""`WatchedController`: a controller that delegates every call to another and keeps the state its last tick saw.

Studies observe the runner's one loop (`wbc.arena.runner.run_episode`) instead of re-writing it. The loop's observer
is called after each tick with the robot and the controller, but what the controller was handed (the state read
before the tick; reading the robot again would draw new sensor noise) is only visible from inside the `act` call:
this wrapper, handed to the runner in the controller's place, keeps it and changes nothing else. The arm-momentum
study reads it. (How long a tick took the runner logs itself, in the episode's ``act_s``.)
"""

from __future__ import annotations

from wbc.control.protocol import Controller
from wbc.types import MotorCommand, RobotState, VelocityCommand

__all__ = ["WatchedController"]


class WatchedController:
    """Delegates `act`, `reset` and `counters` to `inner`; keeps the last tick's input.

    Attributes:
        inner: the controller doing the work.
        last_state: the state the last `act` was handed (None before the first tick).
    """

    def __init__(self, inner: Controller) -> None:
        self.inner = inner
        self.last_state: RobotState | None = None

    @property
    def rate_hz(self) -> float:
        """The inner controller's control rate [Hz]."""
        return self.inner.rate_hz

    def reset(self) -> None:
        """Reset the inner controller and forget the last tick."""
        self.inner.reset()
        self.last_state = None

    def act(self, state: RobotState, command: VelocityCommand) -> MotorCommand:
        """The inner controller's tick; the state it was handed is kept."""
        self.last_state = state
        return self.inner.act(state, command)

    def counters(self) -> dict[str, int]:
        """The inner controller's event counts."""
        return self.inner.counters()
