"""The CRC-16 of Dynamixel Protocol 2.0 packets.

Polynomial 0x8005 (x^16 + x^15 + x^2 + 1), initial value 0, MSB first, no reflection, no final xor (the e-Manual's
"CRC-16 (IBM/ANSI)" as ROBOTIS computes it). It covers every byte of a packet from the header to the last parameter,
byte stuffing included, and is stored little-endian in the packet's last two bytes. Golden value (the e-Manual's
PING example): ``FF FF FD 00 01 03 00 01`` -> 0x4E19.
"""

from __future__ import annotations

__all__ = ["crc16"]


def _table() -> tuple[int, ...]:
    rows = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else (crc << 1)
        rows.append(crc & 0xFFFF)
    return tuple(rows)


_TABLE = _table()
"""CRC of each byte value shifted into the high byte of a zero register: one lookup per byte instead of 8 shifts."""


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """The Protocol 2.0 CRC of `data`, continued from `crc`.

    Args:
        data: the bytes to cover.
        crc: the CRC of the bytes before `data` (0 to start a packet); a fast sync read's blocks continue it.

    Returns:
        The CRC as an unsigned 16-bit integer.
    """
    table = _TABLE
    for byte in bytes(data):
        crc = ((crc << 8) & 0xFFFF) ^ table[(crc >> 8) ^ byte]
    return crc
