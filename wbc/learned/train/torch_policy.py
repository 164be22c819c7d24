"""`TorchPolicy`: a `PolicyFile` rebuilt as a frozen torch module, the teacher of the BC term.

Teachers are loaded from the same torch-free files the controllers run, so a stage trains against exactly the
policy that was shipped or exported from the previous stage (not a checkpoint with optimiser state).
"""

from __future__ import annotations

from wbc.learned.policy.policy_file import PolicyFile
from wbc.optional import require

torch = require("torch")

__all__ = ["TorchPolicy", "sequential"]

_ACT = {"elu": torch.nn.ELU, "relu": torch.nn.ReLU, "tanh": torch.nn.Tanh, "identity": torch.nn.Identity}


def sequential(layers, activation: str):
    """A frozen-weight ``torch.nn.Sequential`` of the (weight, bias) `layers`, `activation` between them (float32)."""
    mods = []
    for i, (w, b) in enumerate(layers):
        lin = torch.nn.Linear(w.shape[1], w.shape[0])
        lin.weight.data = torch.as_tensor(w, dtype=torch.float32).clone()
        lin.bias.data = torch.as_tensor(b, dtype=torch.float32).clone()
        mods.append(lin)
        if i < len(layers) - 1:
            mods.append(_ACT[activation]())
    return torch.nn.Sequential(*mods)


class TorchPolicy(torch.nn.Module):
    """Deterministic actions of a `PolicyFile`, in torch, with no trainable parameters.

    Args:
        policy: the loaded file.
    """

    def __init__(self, policy: PolicyFile) -> None:
        super().__init__()
        meta, a = policy.meta, policy.arrays
        eps = float(meta["normalizer_eps"])
        self.register_buffer("obs_mean", torch.as_tensor(a["obs_mean"], dtype=torch.float32))
        self.register_buffer("obs_div", torch.as_tensor(a["obs_std"], dtype=torch.float32) + eps)
        self.mlp = sequential(policy.layers("policy"), meta["activation"])
        self.uses_extrinsics = meta.get("extrinsics") is not None
        self.reads_history = self.uses_extrinsics and not policy.layers("encoder")
        """z comes from the observation history alone (a distilled student): `forward` takes the window."""
        if self.reads_history:
            self.history = int(meta["adaptation"]["history"])
            self.adaptation = sequential(policy.layers("adaptation"), meta["activation"])
        elif self.uses_extrinsics:
            self.register_buffer("priv_mean", torch.as_tensor(a["privileged_mean"], dtype=torch.float32))
            self.register_buffer("priv_div", torch.as_tensor(a["privileged_std"], dtype=torch.float32) + eps)
            self.encoder = sequential(policy.layers("encoder"), meta["activation"])
        self.requires_grad_(False)
        self.eval()

    def forward(self, obs, privileged=None, history=None):
        """Actions for observations (N, obs_size).

        With extrinsics, the privileged observations (N, P) too or, for a policy that reads its own history, the raw
        window (N, H * obs_size), oldest first.
        """
        x = (obs - self.obs_mean) / self.obs_div
        if self.reads_history:
            n = history.shape[0]
            window = (history.reshape(n, self.history, -1) - self.obs_mean) / self.obs_div
            x = torch.cat([x, self.adaptation(window.reshape(n, -1))], dim=-1)
        elif self.uses_extrinsics:
            z = self.encoder((privileged - self.priv_mean) / self.priv_div)
            x = torch.cat([x, z], dim=-1)
        return self.mlp(x)
