"""`NumpyPolicy`: inference of an exported policy (`PolicyFile`) in numpy, no torch.

actions = MLP_policy([normalise(obs), z]) with z = MLP_encoder(normalise(privileged)) when the policy observes the
RMA extrinsics; normalise(x) = (x - mean) / (std + eps), the rsl-rl empirical normaliser's formula. Computed in
float64 from the float32 weights, so it matches torch's float32 forward pass to about 1e-6.

The layers do not call BLAS: OpenBLAS picks its kernel by the CPU (a Haswell and a Sandy Bridge kernel sum a
matrix-vector product in different orders), so the same policy on the same trial gave different last bits on
different machines, and a closed loop grows those into different trajectories. `dense` multiplies elementwise
(exact) and sums each output with numpy's pairwise reduction, whose order is fixed by the input length alone; it
costs about 0.1 ms more per call of a 256-128-64 policy, at 50 Hz.
"""

from __future__ import annotations

import numpy as np

from wbc.errors import PolicyInputError
from wbc.learned.policy.policy_file import PolicyFile

__all__ = ["NumpyPolicy", "activation", "dense"]


def dense(x: np.ndarray, w: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The affine layer ``x @ w.T + b``, summed in an order that does not depend on the CPU.

    Args:
        x: inputs, shape (..., in).
        w: weights, shape (out, in).
        b: biases, shape (out,).

    Returns:
        Shape (..., out): each output is the pairwise sum, over the inputs in order, of ``x * w``.
    """
    return np.add.reduce(x[..., None, :] * w, axis=-1) + b


def activation(name: str, x: np.ndarray) -> np.ndarray:
    """Apply the named activation (one of `wbc.learned.policy.policy_file.ACTIVATIONS`)."""
    if name == "elu":
        return np.where(x > 0.0, x, np.expm1(np.minimum(x, 0.0)))
    if name == "relu":
        return np.maximum(x, 0.0)
    if name == "tanh":
        return np.tanh(x)
    return x


def _mlp(layers: list[tuple[np.ndarray, np.ndarray]], act: str, x: np.ndarray) -> np.ndarray:
    for i, (w, b) in enumerate(layers):
        x = dense(x, w, b)
        if i < len(layers) - 1:
            x = activation(act, x)
    return x


class NumpyPolicy:
    """A policy evaluated in numpy.

    Args:
        policy: a loaded, validated policy file.
    """

    def __init__(self, policy: PolicyFile) -> None:
        self.file = policy
        meta, a = policy.meta, policy.arrays
        self.activation = meta["activation"]
        self.eps = float(meta["normalizer_eps"])
        self._layers = [(w.astype(np.float64), b.astype(np.float64)) for w, b in policy.layers("policy")]
        self._encoder = [(w.astype(np.float64), b.astype(np.float64)) for w, b in policy.layers("encoder")]
        self._obs_mean = a["obs_mean"].astype(np.float64)
        self._obs_scale = 1.0 / (a["obs_std"].astype(np.float64) + self.eps)
        self.uses_extrinsics = meta.get("extrinsics") is not None
        adapt = meta.get("adaptation")
        self.history = int(adapt["history"]) if adapt is not None else 0
        self._adaptation = [(w.astype(np.float64), b.astype(np.float64)) for w, b in policy.layers("adaptation")]
        self.has_encoder = bool(self._encoder)
        """Whether z can come from privileged observations (False: from the history alone, `adaptation`)."""
        if self.has_encoder:
            self._priv_mean = a["privileged_mean"].astype(np.float64)
            self._priv_scale = 1.0 / (a["privileged_std"].astype(np.float64) + self.eps)

    def extrinsics(self, privileged: np.ndarray) -> np.ndarray:
        """The extrinsics z from privileged observations, (N, P) -> (N, z_dim).

        Raises:
            PolicyInputError: the file's z is learned from the history alone (no encoder; use `adaptation`).
        """
        if not self.has_encoder:
            raise PolicyInputError("this policy's z is learned from its observation history alone (the file has no "
                                   "encoder of privileged observations): compute it with `adaptation`")
        x = (np.asarray(privileged, dtype=np.float64) - self._priv_mean) * self._priv_scale
        return _mlp(self._encoder, self.activation, x)

    def normalise(self, obs: np.ndarray) -> np.ndarray:
        """Observations as the networks see them, (N, obs_size)."""
        return (np.asarray(obs, dtype=np.float64) - self._obs_mean) * self._obs_scale

    def adaptation(self, history: np.ndarray) -> np.ndarray:
        """The estimated extrinsics from (N, H * obs_size) normalised observations, oldest first (RMA phase 2).

        Raises:
            PolicyInputError: the file has no adaptation module.
        """
        if not self._adaptation:
            raise PolicyInputError("this policy file has no adaptation module to estimate z: run RMA phase 2 on it "
                                   "(wbc.learned.train.rma.train_adaptation), or pass z from `extrinsics` in "
                                   "simulation")
        return _mlp(self._adaptation, self.activation, np.asarray(history, dtype=np.float64))

    def __call__(self, obs: np.ndarray, z: np.ndarray | None = None) -> np.ndarray:
        """Deterministic actions, (N, obs_size) [+ (N, z_dim)] -> (N, num_actions).

        Raises:
            PolicyInputError: `z` is missing for a policy that observes the extrinsics, or given to one that does not.
        """
        x = (np.asarray(obs, dtype=np.float64) - self._obs_mean) * self._obs_scale
        if self.uses_extrinsics:
            if z is None:
                raise PolicyInputError("this policy observes the extrinsics z: pass z (from `extrinsics` in "
                                       "simulation, or from the RMA adaptation module on a robot)")
            x = np.concatenate([x, np.asarray(z, dtype=np.float64)], axis=-1)
        elif z is not None:
            raise PolicyInputError("this policy does not observe extrinsics; call it without z")
        return _mlp(self._layers, self.activation, x)
