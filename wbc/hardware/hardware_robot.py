"""The one place a real robot is built from its name: `HardwareRobotConfig` in, `HardwareRobot` out.

A hardware trial, a bring-up script or a bench names the robot as the arena does (``go1-arm``, ``a1-wx200``), its arm
mode and where its parts are reached; `build_hardware_robot` picks the backends and hands back the (unconnected)
robot with what a caller needs around it: the description to control and draw, the backend's name for the records and
the leg position table its safety layer checks against.

Today the Unitree low-level wire drives the whole robot when the arm is absent (``none``) or held on the trunk
(``locked``: fixed mechanically or held by its own servos, commanded by nobody here): a `UnitreeRobot` for the 12 leg
motors. An actuated arm is a second device (the WX200 on its Dynamixel bus) combined with the legs into one 15-joint
robot; those backends are not part of this version, and ``actuated`` is refused with a message naming them.
"""

from __future__ import annotations

from dataclasses import dataclass

from wbc.errors import ConfigError, UnknownNameError
from wbc.hardware.robot import Robot
from wbc.hardware.unitree.robot import DESCRIPTIONS, UnitreeRobot, UnitreeRobotConfig
from wbc.hardware.unitree.target import is_loopback
from wbc.robots.description import RobotDescription, check_arm_mode
from wbc.robots.registry import get_robot

__all__ = ["HARDWARE_ARM_MODES", "HARDWARE_ROBOTS", "HardwareRobot", "HardwareRobotConfig", "build_hardware_robot"]

HARDWARE_ROBOTS: dict[str, str] = {description: unitree for unitree, description in DESCRIPTIONS.items()}
"""Robot registry name -> the Unitree quadruped under it (the name its wire codec and its SDK tables use)."""

HARDWARE_ARM_MODES = ("none", "locked")
"""Arm modes a real robot can be built with in this version: the legs' wire alone drives the whole robot."""


@dataclass(frozen=True, kw_only=True)
class HardwareRobotConfig:
    """Which real robot, and how its parts are reached.

    Attributes:
        robot: robot registry name, one of `HARDWARE_ROBOTS` (``go1-arm``, ``a1-wx200``).
        arm_mode: ``none`` (no arm) or ``locked`` (the arm on the trunk, held); ``actuated`` is refused today.
        legs_host: the legs' low-level UDP address (IPv4 literal); there is no default, and an address outside
            127.0.0.0/8 needs `allow_hardware`.
        legs_port: its UDP port.
        local_host: the address the legs' link binds (None: 127.0.0.1 for a loopback target, else 0.0.0.0).
        local_port: the port it binds; 0 picks a free one.
        allow_hardware: allow targets outside 127.0.0.0/8 (a real robot).
        rate_hz: the legs' link rate, 200..1000 [Hz].
    """

    robot: str
    arm_mode: str
    legs_host: str
    legs_port: int
    local_host: str | None = None
    local_port: int = 0
    allow_hardware: bool = False
    rate_hz: float = 500.0

    def __post_init__(self) -> None:
        if self.robot not in HARDWARE_ROBOTS:
            raise UnknownNameError("hardware robot", self.robot, tuple(HARDWARE_ROBOTS))
        check_arm_mode(self.arm_mode)
        if self.arm_mode not in HARDWARE_ARM_MODES:
            raise ConfigError(
                f"arm mode {self.arm_mode!r} on a real {self.robot}: an actuated arm needs the arm's own backend (the "
                "WX200 on its Dynamixel bus, a DynamixelArm) and the robot that joins it to the legs (a 15-joint "
                "QuadrupedArmRobot), which this version does not have; valid arm modes on hardware today: "
                f"{', '.join(HARDWARE_ARM_MODES)} (the Unitree wire drives the whole robot)")


@dataclass(frozen=True)
class HardwareRobot:
    """A real robot, built and not yet connected.

    Attributes:
        robot: the robot (connect it, or wrap it in `wbc.hardware.safety.SafeRobot` first).
        description: what it is (quadruped, arm, arm mode): what a controller drives and a viewer draws.
        backend: the backend's name, as results record it (``unitree``).
        position_table: the leg position table its safety layer checks measured joints against (``go1``, ``a1``:
            the SDK's PositionLimit table; see `wbc.hardware.safety.SafetyConfig.position_table`).
        target: where its parts are reached, for messages and reports (``legs udp 127.0.0.1:9000``).
    """

    robot: Robot
    description: RobotDescription
    backend: str
    position_table: str
    target: str


def build_hardware_robot(config: HardwareRobotConfig) -> HardwareRobot:
    """Build the real robot `config` names; nothing is connected and no socket exists yet.

    Raises:
        TargetRefusedError: a target outside 127.0.0.0/8 without `allow_hardware`, or not an IPv4 literal.
        ConfigError: an invalid rate.
    """
    unitree = HARDWARE_ROBOTS[config.robot]
    local_host = config.local_host
    if local_host is None:
        local_host = "127.0.0.1" if is_loopback(config.legs_host) else "0.0.0.0"
    legs = UnitreeRobot(UnitreeRobotConfig(
        robot=unitree, target_host=config.legs_host, target_port=config.legs_port, local_host=local_host,
        local_port=config.local_port, allow_hardware=config.allow_hardware, rate_hz=config.rate_hz))
    return HardwareRobot(robot=legs, description=get_robot(config.robot, config.arm_mode), backend="unitree",
                         position_table=unitree, target=f"legs udp {config.legs_host}:{config.legs_port}")
