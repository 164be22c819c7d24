"""`NumpyPolicy`: inference of an exported policy (`PolicyFile`) in numpy, no torch.

actions = MLP_policy([normalise(obs), z]) with z = MLP_encoder(normalise(privileged)) when the policy observes the
RMA extrinsics; normalise(x) = (x - mean) / (std + eps), the rsl-rl empirical normaliser's formula. Computed in
float64 from the float32 weights, so it matches torch's float32 forward pass to about 1e-6.

The layers do not call BLAS: OpenBLAS picks its kernel by the CPU (a Haswell and a Sandy Bridge kernel sum a
matrix-vector product in different orders), so the same policy on the same trial gave different last bits on
different machines, and a closed loop grows those into different trajectories. `dense` multiplies elementwise
(exact) and sums each output in numpy's pairwise order, which the input length alone fixes: ``np.add.reduce`` of the
products, as first written, or the same order step for step in a compiled loop (numba), which gives the same bits
without building the products' array: a 256-128-64 policy with an adaptation module costs ~0.04 ms per call instead
of ~0.35 ms. The ELU is compiled the same way (libm's ``expm1``, which numpy also calls); ``tanh`` stays numpy's
(its own vectorised loop, whose last bits libm's does not share).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from wbc.errors import PolicyInputError
from wbc.learned.policy.policy_file import PolicyFile

__all__ = ["NumpyPolicy", "activation", "dense"]


PAIRWISE_BLOCK = 128
"""numpy's pairwise summation: runs up to this length are summed in eight interleaved partial sums, longer ones split
in two halves whose lengths are multiples of eight (``PW_BLOCKSIZE`` in numpy's loops)."""


@numba.njit(cache=True, nogil=True)
def _block_sums(x, wt, start, n, out):  # pragma: no cover - compiled
    """Into ``out[j]``: numpy's pairwise sum of ``x[i] * wt[i, j]`` over ``i`` in ``start .. start + n`` (n <= 128).

    Every output j at once, along the contiguous rows of `wt` (in, out); each output's additions are numpy's, in
    numpy's order: under eight terms one running sum from 0.0, else eight interleaved partial sums combined as
    ((p0 + p1) + (p2 + p3)) + ((p4 + p5) + (p6 + p7)), then the remainder one by one.
    """
    n_out = wt.shape[1]
    if n < 8:
        for j in range(n_out):
            out[j] = 0.0
        for i in range(start, start + n):
            xi = x[i]
            for j in range(n_out):
                out[j] += xi * wt[i, j]
        return
    acc = np.empty((8, n_out))
    for k in range(8):
        xi = x[start + k]
        for j in range(n_out):
            acc[k, j] = xi * wt[start + k, j]
    i = start + 8
    whole = start + n - n % 8
    while i < whole:
        for k in range(8):
            xi = x[i + k]
            for j in range(n_out):
                acc[k, j] += xi * wt[i + k, j]
        i += 8
    for j in range(n_out):
        out[j] = (((acc[0, j] + acc[1, j]) + (acc[2, j] + acc[3, j]))
                  + ((acc[4, j] + acc[5, j]) + (acc[6, j] + acc[7, j])))
    while i < start + n:
        xi = x[i]
        for j in range(n_out):
            out[j] += xi * wt[i, j]
        i += 1


@numba.njit(cache=True, nogil=True)
def _pairwise_sums(x, wt, n, out):  # pragma: no cover - compiled
    """The pairwise sum over ``0 .. n`` for every output: blocks of up to 128 summed, longer runs halved.

    The halving is walked with an explicit stack (numba's cache does not reload recursive functions safely): the node
    at depth d keeps its sum in ``sums[d]``, its left half's sum first, then the right half's added to it.
    """
    depth_max = 64  # each level halves the run: enough for any array that fits in memory
    starts = np.zeros(depth_max, dtype=np.int64)
    lengths = np.zeros(depth_max, dtype=np.int64)
    phases = np.zeros(depth_max, dtype=np.int64)
    sums = np.empty((depth_max, wt.shape[1]))
    lengths[0] = n
    top = 1
    while top > 0:
        d = top - 1
        start, length = starts[d], lengths[d]
        if length <= PAIRWISE_BLOCK:
            _block_sums(x, wt, start, length, sums[d])
            top -= 1
            continue
        half = length // 2
        half -= half % 8
        if phases[d] == 0:  # the left half next
            phases[d] = 1
            starts[d + 1], lengths[d + 1], phases[d + 1] = start, half, 0
            top += 1
        elif phases[d] == 1:  # the left half's sum kept, the right half next
            sums[d, :] = sums[d + 1, :]
            phases[d] = 2
            starts[d + 1], lengths[d + 1], phases[d + 1] = start + half, length - half, 0
            top += 1
        else:  # left + right
            for j in range(wt.shape[1]):
                sums[d, j] += sums[d + 1, j]
            top -= 1
    out[:] = sums[0]


@numba.njit(cache=True, nogil=True)
def _dense_rows(x, wt, b, out):  # pragma: no cover - compiled
    """``out[r, j] = (0.0 + pairwise_i(x[r, i] * wt[i, j])) + b[j]``: numpy's ``add.reduce`` of the products, plus b."""
    for r in range(x.shape[0]):
        row = out[r]
        _pairwise_sums(x[r], wt, wt.shape[0], row)
        for j in range(wt.shape[1]):
            row[j] = (0.0 + row[j]) + b[j]
    return out


@numba.njit(cache=True, nogil=True)
def _elu_rows(x):  # pragma: no cover - compiled
    """In place, element by element: numpy's ``where(x > 0, x, expm1(minimum(x, 0)))`` (``minimum(-0.0, 0.0)`` is 0)."""
    for r in range(x.shape[0]):
        for j in range(x.shape[1]):
            v = x[r, j]
            if not v > 0.0:
                x[r, j] = math.expm1(v if (v < 0.0 or v != v) else 0.0)
    return x


@numba.njit(cache=True, nogil=True)
def _mlp_rows(x, weights, biases, elu):  # pragma: no cover - compiled
    """The whole network in one call: each layer `_dense_rows`, the hidden ones through the ELU when `elu` (else none).

    `weights` and `biases` are tuples of one array type, the weights transposed (in, out).
    """
    h = x
    n = len(weights)
    for k in range(n):
        wt = weights[k]
        out = np.empty((h.shape[0], wt.shape[1]))
        _dense_rows(h, wt, biases[k], out)
        if elu and k < n - 1:
            _elu_rows(out)
        h = out
    return h


def _rows(x: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(x.reshape(-1, x.shape[-1]), dtype=np.float64)


def _dense_t(x: np.ndarray, wt: np.ndarray, b: np.ndarray) -> np.ndarray:
    rows = _rows(x)
    out = _dense_rows(rows, wt, b, np.empty((rows.shape[0], wt.shape[1])))
    return out.reshape(*x.shape[:-1], wt.shape[1])


def dense(x: np.ndarray, w: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The affine layer ``x @ w.T + b``, summed in an order that does not depend on the CPU.

    The same bits as ``np.add.reduce(x[..., None, :] * w, axis=-1) + b`` (numpy's pairwise sum of the products), from
    a compiled loop that does not build the products' array.

    Args:
        x: inputs, shape (..., in).
        w: weights, shape (out, in).
        b: biases, shape (out,).

    Returns:
        Shape (..., out): each output is the pairwise sum, over the inputs in order, of ``x * w``, plus its bias.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 0 or x.shape[-1] != w.shape[1] or b.shape != (w.shape[0],):
        return np.add.reduce(x[..., None, :] * w, axis=-1) + b  # numpy's own error for shapes that do not fit
    return _dense_t(x, np.ascontiguousarray(np.asarray(w, dtype=np.float64).T), np.asarray(b, dtype=np.float64))


def activation(name: str, x: np.ndarray) -> np.ndarray:
    """Apply the named activation (one of `wbc.learned.policy.policy_file.ACTIVATIONS`)."""
    if name == "elu":
        x = np.asarray(x, dtype=np.float64)
        if x.ndim == 0:
            return np.where(x > 0.0, x, np.expm1(np.minimum(x, 0.0)))
        return _elu_rows(_rows(x).copy()).reshape(x.shape)
    if name == "relu":
        return np.maximum(x, 0.0)
    if name == "tanh":
        return np.tanh(x)
    return x


class _Layers:
    """A network's layers ready for the compiled loop: weights transposed (in, out), biases float64.

    The weights keep the file's float32 where every layer has it (each converts exactly to the float64 the products
    are taken in, and half the bytes stream through the cache), else all become float64.
    """

    def __init__(self, layers: list[tuple[np.ndarray, np.ndarray]]) -> None:
        dtype = np.float32 if all(np.asarray(w).dtype == np.float32 for w, _ in layers) else np.float64
        self.weights = tuple(np.ascontiguousarray(np.asarray(w, dtype=dtype).T) for w, _ in layers)
        self.biases = tuple(np.ascontiguousarray(b, dtype=np.float64) for _, b in layers)

    def __bool__(self) -> bool:
        return bool(self.weights)

    def __len__(self) -> int:
        return len(self.weights)


def _mlp(layers: _Layers, act: str, x: np.ndarray) -> np.ndarray:
    """The network on (..., in) inputs: hidden layers activated, the last one not."""
    x = np.asarray(x, dtype=np.float64)
    n_in = layers.weights[0].shape[0]
    if x.ndim == 0 or x.shape[-1] != n_in:
        raise PolicyInputError(f"the layer takes {n_in} inputs, got an array of shape {x.shape}")
    if act in ("elu", "identity"):
        out = _mlp_rows(_rows(x), layers.weights, layers.biases, act == "elu")
        return out.reshape(*x.shape[:-1], out.shape[1])
    for i, (wt, b) in enumerate(zip(layers.weights, layers.biases, strict=True)):
        x = _dense_t(x, wt, b)
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
        self._layers = _Layers(policy.layers("policy"))
        self._encoder = _Layers(policy.layers("encoder"))
        self._obs_mean = a["obs_mean"].astype(np.float64)
        self._obs_scale = 1.0 / (a["obs_std"].astype(np.float64) + self.eps)
        self.uses_extrinsics = meta.get("extrinsics") is not None
        adapt = meta.get("adaptation")
        self.history = int(adapt["history"]) if adapt is not None else 0
        self._adaptation = _Layers(policy.layers("adaptation"))
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
        return self.normalised((np.asarray(obs, dtype=np.float64) - self._obs_mean) * self._obs_scale, z)

    def normalised(self, x: np.ndarray, z: np.ndarray | None = None) -> np.ndarray:
        """Deterministic actions from observations already normalised (`normalise`), as `__call__`.

        Raises:
            PolicyInputError: as `__call__`.
        """
        if self.uses_extrinsics:
            if z is None:
                raise PolicyInputError("this policy observes the extrinsics z: pass z (from `extrinsics` in "
                                       "simulation, or from the RMA adaptation module on a robot)")
            x = np.concatenate([x, np.asarray(z, dtype=np.float64)], axis=-1)
        elif z is not None:
            raise PolicyInputError("this policy does not observe extrinsics; call it without z")
        return _mlp(self._layers, self.activation, x)
