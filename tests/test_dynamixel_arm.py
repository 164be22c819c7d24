"""`DynamixelArm` over the Dynamixel emulator's pty, with dynamixel_sdk as its serial layer: contract, start-up, the
current law on the wire, the write deadline, close, and fault case 10 with the reaction read off the emulator's
packet log.

Most tests hold the physics still: nobody steps the shared plant, so the servos report the same positions and zero
velocity every cycle. A damping command then asks for exactly zero current, and a hold with an offset asks for a
known one, so the goals on the wire can be compared with numbers. The latency timer is 4 ms here, against 1 ms on a
robot. The emulator runs in this process and must win Python's lock before it can answer, and on a loaded 2-core
machine a 1 ms timer times out a few percent of the reads.
"""

from __future__ import annotations

import dataclasses
import sys
import termios
import time
from collections.abc import Callable, Iterator

import numpy as np
import pytest

from wbc.errors import ConfigError, MissingExtraError, RobotLinkError, SerialPortError, UnknownNameError
from wbc.hardware.contract import check_robot
from wbc.hardware.dynamixel import (
    HW_OVERHEATING,
    HW_OVERLOAD,
    MODE_CORRUPT,
    MODE_HARDWARE_ERROR,
    MODE_NO_ANSWER,
    MODE_PORT_LOST,
    MODE_SERVO,
    WX200_SERVOS,
    CurrentLaw,
    DynamixelArm,
    DynamixelArmConfig,
    Instruction,
    OperatingMode,
    SdkBus,
    sdk_handlers,
)
from wbc.hardware.dynamixel.units import CURRENT_UNIT, TORQUE_CONSTANT
from wbc.hardware.emulators import BusFault, DynamixelEmulator, DynamixelEmulatorConfig, LoggedPacket, SharedPlant
from wbc.types import MotorCommand

sdk = pytest.importorskip("dynamixel_sdk")

FAST = dict(latency_ms=4.0, retries=2)
JOINTS = (1, 2, 4)
NM_PER_UNIT = CURRENT_UNIT * TORQUE_CONSTANT  # [N m] of one current unit on one servo


def _until(cond: Callable[[], object], timeout: float = 2.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.002)
    return bool(cond())


@pytest.fixture(scope="module")
def plant() -> Iterator[SharedPlant]:
    with SharedPlant() as p:
        yield p


@pytest.fixture
def emu(plant: SharedPlant) -> Iterator[DynamixelEmulator]:
    plant.reset()
    with DynamixelEmulator(plant) as e:
        yield e
        assert e.failure is None, e.failure


def _arm(emu: DynamixelEmulator, **kw: object) -> DynamixelArm:
    return DynamixelArm(DynamixelArmConfig(port=emu.port, **{**FAST, **kw}))


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
    end = time.monotonic() + seconds
    for _ in range(int(seconds / 0.005) + 1):
        if time.monotonic() >= end:
            break
        arm.write(cmd)
        arm.advance(0.005)


# -- contract, start-up ------------------------------------------------------------------------------------------
def test_contract_over_the_pty_emulator(emu: DynamixelEmulator, plant: SharedPlant) -> None:
    plant.start_realtime()
    try:
        check_robot(lambda: _arm(emu))
    finally:
        plant.stop_realtime()


def test_start_up_writes_eeprom_only_with_the_torque_off_and_arms_the_watchdog(emu: DynamixelEmulator) -> None:
    for _ in range(2):  # the second start finds the joints parked in mode 5 by the first close
        t0 = time.monotonic()
        with _arm(emu):
            for spec in WX200_SERVOS:
                joint = spec.id <= 4
                assert emu.register(spec.id, "operating_mode") == (OperatingMode.CURRENT if joint
                                                                   else OperatingMode.POSITION)
                assert emu.register(spec.id, "torque_enable") == 1
                assert emu.register(spec.id, "bus_watchdog") == (5 if joint else 0)  # 100 ms; the shadow via ID 2
            for servo_id in (5, 6):  # the wrist at the pose the model lumps it at
                assert emu.register(servo_id, "goal_position") == 2048
        torque = {s.id: None for s in WX200_SERVOS}
        eeprom = 0
        for p in _since(emu, t0):
            for w in p.writes:
                targets = [s.id for s in WX200_SERVOS if w.id in (s.id, s.secondary_id)]
                if w.name == "torque_enable":
                    for i in targets:
                        torque[i] = w.value
                elif w.name == "operating_mode":
                    eeprom += 1
                    assert all(torque[i] == 0 for i in targets), f"EEPROM written to ID {w.id} with its torque on"
        assert eeprom >= 4  # each start switched the joints' mode (3 -> 0, then 5 -> 0)


def test_a_port_name_other_than_the_one_given_is_never_opened(emu: DynamixelEmulator) -> None:
    opened = []

    def elsewhere(port: str) -> tuple[object, object]:
        handler, packet = sdk_handlers(port + "-other", 4.0)
        handler.openPort = lambda: opened.append(True) or True  # would record an open
        return handler, packet

    with pytest.raises(SerialPortError, match="only the port given is ever opened"):
        DynamixelArm(DynamixelArmConfig(port=emu.port), handlers=elsewhere).connect()
    assert not opened


def test_a_missing_sdk_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "dynamixel_sdk", None)
    with pytest.raises(MissingExtraError, match=r"wbc\[hardware\]"):
        sdk_handlers("/dev/ttyUSB0")


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
            SdkBus(Port(exc), object(), port="/dev/null-arm").open(1_000_000)


def test_connect_refuses_a_bus_that_is_not_the_wx200s(plant: SharedPlant) -> None:
    plant.reset()
    servos = tuple(dataclasses.replace(s, secondary_id=255) if s.id == 3 else s for s in WX200_SERVOS)
    with DynamixelEmulator(plant, DynamixelEmulatorConfig(servos=servos)) as emu:
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


# -- the law on the wire -----------------------------------------------------------------------------------------
def test_current_law_units_and_clamps() -> None:
    from wbc.hardware.dynamixel import WX200_ARM_JOINTS

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
        tau = np.array([0.3, 0.8, -0.4])
        cmd = MotorCommand(q=arm.read().q, dq=np.zeros(3), kp=np.zeros(3), kd=np.zeros(3), tau=tau)
        _keep_writing(arm, cmd, 0.1)
        t0 = time.monotonic()
        before = arm.bus_stats()
        _keep_writing(arm, cmd, 0.4)
        after = arm.bus_stats()
        plant_cmd, _ = emu.plant.arm_command()  # before close parks the arm
        emu.plant.step(0.002)  # one physics step, so that the plant's applied torque is the command's
        _keep_writing(arm, cmd, 0.03)
        state = arm.read()
    packets = [p for p in _since(emu, t0) if p.time < t0 + 0.35]
    reads = [p for p in packets if p.instruction == Instruction.SYNC_READ]
    joint_reads = [p for p in reads if p.reads[0].address == 126]
    status = [p for p in reads if p.reads[0].address in (70, 144)]
    goals = _goals(packets)
    assert {tuple(r.id for r in p.reads) for p in joint_reads} == {JOINTS}
    assert all(r.length == 10 for p in joint_reads for r in p.reads)
    assert {tuple(r.id for r in p.reads) for p in status} == {tuple(range(1, 8))}
    # one write per cycle; a failed read is retried, so reads may outnumber writes by the retries
    assert abs(len(goals) - (len(joint_reads) - (after.retries - before.retries))) <= 2
    assert 0.16 <= len(status) / len(goals) <= 0.24  # every 10th cycle one, taking turns: each every 20th
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
    assert after.states - before.states >= 40  # a fresh state per cycle (200 Hz, loaded machine)


def test_a_silent_writer_gets_damping_after_the_deadline(emu: DynamixelEmulator) -> None:
    with _arm(emu) as arm:
        cmd = _hold_with_offset(arm)
        _keep_writing(arm, cmd, 0.1)
        t0 = time.monotonic()
        time.sleep(0.2)  # no write: the deadline (50 ms) passes
        assert arm.bus_stats().deadline_trips == 1
        _keep_writing(arm, cmd, 0.1)
    goals = _timed_goals(_since(emu, t0))
    held = [g for t, g in goals if t < t0 + 0.04]
    quiet = [g for t, g in goals if t0 + 0.07 < t < t0 + 0.19]
    assert held and all(abs(g[1]) > 300 for g in held)  # 2 N m on the waist: ~417 units
    assert quiet and all(g == {1: 0, 2: 0, 4: 0} for g in quiet)  # damping of a still arm asks for nothing


def test_close_damps_then_parks_each_joint_in_a_position_hold(emu: DynamixelEmulator) -> None:
    with _arm(emu, close_damping=0.1) as arm:
        _keep_writing(arm, _hold_with_offset(arm), 0.1)
        t0 = time.monotonic()
    after = _since(emu, t0)
    damping = _goals(after)[1:]  # the first may be the cycle already under way when close was called
    assert len(damping) >= 5 and all(g == {1: 0, 2: 0, 4: 0} for g in damping)  # damping while closing
    park = [(w.id, w.name, w.value) for p in after if p.instruction == Instruction.WRITE for w in p.writes]
    for servo_id in JOINTS:
        steps = [(name, value) for i, name, value in park if i == servo_id]
        assert [n for n, _ in steps] == ["bus_watchdog", "torque_enable", "operating_mode", "goal_current",
                                         "goal_position", "torque_enable"]
        assert steps[1][1] == 0 and steps[2][1] == OperatingMode.CURRENT_BASED_POSITION and steps[-1][1] == 1
        assert steps[3][1] == round(1.0 / CURRENT_UNIT)  # park_current_a
        assert steps[4][1] == emu.register(servo_id, "present_position")  # held where it is
        assert emu.register(servo_id, "torque_enable") == 1 and emu.register(servo_id, "bus_watchdog") == 0
    cmd, _ = emu.plant.arm_command()
    assert (cmd.kp > 0).all()  # the plant holds the arm: a position loop, not a limp arm


# -- fault case 10: bounded retries, then the torque policy, read at the emulator ---------------------------------
def _fault_rig(emu: DynamixelEmulator, arm: DynamixelArm, fault: BusFault,
               value: object = None) -> tuple[float, list[LoggedPacket]]:
    """Hold with an offset (a known, non-zero current), inject `fault`, wait for the latch; (t_inject, packets)."""
    _keep_writing(arm, _hold_with_offset(arm), 0.15)
    t0 = time.monotonic()
    emu.inject(fault, value)
    end = time.monotonic() + 1.0
    while arm.fault is None and time.monotonic() < end:
        arm.write(_hold_with_offset(arm))  # the controller goes on asking for the hold
        arm.advance(0.005)
    assert arm.fault is not None, f"{fault} did not latch a fault"
    _keep_writing(arm, _hold_with_offset(arm), 0.1)
    return t0, _since(emu, t0)


def _after_latch(arm: DynamixelArm, packets: list[LoggedPacket]) -> list[LoggedPacket]:
    return [p for p in packets if p.time > arm.fault.time + 0.002]


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
    before = [p for p in packets if p.time <= arm.fault.time]
    failing = [p for p in before if p.instruction == Instruction.SYNC_READ and 4 in [r.id for r in p.reads]]
    assert arm.config.retries + 1 <= len(failing) <= arm.config.retries + 2  # bounded retries
    pings = [p.id for p in before if p.instruction == Instruction.PING]
    assert pings.count(4) in (1, 2, 3) and len(pings) <= 3 * len(failing[-1].reads)  # pinged up to three times
    later = _after_latch(arm, packets)
    reads = [tuple(r.id for r in p.reads) for p in later if p.instruction == Instruction.SYNC_READ]
    assert (1, 2) in reads and not [r for r in reads if 4 in r]  # the unreadable servo is left out of the reads
    goals = _goals(later)
    assert goals and all(g.get(1) == 0 and g.get(2) == 0 for g in goals)  # damping of a still arm: no current
    if kind == "no_answer":
        assert all(4 not in g for g in goals)  # it hears nothing; its watchdog stops it
    else:
        assert all(g[4] == 0 for g in goals)  # it hears but cannot be read: goal current 0, limp


@pytest.mark.parametrize("fault,value,bits", [(BusFault.OVERLOAD, 4, HW_OVERLOAD),
                                              (BusFault.OVER_TEMPERATURE, (4, 85), HW_OVERHEATING)])
def test_a_hardware_alert_latches_with_its_bits_and_the_others_are_damped(
        emu: DynamixelEmulator, fault: BusFault, value: object, bits: int) -> None:
    with _arm(emu) as arm:
        t0, packets = _fault_rig(emu, arm, fault, value)
        assert arm.fault.kind == "hardware_error" and arm.fault.ids == (4,)
        status = arm.motor_status()
        assert status.motor_mode[3] == MODE_HARDWARE_ERROR | bits and status.hardware_error[3] == bits
        if fault is BusFault.OVER_TEMPERATURE:
            assert _until(lambda: arm.motor_status().motor_temperature[3] == 85)
    assert emu.register(4, "torque_enable") == 0  # the servo's own Shutdown
    later = _after_latch(arm, packets)
    goals = _goals(later)
    assert goals and all(g == {1: 0, 2: 0, 4: 0} for g in goals)
    failed = arm.bus_stats().failed_transfers
    assert failed <= 3  # an alert is no failed read: nothing to retry


def test_a_closed_port_latches_and_the_servos_watchdog_leaves_the_arm_limp(emu: DynamixelEmulator) -> None:
    with _arm(emu) as arm:
        _keep_writing(arm, _hold_with_offset(arm), 0.15)
        held, _ = emu.plant.arm_command()
        assert np.abs(held.tau).min() > 1.0  # the hold's current is on
        emu.inject(BusFault.PORT_CLOSED)
        assert _until(lambda: arm.fault is not None, 1.0)
        assert arm.fault.kind == "port_lost" and "LIMP" in arm.fault.policy
        assert arm.motor_status().motor_mode.tolist() == [MODE_PORT_LOST] * 7
        last = emu.packets()[-1].time
        # the bus watchdog (100 ms) zeroes the goal currents of the servos no one talks to any more
        assert _until(lambda: emu.register(4, "bus_watchdog") == -1, 1.0)
        tripped_after = time.monotonic() - last
    cmd, _ = emu.plant.arm_command()
    assert (cmd.tau == 0).all() and (cmd.kp == 0).all()  # limp, as the policy says
    assert emu.register(4, "torque_enable") == 1  # stopped by the watchdog, not switched off
    assert tripped_after < 0.1 + 0.1
