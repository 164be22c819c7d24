"""`EmulatedServo`: one XM430-W350's control table and the rules that guard it, without any I/O.

The Dynamixel emulator keeps one per ID and hands each instruction to the servos it addresses; time comes in as an
argument, so the rules can be tested without a clock. What it does, as the XM430 e-Manual describes (and where the
e-Manual is silent, the choice is named):

- Writes are all or nothing. A read-only or reserved address, or EEPROM (addresses below 64) written while Torque
  Enable is 1, is an access error (7). Part of a multi-byte register is a data length error (5). A value outside
  the register's range is a data range error (4). A goal beyond the register that bounds it (Current / Velocity /
  PWM Limit; Min / Max Position Limit in position mode) is a data limit error (6).
- Hardware errors (`raise_hardware_error`) latch in Hardware Error Status (70). Every status packet then carries
  the alert bit (0x80). Those selected by Shutdown (63; overload, overheating and electrical shock by default) turn
  the torque off. Only a REBOOT clears them. Writing Torque Enable 1 meanwhile is refused with result fail (1):
  this is our choice, as the e-Manual only says the torque cannot be turned on.
- The bus watchdog (98, in 20 ms units). While the torque is on and the value is 1..127, the servo stops if no
  instruction reaches it for that long. "Reaches it" means its ID, its Secondary ID, broadcast, or a sync / bulk
  list naming it. This is the conservative reading of the e-Manual's "instruction packet". On expiry the register
  reads -1 and the goal registers are refused with a data range error. Writing 0 clears the error; another value
  is refused while it is set. "Stops" is emulated per mode: position modes hold the present position, the others
  get a zero goal (current, velocity, PWM). The torque stays on.
- REBOOT keeps the EEPROM and returns the RAM to its defaults (torque off, errors and watchdog cleared, Goal
  Position = Present Position).
- Goal Position is not changed when the torque is turned on: a host must write it first (the safe assumption).
"""

from __future__ import annotations

import functools

from wbc.hardware.dynamixel.control_table import DRIVE_MODE_REVERSE, XM430_W350, ControlTable, OperatingMode
from wbc.hardware.dynamixel.protocol import (
    ALERT,
    ERR_ACCESS,
    ERR_DATA_LENGTH,
    ERR_DATA_LIMIT,
    ERR_DATA_RANGE,
    ERR_RESULT_FAIL,
)
from wbc.hardware.dynamixel.units import WATCHDOG_UNIT
from wbc.hardware.dynamixel.wx200_bus import ServoSpec

__all__ = ["EmulatedServo", "GOAL_REGISTERS"]

GOAL_REGISTERS = ("goal_pwm", "goal_current", "goal_velocity", "goal_position")
"""The registers that become read-only when the bus watchdog trips."""
_OPERATING_MODES = frozenset(int(m) for m in OperatingMode)
_POSITION_MODES = (OperatingMode.POSITION, OperatingMode.EXTENDED_POSITION, OperatingMode.CURRENT_BASED_POSITION)
_EEPROM_END = 64


@functools.cache
def _layout(table: ControlTable) -> dict[str, tuple[int, int, bool, int]]:
    """Register name -> (address, end, signed, mask) of `table`.

    `get` and `set` run about 90 times per bus cycle of the emulator (its answers wait for them), and looking each
    register up and calling its codec was most of that time.
    """
    return {r.name: (r.address, r.address + r.size, r.signed, (1 << (8 * r.size)) - 1) for r in table.registers}


class EmulatedServo:
    """One servo's registers and rules (not thread-safe: the emulator's bus thread owns it).

    Args:
        spec: its ID and the EEPROM values written into it (drive mode, Secondary ID, limits ...).
        table: its control table.
        now: the time it powers up [s].
    """

    def __init__(self, spec: ServoSpec, table: ControlTable = XM430_W350, *, now: float = 0.0) -> None:
        self.spec = spec
        self.table = table
        self._layout = _layout(table)
        self._regs = table.defaults()
        for name, value in (("id", spec.id), ("baud_rate", spec.baud_rate),
                            ("return_delay_time", spec.return_delay_time), ("drive_mode", spec.drive_mode),
                            ("secondary_id", spec.secondary_id), ("min_position_limit", spec.min_position),
                            ("max_position_limit", spec.max_position), ("velocity_limit", spec.velocity_limit)):
            self.set(name, value)
        self.last_heard = now
        self.powered_at = now
        self.busy_until = now  # a rebooting servo hears nothing until then

    # -- registers --------------------------------------------------------------------------------------------
    def get(self, name: str) -> int:
        """A register's value (signed where the register is)."""
        try:
            start, end, signed, _ = self._layout[name]
        except KeyError:
            self.table[name]  # raises UnknownNameError, naming the registers
            raise
        return int.from_bytes(self._regs[start:end], "little", signed=signed)

    def set(self, name: str, value: int) -> None:
        """Set a register as the servo itself does (present values, errors): no rule is checked."""
        try:
            start, end, _, mask = self._layout[name]
        except KeyError:
            self.table[name]  # raises UnknownNameError, naming the registers
            raise
        self._regs[start:end] = (int(value) & mask).to_bytes(end - start, "little")

    @property
    def id(self) -> int:
        """ID (7)."""
        return self._regs[7]

    @property
    def secondary_id(self) -> int | None:
        """Secondary ID (12), or None when it is 253..255 (none)."""
        sid = self._regs[12]
        return sid if sid <= 252 else None

    @property
    def torque_on(self) -> bool:
        """Torque Enable (64) is 1."""
        return self._regs[64] == 1

    @property
    def mode(self) -> int:
        """Operating Mode (11)."""
        return self._regs[11]

    @property
    def reverse(self) -> bool:
        """Drive Mode's reverse bit."""
        return bool(self._regs[10] & DRIVE_MODE_REVERSE)

    @property
    def hardware_error(self) -> int:
        """Hardware Error Status (70)."""
        return self._regs[70]

    @property
    def watchdog_tripped(self) -> bool:
        """Bus Watchdog reads -1."""
        return self.get("bus_watchdog") == -1

    def status_error(self, number: int = 0) -> int:
        """The error byte of a status packet: `number` with the alert bit while a hardware error is latched."""
        return number | (ALERT if self.hardware_error else 0)

    # -- instructions -----------------------------------------------------------------------------------------
    def read(self, address: int, length: int) -> tuple[int, bytes]:
        """(error number, data) of a READ; data empty on error. Reserved bytes read 0."""
        if length == 0:
            return ERR_DATA_LENGTH, b""
        if address + length > self.table.size:
            return ERR_ACCESS, b""
        return 0, bytes(self._regs[address: address + length])

    def write(self, address: int, data: bytes) -> int:
        """Apply a WRITE if every rule allows it; return the error number (0: written)."""
        error = self._check(address, bytes(data))
        if not error:
            self._regs[address: address + len(data)] = data
        return error

    def _check(self, address: int, data: bytes) -> int:
        if not data:
            return ERR_DATA_LENGTH
        end = address + len(data)
        if end > self.table.size:
            return ERR_ACCESS
        values: dict[str, int] = {}
        k = address
        while k < end:
            reg = self.table.at(k)
            if reg is None or not reg.writable:
                return ERR_ACCESS
            if reg.address < address or reg.address + reg.size > end:
                return ERR_DATA_LENGTH
            if reg.eeprom and self.torque_on:
                return ERR_ACCESS
            values[reg.name] = reg.decode(data[k - address: k - address + reg.size])
            k += reg.size
        for name, value in values.items():
            error = self._check_value(name, value, values)
            if error:
                return error
        return 0

    def _check_value(self, name: str, value: int, values: dict[str, int]) -> int:
        reg = self.table[name]
        if not reg.low <= value <= reg.high:
            return ERR_DATA_RANGE
        if name == "operating_mode" and value not in _OPERATING_MODES:
            return ERR_DATA_RANGE
        if name == "bus_watchdog" and self.watchdog_tripped and value != 0:
            return ERR_DATA_RANGE
        if name in GOAL_REGISTERS:
            if self.watchdog_tripped and values.get("bus_watchdog") != 0:
                return ERR_DATA_RANGE
            if reg.bound is not None and abs(value) > values.get(reg.bound, self.get(reg.bound)):
                return ERR_DATA_LIMIT
            if name == "goal_position" and self.mode == OperatingMode.POSITION and not (
                    self.get("min_position_limit") <= value <= self.get("max_position_limit")):
                return ERR_DATA_LIMIT
        if name == "torque_enable" and value == 1 and self.hardware_error & self.get("shutdown"):
            return ERR_RESULT_FAIL
        return 0

    def reboot(self, now: float, busy_for: float) -> None:
        """REBOOT: RAM back to its defaults (EEPROM kept), deaf for `busy_for` seconds [s]."""
        keep = bytes(self._regs[:_EEPROM_END])
        present = self.get("present_position")
        self._regs = self.table.defaults()
        self._regs[:_EEPROM_END] = keep
        self.set("present_position", present)
        self.set("goal_position", present)
        self.powered_at = now
        self.last_heard = now
        self.busy_until = now + busy_for

    # -- what the servo does by itself -------------------------------------------------------------------------
    def heard(self, now: float) -> None:
        """An instruction reached this servo (it feeds the bus watchdog)."""
        self.last_heard = now

    def watchdog_deadline(self) -> float | None:
        """When the bus watchdog trips if nothing reaches the servo before [s], or None if it is not armed."""
        units = self.get("bus_watchdog")
        if units <= 0 or not self.torque_on:
            return None
        return self.last_heard + units * WATCHDOG_UNIT

    def tick(self, now: float) -> bool:
        """Run the bus watchdog at time `now`; True if it tripped (the goals changed)."""
        deadline = self.watchdog_deadline()
        if deadline is None or now < deadline:
            return False
        self.set("bus_watchdog", -1)
        if self.mode in _POSITION_MODES:
            self.set("goal_position", self.get("present_position"))
        else:
            for name in ("goal_current", "goal_velocity", "goal_pwm"):
                self.set(name, 0)
        return True

    def raise_hardware_error(self, bits: int) -> bool:
        """Latch hardware error `bits`; the torque goes off if Shutdown selects any. True if anything changed."""
        before = (self.hardware_error, self.torque_on)
        self.set("hardware_error_status", self.hardware_error | bits)
        if self.hardware_error & self.get("shutdown"):
            self.set("torque_enable", 0)
        return (self.hardware_error, self.torque_on) != before
