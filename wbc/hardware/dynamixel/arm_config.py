"""`DynamixelArmConfig`: the serial port, the bus rate, the fault handling and the torque policies of `DynamixelArm`.

Every value is checked when the config is built, and a wrong one names its field and its valid range. A port that is
not an emulator's (a real adapter such as ``/dev/ttyUSB0``) is refused unless ``allow_hardware=True``
(`wbc.hardware.serial_port_policy.check_serial_port`), before anything could open it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from wbc.errors import ConfigError, UnknownNameError
from wbc.hardware.dynamixel.control_table import BAUD_RATES
from wbc.hardware.dynamixel.units import CURRENT_UNIT, STALL_CURRENT, WATCHDOG_UNIT
from wbc.hardware.dynamixel.wx200_bus import WX200_ARM_JOINTS, WX200_BAUD_RATE, WX200_SERVOS, ArmJointMap, ServoSpec
from wbc.hardware.serial_port_policy import check_serial_port

__all__ = ["ARM_ROBOTS", "DynamixelArmConfig"]

ARM_ROBOTS = ("a1-wx200", "go1-arm")
"""Robot descriptions that carry the WX200 and whose arm joint table `DynamixelArm` takes."""


@dataclass(frozen=True, kw_only=True)
class DynamixelArmConfig:
    """Configuration of the arm's bus and of its backend.

    Attributes:
        port: the serial device of the U2D2 (``/dev/ttyUSB0``, or the udev name ``/dev/ttyDXL``), or an emulator's
            pseudo-terminal. There is no default, and no other device is ever opened. A device that is not a
            pseudo-terminal needs `allow_hardware`.
        allow_hardware: allow a `port` that is not an emulator's pseudo-terminal (a real adapter and a real arm).
        robot: the description whose arm joints (names, ranges, torque limits) the backend reports.
        baud_rate: the bus's rate [bit/s]; the WX200's servos run at 1 Mbps.
        latency_ms: the adapter's latency timer [ms]; it sets the reply timeout (about 2 x latency + 2 ms).
        rate_hz: the bus thread's rate: one sync read and one sync write per cycle [Hz].
        status_every: cycles between two reads of the servos' status. Hardware errors and temperatures with
            input voltages are read in turn, so each is read every ``2 * status_every`` cycles.
        retries: how often a failed read is tried again (after a flush) before the failing ID is identified.
        retry_wait_s: wait before the flush that precedes a retry, so that a late answer is dropped, not read as the
            next one's [s].
        watchdog_s: the joint servos' Bus Watchdog [s], a multiple of 20 ms. A servo that hears nothing for this long
            sets its goal current to 0 (the arm goes limp).
        write_deadline: longest gap between two `write` calls before the bus thread damps the arm [s].
        damping_kd: the host's damping gain [N m s / rad], used before the first write, after the write deadline,
            after a latched fault and while closing.
        close_damping: how long `close` damps before it parks the arm [s].
        park_current_a: the current bound of the position hold the arm is parked in when closed [A].
        max_current_a: the largest current the host asks of one servo [A]; the joints' torque limits follow from it
            (the datasheet's stall current by default). The servos' Current Limit must not be lower.
        held_ticks: goal positions of the servos without a model joint (wrist angle, wrist rotate, gripper) [ticks];
            None holds a servo where it is. The default holds the wrist at 0 rad, the pose the model lumps it at.
        held_profile_velocity: Profile Velocity of the held servos, so that they reach their goal slowly [0.229 rpm];
            at least 1, since 0 means no limit on the XM430 (full speed).
        connect_retries: how often a start-up or park transfer (`close`) that timed out is tried again.
        connect_timeout: how long `connect` waits for the first state once the bus thread runs [s].
        servos: the servos on the bus (the WX200's, as Interbotix configures them).
        joints: the model's joints on the bus.
    """

    port: str
    robot: str = "a1-wx200"
    allow_hardware: bool = False
    baud_rate: int = WX200_BAUD_RATE
    latency_ms: float = 1.0
    rate_hz: float = 200.0
    status_every: int = 10
    retries: int = 2
    retry_wait_s: float = 0.002
    watchdog_s: float = 0.1
    write_deadline: float = 0.05
    damping_kd: float = 0.5
    close_damping: float = 0.2
    park_current_a: float = 1.0
    max_current_a: float = STALL_CURRENT
    held_ticks: tuple[int | None, int | None, int | None] = (2048, 2048, None)
    held_profile_velocity: int = 20
    connect_retries: int = 10
    connect_timeout: float = 1.0
    servos: tuple[ServoSpec, ...] = WX200_SERVOS
    joints: tuple[ArmJointMap, ...] = WX200_ARM_JOINTS

    def __post_init__(self) -> None:
        if not isinstance(self.port, str) or not self.port:
            raise ConfigError(f"DynamixelArmConfig.port must name the serial device (e.g. /dev/ttyUSB0), got "
                              f"{self.port!r}")
        if self.robot not in ARM_ROBOTS:
            raise UnknownNameError("robot with a WX200 arm", self.robot, ARM_ROBOTS)
        if self.baud_rate not in BAUD_RATES.values():
            raise ConfigError(f"DynamixelArmConfig.baud_rate must be one of {sorted(BAUD_RATES.values())} bit/s, "
                              f"got {self.baud_rate}")
        _in("latency_ms", self.latency_ms, 0.0, 32.0)
        _in("rate_hz", self.rate_hz, 10.0, 1000.0)
        _in("retry_wait_s", self.retry_wait_s, 0.0, 0.05)
        _in("damping_kd", self.damping_kd, 0.0, 5.0)
        _in("close_damping", self.close_damping, 0.0, 2.0)
        _in("park_current_a", self.park_current_a, 0.0, STALL_CURRENT)
        _in("max_current_a", self.max_current_a, CURRENT_UNIT, 1193 * CURRENT_UNIT)
        _in("connect_timeout", self.connect_timeout, 0.01, 10.0)
        if isinstance(self.held_profile_velocity, int) and self.held_profile_velocity == 0:
            raise ConfigError("DynamixelArmConfig.held_profile_velocity must be at least 1 (0.229 rpm), got 0: on the "
                              "XM430 a Profile Velocity of 0 means no limit, so connect would drive the held servos "
                              "(wrist, gripper) to their goals at full speed; the default is 20")
        for name, low, high in (("status_every", 2, 1000), ("retries", 0, 10), ("connect_retries", 0, 100),
                                ("held_profile_velocity", 1, 32767)):
            value = getattr(self, name)
            if not (isinstance(value, int) and low <= value <= high):
                raise ConfigError(f"DynamixelArmConfig.{name} must be an integer in [{low}, {high}], got {value!r}")
        units = self.watchdog_s / WATCHDOG_UNIT
        if not (1 <= round(units) <= 127 and abs(units - round(units)) < 1e-6):
            raise ConfigError(f"DynamixelArmConfig.watchdog_s must be a multiple of 0.02 s in [0.02, 2.54], got "
                              f"{self.watchdog_s}")
        if self.write_deadline < 2.0 / self.rate_hz:
            raise ConfigError(f"DynamixelArmConfig.write_deadline {self.write_deadline} s is shorter than two bus "
                              f"cycles ({2.0 / self.rate_hz} s)")
        if self.watchdog_s < 4.0 / self.rate_hz:
            raise ConfigError(f"DynamixelArmConfig.watchdog_s {self.watchdog_s} s is shorter than four bus cycles "
                              f"({4.0 / self.rate_hz} s): the servos would stop between two cycles")
        ids = [s.id for s in self.servos]
        if len(set(ids)) != len(ids):
            raise ConfigError(f"DynamixelArmConfig.servos: IDs repeat: {ids}")
        if len(self.joints) != 3:
            raise ConfigError(f"DynamixelArmConfig.joints must map the model's 3 arm joints, got {len(self.joints)}")
        for joint in self.joints:
            missing = [i for i in joint.servo_ids if i not in ids]
            if missing or joint.servo_id != joint.servo_ids[0]:
                raise ConfigError(f"DynamixelArmConfig.joints: {joint.name} needs its primary servo first and every "
                                  f"servo on the bus; servo_ids {joint.servo_ids}, bus IDs {ids}")
        held = self.held_servos
        if len(self.held_ticks) != len(held):
            raise ConfigError(f"DynamixelArmConfig.held_ticks needs one goal per held servo "
                              f"({', '.join(s.name for s in held)}), got {self.held_ticks!r}")
        for spec, ticks in zip(held, self.held_ticks, strict=True):
            if ticks is not None and not (isinstance(ticks, int) and spec.min_position <= ticks <= spec.max_position):
                raise ConfigError(f"DynamixelArmConfig.held_ticks: {spec.name} goal {ticks!r} outside its position "
                                  f"limits [{spec.min_position}, {spec.max_position}] ticks (or None: where it is)")
        check_serial_port(self.port, allow_hardware=self.allow_hardware, what="DynamixelArmConfig.port")

    @property
    def joint_servo_ids(self) -> tuple[int, ...]:
        """Every servo that drives a model joint (the shoulder's shadow included), in bus order."""
        mine = {i for j in self.joints for i in j.servo_ids}
        return tuple(s.id for s in self.servos if s.id in mine)

    @property
    def held_servos(self) -> tuple[ServoSpec, ...]:
        """The servos without a model joint, held in position mode, in bus order."""
        mine = {i for j in self.joints for i in j.servo_ids}
        return tuple(s for s in self.servos if s.id not in mine)

    @property
    def watchdog_units(self) -> int:
        """The Bus Watchdog register value (20 ms units)."""
        return round(self.watchdog_s / WATCHDOG_UNIT)


def _in(name: str, value: object, low: float, high: float) -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and low <= value <= high):
        raise ConfigError(f"DynamixelArmConfig.{name} must be a number in [{low}, {high}], got {value!r}")
