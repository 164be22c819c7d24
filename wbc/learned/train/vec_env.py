"""`RslVecEnv`: the numpy `BatchedEnv` behind rsl-rl-lib 5.x's `VecEnv` interface (torch tensors in and out).

Observation groups: ``policy`` (what the robot measures), ``privileged`` (what only the simulator knows), when the
env config names a teacher arm mode ``teacher`` (the teacher policy's view of the same state, for the BC term), and
with a history of H > 0 ``history``: each robot's last H policy observations, raw, oldest first, the newest being the
current one, the window filled with an episode's first observation when it begins (as `ObsHistory` and the
controllers do), for an actor that reads its own memory (`wbc.learned.train.history_actor`).
Episode statistics go to ``extras["log"]`` (keys namespaced with "/"), time-outs to ``extras["time_outs"]``.
"""

from __future__ import annotations

import numpy as np

from wbc.learned.env.env import BatchedEnv
from wbc.learned.policy.obs_history import ObsHistory
from wbc.optional import require

torch = require("torch")
_tensordict = require("tensordict")
_vec_env = require("rsl_rl.env")

__all__ = ["RslVecEnv"]


class RslVecEnv(_vec_env.VecEnv):
    """Adapter from `BatchedEnv` to `rsl_rl.env.VecEnv`.

    Args:
        env: the batched env (owned: `close` closes it).
        device: torch device of the returned tensors.
        history: observations in the ``history`` group (0: no such group).
    """

    def __init__(self, env: BatchedEnv, device: str = "cpu", history: int = 0) -> None:
        self.env = env
        self.num_envs = env.num_envs
        self.num_actions = env.num_actions
        self.max_episode_length = env.max_episode_steps
        self.device = device
        self.cfg = env.config
        self._history: ObsHistory | None = None
        obs, privileged, teacher = env.reset()
        if history > 0:
            self._history = ObsHistory(env.num_envs, history, obs.shape[1])
            self._history.fill(np.arange(env.num_envs), obs)
        self._obs = self._pack(obs, privileged, teacher)

    @property
    def episode_length_buf(self):
        """Policy steps since each episode began, (N,) int64 (a copy; assigning writes through to the env)."""
        return torch.from_numpy(self.env.episode_step.copy())

    @episode_length_buf.setter
    def episode_length_buf(self, value) -> None:
        self.env.episode_step[:] = np.asarray(value.cpu().numpy() if hasattr(value, "cpu") else value)

    def get_observations(self):
        """The current observation TensorDict."""
        return self._obs

    def step(self, actions):
        """One policy step: (obs, rewards, dones, extras)."""
        r = self.env.step(actions.detach().cpu().numpy())
        if self._history is not None:  # a robot whose episode ended starts its new one with a full window
            self._history.push(r.obs)
            began = np.flatnonzero(r.terminated | r.time_out)
            self._history.fill(began, r.obs[began])
        self._obs = self._pack(r.obs, r.privileged, r.teacher)
        rewards = torch.from_numpy(r.reward.astype(np.float32)).to(self.device)
        dones = torch.from_numpy((r.terminated | r.time_out).astype(np.int64)).to(self.device)
        extras = {"time_outs": torch.from_numpy(r.time_out).to(self.device), "log": dict(r.log)}
        return self._obs, rewards, dones, extras

    def close(self) -> None:
        """Close the env."""
        self.env.close()

    def _pack(self, obs: np.ndarray, privileged: np.ndarray, teacher: np.ndarray | None):
        groups = {"policy": torch.from_numpy(obs), "privileged": torch.from_numpy(privileged)}
        if teacher is not None:
            groups["teacher"] = torch.from_numpy(np.ascontiguousarray(teacher))
        if self._history is not None:
            groups["history"] = torch.from_numpy(self._history.flat().copy())
        return _tensordict.TensorDict(groups, batch_size=[self.num_envs], device=self.device)
