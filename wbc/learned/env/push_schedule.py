"""`PushSchedule`: the scenario's pushes of every environment, turned into ``xfrc_applied`` rows per physics step.

Each environment plays the pushes of its current `Trial` (drawn from the scenario's band, as evaluation does), held in
the `PushTable` that `MujocoRobot` uses too: a push acts from its start for its duration, rounded to physics steps by
`wbc.hardware.mujoco.physics.push_steps`, and the table grows to hold every push of a trial. The force is constant in
the world frame; its torque about the trunk's centre of mass is ``(R(t) (offset - c)) x F`` with c the trunk CoM in
the trunk frame (`physics.push_wrench`). MujocoRobot refreshes R(t) every physics step; one rollout call runs a whole
policy step without Python, so the env predicts R(t) to first order from the trunk's rotation and body angular
velocity at the window's start, ``R(t) r ~ R (r + t omega x r)`` (`tests/test_learned.py` holds the two to 1 % of
the angular velocity a 250 N push gives).
"""

from __future__ import annotations

import numpy as np

from wbc.hardware.mujoco.physics import PushTable, push_wrench

__all__ = ["PushSchedule"]


class PushSchedule(PushTable):
    """A `PushTable` of N environments (one row each) that also gives the trunk wrench of a window of physics steps."""

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
        active = self.active(steps)  # (N, T, P)
        if not active.any():
            return None
        r = self.offset - com_in_base[:, None, :]  # (N, P, 3) lever arm in the trunk frame
        if omega_in_body is None:
            arm = np.einsum("nij,npj->npi", rot, r)[:, :, None, :]  # (N, P, 1, 3)
        else:
            t = self.timestep * np.arange(nstep)
            turned = r[:, :, None, :] + t[None, None, :, None] * np.cross(omega_in_body[:, None, :], r)[:, :, None]
            arm = np.einsum("nij,nptj->npti", rot, turned)  # (N, P, T, 3)
        return push_wrench(self.force[:, None], arm.transpose(0, 2, 1, 3), active)
