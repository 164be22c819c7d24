"""Everything a trial knew reaches the results, and the verdict says what the pairs show.

Plug-ins that count their own events, saturate their torques, or act slower than their period are compared with
``stand`` on a one-second scenario: each custom counter lands in ``trials.csv``, ``summary.json`` and the report;
clamped and late ticks are counted per trial and warned about past 1 % of a controller's ticks. The common-window
tracking errors, the exact interval of a paired success difference and the verdict sentences are checked on records
and counts built by hand.
"""

import dataclasses
import json
import math

import numpy as np
import pytest
from conftest import SHORT_SCENARIO, STAND_PLUGIN

from wbc.arena.compare import ArenaConfig, run_arena
from wbc.arena.paired_tests import mcnemar_exact, paired_success_interval
from wbc.arena.report import format_table, paired_comparison, summarize
from wbc.arena.summary import Summary
from wbc.arena.trial_record import TrialRecord, check_counters, decode_counters
from wbc.arena.verdict import verdicts
from wbc.arena.windows import common_window_values
from wbc.errors import RecordError

PLUGINS = {
    "counting": ("counts its ticks", "pass", 'return {"fallbacks": 0, "ticks_seen": self.ticks}'),
    "saturating": ("asks for 1e5 N m", "out = MotorCommand(q=out.q, dq=out.dq, kp=out.kp, kd=out.kd, "
                   "tau=np.full(15, 1e5))", "return {}"),
    # 21 ms at a 20 ms period: late on every tick, on any machine (a sleep lasts at least what it is asked for)
    "slow": ("acts in 21 ms", '__import__("time").sleep(0.021)', "return {}"),
    "badcount": ("counts in halves", "pass", 'return {"half": 0.5}'),
}


@pytest.fixture
def plugins(tmp_path, plugin_package):
    """A package `countpkg` of the plug-ins above on sys.path; the scenario file."""
    plugin_package("countpkg", {name: STAND_PLUGIN.format(doc=doc, reset="pass", act=act, counters=counters)
                                for name, (doc, act, counters) in PLUGINS.items()})
    scenario = tmp_path / "short.toml"
    scenario.write_text(SHORT_SCENARIO, encoding="utf-8")
    return scenario


def _compare(scenario, out, *controllers, trials=2):
    cfg = ArenaConfig(controllers=("stand", *controllers), scenario=scenario, trials=trials, out_dir=out,
                      workers=1, progress=False)
    return run_arena(cfg)


def test_a_custom_counter_reaches_trials_csv_summary_and_report(plugins, tmp_path):
    result = _compare(plugins, tmp_path / "out", "countpkg.counting:make")
    name = "countpkg.counting:make"
    rows = TrialRecord.read_csv(result.out_dir / "trials.csv")
    mine = [r for r in rows if r.controller == name]
    assert [r.counter_values for r in mine] == [{"fallbacks": 0, "ticks_seen": 50}] * 2
    assert {r.counters for r in mine} == {"fallbacks=0;ticks_seen=50"}
    assert all(r.ticks == 50 for r in rows)
    summary = json.loads((result.out_dir / "summary.json").read_text())
    assert summary["controllers"][name]["bands"]["soft"]["counters"] == {
        "fallbacks": {"total": 0, "trials": 0, "per_trial": 0.0},
        "ticks_seen": {"total": 100, "trials": 2, "per_trial": 50.0}}
    assert summary["controllers"]["stand"]["bands"]["soft"]["counters"] == {}
    report = (result.out_dir / "report.md").read_text()
    assert f"| soft | {name} | ticks_seen | 100 | 2 | 50 |" in report
    assert f"{name} in band soft: fallbacks 0, ticks_seen 100" in format_table(result.summary)
    assert result.summary.to_json() == summary  # summary.json is the typed summary's one JSON form
    assert len(result.records) == len(rows) and set(result.records) == set(rows)  # the result carries its records


def test_clamped_and_late_ticks_are_counted_and_warned_about(plugins, tmp_path):
    result = _compare(plugins, tmp_path / "out", "countpkg.saturating:make", "countpkg.slow:make")
    rows = {(r.controller, r.trial): r for r in TrialRecord.read_csv(result.out_dir / "trials.csv")}
    for trial in (0, 1):
        stand, saturating, slow = (rows[(c, trial)] for c in ("stand", "countpkg.saturating:make",
                                                              "countpkg.slow:make"))
        assert stand.clamped_ticks == 0 and slow.clamped_ticks == 0
        assert saturating.clamped_ticks == saturating.ticks > 0
        assert saturating.clamped_rows == f"tau={saturating.ticks}" and stand.clamped_rows == ""
        assert slow.deadline_misses == slow.ticks == 50
        assert slow.act_ms_p50 >= 21.0
    summary = result.summary
    kinds = {(w.controller, w.kind) for w in summary.warnings}
    assert ("countpkg.saturating:make", "clamped_ticks") in kinds
    assert ("countpkg.slow:make", "deadline_misses") in kinds
    assert not any(c == "stand" and k == "clamped_ticks" for c, k in kinds)
    table = format_table(summary)
    assert "warnings (past 1 % of a controller's ticks in a band):" in table
    assert "countpkg.slow:make in band soft: on 100 of 100 ticks (100.0 %) controller.act took longer" in table
    report = (result.out_dir / "report.md").read_text()
    assert "## Warnings" in report and "was clamped before it was sent (feed-forward torques on " in report
    ticks = sum(r.ticks for r in rows.values() if r.controller == "countpkg.saturating:make")
    assert f"| soft | countpkg.saturating:make | {ticks} | 0 | {ticks} |" in report  # timing and commands table


def test_a_controller_whose_counters_are_not_counts_fails_its_trials(plugins, tmp_path):
    result = _compare(plugins, tmp_path / "out", "countpkg.badcount:make")
    rows = [r for r in TrialRecord.read_csv(result.out_dir / "trials.csv") if r.controller != "stand"]
    assert [r.outcome for r in rows] == ["controller_error"] * 2
    assert all("counters() failed" in r.error and "half = 0.5" in r.error for r in rows)
    assert [e.controller for e in result.controller_errors] == ["countpkg.badcount:make"]


def test_counters_are_checked_and_stored_as_text():
    assert check_counters({"b": np.int64(2), "a": 3.0}) == {"a": 3, "b": 2}
    assert decode_counters("a=3;b=2") == {"a": 3, "b": 2} and decode_counters("") == {}
    for bad, match in (({"a": 1.5}, "whole number"), ({"a": True}, "whole number"), ({"a b": 1}, "name"),
                       ({"1a": 1}, "name"), ([("a", 1)], "dict")):
        with pytest.raises(RecordError, match=match):
            check_counters(bad)
    with pytest.raises(RecordError, match="not name=count"):
        decode_counters("a=1;b")


# --- common windows, the paired success interval, the verdict -------------------------------------------------------


def _record(controller, trial, *, success=True, ttf=1.0, vlin=(), vang=(), seed=0):
    return TrialRecord(
        controller=controller, scenario="s", scenario_hash="h", band="b", seed=seed, trial=trial, success=success,
        outcome="success" if success else "fall",
        ttf=ttf, fall_time_s=math.nan if success else ttf * 4.0, vlin_err=float(np.mean(vlin)) if vlin else 0.0,
        vang_err=float(np.mean(vang)) if vang else 0.0, max_roll_deg=1.0, max_pitch_deg=1.0, energy_j=1.0,
        arm_travel_rad=0.0, push_force_n=0.0, n_pushes=0, vx_cmd=0.5, vy_cmd=0.0, yaw_rate_cmd=0.0, friction=1.0,
        payload_kg=0.0, fallbacks=0, wbc_failures=0, debug_truth=False, wall_s=1.0,
        vlin_err_by_s=" ".join(str(v) for v in vlin), vang_err_by_s=" ".join(str(v) for v in vang))


def test_tracking_is_compared_over_the_seconds_both_controllers_survived():
    # A falls after 2 s with small errors before the push; B survives 4 s and is worse after the push, not before
    a = [_record("a", i, success=False, ttf=0.5, vlin=(0.1, 0.1), vang=(0.2, 0.2)) for i in range(3)]
    b = [_record("b", i, vlin=(0.05, 0.05, 0.9, 0.9), vang=(0.1, 0.1, 0.8, 0.8)) for i in range(3)]
    own = paired_comparison(a, b, "vlin_err")
    common = paired_comparison(a, b, "vlin_err_common")
    assert own["diff"] == pytest.approx(0.375)  # over its own time, B looks worse: it kept going through the push
    assert common["diff"] == pytest.approx(-0.05) and common["n"] == 3  # over the same two seconds it is better
    assert common["mean_a"] == pytest.approx(0.1) and common["mean_b"] == pytest.approx(0.05)
    values = common_window_values({"a": a, "b": b, "c": [_record("c", 0, vlin=(0.3,))]}, "vlin_err_common")
    assert values["c"] == {("b", 0, 0): 0.3} and values["b"] == {("b", 0, 0): 0.05}  # trial 0 only; 1 s window
    # a trial one controller played for less than a second has no window
    short = [_record("a", 0, success=False, ttf=0.1, vlin=())]
    assert math.isnan(common_window_values({"a": short, "b": b[:1]}, "vlin_err_common")["b"][("b", 0, 0)])


def test_a_controller_error_does_not_cut_the_others_common_window_in_the_summary():
    # "a" raises on its first tick of every trial; "b" and "c" play 3 s: their run-wide window is their own 3 s
    errored = [dataclasses.replace(_record("a", i, success=False, ttf=0.0), outcome="controller_error",
                                   error=f"controller a, trial {i}: act raised") for i in range(2)]
    b = [_record("b", i, vlin=(0.1, 0.2, 0.3)) for i in range(2)]
    c = [_record("c", i, vlin=(0.3, 0.2, 0.1)) for i in range(2)]
    values = common_window_values({"a": errored, "b": b, "c": c}, "vlin_err_common", skip_errors=True)
    assert values["b"] == {("b", 0, 0): pytest.approx(0.2), ("b", 0, 1): pytest.approx(0.2)}
    assert all(math.isnan(v) for v in values["a"].values())
    # without skip_errors (a pair's comparison) the error's empty window leaves the trial out, as a fall's would
    assert all(math.isnan(v) for v in common_window_values({"a": errored, "b": b}, "vlin_err_common")["b"].values())
    summary = summarize([*errored, *b, *c], scenario_name="s", scenario_hash="h", controllers=("a", "b", "c"),
                        bands=("b",))
    assert summary.cells["b"]["b"].metrics["vlin_err_common"].mean == pytest.approx(0.2)
    assert summary.cells["a"]["b"].metrics["vlin_err_common"].mean is None  # no window: n/a in the table


def test_the_paired_success_interval_excludes_zero_exactly_when_mcnemar_rejects():
    for n in range(1, 21):
        for b in range(n + 1):
            for c in range(n + 1 - b):
                lo, hi = paired_success_interval(b, c, n)
                a_out = np.array([1] * b + [0] * c + [1] * (n - b - c))
                b_out = np.array([0] * b + [1] * c + [1] * (n - b - c))
                assert (lo > 0 or hi < 0) == (mcnemar_exact(a_out, b_out).p_value < 0.05), (n, b, c)
                assert -1.0 <= lo <= (c - b) / n <= hi <= 1.0
    # three pairs all won by B: no longer the point interval [+100, +100] a bootstrap gives
    lo, hi = paired_success_interval(0, 3, 3)
    assert lo < 0 < hi == 1.0
    lo, hi = paired_success_interval(0, 0, 3)  # nothing discordant: wide, not a point
    assert lo == -hi and hi > 0.5


def test_the_paired_success_interval_covers_the_difference_at_least_95_percent():
    rng = np.random.default_rng(7)
    for n, p11, p10, p01 in ((8, 0.3, 0.1, 0.4), (20, 0.5, 0.2, 0.2), (40, 0.1, 0.05, 0.25), (12, 0.6, 0.3, 0.0)):
        counts = rng.multinomial(n, [p11, p10, p01, 1.0 - p11 - p10 - p01], size=1000)
        truth = p01 - p10
        covered = 0
        for _, b, c, _ in counts:
            lo, hi = paired_success_interval(int(b), int(c), n)
            covered += lo - 1e-12 <= truth <= hi + 1e-12
        assert covered / 1000 >= 0.95, (n, p11, p10, p01, covered)


def test_the_verdict_says_who_survives_more_on_how_many_pairs_and_what_would_settle_it():
    a = [_record("mpc", i, success=i < 3, ttf=1.0 if i < 3 else 0.5, vlin=(0.1, 0.1)) for i in range(8)]
    b = [_record("learned", i, success=i != 7, ttf=1.0 if i != 7 else 0.5, vlin=(0.2, 0.2)) for i in range(8)]
    summary = summarize([*a, *b], scenario_name="s", scenario_hash="h", controllers=["mpc", "learned"],
                        bands=["b"])
    lines = verdicts(summary)
    survival = next(line for line in lines if "survival" in line)
    # not significant: the sentence opens with that, never with a side that "survives more"
    assert survival.startswith("band b: mpc and learned do not differ significantly in survival: learned 7 against 3 "
                               "of 8 paired trials (learned - mpc = +50.0 points")
    assert "of 4 discordant pairs learned alone survived 4 and mpc alone 0" in survival
    assert "not significant (exact McNemar p = 0.125)" in survival and "would settle" in survival
    tracking = next(line for line in lines if "linear velocity" in line)
    assert tracking.startswith("band b: mpc tracks the linear velocity better than learned over the seconds both "
                               "survived: mean error 0.100 against 0.200 m/s on 8 trials")
    # the time to fall: mpc's four falls at half time against learned's one
    ttf = next(line for line in lines if "TTF" in line)
    assert ttf.startswith("band b: mpc and learned do not differ significantly in how long they stay up (TTF): "
                          "learned mean TTF (the share of the episode survived) 0.938 against 0.688 on 8 trials "
                          "(learned - mpc = +0.250"), ttf
    assert "Wilcoxon signed-rank" in ttf
    entry = next(p for p in summary.paired if p.metric == "success_rate")
    assert entry.interval == "exact" and entry.ci95[0] < 0 < entry.ci95[1]  # agrees with p = 0.125
    assert format_table(summary).rstrip().splitlines()[-1].strip().endswith(")")
    assert "verdict (paired trials; significant: p < 0.05):" in format_table(summary)
    assert "verdict (paired" not in format_table(summary, verdict=False)
    # alike: no discordant pair
    same = summarize([*a, *(_record("twin", r.trial, success=r.success, ttf=r.ttf, vlin=(0.1, 0.1)) for r in a)],
                     scenario_name="s", scenario_hash="h", controllers=["mpc", "twin"], bands=["b"])
    assert any("mpc and twin survive the same number of these trials: 3 of 8 paired trials each, with no discordant "
               "pair" in line
               for line in verdicts(same))
    assert not any("stays up longer" in line for line in verdicts(same))  # the same times to fall: nothing to say
    # one discordant pair, a tiny significant difference, a p below 1e-4: as the table writes them
    one = [_record("c", i, success=i != 0, vlin=(0.1,)) for i in range(8)]
    tiny = [_record("d", i, vlin=(0.1 + 1e-4 * (1 + i),)) for i in range(8)]
    lines = verdicts(summarize([*one, *tiny], scenario_name="s", scenario_hash="h", controllers=["c", "d"],
                               bands=["b"]))
    assert "of 1 discordant pair d alone survived 1" in next(line for line in lines if "survival" in line)
    tracking = next(line for line in lines if "linear velocity" in line)
    assert "(c - d = -4.5e-04 m/s, 95 % bootstrap interval [-0.001, -2.9e-04])" in tracking, tracking
    assert "significant (Wilcoxon signed-rank p = 0.00781)" in tracking and "-0.000" not in tracking
    strong = [_record("e", i, vlin=(0.1 + 0.01 * i,)) for i in range(40)]
    weak = [_record("f", i, vlin=(0.3 + 0.01 * i,)) for i in range(40)]
    lines = verdicts(summarize([*strong, *weak], scenario_name="s", scenario_hash="h", controllers=["e", "f"],
                               bands=["b"]))
    assert "significant (Wilcoxon signed-rank p < 1e-4)" in next(line for line in lines if "linear velocity" in line)


# --- the typed summary ---------------------------------------------------------------------------------------------


def test_a_summary_reads_back_from_its_json_and_refuses_another_versions():
    a = [_record("mpc", i, vlin=(0.1, 0.2)) for i in range(3)]
    b = [_record("learned", i, success=i > 0, ttf=1.0 if i else 0.5, vlin=(0.3, 0.1)) for i in range(3)]
    summary = summarize([*a, *b], scenario_name="s", scenario_hash="h", controllers=["mpc", "learned"], bands=["b"])
    data = json.loads(json.dumps(summary.to_json(), allow_nan=False))
    assert Summary.from_json(data) == summary
    assert summary.cell("learned", "b")["success_rate"].mean == pytest.approx(2 / 3)
    assert summary.cell("ghost", "b") is None and summary.bands == ["b"] and summary.stored == 6
    # a summary.json of another version (here one before ticks and counters) is refused, saying how to remake it
    old = {"scenario": {"name": "s", "hash": "h"},
           "controllers": {"mpc": {"bands": {"b": {"trials": 3, "seeds": 1,
                                                   "success_rate": {"mean": 1.0, "std": 0.0, "ci95": [0.4, 1.0]}}}}},
           "paired": [], "warnings": []}
    with pytest.raises(RecordError, match="summary.json: not a summary this version reads .*'ticks'.* --resume"):
        Summary.from_json(old, source="summary.json")
    with pytest.raises(RecordError, match="summary.json: not a summary"):
        Summary.from_json({"controllers": {}}, source="summary.json")
