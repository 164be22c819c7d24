"""`ManualClock`: tasks due at the same time by two different sums of periods run in the order they were registered.

An emulator's physics task and a link's period task share a period but not an origin (one starts a period after
the other), so their due times differ by float rounding at some periods. Were the rounding to decide, the link would
sometimes run before the emulator's state of that period existed, and take two states in the next: a phase jitter
that no machine has. Within the clock's tolerance they are due together, and the first registered runs first.
"""

from __future__ import annotations

from wbc.hardware.clock import ManualClock

PERIOD = 0.002  # [s]


def test_two_schedules_of_one_period_keep_their_registration_order_at_every_period() -> None:
    clock = ManualClock()
    runs: list[tuple[str, float]] = []
    clock.call_every(PERIOD, lambda: runs.append(("first", clock.now())), first=PERIOD)  # origin one period on
    clock.call_every(PERIOD, lambda: runs.append(("second", clock.now())))  # origin now
    clock.advance(1.0)
    second = [t for name, t in runs if name == "second"]
    first = [t for name, t in runs if name == "first"]
    assert len(first) == 500 and len(second) == 501
    # at every period both ran, "first" (registered first) before "second", whatever the rounding of their sums
    names = [name for name, _ in runs]
    assert names[0] == "second" and names[1:] == ["first", "second"] * 500


def test_a_task_due_later_than_the_tolerance_still_runs_after() -> None:
    clock = ManualClock()
    runs: list[str] = []
    clock.call_at(0.01 + 1e-6, lambda: runs.append("early-registered, later"))
    clock.call_at(0.01, lambda: runs.append("late-registered, earlier"))
    clock.advance(0.02)
    assert runs == ["late-registered, earlier", "early-registered, later"]
