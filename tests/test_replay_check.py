"""Replay files and ``check-controller --replay``: what the trainer recorded, fed back to a controller.

The shipped pi3 is exported to ONNX (which records a replay beside the model) once for the module. The numpy
controller and the ONNX export both reproduce the recording; the same model with an I/O file whose first two
observation terms are swapped meets the whole contract and fails the replay, naming both terms; a file that is not a
replay file, or is one with a bad field, is refused naming the file and the field.
"""

import numpy as np
import pytest

from wbc.cli.main import main
from wbc.control import CheckConfig, ControllerSpec, check_controller
from wbc.control.registry import get_controller
from wbc.control.stand import StandController
from wbc.errors import ConfigError
from wbc.learned.policy.replay_file import Replay, ReplayFileError, load_replay, replay_path_for, save_replay
from wbc.learned.policy.shipped import WEIGHTS_DIR
from wbc.robots.registry import get_robot

pytest.importorskip("onnxruntime")

PI3 = WEIGHTS_DIR / "a1-wx200-actuated"
ANG_VEL = '[[observation.terms]]\nname = "base_ang_vel"\nscale = 0.25\n'
GRAVITY = '[[observation.terms]]\nname = "projected_gravity"\n'


@pytest.fixture(scope="module")
def export(tmp_path_factory):
    """The shipped pi3 as ONNX: (model, I/O file, the replay the export recorded, an I/O file with two terms
    swapped)."""
    pytest.importorskip("torch")
    from wbc.learned.train.onnx_export import export_onnx

    root = tmp_path_factory.mktemp("pi3")
    model, io = export_onnx(PI3, root / "pi3")
    text = io.read_text()
    assert ANG_VEL in text and GRAVITY in text
    swapped = root / "swapped.toml"
    swapped.write_text(text.replace(ANG_VEL, "@").replace(GRAVITY, ANG_VEL).replace("@", GRAVITY))
    return model, io, replay_path_for(model), swapped


def _replay_outcome(result):
    (outcome,) = [o for o in result.outcomes if o.check == "replay"]
    return outcome


def test_the_recording_holds_the_states_observations_and_actions_of_the_rollout(export):
    _, _, path, _ = export
    replay = load_replay(path)
    desc = get_robot("a1-wx200", "actuated")
    n = len(replay)
    assert (replay.robot, replay.arm_mode, replay.rate_hz) == ("a1-wx200", "actuated", 50.0) and n == 100
    assert replay.obs_terms == ("base_ang_vel", "projected_gravity", "velocity_commands", "joint_pos_rel", "joint_vel",
                                "last_action")
    assert replay.obs_slices == ((0, 3), (3, 6), (6, 9), (9, 24), (24, 39), (39, 54))
    assert replay.obs.shape == (n, 54) and replay.actions.shape == (n, 15) and replay.action_joints == desc.joint_names
    # every term moves during the rollout (the push and the command make them), so a term out of place shows
    for name, (a, b) in zip(replay.obs_terms, replay.obs_slices, strict=True):
        assert np.ptp(replay.obs[:, a:b], axis=0).max() > 0.05, name
    # the observation is the numpy controller's, and the previous action is the action one tick before
    np.testing.assert_array_equal(replay.obs[1:, 39:54], replay.actions[:-1].astype(np.float32))
    np.testing.assert_allclose(replay.obs[:, 9:24], replay.states["q"] - replay.default_q, atol=1e-6)
    state = replay.state(7)
    np.testing.assert_array_equal(state.q, replay.states["q"][7])
    assert replay.velocity_command(99).as_array().tolist() == pytest.approx(replay.command[99].tolist())


def test_the_policy_and_its_onnx_export_reproduce_the_recording(export):
    model, _, path, _ = export
    for name in ("learned", f"onnx:{model}"):
        result = check_controller(name, CheckConfig(seconds=0.1, robots=("a1-wx200",), replay=path))
        result.raise_if_failed()
        outcome = _replay_outcome(result)
        assert outcome.arm_mode == "actuated" and "the observation equals the recording term by term" in outcome.detail


def test_two_observation_terms_swapped_in_the_io_file_meet_the_contract_and_fail_the_replay_by_name(export, capsys):
    model, _, path, swapped = export
    spec = get_controller(f"onnx:{model}", io=swapped)
    result = check_controller(spec, CheckConfig(seconds=0.1, replay=path))
    assert {o.check for o in result.failed()} == {"replay"}  # the contract holds: the layout is another one
    detail = _replay_outcome(result).detail
    assert "entries 0-2 hold base_ang_vel in the recording but projected_gravity in the controller's frame" in detail
    assert "entries 3-5 hold projected_gravity in the recording but base_ang_vel in the controller's frame" in detail
    assert "Check the order, scales and sources of base_ang_vel, projected_gravity" in detail
    assert "velocity_commands" not in detail.split("; the actions")[0]  # the terms in place are not blamed
    # on the command line: the failed check, exit status 1
    assert main(["check-controller", f"onnx:{model}", "--io", str(swapped), "--replay", str(path), "--seconds",
                 "0.1"]) == 1
    out = capsys.readouterr().out
    assert "FAIL replay" in out and "projected_gravity in the controller's frame" in out


def test_a_controller_that_does_not_say_what_it_observes_is_judged_by_its_actions(export):
    _, _, path, _ = export
    spec = ControllerSpec("hold", "actuated", StandController, "a PD hold", robots=("a1-wx200",))
    detail = _replay_outcome(check_controller(spec, CheckConfig(seconds=0.1, replay=path))).detail
    assert "the actions differ from tick 0" in detail and "cannot be traced to an observation term" in detail


def test_a_recording_for_another_robot_or_arm_mode_is_refused_naming_the_file(export, capsys):
    _, _, path, _ = export
    with pytest.raises(ConfigError, match=rf"--replay {path}: robot, arm_mode: recorded on a1-wx200 with arm actuated"):
        check_controller("learned-locked", CheckConfig(replay=path))
    with pytest.raises(ConfigError, match="recorded on a1-wx200"):
        check_controller("learned", CheckConfig(replay=path, robots=("go1-arm",)))
    assert main(["check-controller", "learned-noarm", "--replay", str(path)]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "Traceback" not in err


def _fields(path) -> dict[str, np.ndarray]:
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


BAD = [
    ("obs_slices", lambda f: f.pop("obs_slices"), "missing array"),
    ("actions", lambda f: f.update(actions=f["actions"][:-1]), "expected shape (100, n)"),
    ("q", lambda f: f.update(q=f["q"][:, :12]), "expected shape (100, 15)"),
    ("obs_slices", lambda f: f.update(obs_slices=f["obs_slices"][::-1].copy()), "the terms must tile a frame"),
    ("dq", lambda f: f["dq"].__setitem__((3, 4), np.nan), "not finite at index (3, 4)"),
    ("action_joints", lambda f: f.update(action_joints=np.array(["FR_hip_joint"] * 15)), "once each"),
    ("robot", lambda f: f.update(robot=np.asarray("a2")), "unknown robot 'a2'"),
    ("format", lambda f: f.update(format=np.asarray("wbc-policy")), "expected 'wbc-replay'"),
]


@pytest.mark.parametrize(("field", "damage", "reason"), BAD, ids=[f"{b[0]}-{i}" for i, b in enumerate(BAD)])
def test_a_bad_replay_file_names_the_file_and_the_field(export, tmp_path, field, damage, reason):
    _, _, path, _ = export
    arrays = _fields(path)
    damage(arrays)
    bad = tmp_path / "bad.npz"
    np.savez(bad, **arrays)
    with pytest.raises(ReplayFileError) as caught:
        load_replay(bad)
    assert caught.value.field == field and reason in caught.value.reason and caught.value.path == str(bad)


def test_an_unreadable_replay_file_stops_the_command_before_any_check(tmp_path, capsys):
    cut = tmp_path / "cut.npz"
    cut.write_bytes(b"PK\x03\x04 not a whole zip file")
    for given, says in ((cut, "not a readable .npz file"), (tmp_path / "none.npz", "file not found")):
        assert main(["check-controller", "learned", "--replay", str(given)]) == 2
        captured = capsys.readouterr()
        assert f"{given}: {says}" in captured.err and "Traceback" not in captured.err and "build" not in captured.out


def test_a_replay_written_by_hand_round_trips(export, tmp_path):
    _, _, path, _ = export
    replay = load_replay(path)
    states = {k: v for k, v in replay.states.items() if k in ("q", "dq", "imu_quat", "gyro_in_body")}
    copy = Replay(path="", robot=replay.robot, arm_mode=replay.arm_mode, rate_hz=replay.rate_hz, source="by hand",
                  states=states, command=replay.command, obs=replay.obs, obs_terms=replay.obs_terms,
                  obs_slices=replay.obs_slices, actions=replay.actions, action_joints=replay.action_joints,
                  default_q=replay.default_q, action_scale=replay.action_scale)
    written = save_replay(tmp_path / "hand.npz", copy)
    again = load_replay(written)
    assert again.source == "by hand" and np.all(again.states["foot_force"] == 0.0)  # optional fields: zeros
    np.testing.assert_array_equal(again.states["time"], np.arange(len(replay)) / 50.0)
    result = check_controller("learned", CheckConfig(seconds=0.1, robots=("a1-wx200",), replay=written))
    assert _replay_outcome(result).passed


def test_a_training_run_leaves_a_replay_its_policy_reproduces(tmp_path):
    pytest.importorskip("torch")
    pytest.importorskip("rsl_rl")
    from pathlib import Path

    from wbc.learned.env.env_config import DomainRandomisation
    from wbc.learned.train.stages import stage_config
    from wbc.learned.train.train import train

    root = Path(__file__).resolve().parent.parent
    cfg = stage_config("push", 1, None, run_root=str(tmp_path), seed=0, num_steps_per_env=4, save_interval=1,
                       actor_hidden_dims=(16,), critic_hidden_dims=(16,), extrinsics_dim=0, max_iterations=1,
                       env_overrides=dict(num_envs=4, nthread=1, scenario=str(root / "scenarios" / "push.toml"),
                                          domain=DomainRandomisation(num_variants=1), seed=0))
    result = train(cfg)
    replay = Path(result["replay"])
    assert replay == Path(result["run_dir"]) / "policy.replay.npz"
    recorded = load_replay(replay)
    assert (recorded.robot, recorded.arm_mode) == ("a1-wx200", "none") and len(recorded) >= 1
    outcome = _replay_outcome(check_controller(f"policy:{result['policy']}", CheckConfig(seconds=0.1,
                                                                                         replay=replay)))
    assert outcome.passed, outcome.detail


def _onnx_recording(tmp_path, name: str, permute: list[int] | None, pos_scale: float = 1.0):
    """An ONNX policy (a linear network, Isaac Lab's joint order) and a replay recorded from it on moving joints,
    its joint_pos_rel columns taken in the order `permute` (the controller's entry each recorded entry holds), or
    scaled by `pos_scale`: the recording of a trainer whose joint order or scale differs from the I/O file's."""
    import dataclasses

    from fuzz.cases import ONNX_FRAME, ONNX_IO, ONNX_JOINTS, onnx_linear_model

    rng = np.random.default_rng(3)
    model, io = tmp_path / f"{name}.onnx", tmp_path / f"{name}.toml"
    model.write_bytes(onnx_linear_model(rng.normal(0.0, 0.1, (ONNX_FRAME, 12))))
    io.write_text(ONNX_IO)
    desc = get_robot("a1-wx200", "none")
    index = [desc.joint_names.index(j) for j in ONNX_JOINTS]
    ticks = 30
    states = {"q": desc.nominal_q + rng.normal(0.0, 0.1, (ticks, 12)), "dq": np.zeros((ticks, 12)),
              "imu_quat": np.tile([1.0, 0.0, 0.0, 0.0], (ticks, 1)), "gyro_in_body": rng.normal(0.0, 0.5, (ticks, 3))}
    blank = Replay(path="", robot="a1-wx200", arm_mode="none", rate_hz=50.0, source="by hand", states=states,
                   command=np.tile([0.3, 0.0, 0.0], (ticks, 1)), obs=np.zeros((ticks, ONNX_FRAME)),
                   obs_terms=("base_ang_vel", "velocity_commands", "joint_pos_rel", "last_action"),
                   obs_slices=((0, 3), (3, 6), (6, 18), (18, 30)), actions=np.zeros((ticks, 12)),
                   action_joints=tuple(ONNX_JOINTS), default_q=desc.nominal_q[index], action_scale=np.full(12, 0.5))
    written = save_replay(tmp_path / f"{name}-blank.npz", blank)  # the optional state fields filled in
    blank = load_replay(written)
    ctrl = get_controller(f"onnx:{model}").make(desc)
    ctrl.reset()
    obs, actions = [], []
    for k in range(ticks):
        state, cmd = blank.state(k), blank.velocity_command(k)
        obs.append(np.concatenate([v for _, v in ctrl.observation_terms(state, cmd)]))
        actions.append((ctrl.act(state, cmd).q[index] - blank.default_q) / 0.5)
    obs = np.asarray(obs)
    if permute is not None:
        obs[:, 6:18] = obs[:, 6:18][:, permute]
    obs[:, 6:18] *= pos_scale
    recorded = dataclasses.replace(blank, obs=obs, actions=np.asarray(actions))
    return model, io, save_replay(tmp_path / f"{name}.npz", recorded)


def test_a_joint_order_not_the_trainers_is_traced_to_the_io_files_joint_list(tmp_path):
    # the trainer's legs FR, FL, RR, RL where the I/O file lists FL, FR, RL, RR (Isaac Lab's order, by joint type)
    swap = [i ^ 1 for i in range(12)]
    model, io, path = _onnx_recording(tmp_path, "order", swap)
    result = check_controller(f"onnx:{model}", CheckConfig(seconds=0.1, replay=path))
    assert {o.check for o in result.failed()} == {"replay"}
    detail = _replay_outcome(result).detail
    trained = ", ".join(f"{leg}_{part}_joint" for part in ("hip", "thigh", "calf") for leg in ("FR", "FL", "RR", "RL"))
    for phrase in ("joint_pos_rel equal the recording with the joints in another order: the recording holds the "
                   f"joints in the order {trained}; the controller's frame in the order FL_hip_joint, FR_hip_joint, ",
                   f"list the network's joints in its training order (an ONNX policy's I/O file: {io} [policy] "
                   "joints)"):
        assert phrase in detail, detail
    assert "[[observation.terms]]" not in detail  # the terms' order, scales and sources are not the fix
    # a joint term that no joint order explains (its scale) keeps the terms' hint, the joint order named first
    model, io, path = _onnx_recording(tmp_path, "scale", None, pos_scale=2.0)
    detail = _replay_outcome(check_controller(f"onnx:{model}", CheckConfig(seconds=0.1, replay=path))).detail
    assert ("Check the joint order (an ONNX policy's I/O file: [policy] joints), then the order, scales and sources "
            "of joint_pos_rel (an ONNX policy's I/O file: [[observation.terms]])") in detail, detail
    assert "in another order" not in detail
