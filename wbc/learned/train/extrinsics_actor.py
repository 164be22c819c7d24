"""`ExtrinsicsActor`: the rsl-rl actor of the paper's policies, with the RMA extrinsics encoder inside (torch).

The actor observes the policy observation and the privileged observation (groups ``policy`` and ``privileged``, in
that order); the privileged part goes through an encoder MLP to the extrinsics z (RMA phase 1: encoder and policy
are trained together by PPO), and the policy MLP sees [normalised policy observation, z]. Deployment replaces the
encoder by the RMA adaptation module, which estimates z from the proprioceptive history.
"""

from __future__ import annotations

from wbc.errors import ConfigError
from wbc.optional import require

torch = require("torch")
_models = require("rsl_rl.models")
_modules = require("rsl_rl.modules")

__all__ = ["ExtrinsicsActor"]


class ExtrinsicsActor(_models.MLPModel):
    """An `rsl_rl.models.MLPModel` whose last observation group is encoded into z before the MLP.

    Args:
        obs: observation TensorDict (for the sizes).
        obs_groups: observation sets -> groups.
        obs_set: this model's set (``actor``).
        output_dim: actions.
        extrinsics_dim: size of z.
        encoder_dims: hidden sizes of the encoder.
        privileged_group: the group that is encoded; it must be the set's last group.
        **kwargs: `MLPModel` arguments (hidden_dims, activation, obs_normalization, distribution_cfg).

    Raises:
        ConfigError: `privileged_group` is not the set's last group.
    """

    def __init__(self, obs, obs_groups, obs_set, output_dim, *, extrinsics_dim: int = 8,
                 encoder_dims: tuple[int, ...] | list[int] = (64, 32), privileged_group: str = "privileged",
                 **kwargs) -> None:
        groups = obs_groups[obs_set]
        if not groups or groups[-1] != privileged_group:
            raise ConfigError(f"ExtrinsicsActor: the last observation group of {obs_set!r} must be "
                              f"{privileged_group!r}, got {groups}; list it last in obs_groups[{obs_set!r}] "
                              "(as train.rsl_rl_config does)")
        self._priv_dim = int(obs[privileged_group].shape[-1])
        self._z_dim = int(extrinsics_dim)
        super().__init__(obs, obs_groups, obs_set, output_dim, **kwargs)
        self.encoder = _modules.MLP(self._priv_dim, self._z_dim, list(encoder_dims), kwargs.get("activation", "elu"))
        self.encoder_dims = tuple(encoder_dims)

    def get_latent(self, obs, masks=None, hidden_state=None):
        """[normalised policy observation, z]."""
        x = torch.cat([obs[g] for g in self.obs_groups], dim=-1)
        x = self.obs_normalizer(x)
        return torch.cat([x[..., : -self._priv_dim], self.encoder(x[..., -self._priv_dim:])], dim=-1)

    def _get_latent_dim(self) -> int:
        return self.obs_dim - self._priv_dim + self._z_dim
