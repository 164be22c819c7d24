"""Holm's correction of a family of p-values: what a verdict weighing many paired tests may call significant.

A run's verdict weighs every paired test of its paired-differences table (each pair of controllers, band and metric:
`wbc.arena.summary.Summary.paired`). Each test rejects at 0.05 on its own, so among m tests of controllers that do not
differ about 0.05 m reject by chance: 7 equal controllers give 21 pairs, and most runs of them would call one of the
pairs better. Holm's step-down correction keeps the chance of any false rejection in the family at most alpha, with
no assumption about how the tests depend on each other (they share trials and controllers).

With the m p-values sorted, p_(1) <= ... <= p_(m), the Holm-adjusted p-values are

    p~_(k) = min(1, max_{j <= k} (m - j + 1) p_(j)),

and a test holds after the correction at level alpha exactly when p~ < alpha (the same numbers as statsmodels'
``multipletests(method="holm")``, which the tests check).
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["holm_adjusted"]


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
