"""`RobotDescription`: the one source of numbers for a quadruped with (or without) its arm.

A description names the quadruped's URDF inside the example-robot-data package and adds what the URDF lacks: the
arm (`ArmSpec`), the motors' rotor inertia, damping and friction, the nominal standing pose and the arm mode. The
MuJoCo model and the Pinocchio model are both built from it (`wbc.robots.mujoco_model`, `wbc.robots.pinocchio_model`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wbc.errors import ConfigError, UnknownNameError
from wbc.robots.arm_spec import ArmSpec

__all__ = ["ARM_JOINTS", "ARM_MODES", "LEG_JOINTS", "LEG_NAMES", "LEG_JOINT_NAMES", "FOOT_NAMES", "RobotDescription",
           "check_arm_mode", "joint_gains"]

ARM_MODES = ("none", "locked", "actuated")
"""``none``: no arm on the robot; ``locked``: arm attached and rigid at its nominal pose (fixed joints);
``actuated``: the arm's three motors are driven like the legs'."""

LEG_NAMES = ("FR", "FL", "RR", "RL")
LEG_JOINT_NAMES = tuple(f"{leg}_{part}_joint" for leg in LEG_NAMES for part in ("hip", "thigh", "calf"))
FOOT_NAMES = tuple(f"{leg}_foot" for leg in LEG_NAMES)
LEG_JOINTS = slice(0, 12)
"""The legs' entries of a joint vector in the house order (FR, FL, RR, RL x hip, thigh, calf)."""
ARM_JOINTS = slice(12, 15)
"""The arm's entries (waist, shoulder, elbow) of a joint vector in the house order, when the arm is actuated."""


def joint_gains(num_joints: int, leg_kp: float, leg_kd: float, arm_kp: float,
                arm_kd: float) -> tuple[np.ndarray, np.ndarray]:
    """(kp, kd) of the motor law for `num_joints` joints in the house order: the legs', then the arm's if it has one."""
    kp, kd = np.full(num_joints, float(leg_kp)), np.full(num_joints, float(leg_kd))
    kp[ARM_JOINTS], kd[ARM_JOINTS] = arm_kp, arm_kd
    return kp, kd


def check_arm_mode(arm_mode: str) -> str:
    """Return `arm_mode` if valid, else raise an error listing the valid modes."""
    if arm_mode not in ARM_MODES:
        raise UnknownNameError("arm mode", arm_mode, ARM_MODES)
    return arm_mode


@dataclass(frozen=True, kw_only=True)
class RobotDescription:
    """Everything needed to build the simulation and the kinematic/dynamic model of one robot.

    Attributes:
        name: registry name, e.g. ``a1-wx200``.
        quadruped: the quadruped's name (``a1``, ``go1``).
        urdf_path: the quadruped's URDF, relative to example-robot-data's ``robots/`` folder.
        arm: the arm; used unless `arm_mode` is ``none``.
        arm_mode: one of `ARM_MODES`.
        leg_nominal_q: standing joint positions in the house order, shape (12,) [rad].
        leg_armature: reflected rotor inertia of (hip, thigh, calf) motors [kg m^2].
        leg_damping: viscous damping of (hip, thigh, calf) joints [N m s/rad].
        leg_frictionloss: dry friction of (hip, thigh, calf) joints [N m].
        stand_height: trunk height when standing at the nominal pose on flat ground [m].
        collision_free_links: link-name prefixes whose collision geometry is dropped (sensor stubs).
    """

    name: str
    quadruped: str
    urdf_path: str
    arm: ArmSpec
    arm_mode: str = "actuated"
    leg_nominal_q: np.ndarray = field(default_factory=lambda: np.zeros(12))
    leg_armature: tuple[float, float, float] = (0.01, 0.01, 0.01)
    leg_damping: tuple[float, float, float] = (0.1, 0.1, 0.1)
    leg_frictionloss: tuple[float, float, float] = (0.2, 0.2, 0.2)
    stand_height: float = 0.3
    collision_free_links: tuple[str, ...] = ("imu_link",)

    def __post_init__(self) -> None:
        check_arm_mode(self.arm_mode)
        q = np.asarray(self.leg_nominal_q, dtype=np.float64)
        if q.shape != (12,):
            raise ConfigError(f"{self.name}: leg_nominal_q must have shape (12,) (FR, FL, RR, RL x hip, thigh, calf), "
                              f"got {q.shape}")
        object.__setattr__(self, "leg_nominal_q", q)

    @property
    def has_arm(self) -> bool:
        """True when an arm is attached (locked or actuated)."""
        return self.arm_mode != "none"

    @property
    def arm_joint_names(self) -> tuple[str, ...]:
        """Model names of the arm joints (``arm_waist``, ``arm_shoulder``, ``arm_elbow``)."""
        return tuple(f"arm_{j.name}" for j in self.arm.joints)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Actuated joints in the house order: 12 leg joints, then the 3 arm joints when the arm is actuated."""
        if self.arm_mode == "actuated":
            return LEG_JOINT_NAMES + self.arm_joint_names
        return LEG_JOINT_NAMES

    @property
    def num_joints(self) -> int:
        """Number of actuated joints (12 or 15)."""
        return len(self.joint_names)

    @property
    def nominal_q(self) -> np.ndarray:
        """Nominal joint positions of the actuated joints, shape (num_joints,) [rad]."""
        if self.arm_mode == "actuated":
            return np.concatenate([self.leg_nominal_q, self.arm.nominal_q])
        return self.leg_nominal_q.copy()

    def with_arm_mode(self, arm_mode: str) -> RobotDescription:
        """The same robot with another arm mode."""
        from dataclasses import replace

        return replace(self, arm_mode=check_arm_mode(arm_mode))
