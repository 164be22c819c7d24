"""Robot descriptions (A1 + WX200, Go1 + arm) and the MuJoCo and Pinocchio models built from them."""

from wbc.robots.arm_spec import ArmJointSpec, ArmLinkSpec, ArmSpec
from wbc.robots.conventions import JointIndexMap
from wbc.robots.description import ARM_MODES, FOOT_NAMES, LEG_JOINT_NAMES, RobotDescription
from wbc.robots.joint_table import JointTable, joint_table
from wbc.robots.mujoco_model import robot_mujoco_spec
from wbc.robots.pinocchio_model import PinocchioRobot, build_pinocchio
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
    "PinocchioRobot",
    "RobotDescription",
    "build_pinocchio",
    "get_robot",
    "joint_table",
    "robot_mujoco_spec",
    "robot_urdf",
]
