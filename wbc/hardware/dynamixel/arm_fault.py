"""What `DynamixelArm` reports about its servos and its bus: a latched fault, the servos' status, the bus counters.

`ArmFault` is one latched bus fault: which servos, what was seen, and what the backend does about it (the torque
policy, in words). `ArmMotorStatus` is the servos' status in the shape the safety layer reads (`MotorStatusSource`):
one entry per servo, in ID order, whose mode is `MODE_SERVO` while the servo is fine and an error code otherwise:

| code | meaning |
|---|---|
| 0x0A `MODE_SERVO` | answering, no hardware error |
| 0x80 + bits (`MODE_HARDWARE_ERROR`) | Hardware Error Status bits (0x20 overload, 0x04 overheating ...) |
| 0x41 `MODE_NO_ANSWER` | the servo stopped answering (a silent ID) |
| 0x42 `MODE_CORRUPT` | its answers arrive corrupt (bad CRC) |
| 0x43 `MODE_PORT_LOST` | the serial port failed: no servo can be reached |

`ServoReading` is one servo as a read-only pass over the bus found it (`DynamixelArm.survey`).

`ArmBusStats` counts the bus loop's cycles, retries and timing since `connect`, timed on the backend's clock (on a
`ManualClock` the busy time is the clock time the cycle's reply timeouts and pauses took). Its timing is the bus
loop's own statistics (`wbc.hardware.device_thread.DeviceThreadStats`, from `DynamixelArm.thread_stats()`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = [
    "FAULT_KINDS",
    "MODE_CORRUPT",
    "MODE_HARDWARE_ERROR",
    "MODE_NO_ANSWER",
    "MODE_PORT_LOST",
    "MODE_SERVO",
    "ArmBusStats",
    "ArmFault",
    "ArmMotorStatus",
    "ServoReading",
]

MODE_SERVO = 0x0A
"""A servo that answers and has no hardware error (Unitree's "servo" mode code, which the safety layer accepts)."""
MODE_HARDWARE_ERROR = 0x80
"""Added to the Hardware Error Status bits of a servo that has one."""
MODE_NO_ANSWER = 0x41
"""A servo that no longer answers."""
MODE_CORRUPT = 0x42
"""A servo whose answers arrive corrupt."""
MODE_PORT_LOST = 0x43
"""Every servo, once the serial port has failed."""

FAULT_KINDS = ("no_answer", "corrupt", "hardware_error", "port_lost")
"""`ArmFault.kind` values: a silent ID, corrupt answers, a servo's hardware error, the serial port gone."""


@dataclass(frozen=True, kw_only=True)
class ArmFault:
    """A bus fault the backend latched (until `close`; a new `connect` starts afresh).

    Attributes:
        time: when it was latched, on the backend's clock (the monotonic clock on a robot) [s]; a hardware trial
            records it on the trial's clock instead (`wbc.arena.hw_trial.HardwareTrialResult.arm_faults`).
        kind: one of `FAULT_KINDS`.
        ids: the servos at fault (every servo for ``port_lost``).
        detail: what was seen (the SDK's result, the hardware error bits, the exception).
        policy: what the backend does about it, in words (which joints it damps, which go limp and why).
    """

    time: float
    kind: str
    ids: tuple[int, ...]
    detail: str
    policy: str

    def __str__(self) -> str:
        return f"DynamixelArm: FAULT LATCHED ({self.kind}, IDs {list(self.ids)}): {self.detail}. {self.policy}"


@dataclass(frozen=True, kw_only=True)
class ArmMotorStatus:
    """The servos' status as of the latest status read, one entry per servo in ID order (a `MotorStatus`).

    Attributes:
        ids: the servos' IDs.
        motor_mode: `MODE_SERVO`, or an error code (see the module docstring), uint8.
        motor_temperature: Present Temperature [degC].
        input_voltage: Present Input Voltage [V].
        hardware_error: Hardware Error Status bits, uint8.
    """

    ids: tuple[int, ...]
    motor_mode: np.ndarray
    motor_temperature: np.ndarray
    input_voltage: np.ndarray
    hardware_error: np.ndarray


@dataclass(frozen=True, kw_only=True)
class ServoReading:
    """One servo as a read-only pass over the bus found it (`DynamixelArm.survey`): nothing written, nothing driven.

    Attributes:
        id: the servo's ID.
        name: its name on the arm (``elbow``, ``gripper``).
        answer: the SDK's result of its ping in words; empty when it answered.
        model: its model number (0 when it did not answer).
        operating_mode: its Operating Mode register (0 current, 3 position, 5 current-based position); None when
            it could not be read.
        hardware_error: its Hardware Error Status bits (0x20 overload, 0x04 overheating ...).
        temperature: its Present Temperature [degC]; NaN when it could not be read.
        voltage: its Present Input Voltage [V]; NaN when it could not be read.
    """

    id: int
    name: str
    answer: str = ""
    model: int = 0
    operating_mode: int | None = None
    hardware_error: int = 0
    temperature: float = float("nan")
    voltage: float = float("nan")


@dataclass(frozen=True, kw_only=True)
class ArmBusStats:
    """Counters of the bus thread since `connect`.

    Attributes:
        cycles: bus cycles run.
        states: fresh states published (the freshness tick of `read`).
        status_reads: status reads (hardware errors, or temperatures with voltages).
        failed_transfers: reads that failed (timeout, corrupt), retries included.
        retries: reads tried again after a flush.
        unexplained: failed reads whose retries failed too but whose servos all answered a ping afterwards (no
            fault latched).
        missed_reads: reads whose tries all failed while every servo of the read had answered within the watchdog's
            time (a late host or a late answer, not a dead servo): no fresh state that cycle, no fault.
        late: status packets discarded because they answered an earlier request (another ID or length).
        damping_cycles: cycles that sent the host's damping instead of the written command.
        deadline_trips: times the write deadline expired.
        overruns: cycles that started more than a period after they were due (the bus loop's late cycles,
            `DeviceThreadStats.late`; the loop then starts its schedule afresh).
        period_mean: mean interval between two cycle starts [s].
        period_max: longest such interval [s].
        busy_mean: mean time a cycle of the loop took (read, status, write; the park when closing) [s].
        busy_max: longest such time [s].
        late_advances: `advance` calls that found their deadline already past.
    """

    cycles: int = 0
    states: int = 0
    status_reads: int = 0
    failed_transfers: int = 0
    retries: int = 0
    unexplained: int = 0
    missed_reads: int = 0
    late: int = 0
    damping_cycles: int = 0
    deadline_trips: int = 0
    overruns: int = 0
    period_mean: float = 0.0
    period_max: float = 0.0
    busy_mean: float = 0.0
    busy_max: float = 0.0
    late_advances: int = 0

    def as_dict(self, prefix: str = "arm_bus/") -> dict[str, float]:
        """The counters as a flat dict, keys namespaced with `prefix`."""
        return {f"{prefix}{k}": v for k, v in asdict(self).items()}
