"""Statistics over arena records: per-seed means, and paired controller differences with bootstrap intervals.

The arena plays paired trials: every controller meets exactly the same trials, each identified by
``(band, seed, trial)`` (`TrialRecord.pair_key`). Statistics read a record's metric by its field name
(``record["ttf"]``); booleans such as ``success`` count as 0 / 1, so the mean of ``success`` is a success rate.

Three estimators, all deterministic:

- `mean_std_over_seeds`: the paper's cell, the mean and std across seeds, each seed's trials averaged first. Every
  trial draws its own scenario sample (`wbc.scenario.Scenario.trial`: its generator is seeded by the seed, the
  trial's index and the scenario's hash), so trials are independent draws and a seed is a batch of them: the std is the
  spread of the batch means, not the uncertainty of the mean (0 whenever every trial of every seed succeeds).
  The tables add the Wilson interval over all the trials to a success cell (`wbc.arena.report.cell_text`).
- `paired_difference`: controller B minus controller A on the same trials, with a percentile bootstrap over the
  pairs; pairing removes the trial-to-trial difficulty that both controllers share.
- `wilson_interval`: the interval of a success rate over trials (one seed gives no spread over seeds to quote).

The paired tests (exact McNemar, Wilcoxon signed-rank) are in `wbc.arena.paired_tests`, the trials they need in
`wbc.arena.statistical_power`, the sequential test in `wbc.arena.sequential`.

A mean's last digit depends on the order of its terms, and records arrive in the order trials finished (which
differs between runs with several workers, and on resume); `in_canonical_order` puts them in one order first, so the
same trials give the same statistics to the last bit.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Iterable, Sequence
from typing import Any

import numpy as np

from wbc.arena.trial_record import TrialRecord
from wbc.errors import ConfigError, RecordError

__all__ = [
    "PairKey",
    "in_canonical_order",
    "group_by",
    "mean_std_over_seeds",
    "mean_std_of_seed_values",
    "all_equal",
    "bootstrap_mean_ci",
    "paired_difference",
    "wilson_interval",
]

PairKey = tuple[str, int, int]
"""What identifies a trial across controllers: (band, seed, trial)."""

_CHUNK_ELEMENTS = 1_000_000  # bootstrap resamples drawn per block, to bound memory on large record sets


def _metric(record: TrialRecord, metric: str) -> float:
    return float(record[metric])


def in_canonical_order(records: Iterable[TrialRecord], controllers: Sequence[str],
                       bands: Sequence[str]) -> list[TrialRecord]:
    """The records of the listed controllers and bands, in canonical order.

    Controllers in the order of `controllers`, then bands in the order of `bands` (the scenario's), then seed, then
    trial; records of other controllers or bands are left out.

    Args:
        records: arena records, in any order.
        controllers: controller names, in order.
        bands: band names, in order.

    Returns:
        The sorted records.
    """
    c_rank = {c: i for i, c in enumerate(controllers)}
    b_rank = {b: i for i, b in enumerate(bands)}
    kept = [r for r in records if r.controller in c_rank and r.band in b_rank]
    return sorted(kept, key=lambda r: (c_rank[r.controller], b_rank[r.band], r.seed, r.trial))


def group_by(records: Iterable[TrialRecord],
             key: Callable[[TrialRecord], Hashable]) -> dict[Hashable, list[TrialRecord]]:
    """Group records by ``key(record)``, keeping the records' order inside each group.

    Args:
        records: arena records.
        key: maps a record to its group, e.g. ``lambda r: r.controller``.

    Returns:
        Group -> its records, groups in order of first appearance.
    """
    groups: dict[Hashable, list[TrialRecord]] = {}
    for record in records:
        groups.setdefault(key(record), []).append(record)
    return groups


def mean_std_over_seeds(records: Iterable[TrialRecord], metric: str) -> dict[str, float | int]:
    """Mean and spread of a metric across seeds.

    Records are grouped by ``seed`` and the metric averaged within each seed, m_s = mean over the seed's trials
    (booleans such as ``success`` as 0/1, so m_s is that seed's success rate). Then

        mean = (1 / S) sum_s m_s,    std = sqrt(sum_s (m_s - mean)^2 / (S - 1))   (sample std, ddof = 1),

    with std = 0.0 when S = 1. NaN values (e.g. ``fall_time_s`` of a trial that did not fall) are ignored; a seed
    whose values are all NaN does not count. Within a seed the values are summed in the order given: pass records
    `in_canonical_order` for a result that does not depend on the order trials finished in.

    Args:
        records: the records of one controller (typically in one band).
        metric: the record field, e.g. ``"success"``, ``"ttf"``, ``"vlin_err"``.

    Returns:
        ``{"mean": float, "std": float, "n_seeds": int}``; mean and std are NaN when no seed has a value.

    Raises:
        UnknownNameError: `metric` is not a record field.
    """
    return mean_std_of_seed_values((r.seed, _metric(r, metric)) for r in records)


def mean_std_of_seed_values(values: Iterable[tuple[int, float]]) -> dict[str, float | int]:
    """`mean_std_over_seeds` of (seed, value) pairs: each seed's values averaged, then mean and std across seeds.

    For values that are no record field (a tracking error over a common window, `wbc.arena.windows`). NaN values
    are ignored; within a seed values are summed in the order given.
    """
    by_seed: dict[int, list[float]] = {}
    for seed, value in values:
        by_seed.setdefault(seed, []).append(value)
    seed_means = []
    for seed in sorted(by_seed):  # sorted: the result does not depend on the records' order
        arr = np.array(by_seed[seed], dtype=float)
        arr = arr[~np.isnan(arr)]
        if arr.size:
            seed_means.append(float(arr.mean()))
    n_seeds = len(seed_means)
    if n_seeds == 0:
        return {"mean": math.nan, "std": math.nan, "n_seeds": 0}
    means = np.array(seed_means)
    std = float(means.std(ddof=1)) if n_seeds > 1 else 0.0
    return {"mean": float(means.mean()), "std": std, "n_seeds": n_seeds}


def bootstrap_mean_ci(
    values: np.ndarray, *, n_boot: int = 2000, seed: int = 0, level: float = 0.95
) -> tuple[float, float]:
    """Percentile-bootstrap confidence interval of the mean of `values`.

    Draws `n_boot` resamples of the n values with replacement from ``np.random.default_rng(seed)``, takes each
    resample's mean, and returns the (1 - level) / 2 and (1 + level) / 2 quantiles of those means. Deterministic for a
    given (values, n_boot, seed). When all values are equal the interval is [value, value] exactly: every resample
    is the same, and the interval says nothing of the mean's uncertainty (`all_equal` tells that case, which the
    tables print as the value and "all n equal"). One value has no spread to resample: no interval.

    Args:
        values: 1-D array of finite values.
        n_boot: number of resamples, >= 1.
        seed: seed of the resampling generator.
        level: coverage of the interval, in (0, 1).

    Returns:
        ``(lo, hi)``; ``(nan, nan)`` from fewer than 2 values.

    Raises:
        ConfigError: `n_boot` < 1 or `level` outside (0, 1).
    """
    if n_boot < 1:
        raise ConfigError(f"bootstrap_mean_ci: n_boot must be >= 1 resample, got {n_boot}; pass n_boot=2000 (the "
                          "default) or more")
    if not 0.0 < level < 1.0:
        raise ConfigError(f"bootstrap_mean_ci: level must be in (0, 1), got {level}; pass a coverage such as 0.95")
    values = np.asarray(values, dtype=float).ravel()
    n = values.size
    if n < 2:
        return math.nan, math.nan
    if np.all(values == values[0]):
        return float(values[0]), float(values[0])
    rng = np.random.default_rng(seed)
    rows_per_chunk = max(1, _CHUNK_ELEMENTS // n)
    boot_means = np.empty(n_boot)
    for start in range(0, n_boot, rows_per_chunk):
        stop = min(n_boot, start + rows_per_chunk)
        idx = rng.integers(0, n, size=(stop - start, n))
        boot_means[start:stop] = values[idx].mean(axis=1)
    alpha = (1.0 - level) / 2.0
    lo, hi = np.quantile(boot_means, [alpha, 1.0 - alpha])
    return float(lo), float(hi)


def all_equal(values: np.ndarray) -> int | None:
    """The number of values when there are 2 or more and every one is the same, else None.

    Such values give a bootstrap interval [value, value] (`bootstrap_mean_ci`) that measures no uncertainty: the
    reports print the value and "all n equal" instead of an interval.
    """
    values = np.asarray(values, dtype=float).ravel()
    if values.size < 2 or not np.all(values == values[0]):
        return None
    return int(values.size)


def _index_by_key(records: Iterable[TrialRecord], which: str) -> dict[PairKey, TrialRecord]:
    indexed: dict[PairKey, TrialRecord] = {}
    for record in records:
        key = record.pair_key
        if key in indexed:
            raise RecordError(
                f"records_{which} hold trial (band, seed, trial) = {key} twice; pass the records of one controller"
            )
        indexed[key] = record
    return indexed


def paired_difference(
    records_a: Iterable[TrialRecord], records_b: Iterable[TrialRecord], metric: str, *, n_boot: int = 2000,
    seed: int = 0,
) -> dict[str, Any]:
    """Mean paired difference of a metric between two controllers, B minus A, with a 95 % bootstrap interval.

    Records are paired by ``(band, seed, trial)``; trials present for only one controller are left out. For each pair
    d_i = metric(B_i) - metric(A_i) (booleans as 0/1); pairs where either value is NaN are left out. Then
    diff = mean_i d_i, and ci95 is the percentile bootstrap over pairs (`bootstrap_mean_ci` with
    ``np.random.default_rng(seed)``), [diff, diff] when all d_i are equal (`all_equal`: no uncertainty measured),
    [nan, nan] from one pair.

    A positive diff means B has the larger value: for ``success`` or ``ttf`` B is better, for tracking errors
    (``vlin_err``, ``vang_err``) B is worse.

    Args:
        records_a: the records of controller A (one record per trial).
        records_b: the records of controller B (one record per trial).
        metric: the record field, e.g. ``"success"``.
        n_boot: number of bootstrap resamples.
        seed: seed of the resampling generator.

    Returns:
        ``{"diff": float, "ci95": [lo, hi], "n": int}`` with n the number of pairs used; diff and the bounds are NaN
        when n = 0.

    Raises:
        RecordError: one controller's records repeat a trial.
        UnknownNameError: `metric` is not a record field.
    """
    by_key_a = _index_by_key(records_a, "a")
    by_key_b = _index_by_key(records_b, "b")
    diffs = []
    for key in sorted(by_key_a.keys() & by_key_b.keys()):
        d = _metric(by_key_b[key], metric) - _metric(by_key_a[key], metric)
        if not math.isnan(d):
            diffs.append(d)
    if not diffs:
        return {"diff": math.nan, "ci95": [math.nan, math.nan], "n": 0}
    d_arr = np.array(diffs)
    diff = float(d_arr.mean())
    lo, hi = bootstrap_mean_ci(d_arr, n_boot=n_boot, seed=seed)
    return {"diff": diff, "ci95": [lo, hi], "n": int(d_arr.size)}


def wilson_interval(successes: int, trials: int, *, level: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a success probability from `successes` out of `trials` independent trials.

    With z the standard normal quantile at (1 + level) / 2 and p = successes / trials, the interval is

        (p + z^2 / (2 n) -+ z sqrt(p (1 - p) / n + z^2 / (4 n^2))) / (1 + z^2 / n),

    computed by `scipy.stats.binomtest(...).proportion_ci(method="wilson")`. Unlike the normal (Wald) interval it
    keeps its coverage near 0 and 1 and never collapses to a point: 10 successes out of 10 give [0.72, 1.0].

    Args:
        successes: trials that succeeded, 0 <= successes <= trials.
        trials: trials, >= 0.
        level: coverage, in (0, 1).

    Returns:
        ``(lo, hi)`` as fractions; ``(nan, nan)`` when `trials` is 0.

    Raises:
        ConfigError: counts out of range, or `level` outside (0, 1).
    """
    if not 0 <= successes <= trials:
        raise ConfigError(f"wilson_interval: need 0 <= successes <= trials, got {successes} of {trials}")
    if not 0.0 < level < 1.0:
        raise ConfigError(f"wilson_interval: level must be in (0, 1), got {level}; pass a coverage such as 0.95")
    if trials == 0:
        return math.nan, math.nan
    from scipy.stats import binomtest  # scipy.stats takes about a second to import: only when asked for

    ci = binomtest(int(successes), int(trials)).proportion_ci(confidence_level=level, method="wilson")
    return float(ci.low), float(ci.high)
