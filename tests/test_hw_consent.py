"""Consent for every real device: a serial port that is not an emulator's is refused before anything opens it.

The address policy (`check_target`) keeps a test's datagrams on 127.0.0.1; the serial-port policy
(`check_serial_port`) keeps its serial traffic on the pseudo-terminals our emulators hand out. Opening a real U2D2
would be enough for the arm's start-up to write EEPROM and torque, so every refusal here is checked with every way of
opening a file or a serial port made to fail the test: ``os.open`` (pyserial's), ``builtins.open``, pyserial's
``Serial`` and dynamixel_sdk's ``PortHandler.openPort``; and with sockets made to fail too, the legs' link is never
built either. ``/dev/ttyUSB0`` need not exist: the refusal reads the name, resolves it (``lstat``/``readlink``) and
at most ``stat``s the result.
"""

from __future__ import annotations

import builtins
import dataclasses
import io
import os
import re
import socket
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from wbc.cli import main
from wbc.errors import SerialPortError, TargetRefusedError
from wbc.hardware.dynamixel import DynamixelArm, DynamixelArmConfig, sdk_handlers
from wbc.hardware.dynamixel.sdk_bus import SdkBus
from wbc.hardware.hardware_robot import HardwareRobotConfig
from wbc.hardware.pty_registry import is_served_pty, register_pty, registry_dir, unregister_pty
from wbc.hardware.serial_port_policy import check_serial_port, is_emulated_port, is_pseudo_terminal

REAL_PORTS = ("/dev/ttyUSB0", "/dev/ttyACM0", "/dev/ttyDXL", "/dev/serial/by-id/usb-FTDI_USB__-__Serial_Converter",
              "/dev/ttyS0", "/dev/pts/ptmx", "/dev/pts", "COM3", "relative-name")
"""Adapters, a udev name, a by-id link, a UART, the pty multiplexer, a Windows name, a relative path: never a pty."""


@pytest.fixture(autouse=True)
def own_register(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The cross-process register of emulators' ptys in a directory of this test's own (`registry_dir`)."""
    runtime = tmp_path_factory.mktemp("runtime")
    runtime.chmod(0o700)
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(runtime))
    return runtime / "wbc-ptys"


@pytest.fixture
def bare_pty() -> Iterator[str]:
    """A pseudo-terminal's slave that no emulator serves (a terminal, a socat bridge: anything could be behind it)."""
    master, slave = os.openpty()
    try:
        yield os.ttyname(slave)
    finally:
        os.close(master)
        os.close(slave)


@pytest.fixture
def pty_slave(bare_pty: str) -> Iterator[str]:
    """A pseudo-terminal's slave registered as the Dynamixel emulator registers the one it opens (`register_pty`)."""
    assert register_pty(bare_pty)
    try:
        yield bare_pty
    finally:
        unregister_pty(bare_pty)


@pytest.fixture
def nothing_opened(monkeypatch: pytest.MonkeyPatch) -> list[tuple]:
    """Make every way of opening a device (and creating a socket) fail the test; the list holds the attempts.

    Files the code reads (a robot's model) still open: only a path under /dev, or one of `REAL_PORTS`, fails.
    """
    attempts: list[tuple] = []

    def refuse(what: str, original=None):
        def opened(*args: object, **kwargs: object) -> object:
            path = str(args[0]) if args else ""
            if original is not None and not path.startswith("/dev") and path not in REAL_PORTS:
                return original(*args, **kwargs)
            attempts.append((what, args))
            raise AssertionError(f"{what} was called for a refused device: {args}")
        return opened

    monkeypatch.setattr(os, "open", refuse("os.open", os.open))
    monkeypatch.setattr(builtins, "open", refuse("open", builtins.open))
    monkeypatch.setattr(io, "open", refuse("io.open", io.open))
    monkeypatch.setattr(socket, "socket", refuse("socket.socket"))
    serial = pytest.importorskip("serial")
    monkeypatch.setattr(serial, "Serial", refuse("serial.Serial"))
    sdk = pytest.importorskip("dynamixel_sdk")
    monkeypatch.setattr(sdk.PortHandler, "openPort", refuse("PortHandler.openPort"))
    return attempts


# -- the policy ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("port", REAL_PORTS)
def test_a_port_that_is_not_a_pty_is_refused(port: str) -> None:
    assert not is_pseudo_terminal(port) and not is_emulated_port(port)
    with pytest.raises(TargetRefusedError, match=rf"^port {re.escape(port)} "):
        check_serial_port(port, allow_hardware=False)
    check_serial_port(port, allow_hardware=True)  # the consent allows it


def _path_of_kind(kind: str, tmp_path: Path) -> str:
    """A path that is `kind`: made under `tmp_path`, or a character device every Linux has (/dev/null)."""
    path = tmp_path / "ttyARM"
    if kind == "regular file":
        path.write_text("")
    elif kind == "directory":
        path.mkdir()
    elif kind == "named pipe":
        os.mkfifo(path)
    elif kind == "link to a character device":
        path.symlink_to("/dev/null")
    elif kind == "link to nothing":
        path.symlink_to(tmp_path / "gone")
    elif kind == "character device":
        return "/dev/null"
    return str(path)  # "missing": nothing made


@pytest.mark.parametrize(("kind", "says", "consent"), [
    ("missing", "ttyARM does not exist: no serial device of that name on this machine", False),
    ("link to nothing", "ttyARM resolves to {tmp}/gone, which is missing: no serial device", False),
    ("regular file", "ttyARM is a regular file, not a serial device: nothing to open as the arm's bus", False),
    ("directory", "ttyARM is a directory, not a serial device", False),
    ("named pipe", "ttyARM is a named pipe, not a serial device", False),
    ("character device", "/dev/null is a character device that is not a pseudo-terminal: refusing to open a real "
                         "serial device", True),
    ("link to a character device", "ttyARM resolves to /dev/null, which is a character device that is not a "
                                   "pseudo-terminal", True),
])
def test_the_refusal_says_what_the_path_is(kind: str, says: str, consent: bool, tmp_path: Path,
                                           nothing_opened: list) -> None:
    port = _path_of_kind(kind, tmp_path)
    with pytest.raises(TargetRefusedError) as refused:
        check_serial_port(port, allow_hardware=False)
    message = str(refused.value)
    assert says.format(tmp=os.path.realpath(tmp_path)) in message, message
    assert ("allow_hardware=True" in message) == consent, message  # the consent only where a device may be real
    assert nothing_opened == []


def test_an_emulators_ports_need_no_consent(pty_slave: str, tmp_path: Path) -> None:
    assert pty_slave.startswith("/dev/pts/") and is_pseudo_terminal(pty_slave)
    check_serial_port(pty_slave, allow_hardware=False)
    link = tmp_path / "ttyARM"
    link.symlink_to(pty_slave)
    check_serial_port(str(link), allow_hardware=False)  # a udev-style name for a pty: resolved, still a pty
    check_serial_port("in-process:dynamixel-1", allow_hardware=False)  # an in-process bus: no device at all


def test_a_pty_no_emulator_serves_needs_the_consent(bare_pty: str, nothing_opened: list) -> None:
    # a terminal or a socat bridge to a real adapter is a pty too: only a live emulator's pty passes without consent
    assert is_pseudo_terminal(bare_pty) and not is_emulated_port(bare_pty)
    with pytest.raises(TargetRefusedError, match=r"pseudo-terminal that no wbc emulator serves.*allow_hardware=True"):
        check_serial_port(bare_pty, allow_hardware=False)
    assert nothing_opened == []
    check_serial_port(bare_pty, allow_hardware=True)


def test_an_emulators_pty_passes_only_while_it_serves_it() -> None:
    from wbc.hardware.emulators import DynamixelEmulator, SharedPlant

    with SharedPlant() as plant:
        emulator = DynamixelEmulator(plant).start()
        try:
            port = emulator.port
            assert emulator.registered_everywhere and is_emulated_port(port)
            check_serial_port(port, allow_hardware=False)
        finally:
            emulator.close()
    assert not is_served_pty(port) and not is_emulated_port(port)  # its number may now be anyone's pty
    with pytest.raises(TargetRefusedError):
        check_serial_port(port, allow_hardware=False)


_HOLDER = """
import os, sys, time
from wbc.hardware.pty_registry import register_pty
master, slave = os.openpty()
port = os.ttyname(slave)
print(port, register_pty(port), flush=True)
time.sleep(120)
"""


def test_another_processs_emulator_pty_passes_while_that_process_lives(bare_pty: str, own_register: Path) -> None:
    import subprocess

    holder = subprocess.Popen([sys.executable, "-c", _HOLDER], stdout=subprocess.PIPE, text=True,
                              cwd=Path(__file__).resolve().parent.parent)
    try:
        port, shared = holder.stdout.readline().split()
        assert shared == "True"
        assert is_emulated_port(port)  # registered by the other process, which holds it
        check_serial_port(port, allow_hardware=False)
        assert not is_emulated_port(bare_pty)  # this one nobody registered
    finally:
        holder.kill()
        holder.wait()
    # killed without unregistering: the pty went with it; its record stays behind and registers nothing (the next
    # test gives a pty of that number to someone else)
    assert len(list(own_register.glob("pty-*.json"))) == 1
    assert not is_served_pty(port) and not is_emulated_port(port)


def test_a_stale_record_for_a_reused_pty_registers_nothing(bare_pty: str, own_register: Path) -> None:
    # a record of a process that ended names the same device number as a pty opened since: refused, record removed
    import json

    own_register.mkdir(mode=0o700, exist_ok=True)
    rdev = os.stat(bare_pty).st_rdev
    gone = 2 ** 22 + 12345  # beyond pid_max's default: no such process
    record = own_register / f"pty-{rdev}.json"
    record.write_text(json.dumps({"port": bare_pty, "rdev": rdev, "pid": gone, "start": 1}))
    assert not is_emulated_port(bare_pty)
    assert not record.exists()
    # this process, but a start time that is not its own: a reused process id
    record.write_text(json.dumps({"port": bare_pty, "rdev": rdev, "pid": os.getpid(), "start": -1}))
    assert not is_emulated_port(bare_pty)
    record.write_text("{not json")
    assert not is_emulated_port(bare_pty)


def test_a_register_others_may_write_to_is_not_trusted(bare_pty: str, own_register: Path) -> None:
    own_register.mkdir(mode=0o700)
    own_register.chmod(0o777)
    assert registry_dir() == own_register
    assert not register_pty(bare_pty)  # not written there; this process still knows it
    assert not any(own_register.iterdir())
    assert is_emulated_port(bare_pty)
    unregister_pty(bare_pty)
    assert not is_emulated_port(bare_pty)


def test_a_link_to_a_real_device_is_refused(tmp_path: Path) -> None:
    link = tmp_path / "ttyARM"
    link.symlink_to("/dev/null")  # a character device, as an adapter is: the link is resolved, never opened
    with pytest.raises(TargetRefusedError, match="ttyARM resolves to /dev/null, which is a character device"):
        check_serial_port(str(link), allow_hardware=False)


def test_the_consent_touches_no_file(monkeypatch: pytest.MonkeyPatch) -> None:
    def touched(*args: object) -> None:
        raise AssertionError(f"the filesystem was read: {args}")

    for name in ("stat", "lstat", "readlink"):
        monkeypatch.setattr(os, name, touched)
    check_serial_port("/dev/ttyUSB0", allow_hardware=True)


def test_the_sdk_never_opens_an_in_process_name() -> None:
    pytest.importorskip("dynamixel_sdk")
    with pytest.raises(SerialPortError, match="in_process_handlers"):
        sdk_handlers("in-process:dynamixel-1")  # the SDK would open a file of that name


# -- the serial layer's own doors: a user may build a bus from the SDK's handlers without DynamixelArm ------------
@pytest.mark.parametrize("port", REAL_PORTS)
def test_the_sdks_handlers_for_a_real_device_need_the_consent(port: str, nothing_opened: list) -> None:
    with pytest.raises(TargetRefusedError, match=rf"^sdk_handlers port {re.escape(port)} "):
        sdk_handlers(port)
    assert not nothing_opened


def test_the_sdks_handlers_for_an_emulators_pty_are_built(pty_slave: str) -> None:
    pytest.importorskip("dynamixel_sdk")
    handler, _ = sdk_handlers(pty_slave)
    assert handler.getPortName() == pty_slave  # built, not opened


@pytest.mark.parametrize("port", REAL_PORTS)
def test_a_bus_on_a_real_device_is_not_opened_without_the_consent(port: str, nothing_opened: list) -> None:
    """A handler built with the consent (or by hand) still meets the policy where the bus opens it."""

    class Handler:
        opened = False

        def getPortName(self) -> str:  # noqa: N802 - the SDK's name
            return port

        def openPort(self) -> bool:  # noqa: N802
            Handler.opened = True
            return True

        def setBaudRate(self, rate: int) -> bool:  # noqa: N802
            return True

    with pytest.raises(TargetRefusedError, match=rf"^SdkBus port {re.escape(port)} "):
        SdkBus(Handler(), object(), port=port).open(1_000_000)
    assert not Handler.opened and not nothing_opened
    consented = SdkBus(Handler(), object(), port=port, allow_hardware=True)
    consented.open(1_000_000)  # the same handler, opened once the user said so
    assert Handler.opened and consented.is_open


# -- the backend's config and constructor --------------------------------------------------------------------------
def test_the_arm_config_refuses_a_real_port_and_nothing_is_opened(nothing_opened: list) -> None:
    with pytest.raises(TargetRefusedError, match=r"DynamixelArmConfig\.port /dev/ttyUSB0 does not exist"):
        DynamixelArmConfig(port="/dev/ttyUSB0")
    with pytest.raises(TargetRefusedError, match="arm_port /dev/ttyUSB0 does not exist"):
        HardwareRobotConfig(robot="go1-arm", arm_mode="actuated", legs_host="127.0.0.1", legs_port=9,
                            arm_port="/dev/ttyUSB0")
    consented = DynamixelArmConfig(port="/dev/ttyUSB0", allow_hardware=True)  # built, not opened
    with pytest.raises(TargetRefusedError, match=r"arm\.port /dev/ttyUSB0"):
        # the robot's consent covers its arm: a bus config that brings its own is not enough
        HardwareRobotConfig(robot="go1-arm", arm_mode="actuated", legs_host="127.0.0.1", legs_port=9, arm=consented)
    assert nothing_opened == []


def test_the_backend_checks_again_before_it_opens(nothing_opened: list, pty_slave: str) -> None:
    config = DynamixelArmConfig(port=pty_slave)
    object.__setattr__(config, "port", "/dev/ttyUSB0")  # a config changed behind its checks
    asked = []
    arm = DynamixelArm(config, handlers=lambda port: asked.append(port) or (None, None))
    with pytest.raises(TargetRefusedError, match="/dev/ttyUSB0 does not exist"):
        arm.connect()
    assert asked == [] and nothing_opened == []  # no port handler was even built


# -- the command line ---------------------------------------------------------------------------------------------
def test_check_refuses_a_real_arm_port_before_anything(nothing_opened: list,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    # /dev/null stands in for an adapter: a character device that is not a pseudo-terminal
    assert main(["hw", "check", "--target", "127.0.0.1:9", "--arm-port", "/dev/null"]) == 2
    err = capsys.readouterr().err
    assert "--arm-port /dev/null is a character device that is not a pseudo-terminal" in err, err
    assert "add --allow-hardware" in err and "Traceback" not in err and nothing_opened == []


@pytest.mark.parametrize(("kind", "says"), [
    ("regular file", "is a regular file, not a serial device"),
    ("directory", "is a directory, not a serial device"),
    ("missing", "does not exist: no serial device of that name on this machine"),
])
def test_check_says_what_an_arm_port_that_is_no_device_is(kind: str, says: str, tmp_path: Path, nothing_opened: list,
                                                          monkeypatch: pytest.MonkeyPatch,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    port = _path_of_kind(kind, tmp_path)
    opened = os.open

    def refuse_the_port(path: object, *args: object, **kwargs: object) -> int:
        assert os.path.realpath(str(path)) != os.path.realpath(port), f"{port} was opened"
        return opened(path, *args, **kwargs)

    monkeypatch.setattr(os, "open", refuse_the_port)
    assert main(["hw", "check", "--robot", "go1", "--target", "127.0.0.1:9", "--arm-port", port]) == 2
    err = capsys.readouterr().err
    assert f"--arm-port {port} {says}" in err, err
    assert "real serial device" not in err and "--allow-hardware" not in err, err  # no device to consent to
    assert nothing_opened == []


@pytest.mark.parametrize(("port", "why"), [
    ("/dev/pts/999999", "/dev/pts/999999 names no pseudo-terminal on this machine: an emulator's goes away when the "
                        "emulator stops"),
    ("", "'' is empty: name the arm's serial device"),
])
def test_a_stopped_emulators_pty_or_an_empty_port_is_not_called_a_real_device(port: str, why: str,
                                                                              nothing_opened: list,
                                                                              capsys: pytest.CaptureFixture[str]
                                                                              ) -> None:
    assert main(["hw", "check", "--target", "127.0.0.1:9", "--arm-port", port]) == 2
    err = capsys.readouterr().err
    assert f"--arm-port {why}" in err and "real serial device" not in err and "--allow-hardware" not in err, err
    assert nothing_opened == []


def test_run_refuses_a_real_arm_port_before_anything(nothing_opened: list,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["hw", "run", "stand", "--scenario", "scenarios/push.toml", "--trial", "0", "--target",
                 "127.0.0.1:9", "--arm", "locked", "--arm-port", "/dev/null"]) == 2
    err = capsys.readouterr().err
    assert "--arm-port /dev/null is a character device that is not a pseudo-terminal" in err, err
    assert "run a trial on a real arm" in err, err
    assert nothing_opened == []


def test_the_consent_asks_for_a_real_arm_too(nothing_opened: list, monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    """One flag, one consent: --allow-hardware on loopback legs with a real arm still asks the person at a terminal."""
    monkeypatch.setattr(sys, "stdin", io.StringIO(""))  # nobody at a terminal, and no --yes
    assert main(["hw", "check", "--robot", "a1-wx200", "--target", "127.0.0.1:9", "--arm-port", "/dev/ttyUSB0",
                 "--allow-hardware"]) == 2
    err = capsys.readouterr().err
    assert "at /dev/ttyUSB0 is a REAL ROBOT (the arm's serial device, not a pty an emulator serves)" in err, err
    assert "nobody can confirm" in err and nothing_opened == []


def test_the_consent_for_a_real_arm_warns_of_a_raised_arm_before_anything_is_opened(
        nothing_opened: list, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """The arm's pose is read only by its connect, after the consent: the confirmation itself says what connecting does
    to an arm parked raised and what to do first, for the check and for a run."""
    for command in (["hw", "check", "--robot", "a1-wx200"],
                    ["hw", "run", "stand", "--robot", "a1-wx200", "--arm", "actuated", "--scenario",
                     "scenarios/push.toml", "--trial", "0", "--seconds", "1"]):
        monkeypatch.setattr(sys, "stdin", io.StringIO(""))  # nobody at a terminal, and no --yes
        assert main([*command, "--target", "127.0.0.1:9", "--arm-port", "/dev/ttyUSB0", "--allow-hardware"]) == 2
        err = capsys.readouterr().err
        consent = err.split("is a REAL ROBOT", 1)[1]
        assert "An arm parked raised sags when connecting releases its joints" in consent, err
        assert "support it, or lower it to its stowed pose, before you confirm" in consent, err
        assert nothing_opened == []


def test_a_pty_arm_port_needs_no_flag(pty_slave: str) -> None:
    config = HardwareRobotConfig(robot="a1-wx200", arm_mode="actuated", legs_host="127.0.0.1", legs_port=9,
                                 arm_port=pty_slave)
    assert dataclasses.replace(config, arm_mode="locked").arm_port == pty_slave


def test_the_emulator_banner_says_when_other_processes_cannot_see_its_pty(capsys: pytest.CaptureFixture[str]) -> None:
    from wbc.cli.printers import print_emulator_serving
    from wbc.hardware.realtime import RealtimeGrant
    from wbc.tools.emulate import EmulatorServing

    grant = RealtimeGrant(pid=1, asked="nothing", scheduling="SCHED_OTHER", cpus=(0,), memory_locked=False)
    serving = EmulatorServing(robot="a1-wx200", mode="realtime", address=("127.0.0.1", 9), arm_port="/dev/pts/7",
                              faults=(), seconds=None, held=False, grant=grant, arm_mode="actuated",
                              arm_port_shared=False)
    print_emulator_serving(serving)
    out = capsys.readouterr().out
    assert "/dev/pts/7 could not be registered" in out and "refuses it without --allow-hardware" in out
    print_emulator_serving(dataclasses.replace(serving, arm_port_shared=True))
    assert "could not be registered" not in capsys.readouterr().out
