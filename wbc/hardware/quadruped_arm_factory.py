"""Build the whole real robot from names and addresses: `SafeRobot(QuadrupedArmRobot(UnitreeRobot, DynamixelArm))`.

`build_quadruped_arm_robot` is what a hardware run or a check calls with a robot name (``a1-wx200``, ``go1-arm``), an
arm mode and the two addresses: the legs' UDP target and the arm's serial port. Legs and arm each get their backend,
`QuadrupedArmRobot` joins them into one 15-joint robot (12 in mode ``locked``, where the arm's servos hold it
stowed), and `SafeRobot` wraps the whole, with the legs' ranges checked against Unitree's PositionLimit table.
`build_arm` is the arm alone.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

from wbc.errors import ConfigError, UnknownNameError
from wbc.hardware.dynamixel.arm_config import ARM_ROBOTS, DynamixelArmConfig
from wbc.hardware.dynamixel.arm_robot import DynamixelArm
from wbc.hardware.quadruped_arm_robot import QuadrupedArmConfig, QuadrupedArmRobot
from wbc.hardware.safety import SafeRobot, SafetyConfig
from wbc.hardware.unitree.robot import DESCRIPTIONS, UnitreeRobot, UnitreeRobotConfig
from wbc.hardware.unitree.target import is_loopback
from wbc.robots.description import ARM_MODES

__all__ = ["build_arm", "build_quadruped_arm_robot"]

_WIRE = {description: wire for wire, description in DESCRIPTIONS.items()}


def build_arm(robot: str, port: str, *, handlers: Callable[[str], tuple[Any, Any]] | None = None,
              **settings: Any) -> DynamixelArm:
    """The WX200 of `robot` on serial device `port`, not connected.

    Args:
        robot: ``a1-wx200`` or ``go1-arm``.
        port: the U2D2's device (e.g. ``/dev/ttyUSB0``) or an emulator's pseudo-terminal.
        handlers: dynamixel_sdk's handlers for the port (`DynamixelArm`); None: the SDK's own.
        **settings: any other `DynamixelArmConfig` field (``rate_hz``, ``latency_ms`` ...).

    Raises:
        UnknownNameError: `robot` carries no WX200.
        ConfigError: a setting out of range (the message names it).
    """
    return DynamixelArm(DynamixelArmConfig(robot=robot, port=port, **settings), handlers=handlers)


def build_quadruped_arm_robot(robot: str, arm_mode: str, *, target: tuple[str, int] | None = None,
                              port: str | None = None, allow_hardware: bool = False,
                              legs: UnitreeRobotConfig | None = None, arm: DynamixelArmConfig | None = None,
                              safety: SafetyConfig | None = None,
                              handlers: Callable[[str], tuple[Any, Any]] | None = None) -> SafeRobot:
    """The whole robot behind the safety layer, not connected.

    Args:
        robot: ``a1-wx200`` or ``go1-arm``.
        arm_mode: ``none`` (legs only), ``locked`` (the arm's servos hold it stowed; 12 joints) or ``actuated``
            (15 joints).
        target: the legs' (host, UDP port); a host outside 127.0.0.0/8 needs `allow_hardware`. Not needed when
            `legs` is given.
        port: the arm's serial device; needed in modes ``locked`` and ``actuated`` unless `arm` is given.
        allow_hardware: a real robot is meant (the legs' address policy; the local address becomes 0.0.0.0).
        legs: the legs' link in full, instead of `target` (its robot must be `robot`'s legs).
        arm: the arm's bus in full, instead of `port` (its robot must be `robot`).
        safety: the safety layer's thresholds; default: Unitree's PositionLimit table of the legs.
        handlers: dynamixel_sdk's handlers for the arm's port (`DynamixelArm`); None: the SDK's own.

    Raises:
        UnknownNameError: an unknown robot or arm mode.
        ConfigError: an address or a config missing for the mode, or one that belongs to another robot.
    """
    if robot not in ARM_ROBOTS:
        raise UnknownNameError("robot with an arm", robot, ARM_ROBOTS)
    if arm_mode not in ARM_MODES:
        raise UnknownNameError("arm mode", arm_mode, ARM_MODES)
    wire = _WIRE[robot]
    if legs is None:
        if target is None:
            raise ConfigError(f"{robot}: give the legs' UDP target (HOST, PORT), e.g. the emulator's address")
        host, udp_port = target
        legs = UnitreeRobotConfig(robot=wire, target_host=host, target_port=udp_port, allow_hardware=allow_hardware,
                                  local_host="127.0.0.1" if is_loopback(host) else "0.0.0.0")
    elif legs.robot != wire:
        raise ConfigError(f"{robot}: the legs' config is for the {legs.robot}, expected the {wire}")
    arm_device = None
    if arm_mode == "none":
        if port is not None or arm is not None:
            raise ConfigError(f"{robot}: arm mode 'none' drives no arm; leave out the serial port, or choose "
                              "'locked' or 'actuated'")
    else:
        if arm is None:
            if port is None:
                raise ConfigError(f"{robot}: arm mode {arm_mode!r} drives the arm's servos: give its serial port "
                                  "(the U2D2, e.g. /dev/ttyUSB0, or the emulator's pty)")
            arm = DynamixelArmConfig(robot=robot, port=port)
        elif arm.robot != robot:
            arm = dataclasses.replace(arm, robot=robot)
        arm_device = DynamixelArm(arm, handlers=handlers)
    joined = QuadrupedArmRobot(UnitreeRobot(legs), arm_device, QuadrupedArmConfig(arm_mode=arm_mode))
    return SafeRobot(joined, safety if safety is not None else SafetyConfig(position_table=wire))
