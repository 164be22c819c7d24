"""Fine-tuning a distilled student by PPO + BC: the actor is the student, reading its own window, and exports as one."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from wbc.learned.env.env import BatchedEnv
from wbc.learned.env.env_config import DomainRandomisation, EnvConfig
from wbc.learned.policy.policy_file import load_policy
from wbc.learned.policy.shipped import WEIGHTS_DIR
from wbc.robots.registry import get_robot

torch = pytest.importorskip("torch")
pytest.importorskip("rsl_rl")

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = str(ROOT / "scenarios" / "push.toml")
STUDENT = str(WEIGHTS_DIR / "a1-wx200-actuated-mpc-distilled")
"""The shipped DAgger student: a 25-observation window, an adaptation module 1350-32-8, an actor 256-128-64."""


def _env(**kw) -> EnvConfig:
    base = dict(robot="a1-wx200", arm_mode="actuated", scenario=SCENARIO, num_envs=3, terrain="flat", nthread=1,
                domain=DomainRandomisation(num_variants=2))
    return EnvConfig(**{**base, **kw})


def _actor(obs):
    from wbc.learned.train.history_actor import HistoryActor

    return HistoryActor(obs, {"actor": ["policy", "history"]}, "actor", 15, student_path=STUDENT,
                        distribution_cfg={"class_name": "GaussianDistribution", "init_std": 0.3, "std_type": "scalar"})


def test_the_actor_starts_as_the_student_and_sees_the_window_the_controller_keeps():
    """Played in the training env through two episode ends, the actor's actions are the arena controller's on the
    same observations: the same networks, normaliser and window (filled with an episode's first observation)."""
    from wbc.learned.policy.controller import LearnedController
    from wbc.learned.train.vec_env import RslVecEnv

    vec = RslVecEnv(BatchedEnv(_env(episode_s=0.2)), history=25)  # 10 policy steps an episode
    actor = _actor(vec.get_observations())
    ctrl = LearnedController(get_robot("a1-wx200", "actuated"), STUDENT)
    ctrl.reset()
    obs, ends = vec.get_observations(), 0
    try:
        for _ in range(24):
            with torch.no_grad():
                action = actor(obs)
            want = ctrl.step(obs["policy"][0].numpy().astype(np.float64))
            np.testing.assert_allclose(np.clip(action[0].double().numpy(), -ctrl.clip, ctrl.clip), want, atol=2e-4)
            obs, _, dones, _ = vec.step(action)
            if dones[0]:
                ends += 1
                ctrl.reset()
    finally:
        vec.close()
    assert ends >= 2
    h = obs["history"].reshape(3, 25, -1)
    assert torch.equal(h[:, -1], obs["policy"])  # the newest entry is the current observation


def test_the_actor_refuses_a_policy_whose_latent_needs_privileged_observations(tmp_path):
    from wbc.errors import NetworkMismatchError
    from wbc.learned.train.vec_env import RslVecEnv

    vec = RslVecEnv(BatchedEnv(_env(num_envs=1)), history=25)
    try:
        from wbc.learned.train.history_actor import HistoryActor

        with pytest.raises(NetworkMismatchError, match="history alone"):
            HistoryActor(vec.get_observations(), {"actor": ["policy", "history"]}, "actor", 15,
                         student_path=str(WEIGHTS_DIR / "a1-wx200-actuated"))
    finally:
        vec.close()


def _tiny(root: Path, **kw):
    from wbc.learned.train.stages import fine_tune_config

    env = dict(num_envs=8, nthread=1, scenario=SCENARIO, domain=DomainRandomisation(num_variants=2), seed=0)
    small = dict(num_steps_per_env=6, save_interval=1, critic_hidden_dims=(16,))
    return fine_tune_config("push", STUDENT, run_root=str(root), env_overrides=env, **{**small, **kw})


def test_a_fine_tune_trains_the_critic_first_then_the_student_and_exports_a_policy_the_arena_plays(tmp_path):
    from wbc.arena.runner import run_episode
    from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
    from wbc.learned.policy.controller import LearnedController
    from wbc.learned.train.train import train
    from wbc.scenario.trial import CommandSchedule

    student = load_policy(STUDENT)
    # two iterations with the actor frozen: the export is the student, to float32 rounding
    first = train(_tiny(tmp_path, max_iterations=2, actor_frozen_iterations=2))
    exported = load_policy(Path(first["run_dir"]) / "policy")
    assert exported.arrays.keys() == student.arrays.keys()
    for k, v in student.arrays.items():
        np.testing.assert_allclose(exported.arrays[k], v, rtol=1e-6, atol=1e-7, err_msg=k)
    assert exported.meta["adaptation"] == {**student.meta["adaptation"]}
    training = exported.meta["training"]
    assert training["student"] == STUDENT and training["student_training"] == student.meta["training"]
    # how the fine-tune was made, as its config.json records it: its inputs (the student's sha256) and provenance
    config = json.loads((Path(first["run_dir"]) / "config.json").read_text())
    assert training["inputs"] == config["inputs"] and "student" in training["inputs"]
    assert training["provenance"] == config["provenance"] and training["seed"] == config["seed"]
    assert training["scenario"] == config["scenario"] and len(training["scenario"]["sha256"]) == 64
    from wbc.learned.train.curves import read_scalars

    steps, bc = read_scalars(first["run_dir"])["Loss/bc"]
    assert steps.tolist() == [0, 1] and bc.tolist() == [0.0, 0.0]  # the actor was the student, untouched
    # the BC weight is logged as what it is, not as a loss
    scalars = read_scalars(first["run_dir"])
    assert "Loss/bc_weight" not in scalars and scalars["Train/bc_weight"][0].tolist() == [0, 1]
    from wbc.learned.train.bc_schedule import BCSchedule
    from wbc.learned.train.train import rsl_rl_config

    schedule = BCSchedule(**rsl_rl_config(_tiny(tmp_path, max_iterations=2))["algorithm"]["bc_schedule"])
    np.testing.assert_allclose(scalars["Train/bc_weight"][1], [schedule.weight(0), schedule.weight(1)], rtol=1e-6)
    # one more iteration, now the actor's: PPO + BC move the student
    more = train(_tiny(tmp_path, max_iterations=3, actor_frozen_iterations=2), resume=True)
    assert more["iterations"] == 3
    tuned = load_policy(Path(more["run_dir"]) / "policy")
    assert not np.array_equal(tuned.arrays["policy/0/weight"], exported.arrays["policy/0/weight"])
    assert not np.array_equal(tuned.arrays["adaptation/0/weight"], exported.arrays["adaptation/0/weight"])
    np.testing.assert_array_equal(tuned.arrays["obs_mean"], student.arrays["obs_mean"])  # the normaliser is fixed
    cfg = json.loads((Path(more["run_dir"]) / "config.json").read_text())
    assert cfg["rsl_rl_config"]["actor"]["class_name"].endswith("HistoryActor")
    assert cfg["rsl_rl_config"]["obs_groups"]["actor"] == ["policy", "history"]
    # the arena plays the fine-tuned file as any policy
    sim = MujocoRobot(MujocoRobotConfig(arm_mode="actuated"))
    with sim:
        sim.reset(seed=0)
        ep = run_episode(sim, LearnedController(sim.desc, Path(more["run_dir"]) / "policy"), CommandSchedule(),
                         0.2)
    assert not ep.fell and ep.t.size == 10  # 0.2 s at the policy's 50 Hz


def test_cli_fine_tune_dry_run_and_errors(capsys):
    from wbc.cli.main import main

    assert main(["train", "--task", "push", "--fine-tune", "shipped", "--iterations", "50", "--dry-run"]) == 0
    cfg = json.loads(capsys.readouterr().out)
    assert cfg["student"].endswith("a1-wx200-actuated-mpc-distilled.npz") and cfg["teacher"] == cfg["student"]
    assert cfg["max_iterations"] == 50 and cfg["run_dir"].endswith("push-fine-tune")
    assert cfg["env"]["arm_mode"] == "actuated" and cfg["env"]["teacher_arm_mode"] is None
    assert cfg["actor_frozen_iterations"] == 20 and cfg["bc"]["final"] == 0.1
    assert main(["train", "--task", "push", "--fine-tune", "shipped", "--stage", "3", "--dry-run"]) == 2
    assert "--stage does not apply to --fine-tune" in capsys.readouterr().err
    assert main(["train", "--task", "nope", "--fine-tune", "shipped", "--dry-run"]) == 2
    assert "valid tasks" in capsys.readouterr().err


def _expert_data(path: Path, n: int = 40) -> Path:
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(2 * n, 54)).astype(np.float32)
    np.savez(path, obs=obs, actions=rng.normal(size=(2 * n, 15)), episode=np.repeat([3, 7], n))
    return path


def test_expert_samples_are_drawn_with_the_windows_of_their_own_episodes(tmp_path):
    from wbc.errors import ConfigError
    from wbc.learned.train.ppo_bc import ExpertSamples

    data = ExpertSamples(str(_expert_data(tmp_path / "data.npz", n=5)), history=3)
    inputs, labels = data.draw(200, torch.Generator().manual_seed(0))
    window = inputs["history"].reshape(200, 3, 54)
    assert torch.equal(window[:, -1], inputs["policy"])  # the newest entry is the sample itself
    obs = data.obs.numpy()
    for w, o in zip(window.numpy(), inputs["policy"].numpy(), strict=True):
        i = int(np.flatnonzero((obs == o).all(axis=1))[0])
        first = 0 if i < 5 else 5  # its episode's first sample: the window never reaches into the other episode
        want = [obs[max(i - 2 + k, first)] for k in range(3)]
        np.testing.assert_array_equal(w, np.array(want))
    assert labels.dtype == torch.float32 and labels.shape == (200, 15)
    np.savez(tmp_path / "bad.npz", obs=np.zeros((4, 54)), actions=np.zeros((4, 15)))
    with pytest.raises(ConfigError, match=r"bad\.npz: no episode array"):
        ExpertSamples(str(tmp_path / "bad.npz"), history=3)
    with pytest.raises(ConfigError, match="reads none"):
        ExpertSamples(str(tmp_path / "data.npz"), history=0)


def test_a_fine_tune_can_take_the_experts_samples_as_its_bc_target(tmp_path):
    from wbc.errors import ConfigError
    from wbc.learned.train.curves import read_scalars
    from wbc.learned.train.train import train

    data = _expert_data(tmp_path / "data.npz")
    with pytest.raises(ConfigError, match="no such file"):
        train(_tiny(tmp_path / "none", expert_data=str(tmp_path / "missing.npz"), max_iterations=1))
    np.savez(tmp_path / "legs.npz", obs=np.zeros((4, 54)), actions=np.zeros((4, 12)), episode=np.zeros(4, dtype=int))
    with pytest.raises(ConfigError, match=r"legs\.npz: their actions have 12 entries, the actor has 15"):
        train(_tiny(tmp_path / "legs", expert_data=str(tmp_path / "legs.npz"), max_iterations=1))
    run = train(_tiny(tmp_path, expert_data=str(data), max_iterations=2, actor_frozen_iterations=1))
    assert run["run_dir"].endswith("push-fine-tune-expert")
    pf = load_policy(Path(run["run_dir"]) / "policy")
    assert pf.meta["training"]["bc_towards"] == "the expert's samples"
    assert pf.meta["training"]["expert_data"] == str(data)
    assert "fine-tuned with it by PPO + BC" in pf.meta["extrinsics"]["note"]
    _, bc = read_scalars(run["run_dir"])["Loss/bc"]
    # random labels are far from the student's actions, in both iterations; only the second moved the student
    assert bc.min() > 0.5
    student = load_policy(STUDENT)
    assert not np.array_equal(pf.arrays["policy/0/weight"], student.arrays["policy/0/weight"])


def test_a_fine_tune_refuses_an_env_that_gives_the_student_other_numbers(tmp_path):
    import dataclasses

    from wbc.errors import ConfigError
    from wbc.learned.train.train import train

    cfg = _tiny(tmp_path, max_iterations=1)
    with pytest.raises(ConfigError, match=r"its action_scale is 0\.25, the fine-tune's env gives 0\.5"):
        train(dataclasses.replace(cfg, env=dataclasses.replace(cfg.env, action_scale=0.5)))
    with pytest.raises(ConfigError, match="its obs_scales is"):
        scales = dataclasses.replace(cfg.env.obs_scales, dof_vel=0.1)
        train(dataclasses.replace(cfg, env=dataclasses.replace(cfg.env, obs_scales=scales)))
    assert not (tmp_path / "push-fine-tune" / "config.json").exists()  # refused before anything was written
