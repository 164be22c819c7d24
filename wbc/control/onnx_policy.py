"""`OnnxController`: a policy exported to ONNX by another trainer, run with onnxruntime as its I/O file says.

Every tick, from `RobotState` and the operator's command only: each observation term of the I/O file
(`wbc.control.onnx_io`) in the network's joint order, times its scale, clipped; the frame clipped as a whole if the
file says so; the history (whole frames or each term's own, oldest first; after a reset filled with the first
observation or with zeros); the network's output, clipped, is the action; the motor command holds
``q* = default_q + scale * action`` with the file's PD gains, mapped back to the house joint order, zero target
velocity and feed-forward torque. Nothing from the simulator's truth is read: a ``base_lin_vel`` term (``source =
"estimator"``) is the state estimator's estimate (`wbc.estimation.base_estimate.BaseEstimate`, the one a hardware
trial's metrics use), fed this controller's states at its rate and rotated into the body frame; the arena plays
such a policy as a robot would run it.

onnxruntime is an optional dependency (``pip install 'wbc[onnx]'``); the session runs on one thread, as every arena
worker runs on one core. ``onnx:PATH`` names are resolved by `onnx_spec`, which reads the I/O file and checks the
model against it once, in the parent process, before any trial starts.

A model may keep its weights in external data files beside it: torch's default exporter (torch >= 2.9, ``dynamo``)
writes ``model.onnx`` and ``model.onnx.data``. `open_session` reads the file names the model refers to
(`external_data_files`, the ``location`` of every tensor stored outside the model, read from the protobuf without the
``onnx`` package), refuses a missing one before onnxruntime is asked, naming the model and the file, and builds the
session from the model's real path (symbolic links resolved), from which onnxruntime finds those files. The spec's
provenance (`ControllerSpec.provenance`) holds the sha256 of the model, of each external data file and of the I/O file.

Before any trial `onnx_spec` refuses, with one line naming the file: a model (or external data file) that is not a
regular file or is larger than `wbc.input_files.LIMITS` allows; a model whose sha256 differs from the one its I/O
file records (``[onnx] sha256``, written by ``wbc``'s export; without it the model runs unchecked); a model
onnxruntime cannot load (a damaged file, or a valid one with an operator onnxruntime does not implement for its
element type, named as such: a float64 Elu, say); a graph whose inputs are not exactly the one observation the
controller feeds, or whose output is not the joints' actions (`check_model`); and a graph that fails, or answers with
the wrong size or a non-finite action, on the observation of a robot at rest. A non-finite action the network returns
later, in `OnnxController.act`, is refused as the network's: the error names the model, the output entries with their
joints in the network's order, the step since the reset, and whether the input was finite.
"""

from __future__ import annotations

import functools
import hashlib
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wbc.control.errors import OnnxModelError
from wbc.control.onnx_io import OnnxIo, io_path_for, load_onnx_io
from wbc.control.spec import ControllerSpec, SourceFile
from wbc.errors import ConfigError
from wbc.estimation.base_estimate import BaseEstimate
from wbc.input_files import LIMITS, read_bytes
from wbc.learned.policy.observations import projected_gravity
from wbc.optional import require
from wbc.robots.conventions import quat_to_matrix
from wbc.robots.description import RobotDescription
from wbc.types import MotorCommand, RobotState, VelocityCommand

__all__ = ["ONNX_PREFIX", "NetworkPorts", "OnnxController", "check_model", "external_data_files", "onnx_spec",
           "open_session", "resolve_model"]

ONNX_PREFIX = "onnx:"
"""``onnx:PATH`` names the ONNX model at PATH (its I/O file: PATH with the suffix .toml, or ``--io FILE``)."""

_DTYPES = {"tensor(float)": np.float32, "tensor(double)": np.float64}
_MISSING_KERNEL = re.compile(r"NOT_IMPLEMENTED\s*:\s*Could not find an implementation for (?P<op>[\w.]+)"
                             r"\((?P<version>\d+)\)(?: node with name '(?P<node>[^']*)')?")
"""onnxruntime's message for a valid model's operator that it implements for neither its element type nor version."""


# -- external data: the few protobuf fields of onnx.proto that lead to a tensor's external_data ----------------------
_GRAPH_FIELDS = {1: "node", 5: "tensor", 15: "sparse"}  # GraphProto: node, initializer, sparse_initializer
_NODE_FIELDS = {5: "attribute"}  # NodeProto.attribute
_ATTRIBUTE_FIELDS = {5: "tensor", 6: "graph", 10: "tensor", 11: "graph", 22: "sparse", 23: "sparse"}
_SPARSE_FIELDS = {1: "tensor", 2: "tensor"}  # SparseTensorProto: values, indices
_MODEL_FIELDS = {7: "graph", 20: "training", 25: "function"}  # ModelProto: graph, training_info, functions
_TRAINING_FIELDS = {1: "graph", 2: "graph"}  # TrainingInfoProto: initialization, algorithm
_FUNCTION_FIELDS = {7: "node", 11: "attribute"}  # FunctionProto: node, attribute_proto
_TENSOR_EXTERNAL_DATA = 13  # TensorProto.external_data: repeated StringStringEntryProto (key = 1, value = 2)


class _NotProtobuf(ValueError):
    """The bytes are not the protobuf message they were read as."""


def _varint(buf: memoryview, at: int) -> tuple[int, int]:
    value, shift = 0, 0
    while True:
        if at >= len(buf) or shift > 63:
            raise _NotProtobuf("truncated varint")
        byte = buf[at]
        at += 1
        value |= (byte & 0x7F) << shift
        if byte < 0x80:
            return value, at
        shift += 7


def _fields(buf: memoryview):
    """(field number, wire type, value) of every field of one message; a length-delimited value is its bytes."""
    at = 0
    while at < len(buf):
        key, at = _varint(buf, at)
        number, wire = key >> 3, key & 7
        if wire == 0:
            value, at = _varint(buf, at)
        elif wire == 1:
            value, at = buf[at:at + 8], at + 8
        elif wire == 2:
            size, at = _varint(buf, at)
            value, at = buf[at:at + size], at + size
        elif wire == 5:
            value, at = buf[at:at + 4], at + 4
        else:  # groups (3, 4) are not used by onnx.proto
            raise _NotProtobuf(f"wire type {wire}")
        if at > len(buf) or number == 0:
            raise _NotProtobuf("truncated field")
        yield number, wire, value


_KINDS: dict[str, dict[int, str]] = {"model": _MODEL_FIELDS, "graph": _GRAPH_FIELDS, "node": _NODE_FIELDS,
                                     "attribute": _ATTRIBUTE_FIELDS, "sparse": _SPARSE_FIELDS,
                                     "training": _TRAINING_FIELDS, "function": _FUNCTION_FIELDS}


def _locations(buf: memoryview, kind: str, out: list[str]) -> None:
    """Append the external data ``location`` of every tensor inside `buf`, a message of `kind`."""
    if kind == "tensor":
        for number, wire, value in _fields(buf):
            if number == _TENSOR_EXTERNAL_DATA and wire == 2:
                entry = {n: v for n, w, v in _fields(value) if w == 2}
                if entry.get(1) == b"location" and 2 in entry:
                    out.append(bytes(entry[2]).decode("utf-8"))
        return
    inner = _KINDS[kind]
    for number, wire, value in _fields(buf):
        if wire == 2 and number in inner:
            _locations(value, inner[number], out)


def external_data_files(model: str | Path) -> list[str]:
    """The external data files a model refers to: each tensor's ``location``, once each, in order of appearance.

    The locations are as the model writes them, relative to the model's directory (torch's exporter writes
    ``model.onnx.data``). The model's protobuf is walked along the fields that can hold a tensor (initializers,
    sparse initializers, node attributes and subgraphs, training graphs, functions); the ``onnx`` package is not
    needed.

    Raises:
        InputFileError: the model is missing, not a regular file or larger than ``LIMITS["onnx"]``.
        OnnxModelError: the file is not an ONNX model (not a protobuf ModelProto).
    """
    buf = memoryview(read_bytes(model, kind="onnx"))  # fields are views into it: a large inline tensor is not copied
    found: list[str] = []
    try:
        _locations(buf, "model", found)
    except RecursionError:
        raise OnnxModelError(f"{model}: not an ONNX model onnx:PATH can run (its graphs nest too deep to read); "
                             "onnx:PATH names an exported .onnx model") from None
    except (_NotProtobuf, UnicodeDecodeError) as exc:
        raise OnnxModelError(f"{model}: not an ONNX model (its protobuf cannot be read: {exc}); onnx:PATH names an "
                             "exported .onnx model") from None
    return list(dict.fromkeys(found))


def resolve_model(model: str | Path) -> tuple[Path, list[Path]]:
    """The model's real path (symbolic links resolved) and its external data files, each checked to exist.

    onnxruntime finds external data relative to the directory of the model file it opens, and refuses a file outside
    that directory; a model named through a symbolic link is therefore opened at its real path.

    Raises:
        OnnxModelError: the model is missing or not an ONNX model, or an external data file it names is missing,
            too large or lies outside the model's directory; the message names the model and the file and says how
            to fix it.
        InputFileError: the model is not a regular file or is too large (`external_data_files`).
    """
    given = Path(model)
    if not given.exists():
        raise OnnxModelError(f"{given}: file not found; onnx:PATH names an exported .onnx model")
    path = given.resolve()
    data: list[Path] = []
    for location in external_data_files(path):
        where = Path(os.path.normpath(path.parent / location))  # lexically: the data file may be a link itself
        if not where.is_relative_to(path.parent):
            raise OnnxModelError(
                f"{given}: the model keeps weights in the external data file {location!r}, outside its directory "
                f"{path.parent}; onnxruntime reads external data only from the model's own directory: re-export "
                "with the data beside the model, or with external_data=False (torch.onnx.export) to keep the "
                "weights inside it")
        if not where.is_file():
            raise OnnxModelError(
                f"{given}: the model keeps its weights in the external data file {location!r}, and {where} does not "
                f"exist; keep {location} beside {path.name} (copy or move the two together), or re-export with "
                "external_data=False (torch.onnx.export(..., external_data=False)) to keep the weights inside the "
                "model")
        size = where.stat().st_size
        if size > LIMITS["onnx"]:
            raise OnnxModelError(f"{given}: its external data file {location!r} holds {size >> 20} MiB, more than "
                                 f"the {LIMITS['onnx'] >> 20} MiB an ONNX file may have")
        data.append(where)
    return path, data


def open_session(model: str | Path) -> Any:
    """An onnxruntime session on one CPU thread, of the model and its external data files (`resolve_model`).

    Raises:
        MissingExtraError: onnxruntime is not installed (the message names the ``onnx`` extra).
        OnnxModelError: the file is missing or not a model onnxruntime can run, or an external data file it names is
            missing; a valid model with an operator onnxruntime does not implement for its element type (a float64
            Elu, say) is named as such, with the operator, and asked for in float32.
    """
    path, _ = resolve_model(model)
    ort = require("onnxruntime", "onnx")
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    opts.inter_op_num_threads = 1
    opts.log_severity_level = 3  # errors only: the arena's workers print nothing per trial
    try:
        return ort.InferenceSession(str(path), sess_options=opts, providers=["CPUExecutionProvider"])
    except Exception as exc:  # noqa: BLE001 (onnxruntime raises its own types; all mean "cannot run this file")
        missing = _MISSING_KERNEL.search(str(exc))
        if missing is not None:
            node = f", node {missing['node']!r}" if missing["node"] else ""
            raise OnnxModelError(
                f"{model}: a valid ONNX model that onnxruntime {ort.__version__} cannot run: it has no implementation "
                f"of its {missing['op']} operator (version {missing['version']}{node}) for the element type or the "
                "operator version the model uses (a float64 model meets this most: onnxruntime implements few "
                "operators in double); export the network in float32 (torch: model.float() and a float32 example "
                "input)") from None
        raise OnnxModelError(f"{model}: not an ONNX model onnxruntime can run, or a damaged one "
                             f"({type(exc).__name__}: {_one_line(exc)}); export it again") from None


def _one_line(exc: BaseException) -> str:
    """An exception's text on one line, cut to a length a message can hold (onnxruntime's span several lines)."""
    text = " ".join(str(exc).split())
    return text if len(text) <= 300 else f"{text[:270]}... ({len(text)} characters)"


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


def _carried_state(inputs: list, outputs: list, extra: list[str], actions: str | None) -> tuple[str, str] | None:
    """An input in `extra` and an output of the same shape and type (``h_in``, ``h_out``), or None.

    The actions' output (`actions`, the I/O file's ``[onnx] output``, or else the first) is not such an output.

    Such a pair is a recurrent network's state, which its caller feeds back at the next call: the controller feeds
    the observation only, so no export without it runs the same policy, and the message says so.
    """
    for port in inputs:
        if port.name not in extra:
            continue
        for out in outputs if actions is not None else outputs[1:]:
            if out.name != actions and list(out.shape) == list(port.shape) and out.type == port.type:
                return port.name, out.name
    return None


def check_model(session: Any, io: OnnxIo, model: str | Path) -> NetworkPorts:
    """Check the network against its I/O file and against what the controller feeds it, then run it once.

    The graph must take exactly one input, the observation the controller feeds (named by ``[onnx] input``, or the
    only one): an input beyond it would be left unfed and fail in the first `OnnxController.act`. Its element type
    is float or double, its shape ``[size]`` or ``[batch, size]`` with a batch of 1 (or free) and the I/O file's
    input size; the output read (``[onnx] output``, or the first) is float or double with one entry per joint (a
    model of several outputs whose first is not the actions is refused with each output's size: the I/O file names
    the output to read). The graph is then run once on the zero observation: it must answer with one finite action
    per joint.

    Raises:
        OnnxModelError: a mismatch, or a graph that fails or answers wrongly on the zero observation; the message
            names the model, the I/O file's field and both values.
    """
    inputs, outputs = session.get_inputs(), session.get_outputs()
    names = [i.name for i in inputs]
    if io.input_name is not None and io.input_name not in names:
        raise OnnxModelError(f"{io.path}: [onnx] input: {model} has no input {io.input_name!r}; its inputs: "
                             f"{', '.join(names)}")
    others = [name for name in names if name != io.input_name] if len(inputs) > 1 else []
    state = _carried_state(inputs, outputs, others, io.output_name)
    if state is not None:
        raise OnnxModelError(f"{model}: input {state[0]!r} and output {state[1]!r} carry a state from one call to the "
                             f"next (a recurrent policy: a GRU's or an LSTM's hidden state); recurrent policies are "
                             "not supported: the controller calls the network on the observation alone and keeps "
                             "no state between calls. Give the network its past as observation history instead "
                             f"(history, or a term's own history, in {io.path} [observation]) and train and export "
                             "a network whose only input is the observation")
    if io.input_name is None and len(inputs) != 1:
        raise OnnxModelError(f"{model}: the network has {len(inputs)} inputs ({', '.join(names) or 'none'}); the "
                             "controller feeds one, the observation: export the network with the observation as its "
                             f"only input (and name it in {io.path} [onnx] input)")
    port = inputs[0] if io.input_name is None else inputs[names.index(io.input_name)]
    extra = [name for name in names if name != port.name]
    if extra:
        raise OnnxModelError(f"{model}: input {extra[0]!r} ({len(extra)} besides the observation {port.name!r}: "
                             f"{', '.join(extra)}) would be left unfed; the controller feeds the observation only: "
                             "export the network with the observation as its only input")
    if port.type not in _DTYPES:
        raise OnnxModelError(f"{model}: input {port.name!r} is a {port.type}; the controller feeds tensor(float) "
                             "or tensor(double): export the network in float32 (torch: model.float() and a float32 "
                             "example input)")
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
    if not outputs:
        raise OnnxModelError(f"{model}: the network has no output; it must output the joints' actions")
    out = outputs[0] if io.output_name is None else outputs[out_names.index(io.output_name)]
    if out.type not in _DTYPES:
        raise OnnxModelError(f"{model}: output {out.name!r} is a {out.type}; the actions must be tensor(float) or "
                             "tensor(double): export the network in float32 (torch: model.float() and a float32 "
                             "example input)")
    out_size = _size(list(out.shape))
    if out_size is not None and out_size != io.num_joints and io.output_name is None and len(outputs) > 1:
        _unnamed_output(io, model, [(o.name, _size(list(o.shape))) for o in outputs])
    if out_size is not None and out_size != io.num_joints:
        raise OnnxModelError(f"{io.path}: [policy] joints: {io.num_joints} joints listed, but {model} output "
                             f"{out.name!r} has {out_size} entries; list the network's joints in its order")
    ports = NetworkPorts(input_name=port.name, output_name=out.name, dtype=_DTYPES[port.type],
                         batched=len(shape) == 2)
    _dry_run(session, ports, io, model)
    return ports


def _unnamed_output(io: OnnxIo, model: str | Path, sizes: list[tuple[str, int | None]]) -> None:
    """Refuse a model of several outputs whose first, read by default, is not the joints' actions.

    Args:
        io: the I/O file, which names no ``[onnx] output``.
        model: the model, as named.
        sizes: each output's name and entries (None: fixed only at run time), in the model's order.

    Raises:
        OnnxModelError: always; the message lists the outputs with their sizes and says which to name.
    """
    n = io.num_joints

    def entries(size: int | None) -> str:
        return "size fixed at run time" if size is None else f"{size} {'entry' if size == 1 else 'entries'}"

    listed = ", ".join(f"{name!r} ({entries(size)})" for name, size in sizes)
    fits = [name for name, size in sizes if size == n]
    if len(fits) == 1:
        fix = f'set [onnx] output = "{fits[0]}" (the output with {n} entries)'
    else:
        which = "none has" if not fits else f"{', '.join(map(repr, fits))} have"
        fix = f'set [onnx] output = "NAME", the output that holds the actions ({which} {n} entries)'
    raise OnnxModelError(f"{io.path}: [onnx] output: not set, and {model} has {len(sizes)} outputs: {listed}; the "
                         f"first, {sizes[0][0]!r}, read by default, is not one action per joint ({n}): {fix}")


def _dry_run(session: Any, ports: NetworkPorts, io: OnnxIo, model: str | Path) -> None:
    """Run the network once on the zero observation: it must answer with one finite action per joint."""
    x = np.zeros(io.input_size, dtype=ports.dtype)
    try:
        out = session.run([ports.output_name], {ports.input_name: x[None] if ports.batched else x})[0]
    except Exception as exc:  # noqa: BLE001 (onnxruntime raises its own types; all mean "this graph cannot run")
        raise OnnxModelError(f"{model}: the network fails on the observation the controller feeds ({io.input_size} "
                             f"zeros): {type(exc).__name__}: {_one_line(exc)}; export it again") from None
    action = np.asarray(out, dtype=np.float64)
    outputs = session.get_outputs()
    if action.size != io.num_joints and io.output_name is None and len(outputs) > 1:
        try:
            every = session.run(None, {ports.input_name: x[None] if ports.batched else x})
        except Exception:  # noqa: BLE001 (the output read ran; another may not: its size is then unknown)
            every = [None] * len(outputs)
        _unnamed_output(io, model, [(o.name, None if v is None else int(np.asarray(v).size))
                                    for o, v in zip(outputs, every, strict=True)])
    if action.size != io.num_joints:
        raise OnnxModelError(f"{io.path}: [policy] joints: {io.num_joints} joints listed, but {model} answers with "
                             f"{action.size} actions (shape {list(action.shape)}); list the network's joints in its "
                             "order")
    if not np.all(np.isfinite(action)):
        raise OnnxModelError(
            f"{model}: the network answers the zero observation ({io.input_size} zeros, all finite) with non-finite "
            f"actions: {_non_finite_entries(action.reshape(-1), io, ports.output_name)}. A finite input gave them, so "
            "they arise inside the network; likely causes: weights or normalisation statistics that hold NaN or "
            "infinity (a training run that diverged, a damaged copy or export), or an operation undefined at this "
            "input (a division by a zero standard deviation, the log or square root of zero or less). Run the "
            "network on the same input where it was trained to tell them apart")


def _non_finite_entries(action: np.ndarray, io: OnnxIo, output: str) -> str:
    """The non-finite entries of one action, by their place and joint in the network's order (its I/O file's)."""
    bad = np.flatnonzero(~np.isfinite(action))
    entries = ", ".join(f"{i} ({io.joints[i]}) {action[i]}" for i in bad)
    return (f"output {output!r} entr{'y' if bad.size == 1 else 'ies'} {entries} ({bad.size} of {action.size}, in the "
            f"network's joint order, {io.path} [policy] joints)")


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
        forces = [t.contact_force for t in io.terms if t.source is not None]
        # the base estimator behind the estimated terms (one, whatever their number: the I/O file gives them one
        # contact force), and the last state folded into it with its velocity in the body frame
        self.estimate = BaseEstimate(desc, 1.0 / self.rate_hz, contact_force=forces[0]) if forces else None
        self._folded: tuple[RobotState, np.ndarray] | None = None
        self.estimated_terms = tuple(dict.fromkeys(t.name for t in io.terms if t.source is not None))
        self._recorded: dict[int, np.ndarray] | None = None  # a replay's values for the next act (`feed_recorded`)
        self.model_path = str(model_path)
        self._steps = 0  # acts since the last reset: the step a non-finite action is reported at

    def reset(self) -> None:
        """Forget the previous action, the observation history and the base estimate."""
        self.last_action = np.zeros_like(self.last_action)
        for w in self._windows:
            w[:] = 0.0
        self._fresh = True
        if self.estimate is not None:
            self.estimate.reset()
        self._folded = None
        self._recorded = None
        self._steps = 0

    def feed_recorded(self, values: Mapping[int, np.ndarray]) -> None:
        """For the next `act` only, the network sees `values` in place of these estimated terms' (`EstimatesTerms`).

        ``wbc check-controller --replay`` feeds an estimated term the recording's values: a trainer records the
        simulator's truth, which no estimate equals, and with it the rest of the policy is checked against the
        recorded actions exactly. The estimator still folds the state in, and ``observation_terms`` reports it.

        Args:
            values: by the term's position in the I/O file's terms, its values as the network saw them (scaled and
                clipped).

        Raises:
            ConfigError: a position is not an estimated term's, or a value's size is not the term's.
        """
        terms = self.io.terms
        checked = {}
        for i, value in values.items():
            if not (0 <= i < len(terms) and terms[i].source is not None):
                raise ConfigError(f"{self.io.path}: term {i} is not an estimated term; the estimated ones: "
                                  f"{[j for j, t in enumerate(terms) if t.source is not None]}")
            v = np.asarray(value, dtype=np.float64).reshape(-1)
            if v.size != terms[i].size:
                raise ConfigError(f"{self.io.path}: term {i} ({terms[i].name}) has {terms[i].size} entries, the "
                                  f"values fed to it {v.size}")
            checked[i] = v
        self._recorded = checked

    def _velocity_in_body(self, state: RobotState) -> np.ndarray:
        """The estimated base velocity in the body frame after folding `state` in, once per state (3,) [m/s].

        The observation of a state may be asked for before `act` on it (``observation_terms``, a replay's
        comparison): the same state object is folded into the filter once, so `act` sees the same frame.
        """
        folded = self._folded
        if folded is not None and folded[0] is state:
            return folded[1]
        est = self.estimate.update(state)
        velocity = quat_to_matrix(est.base_quat).T @ est.base_linvel_in_world
        self._folded = (state, velocity)
        return velocity

    def _term(self, name: str, state: RobotState, command: VelocityCommand) -> np.ndarray:
        if name == "base_lin_vel":
            return self._velocity_in_body(state)
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

    def observation_terms(self, state: RobotState, command: VelocityCommand) -> list[tuple[str, np.ndarray]]:
        """This tick's observation frame as (term name, values), in the I/O file's order.

        ``wbc check-controller --replay`` compares it with a recording, term by term. Nothing changes but the base
        estimate, which folds `state` in as `act` on the same state would (once: `act` then feeds the same frame).
        """
        return [(term.name, part) for term, part in zip(self.io.terms, self.observation(state, command), strict=True)]

    def network_input(self, state: RobotState, command: VelocityCommand) -> np.ndarray:
        """Push this tick's observation into the history and return the network's input, (input_size,)."""
        parts = self.observation(state, command)
        recorded, self._recorded = self._recorded, None
        if recorded:
            for i, value in recorded.items():
                parts[i] = value
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
        """One policy step.

        Raises:
            OnnxModelError: the network returned the wrong number of actions, or a non-finite one (NaN, or an
                infinity the action clip does not bound): the message names the model, each such output entry with
                its joint in the network's order, the step since `reset` and its time, and whether the input was
                finite.
        """
        step, self._steps = self._steps, self._steps + 1
        x = self.network_input(state, command).astype(self.ports.dtype)
        out = self.session.run([self.ports.output_name], {self.ports.input_name: x[None] if self.ports.batched
                                                          else x})[0]
        action = np.asarray(out, dtype=np.float64).reshape(-1)
        if action.shape[0] != self.io.num_joints:
            raise OnnxModelError(f"{self.io.path}: the network returned {action.shape[0]} actions for "
                                 f"{self.io.num_joints} joints")
        if self.io.action_clip is not None:
            action = np.clip(action, -self.io.action_clip, self.io.action_clip)
        if not np.all(np.isfinite(action)):
            raise OnnxModelError(self._non_finite(action, x, step))
        self.last_action = action
        target = np.empty_like(action)
        target[self._index] = self.default_q + self.action_scale * action
        return MotorCommand(q=target, dq=self._zeros, kp=self._kp, kd=self._kd, tau=self._zeros)

    def counters(self) -> dict[str, int]:
        """No events."""
        return {}

    def _non_finite(self, action: np.ndarray, x: np.ndarray, step: int) -> str:
        """Why `act` refuses the network's `action` at `step`: what it returned, when, and on what input."""
        bad_in = np.flatnonzero(~np.isfinite(x))
        fed = ("its input was finite, so they arose inside the network (an operation undefined for this input, or "
               "a value beyond its float range)" if not bad_in.size else
               f"its input held {bad_in.size} non-finite entries (the first at entry {int(bad_in[0])}), from the "
               "robot's state or the command")
        entries = _non_finite_entries(action, self.io, self.ports.output_name)
        return (f"{self.model_path}: the network returned non-finite actions at step {step} after reset (t = "
                f"{step / self.rate_hz:.3f} s at {self.rate_hz:g} Hz): {entries}; {fed}")


def _verify_external_data(model: Path, io: OnnxIo, io_path: Path, data: list[Path],
                          hashed: tuple[SourceFile, ...]) -> None:
    """The external data files against ``[onnx] external_data_sha256``.

    With ``[onnx] sha256`` recorded, every file the model names is listed there, nothing else is, and each one's
    sha256 matches.
    """
    if io.model_sha256 is None:
        return
    # the model names its files relative to its own directory; resolve_model returns them resolved the same way
    found = {os.path.relpath(path, model.resolve().parent): f.sha256 for path, f in zip(data, hashed, strict=True)}
    recorded = dict(io.external_data_sha256)
    if set(found) - set(recorded):
        listing = ", ".join(f'"{location}" = "{digest}"' for location, digest in found.items())
        raise OnnxModelError(f"{io_path}: [onnx] external_data_sha256: {model} keeps its weights in "
                             f"{', '.join(sorted(set(found) - set(recorded)))}, whose sha256 is not recorded, while "
                             "the model's is: the weights would run unchecked. If these files are the ones exported, "
                             f"record them: external_data_sha256 = {{ {listing} }}")
    if set(recorded) - set(found):
        unused = ", ".join(sorted(set(recorded) - set(found)))
        used = ", ".join(found) or "none"
        raise OnnxModelError(f"{io_path}: [onnx] external_data_sha256 names {unused}, which {model} does not use "
                             f"(it uses {used}): the I/O file "
                             "belongs to another export; copy the pair again, or export again")
    for location, digest in found.items():
        if digest != recorded[location]:
            raise OnnxModelError(f"{model}: its external data file {location} has sha256 {digest}, not "
                                 f"{recorded[location]} as {io_path} [onnx] external_data_sha256 records: the "
                                 "weights changed since the export (a damaged copy, or another export's data "
                                 "file); copy the files again, or export again")


def onnx_spec(name: str, model: str | Path, io_file: str | Path | None = None) -> ControllerSpec:
    """Resolve ``onnx:PATH``: read the I/O file, check the model against it, and make the spec.

    Args:
        name: the controller's name (``onnx:PATH``).
        model: the ``.onnx`` file.
        io_file: the I/O file (default: beside the model, `io_path_for`).

    Raises:
        OnnxIoError: the I/O file is missing or invalid (``path:line: [table] key: reason``).
        OnnxModelError: the model is missing, unreadable, damaged (its sha256 differs from the I/O file's
            ``[onnx] sha256``, or onnxruntime cannot load it) or does not fit the I/O file (`check_model`).
        InputFileError: the model or the I/O file is not a regular file or is too large (`wbc.input_files`).
        MissingExtraError: onnxruntime is not installed.
    """
    path = Path(model)
    if not path.exists():
        raise OnnxModelError(f"{path}: file not found; onnx:PATH names an exported .onnx model")
    io_path = Path(io_file) if io_file is not None else io_path_for(path)
    io = load_onnx_io(io_path)
    # the checksum first: a damaged model is named as what it is before any parser reads it
    digest = hashlib.sha256(read_bytes(path, kind="onnx")).hexdigest()
    if io.model_sha256 is not None and digest != io.model_sha256:
        raise OnnxModelError(f"{path}: sha256 {digest} differs from {io.model_sha256}, recorded at export in "
                             f"{io_path} [onnx] sha256: the model changed since it was exported (a damaged copy, or "
                             "another export's model beside this I/O file); copy the pair again, or export again")
    real, data = resolve_model(path)
    data_files = tuple(SourceFile.hashed("external data", f) for f in data)
    _verify_external_data(path, io, io_path, data, data_files)
    check_model(open_session(path), io, path)  # once here, so a mismatch fails before any trial
    make = functools.partial(OnnxController, model_path=str(real), io=io)
    files = (SourceFile(role="model", path=str(real), sha256=digest),
             *data_files, SourceFile.hashed("io", io_path))
    return ControllerSpec(name, io.arm_mode, make, io.summary, robots=(io.robot,), kind="onnx",
                          config_file=str(io_path), files=files)
