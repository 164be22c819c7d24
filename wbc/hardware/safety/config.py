"""`SafetyConfig`: the thresholds, gains and timings of the safety layer `SafeRobot`.

Defaults follow what Unitree's SDK and the deployments built on it do:
Unitree's passive damping (Kp 0, Kd 3), PositionProtect's 0.087 rad margin, PowerProtect's consecutive-frame rule
(but latched here), and a ramp from the measured pose with Unitree's example gains (Kp 5, Kd 1).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from wbc.errors import ConfigError
from wbc.hardware.safety.events import SafetyEvent
from wbc.hardware.safety.limits import check_position_table

__all__ = ["SafetyConfig"]


@dataclass(frozen=True, kw_only=True)
class SafetyConfig:
    """Configuration of `SafeRobot`.

    Attributes:
        damping_kd: velocity gain of the damping command on leg joints (Kp 0) [N m s / rad]; Unitree's passive
            mode uses 3.
        arm_damping_kd: the same on arm joints (indices 12..) [N m s / rad]; the arm's links are light, and its
            stand hold uses 0.5.
        stale_timeout_s: longest time the state tick may stay unchanged while ramping or running [s].
        position_table: the leg joint ranges a measured position is checked against: ``robot`` (the robot's own
            `JointTable`), or ``go1`` / ``a1`` (Unitree's PositionLimit table); arm joints always use the robot's.
        joint_margin: how far beyond its range a measured joint may go before the layer trips [rad]; Unitree's
            PositionProtect uses 0.087 (5 degrees).
        power_limit_w: limit on the measured mechanical power sum |tau_est dq| over all joints [W].
        power_frames: the layer trips when the power is above the limit on more than this many consecutive fresh
            frames (PowerProtect's rule, which uses 5).
        max_motor_temperature_c: hottest motor temperature allowed, for robots that report it [degC].
        ok_motor_modes: motor modes that are not faults, for robots that report them (0x0A servo, 0 off/damping).
        max_tilt: largest |roll| or |pitch| of the trunk, from the IMU quaternion, before it counts as a fall [rad].
        ramp_time_s: time over which the gains and the feed-forward are blended from the ramp's start values into
            the controller's [s]; the ramp also lasts until the slewed targets have caught up.
        ramp_slew: largest speed of the commanded joint targets during the ramp [rad/s].
        ramp_hold_s: how long the ramp's first command (the measured pose, start gains) is held before the targets
            move [s]; a few link periods, so that the hold reaches the motors even when a late loop writes twice
            within one period of a link that sends only the newest command.
        ramp_kp: position gain at the start of the ramp [N m / rad] (Unitree's example: 5).
        ramp_kd: velocity gain at the start of the ramp [N m s / rad] (Unitree's example: 1).
        on_event: called with every `SafetyEvent`; None prints it to standard error.
    """

    damping_kd: float = 3.0
    arm_damping_kd: float = 0.5
    stale_timeout_s: float = 0.1
    position_table: str = "robot"
    joint_margin: float = 0.087
    power_limit_w: float = 500.0
    power_frames: int = 5
    max_motor_temperature_c: float = 70.0
    ok_motor_modes: tuple[int, ...] = (0x00, 0x0A)
    max_tilt: float = 1.0
    ramp_time_s: float = 1.0
    ramp_slew: float = 1.0
    ramp_hold_s: float = 0.01
    ramp_kp: float = 5.0
    ramp_kd: float = 1.0
    on_event: Callable[[SafetyEvent], None] | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        positive = ("stale_timeout_s", "power_limit_w", "ramp_time_s", "ramp_slew", "max_motor_temperature_c")
        non_negative = ("damping_kd", "arm_damping_kd", "joint_margin", "ramp_kp", "ramp_kd", "ramp_hold_s")
        for name in positive:
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ConfigError(f"SafetyConfig.{name} must be a positive finite number, got {value!r}")
        for name in non_negative:
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise ConfigError(f"SafetyConfig.{name} must be a finite number >= 0, got {value!r}")
        if not (isinstance(self.power_frames, int) and self.power_frames >= 0):
            raise ConfigError(f"SafetyConfig.power_frames must be an integer >= 0, got {self.power_frames!r}")
        if not 0 < self.max_tilt < math.pi:
            raise ConfigError(f"SafetyConfig.max_tilt must be in (0, pi) rad, got {self.max_tilt!r}")
        check_position_table(self.position_table)
