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

from wbc.bench import machine_description
from wbc.hardware import MujocoRobot, MujocoRobotConfig
from wbc.robots.urdf import example_robot_data_share
from wbc.standing import stand_command


def _rate(model: mujoco.MjModel, data: mujoco.MjData) -> float:
    mujoco.mj_step(model, data, nstep=500)
    best = 0.0
    for _ in range(3):
        t0 = time.perf_counter()
        mujoco.mj_step(model, data, nstep=5000)
        best = max(best, 5000 / (time.perf_counter() - t0))
    return best


def bare_a1() -> float:
    path = example_robot_data_share() / "example-robot-data/robots/a1_description/urdf/a1.urdf"
    text = path.read_text().replace(
        '<robot name="a1">', '<robot name="a1"><mujoco><compiler discardvisual="true" fusestatic="false"/></mujoco>'
    )
    spec = mujoco.MjSpec.from_string(text)
    spec.body("base").add_freejoint()
    spec.compiler.fusestatic = True
    spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 1])
    spec.option.timestep = 0.002
    for joint in spec.joints:
        if joint.type == mujoco.mjtJoint.mjJNT_HINGE:
            act = spec.add_actuator(target=joint.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
            act.gaintype = mujoco.mjtGain.mjGAIN_FIXED
            act.biastype = mujoco.mjtBias.mjBIAS_AFFINE
            act.gainprm = [60.0] + [0.0] * 9
            act.biasprm = [0.0, -60.0, -2.0] + [0.0] * 7
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qpos[2], data.qpos[3] = 0.3, 1.0
    data.qpos[7:] = [0.0, 0.8, -1.5] * 4
    data.ctrl[:] = data.qpos[7:]
    return _rate(model, data)


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
        assert np.isfinite(robot.data.qpos).all()


if __name__ == "__main__":
    main()
