"""`DecodeStats`: how many frames a decoder accepted, and how many it rejected for each reason.

A hardware backend keeps one per stream and hands it to every `decode_state` (or `decode_command`, in the
emulator) call; the decoder counts each frame once, either as accepted or under the first check it failed. The
counts are what a log or a fault-injection test reads: "two corrupt datagrams, both rejected as crc".
"""

from __future__ import annotations

from dataclasses import dataclass

from wbc.errors import UnknownNameError

__all__ = ["REJECT_REASONS", "DecodeStats"]

REJECT_REASONS = ("length", "header", "crc", "non_finite")
"""Why a frame is rejected, in the order the decoders check: exact length, header (magic and levelFlag 0xFF), CRC,
then every decoded float finite."""


@dataclass(kw_only=True)
class DecodeStats:
    """Frame counts of one stream (mutable: a decoder adds to it).

    Attributes:
        accepted: frames decoded and returned.
        length: frames rejected for a length other than the layout's exact frame size.
        header: frames rejected for a wrong magic (Go1 ``FE EF``) or a levelFlag other than 0xFF.
        crc: frames rejected because their CRC did not match.
        non_finite: frames rejected because a decoded float was NaN or infinite.
    """

    accepted: int = 0
    length: int = 0
    header: int = 0
    crc: int = 0
    non_finite: int = 0

    @property
    def rejected(self) -> int:
        """All rejected frames, whatever the reason."""
        return self.length + self.header + self.crc + self.non_finite

    def count_reject(self, reason: str) -> None:
        """Add one rejected frame under `reason`, one of `REJECT_REASONS`.

        Raises:
            UnknownNameError: `reason` is not one of `REJECT_REASONS`.
        """
        if reason not in REJECT_REASONS:
            raise UnknownNameError("frame reject reason", reason, REJECT_REASONS)
        setattr(self, reason, getattr(self, reason) + 1)

    def as_dict(self, prefix: str = "decode/") -> dict[str, int]:
        """The counts as a flat dict for a log, keys namespaced with `prefix` (``decode/crc`` ...)."""
        return {f"{prefix}{name}": getattr(self, name) for name in ("accepted", *REJECT_REASONS)}
