"""`ObsHistory`: the last H (normalised) policy observations of N robots, the input of the RMA adaptation module.

Oldest first. After a reset the whole window is filled with the first observation, in the training env and on the
robot alike, so the adaptation module never sees zeros that the other never produces.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ObsHistory"]


class ObsHistory:
    """A sliding window of observations.

    Args:
        num_envs: robots.
        length: observations kept (H).
        size: observation size (D).
    """

    def __init__(self, num_envs: int, length: int, size: int) -> None:
        self.buf = np.zeros((num_envs, length, size), dtype=np.float32)

    def fill(self, ids: np.ndarray, obs: np.ndarray) -> None:
        """Fill the windows of robots `ids` with their observation `obs` (len(ids), D)."""
        self.buf[ids] = obs[:, None, :]

    def push(self, obs: np.ndarray) -> None:
        """Append the newest observation of every robot, (N, D), dropping the oldest."""
        self.buf[:, :-1] = self.buf[:, 1:]
        self.buf[:, -1] = obs

    def flat(self) -> np.ndarray:
        """(N, H * D), oldest observation first."""
        return self.buf.reshape(self.buf.shape[0], -1)
