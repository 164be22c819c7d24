"""``wbc bench sweep``: throughput of a whole arena sweep (runner, executor, results store) against raw physics."""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from wbc.arena.compare import ArenaConfig, run_arena
from wbc.control.registry import get_controller
from wbc.scenario.scenario import load_scenario
from wbc.tools.bench.references import load_1min, machine_description
from wbc.tools.bench.sim import bench_sim

__all__ = ["SweepBenchResult", "SweepExecutorRow", "bench_sweep"]


@dataclass(frozen=True, kw_only=True)
class SweepExecutorRow:
    """The sweep played on one executor.

    Attributes:
        executor: ``local`` (the process pool) or ``ray``.
        wall_s: the whole sweep's wall time [s].
        sweep_steps_per_s: physics steps of all trials per second of that time [steps/s].
        ratio_to_batched_physics: that rate over the batched physics throughput (`bench_sim`).
    """

    executor: str
    wall_s: float
    sweep_steps_per_s: float
    ratio_to_batched_physics: float

    def as_dict(self) -> dict[str, float]:
        """The figures under their keys in `SweepBenchResult.as_dict` (``<executor>_wall_s`` ...)."""
        return {f"{self.executor}_wall_s": self.wall_s,
                f"{self.executor}_sweep_steps_per_s": self.sweep_steps_per_s,
                f"{self.executor}_ratio_to_batched_physics": self.ratio_to_batched_physics}


@dataclass(frozen=True, kw_only=True)
class SweepBenchResult:
    """What `bench_sweep` measured: a whole arena sweep's throughput on each executor, against raw physics.

    Attributes:
        scenario: the scenario's name.
        controller: controller registry name.
        terrain: the terrain kind of the scenario's trials.
        trials: trials played per executor (all bands).
        batched_physics_steps_per_s: the batched physics throughput of the same robot standing on the same terrain
            (`bench_sim`) [steps/s].
        machine: `machine_description`.
        load_1min: the machine's 1-minute load average at the end (`load_1min`; nan where the OS has none).
        executors: one row per executor, in the order played (local first).
    """

    scenario: str
    controller: str
    terrain: str
    trials: int
    batched_physics_steps_per_s: float
    machine: str
    load_1min: float = float("nan")
    executors: tuple[SweepExecutorRow, ...] = ()

    def executor(self, name: str) -> SweepExecutorRow | None:
        """The row of executor `name`, or None when it was not played."""
        return next((row for row in self.executors if row.executor == name), None)

    @property
    def ray_overhead_per_trial_s(self) -> float | None:
        """Ray's wall time over the local pool's, per trial [s]; None unless both were played."""
        local, ray = self.executor("local"), self.executor("ray")
        if local is None or ray is None:
            return None
        return (ray.wall_s - local.wall_s) / self.trials

    def as_dict(self) -> dict[str, float | str | int]:
        """Plain flat dict (the JSON output of ``wbc bench sweep``): each executor's keys prefixed by its name."""
        out: dict[str, float | str | int] = {
            "scenario": self.scenario, "controller": self.controller, "terrain": self.terrain, "trials": self.trials,
            "batched_physics_steps_per_s": self.batched_physics_steps_per_s, "machine": self.machine,
            "load_1min": self.load_1min,
        }
        for row in self.executors:
            out.update(row.as_dict())
        overhead = self.ray_overhead_per_trial_s
        if overhead is not None:
            out["ray_overhead_per_trial_s"] = overhead
        return out


def bench_sweep(
    scenario: str = "scenarios/push.toml",
    controller: str = "stand",
    *,
    trials: int = 10,
    workers: int | None = None,
    ray: bool = False,
) -> SweepBenchResult:
    """Throughput of a whole arena sweep (runner, executor, results store included) against raw physics.

    Plays `trials` trials per band of `scenario` with `controller` on the local process pool and, if `ray`, again on a
    local Ray; compares the sweep's physics steps per second with the batched physics throughput of the same robot
    standing on the same terrain (`bench_sim`). Results go to a temporary directory, removed after.

    Args:
        scenario: the scenario file (a relative path is resolved as `load_scenario` does).
        controller: controller registry name.
        trials: trials per band (seed 0).
        workers: local worker processes and rollout threads (None: all cores).
        ray: also play the sweep on a local Ray.

    Returns:
        The batched physics throughput and one row per executor played; with `ray` also Ray's overhead per trial.

    Raises:
        ScenarioError, UnknownNameError: a bad scenario or controller.
    """
    sc = load_scenario(scenario)
    arm = get_controller(controller).arm_mode
    kind = sc.trial(sc.bands[0], 0, 0).terrain.kind
    physics = bench_sim(sc.robot, arm, terrain=kind, nthread=workers, repeats=3, reference=False)
    rows = []
    for name in ["local"] + (["ray"] if ray else []):
        with tempfile.TemporaryDirectory() as tmp:
            cfg = ArenaConfig(controllers=(controller,), scenario=Path(scenario), trials=trials,
                              out_dir=Path(tmp) / name, executor=name, workers=workers, progress=False)
            t0 = time.perf_counter()
            result = run_arena(cfg)
            wall = time.perf_counter() - t0
        rows.append(SweepExecutorRow(executor=name, wall_s=wall, sweep_steps_per_s=result.physics_steps / wall,
                                     ratio_to_batched_physics=result.physics_steps / wall
                                     / physics.batched_steps_per_s))
    return SweepBenchResult(scenario=sc.name, controller=controller, terrain=kind, trials=trials * len(sc.bands),
                            batched_physics_steps_per_s=physics.batched_steps_per_s, machine=machine_description(),
                            load_1min=load_1min(), executors=tuple(rows))
