"""Domain randomisation parameters applied by the MuJoCo backend at reset (training and robustness trials)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wbc.errors import ConfigError

__all__ = ["FRICTION_RANGE", "MAX_DELAY_S", "MOTOR_STRENGTH_RANGE", "PAYLOAD_KG_RANGE", "DomainParams", "SensorNoise"]

MAX_DELAY_S = 0.2  # [s] longest actuation or sensing delay accepted: ten 50 Hz control periods

FRICTION_RANGE = (0.05, 2.0)
"""Sliding friction coefficients accepted, both ends included. Ice on rubber is about 0.05 and nothing a quadruped
walks on exceeds 2 (MuJoCo's default is 1, the shipped scenarios draw 0.4-1.0); below 0.05 no controller can stand and
MuJoCo's contact solver meets forces it cannot resolve (a run of ``friction = [1e-10, 1e-10]`` blew up)."""

PAYLOAD_KG_RANGE = (-1.0, 10.0)
"""Extra trunk mass accepted [kg]: from 1 kg lighter to 10 kg heavier, the robots' own payload ratings (A1 5 kg,
Go1 3-5 kg) with margin; more than the robot's ~12 kg trunk would crush it at the first tick, not test it."""

MOTOR_STRENGTH_RANGE = (0.1, 2.0)
"""Motor strength factors accepted: below 0.1 the motors cannot carry the robot's weight at all, above 2 they
exceed any motor the robots have."""


@dataclass(frozen=True, kw_only=True)
class DomainParams:
    """Physical parameters that differ between the model and a real robot.

    Attributes:
        payload_mass: extra mass on the trunk [kg], in `PAYLOAD_KG_RANGE` (negative: a lighter trunk).
        payload_com: where that mass sits in the trunk frame, shape (3,) [m].
        friction: sliding friction coefficient between feet/links and the ground, in `FRICTION_RANGE`.
        motor_strength: multiplies every motor's output torque and torque limit (1.0 = nominal); a scalar or one
            value per actuated joint, each in `MOTOR_STRENGTH_RANGE`.
        actuation_delay: a command written at time t reaches the motors at t + actuation_delay [s], in [0, 0.2]
            (the simulator rounds it to whole physics steps); the motor law keeps running under the command that
            last arrived.
        sensing_delay: what the sensors report is what they measured sensing_delay earlier [s], in [0, 0.2]
            (rounded to whole physics steps too).
    """

    payload_mass: float = 0.0
    payload_com: np.ndarray = field(default_factory=lambda: np.zeros(3))
    friction: float = 1.0
    motor_strength: float | np.ndarray = 1.0
    actuation_delay: float = 0.0
    sensing_delay: float = 0.0

    def __post_init__(self) -> None:
        lo, hi = PAYLOAD_KG_RANGE
        if not lo <= self.payload_mass <= hi:  # NaN fails too
            raise ConfigError(f"DomainParams.payload_mass must be in [{lo:g}, {hi:g}] kg, got {self.payload_mass}")
        lo, hi = FRICTION_RANGE
        if not lo <= self.friction <= hi:
            raise ConfigError(f"DomainParams.friction must be in [{lo:g}, {hi:g}], got {self.friction}")
        lo, hi = MOTOR_STRENGTH_RANGE
        strength = np.asarray(self.motor_strength, dtype=np.float64)
        if not np.all((strength >= lo) & (strength <= hi)):
            raise ConfigError(f"DomainParams.motor_strength must be in [{lo:g}, {hi:g}], got {self.motor_strength}")
        for name in ("actuation_delay", "sensing_delay"):
            value = getattr(self, name)
            if not 0.0 <= value <= MAX_DELAY_S:  # NaN fails too
                raise ConfigError(f"DomainParams.{name} must be in [0, {MAX_DELAY_S:g}] s, got {value}")
        com = np.asarray(self.payload_com, dtype=np.float64)
        if com.shape != (3,):
            raise ConfigError(f"DomainParams.payload_com must have shape (3,), got {com.shape}")
        object.__setattr__(self, "payload_com", com)


@dataclass(frozen=True, kw_only=True)
class SensorNoise:
    """Standard deviations of white noise added to what `read()` reports (zero: exact sensors).

    Attributes:
        q: joint positions [rad].
        dq: joint velocities [rad/s].
        gyro: angular velocity [rad/s].
        accel: accelerometer [m/s^2].
        orientation: small random rotation of the IMU quaternion [rad].
        foot_force: foot force sensors [N].
    """

    q: float = 0.0
    dq: float = 0.0
    gyro: float = 0.0
    accel: float = 0.0
    orientation: float = 0.0
    foot_force: float = 0.0

    @property
    def enabled(self) -> bool:
        """True if any noise is added."""
        return any(v > 0 for v in (self.q, self.dq, self.gyro, self.accel, self.orientation, self.foot_force))
