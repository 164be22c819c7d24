"""Dynamixel Protocol 2.0 packets as pure functions: build, parse, byte stuffing, and every instruction's parameters.

Layout (little-endian)::

    FF FF FD 00 | ID | LEN_L LEN_H | INST | params ... | CRC_L CRC_H

LEN counts the instruction, the parameters (after stuffing) and the CRC. A status packet is the same with INST 0x55
and its first parameter the error byte. Byte stuffing keeps a header out of the body: wherever FF FF FD occurs from
the instruction on, an extra FD follows it (FF FF FD FD), LEN counts the extra bytes, and the CRC covers the stuffed
packet; the receiver checks the CRC first, then drops every FD that follows FF FF FD. The CRC is never stuffed.

A fast sync read (0x8A) or fast bulk read (0x9A) is answered by ONE status packet with ID 0xFE made of one block per
servo, ``ERR ID data CRC_L CRC_H``, where each block's CRC covers the whole packet up to it (the first servo sends
the header; each next one appends its block after hearing the previous) and the last block's CRC is the packet's.
Such a packet is not stuffed.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from wbc.errors import PacketError
from wbc.hardware.dynamixel.crc import crc16
from wbc.hardware.dynamixel.protocol import BROADCAST_ID, Instruction

__all__ = [
    "HEADER",
    "MAX_PACKET_LENGTH",
    "InstructionPacket",
    "PacketReader",
    "StatusPacket",
    "build_fast_read_status",
    "build_instruction",
    "build_status",
    "bulk_read_params",
    "bulk_write_params",
    "parse_bulk_read_params",
    "parse_bulk_write_params",
    "parse_fast_read_status",
    "parse_packet",
    "parse_ping_status",
    "parse_read_params",
    "parse_sync_read_params",
    "parse_sync_write_params",
    "parse_write_params",
    "ping_status_params",
    "read_params",
    "stuff",
    "sync_read_params",
    "sync_write_params",
    "unstuff",
    "write_params",
]

HEADER = b"\xff\xff\xfd\x00"
"""The four bytes that start every packet (the last one is reserved, always 0)."""
MAX_PACKET_LENGTH = 1024
"""Largest whole packet the SDK sends or accepts [bytes] (its TXPACKET_MAX_LEN / RXPACKET_MAX_LEN)."""
_PREFIX = 7  # header, ID, LEN
_MIN_PACKET = 10  # prefix, instruction, CRC


@dataclass(frozen=True)
class InstructionPacket:
    """A host-to-servo packet, unstuffed.

    Attributes:
        id: target ID (0..252, or 0xFE broadcast).
        instruction: the instruction byte (an `Instruction` when known).
        params: the parameters.
    """

    id: int
    instruction: int
    params: bytes


@dataclass(frozen=True)
class StatusPacket:
    """A servo's answer, unstuffed.

    Attributes:
        id: the answering servo's ID (0xFE for a fast read's combined answer).
        error: the error byte (`wbc.hardware.dynamixel.protocol`: an error number in bits 0..6, the alert in bit 7).
        params: the parameters after the error byte (read data, ping data).
    """

    id: int
    error: int
    params: bytes


def stuff(body: bytes) -> bytes:
    """`body` (instruction and parameters) with an FD inserted after every FF FF FD, as it goes on the wire."""
    out = bytearray()
    for byte in body:
        out.append(byte)
        if byte == 0xFD and len(out) >= 3 and out[-3] == 0xFF and out[-2] == 0xFF:
            # the FF FF before this FD are original bytes: an inserted FD is never FF, so `out` can be the context
            out.append(0xFD)
    return bytes(out)


def unstuff(body: bytes) -> bytes:
    """`body` as received with the FD that follows every FF FF FD dropped (the inverse of `stuff`)."""
    out = bytearray()
    for i, byte in enumerate(body):
        if byte == 0xFD and i >= 3 and body[i - 3] == 0xFF and body[i - 2] == 0xFF and body[i - 1] == 0xFD:
            continue
        out.append(byte)
    return bytes(out)


def _check_id(packet_id: int, *, allow_broadcast: bool = True) -> None:
    if not (0 <= packet_id <= 252 or (allow_broadcast and packet_id == BROADCAST_ID)):
        raise PacketError("params", f"ID {packet_id} is not 0..252{' or 254 (broadcast)' if allow_broadcast else ''}")


def _frame(packet_id: int, body: bytes) -> bytes:
    stuffed = stuff(body)
    length = len(stuffed) + 2
    if _PREFIX + length > MAX_PACKET_LENGTH:
        raise PacketError("length", f"{_PREFIX + length} bytes after stuffing, more than {MAX_PACKET_LENGTH}")
    head = HEADER + bytes((packet_id, length & 0xFF, length >> 8)) + stuffed
    return head + crc16(head).to_bytes(2, "little")


def build_instruction(packet_id: int, instruction: int, params: bytes = b"") -> bytes:
    """An instruction packet, stuffed and with its CRC, as the host puts it on the wire.

    Args:
        packet_id: target ID (0..252, or 0xFE broadcast).
        instruction: instruction byte.
        params: the parameters, unstuffed.

    Raises:
        PacketError: the ID is out of range or the packet is longer than `MAX_PACKET_LENGTH`.
    """
    _check_id(packet_id)
    return _frame(packet_id, bytes((int(instruction) & 0xFF,)) + bytes(params))


def build_status(packet_id: int, error: int, params: bytes = b"") -> bytes:
    """A status packet, stuffed and with its CRC, as a servo puts it on the wire.

    Args:
        packet_id: the answering servo's ID (0..252).
        error: the error byte.
        params: the parameters after the error byte, unstuffed.
    """
    _check_id(packet_id, allow_broadcast=False)
    return _frame(packet_id, bytes((Instruction.STATUS, error & 0xFF)) + bytes(params))


def parse_packet(raw: bytes) -> InstructionPacket | StatusPacket:
    """Check and decode one whole packet (header, length, CRC), then remove its stuffing.

    Args:
        raw: exactly one packet, as on the wire.

    Returns:
        A `StatusPacket` if its instruction is STATUS (0x55), else an `InstructionPacket`.

    Raises:
        PacketError: reason ``short`` (fewer than 10 bytes or fewer than LEN says), ``header``, ``length`` (more
            bytes than LEN says), ``crc``, or ``params`` (a status packet without its error byte).
    """
    raw = bytes(raw)
    if len(raw) < _MIN_PACKET:
        raise PacketError("short", f"{len(raw)} bytes, a packet has at least {_MIN_PACKET}")
    if raw[:4] != HEADER:
        raise PacketError("header", f"starts {raw[:4].hex(' ')}, expected {HEADER.hex(' ')}")
    length = raw[5] | raw[6] << 8
    if len(raw) < _PREFIX + length:
        raise PacketError("short", f"LEN {length} needs {_PREFIX + length} bytes, got {len(raw)}")
    if len(raw) > _PREFIX + length:
        raise PacketError("length", f"LEN {length} needs {_PREFIX + length} bytes, got {len(raw)}")
    if length < 3:
        raise PacketError("length", f"LEN {length} is less than 3 (instruction and CRC)")
    crc = raw[-2] | raw[-1] << 8
    if crc16(raw[:-2]) != crc:
        raise PacketError("crc", f"CRC {crc:#06x} on the wire, {crc16(raw[:-2]):#06x} computed")
    body = unstuff(raw[_PREFIX:-2])
    if body[0] == Instruction.STATUS:
        if len(body) < 2:
            raise PacketError("params", "status packet without its error byte")
        return StatusPacket(raw[4], body[1], body[2:])
    return InstructionPacket(raw[4], body[0], body[1:])


class PacketReader:
    """Cuts a byte stream into whole packets: what a servo (or an emulator) does with what it hears on the bus.

    Bytes before a header are dropped and counted in `dropped`; a packet whose LEN is impossible (less than 3, or
    more than `MAX_PACKET_LENGTH` allows) is skipped from its header on. The packets it returns are not yet checked
    (`parse_packet` does that).
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.dropped = 0  # bytes discarded while looking for a header

    @property
    def pending(self) -> int:
        """Bytes held: the start of a packet still incomplete."""
        return len(self._buf)

    def discard(self) -> int:
        """Drop the incomplete packet held (a servo does so after a pause on the bus); return how many bytes."""
        n = len(self._buf)
        self.dropped += n
        self._buf.clear()
        return n

    def feed(self, data: bytes) -> list[bytes]:
        """Add received bytes; return the whole packets they complete, in order."""
        buf = self._buf
        buf += data
        out = []
        while True:
            start = buf.find(HEADER)
            if start < 0:
                keep = 3 if buf.endswith(HEADER[:3]) else 2 if buf.endswith(HEADER[:2]) else 1 if buf.endswith(
                    HEADER[:1]) else 0
                self.dropped += len(buf) - keep
                del buf[: len(buf) - keep]
                return out
            if start:
                self.dropped += start
                del buf[:start]
            if len(buf) < _PREFIX:
                return out
            length = buf[5] | buf[6] << 8
            if length < 3 or _PREFIX + length > MAX_PACKET_LENGTH:
                self.dropped += 1
                del buf[:1]
                continue
            if len(buf) < _PREFIX + length:
                return out
            out.append(bytes(buf[: _PREFIX + length]))
            del buf[: _PREFIX + length]


# -- parameters of each instruction ------------------------------------------------------------------------------
def _u16(value: int, what: str) -> bytes:
    if not 0 <= value <= 0xFFFF:
        raise PacketError("params", f"{what} {value} does not fit 16 bits")
    return value.to_bytes(2, "little")


def _need(params: bytes, n: int, what: str) -> None:
    if len(params) < n:
        raise PacketError("params", f"{what}: {len(params)} parameter bytes, at least {n} needed")


def read_params(address: int, length: int) -> bytes:
    """READ parameters: start address and byte count."""
    return _u16(address, "address") + _u16(length, "length")


def parse_read_params(params: bytes) -> tuple[int, int]:
    """(address, length) of READ parameters.

    Raises:
        PacketError: not exactly 4 bytes.
    """
    if len(params) != 4:
        raise PacketError("params", f"READ takes 4 parameter bytes, got {len(params)}")
    return params[0] | params[1] << 8, params[2] | params[3] << 8


def write_params(address: int, data: bytes) -> bytes:
    """WRITE parameters: start address, then the bytes to write."""
    return _u16(address, "address") + bytes(data)


def parse_write_params(params: bytes) -> tuple[int, bytes]:
    """(address, data) of WRITE parameters.

    Raises:
        PacketError: no data after the address.
    """
    _need(params, 3, "WRITE")
    return params[0] | params[1] << 8, bytes(params[2:])


def sync_read_params(address: int, length: int, ids: Sequence[int]) -> bytes:
    """SYNC_READ (or FAST_SYNC_READ) parameters: address, byte count, then the IDs that answer, in answer order."""
    for i in ids:
        _check_id(i, allow_broadcast=False)
    return _u16(address, "address") + _u16(length, "length") + bytes(ids)


def parse_sync_read_params(params: bytes) -> tuple[int, int, tuple[int, ...]]:
    """(address, length, IDs) of SYNC_READ parameters.

    Raises:
        PacketError: no ID listed.
    """
    _need(params, 5, "SYNC_READ")
    return params[0] | params[1] << 8, params[2] | params[3] << 8, tuple(params[4:])


def sync_write_params(address: int, length: int, data: Iterable[tuple[int, bytes]]) -> bytes:
    """SYNC_WRITE parameters: address, byte count, then each ID followed by its `length` bytes.

    Raises:
        PacketError: an ID's data is not `length` bytes.
    """
    out = bytearray(_u16(address, "address") + _u16(length, "length"))
    for servo_id, chunk in data:
        _check_id(servo_id, allow_broadcast=False)
        if len(chunk) != length:
            raise PacketError("params", f"SYNC_WRITE: ID {servo_id} has {len(chunk)} bytes, the packet {length}")
        out += bytes((servo_id,)) + bytes(chunk)
    return bytes(out)


def parse_sync_write_params(params: bytes) -> tuple[int, int, tuple[tuple[int, bytes], ...]]:
    """(address, length, ((ID, data), ...)) of SYNC_WRITE parameters.

    Raises:
        PacketError: the IDs' data do not divide into blocks of 1 + length bytes.
    """
    _need(params, 4, "SYNC_WRITE")
    address, length = params[0] | params[1] << 8, params[2] | params[3] << 8
    rest = params[4:]
    if length == 0 or not rest or len(rest) % (length + 1):
        raise PacketError("params", f"SYNC_WRITE: {len(rest)} bytes after the header do not make blocks of "
                                    f"1 + {length}")
    step = length + 1
    return address, length, tuple((rest[k], bytes(rest[k + 1: k + step])) for k in range(0, len(rest), step))


def bulk_read_params(items: Iterable[tuple[int, int, int]]) -> bytes:
    """BULK_READ (or FAST_BULK_READ) parameters: for each (ID, address, length), in answer order."""
    out = bytearray()
    for servo_id, address, length in items:
        _check_id(servo_id, allow_broadcast=False)
        out += bytes((servo_id,)) + _u16(address, "address") + _u16(length, "length")
    return bytes(out)


def parse_bulk_read_params(params: bytes) -> tuple[tuple[int, int, int], ...]:
    """((ID, address, length), ...) of BULK_READ parameters.

    Raises:
        PacketError: not a whole number of 5-byte items.
    """
    if not params or len(params) % 5:
        raise PacketError("params", f"BULK_READ takes 5 bytes per ID, got {len(params)}")
    return tuple((params[k], params[k + 1] | params[k + 2] << 8, params[k + 3] | params[k + 4] << 8)
                 for k in range(0, len(params), 5))


def bulk_write_params(items: Iterable[tuple[int, int, bytes]]) -> bytes:
    """BULK_WRITE parameters: for each (ID, address, data), the ID, address, length and data."""
    out = bytearray()
    for servo_id, address, data in items:
        _check_id(servo_id, allow_broadcast=False)
        out += bytes((servo_id,)) + _u16(address, "address") + _u16(len(data), "length") + bytes(data)
    return bytes(out)


def parse_bulk_write_params(params: bytes) -> tuple[tuple[int, int, bytes], ...]:
    """((ID, address, data), ...) of BULK_WRITE parameters.

    Raises:
        PacketError: an item is cut short.
    """
    out, k = [], 0
    while k < len(params):
        if len(params) - k < 6:
            raise PacketError("params", f"BULK_WRITE item at byte {k} is cut short")
        servo_id, address, length = params[k], params[k + 1] | params[k + 2] << 8, params[k + 3] | params[k + 4] << 8
        if length == 0 or k + 5 + length > len(params):
            raise PacketError("params", f"BULK_WRITE item for ID {servo_id} announces {length} bytes, "
                                        f"{len(params) - k - 5} follow")
        out.append((servo_id, address, bytes(params[k + 5: k + 5 + length])))
        k += 5 + length
    if not out:
        raise PacketError("params", "BULK_WRITE without any item")
    return tuple(out)


def ping_status_params(model_number: int, firmware_version: int) -> bytes:
    """A PING answer's parameters: model number (2 bytes) and firmware version."""
    return _u16(model_number, "model number") + bytes((firmware_version & 0xFF,))


def parse_ping_status(params: bytes) -> tuple[int, int]:
    """(model number, firmware version) of a PING answer's parameters.

    Raises:
        PacketError: not 3 bytes.
    """
    if len(params) != 3:
        raise PacketError("params", f"a PING answer has 3 parameter bytes, got {len(params)}")
    return params[0] | params[1] << 8, params[2]


def build_fast_read_status(blocks: Sequence[tuple[int, int, bytes]]) -> bytes:
    """The combined answer to a fast sync / bulk read: one packet, ID 0xFE, one block per servo, not stuffed.

    Args:
        blocks: (error byte, ID, data) of each answering servo, in the order the instruction listed them.

    Returns:
        The packet, each block followed by the CRC of the packet up to it (the last is the packet's CRC).
    """
    if not blocks:
        raise PacketError("params", "a fast read answer needs at least one block")
    length = 1 + sum(4 + len(data) for _, _, data in blocks)  # INST, then ERR ID data CRC per block
    out = bytearray(HEADER + bytes((BROADCAST_ID, length & 0xFF, length >> 8, Instruction.STATUS)))
    crc = crc16(out)
    for error, servo_id, data in blocks:
        block = bytes((error & 0xFF, servo_id)) + bytes(data)
        crc = crc16(block, crc)
        out += block + crc.to_bytes(2, "little")
        crc = crc16(crc.to_bytes(2, "little"), crc)
    return bytes(out)


def parse_fast_read_status(raw: bytes, lengths: Sequence[int]) -> tuple[tuple[int, int, bytes], ...]:
    """The (error byte, ID, data) blocks of a fast read's combined answer, every block's CRC checked.

    Args:
        raw: the whole packet.
        lengths: each block's data length, in order.

    Raises:
        PacketError: wrong header, ID, instruction or length, or a block's CRC does not match.
    """
    raw = bytes(raw)
    expected = _PREFIX + 1 + sum(4 + n for n in lengths)
    if len(raw) != expected:
        raise PacketError("length", f"fast read answer of {len(raw)} bytes, {expected} expected")
    if raw[:4] != HEADER or raw[4] != BROADCAST_ID or raw[7] != Instruction.STATUS:
        raise PacketError("header", f"not a fast read answer: {raw[:8].hex(' ')}")
    if (raw[5] | raw[6] << 8) != expected - _PREFIX:
        raise PacketError("length", f"LEN {raw[5] | raw[6] << 8}, {expected - _PREFIX} expected")
    out, k = [], 8
    for n in lengths:
        end = k + 2 + n
        crc = raw[end] | raw[end + 1] << 8
        if crc16(raw[:end]) != crc:
            raise PacketError("crc", f"block of ID {raw[k + 1]}: CRC {crc:#06x}, {crc16(raw[:end]):#06x} computed")
        out.append((raw[k], raw[k + 1], raw[k + 2: end]))
        k = end + 2
    return tuple(out)
