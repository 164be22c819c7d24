"""Policy files (``policy:PATH``) and ONNX policies (``onnx:PATH``) refuse bad input with one clear line.

Each case is a finding of the input fuzz campaign: a rate that never acts in a trial, a nested field of the wrong
type, a negative clip or normaliser, an ``.npz`` member that claims more than it holds, a model with an input the
controller does not feed, weights that changed since export. Each must be refused when the controller is resolved,
before any trial, by `get_controller` with the project's error naming the file and the field, and by
``wbc check-controller`` with exit status 2 and one line, no traceback. A valid export still loads and plays.
"""

from __future__ import annotations

import io
import json
import math
import zipfile
from pathlib import Path

import numpy as np
import pytest

from wbc.cli.main import main
from wbc.control.errors import OnnxIoError, OnnxModelError
from wbc.control.registry import get_controller
from wbc.errors import InputFileError, WbcError
from wbc.input_files import LIMITS
from wbc.learned.policy.composite_policy import load_composite
from wbc.learned.policy.control_rate import PHYSICS_DT, period_problem, rate_problem
from wbc.learned.policy.observations import ObsLayout
from wbc.learned.policy.policy_file import CHECKSUM_KEY, PolicyFile, PolicyFileError, save_policy, weights_sha256
from wbc.learned.policy.shipped import WEIGHTS_DIR
from wbc.physics_steps import nearest_rates
from wbc.robots.registry import get_robot
from wbc.types import RobotState, VelocityCommand

DESC = get_robot("a1-wx200", "none")
N = DESC.num_joints
OBS = ObsLayout(N).size


def _meta() -> dict:
    return {"robot": "a1-wx200", "arm_mode": "none", "task": "push", "stage": 1, "num_actions": N,
            "obs_layout": ObsLayout(N).as_list(),
            "obs_scales": {"ang_vel": 0.25, "dof_pos": 1.0, "dof_vel": 0.05, "command": [2.0, 2.0, 0.25]},
            "action_scale": 0.25, "clip_actions": 10.0, "default_q": DESC.nominal_q.tolist(), "kp": [20.0] * N,
            "kd": [0.5] * N, "policy_dt": 0.02, "activation": "elu", "hidden_dims": [8], "normalizer_eps": 0.01,
            "extrinsics": None, "training": {}}


def _arrays() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    return {"obs_mean": np.zeros(OBS), "obs_std": np.ones(OBS),
            "policy/0/weight": 0.01 * rng.standard_normal((8, OBS)), "policy/0/bias": np.zeros(8),
            "policy/1/weight": 0.01 * rng.standard_normal((N, 8)), "policy/1/bias": np.zeros(N)}


@pytest.fixture()
def policy(tmp_path) -> tuple[Path, Path]:
    """A valid policy file of a tiny network for the robot without its arm, saved as an export saves it."""
    return save_policy(tmp_path / "pi", PolicyFile(meta=_meta(), arrays=_arrays()))


def _edit_json(js: Path, edit) -> None:
    meta = json.loads(js.read_text())
    edit(meta)
    js.write_text(json.dumps(meta))


def _write_npz(npz: Path, arrays: dict[str, np.ndarray], *, keep_checksum: bool = False) -> None:
    """Replace the weights; without `keep_checksum` the JSON loses its checksum, as an older export has none."""
    np.savez(npz, **arrays)
    if not keep_checksum:
        _edit_json(npz.with_suffix(".json"), lambda m: m.pop(CHECKSUM_KEY))


def _refused_on_the_command_line(name: str, capsys, *needles: str) -> str:
    """``wbc check-controller NAME`` exits 2 with one line naming `needles`, no traceback; returns the line."""
    assert main(["check-controller", name, "--seconds", "0.1"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    for needle in needles:
        assert needle in err, (needle, err)
    return err


# -- policy files: every nested field typed and ranged --------------------------------------------------------------
def _set(path: tuple[str, ...], value):
    def edit(meta: dict) -> None:
        target = meta
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value
    return edit


JSON_CASES = [
    # a controller that never acts in a trial, or divides by zero
    (("policy_dt",), 1e6, "policy_dt", "out of range; the control period must be a whole number of the 2 ms"),
    (("policy_dt",), 0, "policy_dt", "not a positive finite period"),
    (("policy_dt",), 0.003, "policy_dt", "1.5 physics steps, not a whole number"),
    (("policy_dt",), "0.02", "policy_dt", "expected a number"),
    # signs that play without a word
    (("clip_actions",), -1, "clip_actions", "must be in (0, 1000]"),
    (("normalizer_eps",), -0.01, "normalizer_eps", "must be in [0, 1]"),
    (("action_scale",), 0, "action_scale", "must be in (0, 10]"),
    (("kd",), [-0.5] * N, "kd", "every value must be in [0, 100]"),
    (("default_q",), [math.nan] * N, "default_q", "got nan at index 0"),
    # nested values of the wrong type or shape
    (("obs_scales", "command"), ["2", 2.0, 0.25], "obs_scales/command", "expected numbers"),
    (("obs_scales", "ang_vel"), -0.25, "obs_scales/ang_vel", "must be in (0, 100]"),
    (("obs_scales",), {"ang_vel": 0.25}, "obs_scales", "exactly the keys ang_vel, dof_pos, dof_vel, command"),
    (("obs_layout",), [["ang_vel", "3"]], "obs_layout/0", "expected a [name, size] pair"),
    (("obs_layout",), ObsLayout(8).as_list(), "obs_layout", "observes 8 joints but drives 12"),
    (("hidden_dims",), [8.0], "hidden_dims/0", "expected an integer"),
    (("hidden_dims",), [2**40], "hidden_dims/0", "must be in [1, 65536]"),
    (("kp",), [20.0] * (N - 1), "kp", f"expected {N} values"),
    (("num_actions",), 2**40, "num_actions", "must be in [1, 64]"),
    (("stage",), True, "stage", "expected an integer"),
    (("extrinsics",), [8], "extrinsics", "expected an object"),
    (("extrinsics",), {"dim": "8", "hidden_dims": [], "privileged_parts": [["friction", 1]]}, "extrinsics/dim",
     "expected an integer"),
    (("extrinsics",), {"dim": 8, "hidden_dims": []}, "extrinsics/privileged_parts", "missing key"),
    # a latent of no privileged parts comes from the history alone: the file must then declare where it comes from
    (("extrinsics",), {"dim": 8, "hidden_dims": [], "privileged_parts": []}, "extrinsics/privileged_parts",
     "declares no adaptation module"),
    (("training",), [1], "training", "expected an object"),
    ((CHECKSUM_KEY,), "abc", CHECKSUM_KEY, "expected 64 lowercase hex digits"),
]


@pytest.mark.parametrize(("path", "value", "field", "reason"), JSON_CASES,
                         ids=[f"{c[2]}={str(c[1])[:16]}" for c in JSON_CASES])
def test_a_bad_field_is_refused_naming_the_file_the_field_and_the_range(policy, capsys, path, value, field, reason):
    npz, js = policy
    _edit_json(js, _set(path, value))
    with pytest.raises(PolicyFileError) as caught:
        get_controller(f"policy:{npz}")
    message = str(caught.value)
    assert caught.value.field == field and message.startswith(f"{js}: {field}: ") and reason in message, message
    assert "\n" not in message
    _refused_on_the_command_line(f"policy:{npz}", capsys, f"{js}: {field}: ", reason)


def test_a_json_that_is_not_an_object_or_nests_too_deep_is_one_line(policy, capsys):
    npz, js = policy
    js.write_text("[1, 2]")
    with pytest.raises(PolicyFileError, match="expected a JSON object at the top level, got an array"):
        get_controller(f"policy:{npz}")
    js.write_text("[" * 500 + "]" * 500)
    with pytest.raises(PolicyFileError, match="nested more than 32 levels deep"):
        get_controller(f"policy:{npz}")
    _refused_on_the_command_line(f"policy:{npz}", capsys, str(js), "nested more than")


NPZ_CASES = [
    ("obs_std", lambda a: {**a, "obs_std": -a["obs_std"]}, "negative standard deviations"),
    ("policy/1/weight", lambda a: {**a, "policy/1/weight": np.where(np.eye(N, 8) > 0, np.nan, a["policy/1/weight"])},
     "8 values are not finite (first at index (0, 0))"),
    ("policy/0/bias", lambda a: {**a, "policy/0/bias": np.zeros(9)}, "expected shape (8,), got (9,)"),
    ("policy/2/weight", lambda a: {**a, "policy/2/weight": np.zeros((N, N))}, "more layers than hidden_dims"),
    ("encoder/0/weight", lambda a: {**a, "encoder/0/weight": np.zeros((1, 1))}, "the metadata does not describe"),
]


@pytest.mark.parametrize(("field", "edit", "reason"), NPZ_CASES, ids=[c[0] for c in NPZ_CASES])
def test_bad_weights_are_refused_naming_the_array(policy, capsys, field, edit, reason):
    npz, _ = policy
    with np.load(npz) as data:
        arrays = {k: data[k] for k in data.files}
    _write_npz(npz, edit(arrays))
    with pytest.raises(PolicyFileError) as caught:
        get_controller(f"policy:{npz}")
    assert caught.value.field == field and reason in str(caught.value), str(caught.value)
    _refused_on_the_command_line(f"policy:{npz}", capsys, f"{npz}: {field}: ", reason)


def test_a_zero_deviation_needs_a_positive_eps(policy):
    npz, js = policy
    with np.load(npz) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["obs_std"][4] = 0.0
    _write_npz(npz, arrays)
    get_controller(f"policy:{npz}")  # std + eps = 0.01 > 0: a constant observation entry, as training leaves one
    _edit_json(js, _set(("normalizer_eps",), 0.0))
    with pytest.raises(PolicyFileError, match=r"obs_std: standard deviation 0 at index 4 with normalizer_eps 0"):
        get_controller(f"policy:{npz}")


def test_an_npz_member_claiming_2_to_the_40_floats_and_a_deflate_bomb_are_refused_unread(policy, monkeypatch,
                                                                                         capsys):
    npz, _ = policy
    with np.load(npz) as data:
        arrays = {k: data[k] for k in data.files}
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False, "shape": (2**40,)})
    with zipfile.ZipFile(npz, "w") as z:
        for key, value in arrays.items():
            if key == "obs_std":
                continue
            buf = io.BytesIO()
            np.save(buf, value)
            z.writestr(f"{key}.npy", buf.getvalue())
        z.writestr("obs_std.npy", header.getvalue() + bytes(64))
    _edit_json(npz.with_suffix(".json"), lambda m: m.pop(CHECKSUM_KEY))
    with pytest.raises(PolicyFileError, match=r"member obs_std\.npy: its header claims 1099511627776 values"):
        get_controller(f"policy:{npz}")
    _refused_on_the_command_line(f"policy:{npz}", capsys, str(npz), "claims 1099511627776 values")
    # a member that inflates past the limit (here 1 MiB, so that the test writes kilobytes, not gigabytes)
    monkeypatch.setitem(LIMITS, "npz", 1 << 20)
    with zipfile.ZipFile(npz, "w", compression=zipfile.ZIP_DEFLATED) as z:
        buf = io.BytesIO()
        np.save(buf, np.zeros(1 << 19))  # 4 MiB of zeros, a few kB deflated
        z.writestr("obs_std.npy", buf.getvalue())
    assert npz.stat().st_size < 64 << 10
    with pytest.raises(PolicyFileError, match=r"its members hold 4,194,432 bytes uncompressed, more than the 1 MiB"):
        get_controller(f"policy:{npz}")


# -- checksums -------------------------------------------------------------------------------------------------------
def test_an_export_records_the_weights_sha256_and_a_changed_npz_is_refused(policy, capsys):
    npz, js = policy
    meta = json.loads(js.read_text())
    assert meta[CHECKSUM_KEY] == weights_sha256(npz)
    # the same shapes, one weight changed: every other check passes, the checksum does not
    with np.load(npz) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["policy/1/bias"][3] += 0.5
    _write_npz(npz, arrays, keep_checksum=True)
    found = weights_sha256(npz)
    with pytest.raises(PolicyFileError) as caught:
        get_controller(f"policy:{npz}")
    message = str(caught.value)
    assert message.startswith(f"{npz}: sha256 {found} differs from {meta[CHECKSUM_KEY]}, recorded at export in "
                              f"pi.json ({CHECKSUM_KEY})"), message
    _refused_on_the_command_line(f"policy:{npz}", capsys, "differs from", meta[CHECKSUM_KEY])
    # a flipped bit in the file is refused by the checksum before the archive's own CRC is read
    _write_npz(npz, _arrays(), keep_checksum=True)
    _edit_json(js, _set((CHECKSUM_KEY,), weights_sha256(npz)))
    get_controller(f"policy:{npz}")
    raw = bytearray(npz.read_bytes())
    raw[len(raw) // 2] ^= 0x10
    npz.write_bytes(bytes(raw))
    with pytest.raises(PolicyFileError, match="differs from .* the weights changed since they were exported"):
        get_controller(f"policy:{npz}")
    # without a checksum (an export older than it) the file loads unchecked
    _write_npz(npz, arrays)
    assert CHECKSUM_KEY not in json.loads(js.read_text())
    get_controller(f"policy:{npz}")


def test_the_shipped_weights_carry_their_checksum_and_load():
    for npz in sorted(WEIGHTS_DIR.glob("*.npz")):
        meta = json.loads(npz.with_suffix(".json").read_text())
        assert meta[CHECKSUM_KEY] == weights_sha256(npz), npz.name
        assert load_composite(npz).meta[CHECKSUM_KEY] == meta[CHECKSUM_KEY]


def test_a_valid_export_loads_and_plays(policy, capsys):
    npz, _ = policy
    spec = get_controller(f"policy:{npz}")
    ctrl = spec.make(DESC)
    assert ctrl.rate_hz == pytest.approx(50.0)
    assert main(["check-controller", f"policy:{npz}", "--seconds", "0.2"]) == 0
    assert "Traceback" not in capsys.readouterr().err


# -- rates -----------------------------------------------------------------------------------------------------------
def test_the_rate_rule_is_the_arenas_physics_step():
    from wbc.hardware.mujoco import MujocoRobotConfig

    assert MujocoRobotConfig().timestep == PHYSICS_DT
    for good in (500.0, 250.0, 1000.0 / 6.0, 50.0, 1.0):
        assert rate_problem(good) is None, good
    assert period_problem(0.02) is None and period_problem(1.0) is None
    for bad in (0.0, -50.0, 0.02, 1e-6, 1e-300, math.inf, math.nan, 600.0, 33.0):
        assert rate_problem(bad) is not None, bad
    assert "the nearest are 500 Hz and 250 Hz" in rate_problem(300.0)


def test_a_refused_rate_is_told_the_nearest_rates_whose_period_is_whole_steps():
    assert nearest_rates(60.0, PHYSICS_DT) == "the nearest are 62.5 Hz and 55.5556 Hz"
    assert nearest_rates(300.0, 0.001) == "the nearest are 333.333 Hz and 250 Hz"
    assert nearest_rates(600.0, PHYSICS_DT) == "the nearest is 500 Hz"  # faster than one step
    assert rate_problem(60.0).endswith(nearest_rates(60.0, PHYSICS_DT))  # the I/O files' refusal says the same


# -- ONNX policies ---------------------------------------------------------------------------------------------------
IO = """
[policy]
robot = "a1-wx200"
arm_mode = "none"
rate_hz = {rate}
joints = {joints}
{onnx}
[observation]
history = 1

[[observation.terms]]
name = "base_ang_vel"

[[observation.terms]]
name = "joint_pos_rel"

[action]
scale = 0.25

[pd]
kp = 20.0
kd = 0.5
"""
ONNX_IN = 3 + N


def _io_text(rate: str = "50.0", onnx: str = "") -> str:
    joints = "[" + ", ".join(f'"{j}"' for j in DESC.joint_names) + "]"
    return IO.format(rate=rate, joints=joints, onnx=onnx)


def _model(path: Path, *, extra_input: str | None = None) -> None:
    """An ONNX network ``actions = obs @ w + b`` (float32, batch of 1), optionally with an unfed second input."""
    onnx = pytest.importorskip("onnx")
    from onnx import TensorProto, helper, numpy_helper

    rng = np.random.default_rng(1)
    inputs = [helper.make_tensor_value_info("obs", TensorProto.FLOAT, [1, ONNX_IN])]
    if extra_input is not None:
        inputs.append(helper.make_tensor_value_info(extra_input, TensorProto.FLOAT, [1, 1]))
    graph = helper.make_graph(
        [helper.make_node("MatMul", ["obs", "w"], ["y"]), helper.make_node("Add", ["y", "b"], ["actions"])],
        "linear", inputs, [helper.make_tensor_value_info("actions", TensorProto.FLOAT, [1, N])],
        [numpy_helper.from_array(0.01 * rng.standard_normal((ONNX_IN, N)).astype(np.float32), "w"),
         numpy_helper.from_array(np.zeros(N, dtype=np.float32), "b")])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.save(model, str(path))


@pytest.fixture()
def onnx_pair(tmp_path) -> tuple[Path, Path]:
    pytest.importorskip("onnxruntime")
    model, io_file = tmp_path / "m.onnx", tmp_path / "m.toml"
    _model(model)
    io_file.write_text(_io_text())
    return model, io_file


@pytest.mark.parametrize("rate", ["0.02", "1e-6", "1e-300", "600.0", "33.0", "0.0"])
def test_an_io_rate_that_cannot_be_played_is_refused_with_the_rule(onnx_pair, capsys, rate):
    model, io_file = onnx_pair
    io_file.write_text(_io_text(rate=rate))
    with pytest.raises(OnnxIoError) as caught:
        get_controller(f"onnx:{model}")
    err = caught.value
    assert err.field == "[policy] rate_hz" and "whole number of the 2 ms physics steps" in err.reason
    assert io_file.read_text().splitlines()[err.line - 1].startswith("rate_hz")
    _refused_on_the_command_line(f"onnx:{model}", capsys, f"{io_file}:{err.line}: [policy] rate_hz: ",
                                 "1 to 500 Hz")


def test_a_model_with_an_input_the_controller_does_not_feed_is_refused_naming_it(onnx_pair, capsys):
    model, io_file = onnx_pair
    _model(model, extra_input="hidden_state")
    with pytest.raises(OnnxModelError, match=r"the network has 2 inputs \(obs, hidden_state\)"):
        get_controller(f"onnx:{model}")
    io_file.write_text(_io_text(onnx='[onnx]\ninput = "obs"\n'))
    with pytest.raises(OnnxModelError, match=r"input 'hidden_state' .* would be left unfed"):
        get_controller(f"onnx:{model}")
    _refused_on_the_command_line(f"onnx:{model}", capsys, str(model), "'hidden_state'", "left unfed")


def test_a_recorded_model_sha256_is_verified_and_bit_flips_are_refused(onnx_pair, capsys):
    model, io_file = onnx_pair
    good = model.read_bytes()
    io_file.write_text(_io_text(onnx=f'[onnx]\nsha256 = "{weights_sha256(model)}"\n'))
    ctrl = get_controller(f"onnx:{model}").make(DESC)  # the recorded sha256 matches: it loads and acts
    state = RobotState(tick=0, time=0.0, q=DESC.nominal_q.copy(), dq=np.zeros(N), tau_est=np.zeros(N),
                       imu_quat=np.array([1.0, 0.0, 0.0, 0.0]), gyro_in_body=np.zeros(3),
                       accel_in_body=np.array([0.0, 0.0, 9.81]), foot_force=np.zeros(4))
    assert np.all(np.isfinite(ctrl.act(state, VelocityCommand()).q))
    flips = np.linspace(0, len(good) - 1, 12).astype(int)
    for at in flips:
        raw = bytearray(good)
        raw[at] ^= 0x04
        model.write_bytes(bytes(raw))
        with pytest.raises(OnnxModelError, match="differs from .* recorded at export in .* \\[onnx\\] sha256"):
            get_controller(f"onnx:{model}")
    _refused_on_the_command_line(f"onnx:{model}", capsys, "differs from", "[onnx] sha256")
    # without a recorded sha256 a flipped model is refused by whichever check it fails, in one line, or runs
    io_file.write_text(_io_text())
    for at in flips:
        raw = bytearray(good)
        raw[at] ^= 0x04
        model.write_bytes(bytes(raw))
        try:
            get_controller(f"onnx:{model}")
        except WbcError as exc:
            assert "\n" not in str(exc) and str(model) in str(exc), str(exc)
    io_file.write_text(_io_text(onnx='[onnx]\nsha256 = "ABC"\n'))
    with pytest.raises(OnnxIoError, match=r"\[onnx\] sha256: expected 64 lowercase hex digits"):
        get_controller(f"onnx:{model}")


def test_a_model_larger_than_the_limit_is_refused_unread(onnx_pair, monkeypatch, capsys):
    model, _ = onnx_pair
    monkeypatch.setitem(LIMITS, "onnx", 256)
    with pytest.raises(InputFileError, match=r"more than the 256 bytes a onnx file may have"):
        get_controller(f"onnx:{model}")
    _refused_on_the_command_line(f"onnx:{model}", capsys, str(model), "more than the 256 bytes")
