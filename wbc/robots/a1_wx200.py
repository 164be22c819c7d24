"""Unitree A1 with an Interbotix WidowX 200 on its trunk: the paper's push-task robot.

Mounting pose (ours; the paper shows the arm on the trunk's top plate but gives no numbers): arm base frame 6 cm
forward of the trunk frame origin, on the top face of the trunk's collision box (z = 0.114 / 2), axes aligned with
the trunk. Leg nominal pose: legged_gym's A1 defaults (hip +-0.1, thigh 0.8 front / 1.0 rear, calf -1.5).

Motors (A1's URDF gives 33.5 N m and 21 rad/s for every joint): armature 0.01 kg m^2 (rotor inertia ~1.2e-4 kg m^2
times a 9.1:1 reduction squared), damping 0.1 N m s/rad, dry friction 0.2 N m; estimates, configurable.
"""

from __future__ import annotations

import numpy as np

from wbc.robots.description import RobotDescription
from wbc.robots.wx200 import wx200_arm

__all__ = ["a1_wx200"]


def a1_wx200(arm_mode: str = "actuated", *, arm_mass_scale: float = 1.0) -> RobotDescription:
    """The ``a1-wx200`` robot.

    Args:
        arm_mode: ``none``, ``locked`` or ``actuated``.
        arm_mass_scale: scales the arm's masses and inertias (1.0 = real WX200).
    """
    return RobotDescription(
        name="a1-wx200",
        quadruped="a1",
        urdf_path="a1_description/urdf/a1.urdf",
        arm=wx200_arm(mount_xyz=(0.06, 0.0, 0.057), mass_scale=arm_mass_scale),
        arm_mode=arm_mode,
        leg_nominal_q=np.array([-0.1, 0.8, -1.5, 0.1, 0.8, -1.5, -0.1, 1.0, -1.5, 0.1, 1.0, -1.5]),
        leg_armature=(0.01, 0.01, 0.01),
        leg_damping=(0.1, 0.1, 0.1),
        leg_frictionloss=(0.2, 0.2, 0.2),
        stand_height=0.30,
        collision_free_links=("imu_link",),
    )
