"""``wbc bench sim``: physics throughput of a robot standing under the motor law, beside the bare-A1 reference."""

from __future__ import annotations

import os
import time

import mujoco
from mujoco import rollout

from wbc.control.stand import stand_command
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.scenario.terrain import TerrainConfig
from wbc.tools.bench.batched_rollout import BatchedRollout
from wbc.tools.bench.references import REFERENCE_TARGETS, machine_description, reference_a1, scaled_target

__all__ = ["bench_sim"]


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

    Args:
        robot: robot registry name.
        arm_mode: ``actuated``, ``locked`` or ``none``.
        seconds: simulated time of one single-threaded measurement [s].
        batch: environments in the batched rollout.
        nthread: rollout threads (None: all cores).
        batch_steps: physics steps of each environment per batched measurement.
        repeats: measurements of each kind; the best is reported.
        terrain: ``flat`` or ``fractal``.
        reference: also measure the bare A1.

    Returns:
        ``steps_per_s``, ``batched_steps_per_s`` [steps/s], ``realtime_factor`` and the settings used; with
        `reference` also ``reference_steps_per_s``, ``reference_batched_steps_per_s``, the ratios
        ``steps_ratio_to_reference``, ``batched_ratio_to_reference`` and the simulator's targets
        (`REFERENCE_TARGETS`) scaled by this machine's reference (``scaled_target_steps_per_s``,
        ``scaled_target_batched_steps_per_s``).

    Raises:
        UnknownNameError: unknown robot or arm mode.
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
        batched = BatchedRollout(sim.model, sim.data, batch, nthread, batch_steps)
        ref_batched = BatchedRollout(ref_model, ref_data, batch, nthread, batch_steps) if reference else None
        best = {"single": 0.0, "batched": 0.0, "ref_single": 0.0, "ref_batched": 0.0}
        batched.rate()  # the first rollout starts the thread pool: keep that out of the figures
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
            out[f"scaled_target_{key}"] = scaled_target(REFERENCE_TARGETS[key], best[ref_key])
    return out
