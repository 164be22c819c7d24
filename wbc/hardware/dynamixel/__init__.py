"""The WidowX 200 arm's backend on its Dynamixel bus: `DynamixelArm`, its configuration and what it reports.

`DynamixelArm` drives the three model joints behind the `Robot` interface (current mode, with the PD law on the
host), configured by `DynamixelArmConfig` for one of `ARM_ROBOTS`; it reports `ArmFault` (one of `FAULT_KINDS`),
`ArmMotorStatus` and `ArmBusStats`, and read without driving anything (`DynamixelArm.survey`), `ServoReading`. Its
port is the vendor SDK's (`sdk_handlers`, imported only when a bus is opened), or a bus in the same process
(`in_process_handlers`, e.g. an emulator's), timed by a `wbc.hardware.clock.Clock`.

Below it, data and pure functions that need neither the vendor SDK, MuJoCo nor torch, imported from their modules:
`packet` (Protocol 2.0 packets: CRC-16, byte stuffing, every instruction's parameters), `protocol` (instructions and
error codes), `control_table` (the XM430-W350's registers), `units` (their units in SI), `wx200_bus` (which servo
has which ID, and how ticks map to the model's joints), `current_law` and `sdk_bus`. An emulator
(`wbc.hardware.emulators`) and the backend build on the same definitions.
"""

from wbc.hardware.dynamixel.arm_config import ARM_ROBOTS, DynamixelArmConfig
from wbc.hardware.dynamixel.arm_fault import FAULT_KINDS, ArmBusStats, ArmFault, ArmMotorStatus, ServoReading
from wbc.hardware.dynamixel.arm_robot import DynamixelArm
from wbc.hardware.dynamixel.sdk_bus import in_process_handlers, sdk_handlers

__all__ = [
    "ARM_ROBOTS",
    "FAULT_KINDS",
    "ArmBusStats",
    "ArmFault",
    "ArmMotorStatus",
    "DynamixelArm",
    "DynamixelArmConfig",
    "ServoReading",
    "in_process_handlers",
    "sdk_handlers",
]
