"""Speed figures (``wbc bench ...``): measured, printed, never asserted by tests."""

from __future__ import annotations

import os
import platform
import time

import mujoco
import numpy as np
from mujoco import rollout

from wbc.control.stand import stand_command
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.robots.urdf import example_robot_data_share
from wbc.scenario.terrain import TerrainConfig

__all__ = ["MPC_REFERENCE_TARGETS", "REFERENCE_TARGETS", "bench_mpc", "bench_sim", "bench_sweep", "machine_description",
           "reference_a1", "reference_placo_tick_us"]


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


REFERENCE_TARGETS = {"steps_per_s": (80_000.0, 110_000.0), "batched_steps_per_s": (150_000.0, 218_000.0)}
"""Issue 2's speed targets and the bare-A1 figures they were set against (steps/s): (target, reference)."""

MPC_REFERENCE_TARGETS = {"wbc_tick_us_median": (100.0, 40.0), "realtime_factor": (5.0, 110_000.0)}
"""Issue 4's speed targets and what they were set against: (target, reference). The whole-body tick's reference is
a bare-A1 PlaCo DynamicsSolver tick with four contacts [us] (`reference_placo_tick_us`); the closed loop's is the
bare A1's single-threaded physics [steps/s] (`reference_a1`)."""


def reference_a1() -> tuple[mujoco.MjModel, mujoco.MjData]:
    """The reference the simulator's speed targets were set against: the bare A1 URDF of example-robot-data.

    A free joint, a floor plane, one PD actuator per joint, MuJoCo's default contact filtering (every geom against
    every other but its parent), no sensors and no joint friction; the same 2 ms step and solver defaults. Returned
    standing at the nominal pose, settled for 1 s.
    """
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
    mujoco.mj_step(model, data, nstep=500)
    return model, data


def reference_placo_tick_us(ticks: int = 1000) -> float:
    """Median time of a bare-A1 whole-body tick in PlaCo's DynamicsSolver [us]: the reference of the 100 us target.

    The A1 URDF of example-robot-data (geometry stripped), standing at the nominal pose with four unilateral point
    contacts (friction 0.6), a CoM task and a trunk orientation task; a tick sets the state, updates the kinematics
    and solves, as `WholeBodyQp.solve` does.
    """
    import placo

    from wbc.mpc.whole_body import placo_robot

    robot = placo_robot((example_robot_data_share() / "example-robot-data/robots/a1_description/urdf/a1.urdf")
                        .read_text())
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
            raise RuntimeError("the reference PlaCo tick failed to solve")
    return 1e6 * float(np.median(times))


class _Batched:
    """`mujoco.rollout` of `batch` copies of a model's current state over `nstep` steps, repeatable."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, batch: int, nthread: int, nstep: int) -> None:
        which = mujoco.mjtState.mjSTATE_FULLPHYSICS
        state = np.empty(mujoco.mj_stateSize(model, which))
        mujoco.mj_getState(model, data, state, which)
        self.model, self.nstep, self.batch = model, nstep, batch
        self.datas = [mujoco.MjData(model) for _ in range(nthread)]
        self.init = np.tile(state, (batch, 1))
        self.control = np.tile(data.ctrl.copy(), (batch, 1, 1))
        self.out = np.empty((batch, nstep, state.size))

    def rate(self) -> float:
        t0 = time.perf_counter()
        rollout.rollout(self.model, self.datas, self.init, self.control, nstep=self.nstep, state=self.out,
                        persistent_pool=True)
        return self.batch * self.nstep / (time.perf_counter() - t0)


def bench_sim(
    robot: str = "a1-wx200",
    arm_mode: str = "actuated",
    *,
    seconds: float = 2.0,
    batch: int = 64,
    nthread: int | None = None,
    batch_steps: int = 500,
    repeats: int = 5,
    terrain: str = "flat",
    reference: bool = True,
) -> dict[str, float | str | int]:
    """Physics throughput of a robot standing under the motor law, beside the bare-A1 reference.

    Single-threaded: `MujocoRobot.advance` over `seconds` of simulated time (best of `repeats`). Batched:
    ``mujoco.rollout`` over `batch` environments from the settled standing state, `nthread` threads (default: all
    cores), `batch_steps` steps each (best of `repeats`). With `reference`, the bare A1 (`reference_a1`) is measured
    the same way in the same repeats, interleaved, so both see the same machine: on a shared VM absolute figures
    swing by 2x between sessions, the ratio much less.

    Returns:
        ``steps_per_s``, ``batched_steps_per_s``, ``realtime_factor`` and the settings used; with `reference` also
        ``reference_steps_per_s``, ``reference_batched_steps_per_s``, the ratios ``steps_ratio_to_reference``,
        ``batched_ratio_to_reference`` and issue 2's targets scaled by this machine's reference
        (``scaled_target_steps_per_s``, ``scaled_target_batched_steps_per_s``).
    """
    nthread = nthread or os.cpu_count() or 1
    sim = MujocoRobot(MujocoRobotConfig(robot=robot, arm_mode=arm_mode, terrain=TerrainConfig(kind=terrain)))
    ref_model, ref_data = reference_a1() if reference else (None, None)
    with sim:
        sim.reset(seed=1)
        sim.write(stand_command(sim.desc))
        sim.advance(0.5)
        dt = sim.config.timestep
        steps = int(round(seconds / dt))
        batched = _Batched(sim.model, sim.data, batch, nthread, batch_steps)
        ref_batched = _Batched(ref_model, ref_data, batch, nthread, batch_steps) if reference else None
        best = {"single": 0.0, "batched": 0.0, "ref_single": 0.0, "ref_batched": 0.0}
        batched.rate()  # start the thread pool
        for _ in range(repeats):
            t0 = time.perf_counter()
            sim.advance(seconds)
            best["single"] = max(best["single"], steps / (time.perf_counter() - t0))
            best["batched"] = max(best["batched"], batched.rate())
            if reference:
                t0 = time.perf_counter()
                mujoco.mj_step(ref_model, ref_data, nstep=steps)
                best["ref_single"] = max(best["ref_single"], steps / (time.perf_counter() - t0))
                best["ref_batched"] = max(best["ref_batched"], ref_batched.rate())
        rollout.shutdown_persistent_pool()
        height = float(batched.out[0, -1, 1 + 2])  # time is state[0]; qpos starts at 1
    out: dict[str, float | str | int] = {
        "robot": robot,
        "arm_mode": arm_mode,
        "terrain": terrain,
        "timestep_s": dt,
        "steps_per_s": best["single"],
        "batched_steps_per_s": best["batched"],
        "realtime_factor": best["single"] * dt,
        "batch": batch,
        "threads": nthread,
        "final_base_height_m": height,
        "machine": machine_description(),
    }
    if reference:
        out["reference_steps_per_s"] = best["ref_single"]
        out["reference_batched_steps_per_s"] = best["ref_batched"]
        out["steps_ratio_to_reference"] = best["single"] / best["ref_single"]
        out["batched_ratio_to_reference"] = best["batched"] / best["ref_batched"]
        for key, ref_key in (("steps_per_s", "ref_single"), ("batched_steps_per_s", "ref_batched")):
            target, at = REFERENCE_TARGETS[key]
            out[f"scaled_target_{key}"] = target / at * best[ref_key]
    return out


def bench_sweep(
    scenario: str = "scenarios/push.toml",
    controller: str = "stand",
    *,
    trials: int = 10,
    workers: int | None = None,
    ray: bool = False,
) -> dict[str, float | str | int]:
    """Throughput of a whole arena sweep (runner, executor, results store included) against raw physics.

    Plays `trials` trials per band of `scenario` with `controller` on the local process pool and, if `ray`, again on a
    local Ray; compares the sweep's physics steps per second with the batched physics throughput of the same robot
    standing on the same terrain (`bench_sim`).
    """
    import tempfile
    from pathlib import Path

    from wbc.arena.compare import ArenaConfig, run_arena
    from wbc.control.registry import get_controller
    from wbc.scenario.scenario import load_scenario

    sc = load_scenario(scenario)
    arm = get_controller(controller).arm_mode
    kind = sc.trial(sc.bands[0], 0, 0).terrain.kind
    physics = bench_sim(sc.robot, arm, terrain=kind, nthread=workers, repeats=3, reference=False)
    out: dict[str, float | str | int] = {
        "scenario": sc.name, "controller": controller, "terrain": kind, "trials": trials * len(sc.bands),
        "batched_physics_steps_per_s": physics["batched_steps_per_s"], "machine": machine_description(),
    }
    executors = ["local"] + (["ray"] if ray else [])
    for name in executors:
        with tempfile.TemporaryDirectory() as tmp:
            cfg = ArenaConfig(controllers=(controller,), scenario=Path(scenario), trials=trials,
                              out_dir=Path(tmp) / name, executor=name, workers=workers, progress=False)
            t0 = time.perf_counter()
            result = run_arena(cfg)
            wall = time.perf_counter() - t0
        out[f"{name}_wall_s"] = wall
        out[f"{name}_sweep_steps_per_s"] = result.physics_steps / wall
        out[f"{name}_ratio_to_batched_physics"] = result.physics_steps / wall / physics["batched_steps_per_s"]
    if ray:
        out["ray_overhead_per_trial_s"] = (out["ray_wall_s"] - out["local_wall_s"]) / out["trials"]
    return out


def bench_mpc(robot: str = "a1-wx200", controller: str = "mpc", *, seconds: float = 4.0, vx: float = 0.3,
              single_thread: bool = True, reference: bool = True) -> dict[str, float | str | int]:
    """Speed of the MPC controller in closed loop on one core: MPC solves, whole-body ticks, real-time factor.

    With `single_thread` (the default) it runs in a spawned process whose BLAS is single-threaded, as every arena
    worker is: a BLAS that spreads the MPC's condensing products over the cores is no faster on an idle machine and
    many times slower on a busy one (14 ms instead of 1 ms per MPC setup beside a training job on 2 cores).

    The robot walks at `vx` on flat ground for `seconds`; every MPC update's QP solve time (ProxSuite) and setup
    time (linearisation and condensing) are collected; ``wbc_tick_us_median`` is the whole-body QP's time per tick
    (PlaCo: kinematics, dynamics, tasks, QP, plus setting its targets from Python) and ``control_tick_us_median``
    the whole control tick without an MPC update (estimator, kinematics, footholds, swing targets, whole-body QP,
    motor command). The real-time factor covers everything: physics, controller and MPC updates.

    With `reference`, the references issue 4's targets were set against are measured before and after the closed loop
    in the same process (`MPC_REFERENCE_TARGETS`): a bare-A1 PlaCo tick (`reference_placo_tick_us`; "about 40 us") and
    the bare A1's single-threaded physics (`reference_a1`; 110k steps/s). The results then include
    ``reference_placo_tick_us``, ``reference_steps_per_s``, and the targets scaled by them to this machine:
    ``scaled_target_wbc_tick_us`` (100 us times the reference tick over 40 us) and ``scaled_target_realtime_factor``
    (5x times the reference physics over 110k).
    """
    if single_thread:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        from wbc.arena.executors import single_threaded_blas

        with single_threaded_blas(), ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
            result = pool.submit(bench_mpc, robot, controller, seconds=seconds, vx=vx, single_thread=False,
                                 reference=reference).result()
        return {**result, "blas": "single-threaded"}
    from wbc.control.registry import get_controller
    from wbc.types import VelocityCommand

    spec = get_controller(controller)
    sim = MujocoRobot(MujocoRobotConfig(robot=robot, arm_mode=spec.arm_mode))
    ref_ticks, ref_rates = [], []

    def measure_references() -> None:
        ref_ticks.append(reference_placo_tick_us(500))
        model, data = reference_a1()
        t0 = time.perf_counter()
        mujoco.mj_step(model, data, nstep=1000)
        ref_rates.append(1000 / (time.perf_counter() - t0))

    if reference:
        measure_references()
    with sim:
        sim.reset(seed=0)
        ctrl = spec.make(sim.desc)
        ctrl.reset()
        dt = 1.0 / ctrl.rate_hz
        command = VelocityCommand(vx=vx)
        solves, setups, ticks, wbc_ticks = [], [], [], []
        last = None
        wbc = getattr(ctrl, "wbc", None)
        if wbc is not None:
            real_solve = wbc.solve

            def timed_solve(*a, **kw):
                t0 = time.perf_counter()
                out = real_solve(*a, **kw)
                wbc_ticks.append(time.perf_counter() - t0)
                return out

            wbc.solve = timed_solve
        start = time.perf_counter()
        for _ in range(int(round(seconds / dt))):
            state = sim.read()
            t0 = time.perf_counter()
            out = ctrl.act(state, command)
            elapsed = time.perf_counter() - t0
            plan = getattr(ctrl, "plan", None)
            if plan is not None and plan is not last:
                solves.append(plan.solve_s)
                setups.append(plan.setup_s)
                last = plan
            else:
                ticks.append(elapsed)
            sim.write(out)
            sim.advance(dt)
        wall = time.perf_counter() - start
        fell = sim.fallen()
    references: dict[str, float] = {}
    if reference:
        measure_references()
        tick_ref, rate_ref = float(np.mean(ref_ticks)), max(ref_rates)
        tick_target, tick_at = MPC_REFERENCE_TARGETS["wbc_tick_us_median"]
        rt_target, rt_at = MPC_REFERENCE_TARGETS["realtime_factor"]
        references = {"reference_placo_tick_us": tick_ref, "reference_steps_per_s": rate_ref,
                      "scaled_target_wbc_tick_us": tick_target * tick_ref / tick_at,
                      "scaled_target_realtime_factor": rt_target * rate_ref / rt_at}
    return {
        "robot": robot,
        "controller": controller,
        "horizon": int(ctrl.config.mpc.horizon),
        "mpc_solve_ms_median": 1e3 * float(np.median(solves)),
        "mpc_solve_ms_p99": 1e3 * float(np.percentile(solves, 99)),
        "mpc_setup_ms_median": 1e3 * float(np.median(setups)),
        "wbc_tick_us_median": 1e6 * float(np.median(wbc_ticks)) if wbc_ticks else float("nan"),
        "control_tick_us_median": 1e6 * float(np.median(ticks)),
        "realtime_factor": seconds / wall,
        "fell": bool(fell),
        "blas": "default threads",
        "machine": machine_description(),
        **references,
    }
