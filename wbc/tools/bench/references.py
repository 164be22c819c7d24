"""The references every speed target is stated against, and the targets themselves.

A speed target means nothing on its own on a shared VM, where absolute figures swing by 2x between sessions. Each
target is therefore paired with the figure a fixed reference workload reached when the target was set: the bare A1
URDF of example-robot-data in MuJoCo (`reference_a1`) and a bare-A1 whole-body tick in PlaCo
(`reference_placo_tick_us`). A bench measures the reference beside its subject on the same machine, in the same
session, and reports the target scaled to it (`scaled_target`).
"""

from __future__ import annotations

import os
import platform
import time

import mujoco
import numpy as np
import placo

from wbc.errors import BenchError
from wbc.mpc.whole_body import placo_robot
from wbc.robots.urdf import example_robot_data_share

__all__ = ["MPC_REFERENCE_TARGETS", "REFERENCE_STEPS_PER_CONTROL_STEP", "REFERENCE_TARGETS", "TRAIN_TARGET",
           "load_1min", "machine_description", "reference_a1", "reference_a1_steps_per_s", "reference_placo_tick_us",
           "scaled_target"]

REFERENCE_TARGETS = {"steps_per_s": (80_000.0, 110_000.0), "batched_steps_per_s": (150_000.0, 218_000.0)}
"""The simulator's speed targets, each as (target, the bare A1's figure it was set against) [steps/s].

``steps_per_s``: one robot stepped single-threaded; ``batched_steps_per_s``: 64 environments through
``mujoco.rollout`` on 2 threads. The robot of the toolkit (sensors, joint friction, an arm) must reach 73 % and 69 %
of the bare A1 (`reference_a1`) measured the same way."""

MPC_REFERENCE_TARGETS = {"wbc_tick_us_median": (100.0, 40.0), "realtime_factor": (5.0, 110_000.0)}
"""The MPC controller's speed targets, each as (target, the reference figure it was set against).

``wbc_tick_us_median``: a whole-body QP tick of at most 100 us where a bare-A1 PlaCo DynamicsSolver tick with four
contacts takes 40 us (`reference_placo_tick_us`) [us]; ``realtime_factor``: a closed loop (physics, controller, MPC
updates) of at least 5x real time where the bare A1's single-threaded physics runs at 110k steps/s (`reference_a1`)."""

TRAIN_TARGET = (15_000.0, 21_800.0)
"""The training env's target and the physics limit it was set against [control steps/s]: 15k policy steps/s of all
environments where the bare A1 batched over 64 environments on 2 threads (218k physics steps/s, ten physics steps
per control step) gives 21.8k."""

REFERENCE_STEPS_PER_CONTROL_STEP = 10
"""The reference's physics steps per control step: 2 ms steps at 50 Hz."""

A1_URDF = "example-robot-data/robots/a1_description/urdf/a1.urdf"
"""The bare A1 URDF, relative to example-robot-data's share directory."""


def scaled_target(target: tuple[float, float], reference_here: float) -> float:
    """A target as it reads on this machine: ``target * reference_here / reference_then``.

    Args:
        target: (target, the reference's figure when the target was set), in the same unit.
        reference_here: the reference measured on this machine now, in that unit.
    """
    value, at = target
    return value / at * reference_here


def machine_description() -> str:
    """One line naming the CPU and core count of this machine."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, MuJoCo {mujoco.__version__}"


def load_1min() -> float:
    """The machine's load average over the last minute: what else ran beside a bench (nan where the OS has none)."""
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")


def reference_a1() -> tuple[mujoco.MjModel, mujoco.MjData]:
    """The reference the simulator's speed targets were set against: the bare A1 URDF of example-robot-data.

    A free joint, a floor plane, one PD actuator per joint, MuJoCo's default contact filtering (every geom against
    every other but its parent), no sensors and no joint friction; the same 2 ms step and solver defaults. Returned
    standing at the nominal pose, settled for 1 s.
    """
    text = (example_robot_data_share() / A1_URDF).read_text().replace(
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
    mujoco.mj_step(model, data, nstep=500)
    return model, data


def reference_a1_steps_per_s(nstep: int = 1000) -> float:
    """Single-threaded physics rate of the freshly settled bare A1 (`reference_a1`) over `nstep` steps [steps/s]."""
    model, data = reference_a1()
    t0 = time.perf_counter()
    mujoco.mj_step(model, data, nstep=nstep)
    return nstep / (time.perf_counter() - t0)


def reference_placo_tick_us(ticks: int = 1000) -> float:
    """Median time of a bare-A1 whole-body tick in PlaCo's DynamicsSolver [us]: the reference of the 100 us target.

    The A1 URDF of example-robot-data (geometry stripped), standing at the nominal pose with four unilateral point
    contacts (friction 0.6), a CoM task and a trunk orientation task; a tick sets the state, updates the kinematics
    and solves, as `WholeBodyQp.solve` does.

    Raises:
        BenchError: PlaCo failed to solve a tick (the installed placo does not behave as the pinned 0.10.2).
    """
    robot = placo_robot((example_robot_data_share() / A1_URDF).read_text())
    q = robot.state.q.copy()
    q[2], q[3:7] = 0.3, (0.0, 0.0, 0.0, 1.0)
    for leg in ("FR", "FL", "RR", "RL"):
        for joint, value in (("hip", 0.0), ("thigh", 0.8), ("calf", -1.5)):
            q[robot.get_joint_offset(f"{leg}_{joint}_joint")] = value
    robot.state.q = q
    robot.update_kinematics()
    solver = placo.DynamicsSolver(robot)
    solver.mask_fbase(False)
    solver.enable_torque_limits(True)
    for leg in ("FR", "FL", "RR", "RL"):
        task = solver.add_position_task(f"{leg}_foot", robot.get_T_world_frame(f"{leg}_foot")[:3, 3])
        contact = solver.add_point_contact(task)
        contact.mu, contact.unilateral = 0.6, True
    com = solver.add_com_task(robot.com_world())
    com.configure("com", "soft", 10.0)
    trunk = solver.add_orientation_task("trunk", np.eye(3))
    trunk.configure("trunk", "soft", 10.0)
    state = robot.state
    rng = np.random.default_rng(0)
    qd = 0.05 * rng.standard_normal((ticks, robot.model.nv))
    times = np.empty(ticks)
    for k in range(ticks):
        t0 = time.perf_counter()
        state.q = q
        state.qd = qd[k]
        robot.update_kinematics()
        result = solver.solve(False)
        times[k] = time.perf_counter() - t0
        if not result.success:
            raise BenchError(f"the reference PlaCo tick failed to solve at tick {k}: check that the installed placo "
                             "is the pinned 0.10.2 (pip install placo==0.10.2), or skip the references "
                             "(--no-reference, reference=False)")
    return 1e6 * float(np.median(times))
