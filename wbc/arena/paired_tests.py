"""Paired significance tests between two controllers on the same trials: exact McNemar and Wilcoxon signed-rank.

The arena plays paired trials (`wbc.arena.stats`), so the right tests are paired ones:

- success, a binary outcome per trial: the **exact McNemar test**. Of n pairs, only the discordant ones carry
  information about a difference in success rate: b pairs where A succeeded and B failed, c where B succeeded and A
  failed. Under H0 (equal success probabilities) each discordant pair is B's win with probability 1/2, so given
  b + c = m, c ~ Binomial(m, 1/2), and the two-sided p-value is ``min(1, 2 P(Binomial(m, 1/2) <= min(b, c)))``
  (`scipy.stats.binomtest`, the same number as ``statsmodels.stats.contingency_tables.mcnemar(exact=True)``). Exact
  at every n; it needs no large-sample approximation, which the arena's small runs would not justify.
- continuous metrics (TTF, tracking errors): the **Wilcoxon signed-rank test** on the paired differences
  d_i = B_i - A_i (`wilcoxon_signed_rank`; zero differences dropped, Wilcoxon's convention; differences rounded to 12
  decimals first, so that fall times on one tick grid tie instead of being ranked by rounding noise; the exact null
  distribution, ties included, up to 200 nonzero differences, the normal approximation with the ties' variance and a
  continuity correction beyond). H0: the differences are symmetric about 0. It assumes no normality, which TTF (most
  trials at 1.0) and error distributions with long tails do not have. The side it leans to is the side of the larger
  rank sum (`rank_biserial`'s sign), the size of its shift the Hodges-Lehmann estimate (`hodges_lehmann`); the mean
  difference may lie on the other side, when a few large differences outweigh most pairs: the verdict then calls
  neither controller better.

The interval quoted for a paired success difference, `paired_success_interval`, is built from the same discordant
pairs, so that it excludes 0 exactly when the exact McNemar test rejects at its level: of n pairs, m = b + c are
discordant, and the difference is p_B - p_A = r (2 theta - 1), with r the probability that a pair is discordant and
theta the probability that a discordant pair is B's. The interval is the range of r (2 theta - 1) over the exact
(Clopper-Pearson) intervals of theta (c of m) and of r (m of n), both at the quoted level. The McNemar test rejects
exactly when theta's interval excludes 1/2 (its p-value doubles the smaller binomial tail, as the interval's bounds
put half of 1 - level in each), and r > 0 on its interval when m > 0, so the sign of the difference is settled exactly
when the test rejects. Without discordant pairs the interval is [-r_hi, r_hi], r_hi the upper bound of the
discordance rate from n concordant pairs: it does not collapse to a point. Its coverage, checked by simulation over
3 to 80 pairs and a grid of success probabilities and correlations, is at least 95 % at level 0.95 (it is
conservative, as Clopper-Pearson intervals are).

Both tests return p = 1 when nothing differs (no discordant pair, every difference zero). A fixed-n p-value is valid
only when the number of trials was fixed in advance; a run stopped by `wbc.arena.sequential` reports that test's
anytime-valid p-value instead.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from wbc.arena.stats import PairKey
from wbc.arena.trial_record import TrialRecord
from wbc.errors import RecordError

__all__ = ["BINARY_FIELDS", "DIFFERENCE_DECIMALS", "WILCOXON_EXACT_MAX", "McNemarResult", "WilcoxonResult",
           "clopper_pearson", "hodges_lehmann", "mcnemar_exact", "paired_success_interval", "paired_values",
           "rank_biserial", "wilcoxon_signed_rank"]

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
        statistic: the smaller of the positive and negative rank sums (two-sided); NaN when no difference is nonzero.
        p_value: two-sided p-value; 1.0 when every difference is zero.
        rank_sum_plus: the ranks of the positive differences, summed (0 when none is nonzero).
        rank_sum_minus: the ranks of the negative differences, summed: the side with the larger sum is the side the
            test leans to.
        exact: whether `p_value` is the exact permutation p-value (ties included), else the normal approximation.
    """

    n: int
    nonzero: int
    statistic: float
    p_value: float
    rank_sum_plus: float = 0.0
    rank_sum_minus: float = 0.0
    exact: bool = True


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


def clopper_pearson(k: int, n: int, *, level: float = 0.95) -> tuple[float, float]:
    """The exact (Clopper-Pearson) interval of a binomial probability from `k` successes of `n` trials.

    Each bound leaves (1 - level) / 2 in its tail: lo is the beta quantile B((1 - level) / 2; k, n - k + 1) (0 when
    k = 0), hi is B((1 + level) / 2; k + 1, n - k) (1 when k = n).

    Raises:
        RecordError: counts out of range (n >= 1, 0 <= k <= n), or `level` outside (0, 1).
    """
    if not (n >= 1 and 0 <= k <= n) or not 0.0 < level < 1.0:
        raise RecordError(f"clopper_pearson: need n >= 1, 0 <= k <= n and level in (0, 1); got k {k}, n {n}, level "
                          f"{level}")
    from scipy.stats import beta

    tail = (1.0 - level) / 2.0
    lo = 0.0 if k == 0 else float(beta.ppf(tail, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1.0 - tail, k + 1, n - k))
    return lo, hi


def paired_success_interval(a_only: int, b_only: int, n: int, *, level: float = 0.95) -> tuple[float, float]:
    """The interval of a paired success difference p_B - p_A that agrees with the exact McNemar test.

    From the discordant pairs: `a_only` (A succeeded, B failed) and `b_only` (B succeeded, A failed) of `n` pairs
    (module docstring: the range of r (2 theta - 1) over the exact intervals of r and theta).

    Returns:
        (lo, hi) as fractions (multiply by 100 for points); (nan, nan) when `n` is 0.

    Raises:
        RecordError: counts out of range.
    """
    if n == 0:
        return math.nan, math.nan
    m = a_only + b_only
    if min(a_only, b_only) < 0 or m > n:
        raise RecordError(f"paired_success_interval: {a_only} + {b_only} discordant pairs of {n}; counts must be >= 0 "
                          "and discordant pairs at most n")
    r_lo, r_hi = clopper_pearson(m, n, level=level)
    if m == 0:
        return -r_hi, r_hi
    t_lo, t_hi = clopper_pearson(b_only, m, level=level)
    lows = [r * (2.0 * t_lo - 1.0) for r in (r_lo, r_hi)]
    highs = [r * (2.0 * t_hi - 1.0) for r in (r_lo, r_hi)]
    return float(min(lows)), float(max(highs))


WILCOXON_EXACT_MAX = 200
"""Up to this many nonzero differences the Wilcoxon p-value is exact (`wilcoxon_signed_rank`); beyond, the normal
approximation (ties and continuity corrected) is used, within about 1e-3 of it there."""

DIFFERENCE_DECIMALS = 12
"""Differences are rounded to this many decimals before they are ranked: two differences equal in their units
(fall times on the same tick grid, say) differ in their last bits after a subtraction, and must tie, not be ranked
by that noise."""


def wilcoxon_signed_rank(differences: np.ndarray) -> WilcoxonResult:
    """Two-sided Wilcoxon signed-rank test that paired differences are symmetric about zero.

    Zero differences are dropped (Wilcoxon's own convention) and tied magnitudes share their mean rank, after the
    differences are rounded to `DIFFERENCE_DECIMALS` decimals. Up to `WILCOXON_EXACT_MAX` nonzero differences the
    p-value is exact, ties included: the null distribution of the positive rank sum, every sign equally likely, is
    counted over the (doubled, hence whole) ranks. Beyond, it is the normal approximation with the ties' variance
    and a continuity correction.

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
    nonzero = np.round(d, DIFFERENCE_DECIMALS)
    nonzero = nonzero[nonzero != 0.0]
    if nonzero.size == 0:
        return WilcoxonResult(n=int(d.size), nonzero=0, statistic=math.nan, p_value=1.0)
    from scipy.stats import norm, rankdata

    ranks2 = np.rint(2.0 * rankdata(np.abs(nonzero))).astype(np.int64)  # doubled mean ranks: whole numbers
    total2 = int(ranks2.sum())
    plus2 = int(ranks2[nonzero > 0].sum())
    deviation2 = abs(2 * plus2 - total2)  # |W+ - E[W+]|, in quarter ranks
    exact = nonzero.size <= WILCOXON_EXACT_MAX
    if exact:
        dist = np.zeros(total2 + 1)  # P(2 W+ = w), built one rank at a time
        dist[0], top = 1.0, 0
        for r in ranks2:
            shifted = np.zeros_like(dist)
            shifted[r:top + r + 1] = dist[:top + 1]
            dist = 0.5 * (dist + shifted)
            top += int(r)
        w2 = np.arange(total2 + 1)
        p = float(dist[np.abs(2 * w2 - total2) >= deviation2].sum())
    else:
        sd = math.sqrt(float((ranks2.astype(float) ** 2).sum()) / 16.0)  # of W+; ranks2 / 2 are the ranks
        step = math.gcd(*map(int, ranks2)) / 2.0  # how far apart W+'s values lie
        z = max(0.0, deviation2 / 4.0 - step / 2.0) / sd
        p = float(2.0 * norm.sf(z))
    plus, minus = plus2 / 2.0, (total2 - plus2) / 2.0
    return WilcoxonResult(n=int(d.size), nonzero=int(nonzero.size), statistic=min(plus, minus),
                          p_value=min(1.0, p), rank_sum_plus=plus, rank_sum_minus=minus, exact=exact)


HODGES_LEHMANN_EXACT_MAX = 3000
"""Up to this many nonzero differences `hodges_lehmann` takes every Walsh average (4.5 million at most); beyond, the
median of `HODGES_LEHMANN_SAMPLE` of them drawn with a fixed seed (an estimate, the same on every run)."""
HODGES_LEHMANN_SAMPLE = 4_000_000


def hodges_lehmann(differences: np.ndarray) -> float:
    """The Hodges-Lehmann estimate of the differences' centre: the median of their Walsh averages.

    Over the nonzero differences (rounded to `DIFFERENCE_DECIMALS`), as the Wilcoxon test ranks them: with most pairs
    tied at zero (TTF, where most trials survive) the estimate over every pair would be 0 whatever the others say.
    The side the test leans to is the sign of its rank sums (`WilcoxonResult`); this is the size of the shift. NaN
    without a nonzero difference.

    Args:
        differences: d_i = B_i - A_i, shape (n,), finite.
    """
    d = np.round(np.asarray(differences, dtype=float).ravel(), DIFFERENCE_DECIMALS)
    d = d[d != 0.0]
    if d.size == 0:
        return math.nan
    if d.size <= HODGES_LEHMANN_EXACT_MAX:
        i, j = np.triu_indices(d.size)
    else:  # a fixed-seed sample of the pairs (i <= j), so that memory stays bounded and the figure reproducible
        rng = np.random.default_rng(0)
        a, b = rng.integers(0, d.size, (2, HODGES_LEHMANN_SAMPLE))
        i, j = np.minimum(a, b), np.maximum(a, b)
    return float(np.median(0.5 * (d[i] + d[j])))


def rank_biserial(result: WilcoxonResult) -> float:
    """The matched-pairs rank-biserial correlation of a Wilcoxon test: (R+ - R-) / (R+ + R-), in [-1, 1].

    Its sign is the side the test leans to (positive: B - A tends to be positive); 0 without a nonzero difference.
    """
    total = result.rank_sum_plus + result.rank_sum_minus
    return (result.rank_sum_plus - result.rank_sum_minus) / total if total > 0 else 0.0


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
