"""`WallPacer`: how a robot whose motors live in wall time paces its caller's `advance`.

Each call sleeps until the previous deadline plus `dt` on the monotonic clock. A call that finds that deadline already
past is counted as late, with by how much, and resynchronises: a late call does not make the next ones hurry, since a
loop that fell behind would otherwise run its ticks back to back on states that did not change. Every wire backend
(`UnitreeRobot`, `DynamixelArm`, `ProcessRobot`) paces with one, on the backend's clock (`wbc.hardware.clock`): the
monotonic clock on a robot, a `ManualClock` in a deterministic test, where the sleep moves the clock.
"""

from __future__ import annotations

from wbc.hardware.clock import MONOTONIC, Clock

__all__ = ["WallPacer"]


class WallPacer:
    """The deadline of the next `wait`, and the late calls so far.

    Args:
        clock: where the time is read and the sleep happens.
    """

    def __init__(self, clock: Clock = MONOTONIC) -> None:
        self.clock = clock
        self.reset()

    def reset(self) -> None:
        """Forget the deadline and the counts (a new connection)."""
        self._deadline: float | None = None
        self.late_advances = 0
        self.worst_lateness = 0.0  # [s]

    def wait(self, dt: float) -> None:
        """Sleep until `dt` [s] after the previous deadline (the first call: `dt` from now); count a late call."""
        now = self.clock.now()
        if self._deadline is None:
            self._deadline = now
        deadline = self._deadline + dt
        if now > deadline:
            self.late_advances += 1
            self.worst_lateness = max(self.worst_lateness, now - deadline)
            deadline = now
        else:
            self.clock.sleep(deadline - now)
        self._deadline = deadline
