"""Robot descriptions (A1 + WX200, Go1 + arm), their URDF and joint tables.

The MuJoCo and Pinocchio models built from them are imported from `wbc.robots.mujoco_model` and
`wbc.robots.pinocchio_model`, so that reading a description (a scenario file, a policy file) loads neither engine.
"""

from wbc.robots.arm_spec import ArmJointSpec, ArmLinkSpec, ArmSpec
from wbc.robots.conventions import JointIndexMap
from wbc.robots.description import ARM_MODES, FOOT_NAMES, LEG_JOINT_NAMES, RobotDescription
from wbc.robots.joint_table import JointTable, joint_table
from wbc.robots.registry import ROBOTS, get_robot
from wbc.robots.urdf import robot_urdf

__all__ = [
    "ARM_MODES",
    "FOOT_NAMES",
    "LEG_JOINT_NAMES",
    "ROBOTS",
    "ArmJointSpec",
    "ArmLinkSpec",
    "ArmSpec",
    "JointIndexMap",
    "JointTable",
    "RobotDescription",
    "get_robot",
    "joint_table",
    "robot_urdf",
]
