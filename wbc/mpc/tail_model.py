"""The arm as a tail: its momentum, how that momentum changes with the arm's pose, and what its servos can do.

An arm swung at dq_a carries the angular momentum A_arm(q) dq_a about the robot's CoM (A_arm: the arm's columns of
the angular rows of Pinocchio's centroidal momentum matrix A_G, world axes). With the robot's total angular momentum
h held by its feet and gravity, the trunk turns at

    omega = I_c^-1 (h - A_arm(q) dq_a)        (the legs' own momentum neglected)

so swinging the arm turns the trunk the other way, as a cheetah's tail does. A_arm changes a lot with the arm's
pose (extended, it holds about five times the momentum it holds stowed, ../MPC-NOTES), so a plan over more than a
few tens of milliseconds needs its derivative along the way: `ArmTail.momentum_jacobian` is

    d(A_arm(q) dq_bar)/dq_a,

the arm's columns of d(A_G(q) v)/dq at a velocity v of the arm's joints only, from Pinocchio's
`computeCentroidalDynamicsDerivatives` (its first output). Pinocchio's dA_G/dt is no substitute: it satisfies
dh/dt = A_G a + dA_G/dt v only for the v it was computed at, so its columns are not the partial derivatives.

The servos bound what the arm does: a Dynamixel's torque falls linearly with speed, from its stall torque at rest
to zero at its no-load speed (`servo_torque_bounds`); the arm's joint accelerations follow from the torques through
the arm's rows of the equations of motion, M_aa ddq_a + b_a = tau_a (the base's and the legs' accelerations
neglected in the coupling).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from wbc.robots.pinocchio_model import PinocchioRobot

__all__ = ["ArmPoseLeverage", "ArmTail", "arm_leverage", "arm_tail", "choose_ready_pose", "servo_torque_bounds",
           "trunk_rate_change"]


@dataclass(frozen=True)
class ArmTail:
    """The arm's momentum and dynamics at one configuration (Pinocchio order throughout, world axes).

    Attributes:
        mass: the robot's total mass [kg].
        inertia_world: composite centroidal inertia I_c, shape (3, 3) [kg m^2].
        momentum_matrix: A_arm, the arm joints' columns of A_G's angular rows, shape (3, 3) [kg m^2].
        momentum_jacobian: d(A_arm dq_bar)/dq_a at the arm's velocity dq_bar, shape (3, 3) [kg m^2/s].
        mass_matrix: M_aa, the arm's block of the joint-space mass matrix (rotor inertia included), (3, 3) [kg m^2].
        bias: b_a, the arm's rows of the nonlinear effects (Coriolis, centrifugal, gravity), shape (3,) [N m].
    """

    mass: float
    inertia_world: np.ndarray
    momentum_matrix: np.ndarray
    momentum_jacobian: np.ndarray
    mass_matrix: np.ndarray
    bias: np.ndarray

    def arm_momentum(self, arm_dq: np.ndarray) -> np.ndarray:
        """A_arm dq_a: the angular momentum the arm's joint velocities carry about the CoM [N m s]."""
        return self.momentum_matrix @ np.asarray(arm_dq, dtype=np.float64)

    def trunk_rate(self, momentum: np.ndarray, arm_dq: np.ndarray) -> np.ndarray:
        """Omega = I_c^-1 (h - A_arm dq_a): the trunk's angular velocity at total momentum h, world axes [rad/s]."""
        return np.linalg.solve(self.inertia_world, np.asarray(momentum, dtype=np.float64) - self.arm_momentum(arm_dq))


def arm_tail(robot: PinocchioRobot, q: np.ndarray, v: np.ndarray, arm_v_idx: np.ndarray) -> ArmTail:
    """The `ArmTail` of `robot` at configuration `q` and velocity `v` (Pinocchio order).

    Args:
        robot: the Pinocchio model (its data buffer is overwritten).
        q: configuration (free flyer first).
        v: velocity; its arm entries are the dq_bar of `ArmTail.momentum_jacobian`.
        arm_v_idx: velocity indices of the arm joints (waist, shoulder, elbow).
    """
    model, data = robot.model, robot.data
    q = np.asarray(q, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    arm = np.asarray(arm_v_idx)
    arm_only = np.zeros(model.nv)
    arm_only[arm] = v[arm]
    dh_dq = pin.computeCentroidalDynamicsDerivatives(model, data, q, arm_only, np.zeros(model.nv))[0]
    jacobian = dh_dq[3:, arm].copy()
    pin.ccrba(model, data, q, v)
    momentum_matrix = data.Ag[3:, arm].copy()
    inertia, mass = data.Ig.inertia.copy(), float(data.Ig.mass)
    mass_matrix = pin.crba(model, data, q)
    bias = pin.nonLinearEffects(model, data, q, v)[arm].copy()
    return ArmTail(mass=mass, inertia_world=inertia, momentum_matrix=momentum_matrix, momentum_jacobian=jacobian,
                   mass_matrix=mass_matrix[np.ix_(arm, arm)].copy(), bias=bias)


def servo_torque_bounds(dq: np.ndarray, stall_torque: np.ndarray, no_load_speed: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
    """The torque range a DC servo gives at joint speed `dq`: its torque-speed line, capped at the stall torque.

    Driving with the motion, the torque falls from stall at rest to zero at the no-load speed; against the motion
    (braking) the servo gives up to its stall torque.

    Returns:
        (lower, upper) bounds on the joint torque [N m].
    """
    dq = np.asarray(dq, dtype=np.float64)
    stall = np.asarray(stall_torque, dtype=np.float64)
    speed = np.asarray(no_load_speed, dtype=np.float64)
    upper = np.clip(stall * (1.0 - dq / speed), -stall, stall)
    lower = np.clip(-stall * (1.0 + dq / speed), -stall, stall)
    return lower, upper


def trunk_rate_change(tail: ArmTail, arm_dq_before: np.ndarray, arm_dq_after: np.ndarray) -> np.ndarray:
    """The change of the trunk's angular velocity when the arm's speed changes at constant total momentum [rad/s]."""
    change = np.asarray(arm_dq_after, dtype=np.float64) - np.asarray(arm_dq_before, dtype=np.float64)
    return -np.linalg.solve(tail.inertia_world, tail.momentum_matrix @ change)


@dataclass(frozen=True)
class ArmPoseLeverage:
    """What an arm pose offers as a tail, standing at the nominal leg pose.

    Attributes:
        arm_q: the pose (waist, shoulder, elbow) [rad].
        momentum_capacity: the most angular momentum the arm holds about each world axis (roll, pitch, yaw) with
            every joint at its speed limit, sum_j |A_arm[axis, j]| v_max,j [N m s].
        holding: the static torque each joint needs to hold the pose, as a fraction of its stall torque.
        com_shift: the robot's CoM, horizontal, relative to its place with the arm stowed [m].
    """

    arm_q: np.ndarray
    momentum_capacity: np.ndarray
    holding: np.ndarray
    com_shift: np.ndarray


def arm_leverage(robot: PinocchioRobot, q: np.ndarray, arm_v_idx: np.ndarray, poses: np.ndarray,
                 velocity_limit: np.ndarray, stall_torque: np.ndarray) -> list[ArmPoseLeverage]:
    """The `ArmPoseLeverage` of each arm pose in `poses` (rows: waist, shoulder, elbow).

    The rest of `q` (Pinocchio order) is as given; the first pose is the reference of `com_shift`.
    """
    model, data = robot.model, robot.data
    arm = np.asarray(arm_v_idx)
    arm_q_idx = arm + 1  # a free flyer's configuration has one entry more than its velocity
    out, reference = [], None
    for pose in np.asarray(poses, dtype=np.float64):
        qp = np.asarray(q, dtype=np.float64).copy()
        qp[arm_q_idx] = pose
        tail = arm_tail(robot, qp, np.zeros(model.nv), arm)
        com = pin.centerOfMass(model, data, qp)[:2].copy()
        reference = com if reference is None else reference
        out.append(ArmPoseLeverage(arm_q=pose, momentum_capacity=np.abs(tail.momentum_matrix) @ velocity_limit,
                                   holding=np.abs(tail.bias) / stall_torque, com_shift=com - reference))
    return out


def choose_ready_pose(candidates: list[ArmPoseLeverage], *, max_holding: float = 0.5) -> ArmPoseLeverage:
    """The pose with the most leverage about the weaker of roll and pitch.

    Among the poses whose joints hold them with at most `max_holding` of their stall torque (the rest is the servos'
    to swing with); leverage is rounded to 1 mN m s, and ties go to the smaller CoM shift.

    Raises:
        ValueError: no candidate holds with that torque.
    """
    held = [c for c in candidates if np.all(c.holding <= max_holding)]
    if not held:
        raise ValueError(f"no arm pose of {len(candidates)} holds with at most {max_holding:.0%} of stall torque")
    return max(held, key=lambda c: (round(float(min(c.momentum_capacity[0], c.momentum_capacity[1])), 3),
                                    -float(np.linalg.norm(c.com_shift))))
