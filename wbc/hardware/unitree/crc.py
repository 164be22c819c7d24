"""The CRC of Unitree low-level frames, computed by zlib in microseconds.

The SDKs (Go1 3.8, A1 3.3.1) compute a 32-bit CRC with polynomial 0x04C11DB7, initial value 0xFFFFFFFF, MSB
first, no reflection and no final xor, over the first ``(len >> 2) - 1`` little-endian u32 words of the frame, and
store it (little-endian) in the frame's last 4 bytes. The reserve bytes between the last covered word and the CRC
(2 in a LowCmd, 3 in a LowState, on both robots) are not covered.

That CRC is CRC-32/MPEG-2 of the words written big-endian. zlib only computes the reflected CRC-32, but reflecting
every input byte turns one into the other: ``mpeg2(d) = rev32(~zlib.crc32(rev8(d)))``, where ``rev8`` reverses the
bits of each byte (``bytes.translate``) and ``rev32`` those of the 32-bit result. A bit loop in Python takes about
1.5 ms a frame; this takes a few microseconds. The tests hold it against a bit-by-bit reference.

The SDK's receive path also knows an "encrypted" CRC variant for frames with levelFlag 0xEE (high level); the
low-level codec never writes nor accepts those frames, so it is not implemented.
"""

from __future__ import annotations

import zlib

import numpy as np

__all__ = ["crc_words", "frame_crc"]

_REVERSE_BITS = bytes(int(f"{i:08b}"[::-1], 2) for i in range(256))
"""Translation table: each byte value to the value with its 8 bits in reverse order."""


def crc_words(data: bytes | bytearray | memoryview, num_words: int) -> int:
    """The Unitree CRC of the first `num_words` little-endian u32 words of `data`.

    Args:
        data: at least ``4 * num_words`` bytes.
        num_words: how many u32 words to cover.

    Returns:
        The CRC as an unsigned 32-bit integer.
    """
    words_big_endian = np.frombuffer(data, dtype="<u4", count=num_words).astype(">u4").tobytes()
    reflected = zlib.crc32(words_big_endian.translate(_REVERSE_BITS)) ^ 0xFFFFFFFF
    return int.from_bytes(reflected.to_bytes(4, "little").translate(_REVERSE_BITS), "big")


def frame_crc(frame: bytes | bytearray | memoryview) -> int:
    """The CRC a frame of this length must carry in its last 4 bytes, computed as the SDKs do.

    Args:
        frame: a whole LowCmd or LowState frame (its CRC field is not read).

    Returns:
        The CRC over the frame's first ``(len(frame) >> 2) - 1`` words, as an unsigned 32-bit integer.
    """
    return crc_words(frame, (len(frame) >> 2) - 1)
