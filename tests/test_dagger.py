"""DAgger: distilling a controller of the arena into a policy of our form (`wbc train --teacher mpc`)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from wbc.errors import ConfigError
from wbc.types import MotorCommand

torch = pytest.importorskip("torch")


def test_the_expert_action_asks_for_the_expert_torque_at_that_state():
    from wbc.learned.train.distill import expert_action

    rng = np.random.default_rng(3)
    n = 15
    kp, kd = rng.uniform(5.0, 30.0, n), rng.uniform(0.1, 1.0, n)
    default_q, scale = rng.normal(size=n), 0.25
    for _ in range(20):
        cmd = MotorCommand(q=rng.normal(size=n), dq=rng.normal(size=n), kp=rng.uniform(0.0, 40.0, n),
                           kd=rng.uniform(0.0, 2.0, n), tau=rng.normal(scale=5.0, size=n))
        q, dq = rng.normal(size=n), rng.normal(scale=3.0, size=n)
        a = expert_action(cmd, q, dq, default_q=default_q, action_scale=scale, kp=kp, kd=kd)
        expert_torque = cmd.kp * (cmd.q - q) + cmd.kd * (cmd.dq - dq) + cmd.tau
        policy_torque = kp * (default_q + scale * a - q) - kd * dq  # the policy's motor law
        np.testing.assert_allclose(policy_torque, expert_torque, rtol=0, atol=1e-9)
    with pytest.raises(ConfigError, match="kp"):
        expert_action(cmd, q, dq, default_q=default_q, action_scale=scale, kp=np.zeros(n), kd=kd)


def test_the_memoryless_student_fits_its_data_and_exports_as_our_policies_do(tmp_path):
    from wbc.learned.env.env_config import EnvConfig
    from wbc.learned.policy.numpy_policy import NumpyPolicy
    from wbc.learned.policy.observations import ObsLayout
    from wbc.learned.policy.policy_file import load_policy, save_policy
    from wbc.learned.train.distill import FitConfig, fit_student, load_student, save_student, student_policy_file

    rng = np.random.default_rng(0)
    env = EnvConfig(robot="a1-wx200", arm_mode="actuated")
    obs = rng.normal(size=(2000, ObsLayout(15).size)).astype(np.float32) * 3.0 + 1.0
    w = rng.normal(size=(obs.shape[1], 15)) * 0.03
    actions = np.tanh(obs @ w)
    net, losses = fit_student(obs, actions, FitConfig(epochs=60, hidden_dims=(64, 64), history=0))
    assert losses[-1] < 0.1 * losses[0]
    save_policy(tmp_path / "student", student_policy_file(net, env, task="push", extra={"method": "dagger"}))
    pf = load_policy(tmp_path / "student")
    assert (pf.meta["robot"], pf.meta["arm_mode"], pf.meta["stage"], pf.meta["extrinsics"]) == (
        "a1-wx200", "actuated", 3, None)
    with torch.no_grad():
        want = net(torch.from_numpy(obs[:50])).double().numpy()
    np.testing.assert_allclose(NumpyPolicy(pf)(obs[:50].astype(np.float64)), want, atol=1e-4)
    save_student(net, tmp_path / "student.pt")
    again = load_student(tmp_path / "student.pt")
    with torch.no_grad():
        np.testing.assert_array_equal(again(torch.from_numpy(obs[:5])).numpy(), net(torch.from_numpy(obs[:5])).numpy())
    with pytest.raises(ConfigError):
        fit_student(obs[:0], actions[:0], FitConfig())
    # an input the data barely moves is not blown up by the normaliser
    flat = obs.copy()
    flat[:, 0] = 0.5 + 1e-4 * rng.normal(size=flat.shape[0])
    net, _ = fit_student(flat, actions, FitConfig(epochs=1, std_floor=0.1, history=0))
    assert float(net.obs_normalizer._std[0]) == pytest.approx(0.1)


def test_the_history_window_repeats_the_first_observation_until_the_episode_has_enough():
    from wbc.learned.train.distill import history_index

    np.testing.assert_array_equal(history_index(np.array([4, 4, 4, 4, 9, 9]), 3),
                                  [[0, 0, 0], [0, 0, 1], [0, 1, 2], [1, 2, 3], [4, 4, 4], [4, 4, 5]])


def test_the_exported_history_student_reproduces_the_torch_student_on_a_history(tmp_path):
    from wbc.learned.env.env_config import EnvConfig
    from wbc.learned.policy.controller import LearnedController
    from wbc.learned.policy.observations import ObsLayout
    from wbc.learned.policy.policy_file import load_policy, save_policy
    from wbc.learned.train.distill import (
        FitConfig,
        fit_student,
        history_index,
        load_student,
        save_student,
        student_policy_file,
    )
    from wbc.robots.registry import get_robot

    rng = np.random.default_rng(1)
    env = EnvConfig(robot="a1-wx200", arm_mode="actuated")
    n, h = 120, 6
    obs = (rng.normal(size=(3 * n, ObsLayout(15).size)) * 2.0 + 0.5).astype(np.float32)
    episode = np.repeat([0, 1, 2], n)
    # a label that needs the history: the first observation entry three ticks ago
    idx = history_index(episode, h)
    actions = np.tanh(obs[idx[:, -4], :15])
    cfg = FitConfig(epochs=40, batch_size=32, hidden_dims=(32,), history=h, z_dim=4, adaptation_dims=(32,))
    net, losses = fit_student(obs, actions, cfg, episode=episode)
    assert losses[-1] < 0.5 * losses[0]
    with pytest.raises(ConfigError, match="episode"):
        fit_student(obs, actions, cfg)
    save_policy(tmp_path / "student", student_policy_file(net, env, task="push", extra={}))
    pf = load_policy(tmp_path / "student")
    assert pf.meta["adaptation"]["history"] == h and pf.meta["extrinsics"]["dim"] == 4
    # z comes from the history alone: the file has no encoder of privileged observations to ask for it
    from wbc.learned.policy.numpy_policy import NumpyPolicy, PolicyInputError

    assert pf.meta["extrinsics"]["privileged_parts"] == [] and not NumpyPolicy(pf).has_encoder
    with pytest.raises(PolicyInputError, match="history alone"):
        NumpyPolicy(pf).extrinsics(np.zeros((1, 1)))
    # the arena's controller, fed one episode's observations in order, acts as the torch student on its windows
    ctrl = LearnedController(get_robot("a1-wx200", "actuated"), tmp_path / "student")
    ctrl.reset()
    got = np.array([ctrl.step(o) for o in obs[n:2 * n]])
    with torch.no_grad():
        want = net(torch.from_numpy(obs[n:2 * n]), torch.from_numpy(obs[idx[n:2 * n]])).double().numpy()
    np.testing.assert_allclose(got, np.clip(want, -ctrl.clip, ctrl.clip), atol=1e-4)
    save_student(net, tmp_path / "student.pt")
    again = load_student(tmp_path / "student.pt")
    with torch.no_grad():
        np.testing.assert_array_equal(again(torch.from_numpy(obs[:5]), torch.from_numpy(obs[idx[:5]])).numpy(),
                                      net(torch.from_numpy(obs[:5]), torch.from_numpy(obs[idx[:5]])).numpy())


def test_averaged_labels_and_dart_noise_label_the_expert_and_perturb_only_the_robot(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    from wbc.learned.env.env_config import EnvConfig
    from wbc.learned.train.distill import expert_action
    from wbc.robots.registry import get_robot
    from wbc.tools.dagger import DaggerController
    from wbc.types import RobotState, VelocityCommand

    desc = get_robot("a1-wx200", "actuated")
    env = EnvConfig(robot="a1-wx200", arm_mode="actuated")

    class Scripted:
        """An expert whose feed-forward torque is its tick count: its labels are known in closed form."""

        rate_hz = 500.0

        def __init__(self):
            self.k = 0

        def reset(self):
            self.k = 0

        def act(self, state, command):
            self.k += 1
            n = desc.num_joints
            return MotorCommand(q=state.q.copy(), dq=np.zeros(n), kp=np.zeros(n), kd=np.zeros(n),
                                tau=np.full(n, float(self.k)))

    n = desc.num_joints
    state = RobotState(tick=0, time=0.0, q=desc.nominal_q.copy(), dq=np.zeros(n), tau_est=np.zeros(n),
                       imu_quat=np.array([1.0, 0, 0, 0]), gyro_in_body=np.zeros(3),
                       accel_in_body=np.array([0.0, 0.0, 9.81]), foot_force=np.zeros(4))
    kp, _ = env.gains(n)
    for average, noise in ((False, 0.0), (True, 0.0), (True, 0.5)):
        ctrl = DaggerController(Scripted(), desc, env, None, expert_drives=True, noise=noise,
                                rng=np.random.default_rng(0), average=average)
        sent = [ctrl.act(state, VelocityCommand()) for _ in range(20)]
        ctrl.finish()
        first = [1.0, 11.0] if not average else [5.5, 15.5]  # ticks 1..10 and 11..20
        want = [expert_action(MotorCommand(q=state.q, dq=np.zeros(n), kp=np.zeros(n), kd=np.zeros(n),
                                           tau=np.full(n, t)), state.q, state.dq, default_q=desc.nominal_q,
                              action_scale=env.action_scale, kp=kp, kd=env.gains(n)[1]) for t in first]
        np.testing.assert_allclose(np.array(ctrl.labels), np.clip(want, -env.clip_actions, env.clip_actions))
        offset = np.array([s.tau for s in sent]) - np.arange(1, 21)[:, None]
        if noise:
            # drawn each policy period and held over it
            np.testing.assert_allclose(offset[:10], np.broadcast_to(offset[0], offset[:10].shape), atol=1e-9)
            assert np.abs(offset[0]).min() > 0 and np.abs(offset[10] - offset[0]).min() > 0
            # the next observation's previous action is the label plus the offset the robot got
            np.testing.assert_allclose(ctrl.obs[1][-n:], np.clip(ctrl.labels[0] + offset[0] / (kp * env.action_scale),
                                                                 -env.clip_actions, env.clip_actions))
        else:
            assert np.all(offset == 0)
            np.testing.assert_allclose(ctrl.obs[1][-n:], ctrl.labels[0])


def test_the_expert_takes_over_once_the_student_parts_from_its_labels(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    from wbc.learned.env.env_config import EnvConfig
    from wbc.robots.registry import get_robot
    from wbc.tools.dagger import DaggerController
    from wbc.types import RobotState, VelocityCommand

    desc = get_robot("a1-wx200", "actuated")
    env = EnvConfig(robot="a1-wx200", arm_mode="actuated")
    n = desc.num_joints

    class Holding:
        """An expert holding the nominal pose with no torque: its label is the action 0 at the nominal pose."""

        rate_hz = 500.0

        def reset(self):
            pass

        def act(self, state, command):
            return MotorCommand(q=state.q.copy(), dq=np.zeros(n), kp=np.zeros(n), kd=np.zeros(n), tau=np.zeros(n))

    class Drifting:
        """A student whose action grows by 0.5 units a tick."""

        def __init__(self):
            self.k = 0

        def reset(self):
            self.k = 0

        def step(self, obs):
            self.k += 1
            return np.full(n, 0.5 * self.k)

    state = RobotState(tick=0, time=0.0, q=desc.nominal_q.copy(), dq=np.zeros(n), tau_est=np.zeros(n),
                       imu_quat=np.array([1.0, 0, 0, 0]), gyro_in_body=np.zeros(3),
                       accel_in_body=np.array([0.0, 0.0, 9.81]), foot_force=np.zeros(4))
    ctrl = DaggerController(Holding(), desc, env, Drifting(), expert_drives=False, takeover=1.0)
    sent = [ctrl.act(state, VelocityCommand()) for _ in range(100)]
    # errors 0.5, 1.0, 1.5, 2.0 ...: the smoothed disagreement 0.1, 0.28, 0.52, 0.82, 1.15 passes 1 after the 5th
    assert ctrl.taken_over_at == 5 and ctrl.expert_drives
    assert np.all(sent[49].kp > 0) and np.all(sent[50].kp == 0)  # the student's held target, then the expert's
    # the observation after the takeover still reads the student's last action, which the robot got
    np.testing.assert_allclose(ctrl.obs[5][-n:], np.full(n, 2.5))
    ctrl.reset()
    assert not ctrl.expert_drives and ctrl.taken_over_at is None


def test_who_drives_is_the_expert_first_then_less_and_less_often():
    from wbc.tools.dagger import DaggerConfig

    cfg = DaggerConfig(rounds=6, episodes=200, beta=0.5)
    assert all(cfg.expert_drives(0, e) for e in range(200))
    shares = [np.mean([cfg.expert_drives(k, e) for e in range(200)]) for k in range(1, 5)]
    for k, share in enumerate(shares, start=1):
        assert abs(share - 0.5**k) < 0.1
    assert [cfg.expert_drives(3, e) for e in range(50)] == [cfg.expert_drives(3, e) for e in range(50)]
    for bad in ({"rounds": 0}, {"beta": 1.5}, {"episode_s": 0.0}, {"task": "walk"}):
        with pytest.raises(ConfigError):
            DaggerConfig(**bad)


def test_wbc_train_with_mpc_as_teacher_runs_dagger_and_exports_a_policy_the_arena_plays(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # MuJoCo may write its log file here
    from wbc.arena.sim_trial import run_trial
    from wbc.cli.main import main
    from wbc.scenario import load_scenario

    args = ["train", "--task", "push", "--teacher", "mpc", "--episodes", "2", "--episode-s", "0.6",
            "--run-root", str(tmp_path / "runs")]
    assert main([*args, "--rounds", "2"]) == 0
    out = capsys.readouterr().out
    assert "round 0: 2 episodes (0 driven by the student" in out and "round 1:" in out and "distilled mpc" in out
    run = tmp_path / "runs" / "push-dagger-mpc"
    progress = json.loads((run / "progress.json").read_text())
    assert [r["round"] for r in progress["rounds"]] == [0, 1]
    first, second = progress["rounds"]
    # 0.6 s at the student's 50 Hz: 30 labelled ticks per expert-driven episode (a student may fall sooner)
    assert first["samples_total"] == 60 and first["student_episodes"] == 0
    assert second["samples_total"] > 60
    with np.load(run / "data.npz") as data:
        assert data["obs"].shape[0] == data["actions"].shape[0] == second["samples_total"]
        assert np.all(np.abs(data["actions"]) <= 10.0)  # clipped to the policy's action range
    meta = json.loads((run / "policy.json").read_text())
    assert meta["training"]["method"] == "dagger" and meta["training"]["expert"] == "mpc"
    training = meta["training"]  # the run's recipe travels with its student
    assert (training["rounds"], training["episodes"], training["episode_s"]) == (2, 2, 0.6)
    # and how it was made, as its config.json records it: the command, scenario, versions and git revision
    config = json.loads((run / "config.json").read_text())
    assert training["provenance"] == config["provenance"] and "git_revision" in training["provenance"]
    assert training["command"] == config["command"] and training["scenario"]["path"].endswith("push.toml")
    assert len(training["scenario"]["sha256"]) == 64
    # the student reads the last 25 observations through the file's adaptation module; its latent is declared as
    # extrinsics of no privileged parts and no encoder, with a note that it comes from the history
    assert meta["adaptation"]["history"] == 25 and meta["extrinsics"]["privileged_parts"] == []
    with np.load(run / "policy.npz") as weights:
        assert not any(k.startswith(("encoder/", "privileged_")) for k in weights.files)
    assert "history" in meta["extrinsics"]["note"] and "nothing privileged" in meta["extrinsics"]["note"]
    with np.load(run / "data.npz") as data:
        episodes = data["episode"]
        assert episodes.shape == (second["samples_total"],) and list(np.unique(episodes)) == [0, 1, 2, 3]
        assert np.all(np.diff(episodes) >= 0)  # each episode's samples together, in time order
    from wbc.control.controller_contract import check_controller

    check_controller(f"policy:{run / 'policy'}").raise_if_failed()
    # the arena plays the export as it plays any policy file
    trial = load_scenario("scenarios/push.toml").trial("in", 0, 0)
    import dataclasses

    record, episode = run_trial(dataclasses.replace(trial, duration_s=0.2, pushes=()), f"policy:{run / 'policy'}")
    assert not record.error and episode.t.size == 10  # 0.2 s at 50 Hz
    # a finished run is not overwritten; --resume adds rounds after the last finished one
    assert main([*args, "--rounds", "3"]) == 2
    assert "already holds a DAgger run; pass --resume" in capsys.readouterr().err
    assert main([*args, "--rounds", "3", "--resume"]) == 0
    progress = json.loads((run / "progress.json").read_text())
    assert [r["round"] for r in progress["rounds"]] == [0, 1, 2]
    assert progress["rounds"][2]["samples_total"] > second["samples_total"]
    # the run's curves: per round, the fit's loss and how long the students drove (round 0: the expert alone)
    from wbc.learned.train.curves import dagger_rounds, plot_dagger_curves

    figures = dagger_rounds(run)
    assert list(figures["round"]) == [0, 1, 2] and list(figures["samples"]) == [
        r["samples_total"] for r in progress["rounds"]]
    assert np.isnan(figures["driven_s"][0]) and np.isfinite(figures["fit_loss"]).all()
    assert plot_dagger_curves([run], tmp_path / "dagger.png").stat().st_size > 1000
    with pytest.raises(ConfigError, match="not a DAgger run"):
        dagger_rounds(tmp_path)
    # DAgger's options need a controller as teacher, and the stage options do not apply to DAgger
    for wrong, said in ((["train", "--task", "push", "--stage", "3", "--rounds", "2", "--dry-run"], "--rounds"),
                        ([*args, "--stage", "3", "--dry-run"], "--stage does not apply to DAgger"),
                        (["train", "--task", "push", "--dry-run"], "--stage 1|2|3 is required")):
        capsys.readouterr()
        assert main(wrong) == 2
        assert said in capsys.readouterr().err
    # the student's networks are options of the run
    capsys.readouterr()
    fresh = ["--run-root", str(tmp_path / "fresh")]  # the dry run, as the run, refuses the run directory above
    assert main([*args, *fresh, "--student-layers", "128,64", "--memory-layers", "32", "--dry-run"]) == 0
    fit = json.loads(capsys.readouterr().out)["fit"]
    assert fit["hidden_dims"] == [128, 64] and fit["adaptation_dims"] == [32] and fit["history"] == 25
    for wrong, said in (([*args, "--student-layers", "128,x", "--dry-run"], "separated by commas"),
                        ([*args, "--memory-layers", "0", "--dry-run"], "[1, 4096]")):
        with pytest.raises(SystemExit) as exit_:  # a usage error: the parser states what it takes
            main(wrong)
        assert exit_.value.code == 2 and said in capsys.readouterr().err
    assert main(["train", "--task", "push", "--stage", "3", "--memory-layers", "32", "--dry-run"]) == 2
    assert "--memory-layers: only with a controller as --teacher" in capsys.readouterr().err
    # the dry run refuses what the run would: an expert that cannot follow, an adaptation phase with nothing to adapt
    assert main(["train", "--task", "push", "--teacher", "stand", "--expert-follows", "--dry-run"]) == 2
    assert "'stand' is not built by MpcController" in capsys.readouterr().err
    assert main(["train", "--task", "push", "--stage", "3", "--baseline", "decoupled", "--rma-iterations", "5",
                 "--dry-run"]) == 2
    assert "stage 3 --baseline decoupled observes none" in capsys.readouterr().err


def test_a_failing_expert_costs_only_its_episode(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    import wbc.tools.dagger as dagger
    from wbc.control.registry import get_controller

    real = get_controller("mpc")
    calls = {"n": 0}

    class Breaks:
        """The real expert, raising at its 30th tick of the first episode."""

        def __init__(self, inner):
            self.inner, self.rate_hz, self.ticks = inner, inner.rate_hz, 0

        def reset(self):
            self.inner.reset()

        def act(self, state, command):
            self.ticks += 1
            if calls["n"] == 1 and self.ticks == 30:
                raise RuntimeError("expert broke")
            return self.inner.act(state, command)

        def counters(self):
            return self.inner.counters()

    def make(desc):
        calls["n"] += 1
        return Breaks(real.make(desc))

    import dataclasses

    spec = dataclasses.replace(real, make=make)
    monkeypatch.setattr(dagger, "get_controller", lambda name: spec)
    result = dagger.run_dagger(dagger.DaggerConfig(rounds=1, episodes=2, episode_s=0.4, run_dir=str(tmp_path / "r")))
    rounds = json.loads((Path(result["run_dir"]) / "progress.json").read_text())["rounds"]
    eps = rounds[0]["episodes"]
    assert rounds[0]["errors"] == 1 and "expert broke" in eps[0]["error"] and eps[1]["error"] is None
    # the broken episode keeps its samples up to the failure (ticks 0, 10, 20 of the expert's 500 Hz), the other all 20
    assert [e["samples"] for e in eps] == [3, 20] and result["samples"] == 23


def test_an_interrupted_dagger_round_keeps_the_finished_rounds_samples_once(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # MuJoCo may write its log file here
    import wbc.tools.dagger as dagger
    from wbc.cli.main import main

    args = ["train", "--task", "push", "--teacher", "mpc", "--rounds", "2", "--episodes", "1", "--episode-s", "0.1",
            "--run-root", str(tmp_path / "runs")]
    run = tmp_path / "runs" / "push-dagger-mpc"
    savez, save_student = np.savez, dagger.save_student

    def half_written(file, **arrays):  # round 1's data.npz: interrupted while it is written
        if (run / "progress.json").exists():
            with open(file, "wb") if isinstance(file, (str, Path)) else file as f:
                f.write(b"PK\x03\x04 half a zip")
            raise KeyboardInterrupt
        return savez(file, **arrays)

    monkeypatch.setattr(dagger.np, "savez", half_written)
    assert main(args) == 130
    with np.load(run / "data.npz") as data:  # round 0's samples, whole
        assert data["obs"].shape[0] == 5 and set(data["episode"]) == {0}
    monkeypatch.setattr(dagger.np, "savez", savez)

    def interrupted(net, file):  # round 1: stopped after its data.npz, before its progress.json
        if (run / "progress.json").exists():
            raise KeyboardInterrupt
        return save_student(net, file)

    monkeypatch.setattr(dagger, "save_student", interrupted)
    assert main([*args, "--resume"]) == 130
    with np.load(run / "data.npz") as data:
        assert data["obs"].shape[0] == 10  # round 1's samples saved, its progress not
    monkeypatch.setattr(dagger, "save_student", save_student)
    assert main([*args, "--resume"]) == 0
    progress = json.loads((run / "progress.json").read_text())
    with np.load(run / "data.npz") as data:  # round 1's episode once, not twice
        assert data["obs"].shape[0] == progress["rounds"][-1]["samples_total"] == 10
        assert list(data["episode"]) == [0] * 5 + [1] * 5


@pytest.mark.parametrize("stopped_at", ["progress.json", "student.pt"])
def test_a_dagger_run_resumed_after_a_round_wrote_its_student_ends_with_the_uninterrupted_runs(
        tmp_path, monkeypatch, stopped_at):
    """Round 1 stops after its own student is written: before its progress (the round is not finished: it plays
    again from round 0's student), or after it while the run's current student is replaced. Resumed, the run ends
    with the student, the policy and the rounds of the same run never stopped."""
    monkeypatch.chdir(tmp_path)  # MuJoCo may write its log file here
    from contextlib import contextmanager

    import wbc.tools.dagger as dagger
    from wbc.cli.main import main

    args = ["train", "--task", "push", "--teacher", "mpc", "--rounds", "3", "--episodes", "1", "--episode-s", "0.1"]
    assert main([*args, "--run-root", str(tmp_path / "whole")]) == 0
    run = tmp_path / "stopped" / "push-dagger-mpc"
    replacing = dagger._replacing

    @contextmanager
    def stop_in_round_1(path):
        progress = run / "progress.json"
        finished = len(json.loads(progress.read_text())["rounds"]) if progress.exists() else 0
        if path.name == stopped_at and finished == (1 if stopped_at == "progress.json" else 2):
            raise KeyboardInterrupt
        with replacing(path) as f:
            yield f

    monkeypatch.setattr(dagger, "_replacing", stop_in_round_1)
    assert main([*args, "--run-root", str(tmp_path / "stopped")]) == 130
    assert (run / "rounds" / "student-1.pt").is_file()  # round 1's own student was written before it stopped
    monkeypatch.setattr(dagger, "_replacing", replacing)
    assert main([*args, "--run-root", str(tmp_path / "stopped"), "--resume"]) == 0
    whole = tmp_path / "whole" / "push-dagger-mpc"
    samples = [[r["samples_total"] for r in json.loads((d / "progress.json").read_text())["rounds"]]
               for d in (whole, run)]
    assert samples[0] == samples[1] and len(samples[0]) == 3
    for name in ("policy.npz", "rounds/policy-1.npz", "rounds/policy-2.npz"):
        with np.load(whole / name) as a, np.load(run / name) as b:
            assert a.files == b.files and all(np.array_equal(a[k], b[k]) for k in a.files), name
    states = [torch.load(d / "student.pt", weights_only=True)["state"] for d in (whole, run)]
    assert all(torch.equal(states[0][k], states[1][k]) for k in states[0])


def test_a_resumed_dagger_run_takes_the_options_left_out_from_its_config(tmp_path, monkeypatch, capsys):
    """As a stage's resume does: a resumed DAgger run is the run it continues, so only what changes is given (here a
    larger --rounds). It was refused, naming config fields, unless the whole first command was given again."""
    monkeypatch.chdir(tmp_path)  # MuJoCo may write its log file here
    from wbc.cli.main import main

    root = str(tmp_path / "runs")
    assert main(["train", "--task", "push", "--teacher", "mpc", "--rounds", "1", "--episodes", "1", "--episode-s",
                 "0.1", "--history", "3", "--student-layers", "16", "--memory-layers", "4", "--run-root", root]) == 0
    capsys.readouterr()
    assert main(["train", "--task", "push", "--teacher", "mpc", "--rounds", "2", "--run-root", root, "--resume"]) == 0
    out, err = capsys.readouterr()
    assert ("gave the options not given: --episodes 1, --episode-s 0.1, --seed 0, --expert-noise 0.0, --history 3, "
            "--student-layers 16, --memory-layers 4") in err
    progress = json.loads((tmp_path / "runs" / "push-dagger-mpc" / "progress.json").read_text())
    assert len(progress["rounds"]) == 2 and "2 rounds" in out
    # each session recorded, as a stage's are, and carried by the export
    run = tmp_path / "runs" / "push-dagger-mpc"
    segments = json.loads((run / "config.json").read_text())["segments"]
    assert [(s["from_round"], s["to_round"], s["resumed"]) for s in segments] == [(0, 1, False), (1, 2, True)]
    assert segments[0]["command"].startswith("wbc train --task push --teacher mpc --rounds 1 ")
    assert segments[1]["command"] == f"wbc train --task push --teacher mpc --rounds 2 --run-root {root} --resume"
    assert segments[1]["changed"] == {"rounds": [1, 2]}
    training = json.loads((run / "policy.json").read_text())["training"]
    assert training["segments"] == segments
    from wbc.scenario.scenario import load_scenario  # the scenario named as the arena names it, beside the file's hash

    shipped = load_scenario(training["scenario"]["path"])
    assert (training["scenario"]["name"], training["scenario"]["content_hash"]) == (shipped.name, shipped.hash)


@pytest.fixture(scope="module")
def dagger_run(tmp_path_factory) -> Path:
    """A finished one-round, one-episode DAgger run: its run root."""
    from wbc.cli.main import main

    root = tmp_path_factory.mktemp("dagger")
    assert main(["train", "--task", "push", "--teacher", "mpc", "--rounds", "1", "--episodes", "1", "--episode-s",
                 "0.1", "--run-root", str(root)]) == 0
    return root


@pytest.mark.parametrize(("damage", "said"), [
    (lambda run: (run / "config.json").unlink(), "config.json: no such file"),
    (lambda run: (run / "config.json").write_text("{bad"), "config.json: not JSON"),
    (lambda run: (run / "config.json").write_text("[]"), "config.json: dagger_config: missing"),
    (lambda run: (run / "progress.json").write_text("garbage"), "progress.json: not JSON"),
    (lambda run: (run / "progress.json").write_text('{"rounds": [{}]}'), "progress.json: rounds: missing"),
    (lambda run: (run / "data.npz").unlink(), "data.npz: no such file"),
    (lambda run: (run / "data.npz").write_bytes((run / "data.npz").read_bytes()[:100]), "data.npz: not readable"),
    (lambda run: (run / "rounds" / "student-0.pt").write_bytes((run / "rounds" / "student-0.pt").read_bytes()[:100]),
     "student-0.pt: not a readable student"),
    # a run that kept no student per round resumes from its student.pt
    (lambda run: ((run / "rounds" / "student-0.pt").unlink(),
                  (run / "student.pt").write_bytes((run / "student.pt").read_bytes()[:100])),
     "student.pt: not a readable student"),
])
def test_a_dagger_resume_refuses_a_damaged_run_directory_in_one_line(dagger_run, tmp_path, capsys, damage, said):
    import shutil

    from wbc.cli.main import main

    shutil.copytree(dagger_run, tmp_path / "runs")
    damage(tmp_path / "runs" / "push-dagger-mpc")
    capsys.readouterr()
    argv = ["train", "--task", "push", "--teacher", "mpc", "--rounds", "1", "--episodes", "1", "--episode-s", "0.1",
            "--run-root", str(tmp_path / "runs"), "--resume"]
    for dry_run in ([], ["--dry-run"]):  # the dry run refuses what the run would
        assert main([*argv, *dry_run]) == 2
        err = capsys.readouterr().err
        assert said in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_the_dagger_dry_run_checks_the_run_directory_and_the_expert_as_the_run_does(dagger_run, tmp_path, capsys):
    from wbc.cli.main import main

    args = ["train", "--task", "push", "--rounds", "1", "--episodes", "1", "--episode-s", "0.1", "--dry-run"]
    # a run there, and no --resume
    assert main([*args, "--teacher", "mpc", "--run-root", str(dagger_run)]) == 2
    assert "already holds a DAgger run; pass --resume" in capsys.readouterr().err
    assert main([*args, "--teacher", "mpc", "--run-root", str(dagger_run), "--resume"]) == 0
    # --resume, and no run there
    assert main([*args, "--teacher", "mpc", "--run-root", str(tmp_path / "none"), "--resume"]) == 2
    assert "--resume: no finished DAgger round in" in capsys.readouterr().err
    # an expert without a ground-truth switch: refused by the run and by its dry run, before anything is written
    for dry_run in (["--dry-run"], []):
        argv = [*(a for a in args if a != "--dry-run"), *dry_run, "--teacher", "learned", "--expert-truth",
                "--run-root", str(tmp_path / "runs")]
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "--expert-truth: the expert 'learned' (LearnedController) has no ground-truth switch" in err
        assert len(err.strip().splitlines()) == 1 and not (tmp_path / "runs").exists()


def test_an_interrupted_dagger_run_says_which_rounds_it_keeps(dagger_run, tmp_path, capsys, monkeypatch):
    import wbc.tools.dagger as dagger
    from wbc.cli.main import main

    def interrupted(cfg, **_):
        raise KeyboardInterrupt

    monkeypatch.setattr(dagger, "run_dagger", interrupted)
    args = ["train", "--task", "push", "--teacher", "mpc", "--rounds", "2", "--episodes", "1", "--episode-s", "0.1"]
    assert main([*args, "--run-root", str(dagger_run), "--resume"]) == 130
    err = capsys.readouterr().err
    assert "keeps 1 finished DAgger round" in err and "the same command with --resume continues after them" in err
    assert main([*args, "--run-root", str(tmp_path / "new")]) == 130
    assert "holds no finished DAgger round: the same command, without --resume, starts" in capsys.readouterr().err


def test_a_dagger_resume_with_no_more_rounds_says_that_nothing_new_was_trained(dagger_run, tmp_path, capsys):
    import shutil

    from wbc.cli.main import main

    shutil.copytree(dagger_run, tmp_path / "runs")
    run = tmp_path / "runs" / "push-dagger-mpc"
    before = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
    capsys.readouterr()
    assert main(["train", "--task", "push", "--teacher", "mpc", "--rounds", "1", "--episodes", "1", "--episode-s",
                 "0.1", "--run-root", str(tmp_path / "runs"), "--resume"]) == 0
    out = capsys.readouterr().out
    assert "already holds 1 DAgger round, no fewer than --rounds 1: nothing new trained" in out
    assert "round 0:" not in out and "pass a larger --rounds" in out
    assert {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()} == before
