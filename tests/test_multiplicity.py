"""The family a verdict corrects over: Holm's correction with Tarone's refinement, and what it says in words.

From a reviewer comparing 4 MPC variants on 48 paired tests: the verdict's first line bounded the chance of a false
"better" while the claims below it held on their own tests only; the trials it offered to settle a difference were
those of a test on its own, not under the correction; the family counted tests that could never reject (no
discordant pair, every difference zero) and multiplied every other test's p by them; and the verdict's difference was
the better side's minus the other's, unnamed, beside a table of B - A.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from test_significance import make_record

from wbc.arena import verdict
from wbc.arena.multiplicity import holm_adjusted, smallest_attainable_p, tarone_holm_adjusted
from wbc.arena.paired_tests import mcnemar_exact, wilcoxon_signed_rank
from wbc.arena.report import format_table, summarize
from wbc.arena.statistical_power import pairs_for_mcnemar, pairs_for_mean_difference
from wbc.arena.summary import PairSummary, Summary

# --- the correction ------------------------------------------------------------------------------------------------


def test_the_smallest_attainable_p_is_the_exact_tests_own_on_their_informative_pairs():
    assert [smallest_attainable_p(k) for k in (0, 1, 2, 5, 8)] == [1.0, 1.0, 0.5, 0.0625, 2 / 256]
    for d in range(0, 9):  # d discordant pairs, all won by B: the McNemar test's smallest p
        a = np.array([1] * d + [1, 0], dtype=float)
        b = np.array([0] * d + [1, 0], dtype=float)
        assert mcnemar_exact(a, b).p_value == pytest.approx(smallest_attainable_p(d), abs=1e-15)
    for n in range(1, 9):  # n nonzero differences of one sign, ties among them, zeros beside: the Wilcoxon test's
        d = np.array([0.5, 0.5, 1.0, 2.0, 2.0, 3.0, 4.0, 4.0][:n] + [0.0, 0.0])
        assert wilcoxon_signed_rank(d).p_value == pytest.approx(smallest_attainable_p(n), abs=1e-15)


def test_with_no_test_left_out_the_correction_is_holms_exactly():
    rng = np.random.default_rng(3)
    p = list(rng.uniform(0.0, 0.3, 20) ** 2) + [None]
    adjusted, member = tarone_holm_adjusted(p, [2 / 256] * 20 + [None])
    assert adjusted == holm_adjusted(p)
    assert member == [True] * 20 + [False]


def test_with_every_test_left_out_each_keeps_its_own_p():
    p = [1.0, 0.0625, 0.5, None]
    adjusted, member = tarone_holm_adjusted(p, [1.0, 0.0625, 0.5, 1.0])
    assert adjusted == p
    assert member == [False, False, False, False]


def test_the_demos_eight_tests_are_corrected_over_the_five_that_can_reach_005():
    # band in: survival with 0 discordant pairs (p = 1), TTF with every pair equal (p = 1); band ood: survival on 5
    # discordant pairs (smallest p 2 / 32 = 0.0625; its p 0.0625); the five others on 8 nonzero pairs (2 / 256)
    p = [1.0, 1.0, 0.0078125, 0.0078125, 0.0625, 0.15625, 0.0546875, 0.1484375]
    smallest = [1.0, 1.0, 2 / 256, 2 / 256, 0.0625, 2 / 256, 2 / 256, 2 / 256]
    adjusted, member = tarone_holm_adjusted(p, smallest)
    assert member == [False, False, True, True, False, True, True, True]
    # Holm over m = 5: 5 x 0.0078 = 0.039 (twice), then max(0.039, 3 x 0.0547) = 0.164, 2 x 0.148, 1 x 0.156
    assert adjusted == pytest.approx([1.0, 1.0, 0.0390625, 0.0390625, 0.0625, 0.296875, 0.1640625, 0.296875])
    assert sum(1 for a in adjusted if a < 0.05) == 2
    # plain Holm over the 8 would multiply by 8: 0.0625, which does not hold
    assert holm_adjusted(p)[2] == pytest.approx(0.0625)


def test_a_left_out_test_is_never_called_better_after_the_correction():
    for k in range(0, 5):
        p = smallest_attainable_p(k)
        adjusted, member = tarone_holm_adjusted([p, 0.001], [p, 0.001])
        assert not member[0] and adjusted[0] == p and not adjusted[0] < 0.05
        assert adjusted[1] == pytest.approx(0.001)  # the family of one: its own p


# --- the verdict ---------------------------------------------------------------------------------------------------


def _summary(records, bands=("in", "ood")) -> Summary:
    return summarize(records, scenario_name="flat_push", scenario_hash="abc123", controllers=["a", "b"],
                     bands=list(bands))


def _fall(controller, band, t, falls):
    return make_record(controller, band, 0, t, success=not falls, ttf=0.5 if falls else 1.0,
                       fall_time_s=1.0 if falls else math.nan)


def _everyone_survives_but_b_in_band_in(falls: int) -> list:
    """Band in: B falls in `falls` of 10 trials, A in none; band ood: both survive every trial (nothing to test)."""
    return [_fall(c, band, t, c == "b" and band == "in" and t < falls) for band in ("in", "ood") for t in range(10)
            for c in ("a", "b")]


def test_the_family_leaves_out_tests_that_cannot_reach_005_and_says_so():
    summary = _summary(_everyone_survives_but_b_in_band_in(7))
    by = {(p.band, p.metric): p for p in summary.paired}
    # band in: 7 discordant pairs, 7 nonzero TTF differences: p = 2 / 2^7 = 0.0156, times 2 tests, not 4
    assert by["in", "success_rate"].p_holm == pytest.approx(0.03125)
    assert by["in", "ttf"].p_holm == pytest.approx(0.03125)
    assert by["in", "ttf"].nonzero == 7
    # band ood: no discordant pair, every difference zero: left out, their own p
    assert by["ood", "success_rate"].p_holm == 1.0 and by["ood", "ttf"].p_holm == 1.0
    assert by["ood", "ttf"].nonzero == 0
    line = verdict.count_line(summary)
    assert ("This verdict weighs 4 paired tests (every test of the paired differences: 1 pair of controllers, 2 "
            "bands, 2 metrics); 2 of them cannot reach p < 0.05 on their pairs (too few discordant pairs or nonzero "
            "differences) and are left out of Holm's correction, which runs over the other 2 (Tarone's "
            "refinement). 2 have p < 0.05 on their own test; 2 hold after the correction.") in line
    # summary.json keeps what the family is read off: read back, the same adjusted p-values
    data = summary.to_json()
    assert Summary.from_json(data).to_json() == data
    assert [p.p_holm for p in verdict.holm_family(Summary.from_json(data))] == [p.p_holm for p in summary.paired]


def test_an_older_summary_without_nonzero_counts_takes_each_test_to_have_as_many_as_pairs():
    data = _summary(_everyone_survives_but_b_in_band_in(7)).to_json()
    for entry in data["paired"]:
        del entry["nonzero"], entry["n80_holm"]
    family = verdict.holm_family(Summary.from_json(data))
    by = {(p.band, p.metric): p for p in family}
    assert by["in", "ttf"].smallest_p == smallest_attainable_p(10)  # 10 pairs: at most 10 nonzero
    assert by["ood", "ttf"].smallest_p == 1.0  # every difference the same, and 0: none nonzero
    assert by["in", "ttf"].p_holm == pytest.approx(0.03125)


def test_the_first_line_bounds_only_the_claims_that_hold_and_calls_the_others_uncorrected():
    # B falls in 7 of band in's trials; in band ood each falls in 3, apart: every test can reach 0.05, none holds
    records = [_fall(c, band, t, (band == "in" and c == "b" and t < 7) or
                     (band == "ood" and ((c == "a" and t < 3) or (c == "b" and 3 <= t < 6))))
               for band in ("in", "ood") for t in range(10) for c in ("a", "b")]
    line = verdict.count_line(_summary(records))
    assert ("2 have p < 0.05 on their own test; 0 hold after the correction. The correction keeps the chance that "
            "any claim holding after it is a false \"better\" at most 0.05 (none holds here); the 2 claims marked "
            "\"on its own test only\" are each at 0.05 on their own, uncorrected, outside that bound.") in line
    assert "keeps the chance of any false \"better\" in this verdict" not in line


def test_a_verdict_whose_tests_cannot_reach_005_says_none_can_call_a_side_better():
    records = [_fall(c, "in", t, False) for t in range(10) for c in ("a", "b")]
    assert verdict.count_line(_summary(records, bands=("in",))) == (
        "This verdict weighs 2 paired tests (every test of the paired differences: 1 pair of controllers, 1 band, 2 "
        "metrics); none can reach p < 0.05 on its pairs (too few discordant pairs or nonzero differences), so no test "
        "is corrected: none can call a side better.")


# --- the trials a difference needs under the correction ------------------------------------------------------------


def test_the_pairs_needed_at_holms_first_step_are_at_least_those_the_exact_tests_need_to_reach_it():
    alpha = 0.05 / 48  # 0.00104: an exact test needs 2 / 2^n below it, n >= 11
    assert pairs_for_mean_difference(0.1, 0.0, alpha=alpha) == 11
    assert pairs_for_mean_difference(0.1, 0.0) == 6
    n_alone, n_holm = pairs_for_mcnemar(0.0, 0.5), pairs_for_mcnemar(0.0, 0.5, alpha=alpha)
    assert n_holm > n_alone and n_holm >= 11


def test_a_difference_left_open_gives_the_trials_it_needs_alone_and_under_the_correction():
    # band in: B falls in 5 of 10, A in another (6 discordant pairs, p = 0.22): open, yet able to reach 0.05;
    # band ood: B falls in 8 of 10 (p = 0.0078); the family: all 4 tests
    records = [_fall(c, band, t, (c == "b" and t < (5 if band == "in" else 8))
                     or (c == "a" and band == "in" and t == 9)) for band in ("in", "ood") for t in range(10)
               for c in ("a", "b")]
    summary = _summary(records)
    survival = next(p for p in summary.paired if p.band == "in" and p.metric == "success_rate")
    assert survival.p == pytest.approx(14 / 64)
    assert survival.n80 == pairs_for_mcnemar(0.1, 0.5)
    assert survival.n80_holm == pairs_for_mcnemar(0.1, 0.5, alpha=0.05 / 4)
    assert survival.n80_holm > survival.n80
    (sentence,) = [v for v in verdict.verdicts(summary) if v.startswith("band in: a and b do not differ "
                                                                          "significantly in survival")]
    assert (f"about {survival.n80} paired trials would settle a difference this large on its own test (80 % power at "
            f"0.05), and about {survival.n80_holm} would let it hold after Holm's correction whatever the others show "
            f"(80 % power at 0.05/4, 4 the tests this verdict weighs: at most the level of the correction's first "
            f"step)") in sentence
    assert summary.to_json()["paired"][0]["n80_holm"] == survival.n80_holm
    # the table keeps n80 at 0.05 and says so
    assert "n80: paired trials that test needs to detect the observed difference with 80 % power at alpha = 0.05" \
        in " ".join(format_table(summary).split())


# --- the difference, named -----------------------------------------------------------------------------------------


def _pair(metric: str, diff: float, ci95, p: float) -> PairSummary:
    return PairSummary(a="mpc", b="h14", band="in", metric=metric, diff=diff, ci95=ci95, interval="bootstrap", n=16,
                       mean_a=0.062, mean_b=0.062 + diff, test="Wilcoxon signed-rank", p=p, n80=None, a_only=None,
                       b_only=None, rank_biserial=math.copysign(0.8, diff), nonzero=16, p_holm=p)


def _sentence(entry: PairSummary) -> str:
    summary = Summary(scenario_name="s", scenario_hash="h", cells={}, paired=(entry,), warnings=())
    (sentence,) = verdict.verdicts(summary)
    return sentence


def test_the_verdicts_difference_names_its_sides_and_its_interval_is_in_the_same_orientation():
    # the table's B - A = h14 - mpc = -0.012 [-0.025, -0.004]: h14 tracks better, the verdict names h14 - mpc
    sentence = _sentence(_pair("vlin_err_common", -0.012, (-0.025, -0.004), 0.001))
    assert sentence.startswith("band in: h14 tracks the linear velocity better than mpc")
    assert "(h14 - mpc = -0.012 m/s, 95 % bootstrap interval [-0.025, -0.004])" in sentence
    # B - A = +0.012 [+0.004, +0.025]: mpc tracks better, mpc - h14 = -0.012 [-0.025, -0.004]
    sentence = _sentence(_pair("vlin_err_common", 0.012, (0.004, 0.025), 0.001))
    assert sentence.startswith("band in: mpc tracks the linear velocity better than h14")
    assert "(mpc - h14 = -0.012 m/s, 95 % bootstrap interval [-0.025, -0.004])" in sentence


def test_the_survival_difference_names_its_sides():
    records = [_fall(c, "in", t, c == "a" and t < 8) for t in range(10) for c in ("a", "b")]
    (survival, *_) = verdict.verdicts(_summary(records, bands=("in",)))
    assert survival.startswith("band in: b survives more than a: 10 against 2 of 10 paired trials (b - a = +80.0 "
                               "points, 95 % interval [+")


# --- wbc paper's tables weigh their own family by the same rule ---------------------------------------------------


def test_a_paper_tables_count_line_leaves_out_the_tests_that_cannot_reach_005():
    from pathlib import Path
    from types import SimpleNamespace

    from wbc.tools.paper.format import _comparison_lines
    from wbc.tools.paper.result import PaperComparison, PaperTableResult
    from wbc.tools.paper.tables import TABLES

    spec = TABLES["table1"]

    def success(band, a_only, b_only, p):
        return PairSummary(a="mpc", b="learned", band=band, metric="success_rate", diff=(b_only - a_only) / 10,
                           ci95=(None, None), interval="exact", n=10, mean_a=0.5, mean_b=0.5, test="exact McNemar",
                           p=p, n80=None, a_only=a_only, b_only=b_only)

    pairs = (success("in", 0, 0, 1.0), success("ood", 0, 8, 2 / 256), success("far", 0, 7, 2 / 128))
    result = PaperTableResult(spec=spec, contenders=spec.contenders, scenario={}, bands=("in", "ood"),
                              band_columns=(0, 1), trials=10, seeds=(0,), summary=SimpleNamespace(to_json=dict),
                              comparisons=tuple(PaperComparison(question="q", pair=p) for p in pairs), failures={},
                              curve={}, trial_wall_s={}, warm_wall_s={}, out_dir=Path("runs/x"), played=0,
                              wall_s=0.0, workers=1)
    text = " ".join(" ".join(_comparison_lines(result)).split())
    assert ("the verdicts weigh 3 tests, 1 of which cannot reach p < 0.05 on its pairs (too few discordant pairs or "
            "nonzero differences) and is left out of Holm's correction (Tarone's refinement): 2 with p < 0.05 on "
            "their own, 2 after Holm's correction over the 2 that can reach it. The correction keeps the chance that "
            "any 'better' holding after it is false at most 0.05; a 'better' that holds only on its own test says "
            "so, and is at 0.05 on its own, uncorrected, outside that bound") in text
    assert "holds after Holm's correction over the table's 2 tests that can reach p < 0.05, adjusted p = 0.0156" in text
    # a table none of whose tests can reach 0.05 says so, rather than counting a correction over none
    few = dataclasses.replace(result, comparisons=tuple(PaperComparison(question="q", pair=p) for p in (
        success("in", 0, 0, 1.0), success("ood", 1, 3, 0.625))))
    text = " ".join(" ".join(_comparison_lines(few)).split())
    assert "none can reach p < 0.05 on its pairs, so none can call a side better" in text
    assert "over the 0" not in text


def test_a_summary_written_before_n80_holm_was_recorded_makes_no_claim_about_it():
    # the same run as above, read back from a summary.json of before n80_holm: its None is no search's result
    records = [_fall(c, band, t, (c == "b" and t < (5 if band == "in" else 8))
                     or (c == "a" and band == "in" and t == 9)) for band in ("in", "ood") for t in range(10)
               for c in ("a", "b")]
    data = _summary(records).to_json()
    for entry in data["paired"]:
        del entry["n80_holm"]
    old = Summary.from_json(data)
    (sentence,) = [v for v in verdict.verdicts(old) if v.startswith("band in: a and b do not differ "
                                                                      "significantly in survival")]
    assert "paired trials would settle a difference this large on its own test" in sentence
    assert "Holm's correction over" not in sentence and "search's limit" not in sentence


def test_the_trials_to_hold_after_the_correction_count_the_tests_left_out_of_it_which_more_trials_bring_in():
    # band in: B falls in 5 of 10, A in another (6 discordant pairs: in the family); band ood: no one falls, so its
    # survival and TTF tests cannot reach 0.05 and are left out. With more trials they may join it: the level that
    # holds whatever the others show is 0.05 / 4, not 0.05 / 2
    records = [_fall(c, band, t, band == "in" and ((c == "b" and t < 5) or (c == "a" and t == 9)))
               for band in ("in", "ood") for t in range(10) for c in ("a", "b")]
    summary = _summary(records)
    survival = next(p for p in summary.paired if p.band == "in" and p.metric == "success_rate")
    assert sum(1 for p in verdict.holm_family(summary) if verdict.in_family(p)) == 2
    assert survival.n80_holm == pairs_for_mcnemar(0.1, 0.5, alpha=0.05 / 4) and survival.n80_holm_tests == 4
    (sentence,) = [v for v in verdict.verdicts(summary) if v.startswith("band in: a and b do not differ "
                                                                          "significantly in survival")]
    assert (f"about {survival.n80_holm} would let it hold after Holm's correction whatever the others show (80 % "
            "power at 0.05/4, 4 the tests this verdict weighs") in " ".join(sentence.split())
    assert Summary.from_json(summary.to_json()).paired == summary.paired
