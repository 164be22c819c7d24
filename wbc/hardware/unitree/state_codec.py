"""LowState frames: `decode_state` (host side) and `encode_state` (the emulator's side), both pure functions.

Decoding is stricter than the SDK's receive: a frame is used only if it has exactly the layout's length, the
low-level header (Go1: magic ``FE EF`` and levelFlag 0xFF; A1: levelFlag 0xFF, it has no magic), a matching CRC
and finite floats in every field decoded (IMU, q, dq, remote sticks); see `frame_check`. A rejected frame raises
`FrameError` with its reason and is counted in the caller's `DecodeStats`; nothing of it is returned, so a backend
can never act on it. (The SDK instead hands back its last good frame; a backend sees the unchanged tick.)

Decoded values: q, dq, the IMU's quaternion (w, x, y, z), gyroscope and accelerometer as float32 values in float64
arrays; tauEst / 256 [N m]; footForce as floats. The tick is a freshness counter only (its unit is not
verifiable without a robot): it goes to `RobotState.tick`, and `RobotState.time` is the receive time the caller
stamps the frame with, since the frame carries no timestamp of verified unit.

Encoding (for an emulator) writes every field `decode_state` reads, from a `RobotState` and a `LowStateExtras`, and
zeros everywhere else (q_raw, dq_raw, ddq_raw, reserves, SN, version, bandWidth), so decode then encode reproduces
a frame whose other fields are zero, as the vendors' golden frames are. Float fields are written as float32 as
they come, NaN and inf included, so that an emulator can inject a non-finite frame and check that it is rejected;
integer fields (tauEst, foot forces, temperatures ...) are checked and clamped, never wrapped.
"""

from __future__ import annotations

import math
import struct

import numpy as np

from wbc.errors import ConfigError, FrameError
from wbc.hardware.unitree.battery import Battery
from wbc.hardware.unitree.crc import frame_crc
from wbc.hardware.unitree.decode_stats import DecodeStats
from wbc.hardware.unitree.frame_check import check_frame, reject
from wbc.hardware.unitree.layout import (
    IMU_FLOATS,
    NUM_LEG_MOTORS,
    REMOTE_SIZE,
    STATE_MOTOR_DTYPE,
    TAU_EST_SCALE,
    FrameLayout,
)
from wbc.hardware.unitree.remote import Remote
from wbc.hardware.unitree.state_extras import LowStateExtras
from wbc.robots.description import LEG_JOINT_NAMES
from wbc.types import RobotState

__all__ = ["decode_state", "encode_state"]

_U32 = struct.Struct("<I")
_I8 = struct.Struct("<b")
_IMU_TEMPERATURE = 4 * IMU_FLOATS  # offset of the IMU's temperature i8 within the IMU block [B]
_INT16 = np.iinfo(np.int16)


def decode_state(layout: FrameLayout, frame: bytes | bytearray | memoryview, *, time: float,
                 stats: DecodeStats | None = None) -> tuple[RobotState, LowStateExtras]:
    """Decode a LowState frame into the state every controller reads and the extras a hardware backend reads.

    Args:
        layout: the robot's frame layout (`GO1_LAYOUT`, `A1_LAYOUT`).
        frame: the datagram as received: 807 B (Go1) or 771 B (A1).
        time: the time the caller received the frame at [s] (its clock); becomes `RobotState.time`.
        stats: the stream's counters; the frame is counted as accepted or under its reject reason.

    Returns:
        ``(state, extras)``. `state` holds the 12 leg motors in house order: q [rad], dq [rad/s], tau_est [N m];
        imu_quat (w, x, y, z), gyro_in_body [rad/s], accel_in_body [m/s^2]; foot_force (FR, FL, RR, RL) as the
        wire's footForce values (the foot sensors' raw readings: calibrate them per robot before reading them as
        newtons); tick as the wire's u32. `extras` holds the rest (`LowStateExtras`).

    Raises:
        FrameError: ``err.reason`` is ``length``, ``header``, ``crc`` or ``non_finite`` (a NaN or inf in the IMU,
            q, dq or a remote stick); the frame is counted in `stats` and must be dropped.
    """
    check_frame(layout, frame, layout.state_size, "LowState", stats)
    imu = np.frombuffer(frame, "<f4", count=IMU_FLOATS, offset=layout.state_imu_offset).astype(np.float64)
    motors = np.frombuffer(frame, STATE_MOTOR_DTYPE, count=NUM_LEG_MOTORS, offset=layout.state_motor_offset)
    q = motors["q"].astype(np.float64)
    dq = motors["dq"].astype(np.float64)
    ro = layout.state_remote_offset
    remote = Remote(raw=bytes(frame[ro:ro + REMOTE_SIZE]))
    # float32 values summed in float64 cannot overflow: the sum is finite exactly when every term is
    if not math.isfinite(imu.sum() + q.sum() + dq.sum() + sum(remote.sticks())):
        raise _non_finite(layout, stats, imu, q, dq, remote)
    feet = np.frombuffer(frame, "<i2", count=8, offset=layout.state_foot_force_offset).astype(np.float64)
    state = RobotState(
        tick=_U32.unpack_from(frame, layout.state_tick_offset)[0], time=time, q=q, dq=dq,
        tau_est=motors["tau_est"] / TAU_EST_SCALE, imu_quat=imu[0:4], gyro_in_body=imu[4:7],
        accel_in_body=imu[7:10], foot_force=feet[:4],
    )
    extras = LowStateExtras(
        motor_mode=motors["mode"].copy(), motor_temperature=motors["temperature"].copy(),
        ddq_counts=motors["ddq"].copy(), imu_rpy=imu[10:13],
        imu_temperature=_I8.unpack_from(frame, layout.state_imu_offset + _IMU_TEMPERATURE)[0],
        foot_force_est=feet[4:], remote=remote,
        battery=None if layout.state_bms_offset is None else Battery.unpack_from(frame, layout.state_bms_offset),
    )
    if stats is not None:
        stats.accepted += 1
    return state, extras


def _non_finite(layout: FrameLayout, stats: DecodeStats | None, imu: np.ndarray, q: np.ndarray, dq: np.ndarray,
                remote: Remote) -> FrameError:
    imu_names = ("quat w", "quat x", "quat y", "quat z", "gyro x", "gyro y", "gyro z", "acc x", "acc y", "acc z",
                 "roll", "pitch", "yaw")
    where = f"a remote stick is not finite ({remote.sticks()})"
    for name, values, labels in (("IMU", imu, imu_names), ("q", q, LEG_JOINT_NAMES), ("dq", dq, LEG_JOINT_NAMES)):
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            where = f"{name} {labels[bad[0]]} is {values[bad[0]]}"
            break
    return reject(stats, "non_finite", layout, "LowState",
                  f"{where}; the robot never sends one in a healthy frame: the frame is dropped")


def _counts(name: str, values: np.ndarray, scale: float, shape: tuple[int, ...]) -> np.ndarray:
    """`values` x `scale` as int16 counts, truncated toward zero and clamped to the int16 range."""
    a = np.asarray(values, dtype=np.float64)
    if a.shape != shape:
        raise ConfigError(f"encode_state: {name} must have shape {shape}, got {a.shape}")
    if not np.isfinite(a).all():
        raise ConfigError(f"encode_state: {name} holds a non-finite value ({a}); the wire holds it as an int16, "
                          "which cannot carry one (inject non-finite values through the float fields)")
    return np.trunc(np.clip(a * scale, _INT16.min, _INT16.max))


def _exact(name: str, values: np.ndarray, dtype: type[np.integer], shape: tuple[int, ...]) -> np.ndarray:
    """`values` as `dtype`, refusing anything that does not fit exactly.

    An array already of `dtype` and `shape` fits by construction and is returned as it is: the emulator encodes 500
    states a second, each with three such arrays, and their checks were most of the encoding's time.
    """
    a = np.asarray(values)
    if a.dtype == dtype and a.shape == shape:
        return a
    info = np.iinfo(dtype)
    if a.shape != shape or not np.array_equal(a, np.trunc(a)) or a.min() < info.min or a.max() > info.max:
        raise ConfigError(f"encode_state: {name} must be {shape} integers in {info.min}..{info.max}, got {a!r}")
    return a.astype(dtype)


def encode_state(layout: FrameLayout, state: RobotState, extras: LowStateExtras | None = None) -> bytes:
    """The LowState frame a robot would send for `state` and `extras` (the emulator's side of the wire).

    Args:
        layout: the robot's frame layout.
        state: 12 leg joints in house order. q, dq and the IMU are written as float32 (NaN and inf as such);
            tau_est is quantised to 1/256 N m (truncated toward zero, clamped to int16); foot_force to int16;
            tick modulo 2**32 (it is a wrapping counter).
        extras: modes, temperatures, remote, battery ...; `LowStateExtras()` (all zero) if None.

    Returns:
        The frame: 807 B (Go1) or 771 B (A1), header levelFlag 0xFF, CRC in its last 4 bytes.

    Raises:
        ConfigError: `state` does not have 12 joints, an integer field is non-finite or does not fit, or a battery
            is given for the A1 (its LowState has no BMS block).
    """
    if extras is None:
        extras = LowStateExtras()
    if state.num_joints != NUM_LEG_MOTORS:
        raise ConfigError(
            f"encode_state: a LowState carries the {NUM_LEG_MOTORS} leg motors, the state has {state.num_joints} "
            "joints; pass the legs' entries (house indices 0..11, wbc.robots.description.LEG_JOINTS)"
        )
    legs = (NUM_LEG_MOTORS,)
    buf = bytearray(layout.state_size)
    buf[:len(layout.header)] = layout.header

    imu = np.concatenate((state.imu_quat, state.gyro_in_body, state.accel_in_body, extras.imu_rpy))
    if imu.shape != (IMU_FLOATS,):
        raise ConfigError("encode_state: imu_quat (4,), gyro_in_body (3,), accel_in_body (3,) and imu_rpy (3,) "
                          f"must hold {IMU_FLOATS} floats, got {imu.shape[0]}")
    io = layout.state_imu_offset
    with np.errstate(over="ignore"):  # a float64 beyond float32's range is written as inf, as asked
        buf[io:io + 4 * IMU_FLOATS] = imu.astype("<f4").tobytes()
    _pack(_I8, buf, io + _IMU_TEMPERATURE, extras.imu_temperature, "imu_temperature")

    tau_counts = _counts("tau_est", state.tau_est, TAU_EST_SCALE, legs)
    mode = _exact("motor_mode", extras.motor_mode, np.uint8, legs)
    temperature = _exact("motor_temperature", extras.motor_temperature, np.int8, legs)
    ddq = _exact("ddq_counts", extras.ddq_counts, np.int16, legs)
    motors = np.frombuffer(buf, STATE_MOTOR_DTYPE, count=NUM_LEG_MOTORS, offset=layout.state_motor_offset)
    with np.errstate(over="ignore"):
        motors["q"] = state.q
        motors["dq"] = state.dq
    motors["mode"] = mode
    motors["ddq"] = ddq
    motors["tau_est"] = tau_counts
    motors["temperature"] = temperature
    del motors

    feet = np.concatenate((_counts("foot_force", state.foot_force, 1.0, (4,)),
                           _counts("foot_force_est", extras.foot_force_est, 1.0, (4,))))
    fo = layout.state_foot_force_offset
    buf[fo:fo + 16] = feet.astype("<i2").tobytes()
    _U32.pack_into(buf, layout.state_tick_offset, int(state.tick) % 2**32)
    buf[layout.state_remote_offset:layout.state_remote_offset + REMOTE_SIZE] = extras.remote.raw
    if extras.battery is not None:
        if layout.state_bms_offset is None:
            raise ConfigError(f"encode_state: the {layout.robot}'s LowState has no battery block; pass "
                              "LowStateExtras(battery=None)")
        extras.battery.pack_into(buf, layout.state_bms_offset)
    _U32.pack_into(buf, layout.state_crc_offset, frame_crc(buf))
    return bytes(buf)


def _pack(fmt: struct.Struct, buf: bytearray, offset: int, value: int, name: str) -> None:
    try:
        fmt.pack_into(buf, offset, value)
    except struct.error as exc:
        raise ConfigError(f"encode_state: {name} = {value!r} does not fit its wire field ({exc})") from None
