"""`HistoryActor`: a distilled student (`wbc.learned.train.distill`) as an rsl-rl actor, for PPO + BC fine-tuning.

A student with memory reads two things: the policy observation and the window of its last H observations, from
which its adaptation module makes the latent z that the actor reads beside the observation. Our other actors take z
from privileged observations (`ExtrinsicsActor`); this one takes it from the window, as the student does on the robot,
so PPO improves the very networks the arena runs and the export is the student's file format again.

Observation groups (in order): ``policy`` (N, D) and ``history`` (N, H * D), the raw observations of the window,
oldest first, the newest being the current one (`wbc.learned.train.vec_env.RslVecEnv` with a history). Both are
normalised by the student's own normaliser, which stays fixed: the networks were fitted to it, and a normaliser that
drifted with PPO's data would move every input under them. The actor starts as the student, to the float32 rounding
of its weights; its action noise is the run's `TrainConfig.init_std`.
"""

from __future__ import annotations

from typing import Any

from wbc.errors import NetworkMismatchError
from wbc.learned.policy.policy_file import load_policy
from wbc.learned.train.preflight import student_layout
from wbc.learned.train.torch_policy import sequential
from wbc.optional import require

torch = require("torch")
_models = require("rsl_rl.models")
_modules = require("rsl_rl.modules")

__all__ = ["FixedNormaliser", "HistoryActor", "student_layout"]


class FixedNormaliser(torch.nn.Module):
    """``(x - mean) / (std + eps)`` with constant statistics; read by the exporter as our normalisers are."""

    def __init__(self, mean: Any, std: Any, eps: float) -> None:
        super().__init__()
        self.register_buffer("_mean", torch.as_tensor(mean, dtype=torch.float32).reshape(1, -1).clone())
        self.register_buffer("_std", torch.as_tensor(std, dtype=torch.float32).reshape(1, -1).clone())
        self.eps = float(eps)

    def forward(self, x):
        """Normalised `x` (..., D)."""
        return (x - self._mean) / (self._std + self.eps)


class HistoryActor(_models.MLPModel):
    """An `rsl_rl.models.MLPModel` that is a distilled student: [normalised observation, adaptation(window)] -> MLP.

    Args:
        obs: observation TensorDict (for the sizes).
        obs_groups: observation sets -> groups; the set's groups must be the observation and its window, in order.
        obs_set: this model's set (``actor``).
        output_dim: actions (the student's).
        student_path: the student's policy file (.npz/.json pair), whose networks and normaliser the actor starts
            from.
        history_group: the name of the window's group.
        **kwargs: `MLPModel` arguments (the distribution's; hidden sizes and activation come from the student).

    Raises:
        NetworkMismatchError: the student does not read its own history, or its sizes do not match the env's groups
            or `output_dim`.
    """

    def __init__(self, obs, obs_groups, obs_set, output_dim, *, student_path: str, history_group: str = "history",
                 **kwargs) -> None:
        student = load_policy(student_path)
        d, h, z = student_layout(student)
        groups = obs_groups[obs_set]
        if len(groups) != 2 or groups[1] != history_group:
            raise NetworkMismatchError(f"HistoryActor reads [observation, {history_group!r}], got groups {groups}")
        sizes = (int(obs[groups[0]].shape[-1]), int(obs[history_group].shape[-1]))
        if sizes != (d, h * d) or output_dim != student.num_actions:
            raise NetworkMismatchError(
                f"student {student_path} reads {d} observations and a window of {h} x {d}, and drives "
                f"{student.num_actions} joints; the env gives {sizes[0]}, {sizes[1]} and {output_dim} "
                "(give the env the student's history length)")
        self._z_dim, self.history, self._latent_dim = z, h, d + z
        kwargs = {k: v for k, v in kwargs.items() if k not in ("hidden_dims", "activation", "obs_normalization")}
        activation = student.meta["activation"]
        super().__init__(obs, obs_groups, obs_set, output_dim, hidden_dims=list(student.meta["hidden_dims"]),
                         activation=activation, obs_normalization=False, **kwargs)
        self.obs_dim = d  # what the exporter reads: the policy observation's size
        eps = float(student.meta["normalizer_eps"])
        self.obs_normalizer = FixedNormaliser(student.arrays["obs_mean"], student.arrays["obs_std"], eps)
        self.adaptation = sequential(student.layers("adaptation"), activation)  # trainable: nothing freezes it here
        self.adaptation_dims = tuple(int(w.shape[0]) for w, _ in student.layers("adaptation")[:-1])
        self.z_dim = z
        linear = [m for m in self.mlp if isinstance(m, torch.nn.Linear)]
        layers = student.layers("policy")
        if [tuple(m.weight.shape) for m in linear] != [tuple(w.shape) for w, _ in layers]:
            raise NetworkMismatchError(f"student {student_path}: its actor's layers do not match the rebuilt MLP")
        with torch.no_grad():
            for m, (w, b) in zip(linear, layers, strict=True):
                m.weight.copy_(torch.as_tensor(w, dtype=torch.float32))
                m.bias.copy_(torch.as_tensor(b, dtype=torch.float32))

    def get_latent(self, obs, masks=None, hidden_state=None):
        """[normalised observation, z of the normalised window]."""
        x = self.obs_normalizer(obs[self.obs_groups[0]])
        window = obs[self.obs_groups[1]]
        n = window.shape[0]
        w = self.obs_normalizer(window.reshape(n, self.history, -1)).reshape(n, -1)
        return torch.cat([x, self.adaptation(w)], dim=-1)

    def update_normalization(self, obs) -> None:
        """Nothing: the student's normaliser is fixed (see the module docstring)."""

    def _get_latent_dim(self) -> int:
        return self._latent_dim
