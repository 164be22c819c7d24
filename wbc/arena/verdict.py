"""The verdict of a comparison in words: per band and pair of controllers, who survives more and who tracks better.

Each sentence is read off the paired comparisons of a summary (`wbc.arena.report.summarize`, its ``paired``
entries) and says, for one band and one pair of controllers:

- survival: who survived more of the same trials, by how much (percentage points, with the exact interval that
  agrees with the test), on how many discordant pairs (the only ones that tell the two apart), whether the exact
  McNemar test calls it significant, and, when it does not, that the two do not differ significantly (never that
  they are alike: the interval beside it says what is left open) and how many paired trials would settle a
  difference that large (80 % power), on its own test (at 0.05) and after Holm's correction whatever the other tests
  show (at 0.05 / m, the level of the correction's first step: `PairSummary.n80_holm`);
- time to fall: where the two fall at different times, who stays up longer (TTF, the fraction of the episode
  survived), by how much, with the Wilcoxon signed-rank test's verdict and the same count of trials;
- tracking: who tracks the commanded velocity better over the seconds both survived (the common window), by how much,
  with the Wilcoxon signed-rank test's verdict and the same count of trials.

A side is called better only where its test rejects at 0.05 and leans to it (`called_better`, which ``wbc paper``'s
verdicts use too); a sentence whose test does not reject opens by saying so. A difference is written with its sides
named, the first the sentence names minus the other (``h14 - mpc = -0.012 m/s``, its interval in the same
orientation), as ``wbc paper``'s verdicts write it; the table beside it gives B - A. The sentences make no claim the
table does not show.

A run's verdict weighs many tests at once (every pair of controllers, band and metric of the paired-differences
table), and among many tests of controllers that do not differ some reject by chance. Each test keeps its own p; the
verdict also corrects by Holm's method over the tests that can reach p < 0.05 on their pairs (Tarone's refinement,
`wbc.arena.multiplicity`: a test on no or too few discordant pairs or nonzero differences cannot, and is left out).
Its first line (`count_line`) says how many tests it weighs, how many it leaves out, how many reject on their own
and after the correction, and that the correction's bound covers the claims that hold after it only; a sentence
whose test rejects says whether it holds after the correction; one that holds only on its own test says so in its
claim.

Trials that ended in a controller error are not falls. By the arena's documented policy they count as failures in
the success rate (and the McNemar test on it), and their TTF is the share played before the error; the verdict says
so beside the survival and TTF sentences where a side had such trials, and where every trial of a side ended so it
gives no verdict on survival or time to fall for that pair and band.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from wbc.arena.multiplicity import tarone_holm_adjusted
from wbc.arena.summary import SIGNIFICANCE, PairSummary, Summary, p_digits
from wbc.arena.trial_record import CONTROLLER_ERROR

__all__ = ["ALPHA", "LOWER_IS_BETTER", "called_better", "count_line", "holm_family", "in_family", "leans",
           "p_clause", "robots_caveat", "signed", "split", "verdicts"]

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


def _settle(entry: PairSummary, what: str, m: int) -> str:
    """What would settle a difference the test did not: the paired trials for 80 % power, alone and under Holm.

    `n80` is at `ALPHA`, for the test on its own; `n80_holm` at `ALPHA` / m, m every test weighed (`_holm_tests`):
    at most the level of Holm's first, strictest step, which a test that reaches holds after the correction whatever
    the other tests show (where others hold too, fewer may do). Not rejecting is no evidence that
    the two are alike: the sentence never says there is no difference, only what the interval beside it allows and
    how many trials would tell.
    """
    if entry.n80 is None and entry.n < 2 and entry.test != "exact McNemar":
        return f"one pair shows nothing of how the differences spread: play more trials to size a {what} this large"
    if entry.n80:
        return (f"the test leaves the difference open (not rejecting is no evidence of none); about {entry.n80} "
                f"paired trials would settle a {what} this large on its own test (80 % power at {ALPHA:g})"
                f"{_under_holm(entry, m)}")
    return ("the test leaves the difference open (not rejecting is no evidence of none); no number of paired "
            f"trials up to the search's limit would settle a {what} this small")


def _under_holm(entry: PairSummary, m: int) -> str:
    """The clause on the trials a difference needs to hold after Holm's correction (`PairSummary.n80_holm`)."""
    m_with = _holm_tests(entry, m)
    if m_with < 2 or entry.n80 is None or not entry.n80_holm_recorded:  # not recorded: nothing to say of it
        return ""
    level = (f"{ALPHA:g}/{m_with}, {m_with} the tests this verdict weighs: at most the level of the correction's "
             "first step")
    if entry.n80_holm is None:
        return (", and no number up to the search's limit would let it hold after Holm's correction whatever the "
                f"others show (at {level})")
    return (f", and about {entry.n80_holm} would let it hold after Holm's correction whatever the others show (80 % "
            f"power at {level})")


def _holm_tests(entry: PairSummary, m: int) -> int:
    """The m of `entry`'s ``n80_holm`` level: `PairSummary.n80_holm_tests`, every test weighed.

    From a ``summary.json`` written before it was recorded, the family a test would be corrected in: the `m` tests of
    the verdict's, with this one in it.
    """
    if entry.n80_holm_tests is not None:
        return entry.n80_holm_tests
    return m if in_family(entry) else m + 1


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


def _tests(m: int) -> str:
    """The family Holm's correction runs over, as a sentence names it (`count_line` says which tests it leaves out)."""
    return (f"the {m} tests of this verdict that can reach p < {ALPHA:g}" if m != 1 else
            f"the 1 test of this verdict that can reach p < {ALPHA:g}")


def _holds(entry: PairSummary) -> bool:
    """The test rejects after Holm's correction over the verdict's family (`PairSummary.p_holm`)."""
    return entry.p_holm is not None and entry.p_holm < ALPHA


def _significance(entry: PairSummary, test: str, m: int) -> str:
    """Whether `entry`'s test rejects, on its own and, where it does, after Holm's correction over the `m` tests."""
    p = entry.p
    said = p_clause(p)
    if p is None or not p < ALPHA:
        return f"not significant ({test} {said})"
    adjusted = "Holm-adjusted " + p_clause(entry.p_holm)
    if _holds(entry):
        return f"significant ({test} {said}), and after Holm's correction over {_tests(m)} ({adjusted})"
    need = ("" if entry.n80_holm is None else
            f"; about {entry.n80_holm} paired trials would let a difference this large hold after it whatever the "
            f"others show (80 % power at {ALPHA:g}/{_holm_tests(entry, m)})")
    return (f"significant on its own ({test} {said}), not significant after Holm's correction over {_tests(m)} "
            f"({adjusted}){need}")


_OWN_TEST_ONLY = " (on its own test only, not after Holm's correction)"
"""Added to a claim that a side is better where its test rejects alone and not after the correction."""


def _pairs(n: int) -> str:
    return f"{n} discordant pair{'' if n == 1 else 's'}"


def _survival(entry: PairSummary, m: int) -> str:
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
                f"{_significance(entry, 'exact McNemar', m)}")
    more, fewer = (b, a) if b_only > a_only else (a, b)
    won, lost = max(a_only, b_only), min(a_only, b_only)
    s_more, s_fewer = (sb, sa) if more == b else (sa, sb)
    diff = abs(entry.diff) * 100.0
    lo_m, hi_m = (lo, hi) if more == b else (-hi, -lo)
    figures = (f"{s_more} against {s_fewer} of {n} paired trials ({more} - {fewer} = {diff:+.1f} points, 95 % interval "
               f"[{signed(100 * lo_m, 1)}, {signed(100 * hi_m, 1)}]); of {_pairs(discordant)} {more} alone survived "
               f"{won} and {fewer} alone {lost}; {_significance(entry, 'exact McNemar', m)}")
    if entry.significant:
        return f"{more} survives more than {fewer}{'' if _holds(entry) else _OWN_TEST_ONLY}: {figures}"
    return (f"{a} and {b} do not differ significantly in survival: {more} {figures}; "
            f"{_settle(entry, 'difference', m)}")


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
                     higher_is_better: bool, subject: str, m: int) -> str:
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
        return _split(entry, leans(entry), subject, unit, decimals, higher_is_better=higher_is_better, m=m)
    better = called_better(entry, higher_is_better=higher_is_better)
    b_first = better == entry.b if better is not None else (entry.diff > 0) == higher_is_better
    first, second = (entry.b, entry.a) if b_first else (entry.a, entry.b)
    m_first, m_second = (entry.mean_b, entry.mean_a) if b_first else (entry.mean_a, entry.mean_b)
    unit = f" {unit}" if unit else ""
    figures = (f"{what} {m_first:.{decimals}f} against {m_second:.{decimals}f}{unit} on {entry.n} trials ({first} - "
               f"{second} = {signed(m_first - m_second, decimals)}{unit}, {_interval(entry, b_first, decimals)}); "
               f"{_significance(entry, 'Wilcoxon signed-rank', m)}")
    if better is not None:
        return f"{head.format(better=first, worse=second)}{'' if _holds(entry) else _OWN_TEST_ONLY}: {figures}"
    return (f"{entry.a} and {entry.b} do not differ significantly in {subject}: {first} {figures}; "
            f"{_settle(entry, 'difference', m)}")


def _interval(entry: PairSummary, b_first: bool, decimals: int) -> str:
    """The bootstrap interval of a difference of means, first side minus second, or why there is none.

    From one pair there is none; where every pair's difference is the same, a bootstrap gives that value as both
    bounds, which measures nothing: the sentence says the differences are all equal instead.
    """
    if entry.all_equal is not None:
        return f"the same in all {entry.all_equal} pairs: no bootstrap interval"
    lo, hi = entry.ci95
    if lo is None or hi is None:
        return "no interval from one pair" if entry.n == 1 else "no interval"
    lo_f, hi_f = (lo, hi) if b_first else (-hi, -lo)
    return f"95 % bootstrap interval [{signed(lo_f, decimals)}, {signed(hi_f, decimals)}]"


def _split(entry: PairSummary, side: float, subject: str, unit: str, decimals: int, *,
           higher_is_better: bool, m: int) -> str:
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
            f"({entry.b} - {entry.a} = {signed(entry.diff, decimals)}{unit} on {entry.n} trials) favours {by_mean} "
            f"through a few large differences; {_significance(entry, 'Wilcoxon signed-rank', m)}: neither is called "
            "better")


def _tracking(entry: PairSummary, what: str, unit: str, decimals: int, m: int) -> str | None:
    if not entry.n or entry.diff is None:
        return None
    subject = f"how they track the {what} over the seconds both survived"
    if entry.diff == 0.0 and not entry.significant:
        return (f"{entry.a} and {entry.b} have the same mean error in the {what} over the seconds both survived "
                f"({entry.n} trials); {_significance(entry, 'Wilcoxon signed-rank', m)}")
    return _mean_difference(entry, f"{{better}} tracks the {what} better than {{worse}} over the seconds both survived",
                            "mean error", unit, decimals, higher_is_better=False, subject=subject, m=m)


def _time_to_fall(entry: PairSummary, m: int) -> str | None:
    """Who stays up longer, or None where the mean times are the same and the test does not reject (nothing to say)."""
    if not entry.n or entry.diff is None or (entry.diff == 0.0 and not entry.significant):
        return None
    return _mean_difference(entry, "{better} stays up longer than {worse}",
                            "mean TTF (the share of the episode survived)", "", 3, higher_is_better=True,
                            subject="how long they stay up (TTF)", m=m)


def in_family(entry: PairSummary) -> bool:
    """The test is one of the family Holm's correction runs over: it has a p and can reach p < `ALPHA` on its pairs.

    A test whose smallest attainable p (`PairSummary.smallest_p`: no or too few discordant pairs or nonzero
    differences) is >= `ALPHA` is left out (Tarone's refinement, `wbc.arena.multiplicity.tarone_holm_adjusted`).
    """
    return entry.p is not None and (entry.smallest_p is None or entry.smallest_p < ALPHA)


def holm_family(summary: Summary | Sequence[PairSummary]) -> tuple[PairSummary, ...]:
    """The summary's paired comparisons with each test's Holm-adjusted p (`PairSummary.p_holm`), in order.

    The family is every paired test of the summary (each pair of controllers, band and metric that has a test) that
    can reach p < `ALPHA` on its pairs (`in_family`); Holm's correction runs over those (Tarone's refinement,
    `wbc.arena.multiplicity.tarone_holm_adjusted`), and a test left out keeps its own p as its adjusted one (it is
    >= `ALPHA`, so it never holds). The adjusted p is computed here from the tests' own p-values, the same as
    `wbc.arena.report.summarize` records, so that a summary read back from an older ``summary.json`` gets it too
    (there, without the Wilcoxon tests' nonzero differences, each is taken to have as many as it has pairs).

    Args:
        summary: a summary, or paired comparisons (``wbc paper``'s table weighs its own).
    """
    paired = summary.paired if isinstance(summary, Summary) else tuple(summary)
    adjusted, _ = tarone_holm_adjusted([entry.p for entry in paired], [entry.smallest_p for entry in paired],
                                       alpha=ALPHA)
    return tuple(dataclasses.replace(entry, p_holm=p) for entry, p in zip(paired, adjusted, strict=True))


def count_line(summary: Summary) -> str | None:
    """The verdict's first line: how many tests it weighs, the family it corrects over, what rejects and what holds.

    It says which claims the correction's bound covers (those that hold after it) and which it does not (those that
    reject on their own test only, each at `ALPHA` uncorrected). None where the summary has no paired test (a run of
    one controller).
    """
    tested = [entry for entry in holm_family(summary) if entry.p is not None]
    if not tested:
        return None
    weighed = len(tested)
    m = sum(1 for entry in tested if in_family(entry))
    out = weighed - m
    alone = sum(1 for entry in tested if entry.p < ALPHA)
    held = sum(1 for entry in tested if _holds(entry))
    pairs = len({(entry.a, entry.b) for entry in tested})
    bands = len({entry.band for entry in tested})
    metrics = len({entry.metric for entry in tested})
    tests = "1 paired test" if weighed == 1 else f"{weighed} paired tests"
    family = (f"{'both' if m == 2 else f'all {m}'} can reach p < {ALPHA:g} on their pairs, and Holm's correction "
              f"runs over the {m}" if not out
              else f"{out} of them cannot reach p < {ALPHA:g} on their pairs (too few discordant pairs or nonzero "
                   f"differences) and {'is' if out == 1 else 'are'} left out of Holm's correction, which runs over "
                   f"the other {m} (Tarone's refinement)" if m else
              f"none can reach p < {ALPHA:g} on its pairs (too few discordant pairs or nonzero differences), so no "
              "test is corrected")
    if weighed == 1 and not out:
        family = "Holm's correction over 1 test is the test itself"
    alone_text = (f"{alone} {'has' if alone == 1 else 'have'} p < {ALPHA:g} on {'its' if alone == 1 else 'their'} "
                  f"own test; {held} {'holds' if held == 1 else 'hold'} after the correction")
    bound = (f"The correction keeps the chance that any claim holding after it is a false \"better\" at most "
             f"{ALPHA:g}{'' if held else ' (none holds here)'}")
    rest = alone - held
    own_only = ("" if not rest else
                f"; {'the 1 claim' if rest == 1 else f'the {rest} claims'} marked \"on its own test only\" "
                f"{'is' if rest == 1 else 'are'} each at {ALPHA:g} on {'its' if rest == 1 else 'their'} own, "
                "uncorrected, outside that bound")
    if not m:
        return (f"This verdict weighs {tests} (every test of the paired differences: {pairs} pair"
                f"{'' if pairs == 1 else 's'} of controllers, {bands} band{'' if bands == 1 else 's'}, {metrics} "
                f"metric{'' if metrics == 1 else 's'}); {family}: none can call a side better.")
    return (f"This verdict weighs {tests} (every test of the paired differences: {pairs} pair"
            f"{'' if pairs == 1 else 's'} of controllers, {bands} band{'' if bands == 1 else 's'}, {metrics} "
            f"metric{'' if metrics == 1 else 's'}); {family}. {alone_text}. {bound}{own_only}. Where nothing "
            f"differs, about 1 test in 20 has p < {ALPHA:g} on its own by chance.")


def robots_caveat(summary: Summary) -> str | None:
    """The note that the controllers played different robots (`Summary.robots_note`), which ends the verdict; or None.

    The pairing gives both the same trials, not the same robot: a difference the verdict calls can be the arm's.
    """
    if summary.robots_note is None:
        return None
    return f"{summary.robots_note}."


def _errored(summary: Summary, controller: str, band: str) -> tuple[int, int]:
    """(trials that ended in a controller error, trials) of `controller` in `band`; (0, 0) where not counted."""
    cell = summary.cell(controller, band)
    return (0, 0) if cell is None else (cell.outcome(CONTROLLER_ERROR), cell.trials)


def _all_errored(summary: Summary, entry: PairSummary) -> str | None:
    """The sentence for a pair where every trial of a side ended in a controller error: no verdict on survival."""
    sides = [c for c in (entry.a, entry.b) if (k := _errored(summary, c, entry.band))[0] and k[0] == k[1]]
    if not sides:
        return None
    said = " and ".join(f"{c}'s {_errored(summary, c, entry.band)[1]} trials" for c in sides)
    return (f"{said} all ended in controller errors: no verdict on survival or how long they stay up "
            f"(a controller error is not a fall; the success rate counts each as a failure, and the TTF is the "
            f"share played before the error)")


def _error_note(summary: Summary, entry: PairSummary, what: str) -> str:
    """A clause for a sentence on survival or TTF where a side had trials that ended in controller errors."""
    notes = []
    for c in (entry.a, entry.b):
        errors, trials = _errored(summary, c, entry.band)
        if errors:
            notes.append(f"{c}'s {errors} of {trials} trials that ended in controller errors")
    if not notes:
        return ""
    how = ("count as failures, not falls" if what == "survival" else
           "enter with the share played before the error, not a time to fall")
    return f"; {' and '.join(notes)} {how}"


def verdicts(summary: Summary) -> list[str]:
    """The verdict sentences of a summary, band by band, pair by pair (none for a run of one controller).

    Each sentence whose test rejects says whether it holds after Holm's correction over every paired test of the
    summary (`holm_family`; `count_line` says how many). A side whose trials all ended in controller errors gets
    no verdict on survival or TTF for that pair and band; a side with some gets a clause saying how they count.

    Args:
        summary: the output of `wbc.arena.report.summarize` (or `Summary.from_json` of a ``summary.json``).

    Returns:
        One line per sentence, each starting with its band: ``band in: mpc survives more than stand: ...``.
    """
    lines: list[str] = []
    family = holm_family(summary)
    m = sum(1 for entry in family if in_family(entry))
    for entry in family:
        if entry.n == 0 or entry.mean_a is None:
            continue
        prefix = f"band {entry.band}: "
        errored = _all_errored(summary, entry) if entry.metric in ("success_rate", "ttf") else None
        if entry.metric == "success_rate":
            lines.append(prefix + (errored or _survival(entry, m) + _error_note(summary, entry, "survival")))
        if entry.metric == "ttf" and errored is None and (sentence := _time_to_fall(entry, m)) is not None:
            lines.append(prefix + sentence + _error_note(summary, entry, "ttf"))
        for metric, what, unit, decimals in _TRACKING:
            if entry.metric == metric:
                sentence = _tracking(entry, what, unit, decimals, m)
                if sentence is not None:
                    lines.append(prefix + sentence)
    return lines
