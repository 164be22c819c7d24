"""Probe an exported policy in the training env: what it does, per command, with noise-free deterministic actions.

Training logs average stochastic episodes that end at staggered times, a noisy signal; this answers plainly whether
the policy's mean action walks at the commanded speed or stands. Extrinsics come from the encoder on the true
privileged observation (the policy as trained, before RMA phase 2). ``python -m wbc.tools.probe POLICY --task push
--stage 1`` prints one line per command.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from wbc.learned.env.env import BatchedEnv
from wbc.learned.env.env_config import EnvConfig, ObsNoise
from wbc.learned.policy.numpy_policy import NumpyPolicy
from wbc.learned.policy.policy_file import load_policy
from wbc.learned.train.stages import stage_config

__all__ = ["fall_rates", "probe_policy"]


def fall_rates(commands: np.ndarray, terminated: np.ndarray, dt: float) -> dict[tuple[float, float, float], float]:
    """Falls per environment-second under each command: an env's steps and falls count for the command it had.

    Args:
        commands: (T, N, 3) each env's commanded (vx, vy, yaw rate) during each policy step.
        terminated: (T, N) whether the env fell (terminated) at that step, under that step's command.
        dt: policy step [s].

    Returns:
        ``{(vx, vy, yaw_rate): falls / (env-steps under it * dt)}`` for each command held at some step.
    """
    flat = np.asarray(commands, dtype=float).reshape(-1, 3)
    fell = np.asarray(terminated, dtype=bool).reshape(-1)
    rates = {}
    for c in np.unique(flat, axis=0):
        held = np.all(flat == c, axis=1)
        rates[tuple(float(x) for x in c)] = float(fell[held].sum() / (held.sum() * dt))
    return rates


def probe_policy(policy_path: str | Path, env: EnvConfig, *, steps: int = 500, settle: int = 100
                 ) -> list[dict[str, float]]:
    """Run the policy's mean action in `env` (observation noise off) for `steps` policy steps.

    Args:
        policy_path: the exported policy.
        env: the env it was trained in (its robot, arm mode, scenario and randomisation).
        steps: policy steps.
        settle: steps before the velocities are averaged (ramp and start transient).

    Returns:
        One row per distinct commanded (vx, vy, yaw rate) held after `settle`: the command, the mean body-frame
        forward and lateral velocity and yaw rate after `settle` of the envs that held it through a step (an env reset
        in a step, by a fall or its time limit, is left out of that step's), and the falls per environment-second
        under that command
        over all `steps` (`fall_rates`: a fall counts for the command its env had when it fell).
    """
    policy = NumpyPolicy(load_policy(policy_path))
    cfg = dataclasses.replace(env, noise=ObsNoise(dof_pos=0.0, dof_vel=0.0, ang_vel=0.0, gravity=0.0),
                              teacher_arm_mode=None)
    e = BatchedEnv(cfg)
    obs, priv, _ = e.reset()
    cmds, vel, held, fell = [], [], [], []
    try:
        for k in range(steps):
            z = policy.extrinsics(priv) if policy.uses_extrinsics else None
            held.append(e._command_target.copy())  # an env that falls is reset, with its next command, in the step
            r = e.step(policy(obs, z))
            obs, priv = r.obs, r.privileged
            fell.append(np.asarray(r.terminated, dtype=bool).copy())
            if k >= settle:
                # under the command the env held in this step; an env reset in it (a fall or its time limit) has a
                # new command and a fresh state, which are no measure of the old one's
                kept = ~(np.asarray(r.terminated, dtype=bool) | np.asarray(r.time_out, dtype=bool))
                cmds.append(held[-1][kept])
                qvel = e.state[:, 1 + e.nq:1 + e.nq + 6]
                vel.append(np.c_[priv[:, 3:5], qvel[:, 5]][kept])
    finally:
        e.close()
    cmds_a, vel_a = np.concatenate(cmds), np.concatenate(vel)
    falls = fall_rates(np.stack(held), np.stack(fell), cfg.policy_dt)
    rows = []
    for c in np.unique(cmds_a, axis=0):
        m = np.all(cmds_a == c, axis=1)
        v = vel_a[m].mean(axis=0)
        rows.append({"vx_cmd": float(c[0]), "vy_cmd": float(c[1]), "yaw_rate_cmd": float(c[2]), "vx": float(v[0]),
                     "vy": float(v[1]), "yaw_rate": float(v[2]),
                     "falls_per_env_s": falls[tuple(float(x) for x in c)]})
    return rows


def main(argv: list[str] | None = None) -> int:
    """Command line."""
    p = argparse.ArgumentParser(prog="python -m wbc.tools.probe", description=__doc__.splitlines()[0])
    p.add_argument("policy", help="policy file (.npz/.json stem)")
    p.add_argument("--task", default="push")
    p.add_argument("--stage", type=int, default=1)
    p.add_argument("--envs", type=int, default=64)
    p.add_argument("--steps", type=int, default=500)
    args = p.parse_args(argv)
    # the scenario's commands, also for pi1 (trained on a range of commands: `WALKING_PRIOR_COMMANDS`)
    env = dataclasses.replace(stage_config(args.task, args.stage).env, num_envs=args.envs, command_ranges=None)
    for row in probe_policy(args.policy, env, steps=args.steps):
        print(f"command vx {row['vx_cmd']:+.2f} vy {row['vy_cmd']:+.2f} yaw {row['yaw_rate_cmd']:+.2f}: "
              f"vx {row['vx']:+.3f} m/s, vy {row['vy']:+.3f} m/s, yaw {row['yaw_rate']:+.3f} rad/s; "
              f"falls {row['falls_per_env_s']:.4f} per env-second")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
