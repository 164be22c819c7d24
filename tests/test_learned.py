"""Tests of wbc.learned: batched env, policy file and numpy inference, BC term, training, controllers."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from import_graph import imports

from wbc.errors import NetworkMismatchError, PolicyInputError
from wbc.learned.env.env import BatchedEnv
from wbc.learned.env.env_config import DomainRandomisation, EnvConfig, ObsNoise
from wbc.learned.policy.numpy_policy import NumpyPolicy
from wbc.learned.policy.observations import ObsLayout, compatible_indices, compatible_observation
from wbc.learned.policy.policy_file import PolicyFileError, load_policy, save_policy
from wbc.robots.registry import get_robot
from wbc.types import MotorCommand

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = str(ROOT / "scenarios" / "push.toml")


def drop_last_column(npz: Path, key: str) -> dict[str, np.ndarray]:
    """Rewrite `npz` with array `key` one column short; returns the arrays written.

    The JSON's checksum is removed, as from an export older than the checksum, so that the shape check is what
    refuses the file.
    """
    with np.load(npz) as data:
        arrays = {k: data[k] for k in data.files}
    arrays[key] = arrays[key][:, :-1]
    np.savez(npz, **arrays)
    js = npz.with_suffix(".json")
    meta = json.loads(js.read_text())
    meta.pop("weights_sha256")
    js.write_text(json.dumps(meta))
    return arrays


def small_config(**kw) -> EnvConfig:
    base = dict(scenario=SCENARIO, num_envs=4, terrain="flat", nthread=1, domain=DomainRandomisation(num_variants=2))
    base.update(kw)
    return EnvConfig(**base)


@pytest.fixture(scope="module")
def env_pair():
    a, b = BatchedEnv(small_config(seed=3)), BatchedEnv(small_config(seed=3))
    yield a, b
    a.close()


# -- env ---------------------------------------------------------------------------------------------------------
def test_env_shapes_and_seeded_determinism(env_pair):
    a, b = env_pair
    obs_a, priv_a, _ = a.reset()
    obs_b, priv_b, _ = b.reset()
    assert obs_a.shape == (4, ObsLayout(15).size) == (4, 54)
    assert priv_a.shape == (4, 9)
    rng = np.random.default_rng(0)
    for _ in range(5):
        act = 0.3 * rng.standard_normal((4, 15))
        ra, rb = a.step(act), b.step(act)
    np.testing.assert_array_equal(ra.obs, rb.obs)
    np.testing.assert_array_equal(ra.reward, rb.reward)
    assert np.isfinite(ra.obs).all() and np.isfinite(ra.reward).all()
    # the joints moved: the physics ran
    assert np.abs(ra.obs[:, 9:24]).max() > 1e-3


def test_env_other_seed_differs():
    a, b = BatchedEnv(small_config(seed=0)), BatchedEnv(small_config(seed=1))
    assert not np.array_equal(a.reset()[0], b.reset()[0])


def test_env_terminates_when_the_trunk_touches_the_ground():
    env = BatchedEnv(small_config(pushes=False))
    env.state[:, 3] = 0.08  # trunk dropped onto the floor (qpos z is state[1 + 2])
    r = env.step(np.zeros((4, 15)))
    assert r.terminated.all()
    assert "episode/fall_rate" in r.log
    # the environments were reset to standing
    assert np.all(env.state[:, 3] > 0.25) and np.all(env.episode_step == 0)


def _poses(desc, nq: int) -> dict[str, np.ndarray]:
    """Configurations on flat ground: standing on the feet, lying on the side, kneeling on the FR calf (thigh
    vertical, calf 10 degrees off horizontal with the knee end down, the other legs folded: only the calf box touches,
    0.18 m from its foot)."""
    stand = np.zeros(nq)
    stand[2], stand[3], stand[7:] = desc.stand_height, 1.0, desc.nominal_q
    side = stand.copy()
    side[2], side[3:7] = 0.1, (np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0)
    kneel = stand.copy()
    kneel[2] = 0.206
    kneel[7:10] = (0.0, 0.0, -(np.pi / 2 + 0.17))
    for leg in range(1, 4):
        kneel[7 + 3 * leg + 1:7 + 3 * leg + 3] = (0.8, -2.7)
    return {"standing": stand, "on its side": side, "kneeling on a calf": kneel}


def test_env_terminates_exactly_when_evaluation_calls_the_robot_fallen():
    """Training's termination and `MujocoRobot.fallen` apply one rule (`wbc.hardware.mujoco.fall_rule`)."""
    from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig

    robot = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated"))
    poses = _poses(robot.desc, robot.desc.num_joints + 7)
    env = BatchedEnv(small_config(num_envs=len(poses), pushes=False))
    verdicts = {}
    with robot:
        for i, (name, qpos) in enumerate(poses.items()):
            robot.reset(seed=0, qpos=qpos)
            verdicts[name] = robot.fallen()
            env.state[i, 1:1 + env.nq] = qpos
            env.state[i, 1 + env.nq:1 + env.nq + env.nv] = 0.0
        hold = (np.array([q[7:] for q in poses.values()]) - env.default_q) / env.config.action_scale
        r = env.step(hold)
        knee = robot.sim_truth()  # the last pose, kneeling: the calf is on the ground, no foot is
        assert knee.ground_contact_bodies == ("FR_calf",) and not knee.foot_contact.any()
    assert verdicts == {"standing": False, "on its side": True, "kneeling on a calf": True}
    assert dict(zip(poses, r.terminated.tolist(), strict=True)) == verdicts


def test_env_pushes_come_from_the_scenario_band_in():
    env = BatchedEnv(small_config())
    trial = env.scenario.trial("in", env.config.train_seed_offset + env.config.seed, 0)
    assert trial.pushes, "push.toml trials have pushes"
    p = trial.pushes[0]
    k = int(round(p.start / env.config.timestep))
    i = int(np.flatnonzero(env.pushes.start[:, 0] == k)[0])
    np.testing.assert_allclose(env.pushes.force[i, 0], p.force_in_world)
    assert 200.0 <= np.linalg.norm(p.force_in_world) <= 300.0
    w = env.pushes.wrench(np.full(4, k), 10, np.tile(np.eye(3), (4, 1, 1)), np.zeros((4, 3)))
    assert w is not None and np.allclose(w[0][i, 0], p.force_in_world)


def test_env_keeps_every_push_of_a_trial(tmp_path):
    """A scenario may push more often than the schedule's first allocation (8 per episode): no push is dropped."""
    from wbc.hardware.mujoco.physics import push_steps

    often = tmp_path / "often.toml"
    often.write_text(Path(SCENARIO).read_text().replace("interval_s = [4.0, 6.0]", "interval_s = [1.0, 1.2]"))
    env = BatchedEnv(small_config(scenario=str(often)))
    for i in range(env.num_envs):  # the first reset gives environment i trial i
        pushes = env._trial(i).pushes
        assert len(pushes) > 8 and env.pushes.count[i] == len(pushes)
        want = [push_steps(p.start, p.duration, env.config.timestep) for p in pushes]
        got = np.stack([env.pushes.start[i], env.pushes.stop[i]], axis=1)[: len(pushes)]
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(env.pushes.force[i, : len(pushes)], [p.force_in_world for p in pushes])
    last = env.pushes.start[np.arange(env.num_envs), env.pushes.count - 1]  # each environment's last push acts
    np.testing.assert_array_equal(env.pushes.force_at(last), [env._trial(i).pushes[-1].force_in_world
                                                              for i in range(env.num_envs)])


def test_env_and_mujoco_robot_write_the_same_domain_and_spawn_pose():
    """The env's model variants and MujocoRobot apply domain parameters and spawn through one module
    (`wbc.hardware.mujoco.physics`): same parameters, same model numbers and the same initial configuration."""
    from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
    from wbc.scenario.domain import DomainParams

    env = BatchedEnv(small_config(num_envs=1, init_joint_noise=0.0, timestep=0.002, domain=DomainRandomisation(
        num_variants=1, payload_kg=(0.7, 0.7), payload_com_m=0.0, friction=(0.9, 0.9), motor_strength=(1.05, 1.05))))
    m = env.pool.models[0]
    with MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated")) as robot:
        robot.reset(seed=0, domain=DomainParams(payload_mass=0.7, friction=0.9, motor_strength=1.05))
        robot.write(MotorCommand.hold(robot.desc.nominal_q, env.pool.kp, env.pool.kd))
        for name in ("body_mass", "body_ipos", "body_inertia", "body_subtreemass", "geom_friction", "pair_friction",
                     "actuator_gainprm", "actuator_biasprm", "actuator_forcerange"):
            np.testing.assert_array_equal(getattr(m, name), getattr(robot.model, name), err_msg=name)
        np.testing.assert_array_equal(env.state[0, 1:1 + env.nq], robot.data.qpos)


def test_compatible_observation_keeps_the_leg_part():
    full, legs = ObsLayout(15), ObsLayout(12)
    obs = np.arange(full.size, dtype=np.float32)[None]
    sub = compatible_observation(obs, full, legs)
    assert sub.shape == (1, legs.size)
    np.testing.assert_array_equal(sub[0, :9], obs[0, :9])  # ang_vel, gravity, command
    np.testing.assert_array_equal(sub[0, 9:21], obs[0, 9:21])  # leg dof_pos
    np.testing.assert_array_equal(sub[0, 21:33], obs[0, 24:36])  # leg dof_vel
    np.testing.assert_array_equal(sub[0, 33:45], obs[0, 39:51])  # leg last_action


# -- policy file and numpy inference -------------------------------------------------------------------------------
def _actor(vec, extrinsics: bool, seed: int = 0):
    torch = pytest.importorskip("torch")
    models = pytest.importorskip("rsl_rl.models")
    from wbc.learned.train.extrinsics_actor import ExtrinsicsActor

    torch.manual_seed(seed)
    obs = vec.get_observations()
    dist = {"class_name": "GaussianDistribution", "init_std": 1.0, "std_type": "scalar"}
    if extrinsics:
        groups = {"actor": ["policy", "privileged"], "critic": ["policy", "privileged"]}
        actor = ExtrinsicsActor(obs, groups, "actor", vec.num_actions, hidden_dims=[32, 16], activation="elu",
                                obs_normalization=True, distribution_cfg=dist, extrinsics_dim=4, encoder_dims=[8])
    else:
        groups = {"actor": ["policy"], "critic": ["policy", "privileged"]}
        actor = models.MLPModel(obs, groups, "actor", vec.num_actions, hidden_dims=[32, 16], activation="elu",
                                obs_normalization=True, distribution_cfg=dist)
    # non-trivial normaliser statistics
    fake = obs.clone()
    for key in fake.keys():
        fake[key] = torch.randn_like(fake[key]) * 3.0 + 1.5
    actor.update_normalization(fake)
    return actor.eval()


@pytest.fixture(scope="module")
def vec():
    pytest.importorskip("torch")
    pytest.importorskip("rsl_rl")
    from wbc.learned.train.vec_env import RslVecEnv

    v = RslVecEnv(BatchedEnv(small_config(seed=5)))
    yield v


@pytest.mark.parametrize("extrinsics", [False, True])
def test_numpy_inference_matches_torch(vec, tmp_path, extrinsics):
    torch = pytest.importorskip("torch")
    from wbc.learned.train.export import policy_file_from_actor

    actor = _actor(vec, extrinsics)
    pf = policy_file_from_actor(actor, vec.cfg, task="push", stage=3)
    npz, _ = save_policy(tmp_path / "pi", pf)
    policy = NumpyPolicy(load_policy(npz))
    rng = np.random.default_rng(1)
    obs = vec.get_observations().clone()
    obs["policy"] = torch.from_numpy(rng.normal(0, 2, obs["policy"].shape).astype(np.float32))
    obs["privileged"] = torch.from_numpy(rng.normal(0, 2, obs["privileged"].shape).astype(np.float32))
    with torch.no_grad():
        want = actor(obs).numpy()
    z = policy.extrinsics(obs["privileged"].numpy()) if extrinsics else None
    got = policy(obs["policy"].numpy(), z)
    assert got.shape == want.shape == (4, 15)
    np.testing.assert_allclose(got, want, atol=1e-5, rtol=0)
    assert np.abs(want).max() > 1e-2  # not a trivially zero network


@pytest.fixture()
def saved_policy(vec, tmp_path):
    from wbc.learned.train.export import policy_file_from_actor

    npz, js = save_policy(tmp_path / "pi", policy_file_from_actor(_actor(vec, False), vec.cfg, task="push", stage=3))
    return npz, js


def test_policy_file_missing_json_key(saved_policy):
    npz, js = saved_policy
    meta = json.loads(js.read_text())
    del meta["action_scale"]
    js.write_text(json.dumps(meta))
    with pytest.raises(PolicyFileError, match=r"pi\.json: action_scale: missing key"):
        load_policy(npz)


def test_policy_file_wrong_shape(saved_policy):
    npz, _ = saved_policy
    drop_last_column(npz, "policy/1/weight")
    with pytest.raises(PolicyFileError, match=r"pi\.npz: policy/1/weight: expected shape \(16, 32\)"):
        load_policy(npz)


def test_policy_file_refuses_pickles_and_garbage(saved_policy):
    npz, _ = saved_policy
    np.savez(npz, obs_mean=np.array([{"a": 1}], dtype=object))
    with pytest.raises(PolicyFileError, match=r"pi\.npz: sha256 .* recorded at export"):  # the export's checksum first
        load_policy(npz)
    # without a recorded checksum (an older export), the archive itself is checked before anything is read
    meta = npz.with_suffix(".json")
    data = json.loads(meta.read_text())
    del data["weights_sha256"]
    meta.write_text(json.dumps(data))
    with pytest.raises(PolicyFileError, match=r"pi\.npz.*Python objects"):
        load_policy(npz)
    npz.write_bytes(b"not a zip")
    with pytest.raises(PolicyFileError, match="not a readable .npz"):
        load_policy(npz)


def test_policy_file_mismatched_robot(saved_policy):
    npz, _ = saved_policy
    pf = load_policy(npz)
    pf.check_robot(get_robot("a1-wx200", "actuated"))
    with pytest.raises(PolicyFileError, match="arm_mode"):
        pf.check_robot(get_robot("a1-wx200", "locked"), npz)
    with pytest.raises(PolicyFileError, match="robot"):
        pf.check_robot(get_robot("go1-arm", "actuated"), npz)


def test_inputs_and_networks_that_do_not_fit_are_refused_with_the_fix(vec, saved_policy):
    from wbc.learned.train.warm_start import warm_start_actor

    policy = NumpyPolicy(load_policy(saved_policy[0]))  # no extrinsics, no adaptation module
    obs = np.zeros((1, ObsLayout(15).size))
    with pytest.raises(PolicyInputError, match="call it without z"):
        policy(obs, np.zeros((1, 4)))
    with pytest.raises(PolicyInputError, match="run RMA phase 2"):
        policy.adaptation(np.zeros((1, 3 * obs.size)))
    with pytest.raises(NetworkMismatchError, match="TrainConfig.extrinsics_dim"):
        warm_start_actor(_actor(vec, True), load_policy(saved_policy[0]))


def test_policy_file_missing(tmp_path):
    with pytest.raises(PolicyFileError, match="file not found"):
        load_policy(tmp_path / "nothing.npz")


# -- composite policy (the decoupled baseline) ----------------------------------------------------------------------
@pytest.fixture()
def decoupled(tmp_path):
    """A pi2-like locked-arm policy with extrinsics, its decoupled env, a 3-output arm actor and their composite."""
    pytest.importorskip("torch")
    pytest.importorskip("rsl_rl")
    from wbc.learned.policy.composite_policy import save_composite
    from wbc.learned.train.export import decoupled_policy, policy_file_from_actor
    from wbc.learned.train.frozen_legs_vec_env import FrozenLegsVecEnv
    from wbc.learned.train.vec_env import RslVecEnv

    locked = RslVecEnv(BatchedEnv(small_config(arm_mode="locked")))
    pi2 = load_policy(save_policy(tmp_path / "pi2", policy_file_from_actor(
        _actor(locked, True, seed=1), locked.cfg, task="push", stage=2))[0])
    vec = FrozenLegsVecEnv(BatchedEnv(small_config(teacher_arm_mode="locked", seed=7)), pi2)
    assert vec.num_actions == 3
    arm = _actor(vec, False, seed=2)
    npz, js = save_composite(tmp_path / "dec", decoupled_policy(arm, pi2, vec.cfg, task="push", stage=3))
    return vec, pi2, arm, npz, js


def test_composite_numpy_inference_matches_the_torch_composite(decoupled):
    torch = pytest.importorskip("torch")
    from wbc.learned.policy.composite_policy import load_composite
    from wbc.learned.policy.numpy_composite import NumpyComposite
    from wbc.learned.train.torch_policy import TorchPolicy

    vec, pi2, arm, npz, _ = decoupled
    policy = NumpyComposite(load_composite(npz))
    rng = np.random.default_rng(4)
    obs = torch.from_numpy(rng.normal(0, 2, (4, ObsLayout(15).size)).astype(np.float32))
    priv = torch.from_numpy(rng.normal(0, 2, (4, 9)).astype(np.float32))
    legs_obs = obs[:, torch.from_numpy(compatible_indices(ObsLayout(15), ObsLayout(12)))]
    td = vec.get_observations().clone()
    td["policy"], td["privileged"] = obs, priv
    with torch.no_grad():
        want = torch.cat([TorchPolicy(pi2)(legs_obs, priv), arm(td)], dim=1).numpy()
    z = {"legs": policy.parts[0].policy.extrinsics(priv.numpy())}
    got = policy(obs.numpy(), z)
    assert got.shape == want.shape == (4, 15)
    np.testing.assert_allclose(got, want, atol=1e-5, rtol=0)
    assert np.abs(want[:, :12]).max() > 1e-2 and np.abs(want[:, 12:]).max() > 1e-2
    with pytest.raises(PolicyInputError, match="extrinsics"):
        policy(obs.numpy())


def test_frozen_legs_env_steps_the_legs_with_pi2(decoupled):
    torch = pytest.importorskip("torch")
    vec, pi2, _, _, _ = decoupled
    ref = NumpyPolicy(pi2)
    teacher, priv = vec._legs_input  # the leg policy's view of the current state
    legs = ref(teacher, ref.extrinsics(priv))
    arm = torch.full((4, 3), 0.5)
    vec.step(arm)
    np.testing.assert_allclose(vec.env.last_action[:, :12], np.clip(legs, -10, 10), atol=1e-12)
    np.testing.assert_array_equal(vec.env.last_action[:, 12:], 0.5)
    assert "teacher" not in vec.get_observations().keys()


def test_composite_file_errors_name_the_file_and_field(decoupled):
    from wbc.learned.policy.composite_policy import load_composite

    _, _, _, npz, js = decoupled
    with pytest.raises(PolicyFileError, match=r"dec\.json: format: 'wbc-composite-policy'.*load_composite"):
        load_policy(npz)
    good = js.read_text()

    def broken(edit) -> None:
        meta = json.loads(good)
        edit(meta)
        js.write_text(json.dumps(meta))

    broken(lambda m: m["parts"][1].update(joints=[11, 13, 14]))  # the arm part on a leg joint: its pose differs
    with pytest.raises(PolicyFileError, match=r"dec\.json: arm/default_q: .* on the part's joints"):
        load_composite(npz)
    broken(lambda m: m["parts"][0].update(joints=[0, 1, 2, 3, 4, 5, 0, 7, 8, 9, 10, 11]))  # same pose, twice
    with pytest.raises(PolicyFileError, match=r"dec\.json: legs/joints: joint 0 is also driven by part 'legs'"):
        load_composite(npz)
    broken(lambda m: m["parts"][1]["meta"].pop("hidden_dims"))
    with pytest.raises(PolicyFileError, match=r"dec\.json: arm/hidden_dims: missing key"):
        load_composite(npz)
    broken(lambda m: m["parts"][0]["meta"].update(kp=[30.0] * 12))
    with pytest.raises(PolicyFileError, match=r"legs/kp: .* differs from the composite's"):
        load_composite(npz)
    broken(lambda m: m["parts"].pop())
    with pytest.raises(PolicyFileError, match=r"parts: no part drives joints \[12, 13, 14\]"):
        load_composite(npz)
    broken(lambda m: m.pop("default_q"))
    with pytest.raises(PolicyFileError, match=r"dec\.json: default_q: missing key"):
        load_composite(npz)
    js.write_text(good)
    arrays = drop_last_column(npz, "arm/policy/1/weight")
    with pytest.raises(PolicyFileError, match=r"dec\.npz: arm/policy/1/weight: expected shape \(16, 32\)"):
        load_composite(npz)
    np.savez(npz, **{**arrays, "arm/policy/1/weight": np.array([{"a": 1}], dtype=object)})
    with pytest.raises(PolicyFileError, match=r"dec\.npz: member arm/policy/1/weight\.npy: holds Python objects"):
        load_composite(npz)


# -- BC term -------------------------------------------------------------------------------------------------------
def test_bc_schedule_linear_exponential_constant():
    from wbc.errors import ConfigError
    from wbc.learned.train.bc_schedule import BCSchedule

    lin = BCSchedule(initial=1.0, final=0.0, hold_iterations=10, anneal_iterations=100, kind="linear")
    assert lin.weight(0) == lin.weight(10) == 1.0
    assert lin.weight(60) == pytest.approx(0.5)
    assert lin.weight(110) == lin.weight(10_000) == 0.0
    w = [lin.weight(i) for i in range(200)]
    assert all(a >= b for a, b in zip(w, w[1:], strict=False))
    exp = BCSchedule(initial=1.0, final=0.01, anneal_iterations=100, kind="exponential")
    assert exp.weight(50) == pytest.approx(0.1)
    assert exp.weight(100) == pytest.approx(0.01) and exp.weight(500) == pytest.approx(0.01)
    assert BCSchedule(initial=0.3, kind="constant").weight(12345) == 0.3
    with pytest.raises(ConfigError, match="kind"):
        BCSchedule(kind="cosine")
    with pytest.raises(ConfigError, match="exponential"):
        BCSchedule(initial=1.0, final=0.0, kind="exponential")


def test_bc_loss_counts_only_the_compatible_actions():
    torch = pytest.importorskip("torch")
    from wbc.learned.train.ppo_bc import bc_loss

    teacher = torch.randn(8, 12)
    student = torch.zeros(8, 15, requires_grad=True)
    with torch.no_grad():
        student[:, :12] = teacher
        student[:, 12:] = 100.0  # the arm: no teacher for it
    mask = torch.arange(12)
    loss = bc_loss(student, teacher, mask)
    assert loss.item() == pytest.approx(0.0, abs=1e-12)
    with torch.no_grad():
        student[:, 3] += 2.0
    loss = bc_loss(student, teacher, mask)
    assert loss.item() == pytest.approx(4.0 / 12.0)
    loss.backward()
    assert torch.all(student.grad[:, 12:] == 0) and torch.all(student.grad[:, 3] != 0)
    # a mask that permutes: teacher action k is student action mask[k]
    perm = torch.tensor([14, 13, 12])
    assert bc_loss(torch.arange(15.0)[None], torch.tensor([[14.0, 13.0, 12.0]]), perm).item() == 0.0
    with pytest.raises(NetworkMismatchError, match="mask"):
        bc_loss(student, teacher, torch.arange(11))


# -- training ------------------------------------------------------------------------------------------------------
def _tiny(stage: int, root: Path, seed: int = 0, baseline: str | None = None, **kw):
    from wbc.learned.train.adaptation_config import AdaptationConfig
    from wbc.learned.train.stages import stage_config

    small = dict(seed=seed, num_steps_per_env=6, save_interval=1, actor_hidden_dims=(16,), critic_hidden_dims=(16,),
                 encoder_dims=(8,), extrinsics_dim=0 if baseline == "decoupled" else 4, rma=AdaptationConfig(
                     iterations=1, steps_per_iteration=4, history=3, hidden_dims=(8,), minibatch=16))
    return stage_config("push", stage, baseline, run_root=str(root), env_overrides=dict(
        num_envs=8, nthread=1, scenario=SCENARIO, domain=DomainRandomisation(num_variants=2), seed=seed),
        **{**small, **kw})


def _arrays(run_dir) -> dict[str, np.ndarray]:
    return load_policy(Path(run_dir) / "policy").arrays


def test_tiny_seeded_training_is_reproducible_resumable_and_feeds_the_next_stage(tmp_path):
    pytest.importorskip("torch")
    pytest.importorskip("rsl_rl")
    from wbc.errors import ConfigError
    from wbc.learned.train.train import latest_checkpoint, train

    a = train(_tiny(1, tmp_path / "a", max_iterations=2))
    b = train(_tiny(1, tmp_path / "b", max_iterations=2))
    wa, wb = _arrays(a["run_dir"]), _arrays(b["run_dir"])
    assert wa.keys() == wb.keys()
    for k in wa:
        np.testing.assert_array_equal(wa[k], wb[k], err_msg=k)
    assert a["iterations"] == 2 and a["env_steps"] == 2 * 6 * 8
    cfg = json.loads((Path(a["run_dir"]) / "config.json").read_text())
    assert cfg["train_config"]["stage"] == 1 and cfg["seed"] == 0 and "torch" in cfg["provenance"]["packages"]
    from wbc.learned.train.curves import plot_training_curves, read_scalars

    assert "Loss/value" in read_scalars(a["run_dir"])
    assert plot_training_curves([a["run_dir"], b["run_dir"]], tmp_path / "curves.png").stat().st_size > 1000
    # resume: one more iteration from the newest checkpoint
    r = train(_tiny(1, tmp_path / "a", max_iterations=3), resume=True)
    assert r["iterations"] == 3 and latest_checkpoint(r["run_dir"]).name == "model_2.pt"
    assert r["env_steps"] == 3 * 6 * 8
    with pytest.raises(ConfigError, match="differs"):
        train(_tiny(1, tmp_path / "a", max_iterations=3, init_std=0.5), resume=True)
    # stage 2 learns from the stage-1 export with the BC term; without it, a clear error
    with pytest.raises(ConfigError, match="previous stage"):
        train(_tiny(2, tmp_path / "empty", max_iterations=1))
    s2 = train(_tiny(2, tmp_path / "a", max_iterations=1))
    assert load_policy(Path(s2["run_dir"]) / "policy").meta["arm_mode"] == "locked"
    # the fine-tuned pi2 baseline starts from pi2's weights
    f3 = train(_tiny(3, tmp_path / "a", baseline="finetune-pi2", max_iterations=1))
    assert load_policy(Path(f3["run_dir"]) / "policy").meta["arm_mode"] == "actuated"
    # the decoupled baseline: pi2's legs, frozen, plus an arm policy; its export embeds pi2 whole
    from wbc.learned.policy.composite_policy import load_composite

    d3 = train(_tiny(3, tmp_path / "a", baseline="decoupled", max_iterations=2))
    assert d3["iterations"] == 2 and d3["env_steps"] == 2 * 6 * 8
    composite = load_composite(Path(d3["run_dir"]) / "policy")
    legs, arm = composite.parts
    assert (legs.joints, arm.joints) == (tuple(range(12)), (12, 13, 14)) and arm.policy.num_actions == 3
    pi2 = load_policy(Path(s2["run_dir"]) / "policy")
    assert legs.policy.arrays.keys() == pi2.arrays.keys()
    for k, v in pi2.arrays.items():
        np.testing.assert_array_equal(legs.policy.arrays[k], v, err_msg=k)
    assert not (Path(d3["run_dir"]) / "rma.json").exists()  # the arm observes no extrinsics, pi2 keeps its module
    with pytest.raises(ConfigError, match="frozen leg policy"):
        train(_tiny(3, tmp_path / "empty", baseline="decoupled", max_iterations=1))
    # RMA phase 2 ran: the export carries an adaptation module, so a controller can run it from RobotState alone
    from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
    from wbc.learned.policy.controller import LearnedController
    from wbc.types import VelocityCommand

    assert load_policy(Path(a["run_dir"]) / "policy").meta["adaptation"]["history"] == 3
    # the decoupled composite runs on the actuated robot, torch-free; its legs are pi2's on the legs' observation
    robot = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated"))
    ctrl = LearnedController(robot.desc, Path(d3["run_dir"]) / "policy")
    assert set(ctrl.histories) == {"legs"} and ctrl.histories["legs"].buf.shape == (1, 3, ObsLayout(12).size)
    with robot:
        robot.reset(seed=0)
        ctrl.reset()
        for _ in range(3):
            out = ctrl.act(robot.read(), VelocityCommand(vx=0.3))
            assert np.isfinite(out.q).all()
            robot.write(out)
            robot.advance(0.02)
    robot = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none"))
    ctrl = LearnedController(robot.desc, Path(a["run_dir"]) / "policy")
    with robot:
        robot.reset(seed=0)
        ctrl.reset()
        for k in range(4):
            state = robot.read()
            cmd = VelocityCommand(vx=0.3)
            expected = ctrl.policy.parts[0].policy.normalise(ctrl.observation(state, cmd)[None])[0]
            out = ctrl.act(state, cmd)
            assert np.isfinite(out.q).all()
            np.testing.assert_allclose(ctrl.histories["policy"].buf[0, -1], expected, atol=1e-5)
            if k == 0:  # after a reset the window is filled with the first observation
                np.testing.assert_allclose(ctrl.histories["policy"].buf[0, 0], expected, atol=1e-5)
            robot.write(out)
            robot.advance(0.02)


# -- controllers ---------------------------------------------------------------------------------------------------
def test_controller_observation_matches_the_training_env():
    from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
    from wbc.learned.policy.controller import LearnedController
    from wbc.learned.policy.observations import ObsScales
    from wbc.types import VelocityCommand

    # the same start, the same constant joint targets, 10 policy steps in the env and on MujocoRobot (both at the
    # evaluation's 2 ms physics step and with its CG solver: training's default 5 ms Newton step is another simulation)
    env = BatchedEnv(small_config(num_envs=1, pushes=False, init_joint_noise=0.0, timestep=0.002, decimation=10,
                                  solver="cg", noise=ObsNoise(
        dof_pos=0.0, dof_vel=0.0, ang_vel=0.0, gravity=0.0), domain=DomainRandomisation(
        num_variants=1, payload_kg=(0.0, 0.0), payload_com_m=0.0, friction=(1.0, 1.0), motor_strength=(1.0, 1.0))))
    robot = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated"))
    action = np.linspace(-0.5, 0.5, 15)
    ctrl = object.__new__(LearnedController)  # observation() needs only these fields
    ctrl.scales, ctrl.default_q = ObsScales(), robot.desc.nominal_q
    with robot:
        robot.reset(seed=0, qpos=env.state[0, 1:1 + env.nq].copy())
        for _ in range(10):
            r = env.step(action[None])
            robot.write(MotorCommand.hold(robot.desc.nominal_q + 0.25 * action, env.pool.kp, env.pool.kd))
            robot.advance(0.02)
        state = robot.read()
    ctrl.last_action = action
    cmd = VelocityCommand(*env._commands_now()[0])  # the command at the observation's time
    got = ctrl.observation(state, cmd)
    assert np.abs(state.gyro_in_body).max() > 1e-3  # the trunk is moving, so the comparison means something
    np.testing.assert_allclose(got, r.obs[0], atol=1e-5)


def test_learned_controllers_are_registered_and_refuse_missing_or_wrong_weights(vec, tmp_path):
    from wbc.control.registry import get_controller
    from wbc.learned.policy.controller import LearnedController
    from wbc.learned.train.export import policy_file_from_actor

    for name, arm in (("learned", "actuated"), ("learned-locked", "locked"), ("learned-noarm", "none")):
        assert get_controller(name).arm_mode == arm
    desc = get_robot("a1-wx200", "actuated")
    with pytest.raises(PolicyFileError, match="file not found"):
        LearnedController(desc, tmp_path / "none.npz")
    save_policy(tmp_path / "z", policy_file_from_actor(_actor(vec, True), vec.cfg, task="push", stage=3))
    with pytest.raises(PolicyFileError, match="adaptation module"):
        LearnedController(desc, tmp_path / "z")
    save_policy(tmp_path / "p", policy_file_from_actor(_actor(vec, False), vec.cfg, task="push", stage=3))
    with pytest.raises(PolicyFileError, match="arm_mode"):
        LearnedController(get_robot("a1-wx200", "locked"), tmp_path / "p")


def test_the_crouched_names_run_the_crouched_weights_of_each_robot_and_arm_mode():
    from wbc.control.registry import get_controller
    from wbc.errors import ConfigError, UnknownNameError
    from wbc.learned.policy.controller import LearnedController
    from wbc.learned.policy.shipped import shipped_weights

    for name, arm in (("learned-crouched", "actuated"), ("learned-locked-crouched", "locked"),
                      ("learned-noarm-crouched", "none")):
        spec = get_controller(name)
        assert spec.arm_mode == arm
        for robot in ("a1-wx200", "go1-arm"):
            desc = get_robot(robot, arm)
            path = shipped_weights(desc, "crouched")
            assert path.name == f"{robot}-{arm}-crouched.npz" and path != shipped_weights(desc)
            assert path.is_file(), f"{path.name} ships with the package"  # both robots have all three stages crouched
            assert shipped_weights(desc).is_file()
            ctrl = spec.make(desc)
            assert ctrl.path == path
            assert (ctrl.policy.file.meta["robot"], ctrl.policy.file.meta["arm_mode"]) == (robot, arm)
    desc = get_robot("a1-wx200", "none")
    with pytest.raises(UnknownNameError, match="crouched"):
        shipped_weights(desc, "upright")
    with pytest.raises(ConfigError, match="not both"):
        LearnedController(desc, shipped_weights(desc), posture="crouched")


def test_learned_controller_drives_the_simulated_robot(vec, tmp_path):
    from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
    from wbc.learned.policy.controller import LearnedController
    from wbc.learned.train.export import policy_file_from_actor
    from wbc.types import VelocityCommand

    actor = _actor(vec, False)
    save_policy(tmp_path / "p", policy_file_from_actor(actor, vec.cfg, task="push", stage=3))
    robot = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated"))
    ctrl = LearnedController(robot.desc, tmp_path / "p")
    assert ctrl.rate_hz == pytest.approx(50.0)
    with robot:
        robot.reset(seed=0)
        ctrl.reset()
        for _ in range(5):
            state = robot.read()
            obs = ctrl.observation(state, VelocityCommand(vx=0.3))
            out = ctrl.act(state, VelocityCommand(vx=0.3))
            want = robot.desc.nominal_q + 0.25 * np.clip(ctrl.policy(obs[None])[0], -10, 10)
            np.testing.assert_allclose(out.q, want, atol=1e-9)
            np.testing.assert_array_equal(out.kp[:12], 20.0)
            robot.write(out)
            robot.advance(1.0 / ctrl.rate_hz)


def test_reward_terms_see_real_motion():
    env = BatchedEnv(small_config(pushes=False))
    rng = np.random.default_rng(0)
    sums = {}
    for _ in range(10):
        r = env.step(rng.standard_normal((4, 15)))
    for name, value in env._episode_sums.items():
        sums[name] = float(np.abs(value).sum())
    for name in ("dof_acc", "action_rate", "work", "torques", "tracking_lin_vel", "orientation"):
        assert sums[name] > 0.0, name
    assert np.isfinite(r.reward).all()


def test_walking_prior_draws_its_commands_from_the_ranges():
    from wbc.errors import ConfigError
    from wbc.learned.train.stages import TURN_WALKING_PRIOR_COMMANDS, WALKING_PRIOR_COMMANDS, stage_config

    assert stage_config("push", 1).env.command_ranges == WALKING_PRIOR_COMMANDS
    assert stage_config("turn", 1).env.command_ranges == TURN_WALKING_PRIOR_COMMANDS
    assert stage_config("turn", 3).env.command_ranges is None  # pi2 and pi3: the scenario's commands
    assert stage_config("push", 2).env.command_ranges is None  # pi2 and pi3: the scenario's 0 or 0.3 m/s
    ranges = ((0.2, 0.4), (-0.1, 0.0), (0.5, 0.5))
    env = BatchedEnv(small_config(num_envs=16, command_ranges=ranges))
    cmd = env._command_target
    assert (cmd[:, 0] >= 0.2).all() and (cmd[:, 0] <= 0.4).all() and (cmd[:, 1] <= 0.0).all()
    np.testing.assert_array_equal(cmd[:, 2], 0.5)
    assert np.unique(cmd[:, 0]).size == 16  # drawn per episode, not one of the scenario's two options
    with pytest.raises(ConfigError, match="command_ranges"):
        small_config(command_ranges=((0.4, 0.2), (0.0, 0.0), (0.0, 0.0)))
    # a share of the episodes is told to stand; without it the draws are those above, unchanged
    standing = BatchedEnv(small_config(num_envs=64, command_ranges=ranges, standing_share=0.5))._command_target
    still = np.all(standing == 0.0, axis=1)
    assert 16 <= still.sum() <= 48 and np.all(standing[~still, 2] == 0.5)
    np.testing.assert_array_equal(BatchedEnv(small_config(num_envs=16, command_ranges=ranges))._command_target, cmd)
    assert stage_config("turn", 1).env.standing_share == 0.25 and stage_config("push", 1).env.standing_share == 0.0
    with pytest.raises(ConfigError, match="standing_share"):
        small_config(standing_share=1.5)


def test_fall_penalty_survives_the_positive_clipping():
    from wbc.learned.env.env_config import RewardScales
    from wbc.learned.env.rewards import Rewards, StepData

    n, j = 2, 12
    off = {f: 0.0 for f in RewardScales.__dataclass_fields__}
    scales = RewardScales(**{**off, "tracking_lin_vel": 1.0, "orientation": -5.0, "termination": -50.0})
    cfg = small_config(rewards=scales, only_positive_rewards=True)
    rewards = Rewards(cfg, -np.ones(j), np.ones(j), np.zeros(j))
    z = np.zeros((n, 3))
    tilted = np.array([[0.0, 0.0, -1.0], [0.0, 0.8, -0.6]])  # the falling robot is tilted: its step total is < 0
    step = StepData(base_linvel_in_body=z, base_angvel_in_body=z, gravity_in_body=tilted, command=z, q=np.zeros((n, j)),
                    dq=np.zeros((n, j)), dq_before=np.zeros((n, j)), power=None, torque_sq=None,
                    action=np.zeros((n, j)), last_action=np.zeros((n, j)), first_contact=np.zeros((n, 4), bool),
                    air_time=np.zeros((n, 4)), terminated=np.array([False, True]))
    total, terms = rewards.compute(step)
    dt = cfg.policy_dt
    # perfect tracking; the tilted step's negative total is clipped to 0, then the fall's penalty is added
    np.testing.assert_allclose(total, [dt, -50.0 * dt])
    np.testing.assert_allclose(terms["termination"], [0.0, -50.0 * dt])


def test_base_height_term_charges_a_robot_that_lies_down_and_the_env_measures_the_trunk_height():
    from wbc.learned.env.env import BatchedEnv
    from wbc.learned.env.env_config import RewardScales
    from wbc.learned.env.rewards import Rewards, StepData

    n, j = 2, 12
    off = {f: 0.0 for f in RewardScales.__dataclass_fields__}
    cfg = small_config(rewards=RewardScales(**{**off, "tracking_lin_vel": 1.0, "base_height": -30.0}),
                       base_height_target=0.28, only_positive_rewards=False)
    rewards = Rewards(cfg, -np.ones(j), np.ones(j), np.zeros(j))
    z, zj = np.zeros((n, 3)), np.zeros((n, j))
    step = StepData(base_linvel_in_body=z, base_angvel_in_body=z, gravity_in_body=z, command=z, q=zj, dq=zj,
                    dq_before=zj, power=None, torque_sq=None, action=zj, last_action=zj,
                    first_contact=np.zeros((n, 4), bool), air_time=np.zeros((n, 4)), terminated=np.zeros(n, bool),
                    base_height=np.array([0.28, 0.08]))  # standing at the target; lying on folded legs
    total, terms = rewards.compute(step)
    dt = cfg.policy_dt
    np.testing.assert_allclose(terms["base_height"], [0.0, -30.0 * 0.2 ** 2 * dt])
    np.testing.assert_allclose(total, [dt, dt - 30.0 * 0.2 ** 2 * dt])
    # in the env the term sees the trunk's height above the ground: a fresh robot is near its spawn height
    env = BatchedEnv(cfg)
    try:
        env.step(np.zeros((cfg.num_envs, env.num_actions)))
        height = env.state[:, 1 + 2]  # flat ground at z = 0
        assert np.all(np.abs(height - env.desc.stand_height) < 0.05)
        assert env._episode_sums["base_height"] == pytest.approx(-30.0 * (height - 0.28) ** 2 * dt)
    finally:
        env.close()


# -- CLI -----------------------------------------------------------------------------------------------------------
def test_bench_train_reports_control_steps_per_second():
    from wbc.tools.bench import bench_train

    cfg = small_config()
    result = bench_train(cfg, steps=3, repeats=1)
    assert result.control_steps_per_s > 0 and result.rollout_only_control_steps_per_s > 0
    assert result.physics_steps_per_s == pytest.approx(cfg.decimation * result.control_steps_per_s)
    assert result.timestep_s == cfg.timestep and result.decimation == cfg.decimation
    # the target scaled by this machine's bare-A1 reference: 15k at a 21.8k physics limit
    limit = result.reference.physics_limit_control_steps_per_s
    assert limit > 0
    assert result.reference.scaled_target_control_steps_per_s == pytest.approx(15_000 / 21_800 * limit)
    assert result.reference.control_steps_ratio_to_reference == pytest.approx(result.control_steps_per_s / limit)
    without = bench_train(cfg, steps=1, repeats=1, reference=False)
    assert without.reference is None and "reference_physics_limit_control_steps_per_s" not in without.as_dict()


def test_cli_train_dry_run_and_errors(capsys):
    from wbc.cli.main import main

    assert main(["train", "--task", "push", "--stage", "3", "--envs", "64", "--dry-run"]) == 0
    cfg = json.loads(capsys.readouterr().out)
    assert cfg["env"]["arm_mode"] == "actuated" and cfg["env"]["teacher_arm_mode"] == "locked"
    assert cfg["env"]["num_envs"] == 64 and cfg["bc"]["initial"] == 1.0
    assert cfg["teacher"].endswith("push-stage2/policy")
    assert cfg["rma"]["iterations"] == 200
    assert main(["train", "--task", "push", "--stage", "1", "--rma-iterations", "40", "--dry-run"]) == 0
    assert json.loads(capsys.readouterr().out)["rma"]["iterations"] == 40
    assert main(["train", "--task", "push", "--stage", "3", "--baseline", "decoupled", "--dry-run"]) == 0
    cfg = json.loads(capsys.readouterr().out)
    assert cfg["frozen_legs"].endswith("push-stage2/policy") and cfg["run_dir"].endswith("push-stage3-decoupled")
    assert main(["train", "--task", "push", "--stage", "3", "--baseline", "nope", "--dry-run"]) == 2
    assert "valid baselines" in capsys.readouterr().err


# -- warm start ----------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("extrinsics", [False, True])
def test_warm_started_actor_reproduces_the_old_policy_on_the_legs(tmp_path, extrinsics):
    torch = pytest.importorskip("torch")
    pytest.importorskip("rsl_rl")
    from wbc.learned.train.export import policy_file_from_actor
    from wbc.learned.train.vec_env import RslVecEnv
    from wbc.learned.train.warm_start import warm_start_actor

    old_vec = RslVecEnv(BatchedEnv(small_config(arm_mode="locked")))
    new_vec = RslVecEnv(BatchedEnv(small_config(arm_mode="actuated", seed=9)))
    old = load_policy(save_policy(tmp_path / "old", policy_file_from_actor(
        _actor(old_vec, extrinsics, seed=1), old_vec.cfg, task="push", stage=2))[0])
    new = _actor(new_vec, extrinsics, seed=2)
    warm_start_actor(new, old)
    obs = new_vec.get_observations().clone()
    rng = np.random.default_rng(3)
    obs["policy"] = torch.from_numpy(rng.normal(0, 2, obs["policy"].shape).astype(np.float32))
    obs["privileged"] = torch.from_numpy(rng.normal(0, 2, obs["privileged"].shape).astype(np.float32))
    with torch.no_grad():
        got = new(obs).numpy()
    legs_obs = compatible_observation(obs["policy"].numpy(), ObsLayout(15), ObsLayout(12))
    ref = NumpyPolicy(old)
    z = ref.extrinsics(obs["privileged"].numpy()) if extrinsics else None
    np.testing.assert_allclose(got[:, :12], ref(legs_obs, z), atol=1e-5)
    np.testing.assert_array_equal(got[:, 12:], 0.0)


def test_stage_and_baseline_configurations():
    from wbc.errors import ConfigError, UnknownNameError
    from wbc.learned.train.stages import stage_config

    s1, s2, s3 = (stage_config("push", k) for k in (1, 2, 3))
    assert (s1.env.arm_mode, s1.env.pushes, s1.env.terrain, s1.bc) == ("none", False, "flat", None)
    assert (s2.env.arm_mode, s2.env.pushes, s2.env.teacher_arm_mode) == ("locked", True, "none")
    assert s2.teacher.endswith("push-stage1/policy") and s2.action_mask == tuple(range(12))
    assert (s3.env.arm_mode, s3.env.teacher_arm_mode) == ("actuated", "locked") and s3.bc.initial > 0
    assert s3.env.bands == ("in",)
    # the stages after pi1 hold a nominal trunk height (the posture term), on both tasks; pi1 keeps its recipe
    for cfg in (s2, s3, stage_config("push", 3, "ppo"), stage_config("push", 1, "curriculum"),
                stage_config("turn", 2), stage_config("turn", 3)):
        assert (cfg.env.rewards.base_height, cfg.env.base_height_target) == (-50.0, 0.30)
    assert s1.env.rewards.base_height == 0.0
    # the turn task's pi1 is fine-tuned from an upright policy and keeps its posture term
    assert (stage_config("turn", 1).env.rewards.base_height, stage_config("turn", 1).env.base_height_target) == (
        -50.0, 0.30)
    ppo = stage_config("push", 3, "ppo")
    assert ppo.bc is None and ppo.init_from is None and ppo.env.teacher_arm_mode is None
    demo = stage_config("push", 3, "one-stage-demo")
    assert demo.env.teacher_arm_mode == "none" and demo.teacher.endswith("push-stage1/policy")
    ft = stage_config("push", 3, "finetune-pi2")
    assert ft.bc is None and ft.init_from.endswith("push-stage2/policy")
    c1, c3 = stage_config("push", 1, "curriculum"), stage_config("push", 3, "curriculum")
    assert (c1.env.arm_mode, c1.env.pushes, c1.init_from) == ("locked", False, None)
    assert c3.init_from.endswith("push-stage2-curriculum/policy") and c3.run_dir.endswith("push-stage3-curriculum")
    turn = stage_config("turn", 3)
    # the turn task trains on both turn directions, standing and up to 2 m/s
    assert turn.env.robot == "go1-arm" and turn.env.scenario.endswith("turn-both-ways.toml")
    assert turn.env.bands == ("stand", "1.0", "1.5", "2.0")
    # the turn task's pi1 starts from the shipped Go1 pi1, fine-tuned over commands up to 2 m/s and +-2 rad/s
    t1 = stage_config("turn", 1)
    assert s1.init_from is None and t1.init_from is not None and t1.env.robot == "go1-arm"
    prior = load_policy(t1.init_from)
    assert (prior.meta["robot"], prior.meta["arm_mode"], prior.num_actions) == ("go1-arm", "none", 12)
    assert t1.action_mask == tuple(range(12)) and t1.bc is None and t1.env.rewards.termination < 0
    assert t1.env.command_ranges[0][1] >= 2.0 and t1.env.command_ranges[2] == (-2.0, 2.0)
    # the turn task's stages that start from weights explore with less noise than the push task's (a running robot
    # trips on it)
    assert stage_config("turn", 2).init_std < stage_config("push", 2).init_std == 1.0
    assert stage_config("turn", 3).init_std == stage_config("turn", 2).init_std == t1.init_std
    with pytest.raises(ConfigError, match="stage-3"):
        stage_config("push", 2, "ppo")
    # recipe variants change one thing in the method's stage 3 and run in a directory of their own
    held, still, warm = (stage_config("push", 3, variant=v) for v in ("bc-held", "arm-still", "from-pi2"))
    assert held.bc.weight(0) == held.bc.weight(10_000) == 1.0 and s3.bc.weight(10_000) == 0.0
    assert still.env.rewards.arm_deviation < 0.0 == s3.env.rewards.arm_deviation
    assert warm.init_from == warm.teacher == s3.teacher and s3.init_from is None and warm.init_std < s3.init_std
    for v in (held, still, warm):
        assert v.run_dir == s3.run_dir + "-" + v.variant and v.max_iterations == s3.max_iterations
        same = dataclasses.replace(v, variant=None, run_dir=s3.run_dir, bc=s3.bc, init_from=None, init_std=s3.init_std,
                                   env=dataclasses.replace(v.env, rewards=s3.env.rewards))
        assert same == s3  # nothing else differs
    with pytest.raises(ConfigError, match="stage 3"):
        stage_config("push", 2, variant="bc-held")
    with pytest.raises(ConfigError, match="stage 3"):
        stage_config("push", 3, "ppo", variant="bc-held")
    with pytest.raises(UnknownNameError):
        stage_config("push", 3, variant="longer")
    dec = stage_config("push", 3, "decoupled")
    assert dec.frozen_legs.endswith("push-stage2/policy") and dec.env.teacher_arm_mode == "locked"
    assert (dec.env.arm_mode, dec.bc, dec.init_from, dec.extrinsics_dim) == ("actuated", None, None, 0)
    assert stage_config("push", 3, "decoupled", teacher="pi2").frozen_legs == "pi2"
    with pytest.raises(ConfigError, match="stage-3"):
        stage_config("push", 2, "decoupled")
    with pytest.raises(UnknownNameError, match="valid baselines"):
        stage_config("push", 3, "nope")
    with pytest.raises(UnknownNameError, match="valid tasks"):
        stage_config("walk", 1)


def test_env_push_matches_mujoco_robot():
    """A scenario push applied by the env moves the trunk as MujocoRobot's push does."""
    from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
    from wbc.scenario.push import Push

    env = BatchedEnv(small_config(num_envs=1, init_joint_noise=0.0, timestep=0.002, decimation=10,  # MujocoRobot's
                                  solver="cg",
                                  domain=DomainRandomisation(num_variants=1, payload_kg=(0.0, 0.0), payload_com_m=0.0,
                                                             friction=(1.0, 1.0), motor_strength=(1.0, 1.0))))
    push = Push.horizontal(magnitude=250.0, heading=0.7, offset_in_base=(0.0, 0.12, 0.0), start=0.1, duration=0.06)
    env.pushes.set(0, ())
    env.pushes.start[0, 0] = int(round(push.start / 0.002))
    env.pushes.stop[0, 0] = env.pushes.start[0, 0] + 30
    env.pushes.force[0, 0], env.pushes.offset[0, 0] = push.force_in_world, push.offset_in_base
    robot = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated"))
    hold = MotorCommand.hold(robot.desc.nominal_q, env.pool.kp, env.pool.kd)
    with robot:
        robot.reset(seed=0, qpos=env.state[0, 1:1 + env.nq].copy())
        robot.apply_push(push)
        robot.write(hold)
        for _ in range(15):
            env.step(np.zeros((1, 15)))
            robot.advance(0.02)
        v_robot = robot.data.qvel[:6].copy()
    v_env = env.state[0, 1 + env.nq:1 + env.nq + 6]
    assert np.linalg.norm(v_robot[:2]) > 0.3  # the push moved the trunk
    np.testing.assert_allclose(v_env[:3], v_robot[:3], atol=2e-3)
    # the lever arm: MujocoRobot refreshes it every physics step, the env predicts it to first order over the step
    assert np.abs(v_env[3:] - v_robot[3:]).max() < 0.01 * np.abs(v_robot[3:]).max()


def test_probe_reports_per_command_velocities(vec, tmp_path):
    from wbc.learned.train.export import policy_file_from_actor
    from wbc.tools.probe import probe_policy

    save_policy(tmp_path / "p", policy_file_from_actor(_actor(vec, True), vec.cfg, task="push", stage=3))
    rows = probe_policy(tmp_path / "p", small_config(num_envs=8), steps=4, settle=1)
    assert {r["vx_cmd"] for r in rows} <= {0.0, 0.3} and rows
    assert all(np.isfinite([r["vx"], r["vy"], r["yaw_rate"], r["falls_per_env_s"]]).all() for r in rows)


def test_probe_measures_each_command_held_and_an_episode_ending_on_its_last_step(vec, tmp_path):
    from wbc.learned.train.export import policy_file_from_actor
    from wbc.tools.probe import probe_policy

    save_policy(tmp_path / "p", policy_file_from_actor(_actor(vec, True), vec.cfg, task="push", stage=3))
    # commands drawn at random at each reset: the episodes end on the probe's last step, reset onto commands no env
    # held (they were keyed by the command after the step, and the fall rates by the command held in it)
    cfg = small_config(num_envs=4, episode_s=0.1, command_ranges=((0.0, 1.0), (-0.3, 0.3), (-1.0, 1.0)))
    steps = round(cfg.episode_s / cfg.policy_dt)
    rows = probe_policy(tmp_path / "p", cfg, steps=steps, settle=1)
    assert rows and all(np.isfinite([r["vx"], r["vy"], r["yaw_rate"], r["falls_per_env_s"]]).all() for r in rows)


def test_probe_counts_each_fall_under_the_command_its_env_had():
    from wbc.tools.probe import fall_rates

    # two envs, four steps of 0.02 s: env 0 walks at 0.3 m/s and falls twice, env 1 stands and never falls, then
    # env 1 is reset onto 0.3 m/s for its last two steps and falls once
    commands = np.zeros((4, 2, 3))
    commands[:, 0, 0] = 0.3
    commands[2:, 1, 0] = 0.3
    terminated = np.zeros((4, 2), dtype=bool)
    terminated[[1, 3], 0] = True
    terminated[3, 1] = True
    rates = fall_rates(commands, terminated, 0.02)
    assert rates == {(0.0, 0.0, 0.0): 0.0, (0.3, 0.0, 0.0): pytest.approx(3 / (6 * 0.02))}


def test_env_solver_is_configurable_and_checked():
    import mujoco

    from wbc.errors import ConfigError

    with pytest.raises(ConfigError, match="EnvConfig.solver.*newton, cg"):
        small_config(solver="pgs")
    for name, want in (("newton", mujoco.mjtSolver.mjSOL_NEWTON), ("cg", mujoco.mjtSolver.mjSOL_CG)):
        env = BatchedEnv(small_config(num_envs=1, solver=name))
        assert all(m.opt.solver == want for m in env.pool.models)
        env.close()


def test_shipped_ppo_baseline_is_a_policy_controller():
    from wbc.control.registry import get_controller
    from wbc.learned.policy.shipped import WEIGHTS_DIR

    spec = get_controller(f"policy:{WEIGHTS_DIR / 'a1-wx200-actuated-ppo'}")
    assert (spec.robot, spec.arm_mode) == ("a1-wx200", "actuated")
    assert "push task, stage 3" in spec.summary


# -- package boundaries --------------------------------------------------------------------------------------------
TORCH_SIDE = ("torch", "rsl_rl", "tensordict", "tensorboard", "wbc.learned.train")
IMPORT_RULES = {  # package -> what none of its modules may import, anywhere in the file
    "wbc/learned": ("wbc.tools", "wbc.arena", "wbc.control", "wbc.cli", "wbc.viz", "wbc.mpc"),
    "wbc/learned/policy": TORCH_SIDE + ("wbc.learned.env",),
    "wbc/learned/env": TORCH_SIDE,
    "wbc/hardware/mujoco": ("wbc.learned", "wbc.arena", "wbc.control", "wbc.tools", "wbc.cli", "wbc.viz", "wbc.mpc"),
}


def _imports(path: Path) -> list[tuple[str, int, bool]]:
    """(module, line, at module level) of every import in a file, `require("module")` calls included."""
    return [(i.module, i.line, i.top_level) for i in imports(path)]


@pytest.mark.parametrize("package", sorted(IMPORT_RULES))
def test_imports_run_downward_only(package):
    """Inference and the env stay torch-free, nothing learned reaches up to the arena, tools or CLI, the MuJoCo backend
    knows no controller; and no wbc module is imported inside a function, where such an arrow would hide."""
    banned = IMPORT_RULES[package]
    found = []
    for path in sorted((ROOT / package).rglob("*.py")):
        for module, line, top in _imports(path):
            where = f"{path.relative_to(ROOT)}:{line} imports {module}"
            if any(module == b or module.startswith(b + ".") for b in banned):
                found.append(where)
            elif module.startswith("wbc") and not top:
                found.append(where + " inside a function")
    assert not found, found


def test_policy_and_env_import_and_run_without_torch(tmp_path):
    """`wbc.learned.policy` and `wbc.learned.env` are what ships without the ``train`` extra: with torch unimportable,
    they import, the env steps, and a `LearnedController` acts on a robot state from the shipped weights, found from
    the package wherever the working directory is."""
    code = textwrap.dedent(f"""
        import sys
        sys.modules["torch"] = None  # `import torch` now raises ImportError
        import numpy as np
        import wbc.learned.env
        import wbc.learned.policy
        from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
        from wbc.learned.env import BatchedEnv, DomainRandomisation, EnvConfig
        from wbc.learned.policy import LearnedController
        from wbc.types import VelocityCommand

        env = BatchedEnv(EnvConfig(scenario={SCENARIO!r}, num_envs=2, terrain="flat", nthread=1,
                                   domain=DomainRandomisation(num_variants=1)))
        assert np.isfinite(env.step(np.zeros((2, env.num_actions))).obs).all()
        env.close()
        robot = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated"))
        ctrl = LearnedController(robot.desc)
        with robot:
            robot.reset(seed=0)
            out = ctrl.act(robot.read(), VelocityCommand(vx=0.3))
        assert np.isfinite(out.q).all() and out.q.shape == (15,)
        loaded = sorted(m for m in sys.modules if m.startswith(("rsl_rl", "tensordict", "wbc.learned.train")))
        assert not loaded, loaded
        print("torch-free: ok")
    """)
    path = os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=tmp_path,
                         env={**os.environ, "PYTHONPATH": path})
    assert run.returncode == 0 and "torch-free: ok" in run.stdout, run.stderr


_FORWARD = '''
import hashlib, sys
import wbc  # first, as any program of ours: it pins the numeric kernels before numpy loads
import numpy as np
from wbc.learned.policy import WEIGHTS_DIR
from wbc.learned.policy.numpy_policy import NumpyPolicy
from wbc.learned.policy.policy_file import load_policy
policy = NumpyPolicy(load_policy(WEIGHTS_DIR / "a1-wx200-actuated.npz"))
rng = np.random.default_rng(0)
obs_size = len(policy.file.arrays["obs_mean"])
obs = rng.standard_normal((3, obs_size))
z = policy.extrinsics(rng.standard_normal((3, len(policy.file.arrays["privileged_mean"]))))
out = [z, policy(obs, z), policy.adaptation(rng.standard_normal((3, policy.history * obs_size)))]
print(hashlib.sha256(b"".join(a.tobytes() for a in out)).hexdigest())
'''


def test_policy_inference_gives_the_same_bits_whatever_blas_kernel_the_cpu_selects():
    # OpenBLAS chooses its kernels by the CPU; OPENBLAS_CORETYPE makes this machine use another machine's. numpy's
    # own SIMD loops are switched down too, below AVX-512 always: `wbc` switches those off wherever it runs
    # (wbc/_kernels.py), as their last bits differ. A closed loop turns a last-bit difference into another trajectory.
    from wbc._kernels import NUMPY_FEATURES_OFF

    digests = set()
    lowest = {"OPENBLAS_CORETYPE": "Prescott", "NPY_DISABLE_CPU_FEATURES": NUMPY_FEATURES_OFF + " AVX2 FMA3 AVX F16C"}
    for env in ({}, {"OPENBLAS_CORETYPE": "Sandybridge"}, lowest):
        base = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES")}
        out = subprocess.run([sys.executable, "-c", _FORWARD], env={**base, **env}, capture_output=True,
                             text=True, timeout=60, check=True)
        digests.add(out.stdout.strip())
    assert len(digests) == 1, digests


def test_the_compiled_layers_give_numpys_bits_for_every_length_and_batch():
    # the compiled affine layer must add in numpy's pairwise order (runs under 8, blocks of up to 128, halves above)
    # and the ELU must be numpy's: every published trial of a policy was played with `np.add.reduce` and numpy's ELU
    from wbc.learned.policy.numpy_policy import activation, dense

    rng = np.random.default_rng(7)
    lengths = [1, 7, 8, 9, 15, 16, 127, 128, 129, 130, 255, 256, 257, 300, 1350, 2049]
    for n_in in lengths:
        for shape in ((n_in,), (1, n_in), (5, n_in), (2, 3, n_in)):
            x = rng.standard_normal(shape) * rng.choice([1e-3, 1.0, 30.0])
            w32 = rng.standard_normal((int(rng.integers(1, 70)), n_in)).astype(np.float32)
            b = rng.standard_normal(w32.shape[0])
            expected = np.add.reduce(x[..., None, :] * w32.astype(np.float64), axis=-1) + b
            got = dense(x, w32, b)
            assert got.shape == expected.shape and got.tobytes() == expected.tobytes(), (n_in, shape)
    x = np.concatenate([rng.standard_normal(500) * 5, [-0.0, 0.0, -1e-310, -800.0, np.nan, np.inf, -np.inf]])
    expected = np.where(x > 0.0, x, np.expm1(np.minimum(x, 0.0)))
    assert activation("elu", x).tobytes() == expected.tobytes()
    assert activation("elu", x.reshape(1, -1)).tobytes() == expected.tobytes()


def test_one_quaternions_projected_gravity_has_the_bits_of_the_batched_arrays():
    # a robot's tick takes the Python-float path, the training env's batches the arrays' path: one policy, one result
    from wbc.learned.policy.observations import projected_gravity

    rng = np.random.default_rng(11)
    quats = rng.standard_normal((2000, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    quats[:3] = [[1.0, 0.0, 0.0, 0.0], [-0.0, 1.0, -0.0, 0.0], [0.5, -0.5, 0.5, -0.5]]
    batched = projected_gravity(quats)
    assert np.allclose(batched[0], [0.0, 0.0, -1.0]) and np.allclose(batched[1], [0.0, 0.0, 1.0])
    for quat, expected in zip(quats, batched, strict=True):
        assert projected_gravity(quat[None]).tobytes() == expected.tobytes()
        assert projected_gravity(quat).shape == (3,) and projected_gravity(quat).tobytes() == expected.tobytes()


def test_a_policy_handed_an_input_of_the_wrong_width_says_so():
    from wbc.learned.policy import WEIGHTS_DIR
    from wbc.learned.policy.numpy_policy import NumpyPolicy
    from wbc.learned.policy.policy_file import load_policy

    policy = NumpyPolicy(load_policy(WEIGHTS_DIR / "a1-wx200-actuated.npz"))
    obs_size = len(policy.file.arrays["obs_mean"])
    with pytest.raises(PolicyInputError, match=f"takes {policy.history * obs_size} inputs"):
        policy.adaptation(np.zeros((1, policy.history * obs_size + 1)))


@pytest.mark.parametrize("band, option_yaw", [("stand", 0.0), ("2.0", -2.0), ("2.0", 2.0), ("1.0", -0.5)])
def test_the_shipped_turn_policy_turns_both_ways_and_stands(band, option_yaw, tmp_path, monkeypatch):
    """The shipped go1-arm pi3 (`learned`) on turn-both-ways: right turns at 2 m/s, left, and standing still."""
    monkeypatch.chdir(tmp_path)  # MuJoCo may write its log file here
    from wbc.arena.sim_trial import run_trial
    from wbc.scenario import load_scenario

    scenario = load_scenario("scenarios/turn-both-ways.toml")
    trial = next(t for t in (scenario.trial(band, 0, i) for i in range(40)) if t.command.yaw_rate == option_yaw)
    record, episode = run_trial(dataclasses.replace(trial, duration_s=8.0), "learned")
    assert record.success and not record.error
    late = episode.t > 3.0  # after the 1 s command ramp and the turn's build-up
    speed = episode.v_base_in_yaw[late, 0].mean()
    yaw_rate = episode.yaw_rate[late].mean()
    if band == "stand":
        assert np.abs(episode.v_base_in_yaw[late]).mean() < 0.1 and abs(yaw_rate) < 0.1  # it stands, not walks on
    else:
        assert abs(speed - trial.command.vx) < 0.3 * trial.command.vx
        assert np.sign(yaw_rate) == np.sign(option_yaw) and abs(yaw_rate) > 0.5 * abs(option_yaw)


@pytest.mark.parametrize("weights", ["a1-wx200-actuated", "a1-wx200-actuated-mpc-distilled", "a1-wx200-none"])
def test_a_one_part_policy_acts_as_the_parts_loop_does_and_a_faulty_action_still_raises(weights):
    from wbc.learned.policy import WEIGHTS_DIR

    _three_paths_agree(WEIGHTS_DIR / f"{weights}.npz")


def test_a_policy_without_memory_acts_alike_on_every_path(vec, tmp_path):
    from wbc.learned.train.export import policy_file_from_actor

    save_policy(tmp_path / "p", policy_file_from_actor(_actor(vec, False), vec.cfg, task="push", stage=3))
    _three_paths_agree(tmp_path / "p.npz")


def _three_paths_agree(path):
    # a policy of one part (every file but a composite) acts in one compiled call (`policy_tick`), or else through
    # `step`'s short path: both must give the parts' loop's actions and commands to the bit, over an episode of
    # ticks with a reset in it
    from wbc.errors import CommandError
    from wbc.learned.policy import LearnedController
    from wbc.types import RobotState, VelocityCommand

    desc = get_robot("a1-wx200", load_policy(path).meta["arm_mode"])
    fast, whole, loop = (LearnedController(desc, path) for _ in range(3))
    assert fast._tick is not None and fast._whole is not None
    whole._tick = None
    loop._tick, loop._whole = None, None
    rng = np.random.default_rng(3)
    n = len(desc.nominal_q)
    for tick in range(60):
        if tick == 40:
            for ctrl in (fast, whole, loop):
                ctrl.reset()
        quat = rng.standard_normal(4)
        state = RobotState(tick=tick, time=0.02 * tick, q=np.asarray(desc.nominal_q) + 0.1 * rng.standard_normal(n),
                           dq=rng.standard_normal(n), tau_est=np.zeros(n), imu_quat=quat / np.linalg.norm(quat),
                           gyro_in_body=rng.standard_normal(3), accel_in_body=np.array([0.0, 0.0, 9.81]),
                           foot_force=np.full(4, 40.0))
        command = VelocityCommand(vx=float(rng.uniform(-1, 1)), yaw_rate=float(rng.uniform(-1, 1)))
        if tick in (20, 21):  # read-only arrays take the numpy path on the same memory window, then back
            for array in (state.q, state.dq, state.imu_quat, state.gyro_in_body):
                array.setflags(write=False)
        a, b, c = fast.act(state, command), whole.act(state, command), loop.act(state, command)
        assert a.rows.tobytes() == b.rows.tobytes() == c.rows.tobytes(), tick
        assert fast.last_action.tobytes() == whole.last_action.tobytes() == loop.last_action.tobytes()
        if tick == 30:  # the history the numpy path keeps is the one the compiled tick fills
            assert all(fast.histories[k].buf.tobytes() == loop.histories[k].buf.tobytes() for k in fast.histories)
    assert not a.rows.flags.writeable
    bad = RobotState(tick=0, time=0.0, q=np.full(n, np.nan), dq=np.zeros(n), tau_est=np.zeros(n),
                     imu_quat=np.array([1.0, 0.0, 0.0, 0.0]), gyro_in_body=np.zeros(3),
                     accel_in_body=np.array([0.0, 0.0, 9.81]), foot_force=np.full(4, 40.0))
    with pytest.raises(CommandError, match="non-finite"):
        fast.act(bad, VelocityCommand())


def test_curves_name_every_run_once_under_the_panels_where_no_line_is_hidden(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wbc.learned.train.curves import LEGEND_ROW_IN, _save

    fig, axes = plt.subplots(1, 2, figsize=(8.0, 3.0), squeeze=False)
    for k in range(4):  # the last run logs only in the second panel
        if k < 3:
            axes[0][0].plot([0, 1], [k, k + 1], label=f"run {k}")
        axes[0][1].plot([0, 1], [k, 0], label=f"run {k}")
    path = _save(fig, axes, tmp_path / "c.png", plt)
    assert path.stat().st_size > 1000
    assert all(ax.get_legend() is None for ax in axes[0])
    (legend,) = fig.legends
    assert [t.get_text() for t in legend.get_texts()] == ["run 0", "run 1", "run 2", "run 3"]
    # four names in three columns: two rows, and the figure grew by them
    assert fig.get_size_inches()[1] == pytest.approx(3.0 + 2 * LEGEND_ROW_IN + 0.1)
