"""`ProcessRobot`: a hardware robot whose devices (legs link, arm bus) run in a child process, the I/O process.

In one process, a robot's link thread (500 Hz), its arm's bus thread (200 Hz) and the controller share one
interpreter lock: a controller that computes most of each period makes the link overrun its periods and the arm's
reads time out, and a controller stuck holding the lock (a C extension that hangs) freezes the link, whose
write-deadline damping then never goes out. `ProcessRobot` is the same robot (the same joints, limits and
capabilities as `build_hardware_robot`'s) with its devices in a fresh interpreter (`serve.py`) that has its own lock:

- data path: shared memory (`blocks.py`), lock-free both ways. The I/O process publishes every new state (joined
  legs and arm, the remote, the motors' status) as the legs' link receives it; `read` returns the newest.
  `write` clamps (as every `Robot` does) and posts the command; the legs' link thread takes the newest before each
  send and forwards it to the devices' `write`, so it goes out in the same period as a command written in-process;
- `advance(dt)` paces on the monotonic clock as `UnitreeRobot` does: a call that finds its deadline past is counted
  late and resynchronises; then, unless a state newer than the one last read has already been published, it waits
  (at most two link periods) for one;
- control channel (`channel.py`): `connect` starts the I/O process, which builds, connects and reports (a `connect`
  given up, interrupted or timed out, sends it SIGTERM first: it then stops before it reaches the robot); `close`
  asks it to close the robot (which leaves it damped) and exit; `link_stats` fetches the devices' counters and their
  threads' statistics, `faults` the faults the arm's bus latched;
  `realtime_grant` says what scheduling the I/O process asked the OS for and got (`HardwareRobotConfig.realtime`).
  An exception there (a refused connect, `PortBusyError`, `RobotLinkError`, a lost serial port) is raised here as the
  same `wbc` error class with the same message; the I/O process dying is a `RobotLinkError` at the next `read`,
  `write` or `advance`, which says that nothing may have damped the robot (check it); stopped by SIGTERM or SIGQUIT,
  the I/O process closes the robot into damping, and the next call raises `IoProcessStopped` once it has said that
  the robot is closed (a `RobotLinkError` that says nothing may have damped it, if it ended without saying so). A
  ``close`` that meets such a stop does not raise: the robot is closed, as asked (SIGTERM to the whole command
  reaches both processes, and its close then met the I/O process's own). Either way the process, the sockets and
  the shared memory are released at once;
- safety: the devices keep their write deadlines, so when this process stops writing (stalled, or hung holding its
  interpreter lock) the robot is damped within the deadline; when this process dies, the I/O process sees its end
  of the channel close, closes the robot (damped) and exits: no orphan. Address refusals happen in this process, when
  the robot is built, before any process or socket exists.
"""

from __future__ import annotations

import base64
import dataclasses
import pickle
import select
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass

import numpy as np

from wbc.errors import IoProcessStopped, RobotLinkError, WbcError
from wbc.hardware.capabilities import HeldRamp, MotorNames
from wbc.hardware.device_thread import DeviceThreadStats
from wbc.hardware.dynamixel.arm_fault import ArmBusStats, ArmFault
from wbc.hardware.hardware_robot import HardwareRobot, HardwareRobotConfig, build_hardware_robot
from wbc.hardware.interpreter import child_process_env, wbc_interpreter_env
from wbc.hardware.io_process.blocks import HELD_DAMP, HELD_FIELDS, HELD_RAMP, IoBlocks
from wbc.hardware.io_process.channel import ChannelClosed, LineChannel, rebuild_error
from wbc.hardware.io_process.serve import HELD_AT_START
from wbc.hardware.pacing import WallPacer
from wbc.hardware.quadruped_arm_robot import JoinedLinkStats, JointMotorStatus
from wbc.hardware.realtime import RealtimeGrant
from wbc.hardware.robot import Robot
from wbc.hardware.unitree.link_stats import LinkStats
from wbc.hardware.unitree.remote import Remote
from wbc.robots.joint_table import JointTable
from wbc.types import MotorCommand, RobotState

__all__ = ["ProcessLinkStats", "ProcessRobot", "build_process_robot"]

_START = "from wbc.hardware.io_process.serve import serve_io_process; serve_io_process()"

_LEFT_UNKNOWN = ("nothing may have damped the robot: the legs may keep their last command (they have no watchdog of "
                 "their own), and the arm goes limp when its servos' bus watchdog acts; check the robot")
"""What the controller's process is told when the I/O process ended without saying that it closed the robot."""


@dataclass(frozen=True)
class ProcessLinkStats:
    """The devices' counters (from the I/O process) with this process's pacing, and the I/O process's own.

    Attributes:
        devices: the devices' counters: the legs' link, the arm's bus (None without an arm) and each device's loop
            statistics, their ``late_advances`` and ``worst_lateness`` this process's (the I/O process never paces).
        io: the I/O process's counters: ``states_published``, ``commands_forwarded``, ``bells_missed`` (doorbells
            this process's full socket refused: it was not reading) and ``cpu_s`` (its CPU time since the robot was
            connected, every thread [s]).
    """

    devices: JoinedLinkStats
    io: dict[str, float]

    @property
    def late_advances(self) -> int:
        """`advance` calls that found their deadline already past."""
        return self.devices.late_advances

    @property
    def worst_lateness(self) -> float:
        """By how much the latest late `advance` was late [s]."""
        return self.devices.worst_lateness

    @property
    def state_age(self) -> float | None:
        """How old the legs' newest valid state was when the I/O process answered [s] (`JoinedLinkStats.state_age`)."""
        return self.devices.state_age

    def as_dict(self, prefix: str = "link/") -> dict[str, float]:
        """The devices' counters under `prefix`, the I/O process's under `prefix` + ``io/``."""
        return {**self.devices.as_dict(prefix), **{f"{prefix}io/{k}": v for k, v in self.io.items()}}


class ProcessRobot(Robot):
    """The hardware robot `config` describes, its devices in an I/O process (see the module docstring).

    Args:
        config: the robot and where its parts are reached (plain data: it is handed to the I/O process).
        start_timeout: how long `connect` waits for the I/O process to start, build and connect the robot [s] (a
            fresh interpreter imports `wbc` first).

    Raises:
        TargetRefusedError: a target outside 127.0.0.0/8 without `allow_hardware` (no process, no socket).
        ConfigError: an invalid setting (as `build_hardware_robot`).
    """

    def __init__(self, config: HardwareRobotConfig, *, start_timeout: float = 60.0) -> None:
        super().__init__()
        built = build_hardware_robot(config)  # refusals here, before any process or socket exists
        self.config = config
        self._names = built.robot.joint_names
        self._motor_names = built.robot.motor_names if isinstance(built.robot, MotorNames) else ()
        self._limits = built.robot.limits
        self.gain_limits = built.robot.gain_limits
        self._period = 1.0 / config.rate_hz
        self._start_timeout = start_timeout
        self._proc: subprocess.Popen[bytes] | None = None
        self._blocks: IoBlocks | None = None
        self._control: LineChannel | None = None
        self._bell: socket.socket | None = None
        self._reset()

    def _reset(self) -> None:
        self._failure: WbcError | None = None
        self._snapshot: tuple[int, np.ndarray | None] = (0, None)
        self._state: RobotState | None = None
        self._read_count = 0  # the publication the caller last read
        self._state_count = -1  # the publication `_state` was built from
        self._pacer = WallPacer()
        self._grant: RealtimeGrant | None = None
        self._held = np.zeros(len(HELD_FIELDS))  # generation 0, HELD_HOLD: as a robot with no safety layer above
        self._estop_releases = 0  # releases of the link's L2 + B latch asked so far (sent with the next command)

    # -- Robot ----------------------------------------------------------------------------------------------------
    @property
    def joint_names(self) -> tuple[str, ...]:
        """The robot's joints, house order (legs, then the arm's when actuated)."""
        return self._names

    @property
    def limits(self) -> JointTable:
        """The robot's motor limits, as `build_hardware_robot`'s robot has them."""
        return self._limits

    def _connect(self) -> None:
        self._reset()
        blocks = IoBlocks(len(self._names))
        control, control_child = socket.socketpair()
        bell, bell_child = socket.socketpair()
        self._blocks, self._control, self._bell = blocks, LineChannel(control), bell
        try:
            # its BLAS single-threaded (it does no parallel linear algebra, and an idle pool's buffers are memory it
            # would lock) and MuJoCo's rendering off: `child_process_env`
            env = wbc_interpreter_env(child_process_env())
            fds = (blocks.fd, control_child.fileno(), bell_child.fileno())
            # the I/O process starts with the signals it takes blocked (a signal mask survives exec), until it can
            mask = signal.pthread_sigmask(signal.SIG_BLOCK, HELD_AT_START)
            try:
                self._proc = subprocess.Popen(
                    [sys.executable, "-c", _START, base64.b64encode(pickle.dumps(self.config)).decode(),
                     *(str(fd) for fd in fds)], pass_fds=fds, env=env, stdin=subprocess.DEVNULL)
            finally:
                signal.pthread_sigmask(signal.SIG_SETMASK, mask)
            control_child.close()
            bell_child.close()
            bell.setblocking(False)
            reply = self._control.receive(self._start_timeout)
            if reply is None:
                raise RobotLinkError(f"ProcessRobot: the I/O process did not connect the robot within "
                                     f"{self._start_timeout} s")
            if "error" in reply:
                raise rebuild_error(reply, where="ProcessRobot I/O process")
            if not reply.get("connected"):
                raise RobotLinkError(f"ProcessRobot: the I/O process answered {reply!r} instead of connecting")
            self._grant = RealtimeGrant.from_dict(reply["realtime"])
        except ChannelClosed:
            self._release()
            raise RobotLinkError(f"ProcessRobot: the I/O process exited while connecting (status "
                                 f"{self._exit_status()})") from None
        except BaseException:
            self._stop_starting()
            self._release()
            raise
        finally:
            control_child.close()
            bell_child.close()

    def _close(self) -> None:
        failure = None
        if self._failure is None and self._control is not None:
            try:
                self._control.send({"op": "close"})
            except ChannelClosed:
                pass  # it is closing already (a stop signal): what it said before is still to be read
            try:
                failure = self._await("closed", timeout=5.0)
            except WbcError as exc:
                failure = exc
        self._release()
        if isinstance(failure, WbcError) and self._failure is None:
            raise failure

    def _read(self) -> RobotState:
        self._check()
        count, record = self._newest()
        if record is None:
            raise RobotLinkError("ProcessRobot: no state published yet")
        if self._state is None or self._state_count != count:
            self._state = RobotState(
                tick=int(record["tick"]), time=float(record["time"]), q=record["q"].copy(), dq=record["dq"].copy(),
                tau_est=record["tau_est"].copy(), imu_quat=record["imu_quat"].copy(),
                gyro_in_body=record["gyro_in_body"].copy(), accel_in_body=record["accel_in_body"].copy(),
                foot_force=record["foot_force"].copy())
            self._state_count = count
        self._read_count = count
        return self._state

    def _send(self, cmd: MotorCommand) -> None:
        self._check()
        block = self._blocks.command
        record = block.record()
        record["rows"] = (cmd.q, cmd.dq, cmd.kp, cmd.kd, cmd.tau)
        record["held"] = self._held  # with the command it goes with: the I/O process applies both in one period
        record["estop_releases"] = self._estop_releases
        block.publish()  # the link takes it before its next send

    # -- HeldJoints: a locked arm, held in the I/O process --------------------------------------------------------
    def damp_held(self, kd: float) -> None:
        """Damp the joints the robot drives for no controller (a locked arm) from the next write on (`HeldJoints`)."""
        self._set_held(HELD_DAMP, kd=kd)

    def ramp_held(self, ramp: HeldRamp) -> None:
        """Ramp them into their hold, through a ramp built as `ramp` is, from the next write on (`HeldJoints`)."""
        settings = ramp.settings
        self._set_held(HELD_RAMP, duration_s=settings["duration_s"], slew=settings["slew"], kp=settings["kp"],
                       ramp_kd=settings["kd"], hold_s=settings["hold_s"])

    def _set_held(self, mode: float, **values: float) -> None:
        held = np.zeros(len(HELD_FIELDS))
        held[0] = self._held[0] + 1.0  # a new generation: the I/O process calls the robot's HeldJoints again
        held[1] = mode
        for name, value in values.items():
            held[HELD_FIELDS.index(name)] = value
        self._held = held

    def _advance(self, dt: float) -> None:
        self._check()
        start = self._read_count
        self._pacer.wait(dt)
        grace = time.monotonic() + 2.0 * self._period
        block = self._blocks.state
        self._drain_bell()  # the rings of states that came meanwhile: the wait below wakes only on a new one
        while block.count == start and not block.failed:
            remaining = grace - time.monotonic()
            if remaining <= 0 or not select.select([self._bell], [], [], remaining)[0]:
                break
            self._drain_bell()
        self._check()

    def wall_time(self) -> float:
        """Now on the monotonic clock both processes share [s] (the `WallClock` capability)."""
        return time.monotonic()

    # -- capabilities ---------------------------------------------------------------------------------------------
    def remote(self) -> Remote | None:
        """The legs' wireless remote as of the newest published state (`RemoteSource`); None without one.

        Raises:
            RobotLinkError: the I/O process failed or died.
        """
        self._check()
        _, record = self._newest()
        if record is None or not record["has_remote"]:
            return None
        return Remote(raw=record["remote"].tobytes())

    @property
    def remote_estops(self) -> int:
        """The legs' link's L2 + B latches as of the newest published state (`RemoteEstopLatch`).

        Raises:
            RobotLinkError: the I/O process failed or died.
        """
        self._check()
        _, record = self._newest()
        return 0 if record is None else int(record["remote_estops"])

    @property
    def remote_estop_latched(self) -> bool:
        """Whether the legs' link damps on its L2 + B latch, as of the newest published state (`RemoteEstopLatch`).

        Raises:
            RobotLinkError: the I/O process failed or died.
        """
        self._check()
        _, record = self._newest()
        return record is not None and bool(record["remote_estop_latched"])

    def release_remote_estop(self) -> bool:
        """Ask the I/O process to release the link's L2 + B latch, with the next command; False while held.

        Raises:
            RobotLinkError: the I/O process failed or died.
        """
        remote = self.remote()
        if remote is not None and remote.l2_b:
            return False
        self._estop_releases += 1
        return True

    @property
    def stale_frames(self) -> int:
        """Valid leg frames the link refused for their tick (`UnitreeRobot.stale_frames`), fetched from the I/O process.

        Not in the state block: a board that repeats its buffer sends no new state that would carry the count.

        Raises:
            RobotNotConnectedError: not connected.
            RobotLinkError: the I/O process failed or died.
        """
        return int(self._ask("stale_frames")["stale_frames"])

    @property
    def deadline_trips(self) -> int:
        """The devices' write-deadline trips as of the newest published state (`WriteDeadlineTrips`).

        Raises:
            RobotLinkError: the I/O process failed or died.
        """
        self._check()
        _, record = self._newest()
        return 0 if record is None else int(record["deadline_trips"])

    def state_ages(self) -> dict[str, float]:
        """By device, how long its state's tick had stood still as of the newest published state (`JoinedDevices`).

        Empty for a robot in the I/O process that does not tell its devices apart (a bare quadruped).

        Raises:
            RobotLinkError: the I/O process failed or died.
        """
        return {device: float(value) for device, value in self._by_device("age").items() if not np.isnan(value)}

    def deadline_trips_by_device(self) -> dict[str, int]:
        """By device, its write-deadline trips as of the newest published state (`JoinedDevices`).

        Raises:
            RobotLinkError: the I/O process failed or died.
        """
        return {device: int(value) for device, value in self._by_device("deadline_trips").items() if value >= 0}

    def _by_device(self, field: str) -> dict[str, object]:
        """Each device's `field` (``legs_<field>``, ``arm_<field>``) in the newest published state; empty before one.

        Raises:
            RobotLinkError: the I/O process failed or died.
        """
        self._check()
        _, record = self._newest()
        if record is None:
            return {}
        return {device: record[f"{device}_{field}"] for device in ("legs", "arm")}

    @property
    def motor_names(self) -> tuple[str, ...]:
        """One name per entry of `motor_status`, as the robot built in the I/O process names them (`MotorNames`)."""
        return self._motor_names

    def motor_status(self) -> JointMotorStatus | None:
        """Modes and temperatures of the legs' motors, then the arm's servos, as of the newest published state.

        None when no device reports a status (`MotorStatusSource`).

        Raises:
            RobotLinkError: the I/O process failed or died.
        """
        self._check()
        _, record = self._newest()
        if record is None or record["status_n"] < 0:
            return None
        n = int(record["status_n"])
        return JointMotorStatus(motor_mode=record["motor_mode"][:n].copy(),
                                motor_temperature=record["motor_temperature"][:n].copy())

    def link_stats(self) -> ProcessLinkStats:
        """The devices' counters, fetched from the I/O process, with this process's pacing (`HasLinkStats`).

        Raises:
            RobotNotConnectedError: not connected.
            RobotLinkError: the I/O process failed or died.
        """
        reply = self._ask("link_stats")["link_stats"]
        pacing = dict(late_advances=self._pacer.late_advances, worst_lateness=self._pacer.worst_lateness)
        legs = LinkStats(**{**reply["legs"], **pacing}) if reply["legs"] is not None else None
        arm = ArmBusStats(**reply["arm"]) if reply["arm"] is not None else None
        threads = {device: DeviceThreadStats(**thread) for device, thread in reply["threads"].items()}
        return ProcessLinkStats(devices=JoinedLinkStats(legs=legs, arm=arm, threads=threads), io=dict(reply["io"]))

    @property
    def faults(self) -> tuple[ArmFault, ...]:
        """The faults the arm's bus latched since `connect`, fetched from the I/O process (`HasLatchedFaults`).

        Raises:
            RobotNotConnectedError: not connected.
            RobotLinkError: the I/O process failed or died.
        """
        return tuple(ArmFault(**{**fault, "ids": tuple(fault["ids"])}) for fault in self._ask("faults")["faults"])

    @property
    def realtime_grant(self) -> RealtimeGrant | None:
        """What the I/O process asked the OS for and got (`HasRealtimeGrant`); None before the first `connect`."""
        return self._grant

    @property
    def pid(self) -> int | None:
        """The I/O process's id while it runs (None before `connect` and after `close`)."""
        return self._proc.pid if self._proc is not None else None

    # -- internals ------------------------------------------------------------------------------------------------
    def _newest(self) -> tuple[int, np.ndarray | None]:
        block = self._blocks.state
        if block.count != self._snapshot[0]:
            self._snapshot = block.read()
        return self._snapshot

    def _drain_bell(self) -> None:
        try:
            gone = not self._bell.recv(4096)
        except (BlockingIOError, InterruptedError):
            gone = False
        except OSError:
            gone = True
        if gone:
            self._check(dead=True)

    def _check(self, *, dead: bool = False) -> None:
        """Raise the I/O process's failure, or a `RobotLinkError` when it is gone; release everything then."""
        if self._failure is not None:
            raise self._failure
        proc, blocks = self._proc, self._blocks
        if proc is None or blocks is None:
            raise RobotLinkError("ProcessRobot: the I/O process is not running")
        if not (dead or blocks.state.failed or proc.poll() is not None):
            return
        failure: WbcError | None = None
        try:
            while failure is None:
                message = self._control.receive(0.5)
                if message is None:
                    break
                if "error" in message:
                    failure = rebuild_error(message, where="ProcessRobot I/O process")
        except ChannelClosed:
            pass
        if failure is None:
            try:
                status = proc.wait(timeout=1.0)
            except subprocess.TimeoutExpired:
                status = None
            failure = RobotLinkError(f"ProcessRobot: the I/O process died (exit status {status}); the robot's "
                                     f"devices are no longer served: {_LEFT_UNKNOWN}")
        elif isinstance(failure, IoProcessStopped) and failure.connected:
            closed = self._await("closed", timeout=5.0)  # the stop closes the robot: said only once it is
            if isinstance(closed, WbcError):
                failure = closed
        self._failure = failure
        self._release()
        raise failure

    def _ask(self, op: str) -> dict:
        """The I/O process's reply to the request `op` (connected only; its error raised here).

        Raises:
            RobotNotConnectedError: not connected.
            RobotLinkError: the I/O process failed or died.
        """
        self._require_connected(op)
        self._check()
        self._control.send({"op": op})
        reply = self._await(op, timeout=5.0)
        if isinstance(reply, WbcError):
            raise reply
        return reply

    def _await(self, key: str, *, timeout: float) -> dict | WbcError:
        """The reply carrying `key`, or the error the I/O process reported first (returned, not raised).

        Awaiting ``closed``, a stop report (`IoProcessStopped`) is passed over: the I/O process is closing the robot,
        as asked, and says ``closed`` next (or its close's error).
        """
        deadline = time.monotonic() + timeout
        try:
            while True:
                message = self._control.receive(max(0.0, deadline - time.monotonic()))
                if message is None:
                    return RobotLinkError(f"ProcessRobot: the I/O process did not answer {key!r} within {timeout} s")
                if "error" in message:
                    error = rebuild_error(message, where="ProcessRobot I/O process")
                    if key == "closed" and isinstance(error, IoProcessStopped):
                        continue
                    return error
                if key in message:
                    return message
        except ChannelClosed:
            return RobotLinkError(f"ProcessRobot: the I/O process exited (status {self._exit_status()}) before "
                                  f"answering {key!r}: {_LEFT_UNKNOWN}")

    def _stop_starting(self) -> None:
        """Send a start-up that is given up (interrupted, timed out, refused) the I/O process's stop signal.

        Stopped before it reaches the robot, it sends it nothing; caught in the robot's connect, it closes the robot
        (damped) as soon as it is connected. Left to run, it connected a robot nobody would drive, then found its
        channel closed and closed it again.
        """
        if self._proc is not None and self._proc.poll() is None:
            self._proc.send_signal(signal.SIGTERM)

    def _exit_status(self) -> int | None:
        if self._proc is None:
            return None
        try:
            return self._proc.wait(timeout=1.0)
        except subprocess.TimeoutExpired:
            return None

    def _release(self) -> None:
        """Stop the I/O process (asked already, or killed after a grace), close the sockets, unmap the memory."""
        if self._control is not None:
            self._control.close()  # end of file for the I/O process: it closes the robot and exits
            self._control = None
        if self._bell is not None:
            self._bell.close()
            self._bell = None
        if self._proc is not None:
            try:
                self._proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
            self._proc = None
        if self._blocks is not None:
            self._blocks.close()
            self._blocks = None
        self._snapshot = (0, None)


def build_process_robot(config: HardwareRobotConfig) -> HardwareRobot:
    """`build_hardware_robot`'s robot with its devices in an I/O process (`ProcessRobot`); nothing started yet.

    Raises:
        TargetRefusedError: a target outside 127.0.0.0/8 without `allow_hardware`, or not an IPv4 literal.
        ConfigError: an invalid rate, or an arm setting out of range.
    """
    built = build_hardware_robot(config)
    return dataclasses.replace(built, robot=ProcessRobot(config), target=f"{built.target}, devices in an I/O process")
