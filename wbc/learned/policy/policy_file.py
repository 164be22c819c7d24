"""The torch-free policy format: ``<name>.npz`` (weights, ``allow_pickle=False``) + ``<name>.json`` (metadata).

The JSON says what the numbers mean: the robot and arm mode, the stage, the observation layout and scales, the
action scale, the joint defaults and PD gains the actions were trained with, the network's hidden sizes and
activation, and (when the policy observes the RMA extrinsics z) the privileged parts and the encoder's sizes. The
NPZ holds float arrays only:

    policy/<i>/weight, policy/<i>/bias     linear layers of the policy MLP, (out, in) and (out,)
    obs_mean, obs_std                      observation normaliser: x_n = (x - mean) / (std + normalizer_eps)
    encoder/<i>/weight, encoder/<i>/bias   extrinsics encoder, privileged -> z (with extrinsics only)
    privileged_mean, privileged_std        its normaliser (with extrinsics only)
    adaptation/<i>/weight, .../bias        RMA adaptation module: the last H normalised policy observations,
                                           oldest first, flattened -> z (after RMA phase 2)

A latent z learned from the history alone (a distilled student with memory, `wbc.learned.train.distill`) declares
extrinsics with no privileged parts (``privileged_parts: []``, ``hidden_dims: []``) and an adaptation module: the
file then holds no encoder and no privileged normaliser, and z only ever comes from the history.

A network may drive some of the robot's joints only, as a part of a composite file
(`wbc.learned.policy.composite_policy`, the decoupled baseline): then ``num_actions``, ``default_q``, ``kp`` and ``kd``
are its outputs' joints'.

`load_policy` checks everything against everything before the controller sees a number, and every failure is a
`PolicyFileError` naming the file and the field:

- the files are read through `wbc.input_files` (regular files of bounded size; the JSON's nesting bounded; every
  ``.npz`` member's declared size and header checked before any array is read);
- every field, nested ones included, has its type and a range that keeps a run sane (`check_robot_keys`,
  `check_meta`): ``policy_dt`` a whole number of physics steps between 2 ms and 1 s
  (`wbc.learned.policy.control_rate`), ``clip_actions`` and ``action_scale`` > 0, ``normalizer_eps`` >= 0, the
  joint defaults and PD gains bounded as an ONNX I/O file's are, layer widths and histories bounded;
- the arrays (`check_shapes`): each one the metadata describes and no other, of the shape the network's declared
  sizes give, finite floats; standard deviations >= 0, and > 0 where ``normalizer_eps`` is 0;
- the checksum: ``weights_sha256`` in the JSON is the sha256 of the ``.npz`` file's bytes (what ``sha256sum`` prints),
  written by `save_policy` (and `save_composite`); `load_policy` refuses weights whose sha256 differs. A file without
  the key (an export older than the checksum, or a file written by hand) loads without that check.

`PolicyFile.check_robot` compares a loaded file with a robot.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import re
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from wbc.errors import InputFileError, WbcError
from wbc.input_files import LIMITS, open_npz, read_json, short
from wbc.learned.policy.control_rate import period_problem
from wbc.learned.policy.observations import ObsLayout
from wbc.output_files import replace_files
from wbc.robots.description import ARM_MODES, RobotDescription
from wbc.robots.registry import ROBOTS

__all__ = ["ACTIVATIONS", "CHECKSUM_KEY", "COMPOSITE_FORMAT", "FORMAT", "MAX_HISTORY", "MAX_JOINTS", "MAX_LAYERS",
           "MAX_WIDTH", "VERSION", "PolicyFile", "PolicyFileError", "check_checksum_field", "check_meta",
           "check_robot_keys", "check_shapes", "json_text", "layout_joints", "load_policy", "read_arrays", "read_pair",
           "replace_pair", "save_policy", "weights_sha256"]

FORMAT = "wbc-policy"
COMPOSITE_FORMAT = "wbc-composite-policy"
"""The ``format`` of a composite file (`wbc.learned.policy.composite_policy`), which `load_policy` refuses by name."""
VERSION = 1
ACTIVATIONS = ("elu", "relu", "tanh", "identity")
CHECKSUM_KEY = "weights_sha256"
"""The JSON key holding the sha256 of the ``.npz`` file (64 lowercase hex digits), written at export."""

MAX_JOINTS = 64
"""Most joints a policy may drive or observe (the robots here have 12 or 15)."""
MAX_WIDTH = 65536
"""Widest layer (hidden size, extrinsics dimension, privileged part) a file may declare."""
MAX_LAYERS = 16
"""Most hidden layers a network may declare."""
MAX_HISTORY = 1000
"""Longest observation history (frames) an adaptation module may declare."""

_SHA256 = re.compile(r"[0-9a-f]{64}")
_OBS_SCALE_KEYS = ("ang_vel", "dof_pos", "dof_vel", "command")
_REQUIRED = ("format", "version", "robot", "arm_mode", "task", "stage", "num_actions", "obs_layout", "obs_scales",
             "action_scale", "clip_actions", "default_q", "kp", "kd", "policy_dt", "activation", "hidden_dims",
             "normalizer_eps")
_OPTIONAL = ("extrinsics", "adaptation", "training", CHECKSUM_KEY)
"""The keys a network's metadata may hold besides `_REQUIRED` (``weights_sha256`` at the top level only)."""
_CHUNK = 1 << 20


class PolicyFileError(WbcError, ValueError):
    """A policy file is missing, malformed, or does not fit the robot; the message names the file and the field.

    Args:
        path: the file at fault.
        field_name: the field (``<part>/<field>`` inside a composite's part), or None.
        reason: what is wrong and how to fix it.
        message: the whole message, when it is not ``path: field: reason`` (a reader's error, which names the file
            and line itself).
    """

    def __init__(self, path: str | Path, field_name: str | None, reason: str, message: str | None = None) -> None:
        self.path = str(path)
        self.field = field_name
        self.reason = reason
        if message is None:
            message = f"{self.path}: {field_name}: {reason}" if field_name else f"{self.path}: {reason}"
        super().__init__(message)

    def __reduce__(self) -> tuple[type, tuple[str, str | None, str, str]]:
        """Pickle by the constructor's arguments (an arena worker's failure travels back to the parent)."""
        return type(self), (self.path, self.field, self.reason, str(self))

    @classmethod
    def unreadable(cls, path: str | Path, exc: InputFileError) -> PolicyFileError:
        """The `PolicyFileError` of a file `wbc.input_files` refused; its message is the reader's, unchanged."""
        return cls(path, None, str(exc), message=str(exc))


@dataclass(frozen=True, kw_only=True)
class PolicyFile:
    """A loaded (or to-be-saved) policy.

    Attributes:
        meta: the JSON metadata (see the module docstring; `save_policy` fills ``format``, ``version`` and
            ``weights_sha256``).
        arrays: the NPZ arrays, name -> float array.
    """

    meta: dict[str, Any]
    arrays: dict[str, np.ndarray] = field(repr=False)

    @property
    def num_actions(self) -> int:
        """Actions (actuated joints) of the policy."""
        return int(self.meta["num_actions"])

    def layers(self, prefix: str) -> list[tuple[np.ndarray, np.ndarray]]:
        """(weight, bias) of each linear layer of ``policy`` or ``encoder``, in order."""
        out, i = [], 0
        while f"{prefix}/{i}/weight" in self.arrays:
            out.append((self.arrays[f"{prefix}/{i}/weight"], self.arrays[f"{prefix}/{i}/bias"]))
            i += 1
        return out

    def check_robot(self, desc: RobotDescription, path: str | Path = "<policy>") -> None:
        """Refuse a policy trained for another robot, arm mode or joint defaults.

        Raises:
            PolicyFileError: the mismatch, naming the field and both values.
        """
        m = self.meta
        if m["robot"] != desc.name:
            raise PolicyFileError(path, "robot", f"the policy was trained on {m['robot']!r}, not {desc.name!r}")
        if m["arm_mode"] != desc.arm_mode:
            raise PolicyFileError(path, "arm_mode", f"the policy drives arm mode {m['arm_mode']!r}, the robot has "
                                  f"{desc.arm_mode!r}; pick the controller for that arm mode")
        if self.num_actions != desc.num_joints:
            raise PolicyFileError(path, "num_actions", f"{self.num_actions} actions for a robot with "
                                  f"{desc.num_joints} actuated joints")
        default_q = np.asarray(m["default_q"])
        if not np.allclose(default_q, desc.nominal_q, atol=1e-6):
            raise PolicyFileError(path, "default_q", f"{default_q.tolist()} differs from the robot's nominal pose "
                                  f"{desc.nominal_q.tolist()}")


def _paths(path: str | Path) -> tuple[Path, Path]:
    p = Path(path)
    stem = p.with_suffix("") if p.suffix in (".npz", ".json") else p
    return stem.with_suffix(".npz"), stem.with_suffix(".json")


def read_pair(path: str | Path) -> tuple[Path, Path, dict]:
    """The ``.npz`` and ``.json`` paths of a policy (`path`: either file, or their stem) and the JSON object.

    Raises:
        PolicyFileError: a file of the pair is missing, or the JSON is unreadable (not a regular file, too large,
            not UTF-8, nested too deep, not JSON: `wbc.input_files.read_json`) or not an object.
    """
    npz, js = _paths(path)
    for p in (npz, js):
        if not p.exists():
            raise PolicyFileError(p, None, "file not found (a policy is a .npz + .json pair with the same stem)")
    try:
        meta = read_json(js)
    except InputFileError as exc:
        raise PolicyFileError.unreadable(js, exc) from None
    if not isinstance(meta, dict):
        raise PolicyFileError(js, None, f"expected a JSON object at the top level, got {_kind(meta)}")
    return npz, js, meta


def weights_sha256(npz: str | Path) -> str:
    """The sha256 of a file's bytes, as 64 lowercase hex digits (what ``sha256sum`` prints).

    Raises:
        OSError: the file cannot be read.
    """
    digest = hashlib.sha256()
    with Path(npz).open("rb") as f:
        while chunk := f.read(_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


def save_policy(path: str | Path, policy: PolicyFile) -> tuple[Path, Path]:
    """Write ``<path>.npz`` and ``<path>.json`` (a suffix on `path` is replaced); returns both paths.

    The JSON records the ``.npz`` file's sha256 (``weights_sha256``), which `load_policy` verifies. Each file is
    replaced whole (`wbc.output_files.replace_files`): a write that fails, or a process killed while writing, leaves
    the previous pair as it was. The result is loaded back and checked, so a file that `load_policy` would refuse is
    never left behind silently.

    Raises:
        PolicyFileError: the policy does not pass `load_policy`'s checks (the message names the field).
        OSError: a file cannot be written (the previous pair is then as it was).
    """
    npz, js = _paths(path)
    npz.parent.mkdir(parents=True, exist_ok=True)
    meta = {"format": FORMAT, "version": VERSION, **{k: v for k, v in policy.meta.items()
                                                      if k not in ("format", "version", CHECKSUM_KEY)}}
    weights = io.BytesIO()
    np.savez(weights, **{k: np.asarray(v, dtype=np.float32) for k, v in policy.arrays.items()})
    meta[CHECKSUM_KEY] = hashlib.sha256(weights.getvalue()).hexdigest()
    replace_pair(npz, js, weights.getvalue(), meta)
    load_policy(npz)
    return npz, js


def replace_pair(npz: Path, js: Path, weights: bytes, meta: dict[str, Any]) -> None:
    """Replace a policy's ``.npz`` (`weights`, its bytes) and ``.json`` (`meta`, with the weights' sha256), each whole.

    Both are written beside their names before either is renamed, so a failed write changes neither. The weights are
    renamed first and the JSON last: the JSON names the weights it goes with (their sha256), so once the new JSON is
    in place the new pair is complete, and the one state a reader can find between the two renames (a process killed
    there) is new weights beside the old JSON, which `load_policy` refuses for their checksum (and a resumed or
    re-run export writes again), never a pair that loads with the metadata of other weights.
    """
    replace_files({npz: weights, js: json_text(meta).encode("utf-8")})


def json_text(meta: dict[str, Any]) -> str:
    """A policy file's JSON as `save_policy` writes it: keys sorted, indented by 2, one trailing newline."""
    return json.dumps(meta, indent=2, sort_keys=True, allow_nan=False) + "\n"


def load_policy(path: str | Path) -> PolicyFile:
    """Load and validate a policy (`path`: either file of the pair, or their common stem).

    A JSON with ``weights_sha256`` has its ``.npz`` verified against it; one without (an older export, a file made
    elsewhere) loads without that check.

    Raises:
        PolicyFileError: a file is missing or unreadable, a key is missing, mistyped or out of its range, an array is
            missing, unexpected, misshapen or not finite, the layers do not chain, or the weights' sha256 differs
            from the recorded one; the message names the file and the field.
    """
    npz, js, meta = read_pair(path)
    if meta.get("format") == COMPOSITE_FORMAT:
        raise PolicyFileError(js, "format", f"{COMPOSITE_FORMAT!r}: a composite of several networks; load it with "
                              "wbc.learned.policy.composite_policy.load_composite")
    check_meta(meta, js)
    policy = PolicyFile(meta=meta, arrays=read_arrays(npz, sha256=meta.get(CHECKSUM_KEY), json_path=js))
    check_shapes(policy, npz, js)
    return policy


# -- field checks ---------------------------------------------------------------------------------------------------
def _kind(value: object) -> str:
    """A parsed JSON value's type, as JSON names it."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int | float):
        return "a number"
    names = {str: "a string", list: "an array", dict: "an object"}
    return names.get(type(value), type(value).__name__)


def _fail(js: Path, name: str, reason: str) -> NoReturn:
    raise PolicyFileError(js, name, reason)


def _interval(lo: float, hi: float, lo_open: bool) -> str:
    return f"in {'(' if lo_open else '['}{lo:g}, {hi:g}]"


def _integer(value: Any, js: Path, name: str, lo: int, hi: int, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        _fail(js, name, f"expected an integer ({what}), got {_kind(value)} {short(value, 60)}")
    if not lo <= value <= hi:
        _fail(js, name, f"must be in [{lo}, {hi}] ({what}), got {value}")
    return value


def _number(value: Any, js: Path, name: str, lo: float, hi: float, what: str, *, lo_open: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        _fail(js, name, f"expected a number ({what}), got {_kind(value)} {short(value, 60)}")
    x = float(value)
    if not math.isfinite(x) or not (lo < x if lo_open else lo <= x) or not x <= hi:
        _fail(js, name, f"must be {_interval(lo, hi, lo_open)} ({what}), got {value!r}")
    return x


def _numbers(value: Any, n: int, js: Path, name: str, lo: float, hi: float, what: str, *,
             lo_open: bool = False) -> list[float]:
    if not isinstance(value, list):
        _fail(js, name, f"expected an array of {n} numbers ({what}), got {_kind(value)} {short(value, 60)}")
    if len(value) != n:
        _fail(js, name, f"expected {n} values ({what}), got {len(value)}")
    out = []
    for i, x in enumerate(value):
        if isinstance(x, bool) or not isinstance(x, int | float):
            _fail(js, name, f"expected numbers ({what}), got {_kind(x)} {short(x, 60)} at index {i}")
        if not math.isfinite(x) or not (lo < x if lo_open else lo <= x) or not x <= hi:
            _fail(js, name, f"every value must be {_interval(lo, hi, lo_open)} ({what}), got {x!r} at index {i}")
        out.append(float(x))
    return out


def _string(value: Any, js: Path, name: str, what: str) -> str:
    if not isinstance(value, str) or not value:
        _fail(js, name, f"expected a non-empty string ({what}), got {_kind(value)} {short(value, 60)}")
    return value


def _dims(value: Any, js: Path, name: str) -> list[int]:
    if not isinstance(value, list) or len(value) > MAX_LAYERS:
        _fail(js, name, f"expected an array of at most {MAX_LAYERS} layer widths, got {_kind(value)} "
              f"{short(value, 60)}")
    return [_integer(w, js, f"{name}/{i}", 1, MAX_WIDTH, "a layer's width") for i, w in enumerate(value)]


def _named_sizes(value: Any, js: Path, name: str, *, empty: bool = False) -> list[tuple[str, int]]:
    """``[[name, size], ...]``: non-empty (unless `empty`), each name a string, each size an integer >= 1."""
    if not isinstance(value, list) or not (value or empty):
        _fail(js, name, f"expected a non-empty array of [name, size] pairs, got {_kind(value)} {short(value, 60)}")
    out = []
    for i, entry in enumerate(value):
        if (not isinstance(entry, list) or len(entry) != 2 or not isinstance(entry[0], str)
                or isinstance(entry[1], bool) or not isinstance(entry[1], int)):
            _fail(js, f"{name}/{i}", f"expected a [name, size] pair, got {short(entry, 60)}")
        out.append((entry[0], _integer(entry[1], js, f"{name}/{i}", 1, MAX_WIDTH, "a part's size")))
    return out


def layout_joints(obs_layout: Any, js: Path, name: str, most: int = MAX_JOINTS) -> int:
    """The joints k of an observation layout, which must be this version's `ObsLayout` (k) with 1 <= k <= `most`.

    Raises:
        PolicyFileError: the layout is not one, naming `name`.
    """
    parts = _named_sizes(obs_layout, js, name)
    k = dict(parts).get("dof_pos")
    if k is None or not 0 < k <= most or [list(p) for p in parts] != ObsLayout(k).as_list():
        _fail(js, name, f"{short(obs_layout, 200)} is not this version's layout of 1 to {most} joints "
              f"({ObsLayout(12).as_list()} for 12)")
    return k


def check_robot_keys(meta: dict[str, Any], js: Path, prefix: str = "") -> None:
    """Check the keys that say what the numbers mean on the robot, each typed and ranged.

    Args:
        meta: a single policy's metadata, a composite's, or a composite part's.
        js: the JSON file, for the messages.
        prefix: prepended to the field in messages (``<part>/``).

    Raises:
        PolicyFileError: a key is missing, mistyped or out of range; the message gives the range and why.
    """
    def get(key: str) -> Any:
        if key not in meta:
            _fail(js, prefix + key, "missing key")
        return meta[key]

    _string(get("robot"), js, prefix + "robot", "a robot registry name")
    if meta["robot"] not in ROBOTS:
        _fail(js, prefix + "robot", f"{short(meta['robot'], 60)} is not a robot here; valid: {', '.join(ROBOTS)}")
    if get("arm_mode") not in ARM_MODES:
        _fail(js, prefix + "arm_mode", f"must be one of {', '.join(map(repr, ARM_MODES))}, got "
              f"{short(meta['arm_mode'], 60)}")
    _string(get("task"), js, prefix + "task", "the task it was trained on")
    _integer(get("stage"), js, prefix + "stage", 1, 3, "the training stage")
    n = _integer(get("num_actions"), js, prefix + "num_actions", 1, MAX_JOINTS, "the joints the network drives")
    k = layout_joints(get("obs_layout"), js, prefix + "obs_layout")
    if k < n:
        _fail(js, prefix + "obs_layout", f"observes {k} joints but drives {n} (num_actions); a network observes at "
              "least the joints it drives")
    scales = get("obs_scales")
    if not isinstance(scales, dict) or sorted(scales) != sorted(_OBS_SCALE_KEYS):
        _fail(js, prefix + "obs_scales", f"expected an object with exactly the keys {', '.join(_OBS_SCALE_KEYS)}, "
              f"got {short(scales, 120)}")
    for key in ("ang_vel", "dof_pos", "dof_vel"):
        _number(scales[key], js, f"{prefix}obs_scales/{key}", 0.0, 100.0, "an observation multiplier; the "
                "training env's are > 0", lo_open=True)
    _numbers(scales["command"], 3, js, f"{prefix}obs_scales/command", 0.0, 100.0, "vx, vy and yaw-rate "
             "multipliers", lo_open=True)
    _number(get("action_scale"), js, prefix + "action_scale", 0.0, 10.0, "[rad] per unit action: the target is "
            "default_q + action_scale * action; <= 0 would hold or invert every joint", lo_open=True)
    _number(get("clip_actions"), js, prefix + "clip_actions", 0.0, 1000.0, "actions are clipped to +-clip_actions; "
            "<= 0 would hold every joint at default_q, a controller that never acts", lo_open=True)
    _numbers(get("default_q"), n, js, prefix + "default_q", -2 * math.pi, 2 * math.pi,
             "num_actions joint positions [rad]")
    _numbers(get("kp"), n, js, prefix + "kp", 0.0, 1000.0, "num_actions PD gains [N m / rad]")
    _numbers(get("kd"), n, js, prefix + "kd", 0.0, 100.0, "num_actions PD gains [N m s / rad]")
    dt = get("policy_dt")
    if isinstance(dt, bool) or not isinstance(dt, int | float):
        _fail(js, prefix + "policy_dt", f"expected a number (the control period [s]), got {_kind(dt)} "
              f"{short(dt, 60)}")
    problem = period_problem(float(dt))
    if problem is not None:
        _fail(js, prefix + "policy_dt", problem)


def check_meta(meta: dict[str, Any], js: Path, prefix: str = "") -> None:
    """Check one network's metadata: every key, nested ones included, typed and ranged.

    Args:
        meta: the metadata.
        js: the JSON file, for the messages.
        prefix: prepended to the field in errors (``<part>/`` inside a composite).

    Raises:
        PolicyFileError: a key is missing, mistyped or out of range, or the format, version or activation is
            unknown; the message names the field and the valid values.
    """
    for key in _REQUIRED:
        if key not in meta:
            _fail(js, prefix + key, "missing key")
    unknown = sorted(set(meta) - set(_REQUIRED) - set(_OPTIONAL))
    if unknown:  # a misspelt optional key would otherwise be ignored without a word
        _fail(js, prefix + unknown[0], f"unknown key; a network's keys are {', '.join((*_REQUIRED, *_OPTIONAL))}")
    if meta["format"] != FORMAT:
        _fail(js, prefix + "format", f"expected {FORMAT!r}, got {short(meta['format'], 60)}")
    if isinstance(meta["version"], bool) or meta["version"] != VERSION:
        _fail(js, prefix + "version", f"this wbc reads version {VERSION}, the file is {short(meta['version'], 60)}")
    if meta["activation"] not in ACTIVATIONS:
        _fail(js, prefix + "activation", f"{short(meta['activation'], 60)} is not one of {', '.join(ACTIVATIONS)}")
    check_robot_keys(meta, js, prefix)
    _dims(meta["hidden_dims"], js, prefix + "hidden_dims")
    _number(meta["normalizer_eps"], js, prefix + "normalizer_eps", 0.0, 1.0, "added to each standard deviation "
            "before dividing; rsl-rl's is 0.01, 0 without a normaliser")
    extr = meta.get("extrinsics")
    if extr is not None:
        if not isinstance(extr, dict):
            _fail(js, prefix + "extrinsics", f"expected an object {{dim, hidden_dims, privileged_parts}} or null, "
                  f"got {_kind(extr)}")
        for key in ("dim", "hidden_dims", "privileged_parts"):
            if key not in extr:
                _fail(js, f"{prefix}extrinsics/{key}", "missing key")
        _integer(extr["dim"], js, f"{prefix}extrinsics/dim", 1, MAX_WIDTH, "the size of z")
        _dims(extr["hidden_dims"], js, f"{prefix}extrinsics/hidden_dims")
        if not _named_sizes(extr["privileged_parts"], js, f"{prefix}extrinsics/privileged_parts", empty=True):
            # a latent learned from the history alone: no encoder, and an adaptation module to give z
            if meta.get("adaptation") is None:
                _fail(js, f"{prefix}extrinsics/privileged_parts", "empty, so z can only come from the observation "
                      "history, and the file declares no adaptation module: name the privileged parts the encoder "
                      "reads, or declare the adaptation module")
            if extr["hidden_dims"]:
                _fail(js, f"{prefix}extrinsics/hidden_dims", f"{extr['hidden_dims']} for an encoder of no "
                      "privileged parts: a latent learned from the history has no encoder, use []")
    adapt = meta.get("adaptation")
    if adapt is not None:
        if not isinstance(adapt, dict):
            _fail(js, prefix + "adaptation", f"expected an object {{history, hidden_dims, ...}} or null, got "
                  f"{_kind(adapt)}")
        if extr is None:
            _fail(js, prefix + "adaptation", "an adaptation module needs extrinsics to estimate")
        for key in ("history", "hidden_dims"):
            if key not in adapt:
                _fail(js, f"{prefix}adaptation/{key}", "missing key")
        _integer(adapt["history"], js, f"{prefix}adaptation/history", 1, MAX_HISTORY, "observation frames")
        _dims(adapt["hidden_dims"], js, f"{prefix}adaptation/hidden_dims")
    if not isinstance(meta.get("training", {}), dict):
        _fail(js, prefix + "training", f"expected an object (training metadata), got {_kind(meta['training'])}")
    if CHECKSUM_KEY in meta and prefix:
        _fail(js, prefix + CHECKSUM_KEY, "a part has no checksum of its own; the composite's weights_sha256 covers "
              "its whole .npz: remove the key from the part")
    check_checksum_field(meta, js)


def check_checksum_field(meta: dict[str, Any], js: Path) -> None:
    """Check ``weights_sha256``, when present, is 64 lowercase hex digits.

    Raises:
        PolicyFileError: it is not.
    """
    if CHECKSUM_KEY in meta and (not isinstance(meta[CHECKSUM_KEY], str) or not _SHA256.fullmatch(meta[CHECKSUM_KEY])):
        _fail(js, CHECKSUM_KEY, f"expected 64 lowercase hex digits (the .npz file's sha256, as sha256sum prints it), "
              f"got {short(meta[CHECKSUM_KEY], 80)}")


# -- arrays ---------------------------------------------------------------------------------------------------------
def read_arrays(npz: Path, *, sha256: str | None = None, json_path: Path | None = None) -> dict[str, np.ndarray]:
    """The arrays of a ``.npz`` of plain arrays, its members checked before any is read (`wbc.input_files.open_npz`).

    Args:
        npz: the archive.
        sha256: the sha256 recorded at export (``weights_sha256``), verified before any array is read; None: no
            check.
        json_path: the JSON that recorded it, for the message.

    Raises:
        PolicyFileError: the file is not a readable ``.npz`` of plain arrays (too large, a member claiming more than
            it holds, an object array, a corrupt member), or its sha256 is not `sha256`.
    """
    try:
        data = open_npz(npz)
    except InputFileError as exc:
        # a damaged archive that a checksum covers is named as what it is: weights changed since their export
        if sha256 is not None and npz.is_file() and npz.stat().st_size <= LIMITS["npz"]:
            _verify(npz, sha256, json_path)
        raise PolicyFileError.unreadable(npz, exc) from None
    with data:
        if sha256 is not None:
            _verify(npz, sha256, json_path)
        try:
            return {k: np.asarray(data[k]) for k in data.files}
        except (OSError, ValueError, zipfile.BadZipFile, EOFError, zlib.error) as exc:
            raise PolicyFileError(npz, None, f"not a readable .npz of plain arrays ({type(exc).__name__}: "
                                  f"{short(str(exc), 200)})") from None


def _verify(npz: Path, sha256: str, json_path: Path | None) -> None:
    """Refuse `npz` unless its sha256 is `sha256`."""
    found = weights_sha256(npz)
    if found != sha256:
        where = json_path.name if json_path is not None else "its JSON"
        raise PolicyFileError(npz, None, f"sha256 {found} differs from {sha256}, recorded at export in {where} "
                              f"({CHECKSUM_KEY}): the weights changed since they were exported (a damaged copy, or "
                              "another export's .npz beside this .json); copy the pair again, or export the policy "
                              "again")


def check_shapes(policy: PolicyFile, npz: Path, js: Path) -> None:
    """Check one network's arrays against its (already checked, `check_meta`) metadata.

    Every array the metadata describes is present, of its shape, a finite float array; the normalisers' standard
    deviations are >= 0 (and > 0 where ``normalizer_eps`` is 0); no other array is present.

    Raises:
        PolicyFileError: naming the file and the field.
    """
    m, a = policy.meta, policy.arrays
    n = m["num_actions"]
    obs_size = ObsLayout(layout_joints(m["obs_layout"], js, "obs_layout")).size
    eps = float(m["normalizer_eps"])
    expected = {"obs_mean", "obs_std"}
    _check_normaliser(a, "obs", obs_size, eps, npz)
    extr = m.get("extrinsics")
    z_dim = 0
    if extr is not None:
        z_dim = int(extr["dim"])
        priv_size = sum(size for _, size in extr["privileged_parts"])
        if priv_size:  # none: z is learned from the history alone, there is no encoder
            _check_normaliser(a, "privileged", priv_size, eps, npz)
            expected |= {"privileged_mean", "privileged_std"}
            expected |= _check_chain(policy, "encoder", priv_size, z_dim, list(extr["hidden_dims"]), npz)
    adapt = m.get("adaptation")
    if adapt is not None:
        expected |= _check_chain(policy, "adaptation", int(adapt["history"]) * obs_size, z_dim,
                                 list(adapt["hidden_dims"]), npz)
    expected |= _check_chain(policy, "policy", obs_size + z_dim, n, list(m["hidden_dims"]), npz)
    stray = sorted(set(a) - expected)
    if stray:
        raise PolicyFileError(npz, stray[0], "an array the metadata does not describe (with extrinsics "
                              f"{'declared' if extr is not None else 'null'}, adaptation "
                              f"{'declared' if adapt is not None else 'null'}, hidden_dims {m['hidden_dims']}); "
                              "export the policy again, or fix the JSON")


def _check_normaliser(a: dict[str, np.ndarray], name: str, size: int, eps: float, npz: Path) -> None:
    _check_array(a, f"{name}_mean", (size,), npz)
    key = f"{name}_std"
    _check_array(a, key, (size,), npz)
    std = a[key]
    bad = np.flatnonzero(std < 0.0)
    if bad.size:
        raise PolicyFileError(npz, key, f"{bad.size} negative standard deviations (first {float(std[bad[0]])!r} at "
                              f"index {int(bad[0])}); a standard deviation is >= 0: the file was edited or "
                              "mis-exported")
    if eps == 0.0:
        zero = np.flatnonzero(std == 0.0)
        if zero.size:
            raise PolicyFileError(npz, key, f"standard deviation 0 at index {int(zero[0])} with normalizer_eps 0 "
                                  "divides by zero; set normalizer_eps > 0 (rsl-rl uses 0.01)")


def _check_array(a: dict[str, np.ndarray], key: str, shape: tuple[int, ...], npz: Path) -> None:
    if key not in a:
        raise PolicyFileError(npz, key, "missing array")
    if a[key].shape != shape:
        raise PolicyFileError(npz, key, f"expected shape {shape}, got {a[key].shape}")
    if not np.issubdtype(a[key].dtype, np.floating):
        raise PolicyFileError(npz, key, f"expected floats, got {a[key].dtype}")
    finite = np.isfinite(a[key])
    if not finite.all():
        first = tuple(int(i) for i in np.argwhere(~finite)[0])
        raise PolicyFileError(npz, key, f"{int((~finite).sum())} values are not finite (first at index {first}); "
                              "the weights are damaged, or training diverged")


def _check_chain(policy: PolicyFile, prefix: str, n_in: int, n_out: int, hidden: list[int], npz: Path) -> set[str]:
    """Check the layers ``prefix/<i>/{weight,bias}`` chain ``n_in -> *hidden -> n_out``; return their names."""
    dims = [n_in, *hidden, n_out]
    names = set()
    for i in range(len(dims) - 1):
        _check_array(policy.arrays, f"{prefix}/{i}/weight", (dims[i + 1], dims[i]), npz)
        _check_array(policy.arrays, f"{prefix}/{i}/bias", (dims[i + 1],), npz)
        names |= {f"{prefix}/{i}/weight", f"{prefix}/{i}/bias"}
    extra = f"{prefix}/{len(dims) - 1}/weight"
    if extra in policy.arrays:
        raise PolicyFileError(npz, extra, f"more layers than hidden_dims {hidden} says")
    return names
