"""`RunIdentity`: the ``config`` of a results directory's ``run.json``, written, resumed and read back by the viewer.

The old dicts below are built literally as ``run_arena`` and the hardware trial wrote them before the type existed, so
that a directory written then still resumes and replays.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import re
from pathlib import Path

import pytest
from conftest import HOLD_PLUGIN

from wbc.arena.compare import ArenaConfig, run_arena
from wbc.arena.hw_trial import HardwareTrialConfig, run_hardware_trial
from wbc.arena.identity import (
    MAX_CONSECUTIVE_ERRORS,
    MAX_SEED,
    MAX_TRIALS,
    ControllerFile,
    HardwareRunIdentity,
    RunIdentity,
    ScenarioRef,
    SequentialStop,
    SimulatedRunIdentity,
    compared,
    moved_files,
)
from wbc.arena.results import ResultsStore
from wbc.arena.trial_record import TrialRecord
from wbc.errors import ConfigError, RecordError, ResultsDirError, ScenarioError
from wbc.scenario import scenario as scenario_module
from wbc.scenario.scenario import MAX_VERSION, load_scenario
from wbc.viz.errors import ViewerError
from wbc.viz.replay import load_stored_episode

# 0.3 s trials, one push at 0.1 s: enough for a stored episode, cheap enough to play a few.
SHORT = """
[scenario]
name = "idtest"
version = 2
description = "short trials for the run identity tests"
robot = "a1-wx200"
duration_s = 0.3

[terrain]
kind = "fractal"
amplitude_m = 0.03

[commands]
[[commands.options]]
vx = 0.0

[pushes]
first_s = [0.1, 0.1]
interval_s = [5.0, 5.0]
duration_s = 0.05
offset_m = 0.1

[[bands]]
name = "soft"
push_force_n = [100.0, 120.0]
"""

SCENARIO = ScenarioRef(path="scenarios/push-v1.toml", name="push", version=1, hash="ab" * 32, published=True)
SIMULATED = SimulatedRunIdentity(
    controllers=("mpc", "learned"), scenario=SCENARIO, bands=("soft", "hard"), seeds=(0, 1), trials=4, no_push=False,
    debug_truth=True, until_significant=SequentialStop(alpha=0.05, pairs=(("mpc", "learned"),)),
    controller_files=(ControllerFile(controller="mpc", path="gains.toml", sha256="cd" * 32),),
    max_consecutive_errors=0)
HARDWARE = HardwareRunIdentity(
    controllers=("stand-noarm",), scenario=ScenarioRef(path="scenarios/push-v1.toml", name="push", hash="ab" * 32,
                                                       published=False),
    bands=("soft",), seeds=(3,), trial=2, duration_s=2.5, robot="go1-arm", arm_mode="none", backend="unitree",
    target="127.0.0.1:8007")


@pytest.fixture
def short(tmp_path: Path) -> Path:
    path = tmp_path / "idtest.toml"
    path.write_text(SHORT)
    return path


@pytest.fixture
def hold(plugin_package):
    """`HOLD_PLUGIN` as ``holdpkg.hold:make``: its factory takes a configuration table, so a run of it records the
    file in run.json (controller_files)."""
    plugin_package("holdpkg", {"hold": HOLD_PLUGIN})
    return "holdpkg.hold:make"


def _old_simulated(cfg: ArenaConfig, *, published: bool, files: dict | None = None) -> dict:
    """``run_arena``'s identity dict as the code before `RunIdentity` built it, line for line."""
    scenario = load_scenario(cfg.scenario)
    bands = cfg.bands or scenario.bands
    identity = {
        "controllers": list(cfg.controllers),
        "scenario": {"path": str(cfg.scenario), "name": scenario.name, "version": scenario.version,
                     "hash": scenario.hash, "published": published},
        "bands": list(bands),
        "seeds": list(cfg.seeds),
        "trials": cfg.trials,
        "no_push": cfg.no_push,
        "debug_truth": cfg.debug_truth,
    }
    if cfg.until_significant:
        pairs = cfg.sequential_pairs or [(a, b) for i, a in enumerate(cfg.controllers) for b in cfg.controllers[i + 1:]]
        identity["until_significant"] = {"alpha": cfg.alpha, "pairs": [list(p) for p in pairs]}
    if files:
        identity["controller_files"] = files
    if cfg.max_consecutive_errors != 3:
        identity["max_consecutive_errors"] = cfg.max_consecutive_errors
    return identity


def _stored(out: Path) -> dict:
    return json.loads((out / "run.json").read_text())["config"]


def _write_config(out: Path, config: object) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    path = out / "run.json"
    path.write_text(json.dumps({"config": config, "environment": {}}, indent=2))
    return path


# -- the JSON form ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("identity", [SIMULATED, HARDWARE, SimulatedRunIdentity(
    controllers=("stand",), scenario=SCENARIO, bands=("soft",), seeds=(0,), trials=1, no_push=True,
    debug_truth=False)], ids=["simulated", "hardware", "simulated-without-options"])
def test_both_kinds_round_trip_through_json_exactly(identity: RunIdentity, tmp_path: Path) -> None:
    text = json.dumps(identity.as_json(), indent=2)
    back = RunIdentity.from_json(json.loads(text), source="run.json")
    assert back == identity and type(back) is type(identity)
    assert json.dumps(back.as_json(), indent=2) == text  # key order included
    # through a file, as the store writes it and the viewer reads it
    assert RunIdentity.load(_write_config(tmp_path, identity.as_json())) == identity
    assert type(identity).load(tmp_path / "run.json") == identity


def test_the_json_form_is_the_one_written_before_key_for_key() -> None:
    assert list(SIMULATED.as_json()) == ["controllers", "scenario", "bands", "seeds", "trials", "no_push",
                                         "debug_truth", "until_significant", "controller_files",
                                         "max_consecutive_errors"]
    assert SIMULATED.as_json()["scenario"] == {"path": "scenarios/push-v1.toml", "name": "push", "version": 1,
                                               "hash": "ab" * 32, "published": True}
    assert SIMULATED.as_json()["until_significant"] == {"alpha": 0.05, "pairs": [["mpc", "learned"]]}
    assert SIMULATED.as_json()["controller_files"] == {"mpc": {"path": "gains.toml", "sha256": "cd" * 32}}
    # the options at their defaults are absent, as before they existed
    plain = SimulatedRunIdentity(controllers=("stand",), scenario=SCENARIO, bands=("soft",), seeds=(0,), trials=1,
                                 no_push=False, debug_truth=False, max_consecutive_errors=3)
    assert list(plain.as_json()) == ["controllers", "scenario", "bands", "seeds", "trials", "no_push", "debug_truth"]
    assert list(HARDWARE.as_json()) == ["command", "controllers", "scenario", "bands", "seeds", "trial", "duration_s",
                                        "robot", "arm_mode", "backend", "target"]
    assert HARDWARE.as_json()["command"] == "hw run" and "version" not in HARDWARE.as_json()["scenario"]


def test_accessors_the_viewer_reads() -> None:
    assert SIMULATED.trials_played == (0, 1, 2, 3) and SIMULATED.played_on is None
    assert HARDWARE.trials_played == (2,) and HARDWARE.played_on == "go1-arm"
    assert SIMULATED.scenario_path == Path("scenarios/push-v1.toml") and SIMULATED.scenario_hash == "ab" * 32
    assert (HARDWARE.controllers, HARDWARE.bands, HARDWARE.seeds) == (("stand-noarm",), ("soft",), (3,))


# -- what the previous code wrote ------------------------------------------------------------------------------------
def test_a_run_writes_the_old_dict_and_resumes_a_directory_written_before(short: Path, tmp_path: Path) -> None:
    cfg = ArenaConfig(controllers=("stand",), scenario=short, trials=1, out_dir=tmp_path / "r", workers=1,
                      progress=False)
    run_arena(cfg)
    old = _old_simulated(cfg, published=False)
    assert "max_consecutive_errors" not in old and "until_significant" not in old
    assert json.dumps(_stored(cfg.out_dir)) == json.dumps(old)  # key for key, in order
    loaded = RunIdentity.load(cfg.out_dir / "run.json")
    assert loaded == SimulatedRunIdentity.from_json(old, source="old") and loaded.as_json() == old
    # the directory as the previous code left it: its run.json, written literally, resumes; nothing is played again
    _write_config(cfg.out_dir, old)
    assert run_arena(dataclasses.replace(cfg, resume=True)).played == 0
    # another option is refused, naming the field that differs
    with pytest.raises(ResultsDirError, match=r"differs in: max_consecutive_errors\)"):
        run_arena(dataclasses.replace(cfg, resume=True, max_consecutive_errors=5))
    with pytest.raises(ResultsDirError, match=r"differs in: no_push, trials\): no_push stored false, given true; "
                                              r"trials stored 1, given 2; rerun"):
        run_arena(dataclasses.replace(cfg, resume=True, trials=2, no_push=True))
    # another scenario file is refused by its hash, whatever its path
    other = tmp_path / "other.toml"
    other.write_text(SHORT.replace("amplitude_m = 0.03", "amplitude_m = 0.04"))
    with pytest.raises(ResultsDirError, match=r"\(differs in: scenario\): scenario\.hash stored \"[0-9a-f]{64}\", "
                                              r"given \"[0-9a-f]{64}\"; rerun"):
        run_arena(dataclasses.replace(cfg, resume=True, scenario=other))


def test_a_run_resumes_with_its_scenario_by_another_path_or_a_copy(short: Path, tmp_path: Path, monkeypatch,
                                                                    capsys) -> None:
    # a file is its content's hash: the path it is given by is recorded, not compared, and a new one is noted
    monkeypatch.chdir(tmp_path)
    cfg = ArenaConfig(controllers=("stand",), scenario=Path(short.name), trials=2, out_dir=Path("r"), workers=1,
                      progress=False)
    run_arena(dataclasses.replace(cfg, trials=1))
    _write_config(cfg.out_dir, _with(_stored(cfg.out_dir), 2, "trials"))  # one trial of two stored
    capsys.readouterr()
    copy = tmp_path / "elsewhere" / "copy.toml"
    copy.parent.mkdir()
    copy.write_text(SHORT)
    for scenario, out in ((tmp_path / short.name, tmp_path / "r"), (Path("..") / short.name, Path("../r")),
                          (copy, tmp_path / "r")):
        monkeypatch.chdir(tmp_path / ("elsewhere" if str(scenario).startswith("..") else "."))
        was = _stored(out)["scenario"]["path"]
        result = run_arena(dataclasses.replace(cfg, resume=True, scenario=scenario, out_dir=out))
        assert result.played == (1 if was == short.name else 0)
        assert _stored(out)["scenario"]["path"] == str(scenario)  # the path given last, for the viewer
        note = capsys.readouterr().err
        assert (f"wbc: note: {out / 'run.json'}: the scenario is given as {json.dumps(str(scenario))}, the run's was "
                f"{json.dumps(was)}: the same content, so the run resumes") in note
    run_arena(dataclasses.replace(cfg, resume=True, scenario=copy, out_dir=tmp_path / "r"))
    assert "wbc: note" not in capsys.readouterr().err  # the same path: nothing to say


def test_a_run_resumes_once_its_scenario_is_published_and_records_what_was(short: Path, tmp_path: Path,
                                                                           capsys) -> None:
    # begun on an unpublished file, interrupted, the file then published as the warning says: the same content
    cfg = ArenaConfig(controllers=("stand",), scenario=short, trials=2, out_dir=tmp_path / "r", workers=1,
                      progress=False)
    run_arena(dataclasses.replace(cfg, trials=1))
    _write_config(cfg.out_dir, _with(_stored(cfg.out_dir), 2, "trials"))  # one trial of two stored
    assert _stored(cfg.out_dir)["scenario"]["published"] is False
    capsys.readouterr()
    scenario = load_scenario(short)
    (tmp_path / "published.toml").write_text(f'[{scenario.name}]\n"{scenario.version}" = "{scenario.hash}"\n')
    assert run_arena(dataclasses.replace(cfg, resume=True)).played == 1
    err = capsys.readouterr().err
    assert (f"wbc: note: {cfg.out_dir / 'run.json'}: the scenario is published now (a lock lists its hash), and was "
            "not when the run began: the same content, so the run resumes, and run.json records both "
            "(scenario.published true, scenario.published_at_start false)") in err
    assert {k: _stored(cfg.out_dir)["scenario"][k] for k in ("published", "published_at_start")} == {
        "published": True, "published_at_start": False}
    report = (cfg.out_dir / "report.md").read_text()
    assert "yes; not when the run began (published at a resume; the same content)" in report
    # resumed again, published still: what was at the start stays recorded, and nothing more is said
    run_arena(dataclasses.replace(cfg, resume=True))
    assert "published" not in capsys.readouterr().err
    assert _stored(cfg.out_dir)["scenario"]["published_at_start"] is False
    # the lock removed again: published as at the start, which needs no second field
    (tmp_path / "published.toml").unlink()
    run_arena(dataclasses.replace(cfg, resume=True))
    assert "is not published now (no lock lists its hash), as when the run began" in capsys.readouterr().err
    assert "published_at_start" not in _stored(cfg.out_dir)["scenario"]
    assert RunIdentity.load(cfg.out_dir / "run.json").scenario.published is False


def test_a_relative_scenario_path_found_under_the_checkout_is_noted_and_recorded_whole(tmp_path: Path, monkeypatch,
                                                                                      capsys) -> None:
    # `scenarios/idtest.toml` exists in the checkout (here a stand-in), not in the directory the command runs in
    root, work = tmp_path / "checkout", tmp_path / "work"
    (root / "scenarios").mkdir(parents=True)
    work.mkdir()
    (root / "scenarios" / "idtest.toml").write_text(SHORT)
    monkeypatch.setattr(scenario_module, "SOURCE_ROOT", root)
    monkeypatch.chdir(work)
    shipped = str(root / "scenarios" / "idtest.toml")
    cfg = ArenaConfig(controllers=("stand",), scenario=Path("scenarios/idtest.toml"), trials=2, out_dir=work / "r",
                      workers=1, progress=False)
    run_arena(dataclasses.replace(cfg, trials=1))
    assert (f"wbc: note: scenarios/idtest.toml is not found from the working directory ({work}): it plays {shipped}, "
            "the file under the source checkout, and the results record that path") in capsys.readouterr().err
    assert _stored(cfg.out_dir)["scenario"]["path"] == shipped  # a path that names the file from anywhere
    assert f"({shipped})" in (cfg.out_dir / "report.md").read_text()
    # resumed from the checkout, where the relative path names the same file: the same content, and it goes on
    _write_config(cfg.out_dir, _with(_stored(cfg.out_dir), 2, "trials"))
    monkeypatch.chdir(root)
    assert run_arena(dataclasses.replace(cfg, resume=True)).played == 1
    err = capsys.readouterr().err
    assert "is not found from the working directory" not in err
    assert f'the scenario is given as "scenarios/idtest.toml", the run\'s was {json.dumps(shipped)}' in err
    assert _stored(cfg.out_dir)["scenario"]["path"] == "scenarios/idtest.toml"


def test_the_store_compares_files_by_their_hashes_not_their_paths(tmp_path: Path, capsys) -> None:
    moved = dataclasses.replace(SIMULATED, scenario=dataclasses.replace(SCENARIO, path="elsewhere/p.toml"),
                                controller_files=(ControllerFile(controller="mpc", path="../gains.toml",
                                                                 sha256="cd" * 32),))
    assert compared(moved.as_json()) == compared(SIMULATED.as_json()) != compared(HARDWARE.as_json())
    assert moved_files(SIMULATED.as_json(), moved.as_json()) == [
        ("the scenario", "scenarios/push-v1.toml", "elsewhere/p.toml"),
        ("mpc's configuration file", "gains.toml", "../gains.toml")]
    out = tmp_path / "r"
    _write_config(out, SIMULATED.as_json())
    ResultsStore(out, moved, resume=True).close()
    assert RunIdentity.load(out / "run.json") == moved  # the paths given last are recorded
    err = capsys.readouterr().err
    assert 'the scenario is given as "elsewhere/p.toml", the run\'s was "scenarios/push-v1.toml"' in err
    assert 'mpc\'s configuration file is given as "../gains.toml", the run\'s was "gains.toml"' in err
    edited = dataclasses.replace(moved, controller_files=(ControllerFile(controller="mpc", path="gains.toml",
                                                                         sha256="ef" * 32),))
    with pytest.raises(ResultsDirError, match=r"\(differs in: controller_files\): controller_files\.mpc\.sha256 "):
        ResultsStore(out, edited, resume=True)


def test_a_run_with_every_option_writes_the_old_dict(short: Path, hold: str, tmp_path: Path) -> None:
    config = tmp_path / "gains.toml"
    config.write_text("leg_kp = 60.0\n")
    cfg = ArenaConfig(controllers=(hold, "stand"), scenario=short, trials=1, out_dir=tmp_path / "r", workers=1,
                      progress=False, until_significant=True, alpha=0.1, controller_configs={hold: config},
                      max_consecutive_errors=5)
    run_arena(cfg)
    files = {hold: {"path": str(config), "sha256": hashlib.sha256(config.read_bytes()).hexdigest()}}
    old = _old_simulated(cfg, published=False, files=files)
    assert json.dumps(_stored(cfg.out_dir)) == json.dumps(old)
    loaded = RunIdentity.load(cfg.out_dir / "run.json")
    assert isinstance(loaded, SimulatedRunIdentity)
    assert loaded.until_significant == SequentialStop(alpha=0.1, pairs=((hold, "stand"),))
    assert loaded.controller_files == (ControllerFile(controller=hold, path=str(config), sha256=files[hold]["sha256"]),)
    assert loaded.max_consecutive_errors == 5 and loaded.as_json() == old


def test_the_store_resumes_an_old_directory_and_names_the_differing_fields(tmp_path: Path) -> None:
    plain = SimulatedRunIdentity(controllers=("stand",), scenario=SCENARIO, bands=("soft",), seeds=(0,), trials=2,
                                 no_push=False, debug_truth=False)
    out = tmp_path / "old"
    # written by the previous code: no optional keys at all
    _write_config(out, {"controllers": ["stand"], "scenario": {
        "path": "scenarios/push-v1.toml", "name": "push", "version": 1, "hash": "ab" * 32, "published": True},
        "bands": ["soft"], "seeds": [0], "trials": 2, "no_push": False, "debug_truth": False})
    (out / "trials.csv").write_text(",".join(TrialRecord.header()) + "\n")
    store = ResultsStore(out, plain, resume=True)
    store.close()
    assert store.identity == plain and RunIdentity.load(out / "run.json") == plain
    other = SimulatedRunIdentity(controllers=("stand",), scenario=SCENARIO, bands=("soft", "hard"), seeds=(0,),
                                 trials=2, no_push=False, debug_truth=False, max_consecutive_errors=0)
    with pytest.raises(ResultsDirError, match=r'differs in: bands, max_consecutive_errors\): bands stored \["soft"\], '
                                              r'given \["soft", "hard"\]; max_consecutive_errors stored the default '
                                              r'\(3\), given 0'):
        ResultsStore(out, other, resume=True)
    # a hardware run's directory is another run, not a malformed one
    _write_config(out, HARDWARE.as_json())
    with pytest.raises(ResultsDirError, match=r"differs in: arm_mode, backend, command, .*, trial, trials\)"):
        ResultsStore(out, plain, resume=True)
    (out / "run.json").write_text("{not json")
    with pytest.raises(ResultsDirError, match=r"run\.json: unreadable run configuration"):
        ResultsStore(out, plain, resume=True)


def test_a_hardware_trial_writes_the_old_dict_and_the_viewer_finds_its_trial(short: Path, tmp_path: Path) -> None:
    out = tmp_path / "hw"
    result = run_hardware_trial(HardwareTrialConfig(controller="stand", scenario=short, trial=1, seed=2, seconds=0.2,
                                                    robot="go1-arm", arm_mode="none", simulate=True, out_dir=out,
                                                    settle_s=0.0))
    scenario = load_scenario(short)
    old = {  # as the hardware trial wrote it before RunIdentity
        "command": "hw run",
        "controllers": ["stand-noarm"],
        "scenario": {"path": str(short), "name": scenario.name, "hash": scenario.hash, "published": False},
        "bands": ["soft"],
        "seeds": [2],
        "trial": 1,
        "duration_s": 0.2,
        "robot": "go1-arm",
        "arm_mode": "none",
        "backend": "sim",
        "target": result.robot.target,
    }
    assert json.dumps(_stored(out)) == json.dumps(old)
    loaded = RunIdentity.load(out / "run.json")
    assert loaded == HardwareRunIdentity.from_json(old, source="old") and loaded.trials_played == (1,)
    stored = load_stored_episode(out, 1)
    assert (stored.controller, stored.trial.robot, stored.trial.terrain.kind, stored.trial.pushes) == (
        "stand-noarm", "go1-arm", "flat", ())
    assert len(list(stored.frames())) == len(stored.episode.t) - 1 > 0
    with pytest.raises(ViewerError, match=r"run\.json: field trials: --trial 0 is out of range; the run's trials are "
                                          r"1\.\.1 per band and seed"):
        load_stored_episode(out, 0)


def test_the_viewer_finds_the_trials_of_a_simulated_run(short: Path, tmp_path: Path) -> None:
    out = tmp_path / "sim"
    run_arena(ArenaConfig(controllers=("stand",), scenario=short, seeds=(4,), trials=2, out_dir=out, workers=1,
                          progress=False, save_episodes=True))
    for index in (0, 1):
        stored = load_stored_episode(out, index)
        assert stored.path == out / "episodes" / "stand" / f"soft-s4-t{index}.npz"
        assert stored.trial.robot == "a1-wx200" and len(stored.trial.pushes) == 1  # the scenario's robot and pushes
    with pytest.raises(ViewerError, match=r"field seeds: 0 was not played"):
        load_stored_episode(out, 0, seed=0)
    # a malformed run.json reaches the viewer's user with the file and the field
    config = _stored(out)
    config["seeds"] = "4"
    _write_config(out, config)
    with pytest.raises(ViewerError, match=r"run\.json: field seeds: expected a non-empty list of whole numbers"):
        load_stored_episode(out, 0)
    (out / "run.json").unlink()
    with pytest.raises(ViewerError, match=r"run\.json: missing"):
        load_stored_episode(out, 0)


# -- malformed run.json ----------------------------------------------------------------------------------------------
def _without(data: dict, *path: str) -> dict:
    data = json.loads(json.dumps(data))
    table = data
    for key in path[:-1]:
        table = table[key]
    del table[path[-1]]
    return data


def _with(data: dict, value: object, *path: str) -> dict:
    data = json.loads(json.dumps(data))
    table = data
    for key in path[:-1]:
        table = table[key]
    table[path[-1]] = value
    return data


@pytest.mark.parametrize(("config", "field", "reason"), [
    (_without(SIMULATED.as_json(), "seeds"), "seeds", "missing"),
    (_without(SIMULATED.as_json(), "scenario", "hash"), "scenario.hash", "missing"),
    (_without(SIMULATED.as_json(), "scenario", "version"), "scenario.version", "missing"),
    (_without(HARDWARE.as_json(), "robot"), "robot", "missing"),
    (_without(SIMULATED.as_json(), "trials"), "trials", "missing: a simulated run"),
    (_with(SIMULATED.as_json(), "4", "trials"), "trials", "expected a whole number in [1, 100000], got '4'"),
    (_with(SIMULATED.as_json(), 0, "trials"), "trials", "expected a whole number in [1, 100000], got 0"),
    (_with(SIMULATED.as_json(), [0, "1"], "seeds"), "seeds", "expected a non-empty list of whole numbers"),
    (_with(SIMULATED.as_json(), [], "bands"), "bands", "expected a non-empty list of strings"),
    (_with(SIMULATED.as_json(), 1, "no_push"), "no_push", "expected true or false, got 1"),
    (_with(SIMULATED.as_json(), "abc", "scenario"), "scenario", "expected an object"),
    (_with(SIMULATED.as_json(), 7, "scenario", "hash"), "scenario.hash", "expected a string, got 7"),
    (_with(SIMULATED.as_json(), 1.5, "until_significant", "alpha"), "until_significant.alpha", "not in"),
    (_with(SIMULATED.as_json(), [["mpc"]], "until_significant", "pairs"), "until_significant.pairs", "pairs"),
    (_without(SIMULATED.as_json(), "controller_files", "mpc", "sha256"), "controller_files.mpc.sha256", "missing"),
    (_with(SIMULATED.as_json(), -1, "max_consecutive_errors"), "max_consecutive_errors", "in [0, 1000000]"),
    (_with(HARDWARE.as_json(), -2.0, "duration_s"), "duration_s", "not a duration in (0, 600] s"),
    (_with(HARDWARE.as_json(), True, "trial"), "trial", "expected a whole number in [0, 99999], got True"),
    (_with(HARDWARE.as_json(), 4, "trials"), "trials", "not a field of this version's run identity"),
    (_with(SIMULATED.as_json(), 1, "speed"), "speed", "not a field"),
    ([1, 2], "config", "expected an object"),
], ids=lambda v: v if isinstance(v, str) else None)
def test_a_malformed_run_json_names_the_file_and_the_field(config: object, field: str, reason: str,
                                                           tmp_path: Path) -> None:
    path = _write_config(tmp_path / "bad", config)
    with pytest.raises(RecordError, match=rf"^{_re(path)}: field {_re(field)}: .*{_re(reason)}") as caught:
        RunIdentity.load(path)
    assert "another --out" in str(caught.value)  # and says what to do


def test_what_a_run_accepts_its_run_json_reader_accepts(short: Path, tmp_path: Path) -> None:
    # every bound of a field run.json records is the one its writer's input took: a run never writes a run.json that
    # its own --resume then refuses
    path = tmp_path / "run.json"
    for version in (MAX_VERSION, MAX_VERSION + 1):
        text = SHORT.replace("version = 2", f"version = {version}")
        short.write_text(text)
        config = _with(SIMULATED.as_json(), version, "scenario", "version")
        _write_config(tmp_path, config)
        if version <= MAX_VERSION:
            assert load_scenario(short).version == RunIdentity.load(path).scenario.version == version
            continue
        with pytest.raises(ScenarioError, match=rf"^{_re(short)}:4: \[scenario\] version: must be in \[1, "
                                                rf"{MAX_VERSION}\], got {version}$"):
            load_scenario(short)
        with pytest.raises(RecordError, match=rf"whole number in \[1, {MAX_VERSION}\], got {version}"):
            RunIdentity.load(path)
    # the arena's and the hardware trial's options are refused before anything plays, within the reader's bounds
    base = ArenaConfig(controllers=("stand",), scenario=short, out_dir=tmp_path / "r", progress=False)
    for option, bad in (("trials", MAX_TRIALS + 1), ("seeds", (MAX_SEED + 1,)), ("seeds", (-1,)),
                        ("max_consecutive_errors", MAX_CONSECUTIVE_ERRORS + 1)):
        dataclasses.replace(base, **{option: bad // 2 if isinstance(bad, int) else (0,)})
        with pytest.raises(ConfigError, match=r"must be in \["):
            dataclasses.replace(base, **{option: bad})
    hw = dict(controller="stand", scenario=short, trial=0, seed=0, robot="go1-arm", simulate=True,
              out_dir=tmp_path / "hw")
    for option, bad in (("trial", MAX_TRIALS), ("seed", MAX_SEED + 1), ("seed", -1)):
        HardwareTrialConfig(**{**hw, option: MAX_TRIALS - 1 if option == "trial" else MAX_SEED})
        with pytest.raises(ConfigError, match=r"must be in \["):
            HardwareTrialConfig(**{**hw, option: bad})


def test_an_unreadable_run_json_and_one_of_another_kind(tmp_path: Path) -> None:
    path = tmp_path / "run.json"
    with pytest.raises(RecordError, match=rf"^{_re(path)}: missing"):
        RunIdentity.load(path)
    path.write_text("{not json")
    with pytest.raises(RecordError, match=rf"^{_re(path)}:1:2: not valid JSON: Expecting property name"):
        RunIdentity.load(path)
    path.write_text(json.dumps({"environment": {}}))
    with pytest.raises(RecordError, match=rf"^{_re(path)}: field config: missing"):
        RunIdentity.load(path)
    _write_config(tmp_path, HARDWARE.as_json())
    with pytest.raises(RecordError, match="holds a hardware run's identity where a simulated run's is needed"):
        SimulatedRunIdentity.load(path)
    assert HardwareRunIdentity.load(path) == HARDWARE


def _re(text: object) -> str:
    return re.escape(str(text))
