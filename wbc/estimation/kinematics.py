"""`RobotKinematics`: feet, hips, leg Jacobians, gravity torques, CoM and momentum from the base state and joints.

A thin layer over the Pinocchio model that speaks the house joint order and the world-frame quantities the MPC
controller needs. It is split along what a tick can afford:

- `tick` (every control tick, one compiled pass over the model's tree, `wbc.estimation.tree.tree_pass`, equal to
  Pinocchio's to rounding): everything that does not depend on where the base is or how fast it moves: the base's
  rotation matrix, the feet and hips relative to the base (world axes), the feet's velocities relative to the base
  (omega x r + J dq), each leg's 3 x 3 foot Jacobian and the joints' gravity torques. The pass runs with the base at
  the origin, at rest, so the estimator reads its leg-kinematics measurements straight from it.
- `place` (every tick, a few products): puts that configuration at the estimated (or true) base position and
  velocity: feet, foot velocities, hips and CoM in the world.
- `centroidal` (every MPC update): the composite inertia, the arm's momentum matrix, the centroidal momentum and
  the exact CoM at the placed state (Pinocchio's CCRBA), and the CoM's offset in the trunk frame that `place` uses
  between updates.

The per-tick arrays are allocated once, as views of one buffer (`wbc.estimation.tree.tick_arrays`), and overwritten
in place by `tick` and `place` (no allocation at a tick): a caller that keeps one past the tick copies it. A compiled
caller runs the pass and the placement itself on that buffer (`compiled_arrays`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from wbc.estimation.tree import TreeModel, packed_pass, packed_place, tick_arrays, tick_buffer_size
from wbc.robots.description import ARM_JOINTS, FOOT_NAMES, LEG_NAMES, RobotDescription
from wbc.robots.pinocchio_model import PinocchioRobot, build_pinocchio
from wbc.robots.urdf import foot_radii

__all__ = ["CentroidalParams", "RobotKinematics"]


@dataclass(frozen=True)
class CentroidalParams:
    """Numeric quantities the model is evaluated with (frozen over one MPC horizon).

    Attributes:
        mass: total mass [kg].
        inertia_world: composite centroidal inertia I_c, world axes, shape (3, 3) [kg m^2].
        arm_momentum_matrix: A_arm, shape (3, 3) [kg m^2] (zeros without an actuated arm).
        feet_world: foot positions r_i, shape (4, 3) [m].
    """

    mass: float
    inertia_world: np.ndarray
    arm_momentum_matrix: np.ndarray
    feet_world: np.ndarray
    inverse_inertia: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "inverse_inertia", np.linalg.inv(self.inertia_world))

    def vector(self) -> np.ndarray:
        """Flattened as the CasADi parameter vector: mass, I_c^-1 (9), A_arm (9), feet (12)."""
        return np.concatenate([[self.mass], np.linalg.inv(self.inertia_world).ravel(),
                               self.arm_momentum_matrix.ravel(), self.feet_world.ravel()])

    @classmethod
    def from_pinocchio(cls, robot: PinocchioRobot, q: np.ndarray, feet_world: np.ndarray,
                       arm_v_idx: np.ndarray | None) -> CentroidalParams:
        """Composite inertia and arm momentum matrix at configuration `q` (Pinocchio order).

        Args:
            robot: the Pinocchio model.
            q: configuration.
            feet_world: foot positions, shape (4, 3).
            arm_v_idx: velocity indices of the arm joints (waist, shoulder, elbow), None without an actuated arm.
        """
        model, data = robot.model, robot.data
        a_g = pin.computeCentroidalMap(model, data, q)
        pin.ccrba(model, data, q, np.zeros(model.nv))
        arm = np.zeros((3, 3)) if arm_v_idx is None else a_g[3:, arm_v_idx].copy()
        return cls(mass=float(data.Ig.mass), inertia_world=data.Ig.inertia.copy(), arm_momentum_matrix=arm,
                   feet_world=np.asarray(feet_world, dtype=np.float64).reshape(4, 3))


class RobotKinematics:
    """Kinematics and centroidal quantities at one state.

    Args:
        desc: the robot (its arm mode decides whether the arm's joints exist).

    Attributes:
        rot: base orientation, body to world (3, 3).
        feet_rel: foot positions relative to the base origin, world axes, shape (4, 3) [m].
        feet_vel_rel: foot velocities relative to the base (omega x r + J dq), world axes, shape (4, 3) [m/s].
        contact_vel_rel: relative to the base, the velocities of the points of the feet's spheres in contact with
            flat ground (right below each foot frame, fixed to the foot), world axes, shape (4, 3) [m/s]; minus the
            base's velocity while a foot rolls without slipping (`wbc.estimation.tree.tree_pass`).
        hips_rel: thigh joint positions relative to the base origin, world axes, shape (4, 3) [m].
        leg_jacobians: d foot / d (hip, thigh, calf) of each leg, world axes, shape (4, 3, 3) [m/rad].
        gravity: joint torques that hold the configuration against gravity, house order (n,) [N m].
        feet: foot positions, world, shape (4, 3) [m] (after `place`).
        feet_vel: foot velocities, world, shape (4, 3) [m/s].
        com: CoM position, world (3,) [m].
        com_vel: CoM velocity, world (3,) [m/s] (the trunk's motion; the joints' share is counted at `centroidal`).
        omega_world: base angular velocity, world (3,) [rad/s].
        base_position: the placed base position, world (3,) [m].
        base_velocity: the placed base velocity, world (3,) [m/s].
        momentum: centroidal angular momentum, world axes (3,) [kg m^2/s] (at the last `centroidal`).
        params: mass, composite inertia, arm momentum matrix and feet of the last `centroidal`.
    """

    def __init__(self, desc: RobotDescription) -> None:
        self.desc = desc
        self.robot = build_pinocchio(desc)
        model = self.robot.model
        self._perm = self.robot.joints.pin_from_house  # pin joint k is house joint perm[k]
        self._house_cols = 6 + self.robot.joints.house_from_pin  # v index of each house joint
        self.n = desc.num_joints
        self.arm_v = self._house_cols[ARM_JOINTS] if self.n == 15 else None
        self.mass = float(sum(inertia.mass for inertia in model.inertias))
        # every per-tick array is a view of one buffer (`wbc.estimation.tree.tick_arrays`), so that a compiled call
        # is handed one array for all of them; the pass runs with the base at the origin and at rest
        self._buffer = np.zeros(tick_buffer_size(self.n))
        (self.rot, self._q_tick, self._v_tick, self.feet_rel, self.hips_rel, self.feet_vel_rel, self.leg_jacobians,
         self.gravity, self.omega_world, self._com_in_base, self.base_position, self.base_velocity, self.feet,
         self.feet_vel, self.com, self.com_vel, self.contact_vel_rel) = tick_arrays(self._buffer)
        self.rot[:] = np.eye(3)
        self._q_tick[:] = pin.neutral(model)
        # `self._com_in_base`: the CoM in the trunk frame, from the last `centroidal` (or the first tick)
        self.momentum = np.zeros(3)
        self.params: CentroidalParams | None = None
        self._com_known = False
        # the per-tick pass runs compiled on the model's tree (Pinocchio's joint order, from its joint 2 on); its
        # constants, packed once
        pin_of_house = self.robot.joints.house_from_pin  # the Pinocchio-order index of each house joint
        tree = TreeModel.of(model, list(FOOT_NAMES), [f"{leg}_thigh_joint" for leg in LEG_NAMES],
                            pin_of_house[:12].reshape(4, 3), foot_radii(desc))
        self._model = tree.packed(self._perm, float(model.gravity.linear[2]))

    @property
    def com_known(self) -> bool:
        """Whether the CoM's place in the trunk frame is known (`tick` measures it first, `centroidal` again)."""
        return self._com_known

    def compiled_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The packed model and the tick buffer, as a compiled tick takes them (`wbc.estimation.tree.packed_pass`).

        The buffer's views are this object's per-tick attributes (`wbc.estimation.tree.tick_arrays`): a compiled
        call that runs the pass and the placement on it leaves them as `tick` and `place` would.
        """
        return (*self._model, self._buffer)

    def forget_com(self) -> None:
        """Measure the CoM in the trunk frame again at the next `tick` (as at the first tick of a new controller)."""
        self._com_known = False

    # -- every tick -----------------------------------------------------------------------------------------------
    def tick(self, base_quat: np.ndarray, q: np.ndarray, dq: np.ndarray, omega_body: np.ndarray) -> None:
        """The configuration's kinematics relative to the base, and the base's rotation (one compiled pass).

        Args:
            base_quat: base orientation (w, x, y, z).
            q: joint positions, house order.
            dq: joint velocities, house order.
            omega_body: base angular velocity, body frame (3,) [rad/s].
        """
        packed_pass(base_quat, omega_body, q, dq, *self._model, self._buffer)
        if not self._com_known:
            model, data = self.robot.model, self.robot.data
            self._com_in_base[:] = self.rot.T @ pin.centerOfMass(model, data, self._q_tick, False)
            self._com_known = True

    def place(self, base_position: np.ndarray, base_velocity: np.ndarray) -> None:
        """Put the last `tick`'s configuration at a base position and velocity (world) [m], [m/s] (copied)."""
        packed_place(self._buffer, base_position, base_velocity)

    def update(self, base_pos: np.ndarray, base_quat: np.ndarray, q: np.ndarray, dq: np.ndarray,
               v_base_world: np.ndarray, omega_body: np.ndarray, *, centroidal: bool) -> None:
        """Everything at one state: `tick`, `place`, and `centroidal` when asked.

        Args:
            base_pos: base position, world (3,) [m].
            base_quat: base orientation (w, x, y, z).
            q: joint positions, house order [rad].
            dq: joint velocities, house order [rad/s].
            v_base_world: base linear velocity, world (3,) [m/s].
            omega_body: base angular velocity, body frame (3,) [rad/s].
            centroidal: also compute the composite inertia, arm momentum matrix and momentum.
        """
        self.tick(base_quat, q, dq, omega_body)
        self.place(np.asarray(base_pos, dtype=np.float64), np.asarray(v_base_world, dtype=np.float64))
        if centroidal:
            self.centroidal()

    # -- every MPC update -----------------------------------------------------------------------------------------
    def centroidal(self) -> None:
        """Composite inertia, arm momentum matrix, momentum and exact CoM at the placed state (CCRBA)."""
        model, data = self.robot.model, self.robot.data
        qp, vp = self.q_pin, self.v_pin
        pin.ccrba(model, data, qp, vp)
        com = data.com[0]
        self._com_in_base[:] = self.rot.T @ (com - self.base_position)
        self.com[:] = com
        self.com_vel[:] = data.hg.linear / self.mass
        self.momentum = data.hg.angular.copy()
        arm = np.zeros((3, 3)) if self.arm_v is None else data.Ag[3:, self.arm_v].copy()
        self.params = CentroidalParams(mass=float(data.Ig.mass), inertia_world=data.Ig.inertia.copy(),
                                       arm_momentum_matrix=arm, feet_world=self.feet.copy())

    @property
    def q_pin(self) -> np.ndarray:
        """The configuration at the placed base, Pinocchio's convention (base position, quaternion x y z w, joints)."""
        qp = self._q_tick.copy()
        qp[0:3] = self.base_position
        return qp

    @property
    def v_pin(self) -> np.ndarray:
        """The velocity at the placed base, Pinocchio's convention (base velocity and omega in the body frame)."""
        vp = self._v_tick.copy()
        vp[0:3] = self.rot.T @ self.base_velocity
        return vp

    def hip_positions(self) -> np.ndarray:
        """The thigh joints' positions at the placed base, world, shape (4, 3) [m] (only foothold refreshes ask)."""
        return self.hips_rel + self.base_position

    def compute_jacobians(self) -> np.ndarray:
        """The feet's translation Jacobians over all joints, world axes, house columns, shape (4, 3, n) [m/rad].

        Only the leg blocks are non-zero (a foot does not move with another leg or the arm).
        """
        out = np.zeros((4, 3, self.n))
        for i in range(4):
            out[i][:, 3 * i:3 * i + 3] = self.leg_jacobians[i]
        return out
