"""What the verdict's numbers are said to mean: multiplicity, intervals the data cannot give, errors, robots.

From a reviewer's checks of a comparison a paper cites: a verdict that weighed many tests at p < 0.05 each without
saying so; "95 % intervals" of zero width from one value or from values all equal; a controller that raised on every
trial judged as if it had fallen at once; controllers on different robots compared with no caveat in report.md or
summary.json.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re

import numpy as np
import pytest
from test_significance import make_record

from wbc.arena import verdict
from wbc.arena.report import cell_text, format_table, format_verdict, summarize, write_report
from wbc.arena.stats import bootstrap_mean_ci, paired_difference
from wbc.arena.summary import Summary
from wbc.arena.trial_record import TrialRecord


def _summary(records, *, controllers=("a", "b"), bands=("in", "ood"), **kwargs) -> Summary:
    return summarize(records, scenario_name="flat_push", scenario_hash="abc123", controllers=list(controllers),
                     bands=list(bands), **kwargs)


def _a_survives_more(falls_of_b: int, trials: int = 10) -> list[TrialRecord]:
    """A survives every trial of both bands; B falls halfway through `falls_of_b` of band in's, none of ood's."""
    records = []
    for band in ("in", "ood"):
        for t in range(trials):
            records.append(make_record("a", band, 0, t))
            falls = band == "in" and t < falls_of_b
            records.append(make_record("b", band, 0, t, success=not falls, ttf=0.5 if falls else 1.0,
                                       fall_time_s=1.0 if falls else math.nan))
    return records


def _b_falls_in_both_bands() -> list[TrialRecord]:
    """B falls halfway through 7 of band in's 10 trials and A in none; in band ood each falls in 3 of 10, apart."""
    records = []
    for band in ("in", "ood"):
        for t in range(10):
            falls_a = band == "ood" and t < 3
            falls_b = (band == "in" and t < 7) or (band == "ood" and 3 <= t < 6)
            for controller, falls in (("a", falls_a), ("b", falls_b)):
                records.append(make_record(controller, band, 0, t, success=not falls, ttf=0.5 if falls else 1.0,
                                           fall_time_s=1.0 if falls else math.nan))
    return records


# --- 1. multiplicity: Holm's correction over the tests the verdict weighs -------------------------------------------


def test_holm_adjusted_p_values_agree_with_statsmodels():
    multipletests = pytest.importorskip("statsmodels.stats.multitest").multipletests
    from wbc.arena.multiplicity import holm_adjusted  # here: the module the old code lacks fails this test alone

    rng = np.random.default_rng(7)
    for m in (1, 2, 5, 36, 148):
        p = rng.uniform(0.0, 0.2, m) ** 2
        p[rng.integers(0, m, m // 3)] = 1.0  # ties, as tests with nothing to tell give
        expected = multipletests(p, method="holm")[1]
        assert holm_adjusted(list(p)) == pytest.approx(list(expected), abs=1e-15)
    # a test without a p-value (no pair played) is no member of the family
    assert holm_adjusted([0.01, None, 0.04]) == [pytest.approx(0.02), None, pytest.approx(0.04)]


def test_summary_json_gives_each_paired_tests_holm_adjusted_p_beside_its_own():
    multipletests = pytest.importorskip("statsmodels.stats.multitest").multipletests
    summary = _summary(_b_falls_in_both_bands()).to_json()
    tested = [p for p in summary["paired"] if p["p"] is not None]
    assert len(tested) == 4  # success and TTF in two bands; no common window, so no tracking test
    # every test can reach p < 0.05 on its pairs (7 and 6 discordant pairs or nonzero differences): plain Holm
    expected = multipletests([p["p"] for p in tested], method="holm")[1]
    assert [p["p_holm"] for p in tested] == pytest.approx(list(expected), abs=1e-15)
    assert all(p["p_holm"] is None for p in summary["paired"] if p["p"] is None)
    assert Summary.from_json(summary).to_json() == summary


def test_the_verdicts_first_line_counts_its_tests_and_those_that_hold_after_correction(tmp_path):
    summary = _summary(_b_falls_in_both_bands())
    line = verdict.count_line(summary)
    assert line.startswith("This verdict weighs 4 paired tests")
    assert ("all 4 can reach p < 0.05 on their pairs, and Holm's correction runs over the 4. 2 have p < 0.05 on "
            "their own test; 0 hold after the correction.") in line
    # the terminal and report.md say the same, first
    printed = format_verdict(summary).splitlines()
    assert " ".join(s.strip() for s in printed[1:4]).startswith("This verdict weighs 4 paired tests")
    write_report(tmp_path, summary, _b_falls_in_both_bands(), {})
    section = (tmp_path / "report.md").read_text().split("## Verdict\n\n")[1]
    assert section.splitlines()[0] == line
    held = verdict.count_line(_summary(_a_survives_more(10)))
    assert ("2 of them cannot reach p < 0.05 on their pairs (too few discordant pairs or nonzero differences) and are "
            "left out of Holm's correction, which runs over the other 2 (Tarone's refinement). 2 have p < 0.05 on "
            "their own test; 2 hold after the correction.") in held


def test_a_better_side_that_does_not_survive_holms_correction_says_so():
    # 7 against 0 discordant pairs: exact McNemar p = 2 / 2^7 = 0.0156; times 4 tests: 0.0625, not below 0.05
    (survival, ttf, *_) = verdict.verdicts(_summary(_b_falls_in_both_bands()))
    assert survival.startswith("band in: a survives more than b (on its own test only, not after Holm's correction)")
    assert ("significant on its own (exact McNemar p = 0.0156), not significant after Holm's correction over the 4 "
            "tests of this verdict that can reach p < 0.05 (Holm-adjusted p = 0.0625)") in survival
    assert ttf.startswith("band in: a stays up longer than b (on its own test only, not after Holm's correction)")
    # 10 against 0: p = 0.00195; band ood's two tests cannot reach 0.05 (nothing differs there) and are left out of
    # the family: adjusted 2 x 0.00195 = 0.0039, it holds, and the sentence says so
    (survival, _, _) = verdict.verdicts(_summary(_a_survives_more(10)))
    assert survival.startswith("band in: a survives more than b: ")
    assert ("significant (exact McNemar p = 0.00195), and after Holm's correction over the 2 tests of this verdict "
            "that can reach p < 0.05 (Holm-adjusted p = 0.00391)") in survival


# --- 2. no interval the data cannot give -------------------------------------------------------------------------


def test_one_value_gives_no_bootstrap_interval():
    assert all(math.isnan(x) for x in bootstrap_mean_ci(np.array([1.0])))
    assert all(math.isnan(x) for x in paired_difference([make_record("a", "in", 0, 0)],
                                                        [make_record("b", "in", 0, 0, ttf=0.065)], "ttf")["ci95"])
    # one trial, one seed: the cell prints the mean and n/a, summary.json holds null, never [1.000, 1.000]
    records = [make_record("a", "in", 0, 0), make_record("b", "in", 0, 0, success=False, ttf=0.065)]
    summary = _summary(records, bands=("in",))
    cell = summary.cell("a", "in")
    assert cell_text(cell["ttf"], "ttf", 1) == "1.000 [n/a]"
    assert summary.to_json()["controllers"]["a"]["bands"]["in"]["ttf"]["ci95"] == [None, None]
    (ttf,) = [p for p in summary.paired if p.metric == "ttf"]
    assert ttf.ci95 == (None, None) and ttf.all_equal is None
    table = format_table(summary)
    assert "[1.000, 1.000]" not in table and "[-0.935, -0.935]" not in table
    assert re.search(r"\n  in +a +b +TTF +-0\.935 +n/a ", table), table
    assert "no interval from one pair" in " ".join(verdict.verdicts(summary))


def test_values_all_equal_are_said_to_be_equal_not_given_a_zero_width_interval():
    records = [make_record(c, "in", 0, t) for c in ("a", "b") for t in range(6)]
    summary = _summary(records, bands=("in",))
    cell = summary.cell("a", "in")
    assert cell_text(cell["ttf"], "ttf", 1) == "1.000 (all 6 equal)"
    (ttf,) = [p for p in summary.paired if p.metric == "ttf"]
    assert ttf.all_equal == 6
    table = format_table(summary)
    assert "+0.000, +0.000" not in table and "[1.000, 1.000]" not in table
    assert re.search(r"\n  in +a +b +TTF +\+0\.000 +all 6 equal ", table), table
    data = summary.to_json()
    assert data["controllers"]["a"]["bands"]["in"]["ttf"]["all_equal"] == 6
    assert [p["all_equal"] for p in data["paired"] if p["metric"] == "ttf"] == [6]
    # a constant offset: the verdict gives the difference and says every pair had it
    shifted = [dataclasses.replace(r, ttf=0.5, success=False, outcome="fall", fall_time_s=1.0)
               if r.controller == "b" else r for r in records]
    (sentence,) = [v for v in verdict.verdicts(_summary(shifted, bands=("in",))) if "TTF" in v]
    assert "a - b = +0.500, the same in all 6 pairs: no bootstrap interval" in sentence
    assert "bootstrap interval [" not in sentence


# --- 3. a controller error is not a fall -----------------------------------------------------------------------------


def _errored(controller: str, band: str, trial: int) -> TrialRecord:
    return make_record(controller, band, 0, trial, success=False, ttf=0.0, outcome="controller_error",
                       error="act raised RuntimeError at tick 0")


def test_a_controller_whose_every_trial_raised_gets_no_verdict_on_survival_or_time_to_fall():
    records = [make_record("stand", "in", 0, t, success=t != 0, ttf=0.742 if t == 0 else 1.0) for t in range(4)]
    records += [_errored("erring", "in", t) for t in range(4)]
    summary = _summary(records, controllers=("stand", "erring"), bands=("in",), errors=())
    said = verdict.verdicts(summary)
    assert said == ["band in: erring's 4 trials all ended in controller errors: no verdict on survival or how long "
                    "they stay up (a controller error is not a fall; the success rate counts each as a failure, and "
                    "the TTF is the share played before the error)"]
    assert not any("survive the same number" in s or "stays up longer" in s or "TTF): " in s for s in said)
    # the published numbers keep counting the error as a failure, by the documented policy
    assert summary.cell("erring", "in")["success_rate"].mean == 0.0


def test_trials_ended_by_controller_errors_are_said_to_count_as_failures_not_falls():
    records = [make_record("stand", "in", 0, t) for t in range(8)]
    records += [_errored("erring", "in", t) if t < 2 else make_record("erring", "in", 0, t) for t in range(8)]
    summary = _summary(records, controllers=("stand", "erring"), bands=("in",), errors=())
    survival, ttf = verdict.verdicts(summary)
    assert survival.endswith("; erring's 2 of 8 trials that ended in controller errors count as failures, not falls")
    assert ttf.endswith("; erring's 2 of 8 trials that ended in controller errors enter with the share played before "
                        "the error, not a time to fall")


# --- 4. controllers on different robots --------------------------------------------------------------------------


def test_controllers_on_different_robots_carry_the_note_in_report_md_and_summary_json(tmp_path):
    note = ("the controllers play different robots: a: a1-wx200 with no arm (12.00 kg); b: a1-wx200 with its arm "
            "locked (13.80 kg). Every trial's pushes, ground and commands are the same for each, the robot is not")
    robots = {"a": "a1-wx200 with no arm (12.00 kg)", "b": "a1-wx200 with its arm locked (13.80 kg)"}
    records = _a_survives_more(7)
    summary = _summary(records, robots=robots, robots_note=note)
    data = json.loads(json.dumps(summary.to_json()))
    assert data["same_robot"] is False and data["robots"] == robots and data["robots_note"] == note
    assert Summary.from_json(data).to_json() == data
    write_report(tmp_path, summary, records, {})
    section = (tmp_path / "report.md").read_text().split("## Verdict")[1].split("## Results")[0]
    assert f"**Note:** {note}." in section
    assert "note: the controllers play different robots" in " ".join(format_verdict(summary).split())
    same = _summary(records, robots={"a": robots["a"], "b": robots["a"]}).to_json()
    assert same["same_robot"] is True and same["robots_note"] is None
    assert "same_robot" not in _summary(records).to_json()  # records alone: the robots are not known


def test_a_paper_tables_better_side_says_whether_it_holds_after_holms_correction_over_the_tables_tests():
    from wbc.arena.summary import PairSummary
    from wbc.tools.paper.format import verdict as paper_verdict

    def pair(p, p_holm):
        return PairSummary(a="pi2", b="pi3", band="in", metric="success_rate", diff=0.2, ci95=(None, None),
                           interval=None, n=10, mean_a=None, mean_b=None, test="exact McNemar", p=p, n80=42,
                           a_only=None, b_only=None, p_holm=p_holm)

    assert paper_verdict(pair(0.01, 0.37), family=37) == (
        "Success: pi3 better (pi3 - pi2 = +20.00 points, p = 0.01; on its own test only: not after Holm's correction "
        "over the table's 37 tests that can reach p < 0.05, adjusted p = 0.37)")
    assert paper_verdict(pair(0.001, 0.037), family=37) == (
        "Success: pi3 better (pi3 - pi2 = +20.00 points, p = 0.001; holds after Holm's correction over the table's 37 "
        "tests that can reach p < 0.05, adjusted p = 0.037)")
