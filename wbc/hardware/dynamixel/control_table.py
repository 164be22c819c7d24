"""The XM430-W350 control table as data: every register's address, size, access, memory area, default and range.

Source: ROBOTIS's XM430-W350 e-Manual (model number 1020, firmware 45+), the same addresses as the SDK's model files
and Interbotix's driver use. EEPROM registers (addresses 0..63) keep their value over a power cycle and can be
written only while Torque Enable (64) is 0; RAM registers (64 on) return to their default at power-up and on REBOOT.
A register's range is the e-Manual's; a few are bounded by another register (``bound``): Goal PWM by PWM Limit,
Goal Current by Current Limit, Goal Velocity by Velocity Limit, symmetrically; Goal Position by Min / Max Position
Limit in position mode (3) only, and by +-1,048,575 in extended (4) and current-based (5) position modes. Reserved
addresses inside the table read as 0 and cannot be written. Indirect addresses (168..) are not listed.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from wbc.errors import UnknownNameError

__all__ = [
    "BAUD_RATES",
    "HARDWARE_ERROR_BITS",
    "HW_ELECTRICAL_SHOCK",
    "HW_ENCODER",
    "HW_INPUT_VOLTAGE",
    "HW_OVERHEATING",
    "HW_OVERLOAD",
    "DRIVE_MODE_REVERSE",
    "XM430_W350",
    "XM430_W350_MODEL_NUMBER",
    "ControlTable",
    "OperatingMode",
    "Register",
]

XM430_W350_MODEL_NUMBER = 1020
"""What a PING of an XM430-W350 answers, and what Model Number (0) holds."""


class OperatingMode(enum.IntEnum):
    """Operating Mode (11) values of an XM430."""

    CURRENT = 0
    VELOCITY = 1
    POSITION = 3
    EXTENDED_POSITION = 4
    CURRENT_BASED_POSITION = 5
    PWM = 16


DRIVE_MODE_REVERSE = 0x01
"""Drive Mode (10) bit 0: reverse mode (clockwise positive): positions, velocities, currents and goals flip sign."""

HW_INPUT_VOLTAGE = 0x01
"""Hardware Error Status (70) bit 0: input voltage outside Min / Max Voltage Limit."""
HW_OVERHEATING = 0x04
"""Bit 2: Present Temperature above Temperature Limit."""
HW_ENCODER = 0x08
"""Bit 3: motor encoder malfunction."""
HW_ELECTRICAL_SHOCK = 0x10
"""Bit 4: electrical shock on the circuit, or input power too low."""
HW_OVERLOAD = 0x20
"""Bit 5: a load beyond the servo's capacity persisted."""
HARDWARE_ERROR_BITS = {
    HW_INPUT_VOLTAGE: "input voltage",
    HW_OVERHEATING: "overheating",
    HW_ENCODER: "motor encoder",
    HW_ELECTRICAL_SHOCK: "electrical shock",
    HW_OVERLOAD: "overload",
}
"""Hardware Error Status bit -> its e-Manual name. Shutdown (63) selects which of them turn the torque off."""

BAUD_RATES = {0: 9600, 1: 57_600, 2: 115_200, 3: 1_000_000, 4: 2_000_000, 5: 3_000_000, 6: 4_000_000,
              7: 4_500_000}
"""Baud Rate (8) value -> bits per second."""


@dataclass(frozen=True, kw_only=True)
class Register:
    """One entry of a control table.

    Attributes:
        name: the e-Manual's name, snake case (``goal_current``).
        address: first byte.
        size: bytes (1, 2 or 4), little-endian.
        writable: False for read-only registers.
        eeprom: True in the EEPROM area (written only while the torque is off).
        default: value at power-up (EEPROM: the factory value).
        low: smallest value a write may set (None for read-only registers).
        high: largest value a write may set.
        signed: the bytes hold a two's-complement value.
        unit: what one unit means (``"0.229 rpm"``, ``"2.69 mA"``, ``""``).
        bound: name of the register whose value bounds this one (+-bound), or None.
    """

    name: str
    address: int
    size: int
    writable: bool
    eeprom: bool
    default: int
    low: int | None = None
    high: int | None = None
    signed: bool = False
    unit: str = ""
    bound: str | None = None

    def decode(self, data: bytes) -> int:
        """The register's value from its `size` bytes."""
        return int.from_bytes(data[: self.size], "little", signed=self.signed)

    def encode(self, value: int) -> bytes:
        """The `size` bytes of `value` (two's complement for a signed register; wrapped to the size otherwise)."""
        mask = (1 << (8 * self.size)) - 1
        return (int(value) & mask).to_bytes(self.size, "little")


class ControlTable:
    """A model's registers, by name and by address.

    Args:
        model: the model's name.
        model_number: what Model Number (0) holds.
        size: bytes the table spans (reads beyond it are refused).
        registers: the registers, in address order, none overlapping.
    """

    def __init__(self, model: str, model_number: int, size: int, registers: tuple[Register, ...]) -> None:
        self.model = model
        self.model_number = model_number
        self.size = size
        self.registers = registers
        self._by_name = {r.name: r for r in registers}
        self._at = [None] * size
        for r in registers:
            for k in range(r.address, r.address + r.size):
                if self._at[k] is not None:
                    raise ValueError(f"{model}: {r.name} overlaps {self._at[k].name} at address {k}")
                self._at[k] = r

    def __getitem__(self, name: str) -> Register:
        """The register called `name`.

        Raises:
            UnknownNameError: no such register; the message lists them.
        """
        try:
            return self._by_name[name]
        except KeyError:
            raise UnknownNameError(f"{self.model} register", name, tuple(self._by_name)) from None

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def at(self, address: int) -> Register | None:
        """The register that holds byte `address`, or None (reserved, or beyond the table)."""
        return self._at[address] if 0 <= address < self.size else None

    def defaults(self) -> bytearray:
        """The whole table at its default values (reserved bytes 0)."""
        out = bytearray(self.size)
        for r in self.registers:
            out[r.address: r.address + r.size] = r.encode(r.default)
        return out


def _ee(name: str, address: int, size: int, default: int, low: int | None = None, high: int | None = None, *,
        writable: bool = True, signed: bool = False, unit: str = "") -> Register:
    return Register(name=name, address=address, size=size, writable=writable, eeprom=True, default=default,
                    low=low if writable else None, high=high if writable else None, signed=signed, unit=unit)


def _ram(name: str, address: int, size: int, default: int, low: int | None = None, high: int | None = None, *,
         writable: bool = True, signed: bool = False, unit: str = "", bound: str | None = None) -> Register:
    return Register(name=name, address=address, size=size, writable=writable, eeprom=False, default=default,
                    low=low if writable else None, high=high if writable else None, signed=signed, unit=unit,
                    bound=bound)


XM430_W350 = ControlTable("XM430-W350", XM430_W350_MODEL_NUMBER, 148, (
    _ee("model_number", 0, 2, XM430_W350_MODEL_NUMBER, writable=False),
    _ee("model_information", 2, 4, 0, writable=False),
    _ee("firmware_version", 6, 1, 46, writable=False),
    _ee("id", 7, 1, 1, 0, 252),
    _ee("baud_rate", 8, 1, 1, 0, 7),
    _ee("return_delay_time", 9, 1, 250, 0, 254, unit="2 us"),
    _ee("drive_mode", 10, 1, 0, 0, 13),
    _ee("operating_mode", 11, 1, 3, 0, 16),
    _ee("secondary_id", 12, 1, 255, 0, 255),
    _ee("protocol_type", 13, 1, 2, 1, 2),
    _ee("homing_offset", 20, 4, 0, -1_044_479, 1_044_479, signed=True, unit="0.088 deg"),
    _ee("moving_threshold", 24, 4, 10, 0, 1023, unit="0.229 rpm"),
    _ee("temperature_limit", 31, 1, 80, 0, 100, unit="1 degC"),
    _ee("max_voltage_limit", 32, 2, 160, 95, 160, unit="0.1 V"),
    _ee("min_voltage_limit", 34, 2, 95, 95, 160, unit="0.1 V"),
    _ee("pwm_limit", 36, 2, 885, 0, 885, unit="0.113 %"),
    _ee("current_limit", 38, 2, 1193, 0, 1193, unit="2.69 mA"),
    _ee("velocity_limit", 44, 4, 200, 0, 1023, unit="0.229 rpm"),
    _ee("max_position_limit", 48, 4, 4095, 0, 4095, unit="0.088 deg"),
    _ee("min_position_limit", 52, 4, 0, 0, 4095, unit="0.088 deg"),
    _ee("startup_configuration", 60, 1, 0, 0, 3),
    _ee("shutdown", 63, 1, 0x34, 0, 0xFF),
    _ram("torque_enable", 64, 1, 0, 0, 1),
    _ram("led", 65, 1, 0, 0, 1),
    _ram("status_return_level", 68, 1, 2, 0, 2),
    _ram("registered_instruction", 69, 1, 0, writable=False),
    _ram("hardware_error_status", 70, 1, 0, writable=False),
    _ram("velocity_i_gain", 76, 2, 1920, 0, 16383),
    _ram("velocity_p_gain", 78, 2, 100, 0, 16383),
    _ram("position_d_gain", 80, 2, 0, 0, 16383),
    _ram("position_i_gain", 82, 2, 0, 0, 16383),
    _ram("position_p_gain", 84, 2, 800, 0, 16383),
    _ram("feedforward_2nd_gain", 88, 2, 0, 0, 16383),
    _ram("feedforward_1st_gain", 90, 2, 0, 0, 16383),
    _ram("bus_watchdog", 98, 1, 0, 0, 127, signed=True, unit="20 ms"),
    _ram("goal_pwm", 100, 2, 0, -885, 885, signed=True, unit="0.113 %", bound="pwm_limit"),
    _ram("goal_current", 102, 2, 0, -1193, 1193, signed=True, unit="2.69 mA", bound="current_limit"),
    _ram("goal_velocity", 104, 4, 0, -1023, 1023, signed=True, unit="0.229 rpm", bound="velocity_limit"),
    _ram("profile_acceleration", 108, 4, 0, 0, 32767, unit="214.577 rev/min^2"),
    _ram("profile_velocity", 112, 4, 0, 0, 32767, unit="0.229 rpm"),
    _ram("goal_position", 116, 4, 0, -1_048_575, 1_048_575, signed=True, unit="0.088 deg"),
    _ram("realtime_tick", 120, 2, 0, writable=False, unit="1 ms"),
    _ram("moving", 122, 1, 0, writable=False),
    _ram("moving_status", 123, 1, 0, writable=False),
    _ram("present_pwm", 124, 2, 0, writable=False, signed=True, unit="0.113 %"),
    _ram("present_current", 126, 2, 0, writable=False, signed=True, unit="2.69 mA"),
    _ram("present_velocity", 128, 4, 0, writable=False, signed=True, unit="0.229 rpm"),
    _ram("present_position", 132, 4, 0, writable=False, signed=True, unit="0.088 deg"),
    _ram("velocity_trajectory", 136, 4, 0, writable=False, signed=True, unit="0.229 rpm"),
    _ram("position_trajectory", 140, 4, 0, writable=False, signed=True, unit="0.088 deg"),
    _ram("present_input_voltage", 144, 2, 120, writable=False, unit="0.1 V"),
    _ram("present_temperature", 146, 1, 30, writable=False, unit="1 degC"),
    _ram("backup_ready", 147, 1, 0, writable=False),
))
"""The XM430-W350's table (the XM430-W210 shares it). Defaults are the factory values; `WX200_BUS`
(`wbc.hardware.dynamixel.wx200_bus`) lists what Interbotix writes into the EEPROM of each servo of the arm."""
