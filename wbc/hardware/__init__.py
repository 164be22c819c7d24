"""Robot backends: the `Robot` interface and its contract checker; the MuJoCo backend lives in `wbc.hardware.mujoco`.

Importing this package does not import MuJoCo, so a robot computer that runs a real backend does not need it.
"""

from wbc.hardware.quadruped_arm_robot import QuadrupedArmConfig, QuadrupedArmRobot
from wbc.hardware.robot import Robot, clamp_command
from wbc.hardware.robot_contract import RobotContractError, check_robot

__all__ = ["QuadrupedArmConfig", "QuadrupedArmRobot", "Robot", "RobotContractError", "check_robot", "clamp_command"]
