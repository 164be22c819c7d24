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

A network may drive some of the robot's joints only, as a part of a composite file
(`wbc.learned.policy.composite_policy`, the decoupled baseline): then ``num_actions``, ``default_q``, ``kp`` and ``kd``
are its outputs' joints'.

`load_policy` checks everything against everything (keys, types, shapes, layer chaining, the layout's size) and every
failure is a `PolicyFileError` naming the file and the field; `PolicyFile.check_robot` compares it with a robot.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wbc.errors import WbcError
from wbc.robots.description import RobotDescription

__all__ = ["ACTIVATIONS", "COMPOSITE_FORMAT", "FORMAT", "VERSION", "PolicyFile", "PolicyFileError", "check_meta",
           "check_shapes", "load_policy", "read_arrays", "read_pair", "save_policy"]

FORMAT = "wbc-policy"
COMPOSITE_FORMAT = "wbc-composite-policy"
"""The ``format`` of a composite file (`wbc.learned.policy.composite_policy`), which `load_policy` refuses by name."""
VERSION = 1
ACTIVATIONS = ("elu", "relu", "tanh", "identity")


class PolicyFileError(WbcError, ValueError):
    """A policy file is missing, malformed, or does not fit the robot; the message names the file and the field."""

    def __init__(self, path: str | Path, field_name: str | None, reason: str) -> None:
        self.path = str(path)
        self.field = field_name
        self.reason = reason
        super().__init__(f"{self.path}: {field_name}: {reason}" if field_name else f"{self.path}: {reason}")


@dataclass(frozen=True, kw_only=True)
class PolicyFile:
    """A loaded (or to-be-saved) policy.

    Attributes:
        meta: the JSON metadata (see the module docstring; `save_policy` fills ``format`` and ``version``).
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


_META_TYPES: dict[str, type | tuple[type, ...]] = {
    "format": str, "version": int, "robot": str, "arm_mode": str, "task": str, "stage": int, "num_actions": int,
    "obs_layout": list, "obs_scales": dict, "action_scale": (int, float), "clip_actions": (int, float),
    "default_q": list, "kp": list, "kd": list, "policy_dt": (int, float), "activation": str, "hidden_dims": list,
    "normalizer_eps": (int, float),
}


def _paths(path: str | Path) -> tuple[Path, Path]:
    p = Path(path)
    stem = p.with_suffix("") if p.suffix in (".npz", ".json") else p
    return stem.with_suffix(".npz"), stem.with_suffix(".json")


def read_pair(path: str | Path) -> tuple[Path, Path, dict]:
    """The ``.npz`` and ``.json`` paths of a policy (`path`: either file, or their stem) and the JSON object.

    Raises:
        PolicyFileError: a file of the pair is missing, or the JSON is unreadable or not an object.
    """
    npz, js = _paths(path)
    for p in (npz, js):
        if not p.exists():
            raise PolicyFileError(p, None, "file not found (a policy is a .npz + .json pair with the same stem)")
    try:
        meta = json.loads(js.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PolicyFileError(js, None, f"not readable JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise PolicyFileError(js, None, "expected a JSON object at the top level")
    return npz, js, meta


def save_policy(path: str | Path, policy: PolicyFile) -> tuple[Path, Path]:
    """Write ``<path>.npz`` and ``<path>.json`` (a suffix on `path` is replaced); returns both paths.

    The result is loaded back and checked, so a file that `load_policy` would refuse is never left behind silently.
    """
    npz, js = _paths(path)
    npz.parent.mkdir(parents=True, exist_ok=True)
    meta = {"format": FORMAT, "version": VERSION, **{k: v for k, v in policy.meta.items()
                                                      if k not in ("format", "version")}}
    np.savez(npz, **{k: np.asarray(v, dtype=np.float32) for k, v in policy.arrays.items()})
    js.write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    load_policy(npz)
    return npz, js


def load_policy(path: str | Path) -> PolicyFile:
    """Load and validate a policy (`path`: either file of the pair, or their common stem).

    Raises:
        PolicyFileError: a file is missing or unreadable, a key is missing or mistyped, an array is missing or has
            the wrong shape, or the layers do not chain; the message names the file and the field.
    """
    npz, js, meta = read_pair(path)
    if meta.get("format") == COMPOSITE_FORMAT:
        raise PolicyFileError(js, "format", f"{COMPOSITE_FORMAT!r}: a composite of several networks; load it with "
                              "wbc.learned.policy.composite_policy.load_composite")
    check_meta(meta, js)
    policy = PolicyFile(meta=meta, arrays=read_arrays(npz))
    check_shapes(policy, npz, js)
    return policy


def check_meta(meta: dict[str, Any], js: Path, prefix: str = "") -> None:
    """Check the keys and types of one network's metadata; `prefix` is prepended to the field in errors.

    Raises:
        PolicyFileError: a key is missing or mistyped, or the format, version or activation is unknown.
    """
    for key, types in _META_TYPES.items():
        if key not in meta:
            raise PolicyFileError(js, prefix + key, "missing key")
        value = meta[key]
        if isinstance(value, bool) or not isinstance(value, types):
            raise PolicyFileError(js, prefix + key, f"expected {types}, got {type(value).__name__}")
    if meta["format"] != FORMAT:
        raise PolicyFileError(js, prefix + "format", f"expected {FORMAT!r}, got {meta['format']!r}")
    if meta["version"] != VERSION:
        raise PolicyFileError(js, prefix + "version", f"this wbc reads version {VERSION}, the file is "
                              f"{meta['version']}")
    if meta["activation"] not in ACTIVATIONS:
        raise PolicyFileError(js, prefix + "activation", f"{meta['activation']!r} is not one of "
                              f"{', '.join(ACTIVATIONS)}")


def read_arrays(npz: Path) -> dict[str, np.ndarray]:
    """The arrays of a ``.npz`` of plain arrays (pickles refused).

    Raises:
        PolicyFileError: the file is not a readable ``.npz`` of plain arrays.
    """
    try:
        with np.load(npz, allow_pickle=False) as data:
            return {k: np.asarray(data[k]) for k in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise PolicyFileError(npz, None, f"not a readable .npz of plain arrays ({exc})") from None


def check_shapes(policy: PolicyFile, npz: Path, js: Path) -> None:
    """Check one network's arrays against its metadata (sizes, layer chaining, finiteness).

    Raises:
        PolicyFileError: naming the file and the field.
    """
    m, a = policy.meta, policy.arrays
    n = m["num_actions"]
    try:
        obs_size = sum(int(size) for _, size in m["obs_layout"])
    except (TypeError, ValueError):
        raise PolicyFileError(js, "obs_layout", "expected [[name, size], ...]") from None
    for key in ("default_q", "kp", "kd"):
        if len(m[key]) != n:
            raise PolicyFileError(js, key, f"expected {n} values (num_actions), got {len(m[key])}")
    for key, shape in (("obs_mean", (obs_size,)), ("obs_std", (obs_size,))):
        _check_array(a, key, shape, npz)
    extr = m.get("extrinsics")
    z_dim = 0
    if extr is not None:
        if not isinstance(extr, dict) or not {"dim", "hidden_dims", "privileged_parts"} <= extr.keys():
            raise PolicyFileError(js, "extrinsics", "expected {dim, hidden_dims, privileged_parts} or null")
        z_dim = int(extr["dim"])
        priv_size = sum(int(size) for _, size in extr["privileged_parts"])
        for key in ("privileged_mean", "privileged_std"):
            _check_array(a, key, (priv_size,), npz)
        _check_chain(policy, "encoder", priv_size, z_dim, list(extr["hidden_dims"]), npz)
    adapt = m.get("adaptation")
    if adapt is not None:
        if extr is None:
            raise PolicyFileError(js, "adaptation", "an adaptation module needs extrinsics to estimate")
        if not isinstance(adapt, dict) or not {"history", "hidden_dims"} <= adapt.keys():
            raise PolicyFileError(js, "adaptation", "expected {history, hidden_dims, ...} or null")
        _check_chain(policy, "adaptation", int(adapt["history"]) * obs_size, z_dim, list(adapt["hidden_dims"]), npz)
    _check_chain(policy, "policy", obs_size + z_dim, n, list(m["hidden_dims"]), npz)


def _check_array(a: dict[str, np.ndarray], key: str, shape: tuple[int, ...], npz: Path) -> None:
    if key not in a:
        raise PolicyFileError(npz, key, "missing array")
    if a[key].shape != shape:
        raise PolicyFileError(npz, key, f"expected shape {shape}, got {a[key].shape}")
    if not np.issubdtype(a[key].dtype, np.floating) or not np.all(np.isfinite(a[key])):
        raise PolicyFileError(npz, key, "expected finite floats")


def _check_chain(policy: PolicyFile, prefix: str, n_in: int, n_out: int, hidden: list[int], npz: Path) -> None:
    dims = [n_in, *hidden, n_out]
    for i in range(len(dims) - 1):
        _check_array(policy.arrays, f"{prefix}/{i}/weight", (dims[i + 1], dims[i]), npz)
        _check_array(policy.arrays, f"{prefix}/{i}/bias", (dims[i + 1],), npz)
    extra = f"{prefix}/{len(dims) - 1}/weight"
    if extra in policy.arrays:
        raise PolicyFileError(npz, extra, f"more layers than hidden_dims {hidden} says")
