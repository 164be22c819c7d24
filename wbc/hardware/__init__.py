"""The robot interface (`Robot`), its contract checker and the MuJoCo backend."""

from wbc.hardware.contract import RobotContractError, check_robot
from wbc.hardware.domain import DomainParams, SensorNoise
from wbc.hardware.mujoco_robot import MujocoRobot, MujocoRobotConfig, SimTruth
from wbc.hardware.perturbation import Push
from wbc.hardware.robot import Robot, clamp_command
from wbc.hardware.terrain import TerrainConfig

__all__ = [
    "DomainParams",
    "MujocoRobot",
    "MujocoRobotConfig",
    "Push",
    "Robot",
    "RobotContractError",
    "SensorNoise",
    "SimTruth",
    "TerrainConfig",
    "check_robot",
    "clamp_command",
]
