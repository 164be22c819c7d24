"""The composite policy format: several networks in one ``.npz`` + ``.json`` pair, each commanding its own joints.

Built for the paper's decoupled baseline (Table III): pi2's legs (the locked-arm policy, frozen) plus a separately
trained arm policy. The file embeds both networks instead of referencing pi2's file by path, so a shipped composite is
self-contained, content-hashable, and cannot silently change when pi2 is retrained.

The JSON holds the robot-level keys of a single policy file (robot, arm mode, task, stage, ``num_actions`` = the
robot's actuated joints, the full observation layout and scales, action scale, clip, default pose, PD gains, policy
period, training metadata), ``format`` = ``wbc-composite-policy`` and ``parts``, a list of::

    {"name": "legs", "joints": [0, ..., 11], "meta": {<the part's own policy metadata>}}

Each part is a complete single-network policy (`wbc.learned.policy.policy_file`, checked by the same code) whose outputs
drive ``joints`` of the robot, in order, and whose ``num_actions`` is ``len(joints)``. A part observes the robot's
observation restricted to its own layout (`compatible_indices`: a 12-joint layout sees the legs' entries, a full one
sees everything), and its RMA adaptation module, if any, runs on its own normalised observation history. The NPZ
holds each part's arrays under ``<name>/`` (``legs/policy/0/weight`` ...), plain float arrays only.

`load_composite` also accepts a single policy file, as a composite of one part commanding every joint, so the
controller runs both kinds through one path. Every field is typed and ranged as in a single policy file
(`wbc.learned.policy.policy_file.check_robot_keys`, `check_meta`), and the composite's ``weights_sha256`` (the sha256
of its whole ``.npz``, written by `save_composite`) is verified when present; a part has no checksum of its own. Every
failure is a `PolicyFileError` naming the file and the field.
"""

from __future__ import annotations

import hashlib
import io
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wbc.errors import NetworkMismatchError
from wbc.learned.policy.observations import ObsLayout, compatible_indices
from wbc.learned.policy.policy_file import (
    CHECKSUM_KEY,
    COMPOSITE_FORMAT,
    VERSION,
    PolicyFile,
    PolicyFileError,
    check_checksum_field,
    check_meta,
    check_robot_keys,
    check_shapes,
    layout_joints,
    load_policy,
    read_arrays,
    read_pair,
    replace_pair,
)
from wbc.robots.description import RobotDescription

__all__ = ["ROBOT_KEYS", "CompositePolicyFile", "PolicyPart", "compose", "load_composite", "save_composite"]

ROBOT_KEYS = ("robot", "arm_mode", "task", "stage", "num_actions", "obs_layout", "obs_scales", "action_scale",
              "clip_actions", "default_q", "kp", "kd", "policy_dt")
"""Keys a composite's JSON shares with a single policy file (what the numbers mean on the robot)."""

_SHARED = ("obs_scales", "action_scale", "clip_actions", "policy_dt", "robot")
"""Keys every part must agree on with the composite: one observation and one motor law for the whole robot."""

_NAME = re.compile(r"[a-z][a-z0-9_-]*")


@dataclass(frozen=True, kw_only=True)
class PolicyPart:
    """One network of a composite.

    Attributes:
        name: a lowercase identifier (the arrays' prefix in the NPZ).
        joints: the robot's joint index of each of the network's outputs.
        policy: the network, a complete single policy file (its ``num_actions`` is ``len(joints)``).
    """

    name: str
    joints: tuple[int, ...]
    policy: PolicyFile

    def observation_index(self, num_joints: int) -> np.ndarray:
        """Indices into the robot's (num_joints) policy observation of the entries this part observes."""
        return compatible_indices(ObsLayout(num_joints), ObsLayout(_layout_joints(self.policy.meta["obs_layout"])))


@dataclass(frozen=True, kw_only=True)
class CompositePolicyFile:
    """A loaded (or to-be-saved) composite.

    Attributes:
        meta: the robot-level metadata (`ROBOT_KEYS`, plus ``training`` and, once saved, ``format``/``version``).
        parts: the networks, their joints partitioning ``range(num_actions)``.
    """

    meta: dict[str, Any]
    parts: tuple[PolicyPart, ...]

    @property
    def num_actions(self) -> int:
        """Actuated joints of the robot."""
        return int(self.meta["num_actions"])

    def check_robot(self, desc: RobotDescription, path: str | Path = "<policy>") -> None:
        """Refuse a composite for another robot, arm mode or joint defaults (`PolicyFile.check_robot`).

        Raises:
            PolicyFileError: the mismatch, naming the field and both values.
        """
        PolicyFile(meta=self.meta, arrays={}).check_robot(desc, path)


def compose(parts: list[PolicyPart], *, training: dict[str, Any] | None = None,
            **robot_meta: Any) -> CompositePolicyFile:
    """A composite from its parts; the robot-level keys are given (`ROBOT_KEYS`), checked when saved or loaded.

    Raises:
        NetworkMismatchError: a robot-level key is missing.
    """
    missing = [k for k in ROBOT_KEYS if k not in robot_meta]
    if missing:
        raise NetworkMismatchError(f"compose: missing robot-level keys {missing}; pass every key of ROBOT_KEYS "
                                   "(a part's policy file has them for its joints, see export.decoupled_policy)")
    return CompositePolicyFile(meta={**robot_meta, "training": training or {}}, parts=tuple(parts))


def save_composite(path: str | Path, composite: CompositePolicyFile) -> tuple[Path, Path]:
    """Write ``<path>.npz`` and ``<path>.json``; the result is loaded back and checked. Returns both paths.

    The JSON records the ``.npz`` file's sha256 (``weights_sha256``), which `load_composite` verifies; a part's own
    checksum (a part made from a loaded policy file carries one) is dropped, since the composite's covers it. Each
    file is replaced whole, as `save_policy` replaces its own (`wbc.learned.policy.policy_file.replace_pair`).

    Raises:
        PolicyFileError: the composite does not pass `load_composite`'s checks (the message names the field).
    """
    p = Path(path)
    stem = p.with_suffix("") if p.suffix in (".npz", ".json") else p
    npz, js = stem.with_suffix(".npz"), stem.with_suffix(".json")
    npz.parent.mkdir(parents=True, exist_ok=True)
    arrays, parts = {}, []
    for part in composite.parts:
        for k, v in part.policy.arrays.items():
            arrays[f"{part.name}/{k}"] = np.asarray(v, dtype=np.float32)
        meta = {"format": "wbc-policy", "version": VERSION,
                **{k: v for k, v in part.policy.meta.items() if k not in ("format", "version", CHECKSUM_KEY)}}
        parts.append({"name": part.name, "joints": [int(j) for j in part.joints], "meta": meta})
    meta = {"format": COMPOSITE_FORMAT, "version": VERSION,
            **{k: v for k, v in composite.meta.items() if k not in ("format", "version", "parts", CHECKSUM_KEY)},
            "parts": parts}
    weights = io.BytesIO()
    np.savez(weights, **arrays)
    meta[CHECKSUM_KEY] = hashlib.sha256(weights.getvalue()).hexdigest()
    replace_pair(npz, js, weights.getvalue(), meta)  # each file whole, the JSON last, as `save_policy`
    load_composite(npz)
    return npz, js


def load_composite(path: str | Path) -> CompositePolicyFile:
    """Load and validate a composite, or a single policy file as a composite of one part (named ``policy``).

    Raises:
        PolicyFileError: a file is missing or unreadable, a key or array is missing, mistyped, out of range or
            misshapen, the parts' joints do not partition the robot's, a part disagrees with the composite on the
            observation or the motor law, or the weights' sha256 differs from the recorded one; the message names
            the file and the field (``<part>/<field>`` inside a part).
    """
    npz, js, meta = read_pair(path)
    if meta.get("format") != COMPOSITE_FORMAT:
        single = load_policy(npz)
        top = {k: single.meta[k] for k in ROBOT_KEYS}
        top["training"] = single.meta.get("training", {})
        if CHECKSUM_KEY in single.meta:
            top[CHECKSUM_KEY] = single.meta[CHECKSUM_KEY]
        return CompositePolicyFile(meta=top, parts=(PolicyPart(name="policy", joints=tuple(range(single.num_actions)),
                                                              policy=single),))
    _check_top(meta, js)
    arrays = read_arrays(npz, sha256=meta.get(CHECKSUM_KEY), json_path=js)
    parts, claimed = [], {}
    for i, entry in enumerate(meta["parts"]):
        part = _load_part(entry, i, arrays, meta, npz, js)
        for j in part.joints:
            if j in claimed:
                raise PolicyFileError(js, f"{part.name}/joints", f"joint {j} is also driven by part {claimed[j]!r}")
            claimed[j] = part.name
        parts.append(part)
    missing = sorted(set(range(meta["num_actions"])) - claimed.keys())
    if missing:
        raise PolicyFileError(js, "parts", f"no part drives joints {missing} (num_actions {meta['num_actions']})")
    names = {part.name for part in parts}
    stray = sorted(k for k in arrays if k.split("/", 1)[0] not in names)
    if stray:
        raise PolicyFileError(npz, stray[0], f"array of no part (parts: {', '.join(sorted(names))})")
    return CompositePolicyFile(meta={k: v for k, v in meta.items() if k != "parts"}, parts=tuple(parts))


# -- internals ------------------------------------------------------------------------------------------------------
def _layout_joints(obs_layout: list) -> int:
    return int(dict((str(n), s) for n, s in obs_layout)["dof_pos"])


def _check_top(meta: dict[str, Any], js: Path) -> None:
    if isinstance(meta.get("version"), bool) or meta.get("version") != VERSION:
        raise PolicyFileError(js, "version", f"this wbc reads version {VERSION}, the file is "
                              f"{meta.get('version', 'missing')!r}")
    check_robot_keys(meta, js)
    n = meta["num_actions"]
    if layout_joints(meta["obs_layout"], js, "obs_layout") != n:
        raise PolicyFileError(js, "obs_layout", f"the composite's layout must cover its {n} joints")
    if not isinstance(meta.get("training", {}), dict):
        raise PolicyFileError(js, "training", "expected an object (training metadata)")
    check_checksum_field(meta, js)
    parts = meta.get("parts")
    if not isinstance(parts, list) or not parts:
        raise PolicyFileError(js, "parts", "expected a non-empty array of parts {name, joints, meta}")


def _load_part(entry: Any, i: int, arrays: dict[str, np.ndarray], top: dict[str, Any], npz: Path,
               js: Path) -> PolicyPart:
    if not isinstance(entry, dict) or not {"name", "joints", "meta"} <= entry.keys():
        raise PolicyFileError(js, f"parts/{i}", "expected {name, joints, meta}")
    name = entry["name"]
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise PolicyFileError(js, f"parts/{i}/name", f"expected a lowercase identifier, got {name!r}")
    joints, meta = entry["joints"], entry["meta"]
    n = top["num_actions"]
    if not isinstance(joints, list) or not joints or any(
            isinstance(j, bool) or not isinstance(j, int) or not 0 <= j < n for j in joints):
        raise PolicyFileError(js, f"{name}/joints", f"expected a list of joint indices in [0, {n}), got {joints}")
    if not isinstance(meta, dict):
        raise PolicyFileError(js, f"{name}/meta", "expected a JSON object")
    check_meta(meta, js, prefix=f"{name}/")
    if meta["num_actions"] != len(joints):
        raise PolicyFileError(js, f"{name}/num_actions", f"{meta['num_actions']} outputs for {len(joints)} joints")
    layout_joints(meta["obs_layout"], js, f"{name}/obs_layout", n)
    for key in _SHARED:
        if meta[key] != top[key]:
            raise PolicyFileError(js, f"{name}/{key}", f"{meta[key]!r} differs from the composite's {top[key]!r}")
    for key in ("default_q", "kp", "kd"):
        want = np.asarray(top[key], dtype=np.float64)[joints]
        if len(meta[key]) != len(joints) or not np.allclose(meta[key], want, atol=1e-6):
            raise PolicyFileError(js, f"{name}/{key}", f"{meta[key]} differs from the composite's {want.tolist()} "
                                  "on the part's joints")
    prefix = f"{name}/"
    policy = PolicyFile(meta=meta, arrays={k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)})
    try:
        check_shapes(policy, npz, js)
    except PolicyFileError as exc:
        raise PolicyFileError(exc.path, prefix + (exc.field or ""), exc.reason) from None
    return PolicyPart(name=name, joints=tuple(joints), policy=policy)
