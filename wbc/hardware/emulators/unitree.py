"""`UnitreeEmulator`: an A1 or Go1 on 127.0.0.1 that speaks the exact low-level wire, backed by `MujocoRobot`.

Each LowCmd datagram is decoded strictly (`decode_command`; rejects are counted in `stats`), logged, converted to
a `MotorCommand` (a motor whose mode is not servo 0x0A gets no torque, and so does a frame with a negative gain,
counted in `refused`) and written to a legs-only `MujocoRobot`, whose physics and motor law are the arena's. The
reply is an `encode_state` frame of the simulated sensors, sent to the address the command came from.

Two modes. ``lockstep``: each valid command advances physics by one control period and is answered by one state,
so simulated time moves exactly with the commands a backend sends. ``realtime``: physics steps at wall-clock pace
on the emulator's own thread, which sends a state every period to the latest sender, as the robot does. Faults
(`Fault`) bend the replies on demand: `inject` / `clear`.

The handling of a command (`handle_command`: decode, log, write the simulation, the lockstep step) and the making
of a reply (`compose_reply`: the state with the faults applied, and when it leaves) know no socket. Two servers
use them: the UDP server on 127.0.0.1 (`start`), and the in-process `EmulatorTransport` (`transport`), a
`wbc.hardware.unitree.Transport` a backend is handed instead of a socket, on a `Clock` a test controls: each command
it sends is handled within the same call and its reply queued for `receive`, a delayed reply is queued when the
clock reaches its time, and in ``realtime`` mode the physics steps as the clock moves (`ManualClock.call_every`).
The log then stamps each command with that clock's time, so a test can say in which link period a frame went out.
"""

from __future__ import annotations

import collections
import dataclasses
import errno
import math
import random
import select
import socket
import struct
import sys
import threading
from dataclasses import dataclass

import numpy as np

from wbc.errors import CommandError, ConfigError, FrameError, PortBusyError, RobotLinkError, UnknownNameError
from wbc.hardware.clock import MONOTONIC, Clock, ManualClock, ScheduledCall
from wbc.hardware.emulators.faults import Fault, FaultSet, apply_state_faults, mangle_frame
from wbc.hardware.emulators.logged_command import LoggedCommand
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.hardware.unitree import DecodeStats, LowStateExtras
from wbc.hardware.unitree.command_codec import decode_command
from wbc.hardware.unitree.layout import MODE_SERVO, frame_layout
from wbc.hardware.unitree.robot import DESCRIPTIONS
from wbc.hardware.unitree.state_codec import encode_state
from wbc.hardware.unitree.target import is_loopback
from wbc.hardware.unitree.transport import MAX_DATAGRAM
from wbc.types import BaseTruth, MotorCommand

__all__ = ["LEG_ONLY_ARM_MODES", "MODES", "EmulatorTransport", "Reply", "UnitreeEmulator", "UnitreeEmulatorConfig"]

MODES = ("lockstep", "realtime")
_POLL = 0.01  # [s] longest the emulator thread blocks, so `close` is prompt
# Linux's socket option that hands each datagram the count of those the socket has dropped (its buffer full) so far,
# which Python's socket module does not name: the log keeps it, so that a dropped frame is known, not guessed.
_SO_RXQ_OVFL = 40 if sys.platform.startswith("linux") else None
_DROP_COUNT_SPACE = socket.CMSG_SPACE(4)


LEG_ONLY_ARM_MODES = ("none", "locked")
"""Arm modes whose robot the Unitree wire drives whole: the arm absent, or on the trunk and held."""


@dataclass(frozen=True)
class Reply:
    """One state datagram the emulator puts on the wire, as the active faults make it.

    Attributes:
        frame: the bytes (possibly corrupt, short or long).
        delay: how long after now it leaves [s] (DELAY and JITTER; 0 for at once).
        foreign: sent from another port than the one commands go to (FOREIGN_PORT).
    """

    frame: bytes
    delay: float
    foreign: bool


@dataclass(frozen=True, kw_only=True)
class UnitreeEmulatorConfig:
    """Configuration of an emulated robot.

    Attributes:
        robot: ``a1`` or ``go1``.
        arm_mode: ``none`` (the bare quadruped) or ``locked`` (its arm on the trunk, held: its mass and inertia
            are in the physics; the 12 legs are what the wire drives either way).
        mode: ``lockstep`` or ``realtime``.
        host: the loopback address to bind (127.0.0.0/8 only).
        port: the UDP port to bind; 0 picks a free one (read it back from `UnitreeEmulator.address`).
        control_period: physics time per command (lockstep) or per reply (realtime) [s].
        motor_temperature: temperature every motor reports [deg C].
        log_size: most recent decoded commands kept; 0 keeps none (a long log is thousands of objects that each
            full garbage collection traverses, stalling the replies).
        seed: seed of the simulation and of the DROP fault's coin.
        receive_buffer: the UDP server's receive buffer [bytes], asked of the kernel, which caps it at its own limit
            (net.core.rmem_max) and doubles it for its bookkeeping. The default holds seconds of a link's frames while
            a busy machine keeps the emulator's thread off the CPU; a small one has it drop frames sooner, as a
            robot's board with its small buffer does.
        held_until_driven: the robot is held at its spawn pose (the physics waits; states are still sent), as an
            operator or a harness holds a real robot, until the first command that drives a motor (Kp > 0 or a
            torque); `reset` holds it again. Without it, an idle robot with its motors off folds to its joint stops
            within half a second, beyond the range a safety layer accepts for a ramp.
        first_tick: the tick of the first state sent; each state after it carries the robot's own clock, a
            control period later in microseconds (the unit the SDK's header comment gives), modulo 2**32 (a test
            starts it near 2**32 to see the counter wrap).
    """

    robot: str = "go1"
    arm_mode: str = "none"
    mode: str = "lockstep"
    host: str = "127.0.0.1"
    port: int = 0
    control_period: float = 0.002
    motor_temperature: int = 35
    log_size: int = 100_000
    seed: int = 0
    receive_buffer: int = 4 << 20
    held_until_driven: bool = False
    first_tick: int = 0

    def __post_init__(self) -> None:
        if self.robot not in DESCRIPTIONS:
            raise UnknownNameError("Unitree robot", self.robot, tuple(DESCRIPTIONS))
        if self.arm_mode not in LEG_ONLY_ARM_MODES:
            raise UnknownNameError("emulated arm mode (an actuated arm is not on the Unitree wire)", self.arm_mode,
                                   LEG_ONLY_ARM_MODES)
        if self.mode not in MODES:
            raise UnknownNameError("emulator mode", self.mode, MODES)
        if not is_loopback(self.host):
            raise ConfigError(f"UnitreeEmulatorConfig.host {self.host!r}: an emulator binds 127.0.0.0/8 only")
        if not 4096 <= self.receive_buffer <= 1 << 30:
            raise ConfigError(f"UnitreeEmulatorConfig.receive_buffer must be in [4096, 2**30] bytes, got "
                              f"{self.receive_buffer}")
        if not 0 < self.control_period <= 0.01:
            raise ConfigError(f"UnitreeEmulatorConfig.control_period must be in (0, 0.01] s, got "
                              f"{self.control_period}")
        if not (isinstance(self.first_tick, int) and 0 <= self.first_tick < 2**32):
            raise ConfigError(f"UnitreeEmulatorConfig.first_tick must be an integer in [0, 2**32), got "
                              f"{self.first_tick!r}")


class UnitreeEmulator:
    """The emulated robot: a UDP server thread over a `MujocoRobot`. A context manager (`start` / `close`).

    Args:
        config: what to emulate.
        sim: the simulated robot (12 legs); None builds one of ``config.robot`` with ``config.arm_mode``.
    """

    def __init__(self, config: UnitreeEmulatorConfig | None = None, sim: MujocoRobot | None = None) -> None:
        self.config = config if config is not None else UnitreeEmulatorConfig()
        self.layout = frame_layout(self.config.robot)
        self.sim = sim if sim is not None else MujocoRobot(MujocoRobotConfig(
            robot=DESCRIPTIONS[self.config.robot], arm_mode=self.config.arm_mode))
        if self.sim.num_joints != 12:
            raise ConfigError(f"UnitreeEmulator: the sim must drive the 12 legs only (arm mode none or locked), it has "
                              f"{self.sim.num_joints} joints")
        # a simulator advances whole physics steps (`MujocoRobot.physics_steps`): a period that is not one would run
        # more or less time than it says; a plant of another kind (`PlantLegs`) has no such bound
        steps_of = getattr(self.sim, "physics_steps", None)
        if callable(steps_of):
            try:
                steps_of(self.config.control_period)
            except ConfigError as e:
                raise ConfigError(f"UnitreeEmulatorConfig.control_period: {e}") from None
        self.stats = DecodeStats()
        self.last_reject = ""  # the latest rejected LowCmd's reason, empty until one is rejected
        self.refused = 0  # valid frames whose gains a motor cannot apply (negative): the motors got no torque
        self.replies = 0  # state datagrams sent
        self.dropped = 0  # datagrams the server's socket dropped, its buffer full, as of the latest one it took
        self.faults = FaultSet()
        self._log: collections.deque[LoggedCommand] = collections.deque(maxlen=self.config.log_size)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._sock: socket.socket | None = None
        self._foreign: socket.socket | None = None
        self._peer: tuple[str, int] | None = None
        self._pending: list[tuple[float, bytes, tuple[str, int]]] = []
        self._coin = random.Random(self.config.seed)
        self._off = MotorCommand.damping(12, 0.0)
        self.failure: BaseException | None = None
        self.address: tuple[str, int] = (self.config.host, 0)
        self._held = self.config.held_until_driven
        # the robot's own tick: its clock, which runs whether or not the physics does (a held robot, a damped one)
        self._tick = self.config.first_tick
        self._tick_step = max(1, round(self.config.control_period * 1e6))  # [us] per state sent
        self._last_frame: bytes | None = None  # the latest state frame composed (FROZEN_STATE repeats it)
        self.clock: Clock = MONOTONIC  # what the log's times are read from
        self._in_process: EmulatorTransport | None = None
        self._realtime_task: ScheduledCall | None = None

    # -- lifecycle ------------------------------------------------------------------------------------------------
    def prepare(self) -> UnitreeEmulator:
        """Build the simulation and load its compiled code, binding no socket and starting no thread. Idempotent.

        `start` does it when it is not done. A process that asks for real-time scheduling for the emulator's thread
        calls it first (``wbc hw emulate``): the build takes some 0.3 s of CPU, which at a real-time priority would
        hold off every other thread of that priority on the CPU.
        """
        self.sim.connect()
        return self

    def start(self) -> UnitreeEmulator:
        """Bind the socket, build the simulation (unless `prepare` did) and start the server thread. Idempotent.

        Raises:
            PortBusyError: the configured port is held by another socket.
            RobotLinkError: the socket could not be bound for another reason.
            ConfigError: it serves in process already (`transport`).
        """
        if self._thread is not None:
            return self
        if self._in_process is not None:
            raise ConfigError("UnitreeEmulator.start: it serves in process already (transport); use one or the other")
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((self.config.host, self.config.port))
        except OSError as exc:
            sock.close()
            if exc.errno in (errno.EADDRINUSE, errno.EACCES):
                raise PortBusyError(self.config.host, self.config.port, exc.strerror or str(exc)) from None
            raise RobotLinkError(f"UnitreeEmulator: cannot bind {self.config.host}:{self.config.port}: {exc}; "
                                 "port 0 picks a free one") from None
        sock.setblocking(False)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, self.config.receive_buffer)
            if _SO_RXQ_OVFL is not None:
                sock.setsockopt(socket.SOL_SOCKET, _SO_RXQ_OVFL, 1)
        except OSError:  # a kernel without them: the default buffer, and drops not counted
            pass
        foreign = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        foreign.bind((self.config.host, 0))
        self._sock, self._foreign = sock, foreign
        self.address = sock.getsockname()[:2]
        self.sim.connect()
        self.sim.reset(self.config.seed)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f"unitree-{self.config.robot}-emulator", daemon=True)
        self._thread.start()
        return self

    def transport(self, clock: Clock = MONOTONIC) -> EmulatorTransport:
        """An in-process `Transport` to this robot, on `clock`; no socket, no thread (see the module's docstring).

        Builds the simulation at its standing pose (as `start` does) on the first call. A second call hands out a
        new transport, to which the replies then go (the one peer, as the robot answers the latest sender).

        Args:
            clock: the time the log, the delayed replies and (``realtime``) the physics run on; a ``realtime``
                emulator needs a `ManualClock` (its physics is a task of that clock).

        Raises:
            ConfigError: the socket server runs already, or ``realtime`` without a `ManualClock`.
        """
        if self._thread is not None:
            raise ConfigError("UnitreeEmulator.transport: the UDP server runs already (start); use one or the other")
        realtime = self.config.mode == "realtime"
        if realtime and not isinstance(clock, ManualClock):
            raise ConfigError("UnitreeEmulator.transport: a realtime emulator in process steps its physics on a "
                              "ManualClock; hand one in, or use mode='lockstep'")
        if self._in_process is None:
            self.sim.connect()
            self.sim.reset(self.config.seed)
        self.clock = clock
        self._in_process = EmulatorTransport(self, clock)
        if realtime and self._realtime_task is None:
            self._realtime_task = clock.call_every(self.config.control_period, self._realtime_period,
                                                   first=clock.now() + self.config.control_period)
        return self._in_process

    def close(self) -> None:
        """Stop the thread (or the in-process physics task) and close the sockets. Idempotent."""
        if self._realtime_task is not None:
            self._realtime_task.cancel()
            self._realtime_task = None
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        for s in (self._sock, self._foreign):
            if s is not None:
                s.close()
        self._sock = self._foreign = None

    def __enter__(self) -> UnitreeEmulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- test API -------------------------------------------------------------------------------------------------
    def inject(self, fault: Fault, value: object = None) -> None:
        """Activate `fault` (see `Fault` for its value) until `clear`."""
        self.faults.inject(fault, value)

    def clear(self, fault: Fault | None = None) -> None:
        """Deactivate `fault`, or every fault if None."""
        self.faults.clear(fault)

    def reset(self, qpos: np.ndarray | None = None) -> None:
        """Put the emulated robot back at its standing pose, or at configuration `qpos` (e.g. lying folded).

        Args:
            qpos: the simulation's full configuration (trunk position, quaternion w x y z, 12 joints) [m, rad];
                None stands it at the nominal pose.

        Raises:
            ConfigError: `qpos` has the wrong size.
        """
        with self._lock:
            if qpos is not None and np.shape(qpos) != (self.sim.model.nq,):
                raise ConfigError(f"UnitreeEmulator.reset: qpos must have shape ({self.sim.model.nq},), got "
                                  f"{np.shape(qpos)}")
            self.sim.reset(self.config.seed, qpos=None if qpos is None else np.asarray(qpos, dtype=np.float64))
            self._held = self.config.held_until_driven
        # the robot's own tick: its clock, which runs whether or not the physics does (a held robot, a damped one)
        self._tick = self.config.first_tick
        self._tick_step = max(1, round(self.config.control_period * 1e6))  # [us] per state sent
        self._last_frame: bytes | None = None  # the latest state frame composed (FROZEN_STATE repeats it)

    @property
    def held(self) -> bool:
        """True while the robot is held at its spawn pose, waiting for a command that drives a motor."""
        return self._held

    def commands(self) -> list[LoggedCommand]:
        """The decoded commands received so far (the latest `log_size`), oldest first."""
        with self._lock:
            return list(self._log)

    def clear_log(self) -> None:
        """Forget the decoded commands received so far."""
        with self._lock:
            self._log.clear()

    def base_truth(self) -> BaseTruth:
        """The simulated trunk's true pose and velocity now."""
        with self._lock:
            return self.sim.base_truth()

    @property
    def sim_time(self) -> float:
        """Simulation time [s]."""
        with self._lock:
            return self.sim.time

    # -- what a command does, and what the robot answers (no socket) -----------------------------------------------
    def handle_command(self, data: bytes, *, step: bool) -> bool:
        """Take one LowCmd datagram: decode, log, write the simulation, and with `step` advance it one period.

        Returns:
            True if it was a valid command (a reject is counted in `stats` and changes nothing else).
        """
        try:
            wire = decode_command(self.layout, data, stats=self.stats)
        except FrameError as exc:
            self.last_reject = str(exc)  # why, for the operator: a client of another model says so here
            return False
        cmd = self._off
        if (wire.mode == MODE_SERVO).all():
            try:
                cmd = wire.motor_command()
            except CommandError:
                self.refused += 1
        elif (wire.mode == MODE_SERVO).any():
            mask = wire.mode == MODE_SERVO
            try:
                on = wire.motor_command()
                cmd = MotorCommand(q=on.q, dq=on.dq, kp=on.kp * mask, kd=on.kd * mask, tau=on.tau * mask)
            except CommandError:
                self.refused += 1
        with self._lock:
            if self.config.log_size:
                self._log.append(LoggedCommand(time=self.clock.now(), sim_time=self.sim.time, wire=wire,
                                               dropped_before=self.dropped))
            self.sim.write(cmd)
            if self._held and (np.any(cmd.kp > 0) or np.any(cmd.tau != 0)):
                self._held = False
            if step and not self._held:
                self.sim.advance(self.config.control_period)
        return True

    def step_realtime(self) -> None:
        """One period of the realtime mode's physics (nothing while the robot is held)."""
        with self._lock:
            if not self._held:
                self.sim.advance(self.config.control_period)

    def compose_reply(self) -> Reply | None:
        """The state datagram the robot sends now, bent by the active faults; None if none goes out (SILENCE, DROP)."""
        active = self.faults.snapshot()
        tick = self._tick
        self._tick = (tick + self._tick_step) % 2**32  # the robot's clock runs on, whether a frame leaves or not
        if Fault.SILENCE in active:
            return None
        if Fault.DROP in active and self._coin.random() < float(active[Fault.DROP]):
            return None
        with self._lock:
            state = self.sim.read()
        w, x, y, z = state.imu_quat
        rpy = np.array([math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y)),
                        math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x)))),
                        math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))])
        extras = LowStateExtras(motor_mode=np.full(12, MODE_SERVO, dtype=np.uint8),
                                motor_temperature=np.full(12, self.config.motor_temperature, dtype=np.int8),
                                imu_rpy=rpy)
        state, extras = apply_state_faults(active, dataclasses.replace(state, tick=tick), extras)
        if Fault.FROZEN_STATE in active and self._last_frame is not None:
            frame = self._last_frame  # the very bytes sent last: the robot's tick stands still
        else:
            frame = mangle_frame(active, encode_state(self.layout, state, extras))
            self._last_frame = frame
        delay = float(active.get(Fault.DELAY, 0.0) or 0.0)
        if Fault.JITTER in active:
            delay += self._coin.uniform(0.0, float(active[Fault.JITTER]))
        # a delayed reply leaves from the robot's own port (the foreign port is a separate fault's)
        return Reply(frame=frame, delay=delay, foreign=delay <= 0 and Fault.FOREIGN_PORT in active)

    def _realtime_period(self) -> None:
        """The in-process realtime mode: physics steps one period, and the robot answers its peer."""
        self.step_realtime()
        if self._in_process is not None and self._in_process.spoken:
            self._in_process.deliver(self.compose_reply())

    # -- server thread --------------------------------------------------------------------------------------------
    def _run(self) -> None:
        try:
            self._serve()
        except BaseException as exc:  # noqa: BLE001 - kept for the test to read; the thread must not die silently
            self.failure = exc

    def _serve(self) -> None:
        sock, period, clock = self._sock, self.config.control_period, self.clock
        realtime = self.config.mode == "realtime"
        next_step = clock.now() + period
        while not self._stop.is_set():
            now = clock.now()
            wake = [now + _POLL] + ([next_step] if realtime else []) + [p[0] for p in self._pending]
            timeout = min(wake) - now
            if timeout > 0:
                select.select([sock], [], [], timeout)  # not epoll: its timeout is whole milliseconds
            self._drain(sock, step=not realtime)
            now = clock.now()
            if realtime and now >= next_step:
                self.step_realtime()
                if self._peer is not None:
                    self._reply(self._peer)
                next_step += period
                if next_step < now:
                    next_step = now + period
            self._flush(now)

    def _drain(self, sock: socket.socket, *, step: bool) -> None:
        for _ in range(256):
            try:
                data, ancillary, _, peer = sock.recvmsg(MAX_DATAGRAM, _DROP_COUNT_SPACE)
            except (BlockingIOError, InterruptedError):
                return
            except ConnectionRefusedError:
                continue
            for level, kind, value in ancillary:
                if level == socket.SOL_SOCKET and kind == _SO_RXQ_OVFL and len(value) >= 4:
                    self.dropped = struct.unpack("I", value[:4])[0]
            if not self.handle_command(data, step=step):
                continue
            self._peer = peer[:2]
            if step:
                self._reply(self._peer)

    def _reply(self, peer: tuple[str, int]) -> None:
        reply = self.compose_reply()
        if reply is None:
            return
        if reply.delay > 0:
            self._pending.append((self.clock.now() + reply.delay, reply.frame, peer))
            return
        self._send(reply.frame, peer, foreign=reply.foreign)

    def _send(self, frame: bytes, peer: tuple[str, int], *, foreign: bool) -> None:
        sock = self._foreign if foreign else self._sock
        try:
            sock.sendto(frame, peer)
            self.replies += 1
        except (BlockingIOError, ConnectionRefusedError):
            pass

    def _flush(self, now: float) -> None:
        if not self._pending:
            return
        due = [p for p in self._pending if p[0] <= now]
        self._pending = [p for p in self._pending if p[0] > now]
        for _, frame, peer in due:
            self._send(frame, peer, foreign=False)


class EmulatorTransport:
    """A `wbc.hardware.unitree.Transport` straight into a `UnitreeEmulator` in this process (its `transport`).

    `send` hands the datagram to the emulator, which handles it within the call (lockstep: one physics step) and
    whose reply is queued at once, or, delayed, when the clock reaches its time (`ManualClock.call_at`; on another
    clock, at the first `receive` after it). A reply from the foreign port is counted in `foreign` and never
    queued, as `UdpTransport` drops it; corrupt, short and long frames are queued as they are, for the backend's
    decoder to reject.

    Args:
        emulator: the robot.
        clock: the time delayed replies are due on.

    Attributes:
        foreign: replies dropped because they came from another port than the robot's.
    """

    def __init__(self, emulator: UnitreeEmulator, clock: Clock = MONOTONIC) -> None:
        self.emulator = emulator
        self.clock = clock
        self.foreign = 0
        self.spoken = False  # a command was sent: the robot knows where to answer (realtime mode)
        self._inbox: list[bytes] = []
        self._pending: list[tuple[float, bytes]] = []
        self._ready = threading.Condition()
        self._closed = False

    @property
    def closed(self) -> bool:
        """True once `close` ran."""
        return self._closed

    def send(self, frame: bytes) -> None:
        """Hand `frame` to the emulator; in lockstep its reply (if any) is queued before this returns.

        Raises:
            RobotLinkError: the transport is closed.
        """
        if self._closed:
            raise RobotLinkError("EmulatorTransport: closed")
        emu = self.emulator
        lockstep = emu.config.mode == "lockstep"
        if emu.handle_command(frame, step=lockstep):
            self.spoken = True
            if lockstep:
                self.deliver(emu.compose_reply())

    def deliver(self, reply: Reply | None) -> None:
        """Put a reply on its way to `receive`: now, or when the clock reaches its delay."""
        if reply is None or self._closed:
            return
        if reply.delay > 0:
            due = self.clock.now() + reply.delay
            if isinstance(self.clock, ManualClock):
                self.clock.call_at(due, lambda: self._arrive(reply.frame, foreign=False))
            else:
                with self._ready:
                    self._pending.append((due, reply.frame))
            return
        self._arrive(reply.frame, foreign=reply.foreign)

    def _arrive(self, frame: bytes, *, foreign: bool) -> None:
        if self._closed:
            return
        self.emulator.replies += 1
        with self._ready:
            if foreign:
                self.foreign += 1
                return
            self._inbox.append(frame)
            self._ready.notify_all()

    def _due(self) -> None:
        """Move the delayed replies whose time has come into the inbox (a clock without a scheduler)."""
        if not self._pending:
            return
        now = self.clock.now()
        due = sorted((p for p in self._pending if p[0] <= now), key=lambda p: p[0])
        self._pending = [p for p in self._pending if p[0] > now]
        for _, frame in due:
            self.emulator.replies += 1
            self._inbox.append(frame)

    def receive(self) -> list[bytes]:
        """Every reply queued so far, oldest first (empty if none)."""
        with self._ready:
            self._due()
            out, self._inbox = self._inbox, []
        return out

    def wait_readable(self, timeout: float) -> bool:
        """True if a reply is queued; on a `ManualClock` at once, otherwise after waiting up to `timeout` [s] for one.

        On a `ManualClock` time moves only when the clock is moved, so there is nothing to wait for.
        """
        with self._ready:
            self._due()
            if self._inbox or isinstance(self.clock, ManualClock):
                return bool(self._inbox)
            self._ready.wait(max(0.0, timeout))
            self._due()
            return bool(self._inbox)

    def close(self) -> None:
        """Stop taking commands; replies still due are dropped. Idempotent."""
        self._closed = True
        with self._ready:
            self._inbox.clear()
            self._pending.clear()
