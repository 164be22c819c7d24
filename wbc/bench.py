"""Speed figures (``wbc bench ...``): measured, printed, never asserted by tests."""

from __future__ import annotations

import os
import platform
import time

import mujoco
import numpy as np
from mujoco import rollout

from wbc.hardware.mujoco_robot import MujocoRobot, MujocoRobotConfig
from wbc.hardware.terrain import TerrainConfig
from wbc.standing import stand_command

__all__ = ["bench_sim", "bench_sweep", "machine_description"]


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
) -> dict[str, float | str | int]:
    """Physics throughput of a robot standing under the motor law.

    Single-threaded: `MujocoRobot.advance` over `seconds` of simulated time (best of `repeats`). Batched:
    ``mujoco.rollout`` over `batch` environments from the settled standing state, `nthread` threads (default: all
    cores), `batch_steps` steps each (best of `repeats`).

    Returns:
        ``steps_per_s``, ``batched_steps_per_s``, ``realtime_factor`` and the settings used.
    """
    nthread = nthread or os.cpu_count() or 1
    sim = MujocoRobot(MujocoRobotConfig(robot=robot, arm_mode=arm_mode, terrain=TerrainConfig(kind=terrain)))
    with sim:
        sim.reset(seed=1)
        sim.write(stand_command(sim.desc))
        sim.advance(0.5)
        dt = sim.config.timestep
        steps = int(round(seconds / dt))
        best = 0.0
        for _ in range(repeats):
            t0 = time.perf_counter()
            sim.advance(seconds)
            best = max(best, steps / (time.perf_counter() - t0))
        model, data = sim.model, sim.data
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        state = np.empty(mujoco.mj_stateSize(model, spec))
        mujoco.mj_getState(model, data, state, spec)
        ctrl = data.ctrl.copy()
        datas = [mujoco.MjData(model) for _ in range(nthread)]
        init = np.tile(state, (batch, 1))
        control = np.tile(ctrl, (batch, 1, 1))
        out = np.empty((batch, batch_steps, state.size))
        rollout.rollout(model, datas, init, control, nstep=batch_steps, state=out, persistent_pool=True)
        best_batched = 0.0
        for _ in range(repeats):
            t0 = time.perf_counter()
            rollout.rollout(model, datas, init, control, nstep=batch_steps, state=out, persistent_pool=True)
            best_batched = max(best_batched, batch * batch_steps / (time.perf_counter() - t0))
        rollout.shutdown_persistent_pool()
        height = float(out[0, -1, 1 + 2])  # time is state[0]; qpos starts at 1
    return {
        "robot": robot,
        "arm_mode": arm_mode,
        "terrain": terrain,
        "timestep_s": dt,
        "steps_per_s": best,
        "batched_steps_per_s": best_batched,
        "realtime_factor": best * dt,
        "batch": batch,
        "threads": nthread,
        "final_base_height_m": height,
        "machine": machine_description(),
    }


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

    from wbc.arena import ArenaConfig, run_arena
    from wbc.control import get_controller
    from wbc.scenarios import load_scenario

    sc = load_scenario(scenario)
    arm = get_controller(controller).arm_mode
    kind = sc.trial(sc.bands[0], 0, 0).terrain.kind
    physics = bench_sim(sc.robot, arm, terrain=kind, nthread=workers, repeats=3)
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
              single_thread: bool = True) -> dict[str, float | str | int]:
    """Speed of the MPC controller in closed loop on one core: MPC solves, whole-body ticks, real-time factor.

    With `single_thread` (the default) it runs in a spawned process whose BLAS is single-threaded, as every arena
    worker is: a BLAS that spreads the MPC's condensing products over the cores is no faster on an idle machine and
    many times slower on a busy one (14 ms instead of 1 ms per MPC setup beside a training job on 2 cores).

    The robot walks at `vx` on flat ground for `seconds`; every MPC update's QP solve time (ProxSuite) and setup
    time (linearisation and condensing) are collected; ``wbc_tick_us_median`` is the whole-body QP's time per tick
    (PlaCo: kinematics, dynamics, tasks, QP, plus setting its targets from Python) and ``control_tick_us_median``
    the whole control tick without an MPC update (estimator, kinematics, footholds, swing targets, whole-body QP,
    motor command). The real-time factor covers everything: physics, controller and MPC updates.
    """
    if single_thread:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        from wbc.executors import single_threaded_blas

        with single_threaded_blas(), ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
            result = pool.submit(bench_mpc, robot, controller, seconds=seconds, vx=vx, single_thread=False).result()
        return {**result, "blas": "single-threaded"}
    from wbc.control import get_controller
    from wbc.types import VelocityCommand

    spec = get_controller(controller)
    sim = MujocoRobot(MujocoRobotConfig(robot=robot, arm_mode=spec.arm_mode))
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
    }
