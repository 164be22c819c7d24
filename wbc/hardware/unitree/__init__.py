"""The A1 / Go1 legs' backend on the Unitree low-level wire (Go1 SDK 3.8, A1 SDK 3.3.1): `UnitreeRobot` and its parts.

`UnitreeRobot` (configured by `UnitreeRobotConfig`, for one of `DESCRIPTIONS`) runs the link in a thread of its own
over a `Transport`: `UdpTransport` (our socket) or `SdkTransport` (the vendor's Go1 SDK carrying the same frames),
one of `TRANSPORTS`. It reports `LinkStats`, the rejected frames by reason (`DecodeStats`, `REJECT_REASONS`) and
each state's `LowStateExtras` (motor modes and temperatures, the `Remote`, the `Battery`). The address policy is
`check_target` (loopback unless ``allow_hardware``) with `is_loopback`.

Below it, pure functions imported from their modules: `command_codec` (`encode_command` turns a `MotorCommand` into
a LowCmd frame, checked, clamped, then quantised as the SDK does; `decode_command` is the robot's side),
`state_codec` (`decode_state` turns a LowState frame into a `RobotState` and its extras, rejecting any frame of the
wrong length, header or CRC or with a non-finite value; `encode_state` is the robot's side), `layout` (the frames'
layouts and mode codes) and `crc`. The emulator lives in `wbc.hardware.emulators`.
"""

from wbc.hardware.unitree.battery import Battery
from wbc.hardware.unitree.decode_stats import REJECT_REASONS, DecodeStats
from wbc.hardware.unitree.link_stats import LinkStats
from wbc.hardware.unitree.remote import Remote
from wbc.hardware.unitree.robot import DESCRIPTIONS, LEG_WIRES, TRANSPORTS, UnitreeRobot, UnitreeRobotConfig
from wbc.hardware.unitree.sdk_transport import SdkTransport
from wbc.hardware.unitree.state_extras import LowStateExtras
from wbc.hardware.unitree.target import check_target, is_loopback
from wbc.hardware.unitree.transport import Transport, UdpTransport

__all__ = [
    "DESCRIPTIONS",
    "LEG_WIRES",
    "REJECT_REASONS",
    "TRANSPORTS",
    "Battery",
    "DecodeStats",
    "LinkStats",
    "LowStateExtras",
    "Remote",
    "SdkTransport",
    "Transport",
    "UdpTransport",
    "UnitreeRobot",
    "UnitreeRobotConfig",
    "check_target",
    "is_loopback",
]
