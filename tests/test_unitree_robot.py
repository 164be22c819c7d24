"""UnitreeRobot against UnitreeEmulator: the contract, standing, and faults on the wire.

Most tests run the link and the emulator on a `ManualClock` the test moves, over the emulator's in-process
transport (`UnitreeEmulator.transport`): each link period sends one frame, which the emulator handles and answers
within the same call, so what the link does in which period is the same on any machine at any load. The UDP wire
itself (sockets, the vendor SDK, the link thread) is tested with bounded waits and no timing figure; a transport
wrapper (`AwaitReply`) makes a socket lockstep too, waiting for the reply of each frame it sends. The wall-clock
figures (the link's period, round trips) are printed by ``wbc bench hw`` and checked by the ``realtime`` tests.

Every socket binds 127.0.0.1 on a port the kernel picks, and every frame goes to 127.0.0.1; every wait is
bounded. What the backend sent is read from the emulator's log of decoded command frames.
"""

from __future__ import annotations

import errno
import json
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import pytest

from wbc.control.stand import StandController
from wbc.errors import (
    CommandError,
    ConfigError,
    PortBusyError,
    RobotLinkError,
    TargetRefusedError,
    UnknownNameError,
)
from wbc.hardware.clock import ManualClock
from wbc.hardware.emulators import Fault, UnitreeEmulator, UnitreeEmulatorConfig
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.hardware.robot import COMMAND_ROWS, KP_MAX
from wbc.hardware.robot_contract import check_robot
from wbc.hardware.unitree import DESCRIPTIONS, SdkTransport, Transport, UdpTransport, UnitreeRobot, UnitreeRobotConfig
from wbc.hardware.unitree.command_codec import decode_command, encode_command
from wbc.hardware.unitree.crc import frame_crc
from wbc.hardware.unitree.layout import MODE_SERVO, frame_layout
from wbc.hardware.unitree.robot import SDK_POSITION_LIMITS
from wbc.hardware.unitree.state_codec import decode_state, encode_state
from wbc.hardware.unitree.transport import MAX_DATAGRAM
from wbc.types import MotorCommand, RobotState

ROBOTS = ("a1", "go1")
LOOPBACK = "127.0.0.1"
LINK_PERIOD = 0.002  # [s] the link's default rate, 500 Hz
LOOP = 0.004  # [s] the control loop's period in these tests
TIME_EPS = 1e-9  # [s] float rounding of the clock's sums of periods


@dataclass
class Stepped:
    """An emulated robot in process and the clock it and its links run on."""

    clock: ManualClock
    emu: UnitreeEmulator

    def robot(self, **config: object) -> UnitreeRobot:
        """A link to the emulator over a fresh in-process transport, on the clock."""
        cfg = UnitreeRobotConfig(robot=self.emu.config.robot, target_host=LOOPBACK, target_port=9, **config)
        return UnitreeRobot(cfg, self.emu.transport(self.clock), clock=self.clock)


def _stepped(robot: str = "go1", **emulator: object) -> Stepped:
    return Stepped(ManualClock(), UnitreeEmulator(UnitreeEmulatorConfig(robot=robot, **emulator)))


@pytest.fixture(params=ROBOTS)
def stepped(request: pytest.FixtureRequest) -> Iterator[Stepped]:
    rig = _stepped(request.param)
    yield rig
    rig.emu.close()
    assert rig.clock.pending == 0  # every link's task ended with its close
    assert not [t.name for t in threading.enumerate() if t.name.startswith("unitree-")]  # no thread ever started


@pytest.fixture(params=ROBOTS)
def emulator(request: pytest.FixtureRequest) -> Iterator[UnitreeEmulator]:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot=request.param)) as emu:
        yield emu
        assert emu.failure is None, emu.failure
    assert not [t.name for t in threading.enumerate() if t.name.startswith("unitree-")]  # every thread stopped


def _config(emu: UnitreeEmulator, **kw: object) -> UnitreeRobotConfig:
    host, port = emu.address
    assert host == LOOPBACK
    return UnitreeRobotConfig(robot=emu.config.robot, target_host=host, target_port=port, **kw)


def _until(cond: Callable[[], bool], timeout: float = 5.0) -> bool:
    """Poll `cond` every millisecond until it holds or `timeout` passes (a bound, not a figure under test)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.001)
    return cond()


def _hold(robot: UnitreeRobot, kp: float = 30.0) -> MotorCommand:
    return MotorCommand.hold(robot.desc.nominal_q, kp, 1.0)


def _keep_writing(robot: UnitreeRobot, cmd: MotorCommand, seconds: float) -> None:
    """Write `cmd` and advance LOOP, for `seconds` of the robot's clock."""
    for _ in range(int(round(seconds / LOOP))):
        robot.write(cmd)
        robot.advance(LOOP)


class AwaitReply:
    """A socket transport made lockstep: each `send` waits (up to a bound) until the reply is readable.

    A link on a `ManualClock` over it then receives, in the very period it sent a frame, the state a lockstep
    emulator answered it with, however slow the machine: the sockets are real, the timing is the test's.
    """

    def __init__(self, inner: Transport, timeout: float = 5.0) -> None:
        self.inner, self.timeout = inner, timeout

    @property
    def foreign(self) -> int:
        return self.inner.foreign

    def send(self, frame: bytes) -> None:
        self.inner.send(frame)
        self.inner.wait_readable(self.timeout)

    def receive(self) -> list[bytes]:
        return self.inner.receive()

    def wait_readable(self, timeout: float) -> bool:
        return self.inner.wait_readable(timeout)

    def close(self) -> None:
        self.inner.close()


# -- contract and standing ----------------------------------------------------------------------------------------
def test_contract(stepped: Stepped) -> None:
    check_robot(stepped.robot)


def test_contract_over_udp_on_a_manual_clock(emulator: UnitreeEmulator) -> None:
    """The real sockets (`UdpTransport`) to the emulator's UDP server, the link stepped by the test's clock."""
    clock = ManualClock()
    cfg = _config(emulator)

    def make() -> UnitreeRobot:
        return UnitreeRobot(cfg, AwaitReply(UdpTransport((LOOPBACK, 0), emulator.address)), clock=clock)

    check_robot(make)
    assert emulator.stats.accepted > 0 and emulator.stats.rejected == 0


def test_contract_over_the_realtime_emulator() -> None:
    rig = _stepped("go1", mode="realtime")
    check_robot(rig.robot)
    rig.emu.close()


@pytest.mark.realtime
def test_realtime_contract_over_udp(emulator: UnitreeEmulator) -> None:
    check_robot(lambda: UnitreeRobot(_config(emulator)))


@pytest.mark.realtime
def test_realtime_contract_over_the_realtime_emulator() -> None:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="realtime")) as emu:
        check_robot(lambda: UnitreeRobot(_config(emu)))


def test_the_link_thread_over_udp_connects_streams_and_closes(emulator: UnitreeEmulator) -> None:
    """The default clock: a link thread over a real socket (waits bounded, no figure asserted)."""
    robot = UnitreeRobot(_config(emulator))
    for _ in range(2):
        with robot:
            tick = robot.read().tick
            assert _until(lambda tick=tick: (robot.write(_hold(robot)), robot.advance(LOOP),
                                             robot.read().tick > tick + 2)[2])
            assert robot.link_stats().valid_states > 2
        assert not [t.name for t in threading.enumerate() if t.name.endswith("-link")]  # the link thread ended
    log = emulator.commands()
    assert any(not c.damping for c in log) and log[-1].damping  # it drove the motors, and closed damped


def test_a_connect_interrupted_while_it_waits_gives_back_the_link_and_the_address(
        emulator: UnitreeEmulator, monkeypatch: pytest.MonkeyPatch) -> None:
    """A Ctrl-C while the connect waits for the first state: the link thread ends and the robot's address is free
    again, so that a connect in the same process is not refused as held by another (its own pid)."""
    robot = UnitreeRobot(_config(emulator))
    wait_until = type(robot._link).wait_until

    def interrupted(link: object, *args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(type(robot._link), "wait_until", interrupted)
    with pytest.raises(KeyboardInterrupt):
        robot.connect()
    assert not robot.is_connected
    assert not [t.name for t in threading.enumerate() if t.name.endswith("-link")]  # the link thread ended
    monkeypatch.setattr(type(robot._link), "wait_until", wait_until)
    with UnitreeRobot(_config(emulator)) as again:  # the address is free
        assert again.read() is not None


class _NetworkGone:
    """A socket whose network is down while `down` is set: ``sendto`` fails as Linux fails it (ENETUNREACH)."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock, self.down = sock, False

    def sendto(self, data: bytes, address: tuple[str, int]) -> int:
        if self.down:
            raise OSError(errno.ENETUNREACH, "Network is unreachable")
        return self.sock.sendto(data, address)

    def __getattr__(self, name: str) -> object:
        return getattr(self.sock, name)


def test_a_network_that_goes_away_for_a_while_costs_frames_not_the_link(emulator: UnitreeEmulator) -> None:
    """An unplugged cable drops the frames sent meanwhile; the link keeps its period and is heard again after it."""
    robot = UnitreeRobot(_config(emulator))
    with robot:
        transport = robot._transport
        gone = _NetworkGone(transport._sock)
        transport._sock = gone
        tick = robot.read().tick
        assert _until(lambda: (robot.write(_hold(robot)), robot.advance(LOOP), robot.read().tick > tick + 2)[2])
        gone.down = True
        assert _until(lambda: (robot.write(_hold(robot)), robot.advance(LOOP), robot.link_stats().unsent > 20)[2])
        assert robot.link_failure is None and "unreachable" in transport.last_send_error
        heard = len(emulator.commands())
        gone.down = False
        assert _until(lambda: (robot.write(_hold(robot)), robot.advance(LOOP), len(emulator.commands()) > heard + 5)[2])
        assert robot.link_failure is None
    # any other error of the socket still ends the link: it is not the network coming and going
    bad = UdpTransport((LOOPBACK, 0), (LOOPBACK, 9))
    try:
        bad._sock = _NetworkGone(bad._sock)
        bad._sock.sendto = lambda data, address: (_ for _ in ()).throw(OSError(errno.EINVAL, "Invalid argument"))
        with pytest.raises(OSError, match="Invalid argument"):
            bad.send(b"x")
    finally:
        bad.close()


def test_the_in_process_transport_serves_a_link_thread_too() -> None:
    """The emulator's in-process channel on the monotonic clock: the link's own thread sends, each frame is answered
    within its send (no figure asserted; waits bounded)."""
    emu = UnitreeEmulator(UnitreeEmulatorConfig(robot="go1"))
    transport = emu.transport()
    with UnitreeRobot(UnitreeRobotConfig(robot="go1", target_host=LOOPBACK, target_port=9), transport) as robot:
        tick = robot.read().tick
        assert _until(lambda: (robot.write(_hold(robot)), robot.advance(LOOP), robot.read().tick > tick + 2)[2])
        stats = robot.link_stats()
    assert stats.rejected_states == 0 and stats.valid_states > 2
    assert any(not c.damping for c in emu.commands()) and emu.commands()[-1].damping
    with pytest.raises(ConfigError, match="in process"):
        emu.start()  # one server or the other
    with pytest.raises(ConfigError, match="ManualClock"):
        UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="realtime")).transport()
    emu.close()


def test_reconnect(stepped: Stepped) -> None:
    robot = stepped.robot()
    for _ in range(2):
        with robot:
            tick = robot.read().tick
            sent = robot.link_stats().frames_sent
            _keep_writing(robot, _hold(robot), 0.02)
            assert robot.read().tick > tick
            stats = robot.link_stats()
            assert stats.frames_sent - sent == round(0.02 / LINK_PERIOD)  # a frame per link period
            assert stats.frames_sent < 30  # counters start again at each connect


def test_limits_intersect_urdf_and_sdk() -> None:
    for name in ROBOTS:
        robot = UnitreeRobot(UnitreeRobotConfig(robot=name, target_host=LOOPBACK, target_port=9))
        lower, upper = (np.tile(a, 4) for a in SDK_POSITION_LIMITS[name])
        assert robot.num_joints == 12 and robot.desc.name.startswith(DESCRIPTIONS[name].split("-")[0])
        assert np.all(robot.limits.lower >= lower) and np.all(robot.limits.upper <= upper)
        assert np.all(robot.limits.lower < robot.limits.upper)


def _stand_height_in_sim(robot: str, seconds: float) -> float:
    sim = MujocoRobot(MujocoRobotConfig(robot=DESCRIPTIONS[robot], arm_mode="none"))
    with sim:
        ctrl = StandController(sim.desc)
        for _ in range(int(round(seconds * ctrl.rate_hz))):
            sim.write(ctrl.act(sim.read(), None))
            sim.advance(1.0 / ctrl.rate_hz)
        return float(sim.base_truth().base_position_in_world[2])


def test_stand_over_the_wire_matches_simulation(stepped: Stepped, record_property: Callable) -> None:
    seconds = 2.0
    emulator = stepped.emu
    with stepped.robot() as robot:
        ctrl = StandController(robot.desc)
        for _ in range(int(round(seconds * ctrl.rate_hz))):
            robot.write(ctrl.act(robot.read(), None))
            robot.advance(1.0 / ctrl.rate_hz)
        stats, thread = robot.link_stats(), robot.thread_stats()
        wire = float(emulator.base_truth().base_position_in_world[2])  # before close() damps it down
    sim = _stand_height_in_sim(emulator.config.robot, seconds)
    record_property("trunk_height_difference_m", wire - sim)
    print(f"\n{emulator.config.robot}: trunk height over the wire {wire:.5f} m, in simulation {sim:.5f} m, "
          f"difference {(wire - sim) * 1e3:+.3f} mm")
    assert abs(wire - sim) < 0.005
    assert emulator.sim_time >= seconds
    assert stats.rejected_states == 0 and stats.deadline_trips == 0 and stats.overruns == 0
    # the link keeps its 500 Hz schedule: one frame every period, not one early or late (on its clock)
    assert stats.period_min == pytest.approx(LINK_PERIOD, abs=1e-12)
    assert stats.period_max == pytest.approx(LINK_PERIOD, abs=1e-12)
    assert stats.frames_sent >= seconds / LINK_PERIOD and stats.valid_states == stats.frames_sent
    # the link thread's statistics, which the link's period figures are: every send within its period
    assert thread.cycles == stats.frames_sent and thread.late == thread.overruns == 0
    assert thread.period_p50 == thread.period_p99 == pytest.approx(LINK_PERIOD, abs=1e-12)
    assert (thread.period_mean, thread.period_max) == (stats.period_mean, stats.period_max)


@pytest.mark.realtime
def test_realtime_stand_keeps_the_link_period(emulator: UnitreeEmulator) -> None:
    seconds = 2.0
    with UnitreeRobot(_config(emulator)) as robot:
        ctrl = StandController(robot.desc)
        for _ in range(int(round(seconds * ctrl.rate_hz))):
            robot.write(ctrl.act(robot.read(), None))
            robot.advance(1.0 / ctrl.rate_hz)
        stats = robot.link_stats()
    print(f"\nlink period min/mean/max/std {stats.period_min * 1e3:.3f}/{stats.period_mean * 1e3:.3f}/"
          f"{stats.period_max * 1e3:.3f}/{stats.period_std * 1e3:.3f} ms, overruns {stats.overruns}")
    assert abs(stats.period_mean - LINK_PERIOD) < 1e-4


# -- fault 1: silence ---------------------------------------------------------------------------------------------
def test_silence_stops_the_tick(stepped: Stepped) -> None:
    emulator = stepped.emu
    with stepped.robot() as robot:
        _keep_writing(robot, _hold(robot), 0.05)
        emulator.inject(Fault.SILENCE)
        tick = robot.read().tick
        _keep_writing(robot, _hold(robot), 0.06)
        assert robot.read().tick == tick
        assert robot.state_age >= 0.06 - TIME_EPS and robot.link_stats().state_age >= 0.06 - TIME_EPS
        emulator.clear()
        stepped.clock.advance(LINK_PERIOD)  # the next period's frame is answered
        assert robot.read().tick == tick + 1
        assert robot.state_age < LINK_PERIOD


def test_nothing_but_damping_before_the_first_state(stepped: Stepped) -> None:
    stepped.emu.inject(Fault.SILENCE)
    robot = stepped.robot(connect_timeout=0.1)
    with pytest.raises(RobotLinkError, match="no valid LowState"):
        robot.connect()
    sent = stepped.emu.commands()
    assert len(sent) >= 0.1 / LINK_PERIOD and all(c.damping for c in sent)  # a frame every period of the wait
    assert stepped.clock.now() == pytest.approx(0.1)  # it waited its timeout, on its clock
    assert not robot.is_connected


@pytest.mark.parametrize(("fault", "said"), [
    (Fault.FOREIGN_PORT, r"\(0 rejected; \d+ from another address\); \d+ datagram\(s\) came from another address or "
                         r"port than the target and were dropped unread.*check --target"),
    (Fault.CORRUPT, r"\(\d+ rejected: crc \d+; 0 from another address\); frames came but none was a valid"),
])
def test_a_connect_without_a_state_says_what_did_come(stepped: Stepped, fault: Fault, said: str) -> None:
    stepped.emu.inject(fault)
    robot = stepped.robot(connect_timeout=0.1)
    with pytest.raises(RobotLinkError, match=said):
        robot.connect()


# -- fault 2: corrupt, short, long and foreign datagrams ----------------------------------------------------------
@pytest.mark.parametrize(("fault", "reason"), [(Fault.CORRUPT, "crc"), (Fault.SHORT, "length"),
                                               (Fault.LONG, "length"), (Fault.FOREIGN_PORT, None)])
def test_bad_datagrams_are_rejected_and_counted(stepped: Stepped, fault: Fault, reason: str | None) -> None:
    emulator = stepped.emu
    with stepped.robot() as robot:
        _keep_writing(robot, _hold(robot), 0.04)
        emulator.inject(fault)
        before = robot.read()
        stats_before = robot.link_stats()
        _keep_writing(robot, _hold(robot), 0.05)
        after = robot.read()
        stats = robot.link_stats()
        periods = stats.frames_sent - stats_before.frames_sent
        assert periods >= 0.05 / LINK_PERIOD - 1
        assert after is before and after.tick == before.tick
        if reason is None:
            assert stats.foreign - stats_before.foreign == periods  # every reply came from the wrong port
            assert stats.rejected_states == stats_before.rejected_states
        else:
            assert getattr(robot.decode_stats, reason) == periods  # every reply was rejected, for its reason
            assert stats.rejected_states - stats_before.rejected_states == periods
            assert stats.foreign == 0
        emulator.clear()
        stepped.clock.advance(LINK_PERIOD)
        assert robot.read().tick == before.tick + 1


def test_bad_datagrams_over_udp_are_rejected_and_counted(emulator: UnitreeEmulator) -> None:
    """The socket's own filter: a reply from the emulator's other port is foreign, a corrupt one rejected."""
    clock = ManualClock()
    robot = UnitreeRobot(_config(emulator), AwaitReply(UdpTransport((LOOPBACK, 0), emulator.address)),
                         clock=clock)
    with robot:
        for fault in (Fault.FOREIGN_PORT, Fault.CORRUPT):
            emulator.inject(fault)
            before = robot.link_stats()
            _keep_writing(robot, _hold(robot), 0.02)
            emulator.clear()
            after = robot.link_stats()
            grown = after.foreign - before.foreign if fault is Fault.FOREIGN_PORT else \
                after.rejected_states - before.rejected_states
            assert grown >= 5 and after.valid_states == before.valid_states, fault
        assert _until(lambda: (clock.advance(LINK_PERIOD), robot.read().tick > after.valid_states)[1])


# -- fault 3: the control loop stalls ----------------------------------------------------------------------------
def test_write_stall_damps_then_resumes(stepped: Stepped) -> None:
    emulator, clock = stepped.emu, stepped.clock
    config_deadline = 0.05
    with stepped.robot(write_deadline=config_deadline) as robot:
        _keep_writing(robot, _hold(robot, 30.0), 0.05)
        robot.write(_hold(robot, 30.0))
        stalled_at = clock.now()
        clock.advance(0.15)  # the loop stalls: the link runs on, nobody writes
        resumed = _hold(robot, 25.0)
        resumed_at = clock.now()
        robot.write(resumed)
        clock.advance(0.02)
        robot.write(resumed)
        clock.advance(0.02)
        assert robot.link_stats().deadline_trips == 1
    log = emulator.commands()
    stall = [c for c in log if stalled_at < c.time <= resumed_at + TIME_EPS]
    first_damping = next(c for c in stall if c.damping)
    # damping in the first link period past the deadline, the hold in every one before it
    assert config_deadline < first_damping.time - stalled_at <= config_deadline + LINK_PERIOD + TIME_EPS
    assert all(c.wire.kp[0] == 30.0 for c in stall if c.time < first_damping.time)
    assert all(c.damping for c in stall if c.time >= first_damping.time)
    after = [c for c in log if resumed_at + TIME_EPS < c.time < resumed_at + 0.035]
    assert after and not after[-1].damping
    first_servo = after[0]  # the next frame after the write carries it
    assert not first_servo.damping and first_servo.time <= resumed_at + LINK_PERIOD + TIME_EPS
    np.testing.assert_array_equal(first_servo.wire.kp, 25.0)
    np.testing.assert_allclose(first_servo.wire.q, robot.desc.nominal_q.astype(np.float32))
    assert all(not c.damping for c in after if c.time > first_servo.time)
    assert log[-1].damping  # close() left the robot damped


# -- fault 4: NaN and out-of-range commands -----------------------------------------------------------------------
@pytest.mark.parametrize("row", [2, 3], ids=["kp", "kd"])
def test_a_negative_gain_in_an_unchecked_command_is_refused_never_sent_as_zero(stepped: Stepped, row: int) -> None:
    """A trusted command with a negative gain is refused by name; the wire goes on with the last command accepted,
    then the write deadline's damping: never the joint's gain clamped to 0 at a servo target."""
    with stepped.robot() as robot:
        held = _hold(robot)
        robot.write(held)
        stepped.clock.advance(0.01)
        rows = held.stacked()
        rows[row, 4] = -3.0
        refused_at = stepped.clock.now()
        with pytest.raises(CommandError, match=rf"negative gain at {COMMAND_ROWS[row]}\[{robot.joint_names[4]}\]"):
            robot.write(MotorCommand.trusted(rows))
        stepped.clock.advance(2 * robot.config.write_deadline)
    after = [c for c in stepped.emu.commands() if c.time > refused_at]
    servo = [c.wire for c in after if not c.damping]
    assert servo and all((w.kp == held.kp).all() and (w.kd == held.kd).all() for w in servo)  # the last one accepted
    assert after[-1].damping  # then the write deadline's damping


def test_wild_commands_reach_the_wire_clamped(stepped: Stepped) -> None:
    emulator = stepped.emu
    with stepped.robot() as robot:
        lim = robot.limits
        with pytest.raises(CommandError):
            robot.write(MotorCommand.hold(np.full(12, np.nan), 20.0, 1.0))
        # a command built unchecked (as a compiled controller's) is held to the same rule by the robot's write
        held = _hold(robot).stacked()
        for row, value in ((0, np.nan), (4, np.inf), (3, -np.inf)):
            rows = held.copy()
            rows[row, 5] = value
            where = rf"{COMMAND_ROWS[row]}\[{robot.joint_names[5]}\]"
            with pytest.raises(CommandError, match=rf"non-finite value at {where}; refused"):
                robot.write(MotorCommand.trusted(rows))
        wild = MotorCommand(q=lim.upper + 10.0, dq=lim.velocity_limit * 10.0, kp=np.full(12, 1e6),
                            kd=np.full(12, 1e6), tau=-(lim.torque_limit + 100.0))
        sent = robot.write(wild)
        stepped.clock.advance(0.02)
        robot.write(_hold(robot))
        stepped.clock.advance(0.01)
    log = emulator.commands()
    assert emulator.stats.rejected == 0
    servo = [c.wire for c in log if not c.damping]
    wild_frames = [w for w in servo if w.kp[0] > 100.0]
    assert len(wild_frames) >= 0.02 / LINK_PERIOD - 1
    w = wild_frames[-1]
    assert (w.mode == MODE_SERVO).all()
    np.testing.assert_array_equal(w.q, lim.upper.astype(np.float32))
    np.testing.assert_allclose(w.q, sent.q, atol=1e-6)
    assert np.all(w.kp <= KP_MAX) and np.all(w.tau >= -lim.torque_limit)
    assert np.all(np.abs(w.dq) <= lim.velocity_limit.astype(np.float32))
    for frame in servo:
        assert all(np.all(np.isfinite(getattr(frame, row))) for row in COMMAND_ROWS)
        assert np.all(frame.q >= lim.lower.astype(np.float32)) and np.all(frame.q <= lim.upper.astype(np.float32))


# -- state faults are reported, close damps -----------------------------------------------------------------------
def test_state_faults_reach_the_backend(stepped: Stepped) -> None:
    emulator = stepped.emu
    with stepped.robot() as robot:
        checks = [
            (Fault.JOINT_OUT_OF_RANGE, (2, 0.5), lambda: robot.read().q[2] == 0.5),
            (Fault.OVER_TEMPERATURE, 95, lambda: (robot.extras.motor_temperature == 95).all()),
            (Fault.MOTOR_ERROR, 0, lambda: (robot.extras.motor_mode == 0).all()),
            (Fault.FALL, np.pi / 2, lambda: abs(robot.extras.imu_rpy[0] - np.pi / 2) < 1e-6),
            (Fault.REMOTE_L2_B, None, lambda: robot.extras.remote.l2_b),
        ]
        for fault, value, seen in checks:
            emulator.inject(fault, value)
            assert not seen(), fault
            robot.write(_hold(robot))
            robot.advance(LOOP)  # the next state reports it
            assert seen(), fault
            emulator.clear(fault)
            robot.write(_hold(robot))
            robot.advance(LOOP)
            assert not seen(), fault


def test_close_sends_damping(stepped: Stepped) -> None:
    robot = stepped.robot(close_damping=0.05)
    with robot:
        _keep_writing(robot, _hold(robot), 0.03)
        robot.write(_hold(robot))
        closed_at = stepped.clock.now()
    tail = [c for c in stepped.emu.commands() if c.time > closed_at + TIME_EPS]
    assert tail and all(c.damping for c in tail)  # from the very next frame on
    assert tail[0].time <= closed_at + LINK_PERIOD + TIME_EPS
    assert len(tail) >= 0.05 / LINK_PERIOD - 1  # for the whole close_damping
    assert tail[-1].time < closed_at + 0.05 + TIME_EPS  # and then nothing
    assert all((c.wire.kd == robot.config.damping_kd).all() for c in tail)


def test_realtime_emulator_streams_states() -> None:
    rig = _stepped("go1", mode="realtime")
    with rig.robot() as robot:
        tick, t0 = robot.read().tick, rig.clock.now()
        _keep_writing(robot, _hold(robot), 0.2)
        # a state every emulator period, its physics on the clock: 0.2 s in 0.2 s
        assert robot.read().tick >= tick + 0.2 / LINK_PERIOD - 1
        assert abs(rig.emu.sim_time - rig.clock.now()) <= LINK_PERIOD + TIME_EPS and rig.clock.now() - t0 >= 0.2
    rig.emu.close()


@pytest.mark.realtime
def test_realtime_emulator_streams_states_in_real_time() -> None:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="realtime")) as emu, \
            UnitreeRobot(_config(emu)) as robot:
        tick = robot.read().tick
        _keep_writing(robot, _hold(robot), 0.2)
        assert robot.read().tick > tick + 50
        assert 0.1 < emu.sim_time < 0.5
        assert emu.failure is None


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_delay_and_drop(robot_name: str) -> None:
    rig = _stepped(robot_name)
    emu, clock = rig.emu, rig.clock
    with rig.robot() as robot:
        _keep_writing(robot, _hold(robot), 0.02)
        emu.inject(Fault.DROP, 0.5)
        tick = robot.read().tick
        sent = robot.link_stats().frames_sent
        _keep_writing(robot, _hold(robot), 0.1)
        fresh, frames = robot.read().tick - tick, robot.link_stats().frames_sent - sent
        assert 0.2 * frames < fresh < 0.8 * frames
        emu.clear()
        emu.inject(Fault.DELAY, 0.04)
        tick = robot.read().tick
        delayed_at = clock.now()
        for _ in range(100):
            robot.write(_hold(robot))
            robot.advance(LOOP)
            if robot.read().tick > tick:
                break
        # the first reply to a frame sent after the injection arrives 0.04 s after that frame
        assert clock.now() - delayed_at >= 0.04 + LINK_PERIOD - TIME_EPS
        assert robot.state_age < 0.04
        assert robot.read().tick > tick
    emu.close()


TICK_US = 2000  # the emulator's tick advances by its control period in microseconds per state it sends


def test_jitter_spreads_and_reorders_the_replies_and_loses_none() -> None:
    clock = ManualClock()
    emu = UnitreeEmulator(UnitreeEmulatorConfig(robot="go1"))
    transport = emu.transport(clock)
    emu.inject(Fault.JITTER, 0.01)
    frame = encode_command(emu.layout, MotorCommand.hold(emu.sim.desc.nominal_q, 20.0, 1.0))
    sent: dict[int, float] = {}
    arrivals: list[tuple[int, float]] = []
    poll = 0.0005  # [s] how often the test looks for replies

    def send() -> None:
        if len(sent) < 50:
            tick = len(sent) * TICK_US  # the emulator's clock: its k-th reply carries (k - 1) periods [us]
            transport.send(frame)  # a command every 2 ms, as a 500 Hz link sends
            sent[tick] = clock.now()

    def look() -> None:
        arrivals.extend((decode_state(emu.layout, d, time=0.0)[0].tick, clock.now()) for d in transport.receive())

    clock.call_every(LINK_PERIOD, send)
    clock.call_every(poll, look)
    clock.advance(0.2)
    ticks = [t for t, _ in arrivals]
    late = [at - sent[t] for t, at in arrivals]
    print(f"\njitter 10 ms: replies late by {min(late) * 1e3:.1f}..{max(late) * 1e3:.1f} ms, "
          f"{sum(b < a for a, b in zip(ticks, ticks[1:], strict=False))} of 49 arrived before an older one")
    assert sorted(ticks) == [k * TICK_US for k in range(50)]  # none lost
    assert ticks != sorted(ticks)  # out of order
    assert max(late) - min(late) > 0.004 and max(late) <= 0.01 + poll + TIME_EPS
    assert emu.replies == 50


def test_the_link_stays_up_under_jitter() -> None:
    rig = _stepped("go1")
    with rig.robot() as robot:
        rig.emu.inject(Fault.JITTER, 0.01)
        _keep_writing(robot, _hold(robot), 0.3)
        stats = robot.link_stats()
        assert stats.deadline_trips == 0 and stats.rejected_states == 0
        assert stats.valid_states > 0.5 * stats.frames_sent and robot.state_age < 0.02
        assert not any(c.damping for c in rig.emu.commands()[-100:])  # the servo frames kept going out
    rig.emu.close()


class FakeTransport:
    """A transport with no socket: records what is sent, hands out what a test queues."""

    def __init__(self) -> None:
        self.foreign = 0
        self.sent: list[bytes] = []
        self.inbox: list[bytes] = []
        self.lock = threading.Lock()

    def send(self, frame: bytes) -> None:
        with self.lock:
            self.sent.append(frame)

    def deliver(self, frame: bytes) -> None:
        """Queue a datagram for the link, under the lock: `receive` swaps the list, so an unlocked append that had
        fetched the old list (e.g. while the frame was being encoded) could land in one already handed out."""
        with self.lock:
            self.inbox.append(frame)

    def receive(self) -> list[bytes]:
        with self.lock:
            out, self.inbox = self.inbox, []
        return out

    def wait_readable(self, timeout: float) -> bool:
        time.sleep(min(timeout, 0.002))
        with self.lock:
            return bool(self.inbox)

    def close(self) -> None:
        pass


def _still_state(robot: UnitreeRobot, tick: int = 7) -> bytes:
    state = RobotState(tick=tick, time=0.0, q=robot.desc.nominal_q, dq=np.zeros(12), tau_est=np.zeros(12),
                       imu_quat=np.array([1.0, 0, 0, 0]), gyro_in_body=np.zeros(3),
                       accel_in_body=np.array([0, 0, 9.81]), foot_force=np.zeros(4))
    return encode_state(robot.layout, state)


def test_transport_is_a_constructor_argument() -> None:
    fake = FakeTransport()
    assert isinstance(fake, Transport)
    clock = ManualClock()
    robot = UnitreeRobot(UnitreeRobotConfig(robot="go1", target_host=LOOPBACK, target_port=9), transport=fake,
                         clock=clock)
    frame = _still_state(robot)
    clock.call_at(0.05, lambda: fake.deliver(frame))  # the first state arrives 50 ms after the link starts
    with robot:
        assert clock.now() == pytest.approx(0.05)  # connect waited for it, on its clock
        assert robot.read().tick == 1  # the freshness counter, not the wire's tick
        np.testing.assert_allclose(robot.read().q, robot.desc.nominal_q)
        robot.write(_hold(robot))
        clock.advance(0.01)
    wires = [decode_command(robot.layout, f) for f in fake.sent]
    damping = [(w.kp == 0).all() and (w.kd > 0).all() for w in wires]
    assert damping[0] and damping[-1]
    assert any(not d for d in damping)
    before = round(0.05 / LINK_PERIOD) + 1  # the periods at 0, 2 ms, ... 50 ms: the state came in the last
    assert all(damping[:before])  # before the state arrived, and before the first write: damping only
    assert not damping[before]  # the frame after the write carries it


def test_advance_waits_only_when_nothing_newer_than_the_last_read_has_arrived() -> None:
    """A loop whose work took most of its period goes on at once with the state that arrived meanwhile; only when the
    newest state is the one it already read does `advance` wait (at most two link periods) for another."""
    fake = FakeTransport()
    clock = ManualClock()
    robot = UnitreeRobot(UnitreeRobotConfig(robot="go1", target_host=LOOPBACK, target_port=9, rate_hz=200.0),
                         transport=fake, clock=clock)
    grace = 2.0 / 200.0  # [s] two link periods
    fake.deliver(_still_state(robot))
    with robot:
        assert robot.read().tick == 1
        fake.deliver(_still_state(robot, tick=8))  # a state arrives while the loop works
        clock.advance(1.0 / 200.0)  # the link takes it
        assert robot.link_stats().valid_states == 2
        start = clock.now()
        robot.advance(1e-6)
        went_on = clock.now() - start
        assert robot.read().tick == 2
        start = clock.now()
        robot.advance(1e-6)  # nothing newer than tick 2 comes: it waits its grace, then returns
        waited = clock.now() - start
        assert robot.read().tick == 2
    assert went_on <= 1e-6 + TIME_EPS and grace <= waited <= grace + 1e-6 + TIME_EPS  # its dt alone, or dt + grace


@pytest.mark.parametrize(("ticks", "taken"), [
    ((7, 7, 7), (7,)),  # the very same frame again: a board that keeps sending its last buffer
    ((7, 9, 8), (7, 9)),  # a datagram overtaken by a newer one, or replayed: older than the newest taken
    ((2**32 - 2, 2**32 - 1, 0, 3), (2**32 - 2, 2**32 - 1, 0, 3)),  # the u32 counter wraps: still news
    ((0, 0, 0, 0), (0,)),  # a robot whose tick never moves: nothing after its first frame is news
    ((100, 2**31 + 100, 200), (100, 200)),  # half the counter's range ahead counts as behind
], ids=["repeated", "out_of_order", "wraps", "constant_zero", "half_range"])
def test_a_state_is_taken_only_when_the_robots_tick_advanced(ticks: tuple[int, ...], taken: tuple[int, ...]) -> None:
    """The link's freshness is the robot's own tick moving on: a repeated, replayed or overtaken frame is no news."""
    fake = FakeTransport()
    clock = ManualClock()
    robot = UnitreeRobot(UnitreeRobotConfig(robot="go1", target_host=LOOPBACK, target_port=9), transport=fake,
                         clock=clock)
    fake.deliver(_still_state(robot, tick=ticks[0]))
    seen = []
    with robot:
        seen.append((robot.read().tick, robot.state_age))
        for tick in ticks[1:]:
            fake.deliver(_still_state(robot, tick=tick))
            clock.advance(LINK_PERIOD)  # one datagram per link period
            seen.append((robot.read().tick, robot.state_age))
        assert robot.link_stats().valid_states == len(taken)
        assert robot.stale_frames == len(ticks) - len(taken)
    # the freshness counter moved exactly on the frames taken; on the others the state only aged
    moved = [ticks[0]] + [t for t, (a, b) in zip(ticks[1:], zip(seen, seen[1:], strict=False), strict=True)
                          if b[0] != a[0]]
    assert tuple(moved) == taken


_SDK_CLIENT = '''
import json, socket, sys, time
from unitree_legged_sdk import robot_interface as ri
emu_port, nominal = int(sys.argv[1]), json.loads(sys.argv[2])
probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
probe.bind(("127.0.0.1", 0))
port = probe.getsockname()[1]
probe.close()
udp = ri.UDP(0xFF, port, "127.0.0.1", emu_port)
cmd, state = ri.LowCmd(), ri.LowState()
udp.InitCmdData(cmd)
for i in range(12):
    cmd.motorCmd[i].q = nominal[i]
    cmd.motorCmd[i].dq = 0.0
    cmd.motorCmd[i].Kp = 20.0
    cmd.motorCmd[i].Kd = 1.0
    cmd.motorCmd[i].tau = 0.0
recv = []
for _ in range(100):
    udp.SetSend(cmd)
    udp.Send()
    for _ in range(2500):  # wait for this command's reply (bounded: 5 s), however busy the machine
        time.sleep(0.002)
        result = udp.Recv()
        if result == 0:
            break
    recv.append(result)
    udp.GetRecv(state)
print("RESULT", json.dumps({"recv": recv, "tick": state.tick, "q": [state.motorState[i].q for i in range(12)],
                            "quat": list(state.imu.quaternion)}))
'''
"""The vendor's Go1 SDK 3.8 as a client of the emulator (in a subprocess: the SDK prints, may exit the process, and
never closes its socket). Its socket is connect()ed to 127.0.0.1, so it hears nothing else."""


def test_vendor_sdk_client_talks_to_the_emulator() -> None:
    pytest.importorskip("unitree_legged_sdk")
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1")) as emu:
        nominal = [float(x) for x in emu.sim.desc.nominal_q]
        out = subprocess.run([sys.executable, "-c", _SDK_CLIENT, str(emu.address[1]), json.dumps(nominal)],
                             capture_output=True, text=True, timeout=30, check=False)
        line = next((x for x in out.stdout.splitlines() if x.startswith("RESULT ")), None)
        assert line is not None, (out.returncode, out.stdout[-2000:], out.stderr[-2000:])
        result = json.loads(line.removeprefix("RESULT "))
        log = emu.commands()
    assert result["recv"] == [0] * 100  # the SDK accepted every state frame the emulator sent
    # the 100th state carries the emulator's clock 99 periods on [us]
    assert result["tick"] == 99 * TICK_US and abs(result["q"][1] - nominal[1]) < 0.3
    assert emu.stats.rejected == 0 and emu.stats.accepted == len(log) == 100
    np.testing.assert_array_equal(log[-1].wire.kp, 20.0)
    np.testing.assert_allclose(log[-1].wire.q, np.float32(nominal))


class RawClient:
    """A bare UDP socket on 127.0.0.1 that sends hand-made LowCmd frames to an emulator and waits for each reply."""

    def __init__(self, emu: UnitreeEmulator) -> None:
        self.emu = emu
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((LOOPBACK, 0))
        self.sock.settimeout(1.0)

    def exchange(self, frame: bytes) -> bytes:
        self.sock.sendto(frame, self.emu.address)
        return self.sock.recvfrom(MAX_DATAGRAM)[0]

    def close(self) -> None:
        self.sock.close()


def _raw_run(robot: str, steps: int) -> list[bytes]:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot=robot)) as emu:
        client = RawClient(emu)
        try:
            layout, desc = emu.layout, emu.sim.desc
            replies = []
            for k in range(steps):
                q = desc.nominal_q + 0.1 * np.sin(0.05 * k)
                replies.append(client.exchange(encode_command(layout, MotorCommand.hold(q, 40.0, 1.0))))
            return replies
        finally:
            client.close()


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_lockstep_is_deterministic(robot_name: str) -> None:
    first, second = _raw_run(robot_name, 50), _raw_run(robot_name, 50)
    assert first == second
    layout = frame_layout(robot_name)
    ticks = [decode_state(layout, r, time=0.0)[0].tick for r in first]
    assert ticks == [k * TICK_US for k in range(50)]  # one state per command, the robot's clock a period on each




def _queued_bytes(port: int) -> int:
    """The bytes waiting in the receive queue of the UDP socket bound to 127.0.0.1:`port` (Linux's /proc/net/udp)."""
    with open("/proc/net/udp") as table:
        for line in table.readlines()[1:]:
            local, queues = line.split()[1], line.split()[4]
            if local == f"0100007F:{port:04X}":
                return int(queues.split(":")[1], 16)
    raise AssertionError(f"no UDP socket on 127.0.0.1:{port}")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the kernel's drop count, /proc/net/udp: Linux's")
def test_the_emulator_logs_how_many_frames_its_socket_dropped_before_each() -> None:
    """A starved emulator thread (held here by its own lock, as a busy machine holds it off the CPU) finds its socket's
    buffer full: the kernel drops what does not fit. Each logged frame keeps the count of those dropped before it, so a
    frame's place in what its sender sent is known: a test that reads the wire by the link's own frame count (the I/O
    process's closing test) relied on a log that could silently skip frames."""
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="lockstep", receive_buffer=65536)) as emu:
        def frame(k: int) -> bytes:  # motor 0's position target numbers the frame (a float32 on the wire; Kp is 0)
            q = np.zeros(12)
            q[0] = k * 1e-4
            return encode_command(emu.layout, MotorCommand(q=q, dq=np.zeros(12), kp=np.zeros(12), kd=np.ones(12),
                                                           tau=np.zeros(12)))

        count = 2000  # 1.2 MB: past the buffer asked for, which the kernel doubles
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            sender.sendto(frame(0), emu.address)
            for _ in range(500):  # bounded (5 s): the first frame is taken
                if emu.commands():
                    break
                time.sleep(0.01)
            with emu._lock:  # the thread stops at its next frame, holding it; the rest queue, then overflow
                sender.setblocking(False)
                for k in range(1, count):
                    try:
                        sender.sendto(frame(k), emu.address)
                    except BlockingIOError:  # this side's own buffer full: wait for the kernel to pass it on
                        time.sleep(0.001)
                        sender.setblocking(True)
                        sender.sendto(frame(k), emu.address)
                        sender.setblocking(False)
            for _ in range(3000):  # bounded (30 s): the emulator takes what its socket kept
                if _queued_bytes(emu.address[1]) == 0:
                    break
                time.sleep(0.01)
            sender.setblocking(True)
            sender.sendto(frame(count), emu.address)  # then one more
            for _ in range(3000):  # bounded (30 s)
                log = emu.commands()
                if log and round(log[-1].wire.q[0] * 1e4) == count:
                    break
                time.sleep(0.01)
        log = emu.commands()
        assert emu.failure is None
    numbers = [round(c.wire.q[0] * 1e4) for c in log]
    assert numbers[-1] == count  # the last frame sent was kept: the buffer had room again
    assert emu.dropped > 0 and emu.dropped == log[-1].dropped_before and len(log) + emu.dropped == count + 1
    assert [k + c.dropped_before for k, c in enumerate(log)] == numbers  # each frame's place in what was sent


def test_emulator_gives_no_torque_to_what_a_motor_cannot_apply() -> None:
    clock = ManualClock()
    emu = UnitreeEmulator(UnitreeEmulatorConfig(robot="go1"))
    transport = emu.transport(clock)
    layout = emu.layout
    frame = bytearray(encode_command(layout, MotorCommand.hold(emu.sim.desc.nominal_q, 40.0, 1.0)))
    kp = layout.cmd_motor_offset + 11  # motor 0's Kp, int16 x 32: the SDK's wrap of Kp 2000 is -48
    struct.pack_into("<h", frame, kp, -48 * 32)
    struct.pack_into("<I", frame, layout.cmd_crc_offset, frame_crc(frame))
    transport.send(bytes(frame))
    assert len(transport.receive()) == 1
    assert emu.refused == 1 and emu.commands()[-1].wire.kp[0] == -48.0
    off = bytearray(encode_command(layout, MotorCommand.hold(emu.sim.desc.nominal_q, 40.0, 1.0)))
    off[layout.cmd_motor_offset] = 0  # motor 0 in mode 0 (off)
    struct.pack_into("<I", off, layout.cmd_crc_offset, frame_crc(off))
    transport.send(bytes(off))
    assert len(transport.receive()) == 1
    assert emu.refused == 1 and emu.commands()[-1].wire.mode[0] == 0
    transport.send(b"\x00" * 10)  # rejected: no reply, no step
    assert transport.receive() == []
    assert emu.stats.length == 1 and len(emu.commands()) == 2
    assert emu.sim_time == pytest.approx(2 * emu.config.control_period)
    emu.close()


class BrokenTransport(FakeTransport):
    """A fake whose send fails after a few frames, as a socket whose interface went away."""

    def __init__(self, reply: bytes = b"") -> None:
        super().__init__()
        self.reply = reply

    def send(self, frame: bytes) -> None:
        if len(self.sent) >= 40:
            raise OSError("network is unreachable")
        super().send(frame)
        with self.lock:
            self.inbox.append(self.reply)


@pytest.mark.parametrize("clocked", [False, True], ids=["thread", "manual-clock"])
def test_a_dead_link_is_an_error_in_the_callers_thread(clocked: bool) -> None:
    fake = BrokenTransport()
    clock = ManualClock() if clocked else None
    robot = UnitreeRobot(UnitreeRobotConfig(robot="a1", target_host=LOOPBACK, target_port=9), transport=fake,
                         **({"clock": clock} if clocked else {}))
    fake.reply = _still_state(robot)
    with robot:
        robot.write(_hold(robot))
        if clock is not None:
            clock.advance(1.0)
            assert robot.link_failure is not None and len(fake.sent) == 40  # it died at the 41st send
            assert clock.pending == 0  # the task ended with it
        else:
            assert _until(lambda: robot.link_failure is not None)
        with pytest.raises(RobotLinkError, match="unreachable"):
            robot.read()
        with pytest.raises(RobotLinkError, match="link thread died"):
            robot.write(_hold(robot))
    assert not robot.is_connected


# -- sockets and addresses ----------------------------------------------------------------------------------------
def test_busy_port_is_a_clear_error() -> None:
    first = UdpTransport((LOOPBACK, 0), (LOOPBACK, 9))
    port = first.local_address[1]
    try:
        with pytest.raises(PortBusyError, match=str(port)):
            UdpTransport((LOOPBACK, port), (LOOPBACK, 9))
        robot = UnitreeRobot(UnitreeRobotConfig(target_host=LOOPBACK, target_port=9, local_port=port))
        with pytest.raises(PortBusyError, match=f"{LOOPBACK}:{port}"):
            robot.connect()
        assert not robot.is_connected
    finally:
        first.close()
    again = UdpTransport((LOOPBACK, port), (LOOPBACK, 9))  # close() really released the port
    try:
        with pytest.raises(PortBusyError, match=str(port)):
            UnitreeEmulator(UnitreeEmulatorConfig(port=port)).start()
    finally:
        again.close()
    assert again.closed


def test_non_loopback_target_is_refused() -> None:
    with pytest.raises(TargetRefusedError, match="allow_hardware=True"):
        UnitreeRobotConfig(robot="go1", target_host="192.0.2.10", target_port=8007)
    with pytest.raises(TargetRefusedError, match="IPv4"):
        UnitreeRobotConfig(robot="go1", target_host="localhost", target_port=8007)
    with pytest.raises(TypeError):
        UnitreeRobotConfig(robot="go1")  # type: ignore[call-arg]  # no default robot address
    # allowed explicitly it is accepted (and never connected here)
    assert UnitreeRobotConfig(robot="go1", target_host="192.0.2.10", target_port=8007, allow_hardware=True)
    with pytest.raises(ConfigError, match="127.0.0.0/8"):
        UnitreeEmulatorConfig(host="0.0.0.0")
    with pytest.raises(TargetRefusedError, match="allow_hardware"):
        UdpTransport((LOOPBACK, 0), ("203.0.113.5", 8007))
    with pytest.raises(TargetRefusedError, match="allow_hardware"):
        UdpTransport(("0.0.0.0", 0), (LOOPBACK, 9))


_SDK_TRANSPORT = '''
import json, socket, sys, time
import numpy as np
from wbc.control.stand import stand_command
from wbc.errors import PortBusyError
from wbc.hardware.robot_contract import check_robot
from wbc.hardware.emulators import UnitreeEmulator, UnitreeEmulatorConfig
from wbc.hardware.clock import ManualClock
from wbc.hardware.safety import SafeRobot, SafetyConfig, SafetyState
from wbc.hardware.unitree import (Battery, LowStateExtras, Remote, SdkTransport, UnitreeRobot,
                                  UnitreeRobotConfig)
from wbc.hardware.unitree.command_codec import encode_command
from wbc.hardware.unitree.layout import GO1_LAYOUT
from wbc.hardware.unitree.state_codec import encode_state
from wbc.types import MotorCommand, RobotState
out = {}
# 1. frames both ways, against a bare socket standing in for the robot
robot_side = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
robot_side.bind(("127.0.0.1", 0))
robot_side.settimeout(1.0)
sdk = SdkTransport(("127.0.0.1", 0), robot_side.getsockname())
state = RobotState(tick=123456, time=0.0, q=np.linspace(-1, 1, 12), dq=np.linspace(-3, 3, 12),
                   tau_est=np.linspace(-20, 20, 12), imu_quat=np.array([0.9, 0.1, -0.2, 0.3]),
                   gyro_in_body=np.array([0.1, -0.2, 0.3]), accel_in_body=np.array([0.5, -1.0, 9.7]),
                   foot_force=np.array([10.0, 20.0, 30.0, 40.0]))
extras = LowStateExtras(motor_mode=np.full(12, 10, dtype=np.uint8), motor_temperature=np.arange(30, 42, dtype=np.int8),
                        ddq_counts=np.arange(-600, 600, 100, dtype=np.int16), imu_rpy=np.array([0.01, -0.02, 0.03]),
                        imu_temperature=41, foot_force_est=np.array([1.0, 2.0, 3.0, 4.0]),
                        remote=Remote(raw=bytes(range(40))),
                        battery=Battery(version=(1, 2), status=3, soc=87, current=-1.234, cycle=55, bq_ntc=(25, 26),
                                        mcu_ntc=(27, 28), cell_voltage=np.linspace(3.6, 4.1, 10)))
frame = encode_state(GO1_LAYOUT, state, extras)
robot_side.sendto(frame, sdk.local_address)
out["readable"] = sdk.wait_readable(5.0)
out["state_equal"] = sdk.receive() == [frame]
corrupt = bytearray(frame)
corrupt[100] ^= 1
robot_side.sendto(bytes(corrupt), sdk.local_address)
received = []
for _ in range(500):  # until the SDK has taken the datagram (bounded: 5 s), however busy the machine
    time.sleep(0.01)
    received += sdk.receive()
    if sdk.rejected:
        break
out["corrupt_received"] = len(received)
out["rejected"] = sdk.rejected
cmd = encode_command(GO1_LAYOUT, MotorCommand.hold(np.linspace(-0.5, 0.5, 12), 30.0, 1.5))
sdk.send(cmd)
out["cmd_equal"] = robot_side.recvfrom(2048)[0] == cmd
try:
    SdkTransport(("127.0.0.1", robot_side.getsockname()[1]), ("127.0.0.1", 9))
    out["busy"] = "no error"
except PortBusyError as exc:
    out["busy"] = str(exc)
# 2. the backend over it, against the emulator: on a manual clock, each frame's reply awaited (lockstep over the
# vendor's sockets, however busy the machine)
class AwaitReply:
    def __init__(self, inner):
        self.inner = inner
    foreign = property(lambda self: self.inner.foreign)
    def send(self, frame):
        self.inner.send(frame)
        self.inner.wait_readable(5.0)
    receive = property(lambda self: self.inner.receive)
    wait_readable = property(lambda self: self.inner.wait_readable)
    close = property(lambda self: self.inner.close)
with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1")) as emu:
    host, port = emu.address
    config = UnitreeRobotConfig(robot="go1", target_host=host, target_port=port, transport="sdk")
    clock = ManualClock()
    def make():
        return UnitreeRobot(config, AwaitReply(SdkTransport(("127.0.0.1", 0), (host, port))), clock=clock)
    check_robot(make)
    events = []
    safe = SafeRobot(make(), SafetyConfig(on_event=events.append, ramp_time_s=0.2))
    with safe:
        hold = stand_command(safe.robot.desc)
        for _ in range(300):
            safe.read()
            sent = safe.write(hold)
            safe.advance(0.004)
        out["safety"] = safe.safety_state.value
        out["link_rejected"] = safe.robot.link_stats().rejected_states
        last = emu.commands()[-1].wire
        out["wire_matches_sent"] = bool(np.allclose(last.q, sent.q, atol=1e-6) and np.allclose(last.kp, sent.kp))
        out["height"] = float(emu.base_truth().base_position_in_world[2])
print("RESULT", json.dumps(out))
'''


def test_the_vendor_sdk_as_the_backends_transport() -> None:
    # In a subprocess: the SDK prints, may exit its process, and never closes its sockets.
    pytest.importorskip("unitree_legged_sdk")
    out = subprocess.run([sys.executable, "-c", _SDK_TRANSPORT], capture_output=True, text=True, timeout=120,
                         check=False)
    line = next((x for x in out.stdout.splitlines() if x.startswith("RESULT ")), None)
    assert line is not None, (out.returncode, out.stdout[-2000:], out.stderr[-3000:])
    result = json.loads(line.removeprefix("RESULT "))
    print("\nvendor SDK transport:", result)
    assert result["readable"] and result["state_equal"]  # every field the SDK exposes lands back in its place
    assert result["corrupt_received"] == 0 and result["rejected"] == 1
    assert result["cmd_equal"]  # our frame, byte for byte, CRC included
    assert "the vendor SDK would silently run on another port" in result["busy"]
    assert result["safety"] == "run" and result["link_rejected"] == 0 and result["wire_matches_sent"]
    assert result["height"] > 0.25  # it stood


class _DeafSdk:
    """A stand-in for the SDK module whose UDP binds nothing, as the real one does when its port is taken."""

    class UDP:
        def __init__(self, *args: object) -> None:
            self.args = args

    class LowState:
        pass


def test_an_sdk_that_did_not_bind_its_port_is_a_port_busy_error() -> None:
    with pytest.raises(PortBusyError, match="did not bind"):
        SdkTransport((LOOPBACK, 0), (LOOPBACK, 9), sdk=_DeafSdk)  # type: ignore[arg-type]


def test_the_sdk_transport_is_go1_only_and_loopback_only() -> None:
    with pytest.raises(ConfigError, match="go1"):
        UnitreeRobotConfig(robot="a1", target_host=LOOPBACK, target_port=9, transport="sdk")
    with pytest.raises(UnknownNameError, match="udp"):
        UnitreeRobotConfig(robot="go1", target_host=LOOPBACK, target_port=9, transport="tcp")
    with pytest.raises(TargetRefusedError):
        SdkTransport((LOOPBACK, 0), ("192.0.2.10", 8007), sdk=_DeafSdk)  # type: ignore[arg-type]




def test_an_emulator_holds_its_robot_until_a_command_drives_a_motor() -> None:
    rig = _stepped("go1", mode="realtime", held_until_driven=True)
    emu = rig.emu
    with rig.robot() as robot:
        height = emu.base_truth().base_position_in_world[2]
        rig.clock.advance(0.2)  # the link sends damping frames only (nobody wrote): the robot is held, states flow
        assert emu.held and emu.sim_time == 0.0 and robot.link_stats().valid_states >= 0.2 / LINK_PERIOD
        assert emu.base_truth().base_position_in_world[2] == height
        _keep_writing(robot, _hold(robot), 0.2)  # the first servo frame releases it
        assert not emu.held and emu.sim_time >= 0.2 - LINK_PERIOD - TIME_EPS
    emu.reset()  # the link closed (it ended with damping frames): held again
    rig.clock.advance(0.05)
    assert emu.held and emu.sim_time == 0.0
    emu.close()


def test_a_client_of_another_model_is_told_to_check_the_robot_on_both_sides() -> None:
    # an a1 client against a go1 emulator: the emulator drops every LowCmd by its length and says whose it is; the
    # client, hearing nothing, says a robot of another model ignores its commands
    rig = _stepped("go1")
    cfg = UnitreeRobotConfig(robot="a1", target_host=LOOPBACK, target_port=9, connect_timeout=0.05)
    robot = UnitreeRobot(cfg, rig.emu.transport(rig.clock), clock=rig.clock)
    with pytest.raises(RobotLinkError,
                       match=r"nothing came back at all.*port of --target right.*go1\) ignores an a1's LowCmd"
                             r".*--robot"):
        robot.connect()
    assert rig.emu.stats.length >= 0.05 / LINK_PERIOD and rig.emu.stats.accepted == 0
    assert "610 bytes is an a1 LowCmd, and this side speaks go1; check --robot on both sides" in rig.emu.last_reject
    rig.emu.close()


def test_an_l2_b_press_on_any_frame_of_a_receive_batch_latches_damping() -> None:
    """A press shown on a frame that a newer frame without it follows in the same receive batch (a short press between
    two link periods) latches like one on the newest; a press held across batches counts once."""
    import dataclasses

    from wbc.hardware.unitree.remote import Remote

    fake, clock = FakeTransport(), ManualClock()
    robot = UnitreeRobot(UnitreeRobotConfig(robot="go1", target_host=LOOPBACK, target_port=9), transport=fake,
                         clock=clock)

    def frame(tick: int, l2_b: bool) -> bytes:
        state, extras = decode_state(robot.layout, _still_state(robot, tick=tick), time=0.0)
        if l2_b:
            extras = dataclasses.replace(extras, remote=Remote.build(buttons=("L2", "B")))
        return encode_state(robot.layout, state, extras)

    fake.deliver(frame(7, False))
    with robot:
        seen = []
        for batch in ([(8, True), (9, False)], [(10, True)], [(11, True), (12, True)], [(13, False), (14, False)]):
            for tick, pressed in batch:
                fake.deliver(frame(tick, pressed))
            clock.advance(LINK_PERIOD)
            seen.append((robot.remote_estops, robot.remote_estop_latched))
        assert seen == [(1, True), (2, True), (2, True), (2, True)]
        assert robot.release_remote_estop() and not robot.remote_estop_latched
