"""Warm start: an rsl-rl actor initialised from a previous stage's exported policy (torch).

Used by the baselines that transfer weights instead of imitating: the fine-tuned pi2 and the PPO curriculum of the
paper's Table III. The new actor may observe and command more joints than the old one (the arm): its first layer
takes the old weights on the compatible observation entries (`compatible_indices`) and zeros on the new ones, hidden
layers are copied, and its last layer takes the old rows on the compatible actions (`mask`) and zeros elsewhere, so
at the start the new actor outputs exactly the old policy's actions on the old joints and zero (the nominal pose) on
the new ones. The observation normaliser takes the old statistics on the compatible entries; its sample count is set
to `count` so that PPO's updates move the statistics gradually rather than replace them at the first update.
"""

from __future__ import annotations

import numpy as np

from wbc.errors import NetworkMismatchError
from wbc.learned.policy.observations import ObsLayout, compatible_indices
from wbc.learned.policy.policy_file import PolicyFile
from wbc.optional import require

torch = require("torch")

__all__ = ["warm_start_actor"]


def _set(param, value) -> None:
    param.data.copy_(torch.as_tensor(np.asarray(value), dtype=param.dtype))


def warm_start_actor(actor, policy: PolicyFile, mask: list[int] | None = None, count: int = 10_000) -> None:
    """Initialise `actor` (an `MLPModel` or `ExtrinsicsActor`) from `policy`, in place.

    Args:
        actor: the new actor; same hidden sizes as the policy, at least its joints, extrinsics iff the policy's.
        policy: the previous stage's export.
        mask: new actor's action index of each old action (default: the first ones).
        count: sample count given to the normaliser's statistics.

    Raises:
        NetworkMismatchError: the two networks cannot be matched (hidden sizes, extrinsics, encoder sizes).
    """
    old_layers = policy.layers("policy")
    new_linear = [m for m in actor.mlp if isinstance(m, torch.nn.Linear)]
    old_hidden = [w.shape[0] for w, _ in old_layers[:-1]]
    new_hidden = [m.out_features for m in new_linear[:-1]]
    if old_hidden != new_hidden:
        raise NetworkMismatchError(f"warm start needs the same hidden sizes: the policy has {old_hidden}, the new "
                                   f"actor {new_hidden}; set TrainConfig.actor_hidden_dims to {tuple(old_hidden)}")
    has_z = hasattr(actor, "encoder")
    if has_z != (policy.meta.get("extrinsics") is not None):
        raise NetworkMismatchError(f"warm start needs both networks with extrinsics or both without: the policy "
                                   f"{'has' if not has_z else 'has none'}, the new actor "
                                   f"{'has' if has_z else 'has none'}; set TrainConfig.extrinsics_dim to match")
    n_new = new_linear[-1].out_features
    old_layout, new_layout = ObsLayout(policy.num_actions), ObsLayout(n_new)
    idx = compatible_indices(new_layout, old_layout)
    mask = list(range(policy.num_actions)) if mask is None else list(mask)
    a = policy.arrays
    with torch.no_grad():
        w0, b0 = old_layers[0]
        w = np.zeros((new_linear[0].out_features, new_linear[0].in_features))
        w[:, idx] = w0[:, :old_layout.size]
        if has_z:
            w[:, new_layout.size:] = w0[:, old_layout.size:]
        _set(new_linear[0].weight, w)
        _set(new_linear[0].bias, b0)
        for lin, (wk, bk) in zip(new_linear[1:-1], old_layers[1:-1], strict=True):
            _set(lin.weight, wk)
            _set(lin.bias, bk)
        wl, bl = old_layers[-1]
        w = np.zeros((n_new, wl.shape[1]))
        b = np.zeros(n_new)
        w[mask], b[mask] = wl, bl
        _set(new_linear[-1].weight, w)
        _set(new_linear[-1].bias, b)
        if has_z:
            enc_new = [m for m in actor.encoder if isinstance(m, torch.nn.Linear)]
            enc_old = policy.layers("encoder")
            if [tuple(m.weight.shape) for m in enc_new] != [tuple(wk.shape) for wk, _ in enc_old]:
                raise NetworkMismatchError("warm start needs the same extrinsics encoder: the policy's layers are "
                                           f"{[tuple(wk.shape) for wk, _ in enc_old]}, the new actor's "
                                           f"{[tuple(m.weight.shape) for m in enc_new]}; set "
                                           "TrainConfig.encoder_dims and extrinsics_dim to the policy's")
            for lin, (wk, bk) in zip(enc_new, enc_old, strict=True):
                _set(lin.weight, wk)
                _set(lin.bias, bk)
        norm = actor.obs_normalizer
        if not isinstance(norm, torch.nn.Identity):
            mean = norm._mean.detach().cpu().numpy().reshape(-1).astype(np.float64)
            std = norm._std.detach().cpu().numpy().reshape(-1).astype(np.float64)
            # the old divisor (std + eps_old) on the old entries, whatever the new eps
            shift = float(policy.meta["normalizer_eps"]) - float(norm.eps)
            mean[idx], std[idx] = a["obs_mean"], a["obs_std"] + shift
            if has_z:
                mean[new_layout.size:] = a["privileged_mean"]
                std[new_layout.size:] = a["privileged_std"] + shift
            _set(norm._mean, mean[None])
            _set(norm._std, std[None])
            _set(norm._var, std[None] ** 2)
            norm.count.fill_(int(count))
