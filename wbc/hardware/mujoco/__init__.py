"""The simulated robot: `MujocoRobot`, its scene, its fall rule and the physics it shares with the training env.

`robot` (sensors, motor law, pushes, domain), `scene` (robot on its ground), `fall_rule` (what counts as a fall) and
`physics` (domain parameters, motor gains, spawn pose, push rounding and wrench, written once for both simulators).
"""

from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig, SimTruth

__all__ = ["MujocoRobot", "MujocoRobotConfig", "SimTruth"]
