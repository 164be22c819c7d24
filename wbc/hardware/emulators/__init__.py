"""Emulated robots on 127.0.0.1 that speak a real robot's wire, backed by the MuJoCo simulator, with faults on demand.

A hardware backend's tests run against these instead of a robot: `UnitreeEmulator` (the A1 / Go1 low-level UDP
wire) and `DynamixelEmulator` (the WX200 arm's Dynamixel bus on a pseudo-terminal). `SharedPlant` is the one
simulated robot both can drive at once: legs over UDP, arm over the pty, one physics; `RobotEmulator` starts the
three as one robot. This room sits above
`wbc.hardware.mujoco` (it drives a `MujocoRobot`) and below every controller.
"""

from wbc.hardware.emulators.arm_plant import ArmPlant
from wbc.hardware.emulators.bus_faults import BUS_FAULT_DEFAULTS, BusFault
from wbc.hardware.emulators.dynamixel import BusStats, DynamixelEmulator, DynamixelEmulatorConfig
from wbc.hardware.emulators.faults import FRAME_FAULTS, STATE_FAULTS, Fault, FaultSet, apply_state_faults, mangle_frame
from wbc.hardware.emulators.logged_command import LoggedCommand
from wbc.hardware.emulators.logged_packet import LoggedPacket, RegisterRead, RegisterValue, RegisterWrite
from wbc.hardware.emulators.plant import PlantLegs, SharedPlant, SharedPlantConfig
from wbc.hardware.emulators.robot_emulator import LEG_WIRES, RobotEmulator, RobotEmulatorConfig
from wbc.hardware.emulators.servo import EmulatedServo
from wbc.hardware.emulators.unitree import MODES, EmulatorTransport, Reply, UnitreeEmulator, UnitreeEmulatorConfig

__all__ = [
    "BUS_FAULT_DEFAULTS",
    "FRAME_FAULTS",
    "LEG_WIRES",
    "MODES",
    "STATE_FAULTS",
    "ArmPlant",
    "BusFault",
    "BusStats",
    "DynamixelEmulator",
    "DynamixelEmulatorConfig",
    "EmulatedServo",
    "EmulatorTransport",
    "Fault",
    "FaultSet",
    "LoggedCommand",
    "LoggedPacket",
    "PlantLegs",
    "RegisterRead",
    "RegisterValue",
    "RegisterWrite",
    "Reply",
    "RobotEmulator",
    "RobotEmulatorConfig",
    "SharedPlant",
    "SharedPlantConfig",
    "UnitreeEmulator",
    "UnitreeEmulatorConfig",
    "apply_state_faults",
    "mangle_frame",
]
