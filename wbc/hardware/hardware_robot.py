"""The one place a real robot is built from its name: `HardwareRobotConfig` in, `HardwareRobot` out.

A hardware trial, a bring-up script or a bench names the robot as the arena does (``go1-arm``, ``a1-wx200``), its arm
mode and where its parts are reached; `build_hardware_robot` picks the backends and hands back the (unconnected)
robot with what a caller needs around it: the description to control and draw, the backend's name for the records and
the leg position table its safety layer checks against.

The legs are a `UnitreeRobot` (12 motors over the Unitree low-level wire). The arm is a second device, the WX200 on
its Dynamixel bus (`wbc.hardware.dynamixel.DynamixelArm`), joined to the legs into one robot by `QuadrupedArmRobot`:
in mode ``actuated`` (15 joints) the controller drives it; in mode ``locked`` its servos hold it stowed (12 joints),
or, when no serial port is given, it is fixed on the trunk mechanically and the legs' wire alone drives the robot; in
mode ``none`` there is no arm.

Both devices read the time from one `Clock` (`wbc.hardware.clock`): the monotonic clock on a robot, a `ManualClock`
in a deterministic test, which also hands in the legs' datagram channel (an emulator's in-process transport).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from wbc.errors import ConfigError, UnknownNameError
from wbc.hardware.clock import MONOTONIC, Clock
from wbc.hardware.dynamixel.arm_config import DynamixelArmConfig
from wbc.hardware.dynamixel.arm_robot import DynamixelArm
from wbc.hardware.quadruped_arm_robot import QuadrupedArmConfig, QuadrupedArmRobot
from wbc.hardware.realtime import RealtimeRequest
from wbc.hardware.robot import Robot
from wbc.hardware.serial_port_policy import check_serial_port
from wbc.hardware.unitree.robot import DESCRIPTIONS, UnitreeRobot, UnitreeRobotConfig
from wbc.hardware.unitree.target import is_loopback
from wbc.hardware.unitree.transport import Transport
from wbc.robots.description import ARM_MODES, RobotDescription, check_arm_mode
from wbc.robots.registry import get_robot

__all__ = ["HARDWARE_ARM_MODES", "HARDWARE_ROBOTS", "HardwareRobot", "HardwareRobotConfig", "build_hardware_robot"]

HARDWARE_ROBOTS: dict[str, str] = {description: unitree for unitree, description in DESCRIPTIONS.items()}
"""Robot registry name -> the Unitree quadruped under it (the name its wire codec and its SDK tables use)."""

HARDWARE_ARM_MODES = ARM_MODES
"""Arm modes a real robot can be built with: ``none``, ``locked`` (held by its servos, or fixed mechanically when no
serial port is given) and ``actuated`` (its serial port needed)."""


@dataclass(frozen=True, kw_only=True)
class HardwareRobotConfig:
    """Which real robot, and how its parts are reached.

    Attributes:
        robot: robot registry name, one of `HARDWARE_ROBOTS` (``go1-arm``, ``a1-wx200``).
        arm_mode: ``none`` (no arm), ``locked`` (the arm held stowed: by its servos when `arm_port` is given, else
            fixed mechanically) or ``actuated`` (the controller drives it; needs `arm_port`).
        legs_host: the legs' low-level UDP address (IPv4 literal); there is no default, and an address outside
            127.0.0.0/8 needs `allow_hardware`.
        legs_port: its UDP port.
        local_host: the address the legs' link binds (None: 127.0.0.1 for a loopback target, else 0.0.0.0).
        local_port: the port it binds; 0 picks a free one.
        allow_hardware: allow targets outside 127.0.0.0/8 and an arm port that is not a pseudo-terminal (a real
            robot, a real arm): one consent for every device (`check_target`, `check_serial_port`).
        rate_hz: the legs' link rate, 200..1000 [Hz].
        transport: the legs' datagram channel, ``udp`` or ``sdk`` (`UnitreeRobotConfig.transport`).
        arm_port: the arm's serial device (the U2D2, e.g. ``/dev/ttyUSB0``, or an emulator's pseudo-terminal).
        arm: the arm's bus in full (`DynamixelArmConfig`: rate, latency timer, watchdog ...) instead of `arm_port`;
            its ``robot`` is set to `robot`.
        realtime: what the I/O process asks the OS for before it starts the devices' threads (`RealtimeRequest`:
            real-time scheduling, a CPU of its own, locked memory; `NO_REALTIME`: nothing). Only the I/O process
            (`wbc.hardware.io_process.ProcessRobot`) applies it: a robot built in the controller's process never
            changes that process's scheduling.
    """

    robot: str
    arm_mode: str
    legs_host: str
    legs_port: int
    local_host: str | None = None
    local_port: int = 0
    allow_hardware: bool = False
    rate_hz: float = 500.0
    transport: str = "udp"
    arm_port: str | None = None
    arm: DynamixelArmConfig | None = None
    realtime: RealtimeRequest = field(default_factory=RealtimeRequest)

    def __post_init__(self) -> None:
        if self.robot not in HARDWARE_ROBOTS:
            raise UnknownNameError("hardware robot", self.robot, tuple(HARDWARE_ROBOTS))
        check_arm_mode(self.arm_mode)
        if self.arm_port is not None and self.arm is not None:
            raise ConfigError("HardwareRobotConfig: give the arm's serial port (arm_port) or its whole bus config "
                              "(arm), not both")
        has_arm = self.arm_port is not None or self.arm is not None
        if self.arm_mode == "none" and has_arm:
            raise ConfigError(f"arm mode 'none' on the {self.robot} drives no arm; leave out the arm's serial port, "
                              "or choose 'locked' or 'actuated'")
        if self.arm_mode == "actuated" and not has_arm:
            raise ConfigError(f"arm mode 'actuated' on the {self.robot} drives the arm's servos: give its serial port "
                              "(the U2D2, e.g. /dev/ttyUSB0, or the emulator's pseudo-terminal; --arm-port)")
        # the robot's consent covers its arm: a whole bus config does not bring its own
        if self.arm_port is not None:
            check_serial_port(self.arm_port, allow_hardware=self.allow_hardware, what="HardwareRobotConfig.arm_port")
        if self.arm is not None:
            check_serial_port(self.arm.port, allow_hardware=self.allow_hardware, what="HardwareRobotConfig.arm.port")


@dataclass(frozen=True)
class HardwareRobot:
    """A real robot, built and not yet connected.

    Attributes:
        robot: the robot (connect it, or wrap it in `wbc.hardware.safety.SafeRobot` first).
        description: what it is (quadruped, arm, arm mode): what a controller drives and a viewer draws.
        backend: the backend's name, as results record it (``unitree``, or ``unitree+dynamixel`` with the arm's
            bus).
        position_table: the leg position table its safety layer checks measured joints against (``go1``, ``a1``:
            the SDK's PositionLimit table; see `wbc.hardware.safety.SafetyConfig.position_table`).
        target: where its parts are reached, for messages and reports (``legs udp 127.0.0.1:9000, arm serial
            /dev/ttyUSB0``).
    """

    robot: Robot
    description: RobotDescription
    backend: str
    position_table: str
    target: str


def build_hardware_robot(config: HardwareRobotConfig, *, clock: Clock = MONOTONIC,
                         legs_transport: Transport | None = None,
                         arm_handlers: Callable[[str], tuple[Any, Any]] | None = None) -> HardwareRobot:
    """Build the real robot `config` names; nothing is connected and no socket exists yet.

    Args:
        config: which robot, and where its parts are reached.
        clock: the clock both devices run on (`UnitreeRobot`, `DynamixelArm`): the monotonic clock on a robot, a
            `ManualClock` in a deterministic test.
        legs_transport: the legs' datagram channel (e.g. `UnitreeEmulator.transport`); None: the one
            `config.transport` names, built at connect.
        arm_handlers: the arm's port and packet handlers (`DynamixelArm`'s `handlers`, e.g.
            `RobotEmulator.arm_handlers`); None: the serial port's.

    Raises:
        TargetRefusedError: a target outside 127.0.0.0/8 without `allow_hardware`, or not an IPv4 literal (the arm's
            port is checked when the config is built).
        ConfigError: an invalid rate, or an arm setting out of range (the message names it).
    """
    unitree = HARDWARE_ROBOTS[config.robot]
    local_host = config.local_host
    if local_host is None:
        local_host = "127.0.0.1" if is_loopback(config.legs_host) else "0.0.0.0"
    legs = UnitreeRobot(UnitreeRobotConfig(
        robot=unitree, target_host=config.legs_host, target_port=config.legs_port, local_host=local_host,
        local_port=config.local_port, allow_hardware=config.allow_hardware, rate_hz=config.rate_hz,
        transport=config.transport), legs_transport, clock=clock)
    description = get_robot(config.robot, config.arm_mode)
    target = f"legs {config.transport} {config.legs_host}:{config.legs_port}"
    arm_config = config.arm
    if arm_config is None and config.arm_port is not None:
        arm_config = DynamixelArmConfig(robot=config.robot, port=config.arm_port, allow_hardware=config.allow_hardware)
    if arm_config is None:
        return HardwareRobot(robot=legs, description=description, backend="unitree", position_table=unitree,
                             target=target)
    arm = DynamixelArm(dataclasses.replace(arm_config, robot=config.robot), arm_handlers, clock=clock)
    joined = QuadrupedArmRobot(legs, arm, QuadrupedArmConfig(arm_mode=config.arm_mode))
    return HardwareRobot(robot=joined, description=description, backend="unitree+dynamixel", position_table=unitree,
                         target=f"{target}, arm serial {arm_config.port}")
