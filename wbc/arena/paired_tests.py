"""Paired significance tests between two controllers on the same trials: exact McNemar and Wilcoxon signed-rank.

The arena plays paired trials (`wbc.arena.stats`), so the right tests are paired ones:

- success, a binary outcome per trial: the **exact McNemar test**. Of n pairs, only the discordant ones carry
  information about a difference in success rate: b pairs where A succeeded and B failed, c where B succeeded and A
  failed. Under H0 (equal success probabilities) each discordant pair is B's win with probability 1/2, so given
  b + c = m, c ~ Binomial(m, 1/2), and the two-sided p-value is ``min(1, 2 P(Binomial(m, 1/2) <= min(b, c)))``
  (`scipy.stats.binomtest`, the same number as ``statsmodels.stats.contingency_tables.mcnemar(exact=True)``). Exact
  at every n; it needs no large-sample approximation, which the arena's small runs would not justify.
- continuous metrics (TTF, tracking errors): the **Wilcoxon signed-rank test** on the paired differences
  d_i = B_i - A_i (`scipy.stats.wilcoxon`; zero differences dropped, Wilcoxon's convention; exact null distribution
  when the nonzero differences are few and untied, the normal approximation with tie correction otherwise). H0: the
  differences are symmetric about 0. It assumes no normality, which TTF (most trials at 1.0) and error
  distributions with long tails do not have.

Both return p = 1 when nothing differs (no discordant pair, every difference zero). A fixed-n p-value is valid only
when the number of trials was fixed in advance; a run stopped by `wbc.arena.sequential` reports that test's
anytime-valid p-value instead.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from wbc.arena.record import TrialRecord
from wbc.arena.stats import PairKey
from wbc.errors import RecordError

__all__ = ["BINARY_FIELDS", "McNemarResult", "WilcoxonResult", "mcnemar_exact", "paired_values", "wilcoxon_signed_rank"]

BINARY_FIELDS = ("success",)
"""Record fields that are binary outcomes (compared by McNemar); every other metric is compared by Wilcoxon."""


@dataclass(frozen=True)
class McNemarResult:
    """An exact McNemar test.

    Attributes:
        a_only: discordant pairs where A succeeded and B failed (b).
        b_only: discordant pairs where B succeeded and A failed (c).
        n: pairs in all (concordant ones included).
        p_value: two-sided exact p-value; 1.0 without discordant pairs.
    """

    a_only: int
    b_only: int
    n: int
    p_value: float


@dataclass(frozen=True)
class WilcoxonResult:
    """A Wilcoxon signed-rank test on paired differences.

    Attributes:
        n: pairs in all.
        nonzero: pairs whose difference is not zero (the ones the test ranks).
        statistic: scipy's statistic (the smaller of the positive and negative rank sums, two-sided); NaN when no
            difference is nonzero.
        p_value: two-sided p-value; 1.0 when every difference is zero.
    """

    n: int
    nonzero: int
    statistic: float
    p_value: float


def mcnemar_exact(a: np.ndarray, b: np.ndarray) -> McNemarResult:
    """Exact McNemar test of equal success probability for paired binary outcomes.

    Args:
        a: A's outcomes, shape (n,), booleans (or 0/1).
        b: B's outcomes on the same trials, shape (n,).

    Returns:
        The discordant counts and the two-sided exact p-value (see the module docstring).

    Raises:
        RecordError: shapes differ, or a value is not 0/1.
    """
    a_arr, b_arr = np.asarray(a, dtype=float).ravel(), np.asarray(b, dtype=float).ravel()
    if a_arr.shape != b_arr.shape:
        raise RecordError(f"mcnemar_exact: {a_arr.size} outcomes of A against {b_arr.size} of B; pair them first "
                          "(paired_values)")
    if not np.all(np.isin(a_arr, (0.0, 1.0))) or not np.all(np.isin(b_arr, (0.0, 1.0))):
        raise RecordError("mcnemar_exact: outcomes must be booleans (0 or 1); compare continuous metrics with "
                          "wilcoxon_signed_rank")
    a_only = int(np.sum((a_arr == 1.0) & (b_arr == 0.0)))
    b_only = int(np.sum((a_arr == 0.0) & (b_arr == 1.0)))
    m = a_only + b_only
    if m == 0:
        return McNemarResult(a_only=0, b_only=0, n=int(a_arr.size), p_value=1.0)
    from scipy.stats import binomtest  # scipy.stats takes about a second to import: only when a test runs

    p = float(binomtest(b_only, m, 0.5, alternative="two-sided").pvalue)
    return McNemarResult(a_only=a_only, b_only=b_only, n=int(a_arr.size), p_value=min(1.0, p))


def wilcoxon_signed_rank(differences: np.ndarray) -> WilcoxonResult:
    """Two-sided Wilcoxon signed-rank test that paired differences are symmetric about zero.

    Args:
        differences: d_i = B_i - A_i, shape (n,), finite.

    Returns:
        The test; p = 1.0 when every difference is zero.

    Raises:
        RecordError: a difference is not finite.
    """
    d = np.asarray(differences, dtype=float).ravel()
    if not np.all(np.isfinite(d)):
        raise RecordError("wilcoxon_signed_rank: differences must be finite; leave out the pairs where a metric is "
                          "NaN (paired_values does)")
    nonzero = d[d != 0.0]
    if nonzero.size == 0:
        return WilcoxonResult(n=int(d.size), nonzero=0, statistic=math.nan, p_value=1.0)
    from scipy.stats import wilcoxon

    # zeros dropped here (Wilcoxon's own convention), so scipy sees only the differences it ranks
    result = wilcoxon(nonzero, alternative="two-sided")
    return WilcoxonResult(n=int(d.size), nonzero=int(nonzero.size), statistic=float(result.statistic),
                          p_value=min(1.0, float(result.pvalue)))


def _index(records: Iterable[TrialRecord], which: str) -> dict[PairKey, TrialRecord]:
    indexed: dict[PairKey, TrialRecord] = {}
    for record in records:
        if record.pair_key in indexed:
            raise RecordError(f"records_{which} hold trial (band, seed, trial) = {record.pair_key} twice; pass the "
                              "records of one controller")
        indexed[record.pair_key] = record
    return indexed


def paired_values(records_a: Iterable[TrialRecord], records_b: Iterable[TrialRecord],
                  metric: str) -> tuple[np.ndarray, np.ndarray]:
    """A's and B's values of `metric` on the trials both played, in (band, seed, trial) order.

    Pairs where either value is NaN are left out (as `wbc.arena.stats.paired_difference` does); booleans come as
    0.0 / 1.0.

    Raises:
        RecordError: one controller's records repeat a trial.
        UnknownNameError: `metric` is not a record field.
    """
    by_a, by_b = _index(records_a, "a"), _index(records_b, "b")
    keys = sorted(by_a.keys() & by_b.keys())
    a = np.array([float(by_a[k][metric]) for k in keys], dtype=float)
    b = np.array([float(by_b[k][metric]) for k in keys], dtype=float)
    keep = ~(np.isnan(a) | np.isnan(b))
    return a[keep], b[keep]
