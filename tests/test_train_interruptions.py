"""An interrupted `wbc train`: what its run directory keeps, and that --resume continues from it."""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ctrl_c_in_adaptation_round

from wbc.learned.env.env_config import DomainRandomisation

torch = pytest.importorskip("torch")
pytest.importorskip("rsl_rl")

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = str(ROOT / "scenarios" / "push.toml")


def _tiny(root: Path, **kw):
    """A push stage-1 run of 8 environments and tiny networks, a checkpoint every iteration, no adaptation phase."""
    from wbc.learned.train.adaptation_config import AdaptationConfig
    from wbc.learned.train.stages import stage_config

    small = dict(seed=0, num_steps_per_env=6, save_interval=1, actor_hidden_dims=(16,), critic_hidden_dims=(16,),
                 encoder_dims=(8,), extrinsics_dim=4, rma=AdaptationConfig(iterations=0))
    return stage_config("push", 1, run_root=str(root), env_overrides=dict(
        num_envs=8, nthread=1, scenario=SCENARIO, domain=DomainRandomisation(num_variants=2), seed=0),
        **{**small, **kw})


@pytest.fixture(scope="module")
def two_iterations(tmp_path_factory) -> Path:
    """A finished two-iteration run (model_0.pt, model_1.pt): its run root."""
    from wbc.learned.train.train import train

    root = tmp_path_factory.mktemp("runs")
    train(_tiny(root, max_iterations=2))
    return root


def _files(run_dir: Path) -> dict[str, bytes]:
    """The checkpoints, the exported policy and the progress of a run directory, and any temporary file."""
    return {p.name: p.read_bytes() for p in sorted(run_dir.iterdir())
            if p.name.startswith(("model_", "policy.", "progress.")) or p.name.endswith(".tmp")}


def test_a_checkpoint_whose_write_fails_leaves_the_checkpoints_before_it_whole(two_iterations, tmp_path, monkeypatch):
    from wbc.learned.train.preflight import latest_checkpoint
    from wbc.learned.train.train import train

    shutil.copytree(two_iterations, tmp_path / "runs")
    run = tmp_path / "runs" / "push-stage1"
    before = _files(run)
    assert {"model_0.pt", "model_1.pt"} <= set(before)
    save = torch.save

    def torn(obj, f, *args, **kwargs):
        """A megabyte of the checkpoint written, then the disk is full (a kill leaves the same torn file)."""
        save(obj, f, *args, **kwargs)
        with open(f, "r+b") as out:
            out.truncate(min(1 << 20, out.seek(0, 2) // 2))
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(torch, "save", torn)
    with pytest.raises(OSError, match="No space left"):
        train(_tiny(tmp_path / "runs", max_iterations=3), resume=True)
    monkeypatch.setattr(torch, "save", save)
    assert _files(run) == before  # no model_2.pt, whole or torn, nor its temporary file; the export not refreshed
    assert latest_checkpoint(run).name == "model_1.pt"
    result = train(_tiny(tmp_path / "runs", max_iterations=3), resume=True)  # the resume the audit saw refused
    assert result["iterations"] == 3 and latest_checkpoint(run).name == "model_2.pt"
    assert _files(run)["model_1.pt"] == before["model_1.pt"]


def test_a_policy_file_whose_write_fails_leaves_the_pair_before_it_whole(two_iterations, tmp_path, monkeypatch):
    import wbc.output_files
    from wbc.learned.policy.policy_file import PolicyFile, PolicyFileError, load_policy, save_policy

    npz, js = tmp_path / "policy.npz", tmp_path / "policy.json"
    for path in (npz, js):
        shutil.copy(two_iterations / "push-stage1" / path.name, path)
    before = {p: p.read_bytes() for p in (npz, js)}
    old = load_policy(npz)
    new = PolicyFile(meta=old.meta, arrays={k: v + 1.0 for k, v in old.arrays.items()})
    # the JSON's temporary file cannot be written (a directory stands there): neither file changes
    (tmp_path / "policy.json.tmp").mkdir()
    with pytest.raises(OSError):
        save_policy(tmp_path / "policy", new)
    assert {p: p.read_bytes() for p in (npz, js)} == before and not (tmp_path / "policy.npz.tmp").exists()
    (tmp_path / "policy.json.tmp").rmdir()
    # killed between the two renames: the new weights beside the old JSON, a pair refused for its checksum, never one
    # that loads with another pair's metadata
    replace = wbc.output_files.os.replace

    def killed_before_the_json(src, dst):
        if Path(dst) == js:
            raise KeyboardInterrupt
        replace(src, dst)

    monkeypatch.setattr(wbc.output_files.os, "replace", killed_before_the_json)
    with pytest.raises(KeyboardInterrupt):
        save_policy(tmp_path / "policy", new)
    monkeypatch.setattr(wbc.output_files.os, "replace", replace)
    assert js.read_bytes() == before[js] and not list(tmp_path.glob("*.tmp"))
    with pytest.raises(PolicyFileError, match="sha256"):
        load_policy(npz)
    save_policy(tmp_path / "policy", new)  # written again: whole
    np.testing.assert_array_equal(load_policy(npz).arrays["obs_mean"], new.arrays["obs_mean"])


def _ctrl_c_in_update(monkeypatch, at: int, times: int = 1, signum: int = signal.SIGINT) -> None:
    """Ctrl-C (`signum`, `times` times) in the PPO update of the `at`-th iteration (from 0) the run trains from now."""
    from rsl_rl.algorithms import PPO

    update, calls = PPO.update, []

    def interrupted(self, *args, **kwargs):
        calls.append(None)
        if len(calls) == at + 1:
            for _ in range(times):
                signal.raise_signal(signum)
        return update(self, *args, **kwargs)

    monkeypatch.setattr(PPO, "update", interrupted)


def _state(checkpoint: Path) -> dict:
    """A checkpoint's networks, normalisers and optimiser (what rsl-rl saves but the iteration and infos)."""
    saved = torch.load(checkpoint, map_location="cpu", weights_only=False)
    return {k: v for k, v in saved.items() if k not in ("iter", "infos")}


def _same(a, b) -> bool:
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple):
        return isinstance(b, list | tuple) and len(a) == len(b) and all(map(_same, a, b))
    return torch.equal(a, b) if isinstance(a, torch.Tensor) else a == b


@pytest.mark.usefixtures("terminal_signals")
def test_ctrl_c_saves_the_iteration_it_stops_at_and_resume_continues_after_it(tmp_path, monkeypatch, capsys):
    from wbc.learned.train.preflight import latest_checkpoint
    from wbc.learned.train.train import train

    cfg = _tiny(tmp_path / "stopped", max_iterations=5, save_interval=25)  # periodic checkpoints: model_0.pt only
    run = Path(cfg.run_dir)
    _ctrl_c_in_update(monkeypatch, at=2)
    with pytest.raises(KeyboardInterrupt):
        train(cfg)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the handler before is back
    assert "stops at the end of the iteration in progress" in capsys.readouterr().err
    assert sorted(p.name for p in run.glob("model_*")) == ["model_0.pt", "model_2.pt"]
    assert json.loads((run / "progress.json").read_text())["iteration"] == 2
    assert json.loads((run / "policy.json").read_text())["training"]["iteration"] == 2
    monkeypatch.undo()
    # iteration 2 ended before it was saved: its checkpoint is the one a run never interrupted has after it
    whole = Path(train(_tiny(tmp_path / "whole", max_iterations=3, save_interval=25))["run_dir"])
    assert _same(_state(run / "model_2.pt"), _state(whole / "model_2.pt"))
    result = train(_tiny(tmp_path / "stopped", max_iterations=5, save_interval=25), resume=True)
    assert (result["iterations"], result["trained"]) == (5, 2) and latest_checkpoint(run).name == "model_4.pt"


@pytest.mark.usefixtures("terminal_signals")
def test_an_interrupted_run_names_the_checkpoint_it_saved_and_a_second_ctrl_c_stops_at_once(tmp_path, monkeypatch,
                                                                                           capsys):
    from wbc.cli.main import main

    argv = ["train", "--task", "push", "--stage", "1", "--iterations", "4", "--envs", "1", "--rma-iterations", "0",
            "--run-root", str(tmp_path)]
    run = tmp_path / "push-stage1"
    _ctrl_c_in_update(monkeypatch, at=2)
    assert main(argv) == 130
    err = capsys.readouterr().err
    assert "wbc: interrupted; " in err and "keeps its newest checkpoint, model_2.pt: the same command with --resume " \
        "continues from it" in err
    # twice: the second stops in the middle of the update, whose model is no iteration's: nothing more is saved
    monkeypatch.undo()
    _ctrl_c_in_update(monkeypatch, at=0, times=2)
    assert main([*argv, "--resume"]) == 130
    assert "keeps its newest checkpoint, model_2.pt" in capsys.readouterr().err
    assert sorted(p.name for p in run.glob("model_*")) == ["model_0.pt", "model_2.pt"]
    assert json.loads((run / "progress.json").read_text())["iteration"] == 2
    monkeypatch.undo()
    assert main([*argv, "--resume"]) == 0
    assert json.loads((run / "progress.json").read_text())["iteration"] == 3 and (run / "model_3.pt").is_file()


@pytest.mark.usefixtures("terminal_signals")
def test_sigterm_stops_a_training_run_as_ctrl_c_does_at_the_end_of_its_iteration(tmp_path, monkeypatch, capsys):
    """A batch scheduler's SIGTERM: the iteration in progress ends and is saved, then the command stops as Ctrl-C."""
    from wbc.cli.main import main

    argv = ["train", "--task", "push", "--stage", "1", "--iterations", "4", "--envs", "1", "--rma-iterations", "0",
            "--run-root", str(tmp_path)]
    before = signal.getsignal(signal.SIGTERM)
    _ctrl_c_in_update(monkeypatch, at=2, signum=signal.SIGTERM)
    assert main(argv) == 130
    err = capsys.readouterr().err
    assert "wbc: SIGTERM: the run stops at the end of the iteration in progress" in err
    assert "keeps its newest checkpoint, model_2.pt: the same command with --resume continues from it" in err
    assert json.loads((tmp_path / "push-stage1" / "progress.json").read_text())["iteration"] == 2
    assert signal.getsignal(signal.SIGTERM) == before  # the command's handlers are gone
    # the session stopped at iteration 2: config.json says so, and so does the export of that checkpoint
    segment = json.loads((tmp_path / "push-stage1" / "config.json").read_text())["segments"][-1]
    assert (segment["to_iteration"], segment["interrupted"]) == (2, True)
    training = json.loads((tmp_path / "push-stage1" / "policy.json").read_text())["training"]
    assert training["segments"][-1] == segment
    # a command that can be pasted, not the path of the module that ran it
    assert segment["command"] == "wbc " + " ".join(argv) == training["command"]


_HOLDER = """
import signal, sys
from wbc.learned.train.preflight import lock_run_dir
locks = [lock_run_dir(d) for d in sys.argv[1:]]
print("held", flush=True)
signal.pause()
"""


@pytest.fixture()
def holder():
    """Start another process that locks run directories as a run does (`lock_run_dir`), until it is killed."""
    procs: list[subprocess.Popen] = []

    def hold(*run_dirs: Path) -> subprocess.Popen:
        path = os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
        proc = subprocess.Popen([sys.executable, "-c", _HOLDER, *map(str, run_dirs)], stdout=subprocess.PIPE,
                                text=True, env={**os.environ, "PYTHONPATH": path})
        procs.append(proc)
        assert proc.stdout.readline().strip() == "held"
        return proc

    yield hold
    for proc in procs:
        proc.kill()
        proc.wait()


def _tree(run_dir: Path) -> dict[str, bytes]:
    return {str(p.relative_to(run_dir)): p.read_bytes() for p in sorted(run_dir.rglob("*")) if p.is_file()}


def test_a_run_directory_another_run_holds_is_refused_naming_it_and_its_pid(two_iterations, tmp_path, capsys, holder):
    from wbc.cli.main import main
    from wbc.errors import ConfigError
    from wbc.learned.train.preflight import lock_run_dir
    from wbc.learned.train.train import train
    from wbc.tools.dagger import DaggerConfig, run_dagger

    root = tmp_path / "runs"
    shutil.copytree(two_iterations, root)
    stage1, fine_tune, dagger = root / "push-stage1", root / "push-fine-tune", root / "push-dagger-mpc"
    for run in (fine_tune, dagger):
        run.mkdir()
    other = holder(stage1, fine_tune, dagger)
    before = {run: _tree(run) for run in (stage1, fine_tune, dagger)}
    tiny = ["--envs", "1", "--run-root", str(root)]
    for run, argv in ((stage1, ["--stage", "1", "--iterations", "3", "--rma-iterations", "0", *tiny, "--resume"]),
                      (stage1, ["--stage", "1", "--iterations", "3", "--rma-iterations", "0", *tiny]),
                      (fine_tune, ["--fine-tune", "shipped", "--iterations", "1", *tiny]),
                      (dagger, ["--teacher", "mpc", "--rounds", "1", "--episodes", "1", "--run-root", str(root)])):
        for dry_run in ([], ["--dry-run"]):
            assert main(["train", "--task", "push", *argv, *dry_run]) == 2
            err = capsys.readouterr().err
            assert f"{run} is in use by another run (pid {other.pid}, holding {run / '.lock'})" in err, err
            assert "--run-root" in err and len(err.strip().splitlines()) == 1
    # the runs themselves lock their directory before they read it, whoever calls them
    with pytest.raises(ConfigError, match=f"in use by another run \\(pid {other.pid}"):
        train(_tiny(root, max_iterations=3), resume=True)
    with pytest.raises(ConfigError, match=f"in use by another run \\(pid {other.pid}"):
        run_dagger(DaggerConfig(task="push", rounds=1, episodes=1, episode_s=0.1, run_dir=str(dagger)))
    assert {run: _tree(run) for run in before} == before
    # the lock dies with its process, however it ends
    other.kill()
    other.wait()
    lock_run_dir(stage1).release()
    assert train(_tiny(root, max_iterations=3), resume=True)["iterations"] == 3
    assert (stage1 / ".lock").read_bytes() == b""  # released: no pid left to name


@pytest.mark.parametrize("torn", [0, 1 << 20])
def test_a_torn_newest_checkpoint_is_refused_naming_the_one_before_and_nothing_is_deleted(two_iterations, tmp_path,
                                                                                         torn):
    from wbc.errors import ConfigError
    from wbc.learned.train.train import train

    for copy in ("only", "runs"):
        shutil.copytree(two_iterations, tmp_path / copy)
    only = tmp_path / "only" / "push-stage1"
    (only / "model_0.pt").unlink()
    run = tmp_path / "runs" / "push-stage1"
    for newest in (run / "model_1.pt", only / "model_1.pt"):
        with newest.open("r+b") as f:  # as an in-place write killed midway left it: 0 bytes, or exactly 1 MiB
            f.truncate(torn)
    before = _tree(run)
    with pytest.raises(ConfigError) as refused:
        train(_tiny(tmp_path / "runs", max_iterations=3), resume=True)
    assert "model_1.pt: not a readable checkpoint" in str(refused.value)
    assert "to resume from model_0.pt, the newest checkpoint before it (training again from iteration 1)" in str(
        refused.value)
    assert _tree(run) == before  # refused, not skipped: the file may be whole to another version of torch
    with pytest.raises(ConfigError, match="model_1.pt: not a readable checkpoint.*the run's only checkpoint"):
        train(_tiny(tmp_path / "only", max_iterations=3), resume=True)
    # as the message says: moved away, the run resumes from the checkpoint before it
    (run / "model_1.pt").rename(tmp_path / "model_1.pt")
    assert train(_tiny(tmp_path / "runs", max_iterations=3), resume=True)["iterations"] == 3
    assert sorted(p.name for p in run.glob("model_*")) == ["model_0.pt", "model_1.pt", "model_2.pt"]


def _rma(rounds: int):
    from wbc.learned.train.adaptation_config import AdaptationConfig

    return AdaptationConfig(iterations=rounds, steps_per_iteration=4, history=3, hidden_dims=(8,), minibatch=64)


@pytest.mark.usefixtures("terminal_signals")
def test_ctrl_c_in_the_adaptation_phase_keeps_the_export_before_it_and_resume_fits_it_again(tmp_path, monkeypatch):
    """An interrupted phase 2 leaves the export it found (its module too), never the checkpoint's without a module."""
    import wbc.learned.train.train as train_module
    from wbc.learned.policy.policy_file import load_policy

    train_module.train(_tiny(tmp_path, max_iterations=1, rma=_rma(1)))
    run = tmp_path / "push-stage1"
    kept = {n: (run / n).read_bytes() for n in ("policy.npz", "policy.json", "rma.json", "progress.json")}
    ctrl_c_in_adaptation_round(train_module, monkeypatch, 2)
    with pytest.raises(KeyboardInterrupt):
        train_module.train(_tiny(tmp_path, max_iterations=1, rma=_rma(3)), resume=True)
    assert {n: (run / n).read_bytes() for n in kept} == kept
    assert load_policy(run / "policy").meta["adaptation"]["iterations"] == 1  # still playable
    monkeypatch.undo()
    result = train_module.train(_tiny(tmp_path, max_iterations=1, rma=_rma(3)), resume=True)
    assert result["adaptation"] == "fitted" and load_policy(run / "policy").meta["adaptation"]["iterations"] == 3
    assert len(json.loads((run / "rma.json").read_text())["losses"]) == 3
    # resumed again with the same phase 2, the finished run keeps its module: neither fitted again nor replaced
    fitted = {n: (run / n).read_bytes() for n in ("policy.npz", "policy.json", "rma.json")}
    result = train_module.train(_tiny(tmp_path, max_iterations=1, rma=_rma(3)), resume=True)
    assert result["adaptation"] == "kept" and {n: (run / n).read_bytes() for n in fitted} == fitted


def test_the_export_carries_the_runs_provenance_from_its_config(two_iterations):
    """A shipped copy of policy.json says how it was made: the inputs, seed, scenario, command and versions."""
    run = two_iterations / "push-stage1"
    config = json.loads((run / "config.json").read_text())
    training = json.loads((run / "policy.json").read_text())["training"]
    for key in ("seed", "command", "scenario", "inputs", "provenance", "started"):
        assert training[key] == config[key], key
    assert training["scenario"]["path"] == str(Path(SCENARIO).resolve()) and len(training["scenario"]["sha256"]) == 64
    assert "git_revision" in training["provenance"] and training["segments"][0]["from_iteration"] == 0
    # the session's end is recorded before the final export, which carries it
    assert training["segments"] == config["segments"]
    assert (training["segments"][-1]["to_iteration"], training["segments"][-1]["adaptation"]) == (1, "none")


def test_the_training_block_names_the_scenario_by_the_arenas_content_hash_too(two_iterations):
    """The file's sha256 changes with a comment; trials.csv and published.toml name a scenario by its content hash."""
    from wbc.scenario.scenario import load_scenario

    scenario = json.loads((two_iterations / "push-stage1" / "policy.json").read_text())["training"]["scenario"]
    shipped = load_scenario(SCENARIO)
    assert (scenario["name"], scenario["version"], scenario["content_hash"]) == (shipped.name, shipped.version,
                                                                                 shipped.hash)
    assert scenario["content_hash"] != scenario["sha256"]


def test_the_physics_threads_change_no_checkpoint_so_a_resume_may_change_them(two_iterations, tmp_path):
    """A run on 2 threads saves the checkpoint a run on 1 does, bit for bit: its resume may take other threads."""
    from wbc.learned.train.train import train

    other = Path(train(_threads(tmp_path / "two", 2, max_iterations=2))["run_dir"])
    assert _same(_state(other / "model_1.pt"), _state(two_iterations / "push-stage1" / "model_1.pt"))
    shutil.copytree(two_iterations, tmp_path / "runs")
    result = train(_threads(tmp_path / "runs", 2, max_iterations=3), resume=True)
    assert result["iterations"] == 3
    config = json.loads((tmp_path / "runs" / "push-stage1" / "config.json").read_text())
    assert config["train_config"]["env"]["nthread"] == 2
    assert config["segments"][-1]["changed"]["env.nthread"] == [1, 2]


def _threads(root: Path, nthread: int, **kw):
    """`_tiny` on `nthread` physics threads."""
    import dataclasses

    cfg = _tiny(root, **kw)
    return dataclasses.replace(cfg, env=dataclasses.replace(cfg.env, nthread=nthread))


@pytest.mark.usefixtures("terminal_signals")
def test_a_finished_run_extended_then_stopped_keeps_its_playable_export_and_says_how_to_finish(tmp_path, monkeypatch):
    """A checkpoint's export has no adaptation module: it is written beside a playable export, never over it."""
    import wbc.learned.train.train as train_module
    from wbc.learned.policy.policy_file import load_policy

    train_module.train(_tiny(tmp_path, max_iterations=1, rma=_rma(1)))
    run = tmp_path / "push-stage1"
    playable = {n: (run / n).read_bytes() for n in ("policy.npz", "policy.json")}
    _ctrl_c_in_update(monkeypatch, at=1, signum=signal.SIGTERM)
    with pytest.raises(KeyboardInterrupt):
        train_module.train(_tiny(tmp_path, max_iterations=6, rma=_rma(1)), resume=True)
    monkeypatch.undo()
    # every checkpoint since (model_1.pt, model_2.pt) exported beside it: the run's policy plays as it did
    assert {n: (run / n).read_bytes() for n in playable} == playable
    assert load_policy(run / "policy").meta["adaptation"] is not None
    ppo = load_policy(run / "policy_ppo")
    assert ppo.meta["training"]["iteration"] == 2 and ppo.meta.get("adaptation") is None
    # finished at that checkpoint: its module fitted, the run's policy replaced, the PPO-phase export gone
    result = train_module.train(_tiny(tmp_path, max_iterations=3, rma=_rma(1)), resume=True)
    assert result["trained"] == 0 and result["adaptation"] == "fitted"
    finished = load_policy(run / "policy")
    assert finished.meta["training"]["iteration"] == 2 and finished.meta["adaptation"] is not None
    last = finished.meta["training"]["segments"][-1]  # the session's end, in the export phase 2 wrote
    assert (last["from_iteration"], last["to_iteration"], last["adaptation"]) == (3, 2, "fitted")
    assert not (run / "policy_ppo.npz").exists() and not (run / "policy_ppo.json").exists()


@pytest.mark.usefixtures("terminal_signals")
def test_an_interrupted_run_says_whether_its_export_is_playable_and_how_to_finish_it(tmp_path, monkeypatch, capsys):
    from wbc.cli.main import main

    argv = ["train", "--task", "push", "--stage", "1", "--envs", "1", "--rma-iterations", "1", "--run-root",
            str(tmp_path)]
    _ctrl_c_in_update(monkeypatch, at=1, signum=signal.SIGTERM)
    assert main([*argv, "--iterations", "4"]) == 130  # a first interruption: no module yet
    err = capsys.readouterr().err
    assert "its export, policy.json, has no adaptation module yet, so it is not playable: the same command with " \
        "--resume and --iterations 2 fits the module on model_1.pt without training further" in err
    monkeypatch.undo()
    assert main([*argv, "--iterations", "2", "--resume"]) == 0  # finished there, as it says: playable
    _ctrl_c_in_update(monkeypatch, at=1, signum=signal.SIGTERM)
    assert main([*argv, "--iterations", "6", "--resume"]) == 130
    err = capsys.readouterr().err
    assert "its export, policy.json, is playable and of iteration 1 (model_3.pt's, without the module, is " \
        "policy_ppo.json): the same command with --resume and --iterations 4 fits the module on model_3.pt" in err
    assert err.strip().splitlines()[-1].startswith("wbc: interrupted; ")  # all of it in the closing line
