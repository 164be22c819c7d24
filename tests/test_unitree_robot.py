"""UnitreeRobot over the UDP wire against UnitreeEmulator on 127.0.0.1: the contract, standing, and faults on the wire.

Every socket here binds 127.0.0.1 on a port the kernel picks, and every frame goes to 127.0.0.1; every wait is
bounded in time. What the backend sent is read from the emulator's log of decoded command frames.
"""

from __future__ import annotations

import json
import select
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator

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
from wbc.hardware.contract import check_robot
from wbc.hardware.emulators import Fault, UnitreeEmulator, UnitreeEmulatorConfig
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.hardware.robot import KP_MAX
from wbc.hardware.unitree import (
    DESCRIPTIONS,
    MAX_DATAGRAM,
    MODE_SERVO,
    SDK_POSITION_LIMITS,
    SdkTransport,
    Transport,
    UdpTransport,
    UnitreeRobot,
    UnitreeRobotConfig,
    decode_command,
    decode_state,
    encode_command,
    encode_state,
    frame_crc,
    frame_layout,
)
from wbc.types import MotorCommand, RobotState

ROBOTS = ("a1", "go1")
LOOPBACK = "127.0.0.1"


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


def _until(cond: Callable[[], bool], timeout: float = 1.0) -> bool:
    """Poll `cond` every millisecond until it holds or `timeout` passes."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.001)
    return cond()


def _hold(robot: UnitreeRobot, kp: float = 30.0) -> MotorCommand:
    return MotorCommand.hold(robot.desc.nominal_q, kp, 1.0)


def _keep_writing(robot: UnitreeRobot, cmd: MotorCommand, seconds: float) -> None:
    end = time.monotonic() + seconds
    for _ in range(int(seconds / 0.004) + 1):
        if time.monotonic() >= end:
            break
        robot.write(cmd)
        robot.advance(0.004)


# -- contract and standing ----------------------------------------------------------------------------------------
def test_contract(emulator: UnitreeEmulator) -> None:
    check_robot(lambda: UnitreeRobot(_config(emulator)))


def test_contract_over_the_realtime_emulator() -> None:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="realtime")) as emu:
        check_robot(lambda: UnitreeRobot(_config(emu)))


def test_reconnect(emulator: UnitreeEmulator) -> None:
    robot = UnitreeRobot(_config(emulator))
    for _ in range(2):
        with robot:
            tick = robot.read().tick
            _keep_writing(robot, _hold(robot), 0.02)
            assert robot.read().tick > tick
            assert robot.link_stats().frames_sent < 30  # counters start again at each connect


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


def test_stand_over_the_wire_matches_simulation(emulator: UnitreeEmulator, record_property: Callable) -> None:
    seconds = 2.0
    with UnitreeRobot(_config(emulator)) as robot:
        ctrl = StandController(robot.desc)
        for _ in range(int(round(seconds * ctrl.rate_hz))):
            robot.write(ctrl.act(robot.read(), None))
            robot.advance(1.0 / ctrl.rate_hz)
        stats = robot.link_stats()
        wire = float(emulator.base_truth().base_position_in_world[2])  # before close() damps it down
    sim = _stand_height_in_sim(emulator.config.robot, seconds)
    record_property("trunk_height_difference_m", wire - sim)
    record_property("link_period_s", (stats.period_min, stats.period_mean, stats.period_max))
    print(f"\n{emulator.config.robot}: trunk height over the wire {wire:.5f} m, in simulation {sim:.5f} m, "
          f"difference {(wire - sim) * 1e3:+.3f} mm; link period min/mean/max/std {stats.period_min * 1e3:.3f}/"
          f"{stats.period_mean * 1e3:.3f}/{stats.period_max * 1e3:.3f}/{stats.period_std * 1e3:.3f} ms, "
          f"overruns {stats.overruns}, "
          f"late advances {stats.late_advances} (worst {stats.worst_lateness * 1e3:.2f} ms)")
    assert abs(wire - sim) < 0.005
    assert emulator.sim_time > 0.9 * seconds
    assert stats.rejected_states == 0 and stats.deadline_trips == 0
    assert abs(stats.period_mean - 1.0 / 500.0) < 1e-4  # the link keeps its 500 Hz schedule


# -- fault 1: silence ---------------------------------------------------------------------------------------------
def test_silence_stops_the_tick(emulator: UnitreeEmulator) -> None:
    with UnitreeRobot(_config(emulator)) as robot:
        _keep_writing(robot, _hold(robot), 0.05)
        emulator.inject(Fault.SILENCE)
        time.sleep(0.01)  # replies already in flight
        tick = robot.read().tick
        _keep_writing(robot, _hold(robot), 0.06)
        assert robot.read().tick == tick
        assert robot.state_age >= 0.05 and robot.link_stats().state_age >= 0.05
        emulator.clear()
        assert _until(lambda: robot.read().tick > tick)
        assert robot.state_age < 0.05


def test_nothing_but_damping_before_the_first_state(emulator: UnitreeEmulator) -> None:
    emulator.inject(Fault.SILENCE)
    robot = UnitreeRobot(_config(emulator, connect_timeout=0.1))
    with pytest.raises(RobotLinkError, match="no valid LowState"):
        robot.connect()
    sent = emulator.commands()
    assert len(sent) > 10 and all(c.damping for c in sent)
    assert not robot.is_connected


# -- fault 2: corrupt, short, long and foreign datagrams ----------------------------------------------------------
@pytest.mark.parametrize(("fault", "reason"), [(Fault.CORRUPT, "crc"), (Fault.SHORT, "length"),
                                               (Fault.LONG, "length"), (Fault.FOREIGN_PORT, None)])
def test_bad_datagrams_are_rejected_and_counted(emulator: UnitreeEmulator, fault: Fault, reason: str | None) -> None:
    with UnitreeRobot(_config(emulator)) as robot:
        _keep_writing(robot, _hold(robot), 0.04)
        emulator.inject(fault)
        time.sleep(0.01)
        before = robot.read()
        stats_before = robot.link_stats()
        _keep_writing(robot, _hold(robot), 0.05)
        after = robot.read()
        stats = robot.link_stats()
        assert after is before and after.tick == before.tick
        if reason is None:
            assert stats.foreign > stats_before.foreign + 5
            assert stats.rejected_states == stats_before.rejected_states
        else:
            assert getattr(robot.decode_stats, reason) > 5
            assert stats.rejected_states > stats_before.rejected_states + 5
            assert stats.foreign == 0
        emulator.clear()
        assert _until(lambda: robot.read().tick > before.tick)


# -- fault 3: the control loop stalls ----------------------------------------------------------------------------
def test_write_stall_damps_then_resumes(emulator: UnitreeEmulator) -> None:
    config = _config(emulator, write_deadline=0.05)
    period = 1.0 / config.rate_hz
    with UnitreeRobot(config) as robot:
        _keep_writing(robot, _hold(robot, 30.0), 0.05)
        stalled_at = time.monotonic()
        time.sleep(0.15)
        resumed = _hold(robot, 25.0)
        resumed_at = time.monotonic()
        robot.write(resumed)
        time.sleep(0.02)
        robot.write(resumed)
        time.sleep(0.02)
        assert robot.link_stats().deadline_trips == 1
    log = emulator.commands()
    stall = [c for c in log if stalled_at < c.time < resumed_at]
    first_damping = next(c for c in stall if c.damping)
    assert first_damping.time - stalled_at <= config.write_deadline + 10 * period
    assert all(c.wire.kp[0] == 30.0 for c in stall if c.time < first_damping.time)
    assert all(c.damping for c in stall if c.time >= first_damping.time)
    after = [c for c in log if resumed_at < c.time < resumed_at + 0.035]
    assert after and not after[-1].damping
    first_servo = next(c for c in after if not c.damping)
    np.testing.assert_array_equal(first_servo.wire.kp, 25.0)
    np.testing.assert_allclose(first_servo.wire.q, robot.desc.nominal_q.astype(np.float32))
    assert all(not c.damping for c in after if c.time > first_servo.time)
    assert log[-1].damping  # close() left the robot damped


# -- fault 4: NaN and out-of-range commands -----------------------------------------------------------------------
def test_wild_commands_reach_the_wire_clamped(emulator: UnitreeEmulator) -> None:
    with UnitreeRobot(_config(emulator)) as robot:
        lim = robot.limits
        with pytest.raises(CommandError):
            robot.write(MotorCommand.hold(np.full(12, np.nan), 20.0, 1.0))
        wild = MotorCommand(q=lim.upper + 10.0, dq=lim.velocity_limit * 10.0, kp=np.full(12, 1e6),
                            kd=np.full(12, 1e6), tau=-(lim.torque_limit + 100.0))
        sent = robot.write(wild)
        time.sleep(0.02)
        robot.write(_hold(robot))
        time.sleep(0.01)
    log = emulator.commands()
    assert emulator.stats.rejected == 0
    servo = [c.wire for c in log if not c.damping]
    wild_frames = [w for w in servo if w.kp[0] > 100.0]
    assert wild_frames
    w = wild_frames[-1]
    assert (w.mode == MODE_SERVO).all()
    np.testing.assert_array_equal(w.q, lim.upper.astype(np.float32))
    np.testing.assert_allclose(w.q, sent.q, atol=1e-6)
    assert np.all(w.kp <= KP_MAX) and np.all(w.tau >= -lim.torque_limit)
    assert np.all(np.abs(w.dq) <= lim.velocity_limit.astype(np.float32))
    for frame in servo:
        assert np.all(np.isfinite(frame.q)) and np.all(frame.q >= lim.lower.astype(np.float32))
        assert np.all(frame.q <= lim.upper.astype(np.float32))


# -- state faults are reported, close damps -----------------------------------------------------------------------
def test_state_faults_reach_the_backend(emulator: UnitreeEmulator) -> None:
    with UnitreeRobot(_config(emulator)) as robot:
        checks = [
            (Fault.JOINT_OUT_OF_RANGE, (2, 0.5), lambda: robot.read().q[2] == 0.5),
            (Fault.OVER_TEMPERATURE, 95, lambda: (robot.extras.motor_temperature == 95).all()),
            (Fault.MOTOR_ERROR, 0, lambda: (robot.extras.motor_mode == 0).all()),
            (Fault.FALL, np.pi / 2, lambda: abs(robot.extras.imu_rpy[0] - np.pi / 2) < 1e-6),
            (Fault.REMOTE_L2_B, None, lambda: robot.extras.remote.l2_b),
        ]
        for fault, value, seen in checks:
            emulator.inject(fault, value)
            assert _until(lambda seen=seen: (robot.write(_hold(robot)), seen())[1], 0.5), fault
            emulator.clear(fault)
            assert _until(lambda seen=seen: (robot.write(_hold(robot)), not seen())[1], 0.5), fault


def test_close_sends_damping(emulator: UnitreeEmulator) -> None:
    config = _config(emulator, close_damping=0.05)
    robot = UnitreeRobot(config)
    with robot:
        _keep_writing(robot, _hold(robot), 0.03)
        closed_at = time.monotonic()
    tail = [c for c in emulator.commands() if c.time > closed_at]
    first = next(i for i, c in enumerate(tail) if c.damping)
    assert first <= 2  # at most the frames already in flight when close() was called
    assert len(tail) - first >= 10 and all(c.damping for c in tail[first:])
    assert all((c.wire.kd == config.damping_kd).all() for c in tail[first:])


def test_realtime_emulator_streams_states() -> None:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="realtime")) as emu, \
            UnitreeRobot(_config(emu)) as robot:
        tick = robot.read().tick
        _keep_writing(robot, _hold(robot), 0.2)
        assert robot.read().tick > tick + 50
        assert 0.1 < emu.sim_time < 0.5
        assert emu.failure is None


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_delay_and_drop(robot_name: str) -> None:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot=robot_name)) as emu, UnitreeRobot(_config(emu)) as robot:
        _keep_writing(robot, _hold(robot), 0.02)
        emu.inject(Fault.DROP, 0.5)
        tick = robot.read().tick
        sent = robot.link_stats().frames_sent
        _keep_writing(robot, _hold(robot), 0.1)
        fresh, frames = robot.read().tick - tick, robot.link_stats().frames_sent - sent
        assert 0.2 * frames < fresh < 0.8 * frames
        emu.clear()
        emu.inject(Fault.DELAY, 0.04)
        time.sleep(0.01)  # replies sent before the delay are in
        tick = robot.read().tick
        delayed_at = time.monotonic()
        assert _until(lambda: (robot.write(_hold(robot)), robot.read().tick > tick)[1], 0.5)
        assert time.monotonic() - delayed_at >= 0.025
        assert robot.state_age < 0.04


def test_jitter_spreads_and_reorders_the_replies_and_loses_none() -> None:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1")) as emu:
        emu.inject(Fault.JITTER, 0.01)
        client = RawClient(emu)
        try:
            frame = encode_command(emu.layout, MotorCommand.hold(emu.sim.desc.nominal_q, 20.0, 1.0))
            sent: dict[int, float] = {}
            arrivals: list[tuple[int, float]] = []
            end = time.monotonic() + 1.0
            while len(arrivals) < 50 and time.monotonic() < end:
                now = time.monotonic()
                if len(sent) < 50 and now >= len(sent) * 0.002 + (min(sent.values()) if sent else now):
                    client.sock.sendto(frame, emu.address)  # a command every 2 ms, as a 500 Hz link sends
                    sent[len(sent) + 1] = now  # the emulator's k-th step answers with tick k
                if select.select([client.sock], [], [], 0.0005)[0]:
                    data = client.sock.recvfrom(MAX_DATAGRAM)[0]
                    arrivals.append((decode_state(emu.layout, data, time=0.0)[0].tick, time.monotonic()))
        finally:
            client.close()
    ticks = [t for t, _ in arrivals]
    late = [at - sent[t] for t, at in arrivals]
    print(f"\njitter 10 ms: replies late by {min(late) * 1e3:.1f}..{max(late) * 1e3:.1f} ms, "
          f"{sum(b < a for a, b in zip(ticks, ticks[1:], strict=False))} of 49 arrived before an older one")
    assert sorted(ticks) == list(range(1, 51))  # none lost
    assert ticks != sorted(ticks)  # out of order
    assert max(late) - min(late) > 0.004 and max(late) < 0.01 + 0.02


def test_the_link_stays_up_under_jitter() -> None:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1")) as emu, UnitreeRobot(_config(emu)) as robot:
        emu.inject(Fault.JITTER, 0.01)
        _keep_writing(robot, _hold(robot), 0.3)
        stats = robot.link_stats()
        assert stats.deadline_trips == 0 and stats.rejected_states == 0
        assert stats.valid_states > 0.5 * stats.frames_sent and robot.state_age < 0.02
        assert not any(c.damping for c in emu.commands()[-100:])  # the servo frames kept going out


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


def test_transport_is_a_constructor_argument() -> None:
    fake = FakeTransport()
    assert isinstance(fake, Transport)
    robot = UnitreeRobot(UnitreeRobotConfig(robot="go1", target_host=LOOPBACK, target_port=9), transport=fake)
    q = robot.desc.nominal_q
    state = RobotState(tick=7, time=0.0, q=q, dq=np.zeros(12), tau_est=np.zeros(12),
                       imu_quat=np.array([1.0, 0, 0, 0]), gyro_in_body=np.zeros(3),
                       accel_in_body=np.array([0, 0, 9.81]), foot_force=np.zeros(4))
    frame = encode_state(robot.layout, state)
    threading.Timer(0.05, lambda: fake.deliver(frame)).start()
    with robot:
        assert robot.read().tick == 1  # the freshness counter, not the wire's tick
        np.testing.assert_allclose(robot.read().q, q)
        robot.write(_hold(robot))
        time.sleep(0.01)
    wires = [decode_command(robot.layout, f) for f in fake.sent]
    damping = [(w.kp == 0).all() and (w.kd > 0).all() for w in wires]
    assert damping[0] and damping[-1]
    assert any(not d for d in damping)
    assert sum(damping[:20]) >= 20  # before the state arrived (50 ms at 500 Hz), damping only



def test_advance_waits_only_when_nothing_newer_than_the_last_read_has_arrived() -> None:
    """A loop whose work took most of its period goes on at once with the state that arrived meanwhile; only when the
    newest state is the one it already read does `advance` wait (at most two link periods) for another."""
    fake = FakeTransport()
    robot = UnitreeRobot(UnitreeRobotConfig(robot="go1", target_host=LOOPBACK, target_port=9, rate_hz=200.0),
                         transport=fake)
    grace = 2.0 / 200.0  # [s] two link periods
    state = RobotState(tick=7, time=0.0, q=robot.desc.nominal_q, dq=np.zeros(12), tau_est=np.zeros(12),
                       imu_quat=np.array([1.0, 0, 0, 0]), gyro_in_body=np.zeros(3),
                       accel_in_body=np.array([0, 0, 9.81]), foot_force=np.zeros(4))
    fake.deliver(encode_state(robot.layout, state))
    with robot:
        assert robot.read().tick == 1
        fake.deliver(encode_state(robot.layout, state))  # a state arrives while the loop works
        deadline = time.monotonic() + 1.0
        while robot.link_stats().valid_states < 2 and time.monotonic() < deadline:  # until the link has taken it
            time.sleep(0.001)
        start = time.monotonic()
        robot.advance(1e-6)
        went_on = time.monotonic() - start
        assert robot.read().tick == 2
        start = time.monotonic()
        robot.advance(1e-6)  # nothing newer than tick 2 comes: it waits its grace, then returns
        waited = time.monotonic() - start
        assert robot.read().tick == 2
    assert went_on < 0.8 * grace <= waited


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
    time.sleep(0.002)
    recv.append(udp.Recv())
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
    assert result["recv"].count(0) >= 95  # the SDK accepted (almost) every state frame the emulator sent
    assert result["tick"] > 90 and abs(result["q"][1] - nominal[1]) < 0.3
    assert emu.stats.rejected == 0 and emu.stats.accepted == len(log) >= 95
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
    assert ticks == list(range(1, 51))  # one physics step per command


def test_emulator_gives_no_torque_to_what_a_motor_cannot_apply() -> None:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1")) as emu:
        client = RawClient(emu)
        try:
            layout = emu.layout
            frame = bytearray(encode_command(layout, MotorCommand.hold(emu.sim.desc.nominal_q, 40.0, 1.0)))
            kp = layout.cmd_motor_offset + 11  # motor 0's Kp, int16 x 32: the SDK's wrap of Kp 2000 is -48
            struct.pack_into("<h", frame, kp, -48 * 32)
            struct.pack_into("<I", frame, layout.cmd_crc_offset, frame_crc(frame))
            client.exchange(bytes(frame))
            assert emu.refused == 1 and emu.commands()[-1].wire.kp[0] == -48.0
            off = bytearray(encode_command(layout, MotorCommand.hold(emu.sim.desc.nominal_q, 40.0, 1.0)))
            off[layout.cmd_motor_offset] = 0  # motor 0 in mode 0 (off)
            struct.pack_into("<I", off, layout.cmd_crc_offset, frame_crc(off))
            client.exchange(bytes(off))
            assert emu.refused == 1 and emu.commands()[-1].wire.mode[0] == 0
            client.sock.sendto(b"\x00" * 10, emu.address)  # rejected: no reply, no step
            assert _until(lambda: emu.stats.length == 1) and len(emu.commands()) == 2
            assert emu.sim_time == pytest.approx(2 * emu.config.control_period)
        finally:
            client.close()


class BrokenTransport(FakeTransport):
    """A fake whose send fails after a few frames, as a socket whose interface went away."""

    def send(self, frame: bytes) -> None:
        if len(self.sent) >= 40:
            raise OSError("network is unreachable")
        super().send(frame)
        with self.lock:
            self.inbox.append(self.reply)


def test_a_dead_link_thread_is_an_error_in_the_callers_thread() -> None:
    fake = BrokenTransport()
    robot = UnitreeRobot(UnitreeRobotConfig(robot="a1", target_host=LOOPBACK, target_port=9), transport=fake)
    state = RobotState(tick=0, time=0.0, q=robot.desc.nominal_q, dq=np.zeros(12), tau_est=np.zeros(12),
                       imu_quat=np.array([1.0, 0, 0, 0]), gyro_in_body=np.zeros(3),
                       accel_in_body=np.array([0, 0, 9.81]), foot_force=np.zeros(4))
    fake.reply = encode_state(robot.layout, state)
    with robot:
        robot.write(_hold(robot))
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
from wbc.hardware.contract import check_robot
from wbc.hardware.emulators import UnitreeEmulator, UnitreeEmulatorConfig
from wbc.hardware.safety import SafeRobot, SafetyConfig, SafetyState
from wbc.hardware.unitree import (GO1_LAYOUT, Battery, LowStateExtras, Remote, SdkTransport, UnitreeRobot,
                                  UnitreeRobotConfig, encode_command, encode_state)
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
out["readable"] = sdk.wait_readable(1.0)
out["state_equal"] = sdk.receive() == [frame]
corrupt = bytearray(frame)
corrupt[100] ^= 1
robot_side.sendto(bytes(corrupt), sdk.local_address)
time.sleep(0.05)
out["corrupt_received"] = len(sdk.receive())
out["rejected"] = sdk.rejected
cmd = encode_command(GO1_LAYOUT, MotorCommand.hold(np.linspace(-0.5, 0.5, 12), 30.0, 1.5))
sdk.send(cmd)
out["cmd_equal"] = robot_side.recvfrom(2048)[0] == cmd
try:
    SdkTransport(("127.0.0.1", robot_side.getsockname()[1]), ("127.0.0.1", 9))
    out["busy"] = "no error"
except PortBusyError as exc:
    out["busy"] = str(exc)
# 2. the backend over it, against the emulator
with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1")) as emu:
    host, port = emu.address
    config = UnitreeRobotConfig(robot="go1", target_host=host, target_port=port, transport="sdk")
    check_robot(lambda: UnitreeRobot(config))
    events = []
    safe = SafeRobot(UnitreeRobot(config), SafetyConfig(on_event=events.append, ramp_time_s=0.2))
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
    config = UnitreeEmulatorConfig(robot="go1", mode="realtime", held_until_driven=True)
    with UnitreeEmulator(config) as emu:
        with UnitreeRobot(_config(emu)) as robot:
            height = emu.base_truth().base_position_in_world[2]
            time.sleep(0.2)  # the link sends damping frames only (nobody wrote): the robot is held, states flow
            assert emu.held and emu.sim_time == 0.0 and robot.link_stats().valid_states > 20
            assert emu.base_truth().base_position_in_world[2] == height
            _keep_writing(robot, _hold(robot), 0.2)  # the first servo frame releases it
            assert not emu.held and emu.sim_time > 0.1
        emu.reset()  # the link closed (it ended with damping frames): held again
        time.sleep(0.05)
        assert emu.held
