"""How many paired trials a comparison needs: the power of the arena's paired tests, and the trials for 80 %.

A comparison that finds no significant difference says little unless it also says how many trials would have found
one. Each paired comparison prints that number (``n80``: pairs for 80 % power at alpha = 0.05) for the difference it
observed, computed from what the run measured:

- success (exact McNemar, `wbc.arena.paired_tests`): the pairs fall into "A only succeeded" with probability p_a,
  "B only succeeded" with p_b, and concordant. With n pairs, the discordant count D ~ Binomial(n, p_a + p_b) and,
  given D = d, B's wins X ~ Binomial(d, p_b / (p_a + p_b)). The exact test rejects when min(X, d - X) <= c_d, the
  largest c with 2 P(Binomial(d, 1/2) <= c) <= alpha. So its power is exactly

      power(n) = sum_d P(D = d) [P(X <= c_d | d) + P(X >= d - c_d | d)],

  evaluated here without approximation (`mcnemar_power`); p_a and p_b are the observed discordance rates. The exact
  power rises with n in small saw-teeth, so `pairs_for_mcnemar` returns the n found by bisection, at which power is
  at least the target: a few smaller n may reach it too.
- continuous metrics (Wilcoxon signed-rank): the paired t-test's n for the observed mean difference and standard
  deviation of the differences (exact, from the noncentral t distribution), divided by the Wilcoxon test's
  asymptotic relative efficiency for normal differences, 3 / pi (`pairs_for_mean_difference`). An approximation:
  for differences with heavier tails than normal the Wilcoxon test needs fewer pairs than this. The exact Wilcoxon
  test cannot reject at alpha = 0.05 with fewer than 6 nonzero differences (2 / 2^5 > 0.05), the floor returned.

Both are planning figures for the *observed* difference: with the arena's small runs the observed difference is
itself uncertain, and so is n80.
"""

from __future__ import annotations

import math

import numpy as np

from wbc.errors import ConfigError

__all__ = ["N_MAX", "WILCOXON_ARE", "mcnemar_power", "pairs_for_mcnemar", "pairs_for_mean_difference",
           "t_test_power"]

N_MAX = 100_000
"""The largest number of pairs searched; a difference that needs more is reported as needing more than this."""

WILCOXON_ARE = 3.0 / math.pi
"""Asymptotic relative efficiency of the Wilcoxon signed-rank test to the t-test for normal differences (~0.955)."""

_TAIL = 1e-12  # probability mass of the discordant count left out of the power sum, on each side


def _check(alpha: float, power: float | None = None) -> None:
    if not 0.0 < alpha < 1.0:
        raise ConfigError(f"alpha must be in (0, 1), got {alpha}; pass a significance level such as 0.05")
    if power is not None and not 0.0 < power < 1.0:
        raise ConfigError(f"power must be in (0, 1), got {power}; pass a target such as 0.8")


def _critical_counts(d: np.ndarray, alpha: float) -> np.ndarray:
    """Per discordant count d: the largest c with 2 P(Binomial(d, 1/2) <= c) <= alpha, or -1 when none."""
    from scipy.stats import binom  # scipy.stats takes about a second to import: only when power is computed

    c = binom.ppf(alpha / 2.0, d, 0.5)  # the smallest c with P(<= c) >= alpha / 2
    c = np.where(binom.cdf(c, d, 0.5) > alpha / 2.0 * (1.0 + 1e-12), c - 1.0, c)
    return np.where(d > 0, c, -1.0)


def mcnemar_power(n: int, p_a_only: float, p_b_only: float, *, alpha: float = 0.05) -> float:
    """Exact power of the two-sided exact McNemar test with n pairs (see the module docstring).

    Args:
        n: pairs, >= 0.
        p_a_only: probability that a pair is "A succeeded, B failed".
        p_b_only: probability that a pair is "B succeeded, A failed"; p_a_only + p_b_only <= 1.
        alpha: significance level.

    Returns:
        The probability that the test rejects H0 (equal success probabilities).

    Raises:
        ConfigError: probabilities or alpha out of range.
    """
    _check(alpha)
    if not (0.0 <= p_a_only <= 1.0 and 0.0 <= p_b_only <= 1.0 and p_a_only + p_b_only <= 1.0 + 1e-12):
        raise ConfigError(f"mcnemar_power: discordance probabilities must be >= 0 and sum to <= 1, got {p_a_only} and "
                          f"{p_b_only}")
    psi = p_a_only + p_b_only
    if n <= 0 or psi <= 0.0:
        return 0.0
    from scipy.stats import binom

    lo = int(binom.ppf(_TAIL, n, psi)) if psi < 1.0 else n
    hi = int(binom.isf(_TAIL, n, psi)) if psi < 1.0 else n
    d = np.arange(max(0, lo - 1), min(n, hi + 1) + 1, dtype=float)
    weight = binom.pmf(d, n, psi) if psi < 1.0 else (d == n).astype(float)
    c = _critical_counts(d, alpha)
    q = p_b_only / psi
    reject = binom.cdf(c, d, q) + binom.sf(d - c - 1.0, d, q)
    reject = np.where(c >= 0, reject, 0.0)
    return float(np.clip(np.sum(weight * reject), 0.0, 1.0))


def _bisect(reaches, n_lo: int) -> int | None:
    """The smallest n >= n_lo with reaches(n), searched by doubling then bisection; None beyond `N_MAX`."""
    if reaches(n_lo):
        return n_lo
    lo, hi = n_lo, n_lo
    while not reaches(hi):
        if hi >= N_MAX:
            return None
        lo, hi = hi, min(N_MAX, 2 * hi)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if reaches(mid):
            hi = mid
        else:
            lo = mid
    return hi


def pairs_for_mcnemar(p_a_only: float, p_b_only: float, *, alpha: float = 0.05, power: float = 0.8) -> int | None:
    """Pairs the exact McNemar test needs to detect a success difference with the given discordance, at `power`.

    Args:
        p_a_only: probability of "A succeeded, B failed" (the observed fraction of such pairs).
        p_b_only: probability of "B succeeded, A failed".
        alpha: significance level.
        power: target power.

    Returns:
        The number of pairs; None when there is nothing to detect (p_a_only == p_b_only) or it exceeds `N_MAX`.

    Raises:
        ConfigError: probabilities, alpha or power out of range.
    """
    _check(alpha, power)
    if p_a_only == p_b_only:
        return None
    return _bisect(lambda n: mcnemar_power(n, p_a_only, p_b_only, alpha=alpha) >= power, 1)


def t_test_power(n: int, effect: float, *, alpha: float = 0.05) -> float:
    """Power of the two-sided one-sample (paired) t-test with n pairs for standardised effect `effect` = mean / sd.

    With t_c the (1 - alpha / 2) quantile of Student's t with n - 1 degrees of freedom and the noncentrality
    effect * sqrt(n): power = P(|T| > t_c) for T noncentral t.

    Raises:
        ConfigError: alpha out of range.
    """
    _check(alpha)
    if n < 2:
        return 0.0
    from scipy.stats import nct, t

    crit = t.ppf(1.0 - alpha / 2.0, n - 1)
    nc = effect * math.sqrt(n)
    return float(nct.sf(crit, n - 1, nc) + nct.cdf(-crit, n - 1, nc))


def pairs_for_mean_difference(mean_diff: float, sd_diff: float, *, alpha: float = 0.05,
                              power: float = 0.8) -> int | None:
    """Pairs the Wilcoxon signed-rank test needs to detect a mean paired difference, at `power` (approximate).

    The paired t-test's exact n for effect mean_diff / sd_diff, divided by `WILCOXON_ARE` and rounded up; at least
    the smallest n at which the exact Wilcoxon test can reject at all (6 at alpha = 0.05). When sd_diff is 0 every
    pair shows the same nonzero difference and that smallest n is the answer.

    Args:
        mean_diff: the mean of the differences B - A.
        sd_diff: their standard deviation (ddof = 1), >= 0.
        alpha: significance level.
        power: target power.

    Returns:
        The number of pairs; None when mean_diff is 0 (nothing to detect) or the answer exceeds `N_MAX`.

    Raises:
        ConfigError: sd_diff < 0 or not finite, or alpha or power out of range.
    """
    _check(alpha, power)
    if not (math.isfinite(sd_diff) and sd_diff >= 0.0) or not math.isfinite(mean_diff):
        raise ConfigError(f"pairs_for_mean_difference: need a finite mean and sd >= 0, got {mean_diff} and {sd_diff}")
    if mean_diff == 0.0:
        return None
    floor = max(1, math.ceil(math.log2(2.0 / alpha)))  # exact Wilcoxon: the smallest p is 2 / 2^n
    if sd_diff == 0.0:
        return floor
    effect = abs(mean_diff) / sd_diff
    n_t = _bisect(lambda n: t_test_power(n, effect, alpha=alpha) >= power, 2)
    if n_t is None:
        return None
    n_w = max(floor, math.ceil(n_t / WILCOXON_ARE))
    return n_w if n_w <= N_MAX else None
