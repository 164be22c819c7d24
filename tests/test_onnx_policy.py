"""ONNX policies (``onnx:PATH``): the I/O file's validation, the observation and joint map, the pi3 round trip.

Small linear networks written with the ``onnx`` package check what the controller feeds and how it reads the output
(terms, scales, history, the network's joint order mapped to the house order, PD gains); the shipped pi3 exported with
torch and run by onnxruntime must act as the numpy controller does.
"""

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest
from fuzz.cases import ONNX_FRAME, ONNX_IO_TEMPLATE, ONNX_JOINTS, onnx_linear_model

from wbc.arena.compare import ArenaConfig, run_arena
from wbc.arena.trial_record import TrialRecord
from wbc.cli.main import main
from wbc.control import CheckConfig, check_controller
from wbc.control.errors import OnnxIoError, OnnxModelError
from wbc.control.onnx_io import load_onnx_io
from wbc.control.registry import get_controller
from wbc.errors import ConfigError
from wbc.learned.policy.shipped import WEIGHTS_DIR
from wbc.robots.registry import get_robot
from wbc.types import RobotState, VelocityCommand

onnx = pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

LEGS = ("FR", "FL", "RR", "RL")


def _io(history: int = 1) -> str:
    return ONNX_IO_TEMPLATE.format(joints=json.dumps(ONNX_JOINTS), history=history)


def _linear_model(path, weight: np.ndarray, bias: np.ndarray | None = None, *, input_name: str = "obs") -> None:
    """An ONNX network ``actions = obs @ weight + bias`` (float32, batch axis of 1) written to `path`."""
    Path(path).write_bytes(onnx_linear_model(weight, bias, input_name=input_name))


def _state(q: np.ndarray, *, gyro=(0.0, 0.0, 0.0), tick: int = 0) -> RobotState:
    n = q.shape[0]
    return RobotState(tick=tick, time=0.02 * tick, q=q, dq=np.zeros(n), tau_est=np.zeros(n),
                      imu_quat=np.array([1.0, 0.0, 0.0, 0.0]), gyro_in_body=np.asarray(gyro, dtype=float),
                      accel_in_body=np.array([0.0, 0.0, 9.81]), foot_force=np.zeros(4))


def _select(history: int, term_start: int) -> np.ndarray:
    """A weight that outputs the last frame's entries term_start .. term_start + 11."""
    w = np.zeros((history * ONNX_FRAME, 12))
    w[(history - 1) * ONNX_FRAME + term_start + np.arange(12), np.arange(12)] = 1.0
    return w


def test_the_network_sees_its_own_joint_order_and_commands_the_house_order(tmp_path):
    model, io = tmp_path / "p.onnx", tmp_path / "p.toml"
    _linear_model(model, _select(1, 6))  # action = joint_pos_rel, in the network's order
    io.write_text(_io())
    spec = get_controller(f"onnx:{model}")
    assert (spec.kind, spec.arm_mode, spec.robots, spec.config_file) == ("onnx", "none", ("a1-wx200",), str(io))
    desc = get_robot("a1-wx200", "none")
    ctrl = spec.make(desc)
    offset = 0.01 * np.arange(1, 13)  # house order
    out = ctrl.act(_state(desc.nominal_q + offset), VelocityCommand())
    # each joint's target moved by half its own offset: the network's order was mapped there and back
    np.testing.assert_allclose(out.q, desc.nominal_q + 0.5 * offset, atol=1e-7)
    kp = {name: 30.0 + 10.0 * ("thigh" in name) + 20.0 * ("calf" in name) for name in desc.joint_names}
    np.testing.assert_array_equal(out.kp, [kp[name] for name in desc.joint_names])
    np.testing.assert_array_equal(out.kd, 1.5)
    assert np.all(out.dq == 0.0) and np.all(out.tau == 0.0) and ctrl.rate_hz == 50.0
    # the previous action is the network's output, in its own order
    np.testing.assert_allclose(ctrl.last_action, offset[[desc.joint_names.index(j) for j in ONNX_JOINTS]], atol=1e-7)


def test_the_history_holds_frames_oldest_first_filled_with_the_first_after_a_reset(tmp_path):
    model, io = tmp_path / "h.onnx", tmp_path / "h.toml"
    _linear_model(model, np.zeros((3 * ONNX_FRAME, 12)))
    io.write_text(_io(history=3))
    ctrl = get_controller(f"onnx:{model}").make(get_robot("a1-wx200", "none"))
    q = get_robot("a1-wx200", "none").nominal_q
    frames = [ctrl.network_input(_state(q, gyro=(g, 0.0, 0.0)), VelocityCommand(vx=0.5))
              for g in (4.0, 8.0)]
    first, second = (f.reshape(3, ONNX_FRAME) for f in frames)
    assert np.all(first[:, 0] == 1.0)  # 4 rad/s x 0.25 in every frame of the filled window
    assert second[:, 0].tolist() == [1.0, 1.0, 2.0]  # oldest first
    assert np.all(second[:, 3] == 1.0)  # vx 0.5 x 2
    ctrl.reset()
    again = ctrl.network_input(_state(q, gyro=(8.0, 0.0, 0.0)), VelocityCommand()).reshape(3, ONNX_FRAME)
    assert np.all(again[:, 0] == 2.0)
    # each term's own history (Isaac Lab), and zeros after a reset
    text = _io().replace('name = "base_ang_vel"', 'name = "base_ang_vel"\nhistory = 2').replace(
        "history = 1", 'history = 1\nhistory_order = "terms"\nhistory_fill = "zeros"')
    io.write_text(text)
    _linear_model(model, np.zeros((ONNX_FRAME + 3, 12)))
    ctrl = get_controller(f"onnx:{model}").make(get_robot("a1-wx200", "none"))
    x = ctrl.network_input(_state(q, gyro=(4.0, 0.0, 0.0)), VelocityCommand())
    assert x.shape == (ONNX_FRAME + 3,) and x[:6].tolist() == [0.0, 0.0, 0.0, 1.0, 0.0, 0.0]


def _estimating_controller(tmp_path, name: str, weight: np.ndarray | None = None):
    """An ONNX controller on a1-wx200 (no arm) whose first term is the estimated base_lin_vel x 2 (by default a
    network that answers zeros)."""
    model, io = tmp_path / f"{name}.onnx", tmp_path / f"{name}.toml"
    _linear_model(model, np.zeros((3 + ONNX_FRAME, 12)) if weight is None else weight)
    first = '[[observation.terms]]\nname = "base_ang_vel"'
    estimated = '[[observation.terms]]\nname = "base_lin_vel"\nsource = "estimator"\nscale = 2.0\n\n'
    io.write_text(_io().replace(first, estimated + first, 1))
    return get_controller(f"onnx:{model}").make(get_robot("a1-wx200", "none"))


def test_an_estimated_base_velocity_follows_the_simulators_truth_in_the_body_frame(tmp_path):
    """The base_lin_vel term is the estimator's velocity, rotated into the body frame, at the policy's rate.

    The pi1 policy walks the robot at 0.5 m/s and turns it; the ONNX controller reads the same states. Measured: rms
    error 0.013, 0.015 and 0.066 m/s along x, y and z over seconds 1-5 (the estimator runs at 50 Hz, the policy's
    rate).
    """
    from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
    from wbc.robots.conventions import quat_to_matrix

    onnx_ctrl = _estimating_controller(tmp_path, "v")
    walker = get_controller("learned-noarm").make(get_robot("a1-wx200", "none"))
    sim = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none"))
    period = 1.0 / onnx_ctrl.rate_hz
    estimated, true = [], []
    with sim:
        sim.reset(seed=3)
        for episode in range(2):  # the second, on the walking robot, checks reset
            onnx_ctrl.reset()
            walker.reset()
            estimated, true = [], []
            for k in range(int(5.0 / period)):
                state = sim.read()
                command = VelocityCommand(vx=0.5, yaw_rate=0.5 if k * period > 3.0 else 0.0)
                x = onnx_ctrl.network_input(state, command)
                truth = sim.base_truth()
                estimated.append(x[:3] / 2.0)
                true.append(quat_to_matrix(truth.base_quat).T @ truth.base_linvel_in_world)
                sim.write(walker.act(state, command))
                sim.advance(period)
                assert not sim.fallen()
            if episode == 1:  # reset started the estimate over at rest: one update in, it lags the walk far
                assert estimated[0][0] < true[0][0] - 0.2
    estimated, true = np.array(estimated)[50:], np.array(true)[50:]
    assert true[:, 0].mean() > 0.3  # the robot walks: a zero estimate would fail below
    rms = np.sqrt(((estimated - true) ** 2).mean(axis=0))
    assert rms[0] < 0.08 and rms[1] < 0.08 and rms[2] < 0.15, rms


def test_asking_for_the_observation_before_acting_folds_the_state_into_the_estimate_once(tmp_path):
    """A replay asks for a state's observation terms, then acts on it: the network sees what act alone gives it."""
    from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig

    asked, plain = _estimating_controller(tmp_path, "a"), _estimating_controller(tmp_path, "b")
    walker = get_controller("learned-noarm").make(get_robot("a1-wx200", "none"))
    sim = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none"))
    command = VelocityCommand(vx=0.5)
    with sim:
        sim.reset(seed=0)
        for ctrl in (asked, plain, walker):
            ctrl.reset()
        for _ in range(60):
            state = sim.read()
            terms = dict(asked.observation_terms(state, command))
            x_asked, x_plain = asked.network_input(state, command), plain.network_input(state, command)
            np.testing.assert_array_equal(x_asked, x_plain)
            np.testing.assert_array_equal(terms["base_lin_vel"], x_plain[:3])
            sim.write(walker.act(state, command))
            sim.advance(1.0 / walker.rate_hz)
    assert np.abs(x_plain[:3]).max() > 0.1  # it moved: the frames compared were not all zero


@pytest.mark.parametrize("recorded_scale", [2.0, 4.0, -2.0], ids=["the I/O file's scale", "twice it", "flipped"])
def test_a_replay_feeds_an_estimated_term_the_recorded_truth_and_checks_the_rest_of_the_policy_exactly(
        tmp_path, recorded_scale):
    """A trainer records the simulator's truth where the controller estimates: the replay check feeds the network the
    recorded values, compares every other term and the actions as usual, and reports how far the estimate lay. A
    recording at another scale or sign than the I/O file's (2) fails: the feeding would otherwise hide it."""
    from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
    from wbc.learned.policy.replay_file import Replay, save_replay
    from wbc.robots.conventions import quat_to_matrix

    rng = np.random.default_rng(5)
    trainer = _estimating_controller(tmp_path, "r", weight=0.05 * rng.standard_normal((3 + ONNX_FRAME, 12)))
    walker = get_controller("learned-noarm").make(get_robot("a1-wx200", "none"))
    sim = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none"))
    fields = ("tick", "time", "q", "dq", "tau_est", "imu_quat", "gyro_in_body", "accel_in_body", "foot_force")
    states, commands, frames, actions = {f: [] for f in fields}, [], [], []
    with sim:
        sim.reset(seed=2)
        trainer.reset()
        walker.reset()
        for k in range(60):
            state, command = sim.read(), VelocityCommand(vx=0.5, yaw_rate=0.3 * (k > 30))
            truth = sim.base_truth()
            true_velocity = recorded_scale * quat_to_matrix(truth.base_quat).T @ truth.base_linvel_in_world
            terms = trainer.observation_terms(state, command)
            frames.append(np.concatenate([true_velocity] + [v for _, v in terms[1:]]))
            trainer.feed_recorded({0: true_velocity})  # the trainer's network saw the truth
            trainer.act(state, command)
            actions.append(trainer.last_action.copy())
            for f in fields:
                states[f].append(np.copy(getattr(state, f)))
            commands.append(command.as_array())
            sim.write(walker.act(state, command))
            sim.advance(1.0 / walker.rate_hz)
    names = ("base_lin_vel", "base_ang_vel", "velocity_commands", "joint_pos_rel", "last_action")
    sizes = (3, 3, 3, 12, 12)
    ends = np.cumsum(sizes)
    path = save_replay(tmp_path / "r.replay.npz", Replay(
        path="", robot="a1-wx200", arm_mode="none", rate_hz=50.0, source="a trainer's rollout",
        states={f: np.asarray(v) for f, v in states.items()}, command=np.asarray(commands), obs=np.asarray(frames),
        obs_terms=names, obs_slices=tuple((int(e - n), int(e)) for e, n in zip(ends, sizes, strict=True)),
        actions=np.asarray(actions), action_joints=tuple(ONNX_JOINTS), default_q=trainer.default_q,
        action_scale=trainer.action_scale))
    result = check_controller(f"onnx:{tmp_path / 'r.onnx'}", CheckConfig(seconds=0.1, robots=("a1-wx200",),
                                                                          replay=path))
    (outcome,) = [o for o in result.outcomes if o.check == "replay"]
    if recorded_scale != 2.0:
        gain = float(outcome.detail.split("estimate at ")[1].split(" times")[0])
        assert not outcome.passed and gain == pytest.approx(recorded_scale / 2.0, rel=0.2), outcome.detail
        assert ("the term's scale or sign in the I/O file" if recorded_scale < 0 else
                "the term's scale in the I/O file") in outcome.detail
        return
    assert outcome.passed, outcome.detail
    assert "(base_ang_vel, velocity_commands, joint_pos_rel, last_action; max |difference|" in outcome.detail
    assert "base_lin_vel is estimated by the controller, and the network was fed the recorded values" in outcome.detail
    spread = float(outcome.detail.split("lies rms ")[1].split(",")[0])
    assert 0.0 < spread < 0.2  # the estimate, in the network's units (x 2), from the recorded states


def test_recorded_values_are_refused_for_a_measured_term_or_of_the_wrong_size(tmp_path):
    ctrl = _estimating_controller(tmp_path, "f")
    assert ctrl.estimated_terms == ("base_lin_vel",)
    with pytest.raises(ConfigError, match=r"term 1 is not an estimated term; the estimated ones: \[0\]"):
        ctrl.feed_recorded({1: np.zeros(3)})
    with pytest.raises(ConfigError, match=r"term 0 \(base_lin_vel\) has 3 entries, the values fed to it 2"):
        ctrl.feed_recorded({0: np.zeros(2)})
    q = get_robot("a1-wx200", "none").nominal_q
    ctrl.feed_recorded({0: np.array([1.0, 2.0, 3.0])})
    assert ctrl.network_input(_state(q), VelocityCommand())[:3].tolist() == [1.0, 2.0, 3.0]
    assert ctrl.network_input(_state(q, tick=1), VelocityCommand())[:3].tolist() != [1.0, 2.0, 3.0]  # one act only


IO_ERRORS = [
    ('name = "last_action"', 'name = "height"', "[[observation.terms]] #4 name",
     "unknown term 'height'; valid terms: base_lin_vel, base_ang_vel, projected_gravity, velocity_commands"),
    ('name = "last_action"', 'name = "joint_vel_rel"', "[[observation.terms]] #4 name",
     "unknown term 'joint_vel_rel': Isaac Lab's joint_vel_rel is our joint_vel (the same, with a zero default "
     'velocity); write name = "joint_vel"; valid terms: base_lin_vel, '),
    ('name = "base_ang_vel"', 'name = "base_lin_vel"', "[[observation.terms]] #1 name",
     "does not measure its base's linear velocity (RobotState has the IMU and the joint encoders only); add source = "
     '"estimator" to this term'),
    ('name = "base_ang_vel"', 'name = "base_lin_vel"\nsource = "mocap"', "[[observation.terms]] #1 source",
     "must be one of 'estimator', got 'mocap'"),
    ('name = "base_ang_vel"', 'name = "base_ang_vel"\nsource = "estimator"', "[[observation.terms]] #1 source",
     "'base_ang_vel' is measured by the robot; only base_lin_vel takes a source"),
    ('name = "base_ang_vel"', 'name = "base_lin_vel"\nsource = "estimator"\ncontact_force = 0',
     "[[observation.terms]] #1 contact_force", "must be > 0, got 0"),
    ('name = "last_action"', 'name = "base_lin_vel"\nsource = "estimator"\ncontact_force = 20.0\n\n'
     '[[observation.terms]]\nname = "base_lin_vel"\nsource = "estimator"', "[[observation.terms]] #5 contact_force",
     "15, where an earlier estimated term has 20: the terms share one estimator"),
    ('"RR_calf_joint"]', '"RR_thigh_joint"]', "[policy] joints", "listed more than once"),
    ('"FL_hip_joint", ', "", "[policy] joints", "missing: FL_hip_joint"),
    ('"FL_hip_joint", ', '"arm_waist", "FL_hip_joint", ', "[policy] joints", "'arm_waist' not a joint of a1-wx200"),
    ("scale = [2.0, 2.0, 0.25]", "scale = [2.0, 2.0]", "[[observation.terms]] #2 scale",
     "expected one number or 1 or 3 numbers"),
    ('kind = "joint_position"', 'kind = "torque"', "[action] kind", "must be one of 'joint_position'"),
    ('scale = 0.25\n', 'scale = 0.25\nhistory = 3\n', "[[observation.terms]] #1 history",
     'needs history_order = "terms"'),
    ("kd = 1.5", "kd = -1.5", "[pd] kd", "must be in [0, 100]"),
    ("kd = 1.5", "kd = nan", "[pd] kd", "must be in [0, 100] and finite, got nan"),
    ("scale = [2.0, 2.0, 0.25]", "scale = [2.0, nan, 0.25]", "[[observation.terms]] #2 scale",
     "must be finite, got nan at position 2"),
    ("[pd]", "[gains]", "[gains]", "unknown table; valid tables: [policy], [onnx], [observation], [action], [pd]"),
    ('arm_mode = "none"', 'arm_mode = "folded"', "[policy] arm_mode", "must be one of 'none', 'locked', 'actuated'"),
]


@pytest.mark.parametrize(("old", "new", "field", "reason"), IO_ERRORS, ids=[e[2] + " " + e[1][:12] for e in IO_ERRORS])
def test_a_bad_io_file_names_its_line_field_and_what_is_valid(tmp_path, old, new, field, reason):
    text = _io()
    assert old in text
    bad = text.replace(old, new, 1)
    path = tmp_path / "bad.toml"
    path.write_text(bad)
    with pytest.raises(OnnxIoError) as caught:
        load_onnx_io(path)
    err = caught.value
    assert err.field == field and reason in err.reason and err.path == str(path)
    # the line is the offending key's (or its table's header)
    line = bad.splitlines()[err.line - 1]
    key = field.split()[-1]
    assert (key in line) or line.startswith("[")


def test_a_term_listed_twice_is_refused_even_where_the_model_takes_that_many_inputs(tmp_path):
    # joint_pos_rel in place of last_action: the same 30 inputs, so only the duplicate can tell the file is wrong
    model, io = tmp_path / "m.onnx", tmp_path / "m.toml"
    bad = _io().replace('name = "last_action"', 'name = "joint_pos_rel"')
    io.write_text(bad)
    _linear_model(model, np.zeros((ONNX_FRAME, 12)))
    with pytest.raises(OnnxIoError) as caught:
        get_controller(f"onnx:{model}")
    err = caught.value
    assert err.field == "[[observation.terms]] #4 name"
    assert "term 'joint_pos_rel' is listed twice (terms #3 and #4); list each term once" in err.reason
    assert bad.splitlines()[err.line - 1] == 'name = "joint_pos_rel"'
    assert str(err).startswith(f"{io}:{err.line}: [[observation.terms]] #4 name: ")


def test_a_model_that_does_not_fit_its_io_file_is_refused_before_any_trial(tmp_path, capsys):
    model, io = tmp_path / "m.onnx", tmp_path / "m.toml"
    io.write_text(_io())
    _linear_model(model, np.zeros((ONNX_FRAME + 1, 12)))
    with pytest.raises(OnnxModelError, match=r"the terms make 30 inputs .* takes 31"):
        get_controller(f"onnx:{model}")
    _linear_model(model, np.zeros((ONNX_FRAME, 13)))
    with pytest.raises(OnnxModelError, match=r"12 joints listed, but .* has 13 entries"):
        get_controller(f"onnx:{model}")
    _linear_model(model, np.zeros((ONNX_FRAME, 12)), input_name="observations")
    io.write_text(_io().replace("[observation]", '[onnx]\ninput = "obs"\n\n[observation]'))
    with pytest.raises(OnnxModelError, match=r"has no input 'obs'; its inputs: observations"):
        get_controller(f"onnx:{model}")
    # on the command line: no traceback, the file and field named; a missing I/O file says where it was looked for
    assert main(["run", f"onnx:{model}", "--scenario", "scenarios/push.toml", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "[onnx] input" in err and "Traceback" not in err
    io.unlink()
    assert main(["run", f"onnx:{model}", "--scenario", "scenarios/push.toml", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{io}: file not found; an onnx:PATH policy needs its I/O file beside it" in err
    # the recipe is where the message says (the README links to the guide, which holds it)
    guide = Path("docs/guides/own-controller.md")
    assert f"an example and a recipe for each trainer: {guide}, 'A policy from another trainer'" in err
    assert "## A policy from another trainer" in guide.read_text() and "README" not in err
    # --io names another file; it goes only to an onnx: policy
    other = tmp_path / "elsewhere.toml"
    other.write_text(_io())
    _linear_model(model, np.zeros((ONNX_FRAME, 12)))
    assert get_controller(f"onnx:{model}", io=other).config_file == str(other)
    assert main(["run", "stand", "--scenario", "scenarios/push.toml", "--io", str(other)]) == 2
    assert "no controller here is an onnx:PATH policy" in capsys.readouterr().err


def _two_outputs(path: Path, value_size: int, actions_size: int = 12, *, symbolic: bool = False) -> None:
    """A network of two outputs, ``value`` first and ``actions`` second, of the sizes given; with `symbolic`, their
    last axes are named, not sized (the sizes are known only once the network runs)."""
    from onnx import TensorProto, helper, numpy_helper

    def out(name, size):
        return helper.make_tensor_value_info(name, TensorProto.FLOAT, [1, f"{name}_size" if symbolic else size])

    graph = helper.make_graph(
        [helper.make_node("MatMul", ["obs", "w"], ["actions"]), helper.make_node("MatMul", ["obs", "v"], ["value"])],
        "two_outputs", [helper.make_tensor_value_info("obs", TensorProto.FLOAT, [1, ONNX_FRAME])],
        [out("value", value_size), out("actions", actions_size)],
        [numpy_helper.from_array(np.zeros((ONNX_FRAME, actions_size), np.float32), "w"),
         numpy_helper.from_array(np.zeros((ONNX_FRAME, value_size), np.float32), "v")])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    path.write_bytes(model.SerializeToString())


@pytest.mark.parametrize("symbolic", [False, True], ids=["sized", "sized-at-run-time"])
def test_a_model_of_several_outputs_none_named_lists_them_and_says_which_to_name(tmp_path, symbolic):
    model, io = tmp_path / "m.onnx", tmp_path / "m.toml"
    io.write_text(_io())
    desc = get_robot("a1-wx200", "none")
    _two_outputs(model, 1, symbolic=symbolic)  # a value head first, as an actor-critic export may write
    with pytest.raises(OnnxModelError) as caught:
        get_controller(f"onnx:{model}")
    assert str(caught.value) == (
        f"{io}: [onnx] output: not set, and {model} has 2 outputs: 'value' (1 entry), 'actions' (12 entries); the "
        "first, 'value', read by default, is not one action per joint (12): set [onnx] output = \"actions\" (the "
        "output with 12 entries)")
    # no output has one entry per joint: NAME stands for the one that holds the actions
    _two_outputs(model, 1, 13, symbolic=symbolic)
    with pytest.raises(OnnxModelError, match=r"'value' \(1 entry\), 'actions' \(13 entries\); .*: set \[onnx\] "
                       r'output = "NAME", the output that holds the actions \(none has 12 entries\)$'):
        get_controller(f"onnx:{model}")
    # the first output fits: it is read, as the I/O file's default promises
    _two_outputs(model, 12, symbolic=symbolic)
    assert get_controller(f"onnx:{model}").make(desc).ports.output_name == "value"
    # named, the actions' output is read
    _two_outputs(model, 1, symbolic=symbolic)
    io.write_text(_io().replace("[observation]", '[onnx]\noutput = "actions"\n\n[observation]'))
    assert get_controller(f"onnx:{model}").make(desc).ports.output_name == "actions"


def test_a_float64_model_with_an_operator_onnxruntime_lacks_in_double_is_named_valid_and_asked_in_float32(tmp_path):
    import onnxruntime as ort
    from onnx import TensorProto, helper, numpy_helper

    model, io = tmp_path / "f64.onnx", tmp_path / "f64.toml"
    io.write_text(_io())
    graph = helper.make_graph(
        [helper.make_node("MatMul", ["obs", "w"], ["y"]), helper.make_node("Elu", ["y"], ["actions"], name="act")],
        "f64", [helper.make_tensor_value_info("obs", TensorProto.DOUBLE, [1, ONNX_FRAME])],
        [helper.make_tensor_value_info("actions", TensorProto.DOUBLE, [1, 12])],
        [numpy_helper.from_array(np.zeros((ONNX_FRAME, 12)), "w")])
    proto = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    proto.ir_version = 8
    onnx.checker.check_model(proto)  # a valid model
    model.write_bytes(proto.SerializeToString())
    try:
        ort.InferenceSession(str(model), providers=["CPUExecutionProvider"])
        pytest.skip(f"onnxruntime {ort.__version__} runs Elu in double")
    except ort.capi.onnxruntime_pybind11_state.NotImplemented:
        pass
    with pytest.raises(OnnxModelError) as caught:
        get_controller(f"onnx:{model}")
    text = str(caught.value)
    assert text.startswith(f"{model}: a valid ONNX model that onnxruntime ")
    assert "has no implementation of its Elu operator (version 6, node 'act')" in text
    assert text.endswith("export the network in float32 (torch: model.float() and a float32 example input)")
    assert "damaged" not in text and "export it again" not in text


def _graph_model(path: Path, inputs, outputs, nodes, weights) -> None:
    """An ONNX model of float tensors: `inputs` and `outputs` as (name, shape, element type), `weights` by name."""
    from onnx import helper, numpy_helper

    graph = helper.make_graph(nodes, "graph", [helper.make_tensor_value_info(*i) for i in inputs],
                              [helper.make_tensor_value_info(*o) for o in outputs],
                              [numpy_helper.from_array(w, name) for name, w in weights.items()])
    proto = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    proto.ir_version = 8
    path.write_bytes(proto.SerializeToString())


def test_a_recurrent_model_is_refused_as_unsupported_and_pointed_to_observation_history(tmp_path):
    from onnx import TensorProto, helper

    model, io = tmp_path / "gru.onnx", tmp_path / "gru.toml"
    io.write_text(_io())
    f = TensorProto.FLOAT
    nodes = [helper.make_node("MatMul", ["obs", "w"], ["actions"]),
             helper.make_node("MatMul", ["h_in", "u"], ["h_out"])]
    weights = {"w": np.zeros((ONNX_FRAME, 12), np.float32), "u": np.eye(16, dtype=np.float32)}
    _graph_model(model, [("obs", f, [1, ONNX_FRAME]), ("h_in", f, [1, 16])],
                 [("actions", f, [1, 12]), ("h_out", f, [1, 16])], nodes, weights)
    with pytest.raises(OnnxModelError) as caught:
        get_controller(f"onnx:{model}")
    text = str(caught.value)
    for phrase in ("input 'h_in' and output 'h_out' carry a state from one call to the next",
                   "recurrent policies are not supported", f"observation history instead (history, or a term's own "
                   f"history, in {io} [observation])"):
        assert phrase in text, text
    assert "export the network with the observation as its only input" not in text  # impossible for a GRU
    # with the observation named, too
    io.write_text(_io().replace("[observation]", '[onnx]\ninput = "obs"\noutput = "actions"\n\n[observation]'))
    with pytest.raises(OnnxModelError, match=r"input 'h_in' and output 'h_out' carry a state .* not supported"):
        get_controller(f"onnx:{model}")
    # an input with no state output beside it is an input left unfed, as before
    _graph_model(model, [("obs", f, [1, ONNX_FRAME]), ("h_in", f, [1, 16])], [("actions", f, [1, 12])], nodes[:1],
                 weights)
    with pytest.raises(OnnxModelError, match=r"input 'h_in' .* would be left unfed; .* as its only input$"):
        get_controller(f"onnx:{model}")


def test_a_float16_model_is_asked_in_float32(tmp_path):
    from onnx import TensorProto, helper

    model, io = tmp_path / "f16.onnx", tmp_path / "f16.toml"
    io.write_text(_io())
    h = TensorProto.FLOAT16
    _graph_model(model, [("obs", h, [1, ONNX_FRAME])], [("actions", h, [1, 12])],
                 [helper.make_node("MatMul", ["obs", "w"], ["actions"])], {"w": np.zeros((ONNX_FRAME, 12), np.float16)})
    with pytest.raises(OnnxModelError) as caught:
        get_controller(f"onnx:{model}")
    assert str(caught.value) == (f"{model}: input 'obs' is a tensor(float16); the controller feeds tensor(float) or "
                                 "tensor(double): export the network in float32 (torch: model.float() and a float32 "
                                 "example input)")


def _sqrt_model(path: Path, weight: np.ndarray, bias: np.ndarray) -> None:
    """An ONNX network ``actions = sqrt(obs @ weight + bias)``: NaN where the sum is negative."""
    from onnx import TensorProto, helper, numpy_helper

    graph = helper.make_graph(
        [helper.make_node("MatMul", ["obs", "w"], ["y"]), helper.make_node("Add", ["y", "b"], ["z"]),
         helper.make_node("Sqrt", ["z"], ["actions"])],
        "sqrt", [helper.make_tensor_value_info("obs", TensorProto.FLOAT, [1, weight.shape[0]])],
        [helper.make_tensor_value_info("actions", TensorProto.FLOAT, [1, weight.shape[1]])],
        [numpy_helper.from_array(weight.astype(np.float32), "w"),
         numpy_helper.from_array(bias.astype(np.float32), "b")])
    proto = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    proto.ir_version = 8
    path.write_bytes(proto.SerializeToString())


def test_a_network_that_returns_nan_mid_trial_is_named_with_its_outputs_and_the_step(tmp_path):
    model, io = tmp_path / "n.onnx", tmp_path / "n.toml"
    io.write_text(_io())
    weight = np.zeros((ONNX_FRAME, 12))
    weight[3, 1] = -10.0  # the network's entry 1 is sqrt(1 - 10 x the scaled vx): NaN from vx > 0.05 m/s
    _sqrt_model(model, weight, np.ones(12))
    desc = get_robot("a1-wx200", "none")
    ctrl = get_controller(f"onnx:{model}").make(desc)  # the zero observation passes the check before any trial
    ctrl.reset()
    for _ in range(2):
        ctrl.act(_state(desc.nominal_q), VelocityCommand())
    said = (f"{model}: the network returned non-finite actions at step 2 after reset (t = 0.040 s at 50 Hz): output "
            f"'actions' entry 1 ({ONNX_JOINTS[1]}) nan (1 of 12, in the network's joint order, {io} [policy] joints); "
            "its input was finite, so they arose inside the network")
    with pytest.raises(OnnxModelError) as caught:
        ctrl.act(_state(desc.nominal_q), VelocityCommand(vx=0.3))
    assert str(caught.value).startswith(said)
    ctrl.reset()  # the step counts from the reset
    with pytest.raises(OnnxModelError, match=r"at step 0 after reset \(t = 0\.000 s"):
        ctrl.act(_state(desc.nominal_q), VelocityCommand(vx=0.3))
    # the contract checker names the network's failure, at the closed loop's tick (the command ramps up from 0)
    result = check_controller(f"onnx:{model}", CheckConfig(seconds=0.5))
    (output,) = result.failed("output")
    assert output.detail.startswith(f"act raised OnnxModelError: {model}: the network returned non-finite actions "
                                    "at step 4 after reset (t = 0.080 s at 50 Hz): output 'actions' entry 1")
    # no place in wbc's code is named: the model is the user's, and the message names it
    assert output.detail.endswith("or a value beyond its float range) at tick 4")


def test_a_network_that_answers_the_zero_observation_with_nan_says_what_was_seen_and_the_likely_causes(tmp_path):
    model, io = tmp_path / "z.onnx", tmp_path / "z.toml"
    io.write_text(_io())
    _sqrt_model(model, np.zeros((ONNX_FRAME, 12)), np.r_[-1.0, np.ones(11)])
    with pytest.raises(OnnxModelError) as caught:
        get_controller(f"onnx:{model}")
    text = str(caught.value)
    assert text.startswith(f"{model}: the network answers the zero observation (30 zeros, all finite) with "
                           f"non-finite actions: output 'actions' entry 0 ({ONNX_JOINTS[0]}) nan (1 of 12, in the "
                           f"network's joint order, {io} [policy] joints). A finite input gave them")
    assert "likely causes: weights or normalisation statistics that hold NaN" in text
    assert "an operation undefined at this input" in text
    assert "damaged: export it again" not in text


def test_the_shipped_pi3_exported_to_onnx_acts_and_plays_as_the_numpy_controller(tmp_path):
    pytest.importorskip("torch")
    from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
    from wbc.learned.policy.controller import LearnedController
    from wbc.learned.train.onnx_export import export_onnx
    from wbc.scenario import Push, TerrainConfig

    model, io = export_onnx(WEIGHTS_DIR / "a1-wx200-actuated", tmp_path / "pi3")
    # the I/O file records the model's sha256, which onnx:PATH verifies (tests/test_policy_files.py)
    assert f'sha256 = "{hashlib.sha256(model.read_bytes()).hexdigest()}"' in io.read_text()
    name = f"onnx:{model}"
    spec = get_controller(name)
    assert (spec.arm_mode, spec.robots) == ("actuated", ("a1-wx200",)) and "stage 3" in spec.summary
    # actions: the ONNX controller shadows the numpy one along its own closed loop, pushed, on rough ground
    robot = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated",
                                          terrain=TerrainConfig(kind="fractal", amplitude=0.04)))
    with robot:
        robot.reset(seed=3)
        robot.apply_push(Push.horizontal(300.0, math.pi / 2, (0.05, 0.0, 0.0), start=1.0, duration=0.06))
        numpy_ctrl, onnx_ctrl = LearnedController(robot.desc), spec.make(robot.desc)
        numpy_ctrl.reset()
        onnx_ctrl.reset()
        worst = 0.0
        for k in range(150):  # 3 s at 50 Hz
            state, cmd = robot.read(), VelocityCommand(vx=0.3 if k > 25 else 0.0)
            out = numpy_ctrl.act(state, cmd)
            shadow = onnx_ctrl.act(state, cmd)
            worst = max(worst, float(np.abs(numpy_ctrl.last_action - onnx_ctrl.last_action).max()))
            np.testing.assert_allclose(shadow.q, out.q, atol=0.25e-5)
            np.testing.assert_array_equal(shadow.kp, out.kp)
            np.testing.assert_array_equal(shadow.kd, out.kd)
            robot.write(out)
            robot.advance(0.02)
        assert not robot.fallen()
    assert worst < 1e-5
    # it meets the controller contract: deterministic after reset, blind to the simulator, fast enough; and it
    # observes and acts as the policy it was exported from did in the rollout the export recorded beside it
    replay = model.with_name("pi3.replay.npz")
    assert replay.is_file()
    result = check_controller(spec, CheckConfig(seconds=0.3, replay=replay))
    result.raise_if_failed()
    assert [o.check for o in result.outcomes][-1] == "replay"
    # a trial in the arena: the same outcome, the metrics equal to float32 arithmetic's reach (see the README; push
    # version 1's trial, on which that reach was measured)
    cfg = ArenaConfig(controllers=("learned", name), scenario=Path("scenarios/push-v1.toml"), bands=("ood",),
                      seeds=(0,), trials=1, out_dir=tmp_path / "arena", progress=False, workers=1)
    records = {r.controller: r for r in TrialRecord.read_csv(run_arena(cfg).out_dir / "trials.csv")}
    a, b = records["learned"], records[name]
    assert (a.success, a.ttf, a.n_pushes, a.push_force_n) == (b.success, b.ttf, b.n_pushes, b.push_force_n)
    assert math.isnan(a.fall_time_s) == math.isnan(b.fall_time_s)
    for metric in ("vlin_err", "vang_err", "max_roll_deg", "max_pitch_deg", "energy_j", "arm_travel_rad"):
        assert b[metric] == pytest.approx(a[metric], rel=1e-2), metric


# -- weights in an external data file (torch's default exporter writes model.onnx + model.onnx.data) ------------------
def _external(path: Path, weight: np.ndarray) -> Path:
    """`_linear_model`, its weights saved to ``<path>.data`` beside it; returns the data file."""
    _linear_model(path, weight)
    model = onnx.load(str(path))
    data = path.with_name(path.name + ".data")
    onnx.save_model(model, str(path), save_as_external_data=True, all_tensors_to_one_file=True, location=data.name,
                    size_threshold=0)
    return data


def test_a_model_with_external_data_runs_records_both_hashes_and_refuses_a_missing_data_file(tmp_path, capsys):
    from wbc.control.onnx_policy import external_data_files

    model, io = tmp_path / "ext.onnx", tmp_path / "ext.toml"
    data = _external(model, _select(1, 6))  # action = joint_pos_rel, as in the first test
    io.write_text(_io())
    assert data.is_file() and external_data_files(model) == [data.name]
    assert model.stat().st_size < data.stat().st_size  # the weights are in the data file, not in the model
    spec = get_controller(f"onnx:{model}")
    desc = get_robot("a1-wx200", "none")
    offset = 0.01 * np.arange(1, 13)
    out = spec.make(desc).act(_state(desc.nominal_q + offset), VelocityCommand())
    np.testing.assert_allclose(out.q, desc.nominal_q + 0.5 * offset, atol=1e-7)  # the weights were read
    # provenance: the model, its external data and the I/O file, each with its sha256
    files = {f["role"]: f for f in spec.provenance()["files"]}
    assert set(files) == {"model", "external data", "io"}
    for role, path in (("model", model), ("external data", data), ("io", io)):
        assert files[role]["path"] == str(path.resolve())
        assert files[role]["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    # one byte of the data file changed: its hash changes, the model's does not
    raw = bytearray(data.read_bytes())
    raw[-1] ^= 0x01
    data.write_bytes(bytes(raw))
    again = {f["role"]: f["sha256"] for f in get_controller(f"onnx:{model}").provenance()["files"]}
    assert again["external data"] != files["external data"]["sha256"]
    assert again["model"] == files["model"]["sha256"] and again["io"] == files["io"]["sha256"]
    # named through a symbolic link elsewhere, the data is still found beside the real model
    elsewhere = tmp_path / "links"
    elsewhere.mkdir()
    (elsewhere / "linked.onnx").symlink_to(model)
    (elsewhere / "linked.toml").write_text(_io())
    get_controller(f"onnx:{elsewhere / 'linked.onnx'}").make(desc)
    # a model whose data file lies outside its directory (onnxruntime refuses it): said in those words
    outside = onnx.load(str(model), load_external_data=False)
    for tensor in outside.graph.initializer:
        next(e for e in tensor.external_data if e.key == "location").value = "../ext.onnx.data"
    (tmp_path / "sub").mkdir()
    onnx.save(outside, str(tmp_path / "sub" / "ext.onnx"))
    (tmp_path / "sub" / "ext.toml").write_text(_io())
    with pytest.raises(OnnxModelError, match=r"'../ext.onnx.data', outside its directory"):
        get_controller(f"onnx:{tmp_path / 'sub' / 'ext.onnx'}")
    # the data file gone: refused before onnxruntime is asked, naming the model, the file and the two fixes
    data.unlink()
    with pytest.raises(OnnxModelError) as caught:
        get_controller(f"onnx:{model}")
    text = str(caught.value)
    assert str(model) in text and "ext.onnx.data" in text and "does not exist" in text
    assert "beside ext.onnx" in text and "external_data=False" in text
    assert main(["check-controller", f"onnx:{model}"]) == 2
    err = capsys.readouterr().err
    assert "ext.onnx.data" in err and "Traceback" not in err


def test_recorded_checksums_cover_the_weights_in_external_data(tmp_path):
    model, io = tmp_path / "ext.onnx", tmp_path / "ext.toml"
    data = _external(model, _select(1, 6))
    model_sha, data_sha = (hashlib.sha256(p.read_bytes()).hexdigest() for p in (model, data))
    signed = _io().replace("[observation]", f'[onnx]\nsha256 = "{model_sha}"\n'
                                            f'external_data_sha256 = {{ "ext.onnx.data" = "{data_sha}" }}\n\n'
                                            "[observation]")
    io.write_text(signed)
    get_controller(f"onnx:{model}").make(get_robot("a1-wx200", "none"))
    # the model's own sha256 alone: its weights would run unchecked; the message gives the line to record
    io.write_text(signed.replace(f'external_data_sha256 = {{ "ext.onnx.data" = "{data_sha}" }}\n', ""))
    with pytest.raises(OnnxModelError, match="whose sha256 is not recorded") as caught:
        get_controller(f"onnx:{model}")
    assert f'external_data_sha256 = {{ "ext.onnx.data" = "{data_sha}" }}' in str(caught.value)
    # a file the model does not use: another export's I/O file
    io.write_text(signed.replace('"ext.onnx.data" =', f'"ext.onnx.data" = "{data_sha}", "old.data" ='))
    with pytest.raises(OnnxModelError, match=r"names old.data, which .* does not use \(it uses ext.onnx.data\)"):
        get_controller(f"onnx:{model}")
    # the checksums without the model's own, or not a table of digests: the I/O file is refused, naming the key
    io.write_text(signed.replace(f'sha256 = "{model_sha}"\n', "", 1))
    with pytest.raises(OnnxIoError, match=r"\[onnx\] external_data_sha256: .*add \[onnx\] sha256"):
        get_controller(f"onnx:{model}")
    io.write_text(signed.replace(f'"{data_sha}" }}', '"abc" }'))
    with pytest.raises(OnnxIoError, match=r"'ext.onnx.data': expected 64 lowercase hex digits"):
        get_controller(f"onnx:{model}")
    # one bit of the weights flipped: refused before onnxruntime reads them
    io.write_text(signed)
    raw = bytearray(data.read_bytes())
    raw[-1] ^= 0x01
    data.write_bytes(bytes(raw))
    with pytest.raises(OnnxModelError, match=f"its external data file ext.onnx.data has sha256 .*, not {data_sha}"):
        get_controller(f"onnx:{model}")


def test_the_external_data_reader_agrees_with_the_onnx_package(tmp_path):
    from onnx.external_data_helper import _get_all_tensors, uses_external_data

    from wbc.control.onnx_policy import external_data_files

    inline, split = tmp_path / "inline.onnx", tmp_path / "split.onnx"
    _linear_model(inline, np.ones((ONNX_FRAME, 12)))
    assert external_data_files(inline) == []
    _linear_model(split, np.ones((ONNX_FRAME, 12)))
    model = onnx.load(str(split))
    # one tensor per file: every file is listed, once, in the order the tensors come
    onnx.save_model(model, str(split), save_as_external_data=True, all_tensors_to_one_file=False, size_threshold=0)
    loaded = onnx.load(str(split), load_external_data=False)
    expected = [next(e.value for e in t.external_data if e.key == "location") for t in _get_all_tensors(loaded)
                if uses_external_data(t)]
    assert len(expected) == 2 and external_data_files(split) == expected
    garbage = tmp_path / "garbage.onnx"
    garbage.write_bytes(b"\xff" * 64)
    with pytest.raises(OnnxModelError, match="not an ONNX model"):
        external_data_files(garbage)


def test_torchs_default_exporter_output_runs_as_onnx(tmp_path):
    torch = pytest.importorskip("torch")
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Linear(ONNX_FRAME, 16), torch.nn.ELU(), torch.nn.Linear(16, 12)).eval()
    model = tmp_path / "torch.onnx"
    # torch >= 2.9's default (dynamo) exporter, external data as it writes it by default
    torch.onnx.export(net, (torch.zeros(1, ONNX_FRAME),), str(model), input_names=["obs"], output_names=["actions"],
                      external_data=True, verbose=False)
    (tmp_path / "torch.toml").write_text(_io())
    assert (tmp_path / "torch.onnx.data").is_file()  # what failed before: the weights beside the model
    desc = get_robot("a1-wx200", "none")
    ctrl = get_controller(f"onnx:{model}").make(desc)
    x = ctrl.network_input(_state(desc.nominal_q + 0.01), VelocityCommand(vx=0.4))
    with torch.no_grad():
        expected = net(torch.as_tensor(x, dtype=torch.float32)[None]).numpy()[0]
    ctrl.reset()
    ctrl.act(_state(desc.nominal_q + 0.01), VelocityCommand(vx=0.4))
    np.testing.assert_allclose(ctrl.last_action, expected, atol=1e-5)
