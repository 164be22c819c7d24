"""`DynamixelArm` against the Dynamixel emulator, with dynamixel_sdk's packet handler as its serial layer: contract,
start-up, the current law on the wire, the write deadline, close, and fault case 10 with the reaction read off the
emulator's packet log.

Each test runs the arm and the emulator in lockstep on one `ManualClock`: the arm's bus cycle is a task of the
clock, its port (`in_process_handlers`) hands each instruction to the emulator within the same call, and a reply
timeout, a retry's pause or a servo's bus watchdog takes its clock time. What happens in which cycle is therefore
the same on any machine at any load, and the tests check it exactly: how many cycles, retries and pings, when the
damping starts, when a fault latches. The latency timer is the robot's (1 ms). The same backend on its thread
against the emulator's pseudo-terminal, in real time, is what ``wbc bench arm`` measures (loop rate, busy time,
failed reads, the fault-case reaction times) and what the tests marked ``realtime`` run.

Most tests hold the physics still: nobody steps the shared plant, so the servos report the same positions and zero
velocity every cycle. A damping command then asks for exactly zero current, and a hold with an offset asks for a
known one, so the goals on the wire can be compared with numbers.
"""

from __future__ import annotations

import dataclasses
import re
import sys
import termios
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest

from wbc.errors import (
    CommandError,
    ConfigError,
    MissingExtraError,
    RobotLinkError,
    SerialPortError,
    UnknownNameError,
)
from wbc.hardware.clock import ManualClock
from wbc.hardware.dynamixel import DynamixelArm, DynamixelArmConfig, sdk_handlers
from wbc.hardware.dynamixel.arm_fault import (
    MODE_CORRUPT,
    MODE_HARDWARE_ERROR,
    MODE_NO_ANSWER,
    MODE_PORT_LOST,
    MODE_SERVO,
)
from wbc.hardware.dynamixel.arm_robot import ARM_KD_MAX, ARM_KP_MAX, PARK_RETRIES_S
from wbc.hardware.dynamixel.control_table import HW_OVERHEATING, HW_OVERLOAD, XM430_W350, OperatingMode
from wbc.hardware.dynamixel.current_law import CurrentLaw
from wbc.hardware.dynamixel.protocol import Instruction
from wbc.hardware.dynamixel.sdk_bus import COMM_RX_TIMEOUT, COMM_SUCCESS, SdkBus, ServoRead, register_bytes
from wbc.hardware.dynamixel.units import CURRENT_UNIT, TORQUE_CONSTANT
from wbc.hardware.dynamixel.wx200_bus import WX200_SERVOS
from wbc.hardware.emulators import BusFault, DynamixelEmulator, DynamixelEmulatorConfig, LoggedPacket, SharedPlant
from wbc.hardware.emulators.dynamixel import TICK_PERIOD
from wbc.hardware.robot_contract import check_robot
from wbc.robots.wx200 import WX200_NOMINAL_Q
from wbc.types import MotorCommand

sdk = pytest.importorskip("dynamixel_sdk")

LATENCY_MS = 1.0  # the robot's latency timer
JOINTS = (1, 2, 4)
NM_PER_UNIT = CURRENT_UNIT * TORQUE_CONSTANT  # [N m] of one current unit on one servo
STEP = 0.005  # [s] the test's control period


def _timeout_s(answer_bytes: int) -> float:
    """The reply timeout of an answer of `answer_bytes` at 1 Mbit/s with the 1 ms latency timer [s]."""
    return (answer_bytes * 10 / 1e3 + 2.0 * LATENCY_MS + 2.0) * 1e-3


SYNC_READ_TIMEOUT = _timeout_s(3 * 21)  # the joints' sync read: three answers of 21 bytes
PING_TIMEOUT = _timeout_s(11)  # the SDK times a ping's answer as 11 bytes
SILENT_LATCH_S = 3 * SYNC_READ_TIMEOUT + 2 * 0.002 + 3 * PING_TIMEOUT + 0.002 + 0.01
"""[s] From a silent servo's first failed read to the latch, with the default retries (2) and retry wait (2 ms):
three timed-out reads with a pause before each retry, then three timed-out pings with the pauses between them."""


@pytest.fixture(scope="module")
def plant() -> Iterator[SharedPlant]:
    with SharedPlant() as p:
        yield p


@pytest.fixture
def emu(plant: SharedPlant) -> Iterator[DynamixelEmulator]:
    plant.reset()
    with DynamixelEmulator(plant, clock=ManualClock(), in_process=True) as e:
        yield e
        assert e.failure is None, e.failure


def _arm(emu: DynamixelEmulator, **kw: object) -> DynamixelArm:
    return DynamixelArm(DynamixelArmConfig(port=emu.port, **kw), handlers=emu.port_handlers(LATENCY_MS),
                        clock=emu.clock)


def _timed_goals(packets: list[LoggedPacket]) -> list[tuple[float, dict[int, int]]]:
    """Each SYNC_WRITE of Goal Current as (arrival time, {ID: value})."""
    return [(p.time, {w.id: w.value for w in p.writes if w.name == "goal_current"}) for p in packets
            if p.instruction == Instruction.SYNC_WRITE and p.written("goal_current")]


def _goals(packets: list[LoggedPacket]) -> list[dict[int, int]]:
    """Each SYNC_WRITE of Goal Current as {ID: value}."""
    return [g for _, g in _timed_goals(packets)]


def _since(emu: DynamixelEmulator, t: float) -> list[LoggedPacket]:
    return [p for p in emu.packets() if p.time >= t]


def _hold_with_offset(arm: DynamixelArm, offset: float = 0.1, kp: float = 20.0) -> MotorCommand:
    """Hold each joint `offset` rad beyond where it is: with the physics still, a constant torque kp * offset."""
    return MotorCommand.hold(arm.read().q + offset, kp, 0.5)


def _keep_writing(arm: DynamixelArm, cmd: MotorCommand, seconds: float) -> None:
    for _ in range(round(seconds / STEP)):
        arm.write(cmd)
        arm.advance(STEP)


# -- contract, start-up ------------------------------------------------------------------------------------------
def test_contract_against_the_emulator_on_one_clock(emu: DynamixelEmulator, plant: SharedPlant) -> None:
    physics = emu.clock.call_every(plant.sim.config.timestep, lambda: plant.step(plant.sim.config.timestep))
    try:
        check_robot(lambda: _arm(emu))
    finally:
        physics.cancel()
    assert not [t for t in threading.enumerate() if t.name == "dynamixel-arm-bus"]  # no thread on a ManualClock


def test_start_up_writes_eeprom_only_with_the_torque_off_and_arms_the_watchdog(emu: DynamixelEmulator) -> None:
    for _ in range(2):  # the second start finds the joints parked in mode 5 by the first close
        emu.clear_log()
        with _arm(emu):
            for spec in WX200_SERVOS:
                joint = spec.id <= 4
                assert emu.register(spec.id, "operating_mode") == (OperatingMode.CURRENT if joint
                                                                   else OperatingMode.POSITION)
                assert emu.register(spec.id, "torque_enable") == 1
                assert emu.register(spec.id, "bus_watchdog") == (5 if joint else 0)  # 100 ms; the shadow via ID 2
            for servo_id in (5, 6):  # the wrist at the pose the model lumps it at
                assert emu.register(servo_id, "goal_position") == 2048
            started = emu.packets()
        torque = {s.id: None for s in WX200_SERVOS}
        eeprom = 0
        for p in started:
            for w in p.writes:
                targets = [s.id for s in WX200_SERVOS if w.id in (s.id, s.secondary_id)]
                if w.name == "torque_enable":
                    for i in targets:
                        torque[i] = w.value
                elif w.name == "operating_mode":
                    eeprom += 1
                    assert all(torque[i] == 0 for i in targets), f"EEPROM written to ID {w.id} with its torque on"
        assert eeprom == 4  # each start switched the four joint servos' mode (3 -> 0, then 5 -> 0)


def test_connect_retries_a_servo_that_answers_late_then_refuses_it(emu: DynamixelEmulator) -> None:
    emu.inject(BusFault.LATE_ANSWER, (6, 0.05))
    t0 = emu.clock.now()
    with pytest.raises(RobotLinkError, match=r"did not answer a ping: ID 6 \(wrist_rotate\): rx timeout"):
        _arm(emu, connect_retries=3).connect()
    # servos 1..5 answer at once; ID 6's ping times out 4 times, with a 10 ms pause and a flush between tries
    assert emu.clock.now() - t0 == pytest.approx(4 * PING_TIMEOUT + 3 * 0.01, abs=1e-5)
    assert [p.id for p in emu.packets() if p.instruction == Instruction.PING] == [1, 2, 3, 4, 5, 6, 6, 6, 6, 7]
    assert not [p for p in emu.packets() if p.written("torque_enable")]  # refused before any torque write


def test_a_port_name_other_than_the_one_given_is_never_opened(emu: DynamixelEmulator) -> None:
    opened = []

    def elsewhere(port: str) -> tuple[object, object]:
        # built, not opened (an in-process name is refused; a real device's name needs the consent)
        handler, packet = sdk_handlers("/dev/ttyUSB9", 4.0, allow_hardware=True)
        handler.openPort = lambda: opened.append(True) or True  # would record an open
        return handler, packet

    with pytest.raises(SerialPortError, match="only the port given is ever opened"):
        DynamixelArm(DynamixelArmConfig(port=emu.port), handlers=elsewhere).connect()
    assert not opened


def test_a_missing_sdk_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "dynamixel_sdk", None)
    with pytest.raises(MissingExtraError, match=r"wbc\[hardware\]"):
        sdk_handlers("/dev/ttyUSB0", allow_hardware=True)


def test_every_serial_layer_exception_is_one_error() -> None:
    class Port:
        def __init__(self, exc: BaseException) -> None:
            self.exc = exc

        def getPortName(self) -> str:  # noqa: N802 - the SDK's name
            return "/dev/null-arm"

        def openPort(self) -> bool:  # noqa: N802
            raise self.exc

    for exc in (termios.error(5, "Input/output error"), OSError(9, "Bad file descriptor"), TypeError("None")):
        with pytest.raises(SerialPortError, match=type(exc).__name__):
            SdkBus(Port(exc), object(), port="/dev/null-arm", allow_hardware=True).open(1_000_000)


def test_connect_refuses_a_bus_that_is_not_the_wx200s(plant: SharedPlant) -> None:
    plant.reset()
    servos = tuple(dataclasses.replace(s, secondary_id=255) if s.id == 3 else s for s in WX200_SERVOS)
    config = DynamixelEmulatorConfig(servos=servos)
    with DynamixelEmulator(plant, config, clock=ManualClock(), in_process=True) as emu:
        with pytest.raises(RobotLinkError, match=r"ID 3 \(shoulder_shadow\).*Secondary ID 255"):
            _arm(emu, connect_retries=2).connect()
        emu.inject(BusFault.SILENT_ID, 6)
        with pytest.raises(RobotLinkError, match=r"did not answer a ping: ID 6 \(wrist_rotate\)"):
            _arm(emu, connect_retries=2).connect()
        assert not [p for p in emu.packets() if p.written("torque_enable")]  # refused before any torque write


def test_config_names_what_is_wrong() -> None:
    with pytest.raises(ConfigError, match="port"):
        DynamixelArmConfig(port="")
    with pytest.raises(UnknownNameError, match="a1-wx200"):
        DynamixelArmConfig(port="/dev/ttyUSB0", robot="a1")
    with pytest.raises(ConfigError, match="watchdog_s"):
        DynamixelArmConfig(port="/dev/ttyUSB0", watchdog_s=0.03)
    with pytest.raises(ConfigError, match="held_ticks"):
        DynamixelArmConfig(port="/dev/ttyUSB0", held_ticks=(5000, None, None))


def test_a_profile_velocity_of_zero_is_refused_it_means_full_speed_on_the_xm430(emu: DynamixelEmulator) -> None:
    """Profile Velocity 0 is no limit on the XM430: the config refuses it, naming the field and why; the floor, 1,
    is what reaches the held servos' register at connect."""
    with pytest.raises(ConfigError, match=r"held_profile_velocity must be at least 1.*0 means no limit"):
        DynamixelArmConfig(port=emu.port, held_profile_velocity=0)
    arm = _arm(emu, held_profile_velocity=1)
    arm.connect()
    try:
        profile = [(w.id, w.value) for p in emu.packets() for w in p.writes if w.name == "profile_velocity"]
    finally:
        arm.close()
    held = {s.id for s in arm.config.held_servos}
    assert profile and {i for i, _ in profile} == held and all(v == 1 for _, v in profile)


def test_connect_warns_naming_the_joints_when_the_arm_is_away_from_its_stowed_pose(
        plant: SharedPlant, capfd: pytest.CaptureFixture[str]) -> None:
    """A run that parked the arm raised: connect releases the joints (current mode, goal current 0, damping), so it
    says which joints are how far from the stowed pose before gravity takes them; at the stowed pose it says nothing."""
    for raised, said in ((np.array([0.0, 0.8, -0.7]), True), (np.zeros(3), False)):
        qpos = plant.sim.data.qpos.copy()
        qpos[-3:] = WX200_NOMINAL_Q + raised
        plant.reset(qpos=qpos)
        with DynamixelEmulator(plant, clock=ManualClock(), in_process=True) as emu:
            capfd.readouterr()
            arm = _arm(emu)
            arm.connect()
            arm.close()
        err = capfd.readouterr().err
        assert ("away from its stowed pose" in err) is said, err
        if said:
            assert re.search(r"shoulder at -0\.50 rad, 0\.80 rad from stowed", err), err
            assert re.search(r"elbow at \+0\.80 rad, 0\.70 rad from stowed", err), err
            assert "waist" not in err.split("away from its stowed pose")[1].split("Connecting")[0]
    plant.reset()


# -- the law on the wire -----------------------------------------------------------------------------------------
def test_current_law_units_and_clamps() -> None:
    from wbc.hardware.dynamixel.wx200_bus import WX200_ARM_JOINTS

    law = CurrentLaw(WX200_ARM_JOINTS, np.array([4.1, 8.2, 4.1]), 2.3)
    assert law.limit_units == 855
    rows = MotorCommand(q=np.zeros(3), dq=np.zeros(3), kp=np.zeros(3), kd=np.zeros(3),
                        tau=np.array([1.0, 1.0, -100.0])).stacked()
    tau = law.torque(rows, np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(tau, [1.0, 1.0, -law.torque_limit[2]])
    # the shoulder's two servos share its torque; the elbow's -100 N m ends at the current bound
    np.testing.assert_array_equal(law.goal_units(tau), [round(1 / NM_PER_UNIT), round(0.5 / NM_PER_UNIT), -855])


def test_each_cycle_is_one_sync_read_and_one_sync_write_of_the_laws_currents(emu: DynamixelEmulator) -> None:
    with _arm(emu) as arm:
        period, every = 1.0 / arm.config.rate_hz, arm.config.status_every
        tau = np.array([0.3, 0.8, -0.4])
        cmd = MotorCommand(q=arm.read().q, dq=np.zeros(3), kp=np.zeros(3), kd=np.zeros(3), tau=tau)
        _keep_writing(arm, cmd, 0.1)
        t0 = emu.clock.now()
        before = arm.bus_stats()
        _keep_writing(arm, cmd, 0.4)
        after = arm.bus_stats()
        plant_cmd, _ = emu.plant.arm_command()  # before close parks the arm
        emu.plant.step(0.002)  # one physics step, so that the plant's applied torque is the command's
        _keep_writing(arm, cmd, 0.03)
        state = arm.read()
    # the cycles that started in 0.35 s (windows offset by half a period: a cycle's packets share its start time)
    packets = [p for p in emu.packets() if t0 + 0.5 * period <= p.time < t0 + 0.35 + 0.5 * period]
    cycles = round(0.35 / period)
    reads = [p for p in packets if p.instruction == Instruction.SYNC_READ]
    joint_reads = [p for p in reads if p.reads[0].address == 126]
    status = [p for p in reads if p.reads[0].address in (70, 144)]
    goals = _goals(packets)
    assert {tuple(r.id for r in p.reads) for p in joint_reads} == {JOINTS}
    assert all(r.length == 10 for p in joint_reads for r in p.reads)
    assert {tuple(r.id for r in p.reads) for p in status} == {tuple(range(1, 8))}
    assert len(goals) == len(joint_reads) == cycles  # one read and one write per cycle, nothing retried
    assert len(status) == 2 * cycles // every  # two every status_every cycles, taking turns
    assert abs(sum(p.reads[0].address == 70 for p in status) - sum(p.reads[0].address == 144 for p in status)) <= 1
    assert {tuple(sorted(g)) for g in goals} == {JOINTS}  # the shadow follows ID 2 through its Secondary ID
    expected = {1: round(0.3 / NM_PER_UNIT), 2: round(0.4 / NM_PER_UNIT), 4: round(-0.4 / NM_PER_UNIT)}
    assert all(g == expected for g in goals)
    kinds = {p.instruction for p in packets}
    assert kinds <= {Instruction.SYNC_READ, Instruction.SYNC_WRITE, Instruction.READ}
    # the plant got the torque asked for (the shoulder's two servos add up), and the state reads the plant back
    np.testing.assert_allclose(plant_cmd.tau, tau, atol=NM_PER_UNIT)
    q, _, _ = emu.plant.read_arm()
    np.testing.assert_allclose(state.q, q, atol=2 * 2 * np.pi / 4096)
    np.testing.assert_allclose(state.tau_est, tau, atol=2 * NM_PER_UNIT)
    # a fresh state every cycle, no failed read, no late call, and the clock's period between cycles
    assert after.states - before.states == after.cycles - before.cycles == round(0.4 / period)
    assert after.failed_transfers == after.retries == after.overruns == after.late_advances == 0
    assert after.period_mean == pytest.approx(period) and after.period_max == pytest.approx(period)


def test_a_silent_writer_gets_damping_after_the_deadline(emu: DynamixelEmulator) -> None:
    with _arm(emu) as arm:
        deadline = arm.config.write_deadline
        cmd = _hold_with_offset(arm)
        _keep_writing(arm, cmd, 0.1)
        arm.write(cmd)
        written = emu.clock.now()
        emu.clock.advance(0.2)  # no write: the deadline (50 ms) passes
        assert arm.bus_stats().deadline_trips == 1
        _keep_writing(arm, cmd, 0.1)
    period = 1.0 / arm.config.rate_hz
    goals = _timed_goals(_since(emu, written))
    # every cycle before the deadline keeps the hold, every cycle after it damps (the one on it: either)
    held = [g for t, g in goals if t - written < deadline - 0.5 * period]
    quiet = [g for t, g in goals if deadline + 0.5 * period < t - written < 0.2 - 0.5 * period]
    assert len(held) == round(deadline / period) - 1
    assert all(abs(g[1]) > 300 for g in held)  # 2 N m on the waist: ~417 units
    assert len(quiet) == round((0.2 - deadline) / period) - 1
    assert all(g == {1: 0, 2: 0, 4: 0} for g in quiet)  # damping of a still arm asks for nothing


def test_a_non_finite_command_built_unchecked_never_reaches_the_bus(emu: DynamixelEmulator) -> None:
    """The current law would turn a NaN torque into a register value (INT64_MIN cast to 16 bits) on its way out."""
    with _arm(emu) as arm:
        hold = _hold_with_offset(arm)
        _keep_writing(arm, hold, 0.05)
        before = _goals(emu.packets())[-1]
        for value in (np.nan, np.inf):
            rows = hold.stacked()
            rows[4, 1] = value
            with pytest.raises(CommandError, match=r"non-finite value at tau\[.*\]; refused"):
                arm.write(MotorCommand.trusted(rows))
            arm.advance(STEP)
        emu.clear_log()
        emu.clock.advance(0.02)  # the bus goes on with the last command it accepted, until the write deadline
        goals = _goals(emu.packets())
    assert goals and all(g == before for g in goals)


def test_gains_the_bus_loop_cannot_hold_are_clamped_on_the_way_and_the_arm_stays_still(
        emu: DynamixelEmulator, plant: SharedPlant) -> None:
    """The legs' driver takes kd up to 100; closed over the bus at 200 Hz, kd 12 already chatters between the current
    limits (against the emulator). The arm bounds its own gains (`ARM_KP_MAX`, `ARM_KD_MAX`)."""
    ts = plant.sim.config.timestep
    physics = emu.clock.call_every(ts, lambda: plant.step(ts))
    try:
        with _arm(emu) as arm:
            _keep_writing(arm, _hold_with_offset(arm, 0.2, kp=20.0), 0.15)  # the arm moving
            wild = MotorCommand.hold(arm.read().q, 1000.0, 100.0)
            applied = arm.write(wild)
            np.testing.assert_array_equal(applied.kp, ARM_KP_MAX)
            np.testing.assert_array_equal(applied.kd, ARM_KD_MAX)
            start = emu.clock.now()
            _keep_writing(arm, wild, 1.0)
    finally:
        physics.cancel()
    elbow = np.array([g[4] for t, g in _timed_goals(_since(emu, start + 0.5))])
    flips = int((np.diff(np.sign(elbow)) != 0).sum())
    assert elbow.size >= 90 and flips <= 5, (flips, elbow.min(), elbow.max())  # kd 100 flipped on ~9 of 10 cycles
    assert np.abs(elbow).max() < arm.law.limit_units  # never at the current limit: the arm is at rest


def test_damping_opposes_a_moving_arm_on_the_wire(emu: DynamixelEmulator, plant: SharedPlant) -> None:
    """With the physics stepped, the damping after the deadline asks each servo for kd times its joint's speed,
    against it: a zero current (a limp arm) would let the arm fall, and with a still plant the two look the same."""
    ts = plant.sim.config.timestep
    physics = emu.clock.call_every(ts, lambda: plant.step(ts))
    cycles = []
    try:
        with _arm(emu) as arm:
            _keep_writing(arm, _hold_with_offset(arm, 0.4, kp=20.0), 0.05)  # the arm swings towards the hold
            silent = emu.clock.now()
            for _ in range(round(0.15 / STEP)):  # one bus cycle a step, no write: past the deadline, damping
                emu.clock.advance(STEP)
                state = arm.read()
                cycles.append((emu.clock.now(), state.q.copy(), state.dq.copy()))
            damping = MotorCommand.damping(3, arm.config.damping_kd).stacked()
            law, deadline, period = arm.law, arm.config.write_deadline, 1.0 / arm.config.rate_hz
    finally:
        physics.cancel()
    goals = _timed_goals(_since(emu, silent))
    damped = [(t, g) for t, g in goals if t - silent > deadline + 0.5 * period and t < cycles[-1][0]]
    assert len(damped) >= 15
    moving = 0
    for t, g in damped:
        # the state the arm published after the cycle that wrote these goals is the one its law read
        _, q, dq = min((c for c in cycles if c[0] >= t), key=lambda c: c[0])
        expected = law.goal_units(law.torque(damping, q, dq))
        assert [g[i] for i in JOINTS] == expected.tolist()
        moving += int(np.any(np.abs(dq) > 0.2))
        assert all(expected[j] * law.sign[j] * dq[j] <= 0 for j in range(3))  # against the motion
    assert moving >= 10  # the arm was moving: the goals above are not zero by a still plant's chance
    assert any(any(g[i] != 0 for i in JOINTS) for _, g in damped)


def test_close_damps_then_parks_each_joint_in_a_position_hold(emu: DynamixelEmulator) -> None:
    with _arm(emu, close_damping=0.1) as arm:
        _keep_writing(arm, _hold_with_offset(arm), 0.1)
        emu.clear_log()
        closing = emu.clock.now()
    after = emu.packets()
    damping = _goals(after)
    # a cycle of damping every period for close_damping (the one on its end: either), then the park
    assert round(0.1 * arm.config.rate_hz) - 1 <= len(damping) <= round(0.1 * arm.config.rate_hz)
    assert all(g == {1: 0, 2: 0, 4: 0} for g in damping)
    park = [(p.time, w.id, w.name, w.value) for p in after if p.instruction == Instruction.WRITE for w in p.writes]
    assert park and min(t for t, *_ in park) >= closing + 0.1
    for servo_id in JOINTS:
        steps = [(name, value) for _, i, name, value in park if i == servo_id]
        assert [n for n, _ in steps] == ["bus_watchdog", "torque_enable", "operating_mode", "goal_current",
                                         "goal_position", "torque_enable"]
        assert steps[1][1] == 0 and steps[2][1] == OperatingMode.CURRENT_BASED_POSITION and steps[-1][1] == 1
        assert steps[3][1] == round(1.0 / CURRENT_UNIT)  # park_current_a
        assert steps[4][1] == emu.register(servo_id, "present_position")  # held where it is
        assert emu.register(servo_id, "torque_enable") == 1 and emu.register(servo_id, "bus_watchdog") == 0
    cmd, _ = emu.plant.arm_command()
    assert (cmd.kp > 0).all()  # the plant holds the arm: a position loop, not a limp arm
    emu.clock.advance(1.0)  # parked: no host, no watchdog, the hold stays
    assert (emu.plant.arm_command()[0].kp > 0).all()


def test_a_park_the_elbow_misses_is_tried_again_until_it_holds(emu: DynamixelEmulator,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """The elbow neither hears nor answers its park's first three tries (noise on the bus, a connector that lets go
    for an instant; to the host, as an answer that came too late). The park's transfers are tried again as at
    start-up, and every joint ends parked; tried once more only, the elbow would be left limp."""
    arm = _arm(emu, close_damping=0.1)
    arm.connect()
    _keep_writing(arm, _hold_with_offset(arm), 0.1)
    park = DynamixelArm._park

    def elbow_writes() -> list[str]:
        return [w.name for p in emu.packets() if p.instruction == Instruction.WRITE for w in p.writes if w.id == 4]

    def late_park(self: DynamixelArm, bus: SdkBus) -> None:
        emu.inject(BusFault.SILENT_ID, 4)
        sleep = self.clock.sleep

        def wait(seconds: float) -> None:  # the host's waits (the port's, the pause before a try again)
            if len(elbow_writes()) >= 3:  # its third try is on the bus: it hears the next
                emu.clear(BusFault.SILENT_ID)
            sleep(seconds)

        monkeypatch.setattr(self.clock, "sleep", wait)
        park(self, bus)

    monkeypatch.setattr(DynamixelArm, "_park", late_park)
    emu.clear_log()
    arm.close()
    for servo_id in JOINTS:
        assert emu.register(servo_id, "operating_mode") == OperatingMode.CURRENT_BASED_POSITION
        assert emu.register(servo_id, "torque_enable") == 1 and emu.register(servo_id, "bus_watchdog") == 0
    writes = elbow_writes()
    assert writes[:4] == ["bus_watchdog"] * 4 and writes[4] != "bus_watchdog"  # its first write, made four times
    assert (emu.plant.arm_command()[0].kp > 0).all()  # a position hold on every joint


def test_a_park_tries_again_for_a_bounded_time_only(emu: DynamixelEmulator, monkeypatch: pytest.MonkeyPatch) -> None:
    """An elbow that never answers at the park: its transfers are tried again for `PARK_RETRIES_S` in all, however many
    tries `connect_retries` allows and however long each waits, so that the close ends within what its callers wait
    for (the bus loop's join, the I/O process's close); the other joints are parked."""
    arm = _arm(emu, close_damping=0.1, connect_retries=100, retry_wait_s=0.05)  # ~0.05 s a try: 100 tries, ~5 s
    arm.connect()
    _keep_writing(arm, _hold_with_offset(arm), 0.1)
    park = DynamixelArm._park

    def silent_elbow(self: DynamixelArm, bus: SdkBus) -> None:
        emu.inject(BusFault.SILENT_ID, 4)
        park(self, bus)

    monkeypatch.setattr(DynamixelArm, "_park", silent_elbow)
    emu.clear_log()
    start = emu.clock.now()
    arm.close()
    assert emu.clock.now() - start < 0.1 + PARK_RETRIES_S + 0.2  # the damping, the tries, the last one's timeout
    for servo_id in (1, 2):
        assert emu.register(servo_id, "operating_mode") == OperatingMode.CURRENT_BASED_POSITION
    tries = [p for p in emu.packets() if p.instruction == Instruction.WRITE and any(w.id == 4 for w in p.writes)]
    assert 10 < len(tries) < 101


# -- fault case 10: bounded retries, then the torque policy, read at the emulator ---------------------------------
def _fault_rig(emu: DynamixelEmulator, arm: DynamixelArm, fault: BusFault,
               value: object = None) -> tuple[float, list[LoggedPacket]]:
    """Hold with an offset (a known, non-zero current), inject `fault`, step until the latch; (t_inject, packets)."""
    _keep_writing(arm, _hold_with_offset(arm), 0.15)
    t0 = emu.clock.now()
    emu.inject(fault, value)
    for _ in range(round(0.2 / STEP)):
        if arm.fault is not None:
            break
        arm.write(_hold_with_offset(arm))  # the controller goes on asking for the hold
        arm.advance(STEP)
    assert arm.fault is not None, f"{fault} did not latch a fault"
    _keep_writing(arm, _hold_with_offset(arm), 0.1)
    return t0, _since(emu, t0)


def _after_latch(arm: DynamixelArm, packets: list[LoggedPacket]) -> list[LoggedPacket]:
    return [p for p in packets if p.time > arm.fault.time]


@pytest.mark.parametrize("fault,kind,mode", [(BusFault.SILENT_ID, "no_answer", MODE_NO_ANSWER),
                                             (BusFault.BAD_CRC, "corrupt", MODE_CORRUPT)])
def test_an_unreadable_servo_is_retried_identified_then_the_others_damped(
        emu: DynamixelEmulator, fault: BusFault, kind: str, mode: int) -> None:
    with _arm(emu) as arm:
        tick = arm.read().tick
        t0, packets = _fault_rig(emu, arm, fault, 4)
        assert arm.fault.kind == kind and arm.fault.ids == (4,)
        assert "elbow" in arm.fault.policy and "LIMP" in arm.fault.policy
        status = arm.motor_status()
        assert status.motor_mode.tolist() == [MODE_SERVO] * 3 + [mode] + [MODE_SERVO] * 3
        frozen = arm.read().tick
        _keep_writing(arm, _hold_with_offset(arm), 0.05)
        assert arm.read().tick == frozen > tick  # a latched fault freezes the tick: the frame goes stale
        stats = arm.bus_stats()
    retries, period, watchdog = arm.config.retries, 1.0 / arm.config.rate_hz, arm.config.watchdog_s
    before = [p for p in packets if p.time <= arm.fault.time]
    failing = [p for p in before if p.instruction == Instruction.SYNC_READ and 4 in [r.id for r in p.reads]]
    assert failing[0].time - t0 <= period
    cycles = len(failing) // (retries + 1)  # bounded retries in each cycle; missed cycles until the watchdog's time
    assert len(failing) == cycles * (retries + 1) and stats.missed_reads == cycles - 1
    assert stats.failed_transfers == len(failing) and stats.retries == cycles * retries
    pings = [p for p in before if p.instruction == Instruction.PING]
    # late is not dead: no ping, no fault, until the servo has been silent for the watchdog's time
    assert pings[0].time - failing[0].time >= watchdog - period
    assert pings[0].time - failing[0].time < watchdog + period + SILENT_LATCH_S
    if kind == "no_answer":
        assert [p.id for p in pings] == [1, 2, 4, 4, 4]  # every servo of the read pinged; the silent one thrice
    else:
        assert [p.id for p in pings] == [1, 2, 4]  # a corrupt answer to a ping is an answer: no more pings
    later = _after_latch(arm, packets)
    reads = [tuple(r.id for r in p.reads) for p in later if p.instruction == Instruction.SYNC_READ]
    assert (1, 2) in reads and not [r for r in reads if 4 in r]  # the unreadable servo is left out of the reads
    goals = _goals(later)
    assert goals and all(g.get(1) == 0 and g.get(2) == 0 for g in goals)  # damping of a still arm: no current
    if kind == "no_answer":
        assert all(4 not in g for g in goals)  # it hears nothing; its watchdog stops it
    else:
        assert all(g[4] == 0 for g in goals)  # it hears but cannot be read: goal current 0, limp


def test_a_law_on_a_state_older_than_the_write_deadline_asks_for_no_current(emu: DynamixelEmulator) -> None:
    """Between a servo falling silent and the latch (its watchdog's time), the reads fail and the last state ages:
    the law goes on from it for up to the write deadline, then every joint it cannot read fresh gets goal 0."""
    with _arm(emu) as arm:
        _keep_writing(arm, _hold_with_offset(arm), 0.05)
        held = _goals(emu.packets())[-1]
        t0, packets = _fault_rig(emu, arm, BusFault.SILENT_ID, 4)
        deadline, period, latched = arm.config.write_deadline, 1.0 / arm.config.rate_hz, arm.fault.time
    assert held[1] > 300  # the hold's known current (2 N m on the waist: ~417 units)
    reads = [p for p in packets if p.instruction == Instruction.SYNC_READ and 4 in [r.id for r in p.reads]]
    last_good = reads[0].time - period  # the cycle before the first failed read read every joint
    goals = [(t - last_good, g) for t, g in _timed_goals(packets) if t < latched]
    fresh = [g for age, g in goals if age < deadline - 0.5 * period]
    stale = [g for age, g in goals if deadline + 0.5 * period < age]
    # each failing cycle spends its retries' timeouts (~18 ms): the ages run 23, 46, 69, 92 ms
    assert len(fresh) >= 2 and all(g == held for g in fresh)  # open loop, not for long
    assert len(stale) >= 2 and all(g == {1: 0, 2: 0, 4: 0} for g in stale)  # the whole sync read failed: all three


def test_a_late_answer_is_retried_then_latched(emu: DynamixelEmulator) -> None:
    late = 2 * SILENT_LATCH_S  # beyond every timeout and pause of the cycle's retries and pings
    with _arm(emu) as arm:
        _, packets = _fault_rig(emu, arm, BusFault.LATE_ANSWER, (4, late))
        assert arm.fault.kind == "no_answer" and arm.fault.ids == (4,)
        assert arm.motor_status().motor_mode[3] == MODE_NO_ANSWER
        emu.clear(BusFault.LATE_ANSWER)
        _keep_writing(arm, _hold_with_offset(arm), 0.1)
        stats = arm.bus_stats()
        assert arm.fault.kind == "no_answer" and len(arm.faults) == 1  # latched: answers on time do not undo it
    failing = [p for p in packets if p.time <= arm.fault.time and p.instruction == Instruction.SYNC_READ
               and 4 in [r.id for r in p.reads]]
    tries = arm.config.retries + 1
    assert len(failing) >= tries and stats.missed_reads >= 1  # missed cycles first, not a latch
    # no late answer was taken for a later request's: latched as a silent servo, once silent for the watchdog's time
    assert arm.config.watchdog_s <= arm.fault.time - failing[0].time < arm.config.watchdog_s + 0.005 + SILENT_LATCH_S
    goals = _goals(_after_latch(arm, packets))
    assert goals and all(4 not in g and g.get(1) == 0 and g.get(2) == 0 for g in goals)


@pytest.mark.parametrize("late", [2 * SILENT_LATCH_S, 0.05, 0.02])
def test_a_late_answers_latch_says_the_silence_that_triggered_it(emu: DynamixelEmulator, late: float) -> None:
    """The latch's figure is the silence that reached the watchdog's time, in the read that failed: a late elbow fails
    the status reads of all five servos, and the wrist, read only there, is the first silent for 0.1 s. It said "ID 4
    (elbow): no valid answer for 0.085 s (the watchdog's 0.1 s)", counted from the elbow's last answered ping."""
    with _arm(emu) as arm:
        _fault_rig(emu, arm, BusFault.LATE_ANSWER, (4, late))
        fault = arm.fault
    assert fault.kind == "no_answer" and fault.ids == (4,) and fault.detail.startswith("ID 4 (elbow): ")
    (silence,) = re.findall(r"for (\d+\.\d+) s \(the watchdog's 0\.1 s\)", fault.detail)
    assert float(silence) >= arm.config.watchdog_s, fault.detail


def test_a_late_answer_of_another_length_is_discarded_as_late_by_the_bus(emu: DynamixelEmulator) -> None:
    port, packet = emu.port_handlers(LATENCY_MS)(emu.port)
    bus = SdkBus(port, packet, port=emu.port)
    bus.open(1_000_000)
    timeout = _timeout_s(15)  # a 4-byte read's answer: 15 bytes
    emu.inject(BusFault.LATE_ANSWER, (4, 1.5 * timeout))
    first = bus.read(4, 132, 4)
    assert first.result == COMM_RX_TIMEOUT and bus.late == 0
    # the next request (1 byte) waits while the first's 4-byte answer arrives: skipped, never read as its own
    second = bus.read(4, 70, 1)
    assert second.result == COMM_RX_TIMEOUT and second.data == b"" and bus.late == 1
    emu.clear(BusFault.LATE_ANSWER)
    bus.flush()
    assert bus.read(4, 70, 1) == ServoRead(4, b"\x00", COMM_SUCCESS, 0)
    bus.close()


def test_a_register_value_that_does_not_fit_is_refused_not_wrapped(emu: DynamixelEmulator) -> None:
    # without a table: the width only (two's complement below zero, unsigned above)
    assert register_bytes(-1, 2, 102) == [0xFF, 0xFF] and register_bytes(65535, 2, 102) == [0xFF, 0xFF]
    assert register_bytes(np.int64(-32768), 2, 102) == [0x00, 0x80]
    for value in (65536, -32769, 1 << 40):
        with pytest.raises(CommandError, match=rf"register 102: {value} does not fit its 2 bytes"):
            register_bytes(value, 2, 102)
    for value in (1.5, np.float64(3.0), True, "7"):
        with pytest.raises(CommandError, match="not an integer register value"):
            register_bytes(value, 2, 102)
    # with the servos' table: the register the write names, and its range
    assert register_bytes(-1193, 2, 102, XM430_W350) == list((-1193 & 0xFFFF).to_bytes(2, "little"))
    for value in (40000, 1194, -1194):
        with pytest.raises(CommandError, match=rf"register 102 \(goal_current\): {value} lies outside its range "
                                               r"-1193..1193"):
            register_bytes(value, 2, 102, XM430_W350)
    for address, size in ((103, 2), (102, 4), (126, 2), (1000, 1)):  # mid-register, wrong size, read-only, beyond
        with pytest.raises(CommandError, match=rf"register {address} \({size} bytes\) is no writable register"):
            register_bytes(0, size, address, XM430_W350)
    port, packet = emu.port_handlers(LATENCY_MS)(emu.port)
    bus = SdkBus(port, packet, port=emu.port, table=XM430_W350)
    bus.open(1_000_000)
    emu.clear_log()
    # 40000 units of Goal Current fit two bytes and no servo takes them: nothing of either write goes out
    with pytest.raises(CommandError, match="40000 lies outside"):
        bus.sync_write(102, 2, [(1, 10), (4, 40000)])
    with pytest.raises(CommandError, match="-40000 does not fit its 2 bytes"):
        bus.write(4, 102, 2, -40000)
    assert emu.packets() == []
    bus.sync_write(102, 2, [(1, 10), (4, -20)])  # values within the range go out as they are
    assert _goals(emu.packets()) == [{1: 10, 4: -20}]
    bus.close()


@pytest.mark.parametrize("then", ["ping", "write"])
def test_a_late_read_answer_is_not_taken_for_a_ping_or_a_write(emu: DynamixelEmulator, then: str) -> None:
    """A read's answer that arrives during the next request (a ping, a write of the same servo) is discarded: the SDK's
    own ping and write take any answer of the ID (a model number read off present values, an error byte off data)."""
    port, packet = emu.port_handlers(LATENCY_MS)(emu.port)
    bus = SdkBus(port, packet, port=emu.port)
    bus.open(1_000_000)
    emu.inject(BusFault.LATE_ANSWER, (4, 1.5 * _timeout_s(15)))
    assert bus.read(4, 132, 4).result == COMM_RX_TIMEOUT  # its answer is on its way, late
    # the next request's wait sees the read's answer arrive (and its own answer is late too)
    if then == "ping":
        assert bus.ping(4) == (0, COMM_RX_TIMEOUT, 0)  # not a model number read off a present position
    else:
        assert bus.write(4, 116, 4, 2048) == (COMM_RX_TIMEOUT, 0)  # not a success read off a read's answer
    assert bus.late == 1
    bus.close()


@pytest.mark.parametrize("fault,value,bits", [(BusFault.OVERLOAD, 4, HW_OVERLOAD),
                                              (BusFault.OVER_TEMPERATURE, (4, 85), HW_OVERHEATING)])
def test_a_hardware_alert_latches_with_its_bits_and_the_others_are_damped(
        emu: DynamixelEmulator, fault: BusFault, value: object, bits: int) -> None:
    with _arm(emu) as arm:
        t0, packets = _fault_rig(emu, arm, fault, value)
        assert arm.fault.kind == "hardware_error" and arm.fault.ids == (4,)
        assert arm.fault.time - t0 <= 1.0 / arm.config.rate_hz  # the first cycle's read carries the alert
        status = arm.motor_status()
        assert status.motor_mode[3] == MODE_HARDWARE_ERROR | bits and status.hardware_error[3] == bits
        if fault is BusFault.OVER_TEMPERATURE:
            # the temperatures are read every 2 * status_every cycles
            _keep_writing(arm, _hold_with_offset(arm), 2 * arm.config.status_every / arm.config.rate_hz)
            assert arm.motor_status().motor_temperature[3] == 85
        failed = arm.bus_stats().failed_transfers
    assert emu.register(4, "torque_enable") == 0  # the servo's own Shutdown
    later = _after_latch(arm, packets)
    goals = _goals(later)
    assert goals and all(g == {1: 0, 2: 0, 4: 0} for g in goals)
    assert failed == 0  # an alert is no failed read: nothing to retry


def test_a_closed_port_latches_and_the_servos_watchdog_leaves_the_arm_limp(emu: DynamixelEmulator) -> None:
    with _arm(emu) as arm:
        _keep_writing(arm, _hold_with_offset(arm), 0.15)
        held, _ = emu.plant.arm_command()
        assert np.abs(held.tau).min() > 1.0  # the hold's current is on
        last = emu.packets()[-1].time
        emu.inject(BusFault.PORT_CLOSED)
        arm.advance(STEP)  # the next cycle finds the port gone
        assert arm.fault is not None and arm.fault.time - last <= 1.0 / arm.config.rate_hz + 1e-9
        assert arm.fault.kind == "port_lost" and "LIMP" in arm.fault.policy
        assert arm.motor_status().motor_mode.tolist() == [MODE_PORT_LOST] * 7
        # the bus watchdog (100 ms) zeroes the goal currents of the servos no one talks to any more
        emu.clock.advance(arm.config.watchdog_s - (emu.clock.now() - last) - 1.5 * TICK_PERIOD)
        assert emu.register(4, "bus_watchdog") == 5 and (emu.plant.arm_command()[0].tau != 0).all()
        emu.clock.advance(2 * TICK_PERIOD)
        assert emu.register(4, "bus_watchdog") == -1  # tripped 100 ms (within a tick) after the last packet
    cmd, _ = emu.plant.arm_command()
    assert (cmd.tau == 0).all() and (cmd.kp == 0).all()  # limp, as the policy says
    assert emu.register(4, "torque_enable") == 1  # stopped by the watchdog, not switched off


@pytest.mark.parametrize("name,fault,value", [("silent_id", BusFault.SILENT_ID, 4), ("bad_crc", BusFault.BAD_CRC, 4),
                                              ("late_answer", BusFault.LATE_ANSWER, (4, 0.05)),
                                              ("port_closed", BusFault.PORT_CLOSED, None)])
def test_each_fault_latches_by_the_time_the_arm_bench_expects(emu: DynamixelEmulator, name: str, fault: BusFault,
                                                              value: object) -> None:
    """``wbc bench arm`` sets each latch it measures beside `expected_latch_s`: a bound the bus loop keeps."""
    from wbc.tools.bench.arm import expected_latch_s

    with _arm(emu) as arm:
        t0, _ = _fault_rig(emu, arm, fault, value)
        latched = arm.fault.time - t0
    period, watchdog = 1.0 / arm.config.rate_hz, arm.config.watchdog_s
    assert latched <= expected_latch_s(arm.config)[name] + 1e-9
    if name != "port_closed":  # not before the servo's silence reached the watchdog's time
        assert latched >= watchdog - period


# -- the bus thread on the wall clock, against the pty (``make test-realtime``) -----------------------------------
@pytest.fixture
def pty_emu(plant: SharedPlant) -> Iterator[DynamixelEmulator]:
    plant.reset()
    with DynamixelEmulator(plant) as e:
        yield e
        assert e.failure is None, e.failure


@pytest.mark.realtime
def test_the_bus_thread_runs_its_cycles_at_the_rate_over_the_pty(pty_emu: DynamixelEmulator) -> None:
    arm = DynamixelArm(DynamixelArmConfig(port=pty_emu.port, latency_ms=4.0))
    with arm:
        cmd = MotorCommand.hold(arm.read().q, 20.0, 0.5)
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            arm.write(cmd)
            arm.advance(STEP)
        stats = arm.bus_stats()
        assert [t.name for t in threading.enumerate() if t.name == "dynamixel-arm-bus"]
    assert arm.fault is None
    assert stats.states >= 0.5 * 0.5 * arm.config.rate_hz  # at least half the rate, on a loaded machine
    assert stats.period_mean == pytest.approx(1.0 / arm.config.rate_hz, rel=0.5)


@pytest.mark.realtime
def test_a_closed_pty_latches_and_the_watchdog_trips_in_real_time(pty_emu: DynamixelEmulator) -> None:
    with DynamixelArm(DynamixelArmConfig(port=pty_emu.port, latency_ms=4.0)) as arm:
        end = time.monotonic() + 0.15
        while time.monotonic() < end:
            arm.write(_hold_with_offset(arm))
            arm.advance(STEP)
        pty_emu.inject(BusFault.PORT_CLOSED)
        end = time.monotonic() + 1.0
        while arm.fault is None and time.monotonic() < end:
            time.sleep(0.002)
        assert arm.fault is not None and arm.fault.kind == "port_lost"
        last = pty_emu.packets()[-1].time
        while pty_emu.register(4, "bus_watchdog") != -1 and time.monotonic() < end + 1.0:
            time.sleep(0.002)
        tripped_after = time.monotonic() - last
    assert pty_emu.register(4, "bus_watchdog") == -1
    assert tripped_after < 0.1 + 0.1
