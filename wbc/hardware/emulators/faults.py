"""`Fault` and `FaultSet`: what an emulator can be told to do wrong, and how each fault bends a reply.

Frame faults change what goes on the wire (nothing, a corrupt, short or long datagram, one from a foreign port, late
or dropped replies, the same datagram again and again); state faults change what the reported state says (a joint
beyond its range, an overheated motor, a motor in an error mode, sustained over-power, an IMU reading of a fall, the
remote's L2+B). A `FaultSet` is shared by the test thread that injects and the emulator thread that applies, so it is
locked; the Dynamixel emulator keeps one of its own faults (`BusFault`) in the same kind of set.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import threading
from collections.abc import Mapping

import numpy as np

from wbc.errors import ConfigError
from wbc.hardware.unitree import LowStateExtras, Remote
from wbc.hardware.unitree.layout import MODE_OVERHEAT
from wbc.hardware.unitree.remote import L2_B_MASK
from wbc.types import RobotState

__all__ = ["FAULT_VALUES", "FRAME_FAULTS", "STATE_FAULTS", "Fault", "FaultSet", "apply_state_faults", "fault_value",
           "mangle_frame"]


class Fault(enum.Enum):
    """A fault an emulator injects on demand; the value each takes (`FaultSet.inject`) is in brackets.

    Frame faults: SILENCE (no replies); CORRUPT (a flipped bit: bad CRC); SHORT (one byte missing); LONG (four bytes
    more); FOREIGN_PORT (replies sent from another port); DELAY [s, default 0.05] (each reply sent that much later);
    JITTER [s, default 0.004] (each reply sent later by a time drawn uniformly in [0, value], so replies arrive
    unevenly and out of order, as on a busy network); DROP [probability, default 1.0] (each reply dropped with it);
    FROZEN_STATE (each reply is the very datagram sent before the fault, byte for byte: a robot whose board keeps
    sending its last buffer, its tick standing still).
    State faults: JOINT_OUT_OF_RANGE [(joint, q) default (2, 0.5)] (calf 0 reports q); OVER_TEMPERATURE [deg C,
    default 95] (every motor); MOTOR_ERROR [mode, default 0x08: overheat, the fault code the vendor documents,
    `unitree.layout.MOTOR_STATE_MODES`] (every motor reports that mode); OVER_POWER [(tau_est N m, dq rad/s),
    default (20, 5)] (every motor reports that torque and speed: 12 x 100 W, above the safety layer's 500 W, on every
    reply while active); FALL [roll rad, default pi/2] (the IMU reads the trunk
    rolled); BAD_IMU [scale, default 0.5] (the IMU's quaternion comes scaled, no longer of unit norm: a reading no
    orientation has, in a frame whose checksum is right); REMOTE_L2_B (the remote's L2 and B held).
    """

    SILENCE = "silence"
    CORRUPT = "corrupt"
    SHORT = "short"
    LONG = "long"
    FOREIGN_PORT = "foreign_port"
    DELAY = "delay"
    JITTER = "jitter"
    DROP = "drop"
    FROZEN_STATE = "frozen_state"
    JOINT_OUT_OF_RANGE = "joint_out_of_range"
    OVER_TEMPERATURE = "over_temperature"
    MOTOR_ERROR = "motor_error"
    OVER_POWER = "over_power"
    FALL = "fall"
    BAD_IMU = "bad_imu"
    REMOTE_L2_B = "remote_l2_b"


FRAME_FAULTS = (Fault.SILENCE, Fault.CORRUPT, Fault.SHORT, Fault.LONG, Fault.FOREIGN_PORT, Fault.DELAY, Fault.JITTER,
                Fault.DROP, Fault.FROZEN_STATE)
STATE_FAULTS = (Fault.JOINT_OUT_OF_RANGE, Fault.OVER_TEMPERATURE, Fault.MOTOR_ERROR, Fault.OVER_POWER, Fault.FALL,
                Fault.BAD_IMU, Fault.REMOTE_L2_B)

_DEFAULTS: dict[Fault, object] = {
    Fault.DELAY: 0.05, Fault.JITTER: 0.004, Fault.DROP: 1.0, Fault.JOINT_OUT_OF_RANGE: (2, 0.5),
    Fault.OVER_TEMPERATURE: 95, Fault.MOTOR_ERROR: MODE_OVERHEAT, Fault.OVER_POWER: (20.0, 5.0),
    Fault.FALL: math.pi / 2, Fault.BAD_IMU: 0.5,
}


FAULT_VALUES: dict[Fault, tuple[str, float, float, bool]] = {
    Fault.DELAY: ("s", 0.0, 1.0, False), Fault.JITTER: ("s", 0.0, 1.0, False),
    Fault.DROP: ("probability", 0.0, 1.0, False), Fault.OVER_TEMPERATURE: ("deg C", 0.0, 127.0, True),
    Fault.MOTOR_ERROR: ("mode byte", 0.0, 255.0, True), Fault.FALL: ("rad", 0.0, math.pi, False),
    Fault.BAD_IMU: ("scale", 0.0, 10.0, False),
}
"""The faults that take one number from the command line (``--fault drop=0.3``): (unit, lowest, highest, whole).
The lowest is excluded, but for whole numbers. A motor's temperature is a signed byte on the wire (at most 127)."""


def fault_value(fault: Fault, text: str) -> float | int:
    """`fault`'s value read from `text` (``0.3``; a mode byte also as ``0x20``), checked against `FAULT_VALUES`.

    Raises:
        ConfigError: `fault` takes no number, or `text` is not one within its range (the message gives both).
    """
    if fault not in FAULT_VALUES:
        takes = ", ".join(f.value for f in FAULT_VALUES)
        raise ConfigError(f"--fault {fault.value}={text}: {fault.value} takes no value from the command line (it runs "
                          f"at its default, {_DEFAULTS.get(fault, 'on')}); those that take one: {takes}")
    unit, low, high, whole = FAULT_VALUES[fault]
    try:
        value: float | int = int(text, 0) if whole else float(text)
    except ValueError:
        value = math.nan
    inside = low <= value <= high if whole else low < value <= high
    if not (isinstance(value, int) or math.isfinite(value)) or not inside:
        span = f"[{low:g}, {high:g}]" if whole else f"({low:g}, {high:g}]"
        raise ConfigError(f"--fault {fault.value}={text}: expected {'a whole number' if whole else 'a number'} "
                          f"in {span} ({unit})")
    return value


class FaultSet:
    """The faults active now, each with its value (thread-safe).

    Args:
        kind: the enum of faults it accepts (`Fault` for the Unitree wire, `BusFault` for the Dynamixel bus).
        defaults: each fault's value when `inject` gets none (`Fault`'s own table when None).
    """

    def __init__(self, kind: type[enum.Enum] = Fault, defaults: Mapping[enum.Enum, object] | None = None) -> None:
        self._kind = kind
        self._defaults = dict(_DEFAULTS if defaults is None and kind is Fault else defaults or {})
        self._lock = threading.Lock()
        self._active: dict[enum.Enum, object] = {}

    def inject(self, fault: enum.Enum, value: object = None) -> None:
        """Activate `fault` (with `value`, or its default) until `clear`.

        Raises:
            ConfigError: `fault` is not one of this set's kind.
        """
        if not isinstance(fault, self._kind):
            raise ConfigError(f"inject: {fault!r} is not a {self._kind.__name__}; valid: "
                              f"{', '.join(f.name for f in self._kind)}")
        with self._lock:
            self._active[fault] = self._defaults.get(fault) if value is None else value

    def clear(self, fault: enum.Enum | None = None) -> None:
        """Deactivate `fault`, or every fault if None."""
        with self._lock:
            if fault is None:
                self._active.clear()
            else:
                self._active.pop(fault, None)

    def snapshot(self) -> dict[enum.Enum, object]:
        """The active faults and their values, copied."""
        with self._lock:
            return dict(self._active)


def apply_state_faults(active: dict[Fault, object], state: RobotState,
                       extras: LowStateExtras) -> tuple[RobotState, LowStateExtras]:
    """`state` and `extras` as the active state faults make the robot report them."""
    if Fault.JOINT_OUT_OF_RANGE in active:
        joint, value = active[Fault.JOINT_OUT_OF_RANGE]
        q = state.q.copy()
        q[int(joint)] = float(value)
        state = dataclasses.replace(state, q=q)
    if Fault.OVER_TEMPERATURE in active:
        extras = dataclasses.replace(extras, motor_temperature=np.full(12, int(active[Fault.OVER_TEMPERATURE]),
                                                                        dtype=np.int8))
    if Fault.MOTOR_ERROR in active:
        extras = dataclasses.replace(extras, motor_mode=np.full(12, int(active[Fault.MOTOR_ERROR]), dtype=np.uint8))
    if Fault.OVER_POWER in active:
        tau_est, dq = active[Fault.OVER_POWER]
        n = state.num_joints
        state = dataclasses.replace(state, tau_est=np.full(n, float(tau_est)), dq=np.full(n, float(dq)))
    if Fault.FALL in active:
        roll = float(active[Fault.FALL])
        quat = np.array([math.cos(roll / 2), math.sin(roll / 2), 0.0, 0.0])
        gravity_in_body = 9.81 * np.array([0.0, math.sin(roll), math.cos(roll)])
        state = dataclasses.replace(state, imu_quat=quat, accel_in_body=gravity_in_body)
        extras = dataclasses.replace(extras, imu_rpy=np.array([roll, 0.0, 0.0]))
    if Fault.BAD_IMU in active:
        state = dataclasses.replace(state, imu_quat=state.imu_quat * float(active[Fault.BAD_IMU]))
    if Fault.REMOTE_L2_B in active:
        extras = dataclasses.replace(extras, remote=Remote.build(buttons=L2_B_MASK))
    return state, extras


def mangle_frame(active: dict[Fault, object], frame: bytes) -> bytes:
    """`frame` as the active corrupting faults put it on the wire."""
    if Fault.CORRUPT in active:
        buf = bytearray(frame)
        buf[len(buf) // 2] ^= 0x01
        frame = bytes(buf)
    if Fault.SHORT in active:
        frame = frame[:-1]
    if Fault.LONG in active:
        frame = frame + bytes(4)
    return frame
