"""Stand the A1 + WX200 on fractal ground, push it sideways, and watch it recover or fall.

Run: python examples/push_the_standing_robot.py
"""

import numpy as np

from wbc.control.stand import stand_command
from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
from wbc.scenario import Push, TerrainConfig

config = MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated", terrain=TerrainConfig(kind="fractal"))

for force in (100.0, 250.0, 350.0):
    with MujocoRobot(config) as robot:
        robot.reset(seed=0)
        # 0.06 s at t = 1 s, towards +y (heading 90 deg), 5 cm in front of the trunk centre
        robot.apply_push(Push.horizontal(force, np.pi / 2, (0.05, 0.0, 0.0), start=1.0, duration=0.06))
        command = stand_command(robot.desc)
        outcome = "recovered"
        for _ in range(150):  # 3 s at 50 Hz
            robot.write(command)
            robot.advance(0.02)
            if robot.fallen():
                outcome = f"fell at t = {robot.time:.2f} s"
                break
        truth = robot.sim_truth()
        print(f"{force:5.0f} N: {outcome}; trunk moved {np.linalg.norm(truth.base_position_in_world[:2]):.2f} m")
