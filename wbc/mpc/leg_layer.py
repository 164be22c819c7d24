"""`LegLayer`: the leg-level layer that turns the MPC plan into joint torques leg by leg, without a whole-body QP.

Stance feet push the planned ground reaction: tau_leg = -J_leg^T f (the ground pushes the foot with f, so the leg
pushes the ground with -f). Swing feet follow their swing trajectory with a Cartesian PD mapped through the same
Jacobian: tau_leg = J_leg^T (kp (p_des - p) + kd (v_des - v)). J_leg is the foot's translation Jacobian restricted to
its own leg's three joints. The arm gets no torque here (its motors hold it by PD).

It is the whole controller with ``whole_body="legs"``, and the fallback when the whole-body QP fails.
"""

from __future__ import annotations

import numpy as np

from wbc.mpc.kinematics import RobotKinematics

__all__ = ["STANCE_FORCE_BEFORE_PLAN_N", "LegLayer"]

STANCE_FORCE_BEFORE_PLAN_N = 35.0
"""Vertical force each stance foot pushes while there is no plan yet (the first MPC update failed) [N].

About a quarter of the robots' weight (a1-wx200: 15.6 kg, 153 N over four feet). A tuning value from the
controller's first version; no measurement behind it is recorded (docs/mpc-notes.md)."""

_FORCE_BEFORE_PLAN = np.array([0.0, 0.0, STANCE_FORCE_BEFORE_PLAN_N])


class LegLayer:
    """Stance feet: -J^T f; swing feet: a Cartesian PD through J^T.

    Args:
        swing_kp: Cartesian swing stiffness [N/m].
        swing_kd: Cartesian swing damping [N s/m].
    """

    def __init__(self, *, swing_kp: float, swing_kd: float) -> None:
        self.swing_kp = swing_kp
        self.swing_kd = swing_kd

    def torques(self, kin: RobotKinematics, contact: np.ndarray, forces: np.ndarray | None, swing_pos: np.ndarray,
                swing_vel: np.ndarray) -> np.ndarray:
        """Joint torques of one tick.

        Args:
            kin: the robot's kinematics at this tick (its foot Jacobians are computed here, on demand).
            contact: stance flags (4,).
            forces: the plan's contact forces at this tick, world, shape (4, 3) [N]; None before the first plan.
            swing_pos: swing-foot position targets, world, shape (4, 3) (stance rows ignored) [m].
            swing_vel: swing-foot velocity targets, world, shape (4, 3) [m/s].

        Returns:
            Torques, house joint order (n,) [N m]; zero on the arm's joints.
        """
        tau = np.zeros(kin.n)
        jacobians = kin.compute_jacobians()
        for i in range(4):
            jac = jacobians[i][:, 3 * i:3 * i + 3]
            if contact[i]:
                f = forces[i] if forces is not None else _FORCE_BEFORE_PLAN
                tau[3 * i:3 * i + 3] = -jac.T @ f
            else:
                force = self.swing_kp * (swing_pos[i] - kin.feet[i]) + self.swing_kd * (swing_vel[i] - kin.feet_vel[i])
                tau[3 * i:3 * i + 3] = jac.T @ force
        return tau
