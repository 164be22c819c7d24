"""What a results directory records of how its run was made, and that it never shows more than it holds.

A resume removes the files derived from ``trials.csv`` (summary, report, plots, a paper's files) and the completion
mark before it touches anything, and the run's end writes them again, the mark last; ``run.json`` records the code
(the hash of the wbc package's files; a checkout's uncommitted changes kept as ``wbc.diff``), the command, executor,
workers, time limit and times of every call, and copies of its input files; a run resumed under other code says so
in ``summary.json``; every trial seeds the global random generators from its identity.
"""

from __future__ import annotations

import argparse
import copy
import csv
import dataclasses
import io
import json
import math
import random
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from conftest import SHORT_SCENARIO, STAND_PLUGIN

from wbc.arena import results as results_module
from wbc.arena import worker_check
from wbc.arena.compare import ArenaConfig, run_arena
from wbc.arena.identity import RunIdentity
from wbc.arena.results import DERIVED_FILES, ResultsStore, is_complete
from wbc.arena.sim_trial import run_trial
from wbc.arena.trial_record import (
    ADDED_COLUMNS,
    COLUMNS,
    MACHINE_TIMED,
    PREVIOUS_COLUMNS,
    TrialRecord,
    checksum_of,
)
from wbc.cli.main import _interrupted_run
from wbc.errors import RecordError, ResultsDirError
from wbc.provenance import package_files_sha256, package_sha256, provenance
from wbc.scenario import load_scenario


def _config(scenario: Path, out: Path, **changes) -> ArenaConfig:
    options = {"controllers": ("stand",), "scenario": scenario, "seeds": (0,), "trials": 2, "out_dir": out,
               "workers": 1, "progress": False, "command": "compare", **changes}
    return ArenaConfig(**options)


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A finished run of ``stand`` on the short scenario, 2 trials, played in this process: (scenario, directory)."""
    tmp = tmp_path_factory.mktemp("record")
    scenario = tmp / "short.toml"
    scenario.write_text(SHORT_SCENARIO)
    out = tmp / "done"
    run_arena(_config(scenario, out, command_line="wbc compare stand --trials 2"))
    return scenario, out


@pytest.fixture
def copy_of(finished, tmp_path: Path):
    scenario, out = finished
    mine = tmp_path / "o"
    shutil.copytree(out, mine)
    return scenario, mine


def _run(out: Path) -> dict:
    return json.loads((out / "run.json").read_text(encoding="utf-8"))


# -- 1. a directory never looks complete with fewer trials than its summary -----------------------------------------
def test_a_finished_run_is_marked_complete_last_with_its_trial_count(finished) -> None:
    _, out = finished
    run = _run(out)
    assert run["complete"]["trials"] == 2 and is_complete(out)
    assert run["sessions"][-1]["ended_utc"] == run["complete"]["ended_utc"]


def test_a_resume_removes_the_derived_files_and_the_mark_before_it_plays(copy_of, capsys) -> None:
    # an edited row, dropped and to be played again: the run stops (killed) before its first trial
    _, out = copy_of
    lines = (out / "trials.csv").read_text(encoding="utf-8").splitlines(keepends=True)
    lines[1] = lines[1].replace("stand", "stend", 1)
    (out / "trials.csv").write_text("".join(lines), encoding="utf-8")
    (out / "paper.json").write_text("{}")  # a paper's files are derived from the trials too
    held = [name for name in DERIVED_FILES if (out / name).exists()]
    assert {"summary.json", "report.md", "failures.json", "paper.json"} <= set(held)
    store = ResultsStore(out, RunIdentity.load(out / "run.json"), resume=True, drop_bad_rows=True)
    store.close()  # as if killed here: no trial played, no finish
    assert len(store.records) == 1
    assert [name for name in DERIVED_FILES if (out / name).exists()] == []
    assert "complete" not in _run(out) and not is_complete(out)
    capsys.readouterr()


def test_an_interruption_says_which_derived_files_exist(copy_of) -> None:
    _, out = copy_of
    args = argparse.Namespace(out=str(out), results_dir=out)
    said = _interrupted_run(args)
    assert "summary.json, failures.json, report.md" in said and "not yet written" not in said, said
    for name in DERIVED_FILES:
        (out / name).unlink(missing_ok=True)
    assert "its summary and report are not yet written" in _interrupted_run(args)


# -- 2. the code, outside git too -------------------------------------------------------------------------------------
def test_the_package_hash_covers_every_file_but_caches(tmp_path: Path) -> None:
    root = tmp_path / "wbc"
    (root / "control").mkdir(parents=True)
    (root / "control" / "stand.py").write_text("KP = 1.0\n")
    (root / "weights.npz").write_bytes(b"\x00\x01")
    first = package_files_sha256(root)
    (root / "__pycache__").mkdir()
    (root / "__pycache__" / "x.cpython-311.pyc").write_bytes(b"cache")
    (root / "control" / "stand.nbi").write_bytes(b"numba")
    assert package_files_sha256(root) == first
    # strays no install holds: a desktop's folder file, an editor's swap file and backup, a patch's leftovers
    (root / ".DS_Store").write_bytes(b"finder")
    (root / "control" / ".stand.py.swp").write_bytes(b"vim")
    (root / "control" / "stand.py~").write_text("KP = 0.5\n")
    (root / "control" / "stand.py.orig").write_text("KP = 0.5\n")
    (root / ".idea").mkdir()
    (root / ".idea" / "workspace.xml").write_text("<x/>")
    assert package_files_sha256(root) == first
    (root / "control" / "stand.py").write_text("KP = 2.0\n")
    assert package_files_sha256(root) != first


def test_run_json_and_the_worker_fingerprint_carry_the_package_hash(finished) -> None:
    _, out = finished
    assert _run(out)["environment"]["wbc_sha256"] == package_sha256() is not None
    assert dict(worker_check.fingerprint())["wbc package files (sha256)"] == package_sha256()


def test_a_resume_under_other_package_files_warns_outside_git(copy_of, monkeypatch, capsys) -> None:
    scenario, out = copy_of
    lines = (out / "trials.csv").read_text(encoding="utf-8").splitlines(keepends=True)
    (out / "trials.csv").write_text("".join(lines[:-1]), encoding="utf-8")
    run = _run(out)
    run["environment"]["git_revision"] = "unknown"  # an installed wheel: git knows nothing
    run["environment"].pop("git_diff_sha256", None)
    (out / "run.json").write_text(json.dumps(run))
    real = provenance()

    def edited() -> dict:
        env = copy.deepcopy(real)
        env["git_revision"] = "unknown"
        env.pop("git_diff_sha256", None)
        env["wbc_sha256"] = "cd" * 32  # wbc/control/stand.py edited in place
        return env
    monkeypatch.setattr(results_module, "provenance", edited)
    capsys.readouterr()
    run_arena(_config(scenario, out, resume=True))
    err = capsys.readouterr().err
    assert f"wbc_sha256 {real['wbc_sha256']} -> {'cd' * 32}" in err
    assert "the run now mixes trials played by two codes" in err and "summary.json" in err
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["mixed_environments"] is True
    assert any("wbc_sha256" in line for line in summary["environment_changes"])


# -- 3. the uncommitted changes are kept ------------------------------------------------------------------------------
def test_a_dirty_checkout_keeps_its_diff_at_the_start_and_at_a_resume_under_another(finished, tmp_path, monkeypatch,
                                                                                      capsys) -> None:
    scenario, _ = finished
    real = provenance()
    diff = {"text": b"diff --git a/wbc/mpc/controller.py b/wbc/mpc/controller.py\n-KP = 1\n+KP = 2\n"}

    def dirty() -> dict:
        env = copy.deepcopy(real)
        env["git_revision"] = real["git_revision"].removesuffix("-dirty") + "-dirty"
        env["git_diff_sha256"] = str(hash(diff["text"]))
        return env
    monkeypatch.setattr(results_module, "provenance", dirty)
    monkeypatch.setattr(results_module, "git_diff", lambda: diff["text"])
    out = tmp_path / "d"
    run_arena(_config(scenario, out))
    assert (out / "wbc.diff").read_bytes() == diff["text"]
    assert _run(out)["environment"]["git_diff_file"] == "wbc.diff"
    lines = (out / "trials.csv").read_text(encoding="utf-8").splitlines(keepends=True)
    (out / "trials.csv").write_text("".join(lines[:-1]), encoding="utf-8")
    diff["text"] = b"diff --git a/wbc/mpc/controller.py b/wbc/mpc/controller.py\n-KP = 1\n+KP = 3\n"
    capsys.readouterr()
    run_arena(_config(scenario, out, resume=True))
    err = capsys.readouterr().err
    assert "wbc-resume-1.diff keeps this resume's uncommitted changes" in err
    assert (out / "wbc-resume-1.diff").read_bytes() == diff["text"]
    assert (out / "wbc.diff").read_bytes().endswith(b"+KP = 2\n")
    assert _run(out)["environment"]["resumes"][-1]["diff_file"] == "wbc-resume-1.diff"
    assert json.loads((out / "summary.json").read_text(encoding="utf-8"))["mixed_environments"] is True


# -- 4, 8. a resume by another command, or with another time limit, is refused ---------------------------------------
def _session(command: str = "compare", limit: float | None = None) -> dict:
    return {"command": command, "command_line": f"wbc {command}", "cwd": "/", "executor": "local, in this process",
            "workers": 1, "trial_time_limit_s": limit}


def test_a_resume_with_another_trial_time_limit_is_refused_naming_both(copy_of) -> None:
    _, out = copy_of
    identity = RunIdentity.load(out / "run.json")
    assert _run(out)["trial_time_limit_s"] is None
    with pytest.raises(ResultsDirError, match=r"trial_time_limit_s: .*stored none \(no --trial-time-limit\), given "
                                              r"30 s"):
        ResultsStore(out, identity, resume=True, session=_session(limit=30.0))
    ResultsStore(out, identity, resume=True, session=_session()).close()
    run = _run(out)
    assert [s["trial_time_limit_s"] for s in run["sessions"]] == [None, None]
    del run["trial_time_limit_s"]  # a directory written before the limit was recorded takes any
    (out / "run.json").write_text(json.dumps(run))
    ResultsStore(out, identity, resume=True, session=_session(limit=30.0)).close()
    # its trials were played under a limit never recorded: the run's stays unknown, the session's is this call's
    run = _run(out)
    assert "trial_time_limit_s" not in run and run["sessions"][-1]["trial_time_limit_s"] == 30.0


def test_a_resume_by_another_command_is_refused_naming_the_one_to_use(copy_of) -> None:
    _, out = copy_of
    identity = RunIdentity.load(out / "run.json")
    run = _run(out)
    run["command"] = "paper table1"
    (out / "run.json").write_text(json.dumps(run))
    with pytest.raises(ResultsDirError, match=r"field command: the run was written by wbc paper table1.*finish it "
                                              r"with wbc paper table1 \.\.\. --resume"):
        ResultsStore(out, identity, resume=True, session=_session("compare"))
    run["command"] = "run"  # wbc run is wbc compare of one controller: the same directory
    (out / "run.json").write_text(json.dumps(run))
    ResultsStore(out, identity, resume=True, session=_session("compare")).close()


def test_a_paper_directory_written_before_the_command_was_recorded_takes_only_wbc_paper(copy_of) -> None:
    _, out = copy_of
    identity = RunIdentity.load(out / "run.json")
    run = _run(out)
    del run["command"]
    (out / "run.json").write_text(json.dumps(run))
    (out / "paper.json").write_text("{}")
    (out / "paper.txt").write_text("Table I")
    with pytest.raises(ResultsDirError, match=r"field command: the run was written by wbc paper \(its paper.json says "
                                              r"so\).*finish it with wbc paper TABLE \.\.\. --resume"):
        ResultsStore(out, identity, resume=True, session=_session("compare"))
    assert (out / "paper.json").is_file() and (out / "paper.txt").is_file()  # nothing removed
    ResultsStore(out, identity, resume=True, session=_session("paper table1")).close()


def test_a_missing_option_at_its_default_is_named_as_the_default(copy_of, capsys) -> None:
    scenario, out = copy_of
    run = _run(out)
    run["config"]["max_consecutive_errors"] = 2
    (out / "run.json").write_text(json.dumps(run))
    with pytest.raises(ResultsDirError, match=r"max_consecutive_errors stored 2, given the default \(3\)"):
        run_arena(_config(scenario, out, resume=True))


# -- 5, 6. how the run was executed, and its inputs -------------------------------------------------------------------
def test_run_json_records_how_each_call_ran_and_the_report_names_the_executor(finished) -> None:
    scenario, out = finished
    run = _run(out)
    assert run["command"] == "compare"
    session = run["sessions"][0]
    assert session["command_line"] == "wbc compare stand --trials 2"
    assert session["executor"] == "local, in this process" and session["workers"] == 1
    assert session["started_utc"] <= session["ended_utc"] and session["stored_trials"] == 0
    assert Path(session["cwd"]).is_dir()
    assert "**executor**: local, in this process" in (out / "report.md").read_text(encoding="utf-8")


def test_the_report_tells_one_worker_process_from_this_process(finished, tmp_path) -> None:
    scenario, _ = finished
    out = tmp_path / "isolated"
    run_arena(_config(scenario, out, trials=1, isolated=True))
    assert "**executor**: local, 1 worker process" in (out / "report.md").read_text(encoding="utf-8")


def test_the_inputs_are_copied_and_a_resume_checks_them_against_the_copies(copy_of, tmp_path) -> None:
    scenario, out = copy_of
    inputs = _run(out)["inputs"]
    copy_path = out / inputs["scenario"]["copy"]
    assert copy_path.read_bytes() == scenario.read_bytes()
    assert inputs["scenario"]["source"] == str(scenario)
    copy_path.write_text(SHORT_SCENARIO + "\n# edited\n")
    with pytest.raises(ResultsDirError, match=r"the run's copy of its scenario file was changed"):
        run_arena(_config(scenario, out, resume=True))


def test_the_copies_of_two_inputs_differing_only_in_case_are_two_files_on_any_file_system(copy_of, tmp_path) -> None:
    _, out = copy_of
    identity = RunIdentity.load(out / "run.json")
    (tmp_path / "h8.toml").write_text("[mpc]\nhorizon = 8\n")
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "h8.toml").write_text("[mpc]\nhorizon = 9\n")
    roles = {"controller-config:make@H8": tmp_path / "h8.toml",
             "controller-config:make@h8": tmp_path / "other" / "h8.toml"}
    ResultsStore(out, identity, resume=True, session=_session(), inputs=roles).close()
    kept = _run(out)["inputs"]
    copies = [kept[role]["copy"] for role in roles]
    assert len({c.casefold() for c in copies}) == 2
    assert [(out / c).read_text() for c in copies] == [p.read_text() for p in roles.values()]


def _as_previous_version(out: Path) -> list[list[str]]:
    """Rewrite ``trials.csv`` as the version before the last columns wrote it; its rows as they were, in this form."""
    path = out / "trials.csv"
    rows = list(csv.reader(io.StringIO(path.read_text(encoding="utf-8"), newline="")))
    keep = [i for i, name in enumerate(COLUMNS[:-1]) if name not in ADDED_COLUMNS]
    old = [[row[i] for i in keep] for row in rows[1:]]
    buffer = io.StringIO()
    writer = csv.writer(buffer)
    writer.writerow(PREVIOUS_COLUMNS)
    for cells in old:
        writer.writerow([*cells, checksum_of(cells)])
    path.write_text(buffer.getvalue(), encoding="utf-8")
    return rows


def test_a_run_of_the_version_before_the_last_columns_resumes_its_rows_kept_in_this_versions_form(copy_of) -> None:
    scenario, out = copy_of
    rows = _as_previous_version(out)
    lines = (out / "trials.csv").read_text(encoding="utf-8").splitlines(keepends=True)
    (out / "trials.csv").write_text("".join(lines[:-1]), encoding="utf-8")  # its last trial still to play
    run_arena(_config(scenario, out, resume=True))
    again = list(csv.reader(io.StringIO((out / "trials.csv").read_text(encoding="utf-8"), newline="")))
    assert tuple(again[0]) == COLUMNS
    kept = TrialRecord.from_row(again[1])  # the row of before, with the columns it lacked filled and checked
    first = TrialRecord.from_row(rows[1])
    assert math.isnan(kept.act_ms_max) and kept.write_deadline_ramps == 0
    assert dataclasses.replace(kept, act_ms_max=first.act_ms_max) == first
    assert len(again) == len(rows)  # and the trial it lacked played


def test_an_edited_row_of_the_version_before_is_refused_as_edited(copy_of) -> None:
    scenario, out = copy_of
    _as_previous_version(out)
    text = (out / "trials.csv").read_text(encoding="utf-8").splitlines(keepends=True)
    cells = next(csv.reader([text[1]]))
    cells[PREVIOUS_COLUMNS.index("ttf")] = "0.5"
    buffer = io.StringIO()
    csv.writer(buffer).writerow(cells)
    (out / "trials.csv").write_text(text[0] + buffer.getvalue() + "".join(text[2:]), encoding="utf-8")
    with pytest.raises(RecordError, match=r"checksum .* does not match the row's cells"):
        run_arena(_config(scenario, out, resume=True))


# -- 7. the global random generators -----------------------------------------------------------------------------------
def _plays_the_same_after(tmp_path: Path, target: str, disturb: Callable[[], object]) -> None:
    """`target` plays the short scenario's first soft trial the same before and after `disturb` (standing for other
    trials played before on this worker, which drew from the global generators), machine-timed cells left out."""
    path = tmp_path / "short.toml"
    path.write_text(SHORT_SCENARIO)
    trial = load_scenario(path).trial("soft", 0, 0)
    skip = {TrialRecord.header().index(n) for n in MACHINE_TIMED}
    first, _ = run_trial(trial, target)
    disturb()
    second, _ = run_trial(trial, target)
    assert [c for i, c in enumerate(first.to_row()) if i not in skip] == [
        c for i, c in enumerate(second.to_row()) if i not in skip]


def test_a_plugin_drawing_from_the_global_generators_plays_the_same_whatever_ran_before(plugin_package,
                                                                                           tmp_path) -> None:
    plugin_package("noisypkg", {"noisy": STAND_PLUGIN.format(
        doc="The stand hold with noise from numpy's global generator and Python's random.", reset="pass",
        act="import dataclasses, random\n            out = dataclasses.replace(out, q=out.q + np.random.normal("
            "0.0, 0.02, out.q.shape) + random.gauss(0.0, 0.01))",
        counters="return {}")})
    _plays_the_same_after(tmp_path, "noisypkg.noisy:make", lambda: (np.random.seed(12345), random.seed(6789)))


def test_a_plugin_drawing_from_torchs_global_generator_plays_the_same_whatever_ran_before(plugin_package,
                                                                                          tmp_path) -> None:
    import torch
    plugin_package("torchnoisypkg", {"noisy": STAND_PLUGIN.format(
        doc="The stand hold with noise from torch's global generator, torch imported at its first reset.",
        reset="import torch\n            torch.randn(3)",
        act="import dataclasses, torch\n            out = dataclasses.replace(out, q=out.q + 0.02 * torch.randn("
            "out.q.shape, dtype=torch.float64).numpy())",
        counters="return {}")})
    _plays_the_same_after(tmp_path, "torchnoisypkg.noisy:make", lambda: (torch.manual_seed(12345), torch.randn(7)))
