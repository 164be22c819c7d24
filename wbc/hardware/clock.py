"""Clocks for the wire backends: the monotonic clock a real link runs on, and a clock a test moves by hand.

A backend that talks to motors lives in wall time: its link or bus loop wakes every period, a silent state stream
trips after so many milliseconds, a stalled control loop is seen by the time since its last write. Every such
figure is read from a `Clock`. On a robot it is `MONOTONIC`, and each backend runs its loop on a thread of its own.

Handed a `ManualClock`, a backend starts no thread: it registers its loop's body with `ManualClock.call_every`, and
the body runs when somebody moves the clock (`advance`, or a backend's `advance(dt)`, which sleeps on it). An
emulator behind an in-process transport answers within the same call. What a test then observes (which frame went
out in which link period, after how many periods a silent stream damps the motors) is the same on every machine at
any load, because no thread races another and no figure depends on how fast the computer is.

`ManualClock` is a small discrete-event scheduler: `advance(seconds)` runs every task due before the new time in the
order of the times they are due (a tie runs in the order the tasks were registered), with `now()` reading each
task's due time while it runs. A task that sleeps (a retry's pause, a reply timeout) moves the clock forward by that
much without running the other tasks: it takes that time, as a busy loop would, and the tasks it made late run after
it, late. Real concurrency is not modelled; what the tests check is each backend's reaction to time, not its
threads.
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
from collections.abc import Callable
from typing import Protocol, runtime_checkable

from wbc.errors import ConfigError

__all__ = ["MONOTONIC", "Clock", "ManualClock", "MonotonicClock", "ScheduledCall"]


@runtime_checkable
class Clock(Protocol):
    """Where a backend reads the time and waits."""

    def now(self) -> float:
        """The current time [s] (arbitrary origin; only differences mean something)."""

    def sleep(self, seconds: float) -> None:
        """Wait `seconds` [s] (a non-positive value returns at once)."""


class MonotonicClock:
    """The operating system's monotonic clock: what a backend on a real robot (or a real-time emulator) runs on."""

    @staticmethod
    def now() -> float:
        """`time.monotonic()` [s]."""
        return time.monotonic()

    @staticmethod
    def sleep(seconds: float) -> None:
        """`time.sleep`, for a positive `seconds`."""
        if seconds > 0:
            time.sleep(seconds)


_TOLERANCE = 1e-9  # [s] a task due this close after a target time is run by it

MONOTONIC = MonotonicClock()
"""The clock every backend uses unless handed another."""


class ScheduledCall:
    """A task registered on a `ManualClock`; `cancel` removes it."""

    def __init__(self, fn: Callable[[], None], when: float, period: float | None, order: int) -> None:
        self.fn = fn
        self.when = when
        self.period = period
        self.order = order  # registration order: breaks ties between tasks due at the same time
        self.origin = when  # a periodic task is due at origin + k * period (no drift from summing periods)
        self.count = 0
        self.cancelled = False

    def cancel(self) -> None:
        """Never run this task again."""
        self.cancelled = True


class ManualClock:
    """A clock that moves only when told to, running the tasks due on the way.

    Args:
        start: the initial time [s].
    """

    def __init__(self, start: float = 0.0) -> None:
        if not math.isfinite(start):
            raise ConfigError(f"ManualClock start must be finite, got {start}")
        self._now = float(start)
        self._queue: list[tuple[float, int, ScheduledCall]] = []  # (due, registration order, task)
        self._order = itertools.count()
        self._running = False

    def now(self) -> float:
        """The current time [s]."""
        return self._now

    def sleep(self, seconds: float) -> None:
        """Move the clock `seconds` forward: `advance`, or inside a running task, the task taking that time."""
        self.advance(seconds)

    def advance(self, seconds: float) -> None:
        """Move the clock forward by `seconds` [s], running every task that falls due on the way, in time order.

        Called from inside a task, it only moves the clock: the task is taking that time, and the tasks it passes
        run after it returns (late, as they would behind a busy loop).

        Raises:
            ConfigError: `seconds` is negative or not finite.
        """
        if not (math.isfinite(seconds) and seconds >= 0.0):
            raise ConfigError(f"ManualClock.advance: seconds must be finite and >= 0, got {seconds}")
        target = self._now + seconds
        if self._running:
            self._now = target
            return
        self.run_until(target)

    def run_until(self, target: float) -> None:
        """Run every task due at or before `target` [s], then set the clock to `target` (never backwards).

        A task due within a nanosecond after `target` counts as due: times summed from periods differ from a target
        summed otherwise by rounding alone.
        """
        while self._queue and self._queue[0][0] <= target + _TOLERANCE:
            when, order, call = heapq.heappop(self._queue)
            # tasks due within the tolerance of each other are due together: the first registered runs first (two
            # schedules of the same period from different origins differ by rounding alone)
            while self._queue and self._queue[0][0] <= when + _TOLERANCE and self._queue[0][1] < order:
                when, order, call = heapq.heapreplace(self._queue, (when, order, call))
            if call.cancelled:
                continue
            self._now = max(self._now, when)
            self._running = True
            try:
                call.fn()
            finally:
                self._running = False
            if call.period is not None and not call.cancelled:
                # the next run is one period after this one was due; a run that ended later than that (it was late,
                # or took longer than its period) skips the missed runs and keeps a period from now, as a loop
                # that overran does
                call.count += 1
                call.when = call.origin + call.count * call.period
                if call.when < self._now - _TOLERANCE:
                    call.origin, call.count = self._now, 1
                    call.when = self._now + call.period
                heapq.heappush(self._queue, (call.when, call.order, call))
        self._now = max(self._now, target)

    def call_every(self, period: float, fn: Callable[[], None], *, first: float | None = None) -> ScheduledCall:
        """Run `fn` every `period` [s], first at `first` (default: now).

        Raises:
            ConfigError: `period` is not a positive finite number.
        """
        if not (math.isfinite(period) and period > 0.0):
            raise ConfigError(f"ManualClock.call_every: period must be > 0 s, got {period}")
        when = self._now if first is None else float(first)
        call = ScheduledCall(fn, when, period, next(self._order))
        heapq.heappush(self._queue, (when, call.order, call))
        return call

    def call_at(self, when: float, fn: Callable[[], None]) -> ScheduledCall:
        """Run `fn` once at time `when` [s] (at the next `advance` if `when` is already past)."""
        call = ScheduledCall(fn, float(when), None, next(self._order))
        heapq.heappush(self._queue, (call.when, call.order, call))
        return call

    @property
    def pending(self) -> int:
        """Tasks still registered (cancelled ones excluded)."""
        return sum(1 for _, _, c in self._queue if not c.cancelled)
