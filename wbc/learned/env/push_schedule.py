"""`PushSchedule`: the scenario's pushes of every environment, turned into ``xfrc_applied`` rows per physics step.

Each environment plays the pushes of its current `Trial` (drawn from the scenario's band, as evaluation does). A push
acts from its start for its duration, rounded to physics steps exactly as `MujocoRobot.apply_push` rounds them. The
force is constant in the world frame; its torque about the trunk's centre of mass is ``(R(t) (offset - c)) x F``
with c the trunk CoM in the trunk frame. MujocoRobot refreshes R(t) every physics step; within one rollout call the
env predicts it to first order from the trunk's rotation and body angular velocity at the window's start,
``R(t) r ~ R (r + t omega x r)``: the angular velocity a 250 N push gives then matches MujocoRobot's to 0.1 %
(a lever arm frozen for the 20 ms window was 6 % off, the trunk turning at about 1 rad/s).
"""

from __future__ import annotations

import numpy as np

from wbc.scenario.trial import Trial

__all__ = ["PushSchedule"]


class PushSchedule:
    """Pushes of N environments, at most `max_pushes` each.

    Args:
        num_envs: environments.
        timestep: physics step [s].
        max_pushes: pushes kept per episode (later ones are dropped).
    """

    def __init__(self, num_envs: int, timestep: float, max_pushes: int = 8) -> None:
        self.timestep = timestep
        self.start = np.full((num_envs, max_pushes), -1, dtype=np.int64)  # physics step; -1: no push
        self.stop = np.full((num_envs, max_pushes), -1, dtype=np.int64)
        self.force = np.zeros((num_envs, max_pushes, 3))
        self.offset = np.zeros((num_envs, max_pushes, 3))

    def set(self, env: int, trial: Trial | None) -> None:
        """Replace environment `env`'s pushes with `trial`'s (None: no pushes)."""
        self.start[env] = -1
        self.stop[env] = -1
        self.force[env] = 0.0
        self.offset[env] = 0.0
        if trial is None:
            return
        for k, p in enumerate(trial.pushes[: self.start.shape[1]]):
            start = int(round(p.start / self.timestep))
            self.start[env, k] = start
            self.stop[env, k] = start + max(1, int(round(p.duration / self.timestep)))
            self.force[env, k] = p.force_in_world
            self.offset[env, k] = p.offset_in_base

    def wrench(self, step0: np.ndarray, nstep: int, rot: np.ndarray, com_in_base: np.ndarray,
               omega_in_body: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray] | None:
        """Force and torque on the trunk for physics steps ``step0 .. step0 + nstep - 1`` of every environment.

        Args:
            step0: (N,) physics step index (since each episode's start) of the window's first step.
            nstep: window length.
            rot: (N, 3, 3) trunk rotation (body to world) at the window's start.
            com_in_base: (N, 3) trunk centre of mass in the trunk frame [m].
            omega_in_body: (N, 3) trunk angular velocity in the trunk frame at the window's start [rad/s] (None:
                the lever arm is held for the window).

        Returns:
            None when no push acts in the window, else (force, torque), each (N, nstep, 3), world frame [N], [N m].
        """
        steps = step0[:, None] + np.arange(nstep)[None, :]  # (N, T)
        active = (steps[:, None, :] >= self.start[:, :, None]) & (steps[:, None, :] < self.stop[:, :, None])
        if not active.any():
            return None
        act = active.astype(np.float64)  # (N, P, T)
        force = np.einsum("npt,npk->ntk", act, self.force)
        r = self.offset - com_in_base[:, None, :]  # (N, P, 3) lever arm in the trunk frame
        if omega_in_body is None:
            arm = np.einsum("nij,npj->npi", rot, r)[:, :, None, :]  # (N, P, 1, 3)
        else:
            t = self.timestep * np.arange(nstep)
            turned = r[:, :, None, :] + t[None, None, :, None] * np.cross(omega_in_body[:, None, :], r)[:, :, None]
            arm = np.einsum("nij,nptj->npti", rot, turned)  # (N, P, T, 3)
        torque = np.einsum("npt,nptk->ntk", act, np.cross(arm, self.force[:, :, None, :]))
        return force, torque

    def force_at(self, step: np.ndarray) -> np.ndarray:
        """(N, 3) push force acting at physics step `step` (N,) [N], world frame."""
        active = (step[:, None] >= self.start) & (step[:, None] < self.stop)
        return np.einsum("np,npk->nk", active.astype(np.float64), self.force)
