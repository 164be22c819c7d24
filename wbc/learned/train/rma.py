"""RMA phase 2: an adaptation module that estimates the extrinsics z from the proprioceptive history (torch).

Phase 1 (PPO) trains the policy with z = encoder(privileged observation). Phase 2 freezes policy and encoder and fits
an adaptation module phi, z_hat = phi(last H normalised policy observations), by regression on z, on-policy: the
robots are driven by the policy fed with z_hat, so phi learns on the states its own estimates lead to (Kumar et al.
2021). The result is added to the policy file; deployment then needs nothing privileged.

Deviation from RMA, chosen for a numpy-simple deployment: phi is an MLP over the flattened window (default 25 steps,
0.5 s at 50 Hz, the RMA window's duration) instead of RMA's 1-D CNN.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import numpy as np

from wbc.errors import NetworkMismatchError
from wbc.learned.env.env import BatchedEnv
from wbc.learned.env.env_config import EnvConfig
from wbc.learned.policy.obs_history import ObsHistory
from wbc.learned.policy.policy_file import PolicyFile
from wbc.learned.train.adaptation_config import AdaptationConfig
from wbc.learned.train.torch_policy import TorchPolicy
from wbc.optional import require

torch = require("torch")
_modules = require("rsl_rl.modules")

__all__ = ["train_adaptation"]


def train_adaptation(policy: PolicyFile, env_config: EnvConfig, config: AdaptationConfig,
                     log: Any = print) -> tuple[PolicyFile, dict[str, Any]]:
    """Fit the adaptation module of a phase-1 policy.

    Args:
        policy: a policy file with extrinsics (encoder) and no adaptation module.
        env_config: the env it was trained in (the teacher observation group is not needed and is dropped).
        config: phase-2 settings.
        log: called with one line per iteration.

    Returns:
        The policy file with the adaptation module, and a summary (losses per iteration, wall time).

    Raises:
        NetworkMismatchError: the policy does not observe the extrinsics.
    """
    if policy.meta.get("extrinsics") is None:
        raise NetworkMismatchError("RMA phase 2 needs a policy that observes the extrinsics z, and this one has no "
                                   "encoder: train phase 1 with TrainConfig.extrinsics_dim > 0")
    torch.manual_seed(config.seed)
    net = TorchPolicy(policy)
    env = BatchedEnv(replace(env_config, teacher_arm_mode=None))
    obs_size = env.layout.size
    z_dim = int(policy.meta["extrinsics"]["dim"])
    act = policy.meta["activation"]
    phi = _modules.MLP(config.history * obs_size, z_dim, list(config.hidden_dims), act)
    opt = torch.optim.Adam(phi.parameters(), lr=config.learning_rate)
    hist = ObsHistory(env.num_envs, config.history, obs_size)
    mean, div = net.obs_mean.numpy(), net.obs_div.numpy()
    obs, priv, _ = env.reset()
    hist.fill(np.arange(env.num_envs), (obs - mean) / div)
    losses, t0 = [], time.perf_counter()
    try:
        for it in range(config.iterations):
            xs, zs = [], []
            for _ in range(config.steps_per_iteration):
                h = torch.from_numpy(hist.flat().copy())
                p = torch.from_numpy(priv)
                with torch.no_grad():
                    z = net.encoder((p - net.priv_mean) / net.priv_div)
                    z_hat = phi(h)
                    o = (torch.from_numpy(obs) - net.obs_mean) / net.obs_div
                    action = net.mlp(torch.cat([o, z_hat], dim=-1)).numpy()
                xs.append(h)
                zs.append(z)
                r = env.step(action)
                obs, priv = r.obs, r.privileged
                n_obs = (obs - mean) / div
                hist.push(n_obs)
                done = np.flatnonzero(r.terminated | r.time_out)
                if done.size:
                    hist.fill(done, n_obs[done])
            x, y = torch.cat(xs), torch.cat(zs)
            total, count = 0.0, 0
            for _ in range(config.epochs):
                perm = torch.randperm(x.shape[0])
                for start in range(0, x.shape[0], config.minibatch):
                    idx = perm[start:start + config.minibatch]
                    loss = (phi(x[idx]) - y[idx]).pow(2).mean()
                    opt.zero_grad()
                    loss.backward()
                    opt.step()
                    total += loss.item() * idx.numel()
                    count += idx.numel()
            losses.append(total / count)
            log(f"RMA phase 2 iteration {it + 1}/{config.iterations}: z regression loss {losses[-1]:.5f}")
    finally:
        env.close()
    arrays = dict(policy.arrays)
    for i, m in enumerate(mod for mod in phi if isinstance(mod, torch.nn.Linear)):
        arrays[f"adaptation/{i}/weight"] = m.weight.detach().double().numpy()
        arrays[f"adaptation/{i}/bias"] = m.bias.detach().double().numpy()
    meta = dict(policy.meta)
    meta["adaptation"] = {"history": config.history, "hidden_dims": list(config.hidden_dims),
                          "iterations": config.iterations, "final_loss": losses[-1] if losses else None}
    summary = {"losses": losses, "wall_s": time.perf_counter() - t0}
    return PolicyFile(meta=meta, arrays=arrays), summary
