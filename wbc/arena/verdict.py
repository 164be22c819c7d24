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

from wbc.arena.summary import PairSummary, Summary

__all__ = ["ALPHA", "signed", "verdicts"]

ALPHA = 0.05
"""The level a difference is called significant at."""

_PRACTICAL = 1000
"""Beyond this many paired trials to settle it, a difference is called too small to matter in practice."""

_TRACKING = (("vlin_err_common", "linear velocity", "m/s", 3), ("vang_err_common", "yaw rate", "rad/s", 3))


def _p(p: float | None) -> str:
    if p is None:
        return "n/a"
    return "< 1e-4" if p < 1e-4 else f"{p:.3g}"


def _settle(entry: PairSummary, what: str) -> str:
    """What would settle a difference the test did not: the paired trials for 80 % power."""
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
            f"95 % interval [{100 * lo_w:+.1f}, {100 * hi_w:+.1f}]); of {_pairs(discordant)} {winner} alone "
            f"survived {won} and {loser} alone {lost}; {_significance(entry, 'exact McNemar')}")
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


def _tracking(entry: PairSummary, what: str, unit: str, decimals: int) -> str | None:
    a, b, n = entry.a, entry.b, entry.n
    if not n or entry.diff is None:
        return None
    ma, mb = entry.mean_a, entry.mean_b
    lo, hi = entry.ci95
    if entry.diff == 0.0:
        return f"{a} and {b} track the {what} alike over the seconds both survived ({n} trials)"
    better, worse = (b, a) if entry.diff < 0 else (a, b)
    m_better, m_worse = (mb, ma) if better == b else (ma, mb)
    lo_b, hi_b = (lo, hi) if better == b else (-hi, -lo)
    # a difference too small for the decimals is written in scientific notation, never as a -0.000 called better
    text = (f"{better} tracks the {what} better than {worse} over the seconds both survived: mean error "
            f"{m_better:.{decimals}f} against {m_worse:.{decimals}f} {unit} on {n} trials (difference "
            f"{signed(m_better - m_worse, decimals)}, 95 % bootstrap interval "
            f"[{signed(lo_b, decimals)}, {signed(hi_b, decimals)}]); "
            f"{_significance(entry, 'Wilcoxon signed-rank')}")
    if not (entry.p is not None and entry.p < ALPHA):
        text += f"; {_settle(entry, 'difference')}"
    return text


def _time_to_fall(entry: PairSummary) -> str | None:
    """Who stays up longer, or None where the two survive the same share of every episode (nothing to say)."""
    a, b, n = entry.a, entry.b, entry.n
    if not n or entry.diff is None or entry.diff == 0.0:
        return None
    longer, shorter = (b, a) if entry.diff > 0 else (a, b)
    m_longer, m_shorter = (entry.mean_b, entry.mean_a) if longer == b else (entry.mean_a, entry.mean_b)
    lo, hi = entry.ci95
    lo_l, hi_l = (lo, hi) if longer == b else (-hi, -lo)
    text = (f"{longer} stays up longer than {shorter}: mean TTF (the share of the episode survived) "
            f"{m_longer:.3f} against {m_shorter:.3f} on {n} trials (difference {signed(m_longer - m_shorter, 3)}, "
            f"95 % bootstrap interval [{signed(lo_l, 3)}, {signed(hi_l, 3)}]); "
            f"{_significance(entry, 'Wilcoxon signed-rank')}")
    if not (entry.p is not None and entry.p < ALPHA):
        text += f"; {_settle(entry, 'difference')}"
    return text


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
