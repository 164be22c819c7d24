"""A resume under another environment than the run began under (``run.json``'s ``environment``).

A resume keeps the environment the run began under: another version of a package that changes results is refused;
any other change (the revision or its uncommitted changes, the CPU ...) is a warning naming it, old -> new, recorded
in ``run.json`` (``environment.resumes``) and said in the report (`wbc.arena.run_environment`).
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest
from conftest import SHORT_SCENARIO

from wbc.arena import results as results_module
from wbc.arena.compare import ArenaConfig, run_arena
from wbc.arena.run_environment import changes
from wbc.errors import RecordError, ResultsDirError
from wbc.provenance import provenance


# -- a resume under another environment ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def interrupted(tmp_path_factory):
    """A run of ``stand`` on the short scenario, 2 trials, its last row removed as if killed: (scenario, directory)."""
    tmp = tmp_path_factory.mktemp("env")
    scenario = tmp / "short.toml"
    scenario.write_text(SHORT_SCENARIO)
    out = tmp / "o"
    run_arena(_config(scenario, out))
    lines = (out / "trials.csv").read_text(encoding="utf-8").splitlines(keepends=True)
    (out / "trials.csv").write_text("".join(lines[:-1]), encoding="utf-8")
    return scenario, out


def _config(scenario: Path, out: Path, **changes) -> ArenaConfig:
    return ArenaConfig(controllers=("stand",), scenario=scenario, seeds=(0,), trials=2, out_dir=out, workers=1,
                       progress=False, **changes)


@pytest.fixture
def copy_of(interrupted, tmp_path: Path):
    scenario, out = interrupted
    mine = tmp_path / "o"
    mine.mkdir()
    for f in ("run.json", "trials.csv"):
        (mine / f).write_bytes((out / f).read_bytes())
    return scenario, mine


def _environment(out: Path) -> dict:
    return json.loads((out / "run.json").read_text(encoding="utf-8"))["environment"]


def _resumed_under(monkeypatch, change) -> None:
    """Resumes see the environment `change` makes of this one."""
    real = provenance()

    def changed() -> dict:
        env = copy.deepcopy(real)
        change(env)
        return env
    monkeypatch.setattr(results_module, "provenance", changed)


def test_a_resume_under_another_revision_warns_records_it_and_keeps_the_start(copy_of, monkeypatch, capsys) -> None:
    scenario, out = copy_of
    start = _environment(out)

    def edited(env: dict) -> None:  # a gain edited in the source: the same revision, dirty, its diff hashed
        env["git_revision"] = start["git_revision"].removesuffix("-dirty") + "-dirty"
        env["git_diff_sha256"] = "ab" * 32
        env["cpu"] = {"model": "Other CPU", "flags": [*start["cpu"]["flags"], "avx512_zz"]}
    _resumed_under(monkeypatch, edited)
    capsys.readouterr()
    run_arena(_config(scenario, out, resume=True))
    err = capsys.readouterr().err
    assert "--resume under another environment than the run began under" in err
    assert f"cpu.model {start['cpu']['model']} -> Other CPU" in err and "cpu.flags gained avx512_zz" in err
    assert f"git_diff_sha256 {start.get('git_diff_sha256', 'none')} -> {'ab' * 32}" in err
    assert "the run now mixes trials played by two codes (the 1 stored ones by the earlier)" in err
    assert "summary.json marks the run (mixed_environments)" in err
    env = _environment(out)
    assert {k: v for k, v in env.items() if k != "resumes"} == start  # the environment the run began under, kept
    [resume] = env["resumes"]
    assert resume["stored_trials"] == 1
    assert resume["changed"]["git_diff_sha256"] == {"was": start.get("git_diff_sha256"), "now": "ab" * 32}
    assert resume["changed"]["cpu.model"] == {"was": start["cpu"]["model"], "now": "Other CPU"}
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "played under more than one environment" in report and "resumed with 1 trial(s) stored" in report
    assert "cpu.model" in report
    # resumed again with nothing left to play, under the same changed environment: recorded again, the start kept
    run_arena(_config(scenario, out, resume=True))
    assert len(_environment(out)["resumes"]) == 2 and "avx512_zz" not in json.dumps(_environment(out)["cpu"])


def test_a_resume_under_the_same_environment_says_nothing_and_records_no_resume(copy_of, capsys) -> None:
    scenario, out = copy_of
    start = _environment(out)
    capsys.readouterr()
    run_arena(_config(scenario, out, resume=True))
    assert "another environment" not in capsys.readouterr().err
    assert _environment(out) == start
    assert "more than one environment" not in (out / "report.md").read_text(encoding="utf-8")


def test_a_resume_under_another_numerical_package_version_is_refused_and_changes_nothing(copy_of,
                                                                                          monkeypatch) -> None:
    scenario, out = copy_of
    before = {f: (out / f).read_bytes() for f in ("run.json", "trials.csv")}

    def numpy(env: dict) -> None:
        env["packages"]["numpy"] = "9.9.9"
    _resumed_under(monkeypatch, numpy)
    version = provenance()["packages"]["numpy"]
    with pytest.raises(ResultsDirError, match=rf"--resume under other versions of packages that change results "
                                              rf"\(packages\.numpy {version} -> 9\.9\.9; .*the 1 stored trial\(s\) "
                                              r".*make test"):
        run_arena(_config(scenario, out, resume=True))
    assert {f: (out / f).read_bytes() for f in before} == before


def test_a_run_json_written_before_the_new_fields_still_resumes(copy_of, monkeypatch, capsys) -> None:
    scenario, out = copy_of
    run = json.loads((out / "run.json").read_text(encoding="utf-8"))
    env = run["environment"]
    old = {"python": env["python"], "platform": env["platform"],  # what the previous code recorded
           "packages": {k: v for k, v in env["packages"].items() if k not in ("numba", "llvmlite", "scipy",
                                                                                "proxsuite")},
           "git_revision": env["git_revision"]}
    run["environment"] = old
    (out / "run.json").write_text(json.dumps(run, indent=2), encoding="utf-8")
    capsys.readouterr()
    run_arena(_config(scenario, out, resume=True))
    assert "another environment" not in capsys.readouterr().err  # the fields it lacks are unknown, not changed
    assert _environment(out) == old


def test_a_malformed_stored_environment_names_the_field(copy_of) -> None:
    scenario, out = copy_of
    run = json.loads((out / "run.json").read_text(encoding="utf-8"))
    run["environment"]["resumes"] = "yesterday"
    (out / "run.json").write_text(json.dumps(run), encoding="utf-8")
    with pytest.raises(RecordError, match=r"run\.json: field environment\.resumes: expected a list of objects"):
        run_arena(_config(scenario, out, resume=True))


def test_what_refuses_and_what_is_only_noted() -> None:
    start = provenance()
    later = copy.deepcopy(start)
    later["packages"]["meshcat"] = "0.0.1"  # the viewer changes no result: noted
    later["packages"]["scipy"] = "0.0.1"  # the p-values and intervals: refused
    later["git_revision"] = "0" * 40
    later["packages"].pop("onnxruntime", None)  # removed since: noted (nothing stored could have used it now)
    found = {c.field: c for c in changes(start, later)}
    assert found["packages.scipy"].refuses and not found["packages.meshcat"].refuses
    assert not found["git_revision"].refuses
    if "onnxruntime" in start["packages"]:
        assert not found["packages.onnxruntime"].refuses and found["packages.onnxruntime"].now is None
