"""The robot as a MuJoCo `MjSpec`: bodies and collision primitives from the URDF, motors, sensors.

Layout of the compiled model (documented in `wbc.robots.conventions`): one free joint ``root`` on the ``base`` body,
then the actuated joints in the house order; ``qpos = [position (3), quaternion w x y z (4), joints]``,
``qvel = [linear velocity in world (3), angular velocity in body (3), joint velocities]``.

Motors: one `general` actuator per actuated joint with the affine law of a Unitree motor driver,
``force = ctrl + bias``, ``bias = -kp q - kd dq``, ``ctrl = kp q* + kd dq* + tau_ff``, clamped to the torque limit by
``forcerange``. The law therefore runs inside MuJoCo's own step (and inside `mujoco.rollout`) at every physics step.
kp and kd live in ``actuator_biasprm`` and are rewritten whenever a command changes them.

Sensors: ``imu_quat`` (framequat), ``imu_gyro``, ``imu_accel`` at the IMU site, and one ``touch`` sensor per foot
(``FR_touch`` ...), the simulated counterpart of the A1/Go1 foot force sensors.

Collisions: robot geoms collide with the world (floor, terrain) but not with each other.
"""

from __future__ import annotations

import mujoco
import numpy as np

from wbc.errors import WbcError
from wbc.robots.conventions import ROOT_JOINT
from wbc.robots.description import FOOT_NAMES, RobotDescription
from wbc.robots.joint_table import joint_table
from wbc.robots.urdf import robot_urdf

__all__ = ["robot_mujoco_spec", "CONTACT_TIMECONST", "ROBOT_CONTYPE", "WORLD_CONAFFINITY", "FOOT_SITE_RADIUS"]

ROBOT_CONTYPE = 1
WORLD_CONAFFINITY = 1
FOOT_SITE_RADIUS = 0.03  # [m] touch-sensor zone around each 2 cm foot sphere
CONTACT_TIMECONST = 0.005
"""[s] Contact stiffness as a MuJoCo solref time constant, on robot and ground geoms alike. MuJoCo's default (20 ms)
lets a loaded foot sink more than a centimetre, enough for the calf boxes (which run down to the foot centre) to
touch; rubber feet sink millimetres. 5 ms is 2.5 physics steps, the stiffest MuJoCo advises at a 2 ms step."""


def robot_mujoco_spec(desc: RobotDescription) -> mujoco.MjSpec:
    """The robot alone (no floor) as an `MjSpec`, ready to be placed in a scene and compiled."""
    urdf = robot_urdf(desc)
    head = urdf.index(">", urdf.index("<robot")) + 1
    urdf = (urdf[:head] + '<mujoco><compiler discardvisual="true" fusestatic="false" balanceinertia="false" '
            'autolimits="true"/></mujoco>' + urdf[head:])
    spec = mujoco.MjSpec.from_string(urdf)
    spec.modelname = desc.name
    base = spec.body("base")
    if base is None:
        raise WbcError(f"{desc.name}: the URDF has no 'base' link to float")
    base.add_freejoint(name=ROOT_JOINT)

    for geom in spec.geoms:
        geom.contype = ROBOT_CONTYPE
        geom.conaffinity = 0
        geom.condim = 3
        geom.friction = [1.0, 0.005, 0.0001]
        geom.solref = [CONTACT_TIMECONST, 1.0]

    imu = spec.body("imu_link")
    (imu if imu is not None else spec.body("trunk")).add_site(name="imu", size=[0.01, 0.01, 0.01])
    for foot in FOOT_NAMES:
        spec.body(foot).add_site(name=foot, size=[FOOT_SITE_RADIUS, 0, 0])

    table = joint_table(desc)
    for i, name in enumerate(table.names):
        joint = spec.joint(name)
        joint.armature = table.armature[i]
        joint.damping = [table.damping[i], 0.0, 0.0]
        joint.frictionloss = table.frictionloss[i]
        act = spec.add_actuator(name=name, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        act.gainprm = np.r_[1.0, np.zeros(9)]
        act.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        act.biasprm = np.zeros(10)
        act.ctrllimited = False
        act.forcelimited = True
        act.forcerange = [-table.torque_limit[i], table.torque_limit[i]]

    spec.add_sensor(name="imu_quat", type=mujoco.mjtSensor.mjSENS_FRAMEQUAT,
                    objtype=mujoco.mjtObj.mjOBJ_SITE, objname="imu")
    spec.add_sensor(name="imu_gyro", type=mujoco.mjtSensor.mjSENS_GYRO,
                    objtype=mujoco.mjtObj.mjOBJ_SITE, objname="imu")
    spec.add_sensor(name="imu_accel", type=mujoco.mjtSensor.mjSENS_ACCELEROMETER,
                    objtype=mujoco.mjtObj.mjOBJ_SITE, objname="imu")
    for foot in FOOT_NAMES:
        spec.add_sensor(name=foot.replace("_foot", "_touch"), type=mujoco.mjtSensor.mjSENS_TOUCH,
                        objtype=mujoco.mjtObj.mjOBJ_SITE, objname=foot)
    return spec
