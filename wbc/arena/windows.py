"""Tracking errors over a common window: the seconds that every compared controller survived on a trial.

A tracking error averaged over a trial's own survived time favours a controller that falls early: it is judged on
the calm seconds before a push and never on the hard ones after it. To compare controllers on equal terms, each
record keeps its tracking errors second by second (`TrialRecord.vlin_err_by_s`, `vang_err_by_s`: the mean error
over each whole second played, in order), and a comparison averages each controller's errors over the same leading
seconds: those that every controller it is compared with survived on that trial (`common_window_values`).

The window of a trial is a whole number of seconds, the smallest number of whole seconds any of the compared
controllers played on it; a trial on which one of them played less than a second has no window and is left out
(its value is NaN). In a run's summary of every controller, a trial that ended in a controller error (the
controller raised, returned an invalid command, or ended its worker) does not shorten the others' window: it costs
that controller its own trial, not the others' tracking figures. The profiles are stored as text, each second's
mean with 6 significant digits (`wbc.arena.metrics.profile_text`), so that a results file read back gives the same
statistics to the last bit.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from wbc.arena.metrics import per_second, profile_text
from wbc.arena.trial_record import CONTROLLER_ERROR, TrialRecord
from wbc.errors import RecordError

__all__ = ["COMMON_WINDOW", "common_window_values", "parse_profile", "per_second", "profile_text", "window_mean"]

COMMON_WINDOW: Mapping[str, str] = {"vlin_err_common": "vlin_err_by_s", "vang_err_common": "vang_err_by_s"}
"""Common-window metric name -> the record field holding its per-second profile."""


def parse_profile(text: str, *, field: str = "profile") -> np.ndarray:
    """The per-second means of a stored profile (`wbc.arena.metrics.profile_text`).

    Raises:
        RecordError: a value does not parse as a number (the message names the field).
    """
    try:
        return np.array([float(v) for v in text.split()], dtype=float)
    except ValueError:
        raise RecordError(f"{field}: {text!r} is not a list of space-separated numbers (one per second played); "
                          "fix or delete that line of trials.csv") from None


def window_mean(record: TrialRecord, field: str, seconds: int) -> float:
    """The mean of `record`'s profile `field` over its first `seconds` whole seconds; NaN without such a window."""
    profile = parse_profile(str(record[field]), field=f"{record.controller} {record.pair_key} {field}")
    if seconds < 1 or profile.size < seconds:
        return math.nan
    return float(profile[:seconds].mean())


def common_window_values(cells: Mapping[str, Sequence[TrialRecord]], metric: str, *,
                         skip_errors: bool = False) -> dict[str, dict[tuple, float]]:
    """Each controller's tracking error over each trial's common window.

    Args:
        cells: controller -> its records (of one band, say); a trial counts when every controller played it.
        metric: a `COMMON_WINDOW` name (``vlin_err_common``, ``vang_err_common``).
        skip_errors: a record that ended in a controller error does not shorten the window of the others (its own
            value is NaN): the error costs only that controller's trial. Off, it does, as a fall would (a pair of
            controllers is compared on the seconds both played).

    Returns:
        Controller -> {pair key: the mean of its per-second errors over the seconds every controller in `cells`
        survived on that trial}; NaN for a trial whose window is empty. Trials not played by every controller are
        absent.
    """
    field = COMMON_WINDOW[metric]
    by_key = {c: {r.pair_key: r for r in records} for c, records in cells.items()}
    shared = set.intersection(*(set(k) for k in by_key.values())) if by_key else set()
    out: dict[str, dict[tuple, float]] = {c: {} for c in cells}
    for key in sorted(shared):
        judged = [c for c in cells if not (skip_errors and by_key[c][key].outcome == CONTROLLER_ERROR)]
        seconds = min((len(str(by_key[c][key][field]).split()) for c in judged), default=0)
        for c in cells:
            out[c][key] = window_mean(by_key[c][key], field, seconds) if c in judged else math.nan
    return out
