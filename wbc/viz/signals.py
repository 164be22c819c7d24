"""`TrialSignals`: the time plots of a trial page, sampled with the scene's frames, and the events on its timeline.

A trial page (`wbc.viz.page`) draws, beside the 3D scene and on one timeline:

- ``attitude``: trunk roll and pitch [rad]; ``height``: trunk height above the ground under it [m];
- ``velocity``: forward / lateral velocity against the commanded one [m/s]; ``yaw_rate`` against its command [rad/s];
- ``foot_forces``: vertical ground reaction force on each foot [N] (simulation only);
- ``torques``: each joint's torque as a fraction of its limit (1 is saturation) [-] (simulation only);
- ``arm_momentum``: the arm's angular momentum about the robot's centre of mass against the angular impulse of the
  push acting, accumulated over the push [N m s] (simulation with an actuated arm only);
- ``mpc_com``: the MPC plan's CoM (its first predicted step) against the CoM that happened [m] (an MPC only).

A plot holds lines (name, values, style) over the run's time samples; a value that is unknown is None (a gap). The
events are marks: ``push`` (start, duration, force), ``fall`` and ``safety`` (a transition of the safety layer),
``command`` and ``browser_push`` (set from the page, `wbc.viz.live_page`). Values are rounded to 4 significant
digits: a 20 s trial at 50 frames per second stays a few hundred kilobytes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from wbc.arena.episode import Episode
from wbc.robots.conventions import quat_to_matrix
from wbc.viz.frame import VizFrame
from wbc.viz.sim_frames import SimulatedWorld

__all__ = ["PLOTS", "Mark", "TrialSignals"]

PLOTS: dict[str, tuple[str, str]] = {
    "attitude": ("trunk roll / pitch", "rad"),
    "height": ("trunk height", "m"),
    "velocity": ("velocity vs command", "m/s"),
    "yaw_rate": ("yaw rate vs command", "rad/s"),
    "foot_forces": ("foot contact forces (vertical)", "N"),
    "torques": ("joint torque / limit (|1| saturates)", "-"),
    "arm_momentum": ("arm angular momentum vs push angular impulse", "N m s"),
    "mpc_com": ("MPC predicted CoM vs actual", "m"),
}
"""Plot keys, in page order, with their titles and units."""

_LEGS = ("FR", "FL", "RR", "RL")


@dataclass(frozen=True)
class Mark:
    """An event on the timeline.

    Attributes:
        t: when [s].
        kind: ``push``, ``fall``, ``safety``, ``command``, ``browser_push`` or ``divergence``.
        label: what it was, for a person.
        duration: how long it lasted [s] (0 for an instant).
    """

    t: float
    kind: str
    label: str
    duration: float = 0.0

    def to_json(self) -> dict[str, object]:
        """The mark as the page reads it."""
        return {"t": _r(self.t), "kind": self.kind, "label": self.label, "d": _r(self.duration)}


def _r(x: float | None) -> float | None:
    """`x` to 4 significant digits (None for unknown or not finite)."""
    if x is None or not math.isfinite(x):
        return None
    return float(f"{x:.4g}")


@dataclass
class TrialSignals:
    """The plots and marks of one run of a trial.

    Args:
        name: whose run (the controller).

    Attributes:
        t: sample times [s].
        lines: values by plot key and line name, one per sample (None where unknown).
        marks: the events.
    """

    name: str
    t: list[float] = field(default_factory=list)
    lines: dict[str, dict[str, list[float | None]]] = field(default_factory=dict)
    marks: list[Mark] = field(default_factory=list)
    _push_impulse: np.ndarray = field(default_factory=lambda: np.zeros(3))
    _push_was_on: bool = False
    _last_t: float = 0.0
    _model: tuple[mujoco.MjModel, list[str], np.ndarray, int | None] | None = field(default=None, repr=False)

    def _model_info(self, m: mujoco.MjModel) -> tuple[list[str], np.ndarray, int | None]:
        """(actuator names, torque limits, the arm's root body) of `m`, looked up once per model."""
        if self._model is None or self._model[0] is not m:
            names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, i) or f"joint {i}" for i in range(m.nu)]
            self._model = (m, names, m.actuator_forcerange[:, 1].copy(), _arm_root(m))
        return self._model[1], self._model[2], self._model[3]

    def _put(self, plot: str, line: str, value: float | None) -> None:
        column = self.lines.setdefault(plot, {}).setdefault(line, [])
        column.extend([None] * (len(self.t) - 1 - len(column)))  # a line that starts late has a gap before
        column.append(_r(value))

    def add_frame(self, frame: VizFrame, robot: SimulatedWorld | None = None, plan_com: np.ndarray | None = None
                  ) -> None:
        """Sample the frame (and, when given, the simulator it came from) at ``frame.t``.

        Args:
            frame: the frame the scene draws at this time.
            robot: the simulation, for velocity, forces, torques and momentum (None: what the frame holds only).
            plan_com: the MPC's predicted CoM for this time [m], or None.
        """
        dt = frame.t - self._last_t if self.t else 0.0
        self._last_t = frame.t
        self.t.append(_r(frame.t))
        qpos = np.asarray(frame.qpos)
        rot = quat_to_matrix(qpos[3:7])
        roll = math.atan2(rot[2, 1], rot[2, 2])
        pitch = -math.asin(max(-1.0, min(1.0, rot[2, 0])))
        self._put("attitude", "roll", roll)
        self._put("attitude", "pitch", pitch)
        self._put("height", "height", float(qpos[2]))
        cmd = np.asarray(frame.command)
        self._put("velocity", "vx cmd", float(cmd[0]))
        self._put("velocity", "vy cmd", float(cmd[1]))
        self._put("yaw_rate", "cmd", float(cmd[2]))
        if robot is None:
            return
        truth = robot.sim_truth()  # also fills MuJoCo's subtree velocities, read below
        yaw = math.atan2(rot[1, 0], rot[0, 0])
        c, s = math.cos(yaw), math.sin(yaw)
        v = truth.base_linvel_in_world
        self._put("velocity", "vx", c * v[0] + s * v[1])
        self._put("velocity", "vy", -s * v[0] + c * v[1])
        self._put("yaw_rate", "yaw rate", float((rot @ truth.base_angvel_in_body)[2]))
        if frame.foot_force_in_world is not None:
            for leg, f in zip(_LEGS, frame.foot_force_in_world, strict=True):
                self._put("foot_forces", leg, float(f[2]))
        m, d = robot.model, robot.data
        names, limit, arm = self._model_info(m)
        force = d.actuator_force
        for i, name in enumerate(names):
            self._put("torques", name, float(force[i] / limit[i]) if limit[i] > 0 else None)
        com = truth.com_in_world
        if frame.pushed:
            r = frame.push_point_in_world - com
            if not self._push_was_on:
                self._push_impulse = np.zeros(3)
            self._push_impulse = self._push_impulse + np.cross(r, frame.push_force_in_world) * dt
        self._push_was_on = frame.pushed
        if arm is not None:
            mass = float(m.body_subtreemass[arm])
            c_arm, v_arm = d.subtree_com[arm], d.subtree_linvel[arm]
            spin = d.subtree_angmom[arm]
            orbit = mass * np.cross(c_arm - com, v_arm - truth.com_velocity_in_world)
            h = spin + orbit
            for k, axis in enumerate("xyz"):
                self._put("arm_momentum", f"arm L{axis}", float(h[k]))
            for k, axis in enumerate("xyz"):
                self._put("arm_momentum", f"push H{axis}", float(self._push_impulse[k]))
        if plan_com is not None:
            self._put("mpc_com", "plan z", float(plan_com[2]))
            self._put("mpc_com", "CoM z", float(com[2]))
            self._put("mpc_com", "plan x-CoM x", float(plan_com[0] - com[0]))

    def mark_episode(self, episode: Episode, *, pushes: bool = True) -> None:
        """Add the episode's events: its pushes, its fall and its safety layer's transitions."""
        if pushes:
            p = episode.pushes
            for j in range(len(p)):
                f = p.force_in_world[j]
                self.marks.append(Mark(float(p.start[j]), "push", f"push {np.linalg.norm(f):.0f} N "
                                       f"({f[0]:.0f}, {f[1]:.0f}, {f[2]:.0f})", float(p.duration[j])))
        if episode.fell:
            self.marks.append(Mark(float(episode.fall_time_s), "fall", f"{self.name} fell"))
        for t, a, b, reason, _ in episode.safety_events.rows():
            self.marks.append(Mark(t, "safety", f"safety {a} -> {b}: {reason}"))
        self.marks.sort(key=lambda mk: mk.t)

    @classmethod
    def of_episode(cls, name: str, episode: Episode, frames: list[VizFrame] | None = None) -> TrialSignals:
        """The signals a stored episode holds: attitude, height, velocity and yaw rate against the command."""
        out = cls(name)
        for i in range(len(episode.t)):
            q = episode.qpos[i]
            out.add_frame(VizFrame(t=float(episode.t[i]), qpos=q, command=episode.command[i]))
            out._put("velocity", "vx", float(episode.v_base_in_yaw[i, 0]))
            out._put("velocity", "vy", float(episode.v_base_in_yaw[i, 1]))
            out._put("yaw_rate", "yaw rate", float(episode.yaw_rate[i]))
        out.mark_episode(episode)
        return out

    def thinned(self, fps: float) -> TrialSignals:
        """These signals at most `fps` samples per second [1/s] (a stored episode holds every control tick)."""
        keep, last = [], -1
        for i, t in enumerate(self.t):
            k = int(round(t * fps))
            if k > last:
                keep.append(i)
                last = k
        out = TrialSignals(self.name, [self.t[i] for i in keep], marks=list(self.marks))
        out.lines = {p: {n: [v[i] if i < len(v) else None for i in keep] for n, v in ls.items()}
                     for p, ls in self.lines.items()}
        return out

    def to_json(self) -> dict[str, object]:
        """The run as the page reads it: ``{name, t, plots: {key: {title, unit, lines: {name: values}}}, marks}``."""
        n = len(self.t)
        plots = {}
        for key, (title, unit) in PLOTS.items():
            lines = self.lines.get(key)
            if lines:
                plots[key] = {"title": title, "unit": unit,
                              "lines": {name: v + [None] * (n - len(v)) for name, v in lines.items()}}
        return {"name": self.name, "t": self.t, "plots": plots, "marks": [m.to_json() for m in self.marks]}


def _arm_root(m: mujoco.MjModel) -> int | None:
    """The body the arm's first joint moves (None without an actuated arm)."""
    j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "arm_waist")
    return None if j < 0 else int(m.jnt_bodyid[j])
