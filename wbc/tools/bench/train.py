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

import dataclasses
import time
from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco import rollout

from wbc.learned.env.env import BatchedEnv
from wbc.learned.env.env_config import EnvConfig
from wbc.tools.bench.batched_rollout import BatchedRollout, check_memory, rollout_bytes
from wbc.tools.bench.references import (
    REFERENCE_STEPS_PER_CONTROL_STEP,
    TRAIN_TARGET,
    load_1min,
    machine_description,
    reference_a1,
    scaled_target,
)

__all__ = ["TrainBenchResult", "TrainReference", "bench_train", "check_train_memory"]

REFERENCE_BATCH, REFERENCE_STEPS = 64, 500
"""The bare-A1 reference's batched rollout: environments, physics steps per rollout."""


@dataclass(frozen=True, kw_only=True)
class TrainReference:
    """The bare-A1 physics limit measured beside the env, and the target (`TRAIN_TARGET`) scaled by it.

    Attributes:
        physics_limit_control_steps_per_s: the bare A1's batched physics rate over
            `REFERENCE_STEPS_PER_CONTROL_STEP` [control steps/s].
        control_steps_ratio_to_reference: the env's control steps per second over that limit.
        scaled_target_control_steps_per_s: 15k control steps/s times this machine's limit over 21.8k
            [control steps/s].
    """

    physics_limit_control_steps_per_s: float
    control_steps_ratio_to_reference: float
    scaled_target_control_steps_per_s: float

    def as_dict(self) -> dict[str, float]:
        """The figures under their keys in `TrainBenchResult.as_dict` (the limit prefixed ``reference_``)."""
        return {"reference_physics_limit_control_steps_per_s": self.physics_limit_control_steps_per_s,
                "control_steps_ratio_to_reference": self.control_steps_ratio_to_reference,
                "scaled_target_control_steps_per_s": self.scaled_target_control_steps_per_s}


@dataclass(frozen=True, kw_only=True)
class TrainBenchResult:
    """What `bench_train` measured: the batched env's throughput, its physics limit and its CPU time.

    Attributes:
        control_steps_per_s: policy steps of all environments per second, best of the repeats [steps/s].
        physics_steps_per_s: the same times `decimation` [steps/s].
        rollout_only_control_steps_per_s: the same `mujoco.rollout` calls with nothing in Python between them: the
            physics limit [control steps/s].
        env_efficiency: `control_steps_per_s` over that limit.
        python_ms_per_step: wall time of the env's Python per policy step (all environments) [ms].
        python_cpu_ms_per_step: CPU time of the env's Python per policy step, best of the repeats [ms].
        physics_cpu_ms_per_step: CPU time of the rollout per policy step, all its threads [ms].
        cpu_bound_control_steps_per_s: the rate with the `threads` cores to itself, from the CPU times
            [control steps/s].
        cpu_bound_physics_only_control_steps_per_s: the same for the physics alone [control steps/s].
        resets_per_step: environments reset (terminated or timed out) per policy step.
        num_envs: environments.
        threads: rollout threads.
        decimation: physics steps per policy step.
        timestep_s: the physics step [s].
        robot: robot registry name.
        arm_mode: the env's arm mode.
        terrain: the env's terrain.
        mujoco: MuJoCo's version.
        machine: `machine_description`.
        load_1min: the machine's 1-minute load average at the end (`load_1min`; nan where the OS has none).
        reference: the bare-A1 reference, or None when it was not measured.
    """

    control_steps_per_s: float
    physics_steps_per_s: float
    rollout_only_control_steps_per_s: float
    env_efficiency: float
    python_ms_per_step: float
    python_cpu_ms_per_step: float
    physics_cpu_ms_per_step: float
    cpu_bound_control_steps_per_s: float
    cpu_bound_physics_only_control_steps_per_s: float
    resets_per_step: float
    num_envs: int
    threads: int
    decimation: int
    timestep_s: float
    robot: str
    arm_mode: str
    terrain: str
    mujoco: str
    machine: str
    load_1min: float = float("nan")
    reference: TrainReference | None = None

    def as_dict(self) -> dict[str, float | int | str]:
        """Plain flat dict (the JSON output of ``wbc bench train``): the reference's keys follow when measured."""
        out: dict[str, float | int | str] = {
            "control_steps_per_s": self.control_steps_per_s,
            "physics_steps_per_s": self.physics_steps_per_s,
            "rollout_only_control_steps_per_s": self.rollout_only_control_steps_per_s,
            "env_efficiency": self.env_efficiency,
            "python_ms_per_step": self.python_ms_per_step,
            "python_cpu_ms_per_step": self.python_cpu_ms_per_step,
            "physics_cpu_ms_per_step": self.physics_cpu_ms_per_step,
            "cpu_bound_control_steps_per_s": self.cpu_bound_control_steps_per_s,
            "cpu_bound_physics_only_control_steps_per_s": self.cpu_bound_physics_only_control_steps_per_s,
            "resets_per_step": self.resets_per_step,
            "num_envs": self.num_envs,
            "threads": self.threads,
            "decimation": self.decimation,
            "timestep_s": self.timestep_s,
            "robot": self.robot,
            "arm_mode": self.arm_mode,
            "terrain": self.terrain,
            "mujoco": self.mujoco,
            "machine": self.machine,
            "load_1min": self.load_1min,
        }
        if self.reference is not None:
            out.update(self.reference.as_dict())
        return out


def bench_train(config: EnvConfig | None = None, *, steps: int = 50, repeats: int = 3,
                action_std: float = 0.5, reference: bool = True) -> TrainBenchResult:
    """Measure the batched env.

    Args:
        config: the env (default: `EnvConfig()`, the push task's pi3 env: a1-wx200, arm actuated, rough ground,
            pushes, 1024 environments, 2 threads).
        steps: policy steps per measurement.
        repeats: measurements; the best is reported.
        action_std: standard deviation of the random actions.
        reference: also measure the bare-A1 reference (64 environments, `nthread` threads), interleaved.

    Returns:
        The env's control steps per second beside the physics limit, its CPU-time figures and the settings; with
        `reference` also the bare-A1 limit and `TRAIN_TARGET` scaled by it (`TrainReference`).

    Raises:
        ConfigError: the environments' buffers, the bench's and the reference's would take more than half the memory
            available (`check_train_memory`; the message names ``--envs``), checked before any is allocated.
    """
    cfg = config if config is not None else EnvConfig()
    ref_model = reference_a1() if reference else None
    check_train_memory(cfg, steps=steps, reference=None if ref_model is None else ref_model[0])
    env = BatchedEnv(cfg)
    rng = np.random.default_rng(0)
    n = cfg.num_envs
    ref = (BatchedRollout(*ref_model, batch=REFERENCE_BATCH, nthread=cfg.nthread, nstep=REFERENCE_STEPS)
           if ref_model is not None else None)
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
    figures = None
    if reference:
        limit = best_ref / REFERENCE_STEPS_PER_CONTROL_STEP
        figures = TrainReference(physics_limit_control_steps_per_s=limit, control_steps_ratio_to_reference=best / limit,
                                 scaled_target_control_steps_per_s=scaled_target(TRAIN_TARGET, limit))
    return TrainBenchResult(
        control_steps_per_s=best,
        physics_steps_per_s=best * cfg.decimation,
        rollout_only_control_steps_per_s=best_raw,
        env_efficiency=best / best_raw,
        python_ms_per_step=1e3 * max(0.0, n / best - n / best_raw),
        python_cpu_ms_per_step=1e3 * cpu_python,
        physics_cpu_ms_per_step=1e3 * cpu_physics,
        cpu_bound_control_steps_per_s=n / (cpu_python + cpu_physics / cfg.nthread),
        cpu_bound_physics_only_control_steps_per_s=n / (cpu_physics / cfg.nthread),
        resets_per_step=resets / (repeats * steps),
        num_envs=n,
        threads=cfg.nthread,
        decimation=cfg.decimation,
        timestep_s=cfg.timestep,
        robot=cfg.robot,
        arm_mode=cfg.arm_mode,
        terrain=cfg.terrain,
        mujoco=mujoco.__version__,
        machine=machine_description(),
        load_1min=load_1min(),
        reference=figures,
    )


def check_train_memory(config: EnvConfig, *, steps: int, reference: mujoco.MjModel | None = None) -> None:
    """Refuse a `config.num_envs` whose buffers in `bench_train` would not fit in memory, before any is allocated.

    The sizes are read from an env of one environment and one model variant (the variants share them), so nothing
    grows with `config.num_envs` here; `wbc.tools.bench.batched_rollout.check_memory` refuses beyond its share of the
    memory available.

    Args:
        config: the env to be benched.
        steps: policy steps per measurement (the bench draws every step's random actions before it times them).
        reference: the bare-A1 reference's model, when it is measured too (its rollout does not grow with the envs).

    Raises:
        ConfigError: the estimate is more than `MEMORY_SHARE` of the memory available; the message names ``--envs``,
            the estimate, the memory available and the most environments that fit.
    """
    probe = BatchedEnv(dataclasses.replace(config, num_envs=1,
                                           domain=dataclasses.replace(config.domain, num_variants=1)))
    dec = config.decimation
    # An over-estimate, in float64 numbers per environment, of what `BatchedEnv` allocates and the bench adds:
    # - the env's buffers: the state, and per physics step of a policy step the controls, the rollout's states, its
    #   sensor data and the motor torques;
    # - the env's small per-environment vectors (commands, actions, IMU, episode sums) and a step's temporaries (push
    #   wrenches, torques, observations, rewards): each a fraction of those buffers, counted as the buffers once more;
    # - the bench's own: every step's random actions of one measurement, and the copies of the state, the controls
    #   and the rollout's states that the physics-only measurement rolls out with.
    # Against the peak resident memory of the push env (a1-wx200, arm actuated), this is about 1.4x what an
    # environment takes at 50 steps, and 1.1x at 500 (where the actions, counted exactly, are most of it).
    buffers = probe.nstate + dec * (probe.ncontrol + probe.nstate + probe.pool.model.nsensordata
                                    + probe.desc.num_joints)
    bench = steps * probe.num_actions + probe.nstate + dec * (probe.ncontrol + probe.nstate)
    each = 8 * (2 * buffers + bench)
    n = config.num_envs
    fixed = 0 if reference is None else rollout_bytes(reference, REFERENCE_BATCH, REFERENCE_STEPS)
    check_memory("--envs", n, n * each + fixed, each=each,
                 what=f"the training env's buffers and the bench's ({n} environments, {steps} steps of random actions)",
                 none_fits="give fewer --steps, or free some memory (no environment fits in what is left)")
