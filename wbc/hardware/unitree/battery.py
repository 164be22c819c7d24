"""`Battery`: the Go1's battery-management block (BmsState, 24 B of its LowState), decoded as the SDK scales it.

Layout from the block's start (LowState offset 715), little-endian: version_h u8 +0, version_l u8 +1, status u8
+2, SOC u8 +3 [%], current i32 +4 [mA], cycle u16 +8, BQ_NTC i8 x 2 +10 [degC], MCU_NTC i8 x 2 +12 [degC], cell
voltages u8 x 10 +14, which the SDK multiplies by 32 to give mV. The A1's LowState has no such block.

The record converts to SI (A, V) and back; `pack_into` reproduces the wire bytes of any block it was read from.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field

import numpy as np

from wbc.errors import ConfigError

__all__ = ["BATTERY_SIZE", "CELL_VOLTAGE_STEP", "NUM_CELLS", "Battery"]

NUM_CELLS = 10
CELL_VOLTAGE_STEP = 0.032  # [V] one count of a cell-voltage byte: the SDK's x 32 mV
BATTERY_SIZE = 24  # [B]
_BMS = struct.Struct("<4BiH2b2b10B")


@dataclass(frozen=True, kw_only=True)
class Battery:
    """The Go1 battery's state, one LowState's worth.

    Attributes:
        version: BMS firmware version (version_h, version_l).
        status: BMS status byte, as sent.
        soc: state of charge [%], 0..100.
        current: battery current [A] (wire: i32 mA; the SDK documents positive as charging).
        cycle: charge cycles.
        bq_ntc: the two BQ (pack) temperature sensors [degC].
        mcu_ntc: the two BMS-controller temperature sensors [degC].
        cell_voltage: the cells' voltages, shape (10,) [V] (wire: u8 counts of 32 mV).
    """

    version: tuple[int, int] = (0, 0)
    status: int = 0
    soc: int = 0
    current: float = 0.0
    cycle: int = 0
    bq_ntc: tuple[int, int] = (0, 0)
    mcu_ntc: tuple[int, int] = (0, 0)
    cell_voltage: np.ndarray = field(default_factory=lambda: np.zeros(NUM_CELLS))

    def __post_init__(self) -> None:
        cells = np.array(self.cell_voltage, dtype=np.float64)
        if cells.shape != (NUM_CELLS,):
            raise ConfigError(f"Battery.cell_voltage must have shape ({NUM_CELLS},) [V], got {cells.shape}")
        cells.setflags(write=False)
        object.__setattr__(self, "cell_voltage", cells)

    @classmethod
    def unpack_from(cls, frame: bytes | bytearray | memoryview, offset: int) -> Battery:
        """Decode the 24-byte block at `offset` of `frame`."""
        v = _BMS.unpack_from(frame, offset)
        return cls(version=(v[0], v[1]), status=v[2], soc=v[3], current=v[4] * 1e-3, cycle=v[5],
                   bq_ntc=(v[6], v[7]), mcu_ntc=(v[8], v[9]),
                   cell_voltage=np.array(v[10:], dtype=np.float64) * CELL_VOLTAGE_STEP)

    def pack_into(self, buf: bytearray, offset: int) -> None:
        """Encode this record into the 24 bytes at `offset` of `buf`, rounding current and voltages to counts.

        Raises:
            ConfigError: a value does not fit its wire field (the message names it).
        """
        counts = np.rint(self.cell_voltage / CELL_VOLTAGE_STEP)
        if not (np.isfinite(counts).all() and counts.min() >= 0 and counts.max() <= 255):
            raise ConfigError(f"Battery.cell_voltage must lie in 0..{255 * CELL_VOLTAGE_STEP:.3f} V "
                              f"(u8 counts of 32 mV), got {self.cell_voltage}")
        if not math.isfinite(self.current):
            raise ConfigError(f"Battery.current must be a finite number of amperes, got {self.current}")
        current_ma = round(self.current * 1e3)
        try:
            _BMS.pack_into(buf, offset, *self.version, self.status, self.soc, current_ma, self.cycle, *self.bq_ntc,
                           *self.mcu_ntc, *counts.astype(np.uint8).tolist())
        except struct.error as exc:
            raise ConfigError(f"Battery: a field does not fit the BmsState block ({exc}); version, status and soc "
                              "are u8, current an i32 of mA, cycle a u16, the NTCs i8") from None
