"""Walk the A1 + WX200 forward with the centroidal MPC and print what its estimator believes against the truth.

Run: python examples/mpc_walk.py
"""

from wbc.control.registry import get_controller
from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
from wbc.types import VelocityCommand

spec = get_controller("mpc")  # also: mpc-locked, mpc-noarm
with MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode=spec.arm_mode)) as robot:
    controller = spec.make(robot.desc)
    controller.reset()
    command = VelocityCommand(vx=0.3)
    dt = 1.0 / controller.rate_hz
    for tick in range(int(4.0 / dt)):
        state = robot.read()  # proprioception only: the controller never sees simulator truth
        robot.write(controller.act(state, command))
        robot.advance(dt)
        if tick % 250 == 0:
            truth = robot.sim_truth()
            print(f"t = {robot.time:4.1f} s  true vx = {truth.base_linvel_in_world[0]:+.2f} m/s  "
                  f"estimated vx = {controller.estimator.velocity[0]:+.2f} m/s")
    print(controller.counters())
