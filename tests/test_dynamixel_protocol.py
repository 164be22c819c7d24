"""The Dynamixel Protocol 2.0 codec against the e-Manual's golden value and against dynamixel_sdk's own bytes.

The SDK (unmodified) writes its packets into a pseudo-terminal; the test reads them off the other end and compares
them byte for byte with what `wbc.hardware.dynamixel` builds for the same request. Status packets go the other
way: ours are written into the pty and the SDK has to accept them and read the same data out of them.
"""

import os
import random
import select
import subprocess
import sys
import tty

import numpy as np
import pytest

from wbc.errors import PacketError, UnknownNameError
from wbc.hardware.dynamixel.control_table import XM430_W350
from wbc.hardware.dynamixel.crc import crc16
from wbc.hardware.dynamixel.packet import (
    HEADER,
    InstructionPacket,
    PacketReader,
    StatusPacket,
    build_fast_read_status,
    build_instruction,
    build_status,
    bulk_read_params,
    bulk_write_params,
    parse_bulk_read_params,
    parse_bulk_write_params,
    parse_fast_read_status,
    parse_packet,
    parse_sync_read_params,
    parse_sync_write_params,
    parse_write_params,
    ping_status_params,
    read_params,
    stuff,
    sync_read_params,
    sync_write_params,
    unstuff,
    write_params,
)
from wbc.hardware.dynamixel.protocol import ALERT, BROADCAST_ID, Instruction, describe_error
from wbc.hardware.dynamixel.units import (
    TORQUE_CONSTANT,
    current_to_units,
    position_gains_to_pd,
    rad_to_ticks,
    ticks_to_rad,
    units_to_velocity,
    velocity_to_units,
)
from wbc.hardware.dynamixel.wx200_bus import WX200_ARM_JOINTS, WX200_SERVOS, servo_spec

# -- pure codec ----------------------------------------------------------------------------------------------------


def test_crc_matches_the_e_manual_golden_value():
    assert crc16(bytes.fromhex("FF FF FD 00 01 03 00 01")) == 0x4E19
    assert build_instruction(1, Instruction.PING) == bytes.fromhex("FF FF FD 00 01 03 00 01 19 4E")


def test_crc_can_be_continued_block_by_block():
    data = bytes(range(40))
    assert crc16(data[17:], crc16(data[:17])) == crc16(data)


@pytest.mark.parametrize("body, wire", [
    ("55 00 FF FF FD 01", "55 00 FF FF FD FD 01"),
    ("FF FF FD FD", "FF FF FD FD FD"),
    ("FF FF FD FF FF FD", "FF FF FD FD FF FF FD FD"),
    ("FF FF FF FD", "FF FF FF FD FD"),
    ("FF FD FF FF", "FF FD FF FF"),
])
def test_byte_stuffing_inserts_an_fd_after_every_header_pattern(body, wire):
    assert stuff(bytes.fromhex(body)) == bytes.fromhex(wire)
    assert unstuff(bytes.fromhex(wire)) == bytes.fromhex(body)


def test_byte_stuffing_round_trips_random_bodies_dense_in_ff_and_fd():
    rng = random.Random(3)
    for _ in range(2000):
        body = bytes(rng.choice((0xFF, 0xFD, 0x00, rng.randrange(256))) for _ in range(rng.randrange(1, 24)))
        wire = stuff(body)
        assert unstuff(wire) == body
        assert len(wire) - len(body) == _header_runs(body)


def _header_runs(body: bytes) -> int:
    return sum(body[k: k + 3] == b"\xff\xff\xfd" for k in range(len(body) - 2))


def test_a_stuffed_packet_counts_its_extra_bytes_in_len_and_parses_back():
    params = write_params(116, bytes.fromhex("00 FF FF FD"))
    raw = build_instruction(4, Instruction.WRITE, params)
    assert raw[5] | raw[6] << 8 == 1 + len(params) + 1 + 2  # INST, params, the inserted FD, CRC
    assert parse_packet(raw) == InstructionPacket(4, Instruction.WRITE, params)


@pytest.mark.parametrize("mangle, reason", [
    (lambda b: b[:-1], "short"),
    (lambda b: b + b"\x00", "length"),
    (lambda b: b[:8] + bytes([b[8] ^ 1]) + b[9:], "crc"),
    (lambda b: b"\xff\xff\xfe" + b[3:], "header"),
    (lambda b: b[:6], "short"),
])
def test_parse_rejects_damaged_packets_by_reason(mangle, reason):
    raw = build_status(2, 0, bytes(4))
    with pytest.raises(PacketError) as err:
        parse_packet(mangle(raw))
    assert err.value.reason == reason


def test_status_packet_carries_the_error_byte_apart_from_its_data():
    pkt = parse_packet(build_status(7, ALERT | 7, b"\x01\x02"))
    assert pkt == StatusPacket(7, 0x87, b"\x01\x02")
    assert describe_error(pkt.error) == "access error + hardware alert"
    assert describe_error(0) == "ok"


def test_packet_reader_cuts_a_stream_anywhere_and_skips_garbage():
    packets = [build_instruction(i, Instruction.WRITE, write_params(64, bytes([1]))) for i in (1, 2, 4)]
    stream = b"\x00\x13\xff" + packets[0] + b"\xff\xff" + packets[1] + packets[2]
    reader, out = PacketReader(), []
    for k in range(0, len(stream), 3):
        out += reader.feed(stream[k: k + 3])
    assert out == packets
    assert reader.dropped == 5 and reader.pending == 0


def test_parameter_codecs_round_trip():
    assert parse_write_params(write_params(102, b"\x10\x00")) == (102, b"\x10\x00")
    assert parse_sync_read_params(sync_read_params(126, 10, (1, 2, 4))) == (126, 10, (1, 2, 4))
    data = ((1, b"\x01\x00"), (2, b"\xff\xff"))
    assert parse_sync_write_params(sync_write_params(102, 2, data)) == (102, 2, data)
    items = ((1, 132, 4), (7, 70, 1))
    assert parse_bulk_read_params(bulk_read_params(items)) == items
    writes = ((1, 64, b"\x01"), (4, 116, b"\x00\x08\x00\x00"))
    assert parse_bulk_write_params(bulk_write_params(writes)) == writes
    with pytest.raises(PacketError):
        sync_write_params(102, 2, ((1, b"\x01"),))
    with pytest.raises(PacketError):
        parse_sync_write_params(b"\x66\x00\x02\x00\x01\x00")


def test_fast_read_status_chains_one_crc_per_block():
    blocks = ((0, 1, bytes(range(10))), (ALERT, 2, b"\xff\xff\xfd\x00" + bytes(6)), (0, 4, bytes(10)))
    raw = build_fast_read_status(blocks)
    assert parse_fast_read_status(raw, (10, 10, 10)) == blocks
    assert b"\xff\xff\xfd\xfd" not in raw  # a fast read answer is not stuffed
    assert raw[-2] | raw[-1] << 8 == crc16(raw[:-2])
    bad = bytearray(raw)
    bad[12] ^= 0x40  # inside the first block
    with pytest.raises(PacketError, match="ID 1"):
        parse_fast_read_status(bytes(bad), (10, 10, 10))


# -- control table, units, bus map ---------------------------------------------------------------------------------


def test_control_table_holds_the_addresses_the_arm_relies_on():
    expected = {"operating_mode": (11, 1), "secondary_id": (12, 1), "current_limit": (38, 2), "shutdown": (63, 1),
                "torque_enable": (64, 1), "hardware_error_status": (70, 1), "bus_watchdog": (98, 1),
                "goal_current": (102, 2), "goal_position": (116, 4), "present_current": (126, 2),
                "present_velocity": (128, 4), "present_position": (132, 4), "present_temperature": (146, 1)}
    for name, (address, size) in expected.items():
        assert (XM430_W350[name].address, XM430_W350[name].size) == (address, size)
    assert XM430_W350.at(128).name == "present_velocity" and XM430_W350.at(66) is None
    assert XM430_W350["current_limit"].eeprom and not XM430_W350["torque_enable"].eeprom
    assert XM430_W350["bus_watchdog"].decode(b"\xff") == -1
    assert XM430_W350["goal_current"].encode(-5) == b"\xfb\xff"
    # one sync read covers present current, velocity and position: 10 contiguous bytes from 126
    assert [XM430_W350.at(a).name for a in (126, 128, 132, 135)] == ["present_current", "present_velocity",
                                                                    "present_position", "present_position"]
    with pytest.raises(UnknownNameError, match="goal_current"):
        XM430_W350["goal_torque"]


def test_units_convert_as_the_e_manual_says():
    assert rad_to_ticks(0.0) == 2048 and rad_to_ticks(np.pi) == 4096
    assert ticks_to_rad(1024) == pytest.approx(-np.pi / 2)
    assert units_to_velocity(1) == pytest.approx(0.229 * 2 * np.pi / 60)
    assert velocity_to_units(units_to_velocity(-37)) == -37
    assert current_to_units(1.0) == 372  # 1 A / 2.69 mA
    assert 4.1 / TORQUE_CONSTANT == pytest.approx(2.3)
    kp, kd = position_gains_to_pd(800, 0)
    assert 15 < kp < 25 and kd == 0.0


def test_wx200_bus_map_matches_interbotix_and_the_model():
    from wbc.robots.registry import get_robot
    from wbc.robots.wx200 import WX200_NOMINAL_Q

    assert [(s.name, s.id) for s in WX200_SERVOS] == [("waist", 1), ("shoulder", 2), ("shoulder_shadow", 3),
                                                      ("elbow", 4), ("wrist_angle", 5), ("wrist_rotate", 6),
                                                      ("gripper", 7)]
    shadow, elbow = servo_spec("shoulder_shadow"), servo_spec(4)
    assert shadow.secondary_id == 2 and shadow.reverse and elbow.reverse and not servo_spec("shoulder").reverse
    with pytest.raises(UnknownNameError):
        servo_spec(9)
    arm = get_robot("a1-wx200", "actuated").arm
    by_name = {j.name: j for j in arm.joints}
    elbow_map = WX200_ARM_JOINTS[2]
    # the model's elbow range is the EEPROM's 819..3106 ticks; its shoulder top is 3333
    assert elbow_map.to_ticks(by_name["elbow"].lower) == 819 and elbow_map.to_ticks(by_name["elbow"].upper) == 3106
    assert WX200_ARM_JOINTS[1].to_ticks(by_name["shoulder"].upper) in (3333, 3334)
    for joint, q in zip(WX200_ARM_JOINTS, WX200_NOMINAL_Q, strict=True):
        spec = servo_spec(joint.servo_id)
        assert spec.min_position <= joint.to_ticks(q) <= spec.max_position
        assert joint.to_rad(joint.to_ticks(q)) == pytest.approx(q, abs=1e-3)
    assert [j.house_index for j in WX200_ARM_JOINTS] == [12, 13, 14]


def test_the_bus_package_imports_without_the_sdk_mujoco_or_torch():
    code = ("import sys\nsys.modules['dynamixel_sdk'] = None\nimport wbc.hardware.dynamixel\n"
            "print(' '.join(sorted(m for m in sys.modules if m.split('.')[0] in ('mujoco', 'torch', 'serial'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


# -- byte for byte against dynamixel_sdk ---------------------------------------------------------------------------

sdk = pytest.importorskip("dynamixel_sdk")


@pytest.fixture
def sdk_port(monkeypatch):
    """A PortHandler (SDK) on the slave side of a pty, and the master fd the test reads and writes.

    Nothing here waits for an answer within the SDK's timeout: the tests read what the SDK wrote (within a second).
    """
    master, slave = os.openpty()
    tty.setraw(master)
    # as Interbotix's udev rule sets the U2D2's FTDI latency timer (1 ms), for this test only
    monkeypatch.setattr(sdk.port_handler, "LATENCY_TIMER", 1)
    port = sdk.PortHandler(os.ttyname(slave))
    assert port.openPort()
    yield port, master
    port.closePort()
    os.close(master)
    os.close(slave)


def _drain(master: int) -> bytes:
    """The next whole packet that comes out of the pty (b"" if none within 1 s)."""
    reader = PacketReader()
    while select.select([master], [], [], 1.0)[0]:
        packets = reader.feed(os.read(master, 4096))
        if packets:
            assert len(packets) == 1 and reader.pending == 0 and reader.dropped == 0
            return packets[0]
    return b""


def test_sdk_instruction_packets_equal_ours_byte_for_byte(sdk_port):
    port, master = sdk_port
    ph = sdk.PacketHandler(2.0)
    rng = random.Random(7)
    checked = 0
    while checked < 40:
        servo = rng.randrange(0, 253)
        address = rng.choice((64, 102, 116, 0x1FF))
        data = bytes(rng.choice((0xFF, 0xFD, rng.randrange(256))) for _ in range(rng.choice((1, 2, 4))))
        if stuff(bytes([Instruction.WRITE]) + write_params(address, data)) != bytes([3]) + write_params(address, data):
            continue  # needs stuffing: the next test
        assert ph.writeTxOnly(port, servo, address, len(data), list(data)) == sdk.COMM_SUCCESS
        assert _drain(master) == build_instruction(servo, Instruction.WRITE, write_params(address, data))
        checked += 1
    assert ph.readTx(port, 4, 132, 4) == sdk.COMM_SUCCESS
    assert _drain(master) == build_instruction(4, Instruction.READ, read_params(132, 4))
    port.is_using = False  # the SDK holds the port until an answer is read; none will come
    ph.ping(port, 3)
    assert _drain(master) == build_instruction(3, Instruction.PING)
    ph.reboot(port, 2)
    assert _drain(master) == build_instruction(2, Instruction.REBOOT)


def test_sdk_stuffing_equals_ours_but_its_packets_go_out_unstuffed(sdk_port):
    """dynamixel_sdk 4.1's Python `txPacket` drops what `addStuffing` returns when stuffing lengthens the packet.

    Its stuffer agrees with ours, but the packet goes out without the extra FD, its LEN and CRC those of the
    unstuffed packet. A servo (and our parser) reads such a packet by its LEN, and the CRC matches. The parameters
    come out right unless they hold FF FF FD FD, whose second FD an unstuffer drops. That never happens with the
    arm's goal values: 0xFDFFFF.. or below as a little-endian value.
    """
    port, master = sdk_port
    ph = sdk.PacketHandler(2.0)
    data = bytes.fromhex("FF FF FD 07")
    unstuffed = list(HEADER) + [4, 9, 0, Instruction.WRITE, 116, 0] + list(data) + [0, 0]
    stuffed = bytes(ph.addStuffing(unstuffed))  # the CRC's two bytes still 0
    assert stuffed[:-2] == build_instruction(4, Instruction.WRITE, write_params(116, data))[:-2]
    assert ph.writeTxOnly(port, 4, 116, 4, list(data)) == sdk.COMM_SUCCESS
    wire = _drain(master)
    assert wire != build_instruction(4, Instruction.WRITE, write_params(116, data))
    assert wire[5] == 9 and crc16(wire[:-2]) == wire[-2] | wire[-1] << 8  # LEN and CRC of the unstuffed packet
    assert parse_packet(wire) == InstructionPacket(4, Instruction.WRITE, write_params(116, data))


def test_sdk_group_packets_equal_ours_byte_for_byte(sdk_port):
    port, master = sdk_port
    ph = sdk.PacketHandler(2.0)
    reader = sdk.GroupSyncRead(port, ph, 126, 10)
    for i in (1, 2, 4):
        reader.addParam(i)
    assert reader.txPacket() == sdk.COMM_SUCCESS
    assert _drain(master) == build_instruction(BROADCAST_ID, Instruction.SYNC_READ,
                                               sync_read_params(126, 10, (1, 2, 4)))
    port.is_using = False  # the SDK holds the port until the answers are read; none will come
    assert reader.fastSyncReadTxPacket() == sdk.COMM_SUCCESS
    assert _drain(master) == build_instruction(BROADCAST_ID, Instruction.FAST_SYNC_READ,
                                               sync_read_params(126, 10, (1, 2, 4)))
    port.is_using = False
    writer = sdk.GroupSyncWrite(port, ph, 102, 2)
    values = {1: -3, 2: 0x3FD, 4: -259}
    for i, v in values.items():
        writer.addParam(i, list((v & 0xFFFF).to_bytes(2, "little")))
    assert writer.txPacket() == sdk.COMM_SUCCESS
    expected = sync_write_params(102, 2, [(i, (v & 0xFFFF).to_bytes(2, "little")) for i, v in values.items()])
    assert _drain(master) == build_instruction(BROADCAST_ID, Instruction.SYNC_WRITE, expected)
    bulk = sdk.GroupBulkRead(port, ph)
    bulk.addParam(1, 132, 4)
    bulk.addParam(7, 70, 1)
    assert bulk.txPacket() == sdk.COMM_SUCCESS
    assert _drain(master) == build_instruction(BROADCAST_ID, Instruction.BULK_READ,
                                               bulk_read_params(((1, 132, 4), (7, 70, 1))))
    port.is_using = False
    bulk_w = sdk.GroupBulkWrite(port, ph)
    bulk_w.addParam(1, 64, 1, [1])
    bulk_w.addParam(4, 116, 4, [0x00, 0x08, 0x00, 0x00])
    assert bulk_w.txPacket() == sdk.COMM_SUCCESS
    assert _drain(master) == build_instruction(BROADCAST_ID, Instruction.BULK_WRITE, bulk_write_params(
        ((1, 64, b"\x01"), (4, 116, b"\x00\x08\x00\x00"))))


def test_sdk_reads_our_status_packets(sdk_port):
    port, master = sdk_port
    ph = sdk.PacketHandler(2.0)
    # a read answer whose data hold FF FF FD: stuffed by us, unstuffed by the SDK
    data = b"\xff\xff\xfd\x00"
    os.write(master, build_status(4, ALERT, data))
    port.setPacketTimeoutMillis(200)
    got, result, error = ph.readRx(port, 4, 4)
    assert (bytes(got), result, error) == (data, sdk.COMM_SUCCESS, ALERT)
    os.write(master, build_status(1, 0, ping_status_params(1020, 46)))
    port.setPacketTimeoutMillis(200)
    pkt, result = ph.rxPacket(port, False)
    assert result == sdk.COMM_SUCCESS and bytes(pkt) == build_status(1, 0, ping_status_params(1020, 46))
    # a damaged CRC is refused as corrupt
    bad = bytearray(build_status(1, 0, b"\x01\x02"))
    bad[-1] ^= 0xFF
    os.write(master, bytes(bad))
    port.setPacketTimeoutMillis(200)
    _, result = ph.rxPacket(port, False)
    assert result == sdk.COMM_RX_CORRUPT


def test_sdk_parses_our_fast_sync_read_answer(sdk_port):
    port, master = sdk_port
    ph = sdk.PacketHandler(2.0)
    reader = sdk.GroupSyncRead(port, ph, 132, 4)
    for i in (1, 2, 4):
        reader.addParam(i)
    assert reader.fastSyncReadTxPacket() == sdk.COMM_SUCCESS
    _drain(master)
    blocks = [(0, i, (2048 + 100 * i).to_bytes(4, "little")) for i in (1, 2, 4)]
    os.write(master, build_fast_read_status(blocks))
    port.setPacketTimeoutMillis(200)
    assert reader.fastSyncReadRxPacket() == sdk.COMM_SUCCESS
    assert [reader.getData(i, 132, 4) for i in (1, 2, 4)] == [2148, 2248, 2448]
