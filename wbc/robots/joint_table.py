"""`JointTable`: per-joint limits and motor constants of the actuated joints, read from the robot's URDF.

Legs take their limits from the quadruped's URDF and their rotor inertia, damping and friction from the
description; arm joints take everything from the `ArmSpec`. Arrays follow the house joint order.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from wbc.errors import WbcError
from wbc.robots.description import RobotDescription
from wbc.robots.urdf import robot_urdf

__all__ = ["JointTable", "joint_table"]


@dataclass(frozen=True, kw_only=True)
class JointTable:
    """Per-joint constants, shape (num_joints,) each, house joint order.

    Attributes:
        names: joint names.
        lower: lower position limit [rad].
        upper: upper position limit [rad].
        torque_limit: motor torque limit [N m].
        velocity_limit: motor speed limit [rad/s].
        armature: reflected rotor inertia [kg m^2].
        damping: viscous damping [N m s/rad].
        frictionloss: dry friction [N m].
    """

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    torque_limit: np.ndarray
    velocity_limit: np.ndarray
    armature: np.ndarray
    damping: np.ndarray
    frictionloss: np.ndarray


def joint_table(desc: RobotDescription) -> JointTable:
    """Collect the constants of `desc`'s actuated joints."""
    root = ET.fromstring(robot_urdf(desc))
    joints = {j.get("name"): j for j in root.findall("joint")}
    rows = []
    for i, name in enumerate(desc.joint_names):
        el = joints.get(name)
        limit = el.find("limit") if el is not None else None
        if limit is None:
            raise WbcError(f"{desc.name}: joint {name!r} has no <limit> in the robot URDF")
        if i < 12:
            part = i % 3
            arm_const = (desc.leg_armature[part], desc.leg_damping[part], desc.leg_frictionloss[part])
        else:
            spec = desc.arm.joints[i - 12]
            arm_const = (spec.armature, spec.damping, spec.frictionloss)
        rows.append((float(limit.get("lower")), float(limit.get("upper")), float(limit.get("effort")),
                     float(limit.get("velocity")), *arm_const))
    cols = np.array(rows, dtype=np.float64).T
    return JointTable(
        names=desc.joint_names, lower=cols[0], upper=cols[1], torque_limit=cols[2], velocity_limit=cols[3],
        armature=cols[4], damping=cols[5], frictionloss=cols[6],
    )
