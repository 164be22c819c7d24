"""`SdkBus`: the arm's serial bus through dynamixel_sdk, and the one place in `wbc` that calls that library.

The backend (`DynamixelArm`) speaks to the servos only through this class. The SDK's `PacketHandler` (Protocol 2.0)
is used unmodified: its transmit functions (`txPacket`, `syncReadTx`, `syncWriteTxOnly`) and its receive function
`rxPacket`, which returns a whole status packet, CRC checked. Its helpers that wait for an answer are not used.
`GroupSyncRead` throws each status packet's error byte away (the error byte carries the hardware alert) and fails
the whole read without saying which ID failed. `readRx` and `txRxPacket` (behind `ping` and `writeTxRx`) take any
status packet from the right ID as the answer, whatever its length. A late answer to an earlier request then passes
for the answer to this one: on a loaded machine, a 10-byte answer of present values was read as a 1-byte Hardware
Error Status, and its first byte as error bits, and a ping took a read's answer for its model number (the SDK's own
``read4ByteTxRx`` raised `IndexError` on a 1-byte answer it took for a 4-byte one). Here every request says what it
expects (`Expected`: the ID, the instruction, and so the exact length of the answer: a READ's bytes, a PING's three,
a WRITE's none), and a status packet that does not match the outstanding request is an answer to an earlier one:
it is counted in `late` and discarded, and the wait for the right one goes on within the request's reply timeout.
Protocol 2.0 has no sequence number, so an answer of the same ID and length to the same request repeated (a retry)
cannot be told apart: it carries the same registers, read a few milliseconds earlier.

Two things of the SDK's port handler are replaced, in a subclass built when the SDK is first needed
(`sdk_handlers`):

- the latency timer. The SDK reads it from a module constant (16 ms) that sets every port's reply timeout. A silent
  ID then costs about 35 ms. The U2D2's FTDI adapter is set to 1 ms by Interbotix's udev rule, so here the timer is
  an argument of each port.
- the wait for a reply. The SDK polls the port in a tight loop that holds a CPU core and Python's global lock while
  it waits. Here a read that finds nothing waits on the port's file descriptor, for at most 1 ms at a time. On a
  loopback emulator in the same process, the spinning reader starved the emulator's thread: about 15 % of the sync
  reads timed out on a loaded 2-core machine, against under 0.5 % with the wait.

`in_process_handlers` builds a third port handler, for tests and benches: no serial device, but a bus in the same
process (`InProcessDevice`: the Dynamixel emulator built in process). The bytes the SDK writes are handed to the
device within the same call, and its answers are queued for the SDK to read, each once its delay has passed. Every
time the SDK reads (the reply timeout's start and expiry, the wait for a reply) comes from a `Clock`: on a
`ManualClock` a wait moves the clock, so a silent ID times out after exactly its timeout of clock time, on any
machine at any load.

Every exception the serial layer raises becomes a `SerialPortError`. A closed port raises `termios.error`, which is
neither `OSError` nor pyserial's `SerialException`, and a port closed under the SDK can raise `TypeError` or
`AttributeError` as well. All of them mean the port is unusable, and the caller needs one type to catch.
"""

from __future__ import annotations

import functools
import heapq
import itertools
import select
import termios
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar, runtime_checkable

import numpy as np

from wbc.errors import CommandError, SerialPortError
from wbc.hardware.clock import Clock, ManualClock
from wbc.hardware.dynamixel.control_table import ControlTable
from wbc.hardware.dynamixel.protocol import Instruction
from wbc.hardware.serial_port_policy import IN_PROCESS_PREFIX, check_serial_port
from wbc.optional import require

__all__ = [
    "COMM_RX_CORRUPT",
    "COMM_RX_TIMEOUT",
    "COMM_SUCCESS",
    "Expected",
    "InProcessDevice",
    "SdkBus",
    "ServoRead",
    "describe_result",
    "in_process_handlers",
    "register_bytes",
    "sdk_handlers",
]

COMM_SUCCESS = 0
"""The SDK's result of a transfer that worked (`dynamixel_sdk.COMM_SUCCESS`)."""
COMM_RX_TIMEOUT = -3001
"""No status packet arrived in time (a silent ID, or a late answer)."""
COMM_RX_CORRUPT = -3002
"""A status packet arrived with a wrong CRC, or cut short."""
_RESULT_NAMES = {COMM_SUCCESS: "success", -1000: "port busy", -1001: "tx fail", -1002: "rx fail", -2000: "tx error",
                 -3000: "rx waiting", COMM_RX_TIMEOUT: "rx timeout", COMM_RX_CORRUPT: "rx corrupt",
                 -9000: "not available"}
_PING_PARAMS = 3  # a ping's answer: model number (2 bytes), firmware version (1)
_STATUS_OVERHEAD = 11  # header (4), ID, length (2), instruction, error, CRC (2): the bytes a status adds to its data
_WAIT_SLICE = 0.001  # [s] longest single wait for the port's file descriptor
_MIN_WAIT = 1e-6  # [s] the least an in-process wait moves the clock, so that a timeout always comes

T = TypeVar("T")


def describe_result(result: int) -> str:
    """An SDK transfer result in words, e.g. ``"rx timeout (-3001)"``."""
    return f"{_RESULT_NAMES.get(result, 'unknown')} ({result})"


@dataclass(frozen=True)
class ServoRead:
    """One servo's answer to a read.

    Attributes:
        id: the servo asked.
        data: the bytes read (empty unless `result` is `COMM_SUCCESS`).
        result: the SDK's transfer result (`COMM_SUCCESS`, `COMM_RX_TIMEOUT`, `COMM_RX_CORRUPT` ...).
        error: the status packet's error byte (bit 7: hardware alert).
    """

    id: int
    data: bytes
    result: int
    error: int

    @property
    def ok(self) -> bool:
        """The transfer worked (the error byte may still carry an alert)."""
        return self.result == COMM_SUCCESS

    def value(self, offset: int, size: int, *, signed: bool = False) -> int:
        """The little-endian integer of `size` bytes at `offset` of the data."""
        return int.from_bytes(self.data[offset: offset + size], "little", signed=signed)


@dataclass(frozen=True)
class Expected:
    """What the outstanding request expects back: an answer from `id` to `instruction`, carrying `length` bytes.

    A status packet carries no instruction and no sequence number: the request's ID and the length its
    instruction implies (a READ's bytes, a PING's 3, a WRITE's 0) are what an answer is matched on.
    """

    id: int
    instruction: Instruction
    length: int

    def matches(self, packet: Sequence[int]) -> bool:
        """True if `packet` (a whole status packet, stuffing removed) answers this request."""
        # FF FF FD 00 | ID | LEN_L LEN_H | 0x55 | ERR | params | CRC, LEN = params + 4
        return packet[4] == self.id and packet[5] | packet[6] << 8 == self.length + 4


@functools.cache
def _low_latency_port_handler() -> type:
    sdk = require("dynamixel_sdk")

    class LowLatencyPortHandler(sdk.PortHandler):
        """The SDK's port handler with its own latency timer, waiting on the port instead of spinning."""

        def __init__(self, port_name: str, latency_ms: float) -> None:
            super().__init__(port_name)
            self.latency_ms = float(latency_ms)

        def setPacketTimeout(self, packet_length: int) -> None:  # noqa: N802 - the SDK's name
            # the SDK's formula, with this port's latency timer instead of the module constant
            self.packet_start_time = self.getCurrentTime()
            self.packet_timeout = self.tx_time_per_byte * packet_length + 2.0 * self.latency_ms + 2.0

        def readPort(self, length: int) -> bytes:  # noqa: N802 - the SDK's name
            data = self.ser.read(length)
            if data:
                return data
            left = (self.packet_timeout - self.getTimeSinceStart()) * 1e-3
            if left > 0:
                select.select([self.ser.fileno()], [], [], min(left, _WAIT_SLICE))
                data = self.ser.read(length)
            return data

    return LowLatencyPortHandler


@runtime_checkable
class InProcessDevice(Protocol):
    """A Dynamixel bus in this process, as `in_process_handlers` talks to it."""

    @property
    def port_closed(self) -> bool:
        """True once the device is gone (an unplugged adapter): every port operation then fails."""
        ...

    def receive(self, data: bytes, *, baud: int, reply: Callable[[bytes, float], None]) -> None:
        """Bytes the host wrote at `baud` [bit/s]; each answer goes to ``reply(raw, delay [s])`` before returning."""
        ...


@functools.cache
def _in_process_port_handler() -> type:
    sdk = require("dynamixel_sdk")

    class InProcessPortHandler(sdk.PortHandler):
        """The SDK's port handler on a bus in this process, its time read from a `Clock` (see the module docstring).

        An answer with a delay is queued when it falls due: when the port looks at its input (a read, a flush, a
        count of the bytes waiting) at or after that time, or, on a `ManualClock`, when the clock runs a task it
        registered for that time. A read that finds nothing waits on the clock until the next answer is due, the
        reply timeout expires, or a wait slice (1 ms) has passed, whichever comes first.
        """

        def __init__(self, port_name: str, device: InProcessDevice, clock: Clock, latency_ms: float) -> None:
            super().__init__(port_name)
            self.device = device
            self.clock = clock
            self.latency_ms = float(latency_ms)
            self._input = bytearray()
            self._due: list[tuple[float, int, bytes]] = []  # (when [s], order, answer) not yet arrived
            self._order = itertools.count()

        def _alive(self) -> None:
            if self.device.port_closed:
                # what dynamixel_sdk raises on a pty whose other side is gone
                raise termios.error(5, "Input/output error")

        def _arrive(self) -> None:
            now = self.clock.now()
            while self._due and self._due[0][0] <= now:
                self._input += heapq.heappop(self._due)[2]

        def _answer(self, raw: bytes, delay: float) -> None:
            if delay <= 0:
                self._input += raw
                return
            when = self.clock.now() + delay
            heapq.heappush(self._due, (when, next(self._order), bytes(raw)))
            if isinstance(self.clock, ManualClock):
                self.clock.call_at(when, self._arrive)

        def setupPort(self, cflag_baud: int) -> bool:  # noqa: N802 - the SDK's name
            self._alive()
            self.is_open = True
            self._input.clear()
            self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
            return True

        def closePort(self) -> None:  # noqa: N802
            self.is_open = False
            self._input.clear()
            self._due.clear()

        def clearPort(self) -> None:  # noqa: N802
            self._alive()
            self._arrive()
            self._input.clear()

        def getBytesAvailable(self) -> int:  # noqa: N802
            self._alive()
            self._arrive()
            return len(self._input)

        def writePort(self, packet: Sequence[int]) -> int:  # noqa: N802
            self._alive()
            self.device.receive(bytes(packet), baud=self.baudrate, reply=self._answer)
            return len(packet)

        def readPort(self, length: int) -> bytes:  # noqa: N802
            self._alive()
            self._arrive()
            if not self._input:
                left = (self.packet_timeout - self.getTimeSinceStart()) * 1e-3
                wait = min(max(left, 0.0), _WAIT_SLICE)
                if self._due:
                    wait = min(wait, self._due[0][0] - self.clock.now())
                self.clock.sleep(max(wait, _MIN_WAIT))
                self._arrive()
            data = bytes(self._input[:length])
            del self._input[:length]
            return data

        def setPacketTimeout(self, packet_length: int) -> None:  # noqa: N802
            # the SDK's formula, with this port's latency timer instead of the module constant
            self.packet_start_time = self.getCurrentTime()
            self.packet_timeout = self.tx_time_per_byte * packet_length + 2.0 * self.latency_ms + 2.0

        def isPacketTimeout(self) -> bool:  # noqa: N802
            # at the timeout, not a float's width after it: a wait that ends on the timeout ends the read
            if self.getTimeSinceStart() >= self.packet_timeout:
                self.packet_timeout = 0
                return True
            return False

        def getCurrentTime(self) -> float:  # noqa: N802
            return self.clock.now() * 1e3  # [ms], as the SDK's

    return InProcessPortHandler


def in_process_handlers(port: str, device: InProcessDevice, clock: Clock,
                        latency_ms: float = 1.0) -> tuple[Any, Any]:
    """A port handler named `port` on the in-process bus `device`, timed by `clock`, and the Protocol 2.0 handler.

    Args:
        port: the name the port goes by (what `DynamixelArmConfig.port` must name).
        device: the bus (e.g. ``DynamixelEmulator(..., in_process=True)``).
        clock: where the reply timeout is measured and the waits happen.
        latency_ms: the adapter's latency timer [ms], which sets the reply timeout.

    Raises:
        MissingExtraError: dynamixel_sdk is not installed (``pip install 'wbc[hardware]'``).
    """
    sdk = require("dynamixel_sdk")
    return _in_process_port_handler()(port, device, clock, latency_ms), sdk.PacketHandler(2.0)


def register_bytes(value: int, size: int, address: int, table: ControlTable | None = None) -> list[int]:
    """`value` as a register's `size` little-endian bytes (two's complement for a negative value), checked first.

    A value that does not fit is refused, never wrapped: -40000 in a 2-byte Goal Current would reach the servo as
    25536. With the servos' `table`, the write must also name a writable register exactly (its first byte and its
    size) and stay within the register's range (`Register.low` / `high`): 40000 fits two bytes, and no servo takes it
    as a Goal Current.

    Args:
        value: the register value (an integer; numpy integers too).
        size: the register's width [bytes].
        address: the register's address.
        table: the servos' control table; None checks the width only.

    Raises:
        CommandError: `value` is not an integer or does not fit `size` bytes; with `table`, the address and size name
            no writable register, or `value` lies outside its range.
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise CommandError(f"register {address}: {value!r} is not an integer register value")
    v, bits = int(value), 8 * size
    if not -(1 << (bits - 1)) <= v < (1 << bits):
        raise CommandError(f"register {address}: {v} does not fit its {size} bytes; refused, not wrapped")
    if table is not None:
        reg = table.at(address)
        if reg is None or reg.address != address or reg.size != size or not reg.writable:
            raise CommandError(f"register {address} ({size} bytes) is no writable register of the {table.model}")
        if not reg.low <= v <= reg.high:
            raise CommandError(f"register {address} ({reg.name}): {v} lies outside its range {reg.low}..{reg.high}; "
                               "refused, not sent")
    return list((v & ((1 << bits) - 1)).to_bytes(size, "little"))


def sdk_handlers(port: str, latency_ms: float = 1.0, *, allow_hardware: bool = False) -> tuple[Any, Any]:
    """dynamixel_sdk's port handler for `port` (not opened) and its Protocol 2.0 packet handler.

    Args:
        port: the serial device (``/dev/ttyUSB0`` for a U2D2, or an emulator's pseudo-terminal).
        latency_ms: the adapter's latency timer [ms], which sets the reply timeout.
        allow_hardware: whether `port` may be a real device (`wbc.hardware.serial_port_policy`); without it, only an
            emulator's pseudo-terminal is accepted.

    Raises:
        TargetRefusedError: `port` is a real device and `allow_hardware` is False (refused before anything is built).
        MissingExtraError: dynamixel_sdk is not installed (``pip install 'wbc[hardware]'``).
        SerialPortError: `port` names an in-process bus, which only `in_process_handlers` reaches (the SDK would open
            a file of that name).
    """
    if port.startswith(IN_PROCESS_PREFIX):
        raise SerialPortError(port, "an in-process bus is reached through in_process_handlers (the emulator's "
                                    "arm_handlers / port_handlers), never opened as a file")
    check_serial_port(port, allow_hardware=allow_hardware, what="sdk_handlers port")
    sdk = require("dynamixel_sdk")
    return _low_latency_port_handler()(port, latency_ms), sdk.PacketHandler(2.0)


class SdkBus:
    """A Dynamixel bus through dynamixel_sdk's handlers.

    Args:
        port_handler: the SDK's port handler (or one built like it), not yet opened.
        packet_handler: the SDK's Protocol 2.0 packet handler.
        port: the device the handler must name; anything else is refused before it is opened.
        allow_hardware: whether `port` may be a real device; without it, `open` refuses anything but an emulator's
            pseudo-terminal or an in-process bus (`wbc.hardware.serial_port_policy.check_serial_port`).
        table: the servos' control table: every write is then checked against the register it names
            (`register_bytes`); None checks only that each value fits its bytes.

    Raises:
        SerialPortError: the handler names another device than `port`.
    """

    def __init__(self, port_handler: Any, packet_handler: Any, *, port: str, allow_hardware: bool = False,
                 table: ControlTable | None = None) -> None:
        self.port = port
        self.allow_hardware = allow_hardware
        self.table = table
        self._port = port_handler
        self._ph = packet_handler
        named = self._call(port_handler.getPortName)
        if named != port:
            raise SerialPortError(port, f"the port handler names {named!r}; only the port given is ever opened")
        self.is_open = False
        self.late = 0  # status packets discarded: they answered an earlier request (another ID or length)

    def _call(self, fn: Callable[..., T], *args: object) -> T:
        try:
            return fn(*args)
        except Exception as exc:  # noqa: BLE001 - see the module docstring: every serial-layer failure is one error
            raise SerialPortError(self.port, f"{type(exc).__name__}: {exc}") from exc

    # -- port -----------------------------------------------------------------------------------------------------
    def open(self, baud_rate: int) -> None:
        """Open the port at `baud_rate` [bit/s].

        Raises:
            TargetRefusedError: the port is a real device and the bus was not given ``allow_hardware`` (nothing is
                opened).
            SerialPortError: it cannot be opened (missing device, permissions, a rate the SDK does not list).
        """
        check_serial_port(self.port, allow_hardware=self.allow_hardware, what="SdkBus port")
        if not self._call(self._port.openPort):
            raise SerialPortError(self.port, "the SDK could not open it")
        self.is_open = True
        if not self._call(self._port.setBaudRate, int(baud_rate)):
            raise SerialPortError(self.port, f"the SDK refused the baud rate {baud_rate}")

    def close(self) -> None:
        """Close the port; a port that is already gone is not an error."""
        if self.is_open:
            self.is_open = False
            try:
                self._port.closePort()
            except Exception:  # noqa: BLE001, S110 - closing a port that vanished has nothing left to report
                pass

    def flush(self) -> None:
        """Drop whatever has arrived and not been read (a late answer must not pass for the next one's)."""
        self._call(self._port.clearPort)

    # -- transfers ------------------------------------------------------------------------------------------------
    def ping(self, servo_id: int) -> tuple[int, int, int]:
        """(model number, result, error byte) of a PING; only a 3-byte answer from `servo_id` is its answer."""
        read = self._request(servo_id, Instruction.PING, [], _PING_PARAMS)
        return (read.value(0, 2) if read.ok else 0), read.result, read.error

    def read(self, servo_id: int, address: int, length: int) -> ServoRead:
        """READ `length` bytes from `address` of one servo."""
        params = [*address.to_bytes(2, "little"), *length.to_bytes(2, "little")]
        return self._request(servo_id, Instruction.READ, params, length)

    def write(self, servo_id: int, address: int, size: int, value: int) -> tuple[int, int]:
        """WRITE `value` (`size` bytes, little-endian, two's complement) at `address`; (result, error byte).

        Raises:
            CommandError: `value` is refused by `register_bytes` (nothing is sent).
        """
        data = register_bytes(value, size, address, self.table)
        read = self._request(servo_id, Instruction.WRITE, [*address.to_bytes(2, "little"), *data], 0)
        return read.result, read.error

    def _request(self, servo_id: int, instruction: Instruction, params: list[int], answer: int) -> ServoRead:
        """Send one instruction to one servo and wait for its answer of `answer` bytes (see `Expected`)."""
        # the SDK's packet layout: header (4), ID, LEN (2), INST, params, CRC (2), LEN = params + 3
        packet = [0] * (len(params) + 10)
        packet[4], packet[5], packet[6], packet[7] = servo_id, (len(params) + 3) & 0xFF, (len(params) + 3) >> 8, \
            int(instruction)
        packet[8: 8 + len(params)] = params
        result = self._call(self._ph.txPacket, self._port, packet)
        if result != COMM_SUCCESS:
            return ServoRead(servo_id, b"", result, 0)
        # the SDK's reply timeout: the answer's bytes for a READ, 11 for any other (as its txRxPacket)
        self._call(self._port.setPacketTimeout, answer + _STATUS_OVERHEAD if instruction == Instruction.READ
                   else _STATUS_OVERHEAD)
        return self._receive(Expected(servo_id, instruction, answer))

    def _receive(self, expected: Expected) -> ServoRead:
        """The status packet that answers `expected`, discarding late ones, within the SDK's reply timeout."""
        while True:
            packet, result = self._call(self._ph.rxPacket, self._port, False)
            if result != COMM_SUCCESS:
                return ServoRead(expected.id, b"", result, 0)
            if expected.matches(packet):
                return ServoRead(expected.id, bytes(packet[9: 9 + expected.length]), COMM_SUCCESS, packet[8])
            self.late += 1

    def sync_read(self, address: int, length: int, ids: Sequence[int]) -> list[ServoRead]:
        """SYNC_READ `length` bytes at `address` from `ids`, each answer checked for its ID and length.

        Returns:
            One `ServoRead` per ID read, in order, stopping after the first that failed (the answers of the IDs after
            it are not waited for: their time is already spent).
        """
        result = self._call(self._ph.syncReadTx, self._port, address, length, list(ids), len(ids), False)
        if result != COMM_SUCCESS:
            return [ServoRead(ids[0], b"", result, 0)]
        out = []
        for servo_id in ids:
            out.append(self._receive(Expected(servo_id, Instruction.SYNC_READ, length)))
            if not out[-1].ok:
                break
        return out

    def sync_write(self, address: int, size: int, values: Sequence[tuple[int, int]]) -> int:
        """SYNC_WRITE (no answer): `size` bytes at `address`, one (ID, value) pair per servo; the SDK's result.

        Raises:
            CommandError: a value is refused by `register_bytes` (nothing is sent).
        """
        param: list[int] = []
        for servo_id, value in values:
            param.append(servo_id)
            param += register_bytes(value, size, address, self.table)
        return self._call(self._ph.syncWriteTxOnly, self._port, address, size, param, len(param))
