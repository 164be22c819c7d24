"""``wbc bench sweep``: throughput of a whole arena sweep (runner, executor, results store) against raw physics."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from wbc.arena.compare import ArenaConfig, run_arena
from wbc.control.registry import get_controller
from wbc.scenario.scenario import load_scenario
from wbc.tools.bench.references import machine_description
from wbc.tools.bench.sim import bench_sim

__all__ = ["bench_sweep"]


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
    standing on the same terrain (`bench_sim`). Results go to a temporary directory, removed after.

    Args:
        scenario: the scenario file (a relative path is resolved as `load_scenario` does).
        controller: controller registry name.
        trials: trials per band (seed 0).
        workers: local worker processes and rollout threads (None: all cores).
        ray: also play the sweep on a local Ray.

    Returns:
        ``batched_physics_steps_per_s`` and, per executor, ``<executor>_wall_s`` [s], ``<executor>_sweep_steps_per_s``
        and ``<executor>_ratio_to_batched_physics``; with `ray` also ``ray_overhead_per_trial_s`` [s].

    Raises:
        ScenarioError, UnknownNameError: a bad scenario or controller.
    """
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
