"""Units of the XM430-W350's registers, and what they mean in SI: one place for every conversion.

Position: 4096 ticks per turn, 2048 = 0 rad (the middle of the single-turn range). Velocity: 0.229 rpm per unit.
Current: 2.69 mA per unit. Voltage: 0.1 V. Temperature: 1 deg C. PWM: 885 = 100 % of the supply voltage. Bus
Watchdog: 20 ms per unit. Return Delay Time: 2 us per unit.

Torque is not a register. The servo measures current; `TORQUE_CONSTANT` turns it into output torque. It is the
datasheet's stall figures at 12 V, 4.1 N m at 2.3 A (1.78 N m/A at the output shaft, gearbox losses included).
The real relation is not linear: friction costs current at low torque, and efficiency changes with speed.
`position_gains_to_pd` and `velocity_gain_to_kd` are likewise stated approximations. They turn the servo's own
controller gains into the Unitree-style PD gains a simulator applies. ROBOTIS does not publish the exact
internal loop.
"""

from __future__ import annotations

import math

__all__ = [
    "CENTER_TICKS",
    "CURRENT_UNIT",
    "NO_LOAD_SPEED",
    "PWM_MAX",
    "RAD_PER_TICK",
    "STALL_TORQUE",
    "TICKS_PER_TURN",
    "TORQUE_CONSTANT",
    "VELOCITY_UNIT",
    "VOLTAGE_UNIT",
    "WATCHDOG_UNIT",
    "RETURN_DELAY_UNIT",
    "current_to_units",
    "position_gains_to_pd",
    "rad_to_ticks",
    "ticks_to_rad",
    "torque_to_current",
    "units_to_current",
    "velocity_gain_to_kd",
    "velocity_to_units",
    "units_to_velocity",
]

TICKS_PER_TURN = 4096
CENTER_TICKS = 2048
"""Present Position of the middle of the range: 0 rad in the joint convention `WX200_BUS` uses."""
RAD_PER_TICK = 2.0 * math.pi / TICKS_PER_TURN  # [rad] 0.088 deg
VELOCITY_UNIT = 0.229 * 2.0 * math.pi / 60.0  # [rad/s] per unit of the velocity registers (0.229 rpm)
CURRENT_UNIT = 2.69e-3  # [A] per unit of the current registers
VOLTAGE_UNIT = 0.1  # [V]
PWM_MAX = 885  # PWM register value of 100 % duty
WATCHDOG_UNIT = 0.020  # [s] per unit of Bus Watchdog (98)
RETURN_DELAY_UNIT = 2e-6  # [s] per unit of Return Delay Time (9)

STALL_TORQUE = 4.1  # [N m] XM430-W350 at 12 V (datasheet)
STALL_CURRENT = 2.3  # [A] at 12 V (datasheet)
NO_LOAD_SPEED = 46.0 * 2.0 * math.pi / 60.0  # [rad/s] at 12 V (datasheet: 46 rpm)
TORQUE_CONSTANT = STALL_TORQUE / STALL_CURRENT  # [N m / A] output torque per motor current (see module doc)

_POSITION_P_SCALE = 128.0  # the e-Manual's K_PP = Position P Gain / 128
_POSITION_D_SCALE = 16.0  # K_PD = Position D Gain / 16
_VELOCITY_P_SCALE = 128.0  # K_VP = Velocity P Gain / 128
_D_TIME_BASE = 1e-3  # [s] the derivative's time base assumed below (one step of the servo's 1 kHz loop)


def ticks_to_rad(ticks: float) -> float:
    """Radians from 0 at `CENTER_TICKS`, in the register's direction (the drive mode's reverse bit applied)."""
    return (ticks - CENTER_TICKS) * RAD_PER_TICK


def rad_to_ticks(rad: float) -> int:
    """The nearest tick to `rad` (0 rad = `CENTER_TICKS`), as the encoder reports it."""
    return CENTER_TICKS + round(rad / RAD_PER_TICK)


def units_to_velocity(units: float) -> float:
    """Velocity register value -> [rad/s]."""
    return units * VELOCITY_UNIT


def velocity_to_units(rad_per_s: float) -> int:
    """[rad/s] -> the nearest velocity register value."""
    return round(rad_per_s / VELOCITY_UNIT)


def units_to_current(units: float) -> float:
    """Current register value -> [A]."""
    return units * CURRENT_UNIT


def current_to_units(amps: float) -> int:
    """[A] -> the nearest current register value."""
    return round(amps / CURRENT_UNIT)


def torque_to_current(torque: float) -> float:
    """Output torque [N m] -> motor current [A] through `TORQUE_CONSTANT`."""
    return torque / TORQUE_CONSTANT


def position_gains_to_pd(p_gain: int, d_gain: int) -> tuple[float, float]:
    """The joint-space PD gains that stand for the servo's position controller.

    The e-Manual's position loop is ``out = K_PP e + K_PD de/dt`` with ``K_PP = P / 128`` and ``K_PD = D / 16``,
    the error ``e`` in ticks. Here ``out`` is taken in current units, and ``de/dt`` per millisecond (one step of the
    servo's loop). Then ``kp = K_PP * (ticks/rad) * CURRENT_UNIT * TORQUE_CONSTANT`` [N m/rad], and kd likewise
    with the 1 ms time base [N m s/rad]. The factory P gain of 800 gives 19.5 N m/rad per servo, so 0.1 rad of
    error costs about 2 N m, half the stall torque. This is an approximation, not ROBOTIS's internal loop (in
    position mode (3) the loop drives the PWM, not the current; 885 PWM units are close to the 855 current units of
    the stall current, so the scale stays close).

    Args:
        p_gain: Position P Gain (84).
        d_gain: Position D Gain (80).

    Returns:
        (kp [N m/rad], kd [N m s/rad]) of one servo.
    """
    amps_per_rad = CURRENT_UNIT / RAD_PER_TICK
    kp = p_gain / _POSITION_P_SCALE * amps_per_rad * TORQUE_CONSTANT
    kd = d_gain / _POSITION_D_SCALE * amps_per_rad * _D_TIME_BASE * TORQUE_CONSTANT
    return kp, kd


def velocity_gain_to_kd(p_gain: int) -> float:
    """The joint damping gain that stands for the servo's velocity controller.

    Its proportional part only (``K_VP = P / 128`` per velocity unit, output in current units); the integral part
    (Velocity I Gain) is left out. It is an approximation, as in `position_gains_to_pd`.

    Args:
        p_gain: Velocity P Gain (78).

    Returns:
        kd [N m s/rad] of one servo.
    """
    return p_gain / _VELOCITY_P_SCALE * CURRENT_UNIT / VELOCITY_UNIT * TORQUE_CONSTANT
