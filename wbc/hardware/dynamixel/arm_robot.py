"""`DynamixelArm`: the WX200's three model joints behind the `Robot` interface, over its Dynamixel bus.

The mapping of Unitree semantics. The joint servos (waist 1, shoulder 2 with its shadow 3, elbow 4) run in
current mode (Operating Mode 0). Every bus cycle, the host evaluates the command's law
``tau = kp (q* - q) + kd (dq* - dq) + tau_ff`` on the state the cycle just read, and writes each servo the current
that gives that torque (`CurrentLaw`). Current-based position mode (5) was the other choice: there the servo
closes its own position loop at a higher rate. But its gains are registers of undocumented internal units, it has
no feed-forward torque and no pure damping (kp 0), and every change of kp or kd costs more register writes. With
current mode, every command a controller or the safety layer sends means what it means on a Unitree motor: the
stand hold, the ramp's soft gains, damping, a feed-forward torque. The cost is bandwidth: the loop closes over the
bus, once per cycle, with one cycle of delay. The docs' benchmarks page gives the figures (``wbc bench arm``).

The bus thread runs at `DynamixelArmConfig.rate_hz`. Each cycle:

1. one sync read of Present Current, Velocity and Position (addresses 126..135) from the three joints' primary
   servos. A fresh state is published and the freshness tick advances. An answer with the hardware-alert bit makes
   the thread read that servo's Hardware Error Status at once;
2. every `status_every` cycles, one status read of all seven servos, taking turns: Hardware Error Status, or
   Present Input Voltage with Present Temperature;
3. one sync write of Goal Current (102) to the primaries. The shadow follows ID 2 through its Secondary ID. The
   command is the one `write` gave. Damping (kp 0, kd `damping_kd`) replaces it before the first write, once
   `write` has not been called for `write_deadline`, after a latched fault, while closing, and while the condition
   handed to `damp_while` holds (the legs' link's latch of the remote's L2 + B, on a quadruped).

Faults: late is not dead. A read that fails (timeout, corrupt answer) is tried again up to `retries` times, after a
short wait and a flush. A status packet that answers an earlier request (late) is discarded by the bus, never taken for
this one's (`SdkBus`, `ArmBusStats.late`). A read whose tries all failed is only a missed cycle
(`ArmBusStats.missed_reads`: no fresh state, no fault) while every servo of it gave a valid answer within the last
`watchdog_s`: a loaded host that ran a cycle late, or a servo that answered late, is not a dead servo, and the servos
themselves tolerate that much silence before their own watchdog acts. Once a servo of the read has given no valid answer
for `watchdog_s`, each servo of the read is pinged (up to three times), and those that stay silent or answer corrupt are
named in an `ArmFault`, which latches. Meanwhile the law is closed only on a joint state at most `write_deadline` old; a
joint whose last state is older gets goal current 0 (what its own watchdog would do), and the frozen tick lets a safety
layer above trip on the stale state within its own deadline. A hardware error bit latches a fault at once, and so does
any exception of the serial layer (the port is lost). A latched fault is printed to standard error, kept in `faults`,
reported in `motor_status` as an error mode of the servos at fault, and freezes the freshness tick. A safety layer above
therefore trips both on the motor mode and on the stale state. The torque policy while the host lives: the joints whose
servos still answer are damped by the host, whatever `write` asks. A joint that cannot be read gets goal current 0 and
goes limp. A servo with a hardware error has already switched its own torque off (Shutdown) and is limp too. A lost port
can reach nothing: the servos' bus watchdog sets their goal current to 0 after `watchdog_s`, and the arm goes limp.

If the host dies, each joint servo's Bus Watchdog (armed at `watchdog_s`) sets its goal current to 0, with the
torque still on. The arm is then limp: only the gearbox's friction holds it, and it sags under gravity. `close`
avoids that on purpose: it damps for `close_damping` seconds, then parks each joint it can still read. Parking
means: torque off for three register writes (an instant), current-based position mode, goal = where the joint is,
goal current `park_current_a`, torque on, watchdog off. The arm then holds its pose, compliantly, without the host.
Each of those transfers that times out is tried again, as at start-up (`connect_retries`), for `PARK_RETRIES_S` at
most in all: the park is made once, with no bus cycle to keep, and a late answer must not leave a joint limp.

Start-up (`connect`). Every servo is pinged. The backend checks each model number, the drive modes and the
shadow's Secondary ID against the WX200's bus map, and that no hardware error is latched. It refuses to connect
otherwise, and says which servo is wrong and why. EEPROM is written only where it differs from what is needed
(Operating Mode: 0 for the joints, 3 for the held servos), and only after that servo's torque has been switched off.
The backend prints a line each time it does. The held servos (wrist angle, wrist rotate, gripper) go to
`held_ticks` in position mode, at `held_profile_velocity`. The joint servos get goal current 0, torque on, and the
watchdog armed: from then until a controller's ramp, the host only damps them, so an arm found away from its stowed
pose (parked raised by an earlier run's `close`) sags under gravity, slowed by the damping alone; `connect` says so
first, naming each joint and how far it is from the stowed pose.

Time. The bus loop is a `DeviceThread` (`wbc.hardware.device_thread`) whose cycle is one bus cycle. Every time the
backend reads or waits (the cycle's start, the write deadline, a retry's pause, a fault's time, `wall_time`) comes
from its `Clock` (`wbc.hardware.clock`). On the monotonic clock (the default) the bus loop runs on a thread of its
own. Handed a `ManualClock`, the backend starts no thread: each bus cycle (the very body the thread runs) is a task of
that clock, and whoever moves the clock runs the bus: `advance`, `connect`'s wait for the first state and `close`'s
damping all move it. With a port on the same clock (`in_process_handlers`), a reply timeout, a retry and a watchdog
take the same clock time on any machine at any load. `thread_stats()` gives the bus loop's period, busy time, late
cycles and overruns; `bus_stats()` carries its period and busy figures too.
"""

from __future__ import annotations

import enum
import sys
import threading
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from wbc.errors import ArmRefusedError, RobotLinkError, SerialPortError
from wbc.hardware.clock import MONOTONIC, Clock
from wbc.hardware.device_thread import DeviceThread, DeviceThreadStats
from wbc.hardware.dynamixel.arm_config import DynamixelArmConfig
from wbc.hardware.dynamixel.arm_fault import (
    MODE_CORRUPT,
    MODE_HARDWARE_ERROR,
    MODE_NO_ANSWER,
    MODE_PORT_LOST,
    MODE_SERVO,
    ArmBusStats,
    ArmFault,
    ArmMotorStatus,
    ServoReading,
)
from wbc.hardware.dynamixel.control_table import (
    HARDWARE_ERROR_BITS,
    XM430_W350,
    XM430_W350_MODEL_NUMBER,
    OperatingMode,
)
from wbc.hardware.dynamixel.current_law import CurrentLaw
from wbc.hardware.dynamixel.protocol import ALERT, describe_error
from wbc.hardware.dynamixel.sdk_bus import (
    COMM_RX_CORRUPT,
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    SdkBus,
    ServoRead,
    describe_result,
    sdk_handlers,
)
from wbc.hardware.dynamixel.units import CURRENT_UNIT, VOLTAGE_UNIT
from wbc.hardware.pacing import WallPacer
from wbc.hardware.robot import Robot
from wbc.hardware.serial_port_policy import announce_hardware_port, check_serial_port
from wbc.robots.joint_table import JointTable, joint_table
from wbc.robots.registry import get_robot
from wbc.robots.wx200 import WX200_NOMINAL_Q
from wbc.types import MotorCommand, RobotState

__all__ = ["ARM_KD_MAX", "ARM_KP_MAX", "HELD_MODEL_NUMBERS", "PING_WAITS", "DynamixelArm", "arm_joint_table"]

ARM_KP_MAX = 150.0
"""[N m / rad] The largest position gain the arm's host-side law passes on. Its PD is closed over the bus at the
bus rate (200 Hz), far slower than a Unitree driver's: against the emulator the elbow rings from kp 400 (kd 1 to 5)
and holds still to kp 300 (kd 2); this is half of that. Every controller of ours asks for kp 10-20."""
ARM_KD_MAX = 5.0
"""[N m s / rad] The largest velocity gain the arm's law passes on: against the emulator the elbow chatters between
the current limits from kd 12, rings at kd 10 and is still at kd 8 and below (kp 0); this is about half of that.
Every controller of ours asks for kd 0.3-0.5 (the safety layer's damping, 0.5)."""

HELD_MODEL_NUMBERS = (XM430_W350_MODEL_NUMBER, 1060)
"""Models a held servo may be: the XM430-W350, or the XL430-W250 (1060) that some WX200s carry at the wrist rotate
and gripper. The joint servos must be XM430-W350s: the XL430 has no current mode."""

_ADDR = {name: XM430_W350[name].address for name in (
    "drive_mode", "operating_mode", "secondary_id", "current_limit", "torque_enable", "hardware_error_status",
    "bus_watchdog", "goal_current", "profile_velocity", "goal_position", "present_current", "present_position",
    "present_input_voltage")}
_PRESENT = (_ADDR["present_current"], 10)  # current (2), velocity (4), position (4): one read
_STATUS_TEMP = (_ADDR["present_input_voltage"], 3)  # input voltage (2), temperature (1)
PING_WAITS = (0.002, 0.01)
"""[s] The waits before the second and third ping of a servo whose read failed for good."""
PARK_RETRIES_S = 2.0
"""[s] How long the park goes on trying again the transfers that time out, all joints together: well within the
close's wait for the bus loop (`close_damping` + 5 s) and the I/O process's for the close (5 s)."""


class _Next(enum.Enum):
    """What the bus loop does after a cycle."""

    GO_ON = "go_on"
    STOP = "stop"  # end without parking (the port is lost)
    PARK = "park"  # the close damping is over: park the arm, then end


RAISED_TOLERANCE_RAD = 0.2
"""[rad] How far a joint may be from the stowed pose at `connect` before it warns that the arm will fall."""


def _print(line: str) -> None:
    """`line` on standard error, from the bus thread too: a terminal that was closed (OSError) must not end the loop."""
    try:
        print(line, file=sys.stderr, flush=True)
    except OSError:
        pass  # nobody is left to read it; the fault is latched and the park done all the same


def arm_joint_table(robot: str, law: CurrentLaw | None = None) -> JointTable:
    """The arm's three joints of `robot` (arm actuated), torque limits lowered to what `law` can ask if given."""
    table = joint_table(get_robot(robot, "actuated"))
    arm = slice(12, 15)
    torque = table.torque_limit[arm].copy()
    if law is not None:
        torque = np.minimum(torque, law.torque_limit)
    return JointTable(names=table.names[arm], lower=table.lower[arm].copy(), upper=table.upper[arm].copy(),
                      torque_limit=torque, velocity_limit=table.velocity_limit[arm].copy(),
                      armature=table.armature[arm].copy(), damping=table.damping[arm].copy(),
                      frictionloss=table.frictionloss[arm].copy())


class DynamixelArm(Robot):
    """The WX200's waist, shoulder and elbow over its Dynamixel bus (see the module docstring).

    Its gains are bounded by `ARM_KP_MAX` and `ARM_KD_MAX` (`gain_limits`), not by the legs' driver's figures: a
    command above them is clamped on its way to the bus, as every command is to the joints' limits.

    Args:
        config: the port and the bus's behaviour.
        handlers: builds dynamixel_sdk's (port handler, packet handler) for a port name at `connect`; the default
            (`sdk_handlers`) builds the SDK's, with the config's latency timer. A handler that names another port
            than `config.port` is refused before anything is opened.
        clock: where the backend reads the time and waits; the monotonic clock runs the bus loop on a thread, a
            `ManualClock` runs it as a task on that clock (no thread: the bus moves when the clock is moved).
    """

    gain_limits = (ARM_KP_MAX, ARM_KD_MAX)

    def __init__(self, config: DynamixelArmConfig,
                 handlers: Callable[[str], tuple[Any, Any]] | None = None, *, clock: Clock = MONOTONIC) -> None:
        super().__init__()
        self.config = config
        self.clock = clock
        self._handlers = handlers if handlers is not None else (
            lambda port: sdk_handlers(port, config.latency_ms, allow_hardware=config.allow_hardware))
        torque_limit = arm_joint_table(config.robot).torque_limit
        self.law = CurrentLaw(config.joints, torque_limit, config.max_current_a)
        self._limits = arm_joint_table(config.robot, self.law)
        self._names = {s.id: s.name for s in config.servos}
        self._ids = tuple(s.id for s in config.servos)
        self._primaries = tuple(j.servo_id for j in config.joints)
        self._period = 1.0 / config.rate_hz
        self._damping_rows = MotorCommand.damping(3, config.damping_kd).stacked()
        self._lock = threading.Condition()
        self._bus: SdkBus | None = None
        self._damp_while: Callable[[], bool] | None = None
        self._reset()

    def _reset(self) -> None:
        n = len(self._ids)
        self._state: RobotState | None = None
        self._fresh = 0
        self._state_at = -np.inf
        self._rows: np.ndarray | None = None
        self._written_at = -np.inf
        self._tripped = True
        self._closing_until: float | None = None
        self._faults: list[ArmFault] = []
        self._silent: set[int] = set()
        self._corrupt: set[int] = set()
        self._hw_error = np.zeros(n, dtype=np.uint8)
        self._temperature = np.zeros(n)
        self._voltage = np.zeros(n)
        self._port_lost = False
        self._late = 0
        self._counts = dict(cycles=0, states=0, status_reads=0, failed_transfers=0, retries=0, unexplained=0,
                            missed_reads=0, damping_cycles=0, deadline_trips=0)
        self._heard_at = dict.fromkeys(self._ids, -np.inf)  # [s] each servo's latest valid answer
        self._measured_at = np.full(3, -np.inf)  # [s] when each joint's state was last read
        self._loop = DeviceThread("dynamixel-arm-bus", self._period, self._bus_cycle, clock=self.clock,
                                  condition=self._lock, on_failure=self._loop_died)
        self._pacer = WallPacer(self.clock)
        self._measured = (np.zeros(3), np.zeros(3), np.zeros(3))
        self._t0 = self.clock.now()
        self._cycle_k = 0

    # -- Robot ----------------------------------------------------------------------------------------------------
    @property
    def joint_names(self) -> tuple[str, ...]:
        """The model's arm joints: waist, shoulder, elbow."""
        return self._limits.names

    @property
    def limits(self) -> JointTable:
        """The model's arm limits; torque limits within what the current bound gives (`CurrentLaw`)."""
        return self._limits

    def _connect(self) -> None:
        cfg = self.config
        self._reset()
        # the config refused a real device without consent; checked again here, the last step before a port is opened
        check_serial_port(cfg.port, allow_hardware=cfg.allow_hardware, what="DynamixelArmConfig.port")
        announce_hardware_port(cfg.port, f"{cfg.robot} arm bus")
        port_handler, packet_handler = self._handlers(cfg.port)
        bus = SdkBus(port_handler, packet_handler, port=cfg.port, allow_hardware=cfg.allow_hardware,
                     table=XM430_W350)
        try:
            bus.open(cfg.baud_rate)
            self._configure(bus)
        except BaseException:
            bus.close()
            raise
        self._heard_at = dict.fromkeys(self._ids, self.clock.now())  # every servo answered its start-up transfers
        self._bus = bus
        self._loop.start(run_first=True)
        self._loop.wait_until(lambda: self._state is not None or bool(self._faults), cfg.connect_timeout)
        with self._lock:
            ok = self._state is not None
            why = self._loop.failure or (self._faults[0] if self._faults else None)
        if not ok:
            self._shutdown(park=True)
            raise RobotLinkError(f"DynamixelArm({cfg.port}): no state within {cfg.connect_timeout} s after start-up"
                                 + (f": {why}" if why is not None else ""))

    def _close(self) -> None:
        self._shutdown(park=True)

    def _shutdown(self, *, park: bool) -> None:
        if park and self._loop.failure is None and not self._port_lost:
            with self._lock:
                self._closing_until = self.clock.now() + self.config.close_damping
            # the close damping goes out as the loop runs through it; the cycle after it parks and ends the loop
            self._loop.join(timeout=self.config.close_damping + 5.0)
        self._loop.stop()
        if self._bus is not None:
            self._bus.close()
            self._late = self._bus.late
            self._bus = None

    def _read(self) -> RobotState:
        self._raise_failure()
        with self._lock:
            state = self._state
        if state is None:
            raise RobotLinkError(f"DynamixelArm({self.config.port}): no state yet")
        return state

    def _send(self, cmd: MotorCommand) -> None:
        self._raise_failure()
        rows = cmd.stacked()
        with self._lock:
            self._rows = rows
            self._written_at = self.clock.now()

    def _advance(self, dt: float) -> None:
        with self._lock:
            start_tick = self._fresh
        self._pacer.wait(dt)
        self._loop.wait_until(lambda: self._fresh != start_tick or bool(self._faults), 2.0 * self._period)
        self._raise_failure()

    # -- capabilities ---------------------------------------------------------------------------------------------
    def wall_time(self) -> float:
        """Now on the backend's clock [s] (the `WallClock` capability: the servos live in wall time)."""
        return self.clock.now()

    @property
    def motor_names(self) -> tuple[str, ...]:
        """Each servo of `motor_status` by name and ID, e.g. ``elbow (ID 4)`` (`MotorNames`)."""
        return tuple(f"{self._names[i]} (ID {i})" for i in self._ids)

    def motor_status(self) -> ArmMotorStatus:
        """Every servo's mode code and temperature as of the latest reads (a `MotorStatusSource`).

        Raises:
            RobotLinkError: not connected yet, or the bus thread died.
        """
        self._raise_failure()
        with self._lock:
            if self._state is None and not self._faults:
                raise RobotLinkError(f"DynamixelArm({self.config.port}): no status yet; connect() first")
            modes = np.array([self._mode_of(k, i) for k, i in enumerate(self._ids)], dtype=np.uint8)
            return ArmMotorStatus(ids=self._ids, motor_mode=modes, motor_temperature=self._temperature.copy(),
                                  input_voltage=self._voltage.copy(), hardware_error=self._hw_error.copy())

    def _mode_of(self, k: int, servo_id: int) -> int:
        if self._port_lost:
            return MODE_PORT_LOST
        if servo_id in self._silent:
            return MODE_NO_ANSWER
        if servo_id in self._corrupt:
            return MODE_CORRUPT
        if self._hw_error[k]:
            return MODE_HARDWARE_ERROR | int(self._hw_error[k])
        return MODE_SERVO

    # -- backend-only API -----------------------------------------------------------------------------------------
    @property
    def faults(self) -> tuple[ArmFault, ...]:
        """The bus faults latched since `connect`, oldest first (empty while all is well)."""
        with self._lock:
            return tuple(self._faults)

    @property
    def fault(self) -> ArmFault | None:
        """The first latched fault, or None."""
        with self._lock:
            return self._faults[0] if self._faults else None

    @property
    def bus_failure(self) -> BaseException | None:
        """The exception that stopped the bus thread unexpectedly (not a bus fault), or None."""
        return self._loop.failure

    def survey(self) -> tuple[ServoReading, ...]:
        """Each servo as the bus finds it, read once and nothing written: a check of an arm that `connect` refused.

        Each servo is pinged (tried again as at start-up); one that answers has its Operating Mode, Hardware Error
        Status, temperature and input voltage read. No torque, mode or goal is written, no watchdog armed: the servos
        are left as they were. Only while not connected (the bus is `connect`'s otherwise).

        Raises:
            RobotLinkError: connected, or the port could not be opened (`SerialPortError`).
        """
        cfg = self.config
        if self.is_connected:
            raise RobotLinkError(f"DynamixelArm({cfg.port}): survey() reads the bus while not connected; close() first")
        check_serial_port(cfg.port, allow_hardware=cfg.allow_hardware, what="DynamixelArmConfig.port")
        port_handler, packet_handler = self._handlers(cfg.port)
        bus = SdkBus(port_handler, packet_handler, port=cfg.port, allow_hardware=cfg.allow_hardware,
                     table=XM430_W350)
        readings = []
        try:
            bus.open(cfg.baud_rate)
            for spec in cfg.servos:
                model, result, _ = self._retry(bus, lambda i=spec.id: bus.ping(i), lambda r: r[1])
                if result != COMM_SUCCESS:
                    readings.append(ServoReading(id=spec.id, name=spec.name, answer=describe_result(result)))
                    continue
                mode = self._retry(bus, lambda i=spec.id: bus.read(i, _ADDR["operating_mode"], 1), lambda r: r.result)
                error = self._retry(bus, lambda i=spec.id: bus.read(i, _ADDR["hardware_error_status"], 1),
                                    lambda r: r.result)
                heat = self._retry(bus, lambda i=spec.id: bus.read(i, *_STATUS_TEMP), lambda r: r.result)
                readings.append(ServoReading(
                    id=spec.id, name=spec.name, model=model, operating_mode=mode.data[0] if mode.ok else None,
                    hardware_error=error.data[0] if error.ok else 0,
                    temperature=float(heat.data[2]) if heat.ok else float("nan"),
                    voltage=heat.value(0, 2) * VOLTAGE_UNIT if heat.ok else float("nan")))
        finally:
            bus.close()
        return tuple(readings)

    def damp_while(self, condition: Callable[[], bool] | None) -> None:
        """Damp (the host's damping, as after the write deadline) on every bus cycle where `condition()` is true.

        The robot the arm rides on hands it its legs' e-stop latch (`DampsWhile`), so that the remote's L2 + B damps
        the arm within one bus cycle of the legs' link, not at the control loop's next read. None removes it.
        """
        self._damp_while = condition

    @property
    def deadline_trips(self) -> int:
        """Times since `connect` the write deadline expired and the bus switched to damping (`WriteDeadlineTrips`)."""
        with self._lock:
            return self._counts["deadline_trips"]

    def bus_stats(self) -> ArmBusStats:
        """A snapshot of the bus thread's counters; its period and busy figures are the bus loop's (`thread_stats`)."""
        thread = self._loop.stats()
        with self._lock:
            late = self._bus.late if self._bus is not None else self._late
            return ArmBusStats(**self._counts, late_advances=self._pacer.late_advances, late=late,
                               overruns=thread.late, period_mean=thread.period_mean, period_max=thread.period_max,
                               busy_mean=thread.busy_mean, busy_max=thread.busy_max)

    def thread_stats(self) -> DeviceThreadStats:
        """The bus loop's statistics since `connect`: cycles, their period, busy time, late cycles, overruns."""
        return self._loop.stats()

    def _raise_failure(self) -> None:
        failure = self._loop.failure
        if failure is not None:
            raise RobotLinkError(f"DynamixelArm({self.config.port}): the bus thread died: {failure!r}; the servos' "
                                 f"watchdog stops them {self.config.watchdog_s} s later and the arm goes "
                                 "limp") from failure

    # -- start-up -------------------------------------------------------------------------------------------------
    def _say(self, text: str) -> None:
        _print(f"DynamixelArm({self.config.port}): {text}")

    def _name(self, servo_id: int) -> str:
        return f"ID {servo_id} ({self._names.get(servo_id, '?')})"

    def _retry(self, bus: SdkBus, call: Callable[[], Any], result_of: Callable[[Any], int], *,
               until: float | None = None) -> Any:
        """`call()` again after a flush while it times out: `connect_retries` times at most, none from `until` on.

        Start-up's transfers and the park's (which gives an `until`) are made once, with no bus cycle to keep.
        """
        out = call()
        for _ in range(self.config.connect_retries):
            if result_of(out) != COMM_RX_TIMEOUT or (until is not None and self.clock.now() >= until):
                break
            self.clock.sleep(max(self.config.retry_wait_s, 0.01))
            bus.flush()
            out = call()
        return out

    def _read_at_start(self, bus: SdkBus, servo_id: int, address: int, length: int) -> ServoRead:
        out = self._retry(bus, lambda: bus.read(servo_id, address, length), lambda r: r.result)
        if not out.ok:
            raise RobotLinkError(f"DynamixelArm({self.config.port}): reading address {address} of "
                                 f"{self._name(servo_id)} failed: {describe_result(out.result)}")
        return out

    def _write_at_start(self, bus: SdkBus, servo_id: int, name: str, value: int) -> None:
        reg = XM430_W350[name]
        result, error = self._retry(bus, lambda: bus.write(servo_id, reg.address, reg.size, value), lambda r: r[0])
        if result != COMM_SUCCESS or error & ~ALERT:
            raise RobotLinkError(f"DynamixelArm({self.config.port}): writing {name} = {value} to "
                                 f"{self._name(servo_id)} failed: {describe_result(result)}, status "
                                 f"{describe_error(error)}")

    def _configure(self, bus: SdkBus) -> None:
        cfg = self.config
        joint_ids = set(cfg.joint_servo_ids)
        missing = []
        for spec in cfg.servos:
            model, result, _ = self._retry(bus, lambda i=spec.id: bus.ping(i), lambda r: r[1])
            if result != COMM_SUCCESS:
                missing.append(f"{self._name(spec.id)}: {describe_result(result)}")
            elif spec.id in joint_ids and model != XM430_W350_MODEL_NUMBER:
                raise RobotLinkError(f"DynamixelArm({cfg.port}): {self._name(spec.id)} is model {model}, not an "
                                     f"XM430-W350 ({XM430_W350_MODEL_NUMBER}): a joint servo needs current mode")
            elif model not in HELD_MODEL_NUMBERS:
                raise RobotLinkError(f"DynamixelArm({cfg.port}): {self._name(spec.id)} is model {model}, expected "
                                     f"one of {HELD_MODEL_NUMBERS}")
        if missing:
            raise ArmRefusedError(f"DynamixelArm({cfg.port}): servos did not answer a ping: {'; '.join(missing)}. "
                                 f"Check the arm's 12 V supply, the daisy-chain cables, the baud rate "
                                 f"({cfg.baud_rate} bit/s) and the IDs (Dynamixel Wizard)")
        modes = {}
        for spec in cfg.servos:
            eeprom = self._read_at_start(bus, spec.id, _ADDR["drive_mode"], 3)
            drive, mode, secondary = eeprom.data[0], eeprom.data[1], eeprom.data[2]
            if drive & 0x01 != spec.drive_mode & 0x01 or secondary != spec.secondary_id:
                raise RobotLinkError(
                    f"DynamixelArm({cfg.port}): {self._name(spec.id)} has drive mode {drive:#04x} and Secondary ID "
                    f"{secondary}; the WX200's bus map expects {spec.drive_mode:#04x} and {spec.secondary_id}. The "
                    "shoulder's servos would fight, or a joint would turn the wrong way: configure the arm's EEPROM as "
                    "Interbotix does (wx200.yaml) before using it")
            hw = self._read_at_start(bus, spec.id, _ADDR["hardware_error_status"], 1).data[0]
            if hw:
                bits = ", ".join(n for b, n in HARDWARE_ERROR_BITS.items() if hw & b)
                raise ArmRefusedError(f"DynamixelArm({cfg.port}): {self._name(spec.id)} reports a hardware error "
                                     f"({bits}; {hw:#04x}), latched in the servo: find the cause, then reboot it "
                                     "(power-cycle the arm, or REBOOT it with Dynamixel Wizard)")
            if spec.id in joint_ids:
                limit = self._read_at_start(bus, spec.id, _ADDR["current_limit"], 2).value(0, 2)
                if limit * CURRENT_UNIT < cfg.max_current_a - 0.5 * CURRENT_UNIT:
                    raise RobotLinkError(f"DynamixelArm({cfg.port}): {self._name(spec.id)} has Current Limit {limit} "
                                         f"({limit * CURRENT_UNIT:.2f} A), below max_current_a "
                                         f"{cfg.max_current_a:.2f} A: lower max_current_a, or raise the register")
            modes[spec.id] = mode
        self._read_status(bus, "temperature", at_start=True)
        self._warn_if_raised(bus)
        # EEPROM: written only where it differs, and only with that servo's torque off
        for spec in cfg.servos:
            wanted = OperatingMode.CURRENT if spec.id in joint_ids else OperatingMode.POSITION
            if modes[spec.id] != wanted:
                self._say(f"torque off on {self._name(spec.id)} to write its EEPROM: Operating Mode "
                          f"{modes[spec.id]} -> {int(wanted)} ({wanted.name.lower()})")
                self._write_at_start(bus, spec.id, "torque_enable", 0)
                self._write_at_start(bus, spec.id, "operating_mode", int(wanted))
        # RAM: the held servos to their goals, then the joints on at zero current, then the watchdog armed
        for spec, ticks in zip(cfg.held_servos, cfg.held_ticks, strict=True):
            if ticks is None:
                ticks = self._read_at_start(bus, spec.id, _ADDR["present_position"], 4).value(0, 4, signed=True)
                ticks = min(max(ticks, spec.min_position), spec.max_position)
            self._write_at_start(bus, spec.id, "profile_velocity", cfg.held_profile_velocity)
            self._write_at_start(bus, spec.id, "goal_position", ticks)
            self._write_at_start(bus, spec.id, "torque_enable", 1)
        for servo_id in self._primaries:  # the shadow executes ID 2's writes through its Secondary ID
            self._write_at_start(bus, servo_id, "bus_watchdog", 0)  # clears a watchdog tripped in an earlier run
            self._write_at_start(bus, servo_id, "goal_current", 0)
            self._write_at_start(bus, servo_id, "torque_enable", 1)
        for servo_id in self._primaries:
            self._write_at_start(bus, servo_id, "bus_watchdog", cfg.watchdog_units)

    def _warn_if_raised(self, bus: SdkBus) -> None:
        """Say so when a joint is away from the stowed pose: what connect does next lets gravity take it down.

        Connect switches the joint servos' torque off (to write current mode, after a park in mode 5) and on again at
        goal current 0; from then until a controller's ramp, the host only damps them. An arm left raised (a run
        that parked it up) falls, slowed by that damping alone.
        """
        far = []
        for joint, stowed in zip(self.config.joints, WX200_NOMINAL_Q, strict=True):
            ticks = self._read_at_start(bus, joint.servo_id, _ADDR["present_position"], 4).value(0, 4, signed=True)
            q = joint.to_rad(ticks)
            if abs(q - stowed) > RAISED_TOLERANCE_RAD:
                far.append(f"{joint.name} at {q:+.2f} rad, {abs(q - stowed):.2f} rad from stowed ({stowed:+.2f})")
        if far:
            self._say(f"the arm is away from its stowed pose: {'; '.join(far)}. Connecting releases the joints (torque "
                      f"off to write current mode, then goal current 0, damped by the host with kd "
                      f"{self.config.damping_kd} only) until a controller's ramp holds them: gravity takes the arm "
                      "down meanwhile. Support it, or lower it to its stowed pose first")

    # -- the bus loop: one cycle's body, run by the thread or by the clock --------------------------------------------
    def _loop_died(self, exc: BaseException) -> None:
        self._say(f"the bus loop died ({exc!r}): nothing reaches the servos any more; their watchdog sets "
                  f"the goal currents to 0 after {self.config.watchdog_s} s and the arm goes limp")

    def _bus_cycle(self) -> bool:
        """The loop's cycle: one bus cycle; after the close damping, the park. False: the loop is done."""
        bus = self._bus
        step = self._cycle(bus)
        if step is _Next.PARK:
            self._park(bus)
        return step is _Next.GO_ON

    def _cycle(self, bus: SdkBus) -> _Next:
        """One bus cycle: the joints' sync read, every so often a status read, the goals' sync write."""
        every = self.config.status_every
        start = self.clock.now()
        with self._lock:
            if self._closing_until is not None and start >= self._closing_until:
                return _Next.PARK
        k = self._cycle_k
        try:
            self._read_joints(bus)
            if k % every == 0:
                self._read_status(bus, "hardware_error")
            elif k % every == every // 2:
                self._read_status(bus, "temperature")
            damped = self._write_goals(bus, start)
        except SerialPortError as exc:
            self._latch("port_lost", self._ids, f"{exc}",
                        f"Nothing reaches the servos: their bus watchdog sets the goal currents to 0 after "
                        f"{self.config.watchdog_s} s, and the arm goes LIMP (it sags under gravity)")
            return _Next.STOP
        self._cycle_k = k + 1
        with self._lock:  # both counts at once, so that a snapshot never sees one cycle's damping without it
            self._counts["cycles"] += 1
            self._counts["damping_cycles"] += damped
        return _Next.GO_ON

    def _transfer(self, bus: SdkBus, call: Callable[[], list[ServoRead]]) -> list[ServoRead] | None:
        """`call()` (a read), tried again after a flush up to `retries` times; None once every try failed."""
        cfg = self.config
        for attempt in range(cfg.retries + 1):
            reads = call()
            self._heard(r.id for r in reads if r.ok)
            if reads and all(r.ok for r in reads):
                return reads
            with self._lock:
                self._counts["failed_transfers"] += 1
                if attempt < cfg.retries:
                    self._counts["retries"] += 1
            if attempt < cfg.retries:
                self.clock.sleep(cfg.retry_wait_s)
                bus.flush()
        return None

    def _heard(self, ids: Iterable[int]) -> None:
        now = self.clock.now()
        for servo_id in ids:
            self._heard_at[servo_id] = now

    def _unanswered(self, bus: SdkBus, ids: tuple[int, ...]) -> None:
        """A read of `ids` failed for good: a missed cycle while each answered within `watchdog_s`, else identify."""
        now = self.clock.now()
        silence = {i: now - self._heard_at[i] for i in ids}
        if all(s < self.config.watchdog_s for s in silence.values()):
            with self._lock:
                self._counts["missed_reads"] += 1
            return
        self._identify(bus, ids, silence)

    def _identify(self, bus: SdkBus, ids: tuple[int, ...], silence: dict[int, float]) -> None:
        """Ping each of `ids` after their silence reached `watchdog_s`; latch those silent or answering corrupt.

        `silence` is each one's time without a valid answer when the read failed for good [s]: the longest, at or
        past the watchdog's time, is what the latch says triggered it.
        """
        silent, corrupt = [], []
        for servo_id in ids:
            bus.flush()
            _, result, _ = bus.ping(servo_id)
            for wait in PING_WAITS:  # more tries, further apart: a loaded host can miss an answer or two
                if result != COMM_RX_TIMEOUT:
                    break
                self.clock.sleep(wait)
                bus.flush()
                _, result, _ = bus.ping(servo_id)
            if result == COMM_RX_TIMEOUT:
                silent.append(servo_id)
            elif result != COMM_SUCCESS:
                corrupt.append(servo_id)
            else:
                self._heard((servo_id,))
        if not silent and not corrupt:
            with self._lock:
                self._counts["unexplained"] += 1
            return
        retries, watchdog = self.config.retries, self.config.watchdog_s
        trigger = max(ids, key=silence.__getitem__)
        for kind, bad, result in (("no_answer", silent, COMM_RX_TIMEOUT), ("corrupt", corrupt, COMM_RX_CORRUPT)):
            if bad:
                with self._lock:
                    (self._silent if kind == "no_answer" else self._corrupt).update(bad)
                names = ", ".join(self._name(i) for i in bad)
                if trigger in bad:  # the latched servo's own silence is what triggered the pings
                    said = (f"{names}: no valid answer for {silence[trigger]:.3f} s (the watchdog's {watchdog} s), "
                            f"{describe_result(result)} on {retries + 1} reads and on its pings")
                else:
                    said = (f"{names}: {describe_result(result)} on its pings, after the sync read it failed had left "
                            f"{self._name(trigger)} without a valid answer for {silence[trigger]:.3f} s (the "
                            f"watchdog's {watchdog} s) on {retries + 1} reads")
                self._latch(kind, tuple(bad), said, self._policy())

    def _policy(self) -> str:
        """The torque policy in words, for the servos as they are now."""
        limp = [j.name for j in self.config.joints if not self._readable(j.servo_id) or self._has_error((j.servo_id,))]
        damped = [j.name for j in self.config.joints if j.name not in limp]
        text = f"Damping by the host (kd {self.config.damping_kd} N m s/rad) on: {', '.join(damped) or 'none'}"
        if limp:
            text += (f"; LIMP (goal current 0, or its own torque off): {', '.join(limp)}. If the host dies, every "
                     f"joint goes limp {self.config.watchdog_s} s later (bus watchdog)")
        return text

    def _readable(self, servo_id: int) -> bool:
        return servo_id not in self._silent and servo_id not in self._corrupt

    def _has_error(self, ids: tuple[int, ...]) -> bool:
        return any(self._hw_error[self._ids.index(i)] for i in ids)

    def _latch(self, kind: str, ids: tuple[int, ...], detail: str, policy: str) -> None:
        fault = ArmFault(time=self.clock.now(), kind=kind, ids=tuple(ids), detail=detail, policy=policy)
        with self._lock:
            if kind == "port_lost":
                self._port_lost = True
            self._faults.append(fault)
            self._lock.notify_all()
        _print(str(fault))

    def _read_joints(self, bus: SdkBus) -> None:
        ids = tuple(i for i in self._primaries if self._readable(i))
        if not ids:
            return
        reads = self._transfer(bus, lambda: bus.sync_read(*_PRESENT, ids))
        if reads is None:
            self._unanswered(bus, ids)
            return
        current, velocity, ticks = (np.zeros(3) for _ in range(3))
        q0, dq0, tau0 = self._measured
        known = np.zeros(3, dtype=bool)
        for read in reads:
            j = self._primaries.index(read.id)
            current[j] = read.value(0, 2, signed=True)
            velocity[j] = read.value(2, 4, signed=True)
            ticks[j] = read.value(6, 4, signed=True)
            known[j] = True
        q, dq, tau = self.law.state(ticks, velocity, current)
        self._measured = (np.where(known, q, q0), np.where(known, dq, dq0), np.where(known, tau, tau0))
        self._measured_at[known] = self.clock.now()
        for read in reads:
            if read.error & ALERT and not self._has_error((read.id,)):
                self._check_hardware_error(bus, read.id)
        with self._lock:
            if self._faults:
                return  # the tick stays frozen: a latched fault makes every later frame stale
            now = self.clock.now()
            self._fresh += 1
            self._counts["states"] = self._fresh
            self._state_at = now
            q, dq, tau = self._measured
            self._state = RobotState(tick=self._fresh, time=now - self._t0, q=q.copy(), dq=dq.copy(),
                                     tau_est=tau.copy(), imu_quat=np.array([1.0, 0.0, 0.0, 0.0]),
                                     gyro_in_body=np.zeros(3), accel_in_body=np.zeros(3), foot_force=np.zeros(4))
            self._lock.notify_all()

    def _check_hardware_error(self, bus: SdkBus, servo_id: int) -> None:
        read = bus.read(servo_id, _ADDR["hardware_error_status"], 1)
        if read.ok:
            self._note_hardware_error(servo_id, read.data[0])

    def _note_hardware_error(self, servo_id: int, bits: int) -> None:
        k = self._ids.index(servo_id)
        new = bits & ~int(self._hw_error[k])
        with self._lock:
            self._hw_error[k] = bits
        if new:
            words = ", ".join(n for b, n in HARDWARE_ERROR_BITS.items() if new & b) or f"{new:#04x}"
            self._latch("hardware_error", (servo_id,),
                        f"{self._name(servo_id)} reports a hardware error ({words}); its Shutdown switches its "
                        "torque off", self._policy())

    def _read_status(self, bus: SdkBus, what: str, *, at_start: bool = False) -> None:
        ids = tuple(i for i in self._ids if self._readable(i))
        if not ids:
            return
        address, length = (_ADDR["hardware_error_status"], 1) if what == "hardware_error" else _STATUS_TEMP
        if at_start:
            reads = [self._read_at_start(bus, i, address, length) for i in ids]
        else:
            with self._lock:
                self._counts["status_reads"] += 1
            reads = self._transfer(bus, lambda: bus.sync_read(address, length, ids))
            if reads is None:
                self._unanswered(bus, ids)
                return
        for read in reads:
            k = self._ids.index(read.id)
            if what == "hardware_error":
                self._note_hardware_error(read.id, read.data[0])
            else:
                with self._lock:
                    self._voltage[k] = read.value(0, 2) * VOLTAGE_UNIT
                    self._temperature[k] = read.data[2]

    def _write_goals(self, bus: SdkBus, now: float) -> bool:
        """Write this cycle's goal currents: the host's damping, or the written command's law; True if damping."""
        cfg = self.config
        with self._lock:
            quiet = now - self._written_at > cfg.write_deadline
            if quiet and self._rows is not None and not self._tripped:
                self._counts["deadline_trips"] += 1
            self._tripped = quiet
            damp = (self._faults or self._closing_until is not None or self._state is None or self._rows is None
                    or quiet or (self._damp_while is not None and self._damp_while()))
            rows = self._damping_rows if damp else self._rows
        q, dq, _ = self._measured
        tau = self.law.torque(rows, q, dq)
        units = self.law.goal_units(tau)
        current = now - self._measured_at <= cfg.write_deadline  # a law closed on an older state is open-loop
        values = []
        for j, joint in enumerate(cfg.joints):
            servo_id = joint.servo_id
            if servo_id in self._silent:
                continue  # it hears nothing; its watchdog stops it
            reach = self._readable(servo_id) and not self._has_error((servo_id,)) and bool(current[j])
            values.append((servo_id, int(units[j]) if reach else 0))
        if values:
            bus.sync_write(_ADDR["goal_current"], 2, values)
        return bool(damp)

    def _park(self, bus: SdkBus) -> None:
        """Hold every joint that can still be read where it is, in current-based position mode, watchdog off."""
        cfg = self.config
        parked, left = [], []
        park_units = int(round(cfg.park_current_a / CURRENT_UNIT))
        until = self.clock.now() + PARK_RETRIES_S
        for joint in cfg.joints:
            servo_id = joint.servo_id
            if not self._readable(servo_id) or self._has_error((servo_id,)):
                left.append(joint.name)
                continue
            try:
                steps = (("bus_watchdog", 0), ("torque_enable", 0),
                         ("operating_mode", int(OperatingMode.CURRENT_BASED_POSITION)), ("goal_current", park_units))
                ok = all(self._park_write(bus, servo_id, name, value, until) for name, value in steps)
                read = self._retry(bus, lambda i=servo_id: bus.read(i, _ADDR["present_position"], 4),
                                   lambda r: r.result, until=until) if ok else None
                ok = ok and read is not None and read.ok
                if ok:
                    ticks = read.value(0, 4, signed=True)
                    ok = self._park_write(bus, servo_id, "goal_position", ticks, until) and \
                        self._park_write(bus, servo_id, "torque_enable", 1, until)
            except SerialPortError:
                ok = False
            (parked if ok else left).append(joint.name)
            if not ok:
                self._say(f"could not park {self._name(servo_id)}")
        text = f"closed: {', '.join(parked) or 'no joint'} parked (held where it is, <= {cfg.park_current_a} A)"
        if left:
            text += f"; LIMP: {', '.join(left)}"
        self._say(text)

    def _park_write(self, bus: SdkBus, servo_id: int, name: str, value: int, until: float) -> bool:
        # tried again as a start-up transfer is, until `until`: a park made once, at the close, with no cycle to keep;
        # one late answer more than the bus cycle's retries allow (a loaded host, a slow servo) must not leave the
        # joint limp
        reg = XM430_W350[name]
        result, error = self._retry(bus, lambda: bus.write(servo_id, reg.address, reg.size, value), lambda r: r[0],
                                    until=until)
        return result == COMM_SUCCESS and not error & ~ALERT

