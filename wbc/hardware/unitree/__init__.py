"""The Unitree low-level wire codec (Go1 SDK 3.8, A1 SDK 3.3.1): pure functions from records to frames and back.

`encode_command` turns a `MotorCommand` into a LowCmd frame (checked, clamped, then quantised as the SDK does);
`decode_state` turns a LowState frame into a `RobotState` and `LowStateExtras`, rejecting (and counting in a
`DecodeStats`) any frame of the wrong length, header or CRC or with a non-finite value. `decode_command` and
`encode_state` are the other side of the wire, for an emulator. On top of them: `UdpTransport` (the socket),
`SdkTransport` (the vendor's Go1 SDK carrying the same frames), the address policy (`check_target`: loopback unless
``allow_hardware``) and `UnitreeRobot`, the backend with its link thread; the emulator lives in
`wbc.hardware.emulators`.
"""

from wbc.hardware.unitree.battery import Battery
from wbc.hardware.unitree.command_codec import (
    KD_WIRE_MAX,
    KP_WIRE_MAX,
    TAU_WIRE_MAX,
    decode_command,
    encode_command,
)
from wbc.hardware.unitree.crc import crc_words, frame_crc
from wbc.hardware.unitree.decode_stats import REJECT_REASONS, DecodeStats
from wbc.hardware.unitree.layout import (
    A1_LAYOUT,
    GO1_LAYOUT,
    LAYOUTS,
    MODE_DAMPING,
    MODE_OVERHEAT,
    MODE_SERVO,
    MOTOR_STATE_MODES,
    POS_STOP_F,
    VEL_STOP_F,
    FrameLayout,
    frame_layout,
)
from wbc.hardware.unitree.link_stats import LinkStats
from wbc.hardware.unitree.remote import BUTTONS, L2_B_MASK, Remote
from wbc.hardware.unitree.robot import (
    DESCRIPTIONS,
    SDK_POSITION_LIMITS,
    TRANSPORTS,
    UnitreeRobot,
    UnitreeRobotConfig,
    unitree_joint_table,
)
from wbc.hardware.unitree.sdk_transport import SDK_ROBOTS, SdkTransport, sdk_state_frame
from wbc.hardware.unitree.state_codec import decode_state, encode_state
from wbc.hardware.unitree.state_extras import LowStateExtras
from wbc.hardware.unitree.target import announce_hardware_target, check_target, is_loopback
from wbc.hardware.unitree.transport import MAX_DATAGRAM, Transport, UdpTransport
from wbc.hardware.unitree.wire_command import WireCommand

__all__ = [
    "A1_LAYOUT",
    "BUTTONS",
    "DESCRIPTIONS",
    "GO1_LAYOUT",
    "KD_WIRE_MAX",
    "KP_WIRE_MAX",
    "L2_B_MASK",
    "LAYOUTS",
    "MAX_DATAGRAM",
    "MODE_DAMPING",
    "MODE_OVERHEAT",
    "MODE_SERVO",
    "MOTOR_STATE_MODES",
    "POS_STOP_F",
    "REJECT_REASONS",
    "SDK_POSITION_LIMITS",
    "SDK_ROBOTS",
    "TRANSPORTS",
    "TAU_WIRE_MAX",
    "VEL_STOP_F",
    "Battery",
    "DecodeStats",
    "FrameLayout",
    "LinkStats",
    "LowStateExtras",
    "Remote",
    "SdkTransport",
    "Transport",
    "UdpTransport",
    "UnitreeRobot",
    "UnitreeRobotConfig",
    "WireCommand",
    "announce_hardware_target",
    "check_target",
    "crc_words",
    "decode_command",
    "decode_state",
    "encode_command",
    "encode_state",
    "frame_crc",
    "frame_layout",
    "is_loopback",
    "sdk_state_frame",
    "unitree_joint_table",
]
