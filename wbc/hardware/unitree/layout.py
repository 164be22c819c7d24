"""The Unitree low-level frame layouts of the Go1 (SDK 3.8) and the A1 (SDK 3.3.1), as data.

Every offset here was verified on loopback against the vendors' libraries; ``tests/golden/unitree`` holds frames
those libraries produced, and the codec's tests check every offset against them byte for byte. Frames are
little-endian and packed. Both robots share the motor blocks, the IMU block and the remote block; they differ in
the header (the Go1's 22 B start with the magic ``FE EF``, the A1's 10 B have none), in what sits between the
motors and the remote (Go1: BMS; A1: LEDs) and so in every offset after the header. The codecs (`command_codec`,
`state_codec`) read this data; nothing else in the package knows a frame offset.

The numpy dtypes below describe one motor block each; the codecs view a frame's 12 leg slots through them with
``np.frombuffer(..., count=12, offset=...)``, so no Python loop touches single bytes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wbc.errors import UnknownNameError

__all__ = [
    "with_article",
    "A1_LAYOUT",
    "CMD_MOTOR_DTYPE",
    "FrameLayout",
    "GO1_LAYOUT",
    "IMU_FLOATS",
    "KD_SCALE",
    "KP_SCALE",
    "LAYOUTS",
    "MODE_DAMPING",
    "MODE_OVERHEAT",
    "MOTOR_STATE_MODES",
    "LEVEL_LOWLEVEL",
    "MODE_SERVO",
    "NUM_LEG_MOTORS",
    "NUM_MOTOR_SLOTS",
    "POS_STOP_F",
    "REMOTE_SIZE",
    "STATE_MOTOR_DTYPE",
    "TAU_EST_SCALE",
    "TAU_SCALE",
    "VEL_STOP_F",
    "frame_layout",
]

NUM_MOTOR_SLOTS = 20
"""Motor slots in every LowCmd and LowState; the legs use the first 12 (FR, FL, RR, RL x hip, thigh, calf)."""
NUM_LEG_MOTORS = 12
LEVEL_LOWLEVEL = 0xFF
"""levelFlag of a low-level frame (both SDKs' LOWLEVEL); the A1 codec writes it too."""
MODE_SERVO = 0x0A
"""Motor mode ``servo``: the driver runs tau = Kp (q - q_m) + Kd (dq - dq_m) + tau. Mode 0 is damping/off."""
MODE_DAMPING = 0x00
"""Motor mode ``damping``: the driver is off (a command's mode 0; a motor that reports it is idle, not at fault)."""
MODE_OVERHEAT = 0x08
"""Motor mode a LowState reports for an overheated motor: the one fault code the vendor documents on this wire."""
MOTOR_STATE_MODES: dict[int, str] = {MODE_SERVO: "servo", MODE_DAMPING: "damping", MODE_OVERHEAT: "overheat"}
"""The modes a motor reports in a LowState, as the vendor documents them: the Go1 SDK 3.8's ``comm.h``
(``MotorState.mode``: "Servo : 0x0A, Damping : 0x00, Overheat : 0x08") and its Python bindings' stub say the same.
The A1 SDK 3.3.1's ``comm.h`` documents no values ("motor working mode"); the A1 motor's own serial protocol
(Unitree's actuator SDK) lists 0 idle, 5 open-loop slow rotation (calibration), 10 closed-loop FOC. Servo and
damping are the normal modes; overheat is a fault, and so is any other code (0x05 is never right under low-level
control). `wbc.hardware.safety.SafetyConfig.ok_motor_modes` holds the normal ones."""
POS_STOP_F = 2.146e9
"""The SDK's PosStopF: the q an unused slot carries (InitCmdData); ``float32(POS_STOP_F)`` is ``B9 D2 FF 4E``."""
VEL_STOP_F = 16000.0
"""The SDK's VelStopF: the dq an unused slot carries (InitCmdData)."""
TAU_SCALE = 256.0  # command tau on the wire: int16 counts of 1/256 N m
KP_SCALE = 32.0  # command Kp on the wire: int16 counts of 1/32 N m / rad
KD_SCALE = 16.0  # command Kd on the wire: int16 counts of 1/16 N m s / rad
TAU_EST_SCALE = 256.0  # state tauEst on the wire: int16 counts of 1/256 N m
REMOTE_SIZE = 40  # the wireless remote's raw block, in both LowCmd and LowState [B]

CMD_MOTOR_DTYPE = np.dtype({
    "names": ["mode", "q", "dq", "tau", "kp", "kd"],
    "formats": ["u1", "<f4", "<f4", "<i2", "<i2", "<i2"],
    "offsets": [0, 1, 5, 9, 11, 13],
    "itemsize": 27,
})
"""One LowCmd motor block (27 B): mode u8 +0, q f32 +1 [rad], dq f32 +5 [rad/s], tau i16 +9 (x256), Kp i16 +11
(x32), Kd i16 +13 (x16), reserve 3 x u32 +15."""

STATE_MOTOR_DTYPE = np.dtype({
    "names": ["mode", "q", "dq", "ddq", "tau_est", "q_raw", "dq_raw", "ddq_raw", "temperature"],
    "formats": ["u1", "<f4", "<f4", "<i2", "<i2", "<f4", "<f4", "<i2", "i1"],
    "offsets": [0, 1, 5, 9, 11, 13, 17, 21, 23],
    "itemsize": 32,
})
"""One LowState motor block (32 B): mode u8 +0, q f32 +1 [rad], dq f32 +5 [rad/s], ddq i16 +9 (counts, scale not
verified), tauEst i16 +11 (x256), q_raw f32 +13, dq_raw f32 +17, ddq_raw i16 +21, temperature i8 +23 [degC],
reserve 2 x u32 +24."""

IMU_FLOATS = 13
"""The IMU block: quaternion w x y z, gyroscope xyz [rad/s], accelerometer xyz [m/s^2], rpy [rad] (13 x f32), then
the IMU temperature i8 [degC]."""


@dataclass(frozen=True, kw_only=True)
class FrameLayout:
    """Where everything sits in one robot's LowCmd and LowState frames; all offsets in bytes from the frame start.

    The CRC is the last 4 bytes of both frames (see `wbc.hardware.unitree.crc`).

    Attributes:
        robot: the robot's name (``go1``, ``a1``).
        sdk: the vendor SDK whose wire format this is.
        magic: the bytes every frame starts with (Go1 ``FE EF``; the A1 has none).
        level_offset: offset of levelFlag (u8).
        cmd_size: LowCmd length [B].
        cmd_motor_offset: first LowCmd motor block (27 B each, 20 slots).
        cmd_bms_offset: Go1 BmsCmd (off u8, reserve 3 B); None on the A1.
        cmd_led_offset: A1 LED block (4 x RGB, 12 B); None on the Go1.
        cmd_remote_offset: LowCmd wireless remote block (40 B).
        state_size: LowState length [B].
        state_imu_offset: IMU block (13 x f32, then temperature i8).
        state_motor_offset: first LowState motor block (32 B each, 20 slots).
        state_bms_offset: Go1 BmsState (24 B); None on the A1.
        state_foot_force_offset: footForce i16 x 4; footForceEst i16 x 4 follows it.
        state_tick_offset: tick u32.
        state_remote_offset: LowState wireless remote block (40 B).
    """

    robot: str
    sdk: str
    magic: bytes
    level_offset: int
    cmd_size: int
    cmd_motor_offset: int
    cmd_bms_offset: int | None
    cmd_led_offset: int | None
    cmd_remote_offset: int
    state_size: int
    state_imu_offset: int
    state_motor_offset: int
    state_bms_offset: int | None
    state_foot_force_offset: int
    state_tick_offset: int
    state_remote_offset: int

    @property
    def cmd_crc_offset(self) -> int:
        """Offset of the LowCmd CRC (u32): its last 4 bytes."""
        return self.cmd_size - 4

    @property
    def state_crc_offset(self) -> int:
        """Offset of the LowState CRC (u32): its last 4 bytes."""
        return self.state_size - 4

    @property
    def header(self) -> bytes:
        """The bytes a valid low-level frame starts with: the magic, then levelFlag 0xFF."""
        return self.magic + bytes((LEVEL_LOWLEVEL,))


GO1_LAYOUT = FrameLayout(
    robot="go1", sdk="unitree-legged-sdk 3.8",
    # header 22 B: FE EF, levelFlag, frameReserve, SN u32 x 2, version u32 x 2, bandWidth u16
    magic=b"\xfe\xef", level_offset=2,
    cmd_size=614, cmd_motor_offset=22, cmd_bms_offset=562, cmd_led_offset=None, cmd_remote_offset=566,
    state_size=807, state_imu_offset=22, state_motor_offset=75, state_bms_offset=715, state_foot_force_offset=739,
    state_tick_offset=755, state_remote_offset=759,
)

A1_LAYOUT = FrameLayout(
    robot="a1", sdk="unitree_legged_sdk 3.3.1",
    # header 10 B: levelFlag, commVersion u16, robotID u16, SN u32, bandWidth u8
    magic=b"", level_offset=0,
    cmd_size=610, cmd_motor_offset=10, cmd_bms_offset=None, cmd_led_offset=550, cmd_remote_offset=562,
    state_size=771, state_imu_offset=10, state_motor_offset=63, state_bms_offset=None, state_foot_force_offset=703,
    state_tick_offset=719, state_remote_offset=723,
)

LAYOUTS = {"go1": GO1_LAYOUT, "a1": A1_LAYOUT}
"""The layouts by robot name."""


def with_article(robot: str) -> str:
    """A robot's name with its article, for messages: ``an a1``, ``a go1``."""
    return f"{'an' if robot[:1] in 'aeiou' else 'a'} {robot}"


def frame_layout(robot: str) -> FrameLayout:
    """The frame layout of `robot` (``go1`` or ``a1``).

    Raises:
        UnknownNameError: no layout of that name; the message lists the valid ones.
    """
    try:
        return LAYOUTS[robot]
    except KeyError:
        raise UnknownNameError("Unitree frame layout", robot, tuple(LAYOUTS)) from None
