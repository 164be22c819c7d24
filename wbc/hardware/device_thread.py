"""`DeviceThread`: the one periodic loop a device runs (the legs' link, the arm's bus, the Dynamixel emulator).

A device that talks to motors, or stands in for them, does the same thing every period: a cycle (send a frame, read
and write the servos, run the servos' own time), and in between it waits, handling whatever arrives. The owner gives
the cycle and, if it has one, its work in between (`idle`); `DeviceThread` does the rest, the same way for each:

- pacing: cycle k is due one period after cycle k - 1 was due. A cycle that starts more than a period after it was
  due is *late*: its slot has passed (the next one is due already), and the schedule starts afresh from it rather
  than running the missed cycles back to back;
- the first failure: an exception of the cycle or of `idle` ends the loop; it is kept in `failure` for the owner to
  raise in its caller's thread, and the owner hears of it at once (`on_failure`, and its condition is notified);
- a clean stop: the cycle ends the loop by returning False (a device that closes on its own schedule, say after its
  close damping), or the owner calls `stop`; `join` waits for the end;
- typed statistics (`DeviceThreadStats`): cycles, the period between cycle starts (mean, spread, percentiles), how
  long each cycle took, late cycles, and overruns (cycles that took longer than the period).

Every time comes from the owner's `Clock` (`wbc.hardware.clock`). On the monotonic clock the loop runs on a thread of
its own. Handed a `ManualClock`, it starts no thread: `start` registers one period (the cycle, then `idle` with no
time to wait) with `ManualClock.call_every`, and whoever moves the clock runs the device; `join` and `wait_until`
move the clock themselves, a period at a time. Both modes run the very same cycle, and count the same statistics on
the same clock, so a test reads exact figures: a cycle that took 7 ms of clock time at a 5 ms period is one overrun
(and, since the clock runs the next cycle a period after it ended, the next one is late; a thread runs it at once,
2 ms after it was due, within its period).

The loop asks for no scheduling of its own: the processes that drive motors ask Linux for real-time scheduling, a CPU
and locked memory at start-up, before any device starts (`wbc.hardware.realtime`), and each thread inherits that.
"""

from __future__ import annotations

import dataclasses
import math
import threading
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from wbc.errors import ConfigError
from wbc.hardware.clock import MONOTONIC, Clock, ManualClock, ScheduledCall

__all__ = ["PERIOD_WINDOW", "DeviceThread", "DeviceThreadStats"]

PERIOD_WINDOW = 8192
"""The percentiles of the period are taken over this many of the latest periods (16 s of a 500 Hz link)."""
_TOLERANCE = 1e-9  # [s] times summed from periods differ from the clock's by rounding alone


@dataclass(frozen=True, kw_only=True)
class DeviceThreadStats:
    """What a device's loop did since it started, on its clock.

    A period is the interval between the starts of two consecutive cycles; it is the device's rate as achieved, and
    its spread is the device's jitter. Busy is how long a cycle itself took (on a `ManualClock`, the clock time its
    reply timeouts and pauses took). A cycle is due one period after the previous one was due.

    Attributes:
        cycles: cycles run (a cycle that raised included).
        period_mean: mean period [s] (0 before two cycles).
        period_std: standard deviation of the period [s].
        period_min: shortest period [s].
        period_p50: median period over the latest `PERIOD_WINDOW` periods [s].
        period_p99: 99th percentile of the period over the latest `PERIOD_WINDOW` periods [s].
        period_max: longest period [s].
        busy_mean: mean time a cycle took [s].
        busy_max: longest time a cycle took [s].
        late: cycles that started more than a period after they were due, when the next one was due already; the
            schedule then starts afresh from the late cycle, skipping the missed ones.
        overruns: cycles that took longer than the period.
    """

    cycles: int = 0
    period_mean: float = 0.0
    period_std: float = 0.0
    period_min: float = 0.0
    period_p50: float = 0.0
    period_p99: float = 0.0
    period_max: float = 0.0
    busy_mean: float = 0.0
    busy_max: float = 0.0
    late: int = 0
    overruns: int = 0

    def as_dict(self, prefix: str = "thread/") -> dict[str, float]:
        """The statistics as a flat dict, keys namespaced with `prefix`."""
        return {f"{prefix}{k}": v for k, v in asdict(self).items()}


class _Tally:
    """The running sums behind `DeviceThreadStats`; updated by the loop, read by anyone (under its lock)."""

    def __init__(self, period: float) -> None:
        self.period = period
        self.lock = threading.Lock()
        self.cycles = self.late = self.overruns = 0
        self.gaps = 0
        self.gap_sum = self.gap_squares = self.gap_max = 0.0
        self.gap_min = math.inf
        self.recent = np.zeros(PERIOD_WINDOW)  # the latest periods, a ring: period k at k % PERIOD_WINDOW
        self.busy_sum = self.busy_max = 0.0
        self.last_start: float | None = None

    def started(self, start: float, late: bool) -> None:
        with self.lock:
            self.cycles += 1
            self.late += late
            if self.last_start is not None:
                gap = start - self.last_start
                self.gaps += 1
                self.gap_sum += gap
                self.gap_squares += gap * gap
                self.gap_min = min(self.gap_min, gap)
                self.gap_max = max(self.gap_max, gap)
                self.recent[(self.gaps - 1) % PERIOD_WINDOW] = gap
            self.last_start = start

    def ended(self, busy: float) -> None:
        with self.lock:
            self.busy_sum += busy
            self.busy_max = max(self.busy_max, busy)
            self.overruns += busy > self.period + _TOLERANCE

    def snapshot(self) -> DeviceThreadStats:
        with self.lock:  # copied under the lock, the percentiles taken after it: the loop never waits for them
            n, recent = self.gaps, self.recent[:min(self.gaps, PERIOD_WINDOW)].copy()
            mean = self.gap_sum / n if n else 0.0
            stats = DeviceThreadStats(
                cycles=self.cycles, period_mean=mean,
                period_std=float(np.sqrt(max(0.0, self.gap_squares / n - mean * mean))) if n else 0.0,
                period_min=self.gap_min if n else 0.0, period_max=self.gap_max,
                busy_mean=self.busy_sum / self.cycles if self.cycles else 0.0, busy_max=self.busy_max,
                late=self.late, overruns=self.overruns)
        if not n:
            return stats
        p50, p99 = np.percentile(recent, (50, 99))
        return dataclasses.replace(stats, period_p50=float(p50), period_p99=float(p99))


class DeviceThread:
    """A device's periodic loop: `cycle` every `period` on `clock`, `idle` in between (see the module docstring).

    Args:
        name: the thread's name (``unitree-go1-link``, ``dynamixel-arm-bus``).
        period: the cycle's period [s].
        cycle: one period's work; returns False to end the loop (the device is done), True to go on.
        clock: where the loop reads the time; a `ManualClock` runs it as a task of that clock, anything else on a
            thread.
        idle: the work between two cycles, ``idle(until)``: handle what has arrived, and wait for more until the
            clock reads `until` at the latest (returning earlier is fine: the loop calls it again until the next
            cycle is due). On a `ManualClock` it runs once after each cycle with `until` = now. None waits only for
            the next cycle or a `stop`.
        wake: interrupts a wait of `idle` (a byte down the owner's wake-up pipe), so that `stop` ends it at once.
        condition: the owner's condition, notified when the loop fails; `wait_until` waits on it (the owner notifies
            it when what it waits for changes). None: a private one.
        on_failure: called in the loop once it has failed, with the exception (the owner says what that means for
            the motors).

    Raises:
        ConfigError: `period` is not a positive finite number.
    """

    def __init__(self, name: str, period: float, cycle: Callable[[], bool], *, clock: Clock = MONOTONIC,
                 idle: Callable[[float], None] | None = None, wake: Callable[[], None] | None = None,
                 condition: threading.Condition | None = None,
                 on_failure: Callable[[BaseException], None] | None = None) -> None:
        if not (math.isfinite(period) and period > 0.0):
            raise ConfigError(f"DeviceThread {name!r}: period must be > 0 s, got {period}")
        self.name = name
        self.period = period
        self.clock = clock
        self.stepped = isinstance(clock, ManualClock)
        self._cycle = cycle
        self._idle = idle
        self._wake = wake
        self._condition = condition if condition is not None else threading.Condition()
        self._on_failure = on_failure
        self._tally = _Tally(period)
        self._stop = threading.Event()
        self._ended = threading.Event()
        self._thread: threading.Thread | None = None
        self._task: ScheduledCall | None = None
        self._due: float | None = None
        self._failure: BaseException | None = None

    # -- lifecycle ------------------------------------------------------------------------------------------------
    def start(self, *, run_first: bool = False) -> None:
        """Start the loop: its first cycle is due now.

        Args:
            run_first: on a `ManualClock`, run what is due now (this first cycle) before returning, as a thread
                does at once; otherwise it waits for the clock to be moved.

        Raises:
            ConfigError: the loop was started before.
        """
        if self._thread is not None or self._task is not None or self._ended.is_set():
            raise ConfigError(f"DeviceThread {self.name!r}: started twice; build a new one for a new connection")
        if self.stepped:
            self._task = self.clock.call_every(self.period, self._step)
            if run_first:
                self.clock.advance(0.0)
        else:
            self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)
            self._thread.start()

    @property
    def failure(self) -> BaseException | None:
        """The exception that ended the loop, or None (set once, before the owner is told)."""
        return self._failure

    @property
    def running(self) -> bool:
        """True from `start` until the loop has ended (done, failed or stopped)."""
        return (self._thread is not None or self._task is not None) and not self._ended.is_set()

    def stop(self, timeout: float = 2.0) -> None:
        """End the loop before its next cycle (a cycle under way finishes) and wait up to `timeout` [s] for it."""
        self._stop.set()
        if self._task is not None:
            self._task.cancel()
            self._ended.set()
        if self._wake is not None:
            self._wake()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)

    def join(self, timeout: float) -> bool:
        """Wait until the loop has ended by itself, at most `timeout` [s] on its clock; True if it has.

        On a `ManualClock` this moves the clock, a period at a time, and the loop runs as it moves.
        """
        if self._thread is not None:
            self._thread.join(timeout)
        else:
            self.wait_until(lambda: False, timeout)
        return not self.running

    def wait_until(self, done: Callable[[], bool], timeout: float) -> bool:
        """Wait until ``done()``, the loop's end, or `timeout` [s] on the clock, whichever comes first; ``done()``.

        On a thread this waits on the condition, which the owner notifies when what `done` reads changes (a new
        state, a fault). On a `ManualClock` it moves the clock, by a period at most at a time.
        """
        clock = self.clock
        deadline = clock.now() + timeout
        if self.stepped:
            while not done() and self.running and clock.now() < deadline:
                clock.advance(min(self.period, deadline - clock.now()))
            return done()
        with self._condition:
            while not done() and self.running and clock.now() < deadline:
                self._condition.wait(max(0.0, deadline - clock.now()))
            return done()

    def sleep_until(self, until: float) -> None:
        """Wait until the clock reads `until`, or until `stop` (what `idle` does when it has nothing to wait on)."""
        wait = until - self.clock.now()
        if wait > 0 and not self.stepped:
            self._stop.wait(wait)

    # -- statistics -----------------------------------------------------------------------------------------------
    def stats(self) -> DeviceThreadStats:
        """A snapshot of the loop's statistics (all zero before `start`)."""
        return self._tally.snapshot()

    # -- the loop -------------------------------------------------------------------------------------------------
    def _begin(self, now: float) -> None:
        """Count a cycle starting at `now`; a late one starts the schedule afresh."""
        due = now if self._due is None else self._due
        late = now - due > self.period + _TOLERANCE
        self._due = now if late else due
        self._tally.started(now, late)

    def _run_cycle(self) -> bool:
        start = self.clock.now()
        self._begin(start)
        go_on = self._cycle()
        self._tally.ended(self.clock.now() - start)
        self._due += self.period
        return go_on

    def _run(self) -> None:
        """The thread: a cycle whenever one is due; `idle` until then."""
        idle = self._idle if self._idle is not None else self.sleep_until
        try:
            self._due = self.clock.now()
            while not self._stop.is_set():
                if self.clock.now() >= self._due - _TOLERANCE and not self._run_cycle():
                    break
                if not self._stop.is_set():
                    idle(self._due)
        except BaseException as exc:  # noqa: BLE001 - kept for the owner to raise in its caller's thread
            self._fail(exc)
        finally:
            self._ended.set()

    def _step(self) -> None:
        """One period as a task of a `ManualClock`: the cycle, then `idle` with no time to wait."""
        try:
            go_on = self._run_cycle()
            if go_on and self._idle is not None:
                self._idle(self.clock.now())
        except BaseException as exc:  # noqa: BLE001 - kept for the owner to raise, as the thread's
            self._task.cancel()
            self._ended.set()
            self._fail(exc)
            return
        if not go_on:
            self._task.cancel()
            self._ended.set()

    def _fail(self, exc: BaseException) -> None:
        self._failure = exc
        self._ended.set()
        with self._condition:
            self._condition.notify_all()
        if self._on_failure is not None:
            self._on_failure(exc)
