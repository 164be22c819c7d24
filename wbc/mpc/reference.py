"""`MotionReference`: what the MPC tracks, from the operator's velocity command.

Two targets are integrated from the command at the control rate: a horizontal CoM target (x, y) and a yaw target.
Each is held on a leash around the robot's measured CoM and (unwrapped) yaw, so that after a push the reference waits
for the robot instead of running away from it, and the MPC is never asked to catch up more than the leash at once.
Over the MPC horizon (`trajectory`) the commanded body-frame velocity turns with the yaw reference, the CoM height
is held above the stance feet, the angular momentum is the one of turning at the commanded yaw rate, and the arm is
pulled to its nominal pose.

The per-tick update works on a handful of scalars, so in Python floats.
"""

from __future__ import annotations

import math

import numpy as np

from wbc.mpc.centroidal_model import ARM_Q, MOMENTUM, NX
from wbc.types import VelocityCommand

__all__ = ["XY_LEASH_M", "YAW_LEASH_RAD", "MotionReference"]

XY_LEASH_M = 0.15
"""Largest distance, on each horizontal axis, between the CoM target and the measured CoM [m].

The target is where the command says the robot should be; a pushed robot drags it along, so the MPC is never asked
to make up more than this at once. A tuning value from the controller's first version; no measurement behind it is
recorded (docs/mpc-notes.md)."""

YAW_LEASH_RAD = 0.3
"""Largest angle between the yaw target and the measured (unwrapped) yaw [rad].

A spun robot is asked to turn back at most this far at once. A tuning value from the controller's first
version; no measurement behind it is recorded (docs/mpc-notes.md)."""


def _leash(offset: float, length: float) -> float:
    """`offset` clipped to [-length, length] (``min(max(offset, -length), length)``, in two comparisons)."""
    return -length if offset < -length else length if offset > length else offset


class MotionReference:
    """The leashed xy and yaw targets, and the reference trajectory x_ref the MPC tracks over its horizon.

    Args:
        control_dt: control period: the targets advance by the command every tick [s].
        horizon: MPC steps N.
        step_s: MPC step length [s].
        body_height: CoM height above the stance feet to hold [m].
        arm_q: nominal arm joint positions, the arm's reference (3,) [rad].
        xy_leash: the CoM target's leash, per horizontal axis [m] (`XY_LEASH_M`).
        yaw_leash: the yaw target's leash [rad] (`YAW_LEASH_RAD`).

    Attributes:
        yaw: the measured yaw, unwrapped (continuous over turns) [rad].
        yaw_target: the yaw target, within `yaw_leash` of `yaw` [rad].
        xy_target: the horizontal CoM target, world, within `xy_leash` of the CoM on each axis (2,) [m].
        targets: the targets as one array, (yaw, yaw target, CoM target x, CoM target y), updated in place by
            `update` (or the controller's compiled tick, `wbc.mpc.compiled.reference_update`, the same law).
    """

    def __init__(self, *, control_dt: float, horizon: int, step_s: float, body_height: float,
                 arm_q: np.ndarray, xy_leash: float = XY_LEASH_M, yaw_leash: float = YAW_LEASH_RAD) -> None:
        self.control_dt = control_dt
        self.xy_leash, self.yaw_leash = xy_leash, yaw_leash
        self.horizon = horizon
        self.step_s = step_s
        self.body_height = body_height
        self.arm_q = arm_q
        self.step_times = np.arange(1, horizon + 1) * step_s
        """The ends of the horizon's steps from now (N,) [s]."""
        self.targets = np.zeros(4)
        self.reset()

    def reset(self) -> None:
        """Forget the episode's targets (`start` sets the yaw at the first tick)."""
        self.targets[:] = 0.0

    @property
    def yaw(self) -> float:
        """The measured yaw, unwrapped [rad]."""
        return self.targets.item(0)

    @property
    def yaw_target(self) -> float:
        """The yaw target [rad]."""
        return self.targets.item(1)

    @property
    def xy_target(self) -> np.ndarray:
        """The horizontal CoM target, world (2,) [m] (a new array)."""
        return self.targets[2:4].copy()

    def start(self, yaw: float) -> None:
        """Aim at the robot's heading at the first tick of an episode.

        Args:
            yaw: measured yaw [rad].
        """
        self.targets[0] = yaw
        self.targets[1] = yaw

    def update(self, yaw: float, com_x: float, com_y: float, command: VelocityCommand) -> tuple[float, float]:
        """Advance the targets by one control tick of the command, and leash them to the robot.

        Args:
            yaw: measured yaw, in (-pi, pi] [rad]; unwrapped here.
            com_x: measured CoM x, world [m].
            com_y: measured CoM y, world [m].
            command: the operator's command (body-frame velocity, yaw rate).

        Returns:
            The commanded horizontal velocity in the world frame (vx, vy) [m/s], turned by the unwrapped yaw.
        """
        dt, targets = self.control_dt, self.targets
        before = targets.item(0)
        targets[0] = unwrapped = before + math.remainder(yaw - before, 2 * math.pi)
        cy, sy = math.cos(unwrapped), math.sin(unwrapped)
        vx, vy = command.vx, command.vy
        vx_world = cy * vx - sy * vy
        vy_world = sy * vx + cy * vy
        targets[2] = com_x + _leash(targets.item(2) + vx_world * dt - com_x, self.xy_leash)
        targets[3] = com_y + _leash(targets.item(3) + vy_world * dt - com_y, self.xy_leash)
        targets[1] = unwrapped + _leash(targets.item(1) + command.yaw_rate * dt - unwrapped, self.yaw_leash)
        return vx_world, vy_world

    def trajectory(self, command: VelocityCommand, ground_z: float, inertia_world: np.ndarray) -> np.ndarray:
        """The reference states x_1 .. x_N of the MPC from the current targets.

        Step k (at k step_s from now): yaw_k = yaw_target + yaw_rate k step_s; the CoM velocity is the command
        turned by yaw_k and the CoM position its running sum from `xy_target`; the CoM height is `body_height`
        above the ground; the angular momentum is I_c (0, 0, yaw_rate); roll, pitch and the CoM's vertical velocity
        are zero; the arm is at `arm_q`.

        Args:
            command: the operator's command.
            ground_z: height of the ground under the stance feet [m].
            inertia_world: composite centroidal inertia I_c, world axes, shape (3, 3) [kg m^2].

        Returns:
            x_ref, shape (N, 15).
        """
        dt = self.step_s
        x_ref = np.zeros((self.horizon, NX))
        # while turning, the commanded body-frame velocity turns with the yaw reference along the horizon
        yaw_k = self.yaw_target + command.yaw_rate * self.step_times
        cos_k, sin_k = np.cos(yaw_k), np.sin(yaw_k)
        vx_k = cos_k * command.vx - sin_k * command.vy
        vy_k = sin_k * command.vx + cos_k * command.vy
        x_ref[:, 0] = self.targets.item(2) + np.cumsum(vx_k) * dt
        x_ref[:, 1] = self.targets.item(3) + np.cumsum(vy_k) * dt
        x_ref[:, 2] = ground_z + self.body_height
        x_ref[:, 3] = vx_k
        x_ref[:, 4] = vy_k
        x_ref[:, 8] = yaw_k
        x_ref[:, MOMENTUM] = inertia_world @ np.array([0.0, 0.0, command.yaw_rate])
        x_ref[:, ARM_Q] = self.arm_q
        return x_ref
