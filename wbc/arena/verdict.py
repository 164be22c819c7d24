"""The verdict of a comparison in words: per band and pair of controllers, who survives more and who tracks better.

Each sentence is read off the paired comparisons of a summary (`wbc.arena.report.summarize`, its ``paired``
entries) and says, for one band and one pair of controllers:

- survival: who survived more of the same trials, by how much (percentage points, with the exact interval that
  agrees with the test), on how many discordant pairs (the only ones that tell the two apart), whether the exact
  McNemar test calls it significant, and, when it does not, how many paired trials would settle a difference that
  large (80 % power);
- time to fall: where the two fall at different times, who stays up longer (TTF, the fraction of the episode
  survived), by how much, with the Wilcoxon signed-rank test's verdict and the same count of trials;
- tracking: who tracks the commanded velocity better over the seconds both survived (the common window), by how much,
  with the Wilcoxon signed-rank test's verdict and the same count of trials.

The significance level is that of the paired tests' power figures (0.05); the sentences make no claim the table
beside them does not show.
"""

from __future__ import annotations

from wbc.arena.summary import SIGNIFICANCE, PairSummary, Summary, p_digits

__all__ = ["ALPHA", "signed", "verdicts"]

ALPHA = SIGNIFICANCE
"""The level a difference is called significant at."""

_PRACTICAL = 1000
"""Beyond this many paired trials to settle it, a difference is called too small to matter in practice."""

_TRACKING = (("vlin_err_common", "linear velocity", "m/s", 3), ("vang_err_common", "yaw rate", "rad/s", 3))


def _p(p: float | None) -> str:
    if p is None:
        return "n/a"
    return "< 1e-4" if p < 1e-4 else p_digits(p)


def _settle(entry: PairSummary, what: str) -> str:
    """What would settle a difference the test did not: the paired trials for 80 % power."""
    if entry.n80 is None and entry.n < 2 and entry.test != "exact McNemar":
        return f"one pair shows nothing of how the differences spread: play more trials to size a {what} this large"
    if entry.n80 and entry.n80 > _PRACTICAL:
        return (f"a {what} this small would take about {entry.n80} paired trials to settle (80 % power): for "
                "practical purposes there is none")
    if entry.n80:
        return f"about {entry.n80} paired trials would settle a {what} this large (80 % power)"
    return f"no number of paired trials up to the search's limit would settle a {what} this small"


def _significance(entry: PairSummary, test: str) -> str:
    p = entry.p
    said = f"p {_p(p)}" if p is not None and p < 1e-4 else f"p = {_p(p)}"
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
        head = f"{a} and {b} survive alike: {sa} of {n} paired trials each"
        if discordant == 0:
            return (f"{head}, with no discordant pair (95 % interval of the difference [{100 * lo:+.0f}, "
                    f"{100 * hi:+.0f}] points): these trials do not tell them apart")
        return (f"{head}; {_pairs(discordant)} split evenly ({a_only} each); "
                f"{_significance(entry, 'exact McNemar')}")
    winner, loser = (b, a) if b_only > a_only else (a, b)
    won, lost = max(a_only, b_only), min(a_only, b_only)
    s_win, s_lose = (sb, sa) if winner == b else (sa, sb)
    diff = abs(entry.diff) * 100.0
    lo_w, hi_w = (lo, hi) if winner == b else (-hi, -lo)
    text = (f"{winner} survives more than {loser}: {s_win} against {s_lose} of {n} paired trials ({diff:+.1f} points, "
            f"95 % interval [{signed(100 * lo_w, 1)}, {signed(100 * hi_w, 1)}]); of {_pairs(discordant)} {winner} "
            f"alone survived {won} and {loser} alone {lost}; {_significance(entry, 'exact McNemar')}")
    if not (entry.p is not None and entry.p < ALPHA):
        text += f"; {_settle(entry, 'difference')}"
    return text


def signed(value: float, decimals: int) -> str:
    """`value` with its sign to `decimals`, as the table's cells and the verdict write it.

    A nonzero value too small for the decimals is in scientific notation (``-1.2e-04``), never a ``-0.000`` that a
    significant test would call better.
    """
    if value != 0.0 and abs(value) < 0.5 * 10.0 ** -decimals:
        return f"{value:+.1e}"
    return f"{value:+.{decimals}f}"


def _mean_difference(entry: PairSummary, head: str, what: str, unit: str, decimals: int, *,
                     higher_is_better: bool, subject: str) -> str:
    """The sentence of a difference of means read off `entry`: the better side first, its interval and test.

    `head` is the claim with ``{better}`` and ``{worse}`` in it; `what` names the means (``mean error``) and `unit`
    their unit (empty for a share); the better side has the higher mean when `higher_is_better`, else the lower. A
    difference too small for the decimals is written in scientific notation, never as a -0.000 called better.

    A significant test whose side (the sign of its rank-biserial correlation, `PairSummary.rank_biserial`) is not
    the mean's calls neither better: most pairs lean one way and a few large differences pull the mean the other
    (`_split`, which names the `subject` compared).
    """
    b_better = (entry.diff > 0) == higher_is_better
    lean = entry.rank_biserial if entry.rank_biserial is not None else entry.shift  # a summary.json of before
    if entry.p is not None and entry.p < ALPHA and lean is not None and (lean == 0.0 or (lean > 0) != (entry.diff > 0)):
        return _split(entry, lean, subject, unit, decimals, higher_is_better=higher_is_better)
    better, worse = (entry.b, entry.a) if b_better else (entry.a, entry.b)
    m_better, m_worse = (entry.mean_b, entry.mean_a) if b_better else (entry.mean_a, entry.mean_b)
    lo, hi = entry.ci95
    lo_b, hi_b = (lo, hi) if b_better else (-hi, -lo)
    unit = f" {unit}" if unit else ""
    text = (f"{head.format(better=better, worse=worse)}: {what} {m_better:.{decimals}f} against "
            f"{m_worse:.{decimals}f}{unit} on {entry.n} trials (difference {signed(m_better - m_worse, decimals)}, "
            f"95 % bootstrap interval [{signed(lo_b, decimals)}, {signed(hi_b, decimals)}]); "
            f"{_significance(entry, 'Wilcoxon signed-rank')}")
    if not (entry.p is not None and entry.p < ALPHA):
        text += f"; {_settle(entry, 'difference')}"
    return text


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
    if entry.diff == 0.0:
        return f"{entry.a} and {entry.b} track the {what} alike over the seconds both survived ({entry.n} trials)"
    return _mean_difference(entry, f"{{better}} tracks the {what} better than {{worse}} over the seconds both survived",
                            "mean error", unit, decimals, higher_is_better=False,
                            subject=f"how they track the {what} over the seconds both survived")


def _time_to_fall(entry: PairSummary) -> str | None:
    """Who stays up longer, or None where the two survive the same share of every episode (nothing to say)."""
    if not entry.n or entry.diff is None or entry.diff == 0.0:
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
