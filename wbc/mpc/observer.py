"""`MomentumObserver`: the external force on the robot, estimated from its momentum, to re-plan when pushed.

The MPC re-plans on its clock (every MPC step, 32 ms): a push of 0.09 s meets about three updates, the first up to a
step late. A generalised-momentum residual (De Luca and Mattone's observer, at the centroidal level) tells within a
few ticks that something outside the model pushes: the robot's linear momentum p = m v changes by the contact forces,
gravity and whatever else acts,

    dp/dt = sum_i f_i + m g + f_ext,

and the residual

    r(t) = K (p(t) - p(0) - integral_0^t (sum_i f_i + m g + r) ds)

follows f_ext through a first-order lag of time constant 1/K (dr/dt = K (f_ext - r)), with no derivative of a
measured velocity. The contact forces are the ones the controller commands (the plan's forces on the scheduled
stance feet): the residual also holds how far the legs are from delivering them, which is why detection uses a
threshold and the horizontal components only (the vertical one swings with every touchdown).

Measured on the a1-wx200 under ``mpc`` (2 ms ticks, K = 25 1/s): trotting in place the horizontal residual stays
within 7 N, walking at 1 m/s within 41 N (the command's ramp); a 300 N push of 0.09 s crosses 80 N 14 ms after it
starts standing and 20 ms walking.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from wbc.errors import ConfigError
from wbc.robots.conventions import GRAVITY

__all__ = ["MomentumObserver", "ObserverConfig", "stance_force_sum"]


@dataclass(frozen=True, kw_only=True)
class ObserverConfig:
    """Settings of `MomentumObserver`.

    Attributes:
        gain: K, the residual's bandwidth [1/s]: it follows a force step with time constant 1/K.
        threshold_n: horizontal residual at which a disturbance is detected [N].
        rearm_fraction: the detector re-arms once the residual falls below this fraction of the threshold, so one
            push is one detection.
    """

    gain: float = 25.0
    threshold_n: float = 80.0
    rearm_fraction: float = 0.5

    def __post_init__(self) -> None:
        if not (math.isfinite(self.gain) and self.gain > 0):
            raise ConfigError(f"ObserverConfig.gain must be a positive finite rate [1/s], got {self.gain!r}")
        if not (math.isfinite(self.threshold_n) and self.threshold_n > 0):
            raise ConfigError(f"ObserverConfig.threshold_n must be a positive force [N], got {self.threshold_n!r}")
        if not 0.0 <= self.rearm_fraction < 1.0:
            raise ConfigError(f"ObserverConfig.rearm_fraction must be in [0, 1), got {self.rearm_fraction!r}")

    def latency_s(self, force_n: float, dt: float) -> float:
        """How long a horizontal force step of `force_n` takes to pass the threshold, sampled every `dt` [s].

        Inf if it never does. Sampled, the residual of a step is F (1 - (1 - K dt)^n) after n samples (the
        continuous 1 - exp(-K t) to first order in K dt), so detection takes the first n with
        (1 - K dt)^n < 1 - threshold / F.
        """
        if force_n <= self.threshold_n:
            return math.inf
        decay = 1.0 - self.gain * dt
        if decay <= 0.0:  # the residual jumps to the force in one sample
            return dt
        return math.ceil(math.log(1.0 - self.threshold_n / force_n) / math.log(decay) - 1e-9) * dt


@numba.njit(cache=True, nogil=True)
def stance_force_sum(forces: np.ndarray, stance: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """The summed force of the feet in stance into `out` (3,): ``(forces * stance[:, None]).sum(axis=0)``, bit for bit.

    Args:
        forces: each foot's force, (feet, 3) [N].
        stance: each foot's stance flag, (feet,) bool.
        out: (3,) [N], written.
    """
    for j in range(3):
        total = 0.0  # numpy's reduction starts from the sum's identity, +0 (a swing foot's -0 adds to +0), row by row
        for i in range(forces.shape[0]):
            total = total + forces[i, j] * (1.0 if stance[i] else 0.0)
        out[j] = total


@numba.njit(cache=True, nogil=True)
def _residual_step(mass, velocity, p0, contact_force, weight, gain, dt, integral, residual):  # pragma: no cover
    """One sample of the residual, in place: the integral with the last residual, then the residual."""
    for j in range(3):
        integral[j] += (contact_force[j] + weight[j] + residual[j]) * dt
    for j in range(3):
        residual[j] = gain * (mass * velocity[j] - p0[j] - integral[j])


class MomentumObserver:
    """The linear-momentum residual of a robot of mass `mass` [kg] (see the module), sampled every tick.

    Attributes:
        residual: the estimated external force now, world axes, shape (3,) [N] (updated in place by each sample).
        detections: disturbances detected since `reset` (rising edges of the horizontal residual past the
            threshold).
    """

    def __init__(self, mass: float, config: ObserverConfig | None = None) -> None:
        if not (math.isfinite(mass) and mass > 0):
            raise ConfigError(f"MomentumObserver: mass must be positive and finite [kg], got {mass!r}")
        self.mass = float(mass)
        self.config = config or ObserverConfig()
        self._weight = self.mass * np.asarray(GRAVITY, dtype=np.float64)
        self.residual = np.zeros(3)
        self.detections = 0
        self._p0 = np.zeros(3)
        self._integral = np.zeros(3)
        self._armed = True
        self._started = False
        self._stance_force = np.zeros(3)
        # compiled once here (numba's cache on disk), not at a control tick
        _residual_step(1.0, np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), 1.0, 1.0, np.zeros(3), np.zeros(3))
        stance_force_sum(np.zeros((4, 3)), np.zeros(4, dtype=np.bool_), np.zeros(3))

    def reset(self) -> None:
        """Forget the episode: the next `update` is the first sample."""
        self.residual = np.zeros(3)
        self.detections = 0
        self._integral = np.zeros(3)
        self._armed = True
        self._started = False

    def update(self, com_velocity: np.ndarray, contact_force: np.ndarray, dt: float) -> bool:
        """One sample: the CoM velocity now and the summed contact force applied over the last `dt`.

        Args:
            com_velocity: the estimated CoM velocity, world axes [m/s].
            contact_force: the sum of the contact forces the robot applied since the last sample (the commanded
                ones on the stance feet), world axes [N].
            dt: time since the last sample [s].

        Returns:
            True on the sample at which a disturbance is detected (once per disturbance).
        """
        velocity = np.asarray(com_velocity, dtype=np.float64)
        if not self._started:
            self._p0 = self.mass * velocity
            self._started = True
            return False
        residual = self.residual
        _residual_step(self.mass, velocity, self._p0, np.asarray(contact_force, dtype=np.float64), self._weight,
                       self.config.gain, dt, self._integral, residual)
        return self._detect(math.hypot(residual[0], residual[1]))

    def update_stance(self, com_velocity: np.ndarray, forces: np.ndarray, stance: np.ndarray, dt: float) -> bool:
        """`update` with the contact force given as each foot's force and its stance flag (summed over the stance feet).

        Args:
            com_velocity: the estimated CoM velocity, world axes, (3,) float [m/s].
            forces: each foot's commanded force, world axes, (4, 3) float [N].
            stance: each foot's stance flag, (4,) bool.
            dt: time since the last sample [s].
        """
        stance_force_sum(forces, stance, self._stance_force)
        return self.update(com_velocity, self._stance_force, dt)

    def _detect(self, horizontal: float) -> bool:
        """The detector's step on the horizontal residual's magnitude [N]: True at a rising edge past the threshold."""
        cfg = self.config
        if self._armed and horizontal > cfg.threshold_n:
            self._armed = False
            self.detections += 1
            return True
        if not self._armed and horizontal < cfg.rearm_fraction * cfg.threshold_n:
            self._armed = True
        return False
