"""`LegLayer`: the leg-level layer that turns the MPC plan into joint torques leg by leg, without a whole-body QP.

Stance feet push the planned ground reaction: tau_leg = -J_leg^T f + g_leg (the ground pushes the foot with f, so the
leg pushes the ground with -f; g_leg holds the leg's own weight). Swing feet follow their swing trajectory with a
Cartesian PD mapped through the same Jacobian: tau_leg = J_leg^T (kp (p_des - p) + kd (v_des - v)) + g_leg. J_leg is
the foot's translation Jacobian restricted to its own leg's three joints (world axes).

A stance force the motors cannot give is scaled down along its own direction until every joint of the leg is within
its torque limit: the motors would otherwise clamp each joint on its own and push the ground in another direction
than planned (at speed, the Go1's 23.7 N m thighs are reached at the end of each stance).

It is the whole controller with ``whole_body="legs"`` (the default), and the fallback when PlaCo's whole-body QP fails.
"""

from __future__ import annotations

import numpy as np

from wbc.estimation.kinematics import RobotKinematics
from wbc.mpc.compiled import leg_torques

__all__ = ["FORCE_BEFORE_PLAN", "STANCE_FORCE_BEFORE_PLAN_N", "LegLayer"]

STANCE_FORCE_BEFORE_PLAN_N = 35.0
"""Vertical force each stance foot pushes while there is no plan yet (the first MPC update failed) [N].

About a quarter of the robots' weight (a1-wx200: 15.6 kg, 153 N over four feet). A tuning value from the
controller's first version; no measurement behind it is recorded (docs/mpc-notes.md)."""

FORCE_BEFORE_PLAN = np.tile([0.0, 0.0, STANCE_FORCE_BEFORE_PLAN_N], (4, 1))
"""The stance feet's forces while there is no plan, world, shape (4, 3) [N]. Not to be written; left writable so that
the compiled leg layer takes it as it takes a plan's forces (a read-only array would compile another version)."""


class LegLayer:
    """Stance feet: -J^T f (scaled to the torque limits); swing feet: a Cartesian PD through J^T; plus gravity.

    Args:
        swing_kp: Cartesian swing stiffness [N/m].
        swing_kd: Cartesian swing damping [N s/m].
        torque_limit: the leg motors' torque limits, house order (12,) [N m].
        stance_kd: Cartesian damping of the stance feet's world velocity [N s/m]: a stance foot should not move; one
            that slides or bounces is pushed against its motion.
    """

    def __init__(self, *, swing_kp: float, swing_kd: float, torque_limit: np.ndarray, stance_kd: float = 0.0) -> None:
        self.swing_kp = swing_kp
        self.swing_kd = swing_kd
        self.stance_kd = stance_kd
        self.limit = np.array(torque_limit[:12], dtype=np.float64)
        self.scale = np.ones(4)  # each stance leg's push scale at the last call, overwritten by the next

    def torques(self, kin: RobotKinematics, contact: np.ndarray, forces: np.ndarray | None, swing_pos: np.ndarray,
                swing_vel: np.ndarray) -> np.ndarray:
        """Joint torques of one tick.

        Args:
            kin: the robot's kinematics at this tick (its leg Jacobians and gravity torques).
            contact: stance flags (4,): feet that push the plan's force.
            forces: the plan's contact forces at this tick, world, shape (4, 3) [N]; None before the first plan.
            swing_pos: swing-foot position targets, world, shape (4, 3) (stance rows ignored) [m].
            swing_vel: swing-foot velocity targets, world, shape (4, 3) [m/s].

        Returns:
            Torques, house order (n,) [N m]; on the arm's joints, gravity compensation.
        """
        if forces is None:
            forces = FORCE_BEFORE_PLAN
        tau = np.empty(kin.n)
        leg_torques(kin.leg_jacobians, kin.gravity, kin.feet, kin.feet_vel, contact, forces, swing_pos, swing_vel,
                    self.swing_kp, self.swing_kd, self.stance_kd, self.limit, self.scale, tau)
        return tau
