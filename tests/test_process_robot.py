"""`ProcessRobot`: the hardware robot with its devices in an I/O process, against the emulators on 127.0.0.1.

The emulators run in this (the controller's) process; the I/O process reaches them as a robot's, over UDP and the
pty. The cases: the `Robot` contract (legs only; legs and arm actuated), a stand through `SafeRobot(ProcessRobot)`,
damping on the wire when this process stops writing (by holding its interpreter lock), the I/O process killed or
signalled (a stop closes the robot into damping, a hangup is left to this process), this process killed (no orphan),
and the refusals and connect failures raised as in-process.

The I/O process runs its devices on the monotonic clock, in real time, by design: what it achieves in real time (a
stand through the safety layer, how soon its link damps a robot whose controller froze) is checked by the
``realtime`` tests here, whose deterministic twins (the same behaviour of the same link on a clock the test moves)
are in tests/test_hardware_faults.py and tests/test_hw_run.py, and printed as figures by ``wbc bench hw``. The tests
of the default suite check what does not depend on the machine's speed.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from wbc.control.stand import StandController
from wbc.errors import IoProcessStopped, NoStateStreamError, PortBusyError, RobotLinkError, TargetRefusedError
from wbc.hardware.capabilities import HeldJoints
from wbc.hardware.dynamixel import DynamixelArm, DynamixelArmConfig
from wbc.hardware.dynamixel.current_law import CurrentLaw
from wbc.hardware.emulators import (
    Fault,
    LoggedCommand,
    LoggedPacket,
    RobotEmulator,
    RobotEmulatorConfig,
    UnitreeEmulator,
    UnitreeEmulatorConfig,
)
from wbc.hardware.hardware_robot import HardwareRobotConfig, build_hardware_robot
from wbc.hardware.io_process import (
    IoBlocks,
    ProcessLinkStats,
    ProcessRobot,
    build_process_robot,
    error_report,
    rebuild_error,
    serve,
)
from wbc.hardware.quadruped_arm_robot import QuadrupedArmConfig
from wbc.hardware.realtime import NO_REALTIME
from wbc.hardware.robot_contract import check_robot
from wbc.hardware.safety import SafeRobot, SafetyConfig, SafetyEvent, SafetyState
from wbc.robots.registry import get_robot
from wbc.types import MotorCommand

ROOT = Path(__file__).resolve().parents[1]
# The arm emulator's servos answer from a thread of this process (tests/test_dynamixel_arm.py), which a busy machine can
# keep from running for longer than the default watchdog (0.1 s), while the I/O process's bus runs at its real-time
# priority: the bus would then find every servo silent, latch the fault and park no joint at its close. A real servo
# is not starved so; no test here is about the watchdog.
ARM = dict(latency_ms=4.0, watchdog_s=1.0)


def _legs(address: tuple[str, int], **extra: object) -> HardwareRobotConfig:
    return HardwareRobotConfig(robot="go1-arm", arm_mode="none", legs_host=address[0], legs_port=address[1], **extra)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as f:  # a zombie (exited, not yet reaped by its parent) is gone too
        return f.read().rsplit(")", 1)[1].split()[0] != "Z"


# The contract's step: a control period in which any machine's I/O process publishes a new state. `advance` waits dt,
# then at most two link periods more for one; with the 2 ms default a busy machine's I/O process was seen not to
# publish within those 6 ms ("tick did not advance"), which says how late it ran, not what the robot does.
CONTRACT_DT = 0.2  # [s]


def test_contract_legs_only() -> None:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="lockstep")) as emu:
        check_robot(lambda: ProcessRobot(_legs(emu.address)), dt=CONTRACT_DT)
        assert emu.failure is None


def test_contract_legs_and_arm_actuated_and_the_same_robot_as_in_process() -> None:
    with RobotEmulator(RobotEmulatorConfig(robot="go1-arm", mode="lockstep")) as emu:
        cfg = HardwareRobotConfig(robot="go1-arm", arm_mode="actuated", legs_host=emu.address[0],
                                  legs_port=emu.address[1], arm=DynamixelArmConfig(port=emu.port, **ARM))
        check_robot(lambda: ProcessRobot(cfg), dt=CONTRACT_DT)
        in_process = build_hardware_robot(cfg).robot
        robot = ProcessRobot(cfg)
        assert robot.joint_names == in_process.joint_names and robot.num_joints == 15
        np.testing.assert_array_equal(robot.limits.upper, in_process.limits.upper)
        with robot:
            robot.advance(0.01)
            status = robot.motor_status()
            assert status is not None and len(status.motor_mode) == 12 + 7  # legs, then the arm's seven servos
            assert robot.remote() is not None and not robot.remote().l2_b
            for _ in range(1000):  # bounded (10 s of ticks): the counters as the I/O process last published them
                stats = robot.link_stats()
                if stats.as_dict()["link/arm_bus/cycles"] > 0 and stats.as_dict()["link/arm_thread/cycles"] > 0:
                    break
                robot.advance(0.01)
            assert isinstance(stats, ProcessLinkStats) and stats.as_dict()["link/arm_bus/cycles"] > 0
            # both devices' loop statistics come across from the I/O process
            assert stats.as_dict()["link/legs_thread/cycles"] > 0 and stats.as_dict()["link/arm_thread/cycles"] > 0
            assert stats.io["states_published"] > 0
            # each device's state age and write-deadline trips come across too, for the safety layer's words
            ages, trips = robot.state_ages(), robot.deadline_trips_by_device()
            assert set(ages) == {"legs", "arm"} and all(age >= 0.0 for age in ages.values())
            assert set(trips) == {"legs", "arm"} and sum(trips.values()) == robot.deadline_trips
            pid = robot.pid
            grant = robot.realtime_grant  # asked by default; granted, or refused with its reason
            assert grant is not None and grant.pid == pid and grant.asked.startswith("SCHED_FIFO 50")
            assert grant.realtime or any(r.startswith("SCHED_FIFO 50: ") for r in grant.refused)
        assert robot.pid is None and not _alive(pid)
        assert emu.failure is None


def _undamped_goals(packets: list[LoggedPacket], law: CurrentLaw, kd: float, ids: tuple[int, ...]) -> list[str]:
    """The writes of goal currents in `packets` that are not the damping law (kp 0, kd `kd`) of a state the bus read.

    The bus loop writes each joint the law of the state its cycle's joint read took, or 0 where that state is older
    than its write deadline (`DynamixelArm`). The law's goals for each joint read come from the values its answers
    carried, through the bus's own `CurrentLaw` (`state`, `torque`, `goal_units`): the same integers through the same
    arithmetic and the same rounding, so a goal matches exactly, whatever the arm's speed. A write is the law of the
    last complete joint read before it, or of an earlier one: a read whose tries all failed leaves the bus its previous
    state, and the late answer to a read that was tried again has the ID and length of the retry's answer, so the bus
    takes it instead and takes each later answer one read behind. It takes answers in the order they were sent, though:
    each write is checked against the reads from the one the write before it matched to the last one logged before it,
    and matches the earliest of them that gives its goals (never one later than the read the bus used).

    Returns:
        One line per write that matches none of those reads: the packet's index, its goals and the law's goals of the
        latest reads it was checked against.
    """
    rows = MotorCommand.damping(len(ids), kd).stacked()
    expected: list[np.ndarray] = []  # the law's goal currents of each complete joint read, in log order
    taken = 0  # the read the latest checked write matched
    bad = []
    for k, packet in enumerate(packets):
        if all(packet.answered("present_velocity", i) for i in ids):
            ticks, velocity, current = (np.array([packet.answered(name, i)[0] for i in ids])
                                        for name in ("present_position", "present_velocity", "present_current"))
            q, dq, _ = law.state(ticks, velocity, current)
            expected.append(law.goal_units(law.torque(rows, q, dq)))
        goals = [(ids.index(w.id), w.value) for w in packet.writes if w.name == "goal_current"]
        if all(value == 0 for _, value in goals):
            continue  # no goal, or the goal of a joint whose state is stale (the start-up's too)
        match = next((j for j in range(taken, len(expected))
                      if all(value in (0, expected[j][n]) for n, value in goals)), None)
        if match is None:
            bad.append(f"packet {k} ({packet.instruction_name}): goal currents {[v for _, v in goals]}; the damping "
                       f"law of the latest reads: {[e.tolist() for e in expected[taken:][-3:]]}")
        else:
            taken = match
    return bad


def test_a_locked_arm_in_the_io_process_obeys_the_safety_layer_on_the_wire() -> None:
    """The layer's damping of a locked arm travels with the command it goes with (waiting, after an e-stop).

    Every goal current the arm's bus receives is the damping law of the velocity the servos reported, or 0: checked
    against the log of what they answered, it holds however fast the arm sinks and however late a busy machine runs
    the bus loop. Started 0.8 rad from its hold, the arm would get the stall current from the hold's kp 20.
    """
    with RobotEmulator(RobotEmulatorConfig(robot="a1-wx200", mode="lockstep")) as emu:
        qpos = emu.plant.sim.data.qpos.copy()
        qpos[-3:] = QuadrupedArmConfig().stowed_q + np.array([0.8, 0.7, -0.7])  # far from its hold
        emu.reset(qpos)
        cfg = HardwareRobotConfig(robot="a1-wx200", arm_mode="locked", legs_host=emu.address[0],
                                  legs_port=emu.address[1], arm=DynamixelArmConfig(port=emu.port, **ARM))
        robot = ProcessRobot(cfg)
        assert isinstance(robot, HeldJoints)
        safety = SafetyConfig(position_table="a1", on_event=lambda event: None)
        safe = SafeRobot(robot, safety)
        # the layer's damping of the locked arm and the bus's own (before the first command, past the write deadline)
        # are one law here: a goal is checked against it whichever of the two sent it
        assert safety.arm_damping_kd == cfg.arm.damping_kd
        law = DynamixelArm(cfg.arm).law  # the bus's law (built, never connected)
        ids = tuple(joint.servo_id for joint in cfg.arm.joints)

        def goal_currents(since: int = 0) -> list[int]:
            return [w.value for p in emu.arm.packets()[since:] for w in p.writes if w.name == "goal_current"]

        with safe:
            start = time.monotonic()
            # waiting: the layer sends damping only; 0.3 s of it, and on until the emulator's thread, however late a
            # busy machine runs it, has logged some of the arm's writes (bounded: 10 s)
            while time.monotonic() < start + 0.3 or (not goal_currents() and time.monotonic() < start + 10.0):
                safe.write(MotorCommand.damping(12, 3.0))
                safe.advance(0.02)
            assert safe.safety_state is SafetyState.WAITING
            assert goal_currents()
            assert _undamped_goals(emu.arm.packets(), law, safety.arm_damping_kd, ids) == []
            safe.estop()
            estop = len(emu.arm.packets())
            for k in range(500):  # 10 ticks, and on until the arm's writes since the e-stop are logged (bounded)
                safe.write(MotorCommand.hold(np.zeros(12), 30.0, 1.0))  # the controller goes on; the layer damps
                safe.advance(0.02)
                if k >= 9 and goal_currents(estop):
                    break
            assert safe.safety_state is SafetyState.DAMPED
            assert goal_currents(estop)
            assert _undamped_goals(emu.arm.packets(), law, safety.arm_damping_kd, ids) == []
        assert emu.failure is None


def test_the_io_process_asks_for_real_time_once_its_slow_start_up_is_done(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every I/O process takes the same CPU at the same priority. Built and connected after the request, one whose
    first compiled call loaded numba there (~0.2-0.5 s of CPU) held off the link of another beside it: a busy machine
    running several saw that link send nothing for ~0.25 s. The request follows the build, the compiled code and
    the heap's freeze, and still precedes the connect, whose threads inherit it."""
    calls: list[str] = []
    config = _legs(("127.0.0.1", 9))
    built = build_hardware_robot(config)
    monkeypatch.setattr(serve, "build_hardware_robot", lambda cfg: calls.append("build") or built)
    monkeypatch.setattr(serve, "load_write_check", lambda: calls.append("compiled code"))
    monkeypatch.setattr(serve, "IoBlocks", lambda n, fd: calls.append(f"blocks of {n} joints on fd {fd}") or "blocks")
    monkeypatch.setattr(serve, "freeze_heap", lambda: calls.append("heap frozen"))
    monkeypatch.setattr(serve, "request_realtime", lambda request: calls.append("real time") or "grant")
    robot, blocks, grant = serve._start_up(config, 7)
    assert calls == ["build", "compiled code", "blocks of 12 joints on fd 7", "heap frozen", "real time"]
    assert robot is built.robot and not robot.is_connected and (blocks, grant) == ("blocks", "grant")


def test_the_io_process_runs_no_blas_thread_pool() -> None:
    """numpy's and scipy's BLAS each start a pool of worker threads, one per further CPU, whose buffers the I/O
    process's locked memory holds too (~40 MB a worker). Started single-threaded, it runs its own two threads only:
    its main thread and the legs' link."""
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="lockstep")) as emu:
        with ProcessRobot(_legs(emu.address)) as robot:
            robot.advance(0.01)
            environ = Path(f"/proc/{robot.pid}/environ").read_bytes().split(b"\0")
            status = dict(line.split(":", 1) for line in Path(f"/proc/{robot.pid}/status").read_text().splitlines())
            assert b"OPENBLAS_NUM_THREADS=1" in environ and b"OMP_NUM_THREADS=1" in environ
            assert int(status["Threads"]) == 2
        assert emu.failure is None


def test_the_io_process_asks_nothing_when_told_so() -> None:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="lockstep")) as emu:
        with ProcessRobot(_legs(emu.address, realtime=NO_REALTIME)) as robot:
            robot.advance(0.01)
            grant = robot.realtime_grant
            assert grant is not None and not grant.realtime and grant.refused == () and not grant.memory_locked
            counters = robot.link_stats().as_dict()  # the legs alone: their link's counters and its thread's
            assert counters["link/legs_thread/cycles"] > 0 and "link/arm_bus/cycles" not in counters
        assert emu.failure is None


@pytest.mark.realtime
def test_stand_through_the_safety_layer_holds() -> None:
    events: list[SafetyEvent] = []
    with RobotEmulator(RobotEmulatorConfig(robot="a1-wx200", mode="realtime")) as emu:
        cfg = HardwareRobotConfig(robot="a1-wx200", arm_mode="actuated", legs_host=emu.address[0],
                                  legs_port=emu.address[1], arm=DynamixelArmConfig(port=emu.port, **ARM))
        safe = SafeRobot(ProcessRobot(cfg), SafetyConfig(position_table="a1", ramp_time_s=0.3,
                                                         on_event=events.append))
        ctrl = StandController(get_robot("a1-wx200", "actuated"))
        with safe:
            end = time.monotonic() + 3.0
            while time.monotonic() < end:
                safe.write(ctrl.act(safe.read(), None))
                safe.advance(1.0 / ctrl.rate_hz)
            assert safe.safety_state is SafetyState.RUN, [str(e) for e in events]
            height = float(emu.base_truth().base_position_in_world[2])
        assert [e.reason for e in events] == ["fresh_state", "ramp_done"]
        assert height > 0.2
        assert emu.failure is None


def _hold_the_interpreter_lock(seconds: float) -> None:
    """Compute in C without releasing the interpreter lock for about `seconds` (a hung C extension)."""
    n = 1_000_000
    t = time.perf_counter()
    sum(range(n))
    per_item = max((time.perf_counter() - t) / n, 1e-9)
    sum(range(int(seconds / per_item)))


def _freeze_this_process(robot: ProcessRobot, emu: UnitreeEmulator) -> tuple[float, list]:
    """Drive the robot, then hold this process's interpreter lock for 0.5 s; (how long it froze, frames since)."""
    hold = MotorCommand.hold(robot.read().q, 20.0, 0.5)
    for _ in range(100):
        robot.write(hold)
        robot.advance(0.004)
    logged = len(emu.commands())  # the emulator's log lags the link by what a busy machine keeps its thread from taking
    t0 = time.perf_counter()
    _hold_the_interpreter_lock(0.5)  # this process, the emulator's threads included, is frozen meanwhile
    frozen = time.perf_counter() - t0
    for _ in range(200):  # the emulator takes the frames queued while it was frozen (bounded: 2 s)
        time.sleep(0.01)
        if any(c.damping for c in emu.commands()[logged:]):
            break
    time.sleep(0.05)
    return frozen, emu.commands()[logged:]


def test_damping_on_the_wire_when_this_process_stops_writing_even_holding_its_lock() -> None:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="lockstep")) as emu:
        with ProcessRobot(_legs(emu.address)) as robot:
            _, frames = _freeze_this_process(robot, emu)
    # The I/O process sent on: the held command, then damping once its write deadline passed, and nothing else. The
    # frames logged since may begin with some that a busy machine kept from the emulator's log, damping among them
    # where it also kept this process past the deadline between two writes: only the hold and damping, damping last.
    assert frames and all(c.damping or (c.wire.kp == 20.0).all() for c in frames) and frames[-1].damping
    # (that the link sent on during the freeze, at its rate, is what the realtime test below measures)


def _until(what: object, tries: int = 1000) -> bool:
    """Poll `what()` every 5 ms until it is true (at most `tries` times): the I/O process runs in its own time."""
    for _ in range(tries):
        if what():
            return True
        time.sleep(0.005)
    return False


def test_the_links_estop_latch_and_deadline_trips_cross_the_io_process() -> None:
    """The link in the I/O process latches damping on L2 + B and counts it; the count reaches this process in the state
    block, and a release goes back with the next command, before it; its write-deadline trips come over too."""
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="lockstep")) as emu:
        with ProcessRobot(_legs(emu.address)) as robot:
            hold = MotorCommand.hold(robot.read().q, 20.0, 0.5)

            def drive() -> None:
                robot.write(hold)
                robot.advance(0.004)

            for _ in range(50):
                drive()
            # a loaded machine may keep this process from writing past the link's 50 ms write deadline (a trip, and
            # damping, the link's own): counted from here on rather than assumed none
            assert robot.remote_estops == 0
            trips = robot.deadline_trips
            emu.inject(Fault.REMOTE_L2_B)
            assert _until(lambda: (drive(), robot.remote_estops == 1)[1]) and robot.remote_estop_latched
            assert _until(lambda: (drive(), emu.commands()[-1].damping)[1])
            emu.clear(Fault.REMOTE_L2_B)
            assert _until(lambda: (drive(), not robot.remote().l2_b)[1])
            latched = len(emu.commands())
            for _ in range(50):  # released buttons, the hold written on: the latch holds
                drive()
            assert all(c.damping for c in emu.commands()[latched:])
            assert robot.release_remote_estop()
            assert _until(lambda: (drive(), not emu.commands()[-1].damping)[1])  # the hold goes out again
            assert _until(lambda: (drive(), not robot.remote_estop_latched)[1])
            assert robot.remote_estops == 1
            before = robot.deadline_trips
            assert before >= trips
            time.sleep(0.15)  # no write for three write deadlines
            assert _until(lambda: robot.deadline_trips > before)


def test_the_whole_robots_estop_latch_reaches_the_layer_and_its_reset_releases_it_through_the_io_process() -> None:
    """The a1-wx200 in the I/O process: a press of L2 + B the layer never sees on the remote trips it on the
    latch count the state block carries, and its reset's release goes back: the legs are driven again, not damped."""
    events: list[SafetyEvent] = []
    with RobotEmulator(RobotEmulatorConfig(robot="a1-wx200", mode="lockstep")) as emu:
        # the stale timeout long: what is tested is the latch, not how late a loaded machine runs this process
        safe = SafeRobot(ProcessRobot(_arm(emu)), SafetyConfig(position_table="a1", on_event=events.append,
                                                               ramp_time_s=0.2, stale_timeout_s=5.0))
        ctrl = StandController(get_robot("a1-wx200", "actuated"))

        def drive() -> None:
            safe.write(ctrl.act(safe.read(), None))
            safe.advance(0.02)

        with safe:
            assert _until(lambda: (drive(), safe.safety_state is SafetyState.RUN)[1])
            emu.inject(Fault.REMOTE_L2_B)  # pressed and released while this process does not read
            assert _until(lambda: safe.robot.remote_estop_latched)
            emu.clear(Fault.REMOTE_L2_B)
            assert _until(lambda: not safe.robot.remote().l2_b)
            drive()
            assert safe.safety_state is SafetyState.DAMPED and events[-1].reason == "remote_estop"
            safe.reset()
            assert _until(lambda: (drive(), safe.safety_state is SafetyState.RUN)[1])
            assert _until(lambda: (drive(), not safe.robot.remote_estop_latched)[1])
            trips = safe.robot.deadline_trips
            since = len(emu.legs.commands())
            for _ in range(20):
                drive()
            frames = emu.legs.commands()[since:]
            # driven, not damped: a damping frame here could only be a write deadline's, which a loaded machine
            # may let pass between two drives, and is then counted
            assert frames and (not any(c.damping for c in frames) or safe.robot.deadline_trips > trips)
            assert not safe.robot.remote_estop_latched
            assert [e.reason for e in events].count("remote_estop") == 1


def test_the_frames_refused_for_their_tick_are_counted_across_the_io_process() -> None:
    """A board that keeps sending its last buffer: the link in the I/O process refuses the frames for their tick, and
    their count reaches this process in the state block (`wbc hw run`'s hardware.json reads it)."""
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="lockstep")) as emu:
        with ProcessRobot(_legs(emu.address)) as robot:
            hold = MotorCommand.hold(robot.read().q, 20.0, 0.5)
            for _ in range(20):
                robot.write(hold)
                robot.advance(0.004)
            assert robot.stale_frames == 0
            emu.inject(Fault.FROZEN_STATE)
            assert _until(lambda: (robot.write(hold), robot.stale_frames > 0)[1])


@pytest.mark.realtime
def test_realtime_damping_when_this_process_holds_its_lock() -> None:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="lockstep")) as emu:
        with ProcessRobot(_legs(emu.address)) as robot:
            frozen, frames = _freeze_this_process(robot, emu)
    first = next((k for k, c in enumerate(frames) if c.damping), None)
    print(f"\nlock held {frozen:.3f} s: {first} held frames, then {len(frames) - first} damping frames")
    assert frozen > 0.25
    assert first is not None and first <= 0.05 * 500 + 15, first
    assert len(frames) - first > 0.5 * (frozen - 0.05) * 500


def test_the_io_process_killed_is_a_link_error_at_the_next_call_and_all_is_released() -> None:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="lockstep")) as emu:
        robot = ProcessRobot(_legs(emu.address))
        robot.connect()
        hold = MotorCommand.hold(robot.read().q, 20.0, 0.5)
        pid = robot.pid
        os.kill(pid, signal.SIGKILL)
        # killed, it could not damp the robot, and the controller is told so
        with pytest.raises(RobotLinkError, match="I/O process died .* the legs may keep their last command"):
            for _ in range(500):
                robot.read()
                robot.write(hold)
                robot.advance(0.002)
        assert not _alive(pid) and robot.pid is None
        with pytest.raises(RobotLinkError):
            robot.read()  # the same failure again, until closed
        robot.close()
        assert not robot.is_connected


def _arm(emu: RobotEmulator, **extra: object) -> HardwareRobotConfig:
    return HardwareRobotConfig(robot="a1-wx200", arm_mode="actuated", legs_host=emu.address[0],
                               legs_port=emu.address[1], arm=DynamixelArmConfig(port=emu.port, **ARM), **extra)


def _drive(robot: ProcessRobot, hold: MotorCommand, ticks: int) -> None:
    for _ in range(ticks):
        robot.read()
        robot.write(hold)
        robot.advance(0.004)


def _parked(emu: RobotEmulator) -> bool:
    """Every joint of the arm parked (`DynamixelArm` closed): held in current-based position mode, watchdog off."""
    return all(emu.arm.register(i, "operating_mode") == 5 and emu.arm.register(i, "torque_enable") == 1
               and emu.arm.register(i, "bus_watchdog") == 0 for i in (1, 2, 4))


def _ends_damped(emu: UnitreeEmulator, sent: int) -> None:
    """The legs end damped: once the emulator has taken every frame the link sent, the last since `sent` is damping.

    Called once the I/O process has ended: a datagram sent to the emulator now arrives after all of the link's, so
    its rejection (`last_reject`) says that the emulator has taken them, however late a busy machine ran its thread.
    Damping before a later frame of another command is a busy machine's: one that kept the test's process past the
    link's 50 ms write deadline between two of its writes had the legs damped meanwhile, as it should.
    """
    emu.last_reject = ""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as marker:
        marker.sendto(b"the end of the link's frames", emu.address)
    for _ in range(1000):  # bounded (10 s)
        if emu.last_reject:
            break
        time.sleep(0.01)
    assert emu.last_reject, "the emulator did not take the marker sent after the link's frames"
    frames = emu.commands()[sent:]
    assert frames and frames[-1].damping, [f"kp {c.wire.kp.max():g}" for c in frames[-5:]]


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGQUIT])
def test_a_stop_signal_to_the_io_process_closes_the_robot_into_damping(signum: int) -> None:
    """SIGTERM or SIGQUIT to the I/O process (a service manager's stop, ``kill``, Ctrl-\\ at the terminal): it closes
    the robot as on close, the legs damped and the arm parked, says why at the controller's next call and exits. It
    used to die at once, leaving the legs holding the last command (kp 20 here) and the arm unparked."""
    with RobotEmulator(RobotEmulatorConfig(robot="a1-wx200", mode="lockstep")) as emu:
        robot = ProcessRobot(_arm(emu))
        robot.connect()
        try:
            hold = MotorCommand.hold(robot.read().q, 20.0, 0.5)
            _drive(robot, hold, 50)
            # the legs hold the command when the signal comes: driven on (bounded: 10 s of ticks) while a busy machine
            # keeps the emulator's log behind the link, or held this process off for the link's 50 ms write deadline
            for _ in range(100):
                if not emu.legs.commands()[-1].damping:
                    break
                _drive(robot, hold, 25)
            assert not emu.legs.commands()[-1].damping and not _parked(emu)
            sent, pid = len(emu.legs.commands()), robot.pid
            os.kill(pid, signum)
            with pytest.raises(IoProcessStopped, match=f"by {signal.Signals(signum).name}: it closes the robot"):
                _drive(robot, hold, 2500)  # bounded (10 s of ticks): until the controller hears of it
            for _ in range(500):  # bounded (5 s)
                if not _alive(pid):
                    break
                time.sleep(0.01)
            assert not _alive(pid) and robot.pid is None
        finally:
            robot.close()
        _ends_damped(emu.legs, sent)
        assert _parked(emu)
        assert emu.failure is None


def test_a_close_that_meets_a_stop_signal_closes_without_an_error() -> None:
    """SIGTERM to the whole command reaches its I/O process as the command closes the robot: the I/O process's report
    of the stop comes first, then its ``closed``. The close does not raise (the robot is closed into damping, as
    asked); it raised the stop report, which ended the command with status 2 instead of 130."""
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="lockstep")) as emu:
        robot = ProcessRobot(_legs(emu.address))
        robot.connect()
        hold = MotorCommand.hold(robot.read().q, 20.0, 0.5)
        _drive(robot, hold, 20)
        sent, pid = len(emu.commands()), robot.pid
        os.kill(pid, signal.SIGTERM)
        for _ in range(1000):  # bounded (10 s): until it has closed the robot and said so, then exited
            if not _alive(pid):
                break
            time.sleep(0.01)
        assert not _alive(pid)
        robot.close()  # its stop report, then `closed`, wait on the channel: the close reads both
        assert not robot.is_connected and robot.pid is None
        _ends_damped(emu, sent)
        assert emu.failure is None


def test_closing_through_the_safety_layer_damps_the_legs_at_once_then_parks_the_arm() -> None:
    """The safety layer's close posts damping, then asks the I/O process to close: the legs' link takes that damping
    in its next period, then the arm's close (its damping, then its park) runs. The shutdown stopped the forwarding
    first, dropping the damping, and closed the arm first: the legs held their command until their write deadline, 25
    frames at 500 Hz, no sooner than had the I/O process been killed."""
    with RobotEmulator(RobotEmulatorConfig(robot="a1-wx200", mode="lockstep")) as emu:
        # the layer's clock is the wall clock: a stale timeout and a ramp that only a hung machine outlasts keep it
        # ramping through the 50 ticks however slowly a busy machine runs them (the default 0.1 s tripped it)
        safety = SafetyConfig(position_table="a1", on_event=lambda event: None, stale_timeout_s=30.0,
                              ramp_time_s=30.0)
        io_robot = ProcessRobot(_arm(emu))
        safe = SafeRobot(io_robot, safety)
        posted: list[int] = []
        closing = False
        write = io_robot.write

        def counted(cmd: MotorCommand) -> MotorCommand:
            sent = write(cmd)
            if closing and not cmd.kp.any():  # the layer's damping as it closes: the frames the link had sent by then
                posted.append(int(io_robot.link_stats().as_dict()["link/frames_sent"]))
            return sent

        io_robot.write = counted
        with safe:
            hold = MotorCommand.hold(safe.read().q, 20.0, 0.5)
            for _ in range(50):  # the layer ramps the robot towards the hold: frames with kp > 0
                safe.read()
                safe.write(hold)
                safe.advance(0.004)
            assert safe.safety_state is SafetyState.RAMP
            closing = True
        # the frames the link has sent, as the link counts them (the emulator's log of them lags behind by as many as a
        # busy machine keeps its thread from taking): those since the damping was posted. A frame's number in the
        # link's count is its place in the log plus the frames the emulator's socket dropped before it, its buffer
        # full (a machine that starves the emulator's thread for long), which the log keeps.
        sent = posted[0]

        def numbered() -> list[tuple[int, LoggedCommand]]:
            return [(k + c.dropped_before - sent, c) for k, c in enumerate(emu.legs.commands())
                    if k + c.dropped_before >= sent]

        for _ in range(1000):  # bounded (10 s): until the emulator has taken what the I/O process sent
            if any(c.damping for _, c in numbered()):
                break
            time.sleep(0.01)
        frames = numbered()
        assert emu.failure is None
    held = next((k for k, c in frames if c.damping), None)
    # The link forwards the newest command posted before each send, so the damping goes out in the period after it was
    # posted: at most the one frame being sent as it was counted comes before. 5 frames is well short of the 25 of the
    # write deadline, and is counted from the post, on the link's own count: what is bounded is the link's forwarding,
    # not this machine's speed. (That the legs close before the arm is the robot's own order: test_quadruped_arm_robot.)
    assert held is not None and held <= 5, held
    assert all(c.damping for k, c in frames if k >= held)
    assert _parked(emu)


def test_a_hangup_leaves_the_io_process_to_its_controller() -> None:
    """SIGHUP to the I/O process (its terminal closed) is ignored: the controller's process decides, and its close
    then damps the robot. It used to kill the I/O process, the legs holding their last command."""
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="lockstep")) as emu:
        with ProcessRobot(_legs(emu.address)) as robot:
            hold = MotorCommand.hold(robot.read().q, 20.0, 0.5)
            _drive(robot, hold, 20)
            os.kill(robot.pid, signal.SIGHUP)
            sent = len(emu.commands())
            _drive(robot, hold, 50)  # served on, as if nothing came
            pid = robot.pid
            assert _alive(pid)
            # the hold goes on reaching the wire (a busy machine that keeps this process past the link's write deadline
            # between two writes has the legs damped meanwhile, as it should; the next write ends that)
            last = len(emu.commands())
            robot.write(hold)
            robot.advance(0.004)
            for _ in range(1000):  # bounded (10 s): until the emulator has taken a frame of the hold sent since
                if any(not c.damping and (c.wire.kp == 20.0).all() for c in emu.commands()[last:]):
                    break
                time.sleep(0.01)
            assert any(not c.damping and (c.wire.kp == 20.0).all() for c in emu.commands()[last:])
        assert not _alive(pid)
        _ends_damped(emu, sent)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGHUP, signal.SIGTERM])
def test_a_signal_during_the_io_processs_start_up_waits_for_it(signum: int, capfd: pytest.CaptureFixture[str]) -> None:
    """A signal sent as soon as the I/O process exists (during its interpreter's start-up and its imports) is taken as
    it is later: a Ctrl-C or a hangup is ignored, a SIGTERM stops it in order, said at the controller's `connect`. A
    Ctrl-C then ended it with a traceback, and a SIGTERM without a word (status -15)."""
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="lockstep")) as emu:
        robot = ProcessRobot(_legs(emu.address))
        sent: list[int] = []

        def send_at_once() -> None:
            for _ in range(100_000):  # bounded (at most a few seconds): until the process exists
                proc = robot._proc
                if proc is not None:
                    os.kill(proc.pid, signum)
                    sent.append(proc.pid)
                    return
                time.sleep(0.0001)

        sender = threading.Thread(target=send_at_once)
        sender.start()
        try:
            if signum == signal.SIGTERM:
                with pytest.raises(RobotLinkError, match="stopped by SIGTERM"):
                    robot.connect()
            else:
                robot.connect()
                robot.read()
        finally:
            sender.join()
            robot.close()
        assert sent and not _alive(sent[0])
        assert "Traceback" not in capfd.readouterr().err
        assert emu.failure is None


def test_this_process_dying_ends_the_io_process() -> None:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="lockstep")) as emu:
        script = ("import os, sys\n"
                  "from wbc.hardware.hardware_robot import HardwareRobotConfig\n"
                  "from wbc.hardware.io_process import ProcessRobot\n"
                  f"r = ProcessRobot(HardwareRobotConfig(robot='go1-arm', arm_mode='none', legs_host='127.0.0.1', "
                  f"legs_port={emu.address[1]}))\n"
                  "r.connect(); print(r.pid, flush=True); os.kill(os.getpid(), 9)\n")
        proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60, cwd=ROOT,
                              env=dict(os.environ, PYTHONPATH=str(ROOT)))
        assert proc.returncode == -signal.SIGKILL, proc.stderr
        child = int(proc.stdout.split()[0])
        end = time.monotonic() + 5.0
        while _alive(child) and time.monotonic() < end:
            time.sleep(0.05)
        assert not _alive(child)
        frames = emu.commands()
        assert frames and frames[-1].damping  # it closed the robot: damping last


def test_refusals_and_connect_failures_are_the_in_process_errors() -> None:
    refused = ("192.0.2.1", 9)  # TEST-NET-1, discard port: refused before any socket is created
    with pytest.raises(TargetRefusedError) as in_process:
        build_hardware_robot(_legs(refused))
    with pytest.raises(TargetRefusedError) as proc:
        build_process_robot(_legs(refused))
    assert str(proc.value) == str(in_process.value)
    # nothing answers on this port: the I/O process's connect fails as the in-process one does
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:
        silent.bind(("127.0.0.1", 0))
        cfg = _legs(silent.getsockname())
        with pytest.raises(RobotLinkError) as in_process, build_hardware_robot(cfg).robot:
            pass
        robot = ProcessRobot(cfg)
        with pytest.raises(RobotLinkError) as proc:
            robot.connect()
        assert type(proc.value) is type(in_process.value) is NoStateStreamError
        assert str(proc.value) == str(in_process.value)
        assert not robot.is_connected and robot.pid is None
        # a local port held by another socket: PortBusyError, with its attributes
        busy = _legs(silent.getsockname(), local_port=silent.getsockname()[1])
        with pytest.raises(PortBusyError) as proc:
            ProcessRobot(busy).connect()
        assert proc.value.port == silent.getsockname()[1]


def test_shared_blocks_publish_whole_records_and_refuse_a_torn_one() -> None:
    blocks = IoBlocks(3)
    try:
        assert blocks.command.read() == (0, None)
        for k in range(1, 4):
            blocks.command.record()["rows"] = np.full((5, 3), float(k))
            assert blocks.command.publish() == k
        count, record = blocks.command.read()
        assert count == 3 and (record["rows"] == 3.0).all()
        blocks.command.record()["rows"] = 4.0  # begun, not published: readers still get publication 3 whole
        assert blocks.command.read()[0] == 3
        blocks.command.publish()
        other = IoBlocks(3, fd=os.dup(blocks.fd))  # the other process's mapping of the same memory
        try:
            assert other.command.read()[0] == 4 and (other.command.read()[1]["rows"] == 4.0).all()
            blocks.command._raws[0][0] ^= 0xFF  # slot of publication 4, behind its CRC's back
            with pytest.raises(RobotLinkError, match="no consistent copy"):
                other.command.read()
        finally:
            other.close()
    finally:
        blocks.close()


def test_an_error_crosses_the_channel_as_its_own_class() -> None:
    busy = rebuild_error(error_report(PortBusyError("127.0.0.1", 9000, "in use")), where="I/O")
    assert type(busy) is PortBusyError and busy.port == 9000 and str(busy) == str(
        PortBusyError("127.0.0.1", 9000, "in use"))
    foreign = rebuild_error(error_report(OSError(5, "Input/output error")), where="I/O")
    assert type(foreign) is RobotLinkError and "OSError" in str(foreign) and "Input/output error" in str(foreign)
