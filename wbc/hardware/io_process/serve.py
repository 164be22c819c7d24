"""The I/O process: a hardware robot's devices (legs link, arm bus) served to a controller in another process.

`ProcessRobot` (`process_robot.py`) starts this as a fresh interpreter (``python -c``, not multiprocessing, whose
spawn re-imports the parent's ``__main__``). `serve_io_process` shortens the switch interval, builds the robot with
`build_hardware_robot`, loads its compiled code (`load_write_check`) and freezes its heap, then asks the OS for
real-time scheduling, a CPU of its own and locked memory (`HardwareRobotConfig.realtime`, `wbc.hardware.realtime`),
connects the robot and reports on the control channel, with what the OS granted. The slow part of the start-up runs
before the real-time priority is asked: run at that priority, it would hold off every other thread of the same
priority on its CPU (each I/O process takes the same last CPU) for as long as it takes, up to 0.5 s.

The legs' link thread then does the serving itself, through its hooks (`UnitreeRobot.set_link_hooks`), so that no
thread of this process wakes twice a period only to pass data on:

- before each send it forwards the newest command of the shared command block, if a new one was posted, to the
  robot's `write` (legs and arm), so the command goes out in that very period;
- after each new leg state it reads the whole robot (`QuadrupedArmRobot.read`: legs and arm joined), its remote and
  its motors' status, publishes them to the shared state block and rings the doorbell (one byte), so that a waiting
  `advance` wakes.

The main thread answers the control channel (``link_stats``: the devices' counters and their loops' statistics;
``close``) and, every 20 ms, reads the robot, which raises if the link's or the bus's thread died.

The devices keep their own safety: the legs' link damps once `write` has not been called for its write deadline, the
arm's bus likewise, so a controller's process that stalls or hangs (holding its own interpreter lock forever) leaves
the robot damped. A failure of the devices (the link thread died, the serial port is lost) is reported on the channel
and flagged in the state block, and the process closes the robot and exits; so does it when the controller's process
goes away (end of file on the channel: no orphan), and on ``close``. Closing the robot leaves it damped. SIGINT and
SIGHUP are ignored: a Ctrl-C at the terminal, or the terminal closed, reaches both processes, and the controller's
process closes this one in order (or, if it died of it, its end of the channel closes, and this process closes the
robot on its own). SIGTERM and SIGQUIT, to this process alone or to the whole command, stop it in order
(`_STOPPING`): the stop is reported and flagged as a failure, and the robot closed as on ``close``. All four are
blocked from the process's start (`HELD_AT_START`) until they are set so.
"""

from __future__ import annotations

import base64
import math
import os
import pickle
import select
import signal
import socket
import sys
import threading
import time
from dataclasses import asdict

import numpy as np

from wbc.errors import IoProcessStopped, RobotLinkError
from wbc.hardware.capabilities import (
    HasLatchedFaults,
    HeldJoints,
    JoinedDevices,
    MotorStatusSource,
    RemoteEstopLatch,
    RemoteSource,
    WriteDeadlineTrips,
    provides,
)
from wbc.hardware.hardware_robot import HardwareRobotConfig, build_hardware_robot
from wbc.hardware.interpreter import freeze_heap, realtime_switch_interval
from wbc.hardware.io_process.blocks import HELD_DAMP, HELD_FIELDS, HELD_RAMP, MAX_STATUS, IoBlocks
from wbc.hardware.io_process.channel import ChannelClosed, LineChannel, error_report
from wbc.hardware.quadruped_arm_robot import JoinedLinkStats, QuadrupedArmRobot
from wbc.hardware.realtime import RealtimeGrant, request_realtime
from wbc.hardware.robot import Robot, load_write_check
from wbc.hardware.safety.ramp import CommandRamp
from wbc.hardware.unitree.remote import Remote
from wbc.hardware.unitree.robot import UnitreeRobot
from wbc.interrupts import HeldInterrupts
from wbc.types import MotorCommand

__all__ = ["HELD_AT_START", "serve_io_process"]

_WAIT_S = 0.02  # [s] longest a thread blocks before it looks at its stop flag

_TERMINAL = (signal.SIGINT, signal.SIGHUP)
"""The terminal's signals, Ctrl-C and the hangup of a closed terminal, which reach both processes: ignored, the
controller's process decides, and closes this one in order (or, if it died of them, its end of the channel closes)."""

_STOPPING = (signal.SIGTERM, signal.SIGQUIT)
"""The signals that stop the I/O process in order, sent to it alone or to the whole command (a service manager's stop,
``kill``, Ctrl-\\ at the terminal): the robot is closed as on the controller's ``close`` (the legs damped, the
arm parked), then the process exits."""

HELD_AT_START = _TERMINAL + _STOPPING
"""The signals the I/O process starts with blocked: `ProcessRobot` blocks them around its start (a signal mask
survives exec), and `serve_io_process` unblocks them once it has set what they do. One that came meanwhile waits (a
stop is then taken; a Ctrl-C or a hangup is dropped): delivered during the interpreter's start-up and the imports,
they ended the process half started, a Ctrl-C with a traceback."""


def serve_io_process(argv: list[str] | None = None) -> None:
    """Serve the robot described on the command line; returns when the robot is closed (the process then exits).

    Args:
        argv: ``[config, memory fd, control fd, doorbell fd]``: the pickled `HardwareRobotConfig` (base64) and the
            descriptors inherited from the controller's process (default: ``sys.argv[1:]``).
    """
    args = sys.argv[1:] if argv is None else argv
    for signum in _TERMINAL:
        signal.signal(signum, signal.SIG_IGN)
    signals = _StopSignals()
    signal.pthread_sigmask(signal.SIG_UNBLOCK, HELD_AT_START)  # blocked since the start (`ProcessRobot`): taken now
    realtime_switch_interval()
    config: HardwareRobotConfig = pickle.loads(base64.b64decode(args[0]))
    control = LineChannel(socket.socket(fileno=int(args[2])))
    bell = socket.socket(fileno=int(args[3]))
    bell.setblocking(False)
    try:
        robot, blocks, grant = _start_up(config, int(args[1]))
        if signals.received is not None:  # stopped before the robot was reached: nothing to close
            raise signals.stopped(connected=False)
        robot.connect()
        started = time.process_time()
    except BaseException as exc:  # noqa: BLE001 - every failure is reported to the controller's process
        _report(control, error_report(exc))
        return
    server = _Server(robot, blocks, control, bell, started, grant, signals)
    try:
        server.run()
    finally:
        server.shut_down()


def _start_up(config: HardwareRobotConfig, memory_fd: int) -> tuple[Robot, IoBlocks, RealtimeGrant]:
    """Build the robot, load its compiled code, map the shared blocks and freeze the heap; then ask for real time.

    The request comes last: run at a real-time priority, the slow start-up (the first compiled call loads numba,
    some 0.2-0.5 s of CPU) would hold off every other thread of that priority on the CPU, such as another I/O
    process's link, for as long as it takes. It still comes before any of the process's own threads start (the robot
    is connected after it): the link's and the bus's threads inherit the policy and the CPU.
    """
    robot = build_hardware_robot(config).robot
    load_write_check()
    blocks = IoBlocks(robot.num_joints, fd=memory_fd)
    freeze_heap()
    grant = request_realtime(config.realtime)
    return robot, blocks, grant


def _report(control: LineChannel, message: dict) -> None:
    try:
        control.send(message)
    except ChannelClosed:
        pass  # the controller's process is gone; nobody is left to tell


class _StopSignals:
    """SIGTERM and SIGQUIT (`_STOPPING`) noted, the first of them, rather than ending the process.

    The handler only notes the signal; the byte the interpreter then writes to `wake`'s other end
    (`signal.set_wakeup_fd`) wakes the main thread's wait at once, and the main thread reports the stop and closes the
    robot in order. An exception raised from the handler instead could land anywhere: in a message half sent, or in
    the closing itself. The report (`IoProcessStopped`) is followed by ``closed`` once the robot is closed.
    """

    def __init__(self) -> None:
        self.received: int | None = None
        self.wake, self._ring = socket.socketpair()
        for sock in (self.wake, self._ring):
            sock.setblocking(False)
        signal.set_wakeup_fd(self._ring.fileno(), warn_on_full_buffer=False)
        for signum in _STOPPING:
            signal.signal(signum, self._note)

    def _note(self, signum: int, frame: object) -> None:
        if self.received is None:
            self.received = signum

    def drain(self) -> None:
        """Empty `wake` (the bytes of the signals noted), so that a wait on it blocks again."""
        try:
            while self.wake.recv(4096):
                pass
        except (BlockingIOError, InterruptedError):
            pass

    def stopped(self, *, connected: bool) -> IoProcessStopped:
        """The failure the controller's process is told of, once a signal came (`connected`: the robot was)."""
        name = signal.Signals(self.received).name if self.received is not None else "a signal"
        return IoProcessStopped(name, connected=connected)


class _Server:
    def __init__(self, robot: Robot, blocks: IoBlocks, control: LineChannel, bell: socket.socket,
                 started: float, grant: RealtimeGrant, signals: _StopSignals) -> None:
        self.robot = robot
        self.signals = signals
        self.grant = grant
        self.blocks = blocks
        self.control = control
        self.bell = bell
        self.legs = robot.legs if isinstance(robot, QuadrupedArmRobot) else robot
        if not isinstance(self.legs, UnitreeRobot):
            raise RobotLinkError(f"I/O process: the legs are a {type(self.legs).__name__}, not a UnitreeRobot")
        self.send_lock = threading.Lock()
        self.forward_lock = threading.Lock()  # no command is forwarded once `stop` is set under it (`shut_down`)
        self.stop = threading.Event()
        self.failure: dict | None = None
        self.command_seen = 0
        self.held_seen = 0.0  # the generation of the held joints' mode last applied (`_hold_as_asked`)
        self.releases_seen = 0  # the safety layer's releases of the link's L2 + B latch applied so far
        self.counts = dict(states_published=0, commands_forwarded=0, bells_missed=0)
        self.started = started
        # the robot's capabilities, resolved once: a runtime-checkable protocol's isinstance runs its properties (and
        # takes the devices' locks) on every call, too dear for the link thread's every state
        self.latch = robot if provides(robot, RemoteEstopLatch) else None
        self.trips = robot if provides(robot, WriteDeadlineTrips) else None
        self.joined = robot if provides(robot, JoinedDevices) else None
        self.held = robot if provides(robot, HeldJoints) else None
        self.remote_of = robot.remote if provides(robot, RemoteSource) else None
        self.status_of = robot.motor_status if provides(robot, MotorStatusSource) else None

    def run(self) -> None:
        self._publish()  # the first state, before the controller's process is told
        self.legs.set_link_hooks(before_send=self._forward, on_state=self._on_state)
        if self._signalled():  # stopped while connecting: the controller's `connect` raises it
            return
        self._send({"connected": True, "pid": os.getpid(), "realtime": self.grant.to_dict()})
        while not self.stop.is_set():
            ready = select.select([self.control, self.signals.wake], [], [], _WAIT_S)[0]
            if self.signals.wake in ready:
                self.signals.drain()
            if self._signalled():
                return
            if self.control in ready or self.control.pending():
                try:
                    request = self.control.receive(0.0)
                except ChannelClosed:
                    return  # the controller's process is gone
                if request is not None and not self._answer(request):
                    return
            try:
                self.robot.read()  # raises if the link's or the bus's thread died
            except Exception as exc:  # noqa: BLE001 - reported, then the robot is closed
                self._fail(exc)

    def _signalled(self) -> bool:
        """True once SIGTERM or SIGQUIT came: reported and flagged as a failure, then `shut_down` closes the robot."""
        if self.signals.received is None:
            return False
        self._fail(self.signals.stopped(connected=True))
        return True

    def _forward(self) -> None:
        """The link thread, each period before it sends: the newest command, if a new one was posted, to `write`."""
        with self.forward_lock:
            if not self.stop.is_set():
                self._forward_newest()

    def _forward_newest(self) -> None:
        """The newest command, if a new one was posted, to the robot's `write` (the lock held)."""
        try:
            block = self.blocks.command
            if block.count != self.command_seen:
                self.command_seen, record = block.read()
                releases = int(record["estop_releases"])
                if releases != self.releases_seen and self.latch is not None:
                    self.releases_seen = releases
                    self.latch.release_remote_estop()  # before the command it goes with (the ramp after a reset)
                self._hold_as_asked(record["held"])
                self.robot.write(MotorCommand._trusted(np.array(record["rows"])))
                self.counts["commands_forwarded"] += 1
        except Exception as exc:  # noqa: BLE001 - reported, then the robot is closed
            self._fail(exc)

    def _hold_as_asked(self, held: np.ndarray) -> None:
        """A new generation of the held joints' mode (the safety layer's damp or ramp) to the robot (`HeldJoints`)."""
        if held[0] == self.held_seen or self.held is None:
            return
        self.held_seen = float(held[0])
        values = dict(zip(HELD_FIELDS, (float(v) for v in held), strict=True))
        if values["mode"] == HELD_DAMP:
            self.held.damp_held(values["kd"])
        elif values["mode"] == HELD_RAMP:
            self.held.ramp_held(CommandRamp(duration_s=values["duration_s"], slew=values["slew"], kp=values["kp"],
                                             kd=values["ramp_kd"], hold_s=values["hold_s"]))

    def _on_state(self) -> None:
        """The link thread, after each new leg state: the robot's state to the shared block."""
        if self.stop.is_set():
            return
        try:
            self._publish()
        except Exception as exc:  # noqa: BLE001 - reported, then the robot is closed
            self._fail(exc)

    def _answer(self, request: dict) -> bool:
        op = request.get("op")
        if op == "close":
            return False
        if op == "link_stats":
            stats = self.robot.link_stats()
            if not isinstance(stats, JoinedLinkStats):  # the legs alone
                stats = JoinedLinkStats(legs=stats, arm=None, threads={"legs": self.legs.thread_stats()})
            legs, arm = stats.legs, stats.arm
            self._send({"link_stats": {
                "legs": asdict(legs) if legs is not None else None, "arm": asdict(arm) if arm is not None else None,
                "threads": {device: asdict(thread) for device, thread in stats.threads.items()},
                "io": dict(self.counts, cpu_s=time.process_time() - self.started)}})
            return True
        if op == "stale_frames":  # asked, not published: a frozen board publishes no new state to carry it
            self._send({"stale_frames": self.legs.stale_frames})
            return True
        if op == "faults":
            faults = self.robot.faults if isinstance(self.robot, HasLatchedFaults) else ()
            self._send({"faults": [asdict(fault) for fault in faults]})
            return True
        self._send({"error": "ConfigError", "message": f"I/O process: unknown request {op!r}", "attrs": {}})
        return True

    def _send(self, message: dict) -> None:
        with self.send_lock:
            _report(self.control, message)

    def _fail(self, exc: BaseException) -> None:
        with self.send_lock:
            first = self.failure is None
            if first:
                self.failure = error_report(exc)
        if first:
            self._send(self.failure)
            self.blocks.state.set_failed()
            self._ring()
        self.stop.set()

    def _ring(self) -> None:
        try:
            self.bell.send(b"s")
        except (BlockingIOError, InterruptedError):
            self.counts["bells_missed"] += 1  # the controller's process is not reading: it stalled
        except OSError:
            self.stop.set()

    def _publish(self) -> None:
        robot = self.robot
        state = robot.read()
        remote = self.remote_of() if self.remote_of is not None else None
        status = self.status_of() if self.status_of is not None else None
        block = self.blocks.state
        rec = block.record()
        rec["tick"], rec["time"] = state.tick, state.time
        for name in ("q", "dq", "tau_est", "imu_quat", "gyro_in_body", "accel_in_body", "foot_force"):
            rec[name] = getattr(state, name)
        if status is not None:
            modes = np.asarray(status.motor_mode)
            if modes.size > MAX_STATUS:
                raise RobotLinkError(f"I/O process: {modes.size} motors report a status; at most {MAX_STATUS} fit")
            rec["status_n"] = modes.size
            rec["motor_mode"][:modes.size] = modes
            rec["motor_temperature"][:modes.size] = np.asarray(status.motor_temperature)
        else:
            rec["status_n"] = -1
        rec["deadline_trips"] = self.trips.deadline_trips if self.trips is not None else 0
        ages = self.joined.state_ages() if self.joined is not None else {}
        trips = self.joined.deadline_trips_by_device() if self.joined is not None else {}
        for device in ("legs", "arm"):
            rec[f"{device}_age"] = ages.get(device, math.nan)
            rec[f"{device}_deadline_trips"] = trips.get(device, -1)
        latch = self.latch
        rec["remote_estops"] = latch.remote_estops if latch is not None else 0
        rec["remote_estop_latched"] = latch.remote_estop_latched if latch is not None else False
        rec["has_remote"] = isinstance(remote, Remote)  # a class, not a protocol: cheap
        if isinstance(remote, Remote):
            rec["remote"] = np.frombuffer(remote.raw, np.uint8)
        block.publish()
        self.counts["states_published"] += 1
        self._ring()

    def shut_down(self) -> None:
        """Forward the last command, unhook, close the robot (left damped), tell the controller's process, release all.

        The command posted last goes out first, unless a failure stopped the process: before its ``close``, the
        controller's safety layer posts damping, which must not wait for the link's write deadline (the legs would hold
        their last command meanwhile, as long as if nothing had damped them). Then the robot is closed, which damps the
        legs from their next frame on before the arm's close begins (`QuadrupedArmRobot`).
        """
        with self.forward_lock:  # the link thread is not forwarding now, and forwards nothing from now on
            self.stop.set()
            if self.failure is None:
                self._forward_newest()
        self.legs.set_link_hooks()
        try:
            with HeldInterrupts(None):  # its stop signals are noted by its own handlers; the close need not say them
                self.robot.close()
            self._send({"closed": True})
        except BaseException as exc:  # noqa: BLE001 - reported; the process exits anyway
            self._send(error_report(exc))
        finally:
            self.blocks.close()
            self.bell.close()
            self.control.close()
