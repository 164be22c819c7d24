"""`TrialSignals`: the time plots of a trial page, sampled with the scene's frames, and the events on its timeline.

A trial page (`wbc.viz.page`) draws, beside the 3D scene and on one timeline:

- ``attitude``: trunk roll and pitch [rad]; ``height``: the trunk origin's world z [m] (not its height above the
  ground under it: on rough ground the two differ by the terrain's height there);
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
from wbc.arena.trial_record import (
    CONTROLLER_ERROR,
    DIVERGED,
    FALL,
    OPERATOR_STOP,
    SAFETY_TRIP,
    SUCCESS,
    episode_outcome,
)
from wbc.hardware.mujoco.physics import base_body_id
from wbc.viz.frame import VizFrame
from wbc.viz.sim_frames import SimulatedWorld

__all__ = ["PLOTS", "Mark", "TrialSignals"]

PLOTS: dict[str, tuple[str, str]] = {
    "attitude": ("trunk roll / pitch", "rad"),
    "height": ("trunk height (world z)", "m"),
    "velocity": ("velocity vs command", "m/s"),
    "yaw_rate": ("yaw rate vs command", "rad/s"),
    "foot_forces": ("foot contact forces (vertical)", "N"),
    "torques": ("joint torque / limit (|1| saturates)", "-"),
    "arm_momentum": ("arm angular momentum vs push angular impulse", "N m s"),
    "mpc_com": ("MPC predicted CoM vs actual", "m"),
}
"""Plot keys, in page order, with their titles and units."""

_LEGS = ("FR", "FL", "RR", "RL")
# the (plot, line) of each value a frame samples, in the order `TrialSignals.add_frame` computes them
_BASE_KEYS = [("attitude", "roll"), ("attitude", "pitch"), ("height", "height"), ("velocity", "vx cmd"),
              ("velocity", "vy cmd"), ("yaw_rate", "cmd")]
_VELOCITY_KEYS = [("velocity", "vx"), ("velocity", "vy"), ("yaw_rate", "yaw rate")]
_FOOT_KEYS = [("foot_forces", leg) for leg in _LEGS]
_ARM_KEYS = [("arm_momentum", f"arm L{a}") for a in "xyz"] + [("arm_momentum", f"push H{a}") for a in "xyz"]
_PLAN_KEYS = [("mpc_com", "plan z"), ("mpc_com", "CoM z"), ("mpc_com", "plan x-CoM x")]


_END_WORDS = {FALL: "fell", SAFETY_TRIP: "safety trip", OPERATOR_STOP: "operator stop",
              CONTROLLER_ERROR: "controller error", DIVERGED: "simulation diverged"}


def _end_mark(name: str, episode: Episode, outcome: str, error: str) -> Mark | None:
    """The mark of how `episode` ended (None: it played to its end)."""
    if outcome == SUCCESS:
        return None
    t = float(episode.fall_time_s) if episode.fell and math.isfinite(episode.fall_time_s) else (
        float(episode.t[-1]) if len(episode.t) else 0.0)
    tripped = episode.safety_events.reason[episode.safety_events.to_state == "damped"]
    why = f": {tripped[0]}" if outcome in (SAFETY_TRIP, OPERATOR_STOP) and len(tripped) else (
        f": {error.splitlines()[0][:160]}" if error else "")
    if outcome == FALL:
        return Mark(t, "fall", f"{name} fell")
    return Mark(t, "end", f"{name}: {_END_WORDS.get(outcome, outcome.replace('_', ' '))}{why}")


@dataclass(frozen=True)
class Mark:
    """An event on the timeline.

    Attributes:
        t: when [s].
        kind: ``push``, ``fall``, ``end`` (a trial ended otherwise: a trip, a stop, an error), ``safety``,
            ``operator`` (a hardware trial's operator key), ``command``, ``browser_push`` or ``divergence``.
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


def _round4(x: np.ndarray) -> np.ndarray:
    """`_r` of every element of `x` (NaN where unknown or not finite), the same values, in numpy.

    Scaled to four digits before the point and rounded there; a value that lands within a hair of a tie (where the
    scaling's own rounding could decide) is rounded as `_r` does it, from its decimal form.
    """
    out = np.full(x.shape, np.nan)
    ok = np.isfinite(x)
    v = x[ok]
    if not v.size:
        return out
    a = np.abs(v)
    k = 3 - np.floor(np.log10(np.where(a > 0.0, a, 1.0))).astype(np.int64)
    p = 10.0 ** np.abs(k)
    up = k >= 0
    scaled = np.where(up, v * p, v / p)
    rounded = np.round(scaled)
    r = np.where(up, rounded / p, rounded * p)
    near_tie = np.abs(np.abs(scaled - np.trunc(scaled)) - 0.5) < 1e-6
    for i in np.flatnonzero(near_tie).tolist():
        r[i] = float(f"{v[i]:.4g}")
    out[ok] = r
    return out


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
        lines: values by plot key and line name, one per sample (None where unknown); complete after `settle`.
        marks: the events.
    """

    name: str
    t: list[float] = field(default_factory=list)
    lines: dict[str, dict[str, list[float | None]]] = field(default_factory=dict)
    marks: list[Mark] = field(default_factory=list)
    _push_impulse: np.ndarray = field(default_factory=lambda: np.zeros(3))
    _push_was_on: bool = False
    # (sample index, time [s], the push's torque about the CoM then [N m], or None when none acts), per arm sample
    _push_torques: list[tuple[int, float, np.ndarray | None]] = field(default_factory=list, repr=False)
    _last_t: float = 0.0
    _model: tuple[mujoco.MjModel, list[tuple[str, str]], np.ndarray, int | None, int] | None = field(
        default=None, repr=False)
    _rows: list[tuple[int, tuple[tuple[str, str], ...], list[float]]] = field(default_factory=list, repr=False)
    _layouts: dict[tuple[int, ...], tuple[tuple[str, str], ...]] = field(default_factory=dict, repr=False)

    def _model_info(self, m: mujoco.MjModel) -> tuple[list[tuple[str, str]], np.ndarray, int | None, int]:
        """(the torque lines' keys, torque limits, the arm's root body, the trunk's body) of `m`, once per model."""
        if self._model is None or self._model[0] is not m:
            names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, i) or f"joint {i}" for i in range(m.nu)]
            self._model = (m, [("torques", n) for n in names], m.actuator_forcerange[:, 1].copy(), _arm_root(m),
                           base_body_id(m))
            self._layouts.clear()  # a layout names the torque lines of the model before
        return self._model[1], self._model[2], self._model[3], self._model[4]

    def _put(self, plot: str, line: str, value: float | None) -> None:
        self.settle()
        column = self.lines.setdefault(plot, {}).setdefault(line, [])
        column.extend([None] * (len(self.t) - 1 - len(column)))  # a line that starts late has a gap before
        column.append(_r(value))

    def _put_row(self, groups: list[list[tuple[str, str]]], values: list[float | None]) -> None:
        """Sample each (plot, line) of `groups`, in order, with the value at its place in `values`.

        The row waits in `_rows` until `settle` (every sample of a run at once costs a fraction of one at a time).
        """
        layout = tuple(map(id, groups))  # the groups are lists held by the module or by `_model`
        named = self._layouts.get(layout)
        if named is None:
            named = self._layouts[layout] = tuple(key for group in groups for key in group)
        self._rows.append((len(self.t) - 1, named, values))

    def settle(self) -> None:
        """Put the samples still waiting into `lines` (what reads `lines` calls this first)."""
        rows, self._rows = self._rows, []
        if not rows:
            return
        groups: dict[tuple[tuple[str, str], ...], tuple[list[int], list[list[float | None]]]] = {}
        for i, keys, values in rows:
            group = groups.get(keys)
            if group is None:
                group = groups[keys] = ([], [])
            group[0].append(i)
            group[1].append(values)
        samples: dict[tuple[str, str], list[tuple[np.ndarray, np.ndarray]]] = {}
        for keys, (at, values) in groups.items():
            table = _round4(np.array(values, dtype=np.float64))  # None: NaN
            index = np.array(at, dtype=np.int64)
            for j, key in enumerate(keys):
                samples.setdefault(key, []).append((index, table[:, j]))
        for (plot, line), parts in samples.items():
            at = np.concatenate([p[0] for p in parts])
            values = np.concatenate([p[1] for p in parts])
            if len(parts) > 1:
                order = np.argsort(at, kind="stable")
                at, values = at[order], values[order]
            column = self.lines.setdefault(plot, {}).setdefault(line, [])
            start, end = int(at[0]), int(at[-1]) + 1
            if len(column) < start:
                column.extend([None] * (start - len(column)))  # a line that starts late has a gap before
            dense = np.full(end - start, np.nan)
            dense[at - start] = values
            column.extend(v if v == v else None for v in dense.tolist())

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
        qpos = frame.qpos
        w, x, y, z = float(qpos[3]), float(qpos[4]), float(qpos[5]), float(qpos[6])
        # the rotation's entries these need (`quat_to_matrix`)
        r00, r10, r20 = 1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)
        r21, r22 = 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
        cmd = frame.command
        groups = [_BASE_KEYS]
        values: list[float | None] = [math.atan2(r21, r22), -math.asin(max(-1.0, min(1.0, r20))), float(qpos[2]),
                                      float(cmd[0]), float(cmd[1]), float(cmd[2])]
        if robot is None:
            self._put_row(groups, values)
            return
        m, d = robot.model, robot.data
        torque_keys, limit, arm, base = self._model_info(m)
        mujoco.mj_subtreeVel(m, d)  # MuJoCo's subtree velocities, read below
        yaw = math.atan2(r10, r00)
        c, s = math.cos(yaw), math.sin(yaw)
        vx, vy, _ = d.qvel[:3].tolist()
        wx, wy, wz = d.qvel[3:6].tolist()
        groups.append(_VELOCITY_KEYS)
        values += [c * vx + s * vy, -s * vx + c * vy, r20 * wx + r21 * wy + r22 * wz]
        if frame.foot_force_in_world is not None:
            groups.append(_FOOT_KEYS)
            values += np.asarray(frame.foot_force_in_world)[:, 2].tolist()
        groups.append(torque_keys)
        values += [f / lim if lim > 0 else None for f, lim in zip(d.actuator_force.tolist(), limit.tolist(),
                                                                   strict=True)]
        com = d.subtree_com[base].tolist()
        pushed = frame.pushed
        torque = None
        if pushed:
            px, py, pz = (float(v) - c0 for v, c0 in zip(frame.push_point_in_world, com, strict=True))
            fx, fy, fz = (float(v) for v in frame.push_force_in_world)
            if not self._push_was_on:
                self._push_impulse = np.zeros(3)
            torque = np.array([py * fz - pz * fy, pz * fx - px * fz, px * fy - py * fx])
            # while the trial plays; `mark_episode` integrates over each push's own time span
            self._push_impulse = self._push_impulse + dt * torque
        self._push_was_on = pushed
        if arm is not None:
            self._push_torques.append((len(self.t) - 1, frame.t, torque))
            mass = float(m.body_subtreemass[arm])
            ax, ay, az = (a - b for a, b in zip(d.subtree_com[arm].tolist(), com, strict=True))
            ux, uy, uz = (a - b for a, b in zip(d.subtree_linvel[arm].tolist(), d.subtree_linvel[base].tolist(),
                                                strict=True))
            sx, sy, sz = d.subtree_angmom[arm].tolist()
            groups.append(_ARM_KEYS)
            values += [sx + mass * (ay * uz - az * uy), sy + mass * (az * ux - ax * uz),
                       sz + mass * (ax * uy - ay * ux)] + self._push_impulse.tolist()
        if plan_com is not None:
            groups.append(_PLAN_KEYS)
            values += [float(plan_com[2]), com[2], float(plan_com[0]) - com[0]]
        self._put_row(groups, values)

    def mark_episode(self, episode: Episode, *, pushes: bool = True, outcome: str | None = None,
                     error: str = "") -> None:
        """Add the episode's events: its pushes, its end, its safety layer's transitions and its operator's keys.

        The operator's keys are a hardware trial's ``p`` (a push by hand) and ``e`` (the e-stop); an episode that
        played to its end gets no end mark.

        The end's mark says how it ended: `outcome` (a trial record's, one of `wbc.arena.trial_record.OUTCOMES`;
        default: what the episode tells, `wbc.arena.trial_record.episode_outcome`), with the record's `error` for a
        controller's error. An e-stop is an ``operator stop``, the layer's own trip a ``safety trip``, never a fall.

        The push's angular impulse (``arm_momentum``'s ``push H*`` lines) is integrated again over each push's own
        time span, from its start and duration: summed per sample over whole sample intervals, the same 90 ms push
        read 1.39 N m s sampled at 50 Hz and 1.08 sampled at 500 Hz.
        """
        if len(episode.pushes):
            self._integrate_push_impulse(episode)
        if pushes:
            p = episode.pushes
            for j in range(len(p)):
                f = p.force_in_world[j]
                self.marks.append(Mark(float(p.start[j]), "push", f"push {np.linalg.norm(f):.0f} N "
                                       f"({f[0]:.0f}, {f[1]:.0f}, {f[2]:.0f})", float(p.duration[j])))
        end = _end_mark(self.name, episode, episode_outcome(episode) if outcome is None else outcome, error)
        if end is not None:
            self.marks.append(end)
        for t, a, b, reason, _ in episode.safety_events.rows():
            self.marks.append(Mark(t, "safety", f"safety {a} -> {b}: {reason}"))
        for t, key, action in episode.operator_events.rows():
            self.marks.append(Mark(t, "operator", f"operator key {key}: {action}"))
        self.marks.sort(key=lambda mk: mk.t)

    def _integrate_push_impulse(self, episode: Episode) -> None:
        """Replace the sampled push impulse by its integral over the pushes' own time spans.

        Between two samples the push acts for the overlap of their interval with its span, with the torque sampled at
        the later one (the earlier one's when the push ended between them); a new push starts from zero.
        """
        rows = self._push_torques
        if not rows:
            return
        self.settle()
        p = episode.pushes
        spans = [(float(p.start[j]), float(p.start[j] + p.duration[j])) for j in range(len(p))]
        impulse = np.zeros(3)
        columns = [self.lines.get("arm_momentum", {}).get(line) for _, line in _ARM_KEYS[3:]]
        if any(c is None for c in columns):
            return
        prev_t, prev_torque = 0.0, None
        for index, t, torque in rows:
            if any(prev_t < s <= t for s, _ in spans):
                impulse = np.zeros(3)
            acting = torque if torque is not None else prev_torque
            overlap = sum(max(0.0, min(t, e) - max(prev_t, s)) for s, e in spans)
            if acting is not None and overlap > 0.0:
                impulse = impulse + overlap * acting
            for column, value in zip(columns, impulse.tolist(), strict=True):
                if index < len(column):
                    column[index] = _r(value)
            prev_t, prev_torque = t, torque

    @classmethod
    def of_episode(cls, name: str, episode: Episode, frames: list[VizFrame] | None = None, *,
                   outcome: str | None = None, error: str = "") -> TrialSignals:
        """The signals a stored episode holds: attitude, height, velocity and yaw rate against the command.

        Its marks are `mark_episode`'s (`outcome` and `error`: its trial record's, when there is one).
        """
        out = cls(name)
        for i in range(len(episode.t)):
            q = episode.qpos[i]
            out.add_frame(VizFrame(t=float(episode.t[i]), qpos=q, command=episode.command[i]))
            out._put("velocity", "vx", float(episode.v_base_in_yaw[i, 0]))
            out._put("velocity", "vy", float(episode.v_base_in_yaw[i, 1]))
            out._put("yaw_rate", "yaw rate", float(episode.yaw_rate[i]))
        out.mark_episode(episode, outcome=outcome, error=error)
        return out

    def thinned(self, fps: float) -> TrialSignals:
        """These signals at most `fps` samples per second [1/s] (a stored episode holds every control tick)."""
        self.settle()
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
        self.settle()
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
