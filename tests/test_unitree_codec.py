"""The Unitree low-level codec against the vendors' golden frames, and where it is deliberately safer than the SDK.

The golden files (``tests/golden/unitree``) hold frames the Go1 SDK 3.8 and the A1 SDK 3.3.1 produced: commands
for given inputs (motors not listed in an input stay as InitCmdData left them) and states with the SDK's receive
result. Commands must come out byte for byte, except where the SDK wraps or passes a value that we clamp or refuse;
states must decode to what the SDK decoded, re-encode to the same bytes, and be rejected where they are faulty.
"""

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from wbc.errors import CommandError, ConfigError, FrameError, UnknownNameError
from wbc.hardware.unitree import REJECT_REASONS, Battery, DecodeStats, LowStateExtras, Remote
from wbc.hardware.unitree.command_codec import KD_WIRE_MAX, KP_WIRE_MAX, TAU_WIRE_MAX, decode_command, encode_command
from wbc.hardware.unitree.crc import frame_crc
from wbc.hardware.unitree.layout import A1_LAYOUT, GO1_LAYOUT, MODE_SERVO, POS_STOP_F, VEL_STOP_F, frame_layout
from wbc.hardware.unitree.state_codec import decode_state, encode_state
from wbc.robots import get_robot, joint_table
from wbc.types import MotorCommand, RobotState

GOLDEN_DIR = Path(__file__).parent / "golden" / "unitree"
ROBOTS = ("go1", "a1")
LAYOUT = {"go1": GO1_LAYOUT, "a1": A1_LAYOUT}
TABLE = {"go1": "go1-arm", "a1": "a1-wx200"}


def golden(robot: str) -> dict:
    return json.loads((GOLDEN_DIR / f"{robot}_lowlevel.json").read_text())


def golden_remote(robot: str) -> Remote:
    return Remote(raw=bytes.fromhex(golden(robot)["remote_bytes_hex"]))


def command_from_input(inputs: list, override: dict[int, dict] | None = None) -> MotorCommand:
    """The 12 legs' command of a golden input: listed motors as given, the others as InitCmdData leaves them."""
    rows = {"q": np.full(12, POS_STOP_F), "dq": np.full(12, VEL_STOP_F), "Kp": np.zeros(12), "Kd": np.zeros(12),
            "tau": np.zeros(12)}
    for index, motor in inputs:
        assert motor["mode"] == MODE_SERVO
        for key in rows:
            rows[key][index] = (override or {}).get(index, {}).get(key, motor[key])
    return MotorCommand(q=rows["q"], dq=rows["dq"], kp=rows["Kp"], kd=rows["Kd"], tau=rows["tau"])


def motor_block(layout, frame: bytes, index: int) -> slice:
    start = layout.cmd_motor_offset + 27 * index
    return slice(start, start + 27)


def differing_bytes(a: bytes, b: bytes) -> list[int]:
    return [i for i, (x, y) in enumerate(zip(a, b, strict=True)) if x != y]


def crc_bit_loop(frame: bytes) -> int:
    """The SDK's CRC as its source writes it: bit by bit, MSB first, over (len >> 2) - 1 little-endian words."""
    crc = 0xFFFFFFFF
    for (word,) in struct.iter_unpack("<I", frame[: 4 * ((len(frame) >> 2) - 1)]):
        for bit in range(31, -1, -1):
            top = crc >> 31
            crc = (crc << 1) & 0xFFFFFFFF
            if top ^ ((word >> bit) & 1):
                crc ^= 0x04C11DB7
    return crc


def valid_state(robot: str) -> bytes:
    return bytes.fromhex(golden(robot)["lowstate"]["valid"]["hex"])


# -- layouts --------------------------------------------------------------------------------------------------------
def test_frame_sizes_and_lookup():
    assert (GO1_LAYOUT.cmd_size, GO1_LAYOUT.state_size) == (614, 807)
    assert (A1_LAYOUT.cmd_size, A1_LAYOUT.state_size) == (610, 771)
    assert frame_layout("a1") is A1_LAYOUT
    with pytest.raises(UnknownNameError, match="go1"):
        frame_layout("go2")


# -- CRC ------------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("robot", ROBOTS)
def test_crc_equals_the_bit_loop_and_the_crc_in_every_golden_frame(robot):
    g = golden(robot)
    for case, entry in [*g["lowcmd"].items(), *g["lowstate"].items()]:
        frame = bytes.fromhex(entry["hex"])
        assert frame_crc(frame) == crc_bit_loop(frame), case
        if case not in ("bad_crc", "short_by_one"):
            assert frame_crc(frame) == int.from_bytes(frame[-4:], "little"), case


def test_crc_equals_the_bit_loop_on_random_frames():
    rng = np.random.default_rng(0)
    for size in (614, 610, 807, 771, 8, 9):
        frame = rng.integers(0, 256, size, dtype=np.uint8).tobytes()
        assert frame_crc(frame) == crc_bit_loop(frame)


# -- commands: the golden frames --------------------------------------------------------------------------------------
@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("case", ["init_default", "twelve_motors", "damping_kd3"])
def test_golden_commands_are_reproduced_byte_for_byte(robot, case):
    entry = golden(robot)["lowcmd"][case]
    remote = None if case == "init_default" else golden_remote(robot)  # the vendor generator set the remote block
    frame = encode_command(LAYOUT[robot], command_from_input(entry["input"]), remote=remote)
    assert frame.hex() == entry["hex"]


@pytest.mark.parametrize("robot", ROBOTS)
def test_truncation_toward_zero_like_the_sdk(robot):
    """tau 0.0039 N m, Kp 0.03, Kd 0.05 and tau -0.0039 are below one count: they go out as 0, as the SDK sends."""
    layout = LAYOUT[robot]
    entry = golden(robot)["lowcmd"]["truncation_tau0.0039_kp0.03_kd0.05_negkp"]
    expected = bytes.fromhex(entry["hex"])
    ours = encode_command(layout, command_from_input(entry["input"], {1: {"Kp": 0.0}}), remote=golden_remote(robot))
    assert ours[motor_block(layout, ours, 0)] == expected[motor_block(layout, expected, 0)]
    sent = decode_command(layout, ours)
    assert (sent.tau[0], sent.kp[0], sent.kd[0], sent.tau[1]) == (0.0, 0.0, 0.0, 0.0)
    # motor 1: the SDK let Kp -5 through as -160 counts; with Kp 0 we send zeros there, all else is the same
    kp_bytes = [layout.cmd_motor_offset + 27 + 11, layout.cmd_motor_offset + 27 + 12]
    crc_bytes = list(range(layout.cmd_crc_offset, layout.cmd_size))
    assert differing_bytes(ours, expected) == [b for b in kp_bytes + crc_bytes if ours[b] != expected[b]]
    assert struct.unpack_from("<h", expected, kp_bytes[0])[0] == -160
    assert struct.unpack_from("<h", ours, kp_bytes[0])[0] == 0


@pytest.mark.parametrize("robot", ROBOTS)
def test_negative_gain_is_refused_not_sent(robot):
    entry = golden(robot)["lowcmd"]["truncation_tau0.0039_kp0.03_kd0.05_negkp"]
    with pytest.raises(CommandError, match="negative gain"):
        command_from_input(entry["input"])  # a MotorCommand cannot hold Kp -5 ...
    rows = command_from_input(entry["input"], {1: {"Kp": 0.0}}).stacked()
    rows[2, 1] = -5.0
    with pytest.raises(CommandError, match="kp of joint FR_thigh_joint is -5.0"):
        encode_command(LAYOUT[robot], MotorCommand._trusted(rows))  # ... and one that bypassed the check is refused


@pytest.mark.parametrize("robot", ROBOTS)
def test_out_of_range_tau_and_gains_are_clamped_not_wrapped(robot):
    """The SDK sends tau 130 N m as -126, Kp 2000 as -48, Kd 3000 as -1096; we send the largest values that fit."""
    layout = LAYOUT[robot]
    entry = golden(robot)["lowcmd"]["wrap_tau130_kp2000_kd3000"]
    expected = bytes.fromhex(entry["hex"])
    ours = encode_command(layout, command_from_input(entry["input"]), remote=golden_remote(robot))
    sdk, sent = decode_command(layout, expected), decode_command(layout, ours)
    assert (sdk.tau[0], sdk.kp[0], sdk.kd[0]) == (-126.0, -48.0, -1096.0)
    assert (sent.tau[0], sent.kp[0], sent.kd[0]) == (TAU_WIRE_MAX, KP_WIRE_MAX, KD_WIRE_MAX)
    assert (TAU_WIRE_MAX, KP_WIRE_MAX, KD_WIRE_MAX) == (32767 / 256, 32767 / 32, 32767 / 16)
    start = layout.cmd_motor_offset + 9  # slot 0: tau, Kp, Kd
    assert set(differing_bytes(ours, expected)) <= {*range(start, start + 6), *range(layout.cmd_crc_offset,
                                                                                    layout.cmd_size)}


@pytest.mark.parametrize("robot", ROBOTS)
def test_joint_table_clamps_q_dq_and_tau_to_the_motors_limits(robot):
    layout, limits = LAYOUT[robot], joint_table(get_robot(TABLE[robot]))  # 15 joints: the arm's rows are ignored
    big = np.full(12, 1e3)
    sent = decode_command(layout, encode_command(layout, MotorCommand(q=big, dq=-big, kp=big, kd=big, tau=-big),
                                                 limits=limits))
    legs = slice(0, 12)
    np.testing.assert_allclose(sent.q, limits.upper[legs], rtol=1e-7)
    np.testing.assert_allclose(sent.dq, -limits.velocity_limit[legs], rtol=1e-7)
    assert np.all(sent.tau <= 0) and np.all(-sent.tau <= limits.torque_limit[legs])
    np.testing.assert_allclose(sent.tau, -limits.torque_limit[legs], atol=1 / 256)
    np.testing.assert_array_equal(sent.kd, np.full(12, 1e3))  # gains: only the wire's range bounds them
    low = decode_command(layout, encode_command(layout, MotorCommand.hold(-big, 1.0, 0.1), limits=limits))
    np.testing.assert_allclose(low.q, limits.lower[legs], rtol=1e-7)


def test_a_table_of_other_joints_is_refused():
    limits = joint_table(get_robot("go1-arm"))
    shuffled = type(limits)(**{**limits.__dict__, "names": limits.names[3:15] + limits.names[:3]})
    with pytest.raises(ConfigError, match="legs"):
        encode_command(GO1_LAYOUT, MotorCommand.damping(12, 1.0), limits=shuffled)


@pytest.mark.parametrize("field", [0, 1, 4])  # q, dq, tau
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_values_never_reach_the_wire(field, bad):
    rows = MotorCommand.hold(np.zeros(12), 10.0, 1.0).stacked()
    rows[field, 5] = bad
    with pytest.raises(CommandError, match="non-finite"):
        MotorCommand(q=rows[0], dq=rows[1], kp=rows[2], kd=rows[3], tau=rows[4])
    with pytest.raises(CommandError, match="FL_calf_joint"):
        encode_command(GO1_LAYOUT, MotorCommand._trusted(rows))  # the SDK would send a NaN q as is


def test_huge_finite_targets_reach_the_wire_finite():
    sent = decode_command(A1_LAYOUT, encode_command(A1_LAYOUT, MotorCommand.hold(np.full(12, 1e300), 0.0, 1.0)))
    assert np.isfinite(sent.q).all() and sent.q[0] == np.finfo(np.float32).max


def test_a_command_for_other_than_the_twelve_legs_is_refused():
    with pytest.raises(CommandError, match="12 leg motors"):
        encode_command(GO1_LAYOUT, MotorCommand.damping(15, 1.0))


@pytest.mark.parametrize("robot", ROBOTS)
def test_damping_is_servo_mode_with_zero_kp(robot):
    layout = LAYOUT[robot]
    sdk = decode_command(layout, bytes.fromhex(golden(robot)["lowcmd"]["damping_kd3"]["hex"]))
    ours = decode_command(layout, encode_command(layout, MotorCommand.damping(12, 3.0)))
    for wire in (sdk, ours):
        assert np.all(wire.mode == MODE_SERVO)
        assert np.all(wire.kp == 0) and np.all(wire.kd == 3.0) and np.all(wire.dq == 0) and np.all(wire.tau == 0)
    assert np.all(sdk.q == np.float32(POS_STOP_F))


@pytest.mark.parametrize("robot", ROBOTS)
def test_random_commands_within_limits_decode_to_their_quantised_values(robot):
    layout, limits = LAYOUT[robot], joint_table(get_robot(TABLE[robot]))
    legs = slice(0, 12)
    rng = np.random.default_rng(42)
    for _ in range(200):
        q = rng.uniform(limits.lower[legs], limits.upper[legs])
        dq = rng.uniform(-1, 1, 12) * limits.velocity_limit[legs]
        tau = rng.uniform(-1, 1, 12) * limits.torque_limit[legs]
        kp, kd = rng.uniform(0, 200, 12), rng.uniform(0, 20, 12)
        remote = Remote.build(buttons=int(rng.integers(0, 0x10000)), lx=float(rng.uniform(-1, 1)))
        cmd = MotorCommand(q=q, dq=dq, kp=kp, kd=kd, tau=tau)
        stats = DecodeStats()
        wire = decode_command(layout, encode_command(layout, cmd, limits=limits, remote=remote), stats=stats)
        assert stats.accepted == 1
        np.testing.assert_array_equal(wire.mode, np.full(12, MODE_SERVO))
        np.testing.assert_array_equal(wire.q, q.astype(np.float32))
        np.testing.assert_array_equal(wire.dq, dq.astype(np.float32))
        for got, value, scale in ((wire.tau, tau, 256), (wire.kp, kp, 32), (wire.kd, kd, 16)):
            np.testing.assert_array_equal(got, np.trunc(value.astype(np.float32) * scale) / scale)
        assert wire.remote == remote
        np.testing.assert_array_equal(wire.motor_command().kp, wire.kp)


# -- states: the golden frames ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("robot", ROBOTS)
def test_golden_state_decodes_to_what_the_sdk_decoded(robot):
    entry = golden(robot)["lowstate"]["valid"]
    sdk = entry["decoded_by_sdk_after"]
    stats = DecodeStats()
    state, extras = decode_state(LAYOUT[robot], bytes.fromhex(entry["hex"]), time=12.5, stats=stats)
    assert entry["recv_rc"] == 0 and stats.accepted == 1 and stats.rejected == 0
    assert isinstance(state, RobotState) and state.num_joints == 12
    assert state.tick == sdk["tick"] and state.time == 12.5
    for ours, key in ((state.q, "q"), (state.dq, "dq"), (state.tau_est, "tauEst"), (state.imu_quat, "quat"),
                      (state.gyro_in_body, "gyro"), (state.accel_in_body, "acc"), (extras.imu_rpy, "rpy"),
                      (state.foot_force, "footForce"), (extras.motor_temperature, "temperature"),
                      (extras.motor_mode, "mode")):
        np.testing.assert_array_equal(ours, np.array(sdk[key], dtype=np.float64), err_msg=key)
    assert extras.remote.raw.hex() == sdk["remote_hex"]
    if robot == "go1":
        np.testing.assert_array_equal(extras.foot_force_est, sdk["footForceEst"])
        assert isinstance(extras.battery, Battery)
    else:
        # the A1 SDK never copies footForceEst to its users (they read 0); the codec reports what the wire holds
        assert sdk["footForceEst"] == [0, 0, 0, 0]
        np.testing.assert_array_equal(extras.foot_force_est, [11, 22, 33, 44])
        assert extras.battery is None


@pytest.mark.parametrize("robot", ROBOTS)
def test_golden_state_re_encodes_byte_for_byte(robot):
    frame = valid_state(robot)
    state, extras = decode_state(LAYOUT[robot], frame, time=0.0)
    assert encode_state(LAYOUT[robot], state, extras) == frame


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize(("case", "reason"), [("bad_crc", "crc"), ("short_by_one", "length"),
                                              ("level_0x00", "header")])
def test_faulty_golden_states_are_rejected_and_counted(robot, case, reason):
    entry = golden(robot)["lowstate"][case]
    stats = DecodeStats()
    with pytest.raises(FrameError) as err:
        decode_state(LAYOUT[robot], bytes.fromhex(entry["hex"]), time=0.0, stats=stats)
    assert err.value.reason == reason and err.value.robot == robot and err.value.frame_kind == "LowState"
    assert stats.rejected == 1 and getattr(stats, reason) == 1 and stats.accepted == 0


@pytest.mark.parametrize("robot", ROBOTS)
def test_level_0x00_is_rejected_although_the_sdk_takes_it(robot):
    """The SDK never checks levelFlag on receive (rc 0); its CRC is right, only the header marks it foreign."""
    entry = golden(robot)["lowstate"]["level_0x00"]
    frame = bytes.fromhex(entry["hex"])
    assert entry["recv_rc"] == 0 and frame_crc(frame) == int.from_bytes(frame[-4:], "little")
    assert frame[LAYOUT[robot].level_offset] == 0x00
    with pytest.raises(FrameError, match="levelFlag 0x00"):
        decode_state(LAYOUT[robot], frame, time=0.0)


@pytest.mark.parametrize("robot", ROBOTS)
def test_a_longer_frame_is_rejected_although_the_sdk_takes_it(robot):
    stats = DecodeStats()
    with pytest.raises(FrameError, match="expected exactly"):
        decode_state(LAYOUT[robot], valid_state(robot) + b"\0", time=0.0, stats=stats)
    assert stats.length == 1


def test_a_frame_without_the_go1_magic_is_rejected_as_header():
    frame = bytearray(valid_state("go1"))
    frame[0:2] = b"\0\0"
    with pytest.raises(FrameError, match="magic fe ef") as err:
        decode_state(GO1_LAYOUT, bytes(frame), time=0.0)
    assert err.value.reason == "header"


def test_a_go1_frame_cut_to_the_a1_length_is_rejected_as_header():
    with pytest.raises(FrameError) as err:
        decode_state(A1_LAYOUT, valid_state("go1")[:771], time=0.0)
    assert err.value.reason == "header"  # FE: not the A1's levelFlag 0xFF


@pytest.mark.parametrize("robot", ROBOTS)
def test_a_receive_buffer_decodes_like_bytes_and_is_not_aliased(robot):
    buffer = bytearray(valid_state(robot))
    state, extras = decode_state(LAYOUT[robot], memoryview(buffer), time=0.0)
    expected, _ = decode_state(LAYOUT[robot], valid_state(robot), time=0.0)
    buffer[:] = bytes(len(buffer))  # the backend reuses its buffer for the next datagram
    np.testing.assert_array_equal(state.q, expected.q)
    np.testing.assert_array_equal(state.imu_quat, expected.imu_quat)
    assert extras.remote.raw == golden_remote(robot).raw


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("where", ["q", "dq", "imu_quat", "accel_in_body", "remote"])
def test_non_finite_values_with_a_valid_crc_are_rejected(robot, where):
    layout = LAYOUT[robot]
    state, extras = decode_state(layout, valid_state(robot), time=0.0)
    if where == "remote":
        extras = LowStateExtras(**{**extras.__dict__, "remote": Remote.build(buttons=("L2", "B"), ly=np.nan)})
    else:
        value = getattr(state, where).copy()
        value[1] = np.inf if where == "dq" else np.nan
        state = RobotState(**{**state.__dict__, where: value})
    frame = encode_state(layout, state, extras)
    stats = DecodeStats()
    with pytest.raises(FrameError) as err:
        decode_state(layout, frame, time=0.0, stats=stats)
    assert err.value.reason == "non_finite" and stats.non_finite == 1 and stats.accepted == 0


def test_stats_count_a_stream_by_reason():
    g = golden("go1")["lowstate"]
    stream = [g[c]["hex"] for c in ("valid", "bad_crc", "short_by_one", "level_0x00", "valid", "bad_crc")]
    stats = DecodeStats()
    for hexed in stream:
        try:
            decode_state(GO1_LAYOUT, bytes.fromhex(hexed), time=0.0, stats=stats)
        except FrameError:
            pass
    assert stats.as_dict() == {"decode/accepted": 2, "decode/length": 1, "decode/header": 1, "decode/crc": 2,
                               "decode/non_finite": 0}
    assert stats.rejected == 4 and REJECT_REASONS == ("length", "header", "crc", "non_finite")


@pytest.mark.parametrize("robot", ROBOTS)
def test_a_faulty_command_frame_is_rejected_by_the_emulator_side(robot):
    layout = LAYOUT[robot]
    frame = bytearray(encode_command(layout, MotorCommand.damping(12, 1.0)))
    frame[layout.cmd_motor_offset + 1] ^= 0x01
    stats = DecodeStats()
    with pytest.raises(FrameError) as err:
        decode_command(layout, bytes(frame), stats=stats)
    assert err.value.reason == "crc" and err.value.frame_kind == "LowCmd" and stats.crc == 1
    nan_q = bytearray(frame)
    nan_q[layout.cmd_motor_offset + 1:layout.cmd_motor_offset + 5] = struct.pack("<f", np.nan)
    struct.pack_into("<I", nan_q, layout.cmd_crc_offset, frame_crc(nan_q))
    with pytest.raises(FrameError, match="FR_hip_joint"):
        decode_command(layout, bytes(nan_q), stats=stats)
    assert stats.non_finite == 1


# -- remote and battery -----------------------------------------------------------------------------------------------
def test_remote_buttons_and_the_passive_combination():
    golden_block = golden_remote("go1")
    assert golden_block.buttons == 0x6766  # bytes +2, +3 = 0x66, 0x67
    assert golden_block.held == ("L1", "start", "L2", "F1", "A", "B", "X", "right", "down")
    assert golden_block.l2_b
    assert Remote.build(buttons=("L2", "B")).l2_b
    assert not Remote.build(buttons=("L2", "A")).l2_b and not Remote.build(buttons=("B",)).l2_b
    r = Remote.build(buttons=("R1", "left"), lx=0.5, rx=-0.25, ry=1.0, l2=0.75, ly=-1.0)
    assert r.buttons == 0x8001 and r.pressed("left") and not r.pressed("up")
    assert (r.lx, r.rx, r.ry, r.l2, r.ly) == (0.5, -0.25, 1.0, 0.75, -1.0)
    with pytest.raises(UnknownNameError, match="select"):
        r.pressed("Start")


@pytest.mark.parametrize("robot", ROBOTS)
def test_remote_reaches_the_host_through_a_state_frame(robot):
    layout = LAYOUT[robot]
    state, extras = decode_state(layout, valid_state(robot), time=0.0)
    estop = LowStateExtras(**{**extras.__dict__, "remote": Remote.build(buttons=("L2", "B"))})
    _, got = decode_state(layout, encode_state(layout, state, estop), time=0.0)
    assert got.remote.l2_b and got.remote.held == ("L2", "B")


def test_go1_battery_round_trips_in_si_units():
    state, extras = decode_state(GO1_LAYOUT, valid_state("go1"), time=0.0)
    battery = Battery(version=(1, 2), status=3, soc=87, current=-3.25, cycle=41, bq_ntc=(30, 31), mcu_ntc=(35, -5),
                      cell_voltage=np.linspace(3.2, 4.192, 10))
    frame = encode_state(GO1_LAYOUT, state, LowStateExtras(**{**extras.__dict__, "battery": battery}))
    assert frame[729:739] == bytes(round(v / 0.032) for v in np.linspace(3.2, 4.192, 10))  # u8 counts of 32 mV
    got = decode_state(GO1_LAYOUT, frame, time=0.0)[1].battery
    assert (got.version, got.status, got.soc, got.current, got.cycle, got.bq_ntc, got.mcu_ntc) == (
        (1, 2), 3, 87, -3.25, 41, (30, 31), (35, -5))
    np.testing.assert_allclose(got.cell_voltage, np.linspace(3.2, 4.192, 10), atol=0.016)
    with pytest.raises(ConfigError, match="no battery block"):
        a1_state, a1_extras = decode_state(A1_LAYOUT, valid_state("a1"), time=0.0)
        encode_state(A1_LAYOUT, a1_state, LowStateExtras(**{**a1_extras.__dict__, "battery": battery}))


def test_encode_state_clamps_integer_fields_and_refuses_non_finite_ones():
    state, extras = decode_state(GO1_LAYOUT, valid_state("go1"), time=0.0)
    hot = state.tau_est.copy()
    hot[0] = 500.0
    got, _ = decode_state(GO1_LAYOUT, encode_state(GO1_LAYOUT, RobotState(**{**state.__dict__, "tau_est": hot}),
                                                   extras), time=0.0)
    assert got.tau_est[0] == 32767 / 256  # clamped, not wrapped to a negative torque
    hot[0] = np.nan
    with pytest.raises(ConfigError, match="tau_est"):
        encode_state(GO1_LAYOUT, RobotState(**{**state.__dict__, "tau_est": hot}), extras)
