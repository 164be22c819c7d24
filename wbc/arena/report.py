"""Arena report: the typed summary of the records, the paper-style results table, and a Markdown report with plots.

The input is one `wbc.arena.trial_record.TrialRecord` per (controller, trial). This module turns them into:

- `summarize`: a `wbc.arena.summary.Summary`: per controller and band, mean +- std across seeds of each metric
  (`wbc.arena.stats.mean_std_over_seeds`) and a 95 % interval over the trials (Wilson for success, percentile
  bootstrap otherwise), tracking over the common window (`wbc.arena.windows`), ticks, clamps and counters; for every
  ordered pair of controllers the paired difference B - A with its 95 % interval (exact for success,
  `wbc.arena.paired_tests.paired_success_interval`; bootstrap otherwise), its paired test's p-value (exact McNemar for
  success, Wilcoxon signed-rank otherwise; `wbc.arena.paired_tests`) and the pairs a test needs for 80 % power at the
  observed difference (`wbc.arena.statistical_power`), and its p-value after Holm's correction over every paired test
  of the run (`wbc.arena.multiplicity`). A bootstrap interval needs 2 values or more, and values all equal are
  marked as such (`wbc.arena.stats.all_equal`), not given a zero-width interval. Its JSON form (``summary.json``)
  is `Summary.to_json`: NaN becomes ``None``.
- `format_table`: that summary as plain text, one block per band, in the shape of the paper's results table: mean
  ± std across seeds, or, from one seed (which has no spread across seeds), the mean and its interval over trials.
- `write_report`: ``report.md`` plus the PNG plots (drawn by `wbc.arena.plots`) in an output folder.

Everything is deterministic: the same records, in any order, give byte-identical summaries and tables (records are
put `in_canonical_order` before any statistic).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import textwrap
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from wbc.arena.breakdown import breakdown_tables
from wbc.arena.error_guard import ControllerErrors, outcome_counts
from wbc.arena.paired_tests import (
    BINARY_FIELDS,
    hodges_lehmann,
    mcnemar_exact,
    paired_success_interval,
    paired_values,
    rank_biserial,
    wilcoxon_signed_rank,
)
from wbc.arena.plots import PLOTS, write_plots
from wbc.arena.statistical_power import N_MAX, pairs_for_mcnemar, pairs_for_mean_difference
from wbc.arena.stats import (
    all_equal,
    bootstrap_mean_ci,
    in_canonical_order,
    mean_std_of_seed_values,
    mean_std_over_seeds,
    wilson_interval,
)
from wbc.arena.summary import CellSummary, CounterTotal, MetricSummary, PairSummary, Summary, TickWarning, p_digits
from wbc.arena.trial_record import CONTROLLER_ERROR, DIVERGED, OPERATOR_STOP, SAFETY_TRIP, TrialRecord, decode_counters
from wbc.arena.verdict import ALPHA, count_line, holm_family, robots_caveat, signed, verdicts
from wbc.arena.windows import COMMON_WINDOW, common_window_values
from wbc.errors import RecordError
from wbc.output_files import write_text

__all__ = [
    "METRICS",
    "METRIC_KEYS",
    "EXTRA_METRICS",
    "FAILURES_NOTE",
    "LABELS",
    "summarize",
    "format_table",
    "format_verdict",
    "cell_legend",
    "counter_totals",
    "PAIRED_LEGEND",
    "cell_text",
    "md_table",
    "n80_text",
    "number_text",
    "p_text",
    "paired_comparison",
    "resumed_note",
    "compare_pair",
    "signed_text",
    "trial_interval",
    "write_report",
]

METRICS = ("success_rate", "ttf", "vlin_err", "vang_err")
"""The headline metrics, reported per band as the paper reports them (tracking errors over each trial's own survived
time)."""

COMMON_METRICS = ("vlin_err_common", "vang_err_common")
"""The tracking errors over each trial's common window: the leading whole seconds every controller of the run survived
on that trial (`wbc.arena.windows`); reported per band beside `METRICS`."""

PAIRED_METRICS = ("success_rate", "ttf", "vlin_err_common", "vang_err_common")
"""The metrics compared pairwise between controllers: tracking over the common window of the two compared, so that
a controller is not judged smoother for having fallen before the hard seconds."""

METRIC_KEYS: Mapping[str, str] = {
    "success_rate": "success",
    "ttf": "ttf",
    "vlin_err": "vlin_err",
    "vang_err": "vang_err",
    "vlin_err_common": "vlin_err_common",
    "vang_err_common": "vang_err_common",
}
"""Summary metric name -> the record field it is computed from (a common-window name: the windowed profile,
`wbc.arena.windows.COMMON_WINDOW`)."""

EXTRA_METRICS = ("max_roll_deg", "energy_j", "power_w", "arm_travel_rad")
"""Secondary metrics reported per band (named as their record fields), not compared pairwise. ``energy_j`` grows with
the time survived; ``power_w`` is its per-second form."""

LABELS: Mapping[str, str] = {
    "success_rate": "Success %",
    "ttf": "TTF",
    "vlin_err": "V_lin err [m/s]",
    "vang_err": "V_ang err [rad/s]",
    "vlin_err_common": "V_lin err, common [m/s]",
    "vang_err_common": "V_ang err, common [rad/s]",
    "max_roll_deg": "Max roll [deg]",
    "energy_j": "Energy [J]",
    "power_w": "Power [W]",
    "arm_travel_rad": "Arm travel [rad]",
}
"""Summary metric name -> its label (with the unit) in tables and on plot axes."""

WARN_FRACTION = 0.01
"""A controller whose ``act`` misses its deadline, or whose commands are clamped, on more than this fraction of its
ticks in a band gets a warning in the table and the report."""

_SPREAD_LEGEND = {
    "seeds": "cells: mean ± std across seeds (each seed's trials averaged first; the std is the spread of the seeds' "
             "means, batches of independent trials, not the mean's uncertainty: 8 of 8 in each seed gives ± 0.00); "
             "success adds its Wilson 95 % interval over all the trials [lo, hi].",
    "trials": "cells: from one seed, the mean and its 95 % interval over trials [lo, hi] (Wilson for success, "
              "percentile bootstrap otherwise); [n/a]: one trial, which gives no interval; (all n equal): every one "
              "of the n trials had this value, which a bootstrap cannot turn into an interval.",
}
_TRACKING_LEGEND = ("V_lin / V_ang err: over each trial's own survived time, as the paper reports them (a controller "
                    "that falls early is judged on fewer, often calmer, seconds); 'common': over the leading whole "
                    "seconds that every controller survived on that trial.")


def resumed_note(played: int, stored: int) -> str:
    """What a printout adds after "N trials played in T s" when the run resumed a directory that held trials.

    Args:
        played: trials played by this call.
        stored: trials in the results, this call's and those resumed from disk.

    Returns:
        ``" (and 5 stored before, resumed: 14 in all)"``; empty where this call played every trial of the results.
    """
    before = stored - played
    return f" (and {before} stored before, resumed: {stored} in all)" if before > 0 else ""


def cell_legend(summary: Summary) -> str:
    """What a results table's cells mean, printed under the tables: the spread each cell quotes, and the windows."""
    seeds = {cell.seeds for _, _, cell in summary.iter_cells() if cell.trials}
    spread = [_SPREAD_LEGEND["seeds"]] if seeds and 1 not in seeds else [_SPREAD_LEGEND["trials"]] if seeds == {1} \
        else [_SPREAD_LEGEND["seeds"], "From one seed: " + _SPREAD_LEGEND["trials"][len("cells: from one seed, "):]]
    return " ".join([*spread, _TRACKING_LEGEND])

FAILURES_NOTE = ("Success by command (trials), survival of each push by where its force points (world frame; the "
                 "robot starts facing +x) and by the axis its application point is offset along (pushes met: a push "
                 "is survived when no fall came before the next one); falls before any push and after one, and the "
                 "median time from that push to the fall. Cells: rate and successes / trials or pushes.")
"""The legend of the where-it-fails tables."""

_DECIMALS = {"success_rate": 2, "ttf": 3, "vlin_err": 3, "vang_err": 3, "vlin_err_common": 3, "vang_err_common": 3,
             "max_roll_deg": 2, "energy_j": 1, "power_w": 1, "arm_travel_rad": 3}
_SCALE = {"success_rate": 100.0}  # success is stored as a fraction, shown in percent (paired: percentage points)


def trial_interval(records: Sequence[TrialRecord], field: str) -> tuple[float, float]:
    """95 % interval of a metric's mean over trials: Wilson for a binary field, percentile bootstrap otherwise.

    The interval a one-seed run can quote (it has no spread across seeds): trials as independent draws of the
    scenario. NaN values are left out; ``(nan, nan)`` without values, and from one value of a non-binary field
    (`wbc.arena.stats.bootstrap_mean_ci`: one value has no spread to resample).
    """
    values = _values(records, field)
    if values.size == 0:
        return math.nan, math.nan
    if field in BINARY_FIELDS:
        return wilson_interval(int(values.sum()), int(values.size))
    return bootstrap_mean_ci(values)


def _values(records: Sequence[TrialRecord], field: str) -> np.ndarray:
    """The records' values of `field`, NaN left out."""
    values = np.array([float(r[field]) for r in records], dtype=float)
    return values[~np.isnan(values)]


def paired_comparison(records_a: Sequence[TrialRecord], records_b: Sequence[TrialRecord], field: str,
                      *, alpha: float = 0.05) -> dict[str, Any]:
    """B - A on the trials both played: difference, its 95 % interval, paired test, and the pairs for 80 % power.

    The test is the exact McNemar test for a binary field (``success``) and the Wilcoxon signed-rank test otherwise
    (`wbc.arena.paired_tests`). The interval of a success difference is the exact one that agrees with McNemar's
    test (`wbc.arena.paired_tests.paired_success_interval`: it excludes 0 exactly when p < 0.05); that of any other
    metric is the percentile bootstrap over the pairs. A common-window field (``vlin_err_common``,
    ``vang_err_common``) compares the two controllers' tracking errors over the seconds both survived on each trial
    (`wbc.arena.windows`). ``n80`` is the number of pairs the test needs to detect the observed difference with 80 %
    power at `alpha` (`wbc.arena.statistical_power`; None when the observed difference is 0 or needs more than
    `wbc.arena.statistical_power.N_MAX` pairs).

    Args:
        records_a: A's records (one per trial).
        records_b: B's records.
        field: the record field compared, or a common-window name.
        alpha: the significance level the power is computed for.

    Returns:
        ``{"diff", "ci95", "interval", "n", "mean_a", "mean_b", "test", "p", "n80", "a_only", "b_only", "shift",
        "rank_biserial", "all_equal", "nonzero"}``:
        ``interval`` names how ``ci95`` was made (``exact`` or ``bootstrap``), ``mean_a`` / ``mean_b`` are each
        controller's mean over the pairs used, ``a_only`` / ``b_only`` the discordant pair counts of a binary field
        (None otherwise), ``shift`` the Hodges-Lehmann estimate of B - A and ``rank_biserial`` the side and strength
        of the Wilcoxon test's lean (both None for a binary field), ``all_equal`` the number of pairs when every
        difference of a bootstrapped metric is the same (`wbc.arena.stats.all_equal`; None otherwise), ``nonzero``
        the Wilcoxon test's nonzero differences (None for a binary field); NaN where
        undefined. From one pair a bootstrap interval is NaN: one difference has no spread to resample.

    Raises:
        RecordError: one controller's records repeat a trial.
    """
    out, d = _paired(records_a, records_b, field)
    out["n80"] = _n80(out, d, alpha)
    return out


def _paired(records_a: Sequence[TrialRecord], records_b: Sequence[TrialRecord],
            field: str) -> tuple[dict[str, Any], np.ndarray]:
    """`paired_comparison` but n80, and the differences B - A it was read off (for `_n80` at other levels)."""
    if field in COMMON_WINDOW:
        a, b = _common_pairs(records_a, records_b, field)
    else:
        a, b = paired_values(records_a, records_b, field)
    out: dict[str, Any] = {"diff": math.nan, "ci95": [math.nan, math.nan], "interval": None, "n": int(a.size),
                           "mean_a": math.nan, "mean_b": math.nan, "test": None, "p": math.nan, "n80": None,
                           "a_only": None, "b_only": None, "shift": None, "rank_biserial": None, "all_equal": None,
                           "nonzero": None}
    d = b - a
    if a.size == 0:
        return out, d
    out.update(diff=float(d.mean()), mean_a=float(a.mean()), mean_b=float(b.mean()))
    if field in BINARY_FIELDS:
        test = mcnemar_exact(a, b)
        out.update(test="exact McNemar", p=test.p_value, a_only=test.a_only, b_only=test.b_only,
                   ci95=list(paired_success_interval(test.a_only, test.b_only, int(a.size))), interval="exact")
    else:
        test = wilcoxon_signed_rank(d)
        out.update(test="Wilcoxon signed-rank", p=test.p_value, ci95=list(bootstrap_mean_ci(d)), interval="bootstrap",
                   shift=hodges_lehmann(d), rank_biserial=rank_biserial(test), all_equal=all_equal(d),
                   nonzero=test.nonzero)
    return out, d


def _n80(out: Mapping[str, Any], d: np.ndarray, alpha: float) -> int | None:
    """The pairs `out`'s test needs for 80 % power at `alpha` at the difference observed (`paired_comparison`)."""
    if out["test"] == "exact McNemar":
        return pairs_for_mcnemar(out["a_only"] / d.size, out["b_only"] / d.size, alpha=alpha)
    if out["test"] is not None and d.size >= 2:
        return pairs_for_mean_difference(float(d.mean()), float(d.std(ddof=1)), alpha=alpha)
    return None


def compare_pair(records_a: Sequence[TrialRecord], records_b: Sequence[TrialRecord], *, a: str, b: str, band: str,
                 metric: str) -> PairSummary:
    """`paired_comparison` of a summary metric (`METRIC_KEYS`) as a `PairSummary` named by `a`, `b` and `band`."""
    return _compare_pair(records_a, records_b, a=a, b=b, band=band, metric=metric)[0]


def _compare_pair(records_a: Sequence[TrialRecord], records_b: Sequence[TrialRecord], *, a: str, b: str, band: str,
                  metric: str) -> tuple[PairSummary, np.ndarray]:
    """`compare_pair` and the differences B - A it was read off."""
    result, d = _paired(records_a, records_b, METRIC_KEYS[metric])
    result["n80"] = _n80(result, d, ALPHA)
    result["ci95"] = tuple(result["ci95"])
    return PairSummary(a=a, b=b, band=band, metric=metric, **result), d


def _with_family(pairs: Sequence[tuple[PairSummary, np.ndarray]]) -> list[PairSummary]:
    """The paired comparisons with their Holm-adjusted p over the verdict's family and their n80 under it.

    The family is the tests that can reach p < 0.05 on their pairs (`wbc.arena.verdict.holm_family`: Holm's
    correction with Tarone's refinement). ``n80_holm`` is the pairs for 80 % power at 0.05 / m, m every test with
    a p (``n80_holm_tests``): the family's tests and those left out of it, which more trials may bring in, so a
    test that reaches the level holds after the correction whatever the others show.

    Args:
        pairs: each comparison (`compare_pair`) with the differences B - A it was read off.

    Returns:
        The comparisons, in order, with ``p_holm`` and ``n80_holm``.
    """
    entries = holm_family([entry for entry, _ in pairs])
    m = sum(1 for entry in entries if entry.p is not None)
    out = []
    for entry, (_, d) in zip(entries, pairs, strict=True):
        if entry.n80 is None:
            out.append(entry)
            continue
        n80_holm = entry.n80 if m == 1 else _n80(dataclasses.asdict(entry), d, ALPHA / m)
        out.append(dataclasses.replace(entry, n80_holm=n80_holm, n80_holm_tests=None if n80_holm is None else m))
    return out


def _common_pairs(records_a: Sequence[TrialRecord], records_b: Sequence[TrialRecord],
                  metric: str) -> tuple[np.ndarray, np.ndarray]:
    """A's and B's tracking errors over each trial's window of both (`common_window_values`), NaN pairs left out."""
    paired_values(records_a, records_b, "ttf")  # refuses records that repeat a trial, with its message
    values = common_window_values({"a": records_a, "b": records_b}, metric)
    keys = sorted(values["a"])
    a = np.array([values["a"][k] for k in keys], dtype=float)
    b = np.array([values["b"][k] for k in keys], dtype=float)
    keep = ~(np.isnan(a) | np.isnan(b))
    return a[keep], b[keep]


def _records_by_cell(
    records: Iterable[TrialRecord], controllers: Sequence[str], bands: Sequence[str]
) -> dict[str, dict[str, list[TrialRecord]]]:
    """Controller -> band -> its records; records of other controllers or bands are dropped."""
    cells: dict[str, dict[str, list[TrialRecord]]] = {c: {b: [] for b in bands} for c in controllers}
    for record in records:
        if record.controller in cells and record.band in cells[record.controller]:
            cells[record.controller][record.band].append(record)
    return cells


def summarize(
    records: Iterable[TrialRecord],
    *,
    scenario_name: str,
    scenario_hash: str,
    controllers: Sequence[str],
    bands: Sequence[str],
    errors: Sequence[ControllerErrors] | None = None,
    sequential: Mapping[str, Any] | None = None,
    robots: Mapping[str, str] | None = None,
    robots_note: str | None = None,
) -> Summary:
    """Summarise arena records per controller and band, and compare controllers pairwise.

    For each controller and band (`CellSummary`): the number of trials and of seeds; mean / std across seeds
    (`mean_std_over_seeds`) of `METRICS` (success_rate from the ``success`` field, as a fraction in [0, 1]) and of
    `EXTRA_METRICS`, with the 95 % interval of the mean over trials (`trial_interval`); the `COMMON_METRICS` over each
    trial's common window (`wbc.arena.windows`); ticks, deadline misses and clamped ticks; every counter; and, with
    `errors` given (the arena), the trials per outcome. For every ordered pair (a, b) with a listed before b in
    `controllers`, every band and every metric in `PAIRED_METRICS` (`PairSummary`): the paired difference b - a, its
    95 % interval, its paired test and n80 (`paired_comparison`), and its p-value after Holm's correction over the
    paired tests of the run that can reach p < 0.05 on their pairs and n80 under that correction (`with_family`: the
    family the verdict weighs). Warnings for
    deadline misses or clamped ticks past `WARN_FRACTION` of a cell's ticks.

    Records of controllers or bands not listed are ignored. A listed controller or band without records gets
    0 trials and ``None`` statistics. The records are put `in_canonical_order` first, so the summary does not
    depend on the order they come in (the order trials finished).

    Args:
        records: arena records, in any order.
        scenario_name: the scenario's name.
        scenario_hash: the scenario file's content hash; every record's ``scenario_hash``, where set, must match.
        controllers: controller names, in the order of the table (the order also fixes which side of each pair is A).
        bands: band names, in the order of the table.
        errors: the controllers that failed on a trial (`wbc.arena.error_guard.ErrorGuard.report`); given, the
            summary counts outcomes and lists them; None: a summary of records alone.
        sequential: the sequential test's verdict, when the run had one.
        robots: controller -> the robot it played, in words (`wbc.arena.compare.arms_played`); None: not known.
        robots_note: the note for controllers that played different robots (`wbc.arena.compare.arms_note`), else
            None.

    Returns:
        The summary; ``summary.json`` is its `Summary.to_json`.

    Raises:
        RecordError: a record repeats a trial, or comes from another version of the scenario.
    """
    records = list(records)
    for record in records:
        if record.scenario_hash and record.scenario_hash != scenario_hash:
            raise RecordError(
                f"a record of controller {record.controller!r} was produced by scenario hash "
                f"{record.scenario_hash!r}, not {scenario_hash!r}; summarise the records of one scenario version at "
                "a time"
            )
    cells = _records_by_cell(in_canonical_order(records, controllers, bands), controllers, bands)
    per_controller: dict[str, dict[str, CellSummary]] = {c: {} for c in controllers}
    warnings: list[TickWarning] = []
    for band in bands:
        played = {c: cells[c][band] for c in controllers if cells[c][band]}
        common = {m: common_window_values(played, m, skip_errors=True) for m in COMMON_METRICS} if played else {}
        for controller in controllers:
            cell = cells[controller][band]
            metrics: dict[str, MetricSummary] = {}
            for metric in (*METRICS, *EXTRA_METRICS):
                field = METRIC_KEYS.get(metric, metric)
                stats = mean_std_over_seeds(cell, field)
                metrics[metric] = MetricSummary(stats["mean"], stats["std"], trial_interval(cell, field),
                                                all_equal=None if field in BINARY_FIELDS else
                                                all_equal(_values(cell, field)))
            for metric in COMMON_METRICS:
                metrics[metric] = _common_stat(cell, common.get(metric, {}).get(controller, {}))
            summary_cell = CellSummary(trials=len(cell), seeds=len({r.seed for r in cell}), metrics=metrics,
                                       **_tick_counts(cell), counters=counter_totals(cell),
                                       outcomes=outcome_counts(cell) if errors is not None else None)
            per_controller[controller][band] = summary_cell
            warnings += _warnings(controller, band, summary_cell)
    paired = _with_family([_compare_pair(cells[a][band], cells[b][band], a=a, b=b, band=band, metric=metric)
                          for a, b in itertools.combinations(controllers, 2) for band in bands
                          for metric in PAIRED_METRICS])
    return Summary(scenario_name=scenario_name, scenario_hash=scenario_hash, cells=per_controller,
                   paired=tuple(paired), warnings=tuple(warnings),
                   controller_errors=None if errors is None else {e.controller: e for e in errors},
                   sequential=sequential, robots=None if robots is None else dict(robots), robots_note=robots_note)


def _common_stat(cell: Sequence[TrialRecord], values: Mapping[tuple, float]) -> MetricSummary:
    """Mean ± std across seeds and the 95 % bootstrap interval over trials of a common-window tracking error."""
    pairs = [(r.seed, values.get(r.pair_key, math.nan)) for r in cell]
    stats = mean_std_of_seed_values(pairs)
    finite = np.array([v for _, v in pairs if not math.isnan(v)], dtype=float)
    return MetricSummary(stats["mean"], stats["std"], bootstrap_mean_ci(finite), trials=int(finite.size),
                         all_equal=all_equal(finite))


def _tick_counts(cell: Sequence[TrialRecord]) -> dict[str, Any]:
    """Ticks played, deadline misses and clamped-command ticks (in all, and per command row), over a cell's trials."""
    rows: dict[str, int] = {}
    for record in cell:
        for row, ticks in decode_counters(record.clamped_rows).items():
            rows[row] = rows.get(row, 0) + ticks
    return {"ticks": sum(r.ticks for r in cell), "deadline_misses": sum(r.deadline_misses for r in cell),
            "clamped_ticks": sum(r.clamped_ticks for r in cell),
            "clamped_rows": {row: rows[row] for row in _ROW_NAMES if row in rows}}


_ROW_NAMES = {"q": "position targets", "dq": "velocity targets", "kp": "position gains", "kd": "velocity gains",
              "tau": "feed-forward torques"}
"""A command row -> what it is, in words (the clamped-commands warning)."""

_TARGETS_PAST_A_STOP = ("; position targets alone: a PD target past a joint's stop presses the joint against it, "
                        "which the robot plays as the stop, and a policy trained under the same limits (as the shipped "
                        "learned policies are) may mean it (`wbc check-controller` says how far past)")
"""Added to the clamped-commands warning when only position targets were clamped: what that means, and may not."""


def counter_totals(records: Iterable[TrialRecord]) -> dict[str, CounterTotal]:
    """Every event count the controller reported (`TrialRecord.counter_values`), over `records`.

    Returns:
        Name -> its total over the trials, the trials where it was above 0 and the mean per trial (a trial that did
        not report a name counts 0 for it), names sorted.
    """
    records = list(records)
    values = [r.counter_values for r in records]
    names = sorted({name for v in values for name in v})
    out = {}
    for name in names:
        counts = [v.get(name, 0) for v in values]
        out[name] = CounterTotal(total=int(sum(counts)), trials=sum(1 for c in counts if c),
                                 per_trial=float(sum(counts)) / len(records))
    return out


def _warnings(controller: str, band: str, cell: CellSummary) -> list[TickWarning]:
    """A warning for a controller whose deadline misses or clamped ticks pass `WARN_FRACTION` of its ticks."""
    ticks = cell.ticks
    if not ticks:
        return []
    out = []
    for kind, what in (("deadline_misses", "controller.act took longer than its control period (wall time on this "
                        "machine): on a real robot those commands would come late"),
                       ("clamped_ticks", "the command lay outside the motors' limits and was clamped before it was "
                        "sent")):
        count = getattr(cell, kind)
        if count > WARN_FRACTION * ticks:
            text = (f"{controller} in band {band}: on {count} of {ticks} ticks ({100.0 * count / ticks:.1f} %) "
                    f"{what}")
            if kind == "clamped_ticks" and cell.clamped_rows:
                text += " (" + ", ".join(f"{_ROW_NAMES[r]} on {n} ticks" for r, n in cell.clamped_rows.items()) + ")"
                if set(cell.clamped_rows) == {"q"}:
                    text += _TARGETS_PAST_A_STOP
            out.append(TickWarning(controller=controller, band=band, kind=kind, count=count, ticks=ticks, text=text))
    return out


def _number(value: float | None, metric: str) -> str:
    if value is None:
        return "n/a"
    return f"{value * _SCALE.get(metric, 1.0):.{_DECIMALS[metric]}f}"


def _mean_std(stat: MetricSummary, metric: str) -> str:
    if stat.mean is None:
        return "n/a"
    return f"{_number(stat.mean, metric)} ± {_number(stat.std, metric)}"


def cell_text(stat: MetricSummary, metric: str, seeds: int | None) -> str:
    """A table cell: "mean ± std" across seeds, or from one seed "mean [lo, hi]" (its 95 % interval over trials).

    A single seed has no spread across seeds to quote (its std would print as ± 0.00); its interval over trials
    says how far the mean could be off. Where the trials give no interval, none is printed: "mean [n/a]" from one
    trial (one value has no spread to resample), "mean (all n equal)" where every one of its n trials had the same
    value (the bootstrap's [mean, mean] would measure nothing). A cell of several seeds without a mean keeps n/a.

    Several seeds are batches of independent trials (each trial draws its own scenario sample): their std is the
    spread of the batch means, the paper's convention, which says nothing of the mean's uncertainty and is 0 whenever
    every seed succeeds in every trial. A success cell of several seeds therefore adds its Wilson interval over all
    the trials, "mean ± std [lo, hi]": 8 of 8 in each of 2 seeds gives "100.00 ± 0.00 [80.64, 100.00]".

    Args:
        stat: a summary cell's metric.
        metric: the summary metric name (for scale and decimals).
        seeds: the seeds behind the cell (None: unknown).
    """
    ci = stat.ci95
    if seeds == 1 and stat.mean is not None and stat.all_equal is not None:
        return f"{_number(stat.mean, metric)} (all {stat.all_equal} equal)"
    if seeds == 1 and stat.mean is not None and None not in ci:
        return f"{_number(stat.mean, metric)} [{_number(ci[0], metric)}, {_number(ci[1], metric)}]"
    if seeds == 1 and stat.mean is not None:
        return f"{_number(stat.mean, metric)} [n/a]"
    if metric == "success_rate" and stat.mean is not None and None not in ci:
        return f"{_mean_std(stat, metric)} [{_number(ci[0], metric)}, {_number(ci[1], metric)}]"
    return _mean_std(stat, metric)


def p_text(p: float | None) -> str:
    """A p-value as printed: ``<1e-04`` below 1e-4, ``n/a`` when undefined, else `p_digits` (3 digits or more)."""
    if p is None:
        return "n/a"
    return "<1e-04" if p < 1e-4 else p_digits(p)


def n80_text(pair: PairSummary) -> str:
    """A paired comparison's n80 as printed.

    ``-`` when no difference was observed, ``n/a`` from one pair of a continuous metric (no spread to size the test
    by), ``>N`` beyond the search.
    """
    if pair.n80 is not None:
        return str(pair.n80)
    if pair.diff in (None, 0.0) or pair.test is None:
        return "-"
    if pair.n < 2 and pair.test != "exact McNemar":
        return "n/a"  # one pair shows no spread to size a test by
    return f">{N_MAX}"


def signed_text(value: float | None, metric: str) -> str:
    """A difference as printed, with its sign, in the metric's unit and decimals (success in points).

    A nonzero difference too small for the decimals is shown in scientific notation (``-1.2e-04``), never as a
    ``-0.000`` that a significant test would call better.
    """
    if value is None:
        return "n/a"
    return signed(value * _SCALE.get(metric, 1.0), _DECIMALS[metric])


def number_text(value: float | None, metric: str) -> str:
    """A value as printed in the metric's unit and decimals (success in percent), ``n/a`` when undefined."""
    return _number(value, metric)


def _ci(pair: PairSummary) -> str:
    """A paired difference's interval as printed.

    ``all n equal`` where every one of the n differences was the same (no uncertainty measured), ``n/a`` without an
    interval (no pair, or one pair of a bootstrapped metric).
    """
    if pair.all_equal is not None:
        return f"all {pair.all_equal} equal"
    if pair.ci95[0] is None or pair.ci95[1] is None:
        return "n/a"
    return f"[{signed_text(pair.ci95[0], pair.metric)}, {signed_text(pair.ci95[1], pair.metric)}]"


def _result_rows(summary: Summary, band: str, metrics: Sequence[str]) -> list[list[str]]:
    rows = []
    for controller in summary.controllers:
        cell = summary.cell(controller, band)
        if cell is None:
            rows.append([controller, "0", *("n/a" for _ in metrics)])
        else:
            rows.append([controller, str(cell.trials), *(cell_text(cell[m], m, cell.seeds) if m in cell else "n/a"
                                                         for m in metrics)])
    return rows


_OUTCOME_COLUMNS = ((CONTROLLER_ERROR, "errors"), (SAFETY_TRIP, "trips"), (OPERATOR_STOP, "stops"),
                    (DIVERGED, "diverged"))
"""Outcomes other than success and fall that get a column of their own when a trial of the run ended so."""


def _outcome_columns(summary: Summary, band: str, header: list[str],
                     rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
    """`header` and `rows` with a column after the trials for each outcome in `_OUTCOME_COLUMNS` the run had.

    Each row's count is its controller's trials in `band` that ended so (``summary.json``'s ``outcomes``, added by
    `wbc.arena.compare`): controller errors, safety trips, operator stops and diverged simulations, told apart from
    falls. A run without any keeps its table as it was.
    """
    def count(controller: str, outcome: str, where: str = band) -> int:
        cell = summary.cell(controller, where)
        return 0 if cell is None else cell.outcome(outcome)

    present = [(outcome, title) for outcome, title in _OUTCOME_COLUMNS
               if any(count(c, outcome, b) for c in summary.controllers for b in summary.bands)]
    if CONTROLLER_ERROR not in {o for o, _ in present} and summary.controller_errors:
        present.insert(0, (CONTROLLER_ERROR, "errors"))
    if not present:
        return header, rows
    extra = [[str(count(row[0], outcome)) for outcome, _ in present] for row in rows]
    return ([*header[:2], *(title for _, title in present), *header[2:]],
            [[*row[:2], *cells, *row[2:]] for row, cells in zip(rows, extra, strict=True)])


def _error_lines(summary: Summary) -> list[str]:
    """What failed, one line per controller that failed on a trial (`ControllerErrors.line`)."""
    return ["controller errors (each such trial counts as a failure, not as a fall):",
            *(f"  {errors.line()}" for errors in (summary.controller_errors or {}).values())]


_PAIRED_HEADER = ["band", "A", "B", "metric", "B - A", "95% CI", "p", "n80"]

PAIRED_LEGEND = ("95% CI: for success the exact interval built from the discordant pairs, which excludes 0 exactly "
                 "when the McNemar test has p < 0.05; otherwise the percentile bootstrap over the pairs. Tracking "
                 "errors compare the seconds both controllers survived on each trial (common window). p: exact "
                 "McNemar test for success (its discordant pairs' binomial test), Wilcoxon signed-rank test "
                 "otherwise, two-sided; n80: paired trials that test needs to detect the observed difference with "
                 "80 % power at alpha = 0.05, the test on its own (- when no difference was observed; summary.json's "
                 "n80_holm: at 0.05 / m, the first step of the verdict's Holm correction over m tests). On a few pairs "
                 "a bootstrap interval is narrower than the test allows (it may exclude 0 where no test could reject "
                 "on so few pairs): the verdict follows the test. 'all n equal': every one of the n pairs had this "
                 "difference, which a bootstrap cannot turn into an interval; n/a from one pair. Each p is its own "
                 "comparison's, not corrected for the others in this table: where nothing differs, about 1 test in "
                 "20 has p < 0.05 by chance. The verdict says which hold after Holm's correction over the tests of "
                 "this table that can reach p < 0.05 on their pairs (summary.json: p_holm).")
"""What the p and n80 columns of the paired differences mean, printed under them."""


def _paired_rows(summary: Summary) -> list[list[str]]:
    return [
        [p.band, p.a, p.b, LABELS[p.metric], signed_text(p.diff, p.metric), _ci(p), p_text(p.p),
         n80_text(p)]
        for p in summary.paired
    ]


def _sequential_lines(sequential: Mapping[str, Any]) -> list[str]:
    """The sequential test's verdict per pair and band (``wbc compare --until-significant``)."""
    rounds, after = sequential["rounds"], sequential.get("settled_after_rounds") or sequential["rounds"]
    if not sequential["settled"]:
        state = f"NOT every difference settled after {rounds} rounds"
    else:
        state = f"every tested difference settled after {after} rounds"
        if rounds > after:
            state += (f" ({rounds} played: the {rounds - after} after it were under way when it settled, and their "
                      "trials are in the results)")
    lines = [f"sequential test (--until-significant, family-wise alpha {sequential['alpha']:g}): {state}. Its "
             "p-values are anytime-valid; the fixed-n p-values above assume a number of trials fixed in advance, "
             "which a sequential stop breaks."]
    lines += _aligned(*_sequential_table(sequential))
    return lines


def _sequential_table(sequential: Mapping[str, Any]) -> tuple[list[str], list[list[str]]]:
    rows = [[t["band"], t["a"], t["b"], str(t["pairs"]), f"{t['a_only']} / {t['b_only']}", p_text(t["p_value"]),
             f"{t['alpha']:.3g}", f"after {t['rejected_after_pairs']} pairs" if t["rejected"] else "no"]
            for t in sequential["tests"]]
    return ["band", "A", "B", "pairs", "A only / B only", "p (anytime)", "alpha each", "settled"], rows


def _aligned(header: Sequence[str], rows: Sequence[Sequence[str]], indent: str = "  ") -> list[str]:
    widths = [max(len(row[i]) for row in (header, *rows)) for i in range(len(header))]
    lines = [indent + "  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)).rstrip()]
    lines.append(indent + "  ".join("-" * w for w in widths))
    lines += [indent + "  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip() for row in rows]
    return lines


def format_table(summary: Summary, *, verdict: bool = True) -> str:
    """Render a summary (from `summarize`) as plain text in the shape of the paper's results table.

    One block per band, one row per controller, columns Trials, Success %, TTF, V_lin err, V_ang err as
    "mean ± std" across seeds (success in percent with 2 decimals and its Wilson interval over all the trials, e.g.
    ``95.00 ± 0.00 [83.50, 98.62]``; the others with 3), or,
    from a single seed, "mean [lo, hi]" with the 95 % interval over trials (`cell_text`). Then, when two controllers
    or more played, a block "paired differences (B - A, 95% CI)" with one line per pair, band and metric, its test's
    p-value and n80; success differences are in percentage points. Undefined statistics show as ``n/a``. A run
    stopped by the sequential test ends with its verdict.

    Args:
        summary: the output of `summarize` (or the same read back from JSON).
        verdict: end with the verdict sentences (`format_verdict`).

    Returns:
        The table, lines separated by newlines, ending with a newline.
    """
    lines = [f"scenario {summary.scenario_name} ({summary.scenario_hash})", ""]
    metrics = (*METRICS, *_common_of(summary))
    header = ["controller", "trials", *(LABELS[m] for m in metrics)]
    for band in summary.bands:
        lines.append(f"band {band}")
        lines += _aligned(*_outcome_columns(summary, band, header, _result_rows(summary, band, metrics)))
        lines.append("")
    lines += [*textwrap.wrap(cell_legend(summary), width=118, initial_indent="  ", subsequent_indent="  "), ""]
    if summary.warnings:
        lines += ["warnings (past 1 % of a controller's ticks in a band):"]
        for w in summary.warnings:
            lines += textwrap.wrap(w.text, width=118, initial_indent="  ", subsequent_indent="    ")
        lines.append("")
    counters = _counter_lines(summary)
    if counters:
        lines += ["controller counters (totals over the trials; all of them in trials.csv, summary.json and the "
                  "report):", *(f"  {line}" for line in counters), ""]
    if summary.controller_errors:
        lines += [*_error_lines(summary), ""]
    if summary.paired:  # a run of one controller has no pairs, and no block for them
        lines.append("paired differences (B - A, 95% CI)")
        lines += _aligned(_PAIRED_HEADER, _paired_rows(summary))
        lines += textwrap.wrap(PAIRED_LEGEND, width=118, initial_indent="  ", subsequent_indent="  ")
    if summary.sequential:
        said, *table = _sequential_lines(summary.sequential)
        lines += ["", *textwrap.wrap(said, width=120), *table]
    if verdict and verdicts(summary):
        lines += ["", *format_verdict(summary).splitlines()]
    return "\n".join(lines).rstrip("\n") + "\n"


def verdict_basis(summary: Summary, *, where: str) -> str:
    """What the verdict sentences' "significant" means, as the printed table and report.md both say it.

    The fixed-n p-values, which after a sequential test's stop are optimistic: its own verdict, `where` it is
    printed, is the one that holds.
    """
    if summary.sequential is None:
        return f"paired trials; significant: p < {ALPHA:g}"
    return (f"paired trials; significant: fixed-n p < {ALPHA:g}; after the sequential test's stop these p-values are "
            f"optimistic: its own verdict, {where}, at family-wise alpha {summary.sequential['alpha']:g}, is the one "
            "that holds")


def format_verdict(summary: Summary) -> str:
    """The verdict of a summary under a heading, wrapped; empty without sentences.

    Its first line says how many tests it weighs and how many hold after Holm's correction
    (`wbc.arena.verdict.count_line`), then come the sentences (`wbc.arena.verdict.verdicts`), then, where the
    controllers played different robots, that note (`wbc.arena.verdict.robots_caveat`): report.md's Verdict section
    says the same.
    """
    sentences = verdicts(summary)
    if not sentences:
        return ""
    lines = [f"verdict ({verdict_basis(summary, where='above')}):"]
    for said in (count_line(summary), *sentences):
        if said is not None:
            lines += textwrap.wrap(said, width=118, initial_indent="  ", subsequent_indent="    ")
    caveat = robots_caveat(summary)
    if caveat is not None:
        lines += textwrap.wrap(f"note: {caveat}", width=118, initial_indent="  ", subsequent_indent="    ")
    return "\n".join(lines) + "\n"


def _common_of(summary: Summary) -> tuple[str, ...]:
    """The common-window metrics, which every cell of a summary holds (none in a summary without cells)."""
    return COMMON_METRICS if any(True for _ in summary.iter_cells()) else ()


def _counter_lines(summary: Summary) -> list[str]:
    """One line per controller and band whose counters are not all zero: ``mpc in: fallbacks 3, my_count 12``."""
    return [f"{controller} in band {band}: " + ", ".join(f"{name} {c.total}" for name, c in cell.counters.items())
            for controller, band, cell in summary.iter_cells() if any(c.total for c in cell.counters.values())]


def _md_cell(text: Any) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def md_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[str]:
    """A Markdown table, one line per row, cells escaped (``|`` and newlines)."""
    lines = ["| " + " | ".join(_md_cell(h) for h in header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(_md_cell(c) for c in row) + " |" for row in rows]
    return lines


def _md_meta(meta: Mapping[str, Any]) -> list[str]:
    lines = []
    for key, value in meta.items():
        if isinstance(value, Mapping):
            lines.append(f"- **{key}**:")
            lines += [f"  - {sub}: `{_md_cell(v)}`" for sub, v in value.items()]
        elif isinstance(value, list | tuple):
            lines.append(f"- **{key}**: {', '.join(_md_cell(v) for v in value)}")
        else:
            lines.append(f"- **{key}**: {_md_cell(value)}")
    return lines


def write_report(
    out_dir: str | Path, summary: Summary, records: Iterable[TrialRecord], meta: Mapping[str, Any],
    sections: Sequence[tuple[str, Sequence[str]]] = (), failures: Mapping[str, Any] | None = None,
    curve: Mapping[str, Any] | None = None, scenario: str | None = None,
) -> list[Path]:
    """Write ``report.md`` and its PNG plots (`wbc.arena.plots.write_plots`) into `out_dir` (created if missing).

    ``report.md`` holds the title, the scenario name and hash, `meta` as a list (nested mappings as sub-lists), the
    extra `sections`, one Markdown results table per band, the paired-differences table when two controllers or more
    played (with each test's p-value and n80, and the sequential test's verdict when the run had one), where each
    controller fails (`failures`) and links to the plots.

    Args:
        out_dir: output folder.
        summary: the output of `summarize` for `records`.
        records: the arena records summarised (used for the per-trial plots), in any order; those of controllers or
            bands not in the summary are ignored.
        meta: run information to list (controllers, seeds, trials, executor, package versions, git revision ...).
        sections: more (title, Markdown lines) sections, placed after the run information (a hardware trial's
            timing, safety events and operator actions).
        failures: the `wbc.arena.breakdown.breakdown` of the records (None: no such section).
        curve: their `wbc.arena.breakdown.recovery_curve`, drawn as ``push_recovery.png`` when it has pushes.
        scenario: the scenario with its version (``push v2``), as the plots' titles name it; None: the summary's
            scenario name.

    Returns:
        The paths written: ``report.md`` first, then the plots.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    controllers, bands = summary.controllers, summary.bands
    plots = write_plots(out, summary, in_canonical_order(records, controllers, bands), controllers=controllers,
                        bands=bands, labels=LABELS, curve=curve, scenario=scenario)

    name = summary.scenario_name
    lines = [f"# Arena report: {name}", "", f"Scenario `{name}`, hash `{summary.scenario_hash}`."]
    lines += ["", "## Run", ""]
    lines += _md_meta(meta) if meta else ["(no run information given)"]
    for title, body in sections:
        lines += ["", f"## {title}", "", *body]
    sentences = verdicts(summary)
    if sentences:
        lines += ["", "## Verdict", "", count_line(summary) or "", "", "Per band and pair of controllers, on the same "
                  f"trials ({verdict_basis(summary, where='in the section Sequential test')}).", "",
                  *(f"- {sentence}" for sentence in sentences)]
        caveat = robots_caveat(summary)
        if caveat is not None:
            lines += ["", f"**Note:** {caveat}"]
    legend = cell_legend(summary)
    lines += ["", "## Results", "", legend[0].upper() + legend[1:] + " Success in %."]
    metrics = (*METRICS, *_common_of(summary), *EXTRA_METRICS)
    for band in bands:
        lines += ["", f"### Band `{band}`", ""]
        header = ["Controller", "Trials", *(LABELS[m] for m in metrics)]
        lines += md_table(*_outcome_columns(summary, band, header, _result_rows(summary, band, metrics)))
    if summary.warnings:
        lines += ["", "## Warnings", "", "Past 1 % of a controller's ticks in a band:", "",
                  *(f"- {w.text}" for w in summary.warnings)]
    lines += ["", "## Timing and commands", "", "Per controller and band, summed over its trials: control ticks "
              "played, ticks whose `act` took longer than the control period (wall time on the machine that played "
              "them), and ticks whose command the robot clamped to its motors' limits.", ""]
    lines += md_table(["Band", "Controller", "Ticks", "Deadline misses", "Clamped ticks"],
                      [[band, c, cell.ticks, cell.deadline_misses, cell.clamped_ticks]
                       for band in bands for c in controllers if (cell := summary.cell(c, band)) is not None])
    counter_rows = [[band, c, counter, count.total, count.trials, f"{count.per_trial:.3g}"]
                    for band in bands for c in controllers if (cell := summary.cell(c, band)) is not None
                    for counter, count in cell.counters.items()]
    lines += ["", "## Controller counters", ""]
    if counter_rows:
        lines += ["Every event count the controllers reported (`counters()`), over the band's trials: the total, the "
                  "trials where it was above 0, and the mean per trial. Each trial's counts are in the `counters` "
                  "column of `trials.csv`.", "",
                  *md_table(["Band", "Controller", "Counter", "Total", "Trials > 0", "Per trial"], counter_rows)]
    else:
        lines += ["No controller reported a counter."]
    if summary.controller_errors:
        lead, *each = _error_lines(summary)
        lines += ["", "## Controller errors", "", lead[0].upper() + lead[1:], "", *(f"- {e.strip()}" for e in each)]
    if summary.paired:  # a run of one controller has no pairs, and no section for them
        lines += ["", "## Paired differences (B - A, 95% CI)", ""]
        lines += [
            "Same trials for both controllers. Positive: B larger (better for success and TTF, worse for tracking "
            "errors). Success in percentage points.",
            "",
        ]
        lines += md_table(_PAIRED_HEADER, _paired_rows(summary))
        lines += ["", PAIRED_LEGEND[0].upper() + PAIRED_LEGEND[1:].rstrip(".") + "."]
    if summary.sequential:
        header, rows = _sequential_table(summary.sequential)
        lines += ["", "## Sequential test", "", _sequential_lines(summary.sequential)[0]]
        lines += ["", *md_table(header, rows)]
    if failures is not None:
        lines += ["", "## Where each controller fails", "", FAILURES_NOTE, ""]
        has_pushes = curve is not None and bool(curve.get("edges"))
        for band in bands:
            lines += [f"### Band `{band}`", ""]
            for header, rows in breakdown_tables(failures, band, pushes=has_pushes):
                lines += [*md_table(header, rows), ""]
    lines += ["", "## Plots", ""]
    written = {p.name for p in plots}
    for name, title in PLOTS:
        if name in written:
            lines += [f"- [{title}]({name})", "", f"  ![{title}]({name})", ""]
        else:
            lines += [f"- {title}: not drawn (no trial had a push{'' if curve else ', or no push outcomes given'})", ""]
    report = out / "report.md"
    write_text(report, "\n".join(lines).rstrip("\n") + "\n")
    return [report, *plots]
