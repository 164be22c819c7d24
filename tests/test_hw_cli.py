"""The ``wbc hw`` commands and ``wbc bench hw``: emulate, a damping-only check, the address policy, the bench's keys.

``wbc hw check`` reads the robot for ``--seconds`` of its own clock: the deterministic case hands the procedure
(`hw_check`) a robot builder that puts the legs' link on a `ManualClock` over the emulator's in-process channel, so
what it sent in those seconds is exact; the others run it over the UDP wire and assert nothing of its timing.

Every socket binds 127.0.0.1 on a port the kernel picks and every frame goes to 127.0.0.1; the non-loopback targets
(TEST-NET-1, 192.0.2.0/24) are only ever refused, and a test checks that no socket was created for them. Every
run is bounded by its ``--seconds``.
"""

from __future__ import annotations

import contextlib
import gc
import importlib
import io
import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import Stepped

from wbc.cli import main
from wbc.cli.main import hw_check
from wbc.cli.parser import build_parser
from wbc.hardware.clock import ManualClock
from wbc.hardware.dynamixel import DynamixelArmConfig
from wbc.hardware.emulators import (
    BusFault,
    Fault,
    RobotEmulator,
    RobotEmulatorConfig,
    UnitreeEmulator,
    UnitreeEmulatorConfig,
)
from wbc.hardware.hardware_robot import HardwareRobot, HardwareRobotConfig, build_hardware_robot
from wbc.hardware.realtime import NO_REALTIME, RealtimeRequest, request_realtime
from wbc.hardware.safety import REMEDIES, SafetyConfig
from wbc.hardware.unitree import UdpTransport
from wbc.hardware.unitree.command_codec import encode_command
from wbc.hardware.unitree.layout import frame_layout
from wbc.tools import emulate as emulate_tool
from wbc.types import MotorCommand

ROOT = Path(__file__).resolve().parents[1]
NOT_LOOPBACK = "192.0.2.1:9"  # TEST-NET-1 (documentation only), discard port: refused before anything is sent
LINK_PERIOD = 0.002  # [s] the link's default rate, 500 Hz
# Over a real wire the emulator answers when the machine lets it. A check that must find the robot ready is read with
# a stale timeout that only a hung emulator misses: on a busy machine the default 0.1 s trips the layer (exit 1), and
# when the layer trips on time is the lockstep twins' to check.
LENIENT_SAFETY = SafetyConfig(stale_timeout_s=30.0)


def _lenient_arm(config: HardwareRobotConfig) -> HardwareRobot:
    """The robot `config` names, its arm's bus with the longest reply timeout (latency timer 32 ms), start-up retries
    and servo watchdog its config allows: a busy machine's late answers are then retried, never latched as a silent
    servo. What is read and sent is the same; how late an answer may be is the lockstep twin's to check."""
    arm = replace(config.arm, latency_ms=32.0, watchdog_s=2.54, connect_retries=100, connect_timeout=10.0)
    return build_hardware_robot(replace(config, arm=arm))


@pytest.fixture(params=("a1", "go1"))
def stepped(request: pytest.FixtureRequest) -> Iterator[Stepped]:
    rig = Stepped(ManualClock(), UnitreeEmulator(UnitreeEmulatorConfig(robot=request.param, mode="realtime")))
    yield rig
    rig.emu.close()
    assert not [t.name for t in threading.enumerate() if t.name.startswith("unitree-")]  # no thread ever started


@pytest.fixture(params=("a1", "go1"))
def emulator(request: pytest.FixtureRequest) -> Iterator[UnitreeEmulator]:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot=request.param, mode="realtime")) as emu:
        yield emu
        assert emu.failure is None, emu.failure
    assert not [t.name for t in threading.enumerate() if t.name.startswith("unitree-")]


@pytest.fixture
def no_socket(monkeypatch: pytest.MonkeyPatch) -> list[tuple]:
    """Make creating any socket fail the test; the list holds the attempts."""
    attempts: list[tuple] = []

    def refuse(*args: object, **kwargs: object) -> None:
        attempts.append(args)
        raise AssertionError("a socket was opened for a refused target")

    monkeypatch.setattr(socket, "socket", refuse)
    return attempts


def test_emulate_runs_and_prints_counts(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["hw", "emulate", "--robot", "a1", "--seconds", "0.5", "--lockstep", "--fault", "corrupt",
                 "--no-realtime"]) == 0
    out = capsys.readouterr().out
    assert "emulated a1 (lockstep) on 127.0.0.1:" in out and "faults: corrupt" in out
    assert "commands decoded 0; rejected 0 (length 0, header 0, crc 0, non_finite 0)" in out and "replies 0" in out


def test_emulate_asks_for_real_time_once_the_emulator_is_built(monkeypatch: pytest.MonkeyPatch) -> None:
    """Built at a real-time priority, the emulator's physics (~0.3 s of CPU) would hold off every other thread of that
    priority on its CPU. The request follows the build (`prepare`) and precedes the start, whose threads inherit it;
    the request is replaced here, and this process keeps its scheduling."""
    calls: list[str] = []

    def spied(cls: type, name: str) -> None:
        original = getattr(cls, name)
        monkeypatch.setattr(cls, name, lambda self: (calls.append(f"{cls.__name__}.{name}"), original(self))[1])

    for cls in (UnitreeEmulator, RobotEmulator):
        spied(cls, "prepare")
        spied(cls, "start")
    monkeypatch.setattr(emulate_tool, "request_realtime",
                        lambda request: calls.append("real time") or request_realtime(NO_REALTIME))
    expected = {"none": ["UnitreeEmulator.prepare", "real time", "UnitreeEmulator.start"],
                "actuated": ["RobotEmulator.prepare", "real time", "RobotEmulator.start", "UnitreeEmulator.start"]}
    for arm, order in expected.items():
        calls.clear()
        served = emulate_tool.emulate(emulate_tool.EmulateConfig(robot="go1", arm_mode=arm, mode="lockstep",
                                                                 seconds=0.05, realtime=RealtimeRequest()))
        assert served.failure is None and calls == order, arm
    emu = UnitreeEmulator(UnitreeEmulatorConfig(robot="go1"))
    before = set(threading.enumerate())
    assert emu.prepare() is emu and emu.sim.is_connected
    assert set(threading.enumerate()) <= before  # built: no thread started (one of the runs above may end meanwhile)
    emu.close()


def _free_loopback_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_emulate_counts_what_it_decoded_and_rejected(capsys: pytest.CaptureFixture[str]) -> None:
    port = _free_loopback_port()
    codes: list[int] = []
    server = threading.Thread(target=lambda: codes.append(main(["hw", "emulate", "--port", str(port),
                                                                "--seconds", "1.0", "--no-realtime"])))
    server.start()
    layout = frame_layout("go1")
    frame = encode_command(layout, MotorCommand.damping(12, 3.0))
    link = UdpTransport(("127.0.0.1", 0), ("127.0.0.1", port))
    try:
        replies = []
        for _ in range(2000):  # bounded: 2000 x 5 ms (the emulator builds its simulation first), stops once it answers
            link.send(frame)
            if link.wait_readable(0.005):
                replies += link.receive()
                break
        link.send(frame[:-1])  # one byte short: rejected as length
    finally:
        link.close()
    server.join(timeout=60.0)  # a bound for a hung emulator: it builds its simulation, then serves its 1.0 s
    assert codes == [0] and replies, "the emulator never answered"
    out = capsys.readouterr().out
    assert "emulated go1 (realtime) on 127.0.0.1:" + str(port) in out
    assert "rejected 1 (length 1, header 0, crc 0, non_finite 0)" in out and "replies 0" not in out


def test_unknown_fault_exits_2_with_the_valid_names() -> None:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-m", "wbc.cli", "hw", "emulate", "--seconds", "0.1", "--fault", "bogus"],
                          capture_output=True, text=True, timeout=60, cwd=ROOT, env=env)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and "unknown fault 'bogus'" in proc.stderr
    assert all(f.value in proc.stderr for f in Fault)
    assert "emulated" not in proc.stdout  # refused before the emulator started


def test_emulate_injects_a_fault_at_the_value_given(monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """``--fault drop=0.3``: the emulator drops each reply with probability 0.3 (at its default, 1.0, drop was the
    same as silence); a value out of range, or for a fault that takes none, is refused before it starts."""
    injected: list[tuple[object, object]] = []
    inject = UnitreeEmulator.inject

    def spied(self: UnitreeEmulator, fault: Fault, value: object = None) -> None:
        injected.append((fault, value))
        inject(self, fault, value)

    monkeypatch.setattr(UnitreeEmulator, "inject", spied)
    assert main(["hw", "emulate", "--robot", "go1", "--seconds", "0.05", "--lockstep", "--no-realtime", "--fault",
                 "drop=0.3", "--fault", "motor_error=0x20", "--fault", "corrupt"]) == 0
    assert injected == [(Fault.DROP, 0.3), (Fault.MOTOR_ERROR, 0x20), (Fault.CORRUPT, None)]
    assert "faults: drop=0.3, motor_error=32, corrupt;" in capsys.readouterr().out
    for given, said in (("drop=1.5", "--fault drop=1.5: expected a number in (0, 1] (probability)"),
                        ("drop=0", "--fault drop=0: expected a number in (0, 1] (probability)"),
                        ("delay=nan", "--fault delay=nan: expected a number in (0, 1] (s)"),
                        ("motor_error=256", "--fault motor_error=256: expected a whole number in [0, 255] (mode byte)"),
                        ("over_temperature=128", "expected a whole number in [0, 127] (deg C)"),  # a signed byte
                        ("corrupt=1", "--fault corrupt=1: corrupt takes no value from the command line")):
        injected.clear()
        assert main(["hw", "emulate", "--seconds", "0.05", "--lockstep", "--no-realtime", "--fault", given]) == 2
        assert said in capsys.readouterr().err and injected == [], given


def test_check_prints_the_state_and_sends_only_damping(stepped: Stepped, capsys: pytest.CaptureFixture[str]) -> None:
    robot = stepped.emu.config.robot
    args = build_parser().parse_args(["hw", "check", "--robot", robot, "--target", "127.0.0.1:9", "--seconds", "0.3"])
    assert hw_check(args, build=stepped.build) == 0
    out = capsys.readouterr().out
    for text in (f"{robot} at 127.0.0.1:9", "FR_hip_joint", "RL_calf_joint", "IMU roll", "battery",
                 "remote buttons: none", "link:", "rejected states: 0"):
        assert text in out, (text, out)
    # the age is the datagram's since it arrived, not the robot's latency, which damping alone cannot show: said so
    assert "ms old (since its datagram arrived here)" in out and "  latency: NOT MEASURED: " in out
    assert "a constant delay reads as none. `wbc bench latency` gives the delay each controller tolerates" in out
    assert ("none in this robot's state" in out) == (robot == "a1")
    assert ("NOT REPORTED: no cell voltage" in out) == (robot == "go1")  # the emulator reports no battery
    log = stepped.emu.commands()
    assert len(log) >= 0.3 / LINK_PERIOD  # a frame every link period of the 0.3 s, plus the closing damping
    assert stepped.clock.now() >= 0.3  # it read for its --seconds, on the robot's clock
    assert all(c.damping and (c.wire.kp == 0).all() for c in log)


def test_check_freezes_the_heap_once_all_is_built_before_it_connects(
        stepped: Stepped, monkeypatch: pytest.MonkeyPatch) -> None:
    """A full collection of the start-up heap stalled the link and bus threads for 130-300 ms, and the layer called the
    arm's live state stale ("WOULD REFUSE: stale_state"): ``hw check`` freezes the heap as ``hw run`` does, once the
    robot is built and before anything is sent to it."""
    import wbc.tools.hardware_check as hardware_check

    frozen: list[tuple[int, int]] = []  # the frames on the wire when the heap was frozen, and the objects frozen
    real = hardware_check.frozen_heap

    @contextlib.contextmanager
    def watched() -> Iterator[int]:
        with real() as count:
            frozen.append((len(stepped.emu.commands()), gc.get_freeze_count()))
            yield count

    monkeypatch.setattr(hardware_check, "frozen_heap", watched)
    gc.unfreeze()  # as a library caller's heap would be: not frozen
    robot = stepped.emu.config.robot
    args = build_parser().parse_args(["hw", "check", "--robot", robot, "--target", "127.0.0.1:9", "--seconds", "0.1"])
    assert hw_check(args, build=stepped.build) == 0
    assert [f for f, _ in frozen] == [0] and frozen[0][1] > 0 and stepped.emu.commands()
    # a library call: once it returns, what it froze is the collector's again (what it built and dropped is freed)
    assert gc.get_freeze_count() == 0


def test_check_marks_a_joint_beyond_its_range_apart_from_one_beyond_the_safety_margin(
        stepped: Stepped, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """A joint beyond its printed range but within the layer's margin is marked ``margin`` (the layer lets it pass),
    one beyond both ``OUT`` (the layer refuses it); the verdict line says which is which."""
    cli = importlib.import_module("wbc.cli.main")
    read = cli.check_hardware

    def moved(*args: object, **kwargs: object) -> object:
        check = read(*args, **kwargs)
        q, names = check.state.q.copy(), list(check.joint_names)
        rr, fr = names.index("RR_calf_joint"), names.index("FR_calf_joint")
        q[rr] = check.lower[rr] - check.margin / 3  # a little past its stop, within the margin
        q[fr] = check.upper[fr] + 2 * check.margin  # past range and margin
        return replace(check, state=replace(check.state, q=q))

    monkeypatch.setattr(cli, "check_hardware", moved)
    robot = stepped.emu.config.robot
    args = build_parser().parse_args(["hw", "check", "--robot", robot, "--target", "127.0.0.1:9", "--seconds", "0.1"])
    assert hw_check(args, build=stepped.build) == 0  # the layer's verdict on the state it read: ready
    rows = {line.split()[0]: line for line in capsys.readouterr().out.splitlines() if line.startswith("  ")}
    assert "] margin " in rows["RR_calf_joint"] and "OUT" not in rows["RR_calf_joint"]
    assert "] OUT " in rows["FR_calf_joint"] and "margin" not in rows["FR_calf_joint"]
    assert re.search(r"\]\s+0x", rows["FR_hip_joint"])  # inside its range: no mark
    assert ("joint margin 0.087 rad beyond each range: a joint marked margin is beyond its range and within the "
            "margin, which the layer lets pass; one marked OUT is beyond both, which it refuses") in rows["safety:"]


def test_check_over_the_wire_sends_only_damping(emulator: UnitreeEmulator,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    host, port = emulator.address
    assert host == "127.0.0.1"
    robot = emulator.config.robot
    args = build_parser().parse_args(["hw", "check", "--robot", robot, "--target", f"{host}:{port}",
                                      "--seconds", "0.3"])
    assert hw_check(args, safety=LENIENT_SAFETY) == 0
    out = capsys.readouterr().out
    assert f"{robot} at {host}:{port}" in out and "rejected states: 0" in out
    log = emulator.commands()
    assert log and all(c.damping and (c.wire.kp == 0).all() for c in log)


def test_check_shows_the_estop_buttons(capsys: pytest.CaptureFixture[str]) -> None:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1")) as emu:
        emu.inject(Fault.REMOTE_L2_B)
        assert main(["hw", "check", "--target", f"127.0.0.1:{emu.address[1]}", "--seconds", "0.1"]) == 1  # refused
        assert all(c.damping for c in emu.commands())
    assert "remote buttons: L2, B  (L2+B held: e-stop)" in capsys.readouterr().out


def test_check_of_a_robot_that_sends_nothing_is_a_result_not_an_error(capsys: pytest.CaptureFixture[str]) -> None:
    """No state stream at all is what the check found (status 1, said on its line with what to check), as a refusal
    is; a usage error (status 2) is for options and targets refused before anything connects."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:  # bound, and never answers
        silent.bind(("127.0.0.1", 0))
        port = silent.getsockname()[1]
        assert main(["hw", "check", "--robot", "go1", "--target", f"127.0.0.1:{port}", "--seconds", "0.1"]) == 1
        silent.setblocking(False)
        heard = silent.recv(4096)  # the link damped a silent robot: it sent its frames all the same
    captured = capsys.readouterr()
    assert "error" not in captured.err and "Traceback" not in captured.err
    first, *rest = captured.out.splitlines()
    assert first.startswith(f"go1 at 127.0.0.1:{port}: no live state stream: ")
    assert "nothing came back at all: is the robot (or emulator) on" in first  # the link's hint
    assert any(line.startswith("  safety: waiting: no live state stream") for line in rest)
    assert any(line.startswith("  link: ") and "all damping" in line for line in rest)
    assert len(heard) == frame_layout("go1").cmd_size


@pytest.mark.parametrize("target", [NOT_LOOPBACK, "198.51.100.7:9000"])
def test_non_loopback_target_is_refused_before_any_socket(target: str, no_socket: list,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["hw", "check", "--target", target]) == 2
    err = capsys.readouterr().err
    assert "outside 127.0.0.0/8" in err and "--allow-hardware" in err
    assert not no_socket


@pytest.mark.parametrize("local", ["192.0.2.7:0", "0.0.0.0:9000", "198.51.100.2:8007"])
def test_a_local_address_of_a_real_network_is_refused_before_any_socket(local: str, no_socket: list,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["hw", "check", "--target", "127.0.0.1:9", "--local", local]) == 2
    err = capsys.readouterr().err
    assert f"--local {local} is outside 127.0.0.0/8" in err and "--allow-hardware" in err
    for bad, says in (("myhost:9000", "not an IPv4 address literal"), ("127.0.0.1", "give HOST:PORT"),
                      ("127.0.0.1:70000", "out of range 0..65535")):
        assert main(["hw", "check", "--target", "127.0.0.1:9", "--local", bad]) == 2
        assert says in capsys.readouterr().err
    assert not no_socket


def test_hostname_target_is_refused(no_socket: list, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["hw", "check", "--target", "localhost:9000"]) == 2
    assert "not an IPv4 address literal" in capsys.readouterr().err and not no_socket


def test_allow_hardware_without_a_terminal_needs_yes(no_socket: list, monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(sys, "stdin", io.StringIO("yes\n"))  # a piped yes is not a person at a terminal
    assert main(["hw", "check", "--target", NOT_LOOPBACK, "--allow-hardware"]) == 2
    err = capsys.readouterr().err
    assert "192.0.2.1:9 is a REAL ROBOT" in err and "stdin is not a terminal" in err and "--yes" in err
    assert not no_socket


def test_the_confirmation_without_an_arm_port_names_the_legs_alone(no_socket: list, monkeypatch: pytest.MonkeyPatch,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """Without ``--arm-port`` only the legs are driven: the confirmation said "on the arm too" and named go1-arm."""
    monkeypatch.setattr(sys, "stdin", io.StringIO(""))
    assert main(["hw", "check", "--robot", "go1", "--target", NOT_LOOPBACK, "--allow-hardware"]) == 2
    err = capsys.readouterr().err
    assert ("wbc hw check: go1 at 192.0.2.1:9 is a REAL ROBOT (outside 127.0.0.0/8). Only damping will be sent to "
            "its legs (Kp 0); no arm is driven (no --arm-port).") in err
    assert "go1-arm" not in err and "arm too" not in err and not no_socket


def test_allow_hardware_asks_and_a_no_refuses(no_socket: list, monkeypatch: pytest.MonkeyPatch,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    class Terminal:
        def isatty(self) -> bool:
            return True

    prompts: list[str] = []
    monkeypatch.setattr(sys, "stdin", Terminal())
    monkeypatch.setattr("builtins.input", lambda prompt: prompts.append(prompt) or "no")
    assert main(["hw", "check", "--target", NOT_LOOPBACK, "--allow-hardware"]) == 2
    assert prompts == ["type yes to connect: "]
    assert "not confirmed" in capsys.readouterr().err and not no_socket


def test_bench_hw_json_has_the_keys(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "hw", "--seconds", "0.5", "--stand", "0.5", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    # the keys and their order are the JSON's contract (tests/test_bench_types.py checks every bench's)
    assert list(result) == ["robot", "seconds", "rate_hz", "transport", "emulator_process", "sends",
                            "replies_received", "period_ms_p50", "period_ms_p99", "period_ms_max", "round_trip_ms_p50",
                            "round_trip_ms_p99", "cpu_us_per_tick", "advance_ms_p50", "advance_ms_p99",
                            "late_advances", "worst_lateness_ms", "rejects", "emulator", "link", "safety", "machine",
                            "load_1min", "realtime", "emulator_realtime"]
    # both ends asked for real-time scheduling (granted or refused, said), and this thread has its own back
    assert result["realtime"].startswith("asked SCHED_FIFO 50, CPU")
    assert result["emulator_realtime"].startswith("asked SCHED_FIFO 50, CPU")
    if hasattr(os, "sched_getscheduler"):
        assert os.sched_getscheduler(0) == os.SCHED_OTHER
    assert list(result["safety"]) == [
        "robot", "write_deadline_ms", "link_period_ms", "stale_timeout_ms", "estop_to_damping_ms",
        "silence_to_damping_ms", "stall_to_damping_ms", "state_fault_to_damping_ms", "stand_seconds", "stand_wall_s",
        "stand_sim_s", "stand_realtime_factor", "stand_safety_state", "stand_trips", "stand_link_period_ms_mean",
        "stand_link_period_ms_max", "stand_deadline_trips", "stand_act_ms_p99", "stand_deadline_misses"]
    # the counts agree between the two ends (the figures are printed, not asserted: they are this machine's)
    assert result["rejects"] == 0 and result["sends"] > 0 and result["replies_received"] > 0
    assert result["emulator"]["accepted"] >= result["sends"] - 1 and sum(result["emulator"]["rejected"].values()) == 0
    assert result["replies_received"] <= result["emulator"]["replies"]
    assert result["transport"] == "udp"
    assert result["period_ms_p50"] > 0 and result["round_trip_ms_p50"] > 0
    safety = result["safety"]
    for key in ("estop_to_damping_ms", "silence_to_damping_ms", "stall_to_damping_ms", "state_fault_to_damping_ms"):
        assert safety[key] > 0, key  # each reaction's damping reached the wire, after its cause
    # a silent stream and a stalled loop are judged by their timeouts: their damping cannot come before them
    assert safety["silence_to_damping_ms"] > safety["stale_timeout_ms"]
    assert safety["stall_to_damping_ms"] > safety["write_deadline_ms"]
    assert safety["stand_seconds"] == 0.5 and safety["stand_wall_s"] > 0 and safety["stand_sim_s"] > 0
    assert safety["stand_realtime_factor"] == pytest.approx(safety["stand_sim_s"] / safety["stand_wall_s"])


def test_bench_hw_prints_the_safety_figures(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "hw", "--seconds", "0.2", "--stand", "0.2"]) == 0
    out = capsys.readouterr().out
    for text in ("send period", "round trip", "advance(period)", "late advances", "e-stop", "silent stream",
                 "stalled loop", "hot motor", "real-time factor"):
        assert text in out, text
    assert main(["bench", "hw", "--seconds", "0.2", "--no-safety", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["safety"] is None


@pytest.mark.parametrize("argv", [["hw", "check", "--target", "127.0.0.1:9"], ["bench", "hw", "--no-safety"]],
                         ids=["hw check", "bench hw"])
def test_the_vendor_transport_is_refused_for_the_a1_naming_the_options_before_any_socket(
        argv: list[str], no_socket: list, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*argv, "--robot", "a1", "--transport", "sdk"]) == 2
    err = capsys.readouterr().err
    assert ("wbc: error: --transport sdk: the vendor SDK speaks only the go1's wire, not the a1's (--robot a1); leave "
            "--transport out for it (udp, our own socket)") in err
    assert "UnitreeRobotConfig" not in err and "binds its port" not in err and not no_socket
    assert main([*argv, "--transport", "tcp"]) == 2
    assert ("wbc: error: --transport: unknown Unitree transport 'tcp'; valid Unitree "
            "transports: sdk, udp") in capsys.readouterr().err and not no_socket


def test_bench_hw_refuses_a_bad_rate_before_starting_the_emulator(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as usage:  # argparse's usage error, before anything starts
        main(["bench", "hw", "--rate", "50", "--seconds", "0.1"])
    assert usage.value.code == 2
    assert "argument --rate: must be a finite number in [200, 1000] Hz, got '50'" in capsys.readouterr().err


def test_emulate_carries_a_locked_arm_in_its_physics_and_refuses_an_unknown_mode(capsys: pytest.CaptureFixture[str],
                                                                                  ) -> None:
    masses = {}
    for arm in ("none", "locked"):
        with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", arm_mode=arm)) as emu:
            assert emu.sim.num_joints == 12  # the wire drives the same 12 legs
            masses[arm] = float(emu.sim.model.body_mass.sum())
    assert masses["locked"] > masses["none"] + 0.3  # the held arm's mass is on the trunk
    assert main(["hw", "emulate", "--robot", "go1", "--arm", "locked", "--seconds", "0.2", "--lockstep",
                 "--no-realtime"]) == 0
    assert main(["hw", "emulate", "--robot", "go1", "--arm", "welded", "--seconds", "0.2", "--no-realtime"]) == 2
    err = capsys.readouterr().err
    assert "locked" in err and "none" in err and "actuated" in err and "Traceback" not in err


def test_check_reports_the_safety_layers_refusal_of_a_folded_robot(capsys: pytest.CaptureFixture[str]) -> None:
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1")) as emu:
        qpos = emu.sim.data.qpos.copy()
        qpos[7:19] = np.tile([0.0, 1.2, -2.9], 4)  # calves beyond the SDK's range and its margin: no ramp from here
        emu.reset(qpos)
        # a refusal is the command's failure (status 1), so that a bring-up script stops there
        assert main(["hw", "check", "--target", f"127.0.0.1:{emu.address[1]}", "--seconds", "0.2"]) == 1
        assert all(c.damping for c in emu.commands())  # still nothing but damping
    out = capsys.readouterr().out
    assert re.search(r"safety: WOULD REFUSE: joint_range: FR_calf_joint at -2\.\d+ rad", out)
    assert f"what to do: {REMEDIES['joint_range']}" in out
    assert "FR_calf_joint" in out and " OUT" in out


def test_check_reads_the_arm_too_and_never_drives_it_in_lockstep(capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("dynamixel_sdk")
    clock = ManualClock()
    with RobotEmulator(RobotEmulatorConfig(robot="a1-wx200", mode="realtime"), clock=clock) as emu:
        def build(config: HardwareRobotConfig) -> HardwareRobot:
            return build_hardware_robot(config, clock=clock, legs_transport=emu.legs_transport,
                                        arm_handlers=emu.arm_handlers())

        # the wrist and gripper, which no model joint moves, stand away from the goals a run would hold them at
        held = {spec.id: 1500 + 100 * k for k, spec in enumerate(DynamixelArmConfig(port=emu.port).held_servos)}
        for servo in emu.arm._servos:  # the emulator's servos, set as a hand would have left them
            if servo.spec.id in held:
                servo.set("present_position", held[servo.spec.id])
        args = build_parser().parse_args(["hw", "check", "--robot", "a1", "--target", "127.0.0.1:9", "--arm-port",
                                          emu.port, "--seconds", "0.5"])
        assert hw_check(args, build=build) == 0
        legs = emu.legs.commands()
        goals = [(w.id, w.value) for p in emu.arm.packets() for w in p.writes if w.name == "goal_position"]
    out = capsys.readouterr().out
    assert goals and all(value == held[i] for i, value in goals if i in held)  # held where they were: no motion
    assert "arm on " in out and "arm_elbow" in out and "safety: ready: a ramp would start" in out
    cycles = re.search(r"arm bus: (\d+) cycles, (\d+) of them damping", out)
    assert cycles and int(cycles[1]) >= 0.5 * 100 and cycles[1] == cycles[2]  # every cycle damped: no servo command
    assert len(legs) >= 0.5 / LINK_PERIOD and all(c.damping for c in legs)


@pytest.mark.parametrize(("fault", "elbow", "said"), [
    (BusFault.OVERLOAD, r"elbow\s+4\s+1020\s+3 \(position\)\s+0x20 overload",
     "ID 4 (elbow) reports a hardware error (overload; 0x20), latched in the servo: find the cause, then reboot it"),
    (BusFault.SILENT_ID, r"elbow\s+4  NO VALID ANSWER to its ping: rx timeout",
     "servos did not answer a ping: ID 4 (elbow): rx timeout (-3001). Check the arm's 12 V supply")],
    ids=["overload", "silent-id"])
def test_check_of_an_arm_with_a_fault_at_connect_reads_what_answers_and_exits_1(
        fault: BusFault, elbow: str, said: str, capsys: pytest.CaptureFixture[str]) -> None:
    """The elbow overloaded (latched in the servo), or silent, before the check: the arm's backend refuses to drive
    it, and the check reads the legs alone, each servo once without writing to it, says what the arm's refusal says
    and exits 1 (a state the safety layer would refuse). It printed that refusal as an error, no readout, status 2."""
    pytest.importorskip("dynamixel_sdk")
    clock = ManualClock()
    with RobotEmulator(RobotEmulatorConfig(robot="a1-wx200", mode="realtime"), clock=clock) as emu:
        emu.inject(fault)

        def build(config: HardwareRobotConfig) -> HardwareRobot:
            return build_hardware_robot(config, clock=clock, legs_transport=emu.legs_transport,
                                        arm_handlers=emu.arm_handlers())

        args = build_parser().parse_args(["hw", "check", "--robot", "a1", "--target", "127.0.0.1:9", "--arm-port",
                                          emu.port, "--seconds", "0.5"])
        assert hw_check(args, build=build) == 1
        legs = emu.legs.commands()
        writes = [w for p in emu.arm.packets() for w in p.writes]
    out = capsys.readouterr().out
    assert "FR_hip_joint" in out and "arm_elbow" not in out  # the legs' table; the arm's joints were not read
    assert "arm: not driven" in out and re.search(elbow, out), out
    for servo in ("waist", "shoulder_shadow", "wrist_angle", "wrist_rotate", "gripper"):  # those that answer
        assert re.search(rf"{servo}\s+\d\s+1020\s+3 \(position\)\s+none", out), servo
    assert re.search(r"safety: WOULD REFUSE: the arm: DynamixelArm\(\S+\): " + re.escape(said), out), out
    assert not writes  # nothing written to the arm: no torque, no mode, no goal
    assert len(legs) >= 0.5 / LINK_PERIOD and all(c.damping for c in legs)


def test_check_reads_the_arm_too_and_never_drives_it(capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("dynamixel_sdk")
    proc = subprocess.Popen([sys.executable, "-m", "wbc.cli", "hw", "emulate", "--robot", "a1-wx200", "--arm",
                             "actuated", "--seconds", "60"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT)
    try:
        line = proc.stdout.readline()  # bounded: the emulator stops by itself after --seconds
        found = re.search(r"legs on 127\.0\.0\.1:(\d+) \(UDP\), arm on (\S+) \(Dynamixel", line)
        assert found, line
        args = build_parser().parse_args(["hw", "check", "--robot", "a1", "--target", f"127.0.0.1:{found[1]}",
                                          "--arm-port", found[2], "--seconds", "0.5"])
        code = hw_check(args, build=_lenient_arm, safety=LENIENT_SAFETY)
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=20)
    out, err = capsys.readouterr()
    assert code == 0, out + err
    assert "arm on /dev/" in out and "arm_elbow" in out and "safety: ready: a ramp would start" in out
    cycles = re.search(r"arm bus: (\d+) cycles, (\d+) of them damping", out)
    # every cycle damped: no servo command (how many cycles real time allowed: the lockstep twin counts them)
    assert cycles and int(cycles[1]) > 0 and cycles[1] == cycles[2]


def test_check_takes_the_robot_by_either_name(stepped: Stepped, capsys: pytest.CaptureFixture[str]) -> None:
    """``hw check --robot go1-arm`` is ``--robot go1``: one naming across ``hw check`` and ``hw run``."""
    wire = stepped.emu.config.robot
    name = {"go1": "go1-arm", "a1": "a1-wx200"}[wire]
    args = build_parser().parse_args(["hw", "check", "--robot", name, "--target", "127.0.0.1:9", "--seconds", "0.1"])
    assert hw_check(args, build=stepped.build) == 0
    out = capsys.readouterr().out
    assert f"{name} at 127.0.0.1:9" in out and "rejected states: 0" in out
    assert main(["hw", "check", "--robot", "b1", "--target", "127.0.0.1:9"]) == 2


def test_emulate_takes_an_arm_name_only_with_its_arm_and_names_a_locked_arm(capsys: pytest.CaptureFixture[str]
                                                                            ) -> None:
    for arm in ((), ("--arm", "none")):  # go1-arm, served as a bare go1, was a contradiction said nowhere
        assert main(["hw", "emulate", "--robot", "go1-arm", *arm, "--seconds", "0.2", "--no-realtime"]) == 2
        err = capsys.readouterr().err
        assert "--robot go1-arm names the robot with its arm: add --arm locked" in err and "--robot go1" in err
    assert main(["hw", "emulate", "--robot", "go1-arm", "--arm", "locked", "--seconds", "0.2", "--lockstep",
                 "--no-realtime"]) == 0
    assert "emulated go1 with its arm locked on the trunk (lockstep)" in capsys.readouterr().out
    assert main(["hw", "emulate", "--robot", "go1", "--seconds", "0.2", "--lockstep", "--no-realtime"]) == 0
    assert "emulated go1 (lockstep)" in capsys.readouterr().out  # the bare quadruped stays the default


def test_emulate_refuses_a_fault_given_twice(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["hw", "emulate", "--fault", "drop", "--fault", "DROP", "--seconds", "0.2", "--no-realtime"]) == 2
    assert "--fault drop is given twice" in capsys.readouterr().err


def test_check_over_the_vendor_sdk_says_that_it_listens_on_every_interface(capsys: pytest.CaptureFixture[str]
                                                                           ) -> None:
    pytest.importorskip("unitree_legged_sdk")
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1")) as emu:
        args = build_parser().parse_args(["hw", "check", "--robot", "go1", "--target", f"127.0.0.1:{emu.address[1]}",
                                          "--seconds", "0.2", "--transport", "sdk"])
        assert hw_check(args, safety=LENIENT_SAFETY) == 0
        assert all(c.damping for c in emu.commands())
    assert "the vendor SDK binds its port on every interface" in capsys.readouterr().err


def test_check_of_a_robot_answering_from_another_port_counts_its_datagrams_on_the_link_line_too(
        capsys: pytest.CaptureFixture[str]) -> None:
    """Every reply comes from the emulator's other port: the link finds no state stream and closes its channel. The
    link line gives the count the first line gives; it read 0 from the channel already closed."""
    rig = Stepped(ManualClock(), UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="realtime")))
    try:
        rig.emu.inject(Fault.FOREIGN_PORT)
        args = build_parser().parse_args(["hw", "check", "--robot", "go1", "--target", "127.0.0.1:9",
                                          "--seconds", "0.1"])
        assert hw_check(args, build=rig.build) == 1
    finally:
        rig.emu.close()
    first, *rest = capsys.readouterr().out.splitlines()
    counted = re.search(r"\(0 rejected; (\d+) from another address\)", first)
    assert counted is not None and int(counted.group(1)) > 0, first
    (link,) = [line for line in rest if line.startswith("  link: ")]
    assert f"; {counted.group(1)} foreign datagrams" in link, link


def test_check_of_a_robot_whose_tick_stands_still_says_that_frames_arrive_and_are_refused(
        capsys: pytest.CaptureFixture[str]) -> None:
    """A board that keeps sending its last buffer: the link takes its first frame and refuses the others for their
    tick. The check counts them and says what the waiting means (not 'nothing came': 0 rejected by the decoder)."""
    rig = Stepped(ManualClock(), UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="realtime")))
    try:
        rig.emu.inject(Fault.FROZEN_STATE)
        args = build_parser().parse_args(["hw", "check", "--robot", "go1", "--target", "127.0.0.1:9",
                                          "--seconds", "0.1"])
        assert hw_check(args, build=rig.build) == 1
    finally:
        rig.emu.close()
    out = capsys.readouterr().out
    refused = re.search(r"  frames refused for their tick: (\d+) ", out)
    assert refused is not None and int(refused.group(1)) > 0, out
    assert "rejected states: 0 " in out
    (verdict,) = [line for line in out.splitlines() if line.startswith("  safety: ")]
    assert verdict.startswith("  safety: waiting: no live state stream: frames arrive (") and "reconnect" in verdict
