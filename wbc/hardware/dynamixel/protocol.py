"""Dynamixel Protocol 2.0 constants: identifiers, instructions and the status packet's error byte.

From ROBOTIS's Protocol 2.0 e-Manual, checked against dynamixel-sdk 3.7 / 4.1 (`robotis_def`, the Protocol 2.0
packet handler). An instruction packet goes from the host to the servos; a status packet is a servo's answer. Its
error byte holds one error number in bits 0..6 and the hardware alert in bit 7: the alert says "read Hardware Error
Status (70)", it is not an error of the packet, and the packet's data are valid (the SDK reports such a status as a
success with error 0x80).
"""

from __future__ import annotations

import enum

__all__ = [
    "ALERT",
    "BROADCAST_ID",
    "ERROR_NAMES",
    "ERR_ACCESS",
    "ERR_CRC",
    "ERR_DATA_LENGTH",
    "ERR_DATA_LIMIT",
    "ERR_DATA_RANGE",
    "ERR_INSTRUCTION",
    "ERR_RESULT_FAIL",
    "MAX_ID",
    "Instruction",
    "describe_error",
]

BROADCAST_ID = 0xFE
"""Every servo executes a packet sent to this ID; none answers it, except PING (each servo in turn)."""
MAX_ID = 0xFC
"""Largest ID a servo can have (252); 253 and 255 are reserved, 254 is broadcast."""


class Instruction(enum.IntEnum):
    """Instruction byte of a packet (STATUS marks a servo's answer)."""

    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    FACTORY_RESET = 0x06
    REBOOT = 0x08
    CLEAR = 0x10
    CONTROL_TABLE_BACKUP = 0x20
    STATUS = 0x55
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    FAST_SYNC_READ = 0x8A
    BULK_READ = 0x92
    BULK_WRITE = 0x93
    FAST_BULK_READ = 0x9A


ALERT = 0x80
"""Bit 7 of the error byte: the servo has a hardware error (Hardware Error Status, address 70, is not zero)."""
ERR_RESULT_FAIL = 1
"""The instruction could not be processed."""
ERR_INSTRUCTION = 2
"""Undefined instruction, or an ACTION without a REG_WRITE."""
ERR_CRC = 3
"""The instruction packet's CRC did not match."""
ERR_DATA_RANGE = 4
"""A value to write is outside the register's range (a goal beyond its limit, a goal while the bus watchdog has
tripped)."""
ERR_DATA_LENGTH = 5
"""Fewer bytes than the register holds (e.g. 2 bytes written to a 4-byte register)."""
ERR_DATA_LIMIT = 6
"""A value to write exceeds a limit."""
ERR_ACCESS = 7
"""A read-only or undefined address written, or EEPROM written while Torque Enable is 1."""

ERROR_NAMES = {
    ERR_RESULT_FAIL: "result fail",
    ERR_INSTRUCTION: "instruction error",
    ERR_CRC: "CRC error",
    ERR_DATA_RANGE: "data range error",
    ERR_DATA_LENGTH: "data length error",
    ERR_DATA_LIMIT: "data limit error",
    ERR_ACCESS: "access error",
}
"""Error number (the error byte's bits 0..6) -> its e-Manual name."""


def describe_error(error: int) -> str:
    """A status error byte in words, e.g. ``"access error + hardware alert"``; ``"ok"`` for 0.

    Args:
        error: the status packet's error byte (0..255).
    """
    number = error & ~ALERT & 0xFF
    words = []
    if number:
        words.append(ERROR_NAMES.get(number, f"unknown error {number}"))
    if error & ALERT:
        words.append("hardware alert")
    return " + ".join(words) if words else "ok"
