"""``wbc bench train``: training-env throughput, policy steps per second over all environments, random actions.

Next to it, the same call of `mujoco.rollout` on the same models and states with nothing in Python between calls:
the physics limit of this machine, so that the env's own overhead (observations, rewards, pushes, resets) reads as
a fraction. On a machine shared with other work, wall-clock figures swing by 2x from one minute to the next; the CPU
time this process used (``time.process_time``, all its threads) varies less, so the figures also include the
throughput the same work would reach with the `nthread` cores to itself: ``cpu_bound_control_steps_per_s``, from the
env's single-threaded Python CPU time per step plus its rollout CPU time spread over the rollout's threads.

The target (`TRAIN_TARGET`: 15k control steps/s) is stated against a physics limit of 21.8k control steps/s: the bare
A1 URDF batched over 64 environments by `mujoco.rollout` (`reference_a1`), ten 2 ms physics steps per 50 Hz control
step. The same reference is measured in the same repeats, interleaved with the env, so the figures include the target
scaled to this machine's speed (``scaled_target_control_steps_per_s``).
"""

from __future__ import annotations

import time

import mujoco
import numpy as np
from mujoco import rollout

from wbc.learned.env.env import BatchedEnv
from wbc.learned.env.env_config import EnvConfig
from wbc.tools.bench.batched_rollout import BatchedRollout
from wbc.tools.bench.references import (
    REFERENCE_STEPS_PER_CONTROL_STEP,
    TRAIN_TARGET,
    machine_description,
    reference_a1,
    scaled_target,
)

__all__ = ["bench_train"]


def bench_train(config: EnvConfig | None = None, *, steps: int = 50, repeats: int = 3,
                action_std: float = 0.5, reference: bool = True) -> dict[str, float | int | str]:
    """Measure the batched env.

    Args:
        config: the env (default: `EnvConfig()`, the push task's pi3 env: a1-wx200, arm actuated, rough ground,
            pushes, 1024 environments, 2 threads).
        steps: policy steps per measurement.
        repeats: measurements; the best is reported.
        action_std: standard deviation of the random actions.
        reference: also measure the bare-A1 reference (64 environments, `nthread` threads), interleaved.

    Returns:
        ``control_steps_per_s`` (policy steps of all environments per second), ``physics_steps_per_s`` (the same
        figure times `decimation`), ``rollout_only_control_steps_per_s`` (the physics limit), ``env_efficiency``
        (their ratio), ``python_ms_per_step``, the CPU-time figures (``python_cpu_ms_per_step``,
        ``physics_cpu_ms_per_step``, ``cpu_bound_control_steps_per_s``,
        ``cpu_bound_physics_only_control_steps_per_s``) and the settings; with `reference` also
        ``reference_physics_limit_control_steps_per_s`` (the bare A1's batched physics steps/s over 10),
        ``control_steps_ratio_to_reference`` and ``scaled_target_control_steps_per_s`` (`TRAIN_TARGET` scaled:
        15k times this machine's reference over 21.8k).
    """
    cfg = config if config is not None else EnvConfig()
    env = BatchedEnv(cfg)
    rng = np.random.default_rng(0)
    n = cfg.num_envs
    ref = BatchedRollout(*reference_a1(), batch=64, nthread=cfg.nthread, nstep=500) if reference else None
    best_ref = 0.0
    try:
        for _ in range(5):
            env.step(action_std * rng.standard_normal((n, env.num_actions)))
        best, resets, cpu_python, cpu_physics = 0.0, 0, np.inf, np.inf
        for _ in range(repeats):
            if ref is not None:
                best_ref = max(best_ref, ref.rate())
            actions = [action_std * rng.standard_normal((n, env.num_actions)) for _ in range(steps)]
            t0, c0, p0 = time.perf_counter(), time.process_time(), env.physics_cpu_s
            for a in actions:
                r = env.step(a)
                resets += int(r.terminated.sum() + r.time_out.sum())
            best = max(best, n * steps / (time.perf_counter() - t0))
            physics = env.physics_cpu_s - p0
            cpu_physics = min(cpu_physics, physics / steps)
            cpu_python = min(cpu_python, (time.process_time() - c0 - physics) / steps)
        state, control = env.state.copy(), env._control.copy()
        out = np.empty_like(env._out)
        best_raw, cpu_raw = 0.0, np.inf
        for _ in range(repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            for _ in range(steps):
                rollout.rollout(env._models, env._datas, state, control, control_spec=env.control_spec,
                                nstep=cfg.decimation, state=out, persistent_pool=True, skip_checks=True)
            best_raw = max(best_raw, n * steps / (time.perf_counter() - t0))
            cpu_raw = min(cpu_raw, (time.process_time() - c0) / steps)
    finally:
        env.close()
    figures: dict[str, float] = {}
    if reference:
        limit = best_ref / REFERENCE_STEPS_PER_CONTROL_STEP
        figures = {"reference_physics_limit_control_steps_per_s": limit,
                   "control_steps_ratio_to_reference": best / limit,
                   "scaled_target_control_steps_per_s": scaled_target(TRAIN_TARGET, limit)}
    return {
        "control_steps_per_s": best,
        "physics_steps_per_s": best * cfg.decimation,
        "rollout_only_control_steps_per_s": best_raw,
        "env_efficiency": best / best_raw,
        "python_ms_per_step": 1e3 * max(0.0, n / best - n / best_raw),
        "python_cpu_ms_per_step": 1e3 * cpu_python,
        "physics_cpu_ms_per_step": 1e3 * cpu_physics,
        "cpu_bound_control_steps_per_s": n / (cpu_python + cpu_physics / cfg.nthread),
        "cpu_bound_physics_only_control_steps_per_s": n / (cpu_physics / cfg.nthread),
        "resets_per_step": resets / (repeats * steps),
        "num_envs": n,
        "threads": cfg.nthread,
        "decimation": cfg.decimation,
        "timestep_s": cfg.timestep,
        "robot": cfg.robot,
        "arm_mode": cfg.arm_mode,
        "terrain": cfg.terrain,
        "mujoco": mujoco.__version__,
        "machine": machine_description(),
        **figures,
    }
