"""`PlanTargets`: what the whole-body QP tracks from the current MPC plan, at any tick between two MPC updates.

The plan gives states at the ends of its steps (x_1 .. x_N, from x_0 at the update) and constant forces and arm
velocities within each step. At a tick in step k, a fraction a into it:

- CoM position and velocity, orientation: x_k-1 + a (x_k - x_k-1), a linear blend between the step's ends;
- CoM acceleration: sum_i f_i / m + g, from the step's forces (the feed-forward of the CoM task);
- trunk angular velocity: I^-1 (h - A_arm dq_a) along the same blend;
- trunk angular acceleration: I^-1 sum_i (p_i - c) x f_i = I^-1 ([F]x c - sum_i [f_i]x p_i), at the CoM c and feet
  p_i measured now: linear in them, so its two matrices are built once per step and each tick costs two products;
- arm joint velocities: the step's.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from wbc.estimation.kinematics import RobotKinematics
from wbc.mpc.centroidal_model import MOMENTUM, CentroidalParams
from wbc.mpc.centroidal_mpc import MpcSolution
from wbc.robots.conventions import GRAVITY
from wbc.robots.euler import rotation_from_rpy

__all__ = ["PlanTargets", "WholeBodyTargets"]


class WholeBodyTargets(NamedTuple):
    """The plan's targets at one tick (world frame).

    Attributes:
        com: CoM position [m].
        com_vel: CoM velocity [m/s].
        com_acc: CoM acceleration feed-forward [m/s^2].
        rot: trunk orientation (body to world).
        omega: trunk angular velocity [rad/s].
        domega: trunk angular acceleration feed-forward [rad/s^2].
        arm_dq: arm joint velocities [rad/s] (zeros when the arm does not move with the plan).
    """

    com: np.ndarray
    com_vel: np.ndarray
    com_acc: np.ndarray
    rot: np.ndarray
    omega: np.ndarray
    domega: np.ndarray
    arm_dq: np.ndarray


class PlanTargets:
    """The whole-body targets of a plan, with the terms of its current step built once.

    Args:
        horizon: MPC steps N.
        step_s: MPC step length [s].
        arm_moves: the plan moves the arm (an actuated arm with arm momentum terms); otherwise its velocity is zero.
    """

    def __init__(self, *, horizon: int, step_s: float, arm_moves: bool) -> None:
        self.horizon = horizon
        self.step_s = step_s
        self.arm_moves = arm_moves
        self.reset()

    def reset(self) -> None:
        """Forget the cached step terms."""
        self._key: tuple[object, ...] | None = None
        self._terms: tuple[np.ndarray, ...] = ()

    def at(self, plan: MpcSolution, x0: np.ndarray, age_s: float, kin: RobotKinematics) -> WholeBodyTargets:
        """The targets `age_s` after the plan was made.

        Args:
            plan: the current plan.
            x0: the state the plan started from (15,).
            age_s: time since the plan was made [s]; past the horizon, its last step holds.
            kin: the robot's kinematics now (its CoM, feet and the centroidal parameters of the last update).

        Returns:
            The targets.
        """
        s = age_s / self.step_s
        k = min(int(s), self.horizon - 1)
        a = min(s - k, 1.0)
        params = kin.params
        key = self._key
        if key is None or key[0] is not plan or key[1] is not params or key[2] != k:
            self._terms, self._key = self._step_terms(plan, x0, params, k), (plan, params, k)
        start, span, com_acc, w_com, w_feet, omega0, omega1, arm_v = self._terms
        x = start + a * span
        domega = w_com @ kin.com - w_feet @ kin.feet.ravel()
        return WholeBodyTargets(com=x[0:3], com_vel=x[3:6], com_acc=com_acc, rot=rotation_from_rpy(x[6:9]),
                                omega=omega0 + a * omega1, domega=domega, arm_dq=arm_v)

    def _step_terms(self, plan: MpcSolution, x0: np.ndarray, params: CentroidalParams, k: int
                    ) -> tuple[np.ndarray, ...]:
        """What the targets need from step `k` of the plan, built once per step.

        Returns:
            The step's start state and span, CoM acceleration, the two matrices of the trunk's angular acceleration,
            the angular velocity at its start and its span, the arm velocity.
        """
        start = x0 if k == 0 else plan.states[k - 1]
        span = plan.states[k] - start
        forces = plan.forces[k]
        inertia_inv = params.inverse_inertia
        com_acc = forces.sum(axis=0) / params.mass + GRAVITY
        skews = np.zeros((3, 12))  # [ [f_0]x ... [f_3]x ]
        fx, fy, fz = forces[:, 0], forces[:, 1], forces[:, 2]
        skews[0, 1::3], skews[0, 2::3] = -fz, fy
        skews[1, 0::3], skews[1, 2::3] = fz, -fx
        skews[2, 0::3], skews[2, 1::3] = -fy, fx
        total_skew = skews.reshape(3, 4, 3).sum(axis=1)
        arm_v = plan.arm_velocity[k] if self.arm_moves else np.zeros(3)
        omega0 = inertia_inv @ (start[MOMENTUM] - params.arm_momentum_matrix @ arm_v)
        omega1 = inertia_inv @ span[MOMENTUM]
        return (start, span, com_acc, inertia_inv @ total_skew, inertia_inv @ skews, omega0, omega1, arm_v)
