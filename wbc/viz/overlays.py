"""Overlays drawn over the robot: the push, the foot contact forces, the velocity command and the MPC's plan.

Each overlay creates its meshcat objects once (`setup`) and afterwards only poses them (`poses`): a frame is a set
of transforms and visibility flags, which a live viewer sends and a recording turns into animation tracks. Paths:

- ``wbc/push`` arrow pointing at the push's application point, its length proportional to the force (shown while
  the push acts);
- ``wbc/contacts/<FR|FL|RR|RL>`` ground reaction force on each foot (live only: stored episodes lack them);
- ``wbc/command`` the commanded horizontal velocity from the trunk, in the yaw-aligned frame;
- ``wbc/plan/com/<i>`` predicted CoM path; ``wbc/plan/footholds/<leg>`` planned footholds;
  ``wbc/plan/schedule/<leg>/<i>`` the contact schedule as a gait chart standing above the robot (rows FL, FR,
  RL, RR from the top, one column per plan step along the heading, a dark cell where the leg is in stance; the
  cells are posed in the chart's frame, ``wbc/plan/schedule``, which follows the trunk);
  ``wbc/plan/arm/<i>`` the arm tip along the arm plan; ``wbc/plan/forces/<leg>`` the first planned contact force
  at each planned foothold.
"""

from __future__ import annotations

import math

import meshcat
import meshcat.geometry as mg
import numpy as np

from wbc.robots.conventions import quat_to_matrix
from wbc.viz.frame import Pose, PoseTrack, VizFrame, identities, tracks_of
from wbc.viz.geometry import arrow_transforms, arrow_transforms_many, translation, translations
from wbc.viz.scene import RobotScene

__all__ = ["Arrow", "CommandArrow", "ContactArrows", "PlanOverlay", "PushArrow"]

HOUSE_LEGS = ("FR", "FL", "RR", "RL")
PIN_LEGS = ("FL", "FR", "RL", "RR")
"""Leg order of the MPC's arrays (Pinocchio's)."""

_HIDDEN = Pose(np.eye(4), visible=False)
_SHOWN = Pose(np.eye(4))  # a group shown where its parent is


class Arrow:
    """An arrow (cylinder shaft + cone head) at `path`.

    Args:
        path: scene path.
        color: 0xRRGGBB.
        radius: shaft radius [m].
        head_length: cone height [m].
        on_top: drawn over everything (the push arrow ends inside the trunk, at the application point).
    """

    def __init__(self, path: str, color: int, radius: float, head_length: float, *, on_top: bool = False) -> None:
        self.path = path
        self.color = color
        self.radius = radius
        self.head_length = head_length
        self.on_top = on_top

    def setup(self, vis: meshcat.Visualizer) -> None:
        """Create the shaft and head objects, hidden."""
        # on top: drawn after the opaque robot, without depth test, so it shows through the trunk it pushes
        extra = {"depthTest": False, "transparent": True, "opacity": 0.95} if self.on_top else {}
        material = mg.MeshLambertMaterial(color=self.color, **extra)
        vis[f"{self.path}/shaft"].set_object(mg.Cylinder(1.0, self.radius), material)
        vis[f"{self.path}/head"].set_object(
            mg.Cylinder(self.head_length, radiusTop=0.0, radiusBottom=2.2 * self.radius), material)
        vis[self.path].set_property("visible", False)

    def poses(self, start: np.ndarray, vector: np.ndarray, visible: bool) -> dict[str, Pose]:
        """Poses of the arrow running from `start` to ``start + vector`` [m]."""
        if not visible or float(np.linalg.norm(vector)) < 1e-6:
            return {self.path: _HIDDEN}
        shaft, head = arrow_transforms(start, vector, min(self.head_length, 0.5 * float(np.linalg.norm(vector))))
        return {self.path: _SHOWN, f"{self.path}/shaft": Pose(shaft), f"{self.path}/head": Pose(head)}

    def poses_many(self, start: np.ndarray, vector: np.ndarray, visible: np.ndarray) -> dict[str, PoseTrack]:
        """`poses` over a batch of frames: `start`, `vector` shape (n, 3) [m], `visible` shape (n,)."""
        norm = np.sqrt(np.einsum("ij,ij->i", vector, vector))
        shown = np.asarray(visible, dtype=bool) & (norm >= 1e-6)
        out = {self.path: PoseTrack.everywhere(identities(len(vector)), shown)}
        idx = np.flatnonzero(shown)
        if len(idx):
            head = np.minimum(self.head_length, 0.5 * norm[idx])
            shafts, heads = arrow_transforms_many(start[idx], vector[idx], head)
            on = np.ones(len(idx), dtype=bool)
            out[f"{self.path}/shaft"] = PoseTrack(idx, shafts, on)
            out[f"{self.path}/head"] = PoseTrack(idx, heads, on)
        return out


class PushArrow:
    """The push: an arrow ending at its application point, 2 mm per newton, shown while the push acts."""

    path = "wbc/push"
    m_per_n = 0.002

    def __init__(self) -> None:
        self.arrow = Arrow(self.path, 0xE0201B, radius=0.014, head_length=0.08, on_top=True)

    def setup(self, vis: meshcat.Visualizer) -> None:
        """Create the arrow."""
        self.arrow.setup(vis)

    def poses(self, frame: VizFrame) -> dict[str, Pose]:
        """The arrow for `frame` (hidden when no push acts)."""
        vec = self.m_per_n * frame.push_force_in_world
        return self.arrow.poses(frame.push_point_in_world - vec, vec, frame.pushed)

    def poses_many(self, frames: list[VizFrame]) -> dict[str, PoseTrack]:
        """`poses` over a batch of frames."""
        force = np.array([f.push_force_in_world for f in frames], dtype=np.float64).reshape(-1, 3)
        point = np.array([f.push_point_in_world for f in frames], dtype=np.float64).reshape(-1, 3)
        vec = self.m_per_n * force
        return self.arrow.poses_many(point - vec, vec, np.any(force != 0.0, axis=1))


class ContactArrows:
    """Ground reaction force on each foot, from the foot up, 2 mm per newton."""

    m_per_n = 0.002

    def __init__(self) -> None:
        self.arrows = [Arrow(f"wbc/contacts/{leg}", 0x1E9E3A, radius=0.006, head_length=0.025, on_top=True)
                       for leg in HOUSE_LEGS]

    def setup(self, vis: meshcat.Visualizer) -> None:
        """Create the four arrows."""
        for a in self.arrows:
            a.setup(vis)

    def poses(self, frame: VizFrame, feet: np.ndarray) -> dict[str, Pose]:
        """Arrows at the feet (`feet`: house order, shape (4, 3) [m]); hidden without force data or contact."""
        out: dict[str, Pose] = {}
        forces = frame.foot_force_in_world
        for i, a in enumerate(self.arrows):
            f = np.zeros(3) if forces is None else forces[i]
            out.update(a.poses(feet[i], self.m_per_n * f, float(np.linalg.norm(f)) > 1.0))
        return out

    def poses_many(self, frames: list[VizFrame], feet: np.ndarray) -> dict[str, PoseTrack]:
        """`poses` over a batch of frames (`feet`: shape (n, 4, 3) [m])."""
        forces = np.array([np.zeros((4, 3)) if f.foot_force_in_world is None else f.foot_force_in_world
                           for f in frames], dtype=np.float64).reshape(-1, 4, 3)
        out: dict[str, PoseTrack] = {}
        for i, a in enumerate(self.arrows):
            f = forces[:, i]
            out.update(a.poses_many(feet[:, i], self.m_per_n * f, np.sqrt(np.einsum("ij,ij->i", f, f)) > 1.0))
        return out


class CommandArrow:
    """The commanded horizontal velocity, drawn from above the trunk, 1 m per m/s, in the yaw-aligned frame."""

    path = "wbc/command"

    def __init__(self) -> None:
        self.arrow = Arrow(self.path, 0x2660D9, radius=0.008, head_length=0.04)

    def setup(self, vis: meshcat.Visualizer) -> None:
        """Create the arrow."""
        self.arrow.setup(vis)

    def poses(self, frame: VizFrame) -> dict[str, Pose]:
        """The arrow for `frame` (hidden for a zero command)."""
        rot = quat_to_matrix(frame.qpos[3:7])
        yaw = math.atan2(rot[1, 0], rot[0, 0])
        c, s = math.cos(yaw), math.sin(yaw)
        vx, vy = float(frame.command[0]), float(frame.command[1])
        vec = np.array([c * vx - s * vy, s * vx + c * vy, 0.0])
        start = frame.qpos[:3] + np.array([0.0, 0.0, 0.15])
        return self.arrow.poses(start, vec, bool(np.hypot(vx, vy) > 1e-3))

    def poses_many(self, frames: list[VizFrame]) -> dict[str, PoseTrack]:
        """`poses` over a batch of frames."""
        qpos = np.array([f.qpos[:7] for f in frames], dtype=np.float64).reshape(-1, 7)
        cmd = np.array([f.command[:2] for f in frames], dtype=np.float64).reshape(-1, 2)
        w, x, y, z = qpos[:, 3], qpos[:, 4], qpos[:, 5], qpos[:, 6]
        yaw = np.arctan2(2 * (x * y + w * z), 1 - 2 * (y * y + z * z))  # from the rotation's first column
        c, s = np.cos(yaw), np.sin(yaw)
        vec = np.zeros((len(frames), 3))
        vec[:, 0] = c * cmd[:, 0] - s * cmd[:, 1]
        vec[:, 1] = s * cmd[:, 0] + c * cmd[:, 1]
        start = qpos[:, :3] + np.array([0.0, 0.0, 0.15])
        return self.arrow.poses_many(start, vec, np.hypot(cmd[:, 0], cmd[:, 1]) > 1e-3)


class PlanOverlay:
    """The MPC's plan: CoM path, footholds, contact schedule, arm tip path, first planned forces.

    Args:
        horizon: the most plan steps drawn (spheres and schedule cells are created once for that many).
    """

    root = "wbc/plan"
    cell_dx = 0.03   # [m] gait chart: one column per plan step
    cell_dy = 0.025  # [m] one row per leg
    strip_height = 0.45  # [m] above the trunk
    n_per_m = 0.001

    def __init__(self, horizon: int = 16) -> None:
        self.horizon = horizon
        self.forces = [Arrow(f"{self.root}/forces/{leg}", 0x18B5C4, radius=0.005, head_length=0.02)
                       for leg in PIN_LEGS]
        # the paths, named once: a recording poses them at every frame
        self._com_paths = [f"{self.root}/com/{i}" for i in range(horizon)]
        self._arm_paths = [f"{self.root}/arm/{i}" for i in range(horizon)]
        self._hold_paths = [f"{self.root}/footholds/{leg}" for leg in PIN_LEGS]
        self._cell_paths = [[f"{self.root}/schedule/{leg}/{i}" for i in range(horizon)] for leg in PIN_LEGS]
        # the chart's cells at their fixed places in the chart, (hidden, shown), by leg and plan step
        self._cells = [[(Pose(m, visible=False), Pose(m)) for m in (
            translation(np.array([(i - 0.5 * horizon) * self.cell_dx, 0.0, (1.5 - k) * self.cell_dy]))
            for i in range(horizon))] for k in range(len(PIN_LEGS))]

    def setup(self, vis: meshcat.Visualizer) -> None:
        """Create the plan's objects, hidden."""
        # the CoM path runs inside the trunk: drawn over it
        com = mg.MeshLambertMaterial(color=0xF2C12E, depthTest=False, transparent=True, opacity=0.95)
        arm = mg.MeshLambertMaterial(color=0xF08A24)
        foot = mg.MeshLambertMaterial(color=0xC23BD4)
        cell = mg.MeshLambertMaterial(color=0x303030)
        for i in range(self.horizon):
            vis[f"{self.root}/com/{i}"].set_object(mg.Sphere(0.012), com)
            vis[f"{self.root}/arm/{i}"].set_object(mg.Sphere(0.01), arm)
            for leg in PIN_LEGS:
                vis[f"{self.root}/schedule/{leg}/{i}"].set_object(
                    mg.Box([0.9 * self.cell_dx, 0.004, 0.8 * self.cell_dy]), cell)
        for leg in PIN_LEGS:
            vis[f"{self.root}/footholds/{leg}"].set_object(mg.Cylinder(0.004, 0.025), foot)
        for a in self.forces:
            a.setup(vis)
        vis[self.root].set_property("visible", False)

    def poses(self, frame: VizFrame, scene: RobotScene) -> dict[str, Pose]:
        """The plan's poses for `frame` (everything hidden without a plan)."""
        plan = frame.plan
        if plan is None:
            return {self.root: _HIDDEN}
        out: dict[str, Pose] = {self.root: _SHOWN}
        com = translations(np.asarray(plan["com_path_in_world"])[: self.horizon])
        for i, path in enumerate(self._com_paths):
            out[path] = Pose(com[i]) if i < len(com) else _HIDDEN
        tips = None
        if "arm_q_plan" in plan:
            tips = scene.arm_tip_path(frame.qpos, np.asarray(plan["arm_q_plan"])[: self.horizon])
        tips = translations(tips) if tips is not None else ()
        for i, path in enumerate(self._arm_paths):
            out[path] = Pose(tips[i]) if i < len(tips) else _HIDDEN
        rot_z = _yaw_rotation(frame.qpos)
        holds = np.asarray(plan["footholds_in_world"])
        discs = translations(holds[: len(PIN_LEGS)])
        discs[:, :3, :3] = _UPRIGHT  # a disc flat on the ground
        for k, path in enumerate(self._hold_paths):
            out[path] = Pose(discs[k])
        schedule = np.asarray(plan["contact_schedule"], dtype=bool)
        # the chart moves as one (its group's transform); its cells only show or hide, at fixed places in it
        strip = np.eye(4)
        strip[:3, :3] = rot_z
        strip[:3, 3] = frame.qpos[:3] + np.array([0.0, 0.0, self.strip_height])
        out[f"{self.root}/schedule"] = Pose(strip)
        steps = min(len(schedule), self.horizon)
        for k, paths in enumerate(self._cell_paths):
            cells = self._cells[k]
            stance = schedule[:steps, k].tolist()
            for i, path in enumerate(paths):
                out[path] = cells[i][i < steps and stance[i]]
        forces = np.asarray(plan["forces_in_world"])
        for k, a in enumerate(self.forces):
            f = forces[0, k] if len(forces) else np.zeros(3)
            out.update(a.poses(holds[k], self.n_per_m * f, float(np.linalg.norm(f)) > 1.0))
        return out

    def poses_many(self, frames: list[VizFrame], scene: RobotScene) -> dict[str, PoseTrack]:
        """`poses` over a batch of frames (the plan changes shape from frame to frame: posed one frame at a time)."""
        if all(f.plan is None for f in frames):
            return {self.root: PoseTrack.everywhere(identities(len(frames)), np.zeros(len(frames), dtype=bool))}
        return tracks_of([self.poses(f, scene) for f in frames])


_UPRIGHT = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
"""Rotation laying meshcat's cylinder (axis y) flat on the ground (axis z)."""


def _yaw_rotation(qpos: np.ndarray) -> np.ndarray:
    rot = quat_to_matrix(qpos[3:7])
    yaw = math.atan2(rot[1, 0], rot[0, 0])
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
