"""`LoggedPacket`: one instruction packet as the Dynamixel emulator decoded it off the bus, with when it arrived.

A test reads these to check what a backend really sent: the registers each packet wrote, with their values decoded
(signed where the register is), and the ranges it read. It reads what the servos answered too: the register values
each read's status packets carried, decoded the same way, so that a test can check what a backend did with a state
against the state it was given.
"""

from __future__ import annotations

from dataclasses import dataclass

from wbc.hardware.dynamixel.control_table import ControlTable
from wbc.hardware.dynamixel.protocol import Instruction

__all__ = ["LoggedPacket", "RegisterRead", "RegisterValue", "RegisterWrite", "decode_values", "decode_writes"]


@dataclass(frozen=True, kw_only=True)
class RegisterWrite:
    """A value written to one register.

    Attributes:
        id: the ID the write addressed (a servo whose Secondary ID it is executes it too).
        address: the register's address.
        name: the register's name; None for bytes that are not one whole register (a reserved address, or part
            of a register: the servo refuses such a write).
        value: the value, signed where the register is; for ``name`` None the bytes as an unsigned integer.
    """

    id: int
    address: int
    name: str | None
    value: int


@dataclass(frozen=True, kw_only=True)
class RegisterRead:
    """A range of registers read.

    Attributes:
        id: the servo asked.
        address: first byte.
        length: bytes.
    """

    id: int
    address: int
    length: int


@dataclass(frozen=True, kw_only=True)
class RegisterValue:
    """A value one servo answered for one register.

    Attributes:
        id: the servo that answered.
        address: the register's address.
        name: the register's name; None for bytes that are not one whole register (a reserved address, which reads
            0, or part of a register).
        value: the value, signed where the register is; for ``name`` None the bytes as an unsigned integer.
    """

    id: int
    address: int
    name: str | None
    value: int


@dataclass(frozen=True, kw_only=True)
class LoggedPacket:
    """A decoded instruction packet (its CRC checked, its stuffing removed).

    Attributes:
        time: arrival on the emulator's clock (`time.monotonic` unless told otherwise) [s].
        id: the packet's ID (0xFE broadcast for the sync and bulk instructions).
        instruction: the instruction byte.
        params: the parameters.
        writes: the register writes it carries (WRITE, SYNC_WRITE, BULK_WRITE), in packet order.
        reads: the reads it asks for (READ, SYNC_READ, BULK_READ and their fast forms).
        answers: the register values its answers carried (the reads' status packets), servo by servo in the order
            they answered, each servo's registers in address order: the present registers as the plant gave them
            when the packet was executed. A servo that did not answer (silent, rebooting, Status Return Level 0, an
            error) has none. They are logged as the servos sent them: an answer that a fault then spoils on the
            wire (`BusFault.BAD_CRC`) or delays (`BusFault.LATE_ANSWER`) is logged all the same.
    """

    time: float
    id: int
    instruction: int
    params: bytes
    writes: tuple[RegisterWrite, ...] = ()
    reads: tuple[RegisterRead, ...] = ()
    answers: tuple[RegisterValue, ...] = ()

    @property
    def instruction_name(self) -> str:
        """The instruction's name (``SYNC_WRITE``), or its number in hex when unknown."""
        try:
            return Instruction(self.instruction).name
        except ValueError:
            return f"{self.instruction:#04x}"

    def written(self, name: str, servo_id: int | None = None) -> list[int]:
        """The values this packet wrote to register `name` (for ID `servo_id` only, if given), in packet order."""
        return [w.value for w in self.writes if w.name == name and (servo_id is None or w.id == servo_id)]

    def answered(self, name: str, servo_id: int | None = None) -> list[int]:
        """The values this packet's answers carried for register `name` (from `servo_id` only, if given), in order."""
        return [a.value for a in self.answers if a.name == name and (servo_id is None or a.id == servo_id)]


def decode_writes(table: ControlTable, servo_id: int, address: int, data: bytes) -> tuple[RegisterWrite, ...]:
    """Cut bytes written from `address` into the registers of `table` they fill."""
    return tuple(RegisterWrite(id=servo_id, address=k, name=name, value=value)
                 for k, name, value in _cut(table, address, data))


def decode_values(table: ControlTable, servo_id: int, address: int, data: bytes) -> tuple[RegisterValue, ...]:
    """Cut bytes a servo answered from `address` into the registers of `table` they hold."""
    return tuple(RegisterValue(id=servo_id, address=k, name=name, value=value)
                 for k, name, value in _cut(table, address, data))


def _cut(table: ControlTable, address: int, data: bytes) -> list[tuple[int, str | None, int]]:
    """(address, register name or None, value) of each register, or run of other bytes, that `data` spans."""
    out, k, end = [], address, address + len(data)
    while k < end:
        reg = table.at(k)
        if reg is not None and reg.address == k and k + reg.size <= end:
            out.append((k, reg.name, reg.decode(data[k - address: k - address + reg.size])))
            k += reg.size
            continue
        # not a whole register: gather bytes up to the next register start
        j = k + 1
        while j < end and not ((r := table.at(j)) is not None and r.address == j):
            j += 1
        out.append((k, None, int.from_bytes(data[k - address: j - address], "little")))
        k = j
    return out
