"""`WallPacer`: the pacing of every wire backend's `advance` (deadline, late calls counted, resynchronised).

On a `ManualClock`: the pacer's sleeps move the clock, and the test's own "work" moves it too, so each deadline and
each lateness is exact. The same on the monotonic clock is a ``realtime`` test.
"""

from __future__ import annotations

import time

import pytest

from wbc.hardware.clock import ManualClock
from wbc.hardware.pacing import WallPacer

TIME_EPS = 1e-12  # [s] float rounding of the clock's sums


def test_an_on_time_loop_sleeps_to_its_deadlines_and_counts_nothing() -> None:
    clock = ManualClock()
    pacer = WallPacer(clock)
    wakes = []
    for _ in range(6):
        clock.advance(0.003)  # the loop's work takes 3 ms of its 10 ms period
        pacer.wait(0.01)
        wakes.append(clock.now())
    # every wake-up is on its deadline, one period after the previous one: the work's time is not added to the period
    assert wakes == pytest.approx([0.013 + 0.01 * k for k in range(6)], abs=TIME_EPS)
    assert pacer.late_advances == 0 and pacer.worst_lateness == 0.0


def test_a_late_call_is_counted_with_its_lateness_and_does_not_make_the_next_hurry() -> None:
    clock = ManualClock()
    pacer = WallPacer(clock)
    pacer.wait(0.01)
    deadline = clock.now()
    clock.advance(0.05)  # the loop's work overran its 10 ms period by 40 ms
    pacer.wait(0.01)
    assert clock.now() == pytest.approx(deadline + 0.05)  # a late call returns at once
    assert pacer.late_advances == 1 and pacer.worst_lateness == pytest.approx(0.04, abs=TIME_EPS)
    start = clock.now()
    pacer.wait(0.01)  # resynchronised at the late call: a whole period again, not a catch-up
    assert clock.now() - start == pytest.approx(0.01, abs=TIME_EPS)
    clock.advance(0.015)  # late again, by 5 ms: counted, the worst kept
    pacer.wait(0.01)
    assert pacer.late_advances == 2 and pacer.worst_lateness == pytest.approx(0.04, abs=TIME_EPS)
    pacer.reset()
    assert pacer.late_advances == 0 and pacer.worst_lateness == 0.0


@pytest.mark.realtime
def test_realtime_pacing_on_the_monotonic_clock() -> None:
    pacer = WallPacer()
    start = time.monotonic()
    for _ in range(6):
        pacer.wait(0.01)
    assert time.monotonic() - start >= 0.05
    assert pacer.late_advances == 0
    time.sleep(0.05)
    pacer.wait(0.01)
    assert pacer.late_advances == 1 and pacer.worst_lateness >= 0.035
