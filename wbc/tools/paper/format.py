"""A played paper table as text: our rows beside the paper's, the paired comparisons with verdicts, where each fails.

`format_paper_table` is what ``wbc paper TABLE`` prints and writes to ``paper.txt``:

1. a header: the scenario (name, version, file, hash, published or not), the size of the run and the paper's
   protocol, and what a cell shows (ours: mean ± std over seeds, success with its Wilson interval over all the
   trials, or from one seed the mean and its 95 % interval over trials; the paper's: mean ± std over its 5 seeds);
2. one block per metric of the table, a line per paper row followed by our contenders standing beside it (the
   learned and the model-based family), a column per band (the paper's figure beside a band that commands what its
   column did: `wbc.tools.paper.tables.paper_column`); rows of
   ours that the paper does not have (the distilled MPC beside Table III's baselines) come last, their paper cells
   "-";
3. the table's paired comparisons, B - A on the same trials (tracking over the seconds both survived, the arena's
   common window, where the cells are over each trial's own time), with the 95 % interval, the test's p-value
   (exact McNemar for success, Wilcoxon signed-rank otherwise), the discordant pairs and n80, and a verdict per band
   (a side is called better by the arena's rule, `wbc.arena.verdict.called_better`);
4. where each contender fails, per band (`wbc.arena.breakdown`), and the push-recovery curve's file;
5. the run time, each controller's time per trial, and the paper's protocol's cost estimated from them.
"""

from __future__ import annotations

import dataclasses
import textwrap
from collections.abc import Sequence

from wbc.arena.breakdown import breakdown_tables
from wbc.arena.report import LABELS, cell_text, n80_text, p_text, resumed_note, signed_text
from wbc.arena.summary import PairSummary
from wbc.arena.verdict import LOWER_IS_BETTER, called_better, holm_family, in_family, leans, p_clause, split
from wbc.tools.paper.paper_numbers import PaperValue
from wbc.tools.paper.result import PaperComparison, PaperTableResult
from wbc.tools.paper.tables import Contender

__all__ = ["ALPHA", "display_name", "format_paper_table", "verdict"]

ALPHA = 0.05
"""The level the verdicts are read at (two-sided)."""

_WIDTH = 118


def _columns(header: Sequence[str], rows: Sequence[Sequence[str]], indent: str = "  ") -> list[str]:
    widths = [max(len(str(row[i])) for row in (header, *rows)) for i in range(len(header))]
    lines = [indent + "  ".join(str(h).ljust(w) for h, w in zip(header, widths, strict=True)).rstrip(),
             indent + "  ".join("-" * w for w in widths)]
    lines += [indent + "  ".join(str(c).ljust(w) for c, w in zip(row, widths, strict=True)).rstrip() for row in rows]
    return lines


def _wrap(text: str, indent: str = "") -> list[str]:
    return textwrap.wrap(text, width=_WIDTH, initial_indent=indent, subsequent_indent=indent + "  ")


def _paper_cell(value: PaperValue | None) -> str:
    # the paper's digits, not ours: its precision is its own (0.975 ± 0.00, not ± 0.000)
    return "-" if value is None else value.text


def _difference(entry: PairSummary, first: str, metric: str) -> str:
    """The mean difference as `first` minus the other side, named, in the metric's unit.

    Written from the side a verdict names, so that its sign reads with the word beside it: the side called better
    on success or TTF is ahead by a positive difference, on a tracking error by a negative one (a smaller error).
    """
    other, diff = (entry.a, entry.diff) if first == entry.b else (entry.b, -entry.diff)
    unit = " points" if metric == "success_rate" else (f" {LABELS[metric].split(' [')[1].rstrip(']')}"
                                                        if " [" in LABELS[metric] else "")
    return f"{first} - {other} = {signed_text(diff, metric)}{unit}"


def verdict(entry: PairSummary, *, alpha: float = ALPHA, family: int | None = None) -> str:
    """One comparison in words: which side is better, or that the test finds no difference and what would.

    Success and TTF: larger is better; tracking errors: smaller is better. A side is "better" by the arena's rule
    (`wbc.arena.verdict.called_better`): the paired test's p-value is below `alpha` and the test leans to that side,
    the mean difference not on the other. The difference is written as the better side minus the other, both named
    (``mpc better (mpc - pi3 = +17.50 points, p = 0.02)``; on an error ``mpc - pi3 = -0.027 m/s``), and the p-value
    as the arena's verdicts write it (`wbc.arena.verdict.p_clause`: ``p < 1e-4`` below 1e-4). A significant test
    whose lean and mean difference disagree calls neither better. Otherwise "no significant difference", with n80
    (the pairs that would detect the observed difference with 80 % power), or, from one pair of a continuous metric,
    that one pair cannot tell.

    With `family` (the number of tests of the table that can reach `alpha` on their pairs, the family Holm's
    correction runs over: `wbc.arena.verdict.holm_family`) and the entry's Holm-adjusted p (`PairSummary.p_holm`),
    a side called better on its own test that does not hold after that correction says so.
    """
    metric, p, diff = entry.metric, entry.p, entry.diff
    what = LABELS[metric].split(" [")[0].removesuffix(" %")
    if p is None or diff is None:
        return f"{what}: no pairs"
    higher_is_better = metric not in LOWER_IS_BETTER
    winner = called_better(entry, higher_is_better=higher_is_better, alpha=alpha)
    if winner is not None:
        holm = entry.p_holm
        after = ("" if family is None or holm is None else
                 f"; holds after Holm's correction over the table's {family} tests that can reach p < {alpha:g}, "
                 f"adjusted {p_clause(holm)}"
                 if holm < alpha else
                 f"; on its own test only: not after Holm's correction over the table's {family} tests that can "
                 f"reach p < {alpha:g}, adjusted {p_clause(holm)}")
        return f"{what}: {winner} better ({_difference(entry, winner, metric)}, {p_clause(p)}{after})"
    if split(entry, alpha=alpha):
        side = leans(entry)
        ranks = ("lean to neither" if not side else
                 f"favour {entry.b if (side > 0) == higher_is_better else entry.a}")
        by_mean = entry.b if (diff > 0) == higher_is_better else entry.a
        return (f"{what}: neither called better ({p_clause(p)}; the pairs' ranks {ranks}, the mean difference "
                f"({_difference(entry, by_mean, metric)}) favours {by_mean})")
    n80 = n80_text(entry)
    need = ("" if n80 == "-" else
            "; one pair shows no spread to tell how many pairs would detect the observed difference" if n80 == "n/a"
            else f"; {n80} pairs would detect the observed difference")
    return f"{what}: no significant difference ({p_clause(p)}{need})"


def _metric_block(result: PaperTableResult, metric: str) -> list[str]:
    spec, summary = result.spec, result.summary
    # the first column names the paper's row (ours stand beneath it), the second whose figures a line holds
    header = ["row", "paper / ours", *(f"{band} (paper {col})" if col else band
                                       for band, col in _band_columns(result))]
    rows: list[list[str]] = []
    # the paper's rows in its order, then rows of ours the paper does not have (its cells: "-")
    extra = [c.row for c in result.contenders if c.row not in spec.paper]
    for paper_row in (*spec.paper, *dict.fromkeys(extra)):
        cells = spec.paper[paper_row].get(metric, ()) if paper_row in spec.paper else ()
        rows.append([paper_row, "paper", *(_paper_cell(cells[i] if i is not None and i < len(cells) else None)
                                           for i in result.band_columns)])
        for contender in (c for c in result.contenders if c.row == paper_row):
            name = display_name(contender)
            if contender.controller is None:
                rows.append(["", f"{contender.key}: missing", *("-" for _ in result.bands)])
                continue
            cells = [summary.cell(contender.controller, b) for b in result.bands]
            rows.append(["", name, *(cell_text(c[metric], metric, c.seeds) if c is not None and metric in c
                                     else "n/a" for c in cells)])
    return [LABELS[metric], *_columns(header, rows)]


def display_name(contender: Contender) -> str:
    """How a contender is named in the tables.

    Its controller, or its key when that is a policy file (the header lists the file), with pi1 / pi2 / pi3 said for
    the learned arm variants.
    """
    if contender.controller is None or contender.controller.startswith("policy:"):
        return contender.key
    stage = contender.note.split(" ")[0]
    return f"{contender.controller} ({stage})" if stage in ("pi1", "pi2", "pi3") else contender.controller


def _estimate_note(result: PaperTableResult) -> str:
    """What the run-time estimate leaves out, or that it counts compiling (too few trials to leave it out)."""
    if result.estimate_includes_compile:
        return (" (from each worker's first trials, which compile the numba code on a fresh machine: play more "
                "trials than workers for an estimate without it)")
    return " (each worker's first trial of a controller left out: it may compile the numba code)"


def _names(result: PaperTableResult) -> dict[str, str]:
    """Controller name -> its `display_name` in this table."""
    return {c.controller: display_name(c) for c in result.contenders if c.controller is not None}


def _band_columns(result: PaperTableResult) -> list[tuple[str, str]]:
    """Each band and the label of the paper's column it stands in ("" where the paper has none)."""
    cols = result.spec.paper_columns
    return [(band, "" if i is None else cols[i]) for band, i in zip(result.bands, result.band_columns, strict=True)]


def _comparison_lines(result: PaperTableResult) -> list[str]:
    lines = _wrap("paired comparisons, B - A on the same trials (success and its interval in points; tracking errors "
                  "over the seconds both survived on each trial, 'common', where the cells above are over each "
                  "trial's own survived time; p: exact McNemar for success, Wilcoxon signed-rank otherwise, "
                  "two-sided, each comparison on its own, not corrected for the table's many; n80: pairs for 80 % "
                  "power at the observed difference)")
    names = {c.key: display_name(c) for c in result.contenders}
    # as paper.json's p_holm, from any result: Holm over the tests that can reach alpha (Tarone's refinement)
    pairs = holm_family([c.pair for c in result.comparisons])
    tested = sum(1 for pair in pairs if pair.p is not None)
    family = sum(1 for pair in pairs if in_family(pair))
    if tested:
        alone = sum(1 for pair in pairs if pair.p is not None and pair.p < ALPHA)
        held = sum(1 for pair in pairs if pair.p_holm is not None and pair.p_holm < ALPHA)
        left_out = ("" if family == tested else
                    f", {tested - family} of which cannot reach p < {ALPHA:g} on "
                    f"{'its' if tested - family == 1 else 'their'} pairs (too few discordant pairs or nonzero "
                    f"differences) and {'is' if tested - family == 1 else 'are'} left out of Holm's correction "
                    "(Tarone's refinement)")
        if family:
            lines += _wrap(f"the verdicts weigh {tested} tests{left_out}: {alone} with p < {ALPHA:g} on their own, "
                           f"{held} after Holm's correction over the {family} that can reach it. The correction keeps "
                           f"the chance that any 'better' holding after it is false at most {ALPHA:g}; a 'better' that "
                           f"holds only on its own test says so, and is at {ALPHA:g} on its own, uncorrected, outside "
                           "that bound")
        else:
            lines += _wrap(f"the verdicts weigh {tested} tests{left_out}: none can reach p < {ALPHA:g} on its pairs, "
                           "so none can call a side better; more trials could")
    questions: dict[tuple[str, str], list[PaperComparison]] = {}
    for comparison, pair in zip(result.comparisons, pairs, strict=True):
        comparison = dataclasses.replace(comparison, pair=pair)
        questions.setdefault((comparison.pair.a, comparison.pair.b), []).append(comparison)
    if not questions:
        return [*lines, "  (none: a contender of every comparison is missing)"]
    for (a, b), entries in questions.items():
        lines.append("")
        lines.append(f"{entries[0].question}: B = {names[b]}, A = {names[a]}")
        rows = []
        for e in (c.pair for c in entries):
            discordant = f"{e.a_only} / {e.b_only}" if e.a_only is not None else ""
            lo, hi = e.ci95
            ci_text = ("n/a" if lo is None or hi is None else
                       f"[{signed_text(lo, e.metric)}, {signed_text(hi, e.metric)}]")
            rows.append([e.band, LABELS[e.metric], signed_text(e.diff, e.metric), ci_text, p_text(e.p), discordant,
                         n80_text(e)])
        lines += _columns(["band", "metric", "B - A", "95% CI", "p", "A only / B only", "n80"], rows)
        for band in result.bands:
            said = "; ".join(verdict(dataclasses.replace(c.pair, a=names[a], b=names[b]), family=family)
                             for c in entries
                             if c.pair.band == band)
            lines += _wrap(f"band {band}: {said}", indent="  ")
    return lines


def _failure_lines(result: PaperTableResult) -> list[str]:
    pushes = bool(result.curve.get("edges"))
    lines = _wrap("where each contender fails (success by command; each push survived by where its force points and "
                  "by its offset axis; falls before any push / after one, and the median time from that push to the "
                  "fall)" if pushes else "where each contender fails (success by command; the scenario has no pushes)")
    names = _names(result)
    for band in result.bands:
        lines += ["", f"band {band}"]
        for i, (header, rows) in enumerate(breakdown_tables(result.failures, band, pushes=pushes)):
            lines += [""] * (i > 0) + _columns(header, [[names.get(row[0], row[0]), *row[1:]] for row in rows])
    if pushes:
        lines += ["", f"push-recovery curve (survival of each push against its impulse, Wilson 95 % intervals): "
                  f"{result.out_dir / 'push_recovery.png'}"]
    return lines


def format_paper_table(result: PaperTableResult) -> str:
    """The whole printout of a played paper table (module docstring), ending with a newline."""
    spec, sc = result.spec, result.scenario
    one_seed = len(result.seeds) == 1
    lines = [spec.title, ""]
    lines += _wrap(f"scenario {sc['name']} v{sc['version']} ({sc['path']}), hash {sc['hash']}, "
                   + ("published" if sc["published"] else "NOT published (not comparable with published results)")
                   + f"; robot {spec.robot}")
    lines += _wrap(f"ours: {result.trials} trials x {len(result.seeds)} seed{'s' if not one_seed else ''} per band "
                   f"and controller, {sc['duration_s']:g} s each; cells: "
                   + ("mean [95 % interval over trials: Wilson for success, bootstrap otherwise]" if one_seed else
                      "mean ± std over seeds (each seed's trials averaged first: the spread of the seeds' means, "
                      "not the mean's uncertainty), success with its Wilson 95 % interval over all the trials")
                   + f". Paper: {spec.paper_protocol.text}; cells: mean ± std over seeds where it gives one.")
    if result.columns_note is not None:
        lines += _wrap(f"{result.columns_note}.")
    for c in result.contenders:
        if c.controller is None:
            lines += _wrap(f"missing: {c.row} ({c.key}): {c.note}")
        elif c.controller.startswith("policy:"):
            lines += _wrap(f"{c.key} = {c.controller}: {c.note}")
    for metric in spec.metrics:
        lines += ["", *_metric_block(result, metric)]
    lines += ["", *_comparison_lines(result)]
    lines += ["", *_failure_lines(result)]
    names = _names(result)
    per_trial = ", ".join(f"{names.get(c, c)} {s:.1f} s" for c, s in result.trial_wall_s.items())
    lines += [""]
    lines += _wrap(f"run: {result.played} trials played in {result.wall_s:.0f} s ({result.workers or 'all'} "
                   f"worker{'s' if result.workers != 1 else ''}){resumed_note(result.played, result.stored)}; mean "
                   f"wall time per trial: {per_trial}. The paper's "
                   f"protocol (2000 trials per band and contender) would take about "
                   f"{result.paper_protocol_cpu_h:.0f} CPU hours here{_estimate_note(result)}.")
    lines += [f"results: {result.out_dir}/ (paper.txt, paper.json, report.md, trials.csv, summary.json, "
              "failures.json, plots)"]
    return "\n".join(lines) + "\n"
