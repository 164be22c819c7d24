"""`SceneContent`: everything the viewer draws for one robot and trial, and the registry of its scene paths.

It builds the scene once (`setup`) on any meshcat `Visualizer` (a live server's, or a recording's) and turns a
`VizFrame` into node poses (`poses`); the live viewer sends those poses, the recorder turns them into an animation.
The camera follows the trunk: the point under it is posed as `FOLLOW`, which the trial page's script moves the camera
and its orbit target with (`wbc.viz.page_script`).
"""

from __future__ import annotations

import meshcat
import numpy as np

from wbc.robots.description import RobotDescription
from wbc.scenario.terrain import TerrainConfig
from wbc.viz.frame import Pose, PoseTrack, VizFrame
from wbc.viz.geometry import translation, translations
from wbc.viz.overlays import CommandArrow, ContactArrows, PlanOverlay, PushArrow
from wbc.viz.scene import RobotScene
from wbc.viz.sim_frames import SimulatedWorld
from wbc.viz.terrain_mesh import setup_terrain, terrain_heights

__all__ = ["CAMERA", "FOLLOW", "SceneContent"]

CAMERA = "/Cameras/default"
FOLLOW = "/Cameras/follow"
"""An empty node posed at the point on the ground under the trunk, for the trial page to frame (with `follow`).

meshcat's orbit controls look at a target in the world whatever the camera's parent is posed at, so moving
`CAMERA` alone turned the camera towards the world's origin as the robot walked off; the page moves the camera and
the target together by where this node went."""
CAMERA_OFFSET = (0.75, 0.55, 1.05)
"""Camera position relative to the point it orbits, in meshcat's y-up camera frame: 0.75 m along world x, 1.05 m
along world y, 0.55 m up (a three-quarter view of the robot's left side)."""


class SceneContent:
    """The robot, its ground and the overlays.

    Args:
        desc: the robot.
        terrain: the trial's ground.
        heights: its normalised heights (`wbc.viz.terrain_mesh.terrain_heights`; None when flat).
        follow: pose `FOLLOW` under the trunk, for the page's camera to follow.

    Attributes:
        paths: every scene path created by `setup`, by role (``robot``, ``arm``, ``terrain``, ``push``,
            ``contacts``, ``command``, ``plan``), relative to the visualizer's root (``/meshcat``).
    """

    @classmethod
    def for_trial(cls, desc: RobotDescription, terrain: TerrainConfig, terrain_seed: int) -> SceneContent:
        """The content of a trial: its robot and its ground (from the terrain seed)."""
        return cls(desc, terrain, terrain_heights(terrain, terrain_seed))

    @classmethod
    def for_robot(cls, robot: SimulatedWorld) -> SceneContent:
        """The content of a simulated robot as it is now (its heightfield read from the MuJoCo model)."""
        heights = None
        m = robot.model
        if robot.config.terrain.kind != "flat" and m.nhfield > 0:
            heights = m.hfield_data[m.hfield_adr[0]:m.hfield_adr[0] + m.hfield_nrow[0] * m.hfield_ncol[0]]
            heights = heights.reshape(m.hfield_nrow[0], m.hfield_ncol[0]).copy()
        return cls(robot.desc, robot.config.terrain, heights)

    @classmethod
    def for_description(cls, desc: RobotDescription) -> SceneContent:
        """The content of a robot nothing is known of but itself: on flat ground (a real robot's own is unknown)."""
        return cls(desc, TerrainConfig(kind="flat"), None)

    def __init__(self, desc: RobotDescription, terrain: TerrainConfig, heights: np.ndarray | None, *,
                 follow: bool = True) -> None:
        self.robot = RobotScene(desc)
        self.terrain = terrain
        self.heights = heights
        self.follow = follow
        self.push = PushArrow()
        self.contacts = ContactArrows()
        self.command = CommandArrow()
        self.plan = PlanOverlay()
        self.paths: dict[str, list[str]] = {}

    def setup(self, vis: meshcat.Visualizer) -> None:
        """Create every object on `vis` and fill `paths`."""
        self.robot.setup(vis)
        self.paths = {
            "robot": list(self.robot.paths["robot"]),
            "arm": list(self.robot.paths["arm"]),
            "terrain": [setup_terrain(vis, self.terrain, self.heights)],
        }
        self.push.setup(vis)
        self.contacts.setup(vis)
        self.command.setup(vis)
        self.plan.setup(vis)
        self.paths["push"] = [self.push.path]
        self.paths["contacts"] = [a.path for a in self.contacts.arrows]
        self.paths["command"] = [self.command.path]
        self.paths["plan"] = [self.plan.root]
        vis[f"{CAMERA}/rotated/<object>"].set_property("position", list(CAMERA_OFFSET))
        vis["/Axes"].set_property("visible", False)  # its z axis would stand inside the robot at the origin
        # the z = 0 grid would cut through a heightfield
        vis["/Grid"].set_property("visible", self.terrain.kind == "flat")

    def poses(self, frame: VizFrame) -> dict[str, Pose]:
        """Every moving node's pose at `frame` (paths relative to the root, `FOLLOW`'s absolute)."""
        data = self.robot.kinematics(frame.qpos)
        out = self.robot.poses(data)
        out.update(self.push.poses(frame))
        out.update(self.contacts.poses(frame, self.robot.feet_in_world(data)))
        out.update(self.command.poses(frame))
        out.update(self.plan.poses(frame, self.robot))
        if self.follow:
            base = np.asarray(frame.qpos[:3], dtype=np.float64)
            out[FOLLOW] = Pose(translation(np.array([base[0], base[1], 0.0])))
        return out

    def poses_many(self, frames: list[VizFrame]) -> dict[str, PoseTrack]:
        """`poses` over a batch of frames, each moving node's as one track (what a recording keys)."""
        qpos = np.array([f.qpos for f in frames], dtype=np.float64)
        out, feet = self.robot.poses_many(qpos)
        out.update(self.push.poses_many(frames))
        out.update(self.contacts.poses_many(frames, feet))
        out.update(self.command.poses_many(frames))
        out.update(self.plan.poses_many(frames, self.robot))
        if self.follow:
            ground = qpos[:, :3].copy()
            ground[:, 2] = 0.0
            out[FOLLOW] = PoseTrack.everywhere(translations(ground))
        return out
