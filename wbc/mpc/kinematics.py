"""`RobotKinematics`: feet, hips, CoM, momentum and Jacobians of the robot from (estimated) base state and joints.

A thin layer over the Pinocchio model that speaks the house joint order and world-frame quantities the MPC
controller needs every tick.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from wbc.mpc.centroidal_model import CentroidalParams
from wbc.robots.conventions import quat_to_matrix
from wbc.robots.description import ARM_JOINTS, FOOT_NAMES, LEG_NAMES, RobotDescription
from wbc.robots.pinocchio_model import build_pinocchio

__all__ = ["RobotKinematics"]


class RobotKinematics:
    """Kinematics and centroidal quantities at one state.

    Args:
        desc: the robot (its arm mode decides whether the arm's joints exist).
    """

    def __init__(self, desc: RobotDescription) -> None:
        self.desc = desc
        self.robot = build_pinocchio(desc)
        model = self.robot.model
        self._foot_frames = [model.getFrameId(f) for f in FOOT_NAMES]
        # views of the feet's positions inside Pinocchio's data (they follow every placement update): one copy of
        # all four per tick instead of four calls
        data = self.robot.data
        self._foot_views = [data.oMf[fid].translation for fid in self._foot_frames]
        self._hip_joints = [model.getJointId(f"{leg}_thigh_joint") for leg in LEG_NAMES]
        self._perm = self.robot.joints.pin_from_house  # pin joint k is house joint perm[k]
        self._house_cols = 6 + self.robot.joints.house_from_pin  # v index of each house joint
        self.n = desc.num_joints
        self.arm_v = self._house_cols[ARM_JOINTS] if self.n == 15 else None
        self.feet = np.zeros((4, 3))
        self.feet_vel = np.zeros((4, 3))
        self.hips = np.zeros((4, 3))
        self.foot_jacobians = np.zeros((4, 3, self.n))
        self.com = np.zeros(3)
        self.com_vel = np.zeros(3)
        self.momentum = np.zeros(3)
        self.params: CentroidalParams | None = None
        self.q_pin = np.zeros(self.robot.model.nq)
        self.v_pin = np.zeros(self.robot.model.nv)
        self._rot = np.eye(3)
        self._jacobians_valid = False
        self._hips_valid = False
        self._shift_since_update = np.zeros(3)

    def compute_jacobians(self) -> np.ndarray:
        """The feet's translation Jacobians at the last `update`, world axes, house joint columns, shape (4, 3, n).

        Computed on demand: only the leg-level fallback layer needs them.
        """
        if not self._jacobians_valid:
            model, data = self.robot.model, self.robot.data
            pin.computeJointJacobians(model, data, self.q_pin)
            frame = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
            for i, fid in enumerate(self._foot_frames):
                self.foot_jacobians[i] = pin.getFrameJacobian(model, data, fid, frame)[:3, self._house_cols]
            self._jacobians_valid = True
        return self.foot_jacobians

    def hip_positions(self) -> np.ndarray:
        """The thigh joints' positions at the last `update` (moved by any `shift` since), world, shape (4, 3) [m].

        Computed on demand: only foothold refreshes need them.
        """
        if not self._hips_valid:
            data = self.robot.data
            for i, jid in enumerate(self._hip_joints):
                self.hips[i] = data.oMi[jid].translation
            self.hips += self._shift_since_update
            self._hips_valid = True
        return self.hips

    def shift(self, dp: np.ndarray, dv: np.ndarray) -> None:
        """Move the whole state by a base position and velocity correction (the estimator's update).

        `q_pin` and `v_pin` (the configuration and velocity in Pinocchio's convention) move with it.

        Rigidly translating the robot moves every point by `dp` and adds `dv` to every velocity; angular momentum
        about the CoM, Jacobians and inertia are unchanged. One Pinocchio pass per tick thus serves both the
        estimator (before its update) and the controller (after it).
        """
        self.feet += dp
        self._shift_since_update += dp
        if self._hips_valid:
            self.hips += dp
        self.com += dp
        self.feet_vel += dv
        self.com_vel += dv
        self.q_pin[0:3] += dp
        self.v_pin[0:3] += self._rot.T @ dv
        if self.params is not None:
            self.params.feet_world[:] = self.feet

    def update(self, base_pos: np.ndarray, base_quat: np.ndarray, q: np.ndarray, dq: np.ndarray,
               v_base_world: np.ndarray, omega_body: np.ndarray, *, centroidal: bool,
               rot: np.ndarray | None = None) -> None:
        """Recompute everything at a state.

        Args:
            base_pos: base position, world (3,).
            base_quat: base orientation (w, x, y, z).
            q: joint positions, house order.
            dq: joint velocities, house order.
            v_base_world: base linear velocity, world (3,).
            omega_body: base angular velocity, body frame (3,).
            centroidal: also compute the composite inertia and arm momentum matrix (for an MPC update).
            rot: the rotation matrix of `base_quat`, when the caller has it already.
        """
        model, data = self.robot.model, self.robot.data
        if rot is None:
            rot = quat_to_matrix(base_quat)
        # fresh arrays each tick (callers may keep the previous ones), filled without intermediate concatenations
        qp = np.empty(model.nq)
        qp[0:3] = base_pos
        qp[3:6] = base_quat[1:4]
        qp[6] = base_quat[0]
        qp[7:] = q[self._perm]
        vp = np.empty(model.nv)
        vp[0:3] = rot.T @ v_base_world
        vp[3:6] = omega_body
        vp[6:] = dq[self._perm]
        self.q_pin, self.v_pin, self._rot = qp, vp, rot
        pin.forwardKinematics(model, data, qp, vp)
        frame = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        feet_vel = self.feet_vel
        for i, fid in enumerate(self._foot_frames):
            pin.updateFramePlacement(model, data, fid)
            feet_vel[i] = pin.getFrameVelocity(model, data, fid, frame).linear
        self.feet[:] = self._foot_views
        self._jacobians_valid = False
        self._hips_valid = False
        self._shift_since_update[:] = 0.0
        self.com = pin.centerOfMass(model, data, pin.KinematicLevel.VELOCITY, False).copy()
        self.com_vel = data.vcom[0].copy()
        if centroidal:
            pin.ccrba(model, data, qp, vp)
            self.momentum = data.hg.angular.copy()
            a_g = data.Ag
            arm = np.zeros((3, 3)) if self.arm_v is None else a_g[3:, self.arm_v].copy()
            self.params = CentroidalParams(mass=float(data.Ig.mass), inertia_world=data.Ig.inertia.copy(),
                                           arm_momentum_matrix=arm, feet_world=self.feet.copy())
