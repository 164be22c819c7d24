"""``wbc bench sim``: physics throughput of a robot standing under the motor law, beside the bare-A1 reference."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import mujoco
from mujoco import rollout

from wbc.control.stand import stand_command
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.scenario.terrain import TerrainConfig
from wbc.tools.bench.batched_rollout import BatchedRollout, check_rollout_memory
from wbc.tools.bench.references import (
    REFERENCE_TARGETS,
    load_1min,
    machine_description,
    reference_a1,
    scaled_target,
)

__all__ = ["SimBenchResult", "SimReference", "bench_sim"]


@dataclass(frozen=True, kw_only=True)
class SimReference:
    """The bare A1 (`reference_a1`) measured beside the robot, and the simulator's targets scaled by it.

    Attributes:
        steps_per_s: the bare A1 stepped single-threaded [steps/s].
        batched_steps_per_s: the bare A1 through the same batched rollout [steps/s].
        steps_ratio_to_reference: the robot's single-threaded rate over the bare A1's.
        batched_ratio_to_reference: the robot's batched rate over the bare A1's.
        scaled_target_steps_per_s: the single-threaded target (`REFERENCE_TARGETS`) scaled to this machine [steps/s].
        scaled_target_batched_steps_per_s: the batched target scaled to this machine [steps/s].
    """

    steps_per_s: float
    batched_steps_per_s: float
    steps_ratio_to_reference: float
    batched_ratio_to_reference: float
    scaled_target_steps_per_s: float
    scaled_target_batched_steps_per_s: float

    def as_dict(self) -> dict[str, float]:
        """The figures under their keys in `SimBenchResult.as_dict` (the bare A1's rates prefixed ``reference_``)."""
        return {"reference_steps_per_s": self.steps_per_s,
                "reference_batched_steps_per_s": self.batched_steps_per_s,
                "steps_ratio_to_reference": self.steps_ratio_to_reference,
                "batched_ratio_to_reference": self.batched_ratio_to_reference,
                "scaled_target_steps_per_s": self.scaled_target_steps_per_s,
                "scaled_target_batched_steps_per_s": self.scaled_target_batched_steps_per_s}


@dataclass(frozen=True, kw_only=True)
class SimBenchResult:
    """What `bench_sim` measured: a robot's physics throughput, and the bare-A1 reference's when it was measured.

    Attributes:
        robot: robot registry name.
        arm_mode: ``actuated``, ``locked`` or ``none``.
        terrain: ``flat`` or ``fractal``.
        timestep_s: the physics step [s].
        steps_per_s: single-threaded physics rate, best of the repeats [steps/s].
        batched_steps_per_s: batched rollout rate over all environments, best of the repeats [steps/s].
        realtime_factor: simulated seconds per wall-clock second, single-threaded.
        batch: environments in the batched rollout.
        threads: rollout threads.
        final_base_height_m: the base's height at the end of the first environment's rollout [m] (it stood).
        machine: `machine_description`.
        load_1min: the machine's 1-minute load average at the end (`load_1min`; nan where the OS has none).
        reference: the bare A1's figures, or None when they were not measured.
    """

    robot: str
    arm_mode: str
    terrain: str
    timestep_s: float
    steps_per_s: float
    batched_steps_per_s: float
    realtime_factor: float
    batch: int
    threads: int
    final_base_height_m: float
    machine: str
    load_1min: float = float("nan")
    reference: SimReference | None = None

    def as_dict(self) -> dict[str, float | str | int]:
        """Plain flat dict (the JSON output of ``wbc bench sim``): the reference's keys follow when measured."""
        out: dict[str, float | str | int] = {
            "robot": self.robot, "arm_mode": self.arm_mode, "terrain": self.terrain, "timestep_s": self.timestep_s,
            "steps_per_s": self.steps_per_s, "batched_steps_per_s": self.batched_steps_per_s,
            "realtime_factor": self.realtime_factor, "batch": self.batch, "threads": self.threads,
            "final_base_height_m": self.final_base_height_m, "machine": self.machine, "load_1min": self.load_1min,
        }
        if self.reference is not None:
            out.update(self.reference.as_dict())
        return out


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
) -> SimBenchResult:
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
        The single-threaded and batched rates, the real-time factor and the settings used; with `reference` also the
        bare A1's rates, the ratios to them and the simulator's targets (`REFERENCE_TARGETS`) scaled by this
        machine's reference (`SimReference`).

    Raises:
        UnknownNameError: unknown robot or arm mode.
        ConfigError: the batched rollouts' buffers (every step's state of every environment) would take more than
            half the memory available (`check_rollout_memory`; the message names ``--batch``).
    """
    nthread = nthread or os.cpu_count() or 1
    sim = MujocoRobot(MujocoRobotConfig(robot=robot, arm_mode=arm_mode, terrain=TerrainConfig(kind=terrain)))
    ref_model, ref_data = reference_a1() if reference else (None, None)
    with sim:
        check_rollout_memory([sim.model] + ([ref_model] if reference else []), batch, batch_steps)
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
            sim.advance(steps * dt)  # whole physics steps (advance refuses a part of one)
            best["single"] = max(best["single"], steps / (time.perf_counter() - t0))
            best["batched"] = max(best["batched"], batched.rate())
            if reference:
                t0 = time.perf_counter()
                mujoco.mj_step(ref_model, ref_data, nstep=steps)
                best["ref_single"] = max(best["ref_single"], steps / (time.perf_counter() - t0))
                best["ref_batched"] = max(best["ref_batched"], ref_batched.rate())
        rollout.shutdown_persistent_pool()
        load = load_1min()
        height = float(batched.out[0, -1, 1 + 2])  # time is state[0]; qpos starts at 1
    figures = None
    if reference:
        figures = SimReference(
            steps_per_s=best["ref_single"], batched_steps_per_s=best["ref_batched"],
            steps_ratio_to_reference=best["single"] / best["ref_single"],
            batched_ratio_to_reference=best["batched"] / best["ref_batched"],
            scaled_target_steps_per_s=scaled_target(REFERENCE_TARGETS["steps_per_s"], best["ref_single"]),
            scaled_target_batched_steps_per_s=scaled_target(REFERENCE_TARGETS["batched_steps_per_s"],
                                                            best["ref_batched"]))
    return SimBenchResult(robot=robot, arm_mode=arm_mode, terrain=terrain, timestep_s=dt, steps_per_s=best["single"],
                          batched_steps_per_s=best["batched"], realtime_factor=best["single"] * dt, batch=batch,
                          threads=nthread, final_base_height_m=height, machine=machine_description(),
                          load_1min=load, reference=figures)
