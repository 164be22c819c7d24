"""`LoggedPacket`: one instruction packet as the Dynamixel emulator decoded it off the bus, with when it arrived.

A test reads these to check what a backend really sent: the registers each packet wrote, with their values decoded
(signed where the register is), and the ranges it read.
"""

from __future__ import annotations

from dataclasses import dataclass

from wbc.hardware.dynamixel.control_table import ControlTable
from wbc.hardware.dynamixel.protocol import Instruction

__all__ = ["LoggedPacket", "RegisterRead", "RegisterWrite", "decode_writes"]


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
class LoggedPacket:
    """A decoded instruction packet (its CRC checked, its stuffing removed).

    Attributes:
        time: arrival on the emulator's clock (`time.monotonic` unless told otherwise) [s].
        id: the packet's ID (0xFE broadcast for the sync and bulk instructions).
        instruction: the instruction byte.
        params: the parameters.
        writes: the register writes it carries (WRITE, SYNC_WRITE, BULK_WRITE), in packet order.
        reads: the reads it asks for (READ, SYNC_READ, BULK_READ and their fast forms).
    """

    time: float
    id: int
    instruction: int
    params: bytes
    writes: tuple[RegisterWrite, ...] = ()
    reads: tuple[RegisterRead, ...] = ()

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


def decode_writes(table: ControlTable, servo_id: int, address: int, data: bytes) -> tuple[RegisterWrite, ...]:
    """Cut bytes written from `address` into the registers of `table` they fill."""
    out, k, end = [], address, address + len(data)
    while k < end:
        reg = table.at(k)
        if reg is not None and reg.address == k and k + reg.size <= end:
            out.append(RegisterWrite(id=servo_id, address=k, name=reg.name,
                                     value=reg.decode(data[k - address: k - address + reg.size])))
            k += reg.size
            continue
        # not a whole register: gather bytes up to the next register start
        j = k + 1
        while j < end and not ((r := table.at(j)) is not None and r.address == j):
            j += 1
        out.append(RegisterWrite(id=servo_id, address=k, name=None,
                                 value=int.from_bytes(data[k - address: j - address], "little")))
        k = j
    return tuple(out)
