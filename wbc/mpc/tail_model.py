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

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from wbc.robots.pinocchio_model import PinocchioRobot

__all__ = ["ArmPoseLeverage", "ArmTail", "ArmTailPath", "arm_leverage", "arm_tail", "arm_tail_path",
           "choose_ready_pose", "servo_torque_bounds", "trunk_rate_change"]


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

    One pass of Pinocchio's `computeCentroidalDynamicsDerivatives` at the arm's velocity alone gives the momentum
    Jacobian and, on its way, A_G and the composite inertia (which depend on q only: the same as `ccrba`'s); `crba`
    gives the mass matrix and `nonLinearEffects` the bias, at the full velocity.

    Args:
        robot: the Pinocchio model (its data buffer is overwritten).
        q: configuration (free flyer first).
        v: velocity; its arm entries are the dq_bar of `ArmTail.momentum_jacobian`.
        arm_v_idx: velocity indices of the arm joints (waist, shoulder, elbow).
    """
    tails = _TailEvaluator(robot, arm_v_idx, 1)
    tails.fill(0, np.asarray(q, dtype=np.float64), np.asarray(v, dtype=np.float64))
    return ArmTail(mass=float(tails.mass[0]), inertia_world=tails.inertia_world[0],
                   momentum_matrix=tails.momentum_matrix[0], momentum_jacobian=tails.momentum_jacobian[0],
                   mass_matrix=tails.mass_matrix[0], bias=tails.bias[0])


class _TailEvaluator:
    """Evaluates `arm_tail` step by step into stacked arrays (those of an `ArmTailPath` of `n` steps)."""

    def __init__(self, robot: PinocchioRobot, arm_v_idx: np.ndarray, n: int) -> None:
        self.model, self.data = robot.model, robot.data
        arm = np.asarray(arm_v_idx)
        contiguous = arm.size > 0 and np.array_equal(arm, np.arange(arm[0], arm[0] + arm.size))
        self.arm = arm
        self._cols = slice(int(arm[0]), int(arm[0]) + arm.size) if contiguous else arm  # a slice reads faster
        self._block = (self._cols, self._cols) if contiguous else np.ix_(arm, arm)
        self._arm_only = np.zeros(self.model.nv)
        self._zero = np.zeros(self.model.nv)
        self.mass = np.empty(n)
        self.inertia_world = np.empty((n, 3, 3))
        self.momentum_matrix = np.empty((n, 3, 3))
        self.momentum_jacobian = np.empty((n, 3, 3))
        self.mass_matrix = np.empty((n, 3, 3))
        self.bias = np.empty((n, 3))

    def fill(self, k: int, q: np.ndarray, v: np.ndarray) -> None:
        """Step k: the arm's tail at `q`, `v` (float arrays)."""
        model, data, cols = self.model, self.data, self._cols
        self._arm_only[cols] = v[cols]
        dh_dq = pin.computeCentroidalDynamicsDerivatives(model, data, q, self._arm_only, self._zero)[0]
        self.momentum_jacobian[k] = dh_dq[3:, cols]
        self.momentum_matrix[k] = data.Ag[3:, cols]
        composite = data.Ig
        self.inertia_world[k] = composite.inertia
        self.mass[k] = composite.mass
        self.mass_matrix[k] = pin.crba(model, data, q)[self._block]
        self.bias[k] = pin.nonLinearEffects(model, data, q, v)[cols]


@dataclass(frozen=True)
class ArmTailPath:
    """The arm's `ArmTail` at each step of a path of arm poses and speeds, stacked step by step.

    What `wbc.mpc.tail_mpc.TailMpc` plans along: step k's model is linearised about the arm at `arm_q[k]`,
    `arm_dq[k]`, with the rest of the robot where it is now.

    Attributes:
        arm_q: the arm's pose at each step, shape (n, 3) [rad].
        arm_dq: its speed at each step, shape (n, 3) [rad/s].
        mass: `ArmTail.mass` at each step, shape (n,) [kg].
        inertia_world: `ArmTail.inertia_world` at each step, shape (n, 3, 3) [kg m^2].
        momentum_matrix: `ArmTail.momentum_matrix` at each step, shape (n, 3, 3) [kg m^2].
        momentum_jacobian: `ArmTail.momentum_jacobian` at each step, shape (n, 3, 3) [kg m^2/s].
        mass_matrix: `ArmTail.mass_matrix` at each step, shape (n, 3, 3) [kg m^2].
        bias: `ArmTail.bias` at each step, shape (n, 3) [N m].
    """

    arm_q: np.ndarray
    arm_dq: np.ndarray
    mass: np.ndarray
    inertia_world: np.ndarray
    momentum_matrix: np.ndarray
    momentum_jacobian: np.ndarray
    mass_matrix: np.ndarray
    bias: np.ndarray

    def __len__(self) -> int:
        return self.arm_q.shape[0]

    def tail(self, k: int) -> ArmTail:
        """Step k's `ArmTail` (copies)."""
        return ArmTail(mass=float(self.mass[k]), inertia_world=self.inertia_world[k].copy(),
                       momentum_matrix=self.momentum_matrix[k].copy(),
                       momentum_jacobian=self.momentum_jacobian[k].copy(), mass_matrix=self.mass_matrix[k].copy(),
                       bias=self.bias[k].copy())

    @classmethod
    def stack(cls, tails: Sequence[ArmTail], arm_q: np.ndarray, arm_dq: np.ndarray) -> ArmTailPath:
        """The path of `tails`, one per step, at the arm poses `arm_q` and speeds `arm_dq` (n, 3) they were taken at."""
        return cls(arm_q=np.array(arm_q, dtype=np.float64).reshape(-1, 3),
                   arm_dq=np.array(arm_dq, dtype=np.float64).reshape(-1, 3),
                   mass=np.array([t.mass for t in tails], dtype=np.float64),
                   inertia_world=np.array([t.inertia_world for t in tails], dtype=np.float64).reshape(-1, 3, 3),
                   momentum_matrix=np.array([t.momentum_matrix for t in tails], dtype=np.float64).reshape(-1, 3, 3),
                   momentum_jacobian=np.array([t.momentum_jacobian for t in tails],
                                              dtype=np.float64).reshape(-1, 3, 3),
                   mass_matrix=np.array([t.mass_matrix for t in tails], dtype=np.float64).reshape(-1, 3, 3),
                   bias=np.array([t.bias for t in tails], dtype=np.float64).reshape(-1, 3))


def arm_tail_path(robot: PinocchioRobot, q: np.ndarray, v: np.ndarray, arm_v_idx: np.ndarray, arm_q: np.ndarray,
                  arm_dq: np.ndarray) -> ArmTailPath:
    """The `ArmTail` at each arm pose `arm_q[k]` and speed `arm_dq[k]`, the rest of the robot at `q`, `v`.

    Each step's `ArmTail` is the one `arm_tail` gives at `q`, `v` with their arm entries replaced by that step's.

    Args:
        robot: the Pinocchio model (its data buffer is overwritten).
        q: configuration (free flyer first; the arm's revolute joints' entries are their velocity indices plus one).
        v: velocity.
        arm_v_idx: velocity indices of the arm joints (waist, shoulder, elbow).
        arm_q: the arm's pose at each step, shape (n, 3) [rad].
        arm_dq: the arm's speed at each step, shape (n, 3) [rad/s].
    """
    arm_q = np.array(arm_q, dtype=np.float64).reshape(-1, 3)
    arm_dq = np.array(arm_dq, dtype=np.float64).reshape(-1, 3)
    q, v = np.array(q, dtype=np.float64), np.array(v, dtype=np.float64)  # copies: their arm entries change
    tails = _TailEvaluator(robot, arm_v_idx, arm_q.shape[0])
    arm_q_idx = tails.arm + 1
    for k in range(arm_q.shape[0]):
        q[arm_q_idx], v[tails.arm] = arm_q[k], arm_dq[k]
        tails.fill(k, q, v)
    return ArmTailPath(arm_q=arm_q, arm_dq=arm_dq, mass=tails.mass, inertia_world=tails.inertia_world,
                       momentum_matrix=tails.momentum_matrix, momentum_jacobian=tails.momentum_jacobian,
                       mass_matrix=tails.mass_matrix, bias=tails.bias)


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
