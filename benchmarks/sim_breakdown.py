"""Where the physics time goes: the bare A1 URDF against the toolkit's models, on this machine.

Run: python benchmarks/sim_breakdown.py
Prints steps/s (best of 3 x 5000 steps, standing under a PD hold) for
  - the bare A1 URDF: free joint, floor, PD actuators, nothing else (the reference figure);
  - a1-wx200 in each arm mode as the toolkit builds it (sensors, joint friction, limits);
  - a1-wx200 actuated with joint dry friction removed, and with sensors disabled, to show what each costs.
"""

from __future__ import annotations

import time

import mujoco
import numpy as np

from wbc.control.stand import stand_command
from wbc.errors import BenchError
from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
from wbc.tools.bench import machine_description, reference_a1


def _rate(model: mujoco.MjModel, data: mujoco.MjData) -> float:
    mujoco.mj_step(model, data, nstep=500)
    best = 0.0
    for _ in range(3):
        t0 = time.perf_counter()
        mujoco.mj_step(model, data, nstep=5000)
        best = max(best, 5000 / (time.perf_counter() - t0))
    return best


def bare_a1() -> float:
    return _rate(*reference_a1())


def main() -> None:
    print(machine_description())
    print(f"{'model':<44}{'steps/s':>10}")
    print(f"{'bare A1 URDF (no sensors, no joint friction)':<44}{bare_a1():>10,.0f}")
    for arm in ("none", "locked", "actuated"):
        with MujocoRobot(MujocoRobotConfig(arm_mode=arm)) as robot:
            robot.write(stand_command(robot.desc))
            print(f"{'a1-wx200, arm ' + arm:<44}{_rate(robot.model, robot.data):>10,.0f}")
    with MujocoRobot(MujocoRobotConfig()) as robot:
        robot.write(stand_command(robot.desc))
        m = robot.model
        friction = m.dof_frictionloss.copy()
        m.dof_frictionloss[:] = 0.0
        print(f"{'a1-wx200 actuated, no joint dry friction':<44}{_rate(m, robot.data):>10,.0f}")
        m.dof_frictionloss[:] = friction
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_SENSOR
        print(f"{'a1-wx200 actuated, sensors off':<44}{_rate(m, robot.data):>10,.0f}")
        if not np.isfinite(robot.data.qpos).all():
            raise BenchError("the a1-wx200 diverged standing with its sensors off, so the figures above timed a "
                             "diverged simulation; run `pytest tests/test_mujoco_robot.py` to find what in the model "
                             "broke")


if __name__ == "__main__":
    main()
