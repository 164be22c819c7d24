"""The simulated robot: `MujocoRobot` (sensors, motor law, pushes, domain), its scene and its fall rule."""

from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig, SimTruth

__all__ = ["MujocoRobot", "MujocoRobotConfig", "SimTruth"]
