"""The Dynamixel emulator with dynamixel_sdk's packet handler, unmodified, as its client, and the plant behind it.

Most tests reach the emulator in process (`DynamixelEmulator(..., in_process=True)`, `in_process_handlers`) on a
`ManualClock`: each instruction the SDK writes is answered within the same call, and the SDK's reply timeout, a
bus watchdog or a reboot run on the test's clock. Every transfer therefore has one outcome on any machine at any
load, and a test that expects a timeout gets it after exactly its clock time. The pseudo-terminal that
``wbc hw emulate`` serves is checked too, with the SDK's own port handler, unmodified, and a latency timer of
500 ms: a reply timeout of a second, which only a hung machine misses. Its real-time figures (the round trip with
``byte_timing``, the plant's real-time factor) are printed by ``wbc bench arm``; the tests marked ``realtime`` check
them against the wall clock (``make test-realtime``).
"""

import termios
import time
from dataclasses import dataclass

import numpy as np
import pytest

from wbc.errors import ConfigError
from wbc.hardware.clock import ManualClock
from wbc.hardware.dynamixel import in_process_handlers
from wbc.hardware.dynamixel.control_table import HW_OVERHEATING, HW_OVERLOAD, XM430_W350, OperatingMode
from wbc.hardware.dynamixel.protocol import (
    ALERT,
    ERR_ACCESS,
    ERR_DATA_LENGTH,
    ERR_DATA_LIMIT,
    ERR_DATA_RANGE,
    ERR_RESULT_FAIL,
    Instruction,
)
from wbc.hardware.dynamixel.units import CURRENT_UNIT, TORQUE_CONSTANT, VELOCITY_UNIT, position_gains_to_pd
from wbc.hardware.dynamixel.wx200_bus import WX200_ARM_JOINTS, servo_spec
from wbc.hardware.emulators import BusFault, DynamixelEmulator, DynamixelEmulatorConfig, SharedPlant
from wbc.hardware.emulators.dynamixel import TICK_PERIOD
from wbc.hardware.emulators.servo import EmulatedServo
from wbc.types import MotorCommand

sdk = pytest.importorskip("dynamixel_sdk")

LATENCY_MS = 1.0  # the robot's latency timer (Interbotix's udev rule): a reply timeout of about 4 ms
PTY_LATENCY_MS = 500  # over the pty: a reply timeout of about a second, so no load makes an answer late
JOINT_IDS = (1, 2, 4)
REG = {name: XM430_W350[name].address for name in (
    "operating_mode", "drive_mode", "torque_enable", "hardware_error_status", "bus_watchdog", "goal_current",
    "goal_velocity", "goal_pwm",
    "goal_position", "present_current", "present_position", "present_temperature", "current_limit",
    "return_delay_time", "baud_rate")}


@dataclass
class Bus:
    emu: DynamixelEmulator
    plant: SharedPlant
    port: object
    ph: object
    clock: ManualClock | None = None

    # each returns what the SDK returns
    def ping(self, i):
        return self.ph.ping(self.port, i)

    def read(self, i, name, size):
        call = {1: self.ph.read1ByteTxRx, 2: self.ph.read2ByteTxRx, 4: self.ph.read4ByteTxRx}[size]
        value, result, error = call(self.port, i, REG[name])
        signed = value - (1 << (8 * size)) if value >= 1 << (8 * size - 1) else value
        return signed, result, error

    def write(self, i, name, size, value):
        call = {1: self.ph.write1ByteTxRx, 2: self.ph.write2ByteTxRx, 4: self.ph.write4ByteTxRx}[size]
        return call(self.port, i, REG[name], value & ((1 << (8 * size)) - 1))

    def sync_read(self, address=126, length=10, ids=JOINT_IDS):
        group = sdk.GroupSyncRead(self.port, self.ph, address, length)
        for i in ids:
            group.addParam(i)
        return group, group.txRxPacket()

    def timed(self, call):
        """(what `call()` returns, the clock time it took [s])."""
        t0 = self.clock.now()
        out = call()
        return out, self.clock.now() - t0

    def sync_write(self, name, size, values):
        group = sdk.GroupSyncWrite(self.port, self.ph, REG[name], size)
        for i, v in values.items():
            group.addParam(i, list((v & ((1 << (8 * size)) - 1)).to_bytes(size, "little")))
        return group.txPacket()

    def current_mode(self, ids=JOINT_IDS):
        for i in ids:
            assert self.write(i, "operating_mode", 1, OperatingMode.CURRENT) == (0, 0)
            assert self.write(i, "torque_enable", 1, 1) == (0, 0)


def _timeout_s(port, length):
    """The reply timeout the port sets for an answer of `length` bytes [s] (the SDK's formula)."""
    return (port.tx_time_per_byte * length + 2.0 * port.latency_ms + 2.0) * 1e-3


@pytest.fixture(scope="module")
def plant():
    with SharedPlant() as p:
        yield p


def _stand(plant):
    plant.reset()
    legs = plant.sim.desc.leg_nominal_q
    plant.write_legs(MotorCommand.hold(legs, 60.0, 2.0))  # the trunk stands while the arm is tested


@pytest.fixture
def bus(plant):
    _stand(plant)
    clock = ManualClock()
    emu = DynamixelEmulator(plant, clock=clock, in_process=True).start()
    port, ph = in_process_handlers(emu.port, emu, clock, LATENCY_MS)
    assert port.openPort()
    yield Bus(emu, plant, port, ph, clock)
    port.closePort()
    emu.close()
    assert emu.failure is None


@pytest.fixture
def pty_bus(plant, monkeypatch):
    """The emulator on its pseudo-terminal, the SDK's own port handler on it (reply timeout about 1 s)."""
    monkeypatch.setattr(sdk.port_handler, "LATENCY_TIMER", PTY_LATENCY_MS)
    _stand(plant)
    emu = DynamixelEmulator(plant).start()
    port = sdk.PortHandler(emu.port)
    assert port.openPort()
    yield Bus(emu, plant, port, sdk.PacketHandler(2.0))
    try:
        port.closePort()
    except (termios.error, OSError):
        pass  # the port-closed fault left nothing to close
    emu.close()
    assert emu.failure is None


# -- protocol ------------------------------------------------------------------------------------------------------


def test_every_servo_answers_a_ping_with_the_xm430_model_number(bus):
    for i in range(1, 8):
        assert bus.timed(lambda i=i: bus.ping(i)) == ((1020, sdk.COMM_SUCCESS, 0), 0.0)  # answered in the call
    (_, result, _), took = bus.timed(lambda: bus.ping(9))
    assert result == sdk.COMM_RX_TIMEOUT  # nobody has ID 9: the reply timeout of a 14-byte answer, on the clock
    assert took == pytest.approx(_timeout_s(bus.port, 11), abs=2e-6)  # the SDK times a ping as 11 bytes
    assert [p.instruction for p in bus.emu.packets()][-1] == Instruction.PING


def test_present_registers_read_the_plant_in_the_joint_convention(bus):
    q, _, _ = bus.plant.read_arm()
    for joint in WX200_ARM_JOINTS:
        ticks, result, error = bus.read(joint.servo_id, "present_position", 4)
        assert (result, error) == (0, 0)
        assert ticks == joint.to_ticks(q[joint.house_index - 12])
    assert bus.read(3, "present_position", 4)[0] == bus.read(2, "present_position", 4)[0]  # the shadow agrees
    group, result = bus.sync_read()
    assert result == sdk.COMM_SUCCESS
    for joint in WX200_ARM_JOINTS:
        assert group.getData(joint.servo_id, 132, 4) == joint.to_ticks(q[joint.house_index - 12])
        assert group.getData(joint.servo_id, 126, 2) == 0  # torque off: no current
    fast = sdk.GroupSyncRead(bus.port, bus.ph, 126, 10)
    for i in JOINT_IDS:
        fast.addParam(i)
    assert fast.fastSyncRead() == sdk.COMM_SUCCESS
    assert [fast.getData(i, 132, 4) for i in JOINT_IDS] == [group.getData(i, 132, 4) for i in JOINT_IDS]


def test_a_log_size_of_zero_keeps_no_log_and_still_serves(plant):
    """``wbc hw emulate`` runs its emulators without a log: a long one stalls the answers in garbage collections."""
    clock = ManualClock()
    with DynamixelEmulator(plant, DynamixelEmulatorConfig(log_size=0), clock=clock, in_process=True) as emu:
        port, ph = in_process_handlers(emu.port, emu, clock, LATENCY_MS)
        assert port.openPort()
        bus = Bus(emu, plant, port, ph, clock)
        assert bus.ping(1) == (1020, sdk.COMM_SUCCESS, 0)
        assert bus.sync_write("goal_current", 2, {1: 10}) == sdk.COMM_SUCCESS
        assert emu.register(1, "goal_current") == 10
        assert emu.packets() == []
        assert emu.stats.packets == 2  # counted all the same
    assert emu.failure is None


def test_sync_write_of_goal_current_reaches_the_plant_and_the_log(bus):
    bus.current_mode()
    assert bus.sync_write("goal_current", 2, {1: 100, 2: -200, 4: 300}) == sdk.COMM_SUCCESS
    assert bus.emu.register(4, "goal_current") == 300  # executed within the SDK's call
    cmd, _ = bus.plant.arm_command()
    nm = CURRENT_UNIT * TORQUE_CONSTANT
    # the shoulder's shadow (ID 3, Secondary ID 2, reverse) takes ID 2's goal and pushes the same way: twice the torque
    np.testing.assert_allclose(cmd.tau, [100 * nm, -400 * nm, 300 * nm])
    assert (cmd.kp == 0).all() and (cmd.kd == 0).all()
    assert bus.emu.register(3, "goal_current") == -200
    last = [p for p in bus.emu.packets() if p.instruction == Instruction.SYNC_WRITE][-1]
    assert [(w.id, w.name, w.value) for w in last.writes] == [(1, "goal_current", 100), (2, "goal_current", -200),
                                                              (4, "goal_current", 300)]


def test_a_sync_read_is_logged_with_the_values_the_plant_gave(bus):
    """Each answer's registers are logged decoded, signed where the control table says, as the SDK received them."""
    bus.current_mode()
    assert bus.sync_write("goal_current", 2, {1: 300, 2: 200, 4: -500}) == sdk.COMM_SUCCESS
    bus.plant.step(0.05)  # the arm moves under those torques: velocities and currents of both signs
    q, dq, tau = bus.plant.read_arm()
    group, result = bus.sync_read()
    assert result == sdk.COMM_SUCCESS
    logged = [p for p in bus.emu.packets() if p.instruction == Instruction.SYNC_READ][-1]
    names = ("present_current", "present_velocity", "present_position")
    assert [(a.id, a.name) for a in logged.answers] == [(i, name) for i in JOINT_IDS for name in names]
    for joint in WX200_ARM_JOINTS:
        i, j, servos = joint.servo_id, joint.house_index - 12, len(joint.servo_ids)
        assert logged.answered("present_position", i) == [joint.to_ticks(q[j])]
        assert logged.answered("present_velocity", i) == [round(joint.sign * dq[j] / VELOCITY_UNIT)]
        amps = joint.sign * tau[j] / servos / TORQUE_CONSTANT
        assert logged.answered("present_current", i) == [round(amps / CURRENT_UNIT)]
        for name in names:  # what the SDK took off the wire, read as the register's two's complement
            reg = XM430_W350[name]
            assert logged.answered(name, i) == [reg.decode(reg.encode(group.getData(i, reg.address, reg.size)))]
    assert min(logged.answered("present_velocity")) < 0 < max(logged.answered("present_velocity"))
    assert min(logged.answered("present_current")) < 0 < max(logged.answered("present_current"))
    current, _, _ = bus.read(4, "present_current", 2)
    last = bus.emu.packets()[-1]
    assert last.instruction == Instruction.READ and last.answered("present_current") == [current]
    assert [(a.id, a.address) for a in last.answers] == [(4, REG["present_current"])]
    assert bus.sync_write("goal_current", 2, {1: 0, 2: 0, 4: 0}) == sdk.COMM_SUCCESS
    assert bus.emu.packets()[-1].answers == ()  # a write's status carries no register


def test_the_shadow_acts_on_writes_to_the_shoulder_and_never_answers_for_it(bus):
    packets, statuses = bus.emu.stats.packets, bus.emu.stats.statuses
    assert bus.write(2, "goal_position", 4, 1500) == (0, 0)
    assert bus.emu.register(3, "goal_position") == 1500 and bus.emu.register(2, "goal_position") == 1500
    assert bus.read(2, "goal_position", 4)[:2] == (1500, 0)
    # one status per transfer, from ID 2 only: the shadow never answers for it
    assert bus.emu.stats.statuses - statuses == bus.emu.stats.packets - packets == 2
    assert bus.ping(3) == (1020, 0, 0)  # under its own ID the shadow answers


def test_reverse_drive_mode_mirrors_the_shadow_and_cancels_its_torque_when_undone(bus):
    shoulder = bus.read(2, "present_position", 4)[0]
    assert bus.write(3, "drive_mode", 1, 0) == (0, 0)  # the shadow back to normal mode
    assert bus.read(3, "present_position", 4)[0] == pytest.approx(4096 - shoulder, abs=1)
    bus.current_mode((2,))  # ID 2 (and so the shadow, through its Secondary ID) in current mode, torque on
    assert bus.write(2, "goal_current", 2, 300) == (0, 0)
    assert bus.emu.register(3, "goal_current") == 300
    cmd, _ = bus.plant.arm_command()
    assert cmd.tau[1] == pytest.approx(0.0, abs=1e-12)  # the mirrored servo now pushes against the primary


def test_eeprom_is_refused_while_the_torque_is_on(bus):
    assert bus.write(1, "torque_enable", 1, 1) == (0, 0)
    assert bus.write(1, "operating_mode", 1, OperatingMode.CURRENT) == (0, ERR_ACCESS)
    assert bus.read(1, "operating_mode", 1)[0] == OperatingMode.POSITION
    assert bus.write(1, "goal_position", 4, 2100) == (0, 0)  # RAM is fine
    assert bus.write(1, "torque_enable", 1, 0) == (0, 0)
    assert bus.write(1, "operating_mode", 1, OperatingMode.CURRENT) == (0, 0)


def test_value_errors_name_what_is_wrong(bus):
    assert bus.write(4, "goal_current", 2, 1300) == (0, ERR_DATA_RANGE)  # beyond the register's range
    assert bus.write(4, "current_limit", 2, 500) == (0, 0)
    assert bus.write(4, "goal_current", 2, 600) == (0, ERR_DATA_LIMIT)  # beyond Current Limit
    assert bus.write(4, "goal_position", 4, 4000) == (0, ERR_DATA_LIMIT)  # beyond the elbow's 3106 in mode 3
    assert bus.write(4, "operating_mode", 1, 2) == (0, ERR_DATA_RANGE)  # no mode 2
    assert bus.write(4, "present_position", 4, 2048) == (0, ERR_ACCESS)  # read-only
    assert bus.ph.write1ByteTxRx(bus.port, 4, REG["goal_position"], 1) == (0, ERR_DATA_LENGTH)


# -- hardware errors, watchdog ---------------------------------------------------------------------------------------


def test_overload_sets_the_alert_bit_in_every_status_until_a_reboot(bus):
    bus.current_mode((4,))
    bus.emu.inject(BusFault.OVERLOAD, 4)
    bus.clock.advance(TICK_PERIOD)  # the servo's own time: it detects the overload
    assert bus.emu.register(4, "hardware_error_status") == HW_OVERLOAD
    assert bus.ping(4) == (1020, sdk.COMM_SUCCESS, ALERT)
    assert bus.read(4, "hardware_error_status", 1) == (HW_OVERLOAD, sdk.COMM_SUCCESS, ALERT)
    assert bus.read(4, "torque_enable", 1)[0] == 0  # overload is in Shutdown: the torque went off
    assert bus.write(4, "torque_enable", 1, 1) == (0, ALERT | ERR_RESULT_FAIL)
    assert bus.ping(1) == (1020, 0, 0)
    bus.emu.clear(BusFault.OVERLOAD)
    assert bus.read(4, "hardware_error_status", 1) == (HW_OVERLOAD, 0, ALERT)  # latched in the servo
    assert bus.ph.reboot(bus.port, 4) == (0, ALERT)  # the answer still carries the alert; then the RAM is reset
    assert bus.emu.register(4, "hardware_error_status") == 0
    # while it reboots the servo hears nothing, for exactly `reboot_time` of the clock
    bus.clock.advance(bus.emu.config.reboot_time - 0.005)
    assert bus.read(4, "hardware_error_status", 1)[1] == sdk.COMM_RX_TIMEOUT
    bus.clock.advance(0.005)
    assert bus.read(4, "hardware_error_status", 1) == (0, 0, 0)
    assert bus.write(4, "torque_enable", 1, 1) == (0, 0)


def test_over_temperature_reads_hot_and_shuts_the_servo_down(bus):
    bus.emu.inject(BusFault.OVER_TEMPERATURE, (2, 85))
    bus.clock.advance(TICK_PERIOD)
    assert bus.emu.register(2, "hardware_error_status") == HW_OVERHEATING
    assert bus.read(2, "present_temperature", 1) == (85, 0, ALERT)
    assert bus.read(2, "hardware_error_status", 1)[0] == HW_OVERHEATING
    assert bus.read(1, "present_temperature", 1) == (40, 0, 0)


def test_bus_watchdog_stops_a_servo_left_alone_and_is_cleared_by_writing_zero(bus):
    bus.current_mode((4,))
    assert bus.write(4, "goal_current", 2, 300) == (0, 0)
    assert bus.write(4, "bus_watchdog", 1, 10) == (0, 0)  # 200 ms
    for _ in range(20):  # talking every 190 ms for 3.8 s keeps it fed
        bus.clock.advance(0.19)
        assert bus.sync_read()[1] == sdk.COMM_SUCCESS
    assert bus.emu.register(4, "bus_watchdog") == 10
    assert bus.plant.arm_command()[0].tau[2] > 0
    bus.clock.advance(0.2 - 1.5 * TICK_PERIOD)  # silence, a tick short of the watchdog
    assert bus.emu.register(4, "bus_watchdog") == 10 and bus.plant.arm_command()[0].tau[2] > 0
    bus.clock.advance(2 * TICK_PERIOD)  # 200 ms of silence (within a tick): it trips, and the plant sees it
    assert bus.emu.register(4, "bus_watchdog") == -1 and bus.plant.arm_command()[0].tau[2] == 0.0
    assert bus.read(4, "bus_watchdog", 1)[0] == -1
    assert bus.read(4, "goal_current", 2)[0] == 0
    assert bus.plant.arm_command()[0].tau[2] == 0.0
    assert bus.read(4, "torque_enable", 1)[0] == 1  # stopped, not torque-off
    assert bus.write(4, "goal_current", 2, 300) == (0, ERR_DATA_RANGE)  # goals are read-only now
    assert bus.write(4, "bus_watchdog", 1, 10) == (0, ERR_DATA_RANGE)  # only 0 clears it
    assert bus.write(4, "bus_watchdog", 1, 0) == (0, 0)
    assert bus.write(4, "goal_current", 2, 300) == (0, 0)


# -- faults as the SDK sees them -------------------------------------------------------------------------------------


def test_a_silent_id_fails_the_whole_sync_read(bus):
    bus.emu.inject(BusFault.SILENT_ID, 2)
    group = sdk.GroupSyncRead(bus.port, bus.ph, 126, 10)
    for i in JOINT_IDS:
        group.addParam(i)
    result, took = bus.timed(group.txRxPacket)
    assert result == sdk.COMM_RX_TIMEOUT
    assert took == pytest.approx(_timeout_s(bus.port, 3 * 21), abs=2e-6)  # the sync read's one timeout, no more
    assert not any(group.isAvailable(i, 132, 4) for i in JOINT_IDS)
    assert bus.ph.ping(bus.port, 2)[1] == sdk.COMM_RX_TIMEOUT
    # a fast sync read's chain stops at the silent servo: ID 1's block arrives, the packet never completes
    assert group.fastSyncRead() == sdk.COMM_RX_CORRUPT
    assert not group.isAvailable(1, 132, 4)
    bus.emu.clear(BusFault.SILENT_ID)
    assert group.txRxPacket() == sdk.COMM_SUCCESS
    assert group.fastSyncRead() == sdk.COMM_SUCCESS


def test_bad_crc_replies_are_corrupt_to_the_sdk(bus):
    bus.emu.inject(BusFault.BAD_CRC, 4)
    assert bus.ph.read4ByteTxRx(bus.port, 4, REG["present_position"])[1] == sdk.COMM_RX_CORRUPT
    assert bus.read(1, "present_position", 4)[1] == sdk.COMM_SUCCESS
    group = sdk.GroupSyncRead(bus.port, bus.ph, 126, 10)
    for i in JOINT_IDS:
        group.addParam(i)
    assert group.txRxPacket() == sdk.COMM_RX_CORRUPT
    bus.emu.clear()
    assert group.txRxPacket() == sdk.COMM_SUCCESS


def test_a_late_answer_times_out_then_arrives_after_the_timeout_on_the_clock(bus):
    timeout = _timeout_s(bus.port, 15)  # a 4-byte read's answer: 15 bytes
    late = 2 * timeout
    bus.emu.inject(BusFault.LATE_ANSWER, (4, late))
    (_, result, _), took = bus.timed(lambda: bus.read(4, "present_position", 4))
    assert result == sdk.COMM_RX_TIMEOUT and took == pytest.approx(timeout, abs=2e-6)
    assert bus.read(1, "present_position", 4)[1] == sdk.COMM_SUCCESS  # the others answer on time
    assert bus.port.getBytesAvailable() == 0  # the elbow's answer is still on its way ...
    bus.clock.advance(late - took - 1e-4)
    assert bus.port.getBytesAvailable() == 0
    bus.clock.advance(2e-4)
    assert bus.port.getBytesAvailable() == 15  # ... and arrives `late` after its request, as the fault says
    bus.port.clearPort()
    bus.emu.clear(BusFault.LATE_ANSWER)
    assert bus.read(4, "present_position", 4)[1:] == (sdk.COMM_SUCCESS, 0)


def test_a_closed_port_raises_termios_error_in_the_sdk(bus):
    bus.emu.inject(BusFault.PORT_CLOSED)
    assert bus.emu.port_closed
    with pytest.raises(termios.error):
        bus.ph.ping(bus.port, 1)
    bus.emu.register(4, "bus_watchdog")  # the servos are still there, behind the lost adapter


def test_a_client_at_another_baud_rate_is_not_heard(bus):
    assert bus.port.setBaudRate(57600)
    unheard = bus.emu.stats.unheard
    assert bus.ph.ping(bus.port, 1)[1] == sdk.COMM_RX_TIMEOUT
    assert bus.emu.stats.unheard == unheard + 1
    assert bus.port.setBaudRate(1_000_000)
    assert bus.ping(1)[1] == sdk.COMM_SUCCESS


# -- the pseudo-terminal that ``wbc hw emulate`` serves ---------------------------------------------------------------


def test_the_pty_serves_the_unmodified_sdk(pty_bus):
    bus = pty_bus
    assert bus.ping(1) == (1020, sdk.COMM_SUCCESS, 0)
    q, _, _ = bus.plant.read_arm()
    group, result = bus.sync_read()
    assert result == sdk.COMM_SUCCESS
    for joint in WX200_ARM_JOINTS:
        assert group.getData(joint.servo_id, 132, 4) == joint.to_ticks(q[joint.house_index - 12])
    bus.current_mode((4,))
    assert bus.sync_write("goal_current", 2, {4: 300}) == sdk.COMM_SUCCESS
    assert bus.read(4, "goal_current", 2) == (300, 0, 0)  # a later answer: the write was executed before it
    assert bus.plant.arm_command()[0].tau[2] == pytest.approx(300 * CURRENT_UNIT * TORQUE_CONSTANT)
    assert [p.instruction for p in bus.emu.packets()][-2:] == [Instruction.SYNC_WRITE, Instruction.READ]


def test_a_closed_pty_raises_termios_error_in_the_sdk(pty_bus):
    pty_bus.emu.inject(BusFault.PORT_CLOSED)
    assert pty_bus.emu.port_closed
    with pytest.raises(termios.error):
        pty_bus.ph.ping(pty_bus.port, 1)


# -- the plant behind the bus ------------------------------------------------------------------------------------------


def test_goal_current_on_the_elbow_moves_the_arm_as_the_sign_convention_says(bus):
    for i in (1, 2):  # waist and shoulder hold where they are
        assert bus.write(i, "torque_enable", 1, 1) == (0, 0)
    bus.current_mode((4,))
    start = bus.read(4, "present_position", 4)[0]
    for goal, direction in ((-500, -1), (500, 1)):
        assert bus.write(4, "goal_current", 2, goal) == (0, 0)
        assert bus.emu.register(4, "goal_current") == goal  # before the physics runs
        q0 = bus.plant.read_arm()[0][2]
        bus.plant.step(0.3)
        q1 = bus.plant.read_arm()[0][2]
        # -500 units = -1.3 A = -2.4 N m folds the elbow open, well beyond the forearm's ~0.7 N m of gravity
        assert direction * (q1 - q0) > 0.1
        ticks = bus.read(4, "present_position", 4)[0]
        assert ticks == WX200_ARM_JOINTS[2].to_ticks(q1)
        current, _, _ = bus.read(4, "present_current", 2)
        assert np.sign(current) == direction or abs(current) < 10  # at a joint stop the torque is the stop's
    assert bus.read(4, "present_position", 4)[0] != start


def test_current_based_position_mode_bounds_the_torque_by_the_goal_current(bus):
    assert bus.write(4, "operating_mode", 1, OperatingMode.CURRENT_BASED_POSITION) == (0, 0)
    goal = bus.read(4, "present_position", 4)[0] - 600  # 0.9 rad away
    assert bus.write(4, "goal_current", 2, 60) == (0, 0)
    assert bus.write(4, "goal_position", 4, goal) == (0, 0)
    assert bus.write(4, "torque_enable", 1, 1) == (0, 0)
    cmd, tau_max = bus.plant.arm_command()
    kp, _ = position_gains_to_pd(800, 0)
    assert cmd.kp[2] == pytest.approx(kp)
    assert tau_max[2] == pytest.approx(60 * CURRENT_UNIT * TORQUE_CONSTANT)
    bus.plant.step(0.1)
    _, _, tau = bus.plant.read_arm()
    assert abs(tau[2]) <= tau_max[2] + 1e-9  # the PD would ask 17 N m; the servo gives 0.29
    assert abs(bus.read(4, "present_current", 2)[0]) <= 61


def test_the_shared_plant_keeps_both_commands_while_it_steps():
    with SharedPlant() as plant:
        legs = plant.sim.desc.leg_nominal_q
        plant.write_legs(MotorCommand.hold(legs, 60.0, 2.0))
        plant.write_arm(MotorCommand.hold(np.array([0.0, -1.3, 1.5]), 20.0, 0.5))
        t0 = plant.time
        for _ in range(150):
            plant.step(0.002)
        assert plant.time - t0 == pytest.approx(0.3)
        state = plant.read()
        assert state.num_joints == 15
        np.testing.assert_allclose(state.q[12:], [0.0, -1.3, 1.5], atol=0.05)
        assert plant.read_legs().num_joints == 12 and plant.legs.read().num_joints == 12
        assert plant.base_truth().base_position_in_world[2] > 0.2  # standing


@pytest.mark.realtime
def test_the_shared_plant_steps_in_real_time_and_keeps_both_commands():
    with SharedPlant() as plant:
        legs = plant.sim.desc.leg_nominal_q
        plant.write_legs(MotorCommand.hold(legs, 60.0, 2.0))
        plant.write_arm(MotorCommand.hold(np.array([0.0, -1.3, 1.5]), 20.0, 0.5))
        plant.start_realtime()
        t0, w0 = plant.time, time.monotonic()
        time.sleep(0.3)
        plant.stop_realtime()
        elapsed = time.monotonic() - w0
        assert 0.5 * elapsed < plant.time - t0 <= elapsed + 0.02
        assert plant.failure is None
        state = plant.read()
        assert state.num_joints == 15
        np.testing.assert_allclose(state.q[12:], [0.0, -1.3, 1.5], atol=0.05)
        assert plant.read_legs().num_joints == 12 and plant.legs.read().num_joints == 12
        assert plant.base_truth().base_position_in_world[2] > 0.2  # standing


def test_servo_rules_without_a_bus():
    servo = EmulatedServo(servo_spec("elbow"), now=0.0)
    assert servo.write(REG["torque_enable"], b"\x01") == 0
    assert servo.write(REG["bus_watchdog"], b"\x05") == 0
    assert servo.watchdog_deadline() == pytest.approx(0.1)
    assert not servo.tick(0.09)
    servo.heard(0.05)
    assert not servo.tick(0.14) and servo.tick(0.151)
    assert servo.watchdog_tripped and servo.get("goal_position") == servo.get("present_position")


def test_config_refuses_a_joint_without_its_servo():
    with pytest.raises(ConfigError, match="not on the bus"):
        DynamixelEmulatorConfig(servos=(servo_spec(1),))


def test_bulk_read_and_write_plain_and_fast(bus):
    writer = sdk.GroupBulkWrite(bus.port, bus.ph)
    writer.addParam(5, REG["goal_position"], 4, list((2300).to_bytes(4, "little")))  # the wrist: no model joint
    writer.addParam(1, REG["torque_enable"], 1, [1])
    assert writer.txPacket() == sdk.COMM_SUCCESS
    assert bus.emu.register(1, "torque_enable") == 1
    assert bus.write(5, "torque_enable", 1, 1) == (0, 0)
    reader = sdk.GroupBulkRead(bus.port, bus.ph)
    reader.addParam(5, REG["present_position"], 4)
    reader.addParam(1, REG["torque_enable"], 1)
    assert reader.txRxPacket() == sdk.COMM_SUCCESS
    assert (reader.getData(5, REG["present_position"], 4), reader.getData(1, REG["torque_enable"], 1)) == (2300, 1)
    assert reader.fastBulkRead() == sdk.COMM_SUCCESS
    assert reader.getData(5, REG["present_position"], 4) == 2300
    logged = [p for p in bus.emu.packets() if p.instruction == Instruction.BULK_WRITE][-1]
    assert logged.written("goal_position", 5) == [2300] and logged.written("torque_enable", 1) == [1]


def test_each_operating_mode_becomes_the_documented_command(bus):
    from wbc.hardware.dynamixel.units import STALL_TORQUE, VELOCITY_UNIT, velocity_gain_to_kd

    assert bus.write(1, "operating_mode", 1, OperatingMode.VELOCITY) == (0, 0)
    assert bus.write(4, "operating_mode", 1, OperatingMode.PWM) == (0, 0)
    for i in (1, 2, 4):
        assert bus.write(i, "torque_enable", 1, 1) == (0, 0)
    assert bus.write(1, "goal_velocity", 4, -50) == (0, 0)
    assert bus.write(4, "goal_pwm", 2, 442) == (0, 0)
    assert bus.write(2, "goal_position", 4, 1300) == (0, 0)  # ID 2 and its shadow: position mode, twice the gain
    assert bus.emu.register(2, "goal_position") == 1300
    cmd, tau_max = bus.plant.arm_command()
    assert cmd.kd[0] == pytest.approx(velocity_gain_to_kd(100)) and cmd.dq[0] == pytest.approx(-50 * VELOCITY_UNIT)
    kp, _ = position_gains_to_pd(800, 0)
    assert cmd.kp[1] == pytest.approx(2 * kp) and cmd.q[1] == pytest.approx(WX200_ARM_JOINTS[1].to_rad(1300))
    assert cmd.tau[2] == pytest.approx(STALL_TORQUE * 442 / 885) and cmd.kp[2] == 0
    assert tau_max[1] == pytest.approx(2 * 1193 * CURRENT_UNIT * TORQUE_CONSTANT)
    assert bus.write(1, "torque_enable", 1, 0) == (0, 0)
    assert bus.plant.arm_command()[0].kd[0] == 0  # torque off: nothing


def test_byte_timing_answers_after_the_return_delay_and_the_wire_time_on_the_clock(plant):
    plant.reset()
    clock = ManualClock()
    with DynamixelEmulator(plant, DynamixelEmulatorConfig(byte_timing=True), clock=clock, in_process=True) as emu:
        port, ph = in_process_handlers(emu.port, emu, clock, 16.0)
        assert port.openPort()
        bus = Bus(emu, plant, port, ph, clock)
        for i in JOINT_IDS:  # 250 x 2 us = 0.5 ms before each answer
            assert bus.write(i, "return_delay_time", 1, 250) == (0, 0)
        group = sdk.GroupSyncRead(port, ph, 126, 10)
        for i in JOINT_IDS:
            group.addParam(i)
        for _ in range(3):
            assert bus.timed(group.txRxPacket) == (sdk.COMM_SUCCESS, pytest.approx(3 * (0.5e-3 + 21 * 10 / 1e6)))
        # at 57600 bit/s the three answers take their bytes' time at that rate
        for i in JOINT_IDS:  # the shoulder's shadow follows ID 2's write
            assert bus.write(i, "baud_rate", 1, 1) == (0, 0)  # 57600 bit/s, heard from the next packet on
        assert port.setBaudRate(57600)
        assert bus.timed(group.txRxPacket) == (sdk.COMM_SUCCESS, pytest.approx(3 * (0.5e-3 + 21 * 10 / 57600)))


@pytest.mark.realtime
def test_byte_timing_answers_after_the_return_delay_and_the_wire_time(plant, monkeypatch):
    monkeypatch.setattr(sdk.port_handler, "LATENCY_TIMER", 16)
    plant.reset()
    with DynamixelEmulator(plant, DynamixelEmulatorConfig(byte_timing=True)) as emu:
        port = sdk.PortHandler(emu.port)
        assert port.openPort()
        ph = sdk.PacketHandler(2.0)
        for i in JOINT_IDS:  # 250 x 2 us = 0.5 ms before each answer
            assert ph.write1ByteTxRx(port, i, XM430_W350["return_delay_time"].address, 250) == (0, 0)
        group = sdk.GroupSyncRead(port, ph, 126, 10)
        for i in JOINT_IDS:
            group.addParam(i)
        times = []
        for _ in range(5):
            t0 = time.perf_counter()
            assert group.txRxPacket() == sdk.COMM_SUCCESS
            times.append(time.perf_counter() - t0)
        port.closePort()
    # three answers of 21 bytes at 1 Mbit/s (0.21 ms each) after 0.5 ms each: at least 2.1 ms
    assert min(times) >= 3 * (0.5e-3 + 21 * 10 / 1e6)


def test_one_physics_legs_over_udp_and_arm_over_the_bus(bus):
    import socket

    from wbc.hardware.emulators import UnitreeEmulator, UnitreeEmulatorConfig
    from wbc.hardware.unitree.command_codec import encode_command
    from wbc.hardware.unitree.layout import frame_layout
    from wbc.hardware.unitree.state_codec import decode_state

    bus.current_mode((4,))
    assert bus.write(4, "goal_current", 2, -500) == (0, 0)
    assert bus.emu.register(4, "goal_current") == -500
    layout = frame_layout("a1")
    legs = MotorCommand.hold(bus.plant.sim.desc.leg_nominal_q, 60.0, 2.0)
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="a1", mode="lockstep"), sim=bus.plant.legs) as legs_emu, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(2.0)
        elbow0, t0 = bus.plant.read_arm()[0][2], bus.plant.time
        for _ in range(100):  # 0.2 s of lockstep physics, driven by the leg wire alone
            sock.sendto(encode_command(layout, legs), legs_emu.address)
            frame, _ = sock.recvfrom(4096)
        state, _ = decode_state(layout, frame, time=0.0)
        assert legs_emu.failure is None
    assert bus.plant.time - t0 == pytest.approx(0.2)
    assert bus.plant.read_arm()[0][2] < elbow0 - 0.05  # the arm's command acted in the legs' steps
    np.testing.assert_allclose(state.q, bus.plant.read_legs().q, atol=1e-5)  # float32 on the wire
    assert bus.read(4, "present_position", 4)[0] == WX200_ARM_JOINTS[2].to_ticks(bus.plant.read_arm()[0][2])
