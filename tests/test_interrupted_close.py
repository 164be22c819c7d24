"""A robot's close is never cut: Ctrl-C and the requests to end wait for its end, then act (`HeldInterrupts`).

A real robot's close damps its legs and parks an arm (a position hold that needs no host). Cut by a second Ctrl-C, it
would leave the arm limp. The signals here are raised by the test itself, at a known point of the close, so each case
is the same on any machine at any load; the arm's case runs its devices in lockstep with the emulator on one manual
clock.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from conftest import hw_run_arm_in_lockstep

from wbc.arena.trial_record import TrialRecord
from wbc.hardware.dynamixel.arm_robot import DynamixelArm
from wbc.hardware.dynamixel.control_table import OperatingMode
from wbc.hardware.emulators.logged_packet import LoggedPacket
from wbc.hardware.robot import Robot
from wbc.interrupts import DeferredInterrupts, HeldInterrupts
from wbc.robots.joint_table import JointTable
from wbc.types import MotorCommand, RobotState

ROOT = Path(__file__).resolve().parents[1]
PUSH = str(ROOT / "scenarios" / "push-v1.toml")
JOINT_SERVOS = (1, 2, 4)  # the arm's joints' primary servos (the shoulder's shadow follows ID 2)


class _Closing(Robot):
    """A robot of one joint whose close runs `during` (a signal raised there) between two recorded steps."""

    def __init__(self, during: Callable[[], None], *, inner: Robot | None = None) -> None:
        super().__init__()
        self.during, self.inner = during, inner
        self.steps: list[str] = []

    @property
    def joint_names(self) -> tuple[str, ...]:
        return ("j",)

    @property
    def limits(self) -> JointTable:
        one = np.ones(1)
        return JointTable(names=("j",), lower=-one, upper=one, torque_limit=one, velocity_limit=one,
                          armature=0 * one, damping=0 * one, frictionloss=0 * one)

    def _connect(self) -> None:
        if self.inner is not None:
            self.inner.connect()

    def _close(self) -> None:
        self.steps.append("damping")
        self.during()
        if self.inner is not None:
            self.inner.close()
        self.steps.append("parked")

    def _read(self) -> RobotState:
        raise NotImplementedError

    def _send(self, cmd: MotorCommand) -> None:
        raise NotImplementedError

    def _advance(self, dt: float) -> None:
        raise NotImplementedError


def _ctrl_c_twice() -> None:
    signal.raise_signal(signal.SIGINT)
    signal.raise_signal(signal.SIGINT)


@pytest.mark.usefixtures("terminal_signals")
def test_ctrl_c_during_a_close_waits_for_its_end_then_interrupts(capsys: pytest.CaptureFixture[str]) -> None:
    robot = _Closing(_ctrl_c_twice)
    robot.connect()
    with pytest.raises(KeyboardInterrupt):
        robot.close()
    assert robot.steps == ["damping", "parked"] and not robot.is_connected
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the handler before, back
    err = capsys.readouterr().err
    assert err.count("wbc: Ctrl-C waits until the robot is closed") == 1  # said once, however often pressed


@pytest.mark.usefixtures("terminal_signals")
def test_a_robot_closing_the_robots_it_wraps_holds_once(capsys: pytest.CaptureFixture[str]) -> None:
    inner = _Closing(_ctrl_c_twice)
    outer = _Closing(lambda: signal.raise_signal(signal.SIGTERM), inner=inner)
    outer.connect()
    seen: list[int] = []
    signal.signal(signal.SIGTERM, lambda signum, frame: seen.append(signum))
    try:
        outer.close()  # the first signal (SIGTERM, in the outer close) goes to its handler once both are closed
    except KeyboardInterrupt:
        pytest.fail("the inner close's Ctrl-C was not held")
    assert inner.steps == outer.steps == ["damping", "parked"] and not inner.is_connected
    assert seen == [signal.SIGTERM]
    assert capsys.readouterr().err.count("waits until the robot is closed") == 1


@pytest.mark.usefixtures("terminal_signals")
def test_a_close_that_fails_ends_with_its_error_and_says_the_signal_came() -> None:
    """The error says what the close left (a link lost: check the robot by hand); a Ctrl-C must not replace it."""
    def fails() -> None:
        signal.raise_signal(signal.SIGINT)
        raise RuntimeError("the link is lost")

    robot = _Closing(fails)
    robot.connect()
    with pytest.raises(RuntimeError, match="the link is lost") as raised:
        robot.close()
    assert raised.value.__notes__ == ["(Ctrl-C came while this was under way)"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


@pytest.mark.usefixtures("terminal_signals")
def test_an_ignored_signal_stays_ignored_and_a_later_one_still_acts(capsys: pytest.CaptureFixture[str]) -> None:
    """A command started under ``nohup`` ignores the hangup: said nowhere, held by nothing, and a SIGTERM after it
    in the same close still acts once the robot is closed."""
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    seen: list[int] = []
    signal.signal(signal.SIGTERM, lambda signum, frame: seen.append(signum))

    def hangup_then_term() -> None:
        signal.raise_signal(signal.SIGHUP)
        signal.raise_signal(signal.SIGTERM)

    robot = _Closing(hangup_then_term)
    robot.connect()
    robot.close()
    assert robot.steps == ["damping", "parked"] and seen == [signal.SIGTERM]
    assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
    assert capsys.readouterr().err.count("SIGHUP") == 0


@pytest.mark.usefixtures("terminal_signals")
def test_a_deferral_leaves_an_ignored_hangup_ignored() -> None:
    """Training and a hardware trial's results defer the requests to end; under ``nohup`` a hangup requests nothing."""
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    with DeferredInterrupts(lambda what: what) as deferred:
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
        signal.raise_signal(signal.SIGHUP)
    assert deferred.requested is None


@pytest.mark.usefixtures("terminal_signals")
def test_an_install_cut_by_a_signal_leaves_nothing_installed(monkeypatch: pytest.MonkeyPatch) -> None:
    """A request to end that the command's own handler turns into KeyboardInterrupt can come while the handlers are
    being installed: those installed are put back, and the next close holds again."""
    install = signal.signal
    calls = []

    def cut_at_the_second(signum: int, handler: object) -> object:
        calls.append(signum)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return install(signum, handler)

    monkeypatch.setattr(signal, "signal", cut_at_the_second)
    with pytest.raises(KeyboardInterrupt), HeldInterrupts(None):
        pass
    monkeypatch.setattr(signal, "signal", install)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    robot = _Closing(_ctrl_c_twice)
    robot.connect()
    with pytest.raises(KeyboardInterrupt):
        robot.close()
    assert robot.steps == ["damping", "parked"]


def test_nothing_is_held_outside_the_main_thread() -> None:
    installed: list[object] = []

    def close() -> None:
        with HeldInterrupts(lambda what: what):
            installed.append(signal.getsignal(signal.SIGINT))

    before = signal.getsignal(signal.SIGINT)
    thread = threading.Thread(target=close)
    thread.start()
    thread.join()
    assert installed == [before]


def _parked(packets: list[LoggedPacket]) -> set[int]:
    """The joint servos whose close ended in the park: current-based position mode, then torque on, in that order."""
    done = set()
    for servo_id in JOINT_SERVOS:
        steps = [(w.name, w.value) for p in packets for w in p.writes if w.id == servo_id]
        mode = [k for k, step in enumerate(steps) if step == ("operating_mode", OperatingMode.CURRENT_BASED_POSITION)]
        if mode and ("torque_enable", 1) in steps[mode[-1]:]:
            done.add(servo_id)
    return done


@pytest.mark.usefixtures("terminal_signals")
@pytest.mark.parametrize("during_the_trial", [True, False], ids=["twice", "once-at-the-close"])
def test_ctrl_c_while_the_arm_closes_lets_it_park(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                  monkeypatch: pytest.MonkeyPatch, during_the_trial: bool) -> None:
    """`wbc hw run --no-io-process` with an actuated arm: a Ctrl-C as the arm begins its park (after its close's
    damping) lets the park finish. After a first Ctrl-C in the trial, the run ends interrupted, nothing written;
    after a trial played to its end, its results are written whole first."""
    pytest.importorskip("dynamixel_sdk")
    import wbc.arena.hw_trial as hw_trial

    park = DynamixelArm._park

    def interrupted_park(arm: DynamixelArm, bus: object) -> None:
        signal.raise_signal(signal.SIGINT)
        park(arm, bus)

    monkeypatch.setattr(DynamixelArm, "_park", interrupted_park)
    if during_the_trial:
        played = hw_trial.run_episode

        def interrupted_trial(*args: object, **kwargs: object) -> object:
            episode = played(*args, **kwargs)
            signal.raise_signal(signal.SIGINT)  # the first Ctrl-C, as the trial ends: the robot is closed
            return episode

        monkeypatch.setattr(hw_trial, "run_episode", interrupted_trial)
    out = tmp_path / "hw"
    code, emu = hw_run_arm_in_lockstep(PUSH, str(out), 1)
    packets = emu.arm.packets()
    assert emu.failure is None
    err = capsys.readouterr().err
    assert code == 130, err
    assert _parked(packets) == set(JOINT_SERVOS)
    assert err.count("wbc: Ctrl-C waits until the robot is closed (a real robot's legs damp, its arm parks), "
                     "then acts") == 1
    if during_the_trial:
        assert err.strip().endswith("interrupted; the robot was closed into damping; no results were written")
        assert not (out / "trials.csv").exists()
    else:  # the held Ctrl-C, once the robot is closed, is the first after the trial: it waits for the results
        assert "wbc hw run: Ctrl-C: the robot is closed into damping; the trial's results are being written to" in err
        assert err.strip().endswith(f"its results are complete in {out}")
        (record,) = TrialRecord.read_csv(out / "trials.csv")
        assert record.controller == "stand" and record.backend == "unitree+dynamixel"
        assert all((out / name).is_file() for name in ("hardware.json", "summary.json", "report.md", "run.json"))
