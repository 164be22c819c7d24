"""`Episode`: the log of one played trial, at the control rate, from which every metric is computed.

Per control tick it keeps the command, the measured proprioception needed for energy and arm travel, simulator
truth (base velocity, yaw rate, roll, pitch, configuration) for tracking metrics and replay, and how long the
controller took to act (the runner's timing, for deadline misses). The pushes the robot met
are kept as arrays (`PushLog`), so a replay draws them from numbers, not from text; so are the transitions of a
safety layer the robot ran behind (`SafetyLog`), with their times and reasons.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from wbc.errors import ConfigError, EpisodeFileError
from wbc.hardware.capabilities import SafetyEventLike
from wbc.scenario.push import Push

__all__ = ["Episode", "EpisodeBuffer", "PushLog", "SafetyLog"]


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


@dataclass(frozen=True, kw_only=True)
class SafetyLog:
    """Transitions of a safety layer as arrays, one row per transition, oldest first.

    Attributes:
        time: when each happened, on the safety layer's clock, shape (n,) [s] (the robot time since the layer was
            made, unless it was given a wall clock).
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
        n = len(self.time)
        for name in _SAFETY_KEYS:
            value = np.asarray(getattr(self, name))
            if value.shape != (n,):
                raise ConfigError(f"SafetyLog.{name}: shape {value.shape}, expected ({n},) for {n} events; build "
                                  "the log with SafetyLog.of(events)")
            if name == "time":
                value = value.astype(np.float64)
            elif value.dtype.kind != "U":
                if n and value.dtype.kind not in "SU":
                    raise ConfigError(f"SafetyLog.{name}: dtype {value.dtype}, expected text")
                value = value.astype(np.str_)
            object.__setattr__(self, name, value)

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

    def rows(self) -> list[tuple[float, str, str, str, str]]:
        """The transitions as (time, from_state, to_state, reason, detail), oldest first."""
        return [(float(t), str(a), str(b), str(r), str(d)) for t, a, b, r, d in
                zip(self.time, self.from_state, self.to_state, self.reason, self.detail, strict=True)]


_SAFETY_KEYS = ("time", "from_state", "to_state", "reason", "detail")
_PUSH_KEYS = ("start", "duration", "force_in_world", "offset_in_base")
_SCALARS = ("duration_s", "control_dt", "fell", "fall_time_s")
_ARRAYS = ("t", "command", "v_base_in_yaw", "yaw_rate", "roll", "pitch", "power", "arm_q", "qpos", "act_s")


@dataclass(frozen=True, kw_only=True)
class Episode:
    """A finished episode; arrays have one row per control tick actually played.

    Attributes:
        duration_s: the trial's planned length [s].
        control_dt: control period [s].
        fell: the trunk or a non-foot link touched the ground.
        fall_time_s: when (nan if it did not fall) [s].
        t: time of each tick (after the tick's physics) [s].
        command: commanded (vx, vy, yaw_rate) [m/s, m/s, rad/s], shape (k, 3).
        v_base_in_yaw: base horizontal velocity in the yaw-aligned frame, truth, shape (k, 2) [m/s].
        yaw_rate: base yaw rate (world z), truth, shape (k,) [rad/s].
        roll: base roll, truth, shape (k,) [rad].
        pitch: base pitch, truth, shape (k,) [rad].
        power: sum over joints of |tau_est * dq|, measured, shape (k,) [W].
        arm_q: measured arm joint positions, shape (k, 3) (zero columns without an actuated arm) [rad].
        qpos: simulator configuration for replay, shape (k, nq).
        act_s: wall time of each tick's ``controller.act`` call, shape (k,) [s]; a tick whose value exceeds
            `control_dt` missed its deadline on a real robot.
        pushes: the pushes that began before the episode ended.
        safety_events: the transitions of the robot's safety layer during the episode (empty for a robot that has
            none, `wbc.hardware.capabilities.HasSafetyEvents`).
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

    @property
    def survived_s(self) -> float:
        """Time survived [s]: the fall time, or the whole episode."""
        return float(self.fall_time_s) if self.fell else float(self.duration_s)

    def deadline_misses(self, budget_s: float | None = None) -> int:
        """Ticks whose ``controller.act`` took longer than `budget_s` [s] (default: the control period)."""
        return int(np.count_nonzero(self.act_s > (self.control_dt if budget_s is None else budget_s)))

    def save(self, path: str) -> None:
        """Write the episode to a NumPy ``.npz`` file (no pickle).

        The pushes go in as arrays ``push_<field>``, the safety events as ``safety_<field>`` (text as unicode).
        """
        np.savez_compressed(
            path, **{k: getattr(self, k) for k in (*_SCALARS, *_ARRAYS)},
            **{f"push_{k}": getattr(self.pushes, k) for k in _PUSH_KEYS},
            **{f"safety_{k}": getattr(self.safety_events, k) for k in _SAFETY_KEYS},
        )

    @classmethod
    def load(cls, path: str) -> Episode:
        """Read an episode written by `save`; a file from before episodes kept safety events has none.

        Raises:
            EpisodeFileError: a field is missing (a file of another version: its pushes were text, for instance) or
                misshapen.
            OSError, zipfile.BadZipFile: the file cannot be read at all.
        """
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in (*_SCALARS, *_ARRAYS, *(f"push_{k}" for k in _PUSH_KEYS)) if k not in z.files]
            if missing:
                raise EpisodeFileError(f"{path}: field {missing[0]} missing (fields missing: {', '.join(missing)}); "
                                       "the file was written by another version of wbc: replay it with that "
                                       "version, or play the trial again with `wbc run --save-episodes`")
            scalars = {k: z[k].item() for k in _SCALARS}
            arrays = {k: z[k] for k in _ARRAYS}
            safety_keys = [f"safety_{k}" for k in _SAFETY_KEYS]
            present = [k for k in safety_keys if k in z.files]
            if present and len(present) < len(safety_keys):
                missing = [k for k in safety_keys if k not in z.files]
                raise EpisodeFileError(f"{path}: field {missing[0]} missing while {present[0]} is there; the file "
                                       "is damaged: play the trial again with `wbc run --save-episodes`")
            try:
                pushes = PushLog(**{k: z[f"push_{k}"] for k in _PUSH_KEYS})
                safety = SafetyLog(**{k: z[f"safety_{k}"] for k in _SAFETY_KEYS}) if present else SafetyLog()
            except ConfigError as exc:
                raise EpisodeFileError(f"{path}: {exc}") from None
        return cls(**scalars, **arrays, pushes=pushes, safety_events=safety)


@dataclass
class EpisodeBuffer:
    """Preallocated rows filled tick by tick by the runner; `finish` freezes them into an `Episode`."""

    capacity: int
    nq: int
    rows: int = 0
    t: np.ndarray = field(init=False)
    command: np.ndarray = field(init=False)
    v_base_in_yaw: np.ndarray = field(init=False)
    yaw_rate: np.ndarray = field(init=False)
    roll: np.ndarray = field(init=False)
    pitch: np.ndarray = field(init=False)
    power: np.ndarray = field(init=False)
    arm_q: np.ndarray = field(init=False)
    qpos: np.ndarray = field(init=False)
    act_s: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        n = self.capacity
        self.t = np.zeros(n)
        self.command = np.zeros((n, 3))
        self.v_base_in_yaw = np.zeros((n, 2))
        self.yaw_rate = np.zeros(n)
        self.roll = np.zeros(n)
        self.pitch = np.zeros(n)
        self.power = np.zeros(n)
        self.arm_q = np.zeros((n, 3))
        self.qpos = np.zeros((n, self.nq))
        self.act_s = np.zeros(n)

    def finish(self, *, duration_s: float, control_dt: float, fell: bool, fall_time_s: float,
               safety_events: SafetyLog | None = None) -> Episode:
        """The episode made of the rows filled so far (no pushes: the trial's setup adds those it applied)."""
        k = self.rows
        return Episode(
            duration_s=duration_s, control_dt=control_dt, fell=fell, fall_time_s=fall_time_s,
            **{name: getattr(self, name)[:k].copy() for name in _ARRAYS},
            safety_events=SafetyLog() if safety_events is None else safety_events,
        )
