"""Base state estimation from what a real robot has: IMU and leg kinematics (a linear Kalman filter).

State (18): base position p and velocity v (world), and the four foot positions (world). Process: p += v dt,
v += (R a_imu + g) dt, feet constant. Measurements for each foot: its position relative to the base from leg
kinematics (p_foot - p = R r_foot), its velocity relative to the base (0 - v = R (omega x r + J dq), i.e. a stance
foot does not slide) and its height (0: the ground). A foot not in stance has its measurements (and its own
process noise) inflated by 1 + 100 (1 - trust), following the MIT Cheetah estimator. Orientation comes from the IMU
quaternion directly.

Because the model is linear time-invariant for a given set of trusted feet, the default filter runs with the
steady-state Kalman gain of the current contact pattern (trust rounded to 0 or 1; the gains of the 16 patterns come
from iterating the Riccati recursion once, then are cached): one matrix-vector product per tick instead of a 28 x 28
solve; the 16 gains are built with the filter, outside the loop. ``gain="full"`` runs the time-varying filter instead.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numba
import numpy as np

from wbc.config_checks import check_number
from wbc.errors import ConfigError
from wbc.robots.conventions import GRAVITY

__all__ = ["DEFAULT_CONTACT_FORCE", "EstimatorConfig", "BaseEstimator", "steady_step"]

DEFAULT_CONTACT_FORCE = 15.0
"""The foot sensor reading at which an estimator fed from a robot's states trusts a foot as standing, by default
[N in simulation; a real robot's sensors read raw counts] (`wbc.estimation.base_estimate.BaseEstimate`)."""


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
        gain: ``steady`` (the steady-state gain of each contact pattern) or ``full`` (time-varying covariance).

    Raises:
        ConfigError: a noise that is not a positive finite number, or an unknown `gain`.
    """

    accel_noise: float = 0.5
    position_noise: float = 0.02
    foot_process_noise: float = 0.002
    foot_position_noise: float = 0.005
    foot_velocity_noise: float = 0.05
    foot_height_noise: float = 0.02
    gain: str = "steady"

    def __post_init__(self) -> None:
        for name in ("accel_noise", "position_noise", "foot_process_noise", "foot_position_noise",
                     "foot_velocity_noise", "foot_height_noise"):
            check_number(f"EstimatorConfig.{name}", getattr(self, name), above=0.0)
        if self.gain not in ("steady", "full"):
            raise ConfigError(f"EstimatorConfig.gain must be 'steady' (the precomputed gain) or 'full' (a Kalman update"
                              f" every tick), got {self.gain!r}")


def _measurement_matrix() -> np.ndarray:
    c = np.zeros((28, 18))
    for i in range(4):
        c[3 * i:3 * i + 3, 0:3] = -np.eye(3)         # p_foot - p
        c[3 * i:3 * i + 3, 6 + 3 * i:9 + 3 * i] = np.eye(3)
        c[12 + 3 * i:15 + 3 * i, 3:6] = np.eye(3)   # v (from a stance foot)
        c[24 + i, 8 + 3 * i] = 1.0                   # foot height
    return c


def _noise(dt: float, cfg: EstimatorConfig, trust: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Diagonals of the process and measurement noise covariances for contact trust `trust` (4,)."""
    scale = 1.0 + 100.0 * (1.0 - np.asarray(trust, dtype=np.float64))
    q = np.zeros(18)
    q[0:3] = (cfg.position_noise * dt) ** 2
    q[3:6] = (cfg.accel_noise * dt) ** 2
    q[6:18] = (cfg.foot_process_noise * dt) ** 2 / dt * np.repeat(scale**2, 3)
    r = np.zeros(28)
    r[0:12] = cfg.foot_position_noise**2
    r[12:24] = cfg.foot_velocity_noise**2 * np.repeat(scale**2, 3)
    r[24:28] = cfg.foot_height_noise**2 * scale**2
    return q, r


@lru_cache(maxsize=64)
def _steady_gain(dt: float, cfg: EstimatorConfig, pattern: int) -> np.ndarray:
    """Steady-state Kalman gain (18 x 28) for the contact pattern `pattern` (bit i: foot i trusted).

    The predicted covariance solves the filter's discrete algebraic Riccati equation; the structured doubling
    algorithm reaches it in a few dozen iterations (the plain recursion needs thousands: the feet's process noise is
    tiny).
    """
    trust = np.array([(pattern >> i) & 1 for i in range(4)], dtype=np.float64)
    q, r = _noise(dt, cfg, trust)
    a = np.eye(18)
    a[0:3, 3:6] = dt * np.eye(3)
    c = _measurement_matrix()
    eye = np.eye(18)
    # doubling on the dual (control) Riccati equation with A -> A^T, B -> C^T
    ak, gk, hk = a.T.copy(), c.T @ (c / r[:, None]), np.diag(q)
    for _ in range(100):
        w = np.linalg.solve(eye + gk @ hk, np.hstack([ak, gk]))
        w_a, w_g = w[:, :18], w[:, 18:]
        h_next = hk + ak.T @ hk @ w_a
        gk = gk + ak @ w_g @ ak.T
        ak = ak @ w_a
        done = np.max(np.abs(h_next - hk)) <= 1e-12 * max(1.0, np.max(np.abs(h_next)))
        hk = 0.5 * (h_next + h_next.T)
        if done:
            break
    p = hk
    k = np.linalg.solve(c @ p @ c.T + np.diag(r), c @ p).T
    k.setflags(write=False)
    return k


@numba.njit(cache=True, nogil=True)
def steady_step(x, trust, rot, accel_body, feet_rel, feet_vel_rel, keep_a, keep_b, keep_g,
                gain):  # pragma: no cover
    """One predict-and-correct step of the base estimator with the steady gain of the trusted feet's pattern.

    x+ = keep_a[p] x + keep_b[p] (R a) + gain[p] y + keep_g[p], with y the feet's positions and velocities relative
    to the base (12 + 12) and p the pattern of feet trusted at least half (bit i: foot i); `x` is updated in place.
    """
    pattern = 0
    for i in range(4):
        if trust[i] >= 0.5:
            pattern |= 1 << i
    ka, kb, kg, k = keep_a[pattern], keep_b[pattern], keep_g[pattern], gain[pattern]
    aw = np.empty(3)
    for a in range(3):
        aw[a] = rot[a, 0] * accel_body[0] + rot[a, 1] * accel_body[1] + rot[a, 2] * accel_body[2]
    y = np.empty(24)
    for i in range(4):
        for a in range(3):
            y[3 * i + a] = feet_rel[i, a]
            y[12 + 3 * i + a] = feet_vel_rel[i, a]
    n = x.shape[0]
    out = np.empty(n)
    for r in range(n):
        acc = kg[r] + kb[r, 0] * aw[0] + kb[r, 1] * aw[1] + kb[r, 2] * aw[2]
        for c in range(n):
            acc += ka[r, c] * x[c]
        for c in range(24):
            acc += k[r, c] * y[c]
        out[r] = acc
    for r in range(n):
        x[r] = out[r]



class BaseEstimator:
    """Kalman filter over base position, velocity and foot positions.

    Args:
        dt: filter period [s].
        config: noise settings.
    """

    def __init__(self, dt: float, config: EstimatorConfig | None = None) -> None:
        self.dt = dt
        self.config = config or EstimatorConfig()
        self.x = np.zeros(18)
        self.P = np.eye(18) * 1e-2
        self.C = _measurement_matrix()
        self._y = np.zeros(28)
        # the one-step update's matrices of all 16 contact patterns, built here and stacked by pattern (keep_a,
        # keep_b, keep_g, signed gain) for the compiled step: a gain built inside the control loop would stall one
        # tick by ~10 ms (the first time each pattern occurs in a process)
        self._steady: tuple[np.ndarray, ...] = ()
        if self.config.gain == "steady":
            a = np.eye(18)
            a[0:3, 3:6] = dt * np.eye(3)
            b = np.zeros((18, 3))
            b[0:3] = 0.5 * dt * dt * np.eye(3)
            b[3:6] = dt * np.eye(3)
            rows = []
            for pattern in range(16):
                gain = _steady_gain(dt, self.config, pattern)
                keep = np.eye(18) - gain @ self.C
                signed = gain[:, :24].copy()
                signed[:, 12:24] *= -1.0
                rows.append((keep @ a, keep @ b, keep @ b @ GRAVITY, signed))
            self._steady = tuple(np.ascontiguousarray(np.stack(m)) for m in zip(*rows, strict=True))

    def steady_arrays(self) -> tuple[np.ndarray, ...]:
        """The state and the steady-gain step's matrices, as `steady_step` takes them: x, keep_a, keep_b, keep_g, gain.

        `x` is the estimator's own state (a compiled step updates it in place).

        Raises:
            ConfigError: the filter runs the full gain (``EstimatorConfig.gain = "full"``), which has no steady step.
        """
        if not self._steady:
            raise ConfigError("BaseEstimator.steady_arrays: this filter runs the full Kalman gain (EstimatorConfig."
                              "gain='full'), which has no steady-gain step; use gain='steady'")
        return (self.x, *self._steady)

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
            trust: contact trust of each foot in [0, 1] (an array, or a list of four floats).
        """
        dt, x = self.dt, self.x
        if self.config.gain == "steady":
            # predict and correct in one, compiled: x+ = (I - K C) (A x + B (R a + g)) + K y; the velocity rows of y
            # are negated inside the stored gain and its foot-height rows (zeros) dropped
            steady_step(x, np.asarray(trust, dtype=np.float64), rot, np.asarray(accel_body, dtype=np.float64),
                         np.asarray(feet_rel_world, dtype=np.float64),
                         np.asarray(feet_vel_rel_world, dtype=np.float64), *self._steady)
            return
        # predict: x = A x + B a, with A = I + dt [0 I; 0 0] on (p, v)
        a_world = rot @ accel_body + GRAVITY
        x[0:3] += dt * x[3:6] + (0.5 * dt * dt) * a_world
        x[3:6] += dt * a_world
        y = self._y
        y[0:12] = np.ravel(feet_rel_world)
        y[12:24] = np.ravel(feet_vel_rel_world)
        y[12:24] *= -1.0
        p = self.P
        p[0:3, :] += dt * p[3:6, :]
        p[:, 0:3] += dt * p[:, 3:6]
        q, r = _noise(dt, self.config, trust)
        p[np.diag_indices(18)] += q
        # correct
        c = self.C
        pct = p @ c.T
        s_mat = c @ pct
        s_mat[np.diag_indices(28)] += r
        k = np.linalg.solve(s_mat, pct.T).T
        self.x = x + k @ (y - c @ x)
        p = p - k @ pct.T
        self.P = 0.5 * (p + p.T)
