"""The 3-DoF arm as the toolkit models it: four rigid links and three revolute joints.

Only the first three joints of the real arm move (waist yaw, shoulder pitch, elbow pitch); the wrist and gripper are
lumped rigidly into the forearm, as in the paper, which found the last joints contribute little inertia.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wbc.robots.inertial import Inertial

__all__ = ["ArmJointSpec", "ArmLinkSpec", "ArmSpec"]


@dataclass(frozen=True, kw_only=True)
class ArmLinkSpec:
    """One arm link: its mass properties and a capsule-like cylinder used for collision and display.

    Attributes:
        name: link name (prefixed with ``arm_`` in the robot model).
        inertial: mass properties in the link frame.
        shape_from: start of the link's cylinder in the link frame [m].
        shape_to: end of the link's cylinder in the link frame [m].
        radius: cylinder radius [m].
    """

    name: str
    inertial: Inertial
    shape_from: tuple[float, float, float]
    shape_to: tuple[float, float, float]
    radius: float


@dataclass(frozen=True, kw_only=True)
class ArmJointSpec:
    """One arm joint (revolute), placed in its parent link frame.

    Attributes:
        name: joint name (prefixed with ``arm_`` in the robot model).
        origin: position of the child frame in the parent link frame [m].
        axis: rotation axis in the child frame (unit vector).
        lower: lower position limit [rad].
        upper: upper position limit [rad].
        effort: motor torque limit [N m].
        velocity: velocity limit [rad/s].
        armature: reflected rotor inertia [kg m^2].
        damping: viscous joint damping [N m s/rad].
        frictionloss: dry joint friction [N m].
    """

    name: str
    origin: tuple[float, float, float]
    axis: tuple[float, float, float]
    lower: float
    upper: float
    effort: float
    velocity: float
    armature: float
    damping: float
    frictionloss: float


@dataclass(frozen=True, kw_only=True)
class ArmSpec:
    """A 3-DoF arm: base link (fixed to the trunk) then three joints, each followed by its link.

    Attributes:
        name: model name of the arm (e.g. ``wx200``).
        base: the arm's base link, rigidly mounted on the trunk.
        links: the three moving links (shoulder, upper arm, forearm with the wrist and gripper lumped in).
        joints: waist yaw, shoulder pitch, elbow pitch.
        mount_xyz: position of the arm base frame in the trunk frame [m].
        mount_rpy: orientation of the arm base frame in the trunk frame (URDF roll, pitch, yaw) [rad].
        nominal_q: the arm's nominal (stowed) joint positions, also the pose of a locked arm [rad].
    """

    name: str
    base: ArmLinkSpec
    links: tuple[ArmLinkSpec, ArmLinkSpec, ArmLinkSpec]
    joints: tuple[ArmJointSpec, ArmJointSpec, ArmJointSpec]
    mount_xyz: tuple[float, float, float]
    mount_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    nominal_q: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def mass(self) -> float:
        """Total mass of the arm, base included [kg]."""
        return self.base.inertial.mass + sum(link.inertial.mass for link in self.links)

    @property
    def moving_mass(self) -> float:
        """Mass of the links that move with the waist joint [kg]."""
        return sum(link.inertial.mass for link in self.links)
