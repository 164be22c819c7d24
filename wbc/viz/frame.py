"""`VizFrame`: what the viewer draws at one instant, whether it comes from a live simulation or a stored episode.

Live frames carry simulator truth (contact forces, the push being applied) and the controller's plan; frames
rebuilt from an `Episode` carry the configuration, the command and the pushes of its `PushLog`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Pose", "PoseTrack", "VizFrame", "identities", "tracks_of"]


@dataclass(frozen=True, kw_only=True)
class VizFrame:
    """One instant of a trial.

    Attributes:
        t: time [s].
        qpos: MuJoCo configuration [base position (3), base quaternion (w, x, y, z), joints in house order].
        command: commanded (vx, vy, yaw_rate) in the yaw-aligned base frame [m/s, m/s, rad/s].
        push_force_in_world: external push acting now, shape (3,) [N] (zeros when none acts).
        push_point_in_world: where it acts, shape (3,) [m].
        foot_force_in_world: ground reaction force on each foot, house order FR, FL, RR, RL, shape (4, 3) [N];
            None when unknown (replays of stored episodes).
        plan: the controller's plan (`MpcController.debug_plan()`), or None.
    """

    t: float
    qpos: np.ndarray
    command: np.ndarray = field(default_factory=lambda: np.zeros(3))
    push_force_in_world: np.ndarray = field(default_factory=lambda: np.zeros(3))
    push_point_in_world: np.ndarray = field(default_factory=lambda: np.zeros(3))
    foot_force_in_world: np.ndarray | None = None
    plan: dict[str, np.ndarray] | None = None

    @property
    def pushed(self) -> bool:
        """True while a push acts."""
        return bool(np.any(self.push_force_in_world != 0.0))


@dataclass(frozen=True)
class Pose:
    """Where a scene node is and whether it shows.

    Attributes:
        matrix: homogeneous transform of the node in its parent (the world, except for the cells of the MPC's
            gait chart, posed in the chart's frame), may include scale, shape (4, 4); never changed once handed out
            (a recording takes the same array again as the same value).
        visible: whether the node (and its children) is drawn.
    """

    matrix: np.ndarray
    visible: bool = True


@dataclass(frozen=True)
class PoseTrack:
    """A node's poses over a batch of frames: the frames that pose it, with each one's transform and visibility.

    Attributes:
        frames: indices into the batch of the frames that pose the node, increasing, shape (m,).
        matrices: the node's transform in its parent at each of them (see `Pose`), shape (m, 4, 4).
        visible: whether it shows at each of them, shape (m,).
    """

    frames: np.ndarray
    matrices: np.ndarray
    visible: np.ndarray

    @classmethod
    def everywhere(cls, matrices: np.ndarray, visible: np.ndarray | None = None) -> PoseTrack:
        """A node posed at every frame of the batch (shown at all of them unless `visible` says otherwise)."""
        n = len(matrices)
        return cls(np.arange(n), matrices, np.ones(n, dtype=bool) if visible is None else visible)


_IDENTITY = np.eye(4)


def identities(n: int) -> np.ndarray:
    """Identity transforms, shape (n, 4, 4) (a read-only view)."""
    return np.broadcast_to(_IDENTITY, (n, 4, 4))


def tracks_of(poses: list[dict[str, Pose]]) -> dict[str, PoseTrack]:
    """The tracks of a batch of frames each posed on its own (a dict of node poses per frame), in first-posed order."""
    rows: dict[str, tuple[list[int], list[np.ndarray], list[bool]]] = {}
    for i, frame in enumerate(poses):
        for path, pose in frame.items():
            row = rows.get(path)
            if row is None:
                row = rows[path] = ([], [], [])
            row[0].append(i)
            row[1].append(pose.matrix)
            row[2].append(bool(pose.visible))
    return {path: PoseTrack(np.array(ks, dtype=np.int64), np.array(ms, dtype=np.float64), np.array(vs, dtype=bool))
            for path, (ks, ms, vs) in rows.items()}
