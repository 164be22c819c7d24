"""`UnitreeRobot`: an A1 or Go1 (legs only) behind the `Robot` interface, over the low-level UDP wire.

A link thread runs at a fixed rate (500 Hz by default). Every period it takes every queued datagram, decodes each
with `decode_state` (a rejected frame is counted in `decode_stats` and never used) and keeps the newest valid state,
then sends one LowCmd frame:

- damping (Kp 0, Kd `damping_kd`) until the first valid state has arrived and `write` has been called;
- the latest frame `write` encoded, while `write` is called at least every `write_deadline` seconds;
- damping again once that deadline passes, until the next `write` (a stalled control loop leaves the robot
  damped, not holding a stale target: the SDK has no watchdog);
- damping from the first state frame that shows the remote's L2 + B (Unitree's passive), latched until
  `release_remote_estop` (the safety layer's `reset`): the e-stop reaches the wire in the link's next period, not at
  the control loop's next read;
- damping for `close_damping` seconds when the robot is closed, then nothing.

A valid frame is taken only if the robot's own tick (a u32 whose unit is not verified: it serves as a freshness
counter only) is ahead of the newest taken frame's, by 1 to 2**31 - 1 modulo 2**32 (so the counter may wrap): the
very same frame again (a board that keeps sending its last buffer), a replay or a datagram overtaken by a newer one
is counted in `stale_frames` and never taken, so the state goes stale as if the robot were silent. A robot whose
tick never moves (always 0) is stale after its first frame, and a robot that restarts its tick is stale until it
passes the old value: both end in the safety layer's stale trip, which is the safe side. `read` returns the newest
state taken; its `tick` counts the frames taken (a frame whose tick did not advance is stale), and `state_age` says
for how long; `remote()` and `motor_status()` report that state's remote and motor modes and temperatures (the safety
layer's `RemoteSource` and `MotorStatusSource`). `advance(dt)` paces the caller on the link's clock, counts late
calls, and then, unless a state newer than the one the caller last read has already arrived, waits (at most two
link periods) for one: a loop whose work took most of its period goes on at once with the state that came meanwhile,
rather than waiting for yet another (which locked the loop to the state stream's phase and made it late on every
tick over the wire).
Every value that reaches the wire was clamped twice: by `Robot.write` to the joint table (the URDF's position
range intersected with the SDK's PositionLimit table) and by `encode_command` while quantising.

The link is a `DeviceThread` (`wbc.hardware.device_thread`): its cycle is one period's send (the before-send hook,
the frame chosen and sent), and between two sends it takes every datagram as it arrives. Every time the link reads
(the send schedule, the write deadline, a state's age, `wall_time`) comes from its `Clock` (`wbc.hardware.clock`). On
the monotonic clock (the default) the link runs on a thread of its own. Handed a `ManualClock`, it starts no thread:
each link period (the send, then the datagrams received) is a task of that clock, and whoever moves the clock runs
the link: `advance`, `connect`'s wait for the first state and `close`'s damping all move it period by period. Both
modes run the very same period body, so they send the same frames for the same times. `thread_stats()` gives the
link thread's period, busy time, late sends and overruns; `link_stats()` carries its period figures too.
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wbc.errors import ConfigError, FrameError, NoStateStreamError, RobotLinkError, UnknownNameError
from wbc.hardware.clock import MONOTONIC, Clock
from wbc.hardware.device_thread import DeviceThread, DeviceThreadStats
from wbc.hardware.pacing import WallPacer
from wbc.hardware.robot import Robot
from wbc.hardware.unitree.command_codec import encode_command
from wbc.hardware.unitree.decode_stats import REJECT_REASONS, DecodeStats
from wbc.hardware.unitree.layout import LAYOUTS, FrameLayout, frame_layout, with_article
from wbc.hardware.unitree.link_stats import LinkStats
from wbc.hardware.unitree.remote import Remote
from wbc.hardware.unitree.sdk_transport import SDK_ROBOTS, SdkTransport
from wbc.hardware.unitree.state_codec import decode_state
from wbc.hardware.unitree.state_extras import LowStateExtras
from wbc.hardware.unitree.target import announce_hardware_target, check_target
from wbc.hardware.unitree.target_lock import hold_target
from wbc.hardware.unitree.transport import Transport, UdpTransport
from wbc.output_files import DirectoryLock
from wbc.robots.description import RobotDescription
from wbc.robots.joint_table import JointTable, joint_table
from wbc.robots.registry import get_robot
from wbc.types import MotorCommand, RobotState

__all__ = ["DESCRIPTIONS", "LEG_WIRES", "SDK_POSITION_LIMITS", "TRANSPORTS", "UnitreeRobot", "UnitreeRobotConfig",
           "unitree_joint_table"]

TRANSPORTS = ("udp", "sdk")
"""Datagram channels `UnitreeRobotConfig.transport` names: our socket, or the vendor's Go1 SDK."""

DESCRIPTIONS = {"a1": "a1-wx200", "go1": "go1-arm"}
"""Robot name -> registry description whose legs-only variant (arm mode ``none``) the backend drives."""

LEG_WIRES = {description: wire for wire, description in DESCRIPTIONS.items()}
"""Robot with its arm (``a1-wx200``, ``go1-arm``) -> the Unitree wire its legs speak (``a1``, ``go1``)."""

SDK_POSITION_LIMITS = {
    "go1": (np.array([-1.047, -0.663, -2.721]), np.array([1.047, 2.966, -0.837])),
    "a1": (np.array([-0.802, -1.05, -2.7]), np.array([0.802, 4.19, -0.916])),
}
"""The SDK safety class's PositionLimit table (hip, thigh, calf lower and upper [rad]), from the vendors' wheel."""


def unitree_joint_table(robot: str) -> tuple[RobotDescription, JointTable]:
    """The legs-only description of `robot` and its joint table, positions limited to URDF and SDK ranges both.

    Raises:
        UnknownNameError: `robot` is not ``a1`` or ``go1``.
    """
    if robot not in DESCRIPTIONS:
        raise UnknownNameError("Unitree robot", robot, tuple(DESCRIPTIONS))
    desc = get_robot(DESCRIPTIONS[robot], "none")
    table = joint_table(desc)
    lower, upper = (np.tile(a, 4) for a in SDK_POSITION_LIMITS[robot])
    return desc, dataclasses.replace(table, lower=np.maximum(table.lower, lower),
                                     upper=np.minimum(table.upper, upper))


@dataclass(frozen=True, kw_only=True)
class UnitreeRobotConfig:
    """Configuration of a Unitree low-level link.

    Attributes:
        robot: ``a1`` or ``go1``.
        target_host: the robot's (or an emulator's) IPv4 address; there is no default, and an address outside
            127.0.0.0/8 needs `allow_hardware`.
        target_port: its UDP port.
        local_host: the address the link binds.
        local_port: the port it binds; 0 picks a free one.
        allow_hardware: allow a `target_host` outside 127.0.0.0/8 (a real robot).
        rate_hz: link thread rate, 200..1000 [Hz].
        write_deadline: longest gap between two `write` calls before the link damps the motors [s].
        damping_kd: velocity gain of a damping frame [N m s / rad].
        close_damping: how long `close` keeps sending damping frames [s].
        connect_timeout: how long `connect` waits for the first valid state [s].
        transport: the datagram channel `connect` builds when none is handed to the constructor: ``udp`` (our
            socket, `UdpTransport`) or ``sdk`` (the vendor's Go1 SDK, `SdkTransport`; Go1 only).
    """

    robot: str = "go1"
    target_host: str
    target_port: int
    local_host: str = "127.0.0.1"
    local_port: int = 0
    allow_hardware: bool = False
    rate_hz: float = 500.0
    write_deadline: float = 0.05
    damping_kd: float = 3.0
    close_damping: float = 0.1
    connect_timeout: float = 1.0
    transport: str = "udp"

    def __post_init__(self) -> None:
        if self.robot not in DESCRIPTIONS:
            raise UnknownNameError("Unitree robot", self.robot, tuple(DESCRIPTIONS))
        if self.transport not in TRANSPORTS:
            raise UnknownNameError("Unitree transport", self.transport, TRANSPORTS)
        if self.transport == "sdk" and self.robot not in SDK_ROBOTS:
            raise ConfigError(f"UnitreeRobotConfig.transport 'sdk': the vendor SDK speaks the wire of "
                              f"{', '.join(SDK_ROBOTS)} only; use transport='udp' for the {self.robot}")
        check_target(self.target_host, self.target_port, allow_hardware=self.allow_hardware, what="target_host")
        check_target(self.local_host, 1, allow_hardware=self.allow_hardware, what="local_host")
        if not 200.0 <= self.rate_hz <= 1000.0:
            raise ConfigError(f"UnitreeRobotConfig.rate_hz must be in 200..1000 Hz, got {self.rate_hz}")
        for name in ("write_deadline", "close_damping", "connect_timeout"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"UnitreeRobotConfig.{name} must be > 0 s, got {getattr(self, name)}")
        if not 0 < self.damping_kd <= 10:
            raise ConfigError(f"UnitreeRobotConfig.damping_kd must be in (0, 10] N m s/rad, got {self.damping_kd}")
        if self.write_deadline < 2.0 / self.rate_hz:
            raise ConfigError(f"UnitreeRobotConfig.write_deadline {self.write_deadline} s is shorter than two link "
                              f"periods ({2.0 / self.rate_hz} s)")


def _transport_counts(transport: Transport) -> tuple[int, int]:
    """(foreign, unsent): datagrams from another address, frames the network dropped (a fake may count neither)."""
    return int(getattr(transport, "foreign", 0) or 0), int(getattr(transport, "unsent", 0) or 0)


def _no_state_hint(robot: str, stats: DecodeStats, foreign: int = 0) -> str:
    """What to check when no valid LowState came: the frames that did come say which mistake it is.

    Args:
        robot: the robot model the link speaks.
        stats: the frames rejected by reason.
        foreign: datagrams that came from another address or port than the target (dropped unread).
    """
    others = " or ".join(name for name in LAYOUTS if name != robot)
    if foreign and not stats.rejected:
        return (f"{foreign} datagram(s) came from another address or port than the target and were dropped unread: "
                "the robot answers from its own address and port; check --target (the emulator prints it)")
    if stats.length:
        return (f"{stats.length} frame(s) had the wrong length for {with_article(robot)}: a robot of another model "
                f"({others}) answers with frames of its own size; check that --robot names this robot (on the emulator "
                "too)")
    if stats.rejected:
        return "frames came but none was a valid low-level LowState; is the robot in low-level mode?"
    return ("nothing came back at all: is the robot (or emulator) on, in low-level mode, and is the port of --target "
            f"right? A robot of another model ({others}) ignores {with_article(robot)}'s LowCmd, whose length it does "
            "not expect: check that --robot names this robot (on the emulator too)")


class UnitreeRobot(Robot):
    """An A1 or Go1's 12 leg motors over the low-level UDP wire.

    Args:
        config: the link.
        transport: the datagram channel; None builds the one `config.transport` names at `connect` (and closes it
            at `close`). A transport handed in is the caller's to close.
        clock: where the link reads the time; the monotonic clock runs the link on a thread, a `ManualClock` runs
            it as a task on that clock (no thread: the link moves when the clock is moved).
    """

    def __init__(self, config: UnitreeRobotConfig, transport: Transport | None = None, *,
                 clock: Clock = MONOTONIC) -> None:
        super().__init__()
        self.config = config
        self.clock = clock
        self.layout: FrameLayout = frame_layout(config.robot)
        self.desc, self._limits = unitree_joint_table(config.robot)
        self._given_transport = transport
        self._transport: Transport | None = None
        self._target_lock: DirectoryLock | None = None  # held from the connect to the close (`hold_target`)
        self._period = 1.0 / config.rate_hz
        self._damping = encode_command(self.layout, MotorCommand.damping(12, config.damping_kd), limits=self._limits)
        self._lock = threading.Condition()
        self._before_send: Callable[[], None] | None = None
        self._on_state: Callable[[], None] | None = None
        self._reset_link()

    def _reset_link(self) -> None:
        self.decode_stats = DecodeStats()
        self._state: RobotState | None = None
        self._extras: LowStateExtras | None = None
        self._fresh = 0
        self._remote_estops = 0  # L2 + B presses the link saw on a state frame (rising edges)
        self._estop_latched = False  # the link damps until `release_remote_estop`
        self._l2_b_held = False  # L2 + B held on the newest state taken
        self._wire_tick: int | None = None  # the robot's own tick in the newest state taken
        self._read_fresh = 0  # `_fresh` when the caller last read
        self._state_at = -np.inf
        self._frame: bytes | None = None
        self._written_at = -np.inf
        self._tripped = True
        self._closing_until: float | None = None
        self._counts = dict(frames_sent=0, damping_sent=0, deadline_trips=0)
        self._stale_frames = 0
        self._closed_counts = (0, 0)  # the transport's (foreign, unsent) when it was closed: its counts stay readable
        self._link = DeviceThread(f"unitree-{self.config.robot}-link", self._period, self._link_cycle, clock=self.clock,
                                  idle=self._link_idle, condition=self._lock)
        self._pacer = WallPacer(self.clock)
        self._t0 = self.clock.now()

    # -- Robot ----------------------------------------------------------------------------------------------------
    @property
    def joint_names(self) -> tuple[str, ...]:
        """The 12 leg joints, house order (FR, FL, RR, RL x hip, thigh, calf)."""
        return self.desc.joint_names

    @property
    def limits(self) -> JointTable:
        """Motor limits; positions are the intersection of the URDF's and the SDK's PositionLimit ranges."""
        return self._limits

    def _connect(self) -> None:
        cfg = self.config
        self._reset_link()
        if self._given_transport is not None:
            self._transport = self._given_transport
        else:
            # one link to a robot at a time: a second would bind a port of its own and drive it too
            self._target_lock = hold_target(cfg.target_host, cfg.target_port)
            try:
                announce_hardware_target(cfg.target_host, cfg.target_port, cfg.robot)
                channel = SdkTransport if cfg.transport == "sdk" else UdpTransport
                self._transport = channel((cfg.local_host, cfg.local_port), (cfg.target_host, cfg.target_port),
                                          allow_hardware=cfg.allow_hardware)
            except BaseException:
                self._release_target()
                raise
        try:
            self._link.start()
            self._link.wait_until(lambda: self._state is not None, cfg.connect_timeout)
        except BaseException:  # a Ctrl-C while it waits: the link, its socket and the address are given back
            self._shutdown(damp=False)
            raise
        ok = self._state is not None
        if not ok:
            self._shutdown(damp=False)
            foreign = self._closed_counts[0]
            stats = self.decode_stats
            reasons = ", ".join(f"{r} {getattr(stats, r)}" for r in REJECT_REASONS if getattr(stats, r))
            raise NoStateStreamError(
                f"UnitreeRobot({cfg.robot}): no valid LowState from {cfg.target_host}:{cfg.target_port} within "
                f"{cfg.connect_timeout} s ({stats.rejected} rejected{': ' + reasons if reasons else ''}; {foreign} "
                f"from another address); {_no_state_hint(cfg.robot, stats, foreign)}"
            ) from self._link.failure

    def _close(self) -> None:
        self._shutdown(damp=True)

    def _shutdown(self, *, damp: bool) -> None:
        if damp and self._link.failure is None:
            with self._lock:
                self._closing_until = self.clock.now() + self.config.close_damping
            # the close damping goes out as the link runs through it; the period after it ends the link
            self._link.join(timeout=self.config.close_damping + 1.0)
        self._link.stop()
        if self._transport is not None:
            with self._lock:
                self._closed_counts = _transport_counts(self._transport)
        if self._transport is not None and self._given_transport is None:
            self._transport.close()
        self._transport = None
        self._release_target()

    def _release_target(self) -> None:
        """Give back the robot's address (`hold_target`), once nothing of this link can send to it."""
        if self._target_lock is not None:
            lock, self._target_lock = self._target_lock, None
            lock.release()

    def _read(self) -> RobotState:
        self._raise_failure()
        with self._lock:
            state = self._state
            self._read_fresh = self._fresh
        if state is None:
            raise RobotLinkError(f"UnitreeRobot({self.config.robot}): no valid state yet")
        return state

    def _send(self, cmd: MotorCommand) -> None:
        self._raise_failure()
        frame = encode_command(self.layout, cmd, limits=self._limits)
        with self._lock:
            self._frame = frame
            self._written_at = self.clock.now()

    def _advance(self, dt: float) -> None:
        with self._lock:
            start_tick = self._read_fresh
        self._pacer.wait(dt)
        self._link.wait_until(lambda: self._fresh != start_tick, 2.0 * self._period)
        self._raise_failure()

    def wall_time(self) -> float:
        """Now on the link's clock [s] (the `WallClock` capability: the motors live in wall time)."""
        return self.clock.now()

    def set_link_hooks(self, *, before_send: Callable[[], None] | None = None,
                       on_state: Callable[[], None] | None = None) -> None:
        """Functions the link calls every period, for a caller that lives beside the link rather than above it.

        `before_send` runs every period just before the link chooses its frame (a forwarder calls `write` there with
        the newest command, which then goes out in this very period, as a command written in between would);
        `on_state` runs after each new valid state (a publisher calls `read` there). The I/O process
        (`wbc.hardware.io_process`) serves a robot to another process this way, without a thread of its own waking
        twice a period. Both run in the link thread with no lock held: they must be short and must not raise (an
        exception stops the link, as any failure of its thread does). None removes a hook.
        """
        self._before_send = before_send
        self._on_state = on_state

    # -- link-only API --------------------------------------------------------------------------------------------
    @property
    def extras(self) -> LowStateExtras | None:
        """The newest valid state's extras (motor modes, temperatures, remote, battery), None before the first."""
        with self._lock:
            return self._extras

    def remote(self) -> Remote:
        """The wireless remote as of the newest valid state (a `RemoteSource` for the safety layer).

        Raises:
            RobotLinkError: no valid state yet, or the link thread died.
        """
        return self._latest_extras().remote

    def motor_status(self) -> LowStateExtras:
        """Motor modes and temperatures as of the newest valid state (a `MotorStatusSource` for the safety layer).

        Raises:
            RobotLinkError: no valid state yet, or the link thread died.
        """
        return self._latest_extras()

    def _latest_extras(self) -> LowStateExtras:
        self._raise_failure()
        with self._lock:
            extras = self._extras
        if extras is None:
            raise RobotLinkError(f"UnitreeRobot({self.config.robot}): no valid state yet; connect() first")
        return extras

    @property
    def link_failure(self) -> BaseException | None:
        """The exception that stopped the link thread (nothing is sent after it), or None while it runs."""
        return self._link.failure

    @property
    def state_age(self) -> float:
        """Time since the newest valid state arrived [s]; inf before the first."""
        with self._lock:
            return self.clock.now() - self._state_at

    @property
    def remote_estops(self) -> int:
        """Times since `connect` the link saw L2 + B pressed on a state frame and latched damping (`RemoteEstopLatch`).

        The link checks every state frame it takes, so the damping goes out in its next period whatever the control
        loop does; the safety layer learns of it from this count at its next read and trips (``remote_estop``).
        """
        with self._lock:
            return self._remote_estops

    @property
    def remote_estop_latched(self) -> bool:
        """Whether the link damps now on its L2 + B latch (until `release_remote_estop`)."""
        with self._lock:
            return self._estop_latched

    def release_remote_estop(self) -> bool:
        """Release the link's L2 + B latch (the safety layer's `reset` calls it); False, latch kept, while held."""
        with self._lock:
            if self._l2_b_held:
                return False
            self._estop_latched = False
            return True

    @property
    def deadline_trips(self) -> int:
        """Times since `connect` the write deadline expired and the link switched to damping (`WriteDeadlineTrips`)."""
        with self._lock:
            return self._counts["deadline_trips"]

    @property
    def stale_frames(self) -> int:
        """Valid LowState frames not taken since `connect`: the robot's tick had not advanced past the newest taken."""
        with self._lock:
            return self._stale_frames

    def link_stats(self) -> LinkStats:
        """A snapshot of the link's counters; its period figures are the link thread's (`thread_stats`)."""
        thread = self._link.stats()
        with self._lock:
            # once closed, what the transport counted until then: a connect that found no state stream closes it
            # before its caller reads the counts
            foreign, unsent = (_transport_counts(self._transport) if self._transport is not None
                               else self._closed_counts)
            return LinkStats(
                **self._counts, valid_states=self._fresh, rejected_states=self.decode_stats.rejected,
                foreign=foreign, unsent=unsent, state_age=self.clock.now() - self._state_at,
                period_mean=thread.period_mean, period_std=thread.period_std, period_min=thread.period_min,
                period_max=thread.period_max, overruns=thread.late,
                late_advances=self._pacer.late_advances, worst_lateness=self._pacer.worst_lateness,
            )

    def thread_stats(self) -> DeviceThreadStats:
        """The link thread's statistics since `connect`: sends, their period, busy time, late sends, overruns."""
        return self._link.stats()

    def _raise_failure(self) -> None:
        failure = self._link.failure
        if failure is not None:
            raise RobotLinkError(f"UnitreeRobot({self.config.robot}): the link thread died: {failure!r}") from failure

    # -- the link: one period's body, run by the thread or by the clock ------------------------------------------
    def _link_cycle(self) -> bool:
        """The sending half of a period: the before-send hook, the frame chosen and sent; False: the link is done."""
        if self._before_send is not None:
            self._before_send()
        now = self.clock.now()
        with self._lock:
            if self._closing_until is not None and now >= self._closing_until:
                return False
            frame = self._choose_frame(now)
        self._transport.send(frame)
        return True

    def _link_idle(self, until: float) -> None:
        """Between two sends: every datagram as it arrives, until `until` on the link's clock."""
        transport = self._transport
        self._receive(transport)
        wait = until - self.clock.now()
        if wait > 0:
            transport.wait_readable(wait)

    def _choose_frame(self, now: float) -> bytes:
        """The frame to send now (called with the lock held)."""
        counts = self._counts
        counts["frames_sent"] += 1
        quiet = now - self._written_at > self.config.write_deadline
        if quiet and self._frame is not None and not self._tripped:
            counts["deadline_trips"] += 1
        self._tripped = quiet
        if (self._closing_until is not None or self._state is None or self._frame is None or quiet
                or self._estop_latched):
            counts["damping_sent"] += 1
            return self._damping
        return self._frame

    def _receive(self, transport: Transport) -> None:
        newest = None
        # L2 + B pressed on any frame taken in this batch, not only on the newest (a short press between two link
        # periods): a rising edge against the frame before it (only this thread writes `_l2_b_held`)
        pressed, held = False, self._l2_b_held
        for datagram in transport.receive():
            try:
                decoded = decode_state(self.layout, datagram, time=0.0, stats=self.decode_stats)
            except FrameError:
                continue  # counted in decode_stats; the last good state stays
            wire_tick = decoded[0].tick
            last = self._wire_tick if newest is None else newest[0].tick
            if last is not None and not _tick_advanced(last, wire_tick):
                # the robot's own tick did not move on: the same frame again (a board that repeats its buffer),
                # a replay or a datagram overtaken by a newer one; it is no news, and never makes the state fresh
                self._stale_frames += 1
                continue
            newest = decoded
            pressed = pressed or (decoded[1].remote.l2_b and not held)
            held = decoded[1].remote.l2_b
        if newest is None:
            return
        now = self.clock.now()
        state, extras = newest
        with self._lock:
            self._wire_tick = state.tick
            if pressed:  # the e-stop: damping from this period's send on, latched
                self._remote_estops += 1
                self._estop_latched = True
            self._l2_b_held = held  # as the newest frame shows them
            self._fresh += 1
            self._state = dataclasses.replace(state, tick=self._fresh, time=now - self._t0)
            self._extras = extras
            self._state_at = now
            self._lock.notify_all()
        if self._on_state is not None:
            self._on_state()


def _tick_advanced(last: int, tick: int) -> bool:
    """Whether the robot's u32 `tick` is later than `last`: ahead by 1 .. 2**31 - 1, counted modulo 2**32 (a wrap)."""
    return 0 < (tick - last) % 2**32 < 2**31
