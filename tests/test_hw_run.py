"""Hardware trials (``wbc hw run``): a scenario's trial through the runner on a robot over its wire, here an emulated
Go1.

The trials of the default suite run the whole procedure (``wbc hw run``'s `hw_run`, `run_hardware_trial`) on a
`ManualClock`: the procedure is handed a robot builder (`build`) that gives the legs' link that clock and the
emulator's in-process channel, so the emulated robot's physics, the 500 Hz link and the 50 Hz controller all move
with the clock, in lockstep, and what reached the wire in which link period is the same at any load. The same
trials in real time, with the devices in their I/O process, are ``realtime`` tests.

Every socket binds 127.0.0.1 on a port the kernel picks and every frame goes to 127.0.0.1; the non-loopback targets
(TEST-NET-1) are only ever refused, and a test checks that no socket was created for them. Every trial is bounded
by its ``--seconds``. What reached the robot is read from the emulator's log of decoded frames.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import gc
import importlib
import io
import json
import math
import os
import re
import signal
import socket
import subprocess
import sys
import termios
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from conftest import Stepped, hw_run_arm_in_lockstep, terminal_signals_in_child

from wbc.arena import hw_trial
from wbc.arena.episode import Episode
from wbc.arena.hw_trial import ConnectInterrupted, HardwareTrialConfig, run_hardware_trial
from wbc.arena.operator import ScriptedKeys
from wbc.arena.runner import PreparingObserver, run_episode
from wbc.arena.trial_record import TrialRecord
from wbc.cli import main
from wbc.cli.main import hw_run, unpowered_arm_warning
from wbc.cli.parser import build_parser
from wbc.cli.printers import print_hw_run
from wbc.cli.terminal_keys import TerminalKeys
from wbc.control.registry import ControllerSpec, arm_variant, get_controller
from wbc.errors import ConfigError, ResultsDirError, StandUpError
from wbc.estimation.base_estimate import BaseEstimate
from wbc.estimation.estimated_robot import EstimatedRobot
from wbc.hardware.capabilities import ConfigurationEstimate, HasSafetyEvents
from wbc.hardware.clock import ManualClock
from wbc.hardware.emulators import BusFault, Fault, UnitreeEmulator, UnitreeEmulatorConfig
from wbc.hardware.hardware_robot import HardwareRobot, HardwareRobotConfig
from wbc.hardware.io_process import ProcessRobot, build_process_robot
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.hardware.realtime import NO_REALTIME
from wbc.hardware.robot import Robot
from wbc.hardware.safety import SafetyConfig
from wbc.hardware.safety.events import REMEDIES
from wbc.hardware.unitree import UnitreeRobot, UnitreeRobotConfig
from wbc.hardware.unitree.target_lock import hold_target
from wbc.scenario.scenario import load_scenario
from wbc.types import MotorCommand, RobotState, VelocityCommand
from wbc.viz.content import SceneContent
from wbc.viz.frame import VizFrame
from wbc.viz.live import LiveObserver
from wbc.viz.replay import load_stored_episode

ROOT = Path(__file__).resolve().parents[1]
PUSH = str(ROOT / "scenarios" / "push-v1.toml")  # version 1: its trial 0 holds the 4 pushes named below
TURN = ROOT / "scenarios" / "turn.toml"
NOT_LOOPBACK = "192.0.2.1:9"  # TEST-NET-1 (documentation only), discard port: refused before anything is sent
LINK_PERIOD = 0.002  # [s] the link's default rate, 500 Hz
TIME_EPS = 1e-9  # [s] float rounding of the clock's sums of periods
TICK = 0.02  # [s] the stand controller's period (50 Hz)


@pytest.fixture
def stepped_go1() -> Iterator[Stepped]:
    """An emulated Go1 (bare) in real-time mode on a manual clock, held at its standing pose until a command drives a
    motor, as ``wbc hw emulate --robot go1`` serves it: an operator holds a robot in its harness until the controller
    takes it."""
    rig = Stepped(ManualClock(), UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="realtime",
                                                                       held_until_driven=True)))
    yield rig
    rig.emu.close()
    assert not [t.name for t in threading.enumerate() if t.name.startswith("unitree-")]  # no thread ever started


@pytest.fixture
def go1() -> Iterator[UnitreeEmulator]:
    """A real-time emulated Go1 (bare), held at its standing pose until a command drives a motor, as ``wbc hw emulate
    --robot go1`` serves it: an operator holds a robot in its harness until the controller takes it."""
    with UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="realtime", held_until_driven=True)) as emu:
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


def _check_stand_trial(out: Path, printed: pytest.CaptureFixture, io_process: bool,
                       frames: list) -> TrialRecord:
    """What a 3 s stand trial over the wire must have left: its record, episode, report and the frames on the wire."""
    # the devices ran in the I/O process, or in this one; either way the same robot was played
    assert ("devices in an I/O process" in printed.out) == io_process
    (record,) = TrialRecord.read_csv(out / "trials.csv")
    assert record.controller == "stand-noarm"  # stand, on a robot whose arm mode is none
    assert (record.backend, record.metrics_source) == ("unitree", "estimator")
    assert record.success and record.safety_trips == 0 and record.ttf == 1.0
    assert record.n_pushes == 0 and record.push_force_n == 0.0  # the trial's pushes were not played
    assert math.isnan(record.friction) and math.isnan(record.payload_kg)  # the simulator's randomisation: unknown
    # the estimator saw a robot standing still: its velocity near zero, its trunk at the Go1's standing height
    assert record.vlin_err < 0.1 and record.max_roll_deg < 5.0
    (path,) = (out / "episodes" / "stand-noarm").glob("*.npz")
    episode = Episode.load(str(path))
    assert episode.base_source == "estimator" and len(episode.t) == 150  # 3 s at 50 Hz
    assert 0.24 < episode.qpos[-1, 2] < 0.32
    assert len(episode.safety_events) == 0  # the layer ramped the robot up before the trial, and never tripped
    # the push scenario's pushes and terrain were skipped, and both the report and the printout say so
    report = (out / "report.md").read_text()
    for text in ("SKIPPED", "4 push(es)", "fractal ground", "metrics_source = estimator", "## Safety events",
                 "ramp_done", "deadline misses", "late advances", "backend unitree"):
        assert text in report, text
    assert "SKIPPED" in printed.out and "completed" in printed.out
    hardware = json.loads((out / "hardware.json").read_text())
    assert hardware["backend"] == "unitree" and hardware["link"]["rejected_states"] == 0
    assert hardware["stale_frames"] == 0  # no leg frame refused for its tick: the emulator's tick moved on each time
    assert (hardware["io_cpu_s"] is not None) == io_process  # the I/O process's CPU, apart
    ramp_done = [e["time"] for e in hardware["safety_events"] if e["reason"] == "ramp_done"]
    assert [e["reason"] for e in hardware["safety_events"]] == ["fresh_state", "ramp_done"]
    assert ramp_done[0] <= hardware["trial_started_s"]  # the trial's clock started on a standing robot
    assert json.loads((out / "run.json").read_text())["config"]["robot"] == "go1-arm"
    stored = load_stored_episode(out, 0)  # what `wbc view --episode` replays: the robot played on, on flat ground
    assert (stored.trial.robot, stored.trial.terrain.kind, stored.trial.pushes) == ("go1-arm", "flat", ())
    assert len(list(stored.frames())) == 149  # 150 rows: the last has no joints of its instant
    # the controller drove the robot: servo frames reached the wire after the ramp, not damping
    servo = [c for c in frames if not c.damping]
    assert len(servo) > 1000 and np.allclose(servo[-200].wire.kp, 60.0)
    return record


def test_stand_trial_over_the_wire_writes_a_results_dir_with_estimator_metrics(
        stepped_go1: Stepped, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "hw"
    args = build_parser().parse_args(["hw", "run", "stand", "--robot", "go1-arm", "--arm", "none", "--scenario", PUSH,
                                      "--trial", "0", "--target", "127.0.0.1:9", "--seconds", "3", "--out", str(out),
                                      "--no-io-process"])
    frozen: list[int] = []  # the objects frozen while the trial played
    real = hw_trial.frozen_heap

    @contextlib.contextmanager
    def watched() -> Iterator[int]:
        with real() as count:
            frozen.append(gc.get_freeze_count())
            yield count

    monkeypatch.setattr(hw_trial, "frozen_heap", watched)
    gc.unfreeze()  # as a library caller's heap would be: not frozen
    assert hw_run(args, build=stepped_go1.build) == 0
    _check_stand_trial(out, capsys.readouterr(), False, stepped_go1.emu.commands())
    # the heap was frozen once all was built (the robot's clock is a wall clock: the test's), and handed back to the
    # collector once the robot closed, for a caller that plays trial after trial
    assert len(frozen) == 1 and frozen[0] > 0 and gc.get_freeze_count() == 0
    hardware = json.loads((out / "hardware.json").read_text())
    link = hardware["link"]
    # on the trial's clock, the link sent a frame every period and was answered every period, and the controller's
    # advance never found its deadline past
    assert link["deadline_trips"] == 0 and link["overruns"] == 0 and link["late_advances"] == 0
    assert link["valid_states"] >= link["frames_sent"] - 1


def test_a_locked_arm_without_its_port_is_said_to_need_a_mechanical_lock_on_a_real_robot_only(
        stepped_go1: Stepped, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    said = "nothing drives the arm's servos, so the arm must be fixed mechanically"
    assert said in unpowered_arm_warning("stand-locked", "locked", None, real=True)
    assert unpowered_arm_warning("stand-locked", "locked", "/dev/ttyUSB0", real=True) is None  # its servos hold it
    assert unpowered_arm_warning("stand-noarm", "none", None, real=True) is None
    assert unpowered_arm_warning("stand-locked", "locked", None, real=False) is None  # an emulator's physics holds it
    args = build_parser().parse_args(["hw", "run", "stand", "--robot", "go1-arm", "--arm", "locked", "--scenario",
                                      PUSH, "--trial", "0", "--target", "127.0.0.1:9", "--seconds", "0.2",
                                      "--settle", "0.2", "--out", str(tmp_path / "locked"), "--no-io-process"])
    hw_run(args, build=stepped_go1.build)
    assert said not in capsys.readouterr().err


@pytest.mark.realtime
@pytest.mark.parametrize("io_process", ["--io-process", "--no-io-process"])
def test_realtime_stand_trial_over_the_wire(go1: UnitreeEmulator, tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str], io_process: str) -> None:
    out = tmp_path / "hw"
    code = main(["hw", "run", "stand", "--robot", "go1-arm", "--arm", "none", "--scenario", PUSH, "--trial", "0",
                 "--target", f"127.0.0.1:{go1.address[1]}", "--seconds", "3", "--out", str(out), io_process])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    record = _check_stand_trial(out, printed, io_process == "--io-process", go1.commands())
    assert record.deadline_misses == 0 and record.act_ms_p99 < 20.0


def test_a_stand_trial_with_the_devices_in_their_io_process(go1: UnitreeEmulator, tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """The I/O process's path through `wbc hw run`, over real time: a short trial that must complete and report the
    I/O process apart (what it achieves in real time is the realtime twin's to judge)."""
    out = tmp_path / "hw"
    args = build_parser().parse_args(["hw", "run", "stand", "--robot", "go1-arm", "--arm", "none", "--scenario", PUSH,
                                      "--trial", "0", "--target", f"127.0.0.1:{go1.address[1]}", "--seconds", "0.5",
                                      "--out", str(out), "--io-process"])
    # the layer's defaults but a stale timeout that only a hung emulator misses: on a busy machine the default 0.1 s
    # tripped the stand-up (exit 2); when the layer trips on time is the lockstep twins' to check
    code = hw_run(args, safety=SafetyConfig(position_table="go1", stale_timeout_s=30.0))
    printed = capsys.readouterr()
    assert code == 0, printed.err
    assert "devices in an I/O process" in printed.out
    hardware = json.loads((out / "hardware.json").read_text())
    assert hardware["backend"] == "unitree" and hardware["io_cpu_s"] is not None
    # the controller's loop asked for real-time scheduling 10 below the devices' (granted or refused, said), on any
    # CPU, and this thread has its own scheduling back
    loop = hardware["controller_realtime"]
    assert loop["asked"] == "SCHED_FIFO 40" and (loop["realtime"] or loop["refused"])
    assert "controller loop" in printed.out and "controller loop's scheduling" in (out / "report.md").read_text()
    if hasattr(os, "sched_getscheduler"):
        assert os.sched_getscheduler(0) == os.SCHED_OTHER
    (record,) = TrialRecord.read_csv(out / "trials.csv")
    assert record.backend == "unitree" and record.controller == "stand-noarm"
    assert any(not c.damping for c in go1.commands())  # the I/O process drove the motors


def _children(pid: int) -> list[int]:
    """The processes whose parent is `pid` (read from /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and int((entry / "stat").read_text().rpartition(")")[2].split()[1]) == pid:
                found.append(int(entry.name))
        except (OSError, ValueError, IndexError):
            continue  # it ended meanwhile
    return found


def _running(pid: int) -> bool:
    """`pid` runs (neither gone nor a zombie left for its parent to reap)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0] != "Z"
    except OSError:
        return False


def _interrupted_hw_run(args: argparse.Namespace, stepped: Stepped, capsys: pytest.CaptureFixture[str]) -> str:
    """``hw run`` with `args` on the lockstep emulator, which an interruption ends with status 130: its stderr."""
    try:
        code = hw_run(args, build=stepped.build)
    except KeyboardInterrupt:
        pytest.fail("the interruption escaped the command, unsaid")
    err = capsys.readouterr().err
    assert code == 130, err
    return err


def _ctrl_c_while_writing_hardware_json(monkeypatch: pytest.MonkeyPatch, times: int) -> None:
    """Ctrl-C `times` times as a hardware trial writes hardware.json (after the trial's row and episode)."""
    import wbc.arena.hw_trial as hw_trial

    write = hw_trial.write_text

    def interrupted(path, text):
        for _ in range(times):
            signal.raise_signal(signal.SIGINT)
        return write(path, text)

    monkeypatch.setattr(hw_trial, "write_text", interrupted)


def _io_process_ended_and_legs_damped(go1: UnitreeEmulator, sent: int, io_process: int) -> None:
    """The I/O process `io_process` ended (within 5 s), and the frames after the first `sent` end in damping alone."""
    for _ in range(500):  # bounded (5 s)
        if not _running(io_process):
            break
        time.sleep(0.01)
    assert not _running(io_process)
    frames = go1.commands()[sent:]
    first = next((k for k, c in enumerate(frames) if c.damping), None)
    assert first is not None, [f"kp {c.wire.kp.max():g}" for c in frames]
    assert all(c.damping for c in frames[first:])  # damping, and nothing else after it: the legs end damped


def _standing_hw_run(go1: UnitreeEmulator, out: Path, *options: str) -> subprocess.Popen:
    """``wbc hw run stand`` in a process group of its own, once its safety layer drives the emulator's legs.

    The command runs on the real clock: on a busy machine its safety layer can trip on a stale state during the
    stand-up (the stand-up error, exit 2, nothing played), as it should. That start is made again, up to three times:
    what the callers check begins once the robot is driven.
    """
    for attempt in range(3):
        start = len(go1.commands())
        proc = subprocess.Popen(
            [sys.executable, "-m", "wbc.cli", "hw", "run", "stand", "--robot", "go1-arm", "--arm", "none",
             "--scenario", PUSH, "--trial", "0", "--target", f"127.0.0.1:{go1.address[1]}", "--seconds", "20",
             "--no-realtime", "--out", str(out / f"hw-{attempt}"), *options], stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)),
            start_new_session=True,  # a group of its own, as a terminal's
            preexec_fn=terminal_signals_in_child)  # the hangup not ignored, whether or not this suite runs under nohup
        try:
            for _ in range(6000):  # bounded (60 s): until the safety layer drives the legs (the ramp into the stand)
                if proc.poll() is not None or any(not c.damping for c in go1.commands()[start:][-5:]):
                    break
                time.sleep(0.01)
        except BaseException:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            raise
        if proc.poll() is None:
            return proc
        err = proc.stderr.read().decode()
        if proc.returncode != 2 or "nothing was played" not in err or attempt == 2:
            raise AssertionError(f"wbc hw run ended before its robot was driven (exit {proc.returncode}): {err}")
    raise AssertionError("unreachable")


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
def test_a_closed_terminal_closes_the_robot_into_damping_and_ends_the_io_process(go1: UnitreeEmulator,
                                                                                 tmp_path: Path) -> None:
    """SIGHUP to the process group of ``wbc hw run`` (its terminal closed, which reads no more of what it prints): the
    command closes the robot as on Ctrl-C, and the I/O process, which ignores the hangup, damps the legs and exits.
    The command used to die at once, and its I/O process with it, leaving the legs holding the stand's kp 60."""
    proc = _standing_hw_run(go1, tmp_path)
    try:
        io_process = _children(proc.pid)
        assert len(io_process) == 1
        proc.stdout.close()  # the terminal is gone: whatever is printed from now on fails (EPIPE)
        proc.stderr.close()
        sent = len(go1.commands())
        os.killpg(proc.pid, signal.SIGHUP)
        code = proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert code == 130  # interrupted, its last words dropped: neither a lost line nor the flush at exit failed it
    _io_process_ended_and_legs_damped(go1, sent, io_process[0])


def test_a_link_lost_in_the_trial_exits_1_and_says_the_damping_may_not_have_reached_the_robot(
        stepped_go1: Stepped, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The robot stops answering 1 s into the trial: the safety layer trips on the stale stream and sends damping, and
    the results are written, but nothing shows that the damping reached the robot. The command exits 1 and its last
    line says so, with when the last state came. It exited 0, its last line the results directory."""
    emu, clock = stepped_go1.emu, stepped_go1.clock
    started: list[float] = []

    def build(config: HardwareRobotConfig) -> HardwareRobot:
        built = stepped_go1.build(config)
        # the stand-up takes 1.06 s of this clock (the ramp's hold, time and slew): about 1 s into the trial
        clock.call_at(clock.now() + 2.0, lambda: (started.append(clock.now()), emu.inject(Fault.SILENCE)))
        return built

    out = tmp_path / "hw"
    args = build_parser().parse_args(["hw", "run", "stand", "--robot", "go1-arm", "--arm", "none", "--scenario", PUSH,
                                      "--trial", "0", "--target", "127.0.0.1:9", "--seconds", "3", "--settle", "0.5",
                                      "--out", str(out), "--no-io-process"])
    assert hw_run(args, build=build) == 1
    err = capsys.readouterr().err.strip().splitlines()
    (record,) = TrialRecord.read_csv(out / "trials.csv")  # the trial is stored, ended by the trip
    assert record.outcome == "safety_trip" and record.safety_trips == 1
    hardware = json.loads((out / "hardware.json").read_text())
    trip = hardware["safety_events"][-1]
    assert trip["reason"] == "stale_state"
    lost = hardware["link_lost"]  # on the layer's clock: the last state came as the silence began, none after
    last_state, silent = lost["last_state_s"], lost["silent_s"]
    assert last_state <= started[0] + LINK_PERIOD + TIME_EPS and trip["time"] - last_state > 0.1 and silent >= 0.5 + 0.1
    assert err[-1] == (f"wbc hw run: the link to the robot was lost: its last state came {last_state:.3f} s after it "
                       f"was connected ({last_state - hardware['trial_started_s']:.3f} s into the trial) and none "
                       f"came in the {silent:.3f} s after: the damping frames sent since may not have reached the "
                       "robot. Check it and power it down by hand")
    assert "## Link lost" in (out / "report.md").read_text()
    # what went out: the layer's damping from the trip to the close, as on any trip
    after = [c for c in emu.commands() if c.time > trip["time"] + LINK_PERIOD + TIME_EPS]
    assert after and all(c.damping for c in after)


def test_a_frozen_board_is_said_to_send_frames_with_a_frozen_tick_and_its_refused_frames_are_printed(
        stepped_go1: Stepped, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The robot's board freezes 1 s into the trial (every reply the datagram before, its tick standing still): the
    layer trips on the stale stream, and the frames go on arriving, refused for their tick. The last line said that
    none came (the damping "may not have reached the robot"), and neither the run's summary nor the report gave the
    refused frames."""
    emu, clock = stepped_go1.emu, stepped_go1.clock

    def build(config: HardwareRobotConfig) -> HardwareRobot:
        built = stepped_go1.build(config)
        clock.call_at(clock.now() + 2.0, lambda: emu.inject(Fault.FROZEN_STATE))
        return built

    out = tmp_path / "hw"
    args = build_parser().parse_args(["hw", "run", "stand", "--robot", "go1-arm", "--arm", "none", "--scenario", PUSH,
                                      "--trial", "0", "--target", "127.0.0.1:9", "--seconds", "3", "--settle", "0.5",
                                      "--out", str(out), "--no-io-process"])
    assert hw_run(args, build=build) == 1
    printed = capsys.readouterr()
    hardware = json.loads((out / "hardware.json").read_text())
    refused, lost = hardware["stale_frames"], hardware["link_lost"]
    assert refused > 0.5 / LINK_PERIOD and lost["refused_frames"] == refused  # the settle's frames among them
    last = printed.err.strip().splitlines()[-1]
    assert last.startswith("wbc hw run: the robot's state froze: its last fresh state came ")
    assert f"frames still arrive, but with a frozen tick ({refused} refused for their tick" in last
    assert "none came" not in last and "Check it and power it down by hand" in last
    assert f"{refused} frames refused for their tick" in printed.out
    report = (out / "report.md").read_text()
    assert f"| leg frames refused for their tick (stale_frames: a frozen or restarted board) | {refused} |" in report


def test_a_link_lost_during_the_stand_up_says_the_damping_may_not_have_reached_the_robot(
        stepped_go1: Stepped, tmp_path: Path) -> None:
    """The robot stops answering half a second into the stand-up: the layer trips on the stale stream, nothing is
    played, and the error says that the damping may not have reached the robot and to power it down by hand, before
    the stale trip's own remedy. It gave that remedy alone, as if the robot had heard the damping."""
    emu, clock = stepped_go1.emu, stepped_go1.clock

    def build(config: HardwareRobotConfig) -> HardwareRobot:
        built = stepped_go1.build(config)
        clock.call_at(clock.now() + 0.5, lambda: emu.inject(Fault.SILENCE))  # the stand-up takes 1.06 s
        return built

    args = build_parser().parse_args(["hw", "run", "stand", "--robot", "go1-arm", "--arm", "none", "--scenario", PUSH,
                                      "--trial", "0", "--target", "127.0.0.1:9", "--seconds", "3", "--settle", "0.5",
                                      "--out", str(tmp_path / "hw"), "--no-io-process"])
    with pytest.raises(StandUpError) as caught:
        hw_run(args, build=build)
    said = str(caught.value)
    assert said.startswith("the safety layer tripped while standing the robot up, before the trial: stale_state")
    assert re.search(r"nothing was played\. The link to the robot was lost: its last state came [0-9.]+ s after it "
                     r"was connected \(during the stand-up\) and none came in the [0-9.]+ s after: the damping frames "
                     r"sent since may not have reached the robot\. Check it and power it down by hand\. The state "
                     r"went stale, and the detail says whose: the legs' stream", said), said
    assert said.endswith("Then run again")
    assert not (tmp_path / "hw" / "trials.csv").exists()
    frames = emu.commands()
    first = next(k for k, c in enumerate(frames) if k > 0 and c.damping and not frames[k - 1].damping)
    assert all(c.damping for c in frames[first:])  # from the trip on: damping only


@pytest.mark.usefixtures("terminal_signals")
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_a_stop_while_the_io_process_starts_says_that_nothing_was_connected(
        go1: UnitreeEmulator, tmp_path: Path, capsys: pytest.CaptureFixture[str], signum: int) -> None:
    """Ctrl-C or SIGTERM to the command as soon as its I/O process exists, long before it has imported `wbc`: the
    command exits 130 and says that the robot was not connected, and nothing but damping reached it. It said that the
    robot was closed into damping."""
    from wbc.cli.main import _terminate_interrupts

    robots: list[ProcessRobot] = []

    def build(config: HardwareRobotConfig) -> HardwareRobot:
        built = build_process_robot(dataclasses.replace(config, realtime=NO_REALTIME))
        robots.append(built.robot)
        return built

    def stop_at_once() -> None:
        for _ in range(600_000):  # bounded (at most a minute): until the I/O process exists
            if robots and robots[0]._proc is not None:
                os.kill(os.getpid(), signum)
                return
            time.sleep(0.0001)

    out = tmp_path / "hw"
    args = build_parser().parse_args(["hw", "run", "stand", "--robot", "go1-arm", "--arm", "none", "--scenario", PUSH,
                                      "--trial", "0", "--target", f"127.0.0.1:{go1.address[1]}", "--seconds", "1",
                                      "--out", str(out)])
    sender = threading.Thread(target=stop_at_once)
    sender.start()
    try:
        with _terminate_interrupts():
            code = hw_run(args, build=build)
    finally:
        sender.join()
    err = capsys.readouterr().err
    assert code == 130, err
    assert "closed into damping" not in err
    assert err.strip().splitlines()[-1] == ("wbc hw run: interrupted while the robot was being connected, before the "
                                            "controller or the safety layer sent it anything: nothing was played; no "
                                            "results were written")
    assert robots[0].pid is None and not robots[0].is_connected  # the I/O process is gone
    assert all(c.damping for c in go1.commands())  # not one servo frame
    assert not (out / "trials.csv").exists()


def test_a_stop_before_the_robot_connects_is_said_to_have_sent_it_nothing(stepped_go1: Stepped, tmp_path: Path) -> None:
    """Ctrl-C at the confirmation, before the robot's connect began: the trial says that nothing was opened."""
    def confirm(hardware: HardwareRobot, spec: object) -> None:
        raise KeyboardInterrupt

    cfg = HardwareTrialConfig(controller="stand", scenario=Path(PUSH), trial=0, robot="go1-arm", arm_mode="none",
                              seconds=1.0, target=("127.0.0.1", 9), out_dir=tmp_path / "hw", io_process=False)
    with pytest.raises(ConnectInterrupted) as stopped:
        run_hardware_trial(cfg, before_connect=confirm, build=stepped_go1.build)
    assert not stopped.value.opening
    assert not stepped_go1.emu.commands()  # not one frame

def test_a_second_run_on_a_results_directory_is_refused_before_it_sends_anything(
        stepped_go1: Stepped, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A second ``hw run`` with the same ``--out`` while the first plays, and another once the first has written its
    results: each is refused before its robot is built, and its emulator got no frame. The second used to stand its
    robot up and play the trial, and be refused only when it wrote its results, its frames interleaved on the wire
    with the first's when both drove one robot."""
    out = tmp_path / "dup"
    argv = ["hw", "run", "stand", "--robot", "go1-arm", "--arm", "none", "--scenario", PUSH, "--trial", "0",
            "--target", "127.0.0.1:9", "--seconds", "1", "--out", str(out), "--no-io-process"]
    refusals: list[BaseException] = []
    others: list[UnitreeEmulator] = []

    def second_run() -> None:
        other = Stepped(ManualClock(), UnitreeEmulator(UnitreeEmulatorConfig(robot="go1", mode="realtime",
                                                                             held_until_driven=True)))
        others.append(other.emu)
        try:
            hw_run(build_parser().parse_args(argv), build=other.build)
        except ResultsDirError as refused:
            refusals.append(refused)
        finally:
            other.emu.close()

    def build(config: HardwareRobotConfig) -> HardwareRobot:
        built = stepped_go1.build(config)
        # the stand-up takes 1.06 s of this clock: half a second into the trial
        stepped_go1.clock.call_at(stepped_go1.clock.now() + 1.5, second_run)
        return built

    assert hw_run(build_parser().parse_args(argv), build=build) == 0  # the first run, undisturbed
    assert TrialRecord.read_csv(out / "trials.csv")
    second_run()  # once the first has written its results
    capsys.readouterr()
    assert len(refusals) == 2, refusals
    assert str(refusals[0]) == (f"{out} is in use by another wbc run (pid {os.getpid()}); wait for it to end, or "
                                "give another --out")
    assert str(refusals[1]) == f"{out}: already holds results; a hardware trial is played once: choose another --out"
    assert [len(emu.commands()) for emu in others] == [0, 0]  # neither sent its robot a frame


def test_a_second_run_to_a_robot_another_link_drives_is_refused_before_its_socket_exists(
        go1: UnitreeEmulator, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """One link drives the emulated robot (a run's, over UDP); ``hw run`` to the same target is refused with status 2,
    naming the process that holds it, before it makes a socket, and so before any frame of its could reach the robot.
    Each link binds a port of its own, so the second used to connect as well and drive the robot between the first's
    frames. Once the first is closed, its target is free again."""
    config = UnitreeRobotConfig(robot="go1", target_host="127.0.0.1", target_port=go1.address[1],
                                connect_timeout=30.0)  # a bound: a busy machine's emulator answers late
    first = UnitreeRobot(config)
    with first:
        sockets: list[tuple] = []
        made = socket.socket

        def counted(*args: object, **kwargs: object) -> socket.socket:
            sockets.append(args)
            return made(*args, **kwargs)

        monkeypatch.setattr(socket, "socket", counted)
        code = main(["hw", "run", "stand", "--robot", "go1-arm", "--arm", "none", "--scenario", PUSH, "--trial", "0",
                     "--target", f"127.0.0.1:{go1.address[1]}", "--seconds", "1", "--out", str(tmp_path / "hw"),
                     "--no-io-process", "--no-realtime"])
        monkeypatch.undo()
        err = capsys.readouterr().err
        assert code == 2, err
        assert err.strip().splitlines()[-1] == (
            f"wbc: error: 127.0.0.1:{go1.address[1]}: another wbc process (pid {os.getpid()}) is connected to this "
            "robot (a hw run, its I/O process, a hw check or a bench); nothing was sent to it: wait for that one to "
            "end, or stop it, then run again")
        assert not sockets  # no socket, no frame
        assert not (tmp_path / "hw").exists()
    hold_target("127.0.0.1", go1.address[1]).release()  # free once the first link is closed


class _MeshesInterrupted:
    """A live viewer's observer whose meshes load until Ctrl-C comes."""

    def __call__(self, *args: object) -> None:
        raise AssertionError("no tick may be drawn: the trial was interrupted before the robot was connected")

    def prepare(self, robot: Robot) -> None:
        raise KeyboardInterrupt

    def close(self) -> None:
        pass


class _Server:
    def stop(self) -> None:
        pass


def _interrupted(*args: object, **kwargs: object) -> None:
    raise KeyboardInterrupt


def _controller_interrupted(named: ControllerSpec, arm_mode: str) -> ControllerSpec:
    return dataclasses.replace(arm_variant(named, arm_mode), make=_interrupted)


_BEFORE_THE_CONNECT = {
    "viewer's server": ("wbc.cli.main", "_hw_live_observer", _interrupted),
    "viewer's meshes": ("wbc.cli.main", "_hw_live_observer", lambda args: (_Server(), _MeshesInterrupted())),
    "operator's keys": ("wbc.cli.main", "TerminalKeys", _interrupted),
    "scenario": ("wbc.arena.hw_trial", "load_scenario", _interrupted),
    "robot built": ("wbc.arena.hw_trial", "warn_if_unpublished", _interrupted),
    "controller": ("wbc.arena.hw_trial", "arm_variant", _controller_interrupted),
    "safety layer": ("wbc.arena.hw_trial", "SafeRobot", _interrupted),
    "estimator": ("wbc.arena.hw_trial", "BaseEstimate", _interrupted),
}
"""Steps of ``wbc hw run`` before its robot is connected, and what stands in for each to be interrupted there."""


@pytest.mark.parametrize("step", list(_BEFORE_THE_CONNECT))
def test_ctrl_c_at_any_step_before_the_connect_says_that_nothing_was_sent(
        stepped_go1: Stepped, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        step: str) -> None:
    """Ctrl-C while the viewer loads its meshes, the controller is built, the safety layer or the estimator is made
    (and every other step before the robot's connect): the command exits 130 and says that nothing was sent to the
    robot, and the emulator got no frame. It said that the robot was closed into damping."""
    module, name, stand_in = _BEFORE_THE_CONNECT[step]
    monkeypatch.setattr(importlib.import_module(module), name, stand_in)
    out = tmp_path / "hw"
    args = build_parser().parse_args(["hw", "run", "stand", "--robot", "go1-arm", "--arm", "none", "--scenario", PUSH,
                                      "--trial", "0", "--target", "127.0.0.1:9", "--seconds", "1", "--out", str(out),
                                      "--no-io-process", *(["--view"] if "viewer" in step else [])])
    err = _interrupted_hw_run(args, stepped_go1, capsys)
    assert err.strip().splitlines()[-1] == ("wbc hw run: interrupted before the robot was connected: nothing was "
                                            "sent to it; no results were written")
    assert not stepped_go1.emu.commands()  # not one frame
    assert not out.exists()  # the results directory it made, holding nothing, is gone


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
def test_sigterm_to_the_commands_group_is_an_interruption_and_the_robot_ends_damped(go1: UnitreeEmulator,
                                                                                     tmp_path: Path) -> None:
    """SIGTERM to the process group of ``wbc hw run`` (a service manager's stop) during the stand-up, before the
    trial: the command and its I/O process both take it. The command closes the robot as on Ctrl-C and exits 130 with
    the same last line: nothing was played, and no results were written. It exited 2: the I/O process's report that
    SIGTERM stopped it, taken for a failure of the close."""
    proc = _standing_hw_run(go1, tmp_path)
    try:
        (io_process,) = _children(proc.pid)
        sent = len(go1.commands())
        os.killpg(proc.pid, signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    err = err.decode()
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == ("wbc hw run: interrupted; the robot was closed into damping; no results "
                                            "were written")
    _io_process_ended_and_legs_damped(go1, sent, io_process)


def test_sigterm_to_the_commands_group_during_the_settle_after_a_trip_keeps_the_trials_results(
        go1: UnitreeEmulator, tmp_path: Path) -> None:
    """The trial is over at the trip: SIGTERM to the whole group (the command and its I/O process, which closes the
    robot itself) during the 30 s settle after it ends the command with the trial's results written whole. The I/O
    process's stop, met in the settle and in the close, threw them away ("no results were written").

    The command runs on the real clock: a machine busy enough to hold the emulator's thread off for 0.1 s trips the
    stand-up's ramp on a stale state (exit 2, nothing played), as it should. That start is made again, up to three
    times: what is checked begins at the trial's trip."""
    for attempt in range(3):
        out = tmp_path / f"try-{attempt}"
        out.mkdir()
        if attempt:
            go1.reset()  # the tripped start left the robot damped, collapsed: stand it again, held, for the next
        proc = _standing_hw_run(go1, out, "--settle", "30")
        lines: list[str] = []
        reader = threading.Thread(target=lambda p=proc, ls=lines: ls.extend(line.decode() for line in p.stderr),
                                  daemon=True)
        reader.start()

        def said(text: str, proc: subprocess.Popen = proc, lines: list[str] = lines) -> bool:
            for _ in range(6000):  # bounded (60 s)
                if proc.poll() is not None or any(text in line for line in list(lines)):
                    return proc.poll() is None
                time.sleep(0.01)
            return False

        try:
            if said("-> run (ramp_done)"):  # the stand-up is done: the trial begins
                time.sleep(1.0)  # well into the trial (its --seconds are 20): a trip before it is the stand-up's
                go1.inject(Fault.FALL)  # the trunk reads rolled over: the layer trips on tilt and damps the legs
                if said("-> damped (tilt)"):  # the trial ends at the tick that tripped; the settle follows
                    time.sleep(0.5)  # in the settle (30 s), past the trial's last tick
                    os.killpg(proc.pid, signal.SIGTERM)
            proc.wait(timeout=60)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
            go1.clear()
        reader.join(timeout=10)
        err = "".join(lines)
        if not (proc.returncode == 2 and "nothing was played" in err and attempt < 2):
            break
    assert proc.returncode == 130, err
    (results,) = [d for d in out.iterdir() if (d / "trials.csv").exists()] or [err]
    assert err.strip().splitlines()[-1] == ("wbc hw run: interrupted after the trial; the robot was closed into "
                                            f"damping; its results are complete in {results}")
    (record,) = TrialRecord.read_csv(results / "trials.csv")
    assert record.outcome == "safety_trip" and (results / "hardware.json").is_file()


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
@pytest.mark.parametrize("whom", ["group", "io-process"])
def test_sigterm_during_the_trial_writes_the_episode_played_and_the_robot_ends_damped(
        go1: UnitreeEmulator, tmp_path: Path, whom: str) -> None:
    """SIGTERM 1 s into the trial of ``wbc hw run``, to its process group (a service manager's stop: the command and
    its I/O process both take it) or to its I/O process alone (which closes the robot and says so at the command's
    next call): the robot ends damped, and the results hold the episode played up to the stop, recorded as
    interrupted (exit 130). It exited with "no results were written", the trial's second lost.

    The command runs on the real clock: a machine busy enough to hold the emulator's thread off for 0.1 s trips the
    stand-up's ramp on a stale state (exit 2, nothing played), as it should. That start is made again, up to three
    times: what is checked begins once the trial has started."""
    for attempt in range(3):
        out = tmp_path / f"try-{attempt}"
        out.mkdir()
        if attempt:
            go1.reset()  # the tripped start left the robot damped, collapsed: stand it again, held, for the next
        proc = _standing_hw_run(go1, out)
        (io_process,) = _children(proc.pid)
        lines: list[str] = []
        reader = threading.Thread(target=lambda p=proc, ls=lines: ls.extend(line.decode() for line in p.stderr),
                                  daemon=True)
        reader.start()
        sent = None
        try:
            for _ in range(6000):  # bounded (60 s): until the stand-up is done and the trial begins
                if proc.poll() is not None or any("-> run (ramp_done)" in line for line in list(lines)):
                    break
                time.sleep(0.01)
            if proc.poll() is None:
                time.sleep(1.0)  # well into the trial (its --seconds are 20)
                sent = len(go1.commands())
                if whom == "group":
                    os.killpg(proc.pid, signal.SIGTERM)
                else:
                    os.kill(io_process, signal.SIGTERM)
            proc.wait(timeout=60)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        reader.join(timeout=10)
        err = "".join(lines)
        if not (proc.returncode == 2 and "nothing was played" in err and attempt < 2):
            break
    assert proc.returncode == 130 and sent is not None, err
    (results,) = [d for d in out.iterdir() if (d / "trials.csv").exists()] or [err]
    # to the group, SIGTERM reaches the command first, or (a rare order) its I/O process's report that SIGTERM stopped
    # it does; to the I/O process alone, only that report comes
    by = r"(SIGTERM|its I/O process stopped by SIGTERM)" if whom == "group" else r"its I/O process stopped by SIGTERM"
    assert re.fullmatch(rf"wbc hw run: interrupted at \d+\.\d{{3}} s of the 20 s trial \({by}\); the robot was closed "
                        "into damping; the results up to the interruption are complete in "
                        f"{re.escape(str(results))}", err.strip().splitlines()[-1]), err
    (record,) = TrialRecord.read_csv(results / "trials.csv")
    assert record.outcome == "operator_stop" and not record.success and record.error.startswith("interrupted at ")
    (path,) = (results / "episodes" / "stand-noarm").glob("*.npz")
    episode = Episode.load(str(path))
    hardware = json.loads((results / "hardware.json").read_text())
    assert 0 < len(episode.t) == record.ticks == hardware["interrupted"]["tick"] < 1000  # played, not to its end
    # an interruption is no fall: no fall time; where it was interrupted is the end of its last whole tick
    assert math.isnan(record.fall_time_s) and record.ttf == pytest.approx(episode.t[-1] / 20.0)
    assert hardware["interrupted"]["time_s"] == pytest.approx(episode.t[-1])
    _io_process_ended_and_legs_damped(go1, sent, io_process)


def test_a_hangup_interrupts_a_command_unless_it_was_started_under_nohup() -> None:
    from wbc.cli.main import _terminate_interrupts

    before = signal.signal(signal.SIGHUP, signal.SIG_DFL)
    try:
        with _terminate_interrupts(), pytest.raises(KeyboardInterrupt) as hung:  # as Ctrl-C: the robot is damped
            os.kill(os.getpid(), signal.SIGHUP)
            time.sleep(1.0)  # the handler raises at once; this is only a bound
        assert hung.value.args == ("SIGHUP",)  # named: a hardware trial interrupted while it plays records it
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_DFL  # the handler before is back
        signal.signal(signal.SIGHUP, signal.SIG_IGN)  # nohup: the user asked the command to outlive its terminal
        with _terminate_interrupts():
            assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
            assert signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGHUP, before)


def test_estop_key_latches_damping_on_the_wire_and_ends_the_trial(stepped_go1: Stepped, tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    emu, clock = stepped_go1.emu, stepped_go1.clock
    keys = ScriptedKeys([(0.8, "p"), (1.6, "e")], clock=clock.now)  # an operator's push by hand, then the e-stop
    cfg = HardwareTrialConfig(controller="stand", scenario=Path(PUSH), trial=0, robot="go1-arm", arm_mode="none",
                              seconds=3.0, target=("127.0.0.1", 9), out_dir=tmp_path / "hw", settle_s=0.5,
                              io_process=False)
    result = run_hardware_trial(cfg, keys=keys, before_connect=lambda hardware, spec: emu.reset(),
                                build=stepped_go1.build)
    record, episode = result.record, result.episode
    assert record.safety_trips == 1 and not record.success and record.outcome == "operator_stop"
    # the trial's own play time, as a simulated trial's: not the build, the connect, the stand-up and the settle
    assert record.wall_s == result.episode_wall_s
    # ended at the tick that handled the key, which is no fall: the robot stood (fell False, no fall time), and the
    # trial counts as one that did not complete, its TTF the share played
    assert 1.6 <= episode.t[-1] <= 1.6 + TICK + TIME_EPS and record.ttf == pytest.approx(episode.t[-1] / 3.0)
    assert not episode.fell and math.isnan(episode.fall_time_s) and math.isnan(record.fall_time_s)
    saved = Episode.load(str(next((tmp_path / "hw" / "episodes").rglob("*.npz"))))
    assert not saved.fell and math.isnan(saved.fall_time_s) and saved.stopped
    assert [a for _, _, a in episode.operator_events.rows()] == ["push", "estop"]
    assert episode.safety_events.reason[-1] == "software_estop"
    # who stopped it, and when: the key (it said "estop() called"); the marked push acknowledged on the console
    assert re.fullmatch(r"operator key 'e' at 1\.6\d s of the trial", episode.safety_events.detail[-1])
    assert "operator: key 'p': a push by hand marked at 0.8" in capsys.readouterr().err
    # the summary and the report say what to do about the trip that ended the trial (they said nothing)
    print_hw_run(result)
    remedy = "The e-stop was pressed on this computer: make sure the robot is safe, and start again."
    assert f"  what to do: {remedy}" in capsys.readouterr().out.splitlines()
    assert f"What to do: {remedy}" in (tmp_path / "hw" / "report.md").read_text()
    pressed = dict(keys.delivered)["e"]
    frames = emu.commands()
    before = [c for c in frames if c.time <= pressed + TIME_EPS]
    after = [c for c in frames if c.time > pressed + TIME_EPS]
    assert not before[-1].damping  # the stand hold was on the wire when the key came
    # the e-stop reached the wire in the next link period: its first frame is damping
    assert after[0].damping and after[0].time <= pressed + LINK_PERIOD + TIME_EPS
    # from then on nothing but damping, for the whole settle time the trial held the robot before closing
    assert all(c.damping for c in after) and len(after) >= 0.5 / LINK_PERIOD
    report = (tmp_path / "hw" / "report.md").read_text()
    assert "software_estop" in report and "| push |" in report and "| estop |" in report


def test_a_stall_past_the_write_deadline_in_the_trial_is_counted_in_the_record_and_the_summary(
        stepped_go1: Stepped, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The control loop stalls 70 ms at 1 s into the trial: the legs' link damps on its 50 ms write deadline, and the
    layer ramps the robot again from Kp 5, as documented. The trial goes on to its end, a success; trials.csv and the
    run's summary line count the damping. They said 0 trips, 0 deadline misses and nothing else."""
    emu, clock = stepped_go1.emu, stepped_go1.clock
    stalled: list[float] = []

    def stall(t: float, *args: object) -> None:
        if not stalled and t >= 1.0:
            stalled.append(clock.now())
            clock.advance(0.07)

    cfg = HardwareTrialConfig(controller="stand", scenario=Path(PUSH), trial=0, robot="go1-arm", arm_mode="none",
                              seconds=2.0, target=("127.0.0.1", 9), out_dir=tmp_path / "hw", settle_s=0.5,
                              io_process=False)
    result = run_hardware_trial(cfg, observer=stall, before_connect=lambda hardware, spec: emu.reset(),
                                build=stepped_go1.build)
    (record,) = TrialRecord.read_csv(tmp_path / "hw" / "trials.csv")
    assert record.success and record.safety_trips == 0 and record.write_deadline_ramps == 1
    assert "write_deadline" in list(result.episode.safety_events.reason)
    # on the wire: the link's damping in the stall, then a new ramp from the ramp's gain
    frames = [c for c in emu.commands() if c.time > stalled[0]]
    first = next(k for k, c in enumerate(frames) if c.damping)
    ramp = next(c for c in frames[first:] if not c.damping)
    np.testing.assert_allclose(ramp.wire.kp.max(), SafetyConfig().ramp_kp)
    print_hw_run(result)
    out = capsys.readouterr().out
    assert "safety: 0 trip(s) in the trial, 1 write-deadline damping(s) ramped again;" in out
    report = (tmp_path / "hw" / "report.md").read_text()
    assert "| write-deadline dampings ramped again (the loop stalled past a device's write deadline) | 1 |" in report


@pytest.mark.usefixtures("terminal_signals")
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_a_request_to_end_during_the_settle_after_an_estop_keeps_the_trials_results(
        stepped_go1: Stepped, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        signum: int) -> None:
    """The trial is over at the e-stop: a Ctrl-C or SIGTERM in the settle after it (5 s here) cuts the settle short,
    the robot kept in damping, and the trial's record is written whole. It was thrown away: no results were written."""
    import wbc.arena.hw_trial as hw_trial
    from wbc.cli.main import _terminate_interrupts

    emu, clock = stepped_go1.emu, stepped_go1.clock
    settle = hw_trial._settle
    sent: list[float] = []

    def settle_then_signal(robot, dt, seconds, **kwargs):  # the request to end comes 0.3 s into the settle
        if seconds == 5.0:
            sent.append(clock.now() + 0.3)
            clock.call_at(sent[0], lambda: signal.raise_signal(signum))
        return settle(robot, dt, seconds, **kwargs)

    monkeypatch.setattr(hw_trial, "_settle", settle_then_signal)
    keys = ScriptedKeys([(1.0, "e")], clock=clock.now)
    out = tmp_path / "hw"
    cfg = HardwareTrialConfig(controller="stand", scenario=Path(PUSH), trial=0, robot="go1-arm", arm_mode="none",
                              seconds=3.0, target=("127.0.0.1", 9), out_dir=out, settle_s=5.0, io_process=False)
    with _terminate_interrupts(), pytest.raises(KeyboardInterrupt) as stopped:
        run_hardware_trial(cfg, keys=keys, before_connect=lambda hardware, spec: emu.reset(), build=stepped_go1.build)
    assert isinstance(stopped.value, hw_trial.ResultsInterrupted), "the trial's results were thrown away"
    assert stopped.value.complete and stopped.value.out_dir == out
    said = capsys.readouterr().err
    assert "the settle after the trip or e-stop is cut short and the robot is closed into damping" in said
    (record,) = TrialRecord.read_csv(out / "trials.csv")
    assert record.outcome == "operator_stop" and math.isnan(record.fall_time_s)
    assert 1.0 <= record.ttf * 3.0 <= 1.0 + TICK + TIME_EPS
    assert all((out / name).is_file() for name in ("hardware.json", "summary.json", "report.md"))
    pressed = dict(keys.delivered)["e"]
    after = [c for c in emu.commands() if c.time > pressed + LINK_PERIOD + TIME_EPS]
    assert after and all(c.damping for c in after)  # damping to the end, and the end came soon after the signal
    assert after[-1].time < sent[0] + 0.1
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def _interrupted_at_tick(tick: int, pressed: list[float], clock: ManualClock):
    """`arm_variant` whose controller is interrupted (Ctrl-C) as it computes tick `tick` (0-based): `tick` ticks were
    played whole. The clock's time then is appended to `pressed`."""
    def variant(named: ControllerSpec, arm_mode: str) -> ControllerSpec:
        spec = arm_variant(named, arm_mode)

        def make(desc: object) -> object:
            ctrl = spec.make(desc)
            act, calls = ctrl.act, [0]

            def act_until(state: RobotState, command: VelocityCommand) -> MotorCommand:
                calls[0] += 1
                if calls[0] > tick:
                    pressed.append(clock.now())
                    raise KeyboardInterrupt  # as Python's own Ctrl-C handler raises it
                return act(state, command)

            ctrl.act = act_until
            return ctrl

        return dataclasses.replace(spec, make=make)

    return variant


@pytest.mark.usefixtures("terminal_signals")
@pytest.mark.parametrize("again", [0, 1, 2], ids=["once", "again-while-written", "twice-while-written"])
def test_ctrl_c_during_the_trial_damps_the_robot_at_once_and_writes_the_episode_played(
        stepped_go1: Stepped, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        again: int) -> None:
    """Ctrl-C 1 s into a 3 s trial (as the controller computes tick 50): the safety layer damps the robot from the
    next link period on, nothing but damping reaches the wire until the close and nothing after it, and the results
    hold the 50 ticks played, recorded as interrupted (exit 130). It closed the robot and wrote no results, throwing
    away what the operator who stopped the trial needs. A further Ctrl-C while the results are written waits for them;
    a second stops the writing, as after a trial."""
    import wbc.arena.hw_trial as hw_trial

    emu, clock = stepped_go1.emu, stepped_go1.clock
    pressed: list[float] = []
    monkeypatch.setattr(hw_trial, "arm_variant", _interrupted_at_tick(50, pressed, clock))
    _ctrl_c_while_writing_hardware_json(monkeypatch, again)
    out = tmp_path / "hw"
    args = build_parser().parse_args(["hw", "run", "stand", "--robot", "go1-arm", "--arm", "none", "--scenario", PUSH,
                                      "--trial", "0", "--target", "127.0.0.1:9", "--seconds", "3", "--out", str(out),
                                      "--no-io-process"])
    err = _interrupted_hw_run(args, stepped_go1, capsys)
    when = "interrupted at 1.000 s of the 3 s trial (Ctrl-C)"
    if again < 2:
        assert err.strip().splitlines()[-1] == (f"wbc hw run: {when}; the robot was closed into damping; the results "
                                                f"up to the interruption are complete in {out}")
        assert all((out / name).is_file() for name in ("hardware.json", "summary.json", "report.md", "run.json"))
    else:
        assert err.strip().splitlines()[-1] == (f"wbc hw run: {when}; the robot was closed into damping; the writing "
                                                f"of its results was stopped: {out} holds what was written until "
                                                "then, and a hardware trial is played once (no --resume)")
        assert not (out / "hardware.json").exists() and not (out / "summary.json").exists()
    if again:
        assert "the robot is closed into damping; the trial's results are being written to" in err
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    # the record: stopped, not a success, when and how said; the episode: the 50 ticks played, nothing else
    (record,) = TrialRecord.read_csv(out / "trials.csv")
    assert record.outcome == "operator_stop" and not record.success
    assert record.error == (f"{when}: the robot was closed into damping, and the episode up to the interruption is "
                            "recorded")
    assert record.ticks == 50 and math.isnan(record.fall_time_s) and record.ttf == pytest.approx(1 / 3)
    (path,) = (out / "episodes" / "stand-noarm").glob("*.npz")
    episode = Episode.load(str(path))
    assert len(episode.t) == 50 and episode.t[-1] == pytest.approx(1.0) and not episode.fell
    if again < 2:
        hardware = json.loads((out / "hardware.json").read_text())
        assert hardware["interrupted"] == {"time_s": pytest.approx(1.0), "tick": 50, "by": "Ctrl-C"}
        assert hardware["safety_events"][-1]["detail"] == "the command was interrupted during the trial (Ctrl-C)"
        report = (out / "report.md").read_text()
        assert "## Interrupted" in report and f"{when[0].upper()}{when[1:]}" in report
    # the wire: the stand hold up to the interruption, then damping (kp 0) until the close, and nothing after it
    frames = emu.commands()
    before = [c for c in frames if c.time <= pressed[0] + TIME_EPS]
    after = [c for c in frames if c.time > pressed[0] + TIME_EPS]
    assert not before[-1].damping and np.allclose(before[-1].wire.kp, 60.0)  # the controller drove it until then
    assert after and after[0].time <= pressed[0] + LINK_PERIOD + TIME_EPS  # damped from the next link period on
    assert all(c.damping and (c.wire.kp == 0).all() for c in after)
    sent = len(frames)
    clock.advance(0.5)
    assert len(emu.commands()) == sent  # closed: the link sends nothing more


BROKEN_ON_HARDWARE = '''
    """The stand hold on a robot without its arm, until it raises after half a second."""
    from wbc.control.plugin import ControllerPlugin
    from wbc.control.stand import StandController


    class Late:
        def __init__(self, desc):
            self.inner = StandController(desc)
            self.rate_hz = self.inner.rate_hz
            self.ticks = 0

        def reset(self):
            self.inner.reset()

        def act(self, state, command):
            self.ticks += 1
            if self.ticks > 25:
                raise RuntimeError("lost track of the ground")  # MARK
            return self.inner.act(state, command)

        def counters(self):
            return {}


    plugin = ControllerPlugin(make=Late, summary="raises after half a second", arm_modes=("none",))
'''


@pytest.mark.parametrize(("raised", "said"), [
    ('RuntimeError("lost track of the ground")', "RuntimeError at tick 25 (t = 0.500 s): lost track of the ground"),
    ("SystemExit(7)", "SystemExit at tick 25 (t = 0.500 s): 7"),  # sys.exit in a plug-in: not the end of the run
], ids=["raises", "exits"])
def test_a_controller_error_on_the_wire_damps_the_robot_and_is_recorded(stepped_go1: Stepped, tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch, raised: str,
                                                                        said: str) -> None:
    import textwrap

    (tmp_path / "plug" / "hwbroken").mkdir(parents=True)
    (tmp_path / "plug" / "hwbroken" / "__init__.py").write_text('"""Broken plug-ins."""\n')
    source = tmp_path / "plug" / "hwbroken" / "late.py"
    text = textwrap.dedent(BROKEN_ON_HARDWARE).lstrip()
    source.write_text(text.replace('RuntimeError("lost track of the ground")', raised))
    monkeypatch.syspath_prepend(str(tmp_path / "plug"))
    monkeypatch.delitem(sys.modules, "hwbroken", raising=False)
    monkeypatch.delitem(sys.modules, "hwbroken.late", raising=False)
    emu = stepped_go1.emu
    cfg = HardwareTrialConfig(controller="hwbroken.late:plugin", scenario=Path(PUSH), trial=0, robot="go1-arm",
                              arm_mode="none", seconds=2.0, target=("127.0.0.1", 9), out_dir=tmp_path / "hw",
                              settle_s=0.5, io_process=False)
    try:
        result = run_hardware_trial(cfg, before_connect=lambda hardware, spec: emu.reset(), build=stepped_go1.build)
    finally:
        for name in [m for m in sys.modules if m.startswith("hwbroken")]:
            del sys.modules[name]
    record = result.record
    # an error, not a fall nor a trip: recorded with what failed, when, and where in the plug-in
    assert record.outcome == "controller_error" and not record.success and math.isnan(record.fall_time_s)
    line = next(i for i, text in enumerate(source.read_text().splitlines(), start=1) if "# MARK" in text)
    assert record.error == (f"controller hwbroken.late:plugin, band {record.band}, seed 0, trial 0: act raised "
                            f"{said} [{source}:{line}]")
    assert len(result.episode.t) == 25 and record.ttf == pytest.approx(0.25)
    assert TrialRecord.read_csv(tmp_path / "hw" / "trials.csv") == [record]
    # the robot did not keep the broken controller's last command: the layer damped it, for the whole settle time
    assert result.safety_events[-1].reason == "software_estop"
    frames = emu.commands()
    last_driven = max(i for i, c in enumerate(frames) if not c.damping)
    assert frames[last_driven].time > frames[0].time + 0.5  # the stand hold drove it, trial included
    assert len(frames) - last_driven - 1 >= 0.5 / LINK_PERIOD  # then damping only, to the end


def test_estop_while_the_robot_is_stood_up_stops_it_and_plays_nothing(stepped_go1: Stepped, tmp_path: Path) -> None:
    emu, clock = stepped_go1.emu, stepped_go1.clock
    keys = ScriptedKeys([(-math.inf, "e")], clock=clock.now)  # pressed before the trial's clock starts: first poll
    cfg = HardwareTrialConfig(controller="stand", scenario=Path(PUSH), trial=0, robot="go1-arm", arm_mode="none",
                              seconds=2.0, target=("127.0.0.1", 9), out_dir=tmp_path / "hw", settle_s=0.2,
                              io_process=False)
    with pytest.raises(StandUpError, match="software_estop") as stopped:
        run_hardware_trial(cfg, keys=keys, before_connect=lambda hardware, spec: emu.reset(),
                           build=stepped_go1.build)
    # the e-stop's own remedy, not the joint-range one every trip used to end with
    assert REMEDIES["software_estop"] in str(stopped.value) and "joint ranges" not in str(stopped.value)
    pressed = dict(keys.delivered)["e"]
    after = [c for c in emu.commands() if c.time > pressed + TIME_EPS]
    assert after and all(c.damping for c in after)  # from the next link period on
    assert not (tmp_path / "hw" / "trials.csv").exists()


def test_a_robot_outside_its_joint_ranges_is_not_stood_up_and_nothing_is_played(stepped_go1: Stepped,
                                                                                  tmp_path: Path, capsys) -> None:
    # folded to its calf stops, as the real-time emulator leaves an idle robot: beyond the SDK's position table
    emu = stepped_go1.emu
    emu.transport(stepped_go1.clock)  # the simulation is built (the trial's builder hands out another channel)
    qpos = emu.sim.data.qpos.copy()
    qpos[2] = 0.06
    qpos[7:] = np.tile([0.0, 1.35, -2.82], 4)
    emu.reset(qpos)
    out = tmp_path / "hw"
    args = build_parser().parse_args(["hw", "run", "stand", "--robot", "go1-arm", "--arm", "none", "--scenario", PUSH,
                                      "--trial", "0", "--target", "127.0.0.1:9", "--seconds", "2", "--settle", "0.2",
                                      "--out", str(out), "--no-io-process"])
    with pytest.raises(StandUpError) as refused:
        hw_run(args, build=stepped_go1.build)
    err = str(refused.value)
    assert "tripped while standing the robot up" in err and "joint_range" in err and "nothing was played" in err
    assert REMEDIES["joint_range"] in err
    # in-process devices, said as the run starts: nothing damps the legs if this process dies
    assert "--no-io-process: the robot's devices run in this process; if it dies, nothing damps" in (
        capsys.readouterr().err)
    assert not (out / "trials.csv").exists()
    assert emu.commands() and all(c.damping for c in emu.commands())  # not one servo frame reached the robot


def test_a_robot_outside_its_joint_ranges_is_refused_by_the_command(go1: UnitreeEmulator, tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """The same refusal through ``wbc hw run`` over the UDP wire: the exit status and the message."""
    qpos = go1.sim.data.qpos.copy()
    qpos[2] = 0.06
    qpos[7:] = np.tile([0.0, 1.35, -2.82], 4)
    go1.reset(qpos)
    out = tmp_path / "hw"
    assert main(["hw", "run", "stand", "--robot", "go1-arm", "--arm", "none", "--scenario", PUSH, "--trial", "0",
                 "--target", f"127.0.0.1:{go1.address[1]}", "--seconds", "2", "--settle", "0.2",
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "tripped while standing the robot up" in err and "joint_range" in err and "nothing was played" in err
    assert not (out / "trials.csv").exists()
    assert all(c.damping for c in go1.commands())  # not one servo frame reached the robot


@pytest.mark.realtime
def test_realtime_estop_key_latency(go1: UnitreeEmulator, tmp_path: Path) -> None:
    keys = ScriptedKeys([(0.8, "p"), (1.6, "e")])
    cfg = HardwareTrialConfig(controller="stand", scenario=Path(PUSH), trial=0, robot="go1-arm", arm_mode="none",
                              seconds=3.0, target=go1.address, out_dir=tmp_path / "hw", settle_s=0.5)
    result = run_hardware_trial(cfg, keys=keys, before_connect=lambda hardware, spec: go1.reset())
    assert 1.6 <= result.record.fall_time_s <= 1.64
    pressed = dict(keys.delivered)["e"]
    first = next(c for c in go1.commands() if c.time > pressed and c.damping)
    assert first.time - pressed < 5 * LINK_PERIOD


def test_a_local_address_of_a_real_network_is_refused_before_any_socket_the_viewers_too(
        no_socket: list, capsys: pytest.CaptureFixture[str]) -> None:
    base = ["hw", "run", "stand", "--arm", "none", "--scenario", PUSH, "--trial", "0", "--target", "127.0.0.1:9"]
    assert main([*base, "--local", "192.0.2.7:0", "--view"]) == 2
    err = capsys.readouterr().err
    assert "--local 192.0.2.7:0 is outside 127.0.0.0/8" in err and "--allow-hardware" in err
    assert not no_socket


def test_non_loopback_target_is_refused_before_any_socket(no_socket: list, monkeypatch: pytest.MonkeyPatch,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    base = ["hw", "run", "stand", "--arm", "none", "--scenario", PUSH, "--trial", "0", "--target", NOT_LOOPBACK]
    assert main(base) == 2
    err = capsys.readouterr().err
    assert "outside 127.0.0.0/8" in err and "--allow-hardware" in err
    monkeypatch.setattr(sys, "stdin", io.StringIO("yes\n"))  # a piped yes is not a person at a terminal
    assert main([*base, "--allow-hardware"]) == 2
    err = capsys.readouterr().err
    assert "is a REAL ROBOT" in err and "will MOVE it" in err and "stdin is not a terminal" in err
    assert not no_socket


def test_the_vendor_transport_for_the_scenarios_a1_names_the_options_and_the_scenario_before_any_socket(
        no_socket: list, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # no --robot: the scenario's robot (the push scenario's a1-wx200) is the one refused, not an internal field
    assert load_scenario(PUSH).robot == "a1-wx200"
    assert main(["hw", "run", "stand", "--arm", "none", "--scenario", PUSH, "--trial", "0", "--target", "127.0.0.1:9",
                 "--transport", "sdk", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert (f"wbc: error: --transport sdk: the vendor SDK speaks only the go1's wire, not the a1's (the a1-wx200, "
            f"{PUSH}'s robot, played as no --robot is given); leave --transport out for it (udp, our own socket), or "
            "give --robot go1-arm to play it on the go1") in err
    assert "UnitreeRobotConfig" not in err and "binds its port" not in err and not no_socket
    assert not (tmp_path / "run").exists()


def test_the_same_protocol_on_the_simulator(tmp_path: Path, no_socket: list,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sim"
    assert main(["hw", "run", "stand", "--robot", "go1-arm", "--arm", "none", "--scenario", PUSH, "--trial", "0",
                 "--sim", "--seconds", "2", "--out", str(out)]) == 0
    (record,) = TrialRecord.read_csv(out / "trials.csv")
    assert (record.backend, record.metrics_source, record.safety_trips, record.success) == ("sim", "estimator", 0, True)
    assert "pushes" in capsys.readouterr().out and not no_socket  # skipped as on a robot; nothing was sent anywhere
    assert main(["hw", "run", "stand", "--scenario", PUSH, "--trial", "0", "--sim", "--target", "127.0.0.1:9"]) == 2
    assert main(["hw", "run", "stand", "--scenario", PUSH, "--trial", "0"]) == 2
    assert capsys.readouterr().err.count("or --sim") == 2


@pytest.mark.usefixtures("terminal_signals")
@pytest.mark.parametrize("times", [1, 2])
def test_ctrl_c_while_the_results_are_written_waits_for_them_and_twice_says_what_is_left(
        tmp_path: Path, no_socket: list, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
        times: int) -> None:
    """A trial is played once: Ctrl-C after it (the robot closed) lets its results be written whole; a second stops
    the writing, and the line says what the directory then holds."""
    import signal


    _ctrl_c_while_writing_hardware_json(monkeypatch, times)
    out = tmp_path / "sim"
    assert main(["hw", "run", "stand", "--robot", "go1-arm", "--arm", "none", "--scenario", PUSH, "--trial", "0",
                 "--sim", "--seconds", "0.5", "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert "the robot is closed into damping; the trial's results are being written to" in err
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    (record,) = TrialRecord.read_csv(out / "trials.csv")
    if times == 1:
        assert err.strip().endswith(f"interrupted after the trial; the robot was closed into damping; its results are "
                                    f"complete in {out}")
        assert all((out / name).is_file() for name in ("hardware.json", "summary.json", "report.md", "run.json"))
    else:
        assert err.strip().endswith(f"the writing of its results was stopped: {out} holds what was written until "
                                    "then, and a hardware trial is played once (no --resume)")
        assert not (out / "hardware.json").exists() and not (out / "summary.json").exists()


def test_an_actuated_arm_needs_its_serial_port(no_socket: list, capsys: pytest.CaptureFixture[str]) -> None:
    # stand drives an actuated arm: on the robot that is a second device, on its own bus
    assert main(["hw", "run", "stand", "--robot", "go1-arm", "--scenario", PUSH, "--trial", "0", "--target",
                 "127.0.0.1:9"]) == 2
    assert "give its serial port" in capsys.readouterr().err
    with pytest.raises(ConfigError, match="--arm-port"):
        HardwareRobotConfig(robot="a1-wx200", arm_mode="actuated", legs_host="127.0.0.1", legs_port=9)
    assert main(["hw", "run", "stand", "--robot", "spot", "--arm", "none", "--scenario", PUSH, "--trial", "0",
                 "--target", "127.0.0.1:9"]) == 2
    assert "valid robots: a1-wx200 (or a1), go1-arm (or go1)" in capsys.readouterr().err
    assert not no_socket


def test_a_trial_with_the_arm_actuated_over_both_wires_in_lockstep(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """The robot with its arm actuated: legs and arm emulated in process on one manual clock, the trial's devices
    (the legs' link and the arm's bus) on that clock too."""
    pytest.importorskip("dynamixel_sdk")
    out = tmp_path / "hw"
    code, emu = hw_run_arm_in_lockstep(PUSH, str(out), 3)
    assert code == 0, capsys.readouterr().err
    packets = emu.arm.stats.packets
    (record,) = TrialRecord.read_csv(out / "trials.csv")
    assert record.controller == "stand" and record.backend == "unitree+dynamixel" and record.safety_trips == 0
    assert record.success and record.metrics_source == "estimator"
    (path,) = (out / "episodes" / "stand").glob("*.npz")
    assert Episode.load(str(path)).qpos.shape[1] == 7 + 15  # the arm's joints are in the episode
    assert packets > 3 * 150  # the arm's bus cycled all through the trial (about 200 cycles a second)


@pytest.mark.parametrize(("fault", "kind", "trip"), [(BusFault.OVERLOAD, "hardware_error", "motor_mode"),
                                                     (BusFault.SILENT_ID, "no_answer", "stale_state")],
                         ids=["overload", "silent-id"])
def test_an_arm_fault_in_the_trial_is_its_outcome_and_not_a_lost_link(
        fault: BusFault, kind: str, trip: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The elbow overloads, or stops answering, about 0.9 s into the trial, the legs' link alive throughout: the
    layer trips (on the servo's mode, or on the joined state the silent arm froze) and damps the legs, which hear it.
    That is the trial's outcome, exit 0, the arm's fault recorded as the arm's. The frozen arm froze the joined frames'
    freshness, which the lost-link verdict read: the run exited 1 and called it the robot's link lost."""
    pytest.importorskip("dynamixel_sdk")
    out = tmp_path / "hw"
    code, emu = hw_run_arm_in_lockstep(PUSH, str(out), 2, inject=lambda e: e.inject(fault), inject_at=2.0)
    printed = capsys.readouterr()
    err = printed.err
    assert code == 0, err
    assert "the link to the robot was lost" not in err
    (record,) = TrialRecord.read_csv(out / "trials.csv")
    assert record.outcome == "safety_trip" and record.safety_trips == 1
    # a trip is no fall: the robot stood in its harness; the trial counts the share it played
    (path,) = (out / "episodes" / "stand").glob("*.npz")
    episode = Episode.load(str(path))
    assert not episode.fell and math.isnan(episode.fall_time_s) and math.isnan(record.fall_time_s)
    assert record.ttf == pytest.approx(episode.t[-1] / 2.0) and record.ttf < 1.0
    hardware = json.loads((out / "hardware.json").read_text())
    assert hardware["link_lost"] is None
    last = hardware["safety_events"][-1]
    assert last["reason"] == trip and last["to_state"] == "damped"
    (arm_fault,) = hardware["arm_faults"]
    assert (arm_fault["kind"], arm_fault["ids"]) == (kind, [4]) and "LIMP" in arm_fault["policy"]
    # on the trial's clock, as the layer's trip it caused (it was the host's monotonic clock, which nothing else is on)
    assert hardware["clocks"]["arm_faults"].startswith("trial time")
    tripped = last["time"] - hardware["trial_started_s"]
    assert 0.0 < arm_fault["time"] < 2.0 and abs(arm_fault["time"] - tripped) < 0.3
    report = (out / "report.md").read_text()
    assert "## Arm faults" in report and "## Link lost" not in report
    assert f"- at {arm_fault['time']:.3f} s: DynamixelArm: FAULT LATCHED ({kind}, IDs [4])" in report
    assert f"arm bus, at {arm_fault['time']:.2f} s of the trial: DynamixelArm: FAULT LATCHED" in printed.out
    # the replay reads it at trial time, to mark it beside the trip
    assert load_stored_episode(out, 0).arm_faults == ((arm_fault["time"], f"arm fault: {kind} (IDs [4])"),)
    # the legs heard the layer's damping from the trip to the close: nothing lost on their wire
    frames = emu.legs.commands()
    after = [c for c in frames if c.time > last["time"] + LINK_PERIOD + TIME_EPS]
    assert len(after) > 400 and all(c.damping for c in after)  # the 1 s settle at 500 Hz, then the close


def test_a_legs_link_lost_with_the_arm_actuated_is_still_a_lost_link(tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """The legs stop answering while the arm's bus is fine: the verdict rests on the legs' link, exit 1."""
    pytest.importorskip("dynamixel_sdk")
    out = tmp_path / "hw"
    code, _ = hw_run_arm_in_lockstep(PUSH, str(out), 2, inject=lambda e: e.inject(Fault.SILENCE), inject_at=2.0)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert err[-1].startswith("wbc hw run: the link to the robot was lost: its last state came 2.000 s after it was "
                              "connected")
    hardware = json.loads((out / "hardware.json").read_text())
    assert hardware["safety_events"][-1]["reason"] == "stale_state" and hardware["arm_faults"] == []
    assert hardware["link_lost"]["last_state_s"] == pytest.approx(2.0, abs=LINK_PERIOD)


@pytest.mark.realtime
def test_a_trial_with_the_arm_actuated_over_both_wires(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # the emulated robot in its own process, as `wbc hw emulate` serves it (a robot is another machine)
    pytest.importorskip("dynamixel_sdk")
    out = tmp_path / "hw"
    proc = subprocess.Popen([sys.executable, "-m", "wbc.cli", "hw", "emulate", "--robot", "a1-wx200", "--arm",
                             "actuated", "--seconds", "60"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT)
    try:
        line = proc.stdout.readline()  # bounded: the emulator stops by itself after --seconds
        found = re.search(r"legs on 127\.0\.0\.1:(\d+) \(UDP\), arm on (\S+) \(Dynamixel", line)
        assert found, (line, proc.stderr.read() if proc.poll() is not None else "")
        code = main(["hw", "run", "stand", "--robot", "a1-wx200", "--arm", "actuated", "--scenario", PUSH, "--trial",
                     "0", "--target", f"127.0.0.1:{found[1]}", "--arm-port", found[2], "--seconds", "3",
                     "--out", str(out)])
    finally:
        proc.send_signal(signal.SIGINT)  # Ctrl-C: the emulator stops and prints its counts
        emulated, emulator_err = proc.communicate(timeout=20)
    printed = capsys.readouterr()
    assert code == 0, printed.err
    assert proc.returncode == 0 and "Traceback" not in emulator_err, emulator_err
    (record,) = TrialRecord.read_csv(out / "trials.csv")
    assert record.controller == "stand" and record.backend == "unitree+dynamixel" and record.safety_trips == 0
    assert record.success and record.metrics_source == "estimator"
    (path,) = (out / "episodes" / "stand").glob("*.npz")
    assert Episode.load(str(path)).qpos.shape[1] == 7 + 15  # the arm's joints are in the episode
    packets = re.search(r"arm bus: packets decoded (\d+)", emulated)
    assert packets and int(packets[1]) > 3 * 150  # about 200 cycles a second went over the arm's bus


def test_estimated_metrics_track_the_simulators_truth() -> None:
    # a robot seen through its own sensors, in simulation, where the truth is known: a 1 m/s turn of the learned
    # policy, the metrics' estimate against the simulator's base velocity
    trial = load_scenario(TURN).trial("1.0", 0, 0)
    sim = MujocoRobot(MujocoRobotConfig(robot="go1-arm", arm_mode="none", terrain=trial.terrain))
    ctrl = get_controller("learned-noarm").make(sim.desc)
    robot = EstimatedRobot(sim, sim.desc, BaseEstimate(sim.desc, 1.0 / ctrl.rate_hz))
    truth: list[np.ndarray] = []
    with robot:
        sim.reset(seed=trial.terrain_seed, domain=trial.domain)
        episode = run_episode(robot, ctrl, trial.command, 4.0, truth=robot.base_estimate, fallen=sim.fallen,
                              observer=lambda t, r, c, cmd: truth.append(sim.base_truth().base_linvel_in_world))
    assert not episode.fell and isinstance(robot, ConfigurationEstimate) and isinstance(robot, HasSafetyEvents)
    # the estimate of tick k is of the state read at its start, which is the truth seen after tick k - 1
    estimated = np.linalg.norm(episode.v_base_in_yaw[1:], axis=1)
    true_speed = np.linalg.norm(np.array(truth)[:-1, :2], axis=1)
    moving = true_speed > 0.5
    assert moving.sum() > 50
    assert np.median(np.abs(estimated - true_speed)[moving]) < 0.1  # [m/s]; 0.06 when written
    assert abs(estimated[moving].mean() - true_speed[moving].mean()) < 0.1  # 0.94 against 1.02 when written


class _Screen:
    """Stands in for a `LiveViewer`: keeps what it was asked to load and show, posing every frame's nodes."""

    def __init__(self) -> None:
        self.content: SceneContent | None = None
        self.loads = 0
        self.shown: list[VizFrame] = []
        self.threads: set[str] = set()

    def load(self, content: SceneContent) -> None:
        self.content, self.loads = content, self.loads + 1

    def show(self, frame: VizFrame) -> None:
        self.content.poses(frame)  # the robot's kinematics at the frame, as the live viewer computes them
        self.shown.append(frame)
        self.threads.add(threading.current_thread().name)


def test_live_viewer_draws_a_robot_from_its_state_alone_without_blocking_its_loop() -> None:
    sim = MujocoRobot(MujocoRobotConfig(robot="go1-arm", arm_mode="none"))
    ctrl = get_controller("stand-noarm").make(sim.desc)
    robot = EstimatedRobot(sim, sim.desc, BaseEstimate(sim.desc, 1.0 / ctrl.rate_hz))
    screen = _Screen()
    observer = LiveObserver(screen, background=True)
    assert isinstance(observer, PreparingObserver)
    observer.prepare(robot)  # before the robot is connected: the scene (its meshes) is built now, not in a tick
    assert screen.loads == 1 and screen.content.robot.desc.arm_mode == "none" and not screen.content.robot.paths["arm"]
    configurations = []
    with robot:
        episode = run_episode(robot, ctrl, load_scenario(TURN).trial("1.0", 0, 0).command, 1.0,
                              truth=robot.base_estimate, fallen=lambda: False,
                              observer=lambda *tick: (observer(*tick), configurations.append(
                                  robot.estimated_configuration())))
    observer.close()
    assert screen.loads == 1 and screen.threads == {"wbc-viewer"}  # drawn on the viewer's own thread
    assert 1 <= len(screen.shown) <= 31  # at most 30 frames per second of the episode, the newest ones
    last = screen.shown[-1]
    assert last.foot_force_in_world is None and not last.pushed  # nobody knows a real robot's contacts or pushes
    tick = int(round(last.t * ctrl.rate_hz)) - 1
    np.testing.assert_allclose(last.qpos, configurations[tick])  # base pose estimated, joints measured
    np.testing.assert_allclose(last.qpos[7:], episode.qpos[tick, 7:])
    assert last.qpos[2] > 0.2  # the estimate stands it on its feet, not at the origin


def test_live_viewer_says_once_that_a_robot_without_either_capability_is_not_drawn(
        capsys: pytest.CaptureFixture[str]) -> None:
    sim = MujocoRobot(MujocoRobotConfig(robot="go1-arm", arm_mode="none"))
    observer = LiveObserver(None, None, recording_fps=10.0)
    bare = _Bare(sim)
    with bare:
        for k in range(3):
            observer(0.02 * (k + 1), bare, None, VelocityCommand())
    assert observer.recordings == []
    assert capsys.readouterr().err.count("nothing to draw") == 1


class _Bare(Robot):
    """A robot that offers nothing to draw: neither a simulation nor a configuration estimate."""

    def __init__(self, inner: MujocoRobot) -> None:
        super().__init__()
        self.inner = inner

    joint_names = property(lambda self: self.inner.joint_names)
    limits = property(lambda self: self.inner.limits)

    def _connect(self) -> None:
        self.inner.connect()

    def _close(self) -> None:
        self.inner.close()

    def _read(self) -> RobotState:
        return self.inner.read()

    def _send(self, cmd: MotorCommand) -> None:
        self.inner.write(cmd)

    def _advance(self, dt: float) -> None:
        self.inner.advance(dt)


def test_terminal_keys_read_single_keys_and_restore_the_terminal() -> None:
    master, slave = os.openpty()
    stream = os.fdopen(slave, "r")
    before = termios.tcgetattr(slave)
    keys = TerminalKeys(stream)
    try:
        assert keys.interactive and keys.poll(0.0) == []  # the first poll starts reading, in cbreak mode
        assert not termios.tcgetattr(slave)[3] & termios.ICANON
        os.write(master, b"pe")
        got: list[str] = []
        for _ in range(6000):  # bounded (60 s): until the reader thread, however late it runs, has read both
            got += keys.poll(0.0)
            if len(got) == 2:
                break
            threading.Event().wait(0.01)
        assert got == ["p", "e"]
    finally:
        keys.close()
        assert termios.tcgetattr(slave) == before
        stream.close()
        os.close(master)
    assert TerminalKeys(io.StringIO("e")).poll(0.0) == []  # not a terminal: nothing is read
