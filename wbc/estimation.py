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
        c = np.zeros((28, n))
        for i in range(4):
            c[3 * i:3 * i + 3, 0:3] = -np.eye(3)         # p_foot - p
            c[3 * i:3 * i + 3, 6 + 3 * i:9 + 3 * i] = np.eye(3)
            c[12 + 3 * i:15 + 3 * i, 3:6] = np.eye(3)   # v (from a stance foot)
            c[24 + i, 8 + 3 * i] = 1.0                   # foot height
        self.C = c
        cfg = self.config
        self._q_base = np.zeros(n)
        self._q_base[0:3] = (cfg.position_noise * dt) ** 2
        self._q_base[3:6] = (cfg.accel_noise * dt) ** 2
        self._q_base[6:18] = (cfg.foot_process_noise * dt) ** 2 / dt
        self._r_base = np.zeros(28)
        self._r_base[0:12] = cfg.foot_position_noise**2
        self._r_base[12:24] = cfg.foot_velocity_noise**2
        self._r_base[24:28] = cfg.foot_height_noise**2

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
        dt, x, p = self.dt, self.x, self.P
        # predict: x = A x + B a, P = A P A^T + Q, with A = I + dt [0 I; 0 0] on (p, v)
        a_world = rot @ accel_body + GRAVITY
        x[0:3] += dt * x[3:6] + (0.5 * dt * dt) * a_world
        x[3:6] += dt * a_world
        p[0:3, :] += dt * p[3:6, :]
        p[:, 0:3] += dt * p[:, 3:6]
        scale = 1.0 + 100.0 * (1.0 - np.asarray(trust, dtype=np.float64))
        q = self._q_base.copy()
        q[6:18] *= np.repeat(scale**2, 3)
        p[np.diag_indices(18)] += q
        r = self._r_base.copy()
        r[12:24] *= np.repeat(scale**2, 3)
        r[24:28] *= scale**2
        # correct
        c = self.C
        y = np.concatenate([np.asarray(feet_rel_world).ravel(), -np.asarray(feet_vel_rel_world).ravel(),
                            np.zeros(4)])
        pct = p @ c.T
        s_mat = c @ pct
        s_mat[np.diag_indices(28)] += r
        k = np.linalg.solve(s_mat, pct.T).T
        self.x = x + k @ (y - c @ x)
        p = p - k @ pct.T
        self.P = 0.5 * (p + p.T)
