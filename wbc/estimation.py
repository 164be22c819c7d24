"""Base state estimation from what a real robot has: IMU and leg kinematics (a linear Kalman filter).

State (18): base position p and velocity v (world), and the four foot positions (world). Process: p += v dt,
v += (R a_imu + g) dt, feet constant. Measurements for each foot: its position relative to the base from leg
kinematics (p_foot - p = R r_foot), its velocity relative to the base (0 - v = R (omega x r + J dq), i.e. a stance
foot does not slide) and its height (0: the ground). A foot not in stance has its measurements (and its own
process noise) inflated by 1 + 100 (1 - trust), following the MIT Cheetah estimator. Orientation comes from the IMU
quaternion directly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["EstimatorConfig", "BaseEstimator"]

GRAVITY = np.array([0.0, 0.0, -9.81])


@dataclass(frozen=True, kw_only=True)
class EstimatorConfig:
    """Noise standard deviations.

    Attributes:
        accel_noise: process noise of the base velocity [m/s^2].
        position_noise: process noise of the base position [m/s].
        foot_process_noise: process noise of the feet [m/s].
        foot_position_noise: leg-kinematics foot position measurement [m].
        foot_velocity_noise: stance-foot velocity measurement [m/s].
        foot_height_noise: foot height measurement [m].
    """

    accel_noise: float = 0.5
    position_noise: float = 0.02
    foot_process_noise: float = 0.002
    foot_position_noise: float = 0.005
    foot_velocity_noise: float = 0.05
    foot_height_noise: float = 0.02


class BaseEstimator:
    """Kalman filter over base position, velocity and foot positions.

    Args:
        dt: filter period [s].
        config: noise settings.
    """

    def __init__(self, dt: float, config: EstimatorConfig | None = None) -> None:
        self.dt = dt
        self.config = config or EstimatorConfig()
        n = 18
        self.x = np.zeros(n)
        self.P = np.eye(n) * 1e-2
        self.A = np.eye(n)
        self.A[0:3, 3:6] = np.eye(3) * dt
        self.B = np.zeros((n, 3))
        self.B[3:6] = np.eye(3) * dt
        c = np.zeros((28, n))
        for i in range(4):
            c[3 * i:3 * i + 3, 0:3] = -np.eye(3)         # p_foot - p
            c[3 * i:3 * i + 3, 6 + 3 * i:9 + 3 * i] = np.eye(3)
            c[12 + 3 * i:15 + 3 * i, 3:6] = np.eye(3)   # v (from a stance foot)
            c[24 + i, 8 + 3 * i] = 1.0                   # foot height
        self.C = c

    def reset(self, base_pos: np.ndarray, feet_world: np.ndarray) -> None:
        """Start at a known base position with zero velocity and the feet where kinematics put them."""
        self.x[:] = 0.0
        self.x[0:3] = base_pos
        self.x[6:18] = np.asarray(feet_world).ravel()
        self.P = np.eye(18) * 1e-4

    @property
    def position(self) -> np.ndarray:
        """Estimated base position, world (3,)."""
        return self.x[0:3].copy()

    @property
    def velocity(self) -> np.ndarray:
        """Estimated base velocity, world (3,)."""
        return self.x[3:6].copy()

    def update(self, rot: np.ndarray, accel_body: np.ndarray, feet_rel_world: np.ndarray,
               feet_vel_rel_world: np.ndarray, trust: np.ndarray) -> None:
        """One predict-and-correct step.

        Args:
            rot: base rotation (body to world) from the IMU.
            accel_body: accelerometer reading (specific force), body frame.
            feet_rel_world: foot positions relative to the base, world axes, shape (4, 3).
            feet_vel_rel_world: foot velocities relative to the base (omega x r + J dq), world axes, shape (4, 3).
            trust: contact trust of each foot in [0, 1].
        """
        cfg, dt = self.config, self.dt
        a_world = rot @ accel_body + GRAVITY
        self.x = self.A @ self.x + self.B @ a_world
        q = np.zeros(18)
        q[0:3] = (cfg.position_noise * dt) ** 2
        q[3:6] = (cfg.accel_noise * dt) ** 2
        r = np.zeros(28)
        for i in range(4):
            scale = 1.0 + 100.0 * (1.0 - float(trust[i]))
            q[6 + 3 * i:9 + 3 * i] = (cfg.foot_process_noise * dt) ** 2 * scale**2 / dt
            r[3 * i:3 * i + 3] = cfg.foot_position_noise**2
            r[12 + 3 * i:15 + 3 * i] = (cfg.foot_velocity_noise * scale) ** 2
            r[24 + i] = (cfg.foot_height_noise * scale) ** 2
        self.P = self.A @ self.P @ self.A.T + np.diag(q)
        y = np.concatenate([np.asarray(feet_rel_world).ravel(), -np.asarray(feet_vel_rel_world).ravel(),
                            np.zeros(4)])
        c = self.C
        s = c @ self.P @ c.T + np.diag(r)
        k = np.linalg.solve(s, c @ self.P).T
        self.x = self.x + k @ (y - c @ self.x)
        self.P = (np.eye(18) - k @ c) @ self.P
        self.P = 0.5 * (self.P + self.P.T)
