"""``wbc paper table1|table2|table3``: the protocols, the paper's numbers beside ours, verdicts, the printed structure.

End to end on a tiny run (1 trial, 1 seed, 1.5 s trials of a short push scenario for the same robot), through the
command line: every row of the paper and of ours, the comparisons with their tests, where each contender fails and
the run time are printed, and ``paper.txt`` holds exactly what was printed. The results directory stays held until
``paper.txt`` and ``paper.json`` are written, checked with the real lock from a second file descriptor.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import os
import re
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from wbc.arena.results import LOCK_FILE
from wbc.arena.summary import PairSummary
from wbc.arena.verdict import p_clause
from wbc.cli.main import main
from wbc.errors import ConfigError, ResultsDirError, UnknownNameError
from wbc.learned.policy.shipped import WEIGHTS_DIR
from wbc.output_files import directory_holder, lock_directory
from wbc.scenario import check_published, load_scenario
from wbc.tools.paper import TABLE_I, TABLES, PaperRunConfig, resolve_contenders, run_paper_table, verdict
from wbc.tools.paper.format import _metric_block
from wbc.tools.paper.paper_table import PAPER_TRIALS_PER_BAND
from wbc.tools.paper.result import PaperTableResult, warm_trial_wall_s
from wbc.tools.paper.tables import paper_column

paper_table = importlib.import_module("wbc.tools.paper.paper_table")  # the module (the package re-exports names)

TINY_PUSH = """
[scenario]
name = "tinypush"
version = 1
description = "short push trials for the table command's test"
robot = "a1-wx200"
duration_s = 1.5

[terrain]
kind = "flat"

[domain]
friction = [0.8, 1.0]

[commands]
ramp_s = 0.2

[[commands.options]]
vx = 0.0

[[commands.options]]
vx = 0.3

[pushes]
first_s = [0.5, 0.6]
interval_s = [0.5, 0.6]
duration_s = 0.06
offset_m = 0.12

[[bands]]
name = "in"
push_force_n = [200.0, 300.0]

[[bands]]
name = "ood"
push_force_n = [300.0, 400.0]
"""


@pytest.fixture
def tiny(tmp_path):
    path = tmp_path / "tinypush.toml"
    path.write_text(TINY_PUSH)
    return path


@pytest.fixture
def tiny_protocol(tmp_path):
    """The tiny scenario under the push table's own name, published by a lock beside it: the paper's figures stand
    beside the bands of a published version of the table's scenario only."""
    from wbc.scenario import load_scenario as load

    folder = tmp_path / "protocol"
    folder.mkdir()
    path = folder / "push-tiny.toml"
    path.write_text(TINY_PUSH.replace('name = "tinypush"\nversion = 1', 'name = "push"\nversion = 99'))
    (folder / "published.toml").write_text(f'[push]\n"99" = "{load(path).hash}"\n')
    return path


def test_table1_end_to_end_prints_both_families_beside_the_paper(tiny_protocol, tmp_path, capsys):
    out = tmp_path / "t1"
    assert main(["paper", "table1", "--trials", "1", "--seeds", "1", "--scenario", str(tiny_protocol), "--out",
                 str(out), "--workers", "1", "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert (out / "paper.txt").read_text(encoding="utf-8") == printed
    lines = printed.splitlines()
    assert lines[0] == "Table I: locomotion under pushes, arm actuated / locked / absent"
    assert "scenario push v99" in printed and "NOT published" not in printed and "robot a1-wx200" in printed
    assert "no paper figures" not in printed
    assert "1 trials x 1 seed per band" in printed and "mean [95 % interval over trials" in printed
    # one block per metric; each paper row, then our learned and model-based rows beside it
    for label in ("Success %", "TTF", "V_lin err [m/s]"):
        assert label in lines
    block = lines[lines.index("Success %"):lines.index("TTF")]
    assert "in (paper 200-300)" in block[1] and "ood (paper 300-400)" in block[1]
    def row(*tokens):
        return next(i for i, line in enumerate(block) if tuple(line.split()[:len(tokens)]) == tokens)

    order = [row("No", "arm", "paper"), row("learned-noarm", "(pi1)"), row("mpc-noarm"), row("Locked", "paper"),
             row("learned-locked", "(pi2)"), row("mpc-locked"), row("Actuated", "paper"), row("learned", "(pi3)"),
             row("mpc"), row("mpc-tail")]
    assert order == sorted(order)
    assert "95.02 ± 0.62" in block[order[0]] and "68.03 ± 1.14" in block[order[0]]  # the paper's no-arm row
    assert "96.11 ± 0.37" in block[order[6]] and "78.20 ± 1.77" in block[order[6]]
    assert "[" in block[order[7]] and "± 0.00" not in "\n".join(block)  # one seed: an interval over trials
    # the six comparisons, each per band and metric, with its test and a verdict per band
    for question in ("actuated vs locked arm, learned (pi3 - pi2): B = learned (pi3), A = learned-locked (pi2)",
                     "actuated vs locked arm, model-based: B = mpc, A = mpc-locked",
                     "actuated arm vs no arm, model-based", "learned vs model-based, arm actuated"):
        assert question in printed
    assert "arm as a tail vs locked arm, model-based: B = mpc-tail, A = mpc-locked" in printed
    assert printed.count("  band in: Success: ") == 6 and printed.count("  band ood: Success: ") == 6
    assert "A only / B only" in printed and "n80" in printed
    # where each contender fails, per band, and the push-recovery curve
    assert "where each contender fails" in printed and "pushed forward" in printed and "offset y" in printed
    assert "push_recovery.png" in printed and (out / "push_recovery.png").is_file()
    assert "CPU hours here" in printed and "mean wall time per trial: learned" in printed
    saved = json.loads((out / "paper.json").read_text(encoding="utf-8"))
    assert saved["table"] == "table1" and saved["bands"] == ["in", "ood"] and saved["trials"] == 1
    assert len(saved["comparisons"]) == 6 * 2 * 3
    # the tests compare tracking over the seconds both survived; the cells stay over each trial's own time
    assert {c["metric"] for c in saved["comparisons"]} == {"success_rate", "ttf", "vlin_err_common"}
    assert "V_lin err, common [m/s]" in printed and "over the seconds both survived" in " ".join(printed.split())
    assert {c["controller"] for c in saved["contenders"]} == {"learned", "learned-locked", "learned-noarm", "mpc",
                                                              "mpc-tail", "mpc-locked", "mpc-noarm"}
    # our rows too, as summary.json holds them: what the table prints beside the paper's (it held the paper's only)
    assert saved["ours"] == json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert saved["columns_note"] is None and saved["band_columns"] == {"in": "200-300", "ood": "300-400"}
    assert set(saved["ours"]["controllers"]) == {c["controller"] for c in saved["contenders"]}
    # the n behind each side's figures: the paper's protocol beside its numbers, each of our cells' trials and seeds
    assert saved["paper_protocol"] == {"seeds": 5, "trials": 2000, "trials_per_seed": 400, "duration_s": 20.0,
                                       "note": ""}
    cell = saved["ours"]["controllers"]["learned"]["bands"]["in"]
    assert (cell["trials"], cell["seeds"], saved["trials"], saved["seeds"]) == (1, 1, 1, [0])
    # resuming the finished run plays nothing and prints the same table but for the run line
    assert main(["paper", "table1", "--trials", "1", "--seeds", "1", "--scenario", str(tiny_protocol), "--out",
                 str(out), "--workers", "1", "--quiet", "--resume"]) == 0
    again = capsys.readouterr().out
    assert again.split("\nrun: ")[0] == printed.split("\nrun: ")[0] and "run: 0 trials played" in again
    assert "(and 14 stored before, resumed: 14 in all)" in again and "resumed" not in printed.split("\nrun: ")[1]
    assert json.loads((out / "paper.json").read_text(encoding="utf-8"))["stored"] == 14
    # a row edited by hand is refused on --resume, naming its line; --drop-bad-rows drops it and plays it again
    lines = (out / "trials.csv").read_text(encoding="utf-8").splitlines(keepends=True)
    row = lines[3].rstrip("\n")
    lines[3] = row[:-1] + ("0" if row[-1] != "0" else "1") + "\n"  # its checksum no longer matches its cells
    (out / "trials.csv").write_text("".join(lines), encoding="utf-8")
    again_argv = ["paper", "table1", "--trials", "1", "--seeds", "1", "--scenario", str(tiny_protocol), "--out",
                  str(out), "--workers", "1", "--quiet", "--resume"]
    assert main(again_argv) == 2
    assert f"{out / 'trials.csv'}:4:" in capsys.readouterr().err
    assert main([*again_argv, "--drop-bad-rows"]) == 0
    captured = capsys.readouterr()
    assert f"{out / 'trials.csv'}:4:" in captured.err and "row dropped (--drop-bad-rows)" in captured.err
    assert "run: 1 trials played" in captured.out


def test_table3_lists_its_baselines_and_says_which_are_missing(tiny_protocol, tmp_path):
    result = run_paper_table(PaperRunConfig(table="table3", trials=1, seeds=1, scenario=tiny_protocol,
                                            out_dir=tmp_path / "t3", workers=1, progress=False))
    shipped = {p.stem.removeprefix("a1-wx200-actuated-") for p in WEIGHTS_DIR.glob("a1-wx200-actuated-*.npz")
               if not p.stem.endswith("crouched")}  # the crouched variants play with --crouched
    rows = {c.key: c for c in result.contenders}
    for key in ("ppo", "curriculum", "finetune-pi2", "decoupled", "one-stage-demo"):
        assert (rows[key].controller is not None) == (key in shipped)
    text = (tmp_path / "t3" / "paper.txt").read_text(encoding="utf-8")
    baselines = {"ppo", "curriculum", "finetune-pi2", "decoupled", "one-stage-demo"}
    for key in baselines - shipped:
        assert f"({key}): no shipped weights (train: wbc train --task push --stage 3 --baseline {key}" in text
        assert f"{key}: missing" in text
    for key in shipped & baselines:
        assert f"{key} = policy:" in text
    # beside the paper's rows: the distilled MPC and its expert, in rows the paper does not have, compared
    assert rows["mpc"].controller == "mpc" and rows["mpc-distilled"].controller == (
        "mpc-distilled" if "mpc-distilled" in shipped else None)
    assert "MPC distilled (not in the paper)" in text and "MPC (not in the paper)" in text
    assert "MPC distilled vs its expert, mpc" in text
    assert "Ours vs PPO: B = learned" in text or "ppo" not in shipped
    assert "95.73" in text and "84.73" in text  # the paper's "Ours"
    # 2 trials per controller on one worker: the estimate leaves out the first (the slower), which compiles
    assert set(result.warm_wall_s) == set(result.trial_wall_s) and not result.estimate_includes_compile
    assert result.paper_protocol_cpu_h == pytest.approx(
        sum(result.warm_wall_s.values()) * PAPER_TRIALS_PER_BAND * 2 / 3600)
    assert "each worker's first trial of a controller left out" in " ".join(text.split())  # wrapped


def test_the_run_time_estimate_leaves_out_each_workers_first_trial():
    # a worker's first trial of a controller compiles its numba code on a fresh machine: 89 s, against ~11 s after
    assert warm_trial_wall_s([89.0, 11.0, 12.0], workers=1) == pytest.approx(11.5)
    assert warm_trial_wall_s([80.0, 10.0, 85.0, 12.0, 11.0], workers=2) == pytest.approx(11.0)
    assert warm_trial_wall_s([89.0], workers=1) is None and warm_trial_wall_s([89.0, 80.0], workers=2) is None


def test_the_paper_files_are_written_while_the_results_directory_is_still_held(tiny, tmp_path, monkeypatch):
    # as each paper file is written, the directory's lock is tried from a second file descriptor, as a `wbc paper
    # --resume` or `wbc compare --resume` started at that moment would try it: it must find this run holding it
    out = tmp_path / "t3"
    holders = {}
    write = paper_table.write_text

    def write_and_check(path, text):
        holders[Path(path).name] = directory_holder(Path(path).parent)
        write(path, text)

    monkeypatch.setattr(paper_table, "write_text", write_and_check)
    run_paper_table(PaperRunConfig(table="table3", trials=1, seeds=1, scenario=tiny, out_dir=out, workers=1,
                                   progress=False))
    assert set(holders) == {"paper.txt", "paper.json"}
    for name, holder in holders.items():
        assert holder is not None, f"{name} was written with {out} free to another run"
        assert holder.pid == os.getpid()
    lock_directory(out).release()  # given back once they are written


def test_a_paper_run_on_a_directory_another_run_holds_is_refused_before_anything_is_played(tiny, tmp_path):
    out = tmp_path / "held"
    out.mkdir()
    with lock_directory(out):
        with pytest.raises(ResultsDirError, match=re.escape(f"{out} is in use by another wbc run (pid {os.getpid()})")):
            run_paper_table(PaperRunConfig(table="table3", trials=1, seeds=1, scenario=tiny, out_dir=out, workers=1,
                                           progress=False))
    assert [p.name for p in out.iterdir()] == [LOCK_FILE]


@pytest.fixture
def refusing_plugin(tmp_path, monkeypatch):
    """A plug-in whose factory raises, importable as ``paperrefused:make``."""
    root = tmp_path / "refusedroot"
    root.mkdir()
    (root / "paperrefused.py").write_text('"""Builds no controller."""\n\n\n'
                                          "def make(desc):\n"
                                          '    raise RuntimeError("no weights for this robot")\n', encoding="utf-8")
    monkeypatch.syspath_prepend(str(root))
    yield "paperrefused:make"
    sys.modules.pop("paperrefused", None)


REFUSED_INPUT = {
    "an unknown controller": (["table1", "--contender", "learned=nosuch"], "nosuch"),
    "a missing policy file": (["table1", "--contender", "learned=policy:{tmp}/missing"], "missing"),
    "a controller for another robot": (["table2", "--contender", f"learned=policy:{WEIGHTS_DIR}/a1-wx200-actuated"],
                                       "drives a1-wx200"),
    "a plug-in whose factory raises": (["table1", "--contender", "mpc={plugin}"], "no weights for this robot"),
    "a controller of another arm mode than its row's": (
        ["table1", "--contender", f"learned=policy:{WEIGHTS_DIR}/a1-wx200-locked"],
        f"--contender learned=policy:{WEIGHTS_DIR}/a1-wx200-locked: it plays with the arm 'locked', and table1's row "
        "learned (Actuated) stands for the arm 'actuated'"),
    "--drop-bad-rows without --resume": (["table1", "--drop-bad-rows"], "--drop-bad-rows"),
    "more trials than a run plays": (["table1", "--trials", "100000", "--seeds", "10"], "more than the"),
}


@pytest.mark.parametrize("case", REFUSED_INPUT)
def test_a_paper_run_refused_for_its_input_creates_no_directory(case, tiny, tmp_path, capsys, refusing_plugin):
    # as wbc compare, everything the input can refuse is checked before --out (and its missing parent) is created
    args, said = REFUSED_INPUT[case]
    table, *options = [a.format(tmp=tmp_path, plugin=refusing_plugin) for a in args]
    scenario = tiny
    if table == "table2":
        scenario = tmp_path / "tinyturn.toml"
        scenario.write_text(TINY_PUSH.replace('robot = "a1-wx200"', 'robot = "go1-arm"'))
    out = tmp_path / "new" / "paper"
    assert main(["paper", table, "--trials", "1", "--seeds", "1", "--scenario", str(scenario), "--out", str(out),
                 "--workers", "1", "--quiet", *options]) == 2
    assert said in capsys.readouterr().err
    assert not (tmp_path / "new").exists()


def test_a_refused_paper_run_leaves_a_directory_with_results_as_it_was(tiny, tmp_path, capsys):
    out = tmp_path / "done"
    out.mkdir()
    stored = {"trials.csv": "a row\n", "run.json": "{}", "paper.txt": "the table\n"}
    for name, text in stored.items():
        (out / name).write_text(text)
    base = ["paper", "table1", "--trials", "1", "--seeds", "1", "--scenario", str(tiny), "--out", str(out),
            "--workers", "1", "--quiet"]
    assert main([*base, "--contender", "learned=nosuch"]) == 2  # refused before the directory is taken
    assert {p.name: p.read_text() for p in out.iterdir()} == stored
    assert main(base) == 2  # refused by the results store, the directory held: it already holds a run
    assert "already holds results" in capsys.readouterr().err
    assert {p.name: p.read_text() for p in out.iterdir() if p.name != LOCK_FILE} == stored


def test_a_paper_run_stopped_before_it_stored_anything_removes_the_directory_it_created(tiny, tmp_path,
                                                                                       monkeypatch):
    # Ctrl-C, or a refusal that comes only once the directory is held, before the results store wrote anything there
    def stopped(plan, *, lock):
        assert lock.held and [p.name for p in plan.cfg.out_dir.iterdir()] == [LOCK_FILE]
        raise KeyboardInterrupt

    monkeypatch.setattr(paper_table, "play_arena", stopped)
    config = {"table": "table1", "trials": 1, "seeds": 1, "scenario": tiny, "workers": 1, "progress": False}
    with pytest.raises(KeyboardInterrupt):
        run_paper_table(PaperRunConfig(out_dir=tmp_path / "new" / "paper", **config))
    assert not (tmp_path / "new").exists()
    mine = tmp_path / "mine"
    mine.mkdir()  # the user's: it stays, with the lock file any run leaves
    with pytest.raises(KeyboardInterrupt):
        run_paper_table(PaperRunConfig(out_dir=mine, **config))
    assert [p.name for p in mine.iterdir()] == [LOCK_FILE]


def test_contenders_can_be_replaced_and_tables_check_their_robot(tiny):
    spec = TABLES["table1"]
    rows = resolve_contenders(spec, {"learned": "policy:runs/v2/policy"})
    assert next(c for c in rows if c.key == "learned").controller == "policy:runs/v2/policy"
    with pytest.raises(UnknownNameError, match="learned-locked"):
        resolve_contenders(spec, {"pi9": "stand"})
    with pytest.raises(ConfigError, match="same controller"):
        resolve_contenders(spec, {"learned": "mpc"})
    with pytest.raises(ConfigError, match="go1-arm"):
        run_paper_table(PaperRunConfig(table="table2", scenario=tiny, progress=False))
    with pytest.raises(UnknownNameError):
        PaperRunConfig(table="table4")
    assert main(["paper", "table1", "--contender", "learned"]) == 2


def test_verdicts_name_the_better_side_only_when_the_test_says_so():
    def pair(metric, diff, p, n80=42):
        return PairSummary(a="pi2", b="pi3", band="in", metric=metric, diff=diff, ci95=(None, None), interval=None,
                           n=10, mean_a=None, mean_b=None, test="exact McNemar", p=p, n80=n80, a_only=None,
                           b_only=None)

    assert verdict(pair("success_rate", 0.2, 0.01)) == "Success: pi3 better (pi3 - pi2 = +20.00 points, p = 0.01)"
    assert verdict(pair("vlin_err", 0.02, 0.001)) == "V_lin err: pi2 better (pi2 - pi3 = -0.020 m/s, p = 0.001)"
    assert verdict(pair("success_rate", 0.05, 0.5)) == (
        "Success: no significant difference (p = 0.5; 42 pairs would detect the observed difference)")
    assert verdict(pair("ttf", 0.0, 1.0, n80=None)) == "TTF: no significant difference (p = 1)"


def test_a_paper_verdict_follows_the_side_the_test_leans_to_as_the_arenas_does():
    def pair(metric, diff, p, rank_biserial):
        return PairSummary(a="pi2", b="pi3", band="in", metric=metric, diff=diff, ci95=(None, None), interval=None,
                           n=21, mean_a=None, mean_b=None, test="Wilcoxon signed-rank", p=p, n80=40, a_only=None,
                           b_only=None, shift=0.01 if rank_biserial > 0 else -0.01, rank_biserial=rank_biserial)

    # 20 pairs 0.01 worse and one 1.0 better: the mean favours pi3, the test finds pi3 worse on most pairs
    split = verdict(pair("vlin_err_common", -0.038, 0.0002, 0.82))
    assert split.startswith("V_lin err, common: neither called better") and "pi3 better" not in split
    assert "ranks favour pi2" in split and "favours pi3" in split
    # TTF the other way round; a mean difference of 0 follows the test
    assert "neither called better" in verdict(pair("ttf", 0.036, 0.0002, -0.82))
    assert verdict(pair("ttf", 0.0, 0.002, 0.78)).startswith("TTF: pi3 better")
    # the common-window errors are errors: smaller is better
    assert verdict(pair("vang_err_common", -0.02, 0.001, -0.9)).startswith("V_ang err, common: pi3 better")
    # significant means p < alpha, as everywhere else
    assert verdict(pair("ttf", 0.05, 0.05, 0.9)).startswith("TTF: no significant difference (p = 0.05")


def test_the_paired_tests_of_tracking_use_the_common_window():
    assert TABLES["table1"].paired_metrics == ("success_rate", "ttf", "vlin_err_common")
    assert TABLES["table2"].paired_metrics == ("success_rate", "vang_err_common", "vlin_err_common")
    assert TABLES["table3"].paired_metrics == ("success_rate", "ttf", "vlin_err_common")
    assert TABLES["table1"].metrics == ("success_rate", "ttf", "vlin_err")  # the cells: the paper's own time


def _pair(metric, diff, p, *, a="mpc", b="pi3"):
    test = "exact McNemar" if metric == "success_rate" else "Wilcoxon signed-rank"
    return PairSummary(a=a, b=b, band="in", metric=metric, diff=diff, ci95=(None, None), interval=None, n=40,
                       mean_a=None, mean_b=None, test=test, p=p, n80=None, a_only=None, b_only=None)


def _said_difference(text):
    """The side a verdict names better, and the difference it writes: (better, minuend, subtrahend, signed value)."""
    found = re.fullmatch(r"[^:]+: (\S+) better \((\S+) - (\S+) = ([+-][\d.e+-]+)(?: points| m/s)?, p [=<] .+\)", text)
    assert found, text
    return found.group(1), found.group(2), found.group(3), float(found.group(4))


@pytest.mark.parametrize("diff", [-0.175, 0.175])
def test_a_success_verdicts_sign_agrees_with_the_side_it_calls_better(diff):
    # B - A = -17.5 points with A = mpc: mpc survives more, and its lead is written as a positive mpc - pi3
    said = verdict(_pair("success_rate", diff, 0.02))
    better, first, second, value = _said_difference(said)
    assert better == first == ("pi3" if diff > 0 else "mpc") and second == ("mpc" if diff > 0 else "pi3")
    assert value == pytest.approx(17.5)
    assert said == f"Success: {better} better ({better} - {second} = +17.50 points, p = 0.02)"


@pytest.mark.parametrize("diff", [-0.027, 0.027])
def test_an_error_verdicts_sign_agrees_with_the_side_it_calls_better(diff):
    # a smaller error is better: the better side's error minus the other's is negative
    said = verdict(_pair("vlin_err_common", diff, 3e-5))
    better, first, second, value = _said_difference(said)
    assert better == first == ("mpc" if diff > 0 else "pi3") and second == ("pi3" if diff > 0 else "mpc")
    assert value == pytest.approx(-0.027)
    assert said == f"V_lin err, common: {better} better ({better} - {second} = -0.027 m/s, p < 1e-4)"


def test_a_split_verdict_names_the_sides_of_its_mean_difference():
    entry = dataclasses.replace(_pair("ttf", 0.036, 0.0002, a="pi2", b="pi3"), rank_biserial=-0.82, shift=-0.01)
    assert verdict(entry) == ("TTF: neither called better (p = 0.0002; the pairs' ranks favour pi2, the mean "
                              "difference (pi3 - pi2 = +0.036) favours pi3)")


def test_a_verdict_writes_its_p_value_as_the_arenas_verdicts_do():
    assert [p_clause(p) for p in (3e-5, 1e-4, 0.0156, None)] == ["p < 1e-4", "p = 0.0001", "p = 0.0156", "p = n/a"]
    for entry in (_pair("vlin_err_common", 0.027, 3e-5), _pair("success_rate", 0.0, 3e-5)):
        said = verdict(entry)
        assert "p < 1e-4" in said and "p = <" not in said and "<1e-04" not in said
    assert "(p = 0.5;" in verdict(_pair("success_rate", 0.05, 0.5))


def test_the_papers_numbers_are_printed_with_the_papers_own_digits():
    def paper_row(name, metric, row):
        spec = TABLES[name]
        result = SimpleNamespace(spec=spec, contenders=(), bands=spec.paper_columns,
                                 band_columns=tuple(range(len(spec.paper_columns))),
                                 summary=SimpleNamespace(cell=lambda controller, band: None))
        lines = [[cell.strip() for cell in line.split("  ") if cell.strip()] for line in _metric_block(result, metric)]
        return next(line[2:] for line in lines if line[:2] == [row, "paper"])

    # the paper gives TTF and Table I's errors a std of two decimals: no third digit it never gave
    assert paper_row("table1", "ttf", "No arm") == ["0.975 ± 0.00", "0.809 ± 0.01"]
    assert paper_row("table1", "vlin_err", "Actuated") == ["0.027 ± 0.00", "0.120 ± 0.02"]
    assert paper_row("table1", "success_rate", "Actuated") == ["96.11 ± 0.37", "78.20 ± 1.77"]
    assert paper_row("table2", "vang_err", "Locked") == ["0.234 ± 0.012", "0.228 ± 0.010", "0.226 ± 0.008"]
    assert paper_row("table3", "ttf", "Ours") == ["0.975", "0.916"]
    # the values behind the digits, in the arena's units (success as a fraction)
    actuated = TABLE_I["Actuated"]
    assert (actuated["ttf"][0].mean, actuated["ttf"][0].std) == (0.982, 0.0)
    assert (actuated["success_rate"][1].mean, actuated["success_rate"][1].std) == (0.782, 0.0177)
    assert TABLES["table3"].paper["Ours"]["ttf"][1].std is None


def _result(name):
    spec = TABLES[name]
    return PaperTableResult(spec=spec, contenders=spec.contenders, scenario={}, bands=("in", "ood"),
                            band_columns=(0, 1), trials=4, seeds=(0, 1), summary=SimpleNamespace(to_json=dict),
                            comparisons=(), failures={}, curve={}, trial_wall_s={}, warm_wall_s={},
                            out_dir=Path("runs/x"), played=0, wall_s=0.0, workers=1)


def test_paper_json_holds_the_papers_n_beside_its_numbers():
    saved = json.loads(json.dumps(_result("table1").as_dict()))
    assert saved["paper_protocol"] == {"seeds": 5, "trials": 2000, "trials_per_seed": 400, "duration_s": 20.0,
                                       "note": ""}
    assert saved["paper"]["No arm"]["ttf"][0] == {"mean": 0.975, "std": 0.0, "printed": "0.975 ± 0.00"}
    assert saved["paper"]["No arm"]["success_rate"][0] == {"mean": 0.9502, "std": 0.0062, "printed": "95.02 ± 0.62"}
    table3 = json.loads(json.dumps(_result("table3").as_dict()))
    assert table3["paper_protocol"] == {"seeds": None, "trials": 2000, "trials_per_seed": None, "duration_s": 20.0,
                                        "note": "half standing, half at 0.3 m/s"}
    assert table3["paper"]["Ours"]["success_rate"][1] == {"mean": 0.8473, "std": None, "printed": "84.73"}
    # the header says the same protocol as before
    assert [TABLES[t].paper_protocol.text for t in ("table1", "table2", "table3")] == [
        "5 seeds, 2000 trials, 20 s each",
        "5 seeds, 2000 trials, 20 s each; yaw rate 0.5 rad/s in half the trials, 2 rad/s in the rest",
        "2000 trials, 20 s each; half standing, half at 0.3 m/s"]


def test_the_table_headings_hold_for_the_papers_rows_and_ours():
    spec = TABLES["table1"]
    contenders = tuple(c for c in spec.contenders if c.key in ("learned", "mpc"))
    result = SimpleNamespace(spec=spec, contenders=contenders, bands=("in", "ood"), band_columns=(0, 1),
                             summary=SimpleNamespace(cell=lambda controller, band: None))
    lines = [[cell.strip() for cell in line.split("  ") if cell.strip()] for line in _metric_block(result, "ttf")]
    assert lines[1] == ["row", "paper / ours", "in (paper 200-300)", "ood (paper 300-400)"]
    actuated = lines.index(["Actuated", "paper", "0.982 ± 0.00", "0.875 ± 0.01"])
    # under "paper / ours": the paper's line says paper, ours name their controller
    assert lines[actuated + 1] == ["learned (pi3)", "n/a", "n/a"] and lines[actuated + 2] == ["mpc", "n/a", "n/a"]


def test_a_verdict_from_one_pair_says_that_one_pair_cannot_size_the_test():
    one = PairSummary(a="pi2", b="pi3", band="in", metric="ttf", diff=1.5, ci95=(None, None), interval=None, n=1,
                      mean_a=None, mean_b=None, test="Wilcoxon signed-rank", p=1.0, n80=None, a_only=None, b_only=None)
    assert verdict(one) == ("TTF: no significant difference (p = 1; one pair shows no spread to tell how many pairs "
                            "would detect the observed difference)")


def test_the_paper_rows_are_the_published_ones():
    assert [row for row in TABLE_I] == ["No arm", "Locked", "Actuated"]
    assert TABLE_I["Locked"]["success_rate"][1].mean == pytest.approx(0.4583)
    assert TABLES["table3"].paper["Ours"]["success_rate"][1].mean == pytest.approx(0.8473)
    assert TABLES["table2"].paper["Locked"]["vang_err"][2].mean == pytest.approx(0.226)


def test_the_push_tables_play_the_current_push_version_by_default():
    # version 2, recalibrated on the locked-arm contenders; version 1 stays playable with --scenario
    for name in ("table1", "table3"):
        scenario = load_scenario(TABLES[name].scenario)
        assert (scenario.name, scenario.version, scenario.robot) == ("push", 2, TABLES[name].robot)
        check_published(scenario)


def test_the_crouched_option_plays_every_learned_rows_posture_variant_under_the_same_keys():
    for name in ("table1", "table2"):
        rows = {c.key: c for c in resolve_contenders(TABLES[name], {}, crouched=True)}
        assert {k: c.controller for k, c in rows.items() if c.family == "learned"} == {
            "learned": "learned-crouched", "learned-locked": "learned-locked-crouched",
            "learned-noarm": "learned-noarm-crouched"}
        assert {c.controller for c in rows.values() if c.family == "model-based"} == {"mpc", "mpc-tail", "mpc-locked",
                                                                                       "mpc-noarm"}
    rows = {c.key: c for c in resolve_contenders(TABLES["table3"], {"ppo": "policy:runs/ppo/policy"}, crouched=True)}
    assert rows["ours"].controller == "learned-crouched" and rows["ppo"].controller == "policy:runs/ppo/policy"
    for key in ("curriculum", "finetune-pi2", "decoupled", "one-stage-demo"):
        weights = WEIGHTS_DIR / f"a1-wx200-actuated-{key}-crouched.npz"
        if weights.is_file():
            assert rows[key].controller.endswith(f"a1-wx200-actuated-{key}-crouched")
        else:
            assert rows[key].controller is None and weights.name in rows[key].note
    # the comparisons are the same pairs of keys, so every contrast finds both sides
    for name, spec in TABLES.items():
        keys = {c.key for c in spec.crouched_contenders}
        assert all(c.a in keys and c.b in keys for c in spec.contrasts), name


def test_a_contender_that_fails_costs_its_trials_and_the_command_exits_1(tiny, tmp_path, capsys, monkeypatch):
    root = tmp_path / "pkgroot"
    root.mkdir()
    (root / "paperbroken.py").write_text(
        '"""Raises on its first tick."""\n'
        "from wbc.control.stand import StandController\n\n\n"
        "class Broken(StandController):\n"
        "    def act(self, state, command):\n"
        '        raise RuntimeError("no estimate")\n\n\n'
        "def make(desc):\n"
        "    return Broken(desc)\n", encoding="utf-8")
    monkeypatch.syspath_prepend(str(root))
    out = tmp_path / "t2"
    try:
        code = main(["paper", "table1", "--trials", "1", "--seeds", "1", "--scenario", str(tiny), "--out", str(out),
                     "--workers", "1", "--quiet", "--contender", "mpc=paperbroken:make"])
    finally:
        sys.modules.pop("paperbroken", None)
    captured = capsys.readouterr()
    assert code == 1
    lines = [line for line in captured.err.splitlines() if line.startswith("wbc: controller ")]
    assert len(lines) == 1 and lines[0].startswith("wbc: controller paperbroken:make: 2 of 2 trial(s) failed with a "
                                                   "controller error; first: ")
    assert "Table I" in captured.out  # the table is printed all the same, the other contenders' rows included
    # a scenario of another name than the table's: the paper's figures stand beside none of its bands, and it says why
    assert ("no paper figures beside our bands: the paper's task is that of scenario 'push' (its published "
            "versions), and 'tinypush' plays another.") in " ".join(captured.out.split())


def test_the_paper_figures_stand_only_beside_a_published_version_of_the_tables_own_scenario(tmp_path):
    """A band's settings alone do not make the paper's task: turn-both-ways' 1.0 band turns right or runs straight,
    push-strong's pushes last longer, push-low-friction is slippery; an edited copy of turn.toml plays what it was
    edited to. None of them has the paper's figures beside it, and the reason is said."""
    from wbc.tools.paper.tables import paper_columns_of

    turn, push = TABLES["table2"], TABLES["table1"]
    assert paper_columns_of(turn, load_scenario("scenarios/turn.toml"), published=True) == ((0, 1, 2), None)
    for table in (push, TABLES["table3"]):
        for path in ("scenarios/push.toml", "scenarios/push-v1.toml"):
            assert paper_columns_of(table, load_scenario(path), published=True) == ((0, 1), None)
    for table, path in ((turn, "scenarios/turn-both-ways.toml"), (push, "scenarios/push-strong.toml"),
                        (push, "scenarios/push-low-friction.toml"), (TABLES["table3"], "scenarios/push-strong.toml")):
        scenario = load_scenario(path)
        columns, why = paper_columns_of(table, scenario, published=True)
        assert columns == (None,) * len(scenario.bands)
        assert why == (f"no paper figures beside our bands: the paper's task is that of scenario "
                       f"{table.protocol_scenario!r} (its published versions), and {scenario.name!r} plays another")
    columns, why = paper_columns_of(turn, load_scenario("scenarios/turn.toml"), published=False)
    assert columns == (None, None, None) and "this copy of scenario 'turn' is not published" in why


def test_a_band_stands_beside_the_paper_column_that_commands_what_it_does():
    spec = TABLES["table2"]
    columns = {path: tuple(paper_column(spec, load_scenario(path).band_settings(b)) for b in load_scenario(path).bands)
               for path in ("scenarios/turn.toml", "scenarios/turn-both-ways.toml")}
    # the published turn: each band in its column, as before; turn-both-ways: stand and 2.0 have no paper figure
    assert columns == {"scenarios/turn.toml": (0, 1, 2), "scenarios/turn-both-ways.toml": (None, 0, 2, None)}
    for path in ("scenarios/push.toml", "scenarios/push-v1.toml", "scenarios/push-strong.toml"):
        scenario = load_scenario(path)
        assert [paper_column(TABLES["table1"], scenario.band_settings(b)) for b in scenario.bands] == [0, 1]
    # a band that also fixes the yaw rate, or another force, is not the paper's column
    assert paper_column(spec, {"vx": 1.25, "yaw_rate": 0.5}) is None
    assert paper_column(TABLES["table1"], {"push_force_n": (200.0, 350.0)}) is None

    def block(bands, band_columns):
        result = SimpleNamespace(spec=spec, contenders=(), bands=bands, band_columns=band_columns,
                                 summary=SimpleNamespace(cell=lambda controller, band: None))
        return [line.split("  ") for line in _metric_block(result, "success_rate")]

    def cells(lines):
        return [[cell.strip() for cell in line if cell.strip()] for line in lines]

    both = cells(block(("stand", "1.0", "1.5", "2.0"), columns["scenarios/turn-both-ways.toml"]))
    assert both[1] == ["row", "paper / ours", "stand", "1.0 (paper 1)", "1.5 (paper 1.5)", "2.0"]
    assert both[3] == ["No arm", "paper", "-", "90.29 ± 0.46", "86.48 ± 0.85", "-"]
    turn = cells(block(("1.0", "1.25", "1.5"), columns["scenarios/turn.toml"]))
    assert turn[1] == ["row", "paper / ours", "1.0 (paper 1)", "1.25 (paper 1.25)", "1.5 (paper 1.5)"]
    assert turn[3] == ["No arm", "paper", "90.29 ± 0.46", "89.14 ± 0.70", "86.48 ± 0.85"]
