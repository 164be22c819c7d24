"""The clocks the wire backends read: a test's `ManualClock` runs tasks in time order, and only when moved."""

from __future__ import annotations

import pytest

from wbc.errors import ConfigError
from wbc.hardware.clock import MONOTONIC, Clock, ManualClock
from wbc.hardware.pacing import WallPacer


def test_both_clocks_satisfy_the_protocol():
    assert isinstance(MONOTONIC, Clock) and isinstance(ManualClock(), Clock)
    before = MONOTONIC.now()
    MONOTONIC.sleep(-1.0)  # a non-positive sleep returns at once
    assert MONOTONIC.now() >= before


def test_periodic_tasks_run_at_their_times_and_only_when_the_clock_moves():
    clock = ManualClock(start=10.0)
    seen: list[tuple[str, float]] = []
    clock.call_every(0.002, lambda: seen.append(("link", clock.now())))
    clock.call_every(0.005, lambda: seen.append(("bus", clock.now())), first=10.001)
    assert seen == []  # nothing runs until the clock is moved
    clock.advance(0.006)
    assert [name for name, _ in seen] == ["link", "bus", "link", "link", "link", "bus"]
    assert [t for _, t in seen] == pytest.approx([10.0, 10.001, 10.002, 10.004, 10.006, 10.006])
    assert clock.now() == pytest.approx(10.006)


def test_a_tie_runs_in_registration_order_and_call_at_runs_once():
    clock = ManualClock()
    order: list[str] = []
    clock.call_at(0.01, lambda: order.append("b"))
    clock.call_at(0.01, lambda: order.append("c"))
    clock.call_at(0.005, lambda: order.append("a"))
    clock.advance(0.02)
    clock.advance(0.02)
    assert order == ["a", "b", "c"] and clock.pending == 0


def test_a_task_that_sleeps_takes_that_time_and_the_tasks_it_passed_run_late():
    clock = ManualClock()
    runs: list[float] = []

    def slow() -> None:
        clock.sleep(0.003)  # e.g. a reply timeout inside a bus cycle

    clock.call_at(0.0, slow)
    clock.call_every(0.001, lambda: runs.append(clock.now()), first=0.001)
    clock.advance(0.0045)
    # the 1 ms task was due at 1, 2 and 3 ms; the sleep held the clock until 3 ms, so it runs once at 3 ms
    # (late, as behind a busy loop), then keeps its schedule from there
    assert runs == pytest.approx([0.003, 0.004])


def test_cancel_stops_a_periodic_task():
    clock = ManualClock()
    count = []
    call = clock.call_every(0.001, lambda: count.append(1))
    clock.advance(0.0025)
    call.cancel()
    clock.advance(0.01)
    assert len(count) == 3 and clock.pending == 0


@pytest.mark.parametrize("bad", [-0.001, float("nan"), float("inf")])
def test_bad_durations_are_refused(bad):
    clock = ManualClock()
    with pytest.raises(ConfigError, match="ManualClock.advance"):
        clock.advance(bad)
    with pytest.raises(ConfigError, match="period"):
        clock.call_every(bad if bad != -0.001 else 0.0, lambda: None)


def test_the_pacer_sleeps_on_the_clock_it_is_given_and_counts_late_calls():
    clock = ManualClock()
    ticks: list[float] = []
    clock.call_every(0.002, lambda: ticks.append(clock.now()))
    pacer = WallPacer(clock)
    pacer.wait(0.01)
    assert clock.now() == pytest.approx(0.01) and len(ticks) == 6  # the link ran while the loop slept
    pacer.wait(0.01)
    assert clock.now() == pytest.approx(0.02) and len(ticks) == 11 and pacer.late_advances == 0
    clock.advance(0.015)  # the loop's work took longer than its period
    pacer.wait(0.01)
    assert pacer.late_advances == 1 and pacer.worst_lateness == pytest.approx(0.005)
    assert clock.now() == pytest.approx(0.035)  # a late call does not sleep, and resynchronises
    pacer.wait(0.01)
    assert clock.now() == pytest.approx(0.045) and pacer.late_advances == 1
