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

__all__ = ["probe_policy"]


def probe_policy(policy_path: str | Path, env: EnvConfig, *, steps: int = 500, settle: int = 100
                 ) -> list[dict[str, float]]:
    """Run the policy's mean action in `env` (observation noise off) for `steps` policy steps.

    Args:
        policy_path: the exported policy.
        env: the env it was trained in (its robot, arm mode, scenario and randomisation).
        steps: policy steps.
        settle: steps before the velocities are averaged (ramp and start transient).

    Returns:
        One row per distinct commanded (vx, vy, yaw rate): the command, the mean body-frame forward and lateral
        velocity and yaw rate after `settle`, and the falls per environment-second.
    """
    policy = NumpyPolicy(load_policy(policy_path))
    cfg = dataclasses.replace(env, noise=ObsNoise(dof_pos=0.0, dof_vel=0.0, ang_vel=0.0, gravity=0.0),
                              teacher_arm_mode=None)
    e = BatchedEnv(cfg)
    obs, priv, _ = e.reset()
    cmds, vel, falls = [], [], np.zeros(e.num_envs)
    try:
        for k in range(steps):
            z = policy.extrinsics(priv) if policy.uses_extrinsics else None
            r = e.step(policy(obs, z))
            obs, priv = r.obs, r.privileged
            falls += r.terminated
            if k >= settle:
                cmds.append(e._command_target.copy())
                qvel = e.state[:, 1 + e.nq:1 + e.nq + 6]
                vel.append(np.c_[priv[:, 3:5], qvel[:, 5]])
    finally:
        e.close()
    cmds_a, vel_a = np.concatenate(cmds), np.concatenate(vel)
    rows = []
    for c in np.unique(cmds_a, axis=0):
        m = np.all(cmds_a == c, axis=1)
        v = vel_a[m].mean(axis=0)
        rows.append({"vx_cmd": float(c[0]), "vy_cmd": float(c[1]), "yaw_rate_cmd": float(c[2]), "vx": float(v[0]),
                     "vy": float(v[1]), "yaw_rate": float(v[2]),
                     "falls_per_env_s": float(falls.sum() / (e.num_envs * steps * cfg.policy_dt))})
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
