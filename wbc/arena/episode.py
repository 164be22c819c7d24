"""`Episode`: the log of one played trial, at the control rate, from which every metric is computed.

Per control tick it keeps the command, the measured proprioception needed for energy and arm travel, simulator
truth (base velocity, yaw rate, roll, pitch, configuration) for tracking metrics and replay, and how long the
controller took to act (the runner's timing, for deadline misses). On a robot without simulator truth the base
quantities come from a state estimator instead, and the episode says so (`Episode.base_source`). The pushes the robot
met are kept as arrays (`PushLog`), so a replay draws them from numbers, not from text; so are the transitions of a
safety layer the robot ran behind (`SafetyLog`), with their times and reasons, and the keys an operator pressed during
a hardware trial (`OperatorLog`).
"""

from __future__ import annotations

import dataclasses
import math
import os
import zipfile
import zlib
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import NoReturn

import numpy as np

from wbc.errors import ConfigError, EpisodeError, EpisodeFileError, InputFileError
from wbc.hardware.capabilities import SafetyEventLike
from wbc.input_files import open_npz, short
from wbc.robots.conventions import quat_to_matrices
from wbc.scenario.push import Push
from wbc.scenario.scenario import MAX_DURATION_S
from wbc.types import BaseTruth, RobotState, VelocityCommand

__all__ = ["BASE_SOURCES", "Episode", "EpisodeBuffer", "OperatorLog", "PushLog", "SafetyLog"]

BASE_SOURCES = ("truth", "estimator")
"""Where an episode's base quantities come from: the simulator's (or motion capture's) truth, or the state
estimator from the robot's own sensors (IMU and leg kinematics, `wbc.estimation`)."""


@dataclass(frozen=True, kw_only=True)
class PushLog:
    """Pushes as arrays, one row per push, in the order they were applied.

    Attributes:
        start: when each push began, shape (n,) [s].
        duration: how long each acted, shape (n,) [s].
        force_in_world: force, shape (n, 3) [N].
        offset_in_base: application point in the trunk frame, shape (n, 3) [m].
    """

    start: np.ndarray = field(default_factory=lambda: np.zeros(0))
    duration: np.ndarray = field(default_factory=lambda: np.zeros(0))
    force_in_world: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    offset_in_base: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def __post_init__(self) -> None:
        n = len(self.start)
        shapes = {"start": (n,), "duration": (n,), "force_in_world": (n, 3), "offset_in_base": (n, 3)}
        for name, shape in shapes.items():
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if value.shape != shape:
                raise ConfigError(f"PushLog.{name}: shape {value.shape}, expected {shape} for {n} pushes; build the "
                                  "log with PushLog.of(pushes)")
            object.__setattr__(self, name, value)
        if np.any(self.start < 0.0) or np.any(self.duration <= 0.0):
            raise ConfigError(f"PushLog: every push starts at 0 s or later and lasts some time; got starts "
                              f"{short(str(self.start.tolist()), 80)} and durations "
                              f"{short(str(self.duration.tolist()), 80)}")

    @classmethod
    def of(cls, pushes: Iterable[Push]) -> PushLog:
        """The log of `pushes`."""
        pushes = list(pushes)
        return cls(start=np.array([p.start for p in pushes], dtype=np.float64),
                   duration=np.array([p.duration for p in pushes], dtype=np.float64),
                   force_in_world=np.array([p.force_in_world for p in pushes], dtype=np.float64).reshape(-1, 3),
                   offset_in_base=np.array([p.offset_in_base for p in pushes], dtype=np.float64).reshape(-1, 3))

    def __len__(self) -> int:
        """Number of pushes."""
        return len(self.start)


def _adopt_columns(log: object, keys: tuple[str, ...], rows: str, builder: str) -> None:
    """Check that a frozen log's columns are one per row (`time` float, the others text) and store them as such."""
    kind = type(log).__name__
    n = len(log.time)
    for name in keys:
        value = np.asarray(getattr(log, name))
        if value.shape != (n,):
            raise ConfigError(f"{kind}.{name}: shape {value.shape}, expected ({n},) for {n} {rows}; build the log "
                              f"with {builder}")
        if name == "time":
            value = value.astype(np.float64)
        elif value.dtype.kind != "U":
            if n and value.dtype.kind not in "SU":
                raise ConfigError(f"{kind}.{name}: dtype {value.dtype}, expected text")
            value = value.astype(np.str_)
        object.__setattr__(log, name, value)


@dataclass(frozen=True, kw_only=True)
class SafetyLog:
    """Transitions of a safety layer as arrays, one row per transition, oldest first.

    Attributes:
        time: when each happened, shape (n,) [s]. In an `Episode` it is the episode's own clock (0 at its first
            tick): the runner stores the layer's clock (robot time since the layer was made, which in simulation is
            the episode's), and a hardware trial (`wbc hw run`) moves it by the stand-up before the trial
            (``trial_started_s`` in ``hardware.json``). Results written before that move store the layer's clock;
            ``hardware.json`` without a ``clocks`` key tells them apart (`wbc.viz.replay` moves them when it reads).
        from_state: the state left, shape (n,) (unicode).
        to_state: the state entered, shape (n,) (unicode).
        reason: why, shape (n,) (unicode; a trip's reason names the check that fired).
        detail: what was measured against which limit, shape (n,) (unicode, may be empty).
    """

    time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    from_state: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.str_))
    to_state: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.str_))
    reason: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.str_))
    detail: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.str_))

    def __post_init__(self) -> None:
        _adopt_columns(self, _SAFETY_KEYS, "events", "SafetyLog.of(events)")

    @classmethod
    def of(cls, events: Iterable[SafetyEventLike]) -> SafetyLog:
        """The log of `events` (states by name)."""
        events = list(events)

        def text(name: str) -> np.ndarray:
            return np.array([str(getattr(e, name)) for e in events], dtype=np.str_)

        return cls(time=np.array([e.time for e in events], dtype=np.float64), from_state=text("from_state"),
                   to_state=text("to_state"), reason=text("reason"), detail=text("detail"))

    def __len__(self) -> int:
        """Number of transitions."""
        return len(self.time)

    def shifted(self, by_s: float) -> SafetyLog:
        """The same transitions with `by_s` [s] added to each time (to move them onto another clock)."""
        return dataclasses.replace(self, time=np.asarray(self.time, dtype=np.float64) + by_s)

    def rows(self) -> list[tuple[float, str, str, str, str]]:
        """The transitions as (time, from_state, to_state, reason, detail), oldest first."""
        return [(float(t), str(a), str(b), str(r), str(d)) for t, a, b, r, d in
                zip(self.time, self.from_state, self.to_state, self.reason, self.detail, strict=True)]


@dataclass(frozen=True, kw_only=True)
class OperatorLog:
    """What an operator did during a trial (keys pressed at the terminal), one row per action, oldest first.

    Attributes:
        time: trial time of the control tick at which the action was taken, shape (n,) [s].
        key: the key pressed, shape (n,) (unicode).
        action: what it did, shape (n,) (unicode: ``estop``, ``push`` ...).
    """

    time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    key: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.str_))
    action: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.str_))

    def __post_init__(self) -> None:
        _adopt_columns(self, _OPERATOR_KEYS, "actions", "OperatorLog.of(rows)")

    @classmethod
    def of(cls, rows: Iterable[tuple[float, str, str]]) -> OperatorLog:
        """The log of (time, key, action) rows."""
        rows = list(rows)
        return cls(time=np.array([r[0] for r in rows], dtype=np.float64),
                   key=np.array([r[1] for r in rows], dtype=np.str_),
                   action=np.array([r[2] for r in rows], dtype=np.str_))

    def __len__(self) -> int:
        """Number of actions."""
        return len(self.time)

    def rows(self) -> list[tuple[float, str, str]]:
        """The actions as (time, key, action), oldest first."""
        return [(float(t), str(k), str(a)) for t, k, a in zip(self.time, self.key, self.action, strict=True)]


_OPERATOR_KEYS = ("time", "key", "action")
_SAFETY_KEYS = ("time", "from_state", "to_state", "reason", "detail")
_PUSH_KEYS = ("start", "duration", "force_in_world", "offset_in_base")
_SCALARS = ("duration_s", "control_dt", "fell", "fall_time_s")
_ARRAYS = ("t", "command", "v_base_in_yaw", "yaw_rate", "roll", "pitch", "power", "arm_q", "qpos", "act_s")
_FILE_FIELDS = (*_SCALARS, *_ARRAYS, *(f"push_{k}" for k in _PUSH_KEYS), *(f"safety_{k}" for k in _SAFETY_KEYS),
                *(f"operator_{k}" for k in _OPERATOR_KEYS), "base_source", "clamped_ticks", "clamped_rows")
"""Every member of an episode file (`Episode.save`); a file without one of them is another version's, or damaged."""


@dataclass(frozen=True, kw_only=True)
class Episode:
    """A finished episode; arrays have one row per control tick actually played.

    Attributes:
        duration_s: the trial's planned length [s].
        control_dt: control period [s].
        fell: the robot fell: the trunk or a non-foot link touched the ground (the simulator's fall rule), or the
            truth's trunk was upside down at the last tick. A robot's safety layer that latched its damping (a trip,
            an e-stop) ends the episode too, but that is no fall: ``fell`` is False, the episode holds the ticks
            played up to it (`stopped`), and `safety_events` says why.
        fall_time_s: when it fell (nan if it did not fall: a trip, an e-stop, an interruption or a controller's
            error is not a fall) [s].
        t: time of each tick (after the tick's physics) [s].
        command: commanded (vx, vy, yaw_rate) [m/s, m/s, rad/s], shape (k, 3).
        v_base_in_yaw: base horizontal velocity in the yaw-aligned frame (from `base_source`), shape (k, 2) [m/s].
        yaw_rate: base yaw rate (world z), shape (k,) [rad/s].
        roll: base roll, shape (k,) [rad].
        pitch: base pitch, shape (k,) [rad].
        power: sum over joints of |tau_est * dq|, measured, shape (k,) [W].
        arm_q: measured arm joint positions, shape (k, 3) [rad]; zeros where the arm is not actuated (arm mode
            ``none`` or ``locked``).
        qpos: configuration for replay (base pose from `base_source`, joints measured), shape (k, nq).
        act_s: wall time of each tick's ``controller.act`` call, shape (k,) [s]; a tick whose value exceeds
            `control_dt` missed its deadline on a real robot.
        pushes: the pushes that began before the episode ended.
        safety_events: the transitions of the robot's safety layer during the episode (empty for a robot that has
            none, `wbc.hardware.capabilities.HasSafetyEvents`), at trial time as `t` (see `SafetyLog.time`).
        operator_events: the keys an operator pressed during a hardware trial (a marked push, an e-stop).
        base_source: where `v_base_in_yaw`, `yaw_rate`, `roll`, `pitch` and the base pose in `qpos` come from, one
            of `BASE_SOURCES`: ``truth`` (the simulator) or ``estimator`` (the robot's own sensors).
        clamped_ticks: ticks whose command lay outside the motors' limits (position range, speed, gains, torque),
            so that the robot clamped it before sending (`wbc.hardware.robot.clamp_command`).
        clamped_rows: of those, the ticks each command row was clamped on, in the order q, dq, kp, kd, tau
            (`wbc.hardware.robot.COMMAND_ROWS`).
    """

    duration_s: float
    control_dt: float
    fell: bool
    fall_time_s: float
    t: np.ndarray
    command: np.ndarray
    v_base_in_yaw: np.ndarray
    yaw_rate: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    power: np.ndarray
    arm_q: np.ndarray
    qpos: np.ndarray
    act_s: np.ndarray
    pushes: PushLog = field(default_factory=PushLog)
    safety_events: SafetyLog = field(default_factory=SafetyLog)
    operator_events: OperatorLog = field(default_factory=OperatorLog)
    base_source: str = "truth"
    clamped_ticks: int = 0
    clamped_rows: tuple[int, int, int, int, int] = (0, 0, 0, 0, 0)

    def __post_init__(self) -> None:
        if self.base_source not in BASE_SOURCES:
            raise ConfigError(f"Episode.base_source {self.base_source!r}: valid sources are "
                              f"{', '.join(BASE_SOURCES)}")

    @property
    def stopped(self) -> bool:
        """The robot's safety layer latched its damping during the episode (a trip, an e-stop), which ended it.

        That is no fall (``fell`` False): the episode holds the ticks played up to it. The runner ends a hardware
        trial's episode there (`wbc.arena.runner.run_episode`'s ``stopped``).
        """
        return not self.fell and bool(np.any(self.safety_events.to_state == "damped"))

    @property
    def survived_s(self) -> float:
        """Time survived [s]: the fall time, the time played when its safety layer stopped it, or the whole episode.

        A stopped episode (`stopped`) counts the time it played, as the arena counts a trial that did not complete.
        """
        if self.fell:
            return float(self.fall_time_s)
        if self.stopped:
            return float(self.t[-1]) if len(self.t) else 0.0
        return float(self.duration_s)

    def deadline_misses(self, budget_s: float | None = None) -> int:
        """Ticks whose ``controller.act`` took longer than `budget_s` [s] (default: the control period)."""
        return int(np.count_nonzero(self.act_s > (self.control_dt if budget_s is None else budget_s)))

    def validate(self, where: str = "episode") -> None:
        """Check this episode as `load` checks a file.

        Every scalar in range, ``t`` finite and strictly increasing, one row per tick in every per-tick array with
        the columns its field needs, finite numbers, unit base quaternions, no negative power or act time, finite
        push, safety and operator times. An episode built in memory (by a tool of one's own, or edited) is checked
        before it is drawn (`wbc.viz.replay.frames_of`); the runner's own pass, but for a diverged one's last tick.

        Raises:
            EpisodeError: naming `where` and the field at fault.
        """
        get = {**{k: getattr(self, k) for k in (*_SCALARS, *_ARRAYS)},
               **{f"push_{k}": getattr(self.pushes, k) for k in _PUSH_KEYS},
               "safety_time": self.safety_events.time, "operator_time": self.operator_events.time,
               "clamped_ticks": self.clamped_ticks, "clamped_rows": self.clamped_rows}
        fields = _EpisodeFields(where, lambda name: np.asarray(get[name]), _MEMORY_ADVICE)
        _, arrays = _checked_core(fields)
        for name in (*(f"push_{k}" for k in _PUSH_KEYS), "safety_time", "operator_time"):
            fields.numbers(name, ndim=None)
        _clamped_rows(fields, fields.scalar("clamped_ticks", lo=0, hi=len(arrays["t"]) + 1))

    def save(self, path: str) -> None:
        """Write the episode to a NumPy ``.npz`` file (no pickle).

        The pushes go in as arrays ``push_<field>``, the safety events as ``safety_<field>``, the operator's actions
        as ``operator_<field>`` (text as unicode), and the base quantities' source as ``base_source``. As NumPy does,
        ``.npz`` is added to a `path` without it; `load` takes the same `path`.

        Raises:
            EpisodeError: ``duration_s`` or ``control_dt`` is outside what `load` reads back (``duration_s`` in
                (0, 600] s, ``control_dt`` in (0, 1] s): refused before anything is written, rather than written
                as a file `load` would call damaged.
        """
        for name, hi in (("duration_s", MAX_DURATION_S), ("control_dt", 1.0)):
            value = getattr(self, name)
            if not 0.0 < value <= hi:  # NaN too
                raise EpisodeError(f"Episode.save: {name} {value:g} s is outside (0, {hi:g}] s, "
                                   f"which Episode.load reads back; save a shorter episode (or its parts)")
        np.savez_compressed(
            path, **{k: getattr(self, k) for k in (*_SCALARS, *_ARRAYS)},
            **{f"push_{k}": getattr(self.pushes, k) for k in _PUSH_KEYS},
            **{f"safety_{k}": getattr(self.safety_events, k) for k in _SAFETY_KEYS},
            **{f"operator_{k}": getattr(self.operator_events, k) for k in _OPERATOR_KEYS},
            base_source=np.str_(self.base_source), clamped_ticks=np.int64(self.clamped_ticks),
            clamped_rows=np.array(self.clamped_rows, dtype=np.int64),
        )

    @classmethod
    def load(cls, path: str) -> Episode:
        """Read an episode written by `save`, every field checked before the episode is made.

        `path` is the one `save` was given: without ``.npz``, and no such file, the ``.npz`` NumPy wrote is read.

        The archive is opened through `wbc.input_files.open_npz` (a regular file, at most 1 GiB uncompressed, plain
        arrays, no pickles), then checked in depth: the scalars are single numbers (``duration_s`` in
        (0, 600] s, ``control_dt`` in (0, 1] s, ``fall_time_s`` NaN or >= 0); ``t`` is one-dimensional, finite and
        strictly increasing; every per-tick array has one row per entry of ``t``, the column count its field needs,
        and finite numbers; ``qpos`` rows hold a base position and a quaternion of norm 1 (to 1e-3) and at least one
        joint; pushes, safety events and operator actions have finite times.

        Raises:
            EpisodeFileError: the file cannot be read (missing, not a regular file, too large, not an ``.npz``, a
                damaged member), or a field is missing (a file of another version: its pushes were text, for
                instance), misshapen, of the wrong type, not finite or out of range; the message names the file and
                the field.
        """
        path = _saved_as(path)
        try:
            archive = open_npz(path)
        except InputFileError as exc:
            raise EpisodeFileError(f"{exc}; play the trial again with `wbc run --save-episodes`") from None
        try:
            with archive as z:
                return cls._read(path, z)
        except (OSError, EOFError, zipfile.BadZipFile, zlib.error) as exc:  # a member damaged past its header
            raise EpisodeFileError(f"{path}: a damaged member ({type(exc).__name__}: {short(str(exc))}); play the "
                                   "trial again with `wbc run --save-episodes`") from None

    @classmethod
    def _read(cls, path: str, z: np.lib.npyio.NpzFile) -> Episode:
        """The episode in an open archive, checked field by field (see `load`)."""
        missing = [k for k in _FILE_FIELDS if k not in z.files]
        if missing:
            raise EpisodeFileError(f"{path}: field {missing[0]} missing (fields missing: {', '.join(missing)}); "
                                   "the file was written by another version of wbc: replay it with that "
                                   "version, or play the trial again with `wbc run --save-episodes`")
        fields = _EpisodeFields(path, z.__getitem__, _FILE_ADVICE)
        scalars, arrays = _checked_core(fields)
        k = len(arrays["t"])
        for name in (*(f"push_{k}" for k in _PUSH_KEYS), "safety_time", "operator_time"):
            fields.numbers(name, ndim=None)
        source = str(fields.scalar_text("base_source"))
        if source not in BASE_SOURCES:
            fields.fail("base_source", f"{short(source, 60)} is not a source; valid: {', '.join(BASE_SOURCES)}")
        # the tick a controller failed on may be counted before its row was stored: k + 1 at most
        clamped = int(fields.scalar("clamped_ticks", lo=0, hi=k + 1))
        rows = tuple(int(v) for v in _clamped_rows(fields, clamped))
        logs = []
        for prefix, log, keys in (("push", PushLog, _PUSH_KEYS), ("safety", SafetyLog, _SAFETY_KEYS),
                                  ("operator", OperatorLog, _OPERATOR_KEYS)):
            try:
                logs.append(log(**{k: z[f"{prefix}_{k}"] for k in keys}))
            except (ConfigError, ValueError, TypeError) as exc:  # the log's own check: lengths, values
                raise EpisodeFileError(f"{path}: fields {prefix}_*: {_cut(str(exc))}; {_FILE_ADVICE}") from None
        try:
            return cls(**scalars, **arrays, pushes=logs[0], safety_events=logs[1], operator_events=logs[2],
                       base_source=source, clamped_ticks=clamped, clamped_rows=rows)
        except (ConfigError, ValueError, TypeError) as exc:
            raise EpisodeFileError(f"{path}: {_cut(str(exc))}") from None


def _clamped_rows(fields: _EpisodeFields, clamped_ticks: float) -> np.ndarray:
    """``clamped_rows``: per command row, the ticks it was clamped on, each between 0 and ``clamped_ticks``."""
    rows = fields.numbers("clamped_rows", rows=5)
    if np.any(rows < 0) or np.any(rows > clamped_ticks) or np.any(rows != np.round(rows)):
        fields.fail("clamped_rows", f"{rows.tolist()}: each row's count of clamped ticks is a whole number from 0 to "
                                    f"clamped_ticks ({clamped_ticks:g})")
    return rows


def _saved_as(path: str | os.PathLike) -> str | os.PathLike:
    """The file `Episode.save(path)` wrote: `path` itself if it exists or ends with ``.npz``, else ``path.npz``.

    NumPy adds the suffix to a name without it: `load` takes the path `save` was given.
    """
    name = path if isinstance(path, str) else os.fspath(path) if isinstance(path, os.PathLike) else None
    if not isinstance(name, str) or name.endswith(".npz") or os.path.lexists(name):
        return path
    return f"{name}.npz" if os.path.lexists(f"{name}.npz") else path


def _cut(text: str, limit: int = 300) -> str:
    """`text` cut to `limit` characters (a message quoted inside another, without the quotes `short` adds)."""
    return text if len(text) <= limit else f"{text[: limit - 30]}... ({len(text)} characters)"


def _checked_core(fields: _EpisodeFields) -> tuple[dict[str, float | bool], dict[str, np.ndarray]]:
    """The scalars and per-tick arrays every episode has, checked (see `Episode.load`), as `Episode` takes them."""
    scalars = {"duration_s": fields.scalar("duration_s", lo=0.0, hi=MAX_DURATION_S, lo_open=True),
               "control_dt": fields.scalar("control_dt", lo=0.0, hi=1.0, lo_open=True),
               "fell": bool(fields.scalar("fell", lo=0.0, hi=1.0)),
               "fall_time_s": fields.scalar("fall_time_s", lo=0.0, hi=math.inf, nan=True)}
    t = fields.numbers("t", ndim=1)
    if t.size > 1 and not np.all(np.diff(t) > 0):
        i = int(np.argmin(np.diff(t) > 0))
        fields.fail("t", f"not strictly increasing (t[{i}] = {t[i]:g}, t[{i + 1}] = {t[i + 1]:g})")
    k = len(t)
    # the runner stores a tick's row at its end, (k + 1) dt: within the episode, as a fall is
    end = scalars["duration_s"] + scalars["control_dt"]
    if k and (t[0] < 0.0 or t[-1] > end):
        fields.fail("t", f"runs from {t[0]:g} to {t[-1]:g} s, outside the {scalars['duration_s']:g} s episode")
    if scalars["fall_time_s"] > end:  # NaN (no fall) compares False
        fields.fail("fall_time_s", f"{scalars['fall_time_s']:g} s, after the {scalars['duration_s']:g} s episode")
    arrays = {"t": t, "command": fields.numbers("command", rows=k, cols=3),
              "v_base_in_yaw": fields.numbers("v_base_in_yaw", rows=k, cols=2),
              "yaw_rate": fields.numbers("yaw_rate", rows=k), "roll": fields.numbers("roll", rows=k),
              "pitch": fields.numbers("pitch", rows=k), "power": fields.numbers("power", rows=k),
              "arm_q": fields.numbers("arm_q", rows=k, ndim=2), "qpos": fields.numbers("qpos", rows=k, ndim=2),
              "act_s": fields.numbers("act_s", rows=k)}
    qpos = arrays["qpos"]
    if np.any(np.abs(qpos) > _QPOS_BOUND):
        fields.fail("qpos", f"values beyond +-{_QPOS_BOUND:g} (m or rad): no trunk travels so far in an episode, and "
                            "no joint turns so far")
    if qpos.shape[1] < 8:
        fields.fail("qpos", f"shape {qpos.shape}, expected (ticks, 7 + joints): a base position, a quaternion and the "
                            "joints")
    with np.errstate(over="ignore"):  # huge values give an infinite norm, refused below
        norms = np.linalg.norm(qpos[:, 3:7], axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > _QUAT_TOLERANCE)
    if bad.size:
        fields.fail("qpos", f"the base quaternion qpos[{bad[0]}, 3:7] has norm {norms[bad[0]]:.6g}, not 1 (to "
                            f"{_QUAT_TOLERANCE:g}; {bad.size} such ticks)")
    for name in ("power", "act_s"):
        if np.any(arrays[name] < 0):
            fields.fail(name, "negative values, expected >= 0")
    return scalars, arrays


_FILE_ADVICE = ("the file is damaged or was not written by `Episode.save`: play the trial again with `wbc run "
                "--save-episodes`")
_MEMORY_ADVICE = "the episode was not made by the runner (`wbc.arena.runner.run_episode`) or was changed since"


_QPOS_BOUND = 1e4
"""The largest magnitude a stored configuration entry may have [m or rad]."""

_QUAT_TOLERANCE = 1e-3
"""How far a stored base quaternion's norm may be from 1: a simulator's and an estimator's are unit to ~1e-9."""


class _EpisodeFields:
    """The arrays of an open episode archive, read with their shapes, types and values checked.

    Every failure is an `EpisodeFileError` naming the file and the field (an `EpisodeError` naming `where` for an
    episode in memory: `advice` is not the file one).

    Args:
        where: the file, or what the episode is.
        get: returns a field's array by name.
        advice: what to do, after the reason.
    """

    def __init__(self, where: str, get: Callable[[str], np.ndarray], advice: str) -> None:
        self.where, self.get, self.advice = where, get, advice

    def fail(self, name: str, reason: str) -> NoReturn:
        """Raise the error of field `name`."""
        error = EpisodeFileError if self.advice is _FILE_ADVICE else EpisodeError
        raise error(f"{self.where}: field {name}: {reason}; {self.advice}")

    def _array(self, name: str) -> np.ndarray:
        value = self.get(name)
        if value.dtype.kind not in "biuf":
            self.fail(name, f"dtype {value.dtype}, expected numbers")
        return value

    def scalar(self, name: str, *, lo: float, hi: float, lo_open: bool = False, nan: bool = False) -> float:
        """A single number in [lo, hi] (lo excluded when `lo_open`; NaN accepted when `nan`)."""
        value = self._array(name)
        if value.size != 1:
            self.fail(name, f"shape {value.shape}, expected a single number")
        x = float(value.reshape(()))
        if nan and math.isnan(x):
            return x
        if not (math.isfinite(x) and (x > lo if lo_open else x >= lo) and x <= hi):
            self.fail(name, f"{x!r}, expected a finite number in {'(' if lo_open else '['}{lo:g}, {hi:g}]")
        return x

    def scalar_text(self, name: str) -> str:
        """A single string."""
        value = self.get(name)
        if value.dtype.kind not in "SU" or value.size != 1:
            self.fail(name, f"dtype {value.dtype}, shape {value.shape}, expected one string")
        return str(value.reshape(()))

    def numbers(self, name: str, *, rows: int | None = None, cols: int | None = None,
                ndim: int | None = 1) -> np.ndarray:
        """A finite float64 array of `rows` rows and `cols` columns (then 2-D) or `ndim` dimensions; None: any."""
        value = self._array(name)
        ndim = 2 if cols is not None else ndim
        if ndim is not None and value.ndim != ndim:
            expected = "(ticks,)" if ndim == 1 else f"(ticks, {cols if cols is not None else 'n'})"
            self.fail(name, f"shape {value.shape}, expected {expected}")
        if rows is not None and value.shape[0] != rows:
            self.fail(name, f"{value.shape[0]} rows, expected {rows} (one per entry of t)"
                       if name != "clamped_rows" else f"shape {value.shape}, expected (5,)")
        if cols is not None and value.shape[1] != cols:
            self.fail(name, f"shape {value.shape}, expected (ticks, {cols})")
        value = value.astype(np.float64)
        if not np.all(np.isfinite(value)):
            where = np.argwhere(~np.isfinite(value))[0]
            self.fail(name, f"{value[tuple(where)]} at index {tuple(int(i) for i in where)}, expected finite numbers")
        return value


class EpisodeBuffer:
    """The rows the runner collects tick by tick; `finish` stacks them into an `Episode`.

    A tick stores only what it measured: the time, the command, the act time, the trunk's true pose and velocity, and
    the joints' positions, torques and speeds, as one new row (one numpy call: the tick copies what it was handed,
    so a robot may reuse its buffers). What the episode derives from them (roll, pitch, the velocity in the yaw
    frame, the yaw rate, the power, the arm's joints) is computed once, for all rows, at `finish`: per tick those few
    dozen scalar operations, or a dozen slice assignments into preallocated arrays, cost more than the physics step.

    Args:
        nq: 7 + the robot's joints.
        arm: the arm's joints among the robot's (None without an actuated arm).
    """

    def __init__(self, nq: int, arm: slice | None = None) -> None:
        self.nq = nq
        self.arm = arm
        self._rows: list[np.ndarray] = []  # qpos (nq), base velocity (6), joint torques (nj), joint speeds (nj)
        self._scalars: list[tuple[float, float, float, float, float]] = []  # t, vx, vy, yaw rate, act time

    @property
    def rows(self) -> int:
        """Ticks stored whole (`add` returned)."""
        return min(len(self._rows), len(self._scalars))

    def measured(self, state: RobotState) -> np.ndarray:
        """A tick's row with the robot's frame (q, tau_est, dq) copied in; `add` fills in the rest.

        Taken before the controller acts on `state`, whose arrays it could change.
        """
        nq, nj = self.nq, self.nq - 7
        row = np.empty(nq + 6 + 2 * nj)
        row[7:nq] = state.q
        row[nq + 6:nq + 6 + nj] = state.tau_est
        row[nq + 6 + nj:] = state.dq
        return row

    def add(self, t: float, command: VelocityCommand, act_s: float, truth: BaseTruth, row: np.ndarray) -> None:
        """Store one tick: its end time [s], command, act time [s], the trunk's truth, and its row.

        `row` is `measured` of the tick's state, taken before the controller acted; the truth is written into it.
        """
        nq = self.nq
        row[0:3] = truth.base_position_in_world
        row[3:7] = truth.base_quat
        row[nq:nq + 3] = truth.base_linvel_in_world
        row[nq + 3:nq + 6] = truth.base_angvel_in_body
        self._rows.append(row)
        self._scalars.append((t, command.vx, command.vy, command.yaw_rate, act_s))

    def _stacked(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """t, command, act_s, qpos, base_vel, tau_dq of the rows so far."""
        nq, nj = self.nq, self.nq - 7
        # the ticks stored whole: an interruption inside `add` (Ctrl-C lands between any two bytecodes) may have left
        # a row without its scalars, which belongs to no complete tick
        k = min(len(self._rows), len(self._scalars))
        rows = np.array(self._rows[:k], dtype=np.float64).reshape(k, nq + 6 + 2 * nj)
        scalars = np.array(self._scalars[:k], dtype=np.float64).reshape(k, 5)
        tau_dq = rows[:, nq + 6:].reshape(-1, 2, nj)
        return scalars[:, 0], scalars[:, 1:4], scalars[:, 4], rows[:, :nq], rows[:, nq:nq + 6], tau_dq

    def derived(self) -> dict[str, np.ndarray]:
        """The per-tick metrics of the rows filled so far: roll, pitch, v_base_in_yaw, yaw_rate, power, arm_q."""
        _, _, _, qpos, vel, tau_dq = self._stacked()
        return self._derived(qpos, vel, tau_dq)

    def _derived(self, qpos: np.ndarray, vel: np.ndarray, tau_dq: np.ndarray) -> dict[str, np.ndarray]:
        k = qpos.shape[0]
        rot = quat_to_matrices(qpos[:, 3:7])
        roll = np.arctan2(rot[:, 2, 1], rot[:, 2, 2])
        pitch = -np.arcsin(np.clip(rot[:, 2, 0], -1.0, 1.0))
        yaw = np.arctan2(rot[:, 1, 0], rot[:, 0, 0])
        c, s = np.cos(yaw), np.sin(yaw)
        v = vel[:, 0:3]
        v_yaw = np.stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1]], axis=1)
        yaw_rate = np.einsum("ij,ij->i", rot[:, 2, :], vel[:, 3:6])
        power = np.abs(tau_dq[:, 0] * tau_dq[:, 1]).sum(axis=1)
        arm_q = qpos[:, 7:][:, self.arm] if self.arm is not None else np.zeros((k, 3))
        return {"roll": roll, "pitch": pitch, "v_base_in_yaw": v_yaw, "yaw_rate": yaw_rate, "power": power,
                "arm_q": arm_q}

    def finish(self, *, duration_s: float, control_dt: float, fell: bool, fall_time_s: float,
               safety_events: SafetyLog | None = None, clamped_ticks: int = 0,
               clamped_rows: tuple[int, ...] = (0, 0, 0, 0, 0)) -> Episode:
        """The episode made of the rows filled so far (no pushes: the trial's setup adds those it applied)."""
        t, command, act_s, qpos, vel, tau_dq = self._stacked()
        return Episode(
            duration_s=duration_s, control_dt=control_dt, fell=fell, fall_time_s=fall_time_s,
            t=t.copy(), command=command.copy(), qpos=qpos.copy(), act_s=act_s.copy(),
            **self._derived(qpos, vel, tau_dq),
            safety_events=SafetyLog() if safety_events is None else safety_events, clamped_ticks=clamped_ticks,
            clamped_rows=tuple(int(v) for v in clamped_rows),
        )
