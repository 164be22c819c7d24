"""`WholeBodyQp`: the whole-body controller, an inverse-dynamics QP solved by PlaCo's `DynamicsSolver` every tick.

Decision variables (inside PlaCo): joint accelerations, contact forces of the stance feet and joint torques, subject
to the floating-base equations of motion, unilateral friction cones (a pyramid with coefficient `friction`) and the
motors' torque limits. Weighted tasks:

- CoM: the MPC's predicted CoM position and velocity, with the acceleration the MPC's forces produce
  (sum f / m + g) as feed-forward, so the QP reproduces the planned net force;
- trunk orientation: the planned orientation, with the angular acceleration the MPC's moments produce as feed-forward;
- swing feet: position, velocity of their swing trajectories (Cartesian PD at acceleration level);
- arm joints: the arm's planned positions and velocities;
- stance feet: zero acceleration, through the contacts.

Why PlaCo rather than our own ProxSuite QP: the whole problem (kinematics, mass matrix, task Jacobians, QP) stays in
C++, one Python call per tick, where a numpy-assembled QP of the same size pays several times more in Python
overhead; sending the targets is kept cheap by sending only what changes (measurements and the alternatives weighed:
docs/mpc-notes.md).
PlaCo reads the same URDF as the MuJoCo and Pinocchio models (visuals stripped: it only needs the dynamics).
"""

from __future__ import annotations

import math
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import placo

from wbc.config_checks import check_number
from wbc.robots.description import FOOT_NAMES, RobotDescription
from wbc.robots.joint_table import joint_table
from wbc.robots.urdf import robot_urdf

__all__ = ["WholeBodyConfig", "WholeBodyQp", "WholeBodyResult", "placo_robot"]


@dataclass(frozen=True, kw_only=True)
class WholeBodyConfig:
    """Gains and weights of the whole-body QP (gains at acceleration level).

    Attributes:
        friction: friction coefficient of the contact pyramids: 0.6, below the lowest ground friction of most
            scenarios (0.8) but above push-low-friction's 0.4-0.5, where the QP may ask for forces the ground cannot
            hold (the MPC's own pyramids, `MpcConfig.mu` 0.4, stay inside it).
        com_kp: CoM stiffness [1/s^2].
        com_kd: CoM damping [1/s].
        trunk_kp: trunk orientation stiffness [1/s^2].
        trunk_kd: trunk orientation damping [1/s].
        swing_kp: swing-foot stiffness [1/s^2].
        swing_kd: swing-foot damping [1/s].
        arm_kp: arm joint stiffness [1/s^2].
        arm_kd: arm joint damping [1/s].
        com_weight: weight of the CoM task.
        trunk_weight: weight of the trunk orientation task.
        swing_weight: weight of each swing-foot task.
        arm_weight: weight of the arm task.
        force_weight: regularisation of the contact forces (spreads the load over the stance feet).

    Raises:
        ConfigError: a `friction` that is not a positive finite number, or a gain or weight that is negative or not
            finite.
    """

    friction: float = 0.6
    com_kp: float = 40.0
    com_kd: float = 12.0
    trunk_kp: float = 120.0
    trunk_kd: float = 22.0
    swing_kp: float = 900.0
    swing_kd: float = 60.0
    arm_kp: float = 300.0
    arm_kd: float = 35.0
    com_weight: float = 10.0
    trunk_weight: float = 10.0
    swing_weight: float = 1.0
    arm_weight: float = 1.0
    force_weight: float = 1e-4

    def __post_init__(self) -> None:
        check_number("WholeBodyConfig.friction", self.friction, above=0.0)
        for name in ("com_kp", "com_kd", "trunk_kp", "trunk_kd", "swing_kp", "swing_kd", "arm_kp", "arm_kd",
                     "com_weight", "trunk_weight", "swing_weight", "arm_weight", "force_weight"):
            check_number(f"WholeBodyConfig.{name}", getattr(self, name), at_least=0.0)


@dataclass
class WholeBodyResult:
    """One solve.

    Attributes:
        success: the QP was solved.
        tau: joint torques, house order [N m].
        forces: contact forces of the feet (zero in swing), house leg order, world frame, shape (4, 3) [N]; None when
            the solve was asked not to read them.
    """

    success: bool
    tau: np.ndarray
    forces: np.ndarray | None


def placo_robot(urdf: str) -> placo.RobotWrapper:
    """A PlaCo robot from URDF text, its visual and collision geometry removed.

    PlaCo would try to load the meshes and only needs the dynamics; it reads a file once, at construction, and the
    file is not kept.
    """
    root = ET.fromstring(urdf)
    for link in root.iter("link"):
        for child in list(link.findall("visual")) + list(link.findall("collision")):
            link.remove(child)
    with tempfile.TemporaryDirectory(prefix="wbc-placo-") as folder:
        path = Path(folder) / "robot.urdf"
        path.write_text(ET.tostring(root, encoding="unicode"))
        return placo.RobotWrapper(str(path), placo.Flags.ignore_collisions)


class WholeBodyQp:
    """Build once per robot; `solve` every control tick.

    Args:
        desc: the robot.
        config: gains and weights.
    """

    def __init__(self, desc: RobotDescription, config: WholeBodyConfig | None = None) -> None:
        self.desc = desc
        self.config = cfg = config or WholeBodyConfig()
        self.robot = placo_robot(robot_urdf(desc))
        names = list(self.robot.joint_names())
        house = list(desc.joint_names)
        # the v index of each house joint in PlaCo's (= Pinocchio's) order
        self._house_cols = 6 + np.array([names.index(n) for n in house])
        self.mass = float(self.robot.total_mass())
        table = joint_table(desc)
        self.robot.update_kinematics()
        solver = placo.DynamicsSolver(self.robot)
        solver.mask_fbase(False)
        solver.enable_torque_limits(True)
        for name, limit in zip(table.names, table.torque_limit, strict=True):
            solver.set_torque_limit(name, float(limit))
        self.solver = solver
        self._state = self.robot.state  # a handle on the wrapper's state, kept: fetching it costs a call per tick
        self.feet_tasks = []
        self.contacts = []
        for foot in FOOT_NAMES:
            task = solver.add_position_task(foot, np.zeros(3))
            task.configure(foot, "soft", cfg.swing_weight)
            contact = solver.add_point_contact(task)
            contact.mu = cfg.friction
            contact.unilateral = True
            contact.weight_forces = cfg.force_weight
            self.feet_tasks.append(task)
            self.contacts.append(contact)
        self.com_task = solver.add_com_task(np.zeros(3))
        self.com_task.configure("com", "soft", cfg.com_weight)
        self.com_task.kp, self.com_task.kd = cfg.com_kp, cfg.com_kd
        self.trunk_task = solver.add_orientation_task("trunk", np.eye(3))
        self.trunk_task.configure("trunk", "soft", cfg.trunk_weight)
        self.trunk_task.kp, self.trunk_task.kd = cfg.trunk_kp, cfg.trunk_kd
        self.arm_task = None
        if desc.arm_mode == "actuated":
            self.arm_task = solver.add_joints_task()
            self.arm_task.set_joints(dict(zip(desc.arm_joint_names, desc.nominal_q[12:15].tolist(), strict=True)))
            self.arm_task.configure("arm", "soft", cfg.arm_weight)
            self.arm_task.kp, self.arm_task.kd = cfg.arm_kp, cfg.arm_kd
        self._arm_names = tuple(desc.arm_joint_names) if self.arm_task is not None else ()
        self._stance = [False] * 4
        self._set_stance([True] * 4)

    def _set_stance(self, stance: list[bool]) -> None:
        cfg = self.config
        for i in range(4):
            if stance[i] == self._stance[i]:
                continue
            task, contact = self.feet_tasks[i], self.contacts[i]
            contact.active = stance[i]
            if stance[i]:
                # a stance foot must not accelerate: no stiffness towards a target, no damping
                task.kp, task.kd = 0.0, 0.0
            else:
                task.kp, task.kd = cfg.swing_kp, cfg.swing_kd
        self._stance = stance

    def solve(self, q_pin: np.ndarray, v_pin: np.ndarray, stance: np.ndarray, *, com: np.ndarray,
              com_vel: np.ndarray, com_acc: np.ndarray, rot: np.ndarray, omega_world: np.ndarray,
              domega_world: np.ndarray, feet_pos: np.ndarray, feet_vel: np.ndarray,
              arm_q: np.ndarray | None = None, arm_dq: np.ndarray | None = None,
              with_forces: bool = True) -> WholeBodyResult:
        """One whole-body QP.

        Args:
            q_pin: configuration in Pinocchio's convention (base position, quaternion x, y, z, w, joints).
            v_pin: velocity in Pinocchio's convention (base linear and angular velocity in the base frame, joints).
            stance: which feet are in contact, house leg order (4,).
            com: CoM target, world [m].
            com_vel: CoM velocity target, world [m/s].
            com_acc: CoM acceleration feed-forward, world [m/s^2].
            rot: trunk orientation target (body to world).
            omega_world: trunk angular velocity target, world [rad/s].
            domega_world: trunk angular acceleration feed-forward, world [rad/s^2].
            feet_pos: swing-foot position targets, world, shape (4, 3) (rows of stance feet ignored) [m].
            feet_vel: swing-foot velocity targets, world, shape (4, 3) [m/s].
            arm_q: arm joint targets [rad] (actuated arm only).
            arm_dq: arm joint velocity targets [rad/s].
            with_forces: read the contact forces back (the controller, which needs only the torques, skips it).

        Returns:
            Torques and contact forces; ``success`` False when PlaCo's QP failed (torques are then zero).
        """
        # Every line here runs at the control rate and each PlaCo property costs ~1 us from Python: only what
        # changed is sent, as plain floats and whole arrays.
        state = self._state
        state.q = q_pin
        state.qd = v_pin
        self.robot.update_kinematics()
        stance = stance.tolist()
        if stance != self._stance:
            self._set_stance(stance)
        for i in range(4):
            # a stance foot's task has no gains: its targets do not matter
            if not stance[i]:
                task = self.feet_tasks[i]
                task.target_world = feet_pos[i]
                task.dtarget_world = feet_vel[i]
        com_task, trunk_task = self.com_task, self.trunk_task
        com_task.target_world = com
        com_task.dtarget_world = com_vel
        com_task.ddtarget_world = com_acc
        trunk_task.R_world_frame = rot
        trunk_task.omega_world = omega_world
        trunk_task.domega_world = domega_world
        if self.arm_task is not None and arm_q is not None:
            set_joint = self.arm_task.set_joint
            velocities = (0.0,) * len(arm_q) if arm_dq is None else arm_dq.tolist()
            for name, qa, va in zip(self._arm_names, arm_q.tolist(), velocities, strict=True):
                set_joint(name, qa, va)
        result = self.solver.solve(False)
        forces = np.zeros((4, 3)) if with_forces else None
        if not result.success:
            return WholeBodyResult(success=False, tau=np.zeros(len(self._house_cols)), forces=forces)
        if with_forces:
            for i in range(4):
                if stance[i]:
                    forces[i] = self.contacts[i].wrench[:3]
        tau = result.tau[self._house_cols]
        return WholeBodyResult(success=math.isfinite(tau.dot(tau)), tau=tau, forces=forces)
