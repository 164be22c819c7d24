"""LowCmd frames: `encode_command` (host side) and `decode_command` (the emulator's side), both pure functions.

Encoding follows the SDK byte for byte where the SDK is safe, and departs from it where it is not:

- Like the SDK: the header as it writes it (levelFlag 0xFF; on the Go1 after the magic ``FE EF``; everything else
  zero), the 12 leg slots in house order (= SDK order) in servo mode 0x0A, the 8 unused slots as InitCmdData
  leaves them (mode 0x0A, q = PosStopF, dq = VelStopF, gains and torque 0), the Go1's BMS byte and the A1's LEDs
  zero, the remote block as given (zeros by default), q and dq as float32, and tau / Kp / Kd quantised the SDK's
  way: the value as a float32, times 256 / 32 / 16, truncated toward zero (so tau 0.0039 N m goes out as 0).
- Unlike the SDK, which wraps to int16 (tau 130 N m goes out as -126, Kp 2000 as -48) and lets a NaN q and a
  negative Kp through: a non-finite value or a negative gain is refused (`CommandError`: such a command is a bug
  upstream, since a `MotorCommand` cannot even be built with one), and everything else is clamped BEFORE it is
  quantised: tau to the int16 range of its scale (+-127.996 N m) and to the motor's torque limit, Kp to
  [0, 1023.97], Kd to [0, 2047.94], and, when a `JointTable` is given, q to the joint's range and dq to its speed
  limit. q and dq are always kept within float32's range (a larger finite float64 would reach the wire as inf).

A damping command is servo mode with Kp 0 and Kd > 0 (the SDK's and unitree_guide's passive mode: the golden frame
``damping_kd3`` carries mode 0x0A, q = PosStopF, dq 0, Kp 0, Kd 3); `MotorCommand.damping` encodes to exactly that
with q 0 instead of PosStopF, which Kp 0 makes irrelevant.
"""

from __future__ import annotations

import functools
import math
import struct

import numpy as np

from wbc.errors import CommandError, ConfigError, FrameError
from wbc.hardware.unitree.crc import frame_crc
from wbc.hardware.unitree.decode_stats import DecodeStats
from wbc.hardware.unitree.frame_check import check_frame, reject
from wbc.hardware.unitree.layout import (
    CMD_MOTOR_DTYPE,
    KD_SCALE,
    KP_SCALE,
    MODE_SERVO,
    NUM_LEG_MOTORS,
    NUM_MOTOR_SLOTS,
    POS_STOP_F,
    REMOTE_SIZE,
    TAU_SCALE,
    VEL_STOP_F,
    FrameLayout,
)
from wbc.hardware.unitree.remote import Remote
from wbc.hardware.unitree.wire_command import WireCommand
from wbc.robots.description import LEG_JOINT_NAMES, LEG_JOINTS
from wbc.robots.joint_table import JointTable
from wbc.types import MotorCommand

__all__ = ["KD_WIRE_MAX", "KP_WIRE_MAX", "TAU_WIRE_MAX", "decode_command", "encode_command"]

TAU_WIRE_MAX = 32767 / TAU_SCALE  # [N m] largest |tau| the int16 field holds: 127.996
KP_WIRE_MAX = 32767 / KP_SCALE  # [N m / rad] largest Kp the int16 field holds: 1023.97
KD_WIRE_MAX = 32767 / KD_SCALE  # [N m s / rad] largest Kd the int16 field holds: 2047.94
_F32_MAX = float(np.finfo(np.float32).max)
_FIELDS = ("q", "dq", "kp", "kd", "tau")  # MotorCommand.stacked() row order
_SCALES = np.array([KP_SCALE, KD_SCALE, TAU_SCALE], dtype=np.float32)[:, None]  # rows kp, kd, tau
_LOWER = np.array([-_F32_MAX, -_F32_MAX, 0.0, 0.0, -TAU_WIRE_MAX])[:, None]
_UPPER = np.array([_F32_MAX, _F32_MAX, KP_WIRE_MAX, KD_WIRE_MAX, TAU_WIRE_MAX])[:, None]
_CRC = struct.Struct("<I")


@functools.cache
def _init_cmd(layout: FrameLayout) -> bytes:
    """The LowCmd the SDK's InitCmdData leaves: header, 20 slots in servo mode at PosStopF / VelStopF, rest zero."""
    buf = bytearray(layout.cmd_size)
    buf[:len(layout.header)] = layout.header
    slots = np.frombuffer(buf, CMD_MOTOR_DTYPE, count=NUM_MOTOR_SLOTS, offset=layout.cmd_motor_offset)
    slots["mode"] = MODE_SERVO
    slots["q"] = POS_STOP_F
    slots["dq"] = VEL_STOP_F
    del slots  # release the view before the buffer is copied
    return bytes(buf)


def _bounds(limits: JointTable | None) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of the rows q, dq, kp, kd, tau, broadcastable to (5, 12)."""
    if limits is None:
        return _LOWER, _UPPER
    if tuple(limits.names[LEG_JOINTS]) != LEG_JOINT_NAMES:
        raise ConfigError(
            f"encode_command: limits must be a house-order JointTable whose first 12 joints are the legs "
            f"{', '.join(LEG_JOINT_NAMES)}; got {', '.join(limits.names[LEG_JOINTS])}"
        )
    legs = LEG_JOINTS
    tau_max = np.minimum(limits.torque_limit[legs], TAU_WIRE_MAX)
    zeros = np.zeros(NUM_LEG_MOTORS)
    lower = np.array((limits.lower[legs], -limits.velocity_limit[legs], zeros, zeros, -tau_max))
    upper = np.array((limits.upper[legs], limits.velocity_limit[legs], zeros + KP_WIRE_MAX, zeros + KD_WIRE_MAX,
                      tau_max))
    return lower, upper


def _refuse(rows: np.ndarray) -> None:
    """Raise `CommandError` for the first non-finite value or negative gain in `rows`, if any."""
    bad = ~np.isfinite(rows)
    if bad.any():
        field, joint = np.argwhere(bad)[0]
        raise CommandError(
            f"encode_command: {_FIELDS[field]} of joint {LEG_JOINT_NAMES[joint]} is {rows[field, joint]}; a "
            "non-finite value never reaches the wire (the SDK would send a NaN q as is): fix the controller"
        )
    negative = rows[2:4] < 0
    if negative.any():
        field, joint = np.argwhere(negative)[0]
        raise CommandError(
            f"encode_command: {_FIELDS[2 + field]} of joint {LEG_JOINT_NAMES[joint]} is {rows[2 + field, joint]}; "
            "gains must be >= 0 (the SDK would send a negative gain as is): fix the controller"
        )


def encode_command(layout: FrameLayout, cmd: MotorCommand, *, limits: JointTable | None = None,
                   remote: Remote | None = None) -> bytes:
    """The LowCmd frame that sends `cmd` to the 12 leg motors, clamped and quantised (see the module docstring).

    Args:
        layout: the robot's frame layout (`GO1_LAYOUT`, `A1_LAYOUT`).
        cmd: the legs' command, 12 joints in house order (FR, FL, RR, RL x hip, thigh, calf).
        limits: the robot's joint table (house order, legs first; arm rows are ignored). When given, q is clamped
            to the range from lower to upper [rad], dq to +-velocity_limit [rad/s] and tau to +-torque_limit [N m].
        remote: the remote block to send (LowCmd offset: Go1 566, A1 562); zeros if None, as InitCmdData leaves it.

    Returns:
        The frame: 614 B (Go1) or 610 B (A1), CRC in its last 4 bytes.

    Raises:
        CommandError: `cmd` does not have 12 joints, or holds a non-finite value or a negative gain.
        ConfigError: `limits` is not a house-order table of this robot's legs.
    """
    if cmd.num_joints != NUM_LEG_MOTORS:
        raise CommandError(
            f"encode_command: a LowCmd carries the {NUM_LEG_MOTORS} leg motors, the command has {cmd.num_joints} "
            "joints; pass the legs' entries (house indices 0..11, wbc.robots.description.LEG_JOINTS)"
        )
    rows = cmd.stacked()
    if not (np.isfinite(rows).all() and rows[2:4].min() >= 0.0):
        _refuse(rows)
    lower, upper = _bounds(limits)
    np.minimum(np.maximum(rows, lower, out=rows), upper, out=rows)
    f32 = rows.astype(np.float32)
    # the SDK's cast: float32 value x power-of-two scale (exact), truncated toward zero; clamping made it fit int16
    counts = np.trunc(f32[2:] * _SCALES)

    buf = bytearray(_init_cmd(layout))
    motors = np.frombuffer(buf, CMD_MOTOR_DTYPE, count=NUM_LEG_MOTORS, offset=layout.cmd_motor_offset)
    motors["q"] = f32[0]
    motors["dq"] = f32[1]
    motors["kp"] = counts[0]
    motors["kd"] = counts[1]
    motors["tau"] = counts[2]
    del motors
    if remote is not None:
        buf[layout.cmd_remote_offset:layout.cmd_remote_offset + REMOTE_SIZE] = remote.raw
    _CRC.pack_into(buf, layout.cmd_crc_offset, frame_crc(buf))
    return bytes(buf)


def decode_command(layout: FrameLayout, frame: bytes | bytearray | memoryview, *,
                   stats: DecodeStats | None = None) -> WireCommand:
    """Decode a LowCmd frame (the emulator's side of the wire), as strictly as `decode_state` decodes a LowState.

    Args:
        layout: the robot's frame layout.
        frame: the datagram as received.
        stats: the stream's counters; the frame is counted as accepted or under its reject reason.

    Returns:
        The 12 leg motors' modes, targets and gains, dequantised, and the remote block.

    Raises:
        FrameError: the frame has the wrong length, header or CRC, or a non-finite q, dq or remote stick;
            ``err.reason`` says which, and `stats` counts it.
    """
    check_frame(layout, frame, layout.cmd_size, "LowCmd", stats)
    motors = np.frombuffer(frame, CMD_MOTOR_DTYPE, count=NUM_LEG_MOTORS, offset=layout.cmd_motor_offset)
    q = motors["q"].astype(np.float64)
    dq = motors["dq"].astype(np.float64)
    remote = Remote(raw=bytes(frame[layout.cmd_remote_offset:layout.cmd_remote_offset + REMOTE_SIZE]))
    if not math.isfinite(q.sum() + dq.sum() + sum(remote.sticks())):
        raise _non_finite(layout, stats, q, dq, remote)
    if stats is not None:
        stats.accepted += 1
    return WireCommand(
        mode=motors["mode"].copy(), q=q, dq=dq, kp=motors["kp"] / KP_SCALE, kd=motors["kd"] / KD_SCALE,
        tau=motors["tau"] / TAU_SCALE, remote=remote,
    )


def _non_finite(layout: FrameLayout, stats: DecodeStats | None, q: np.ndarray, dq: np.ndarray,
                remote: Remote) -> FrameError:
    for name, values in (("q", q), ("dq", dq)):
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            where = f"{name} of joint {LEG_JOINT_NAMES[bad[0]]} is {values[bad[0]]}"
            break
    else:
        where = f"a remote stick is not finite ({remote.sticks()})"
    return reject(stats, "non_finite", layout, "LowCmd", f"{where}; the sender must never put it on the wire")
