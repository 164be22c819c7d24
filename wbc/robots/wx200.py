"""Interbotix WidowX 200 (WX200) arm parameters, reduced to the toolkit's 3-DoF arm.

Source of every inertial and kinematic number below: Interbotix's public arm description,
``interbotix_ros_manipulators/interbotix_ros_xsarms/interbotix_xsarm_descriptions/urdf/wx200.urdf.xacro``
(links ``base_link``, ``shoulder_link``, ``upper_arm_link``, ``forearm_link``, ``wrist_link``, ``gripper_link``,
``gripper_prop_link``, ``gripper_bar_link``, ``left_finger_link``, ``right_finger_link``; joints ``waist``,
``shoulder``, ``elbow``, ``wrist_angle``, ``wrist_rotate``). That file rotates each inertia frame by yaw pi/2; the
rotation is applied here.

What is ours, not Interbotix's:
- Wrist, gripper and fingers are lumped rigidly into the forearm at wrist_angle = wrist_rotate = 0, fingers at the
  middle of their stroke. The description's placeholder frames ``ee_arm_link``, ``fingers_link`` and
  ``ee_gripper_link`` (1 g with a 1e-3 kg m^2 dummy inertia, larger than the real wrist's) are left out.
- Torque and speed limits are the servos' datasheet figures, not the description's (which are generous): the waist
  and elbow use one Dynamixel XM430-W350 (stall 4.1 N m at 12 V, no-load 46 rpm = 4.8 rad/s), the shoulder two in
  tandem (8.2 N m). Position limits are the description's.
- Armature (reflected rotor inertia) 0.01 kg m^2 per joint, damping 0.1 N m s/rad and friction 0.1 N m per joint
  (the description's dynamics tags give the last two); the armature is an estimate for a 353.5:1 servo.
- Collision/display cylinders approximate each link's envelope (the meshes are not shipped with this package).
"""

from __future__ import annotations

import math

import numpy as np

from wbc.errors import ConfigError
from wbc.robots.arm_spec import ArmJointSpec, ArmLinkSpec, ArmSpec
from wbc.robots.inertial import Inertial, lump

__all__ = ["wx200_arm", "WX200_NOMINAL_Q"]

_YAW90 = (0.0, 0.0, math.pi / 2)

# Stowed pose: upper arm leaning back, forearm folded forward above the trunk (the arm's "sleep" shape within the
# description's shoulder limit). [rad]
WX200_NOMINAL_Q = np.array([0.0, -1.3, 1.5])


def _forearm_with_wrist_and_gripper() -> Inertial:
    """Forearm plus everything distal to the elbow, in the forearm frame."""
    forearm = Inertial.from_urdf(0.283651, (0.1211920, -0.0001238123, 0.0), _YAW90,
                                 0.0011850, 0.00006829, 0.0012060, -0.0000024317, 0.0, 0.0)
    wrist = Inertial.from_urdf(0.084957, (0.0423600, -0.000010663, 0.0105770), _YAW90,
                               0.00003082, 0.00002822, 0.00003152, 0.0000000191, 0.0000000023, 0.0000025481)
    gripper = Inertial.from_urdf(0.072885, (0.0216310, 0.0000002516, 0.0114100), _YAW90,
                                 0.00002537, 0.00001836, 0.00001674, 0.0, 0.0, 0.000000434)
    prop = Inertial.from_urdf(0.00434, (0.000846, -0.0000016817, 0.000042), _YAW90,
                              0.0000005923, 0.0000011156, 0.0000005743, 0.0, 0.0000003195, -0.0000000004)
    bar = Inertial.from_urdf(0.034199, (0.009687, 0.0000008177, 0.004962), _YAW90,
                             0.0000074125, 0.00002843, 0.0000286, -0.0000000008, -0.0000000006, -0.0000013889)
    finger_l = Inertial.from_urdf(0.016246, (0.013816, 0.0, 0.0), (math.pi, math.pi, math.pi / 2),
                                  0.000004731, 0.0000015506, 0.0000037467, -0.000000456, 0.0, 0.0)
    finger_r = Inertial.from_urdf(0.016246, (0.013816, 0.0, 0.0), (0.0, math.pi, math.pi / 2),
                                  0.000004731, 0.0000015506, 0.0000037467, 0.000000456, 0.0, 0.0)
    eye = np.eye(3)
    wrist_at = np.array([0.2, 0.0, 0.0])            # wrist_angle joint in the forearm frame
    gripper_at = wrist_at + [0.065, 0.0, 0.0]       # wrist_rotate joint
    ee_arm_at = gripper_at + [0.043, 0.0, 0.0]      # ee_arm (fixed)
    prop_at = ee_arm_at + [0.0055, 0.0, 0.0]        # gripper (prop) joint
    fingers_at = ee_arm_at + [0.023, 0.0, 0.0]      # gripper_bar (fixed, at ee_arm) then ee_bar
    stroke = 0.5 * (0.015 + 0.037)                  # finger joints at mid stroke
    parts = [
        forearm,
        wrist.transformed(eye, wrist_at),
        gripper.transformed(eye, gripper_at),
        prop.transformed(eye, prop_at),
        bar.transformed(eye, ee_arm_at),
        finger_l.transformed(eye, fingers_at + [0.0, stroke, 0.0]),
        finger_r.transformed(eye, fingers_at + [0.0, -stroke, 0.0]),
    ]
    return lump(parts)


def wx200_arm(
    *,
    mount_xyz: tuple[float, float, float],
    mount_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0),
    mass_scale: float = 1.0,
    nominal_q: np.ndarray | None = None,
) -> ArmSpec:
    """The WX200 reduced to 3 DoF, mounted on a trunk.

    Args:
        mount_xyz: arm base frame position in the trunk frame [m].
        mount_rpy: arm base frame orientation in the trunk frame [rad].
        mass_scale: multiplies every link's mass and inertia (1.0 = the real WX200); a lighter build of the same
            kinematics.
        nominal_q: stowed joint positions [rad]; defaults to `WX200_NOMINAL_Q`.

    Returns:
        The arm specification.
    """
    base = Inertial.from_urdf(0.540142, (-0.0381747, 0.000647863, 0.0193458), _YAW90,
                              0.002119, 0.0006925, 0.002528, -0.00001721, 0.0000006389, 0.00004612)
    shoulder = Inertial.from_urdf(0.480879, (0.000022321, 0.0000414608, 0.0066287), _YAW90,
                                  0.000379, 0.0005557, 0.0005889, 0.0000000022, -0.0000003561, 0.0000012247)
    upper_arm = Inertial.from_urdf(0.297781, (0.0119707, -0.0001179264, 0.139429), _YAW90,
                                   0.00171, 0.001631, 0.0001482, -0.0000011433, 0.0000021161, 0.0002135)
    forearm = _forearm_with_wrist_and_gripper()
    s = float(mass_scale)
    links = (
        ArmLinkSpec(name="shoulder_link", inertial=shoulder.scaled(s),
                    shape_from=(0.0, 0.0, -0.02), shape_to=(0.0, 0.0, 0.03), radius=0.035),
        ArmLinkSpec(name="upper_arm_link", inertial=upper_arm.scaled(s),
                    shape_from=(0.0, 0.0, 0.0), shape_to=(0.05, 0.0, 0.2), radius=0.025),
        ArmLinkSpec(name="forearm_link", inertial=forearm.scaled(s),
                    shape_from=(0.0, 0.0, 0.0), shape_to=(0.33, 0.0, 0.0), radius=0.025),
    )
    joints = (
        ArmJointSpec(name="waist", origin=(0.0, 0.0, 0.072), axis=(0.0, 0.0, 1.0),
                     lower=-math.pi + 1e-5, upper=math.pi - 1e-5, effort=4.1, velocity=4.8,
                     armature=0.01, damping=0.1, frictionloss=0.1),
        ArmJointSpec(name="shoulder", origin=(0.0, 0.0, 0.03865), axis=(0.0, 1.0, 0.0),
                     lower=math.radians(-80.0), upper=math.radians(113.0), effort=8.2, velocity=4.8,
                     armature=0.01, damping=0.1, frictionloss=0.1),
        ArmJointSpec(name="elbow", origin=(0.05, 0.0, 0.2), axis=(0.0, 1.0, 0.0),
                     lower=math.radians(-108.0), upper=math.radians(93.0), effort=4.1, velocity=4.8,
                     armature=0.01, damping=0.1, frictionloss=0.1),
    )
    q0 = WX200_NOMINAL_Q if nominal_q is None else np.asarray(nominal_q, dtype=np.float64)
    if q0.shape != (3,):
        raise ConfigError(f"nominal_q must have shape (3,) (waist, shoulder, elbow [rad]), got {q0.shape}")
    return ArmSpec(
        name="wx200" if s == 1.0 else f"wx200x{s:g}",
        base=ArmLinkSpec(name="base_link", inertial=base.scaled(s),
                         shape_from=(-0.06, 0.0, 0.02), shape_to=(0.02, 0.0, 0.02), radius=0.03),
        links=links,
        joints=joints,
        mount_xyz=mount_xyz,
        mount_rpy=mount_rpy,
        nominal_q=q0.copy(),
    )

