"""Tests of `wbc.arena.trial_record`, `wbc.arena.stats` and `wbc.arena.report` on synthetic records."""

from __future__ import annotations

import csv
import dataclasses
import json
import math

import numpy as np
import pytest

from wbc.arena.report import (
    COMMON_METRICS,
    EXTRA_METRICS,
    METRICS,
    PAIRED_METRICS,
    format_table,
    summarize,
    write_report,
)
from wbc.arena.stats import in_canonical_order, mean_std_over_seeds, paired_difference
from wbc.arena.summary import Summary
from wbc.arena.trial_record import TrialRecord
from wbc.errors import RecordError, UnknownNameError

CONTROLLERS = ("mpc", "rl", "wbc")
BANDS = ("nominal", "push")
SEEDS = (0, 1, 2)
N_TRIALS = 10
SCENARIO = "flat_push"
HASH = "abc123"


def make_record(controller: str, band: str, seed: int, trial: int, **overrides) -> TrialRecord:
    """One record with deterministic values; `overrides` replace fields."""
    record = {
        "controller": controller,
        "scenario": SCENARIO,
        "scenario_hash": HASH,
        "band": band,
        "seed": seed,
        "trial": trial,
        "success": True,
        "ttf": 1.0,
        "fall_time_s": math.nan,
        "vlin_err": 0.1,
        "vang_err": 0.2,
        "max_roll_deg": 5.0,
        "max_pitch_deg": 3.0,
        "energy_j": 100.0,
        "arm_travel_rad": 0.5,
        "push_force_n": 0.0,
        "n_pushes": 0,
        "vx_cmd": 0.5,
        "vy_cmd": 0.0,
        "yaw_rate_cmd": 0.0,
        "friction": 0.8,
        "payload_kg": 0.0,
        "fallbacks": 0,
        "wbc_failures": 0,
        "debug_truth": False,
        "wall_s": 1.5,
        "power_w": 40.0,
    }
    record.update(overrides)
    record.setdefault("outcome", "success" if record["success"] else "fall")
    return TrialRecord(**record)


def arena_records(*, pushes: bool = True) -> list[TrialRecord]:
    """3 controllers x 2 bands x 3 seeds x 10 trials with varied, reproducible values."""
    rng = np.random.default_rng(42)
    records = []
    for c_index, controller in enumerate(CONTROLLERS):
        for band in BANDS:
            for seed in SEEDS:
                for trial in range(N_TRIALS):
                    push = float(rng.uniform(0.0, 120.0)) if (pushes and band == "push") else 0.0
                    success = bool(rng.random() < 0.9 - 0.1 * c_index - push / 400.0)
                    ttf = 1.0 if success else float(rng.uniform(0.1, 0.9))
                    records.append(
                        make_record(
                            controller,
                            band,
                            seed,
                            trial,
                            success=success,
                            ttf=ttf,
                            fall_time_s=math.nan if success else 10.0 * ttf,
                            vlin_err=float(rng.uniform(0.05, 0.2)) + 0.02 * c_index,
                            vang_err=float(rng.uniform(0.1, 0.3)),
                            push_force_n=push,
                            n_pushes=int(push > 0.0),
                            energy_j=float(rng.uniform(80.0, 120.0)),
                        )
                    )
    return records


def through_csv(records: list[TrialRecord], path) -> list[TrialRecord]:
    """Write the records to a trials.csv as the results store does, and read them back."""
    with path.open("w", encoding="utf-8", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(TrialRecord.header())
        writer.writerows(r.to_row() for r in records)
    return TrialRecord.read_csv(path)


def summary_of(records: list[TrialRecord], controllers=CONTROLLERS, bands=BANDS) -> Summary:
    return summarize(records, scenario_name=SCENARIO, scenario_hash=HASH, controllers=controllers, bands=bands)


def json_of(records: list[TrialRecord], controllers=CONTROLLERS, bands=BANDS) -> dict:
    """The summary's JSON form (``summary.json``)."""
    return summary_of(records, controllers, bands).to_json()


# --- wbc.arena.trial_record -------------------------------------------------------------------------------------------


def test_record_round_trips_through_csv_to_the_last_bit(tmp_path):
    records = arena_records()
    records[0] = dataclasses.replace(records[0], vlin_err=0.1 + 0.2, wall_s=1e-300, debug_truth=True, wbc_failures=3)
    back = through_csv(records, tmp_path / "trials.csv")
    assert len(back) == len(records)
    assert back == records  # equal as stored: floats keep every bit, NaN stays NaN
    assert back[1] != dataclasses.replace(back[1], vlin_err=np.nextafter(back[1].vlin_err, 1.0))
    assert len({*back, *records}) == len(records)
    for a, b in zip(records, back, strict=True):
        assert {k: type(a[k]) for k in TrialRecord.header()} == {k: type(b[k]) for k in TrialRecord.header()}
    assert back[0].vlin_err == 0.1 + 0.2 and back[0].debug_truth is True and back[0].wbc_failures == 3
    assert (tmp_path / "trials.csv").read_text().splitlines()[0] == ",".join(TrialRecord.header())


EARLIER_COLUMNS = ("controller,scenario,scenario_hash,band,seed,trial,success,ttf,fall_time_s,vlin_err,vang_err,"
                   "max_roll_deg,max_pitch_deg,energy_j,arm_travel_rad,push_force_n,n_pushes,vx_cmd,vy_cmd,yaw_rate_cmd,"
                   "friction,payload_kg,fallbacks,wbc_failures,debug_truth,wall_s")
"""The ``trials.csv`` columns of a results directory written before hardware trials."""


def test_the_trials_csv_columns_are_the_stored_format_and_any_other_is_another_versions(tmp_path):
    # the stored format: changing it silently would stop results directories from resuming
    assert ",".join(TrialRecord.header()) == (
        "controller,scenario,scenario_hash,band,seed,trial,success,outcome,ttf,fall_time_s,vlin_err,vang_err,"
        "max_roll_deg,max_pitch_deg,energy_j,arm_travel_rad,push_force_n,n_pushes,vx_cmd,vy_cmd,yaw_rate_cmd,friction,"
        "payload_kg,fallbacks,wbc_failures,debug_truth,backend,metrics_source,safety_trips,late_advances,"
        "worst_lateness_ms,deadline_misses,act_ms_p50,act_ms_p99,act_ms_max,write_deadline_ramps,wall_s,error,ticks,clamped_ticks,clamped_rows,"
        "power_w,vlin_err_by_s,vang_err_by_s,counters,checksum")
    # a file of any other columns is another version's, refused with what to do: fewer columns (before hardware
    # trials, before outcomes, before the checksum, before ticks and counters), or the same in another order
    record = make_record("mpc", "nominal", 0, 1, success=True, power_w=math.nan)
    row = dict(zip(TrialRecord.header(), record.to_row(), strict=True))
    header = TrialRecord.header()
    old = tmp_path / "trials.csv"
    for columns in (EARLIER_COLUMNS.split(","), [c for c in header if c not in ("outcome", "error", "checksum")],
                    header[:-1], header[:header.index("error") + 1], EARLIER_COLUMNS.replace(",wall_s", "").split(","),
                    EARLIER_COLUMNS.replace("seed,trial", "trial,seed").split(",")):
        old.write_text(",".join(columns) + "\n" + ",".join(row.get(c, "") for c in columns) + "\n")
        with pytest.raises(RecordError, match="another version of wbc: resume it with that version"):
            TrialRecord.read_csv(old)
    # an outcome must be one of the six, and agree with success
    with pytest.raises(RecordError, match="outcome must be one of"):
        make_record("mpc", "nominal", 0, 0, outcome="crash")
    with pytest.raises(RecordError, match="contradicts outcome 'controller_error'"):
        make_record("mpc", "nominal", 0, 0, success=True, outcome="controller_error")


def test_a_header_of_other_columns_is_refused_naming_the_columns_that_differ(tmp_path):
    # the columns that differ are named, wherever they are: a header is longer than a message can quote
    header = list(TrialRecord.header())
    old = tmp_path / "trials.csv"
    seed, trial = header.index("seed"), header.index("trial")
    swapped = [*header[:seed], "trial", "seed", *header[trial + 1:]]
    for columns, said in ((header + ["pull_ms"], "(extra 'pull_ms')"),
                          ([c for c in header if c != "counters"], "(missing 'counters')"),
                          (swapped, f"(out of place 'seed' (column {trial + 1}, this version's {seed + 1}))"),
                          ([*header, "seed"], "(repeated 'seed')"),
                          ([c for c in header if c != "wall_s"] + ["pull_ms", "wall_s"],
                           f"(extra 'pull_ms'; out of place 'wall_s' (column {len(header) + 1}, this version's "
                           f"{header.index('wall_s') + 1}))")):
        old.write_text(",".join(columns) + "\n")
        with pytest.raises(RecordError) as refused:
            TrialRecord.read_csv(old)
        assert f"trials.csv: columns not this version's {said}; the directory was written by another version" \
            in str(refused.value)
    old.write_text(",".join([f"extra_{i}" for i in range(12)] + header) + "\n")
    with pytest.raises(RecordError, match=r"\(extra 'extra_0', .*, 'extra_7' and 4 more\);"):
        TrialRecord.read_csv(old)


def test_read_csv_drops_a_torn_last_line_and_refuses_other_columns(tmp_path):
    records = arena_records()[:3]
    path = tmp_path / "trials.csv"
    through_csv(records, path)
    with path.open("a", encoding="utf-8") as f:
        f.write("mpc,flat_push,abc123,nominal,0")  # a write cut short by a kill
    assert [r.run_key for r in TrialRecord.read_csv(path)] == [r.run_key for r in records]
    other = tmp_path / "old.csv"
    other.write_text("controller,band,seed\nmpc,nominal,0\n")
    with pytest.raises(RecordError, match="another version of wbc"):
        TrialRecord.read_csv(other)


def test_record_fields_are_typed_and_bad_cells_are_named():
    row = make_record("mpc", "nominal", 0, 0).to_row()
    header = TrialRecord.header()
    bad = list(row)
    bad[header.index("ttf")] = "fast"
    with pytest.raises(RecordError, match=r"trials\.csv:7: field ttf holds 'fast'"):
        TrialRecord.from_row(bad, source="trials.csv:7")
    bad = list(row)
    bad[header.index("success")] = "maybe"
    with pytest.raises(RecordError, match="field success"):
        TrialRecord.from_row(bad)
    with pytest.raises(RecordError, match="cells"):
        TrialRecord.from_row(row[:-1])
    with pytest.raises(RecordError, match=r"TrialRecord\.ttf must be of type float"):
        make_record("mpc", "nominal", 0, 0, ttf="1.0")
    with pytest.raises(RecordError, match=r"TrialRecord\.seed must be of type int"):
        make_record("mpc", "nominal", True, 0)
    typed = make_record("mpc", "nominal", np.int64(2), 0, ttf=np.float64(0.5), success=np.bool_(False))
    assert type(typed.seed) is int and type(typed.ttf) is float and typed.success is False
    assert typed["ttf"] == 0.5 and typed.pair_key == ("nominal", 2, 0)
    with pytest.raises(UnknownNameError, match="valid record fields: .*vlin_err"):
        typed["speed"]


# --- wbc.arena.stats --------------------------------------------------------------------------------------------------


def test_mean_std_over_seeds_by_hand():
    # seed 0: vlin_err 0.1 and 0.3 -> 0.2; seed 1: 0.4 -> 0.4; seed 2: 0.5, 0.7, nan -> 0.6 (nan ignored)
    records = [
        make_record("mpc", "nominal", 0, 0, vlin_err=0.1, success=True),
        make_record("mpc", "nominal", 0, 1, vlin_err=0.3, success=False),
        make_record("mpc", "nominal", 1, 0, vlin_err=0.4, success=True),
        make_record("mpc", "nominal", 2, 0, vlin_err=0.5, success=True),
        make_record("mpc", "nominal", 2, 1, vlin_err=0.7, success=True),
        make_record("mpc", "nominal", 2, 2, vlin_err=math.nan, success=False),
    ]
    stats = mean_std_over_seeds(records, "vlin_err")
    seed_means = np.array([0.2, 0.4, 0.6])
    assert stats["n_seeds"] == 3
    assert stats["mean"] == pytest.approx(0.4)
    assert stats["std"] == pytest.approx(math.sqrt(((seed_means - 0.4) ** 2).sum() / 2))  # = 0.2
    success = mean_std_over_seeds(records, "success")  # per seed: 0.5, 1.0, 2/3
    assert success["mean"] == pytest.approx((0.5 + 1.0 + 2 / 3) / 3)
    assert success["std"] == pytest.approx(np.std([0.5, 1.0, 2 / 3], ddof=1))


def test_mean_std_over_seeds_single_seed_and_all_nan():
    one_seed = [make_record("mpc", "nominal", 7, t, ttf=0.1 * t) for t in range(4)]
    assert mean_std_over_seeds(one_seed, "ttf") == {"mean": pytest.approx(0.15), "std": 0.0, "n_seeds": 1}
    no_fall = mean_std_over_seeds(one_seed, "fall_time_s")  # every fall_time_s is nan
    assert no_fall["n_seeds"] == 0 and math.isnan(no_fall["mean"]) and math.isnan(no_fall["std"])


def test_paired_difference_constant_offset_has_degenerate_ci():
    records_a = [make_record("a", "nominal", s, t, ttf=0.25 + 0.0625 * t) for s in SEEDS for t in range(N_TRIALS)]
    records_b = [dataclasses.replace(r, controller="b", ttf=r.ttf + 0.125) for r in records_a]
    result = paired_difference(records_a, records_b, "ttf")
    assert result == {"diff": 0.125, "ci95": [0.125, 0.125], "n": 30}
    reverse = paired_difference(records_b, records_a, "ttf")
    assert reverse["diff"] == -0.125  # positive diff: B larger


def _noisy_pair(n_pairs: int, seed: int) -> tuple[list[dict], list[dict]]:
    rng = np.random.default_rng(seed)
    records_a, records_b = [], []
    for t in range(n_pairs):
        base = float(rng.uniform(0.1, 0.3))
        records_a.append(make_record("a", "nominal", 0, t, vlin_err=base))
        records_b.append(make_record("b", "nominal", 0, t, vlin_err=base + 0.05 + float(rng.normal(0.0, 0.03))))
    return records_a, records_b


def test_paired_difference_noisy_ci_contains_diff_and_shrinks():
    small = paired_difference(*_noisy_pair(30, seed=1), "vlin_err")
    large = paired_difference(*_noisy_pair(300, seed=1), "vlin_err")
    for result in (small, large):
        lo, hi = result["ci95"]
        assert lo < result["diff"] < hi
        assert lo < 0.05 + 0.03 and hi > 0.05 - 0.03
    assert small["n"] == 30 and large["n"] == 300
    assert large["ci95"][1] - large["ci95"][0] < 0.6 * (small["ci95"][1] - small["ci95"][0])
    # deterministic: same seed, same interval; another bootstrap seed, another one
    assert paired_difference(*_noisy_pair(30, seed=1), "vlin_err") == small
    assert paired_difference(*_noisy_pair(30, seed=1), "vlin_err", seed=5)["ci95"] != small["ci95"]


def test_paired_difference_uses_only_common_keys():
    records_a = [make_record("a", "nominal", 0, t, success=False) for t in range(5)]
    records_a.append(make_record("a", "nominal", 1, 0, success=True))  # only A played this one
    records_b = [make_record("b", "nominal", 0, t, success=True) for t in range(5)]
    records_b += [make_record("b", "push", 0, 0, success=False), make_record("b", "nominal", 0, 99, success=False)]
    result = paired_difference(records_a, records_b, "success")
    assert result == {"diff": 1.0, "ci95": [1.0, 1.0], "n": 5}
    empty = paired_difference(records_a, [make_record("b", "other", 0, 0)], "success")
    assert empty["n"] == 0 and math.isnan(empty["diff"])


def test_paired_difference_rejects_repeated_trials():
    records = [make_record("a", "nominal", 0, 0), make_record("a", "nominal", 0, 0)]
    with pytest.raises(RecordError, match="twice"):
        paired_difference(records, records[:1], "ttf")


# --- wbc.arena.report -------------------------------------------------------------------------------------------------


def test_summary_has_exactly_the_required_shape():
    records = arena_records()
    summary = json_of(records)
    assert set(summary) == {"scenario", "controllers", "paired", "warnings"}
    assert summary["warnings"] == []
    assert summary["scenario"] == {"name": SCENARIO, "hash": HASH}
    assert list(summary["controllers"]) == list(CONTROLLERS)
    for entry in summary["controllers"].values():
        assert set(entry) == {"bands"}
        assert list(entry["bands"]) == list(BANDS)
        for cell in entry["bands"].values():
            assert cell["trials"] == len(SEEDS) * N_TRIALS
            assert cell["seeds"] == len(SEEDS)
            assert set(cell) == {"trials", "seeds", *METRICS, *EXTRA_METRICS, *COMMON_METRICS, "ticks",
                                 "deadline_misses", "clamped_ticks", "clamped_rows", "counters"}
            for metric in COMMON_METRICS:  # these records keep no per-second profile: no common window
                assert cell[metric] == {"mean": None, "std": None, "ci95": [None, None], "trials": 0}
            for metric in (*METRICS, *EXTRA_METRICS):
                assert set(cell[metric]) - {"all_equal"} == {"mean", "std", "ci95"}  # all_equal: when they are
                lo, hi = cell[metric]["ci95"]
                assert lo <= cell[metric]["mean"] <= hi
    cell = summary["controllers"]["mpc"]["bands"]["push"]
    mine = [r for r in records if r.controller == "mpc" and r.band == "push"]
    assert cell["success_rate"]["mean"] == pytest.approx(mean_std_over_seeds(mine, "success")["mean"])
    assert 0.0 <= cell["success_rate"]["mean"] <= 1.0

    pairs = [(p["a"], p["b"], p["band"], p["metric"]) for p in summary["paired"]]
    expected = [(a, b, band, m) for a, b in (("mpc", "rl"), ("mpc", "wbc"), ("rl", "wbc")) for band in BANDS
                for m in PAIRED_METRICS]
    assert pairs == expected
    for p in summary["paired"]:
        assert set(p) == {"a", "b", "band", "metric", "diff", "ci95", "interval", "n", "mean_a", "mean_b", "test",
                          "p", "n80", "a_only", "b_only", "shift", "rank_biserial", "p_holm", "all_equal",
                          "nonzero", "n80_holm", "n80_holm_tests"}
        assert len(p["ci95"]) == 2
        if p["metric"] in COMMON_METRICS:
            assert p["n"] == 0 and p["test"] is None
            continue
        assert p["n"] == len(SEEDS) * N_TRIALS and 0.0 < p["p"] <= 1.0
        assert p["interval"] == ("exact" if p["metric"] == "success_rate" else "bootstrap")
        assert p["test"] == ("exact McNemar" if p["metric"] == "success_rate" else "Wilcoxon signed-rank")
        assert (p["a_only"] is None) == (p["metric"] != "success_rate")
    assert json.loads(json.dumps(summary, allow_nan=False)) == summary


def test_summary_with_missing_cells_renders_null():
    records = [r for r in arena_records() if not (r.controller == "rl" and r.band == "push")]
    typed = summary_of(records, controllers=(*CONTROLLERS, "ghost"), bands=(*BANDS, "ice"))
    summary = typed.to_json()
    text = json.dumps(summary, allow_nan=False)  # no NaN may reach JSON
    assert json.loads(text) == summary
    assert summary["controllers"]["ghost"]["bands"]["nominal"] == {
        "trials": 0, "seeds": 0,
        **{m: {"mean": None, "std": None, "ci95": [None, None]} for m in (*METRICS, *EXTRA_METRICS)},
        **{m: {"mean": None, "std": None, "ci95": [None, None], "trials": 0} for m in COMMON_METRICS},
        "ticks": 0, "deadline_misses": 0, "clamped_ticks": 0, "clamped_rows": {}, "counters": {},
    }
    assert summary["controllers"]["rl"]["bands"]["push"]["trials"] == 0
    assert summary["controllers"]["mpc"]["bands"]["ice"]["ttf"] == {"mean": None, "std": None, "ci95": [None, None]}
    missing = [p for p in summary["paired"] if p["b"] == "rl" and p["band"] == "push"]
    assert missing and all(p["diff"] is None and p["ci95"] == [None, None] and p["p"] is None and p["n"] == 0
                           and p["n80"] is None for p in missing)
    assert "n/a" in format_table(typed)
    assert Summary.from_json(json.loads(text)) == typed  # the one JSON form reads back to the same summary


def test_summary_rejects_other_scenario_versions():
    records = arena_records()
    records[3] = dataclasses.replace(records[3], scenario_hash="other")
    with pytest.raises(RecordError, match="scenario hash"):
        summary_of(records)


def test_summary_does_not_depend_on_the_order_trials_finished_in():
    records = arena_records()
    # the data is order-sensitive: summing a seed's values in another order changes some means in the last digit
    cells = [[r for r in records if (r.controller, r.band) == (c, b)] for c in CONTROLLERS for b in BANDS]
    assert any(mean_std_over_seeds(cell, m) != mean_std_over_seeds(cell[::-1], m) for cell in cells
               for m in ("vlin_err", "vang_err", "energy_j"))
    want = json.dumps(json_of(records), indent=2)
    for seed in range(3):
        shuffled = list(records)
        np.random.default_rng(seed).shuffle(shuffled)
        assert json.dumps(json_of(shuffled), indent=2) == want
    assert in_canonical_order(records[::-1], CONTROLLERS, BANDS) == records  # arena_records is in canonical order
    assert in_canonical_order(records, ("wbc", "mpc"), ("push",)) == [
        r for c in ("wbc", "mpc") for r in records if r.controller == c and r.band == "push"]


def test_records_read_back_from_csv_give_the_same_summary(tmp_path):
    records = arena_records()
    back = through_csv(records, tmp_path / "trials.csv")
    assert json.dumps(json_of(back)) == json.dumps(json_of(records))


def test_format_table_lists_controllers_bands_and_pairs():
    summary = summary_of(arena_records())
    table = format_table(summary)
    for name in (*CONTROLLERS, *BANDS, SCENARIO, HASH):
        assert name in table
    assert "±" in table
    assert "paired differences (B - A, 95% CI)" in table
    for header in ("Success %", "TTF", "V_lin err", "V_ang err", "trials"):
        assert header in table
    # success in percent with 2 decimals, as in the paper
    rate = summary.cell("mpc", "nominal")["success_rate"]
    assert f"{100 * rate.mean:.2f} ± {100 * rate.std:.2f}" in table
    # deterministic, and the same on the summary read back from its JSON
    assert table == format_table(Summary.from_json(json.loads(json.dumps(summary.to_json()))))


def test_write_report_writes_markdown_and_plots(tmp_path):
    records = arena_records()
    summary = summary_of(records)
    meta = {"controllers": list(CONTROLLERS), "seeds": list(SEEDS), "trials": N_TRIALS, "executor": "serial",
            "versions": {"numpy": np.__version__}, "git": "deadbeef"}
    paths = write_report(tmp_path / "out", summary, records, meta)
    names = {p.name for p in paths}
    assert names == {"report.md", "ttf.png", "tracking.png"}  # push survival needs the push outcomes (curve)
    for path in paths:
        assert path.is_file() and path.parent == tmp_path / "out"
        if path.suffix == ".png":
            assert path.stat().st_size > 1024
            assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    report = (tmp_path / "out" / "report.md").read_text(encoding="utf-8")
    for text in (SCENARIO, HASH, "deadbeef", "serial", "numpy", "±", "(tracking.png)", "(ttf.png)", "## Verdict",
                 "## Controller counters", "## Timing and commands", *CONTROLLERS, *BANDS):
        assert text in report


def test_write_report_skips_push_plot_without_pushes(tmp_path):
    records = arena_records(pushes=False)
    paths = write_report(tmp_path, summary_of(records), through_csv(records, tmp_path / "trials.csv"), {})
    assert {p.name for p in paths} == {"report.md", "ttf.png", "tracking.png"}
    assert not (tmp_path / "push_recovery.png").exists()
    assert all(p.stat().st_size > 1024 for p in paths if p.suffix == ".png")
    assert "(push_recovery.png)" not in (tmp_path / "report.md").read_text(encoding="utf-8")


def test_tables_and_summaries_need_no_plotting_library():
    # text and plots apart: summarising and printing a table never imports matplotlib (wbc.arena.plots does, lazily)
    import subprocess
    import sys

    code = ("import sys\nfrom wbc.arena.report import format_table, summarize\n"
            "s = summarize([], scenario_name='x', scenario_hash='h', controllers=['a'], bands=['b'])\n"
            "format_table(s)\nprint('matplotlib' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


def test_a_warning_of_clamped_position_targets_alone_says_what_a_target_past_a_stop_means():
    """A PD target past a joint's stop is clamped to the stop on most ticks of a shipped policy: the warning stays,
    and says what it means, where clamped torques or gains get no such words."""
    from types import SimpleNamespace

    from wbc.arena.report import _warnings

    def cell(rows):
        return SimpleNamespace(ticks=1000, deadline_misses=0, clamped_ticks=935, clamped_rows=rows)

    (only_q,) = _warnings("learned", "1.5", cell({"q": 935}))
    assert only_q.text.startswith("learned in band 1.5: on 935 of 1000 ticks (93.5 %) the command lay outside")
    assert "(position targets on 935 ticks); position targets alone: a PD target past a joint's stop presses the " \
        "joint against it" in only_q.text
    (torques,) = _warnings("mpc", "2.0", cell({"q": 10, "tau": 935}))
    assert "position targets alone" not in torques.text and "feed-forward torques on 935 ticks" in torques.text
