"""The verdict of a comparison in words: per band and pair of controllers, who survives more and who tracks better.

Each sentence is read off the paired comparisons of a summary (`wbc.arena.report.summarize`, its ``paired``
entries) and says, for one band and one pair of controllers:

- survival: who survived more of the same trials, by how much (percentage points, with the exact interval that
  agrees with the test), on how many discordant pairs (the only ones that tell the two apart), whether the exact
  McNemar test calls it significant, and, when it does not, that the two do not differ significantly (never that
  they are alike: the interval beside it says what is left open) and how many paired trials would settle a
  difference that large (80 % power);
- time to fall: where the two fall at different times, who stays up longer (TTF, the fraction of the episode
  survived), by how much, with the Wilcoxon signed-rank test's verdict and the same count of trials;
- tracking: who tracks the commanded velocity better over the seconds both survived (the common window), by how much,
  with the Wilcoxon signed-rank test's verdict and the same count of trials.

A side is called better only where its test rejects at 0.05 and leans to it (`called_better`, which ``wbc paper``'s
verdicts use too); a sentence whose test does not reject opens by saying so. The sentences make no claim the table
beside them does not show.
"""

from __future__ import annotations

from wbc.arena.summary import SIGNIFICANCE, PairSummary, Summary, p_digits

__all__ = ["ALPHA", "LOWER_IS_BETTER", "called_better", "leans", "p_clause", "signed", "split", "verdicts"]

ALPHA = SIGNIFICANCE
"""The level a difference is called significant at."""

LOWER_IS_BETTER = frozenset({"vlin_err", "vang_err", "vlin_err_common", "vang_err_common"})
"""The metrics whose smaller value is the better one (tracking errors); success and TTF: larger is better."""

_TRACKING = (("vlin_err_common", "linear velocity", "m/s", 3), ("vang_err_common", "yaw rate", "rad/s", 3))


def _p(p: float | None) -> str:
    if p is None:
        return "n/a"
    return "< 1e-4" if p < 1e-4 else p_digits(p)


def p_clause(p: float | None) -> str:
    """A p-value as a sentence says it: ``p < 1e-4`` below 1e-4, else ``p = 0.0156`` (`p_digits`) or ``p = n/a``.

    The verdicts of the arena and of ``wbc paper`` write it so; a table's p column writes `wbc.arena.report.p_text`.
    """
    return f"p {_p(p)}" if p is not None and p < 1e-4 else f"p = {_p(p)}"


def _settle(entry: PairSummary, what: str) -> str:
    """What would settle a difference the test did not: the paired trials for 80 % power.

    Not rejecting is no evidence that the two are alike: the sentence never says there is no difference, only what
    the interval beside it allows and how many trials would tell.
    """
    if entry.n80 is None and entry.n < 2 and entry.test != "exact McNemar":
        return f"one pair shows nothing of how the differences spread: play more trials to size a {what} this large"
    if entry.n80:
        return (f"the test leaves the difference open (not rejecting is no evidence of none); about {entry.n80} "
                f"paired trials would settle a {what} this large (80 % power)")
    return ("the test leaves the difference open (not rejecting is no evidence of none); no number of paired "
            f"trials up to the search's limit would settle a {what} this small")


def leans(entry: PairSummary) -> float | None:
    """The side the paired test leans to, as the sign of B - A (0: neither); None without pairs.

    Exact McNemar: the side with more discordant pairs (the sign of the difference in success). Wilcoxon signed-rank:
    the sign of the matched-pairs rank-biserial correlation (`PairSummary.rank_biserial`), or of the Hodges-Lehmann
    shift or the mean difference in a ``summary.json`` written before they were recorded.
    """
    if entry.diff is None:
        return None
    if entry.test == "exact McNemar" or entry.metric == "success_rate":
        return entry.diff
    for side in (entry.rank_biserial, entry.shift):
        if side is not None:
            return side
    return entry.diff


def split(entry: PairSummary, *, alpha: float = ALPHA) -> bool:
    """A significant test that calls neither side better.

    Its lean is to neither, or the mean difference is on the other side (most pairs lean one way and a few large
    differences pull the mean the other).
    """
    side = leans(entry)
    if entry.p is None or not entry.p < alpha or side is None or entry.diff is None:
        return False
    return side == 0.0 or (entry.diff != 0.0 and (side > 0) != (entry.diff > 0))


def called_better(entry: PairSummary, *, higher_is_better: bool, alpha: float = ALPHA) -> str | None:
    """The controller a comparison calls better, or None where it calls neither.

    One side is called better only where the paired test rejects (p < `alpha`) and leans to it (`leans`), and the
    mean difference does not lie on the other side (`split`); a mean difference of exactly 0 follows the test.
    The arena's verdicts and ``wbc paper``'s read comparisons by this one rule.
    """
    side = leans(entry)
    if entry.p is None or not entry.p < alpha or side is None or split(entry, alpha=alpha):
        return None
    return entry.b if (side > 0) == higher_is_better else entry.a


def _significance(entry: PairSummary, test: str) -> str:
    p = entry.p
    said = p_clause(p)
    if p is not None and p < ALPHA:
        return f"significant ({test} {said})"
    return f"not significant ({test} {said})"


def _pairs(n: int) -> str:
    return f"{n} discordant pair{'' if n == 1 else 's'}"


def _survival(entry: PairSummary) -> str:
    a, b, n = entry.a, entry.b, entry.n
    sa, sb = round(entry.mean_a * n), round(entry.mean_b * n)
    a_only, b_only = entry.a_only, entry.b_only
    discordant = a_only + b_only
    lo, hi = entry.ci95
    if a_only == b_only:
        head = f"{a} and {b} survive the same number of these trials: {sa} of {n} paired trials each"
        if discordant == 0:
            return (f"{head}, with no discordant pair (95 % interval of the difference [{signed(100 * lo, 0)}, "
                    f"{signed(100 * hi, 0)}] points): these trials do not tell them apart")
        return (f"{head}; {_pairs(discordant)} split evenly ({a_only} each); "
                f"{_significance(entry, 'exact McNemar')}")
    more, fewer = (b, a) if b_only > a_only else (a, b)
    won, lost = max(a_only, b_only), min(a_only, b_only)
    s_more, s_fewer = (sb, sa) if more == b else (sa, sb)
    diff = abs(entry.diff) * 100.0
    lo_m, hi_m = (lo, hi) if more == b else (-hi, -lo)
    figures = (f"{s_more} against {s_fewer} of {n} paired trials ({diff:+.1f} points, 95 % interval "
               f"[{signed(100 * lo_m, 1)}, {signed(100 * hi_m, 1)}]); of {_pairs(discordant)} {more} alone survived "
               f"{won} and {fewer} alone {lost}; {_significance(entry, 'exact McNemar')}")
    if entry.significant:
        return f"{more} survives more than {fewer}: {figures}"
    return (f"{a} and {b} do not differ significantly in survival: {more} {figures}; "
            f"{_settle(entry, 'difference')}")


def signed(value: float, decimals: int) -> str:
    """`value` with its sign to `decimals`, as the table's cells and the verdict write it.

    A nonzero value too small for the decimals is in scientific notation (``-1.2e-04``), never a ``-0.000`` that a
    significant test would call better.
    """
    if value == 0.0:
        value = 0.0  # a negated zero (the lower bound of [-0.0, ...]) is written +0.000
    elif abs(value) < 0.5 * 10.0 ** -decimals:
        return f"{value:+.1e}"
    return f"{value:+.{decimals}f}"


def _mean_difference(entry: PairSummary, head: str, what: str, unit: str, decimals: int, *,
                     higher_is_better: bool, subject: str) -> str:
    """The sentence of a difference of means read off `entry`: the side the test calls better first, or none.

    `head` is the claim with ``{better}`` and ``{worse}`` in it, said only where the test rejects and leans to that
    side (`called_better`; a mean difference of exactly 0 follows the test's lean); `what` names the means (``mean
    error``) and `unit` their unit (empty for a share); the better side has the higher mean when `higher_is_better`,
    else the lower. A difference too small for the decimals is written in scientific notation, never as a -0.000
    called better.

    A significant test whose side (the sign of its rank-biserial correlation, `PairSummary.rank_biserial`) is not
    the mean's calls neither better: most pairs lean one way and a few large differences pull the mean the other
    (`_split`, which names the `subject` compared). A test that does not reject opens with that, ``{a} and {b} do
    not differ significantly in {subject}``, and says what the interval leaves open (`_settle`).
    """
    if split(entry):
        return _split(entry, leans(entry), subject, unit, decimals, higher_is_better=higher_is_better)
    better = called_better(entry, higher_is_better=higher_is_better)
    b_first = better == entry.b if better is not None else (entry.diff > 0) == higher_is_better
    first, second = (entry.b, entry.a) if b_first else (entry.a, entry.b)
    m_first, m_second = (entry.mean_b, entry.mean_a) if b_first else (entry.mean_a, entry.mean_b)
    lo, hi = entry.ci95
    lo_f, hi_f = (lo, hi) if b_first else (-hi, -lo)
    unit = f" {unit}" if unit else ""
    figures = (f"{what} {m_first:.{decimals}f} against {m_second:.{decimals}f}{unit} on {entry.n} trials (difference "
               f"{signed(m_first - m_second, decimals)}, 95 % bootstrap interval [{signed(lo_f, decimals)}, "
               f"{signed(hi_f, decimals)}]); {_significance(entry, 'Wilcoxon signed-rank')}")
    if better is not None:
        return f"{head.format(better=first, worse=second)}: {figures}"
    return (f"{entry.a} and {entry.b} do not differ significantly in {subject}: {first} {figures}; "
            f"{_settle(entry, 'difference')}")


def _split(entry: PairSummary, side: float, subject: str, unit: str, decimals: int, *,
           higher_is_better: bool) -> str:
    """A significant Wilcoxon test that leans to `side` (its sign), the mean difference to the other: neither wins."""
    unit = f" {unit}" if unit else ""
    if not side:
        lean = "the pairs' ranks lean to neither"
    else:
        favoured = entry.b if (side > 0) == higher_is_better else entry.a
        figures = [f"rank-biserial r = {entry.rank_biserial:+.2f}"] if entry.rank_biserial is not None else []
        if entry.shift is not None:
            figures.append(f"Hodges-Lehmann shift {signed(entry.shift, decimals)}{unit}")
        lean = f"the pairs' ranks favour {favoured} ({', '.join(figures)})"
    by_mean = entry.b if (entry.diff > 0) == higher_is_better else entry.a
    return (f"{entry.a} and {entry.b} differ in {subject}, but not one way: {lean}, while the mean difference "
            f"({signed(entry.diff, decimals)}{unit} on {entry.n} trials, B - A with B = {entry.b}) favours {by_mean} "
            f"through a few large differences; {_significance(entry, 'Wilcoxon signed-rank')}: neither is called "
            "better")


def _tracking(entry: PairSummary, what: str, unit: str, decimals: int) -> str | None:
    if not entry.n or entry.diff is None:
        return None
    subject = f"how they track the {what} over the seconds both survived"
    if entry.diff == 0.0 and not entry.significant:
        return (f"{entry.a} and {entry.b} have the same mean error in the {what} over the seconds both survived "
                f"({entry.n} trials); {_significance(entry, 'Wilcoxon signed-rank')}")
    return _mean_difference(entry, f"{{better}} tracks the {what} better than {{worse}} over the seconds both survived",
                            "mean error", unit, decimals, higher_is_better=False, subject=subject)


def _time_to_fall(entry: PairSummary) -> str | None:
    """Who stays up longer, or None where the mean times are the same and the test does not reject (nothing to say)."""
    if not entry.n or entry.diff is None or (entry.diff == 0.0 and not entry.significant):
        return None
    return _mean_difference(entry, "{better} stays up longer than {worse}",
                            "mean TTF (the share of the episode survived)", "", 3, higher_is_better=True,
                            subject="how long they stay up (TTF)")


def verdicts(summary: Summary) -> list[str]:
    """The verdict sentences of a summary, band by band, pair by pair (none for a run of one controller).

    Args:
        summary: the output of `wbc.arena.report.summarize` (or `Summary.from_json` of a ``summary.json``).

    Returns:
        One line per sentence, each starting with its band: ``band in: mpc survives more than stand: ...``.
    """
    lines: list[str] = []
    for entry in summary.paired:
        if entry.n == 0 or entry.mean_a is None:
            continue
        prefix = f"band {entry.band}: "
        if entry.metric == "success_rate":
            lines.append(prefix + _survival(entry))
        if entry.metric == "ttf" and (sentence := _time_to_fall(entry)) is not None:
            lines.append(prefix + sentence)
        for metric, what, unit, decimals in _TRACKING:
            if entry.metric == metric:
                sentence = _tracking(entry, what, unit, decimals)
                if sentence is not None:
                    lines.append(prefix + sentence)
    return lines
