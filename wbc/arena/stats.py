"""Statistics over arena records: per-seed means, and paired controller differences with bootstrap intervals.

The arena plays paired trials: every controller meets exactly the same trials, each identified by
``(band, seed, trial)``. One record per (controller, trial) is a flat mapping (see `wbc.arena.report` for its keys);
records read back from CSV hold strings, so every value goes through `record_float` / `record_int` / `record_str`,
which accept both typed and string values.

Two estimators, both pure numpy and deterministic:

- `mean_std_over_seeds`: the spread a reader should quote is across seeds (independent runs of the whole
  experiment), not across trials, which share a seed's scenario sample. Each seed's trials are averaged first.
- `paired_difference`: controller B minus controller A on the same trials, with a percentile bootstrap over the
  pairs; pairing removes the trial-to-trial difficulty that both controllers share.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Iterable, Mapping
from typing import Any

import numpy as np

from wbc.errors import WbcError

__all__ = [
    "Record",
    "PairKey",
    "RecordError",
    "record_float",
    "record_int",
    "record_str",
    "pair_key",
    "group_by",
    "mean_std_over_seeds",
    "bootstrap_mean_ci",
    "paired_difference",
]

Record = Mapping[str, Any]
"""One arena record: a flat mapping from field name to value (typed, or strings as read from CSV)."""

PairKey = tuple[str, int, int]
"""What identifies a trial across controllers: (band, seed, trial)."""

_TRUE = frozenset({"true", "t", "yes", "y"})
_FALSE = frozenset({"false", "f", "no", "n"})
_CHUNK_ELEMENTS = 1_000_000  # bootstrap resamples drawn per block, to bound memory on large record sets


class RecordError(WbcError, ValueError):
    """A record lacks a field, holds a value that is not a number, or repeats a trial key."""


def _field(record: Record, key: str) -> Any:
    try:
        return record[key]
    except KeyError:
        raise RecordError(f"record has no field {key!r}; its fields: {', '.join(sorted(record))}") from None


def record_float(record: Record, key: str) -> float:
    """Read field `key` of `record` as a float, whatever type it arrived as.

    Booleans become 1.0 / 0.0 (so a success rate is the mean of ``success``); the strings ``"True"``, ``"False"``,
    ``"1"``, ``"0"`` (any case) likewise; ``None`` and the empty string (a blank CSV cell) become NaN; other strings
    are parsed with `float` (``"nan"`` included).

    Args:
        record: one arena record.
        key: the field to read.

    Returns:
        The value as a float (NaN when missing from the cell).

    Raises:
        RecordError: the field is absent or its value is not a number.
    """
    value = _field(record, key)
    if value is None:
        return math.nan
    if isinstance(value, bool | np.bool_):
        return 1.0 if value else 0.0
    if isinstance(value, str):
        text = value.strip()
        if not text:
            return math.nan
        low = text.lower()
        if low in _TRUE:
            return 1.0
        if low in _FALSE:
            return 0.0
        value = text
    try:
        return float(value)
    except (TypeError, ValueError):
        raise RecordError(f"field {key!r} holds {value!r}, which is not a number or a boolean") from None


def record_int(record: Record, key: str) -> int:
    """Read field `key` of `record` as an int (accepts ``3``, ``3.0``, ``"3"`` and ``"3.0"``).

    Args:
        record: one arena record.
        key: the field to read.

    Returns:
        The integer value.

    Raises:
        RecordError: the field is absent, or its value is not a finite whole number.
    """
    value = record_float(record, key)
    if not math.isfinite(value) or value != int(value):
        raise RecordError(f"field {key!r} holds {_field(record, key)!r}, which is not a whole number")
    return int(value)


def record_str(record: Record, key: str) -> str:
    """Read field `key` of `record` as a string, stripped of surrounding white space.

    Raises:
        RecordError: the field is absent.
    """
    return str(_field(record, key)).strip()


def pair_key(record: Record) -> PairKey:
    """The key that identifies a record's trial across controllers.

    Args:
        record: one arena record with fields ``band``, ``seed`` and ``trial``.

    Returns:
        ``(band, seed, trial)``, normalised so that typed and CSV-read records give equal keys.

    Raises:
        RecordError: one of the three fields is absent or malformed.
    """
    return record_str(record, "band"), record_int(record, "seed"), record_int(record, "trial")


def group_by(records: Iterable[Record], key: Callable[[Record], Hashable]) -> dict[Hashable, list[Record]]:
    """Group records by ``key(record)``, keeping the records' order inside each group.

    Args:
        records: arena records.
        key: maps a record to its group, e.g. ``lambda r: record_str(r, "controller")``.

    Returns:
        Group -> its records, groups in order of first appearance.
    """
    groups: dict[Hashable, list[Record]] = {}
    for record in records:
        groups.setdefault(key(record), []).append(record)
    return groups


def mean_std_over_seeds(records: Iterable[Record], metric: str) -> dict[str, float | int]:
    """Mean and spread of a metric across seeds.

    Records are grouped by ``seed`` and the metric averaged within each seed, m_s = mean over the seed's trials
    (booleans such as ``success`` as 0/1, so m_s is that seed's success rate). Then

        mean = (1 / S) sum_s m_s,    std = sqrt(sum_s (m_s - mean)^2 / (S - 1))   (sample std, ddof = 1),

    with std = 0.0 when S = 1. NaN values (e.g. ``fall_time_s`` of a trial that did not fall) are ignored; a seed
    whose values are all NaN does not count.

    Args:
        records: the records of one controller (typically in one band).
        metric: the record field, e.g. ``"success"``, ``"ttf"``, ``"vlin_err"``.

    Returns:
        ``{"mean": float, "std": float, "n_seeds": int}``; mean and std are NaN when no seed has a value.

    Raises:
        RecordError: a record lacks ``seed`` or `metric`, or holds a non-numeric value.
    """
    by_seed = group_by(records, lambda r: record_int(r, "seed"))
    seed_means = []
    for seed in sorted(by_seed):  # sorted: the result does not depend on the records' order
        values = np.array([record_float(r, metric) for r in by_seed[seed]], dtype=float)
        values = values[~np.isnan(values)]
        if values.size:
            seed_means.append(float(values.mean()))
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
    given (values, n_boot, seed). When all values are equal the interval is [value, value] exactly.

    Args:
        values: 1-D array of finite values, n >= 1.
        n_boot: number of resamples, >= 1.
        seed: seed of the resampling generator.
        level: coverage of the interval, in (0, 1).

    Returns:
        ``(lo, hi)``; ``(nan, nan)`` when `values` is empty.

    Raises:
        ValueError: `n_boot` < 1 or `level` outside (0, 1).
    """
    if n_boot < 1:
        raise ValueError(f"n_boot must be >= 1, got {n_boot}")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    values = np.asarray(values, dtype=float).ravel()
    n = values.size
    if n == 0:
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


def _index_by_key(records: Iterable[Record], which: str) -> dict[PairKey, Record]:
    indexed: dict[PairKey, Record] = {}
    for record in records:
        key = pair_key(record)
        if key in indexed:
            raise RecordError(
                f"records_{which} hold trial (band, seed, trial) = {key} twice; pass the records of one controller"
            )
        indexed[key] = record
    return indexed


def paired_difference(
    records_a: Iterable[Record], records_b: Iterable[Record], metric: str, *, n_boot: int = 2000, seed: int = 0
) -> dict[str, Any]:
    """Mean paired difference of a metric between two controllers, B minus A, with a 95 % bootstrap interval.

    Records are paired by ``(band, seed, trial)``; trials present for only one controller are left out. For each pair
    d_i = metric(B_i) - metric(A_i) (booleans as 0/1); pairs where either value is NaN are left out. Then
    diff = mean_i d_i, and ci95 is the percentile bootstrap over pairs (`bootstrap_mean_ci` with
    ``np.random.default_rng(seed)``), [diff, diff] when all d_i are equal.

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
        RecordError: a record is malformed, or one controller's records repeat a trial.
    """
    by_key_a = _index_by_key(records_a, "a")
    by_key_b = _index_by_key(records_b, "b")
    diffs = []
    for key in sorted(by_key_a.keys() & by_key_b.keys()):
        d = record_float(by_key_b[key], metric) - record_float(by_key_a[key], metric)
        if not math.isnan(d):
            diffs.append(d)
    if not diffs:
        return {"diff": math.nan, "ci95": [math.nan, math.nan], "n": 0}
    d_arr = np.array(diffs)
    diff = float(d_arr.mean())
    if np.all(d_arr == d_arr[0]):
        lo = hi = diff
    else:
        lo, hi = bootstrap_mean_ci(d_arr, n_boot=n_boot, seed=seed)
    return {"diff": diff, "ci95": [lo, hi], "n": int(d_arr.size)}
