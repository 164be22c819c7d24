"""`DynamixelEmulator`: the WX200's Dynamixel bus on a pseudo-terminal, its XM430 servos backed by an `ArmPlant`.

A client opens `DynamixelEmulator.port` (the pty's slave, e.g. ``/dev/pts/7``) as it would open the U2D2
(``PortHandler(port)`` of dynamixel_sdk, unmodified) and speaks Protocol 2.0. The emulator registers its pty while it
holds it (`wbc.hardware.pty_registry`): the serial-port policy opens a pty without consent only if an emulator serves
it (``registered_everywhere`` says whether other processes can see it too). One thread (a `DeviceThread`,
`wbc.hardware.device_thread`) reads the master side, decodes each instruction packet (`wbc.hardware.dynamixel`), hands
it to the servos it addresses (`EmulatedServo`: the control table and its rules), logs it with the register values its
answers carry (`packets()`) and writes the servos' status packets back, in ID-list order. Its cycle is the servos' own
time, every `THREAD_PERIOD` and after every packet; `thread_stats()` gives its period, late cycles and overruns.

The packet handling does not depend on that thread. Built with ``in_process=True`` the emulator opens no pty and
starts no thread: `receive` takes the bytes a client wrote and hands every answer, with when it reaches the client,
to that client's callback, within the same call. `port_handlers` builds dynamixel_sdk handlers around it
(`wbc.hardware.dynamixel.in_process_handlers`): the SDK writes, and its answers wait for it when it reads.
On a `ManualClock` (`wbc.hardware.clock`), the servos' own time (bus watchdogs, injected overloads and heat, reboots)
is a task of the clock every `TICK_PERIOD` (the same `DeviceThread`, run by the clock), and a late answer
(`BusFault.LATE_ANSWER`, or the wire time of ``byte_timing``) reaches the client that much later on the clock. What a
test then sees is the same on every machine at any load.

Instructions: PING (one ID or broadcast), READ, WRITE, REBOOT, SYNC_READ, SYNC_WRITE, BULK_READ, BULK_WRITE,
FAST_SYNC_READ and FAST_BULK_READ (one combined answer). Anything else gets an instruction error. A servo executes
a packet sent to its ID, to its Secondary ID (without answering: the shoulder's shadow follows every write to ID 2),
or broadcast. Status Return Level (68) is obeyed. A packet whose CRC is wrong gets a CRC error from the servo it
names. With ``check_baud``, servos hear only a client whose port is set to their baud rate.

The physics: whenever a servo's drive registers change (torque, mode, goals, gains, limits, a tripped watchdog, a
shutdown), the servos of each model joint become one `MotorCommand` for the plant's three arm joints, in the joint
convention of `WX200_ARM_JOINTS`. Each servo contributes in its own direction, which its drive mode (reverse bit)
and its mounting (the shadow is mirrored) decide:

- torque off: nothing;
- current (0): tau = Goal Current within Current Limit, times `TORQUE_CONSTANT` (kp = kd = 0);
- velocity (1): damping toward Goal Velocity, kd from Velocity P Gain (`velocity_gain_to_kd`; the integral part is
  left out);
- position (3) and extended position (4): the servo's PD, kp and kd from Position P and D Gains
  (`position_gains_to_pd`), toward Goal Position (within the position limits in mode 3), bounded by Current Limit;
- current-based position (5): the same PD, bounded by Goal Current. The plant applies the bound every physics
  step (`ArmPlant.write_arm`'s ``tau_max``);
- PWM (16): a DC motor at that duty: tau = stall torque x duty - (stall torque / no-load speed) x dq.

The shoulder's two servos add up. The present registers come from the plant each time a packet reads them: position
and velocity rounded as the encoder reports them; current = the joint's applied torque shared among its torque-on
servos, over `TORQUE_CONSTANT`. Servos without a model joint (wrist angle, wrist rotate, gripper) power up at tick
2048 and sit at their Goal Position while their torque is on. The emulator never steps the plant: the leg emulator,
a test, or the plant's own real-time thread does.

Faults (`BusFault`) are injected on demand: `inject` / `clear`. They act the same through the pty and in process.
"""

from __future__ import annotations

import collections
import heapq
import itertools
import math
import os
import select
import termios
import threading
import time
import tty
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wbc.errors import ConfigError, PacketError
from wbc.hardware.clock import MONOTONIC, Clock, ManualClock
from wbc.hardware.device_thread import DeviceThread, DeviceThreadStats
from wbc.hardware.dynamixel.control_table import (
    BAUD_RATES,
    HW_INPUT_VOLTAGE,
    HW_OVERHEATING,
    HW_OVERLOAD,
    XM430_W350,
    OperatingMode,
)
from wbc.hardware.dynamixel.crc import crc16
from wbc.hardware.dynamixel.packet import (
    HEADER,
    InstructionPacket,
    PacketReader,
    build_status,
    parse_bulk_read_params,
    parse_bulk_write_params,
    parse_packet,
    parse_read_params,
    parse_sync_read_params,
    parse_sync_write_params,
    parse_write_params,
    ping_status_params,
)
from wbc.hardware.dynamixel.protocol import BROADCAST_ID, ERR_CRC, ERR_DATA_LENGTH, ERR_INSTRUCTION, Instruction
from wbc.hardware.dynamixel.sdk_bus import in_process_handlers
from wbc.hardware.dynamixel.units import (
    CENTER_TICKS,
    CURRENT_UNIT,
    NO_LOAD_SPEED,
    PWM_MAX,
    RAD_PER_TICK,
    RETURN_DELAY_UNIT,
    STALL_TORQUE,
    TORQUE_CONSTANT,
    VELOCITY_UNIT,
    VOLTAGE_UNIT,
    position_gains_to_pd,
    velocity_gain_to_kd,
)
from wbc.hardware.dynamixel.wx200_bus import WX200_ARM_JOINTS, WX200_SERVOS, ArmJointMap, ServoSpec
from wbc.hardware.emulators.arm_plant import ArmPlant
from wbc.hardware.emulators.bus_faults import BUS_FAULT_DEFAULTS, BusFault, fault_ids
from wbc.hardware.emulators.faults import FaultSet
from wbc.hardware.emulators.logged_packet import LoggedPacket, RegisterRead, decode_values, decode_writes
from wbc.hardware.emulators.servo import EmulatedServo
from wbc.hardware.pty_registry import register_pty, unregister_pty
from wbc.hardware.serial_port_policy import IN_PROCESS_PREFIX
from wbc.types import MotorCommand

__all__ = ["THREAD_PERIOD", "TICK_PERIOD", "BusStats", "DynamixelEmulator", "DynamixelEmulatorConfig"]

THREAD_PERIOD = 0.01
"""[s] How often the pty's thread runs the servos' own time when no packet comes: the longest it blocks, so that
faults and watchdogs are seen promptly."""
TICK_PERIOD = 0.002
"""[s] How often the servos' own time runs (watchdogs, injected overloads) as a task of a `ManualClock`; on any
clock it also runs before every packet, so a watchdog is never seen late by a packet."""
_READS = (Instruction.READ, Instruction.SYNC_READ, Instruction.FAST_SYNC_READ, Instruction.BULK_READ,
          Instruction.FAST_BULK_READ)
_SPEEDS = {getattr(termios, f"B{rate}"): rate for rate in BAUD_RATES.values() if hasattr(termios, f"B{rate}")}


@dataclass(frozen=True, kw_only=True)
class DynamixelEmulatorConfig:
    """Configuration of an emulated arm bus.

    Attributes:
        servos: the servos on the bus and their EEPROM (default: the WX200's, as Interbotix configures them).
        joints: which servos drive which model joint, and the tick convention (default: `WX200_ARM_JOINTS`).
        temperature: Present Temperature of every servo [deg C].
        input_voltage: Present Input Voltage [V].
        reboot_time: how long a rebooting servo hears nothing [s] (not measured on an XM430; a guess).
        byte_timing: answer after each servo's Return Delay Time plus the packets' time on the wire at its baud
            rate (1 start, 8 data, 1 stop bit per byte), as a real bus would; off, answers go out at once.
        check_baud: servos hear only a client that set the port to their baud rate.
        packet_timeout: an incomplete packet is dropped after this much silence on the bus [s].
        log_size: most recent decoded packets kept; 0 keeps none and skips decoding them for the log (a long log
            is thousands of objects that each full garbage collection traverses, stalling the answers).
    """

    servos: tuple[ServoSpec, ...] = WX200_SERVOS
    joints: tuple[ArmJointMap, ...] = WX200_ARM_JOINTS
    temperature: float = 40.0
    input_voltage: float = 12.0
    reboot_time: float = 0.05
    byte_timing: bool = False
    check_baud: bool = True
    packet_timeout: float = 0.05
    log_size: int = 100_000

    def __post_init__(self) -> None:
        ids = [s.id for s in self.servos]
        if len(set(ids)) != len(ids):
            raise ConfigError(f"DynamixelEmulatorConfig.servos: IDs repeat: {ids}")
        for joint in self.joints:
            missing = [i for i in joint.servo_ids if i not in ids]
            if missing:
                raise ConfigError(f"DynamixelEmulatorConfig.joints: {joint.name} names servo IDs {missing} that are "
                                  f"not on the bus ({ids})")
        if not 0 <= self.reboot_time <= 5:
            raise ConfigError(f"DynamixelEmulatorConfig.reboot_time must be in [0, 5] s, got {self.reboot_time}")


@dataclass(kw_only=True)
class BusStats:
    """What the bus thread has seen and done (mutable, read by tests).

    Attributes:
        packets: instruction packets decoded (and logged).
        rejected: packets refused by the codec, by `PacketError` reason (``crc``, ``short`` ...).
        dropped_bytes: bytes skipped while looking for a header, or left of a packet that never completed.
        statuses: status packets written.
        unheard: packets no servo heard (a wrong baud rate, a silent or rebooting ID, nobody with that ID).
    """

    packets: int = 0
    rejected: dict[str, int] = field(default_factory=dict)
    dropped_bytes: int = 0
    statuses: int = 0
    unheard: int = 0


@dataclass(frozen=True)
class _Wiring:
    joint: int | None  # index into config.joints, None for a servo without a model joint
    mount: int  # +1 / -1: the servo's native direction against the model joint's
    offset: float  # [rad] the model angle at the servo's native centre


class DynamixelEmulator:
    """The emulated bus: a pty, a thread, the servos, the plant. A context manager (`start` / `close`).

    Args:
        plant: the physics of the three model joints (`SharedPlant`, started by the caller).
        config: what is on the bus.
        clock: the time of the watchdogs, reboots, late answers and the log: a `Clock` (whose `sleep` an in-process
            client's port waits on), or a function giving the time [s].
        in_process: open no pty and start no thread: clients reach the bus through `port_handlers` (see the module
            docstring).

    Raises:
        ConfigError: a `ManualClock` for a pty (its thread lives in wall time; build it with ``in_process=True``).
    """

    def __init__(self, plant: ArmPlant, config: DynamixelEmulatorConfig | None = None, *,
                 clock: Clock | Callable[[], float] = time.monotonic, in_process: bool = False) -> None:
        self.plant = plant
        self.config = config if config is not None else DynamixelEmulatorConfig()
        self.table = XM430_W350
        self.clock: Clock = clock if isinstance(clock, Clock) else _FunctionClock(clock)
        if isinstance(self.clock, ManualClock) and not in_process:
            raise ConfigError("DynamixelEmulator: a pty is served by a thread in wall time; on a ManualClock build the "
                              "emulator with in_process=True")
        self._clock = self.clock.now
        self.in_process = in_process
        now = self._clock()
        self._servos = [EmulatedServo(spec, self.table, now=now) for spec in self.config.servos]
        self._wiring = [self._wire(spec) for spec in self.config.servos]
        for servo, wiring in zip(self._servos, self._wiring, strict=True):
            if wiring.joint is None:
                servo.set("present_position", CENTER_TICKS)  # within every WX200 servo's limits
        self.faults = FaultSet(BusFault, BUS_FAULT_DEFAULTS)
        self.stats = BusStats()
        self._log: collections.deque[LoggedPacket] = collections.deque(maxlen=self.config.log_size)
        self._answered: list[tuple[int, int, bytes]] = []  # (servo ID, address, data) of the running packet's answers
        self._lock = threading.RLock()
        self._reader = PacketReader()
        self._master: int | None = None
        self._slave: int | None = None
        self._wake: tuple[int, int] | None = None
        self._closed = threading.Event()
        self._device: DeviceThread | None = None  # the pty's thread, or the servos' time as a task of a ManualClock
        self._last_rx = now
        self._bus_free_at = 0.0
        self._outbox: list[tuple[bytes, EmulatedServo]] = []
        self._late: list[tuple[float, int, bytes]] = []  # (due, order, answer): late answers the pty still owes
        self._order = itertools.count()
        self._reply: Callable[[bytes, float], None] | None = None  # the in-process client being answered
        self._started = False
        self._sent: tuple[np.ndarray, np.ndarray] | None = None
        self.port = ""
        self.registered_everywhere = False

    def _wire(self, spec: ServoSpec) -> _Wiring:
        for k, joint in enumerate(self.config.joints):
            if spec.id in joint.servo_ids:
                # the arm is assembled so that the configured drive mode reads the joint in `joint.sign`
                return _Wiring(joint=k, mount=joint.sign * (-1 if spec.reverse else 1), offset=joint.offset)
        return _Wiring(joint=None, mount=1, offset=0.0)

    # -- lifecycle ------------------------------------------------------------------------------------------------
    def start(self) -> DynamixelEmulator:
        """Power the servos up at the plant's pose; open the pty and start the bus thread (unless in process).

        Idempotent. In process, the servos' own time becomes a task of the clock if it is a `ManualClock`.
        """
        if self.in_process:
            if not self._started:
                self._started = True
                self._closed.clear()
                self.port = f"{IN_PROCESS_PREFIX}dynamixel-{id(self):x}"
                self._power_up()
                if isinstance(self.clock, ManualClock):
                    self._device = DeviceThread("dynamixel-emulator", TICK_PERIOD, self._servo_time, clock=self.clock)
                    self._device.start()
            return self
        if self._master is not None or (self._device is not None and self._device.running):
            return self
        master, slave = os.openpty()
        tty.setraw(master)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self._wake = os.pipe()
        self.port = os.ttyname(slave)
        self.registered_everywhere = register_pty(self.port)  # the serial-port policy lets only ours through
        self._power_up()
        self._closed.clear()
        self._device = DeviceThread("dynamixel-emulator", THREAD_PERIOD, self._servo_time, clock=self.clock,
                                    idle=self._serve, wake=self._wakeup, on_failure=self._died)
        self._device.start()
        return self

    def _power_up(self) -> None:
        """The servos come up where the plant's arm is, holding that position as their goal."""
        with self._lock:
            now = self._clock()
            self._refresh(now)
            for servo in self._servos:
                servo.set("goal_position", servo.get("present_position"))
            self._update_plant()

    def close(self) -> None:
        """Stop the thread and close the pty (in process: stop the servos' task). Idempotent."""
        if self._device is not None:
            self._device.stop()
        if self.in_process:
            self._closed.set()
            return
        self._close_fds()

    @property
    def failure(self) -> BaseException | None:
        """The exception that stopped the bus thread (or the servos' task), or None while it runs."""
        return self._device.failure if self._device is not None else None

    def thread_stats(self) -> DeviceThreadStats:
        """The bus thread's (or the servos' task's) statistics: cycles of the servos' time, their period, lateness."""
        return self._device.stats() if self._device is not None else DeviceThreadStats()

    def __enter__(self) -> DynamixelEmulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def port_closed(self) -> bool:
        """True once the pty was closed (`close`, or the PORT_CLOSED fault); in process, once closed or unplugged."""
        return self._closed.is_set()

    # -- in process -----------------------------------------------------------------------------------------------
    def port_handlers(self, latency_ms: float = 1.0) -> Callable[[str], tuple[Any, Any]]:
        """What `DynamixelArm(handlers=...)` takes: dynamixel_sdk handlers wired to this bus in process.

        The port's reply timeout and its waits run on this emulator's clock (`in_process_handlers`).

        Args:
            latency_ms: the adapter's latency timer [ms], which sets the reply timeout.

        Raises:
            ConfigError: the emulator was not built with ``in_process=True``.
        """
        if not self.in_process:
            raise ConfigError("DynamixelEmulator.port_handlers: this emulator serves a pty; build it with "
                              "in_process=True to reach it in process, or open its `port` with the SDK")
        return lambda port: in_process_handlers(port, self, self.clock, latency_ms)

    def receive(self, data: bytes, *, baud: int, reply: Callable[[bytes, float], None]) -> None:
        """Bytes a client wrote at `baud` [bit/s]; each answer goes to ``reply(raw, delay)`` before this returns.

        `delay` [s] is how long after now the answer reaches the client: 0, or the wire time with ``byte_timing``,
        plus the delay of `BusFault.LATE_ANSWER`.

        Raises:
            ConfigError: the emulator is not in process, or not started.
        """
        if not (self.in_process and self._started):
            raise ConfigError("DynamixelEmulator.receive: only an in-process emulator, once started, takes bytes")
        now = self._clock()
        self._tick(now)  # what the servos did by themselves since the last packet comes first
        with self._lock:
            self._reply = reply
            try:
                if self._reader.pending and now - self._last_rx >= self.config.packet_timeout:
                    self.stats.dropped_bytes += self._reader.discard()
                self._last_rx = now
                dropped = self._reader.dropped
                for raw in self._reader.feed(bytes(data)):
                    self._on_packet(raw, now, baud)
                self.stats.dropped_bytes += self._reader.dropped - dropped
            finally:
                self._reply = None

    # -- test API -------------------------------------------------------------------------------------------------
    def inject(self, fault: BusFault, value: object = None) -> None:
        """Activate `fault` (see `BusFault` for its value) until `clear`; PORT_CLOSED returns once the pty is closed.

        Raises:
            ConfigError: not a `BusFault`, or a value that names no servo.
        """
        self.faults.inject(fault, value)
        self._fault_ids(fault)  # a bad value is the caller's error, raised here rather than on the bus thread
        self._wakeup()
        if fault is BusFault.PORT_CLOSED and self.in_process:
            self._closed.set()  # unplugged: the servos' task goes on, their watchdogs still trip
        if fault is BusFault.PORT_CLOSED and not self.in_process and self._device is not None:
            self._closed.wait(timeout=2.0)

    def clear(self, fault: BusFault | None = None) -> None:
        """Deactivate `fault`, or every fault if None (a latched hardware error stays until a REBOOT)."""
        self.faults.clear(fault)
        self._wakeup()

    def packets(self) -> list[LoggedPacket]:
        """The decoded instruction packets received so far (the latest `log_size`), oldest first.

        Each carries the register values its answers carried (`LoggedPacket.answers`).
        """
        with self._lock:
            return list(self._log)

    def clear_log(self) -> None:
        """Forget the packets received so far."""
        with self._lock:
            self._log.clear()

    def register(self, servo_id: int, name: str) -> int:
        """A register of the servo whose ID is `servo_id`, read inside the servo (not over the bus).

        Raises:
            ConfigError: no servo has that ID.
        """
        with self._lock:
            return self._by_id(servo_id).get(name)

    def _by_id(self, servo_id: int) -> EmulatedServo:
        for servo in self._servos:
            if servo.id == servo_id:
                return servo
        raise ConfigError(f"DynamixelEmulator: no servo with ID {servo_id}; IDs: "
                          f"{', '.join(str(s.id) for s in self._servos)}")

    # -- bus thread -----------------------------------------------------------------------------------------------
    def _servo_time(self) -> bool:
        """The device thread's cycle: the servos' own time (their watchdogs go on when the port is unplugged)."""
        self._tick(self._clock())
        return True

    def _died(self, exc: BaseException) -> None:
        """The thread failed: a port closed by a fault stays closed (its `inject` is waiting for that)."""
        if BusFault.PORT_CLOSED in self.faults.snapshot():
            self._close_fds()

    def _serve(self, until: float) -> None:
        """Between two cycles of the thread: every packet as it arrives and the late answers when due, until `until`.

        Once the port is unplugged (`BusFault.PORT_CLOSED`) the pty is closed and nothing arrives any more: the
        thread only runs the servos' time.
        """
        if BusFault.PORT_CLOSED in self.faults.snapshot():
            if self._master is not None:
                self._close_fds()
            self._device.sleep_until(until)
            return
        master, wake = self._master, self._wake[0]
        now = self._clock()
        wait = until - now
        with self._lock:
            for servo in self._servos:
                deadline = servo.watchdog_deadline()
                if deadline is not None:
                    wait = min(wait, deadline - now)
        if self._reader.pending:
            wait = min(wait, self._last_rx + self.config.packet_timeout - now)
        if self._late:
            wait = min(wait, self._late[0][0] - now)
        ready = select.select([master, wake], [], [], max(0.0, wait))[0]
        if wake in ready:
            os.read(wake, 64)
        if master in ready:
            try:
                data = os.read(master, 4096)
            except (BlockingIOError, InterruptedError):
                data = b""
            now = self._clock()
            if data:
                self._last_rx = now
                dropped = self._reader.dropped
                baud = self._client_baud()
                for raw in self._reader.feed(data):
                    self._on_packet(raw, now, baud)
                self.stats.dropped_bytes += self._reader.dropped - dropped
        elif self._reader.pending and self._clock() - self._last_rx >= self.config.packet_timeout:
            self.stats.dropped_bytes += self._reader.discard()
        now = self._clock()
        self._write_late(now)
        if now < until:
            self._tick(now)  # woken early (a packet, a watchdog's deadline): the servos' time now, not at the cycle

    def _write_late(self, now: float) -> None:
        """Write the late answers now due, in the order they fall due."""
        while self._late and self._late[0][0] <= now:
            _, _, raw = heapq.heappop(self._late)
            self._write(raw)

    def _tick(self, now: float) -> None:
        """What the servos do by themselves: temperatures, voltages, injected overloads, their bus watchdogs."""
        active = self.faults.snapshot()
        overload = self._fault_ids(BusFault.OVERLOAD, active)
        hot_ids, hot_temp = self._hot(active)
        changed = False
        with self._lock:
            volts = round(self.config.input_voltage / VOLTAGE_UNIT)
            for servo in self._servos:
                if now < servo.busy_until:
                    continue
                temp = hot_temp if servo.id in hot_ids else round(self.config.temperature)
                servo.set("present_temperature", temp)
                servo.set("present_input_voltage", volts)
                bits = HW_OVERLOAD if servo.id in overload else 0
                if temp > servo.get("temperature_limit"):
                    bits |= HW_OVERHEATING
                if not servo.get("min_voltage_limit") <= volts <= servo.get("max_voltage_limit"):
                    bits |= HW_INPUT_VOLTAGE
                if bits:
                    changed |= servo.raise_hardware_error(bits)
                changed |= servo.tick(now)
            if changed:
                self._update_plant()

    def _on_packet(self, raw: bytes, now: float, baud: int | None) -> None:
        try:
            pkt = parse_packet(raw)
        except PacketError as err:
            self.stats.rejected[err.reason] = self.stats.rejected.get(err.reason, 0) + 1
            if err.reason == "crc":
                with self._lock:
                    servo = self._primary(raw[4], self._listeners(now, baud))
                    if servo is not None:
                        self._answer(servo, servo.status_error(ERR_CRC))
                    self._flush()
            return
        if not isinstance(pkt, InstructionPacket):
            self.stats.rejected["status"] = self.stats.rejected.get("status", 0) + 1
            return
        self.stats.packets += 1
        with self._lock:
            self._answered.clear()
            try:
                listeners = self._listeners(now, baud)
                if not listeners:
                    self.stats.unheard += 1
                    return
                if self._execute(pkt, listeners, now):
                    self._update_plant()
            finally:
                if self.config.log_size:  # logged once run, with what it answered, and before the answers go out
                    self._log.append(self._logged(pkt, now))
            # the answers go out once the servos have acted: a client that reads a status sees the plant updated
            self._flush()

    def _listeners(self, now: float, baud: int | None) -> list[EmulatedServo]:
        """The servos that hear the bus now: not cut off, not rebooting, at the client's baud rate (if checked)."""
        silent = self._fault_ids(BusFault.SILENT_ID)
        baud = baud if self.config.check_baud else None
        return [s for s in self._servos if s.id not in silent and now >= s.busy_until
                and (baud is None or BAUD_RATES.get(s.get("baud_rate")) == baud)]

    def _client_baud(self) -> int | None:
        """The rate the client set on the pty (None if it cannot be read)."""
        try:
            return _SPEEDS.get(termios.tcgetattr(self._slave)[5])
        except termios.error:
            return None

    @staticmethod
    def _primary(servo_id: int, listeners: list[EmulatedServo]) -> EmulatedServo | None:
        for servo in listeners:
            if servo.id == servo_id:
                return servo
        return None

    @staticmethod
    def _addressed(servo_id: int, listeners: list[EmulatedServo]) -> list[EmulatedServo]:
        """The servos that execute a packet for `servo_id`: its owner, those whose Secondary ID it is, or all."""
        if servo_id == BROADCAST_ID:
            return list(listeners)
        return [s for s in listeners if servo_id in (s.id, s.secondary_id)]

    def _execute(self, pkt: InstructionPacket, listeners: list[EmulatedServo], now: float) -> bool:
        """Run one instruction on the servos that hear it; True if a drive register may have changed."""
        inst, pid = pkt.instruction, pkt.id
        if inst in (Instruction.SYNC_READ, Instruction.FAST_SYNC_READ, Instruction.BULK_READ,
                    Instruction.FAST_BULK_READ, Instruction.SYNC_WRITE, Instruction.BULK_WRITE):
            return self._execute_group(pkt, listeners, now)
        targets = self._addressed(pid, listeners)
        if not targets:
            self.stats.unheard += 1
            return False
        for servo in targets:
            servo.heard(now)
        owner = None if pid == BROADCAST_ID else self._primary(pid, targets)
        if inst == Instruction.PING:
            answering = sorted(targets, key=lambda s: s.id) if pid == BROADCAST_ID else [owner] if owner else []
            for servo in answering:
                params = ping_status_params(self.table.model_number, servo.get("firmware_version"))
                self._answer(servo, servo.status_error(), params)
            return False
        if inst == Instruction.READ:
            if owner is None or owner.get("status_return_level") < 1:
                return False
            try:
                address, length = parse_read_params(pkt.params)
            except PacketError:
                self._answer(owner, owner.status_error(ERR_DATA_LENGTH))
                return False
            self._refresh(now, (owner,))
            error, data = self._read(owner, address, length)
            self._answer(owner, owner.status_error(error), data)
            return False
        if inst == Instruction.WRITE:
            try:
                address, data = parse_write_params(pkt.params)
            except PacketError:
                if owner is not None:
                    self._answer_write(owner, ERR_DATA_LENGTH)
                return False
            for servo in targets:
                error = servo.write(address, data)
                if servo is owner:
                    self._answer_write(owner, error)
            return True
        if inst == Instruction.REBOOT:
            if owner is not None:
                self._answer_write(owner, 0)
            for servo in targets:
                servo.reboot(now, self.config.reboot_time)
            return True
        if owner is not None:
            self._answer_write(owner, ERR_INSTRUCTION)
        return False

    def _execute_group(self, pkt: InstructionPacket, listeners: list[EmulatedServo], now: float) -> bool:
        inst = pkt.instruction
        try:
            if inst in (Instruction.SYNC_READ, Instruction.FAST_SYNC_READ):
                address, length, ids = parse_sync_read_params(pkt.params)
                items = [(i, address, length) for i in ids]
            elif inst in (Instruction.BULK_READ, Instruction.FAST_BULK_READ):
                items = list(parse_bulk_read_params(pkt.params))
            elif inst == Instruction.SYNC_WRITE:
                address, _, chunks = parse_sync_write_params(pkt.params)
                items = [(i, address, data) for i, data in chunks]
            else:
                items = list(parse_bulk_write_params(pkt.params))
        except PacketError:
            return False  # a malformed group packet: nobody answers a broadcast
        heard = False
        for servo_id, *_ in items:
            for servo in self._addressed(servo_id, listeners):
                servo.heard(now)
                heard = True
        if not heard:
            self.stats.unheard += 1
            return False
        if inst in (Instruction.SYNC_WRITE, Instruction.BULK_WRITE):
            for servo_id, address, data in items:
                for servo in self._addressed(servo_id, listeners):
                    servo.write(address, data)
            return True
        self._refresh(now, [s for s in (self._primary(i, listeners) for i, *_ in items) if s is not None])
        answers = []
        for servo_id, address, length in items:
            servo = self._primary(servo_id, listeners)
            if servo is None or servo.get("status_return_level") < 1:
                if inst in (Instruction.FAST_SYNC_READ, Instruction.FAST_BULK_READ):
                    break  # the chain of a fast read stops at the first servo that does not answer
                continue
            error, data = self._read(servo, address, length)
            answers.append((servo, servo.status_error(error), data))
        if inst in (Instruction.SYNC_READ, Instruction.BULK_READ):
            for servo, error, data in answers:
                self._answer(servo, error, data)
        elif answers:
            self._answer_fast(answers, items)
        return False

    # -- answers ----------------------------------------------------------------------------------------------
    def _read(self, servo: EmulatedServo, address: int, length: int) -> tuple[int, bytes]:
        """`servo`'s READ of `length` bytes at `address`: (error number, data); the data is kept for the log."""
        error, data = servo.read(address, length)
        if data and self.config.log_size:
            self._answered.append((servo.id, address, data))
        return error, data

    def _answer_write(self, servo: EmulatedServo, error: int) -> None:
        if servo.get("status_return_level") >= 2:
            self._answer(servo, servo.status_error(error))

    def _answer(self, servo: EmulatedServo, error: int, params: bytes = b"") -> None:
        raw = bytearray(build_status(servo.id, error, params))
        if servo.id in self._fault_ids(BusFault.BAD_CRC):
            raw[-2] ^= 0x01
        self._send(bytes(raw), servo)

    def _answer_fast(self, answers: list[tuple[EmulatedServo, int, bytes]],
                     items: list[tuple[int, int, int]]) -> None:
        """One packet for every answering servo.

        A chain cut short keeps the LEN of the whole (the first servo announces it) and ends where the silent
        servo's block should start.
        """
        bad = self._fault_ids(BusFault.BAD_CRC)
        length = 1 + sum(4 + n for *_, n in items)
        out = bytearray(HEADER + bytes((BROADCAST_ID, length & 0xFF, length >> 8, Instruction.STATUS)))
        for servo, error, data in answers:
            out += bytes((error, servo.id)) + data
            crc = crc16(out) ^ (0x0001 if servo.id in bad else 0)
            out += crc.to_bytes(2, "little")
        self._send(bytes(out), answers[0][0])

    def _send(self, raw: bytes, servo: EmulatedServo) -> None:
        self._outbox.append((raw, servo))

    def _flush(self) -> None:
        """Send the answers queued while the current packet ran, in order.

        With ``byte_timing`` an answer reaches the client after its servo's Return Delay Time and its bytes' time
        on the wire, behind the answers before it; a servo with `BusFault.LATE_ANSWER` answers that much later.
        Through the pty the bus thread waits for the wire time (a late answer is written by the thread when due,
        without holding up the others); in process the client is told each answer's delay.
        """
        outbox, self._outbox = self._outbox, []
        late_ids, late_by = self._late_answers()
        for raw, servo in outbox:
            now = self._clock()
            at = now
            if self.config.byte_timing:
                baud = BAUD_RATES.get(servo.get("baud_rate"), 1_000_000)
                start = max(now, self._bus_free_at) + servo.get("return_delay_time") * RETURN_DELAY_UNIT
                self._bus_free_at = at = start + len(raw) * 10 / baud
            if servo.id in late_ids:
                at += late_by
            if self._reply is not None:
                self._reply(raw, at - now)
                self.stats.statuses += 1
            elif servo.id in late_ids:
                heapq.heappush(self._late, (at, next(self._order), raw))
            else:
                if self.config.byte_timing:
                    _sleep_until(at, self._clock)
                self._write(raw)

    def _write(self, raw: bytes) -> None:
        """Write an answer to the pty."""
        try:
            os.write(self._master, raw)
            self.stats.statuses += 1
        except (OSError, TypeError):
            pass  # nobody reads the port (or it is gone): the answer is lost, as on an unplugged bus

    # -- registers <-> plant ----------------------------------------------------------------------------------
    def _direction(self, k: int) -> int:
        """+1 / -1: the servo's register direction against its model joint's, drive mode included."""
        return self._wiring[k].mount * (-1 if self._servos[k].reverse else 1)

    def _refresh(self, now: float, servos: Sequence[EmulatedServo] | None = None) -> None:
        """Present registers of `servos` (all if None) from the plant, rounded as the servo reports them.

        A read refreshes only the servos it asks: the registers of the others are not seen until a read asks them, and
        refreshing all seven servos took half of the 0.26 ms that the emulator spent on a sync read of three, time
        that the host waits for its answer.
        """
        q, dq, tau = self.plant.read_arm()
        on = [0] * len(self.config.joints)
        for k, servo in enumerate(self._servos):
            j = self._wiring[k].joint
            if j is not None and servo.torque_on:
                on[j] += 1
        for k, servo in enumerate(self._servos):
            if servos is not None and servo not in servos:
                continue
            wiring = self._wiring[k]
            if wiring.joint is None:
                if servo.torque_on and servo.mode in (OperatingMode.POSITION, OperatingMode.EXTENDED_POSITION,
                                                       OperatingMode.CURRENT_BASED_POSITION):
                    servo.set("present_position", servo.get("goal_position"))
                servo.set("present_velocity", 0)
                servo.set("present_current", 0)
            else:
                j, d = wiring.joint, self._direction(k)
                ticks = CENTER_TICKS + d * (float(q[j]) - wiring.offset) / RAD_PER_TICK + servo.get("homing_offset")
                servo.set("present_position", round(ticks))
                velocity = round(d * float(dq[j]) / VELOCITY_UNIT)
                servo.set("present_velocity", velocity)
                amps = d * float(tau[j]) / on[j] / TORQUE_CONSTANT if servo.torque_on else 0.0
                servo.set("present_current", max(-32768, min(32767, round(amps / CURRENT_UNIT))))
            servo.set("moving", int(abs(servo.get("present_velocity")) > servo.get("moving_threshold")))
            servo.set("realtime_tick", int((now - servo.powered_at) * 1000) % 32768)

    def _update_plant(self) -> None:
        """Turn every servo's drive registers into the plant's arm command; send it if it changed."""
        n = len(self.config.joints)
        kp, kd, kp_q, kd_dq, ff, bound = (np.zeros(n) for _ in range(6))
        for k, servo in enumerate(self._servos):
            wiring = self._wiring[k]
            if wiring.joint is None or not servo.torque_on:
                continue
            j, d, mode = wiring.joint, self._direction(k), servo.mode
            current_limit = servo.get("current_limit")
            limit_torque = current_limit * CURRENT_UNIT * TORQUE_CONSTANT
            if mode == OperatingMode.CURRENT:
                goal = max(-current_limit, min(current_limit, servo.get("goal_current")))
                ff[j] += d * goal * CURRENT_UNIT * TORQUE_CONSTANT
                bound[j] += limit_torque
            elif mode == OperatingMode.VELOCITY:
                gain = velocity_gain_to_kd(servo.get("velocity_p_gain"))
                limit = servo.get("velocity_limit")
                kd[j] += gain
                kd_dq[j] += gain * d * max(-limit, min(limit, servo.get("goal_velocity"))) * VELOCITY_UNIT
                bound[j] += limit_torque
            elif mode == OperatingMode.PWM:
                limit = servo.get("pwm_limit")
                ff[j] += d * STALL_TORQUE * max(-limit, min(limit, servo.get("goal_pwm"))) / PWM_MAX
                kd[j] += STALL_TORQUE / NO_LOAD_SPEED
                bound[j] += STALL_TORQUE
            else:  # the position modes
                p, dgain = position_gains_to_pd(servo.get("position_p_gain"), servo.get("position_d_gain"))
                goal = servo.get("goal_position")
                if mode == OperatingMode.POSITION:
                    goal = max(servo.get("min_position_limit"), min(servo.get("max_position_limit"), goal))
                q_goal = wiring.offset + d * (goal - servo.get("homing_offset") - CENTER_TICKS) * RAD_PER_TICK
                kp[j] += p
                kp_q[j] += p * q_goal
                kd[j] += dgain
                if mode == OperatingMode.CURRENT_BASED_POSITION:
                    limit_torque = min(abs(servo.get("goal_current")), current_limit) * CURRENT_UNIT * TORQUE_CONSTANT
                bound[j] += limit_torque
        q = np.divide(kp_q, kp, out=np.zeros(n), where=kp > 0)
        dq = np.divide(kd_dq, kd, out=np.zeros(n), where=kd > 0)
        idle = (kp == 0) & (kd == 0) & (ff == 0)
        bound[idle] = math.inf  # nothing to bound: keep the plant on its fast path
        rows = np.array((q, dq, kp, kd, ff))
        if self._sent is not None and np.array_equal(rows, self._sent[0]) and np.array_equal(bound, self._sent[1]):
            return
        self.plant.write_arm(MotorCommand(q=q, dq=dq, kp=kp, kd=kd, tau=ff), tau_max=bound)
        self._sent = (rows, bound)

    # -- helpers ----------------------------------------------------------------------------------------------
    def _logged(self, pkt: InstructionPacket, now: float) -> LoggedPacket:
        writes, reads = (), ()
        try:
            if pkt.instruction == Instruction.WRITE:
                address, data = parse_write_params(pkt.params)
                writes = decode_writes(self.table, pkt.id, address, data)
            elif pkt.instruction == Instruction.SYNC_WRITE:
                address, _, chunks = parse_sync_write_params(pkt.params)
                writes = tuple(w for i, data in chunks for w in decode_writes(self.table, i, address, data))
            elif pkt.instruction == Instruction.BULK_WRITE:
                writes = tuple(w for i, address, data in parse_bulk_write_params(pkt.params)
                               for w in decode_writes(self.table, i, address, data))
            elif pkt.instruction == Instruction.READ:
                address, length = parse_read_params(pkt.params)
                reads = (RegisterRead(id=pkt.id, address=address, length=length),)
            elif pkt.instruction in (Instruction.SYNC_READ, Instruction.FAST_SYNC_READ):
                address, length, ids = parse_sync_read_params(pkt.params)
                reads = tuple(RegisterRead(id=i, address=address, length=length) for i in ids)
            elif pkt.instruction in (Instruction.BULK_READ, Instruction.FAST_BULK_READ):
                reads = tuple(RegisterRead(id=i, address=a, length=n) for i, a, n in parse_bulk_read_params(pkt.params))
        except PacketError:
            pass  # logged with its raw parameters only
        answers = tuple(v for i, address, data in self._answered for v in decode_values(self.table, i, address, data))
        return LoggedPacket(time=now, id=pkt.id, instruction=pkt.instruction, params=pkt.params, writes=writes,
                            reads=reads, answers=answers)

    def _fault_ids(self, fault: BusFault, active: dict | None = None) -> frozenset[int]:
        """The servo IDs an active fault names (none if it is not active)."""
        active = self.faults.snapshot() if active is None else active
        if fault is BusFault.OVER_TEMPERATURE:
            return self._hot(active)[0]
        if fault is BusFault.LATE_ANSWER:
            return self._late_answers(active)[0]
        if fault not in active or fault is BusFault.PORT_CLOSED:
            return frozenset()
        return fault_ids(active[fault], tuple(s.spec.id for s in self._servos))

    def _hot(self, active: dict) -> tuple[frozenset[int], int]:
        if BusFault.OVER_TEMPERATURE not in active:
            return frozenset(), 0
        value = active[BusFault.OVER_TEMPERATURE]
        if not (isinstance(value, tuple) and len(value) == 2):
            raise ConfigError(f"BusFault.OVER_TEMPERATURE value {value!r}: expected (ID or IDs, deg C)")
        return fault_ids(value[0], tuple(s.spec.id for s in self._servos)), int(value[1])

    def _late_answers(self, active: dict | None = None) -> tuple[frozenset[int], float]:
        """The servos whose answers come late, and by how much [s] (none, 0 if the fault is not active)."""
        active = self.faults.snapshot() if active is None else active
        if BusFault.LATE_ANSWER not in active:
            return frozenset(), 0.0
        value = active[BusFault.LATE_ANSWER]
        if not (isinstance(value, tuple) and len(value) == 2 and isinstance(value[1], int | float)
                and math.isfinite(value[1]) and 0 < value[1] <= 1.0):
            raise ConfigError(f"BusFault.LATE_ANSWER value {value!r}: expected (ID or IDs, delay in (0, 1] s)")
        return fault_ids(value[0], tuple(s.spec.id for s in self._servos)), float(value[1])

    def _wakeup(self) -> None:
        if self._wake is not None:
            try:
                os.write(self._wake[1], b"\x00")
            except OSError:
                pass

    def _close_fds(self) -> None:
        with self._lock:
            if self._slave is not None:
                unregister_pty(self.port)  # before the close: a pty's number is handed out again
            for fd in (self._master, self._slave, *(self._wake or ())):
                if fd is not None:
                    try:
                        os.close(fd)
                    except OSError:
                        pass
            self._master = self._slave = None
            self._wake = None
            self._closed.set()


class _FunctionClock:
    """A `Clock` around a function that gives the time; it sleeps on the monotonic clock."""

    def __init__(self, now: Callable[[], float]) -> None:
        self.now = now

    @staticmethod
    def sleep(seconds: float) -> None:
        """`MONOTONIC.sleep`."""
        MONOTONIC.sleep(seconds)


def _sleep_until(deadline: float, clock: Callable[[], float]) -> None:
    """Wait until `deadline`: sleep while far, then spin (a sleep of a few tens of microseconds overshoots)."""
    while True:
        left = deadline - clock()
        if left <= 0:
            return
        if left > 0.002:
            time.sleep(left - 0.001)
