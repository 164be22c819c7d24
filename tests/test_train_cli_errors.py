"""`wbc train`: refusals of bad runs and arguments, one line and status 2, and what a resumed run reports."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from pathlib import Path

import pytest
from conftest import ctrl_c_in_adaptation_round

from wbc.cli.main import main
from wbc.errors import ConfigError

TINY = ["--iterations", "1", "--envs", "1", "--rma-iterations", "0"]


@pytest.fixture(scope="module")
def stage1_run(tmp_path_factory) -> Path:
    """A finished one-iteration push stage-1 run: its run root."""
    pytest.importorskip("torch")
    pytest.importorskip("rsl_rl")
    root = tmp_path_factory.mktemp("runs")
    assert main(["train", "--task", "push", "--stage", "1", *TINY, "--run-root", str(root)]) == 0
    return root


def _copy(root: Path, tmp_path: Path) -> Path:
    """A copy of the run under `root`, its config.json naming where the copy lies (a resumed run must match it)."""
    shutil.copytree(root, tmp_path / "runs")
    config = tmp_path / "runs" / "push-stage1" / "config.json"
    saved = json.loads(config.read_text())
    saved["train_config"]["run_dir"] = str(config.parent)
    config.write_text(json.dumps(saved, indent=2) + "\n")
    return tmp_path / "runs"


def _snapshot(run_dir: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(run_dir.iterdir()) if p.is_file()}


def test_a_new_run_refuses_a_run_directory_that_holds_a_run(stage1_run, tmp_path, capsys):
    root = _copy(stage1_run, tmp_path)
    before = _snapshot(root / "push-stage1")
    capsys.readouterr()
    assert main(["train", "--task", "push", "--stage", "1", *TINY, "--run-root", str(root)]) == 2
    err = capsys.readouterr().err
    assert "push-stage1 already holds a training run" in err and "--resume" in err and "--run-root" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert _snapshot(root / "push-stage1") == before
    # a fine-tune's run directory too
    run = root / "push-fine-tune"
    run.mkdir()
    (run / "config.json").write_text("{}")
    assert main(["train", "--task", "push", "--fine-tune", "shipped", *TINY[:4], "--run-root", str(root)]) == 2
    assert "push-fine-tune already holds a training run" in capsys.readouterr().err
    assert (run / "config.json").read_text() == "{}"


def test_a_resume_that_reaches_no_further_trains_nothing_and_exports_its_checkpoint(stage1_run, tmp_path, capsys):
    root = _copy(stage1_run, tmp_path)
    run = root / "push-stage1"
    before = _snapshot(run)
    capsys.readouterr()
    assert main(["train", "--task", "push", "--stage", "1", *TINY, "--run-root", str(root), "--resume"]) == 0
    out = capsys.readouterr().out
    assert "already holds 1 iterations" in out and "nothing new trained" in out and "2 iterations" not in out
    assert "its newest checkpoint is exported as it is" in out  # how an interrupted run is finished (the guide's)
    assert json.loads((run / "progress.json").read_text())["iteration"] == 0
    assert json.loads((run / "policy.json").read_text())["training"]["iteration"] == 0
    assert not (run / "model_1.pt").exists()
    after = _snapshot(run)
    assert after["model_0.pt"] == before["model_0.pt"]  # the run itself untouched; its policy exported again
    # its config.json the same but for the segment this resume adds, which changed nothing
    config, began = json.loads(after["config.json"]), json.loads(before["config.json"])
    segments = config.pop("segments")
    assert segments[:-1] == began.pop("segments") and config == began
    assert segments[-1]["resumed"] and segments[-1]["changed"] == {} and segments[-1]["to_iteration"] == 0


@pytest.mark.parametrize(("damage", "said"), [
    (lambda run: (run / "config.json").unlink(), "config.json: no such file"),
    (lambda run: (run / "config.json").write_text("{bad"), "config.json: not JSON"),
    (lambda run: (run / "config.json").write_text("{}"), "config.json: train_config: missing"),
    (lambda run: (run / "progress.json").write_text("nope"), "progress.json: not JSON"),
    (lambda run: (run / "model_0.pt").write_text("text"), "model_0.pt: not a readable checkpoint"),
])
def test_resume_refuses_a_damaged_run_directory_in_one_line(stage1_run, tmp_path, capsys, damage, said):
    root = _copy(stage1_run, tmp_path)
    damage(root / "push-stage1")
    capsys.readouterr()
    argv = ["train", "--task", "push", "--stage", "1", "--iterations", "2", "--envs", "1", "--rma-iterations", "0",
            "--run-root", str(root), "--resume"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert said in err and "--resume" in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("where", [["--stage", "1"], ["--stage", "3", "--baseline", "ppo"]])
def test_teacher_is_refused_where_it_does_not_apply(tmp_path, capsys, where):
    argv = ["train", "--task", "push", *where, "--teacher", str(tmp_path / "missing.npz"), "--dry-run"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--teacher does not apply to stage" in err and len(err.strip().splitlines()) == 1


def test_a_mistyped_teacher_names_the_controllers_and_dry_run_checks_files(tmp_path, capsys):
    assert main(["train", "--task", "push", "--teacher", "mcp", "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert "--teacher mcp is neither a controller nor a file" in err and "mpc" in err and "--stage" not in err
    assert main(["train", "--task", "push", "--stage", "2", "--teacher", "mcp", "--dry-run"]) == 2
    assert "--teacher mcp is neither a controller nor a file" in capsys.readouterr().err
    # with DAgger's own options, the name is what is wrong, not the options (they were said to need a controller)
    assert main(["train", "--task", "push", "--teacher", "mcp", "--rounds", "1", "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert "--teacher mcp is neither a controller nor a file" in err and "--rounds" not in err
    missing = tmp_path / "student.npz"
    assert main(["train", "--task", "push", "--fine-tune", str(missing), "--dry-run"]) == 2
    assert f"--fine-tune {missing}: no such file" in capsys.readouterr().err


def test_a_fine_tune_refuses_expert_samples_of_another_task(tmp_path, capsys):
    pytest.importorskip("torch")
    pytest.importorskip("rsl_rl")
    dagger = tmp_path / "push-dagger-mpc"
    dagger.mkdir()
    (dagger / "data.npz").write_bytes(b"")  # refused before it is read
    (dagger / "config.json").write_text(json.dumps({"dagger_config": {"task": "push", "expert": "mpc"}}))
    argv = ["train", "--task", "turn", "--fine-tune", "shipped", "--expert-data", str(dagger / "data.npz"),
            "--iterations", "1", "--envs", "1", "--run-root", str(tmp_path / "runs")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "data.npz: collected on task 'push' (a1-wx200" in err and "task 'turn' (go1-arm)" in err
    assert not (tmp_path / "runs").exists()
    assert main([*argv, "--dry-run"]) == 2
    assert "collected on task 'push'" in capsys.readouterr().err


@pytest.mark.parametrize("resume", [[], ["--resume"]])
def test_a_run_interrupted_before_its_first_checkpoint_starts_afresh(stage1_run, tmp_path, capsys, resume):
    root = tmp_path / "runs"
    run = root / "push-stage1"
    run.mkdir(parents=True)
    shutil.copy(stage1_run / "push-stage1" / "config.json", run / "config.json")  # all such a run leaves
    capsys.readouterr()
    assert main(["train", "--task", "push", "--stage", "1", *TINY, "--run-root", str(root), *resume]) == 0
    err = capsys.readouterr().err
    assert "interrupted before its first checkpoint" in err and "starts afresh" in err
    assert json.loads((run / "progress.json").read_text())["iteration"] == 0 and (run / "model_0.pt").is_file()
    assert json.loads((run / "config.json").read_text())["train_config"]["run_dir"] == str(run)


def test_resume_compares_the_run_directory_and_the_inputs_as_paths_not_text(tmp_path, monkeypatch):
    from wbc.learned.train.preflight import check_run_dir
    from wbc.learned.train.stages import stage_config

    monkeypatch.chdir(tmp_path)
    began = stage_config("push", 2, run_root="runs", teacher="teachers/pi1/policy")  # as the run began
    run = tmp_path / "runs" / "push-stage2"
    run.mkdir(parents=True)
    (run / "model_0.pt").write_bytes(b"")  # its name is all this check reads
    saved = json.loads(json.dumps(dataclasses.asdict(began), default=list))
    (run / "config.json").write_text(json.dumps({"train_config": saved}))
    # the same run, its root given as an absolute path and its teacher by the pair's .npz
    same = stage_config("push", 2, run_root=str(tmp_path / "runs"), teacher=str(tmp_path / "teachers/pi1/policy.npz"))
    assert check_run_dir(same, resume=True).done == 1
    other = stage_config("push", 2, run_root="runs", teacher="teachers/pi0/policy")
    # a run begun before its inputs' hashes were recorded: compared by path
    with pytest.raises(ConfigError, match=r"teacher: this run reads .*pi0/policy, whose path is not the one"):
        check_run_dir(other, resume=True)


def test_a_dagger_run_resumes_under_another_spelling_of_its_run_root(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # MuJoCo may write its log file here
    args = ["train", "--task", "push", "--teacher", "mpc", "--rounds", "1", "--episodes", "1", "--episode-s", "0.1"]
    assert main([*args, "--run-root", "runs"]) == 0
    assert main([*args, "--run-root", str(tmp_path / "runs"), "--resume"]) == 0
    assert "differs" not in capsys.readouterr().err


def test_a_resume_takes_the_options_not_given_from_the_run_and_names_a_changed_nested_field(stage1_run, tmp_path,
                                                                                           capsys):
    root = _copy(stage1_run, tmp_path)
    run = root / "push-stage1"
    capsys.readouterr()
    # made with --iterations 1 --envs 1 --rma-iterations 0: resumed without them, it is that run, not the defaults'
    assert main(["train", "--task", "push", "--stage", "1", "--run-root", str(root), "--resume"]) == 0
    captured = capsys.readouterr()
    assert "gave the options not given" in captured.err
    assert "--iterations 1" in captured.err and "--envs 1" in captured.err and "--rma-iterations 0" in captured.err
    assert "nothing new trained" in captured.out and not (run / "rma.json").exists()
    assert main(["train", "--task", "push", "--stage", "1", "--envs", "2", "--run-root", str(root), "--resume"]) == 2
    err = capsys.readouterr().err
    assert "differs from this run's config in ['env.num_envs']" in err.strip().splitlines()[-1]
    assert "Traceback" not in err


def test_a_resumed_stage_says_which_options_it_took_before_it_trains(stage1_run, tmp_path, capsys, monkeypatch):
    """The note comes once the run's checks pass, before anything is built: it came at the run's end, after hours."""
    import wbc.learned.train.train as train_module

    root = _copy(stage1_run, tmp_path)
    said_before: list[str] = []
    real = train_module._train

    def training(cfg, point, *args):
        said_before.append(capsys.readouterr().err)
        return real(cfg, point, *args)

    monkeypatch.setattr(train_module, "_train", training)
    capsys.readouterr()
    assert main(["train", "--task", "push", "--stage", "1", "--run-root", str(root), "--resume"]) == 0
    assert len(said_before) == 1 and said_before[0].count("gave the options not given") == 1
    assert "gave the options not given" not in capsys.readouterr().err  # said once


def test_a_resume_refuses_a_teacher_whose_weights_changed_since_the_run_began(stage1_run, tmp_path, monkeypatch):
    from wbc.learned.train.preflight import check_run_dir, input_files
    from wbc.learned.train.stages import stage_config

    assert json.loads((stage1_run / "push-stage1" / "config.json").read_text())["inputs"] == {}  # stage 1 reads none
    monkeypatch.chdir(tmp_path)
    teacher = tmp_path / "runs" / "push-stage1"
    shutil.copytree(stage1_run / "push-stage1", teacher)
    cfg = stage_config("push", 2, run_root="runs")  # its teacher: the stage-1 export beside it
    run = tmp_path / "runs" / "push-stage2"
    run.mkdir()
    (run / "model_0.pt").write_bytes(b"")
    inputs = input_files(cfg)
    assert set(inputs["teacher"]["sha256"]) == {str(teacher / "policy.npz"), str(teacher / "policy.json")}
    saved = json.loads(json.dumps(dataclasses.asdict(cfg), default=list))
    (run / "config.json").write_text(json.dumps({"train_config": saved, "inputs": inputs}))
    assert check_run_dir(cfg, resume=True).done == 1
    (teacher / "policy.npz").write_bytes((teacher / "policy.npz").read_bytes() + b"\0")  # stage 1 trained again
    with pytest.raises(ConfigError, match=r"policy\.npz \(teacher\) changed since the run began"):
        check_run_dir(cfg, resume=True)


def test_a_resume_scales_progress_of_another_checkpoint_and_refuses_counts_that_are_not_finite(stage1_run, tmp_path,
                                                                                                capsys):
    root = _copy(stage1_run, tmp_path)
    run = root / "push-stage1"
    progress = json.loads((run / "progress.json").read_text())
    assert progress["iteration"] == 0
    # a newer checkpoint, model_2.pt, was damaged and deleted: progress.json still counts its 3 iterations
    (run / "progress.json").write_text(json.dumps({"iteration": 2, "env_steps": 3 * progress["env_steps"],
                                                   "wall_s": 3.0}))
    capsys.readouterr()
    argv = ["train", "--task", "push", "--stage", "1", *TINY, "--run-root", str(root), "--resume"]
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "counts 3 iterations, model_0.pt holds 1" in err
    assert json.loads((run / "progress.json").read_text())["env_steps"] == progress["env_steps"]
    assert json.loads((run / "policy.json").read_text())["training"]["env_steps"] == progress["env_steps"]
    (run / "progress.json").write_text('{"iteration": 0, "env_steps": 24, "wall_s": NaN}')
    assert main([*argv, "--dry-run"]) == 2
    assert "progress.json: wall_s: missing, negative or not a finite number" in capsys.readouterr().err


@pytest.mark.parametrize("teacher", [[], ["--teacher", "mpc", "--rounds", "1", "--episodes", "1"]])
def test_a_run_root_that_is_a_file_is_refused_naming_the_option(tmp_path, capsys, teacher):
    pytest.importorskip("torch")
    (tmp_path / "a-file").write_text("")
    stage = [] if teacher else ["--stage", "1", *TINY]
    for root in (tmp_path / "a-file", tmp_path / "a-file" / "below"):
        assert main(["train", "--task", "push", *stage, *teacher, "--run-root", str(root)]) == 2
        err = capsys.readouterr().err
        assert "--run-root: " in err and "is a file, not a directory" in err and "Traceback" not in err


@pytest.mark.parametrize("teacher", [[], ["--teacher", "mpc", "--rounds", "1", "--episodes", "1"]])
def test_a_run_root_this_user_cannot_write_is_refused_by_the_dry_run_too(tmp_path, capsys, monkeypatch, teacher):
    # root may write anywhere, so the folder's mode cannot show it here: os.access answers as for another user
    pytest.importorskip("torch")
    from wbc.learned.train import preflight

    locked = tmp_path / "locked"
    locked.mkdir()
    monkeypatch.setattr(preflight.os, "access", lambda path, mode: Path(path) != locked)
    stage = [] if teacher else ["--stage", "1", *TINY]
    for root in (locked, locked / "below"):
        assert main(["train", "--task", "push", *stage, *teacher, "--run-root", str(root), "--dry-run"]) == 2
        err = capsys.readouterr().err
        assert f"--run-root: {locked} cannot be written by this user" in err and "Traceback" not in err
    assert not any(locked.iterdir())


def test_the_dry_run_refuses_the_checkpoint_student_and_expert_samples_the_run_would(stage1_run, tmp_path, capsys):
    root = _copy(stage1_run, tmp_path)
    checkpoint = root / "push-stage1" / "model_0.pt"
    checkpoint.write_bytes(checkpoint.read_bytes()[:1000])  # truncated
    capsys.readouterr()
    assert main(["train", "--task", "push", "--stage", "1", *TINY, "--run-root", str(root), "--resume",
                 "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert "model_0.pt: not a readable checkpoint" in err and len(err.strip().splitlines()) == 1
    # a student that does not read its own history (a stage's policy), and expert samples that are no samples
    fine_tune = ["train", "--task", "push", "--iterations", "1", "--envs", "1", "--run-root", str(tmp_path / "ft")]
    assert main([*fine_tune, "--fine-tune", str(stage1_run / "push-stage1" / "policy"), "--dry-run"]) == 2
    assert "latent z comes from its observation history alone" in capsys.readouterr().err
    junk = tmp_path / "data.npz"
    junk.write_bytes(b"junk")
    assert main([*fine_tune, "--fine-tune", "shipped", "--expert-data", str(junk), "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert f"--expert-data {junk}: cannot be read" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "ft").exists()


def test_a_refused_input_file_is_named_by_the_option_that_gave_it(stage1_run, tmp_path, capsys):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"junk")
    args = ["train", "--task", "push", "--run-root", str(tmp_path / "runs"), "--dry-run"]
    assert main([*args, "--stage", "2", "--teacher", str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"--teacher {bad}: not usable" in err and "Train the previous stage first" not in err
    stage1 = stage1_run / "push-stage1" / "policy"  # drives the arm 'none'
    assert main([*args, "--stage", "3", "--teacher", str(stage1)]) == 2
    assert f"--teacher {stage1} drives a1-wx200 with arm 'none'; stage 3 needs" in capsys.readouterr().err
    # the student is the fine-tune's option, not a teacher
    for student in (bad, stage1):
        assert main([*args, "--fine-tune", str(student)]) == 2
        err = capsys.readouterr().err
        assert f"--fine-tune {student}: " in err and "error: teacher" not in err and len(err.strip().splitlines()) == 1
    # a default input is still named as the previous stage's, which may be trained after the dry run
    assert main([*args, "--stage", "2"]) == 0
    assert "learns from the previous stage's policy" in capsys.readouterr().err


def test_a_policy_exported_without_its_adaptation_module_says_it_is_not_playable(stage1_run, tmp_path, capsys):
    root = _copy(stage1_run, tmp_path)  # made with --rma-iterations 0
    capsys.readouterr()
    argv = ["train", "--task", "push", "--stage", "1", *TINY, "--run-root", str(root), "--resume"]
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "observes extrinsics (RMA's z) and has no adaptation module" in err and "not playable" in err
    assert "--resume --rma-iterations K" in err
    # as the note says: the module is added, and the note is gone
    assert main(["train", "--task", "push", "--stage", "1", "--iterations", "1", "--envs", "1", "--rma-iterations", "1",
                 "--run-root", str(root), "--resume"]) == 0
    assert "not playable" not in capsys.readouterr().err
    assert (root / "push-stage1" / "rma.json").is_file()


def test_an_interrupted_run_says_which_checkpoint_it_keeps_and_that_resume_continues(stage1_run, tmp_path, capsys,
                                                                                     monkeypatch):
    import wbc.learned.train.train as train_module

    def interrupted(cfg, **_):
        raise KeyboardInterrupt

    monkeypatch.setattr(train_module, "train", interrupted)
    root = _copy(stage1_run, tmp_path)
    capsys.readouterr()
    assert main(["train", "--task", "push", "--stage", "1", *TINY, "--run-root", str(root), "--resume"]) == 130
    err = capsys.readouterr().err
    assert "wbc: interrupted; " in err and "keeps its newest checkpoint, model_0.pt" in err
    assert "the same command with --resume continues from it" in err and len(err.strip().splitlines()) == 1
    assert main(["train", "--task", "push", "--stage", "1", *TINY, "--run-root", str(tmp_path / "new")]) == 130
    assert "holds no checkpoint yet (model_<it>.pt): the same command starts the run afresh" in capsys.readouterr().err



@pytest.mark.usefixtures("terminal_signals")
def test_ctrl_c_in_the_adaptation_phase_says_the_export_keeps_the_module_it_had(stage1_run, tmp_path, capsys,
                                                                                 monkeypatch):

    import wbc.learned.train.train as train_module
    from wbc.learned.policy.policy_file import load_policy

    root = _copy(stage1_run, tmp_path)
    run = root / "push-stage1"
    argv = ["train", "--task", "push", "--stage", "1", "--run-root", str(root), "--resume"]
    assert main([*argv, "--rma-iterations", "1"]) == 0  # the module added without training PPO further
    kept = {n: (run / n).read_bytes() for n in ("policy.npz", "policy.json", "rma.json")}
    ctrl_c_in_adaptation_round(train_module, monkeypatch, 2)
    capsys.readouterr()
    assert main([*argv, "--rma-iterations", "3"]) == 130
    err = capsys.readouterr().err
    assert "keeps its newest checkpoint, model_0.pt, and its export the adaptation module it had (1 round" in err
    assert {n: (run / n).read_bytes() for n in kept} == kept
    assert load_policy(run / "policy").meta["adaptation"]["iterations"] == 1

def test_the_help_names_every_run_directory_and_when_stage_is_not_needed(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["train", "--help"])
    assert exit_.value.code == 0
    text = " ".join(capsys.readouterr().out.split())  # argparse wraps the lines
    assert "RUN_ROOT/<task>-dagger-<controller>" in text and "RUN_ROOT/<task>-fine-tune[-expert]" in text
    assert "required unless --teacher names a controller, or with --fine-tune" in text
    assert main(["train", "--task", "push", "--dry-run"]) == 2
    assert "or --fine-tune STUDENT" in capsys.readouterr().err


def test_a_stage_refuses_the_export_of_a_previous_stage_that_still_trains(tmp_path, capsys):
    """Stage 2 started while stage 1 trains would learn from stage 1's latest export, which changes under it (before
    stage 1's adaptation phase, a policy without its module), and could not be resumed once it had changed."""
    from wbc.learned.train.preflight import lock_run_dir

    (tmp_path / "push-stage1").mkdir()
    held = lock_run_dir(tmp_path / "push-stage1")  # the stage-1 run, still training
    try:
        for dry in ([], ["--dry-run"]):
            assert main(["train", "--task", "push", "--stage", "2", "--run-root", str(tmp_path), "--iterations", "1",
                         "--envs", "2", *dry]) == 2
            err = capsys.readouterr().err
            assert f"the teacher {tmp_path / 'push-stage1' / 'policy'} is the export of a run still training" in err
            assert f"(pid {os.getpid()})" in err and not (tmp_path / "push-stage2").exists()
    finally:
        held.release()


def test_a_resume_records_the_settings_it_changed_and_a_later_plain_resume_takes_them(stage1_run, tmp_path, capsys):
    root = _copy(stage1_run, tmp_path)
    run = root / "push-stage1"
    began = json.loads((run / "config.json").read_text())
    assert [s["resumed"] for s in began["segments"]] == [False] and began["segments"][0]["to_iteration"] == 0
    capsys.readouterr()
    assert main(["train", "--task", "push", "--stage", "1", "--iterations", "2", "--run-root", str(root),
                 "--resume"]) == 0
    config = json.loads((run / "config.json").read_text())
    assert config["train_config"]["max_iterations"] == 2  # the current settings, not the ones the run began with
    assert config["provenance"] == began["provenance"] and config["inputs"] == began["inputs"]
    segment = config["segments"][-1]
    assert segment["resumed"] and segment["changed"]["max_iterations"] == [1, 2]
    assert (segment["from_iteration"], segment["to_iteration"]) == (1, 1)
    assert segment["provenance"]["git_revision"] == began["provenance"]["git_revision"]
    capsys.readouterr()
    assert main(["train", "--task", "push", "--stage", "1", "--run-root", str(root), "--resume"]) == 0
    captured = capsys.readouterr()
    assert "--iterations 2" in captured.err and "nothing new trained" in captured.out
    assert json.loads((run / "config.json").read_text())["segments"][-1]["changed"] == {}


def test_a_moved_run_root_resumes_a_later_stage_whose_inputs_are_compared_by_content(stage1_run, tmp_path,
                                                                                     monkeypatch):
    from wbc.learned.train.preflight import check_run_dir, input_files
    from wbc.learned.train.stages import stage_config

    monkeypatch.chdir(tmp_path)
    shutil.copytree(stage1_run / "push-stage1", tmp_path / "R1" / "push-stage1")
    cfg = stage_config("push", 2, run_root="R1")  # its teacher: R1/push-stage1/policy
    run = tmp_path / "R1" / "push-stage2"
    run.mkdir()
    (run / "model_0.pt").write_bytes(b"")
    saved = json.loads(json.dumps(dataclasses.asdict(cfg), default=list))
    (run / "config.json").write_text(json.dumps({"train_config": saved, "inputs": input_files(cfg)}))
    (tmp_path / "R1").rename(tmp_path / "R2")
    # the previous stage's export moved with it: the same teacher, by default or given
    assert check_run_dir(stage_config("push", 2, run_root="R2"), resume=True).done == 1
    given = stage_config("push", 2, run_root="R2", teacher=str(tmp_path / "R2" / "push-stage1" / "policy.npz"))
    assert check_run_dir(given, resume=True).done == 1
    # another teacher, wherever it lies, is refused, naming the file read and the one recorded
    other = tmp_path / "other"
    shutil.copytree(tmp_path / "R2" / "push-stage1", other)
    (other / "policy.npz").write_bytes((other / "policy.npz").read_bytes() + b"\0")
    with pytest.raises(ConfigError, match=r"teacher: this run reads .*other/policy, whose content is not the one "
                                          r".*R1/push-stage1/policy"):
        check_run_dir(stage_config("push", 2, run_root="R2", teacher=str(other / "policy")), resume=True)


def test_the_curves_tool_draws_a_ppo_run_and_labels_runs_of_one_name_by_their_roots(stage1_run, tmp_path):
    pytest.importorskip("matplotlib")
    from wbc.learned.train.curves import is_dagger_run, run_labels
    from wbc.learned.train.curves import main as curves

    assert (stage1_run / "push-stage1" / "progress.json").is_file()  # a PPO run writes one too: not a DAgger run's
    assert not is_dagger_run(stage1_run / "push-stage1")
    other = tmp_path / "other" / "push-stage1"
    shutil.copytree(stage1_run / "push-stage1", other)
    runs = [str(stage1_run / "push-stage1"), str(other)]
    assert curves([*runs, "-o", str(tmp_path / "c.png")]) == 0 and (tmp_path / "c.png").stat().st_size > 1000
    assert run_labels(runs) == [f"{stage1_run.name}/push-stage1", "other/push-stage1"]
    assert run_labels(runs[:1]) == ["push-stage1"]


def _rewrite_checkpoint(source: Path, target: Path, change) -> None:
    """Save `source`'s checkpoint as `target`, `change` applied to its loaded dict first."""
    import torch

    saved = torch.load(source, map_location="cpu", weights_only=False)
    change(saved)
    torch.save(saved, target)


def _identity(saved: dict, **fields) -> None:
    saved["infos"]["wbc"].update(fields)


@pytest.mark.parametrize(("change", "said"), [
    (lambda saved: _identity(saved, task="turn", robot="go1-arm"),
     "a checkpoint of another run: task 'turn' (this run: 'push'), robot 'go1-arm' (this run: 'a1-wx200')"),
    (lambda saved: _identity(saved, stage=2), "a checkpoint of another run: stage 2 (this run: 1)"),
])
def test_a_resume_refuses_a_checkpoint_of_another_run_naming_the_field_and_the_checkpoint_before_it(
        stage1_run, tmp_path, capsys, change, said):
    root = _copy(stage1_run, tmp_path)
    run = root / "push-stage1"
    saved = __import__("torch").load(run / "model_0.pt", map_location="cpu", weights_only=False)
    assert saved["infos"]["wbc"] == {"task": "push", "stage": 1, "baseline": None, "variant": None,
                                     "robot": "a1-wx200", "arm_mode": "none", "iteration": 0}

    def stray(saved):  # another run's checkpoint at iteration 3, copied in as this run's model_3.pt
        saved["iter"] = 3
        saved["infos"]["wbc"]["iteration"] = 3
        change(saved)

    _rewrite_checkpoint(run / "model_0.pt", run / "model_3.pt", stray)
    before = _snapshot(run)
    capsys.readouterr()
    argv = ["train", "--task", "push", "--stage", "1", "--iterations", "5", "--envs", "1", "--rma-iterations", "0",
            "--run-root", str(root), "--resume"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"{run / 'model_3.pt'}: {said}" in err and "to resume from model_0.pt" in err
    assert len(err.strip().splitlines()) == 1 and _snapshot(run) == before
    assert main([*argv, "--dry-run"]) == 2 and said in capsys.readouterr().err


def test_a_resume_refuses_a_checkpoint_whose_iteration_is_not_its_names(stage1_run, tmp_path, capsys):
    root = _copy(stage1_run, tmp_path)
    run = root / "push-stage1"
    shutil.copy(run / "model_0.pt", run / "model_3.pt")  # its counter says 0: the progress would be scaled by 4
    assert main(["train", "--task", "push", "--stage", "1", "--iterations", "5", "--envs", "1", "--rma-iterations",
                 "0", "--run-root", str(root), "--resume", "--dry-run"]) == 2
    assert "model_3.pt: a checkpoint of another run: iteration 0 (this run: 3)" in capsys.readouterr().err
    # one written before checkpoints recorded their run: its counter alone
    _rewrite_checkpoint(run / "model_0.pt", run / "model_3.pt", lambda saved: saved.update(infos=None))
    capsys.readouterr()
    argv = ["train", "--task", "push", "--stage", "1", "--iterations", "5", "--envs", "1", "--rma-iterations", "0",
            "--run-root", str(root), "--resume"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "model_3.pt: iter: 0, not the 3 its name says" in err and "to resume from model_0.pt" in err
    assert json.loads((run / "progress.json").read_text())["iteration"] == 0


def test_a_checkpoint_written_before_runs_recorded_their_identity_still_resumes(stage1_run, tmp_path, capsys):
    root = _copy(stage1_run, tmp_path)
    run = root / "push-stage1"
    _rewrite_checkpoint(run / "model_0.pt", run / "model_0.pt", lambda saved: saved.update(infos=None))
    capsys.readouterr()
    assert main(["train", "--task", "push", "--stage", "1", "--iterations", "2", "--envs", "1", "--rma-iterations",
                 "0", "--run-root", str(root), "--resume"]) == 0
    assert json.loads((run / "progress.json").read_text())["iteration"] == 1


def test_a_checkpoint_that_does_not_fit_the_networks_is_refused_in_one_line_before_they_are_printed(
        stage1_run, tmp_path, capsys):
    import torch

    root = _copy(stage1_run, tmp_path)
    run = root / "push-stage1"

    def wider(saved):  # the same run's identity, other layers (a checkpoint of an edited config)
        saved["iter"] = 1
        if saved["infos"] is not None:
            saved["infos"]["wbc"]["iteration"] = 1
        state = saved["actor_state_dict"]
        name = next(k for k, v in state.items() if k.endswith("weight") and v.dim() == 2)
        state[name] = torch.zeros(state[name].shape[0] + 1, state[name].shape[1])

    _rewrite_checkpoint(run / "model_0.pt", run / "model_1.pt", wider)
    capsys.readouterr()
    assert main(["train", "--task", "push", "--stage", "1", "--iterations", "3", "--envs", "1", "--rma-iterations",
                 "0", "--run-root", str(root), "--resume"]) == 2
    captured = capsys.readouterr()
    err = captured.err
    assert "model_1.pt: does not fit this run's networks (size mismatch for " in err
    # the refusal is its last line, one line (the note before it: progress.json counts model_0.pt's iterations)
    refusal = err.strip().splitlines()[-1]
    assert "does not fit" in refusal and "to resume from model_0.pt" in refusal and "Traceback" not in err
    assert "Actor Model" not in captured.out
