"""`DeviceThread`: the periodic loop of the wire backends and the Dynamixel emulator, on clocks the tests control.

On a `ManualClock` the loop is a task of the clock; a cycle that sleeps takes that much clock time. On a thread the
clock is a `ScriptedClock`, which only the loop's own cycle and `idle` move: the thread runs on its own, but every
time it reads is the test's. The figures checked are clock time, exact, never the wall clock's.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import pytest

from wbc.errors import ConfigError
from wbc.hardware.clock import ManualClock
from wbc.hardware.device_thread import PERIOD_WINDOW, DeviceThread, DeviceThreadStats

PERIOD = 0.005  # [s]
WAIT = 10.0  # [s] bound of a wall-clock wait for the thread (never reached when all is well)


class ScriptedClock:
    """A clock read by a loop on its thread, moved only by that loop (its cycle takes time, its `idle` waits)."""

    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += max(0.0, seconds)


def _waits(clock: ScriptedClock, seen: list[float] | None = None) -> Callable[[float], None]:
    """An `idle` that waits until the next cycle is due, as a real wait would (it moves the scripted clock there)."""
    def idle(until: float) -> None:
        if seen is not None:
            seen.append(until)
        clock.t = max(clock.t, until)
    return idle


def _cycle(clock: ManualClock | ScriptedClock, busy: list[float], log: list[float]) -> Callable[[], bool]:
    """A cycle that logs its start and takes ``busy[k]`` of clock time; it ends the loop after the last."""
    def cycle() -> bool:
        log.append(clock.now())
        clock.sleep(busy[len(log) - 1])
        return len(log) < len(busy)
    return cycle


def test_a_steady_loop_runs_on_its_period_with_no_late_cycle_and_no_overrun() -> None:
    clock = ManualClock(start=3.0)
    log: list[float] = []
    loop = DeviceThread("steady", PERIOD, _cycle(clock, [0.001] * 1000, log), clock=clock)
    assert loop.stats() == DeviceThreadStats()  # all zero before the start
    loop.start()
    assert log == []  # a task of the clock: nothing runs until the clock moves
    clock.advance(10 * PERIOD)
    assert log == pytest.approx([3.0 + k * PERIOD for k in range(11)])
    stats = loop.stats()
    assert stats.cycles == 11 and stats.late == 0 and stats.overruns == 0
    for value in (stats.period_mean, stats.period_min, stats.period_p50, stats.period_p99, stats.period_max):
        assert value == pytest.approx(PERIOD, abs=1e-12)
    assert stats.period_std == pytest.approx(0.0, abs=1e-9)
    assert stats.busy_mean == pytest.approx(0.001) and stats.busy_max == pytest.approx(0.001)
    assert loop.running and loop.failure is None


def test_a_cycle_longer_than_the_period_is_an_overrun_and_the_next_one_is_late() -> None:
    clock = ManualClock()
    log: list[float] = []
    busy = [0.001, 0.001, 0.007, 0.001, 0.001, 0.001]  # the third takes 7 ms of a 5 ms period
    loop = DeviceThread("overrun", PERIOD, _cycle(clock, busy, log), clock=clock)
    loop.start()
    clock.advance(0.1)
    # the clock runs the cycle after the long one a period after it ended; the schedule starts afresh from there
    assert log == pytest.approx([0.0, 0.005, 0.010, 0.022, 0.027, 0.032])
    stats = loop.stats()
    assert stats.overruns == 1 and stats.late == 1 and stats.cycles == 6
    assert stats.period_max == pytest.approx(0.012) and stats.period_min == pytest.approx(PERIOD)
    assert stats.period_mean == pytest.approx(0.032 / 5)
    assert stats.busy_max == pytest.approx(0.007) and stats.busy_mean == pytest.approx(0.012 / 6)
    assert not loop.running  # the last cycle returned False: the loop is done, and the clock runs it no more


def test_on_a_manual_clock_an_overrun_makes_the_next_cycle_late() -> None:
    clock = ManualClock()
    log: list[float] = []
    # 5.5 ms: the clock runs the next cycle a period after this one ended, 5.5 ms after it was due (a slot missed)
    loop = DeviceThread("slow", PERIOD, _cycle(clock, [0.0055, 0.001, 0.001], log), clock=clock)
    loop.start()
    clock.advance(0.05)
    assert log == pytest.approx([0.0, 0.0105, 0.0155])
    stats = loop.stats()
    assert stats.overruns == 1 and stats.late == 1


def test_the_percentiles_are_taken_over_the_latest_periods() -> None:
    clock = ManualClock()
    log: list[float] = []
    busy = [0.0] * (PERIOD_WINDOW + 200)
    busy[10] = 0.02  # one long gap, early: out of the window at the end, still the longest period
    loop = DeviceThread("window", PERIOD, _cycle(clock, busy, log), clock=clock)
    loop.start()
    clock.advance(len(busy) * PERIOD + 0.1)
    stats = loop.stats()
    assert stats.cycles == len(busy) and stats.late == 1 and stats.overruns == 1
    assert stats.period_max == pytest.approx(0.02 + PERIOD)
    assert stats.period_p50 == pytest.approx(PERIOD) and stats.period_p99 == pytest.approx(PERIOD)
    assert stats.as_dict("link/thread/")["link/thread/period_max"] == stats.period_max


def test_idle_runs_after_each_cycle_with_no_time_to_wait_on_a_manual_clock() -> None:
    clock = ManualClock()
    seen: list[tuple[str, float, float]] = []

    def cycle() -> bool:
        seen.append(("cycle", clock.now(), clock.now()))
        return True

    def idle(until: float) -> None:
        seen.append(("idle", clock.now(), until))

    loop = DeviceThread("idle", PERIOD, cycle, clock=clock, idle=idle)
    loop.start()
    clock.advance(PERIOD)
    assert seen == [("cycle", 0.0, 0.0), ("idle", 0.0, 0.0), ("cycle", PERIOD, PERIOD), ("idle", PERIOD, PERIOD)]


def test_the_first_failure_ends_the_loop_and_is_kept_for_the_owner() -> None:
    clock = ManualClock()
    condition = threading.Condition()
    calls: list[int] = []
    told: list[BaseException] = []
    boom = RuntimeError("the port fell out")

    def cycle() -> bool:
        calls.append(1)
        if len(calls) == 3:
            raise boom
        return True

    loop = DeviceThread("failing", PERIOD, cycle, clock=clock, condition=condition, on_failure=told.append)
    loop.start()
    clock.advance(1.0)
    assert loop.failure is boom and told == [boom]  # kept once, the owner told once
    assert len(calls) == 3 and not loop.running  # nothing runs after the failure
    assert loop.stats().cycles == 3  # the cycle that raised counts
    assert not loop.wait_until(lambda: False, 1.0)  # a wait ends with the loop
    assert clock.now() == pytest.approx(1.0)  # and moves no clock time for it


def test_a_failure_on_a_thread_wakes_the_owner_waiting_on_its_condition() -> None:
    clock = ScriptedClock()
    condition = threading.Condition()
    boom = ValueError("a bad frame")

    def cycle() -> bool:
        clock.sleep(0.001)
        if clock.now() > 0.05:
            raise boom
        return True

    loop = DeviceThread("failing-thread", PERIOD, cycle, clock=clock, idle=_waits(clock), condition=condition)
    loop.start()
    assert not loop.wait_until(lambda: False, WAIT)  # returns once the loop has ended: the failure notified it
    assert loop.failure is boom and not loop.running
    loop.stop(WAIT)


def test_the_cycle_ends_the_loop_and_join_waits_for_it_on_the_clock() -> None:
    clock = ManualClock()
    log: list[float] = []
    loop = DeviceThread("closing", PERIOD, _cycle(clock, [0.0] * 5, log), clock=clock)
    loop.start(run_first=True)
    assert log == [0.0]  # the first cycle ran at once, as a thread's does
    assert loop.join(1.0)  # moves the clock until the loop is done
    assert len(log) == 5 and clock.now() == pytest.approx(4 * PERIOD)
    assert loop.failure is None and loop.stats().cycles == 5


def test_stop_ends_the_loop_before_its_next_cycle_and_the_stats_stay_readable() -> None:
    clock = ManualClock()
    log: list[float] = []
    loop = DeviceThread("stopped", PERIOD, _cycle(clock, [0.0] * 100, log), clock=clock)
    loop.start()
    clock.advance(2 * PERIOD)
    loop.stop()
    clock.advance(1.0)
    assert len(log) == 3 and not loop.running and loop.failure is None
    assert loop.stats().cycles == 3
    with pytest.raises(ConfigError, match="started twice"):
        loop.start()


def test_wait_until_moves_a_manual_clock_a_period_at_a_time() -> None:
    clock = ManualClock()
    log: list[float] = []
    loop = DeviceThread("waited", PERIOD, _cycle(clock, [0.0] * 100, log), clock=clock)
    loop.start()
    assert loop.wait_until(lambda: len(log) >= 4, 1.0)
    assert clock.now() == pytest.approx(3 * PERIOD)  # the fourth cycle runs at 15 ms: no further
    assert not loop.wait_until(lambda: False, 0.012)
    assert clock.now() == pytest.approx(3 * PERIOD + 0.012)  # the timeout, to the tick


def test_on_a_thread_a_cycle_within_its_period_keeps_the_schedule() -> None:
    clock = ScriptedClock()
    log: list[float] = []
    idles: list[float] = []
    busy = [0.001, 0.001, 0.007, 0.001, 0.001, 0.001]
    loop = DeviceThread("on-a-thread", PERIOD, _cycle(clock, busy, log), clock=clock, idle=_waits(clock, idles))
    loop.start()
    assert loop.join(WAIT) and loop.failure is None
    assert [t.name for t in threading.enumerate() if t.name == "on-a-thread"] == []  # the thread ended
    # the cycle after the long one starts at once, 2 ms after it was due: within its period, not late; the
    # schedule keeps its phase
    assert log == pytest.approx([0.0, 0.005, 0.010, 0.017, 0.020, 0.025])
    assert idles == pytest.approx([0.005, 0.010, 0.015, 0.020, 0.025])
    stats = loop.stats()
    assert stats.cycles == 6 and stats.overruns == 1 and stats.late == 0
    assert stats.period_max == pytest.approx(0.007) and stats.period_min == pytest.approx(0.003)


def test_on_a_thread_a_cycle_starting_a_period_after_it_was_due_is_late() -> None:
    clock = ScriptedClock()
    log: list[float] = []
    busy = [0.0, 0.012, 0.0, 0.0]  # the second cycle blocks 12 ms: the third starts 7 ms after it was due
    loop = DeviceThread("late", PERIOD, _cycle(clock, busy, log), clock=clock, idle=_waits(clock))
    loop.start()
    assert loop.join(WAIT)
    assert log == pytest.approx([0.0, 0.005, 0.017, 0.022])  # the third at once, the schedule afresh from it
    stats = loop.stats()
    assert stats.late == 1 and stats.overruns == 1


def test_stop_wakes_a_thread_waiting_in_idle_and_joins_it() -> None:
    clock = ScriptedClock()
    woken = threading.Event()
    waiting = threading.Event()

    def idle(until: float) -> None:  # a wait for the device that only `wake` ends
        waiting.set()
        woken.wait(WAIT)

    loop = DeviceThread("woken", PERIOD, lambda: True, clock=clock, idle=idle, wake=woken.set)
    loop.start()
    assert waiting.wait(WAIT)
    loop.stop(WAIT)
    assert not loop.running and loop.failure is None and loop.stats().cycles == 1


def test_a_period_must_be_positive() -> None:
    with pytest.raises(ConfigError, match="period must be > 0"):
        DeviceThread("bad", 0.0, lambda: True, clock=ManualClock())
