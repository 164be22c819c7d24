"""The main job's A/B (``wbc demo``, ``make demo``): which controllers, and which trial is worth watching afterwards.

The demo plays `DEMO_CONTROLLERS` on the same push trials through the arena and ends with the table, the paired
differences, the report and one command that opens a trial in the browser: `trial_to_watch` picks it from the
records, preferring a trial the two controllers ended differently.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from wbc.arena.trial_record import TrialRecord

__all__ = ["DEMO_CONTROLLERS", "TrialToWatch", "trial_to_watch"]

DEMO_CONTROLLERS = ("mpc", "learned")
"""The A/B the arena exists for: the model-based controller against the learned policy, arm actuated."""


@dataclass(frozen=True, kw_only=True)
class TrialToWatch:
    """A trial to open in the viewer.

    Attributes:
        controller: whose run to watch.
        band: the band.
        seed: the seed.
        trial: the trial index within (band, seed).
        why: one phrase on why this one.
        other: the controller to watch it beside (`wbc view A B`): the one that stood where `controller` fell, else
            another of the comparison; None in a run of one controller.
        at_s: where in the trial to open it [s]: a second before the fall, or None (the start).
    """

    controller: str
    band: str
    seed: int
    trial: int
    why: str
    other: str | None = None
    at_s: float | None = None


def trial_to_watch(records: Sequence[TrialRecord], controllers: Sequence[str]) -> TrialToWatch | None:
    """The most telling trial of a comparison.

    A trial the controllers ended differently (one fell, another survived), watched with the one that fell; else
    the trial with the strongest push (without pushes, the largest roll), watched with the controller that rolled
    most in it. Only runs that stood or fell are watched: one that ended otherwise (a controller error, a safety
    trip, a stop, diverged physics) has no fall to show, and a controller that raised would raise again in the
    viewer. None without a run to watch.
    """
    by_trial: dict[tuple[str, int, int], dict[str, TrialRecord]] = {}
    for r in records:
        if r.controller in controllers and r.outcome in ("success", "fall"):
            by_trial.setdefault(r.pair_key, {})[r.controller] = r
    if not by_trial:
        return None
    for key in sorted(by_trial):
        played = by_trial[key]
        fell = [c for c in controllers if c in played and not played[c].success]
        if fell and len(fell) < len(played):
            band, seed, index = key
            stood = next(c for c in controllers if c in played and played[c].success)
            fall = played[fell[0]].fall_time_s
            return TrialToWatch(controller=fell[0], band=band, seed=seed, trial=index, other=stood,
                                at_s=max(0.0, round(fall - 1.0, 1)),
                                why=f"{fell[0]} fell at {fall:.1f} s where {stood} stood")
    pushed = any(r.push_force_n > 0 for played in by_trial.values() for r in played.values())
    if pushed:
        key = max(by_trial, key=lambda k: (max(r.push_force_n for r in by_trial[k].values()), k))
    else:  # played without pushes (--no-push): the trial some controller rolled most in
        key = max(by_trial, key=lambda k: (max(r.max_roll_deg for r in by_trial[k].values()), k))
    played = by_trial[key]
    worst = max(played.values(), key=lambda r: (r.max_roll_deg, r.controller))
    band, seed, index = key
    other = next((c for c in controllers if c in played and c != worst.controller), None)
    why = (f"the strongest push, {worst.push_force_n:.0f} N; {worst.controller} rolled {worst.max_roll_deg:.0f} deg"
           if pushed else f"no pushes; {worst.controller} rolled {worst.max_roll_deg:.0f} deg, the most of any trial")
    return TrialToWatch(controller=worst.controller, band=band, seed=seed, trial=index, other=other, why=why)
