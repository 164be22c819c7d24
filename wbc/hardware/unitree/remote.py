"""`Remote`: the 40-byte wireless-remote block that both LowCmd and LowState carry, with its buttons and sticks.

The block is kept as its raw bytes (the record re-encodes them exactly, head and idle bytes included); buttons and
sticks are read from them on demand. Layout (both robots, little-endian): head 2 B +0, buttons u16 +2, sticks f32
lx +4, rx +8, ry +12, L2 (analog) +16, ly +20, idle 16 B +24. Button bits of the u16 (byte +2 is the low byte):
R1 0, L1 1, start 2, select 3, R2 4, L2 5, F1 6, F2 7, A 8, B 9, X 10, Y 11, up 12, right 13, down 14, left 15.

Unitree's own convention (unitree_guide) reads L2 + B as "go passive" (damping); `Remote.l2_b` is that test.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from wbc.errors import ConfigError, UnknownNameError
from wbc.hardware.unitree.layout import REMOTE_SIZE

__all__ = ["BUTTONS", "L2_B_MASK", "Remote"]

BUTTONS = {
    "R1": 1 << 0, "L1": 1 << 1, "start": 1 << 2, "select": 1 << 3, "R2": 1 << 4, "L2": 1 << 5, "F1": 1 << 6,
    "F2": 1 << 7, "A": 1 << 8, "B": 1 << 9, "X": 1 << 10, "Y": 1 << 11, "up": 1 << 12, "right": 1 << 13,
    "down": 1 << 14, "left": 1 << 15,
}
"""Button name -> its bit mask in the remote's buttons u16."""

L2_B_MASK = BUTTONS["L2"] | BUTTONS["B"]
"""0x0220: L2 and B held together, Unitree's "passive" (damping) combination."""

_HEAD_BUTTONS_STICKS = struct.Struct("<2sH5f")  # head, buttons, lx, rx, ry, L2, ly: the first 24 bytes
_IDLE = bytes(REMOTE_SIZE - _HEAD_BUTTONS_STICKS.size)


@dataclass(frozen=True, kw_only=True)
class Remote:
    """One wireless-remote block, as it sat on the wire.

    Attributes:
        raw: the 40 bytes of the block.
    """

    raw: bytes = bytes(REMOTE_SIZE)

    def __post_init__(self) -> None:
        if len(self.raw) != REMOTE_SIZE:
            raise ConfigError(f"Remote.raw must be the {REMOTE_SIZE}-byte remote block, got {len(self.raw)} bytes")

    @classmethod
    def build(cls, *, buttons: int | tuple[str, ...] = 0, lx: float = 0.0, rx: float = 0.0, ry: float = 0.0,
              l2: float = 0.0, ly: float = 0.0) -> Remote:
        """A block with the given buttons held and sticks deflected (head and idle bytes zero), e.g. for an emulator.

        Args:
            buttons: the buttons u16, or the names of the buttons held (keys of `BUTTONS`).
            lx: left stick x, in [-1, 1].
            rx: right stick x, in [-1, 1].
            ry: right stick y, in [-1, 1].
            l2: analog L2 trigger, in [0, 1].
            ly: left stick y, in [-1, 1].

        Raises:
            UnknownNameError: a button name is not in `BUTTONS`.
            ConfigError: `buttons` is an integer outside 0..0xFFFF.
        """
        if isinstance(buttons, int):
            if not 0 <= buttons <= 0xFFFF:
                raise ConfigError(f"Remote.build: buttons must be a u16 (0..0xFFFF), got {buttons:#x}")
            mask = buttons
        else:
            mask = 0
            for name in buttons:
                if name not in BUTTONS:
                    raise UnknownNameError("remote button", name, tuple(BUTTONS))
                mask |= BUTTONS[name]
        return cls(raw=_HEAD_BUTTONS_STICKS.pack(b"\0\0", mask, lx, rx, ry, l2, ly) + _IDLE)

    @property
    def buttons(self) -> int:
        """The buttons u16: bit masks in `BUTTONS`."""
        return self.raw[2] | (self.raw[3] << 8)

    def sticks(self) -> tuple[float, float, float, float, float]:
        """The five analog values (lx, rx, ry, l2, ly), in wire order."""
        return _HEAD_BUTTONS_STICKS.unpack_from(self.raw)[2:]

    @property
    def lx(self) -> float:
        """Left stick x."""
        return self.sticks()[0]

    @property
    def rx(self) -> float:
        """Right stick x."""
        return self.sticks()[1]

    @property
    def ry(self) -> float:
        """Right stick y."""
        return self.sticks()[2]

    @property
    def l2(self) -> float:
        """Analog L2 trigger."""
        return self.sticks()[3]

    @property
    def ly(self) -> float:
        """Left stick y."""
        return self.sticks()[4]

    def pressed(self, name: str) -> bool:
        """True if button `name` (a key of `BUTTONS`) is held.

        Raises:
            UnknownNameError: `name` is not a button; the message lists them.
        """
        if name not in BUTTONS:
            raise UnknownNameError("remote button", name, tuple(BUTTONS))
        return bool(self.buttons & BUTTONS[name])

    @property
    def held(self) -> tuple[str, ...]:
        """Names of every button held, in bit order."""
        b = self.buttons
        return tuple(name for name, mask in BUTTONS.items() if b & mask)

    @property
    def l2_b(self) -> bool:
        """L2 and B held together: Unitree's "go passive" (damping) request."""
        return (self.buttons & L2_B_MASK) == L2_B_MASK
