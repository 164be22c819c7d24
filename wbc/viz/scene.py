"""`RobotScene`: the robot and its arm in meshcat, posed from a MuJoCo configuration through Pinocchio.

Every visual geometry object hangs, at its fixed placement, under a node per Pinocchio joint:
``wbc/robot/<joint>/<geometry>`` for the quadruped, ``wbc/arm/<joint>/<geometry>`` for the arm's links. Only the
joint nodes move, so a frame is one transform per joint (17 for the A1 with its arm), live or in a recorded
animation.
"""

from __future__ import annotations

import meshcat
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin

from wbc.robots.description import FOOT_NAMES, RobotDescription
from wbc.robots.pinocchio_model import build_pinocchio
from wbc.viz.frame import Pose, PoseTrack
from wbc.viz.meshes import robot_parts

__all__ = ["RobotScene"]

ROBOT = "wbc/robot"
ARM = "wbc/arm"
_REVOLUTE = {"JointModelRX": 0, "JointModelRY": 1, "JointModelRZ": 2}
"""Pinocchio's revolute joints about one axis of their frame, and that axis."""


class RobotScene:
    """The robot's meshes and the kinematics that pose them.

    Args:
        desc: the robot (its arm mode decides whether the arm is drawn and moves).
        mesh_cell: mesh simplification grid [m].

    Attributes:
        paths: scene paths created by `setup`, by role: ``robot`` (trunk and legs) and ``arm``.
    """

    def __init__(self, desc: RobotDescription, *, mesh_cell: float = 0.003) -> None:
        self.desc = desc
        self.pin = build_pinocchio(desc)
        self.parts = robot_parts(desc, self.pin.model, cell=mesh_cell)
        model = self.pin.model
        self._foot_frames = [model.getFrameId(f) for f in FOOT_NAMES]
        self._nodes: list[tuple[str, int]] = []  # (path, joint id) of every moving node
        self.paths: dict[str, list[str]] = {"robot": [], "arm": []}
        self._tip = self._arm_tip()

    def _arm_tip(self) -> tuple[int, np.ndarray] | None:
        """(joint id, point in joint frame) of the arm's far end: the last arm link's cylinder end."""
        arm = [p for p in self.parts if p.is_arm and isinstance(p.geometry, mg.Cylinder)]
        if not arm:
            return None
        last = arm[-1]
        half = 0.5 * float(last.geometry.height)
        # the cylinder's axis is the placement's y (meshcat's cylinder axis), its far end at +y
        return last.joint_id, last.placement[:3, 3] + half * last.placement[:3, 1]

    def setup(self, vis: meshcat.Visualizer) -> None:
        """Send every mesh to `vis` (static placements under the joint nodes)."""
        seen = set()
        for part in self.parts:
            root = ARM if part.is_arm else ROBOT
            node = f"{root}/{part.joint}"
            path = f"{node}/{part.name}"
            material = mg.MeshLambertMaterial(color=part.color)
            vis[path].set_object(mg.Mesh(part.geometry, material))
            vis[path].set_transform(part.placement)
            self.paths["arm" if part.is_arm else "robot"].append(path)
            if node not in seen:
                seen.add(node)
                self._nodes.append((node, part.joint_id))

    def kinematics(self, qpos: np.ndarray) -> pin.Data:
        """Forward kinematics (joint placements and frames) at MuJoCo configuration `qpos`."""
        model, data = self.pin.model, self.pin.data
        pin.framesForwardKinematics(model, data, self.pin.joints.q_pin(qpos))
        return data

    def poses(self, data: pin.Data) -> dict[str, Pose]:
        """Poses of the joint nodes after `kinematics`."""
        return {path: Pose(data.oMi[j].homogeneous.copy()) for path, j in self._nodes}

    def poses_many(self, qpos: np.ndarray) -> tuple[dict[str, PoseTrack], np.ndarray]:
        """`poses` and `feet_in_world` over a batch of configurations, shape (n, nq).

        Returns:
            (the joint nodes' tracks, the foot centres shape (n, 4, 3) [m]).
        """
        # `q_pin` over the batch: base position, quaternion (x, y, z, w), joints in Pinocchio's order
        q = np.concatenate([qpos[:, :3], qpos[:, [4, 5, 6, 3]], qpos[:, 7:][:, self.pin.joints.pin_from_house]],
                           axis=1)
        placements = self._placements(q)
        model = self.pin.model
        feet = np.empty((len(q), 4, 3))
        for k, f in enumerate(self._foot_frames):
            frame = model.frames[f]
            parent, point = placements[frame.parentJoint], frame.placement.translation
            feet[:, k] = parent[:, :3, :3] @ point + parent[:, :3, 3]
        return {path: PoseTrack.everywhere(placements[j]) for path, j in self._nodes}, feet

    def _placements(self, q: np.ndarray) -> np.ndarray:
        """Every joint's placement in the world (Pinocchio's ``oMi``) at each configuration of `q` (n, nq).

        Forward kinematics over the whole batch at once, joint by joint down the tree: a free flyer at the root,
        revolute joints about x, y or z below it (the robots' joints); any other joint is posed by Pinocchio, one
        configuration at a time.

        Returns:
            Shape (njoints, n, 4, 4).
        """
        model = self.pin.model
        n = len(q)
        out = np.empty((model.njoints, n, 4, 4))
        out[0] = np.eye(4)
        for j in range(1, model.njoints):
            joint = model.joints[j]
            kind, iq = joint.shortname(), joint.idx_q
            local = np.zeros((n, 4, 4))
            local[:, 3, 3] = 1.0
            if kind == "JointModelFreeFlyer":
                local[:, :3, 3] = q[:, iq:iq + 3]
                x, y, z, w = (q[:, iq + 3 + i] for i in range(4))
                local[:, 0, 0], local[:, 0, 1], local[:, 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), \
                    2 * (x * z + w * y)
                local[:, 1, 0], local[:, 1, 1], local[:, 1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), \
                    2 * (y * z - w * x)
                local[:, 2, 0], local[:, 2, 1], local[:, 2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), \
                    1 - 2 * (x * x + y * y)
            elif kind in _REVOLUTE:
                a = _REVOLUTE[kind]
                b, c = (a + 1) % 3, (a + 2) % 3
                cos, sin = np.cos(q[:, iq]), np.sin(q[:, iq])
                local[:, a, a] = 1.0
                local[:, b, b], local[:, b, c], local[:, c, b], local[:, c, c] = cos, -sin, sin, cos
            else:
                return self._placements_one_by_one(q)
            out[j] = out[model.parents[j]] @ model.jointPlacements[j].homogeneous @ local
        return out

    def _placements_one_by_one(self, q: np.ndarray) -> np.ndarray:
        """`_placements` by Pinocchio, one configuration at a time (for joints the batch does not pose)."""
        model, data = self.pin.model, self.pin.data
        out = np.empty((model.njoints, len(q), 4, 4))
        for i in range(len(q)):
            pin.forwardKinematics(model, data, q[i])
            for j in range(model.njoints):
                out[j, i] = data.oMi[j].homogeneous
        return out

    def feet_in_world(self, data: pin.Data) -> np.ndarray:
        """Foot centres, house order FR, FL, RR, RL, after `kinematics`, shape (4, 3) [m]."""
        return np.array([data.oMf[f].translation for f in self._foot_frames])

    def arm_tip_path(self, qpos: np.ndarray, arm_q: np.ndarray) -> np.ndarray | None:
        """Arm tip positions in the world for each row of arm joint angles `arm_q` (waist, shoulder, elbow).

        Args:
            qpos: the current MuJoCo configuration (the base and legs stay as they are).
            arm_q: arm joint angles, shape (N, 3) [rad].

        Returns:
            Shape (N, 3) [m], or None without an actuated arm.
        """
        if self._tip is None or self.desc.arm_mode != "actuated":
            return None
        joint, point = self._tip
        q = qpos.copy()
        out = np.empty((len(arm_q), 3))
        model, data = self.pin.model, self.pin.data
        for i, row in enumerate(arm_q):
            q[7 + 12:7 + 15] = row
            pin.forwardKinematics(model, data, self.pin.joints.q_pin(q))
            out[i] = data.oMi[joint].act(point)
        return out
