"""`WallPacer`: the pacing of every wire backend's `advance` (deadline, late calls counted, resynchronised)."""

from __future__ import annotations

import time

from wbc.hardware.pacing import WallPacer


def test_an_on_time_loop_sleeps_to_its_deadlines_and_counts_nothing() -> None:
    pacer = WallPacer()
    start = time.monotonic()
    for _ in range(6):
        pacer.wait(0.01)
    assert time.monotonic() - start >= 0.05  # the first call returns at once, then five periods
    assert pacer.late_advances == 0 and pacer.worst_lateness == 0.0


def test_a_late_call_is_counted_with_its_lateness_and_does_not_make_the_next_hurry() -> None:
    pacer = WallPacer()
    pacer.wait(0.01)
    time.sleep(0.05)  # the loop's work overran its 10 ms period by about 40 ms
    pacer.wait(0.01)
    assert pacer.late_advances == 1 and pacer.worst_lateness >= 0.035
    start = time.monotonic()
    pacer.wait(0.01)  # resynchronised at the late call: a whole period again, not a catch-up
    assert time.monotonic() - start >= 0.009
    pacer.reset()
    assert pacer.late_advances == 0 and pacer.worst_lateness == 0.0
