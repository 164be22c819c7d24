"""The I/O file of an ONNX policy: what the network eats and what its outputs mean, checked line by line.

A policy trained elsewhere (legged_gym, Isaac Lab, mjlab, MuJoCo Playground ...) and exported to ONNX runs in the
arena as ``onnx:PATH``; the TOML file beside it (``PATH`` with the suffix ``.toml``, or ``--io FILE``) declares:

- ``[policy]``: ``robot`` (a registry name) and ``arm_mode`` it drives; ``rate_hz`` (its control rate [Hz]: 1 to 500
  Hz, its period a whole number of the arena's 2 ms physics steps, `wbc.learned.policy.control_rate`);
  ``joints``, the network's joint order as the robot's joint names (every joint of the robot once: this is the map
  from the network's order to the house order); ``default_q`` (optional, [rad], the network's order; default: the
  robot's nominal pose); ``summary`` (optional, one line).
- ``[onnx]`` (optional): ``input`` and ``output``, the names of the network's input and output (default: its only
  input, its first output); ``sha256``, the sha256 of the ``.onnx`` file (64 lowercase hex digits, what ``sha256sum``
  prints), which `wbc.control.onnx_policy.onnx_spec` verifies before any trial. ``wbc``'s own export
  (`wbc.learned.train.onnx_export`) writes it; an I/O file without it (a policy exported elsewhere) runs its model
  unchecked. A model that keeps its weights in external data files has those checked too:
  ``external_data_sha256`` is a table of each file's ``location`` (as the model names it) and its sha256, required
  with ``sha256`` for such a model (the weights are what a checksum is for), every file named once.
- ``[observation]``: ``history`` (frames of each term the network sees, default 1), ``history_order`` (``frames``:
  whole observation frames stacked oldest first, legged_gym style; ``terms``: each term's own history, oldest first,
  then the next term, Isaac Lab style), ``history_fill`` (after a reset the history holds the first observation,
  ``first``, or zeros, ``zeros``), ``clip`` (optional: the whole vector clipped to [-clip, clip] after scaling) and
  the terms in order, ``[[observation.terms]]``: ``name`` (one of `TERMS`, each once), ``scale`` (a number or one
  per entry, default 1), ``clip`` (optional, a bound c for [-c, c] or an interval, applied after the scale),
  ``history`` (optional, with ``history_order = "terms"`` only). A robot does not measure its base's linear velocity:
  ``base_lin_vel`` takes ``source = "estimator"`` (required: the policy then sees the state estimator's estimate
  where it trained on the simulator's truth, and the file says so) and ``contact_force`` (optional, default 15: the
  foot sensor reading at which the estimator trusts a foot as standing [N, or a real robot's sensor counts]).
- ``[action]``: ``kind = "joint_position"`` (targets = default_q + scale * action), ``scale`` (a number or one per
  joint, in [-10, 10] rad per unit action), ``clip`` (optional: the raw action is clipped to [-clip, clip] first;
  ``last_action`` sees the clipped one).
- ``[pd]``: ``kp`` [N m / rad] and ``kd`` [N m s / rad], a number or one per joint (network order), the gains the
  motors track the targets with.

A term a trainer names otherwise (`TRAINER_NAMES`: Isaac Lab's ``joint_vel_rel``) is refused with our name for it.

The file is read through `wbc.input_files.read_toml` (a regular file of at most 1 MiB, UTF-8, nesting bounded, valid
TOML: an `InputFileError` otherwise, naming the file and line). Every bad value is an `OnnxIoError` that reads
``path:line: [table] key: what is wrong``, like a scenario file's.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wbc.control.errors import OnnxIoError
from wbc.errors import UnknownNameError
from wbc.estimation.filter import DEFAULT_CONTACT_FORCE
from wbc.input_files import read_text, read_toml
from wbc.learned.policy.control_rate import rate_problem
from wbc.robots.description import ARM_MODES, RobotDescription
from wbc.robots.registry import ROBOTS, get_robot
from wbc.scenario.toml_fields import Range, TomlTable, show
from wbc.toml_lines import TomlLines

__all__ = ["ACTION_KINDS", "ESTIMATED", "HISTORY_FILLS", "HISTORY_ORDERS", "NOT_MEASURED",
           "SOURCES", "TERMS", "TRAINER_NAMES", "ObsTerm", "OnnxIo", "io_path_for", "load_onnx_io"]

TERMS: dict[str, str] = {
    "base_lin_vel": "the trunk's linear velocity, body frame (3) [m/s], estimated from the IMU and the legs' "
                    "kinematics (`wbc.estimation.base_estimate`; needs source = \"estimator\")",
    "base_ang_vel": "the trunk's angular velocity from the IMU gyro, body frame (3) [rad/s]",
    "projected_gravity": "unit gravity direction in the body frame, from the IMU quaternion (3)",
    "velocity_commands": "the operator's command (vx [m/s], vy [m/s], yaw rate [rad/s]) (3)",
    "joint_pos_rel": "joint positions minus default_q (one per joint) [rad]",
    "joint_pos": "joint positions (one per joint) [rad]",
    "joint_vel": "joint velocities (one per joint) [rad/s]",
    "last_action": "the previous network output after the action clip, zeros after a reset (one per joint)",
}
"""Observation terms a robot provides, by name (Isaac Lab's names), with what they hold."""

NOT_MEASURED: dict[str, str] = {
    "height_scan": "this robot has no height scanner; retrain the policy blind (without the height scan term)",
}
"""Terms trainers offer that a robot cannot give a controller, with what to do instead."""

TRAINER_NAMES: dict[str, tuple[str, str]] = {
    "joint_vel_rel": ("joint_vel", "Isaac Lab's joint_vel_rel is our joint_vel (the same, with a zero default "
                                   "velocity)"),
}
"""Terms a trainer names otherwise, by the trainer's name: our name and the correspondence, which an unknown-term
message gives (docs/guides/own-controller.md, the Isaac Lab recipe)."""

ESTIMATED: dict[str, str] = {
    "base_lin_vel": "a robot does not measure its base's linear velocity (RobotState has the IMU and the joint "
                    "encoders only); add source = \"estimator\" to this term to feed the state estimator's estimate "
                    "(IMU and leg kinematics, updated at the policy's rate; the policy trained on the simulator's "
                    "truth), or retrain the policy without it (legged_gym: drop it from compute_observations; Isaac "
                    "Lab: remove the base_lin_vel term)",
}
"""Terms a robot does not measure that the state estimator gives (``source = "estimator"``), with the choice."""

SOURCES = ("estimator",)
"""Where an `ESTIMATED` term comes from: the base estimator (`wbc.estimation.base_estimate.BaseEstimate`)."""

HISTORY_ORDERS = ("frames", "terms")
HISTORY_FILLS = ("first", "zeros")
ACTION_KINDS = ("joint_position",)
_TABLES = ("policy", "onnx", "observation", "action", "pd")
_SHA256 = re.compile(r"[0-9a-f]{64}")
_MAX_EXTERNAL_FILES = 1000  # torch writes one data file, onnx's save one per tensor at most


@dataclass(frozen=True, kw_only=True)
class ObsTerm:
    """One observation term, as the network sees it.

    Attributes:
        name: a key of `TERMS`.
        size: entries per frame.
        scale: multiplier of each entry (size,).
        clip: bounds applied after the scale, or None.
        history: frames of this term in the network's input.
        source: ``estimator`` for an `ESTIMATED` term, None for a measured one.
        contact_force: an estimated term's foot sensor reading at which the estimator trusts a foot as standing
            [N, or sensor counts]; None for a measured term.
    """

    name: str
    size: int
    scale: tuple[float, ...]
    clip: tuple[float, float] | None
    history: int
    source: str | None = None
    contact_force: float | None = None


@dataclass(frozen=True, kw_only=True)
class OnnxIo:
    """A validated I/O file, resolved against its robot.

    Attributes:
        path: the file, as given.
        robot: robot registry name.
        arm_mode: arm mode of the robot it drives.
        rate_hz: control rate [Hz].
        summary: one line for listings.
        joints: the network's joint order (robot joint names).
        house_index: for each network joint, its index in the house order.
        default_q: (network order) [rad].
        input_name: the network input's name, or None for its only input.
        output_name: the network output's name, or None for its first output.
        model_sha256: the model file's sha256 (hex) to verify, or None: no check.
        external_data_sha256: each external data file's location and sha256 (hex) to verify, in file order (empty:
            none recorded).
        terms: the observation terms, in order.
        history_order: ``frames`` or ``terms``.
        history_fill: ``first`` or ``zeros``.
        obs_clip: bound of the whole observation after scaling, or None.
        action_kind: ``joint_position``.
        action_scale: (network order).
        action_clip: bound of the raw action, or None.
        kp: (network order) [N m / rad].
        kd: (network order) [N m s / rad].
    """

    path: str
    robot: str
    arm_mode: str
    rate_hz: float
    summary: str
    joints: tuple[str, ...]
    house_index: tuple[int, ...]
    default_q: tuple[float, ...]
    input_name: str | None
    output_name: str | None
    terms: tuple[ObsTerm, ...]
    history_order: str
    history_fill: str
    obs_clip: float | None
    action_kind: str
    action_scale: tuple[float, ...]
    action_clip: float | None
    kp: tuple[float, ...]
    kd: tuple[float, ...]
    model_sha256: str | None = None
    external_data_sha256: tuple[tuple[str, str], ...] = ()

    @property
    def num_joints(self) -> int:
        """Joints the network commands."""
        return len(self.joints)

    @property
    def frame_size(self) -> int:
        """Entries of one observation frame (every term once)."""
        return sum(t.size for t in self.terms)

    @property
    def input_size(self) -> int:
        """Entries of the network's input: every term times its history."""
        return sum(t.size * t.history for t in self.terms)


def io_path_for(model: str | Path) -> Path:
    """The I/O file that sits beside an ONNX model: the same path with the suffix ``.toml``."""
    return Path(model).with_suffix(".toml")


def _numbers(table: TomlTable, key: str, sizes: tuple[int, ...], what: str, allowed: Range,
             default: Any = None) -> tuple[float, ...]:
    """A number (broadcast to the largest of `sizes`) or an array of one of `sizes` numbers, each within `allowed`."""
    n = max(sizes)
    if key not in table.data:
        if default is None:
            table.fail(key, f"missing required key; add `{key} = ...` ({what}) to {table.label}", at_header=True)
        return (float(default),) * n
    value = table.data[key]
    items = value if isinstance(value, list) else [value]
    if isinstance(value, list) and len(value) not in sizes:
        table.fail(key, f"expected one number or {' or '.join(map(str, sorted(set(sizes))))} numbers ({what}), "
                   f"got an array of {len(value)}")
    for position, x in enumerate(items, start=1):
        if isinstance(x, bool) or not isinstance(x, int | float):
            at = f" at position {position}" if isinstance(value, list) else ""
            table.fail(key, f"expected a number or an array of numbers ({what}), got {show(x)}{at}")
        if not math.isfinite(x) or x not in allowed:
            at = f" at position {position}" if isinstance(value, list) else ""
            bounded = allowed.lo > -math.inf or allowed.hi < math.inf
            table.fail(key, f"must be {f'{allowed} and ' if bounded else ''}finite, got {x}{at}")
    floats = tuple(float(x) for x in items)
    return floats * n if len(floats) == 1 else floats


def _clip(table: TomlTable, key: str) -> tuple[float, float] | None:
    """A clip: absent, a bound c > 0 for [-c, c], or an interval [lo, hi]."""
    if key not in table.data:
        return None
    value = table.data[key]
    if isinstance(value, list):
        return table.interval(key, Range())
    bound = table.number(key, Range(lo=0.0, lo_open=True))
    return (-bound, bound)


def _external_data_sha256(net: TomlTable, model_sha256: str | None) -> tuple[tuple[str, str], ...]:
    """``[onnx] external_data_sha256``: each external data file's location and sha256.

    Checked for form only here; the model's own list of files is compared in `wbc.control.onnx_policy.onnx_spec`.
    """
    key = "external_data_sha256"
    if key not in net.data:
        return ()
    table = net.data[key]
    if model_sha256 is None:
        net.fail(key, "records the weights' checksums of a model whose own sha256 is not recorded: add [onnx] sha256 "
                      "(the .onnx file's, as sha256sum prints it), or remove both to run the model unchecked")
    if not isinstance(table, dict) or not table:
        net.fail(key, f"expected a table of each external data file's location and its sha256, e.g. "
                      f'{{ "policy.onnx.data" = "<64 hex digits>" }}, got {show(table)}')
    if len(table) > _MAX_EXTERNAL_FILES:
        net.fail(key, f"names {len(table)} files; a model of wbc's size keeps its weights in at most "
                      f"{_MAX_EXTERNAL_FILES}")
    for location, digest in table.items():
        if not (isinstance(digest, str) and _SHA256.fullmatch(digest)):
            net.fail(key, f"{show(location)}: expected 64 lowercase hex digits (the file's sha256, as sha256sum "
                          f"prints it), got {show(digest)}")
    return tuple(table.items())


def _source(term: TomlTable, name: str) -> tuple[str | None, float | None]:
    """A term's ``source`` and ``contact_force``: both for an `ESTIMATED` term (``source`` required), neither else."""
    if name not in ESTIMATED:
        for key in ("source", "contact_force"):
            if key in term.data:
                term.fail(key, f"{name!r} is measured by the robot; only {', '.join(ESTIMATED)} takes a source and "
                          "a contact_force (it is estimated)")
        return None, None
    if "source" not in term.data:
        term.fail("name", f"{name!r}: {ESTIMATED[name]}")
    source = _choice(term, "source", SOURCES, SOURCES[0])
    contact_force = term.number("contact_force", Range(lo=0.0, lo_open=True), DEFAULT_CONTACT_FORCE)
    return source, contact_force


def _choice(table: TomlTable, key: str, valid: tuple[str, ...], default: str) -> str:
    value = table.string(key, default)
    if value not in valid:
        table.fail(key, f"must be one of {', '.join(map(repr, valid))}, got {value!r}")
    return value


def _joints(table: TomlTable, desc: RobotDescription) -> tuple[tuple[str, ...], tuple[int, ...]]:
    valid = desc.joint_names
    value = table.data.get("joints")
    if value is None:
        table.fail("joints", "missing required key; list the network's joints in its order, as the robot's joint "
                   f"names: {', '.join(valid)}", at_header=True)
    if not isinstance(value, list) or not all(isinstance(j, str) for j in value):
        table.fail("joints", f"expected an array of joint names, got {show(value)}")
    unknown = [j for j in value if j not in valid]
    if unknown:
        table.fail("joints", f"{', '.join(map(repr, unknown))} not a joint of {desc.name} (arm {desc.arm_mode}); "
                   f"its joints: {', '.join(valid)}")
    repeated = sorted(j for j, n in Counter(value).items() if n > 1)  # linear: a joint list may be long
    if repeated:
        table.fail("joints", f"{', '.join(map(repr, repeated))} listed more than once; list every joint once")
    listed = set(value)
    missing = [j for j in valid if j not in listed]
    if missing:
        table.fail("joints", f"the network must command every joint of {desc.name} (arm {desc.arm_mode}); missing: "
                   f"{', '.join(missing)} (with the arm locked or absent the robot has its 12 leg joints)")
    return tuple(value), tuple(valid.index(j) for j in value)


def load_onnx_io(path: str | Path) -> OnnxIo:
    """Read and validate an ONNX policy's I/O file (schema in the module docstring).

    Raises:
        OnnxIoError: the file is missing or breaks the schema (a value mistyped or out of its range); ``path:line:
            [table] key: reason``, listing the valid values.
        InputFileError: the file is not a regular file, larger than 1 MiB, not UTF-8, nested too deep or not TOML
            (`wbc.input_files.read_toml`; the message names the file and the line).
    """
    shown = str(path)
    if not Path(path).exists():
        raise OnnxIoError(shown, "file not found; an onnx:PATH policy needs its I/O file beside it (PATH with the "
                          "suffix .toml) or named with --io FILE; an example and a recipe for each trainer: "
                          "docs/guides/own-controller.md, 'A policy from another trainer'")
    data = read_toml(path)
    lines = TomlLines(read_text(path, kind="toml"))
    top = TomlTable(shown, lines, data, "", ("", 0), error=OnnxIoError)
    for key in data:
        if key not in _TABLES:
            raise OnnxIoError(shown, f"unknown table; valid tables: {', '.join(f'[{t}]' for t in _TABLES)}",
                              line=lines.header((key, 0)) or lines.key(("", 0), key), field=f"[{key}]")

    pol = top.sub_table("policy", ("robot", "arm_mode", "rate_hz", "joints", "default_q", "summary"), required=True)
    robot = pol.string("robot")
    if robot not in ROBOTS:
        pol.fail("robot", f"unknown robot {robot!r}; valid robots: {', '.join(sorted(ROBOTS))}")
    arm_mode = pol.string("arm_mode")
    if arm_mode not in ARM_MODES:
        pol.fail("arm_mode", f"must be one of {', '.join(map(repr, ARM_MODES))}, got {arm_mode!r}")
    try:
        desc = get_robot(robot, arm_mode)
    except UnknownNameError as exc:  # pragma: no cover (both names were checked above)
        pol.fail("robot", str(exc))
    rate_hz = pol.number("rate_hz", Range())
    problem = rate_problem(rate_hz)
    if problem is not None:
        pol.fail("rate_hz", problem)
    joints, house_index = _joints(pol, desc)
    n = len(joints)
    nominal = desc.nominal_q
    if "default_q" in pol.data:
        default_q = _numbers(pol, "default_q", (n,), f"{n} joint positions [rad], the network's order",
                             Range(lo=-2 * math.pi, hi=2 * math.pi))
        if not isinstance(pol.data["default_q"], list):
            pol.fail("default_q", f"expected an array of {n} joint positions [rad], got {show(pol.data['default_q'])}")
    else:
        default_q = tuple(float(nominal[i]) for i in house_index)
    summary = pol.string("summary", f"ONNX policy for {robot} (arm {arm_mode}) at {rate_hz:g} Hz")

    net = top.sub_table("onnx", ("input", "output", "sha256", "external_data_sha256"), required=False)
    input_name = net.string("input") if "input" in net.data else None
    output_name = net.string("output") if "output" in net.data else None
    model_sha256 = net.string("sha256") if "sha256" in net.data else None
    if model_sha256 is not None and not _SHA256.fullmatch(model_sha256):
        net.fail("sha256", f"expected 64 lowercase hex digits (the .onnx file's sha256, as sha256sum prints it), got "
                 f"{show(model_sha256)}; remove the key to run the model unchecked")
    external = _external_data_sha256(net, model_sha256)

    obs = top.sub_table("observation", ("history", "history_order", "history_fill", "clip", "terms"), required=True)
    history = obs.integer("history", Range(lo=1, hi=1000), 1)
    order = _choice(obs, "history_order", HISTORY_ORDERS, "frames")
    fill = _choice(obs, "history_fill", HISTORY_FILLS, "first")
    obs_clip = obs.optional_number("clip", Range(lo=0.0, lo_open=True))
    terms: list[ObsTerm] = []
    sizes = {"base_lin_vel": 3, "base_ang_vel": 3, "projected_gravity": 3, "velocity_commands": 3}
    shared_force: float | None = None  # one estimator serves every estimated term
    first_at: dict[str, int] = {}  # each term's position (1-based) where it is first listed
    for position, term in enumerate(obs.table_array("terms", "[[observation.terms]]"), start=1):
        term.check_keys(("name", "scale", "clip", "history", "source", "contact_force"))
        name = term.string("name")
        if name in NOT_MEASURED:
            term.fail("name", f"{name!r}: {NOT_MEASURED[name]}")
        if name not in TERMS:
            ours, why = TRAINER_NAMES.get(name, (None, ""))
            hint = f": {why}; write name = \"{ours}\"" if ours is not None else ""
            term.fail("name", f"unknown term {name!r}{hint}; valid terms: {', '.join(TERMS)}")
        source, contact_force = _source(term, name)
        if contact_force is not None:
            if shared_force is not None and contact_force != shared_force:
                term.fail("contact_force", f"{contact_force:g}, where an earlier estimated term has {shared_force:g}: "
                          "the terms share one estimator; give them the same value")
            shared_force = contact_force
        if name in first_at:
            term.fail("name", f"term {name!r} is listed twice (terms #{first_at[name]} and #{position}); list each "
                      "term once, in the network's order (a term's past frames are its history, not a second entry)")
        first_at[name] = position
        size = sizes.get(name, n)
        if "history" in term.data and order != "terms":
            term.fail("history", "a term's own history needs history_order = \"terms\" in [observation]; with "
                      "\"frames\" every term has the [observation] history")
        terms.append(ObsTerm(
            name=name, size=size,
            scale=_numbers(term, "scale", (1, size), f"1 or {size} multipliers", Range(), default=1.0),
            clip=_clip(term, "clip"),
            history=term.integer("history", Range(lo=1, hi=1000), history),
            source=source, contact_force=contact_force,
        ))

    act = top.sub_table("action", ("kind", "scale", "clip"), required=True)
    kind = _choice(act, "kind", ACTION_KINDS, "joint_position")
    action_scale = _numbers(act, "scale", (1, n), f"1 or {n} multipliers [rad]", Range(lo=-10.0, hi=10.0))
    action_clip = act.optional_number("clip", Range(lo=0.0, lo_open=True))

    pd = top.sub_table("pd", ("kp", "kd"), required=True)
    kp = _numbers(pd, "kp", (1, n), f"1 or {n} gains [N m / rad]", Range(lo=0.0, hi=1000.0))
    kd = _numbers(pd, "kd", (1, n), f"1 or {n} gains [N m s / rad]", Range(lo=0.0, hi=100.0))

    return OnnxIo(path=shown, robot=robot, arm_mode=arm_mode, rate_hz=rate_hz, summary=summary, joints=joints,
                  house_index=house_index, default_q=default_q, input_name=input_name, output_name=output_name,
                  model_sha256=model_sha256, external_data_sha256=external, terms=tuple(terms), history_order=order,
                  history_fill=fill, obs_clip=obs_clip, action_kind=kind, action_scale=action_scale,
                  action_clip=action_clip, kp=kp, kd=kd)
