"""Holm's correction of a family of p-values: what a verdict weighing many paired tests may call significant.

A run's verdict weighs every paired test of its paired-differences table (each pair of controllers, band and metric:
`wbc.arena.summary.Summary.paired`). Each test rejects at 0.05 on its own, so among m tests of controllers that do not
differ about 0.05 m reject by chance: 7 equal controllers give 21 pairs, and most runs of them would call one of the
pairs better. Holm's step-down correction keeps the chance of any false rejection in the family at most alpha, with
no assumption about how the tests depend on each other (they share trials and controllers).

With the m p-values sorted, p_(1) <= ... <= p_(m), the Holm-adjusted p-values are

    p~_(k) = min(1, max_{j <= k} (m - j + 1) p_(j)),

and a test holds after the correction at level alpha exactly when p~ < alpha (the same numbers as statsmodels'
``multipletests(method="holm")``, which the tests check; `holm_adjusted`).

The arena's tests are exact and discrete, and many cannot reject at all: a McNemar test on d discordant pairs cannot
give a two-sided p below 2 (1/2)^d, nor a Wilcoxon signed-rank test on n nonzero differences one below 2 (1/2)^n
(every sign the same; ties do not change it), so a test on 0 to 5 of them has p >= 0.05 whatever the outcome
(`smallest_attainable_p`). Counting such a test in m multiplies every other test's p for nothing. Tarone's
refinement (R. E. Tarone, "A modified Bonferroni method for discrete data", Biometrics 46(2):515-522, 1990; for
Holm's step-down, G. Hommel and T. Krummenauer, "Improvements and modifications of Tarone's multiple test
procedure for discrete data", Biometrics 54(2):673-681, 1998) leaves them out: the smallest attainable p of each
test is fixed by its discordant pairs or nonzero differences, on which the exact tests are conditional, so a test
whose smallest attainable p is >= alpha can never reject and can never be a false rejection; Holm's correction over
the others keeps the chance of any false rejection at most alpha (`tarone_holm_adjusted`). This is the first step of
Hommel and Krummenauer's procedure (leave out what cannot reach alpha); their further steps, which also leave out
tests that cannot reach alpha / k at Holm's k-th step, are not taken, so the correction is at least as strict as
theirs.
"""

from __future__ import annotations

from collections.abc import Sequence

from wbc.errors import ConfigError

__all__ = ["holm_adjusted", "smallest_attainable_p", "tarone_holm_adjusted"]


def holm_adjusted(p_values: Sequence[float | None]) -> list[float | None]:
    """The Holm-adjusted p-values of a family, in the order given; None where a p-value is None (no test).

    The family is the tests with a p-value: a None is no test (no pair played) and does not count in m.

    Args:
        p_values: each test's own two-sided p-value, in [0, 1], or None.

    Returns:
        Each test's adjusted p-value, >= its own, in [0, 1].
    """
    tested = sorted((p, i) for i, p in enumerate(p_values) if p is not None)
    m = len(tested)
    adjusted: list[float | None] = [None] * len(p_values)
    running = 0.0
    for rank, (p, i) in enumerate(tested):
        running = max(running, min(1.0, (m - rank) * p))
        adjusted[i] = running
    return adjusted


def smallest_attainable_p(informative: int) -> float:
    """The smallest two-sided p an exact sign test can give on `informative` pairs: min(1, 2 (1/2)^informative).

    The informative pairs are the discordant ones of an exact McNemar test (its p is the binomial test's on them,
    `wbc.arena.paired_tests.mcnemar_exact`) and the nonzero differences of the exact Wilcoxon signed-rank test (its
    p is smallest when every sign is the same: 2 of the 2^n equally likely sign patterns, whatever the ties,
    `wbc.arena.paired_tests.wilcoxon_signed_rank`). Beyond 200 nonzero differences that test uses the normal
    approximation, whose smallest p lies far below any level a verdict uses, as this one does.

    Args:
        informative: discordant pairs or nonzero differences, >= 0.

    Returns:
        1.0 for 0 or 1 of them, else 2 / 2^informative.
    """
    return min(1.0, 2.0 * 0.5 ** max(0, informative))


def tarone_holm_adjusted(p_values: Sequence[float | None], smallest_p: Sequence[float | None], *,
                         alpha: float = 0.05) -> tuple[list[float | None], list[bool]]:
    """Holm's correction with Tarone's refinement: over the tests that can reach `alpha`, in the order given.

    A test whose smallest attainable p (`smallest_attainable_p`) is >= `alpha` is left out of the family: it does not
    count in m, and its adjusted p is its own p (>= `alpha` by construction, so it never holds). Holm's correction
    (`holm_adjusted`) runs over the rest. Where no test is left out this is Holm's correction exactly. The adjusted
    p-values are for the level `alpha` the family was chosen at: a test holds when its adjusted p < `alpha`.

    Args:
        p_values: each test's own two-sided p-value, or None (no test: in no family).
        smallest_p: each test's smallest attainable p; None where unknown (the test stays in the family).
        alpha: the family-wise level.

    Returns:
        (adjusted p-values, None where p is None; whether each test is in the family Holm's correction runs over).

    Raises:
        ConfigError: the two sequences differ in length.
    """
    if len(p_values) != len(smallest_p):
        raise ConfigError(f"tarone_holm_adjusted: {len(p_values)} p-values against {len(smallest_p)} smallest p-values;"
                         " give one of each per test")
    member = [p is not None and (s is None or s < alpha) for p, s in zip(p_values, smallest_p, strict=True)]
    adjusted = holm_adjusted([p if keep else None for p, keep in zip(p_values, member, strict=True)])
    return [a if keep else p for a, p, keep in zip(adjusted, p_values, member, strict=True)], member
