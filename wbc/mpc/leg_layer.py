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

from wbc.mpc.kinematics import RobotKinematics

__all__ = ["STANCE_FORCE_BEFORE_PLAN_N", "LegLayer", "scale_to_torque_limits"]

STANCE_FORCE_BEFORE_PLAN_N = 35.0
"""Vertical force each stance foot pushes while there is no plan yet (the first MPC update failed) [N].

About a quarter of the robots' weight (a1-wx200: 15.6 kg, 153 N over four feet). A tuning value from the
controller's first version; no measurement behind it is recorded (docs/mpc-notes.md)."""

_FORCE_BEFORE_PLAN = np.array([0.0, 0.0, STANCE_FORCE_BEFORE_PLAN_N])
_ONES = np.ones(4)
_ONES.setflags(write=False)


def scale_to_torque_limits(push: np.ndarray, hold: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """The largest s in [0, 1] per leg such that |s push + hold| <= limit on each of its joints.

    Args:
        push: the torques of the full force, per leg and joint, shape (4, 3) [N m].
        hold: torques that are not scaled (gravity), shape (4, 3) [N m].
        limit: torque limits, shape (4, 3) [N m].

    Returns:
        s per leg (4,); 0 where even the unscaled torques exceed a limit.
    """
    # s push + hold <= limit and >= -limit: for push > 0, s <= (limit - hold) / push; for push < 0, s <= (-limit -
    # hold) / push; joints that the force does not load give no bound
    room = np.where(push > 0.0, limit - hold, -limit - hold)
    loaded = np.abs(push) > 1e-9
    bound = np.divide(room, push, out=np.full(push.shape, np.inf), where=loaded)
    return np.clip(bound.min(axis=1), 0.0, 1.0)


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
        self.limit = np.asarray(torque_limit, dtype=np.float64)[:12].reshape(4, 3)
        self.scale = np.ones(4)

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
        stance = contact[:, None]
        if forces is None:
            forces = np.broadcast_to(_FORCE_BEFORE_PLAN, (4, 3))
        swing = self.swing_kp * (swing_pos - kin.feet) + self.swing_kd * (swing_vel - kin.feet_vel)
        push = -forces if self.stance_kd == 0.0 else -forces - self.stance_kd * kin.feet_vel
        cartesian = np.where(stance, push, swing)
        legs = (kin.leg_jacobians * cartesian[:, :, None]).sum(axis=1)  # J^T F per leg, (4, 3)
        hold = kin.gravity[:12].reshape(4, 3)
        tau = kin.gravity.copy()
        # the cheap test first: most ticks no leg is near its limits
        if np.any(np.abs(legs + hold) > self.limit):
            self.scale = np.where(contact, scale_to_torque_limits(legs, hold, self.limit), 1.0)
            legs = legs * self.scale[:, None]
        else:
            self.scale = _ONES
        tau[:12] += legs.ravel()
        return tau
