"""The checks every received frame passes before any field of it is read: exact length, header, CRC.

Stricter than the SDKs, on purpose. The SDK accepts a frame longer than its struct (it reads the prefix), never
looks at levelFlag on receive, and on the A1 has no magic to look at at all. Here:

- length: exactly the layout's frame size, nothing longer or shorter.
- header: the Go1's magic ``FE EF`` and levelFlag 0xFF; the A1 has no magic, so its header check is levelFlag
  0xFF alone. A low-level stream always carries 0xFF; any other value is another stream (0xEE is the Go1's high
  level, 0x00 the A1's high level) or a corrupt or foreign datagram that happens to have the right length and
  CRC, and its fields cannot be trusted to mean what the low-level layout says.
- crc: the CRC the frame carries equals the one computed over it (`wbc.hardware.unitree.crc`).

A failed check counts the frame in the stream's `DecodeStats` and raises `FrameError` naming the reason; the
non-finite check comes after these, in the decoders, once the floats are read.
"""

from __future__ import annotations

from wbc.errors import FrameError
from wbc.hardware.unitree.crc import frame_crc
from wbc.hardware.unitree.decode_stats import DecodeStats
from wbc.hardware.unitree.layout import LAYOUTS, LEVEL_LOWLEVEL, FrameLayout, with_article

__all__ = ["check_frame", "reject"]


def reject(stats: DecodeStats | None, reason: str, layout: FrameLayout, frame_kind: str, detail: str) -> FrameError:
    """Count a rejected frame in `stats` and return the `FrameError` for the caller to raise."""
    if stats is not None:
        stats.count_reject(reason)
    return FrameError(reason, layout.robot, frame_kind, detail)


def _robot_of_size(length: int, frame_kind: str, layout: FrameLayout) -> str | None:
    """The other robot whose `frame_kind` is exactly `length` bytes, or None."""
    for name, other in LAYOUTS.items():
        if name != layout.robot and length == (other.state_size if frame_kind == "LowState" else other.cmd_size):
            return name
    return None


def check_frame(layout: FrameLayout, frame: bytes, size: int, frame_kind: str, stats: DecodeStats | None) -> None:
    """Check length, header and CRC of a received frame, in that order.

    Args:
        layout: the robot's frame layout.
        frame: the datagram as received.
        size: the exact frame size for `frame_kind` [B].
        frame_kind: ``LowState`` or ``LowCmd``, for the message.
        stats: the stream's counters, or None.

    Raises:
        FrameError: with reason ``length``, ``header`` or ``crc``; counted in `stats`.
    """
    if len(frame) != size:
        other = _robot_of_size(len(frame), frame_kind, layout)
        if other is not None:  # the exact size of another robot's frame: a client and a robot of different models
            raise reject(stats, "length", layout, frame_kind,
                         f"{len(frame)} bytes, expected exactly {size}: {len(frame)} bytes is {with_article(other)} "
                         f"{frame_kind}, and this side speaks {layout.robot}; check --robot on both sides "
                         f"({with_article(other)} client against {with_article(layout.robot)} robot, or the reverse)")
        raise reject(stats, "length", layout, frame_kind,
                     f"{len(frame)} bytes, expected exactly {size} (a truncated or padded datagram, or a frame of "
                     f"another robot or SDK version; check that the codec's layout is the robot's)")
    header = layout.header
    if frame[:len(header)] != header:
        magic = layout.magic
        if frame[:len(magic)] != magic:
            raise reject(stats, "header", layout, frame_kind,
                         f"starts with {frame[:len(magic)].hex(' ')}, expected the magic {magic.hex(' ')}: not a "
                         f"{layout.robot} frame (a foreign datagram on this port?)")
        level = frame[layout.level_offset]
        raise reject(stats, "header", layout, frame_kind,
                     f"levelFlag {level:#04x}, expected {LEVEL_LOWLEVEL:#04x} (low level): this is another stream "
                     "(0xEE is the Go1's high level, 0x00 the A1's) or a corrupt datagram; put the robot into "
                     "low-level mode, or find which process sends to this port")
    stored = int.from_bytes(frame[size - 4:size], "little")
    computed = frame_crc(frame)
    if stored != computed:
        raise reject(stats, "crc", layout, frame_kind,
                     f"the frame carries CRC {stored:#010x}, its bytes give {computed:#010x}: the datagram was "
                     "corrupted on the way; it is dropped (check the cable and the network load)")
