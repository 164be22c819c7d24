"""`Episode`: the log of one played trial, at the control rate, from which every metric is computed.

Per control tick it keeps the command, the measured proprioception needed for energy and arm travel, and simulator
truth (base velocity, yaw rate, roll, pitch, configuration) for tracking metrics and replay.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Episode", "EpisodeBuffer"]


@dataclass(frozen=True)
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
        events: (time, kind, detail) tuples: pushes, controller fallbacks.
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
    events: tuple[tuple[float, str, str], ...] = ()

    @property
    def survived_s(self) -> float:
        """Time survived [s]: the fall time, or the whole episode."""
        return float(self.fall_time_s) if self.fell else float(self.duration_s)

    def save(self, path: str) -> None:
        """Write the episode to a NumPy ``.npz`` file (no pickle)."""
        np.savez_compressed(
            path, duration_s=self.duration_s, control_dt=self.control_dt, fell=self.fell,
            fall_time_s=self.fall_time_s, t=self.t, command=self.command, v_base_in_yaw=self.v_base_in_yaw,
            yaw_rate=self.yaw_rate, roll=self.roll, pitch=self.pitch, power=self.power, arm_q=self.arm_q,
            qpos=self.qpos, events=np.array([f"{float(t)!r}|{k}|{d}" for t, k, d in self.events], dtype=str),
        )

    @classmethod
    def load(cls, path: str) -> Episode:
        """Read an episode written by `save`."""
        with np.load(path, allow_pickle=False) as z:
            events = tuple((float(t), k, d) for t, k, d in (e.split("|", 2) for e in z["events"]))
            scalars = {k: z[k].item() for k in ("duration_s", "control_dt", "fell", "fall_time_s")}
            arrays = {k: z[k] for k in ("t", "command", "v_base_in_yaw", "yaw_rate", "roll", "pitch", "power",
                                        "arm_q", "qpos")}
        return cls(**scalars, **arrays, events=events)


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
    events: list[tuple[float, str, str]] = field(default_factory=list)

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

    def finish(self, *, duration_s: float, control_dt: float, fell: bool, fall_time_s: float) -> Episode:
        """The episode made of the rows filled so far."""
        k = self.rows
        return Episode(
            duration_s=duration_s, control_dt=control_dt, fell=fell, fall_time_s=fall_time_s,
            t=self.t[:k].copy(), command=self.command[:k].copy(), v_base_in_yaw=self.v_base_in_yaw[:k].copy(),
            yaw_rate=self.yaw_rate[:k].copy(), roll=self.roll[:k].copy(), pitch=self.pitch[:k].copy(),
            power=self.power[:k].copy(), arm_q=self.arm_q[:k].copy(), qpos=self.qpos[:k].copy(),
            events=tuple(self.events),
        )
