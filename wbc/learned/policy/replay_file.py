"""The replay file: a policy's observation / action pairs with the robot states they came from, as one ``.npz``.

A trainer writes one beside the weights it exports (`wbc.learned.policy.replay_recorder.record_replay`; ``wbc train``
leaves ``policy.replay.npz`` in its run directory and the ONNX export ``<name>.replay.npz`` beside the model), and
``wbc check-controller NAME --replay FILE.npz`` feeds the recorded states to the controller under test: the
observation it builds is compared with the recorded one term by term, and its actions with the recorded actions
(a term the controller estimates, an ONNX policy's ``base_lin_vel``, is fed the recorded values instead).
A controller that passes the contract but reads its inputs in another layout (two observation terms swapped in an
I/O file, a policy trained with another layout) fails there, with the terms named.

The file (``numpy.savez``, no pickled objects) holds, for n recorded control ticks:

    format          "wbc-replay"                          ()
    version         1                                     ()
    robot           robot registry name                   ()
    arm_mode        "none", "locked" or "actuated"        ()
    rate_hz         the policy's control rate [Hz]        ()
    source          what was recorded (optional)          ()
    -- the inputs of every tick: a RobotState (house joint order, J joints of the robot) and the command
    q               joint positions [rad]                 (n, J)
    dq              joint velocities [rad/s]              (n, J)
    imu_quat        IMU orientation (w, x, y, z)          (n, 4)
    gyro_in_body    IMU angular velocity [rad/s]          (n, 3)
    command         (vx [m/s], vy [m/s], yaw rate [rad/s])  (n, 3)
    tick, time, tau_est, accel_in_body, foot_force        optional: (n,), (n,), (n, J), (n, 3), (n, 4); zeros if absent
    -- what the policy saw and did
    obs             one observation frame as the network sees it (scaled, clipped, no history)   (n, D)
    obs_terms       the frame's terms in order, Isaac Lab names (`OBS_TERM_NAMES` values)      (k,) str
    obs_slices      [start, stop) of each term in a frame; contiguous from 0 to D              (k, 2) int
    actions         the network's output after its clip                                         (n, A)
    action_joints   the joint each action drives, by name (optional: the robot's joint order)   (A,) str
    default_q       the joints' positions the actions are offsets from [rad]                    (A,)
    action_scale    target = default_q + action_scale * action                                   (A,)

Ticks are consecutive from a reset (the policy's history and previous action start empty at the first one). A trainer
elsewhere (Isaac Lab, legged_gym) writes the same arrays from its own rollout: ``q`` and ``dq`` in the robot's joint
order as wbc names it (`RobotDescription.joint_names`), ``obs`` and ``actions`` in its network's own order, with
``action_joints`` saying which joint each action drives.

Every failure to read one is a `ReplayFileError` naming the file and the field.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wbc.errors import FileFieldError, UnknownNameError
from wbc.robots.description import ARM_MODES
from wbc.robots.registry import ROBOTS, get_robot
from wbc.types import RobotState, VelocityCommand

__all__ = ["OPTIONAL_STATE_FIELDS", "REPLAY_FORMAT", "REPLAY_VERSION", "Replay", "ReplayFileError", "load_replay",
           "replay_path_for", "save_replay"]

REPLAY_FORMAT = "wbc-replay"
REPLAY_VERSION = 1

OPTIONAL_STATE_FIELDS = ("tick", "time", "tau_est", "accel_in_body", "foot_force")
"""RobotState fields a replay file may leave out (zeros: no policy of wbc observes them)."""


class ReplayFileError(FileFieldError):
    """A replay file is missing, unreadable or inconsistent; ``path: field: what is wrong``."""


def replay_path_for(weights: str | Path) -> Path:
    """The replay file beside exported weights: ``policy.npz`` (or ``.json``, ``.onnx``) -> ``policy.replay.npz``."""
    p = Path(weights)
    stem = p.with_suffix("") if p.suffix in (".npz", ".json", ".onnx") else p
    return stem.with_name(stem.name + ".replay.npz")


@dataclass(frozen=True, kw_only=True)
class Replay:
    """A replay file's content, checked (see the module docstring for what each array holds).

    Attributes:
        path: the file, as given ("" before it is saved).
        robot: robot registry name.
        arm_mode: the robot's arm mode.
        rate_hz: control rate [Hz].
        source: what was recorded.
        states: the RobotState arrays by field name (every field of `RobotState`), each (n, ...).
        command: (n, 3).
        obs: (n, D).
        obs_terms: the terms of a frame, in order.
        obs_slices: [start, stop) of each term.
        actions: (n, A).
        action_joints: the joint each action drives, by name.
        default_q: (A,) [rad].
        action_scale: (A,).
    """

    path: str
    robot: str
    arm_mode: str
    rate_hz: float
    source: str
    states: dict[str, np.ndarray]
    command: np.ndarray
    obs: np.ndarray
    obs_terms: tuple[str, ...]
    obs_slices: tuple[tuple[int, int], ...]
    actions: np.ndarray
    action_joints: tuple[str, ...]
    default_q: np.ndarray
    action_scale: np.ndarray

    def __len__(self) -> int:
        return int(self.obs.shape[0])

    def state(self, k: int) -> RobotState:
        """The robot state of tick `k`."""
        s = self.states
        return RobotState(tick=int(s["tick"][k]), time=float(s["time"][k]), q=s["q"][k].copy(), dq=s["dq"][k].copy(),
                          tau_est=s["tau_est"][k].copy(), imu_quat=s["imu_quat"][k].copy(),
                          gyro_in_body=s["gyro_in_body"][k].copy(), accel_in_body=s["accel_in_body"][k].copy(),
                          foot_force=s["foot_force"][k].copy())

    def velocity_command(self, k: int) -> VelocityCommand:
        """The operator's command of tick `k`."""
        vx, vy, yaw_rate = (float(x) for x in self.command[k])
        return VelocityCommand(vx=vx, vy=vy, yaw_rate=yaw_rate)

    def action_index(self) -> np.ndarray:
        """For each action, its joint's index in the robot's (house) joint order."""
        names = get_robot(self.robot, self.arm_mode).joint_names
        return np.asarray([names.index(j) for j in self.action_joints], dtype=int)


def save_replay(path: str | Path, replay: Replay) -> Path:
    """Write `replay` to `path` (``.npz``); the file is read back and checked. Returns the path.

    Raises:
        ReplayFileError: the content does not pass `load_replay`'s checks.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    arrays = {"format": np.asarray(REPLAY_FORMAT), "version": np.asarray(REPLAY_VERSION),
              "robot": np.asarray(replay.robot), "arm_mode": np.asarray(replay.arm_mode),
              "rate_hz": np.asarray(float(replay.rate_hz)), "source": np.asarray(replay.source),
              **{k: np.asarray(v) for k, v in replay.states.items()}, "command": replay.command, "obs": replay.obs,
              "obs_terms": np.asarray(replay.obs_terms, dtype=str),
              "obs_slices": np.asarray(replay.obs_slices, dtype=np.int64).reshape(-1, 2),
              "actions": replay.actions, "action_joints": np.asarray(replay.action_joints, dtype=str),
              "default_q": replay.default_q, "action_scale": replay.action_scale}
    with open(p, "wb") as f:  # a path without the .npz suffix keeps its name (np.savez would add one)
        np.savez(f, **arrays)
    load_replay(p)
    return p


def _scalar(arrays: dict[str, np.ndarray], path: str, key: str, kind: type) -> object:
    if key not in arrays:
        raise ReplayFileError(path, f"missing array; a replay file holds {key} (see wbc.learned.policy.replay_file)",
                              field=key)
    a = arrays[key]
    if a.shape != ():
        raise ReplayFileError(path, f"expected a single value, got an array of shape {a.shape}", field=key)
    value = a.item()
    if kind is str and not isinstance(value, str):
        raise ReplayFileError(path, f"expected a string, got {value!r}", field=key)
    if kind is float and (isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value)):
        raise ReplayFileError(path, f"expected a finite number, got {value!r}", field=key)
    return value


def _array(arrays: dict[str, np.ndarray], path: str, key: str, shape: tuple[int | None, ...],
           what: str) -> np.ndarray:
    """A finite float array of `shape` (None: any length), named `key`."""
    if key not in arrays:
        raise ReplayFileError(path, f"missing array; expected {what}, shape {_shape(shape)}", field=key)
    a = arrays[key]
    if a.dtype.kind not in "fiu":
        raise ReplayFileError(path, f"expected numbers ({what}), got an array of {a.dtype}", field=key)
    if a.ndim != len(shape) or any(want is not None and got != want for got, want in zip(a.shape, shape, strict=True)):
        raise ReplayFileError(path, f"expected shape {_shape(shape)} ({what}), got {a.shape}", field=key)
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0]
        raise ReplayFileError(path, f"not finite at index {tuple(int(i) for i in bad)}", field=key)
    return a.astype(np.float64)


def _shape(shape: tuple[int | None, ...]) -> str:
    return "(" + ", ".join("n" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"


def _names(arrays: dict[str, np.ndarray], path: str, key: str) -> tuple[str, ...]:
    a = arrays[key]
    if a.ndim != 1 or a.dtype.kind != "U":
        raise ReplayFileError(path, f"expected a 1-d array of names, got {a.dtype} of shape {a.shape}", field=key)
    return tuple(str(x) for x in a)


def _read(path: str) -> dict[str, np.ndarray]:
    p = Path(path)
    if not p.is_file():
        raise ReplayFileError(path, "file not found; record one with wbc.learned.policy.replay_recorder.record_replay "
                              "(wbc train and the ONNX export write <name>.replay.npz beside the weights)")
    try:
        with np.load(p, allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise ReplayFileError(path, f"not a readable .npz file ({type(exc).__name__}: {exc}); write it with "
                              "numpy.savez (see wbc.learned.policy.replay_file)") from None


def load_replay(path: str | Path) -> Replay:
    """Read and check a replay file (format in the module docstring).

    Raises:
        ReplayFileError: the file is missing or unreadable, or an array is missing, mistyped, misshapen, not finite
            or inconsistent with another (rows, the robot's joints, the terms' slices); the message names the file
            and the field and says what was expected.
    """
    shown = str(path)
    arrays = _read(shown)
    if _scalar(arrays, shown, "format", str) != REPLAY_FORMAT:
        raise ReplayFileError(shown, f"expected {REPLAY_FORMAT!r}, got {arrays['format'].item()!r}", field="format")
    version = arrays.get("version")
    if version is None or version.shape != () or version.item() != REPLAY_VERSION:
        raise ReplayFileError(shown, f"this wbc reads version {REPLAY_VERSION}, the file has "
                              f"{None if version is None else version.tolist()}", field="version")
    robot = str(_scalar(arrays, shown, "robot", str))
    if robot not in ROBOTS:
        raise ReplayFileError(shown, f"unknown robot {robot!r}; valid robots: {', '.join(sorted(ROBOTS))}",
                              field="robot")
    arm_mode = str(_scalar(arrays, shown, "arm_mode", str))
    if arm_mode not in ARM_MODES:
        raise ReplayFileError(shown, f"must be one of {', '.join(ARM_MODES)}, got {arm_mode!r}", field="arm_mode")
    try:
        desc = get_robot(robot, arm_mode)
    except UnknownNameError as exc:  # pragma: no cover (both names were checked above)
        raise ReplayFileError(shown, str(exc), field="robot") from None
    rate_hz = float(_scalar(arrays, shown, "rate_hz", float))  # type: ignore[arg-type]
    if not rate_hz > 0:
        raise ReplayFileError(shown, f"must be > 0 [Hz], got {rate_hz}", field="rate_hz")
    source = str(_scalar(arrays, shown, "source", str)) if "source" in arrays else ""

    obs = _array(arrays, shown, "obs", (None, None), "one observation frame per tick")
    n, width = obs.shape
    if n == 0:
        raise ReplayFileError(shown, "no ticks recorded", field="obs")
    joints = desc.num_joints
    states = {
        "q": _array(arrays, shown, "q", (n, joints), f"joint positions of the {joints} joints of {robot} (arm "
                    f"{arm_mode}), one row per tick of obs"),
        "dq": _array(arrays, shown, "dq", (n, joints), "joint velocities"),
        "imu_quat": _array(arrays, shown, "imu_quat", (n, 4), "IMU orientation (w, x, y, z)"),
        "gyro_in_body": _array(arrays, shown, "gyro_in_body", (n, 3), "IMU angular velocity"),
    }
    optional = {"tick": ((n,), np.arange(n)), "time": ((n,), np.arange(n) / rate_hz),
                "tau_est": ((n, joints), np.zeros((n, joints))), "accel_in_body": ((n, 3), np.zeros((n, 3))),
                "foot_force": ((n, 4), np.zeros((n, 4)))}
    for key, (shape, default) in optional.items():
        states[key] = _array(arrays, shown, key, shape, key) if key in arrays else default
    command = _array(arrays, shown, "command", (n, 3), "(vx, vy, yaw rate) per tick")

    if "obs_terms" not in arrays or "obs_slices" not in arrays:
        missing = "obs_terms" if "obs_terms" not in arrays else "obs_slices"
        raise ReplayFileError(shown, "missing array; the observation's layout is its terms' names (obs_terms) and "
                              "their [start, stop) in a frame (obs_slices)", field=missing)
    terms = _names(arrays, shown, "obs_terms")
    slices = arrays["obs_slices"]
    if slices.dtype.kind not in "iu" or slices.shape != (len(terms), 2):
        raise ReplayFileError(shown, f"expected ({len(terms)}, 2) integers, [start, stop) of each of obs_terms, got "
                              f"{slices.dtype} of shape {slices.shape}", field="obs_slices")
    at = 0
    for name, (start, stop) in zip(terms, slices.tolist(), strict=True):
        if start != at or stop <= start:
            raise ReplayFileError(shown, f"term {name!r} spans [{start}, {stop}); the terms must tile a frame in "
                                  f"order, the next starting at {at}", field="obs_slices")
        at = stop
    if at != width:
        raise ReplayFileError(shown, f"the terms cover {at} entries, a frame of obs has {width}", field="obs_slices")
    if len(set(terms)) != len(terms):
        raise ReplayFileError(shown, "a term is listed twice", field="obs_terms")

    actions = _array(arrays, shown, "actions", (n, None), "one action per tick and joint")
    count = actions.shape[1]
    action_joints = _names(arrays, shown, "action_joints") if "action_joints" in arrays else desc.joint_names
    unknown = [j for j in action_joints if j not in desc.joint_names]
    if len(action_joints) != count or unknown or len(set(action_joints)) != count:
        raise ReplayFileError(shown, f"expected the {count} joints the actions drive, once each, named as the robot's "
                              f"joints ({', '.join(desc.joint_names)}); got {list(action_joints)}",
                              field="action_joints")
    default_q = _array(arrays, shown, "default_q", (count,), "the joint positions the actions are offsets from")
    action_scale = _array(arrays, shown, "action_scale", (count,), "the scale of each action")
    if np.any(action_scale == 0.0):
        raise ReplayFileError(shown, "a scale of 0 makes its action unobservable in the motor target; record the "
                              "scale the policy was trained with", field="action_scale")
    return Replay(path=shown, robot=robot, arm_mode=arm_mode, rate_hz=rate_hz, source=source, states=states,
                  command=command, obs=obs, obs_terms=terms, obs_slices=tuple((int(a), int(b)) for a, b in slices),
                  actions=actions, action_joints=tuple(action_joints), default_q=default_q, action_scale=action_scale)
