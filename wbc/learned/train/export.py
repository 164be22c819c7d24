"""Export a trained rsl-rl actor (torch) to the torch-free `PolicyFile` format.

Reads the actor's observation normaliser and the linear layers of its MLP (and of its extrinsics encoder), and takes
the meaning of the numbers (observation layout, scales, joint defaults, gains) from the env configuration the actor
was trained in. The decoupled baseline's arm actor commands only some joints: its export is a part (``joints``) that
`decoupled_policy` embeds, beside the frozen leg policy, in a composite file (`wbc.learned.policy.composite_policy`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wbc.errors import NetworkMismatchError
from wbc.learned.env.env_config import EnvConfig
from wbc.learned.policy.composite_policy import ROBOT_KEYS, CompositePolicyFile, PolicyPart, compose
from wbc.learned.policy.observations import PRIVILEGED_PARTS, ObsLayout
from wbc.learned.policy.policy_file import ACTIVATIONS, PolicyFile
from wbc.learned.train.preflight import env_meta
from wbc.optional import require
from wbc.robots.registry import get_robot

torch = require("torch")

__all__ = ["decoupled_policy", "env_meta", "policy_file_from_actor"]


def _linear_layers(mlp: Any) -> list[tuple[np.ndarray, np.ndarray]]:
    return [(m.weight.detach().cpu().double().numpy(), m.bias.detach().cpu().double().numpy())
            for m in mlp if isinstance(m, torch.nn.Linear)]


def _activation_name(mlp: Any) -> str:
    names = {torch.nn.ELU: "elu", torch.nn.ReLU: "relu", torch.nn.Tanh: "tanh"}
    found = {names.get(type(m), type(m).__name__) for m in mlp if not isinstance(m, torch.nn.Linear)}
    if len(found) != 1 or next(iter(found)) not in ACTIVATIONS:
        raise NetworkMismatchError(f"cannot export activations {sorted(found)}; the policy file supports one of "
                                   f"{', '.join(ACTIVATIONS)} throughout: set TrainConfig.activation to one")
    return next(iter(found))


def policy_file_from_actor(actor: Any, env: EnvConfig, *, task: str, stage: int,
                           extra: dict[str, Any] | None = None, joints: tuple[int, ...] | None = None) -> PolicyFile:
    """The `PolicyFile` of an rsl-rl `MLPModel` (or `ExtrinsicsActor`) trained in an env configured by `env`.

    Args:
        actor: the actor (its distribution's deterministic output must be the MLP output: Gaussian).
        env: the env configuration it was trained with.
        task: ``push`` or ``turn``.
        stage: 1, 2 or 3.
        extra: more metadata (baseline, iterations, wall time, git revision ...), stored under ``training``.
        joints: the robot joints the actor's outputs drive, in order (default: all); with a subset, the file is a
            part of a composite (its default pose and gains are those joints').

    Raises:
        NetworkMismatchError: the actor's outputs do not match `joints`, or its layers or activations cannot be
            exported.
    """
    desc = get_robot(env.robot, env.arm_mode)
    layout = ObsLayout(desc.num_joints)
    norm = actor.obs_normalizer
    d = actor.obs_dim
    if isinstance(norm, torch.nn.Identity):
        mean, std, eps = np.zeros(d), np.ones(d), 0.0
    else:
        mean = norm._mean.detach().cpu().double().numpy().reshape(-1)
        std = norm._std.detach().cpu().double().numpy().reshape(-1)
        eps = float(norm.eps)
    arrays: dict[str, np.ndarray] = {}
    n_obs = layout.size
    arrays["obs_mean"], arrays["obs_std"] = mean[:n_obs], std[:n_obs]
    extrinsics = None
    if hasattr(actor, "encoder"):
        arrays["privileged_mean"], arrays["privileged_std"] = mean[n_obs:], std[n_obs:]
        for i, (w, b) in enumerate(_linear_layers(actor.encoder)):
            arrays[f"encoder/{i}/weight"], arrays[f"encoder/{i}/bias"] = w, b
        extrinsics = {"dim": int(actor._z_dim), "hidden_dims": list(actor.encoder_dims),
                      "privileged_parts": [[n, s] for n, s in PRIVILEGED_PARTS]}
    elif d != n_obs:
        raise NetworkMismatchError(f"the actor observes {d} values but the policy layout has {n_obs}: export "
                                   "supports the policy observation alone (obs group 'policy'), or with extrinsics "
                                   "through ExtrinsicsActor (TrainConfig.extrinsics_dim > 0)")
    layers = _linear_layers(actor.mlp)
    for i, (w, b) in enumerate(layers):
        arrays[f"policy/{i}/weight"], arrays[f"policy/{i}/bias"] = w, b
    idx = np.arange(desc.num_joints) if joints is None else np.asarray(joints, dtype=int)
    if layers[-1][0].shape[0] != idx.size:
        raise NetworkMismatchError(f"the actor has {layers[-1][0].shape[0]} outputs for joints {idx.tolist()}; "
                                   "pass the joints it drives (joints=...), one per output")
    meta = {
        **env_meta(env, idx), "task": task, "stage": int(stage), "num_actions": int(idx.size),
        "obs_layout": layout.as_list(),
        "activation": _activation_name(actor.mlp), "hidden_dims": [int(w.shape[0]) for w, _ in layers[:-1]],
        "normalizer_eps": eps, "extrinsics": extrinsics, "training": extra or {},
    }
    return PolicyFile(meta=meta, arrays=arrays)


def decoupled_policy(actor: Any, legs: PolicyFile, env: EnvConfig, *, task: str, stage: int,
                     extra: dict[str, Any] | None = None) -> CompositePolicyFile:
    """The decoupled baseline's composite: the frozen `legs` policy on the first joints, `actor` on the others.

    Args:
        actor: the arm actor, trained in the actuated-arm env `env` (its outputs: the joints after the legs').
        legs: the frozen leg policy (pi2), embedded whole (its extrinsics encoder and adaptation module included).
        env: the env configuration the actor was trained with.
        task: ``push`` or ``turn``.
        stage: 3.
        extra: training metadata of the composite (baseline, iterations ...), stored under ``training``.
    """
    desc = get_robot(env.robot, env.arm_mode)
    n, n_legs = desc.num_joints, legs.num_actions
    arm = policy_file_from_actor(actor, env, task=task, stage=stage, joints=tuple(range(n_legs, n)))
    kp, kd = env.gains(n)
    robot = {**{k: arm.meta[k] for k in ROBOT_KEYS}, "num_actions": n, "default_q": desc.nominal_q.tolist(),
             "kp": kp.tolist(), "kd": kd.tolist()}
    parts = [PolicyPart(name="legs", joints=tuple(range(n_legs)), policy=legs),
             PolicyPart(name="arm", joints=tuple(range(n_legs, n)), policy=arm)]
    return compose(parts, training=extra, **robot)
