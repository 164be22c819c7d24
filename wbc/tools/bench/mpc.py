"""``wbc bench mpc``: the MPC controller's speed in closed loop on one core."""

from __future__ import annotations

import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from wbc.arena.executors import single_threaded_blas
from wbc.control.registry import get_controller
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.tools.bench.references import (
    MPC_REFERENCE_TARGETS,
    machine_description,
    reference_a1_steps_per_s,
    reference_placo_tick_us,
)
from wbc.types import VelocityCommand

__all__ = ["bench_mpc"]


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

    With `reference`, the references of the MPC targets (`MPC_REFERENCE_TARGETS`) are measured before and after
    the closed loop in the same process: a bare-A1 PlaCo tick (`reference_placo_tick_us`; "about 40 us") and
    the bare A1's single-threaded physics (`reference_a1`; 110k steps/s). The results then include
    ``reference_placo_tick_us``, ``reference_steps_per_s``, and the targets scaled by them to this machine:
    ``scaled_target_wbc_tick_us`` (100 us times the reference tick over 40 us) and ``scaled_target_realtime_factor``
    (5x times the reference physics over 110k).
    """
    if single_thread:
        with single_threaded_blas(), ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
            result = pool.submit(bench_mpc, robot, controller, seconds=seconds, vx=vx, single_thread=False,
                                 reference=reference).result()
        return {**result, "blas": "single-threaded"}
    spec = get_controller(controller)
    sim = MujocoRobot(MujocoRobotConfig(robot=robot, arm_mode=spec.arm_mode))
    ref_ticks, ref_rates = [], []

    def measure_references() -> None:
        ref_ticks.append(reference_placo_tick_us(500))
        ref_rates.append(reference_a1_steps_per_s(1000))

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
