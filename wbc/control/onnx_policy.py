"""`OnnxController`: a policy exported to ONNX by another trainer, run with onnxruntime as its I/O file says.

Every tick, from `RobotState` and the operator's command only: each observation term of the I/O file
(`wbc.control.onnx_io`) in the network's joint order, times its scale, clipped; the frame clipped as a whole if the
file says so; the history (whole frames or each term's own, oldest first; after a reset filled with the first
observation or with zeros); the network's output, clipped, is the action; the motor command holds
``q* = default_q + scale * action`` with the file's PD gains, mapped back to the house joint order, zero target
velocity and feed-forward torque. Nothing from the simulator's truth is read.

onnxruntime is an optional dependency (``pip install 'wbc[onnx]'``); the session runs on one thread, as every arena
worker runs on one core. ``onnx:PATH`` names are resolved by `onnx_spec`, which reads the I/O file and checks the
model against it once, in the parent process, before any trial starts.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wbc.control.errors import OnnxModelError
from wbc.control.onnx_io import OnnxIo, io_path_for, load_onnx_io
from wbc.control.spec import ControllerSpec
from wbc.errors import ConfigError
from wbc.learned.policy.observations import projected_gravity
from wbc.optional import require
from wbc.robots.description import RobotDescription
from wbc.types import MotorCommand, RobotState, VelocityCommand

__all__ = ["ONNX_PREFIX", "NetworkPorts", "OnnxController", "check_model", "onnx_spec", "open_session"]

ONNX_PREFIX = "onnx:"
"""``onnx:PATH`` names the ONNX model at PATH (its I/O file: PATH with the suffix .toml, or ``--io FILE``)."""

_DTYPES = {"tensor(float)": np.float32, "tensor(double)": np.float64}


def open_session(model: str | Path) -> Any:
    """An onnxruntime session on one CPU thread.

    Raises:
        MissingExtraError: onnxruntime is not installed (the message names the ``onnx`` extra).
        OnnxModelError: the file is missing or not a model onnxruntime can run.
    """
    path = Path(model)
    if not path.is_file():
        raise OnnxModelError(f"{path}: file not found; onnx:PATH names an exported .onnx model")
    ort = require("onnxruntime", "onnx")
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    opts.inter_op_num_threads = 1
    opts.log_severity_level = 3  # errors only: the arena's workers print nothing per trial
    try:
        return ort.InferenceSession(str(path), sess_options=opts, providers=["CPUExecutionProvider"])
    except Exception as exc:  # noqa: BLE001 (onnxruntime raises its own types; all mean "cannot run this file")
        raise OnnxModelError(f"{path}: not an ONNX model onnxruntime can run ({type(exc).__name__}: {exc})") from None


@dataclass(frozen=True)
class NetworkPorts:
    """The network's input and output as the controller feeds and reads them.

    Attributes:
        input_name: the input fed.
        output_name: the output read.
        dtype: the input's element type (float32 or float64).
        batched: the input has a leading batch axis of 1.
    """

    input_name: str
    output_name: str
    dtype: type
    batched: bool


def _size(shape: list) -> int | None:
    """The last axis' length, or None when it is symbolic (fixed only at run time)."""
    last = shape[-1] if shape else None
    return last if isinstance(last, int) else None


def check_model(session: Any, io: OnnxIo, model: str | Path) -> NetworkPorts:
    """Check the network against its I/O file: names, input size and element type, output size.

    Raises:
        OnnxModelError: a mismatch; the message names the model, the I/O file's field and both values.
    """
    inputs, outputs = session.get_inputs(), session.get_outputs()
    names = [i.name for i in inputs]
    if io.input_name is None and len(inputs) != 1:
        raise OnnxModelError(f"{model}: the network has {len(inputs)} inputs ({', '.join(names)}); name the "
                             f"observation's in {io.path} [onnx] input")
    if io.input_name is not None and io.input_name not in names:
        raise OnnxModelError(f"{io.path}: [onnx] input: {model} has no input {io.input_name!r}; its inputs: "
                             f"{', '.join(names)}")
    port = inputs[0] if io.input_name is None else inputs[names.index(io.input_name)]
    if port.type not in _DTYPES:
        raise OnnxModelError(f"{model}: input {port.name!r} is a {port.type}; the controller feeds tensor(float) "
                             "or tensor(double)")
    shape = list(port.shape)
    if len(shape) not in (1, 2) or (len(shape) == 2 and isinstance(shape[0], int) and shape[0] != 1):
        raise OnnxModelError(f"{model}: input {port.name!r} has shape {shape}; expected [size] or [batch, size] "
                             "with a batch of 1 or a free batch axis")
    size = _size(shape)
    if size is not None and size != io.input_size:
        per = " + ".join(f"{t.name} {t.size}x{t.history}" for t in io.terms)
        raise OnnxModelError(f"{io.path}: [observation]: the terms make {io.input_size} inputs ({per}), but {model} "
                             f"input {port.name!r} takes {size}; fix the terms, their order or the history")
    out_names = [o.name for o in outputs]
    if io.output_name is not None and io.output_name not in out_names:
        raise OnnxModelError(f"{io.path}: [onnx] output: {model} has no output {io.output_name!r}; its outputs: "
                             f"{', '.join(out_names)}")
    out = outputs[0] if io.output_name is None else outputs[out_names.index(io.output_name)]
    out_size = _size(list(out.shape))
    if out_size is not None and out_size != io.num_joints:
        raise OnnxModelError(f"{io.path}: [policy] joints: {io.num_joints} joints listed, but {model} output "
                             f"{out.name!r} has {out_size} entries; list the network's joints in its order")
    return NetworkPorts(input_name=port.name, output_name=out.name, dtype=_DTYPES[port.type], batched=len(shape) == 2)


class OnnxController:
    """Runs an ONNX policy as its I/O file declares.

    Args:
        desc: the robot it drives (must be the I/O file's robot and arm mode).
        model_path: the ``.onnx`` file.
        io: its validated I/O file (`load_onnx_io`).

    Raises:
        ConfigError: `desc` is not the robot or arm mode of the I/O file.
        OnnxModelError: the model does not fit the I/O file (`check_model`).
        MissingExtraError: onnxruntime is not installed.
    """

    def __init__(self, desc: RobotDescription, *, model_path: str | Path, io: OnnxIo) -> None:
        if (desc.name, desc.arm_mode) != (io.robot, io.arm_mode):
            raise ConfigError(f"{io.path}: the policy drives {io.robot} with arm {io.arm_mode}, not {desc.name} with "
                              f"arm {desc.arm_mode}; play it on a scenario for {io.robot}")
        self.io = io
        self.rate_hz = float(io.rate_hz)
        self.session = open_session(model_path)
        self.ports = check_model(self.session, io, model_path)
        idx = np.asarray(io.house_index, dtype=int)
        self._index = idx
        n = io.num_joints
        self.default_q = np.asarray(io.default_q, dtype=np.float64)
        self.action_scale = np.asarray(io.action_scale, dtype=np.float64)
        self._kp = np.empty(n)
        self._kd = np.empty(n)
        self._kp[idx] = io.kp
        self._kd[idx] = io.kd
        self._zeros = np.zeros(n)
        self._scales = [np.asarray(t.scale, dtype=np.float64) for t in io.terms]
        self._frames = max(t.history for t in io.terms)
        # frames order: one (H, frame) window; terms order: each term's own (h, size) window
        self._windows = ([np.zeros((self._frames, io.frame_size))] if io.history_order == "frames"
                         else [np.zeros((t.history, t.size)) for t in io.terms])
        self.last_action = np.zeros(n)
        self._fresh = True

    def reset(self) -> None:
        """Forget the previous action and the observation history."""
        self.last_action = np.zeros_like(self.last_action)
        for w in self._windows:
            w[:] = 0.0
        self._fresh = True

    def _term(self, name: str, state: RobotState, command: VelocityCommand) -> np.ndarray:
        if name == "base_ang_vel":
            return state.gyro_in_body
        if name == "projected_gravity":
            return projected_gravity(state.imu_quat)
        if name == "velocity_commands":
            return command.as_array()
        if name == "joint_pos_rel":
            return state.q[self._index] - self.default_q
        if name == "joint_pos":
            return state.q[self._index]
        if name == "joint_vel":
            return state.dq[self._index]
        return self.last_action  # last_action (the I/O file admits no other name)

    def observation(self, state: RobotState, command: VelocityCommand) -> list[np.ndarray]:
        """This tick's terms, scaled and clipped, in the I/O file's order (one frame, float64)."""
        parts = []
        for term, scale in zip(self.io.terms, self._scales, strict=True):
            value = self._term(term.name, state, command) * scale
            if term.clip is not None:
                value = np.clip(value, *term.clip)
            parts.append(value)
        if self.io.obs_clip is not None:
            parts = [np.clip(p, -self.io.obs_clip, self.io.obs_clip) for p in parts]
        return parts

    def network_input(self, state: RobotState, command: VelocityCommand) -> np.ndarray:
        """Push this tick's observation into the history and return the network's input, (input_size,)."""
        parts = self.observation(state, command)
        rows = [np.concatenate(parts)] if self.io.history_order == "frames" else parts
        for window, row in zip(self._windows, rows, strict=True):
            if self._fresh and self.io.history_fill == "first":
                window[:] = row
            else:
                window[:-1] = window[1:]
                window[-1] = row
        self._fresh = False
        return np.concatenate([w.reshape(-1) for w in self._windows])

    def act(self, state: RobotState, command: VelocityCommand) -> MotorCommand:
        """One policy step."""
        x = self.network_input(state, command).astype(self.ports.dtype)
        out = self.session.run([self.ports.output_name], {self.ports.input_name: x[None] if self.ports.batched
                                                          else x})[0]
        action = np.asarray(out, dtype=np.float64).reshape(-1)
        if action.shape[0] != self.io.num_joints:
            raise OnnxModelError(f"{self.io.path}: the network returned {action.shape[0]} actions for "
                                 f"{self.io.num_joints} joints")
        if self.io.action_clip is not None:
            action = np.clip(action, -self.io.action_clip, self.io.action_clip)
        self.last_action = action
        target = np.empty_like(action)
        target[self._index] = self.default_q + self.action_scale * action
        return MotorCommand(q=target, dq=self._zeros, kp=self._kp, kd=self._kd, tau=self._zeros)

    def counters(self) -> dict[str, int]:
        """No events."""
        return {}


def onnx_spec(name: str, model: str | Path, io_file: str | Path | None = None) -> ControllerSpec:
    """Resolve ``onnx:PATH``: read the I/O file, check the model against it, and make the spec.

    Args:
        name: the controller's name (``onnx:PATH``).
        model: the ``.onnx`` file.
        io_file: the I/O file (default: beside the model, `io_path_for`).

    Raises:
        OnnxIoError: the I/O file is missing or invalid (``path:line: [table] key: reason``).
        OnnxModelError: the model is missing, unreadable or does not fit the I/O file.
        MissingExtraError: onnxruntime is not installed.
    """
    path = Path(model)
    if not path.is_file():
        raise OnnxModelError(f"{path}: file not found; onnx:PATH names an exported .onnx model")
    io_path = Path(io_file) if io_file is not None else io_path_for(path)
    io = load_onnx_io(io_path)
    check_model(open_session(path), io, path)  # once here, so a mismatch fails before any trial
    make = functools.partial(OnnxController, model_path=str(path.resolve()), io=io)
    return ControllerSpec(name, io.arm_mode, make, io.summary, robots=(io.robot,), kind="onnx",
                          config_file=str(io_path))
