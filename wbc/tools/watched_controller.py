"""`WatchedController`: a controller that delegates every call to another and keeps what its last tick saw and cost.

Benches and studies observe the runner's one loop (`wbc.arena.runner.run_episode`) instead of re-writing it. The
loop's observer is called after each tick with the robot and the controller, but what the controller was handed
(the state read before the tick) and how long it took are only visible from inside the `act` call: this wrapper,
handed to the runner in the controller's place, records both and changes nothing else. The MPC bench reads its act
durations and the controller's own breakdown (`HasTickTimings`); the arm-momentum study the state each tick saw.
"""

from __future__ import annotations

import time
from collections.abc import Mapping

from wbc.control.protocol import Controller, HasTickTimings
from wbc.types import MotorCommand, RobotState, VelocityCommand

__all__ = ["WatchedController"]


class WatchedController:
    """Delegates `act`, `reset` and `counters` to `inner`; keeps the last tick's input and timings.

    Attributes:
        inner: the controller doing the work.
        last_state: the state the last `act` was handed (None before the first tick).
        last_act_s: wall time of the last `act` call, the inner controller's whole tick [s].
        last_timings: the inner controller's own breakdown of that tick (`HasTickTimings.tick_timings`, copied), or
            None when the inner controller does not report one.
    """

    def __init__(self, inner: Controller) -> None:
        self.inner = inner
        self.last_state: RobotState | None = None
        self.last_act_s = float("nan")
        self.last_timings: Mapping[str, float] | None = None
        self._timed = isinstance(inner, HasTickTimings)

    @property
    def rate_hz(self) -> float:
        """The inner controller's control rate [Hz]."""
        return self.inner.rate_hz

    def reset(self) -> None:
        """Reset the inner controller and forget the last tick."""
        self.inner.reset()
        self.last_state, self.last_act_s, self.last_timings = None, float("nan"), None

    def act(self, state: RobotState, command: VelocityCommand) -> MotorCommand:
        """The inner controller's tick, timed; its breakdown read just after, outside the timed span."""
        t0 = time.perf_counter()
        out = self.inner.act(state, command)
        self.last_act_s = time.perf_counter() - t0
        self.last_state = state
        self.last_timings = dict(self.inner.tick_timings()) if self._timed else None
        return out

    def counters(self) -> dict[str, int]:
        """The inner controller's event counts."""
        return self.inner.counters()
