"""Unitree Go1 with a light 3-DoF arm: the paper's turn-task robot.

The paper's arm for the Go1 (a "K1" arm) is not documented anywhere public, so this robot carries the WX200's
kinematics and inertias (`wbc.robots.wx200`) by default, a WX200-class arm; `arm_mass_scale` makes it lighter or
heavier. Mounting pose as on the A1: 6 cm forward of the trunk origin on the top face of the trunk's collision box.

Motors (Go1's URDF: hip/thigh 23.7 N m at 30.1 rad/s, calf 35.55 N m at 20.06 rad/s): armature 0.005 kg m^2 for
hip and thigh (6.33:1 reduction) and 0.011 kg m^2 for the calf (the extra 1.5:1 linkage), damping 0.1 N m s/rad,
dry friction 0.2 N m; estimates, configurable. The URDF's explicit rotor links carry the rotors' mass. The
camera and ultrasound stubs keep their (1e-5 kg) mass but lose their collision boxes.
"""

from __future__ import annotations

import numpy as np

from wbc.robots.description import RobotDescription
from wbc.robots.wx200 import wx200_arm

__all__ = ["go1_arm"]


def go1_arm(arm_mode: str = "actuated", *, arm_mass_scale: float = 1.0) -> RobotDescription:
    """The ``go1-arm`` robot.

    Args:
        arm_mode: ``none``, ``locked`` or ``actuated``.
        arm_mass_scale: scales the arm's masses and inertias (1.0 = a WX200).
    """
    return RobotDescription(
        name="go1-arm",
        quadruped="go1",
        urdf_path="go1_description/urdf/go1.urdf",
        arm=wx200_arm(mount_xyz=(0.06, 0.0, 0.057), mass_scale=arm_mass_scale),
        arm_mode=arm_mode,
        leg_nominal_q=np.array([-0.1, 0.8, -1.5, 0.1, 0.8, -1.5, -0.1, 1.0, -1.5, 0.1, 1.0, -1.5]),
        leg_armature=(0.005, 0.005, 0.011),
        leg_damping=(0.1, 0.1, 0.1),
        leg_frictionloss=(0.2, 0.2, 0.2),
        stand_height=0.30,
        collision_free_links=("imu_link", "camera", "ultraSound"),
    )
