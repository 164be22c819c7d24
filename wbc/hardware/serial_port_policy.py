"""The serial-port policy of a hardware bus: an emulator's port unless a real device is asked for in so many words.

The serial counterpart of the address policy (`wbc.hardware.unitree.check_target`). A test, an emulator run or a
benchmark must never open a real adapter by accident: opening the arm's U2D2 is enough for the start-up to write
EEPROM and torque to the servos. So a port is opened without consent only if it is what an emulator hands out:

- a pseudo-terminal's slave that one of our emulators serves: the path resolves (symlinks followed) to
  ``/dev/pts/N``, is a character device there, and a live `wbc.hardware.emulators.DynamixelEmulator` registered it
  when it opened it (`wbc.hardware.pty_registry`). Any other pty is refused like a device: a terminal, or a
  ``socat`` bridge to a real adapter, is a pty too;
- an in-process bus (a name starting with `IN_PROCESS_PREFIX`), which no serial device is ever opened for.

Anything else (``/dev/ttyUSB0``, ``/dev/ttyACM0``, ``/dev/serial/by-id/...``, the udev name ``/dev/ttyDXL``, a path
that does not exist, a regular file) is refused unless the config says ``allow_hardware=True``; the refusal says
what the path is, and points to the consent only where it may be a real device (a character device). The decision
reads the name, then at most resolves its symlinks (``lstat`` / ``readlink``), calls ``stat`` on the result and reads
the register; it never opens the path. A refusal with ``allow_hardware=False`` therefore happens before any ``open``
of a device, and with ``allow_hardware=True`` the filesystem is not touched at all by the check. (On macOS, where ptys
are ``/dev/ttysNNN``, an emulator's port needs ``allow_hardware`` too: the policy errs on the side of refusing.)
"""

from __future__ import annotations

import os
import stat
import sys

from wbc.errors import TargetRefusedError
from wbc.hardware.pty_registry import is_served_pty

__all__ = ["IN_PROCESS_PREFIX", "announce_hardware_port", "check_serial_port", "is_emulated_port",
           "is_pseudo_terminal", "why_not_emulated"]

IN_PROCESS_PREFIX = "in-process:"
"""How an in-process bus names its port (`wbc.hardware.dynamixel.in_process_handlers`): never a file."""

_PTY_DIR = "/dev/pts"

_NOT_DEVICES = ((stat.S_ISREG, "a regular file"), (stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a named pipe"),
                (stat.S_ISSOCK, "a socket"), (stat.S_ISBLK, "a block device (a disk)"))
"""What a path may be besides a character device, in the refusal's words."""


def is_pseudo_terminal(path: str) -> bool:
    """True if `path` resolves to a pseudo-terminal's slave, ``/dev/pts/N`` (decided without opening it).

    Args:
        path: a serial device path.
    """
    real = os.path.realpath(path)
    head, _, tail = real.rpartition("/")
    if head != _PTY_DIR or not tail.isdigit():
        return False
    try:
        return stat.S_ISCHR(os.stat(real).st_mode)
    except OSError:
        return False


def is_emulated_port(port: str) -> bool:
    """True for what an emulator hands out: an in-process bus's name, or a pty a live emulator of ours serves.

    Nothing is opened: the name is resolved and stat'ed, and the register read (`wbc.hardware.pty_registry`).
    """
    return port.startswith(IN_PROCESS_PREFIX) or (is_pseudo_terminal(port) and is_served_pty(port))


def why_not_emulated(port: str) -> tuple[str, bool]:
    """Why `port` is not an emulator's: a sentence that starts with the port's name, and whether it may be real.

    The sentence says what the path is (missing, a regular file, a directory, a character device that is not a
    pseudo-terminal ...), read with ``stat`` only, never opened. Only a character device (a serial adapter, a
    UART, a pty no emulator serves) or a path that cannot be examined may be a real device (True); the others
    (an empty name, a pseudo-terminal's name that names no device, as an emulator that stopped takes its pty with
    it, a path that does not exist, a file that is no device) are told apart (False), so that the refusal does not
    send the user to ``--allow-hardware`` for a typo, a stopped emulator or an adapter not plugged in.
    """
    if not port:
        return "'' is empty: name the arm's serial device (an emulator prints its pseudo-terminal)", False
    real = os.path.realpath(port)
    if real.rpartition("/")[0] == _PTY_DIR and not os.path.exists(real):
        return (f"{port} names no pseudo-terminal on this machine: an emulator's goes away when the emulator stops "
                "(is it still running? it prints the one to use)"), False
    if is_pseudo_terminal(port):
        return (f"{port} is a pseudo-terminal that no wbc emulator serves: refusing to open it without consent (a "
                "terminal, or a bridge such as socat to a real adapter, is a pty too; an emulator's pty is known "
                "while the emulator runs)"), True
    subject = f"{port} is" if real == os.path.abspath(port) else f"{port} resolves to {real}, which is"
    try:
        mode = os.stat(real).st_mode
    except FileNotFoundError:
        subject = f"{port} does not exist" if real == os.path.abspath(port) else f"{subject} missing"
        return (f"{subject}: no serial device of that name on this machine (an adapter appears once plugged in, as "
                "/dev/ttyUSB0 or a name under /dev/serial/by-id; an emulator prints the pseudo-terminal to use)"), False
    except OSError as err:
        return (f"{port} cannot be examined ({err.strerror}): refusing to open it as a real serial device (the "
                "arm's adapter; opening it writes the servos' settings and torque)"), True
    if stat.S_ISCHR(mode):
        return (f"{subject} a character device that is not a pseudo-terminal: refusing to open a real serial device "
                "(the arm's adapter; opening it writes the servos' settings and torque)"), True
    kind = next((name for test, name in _NOT_DEVICES if test(mode)), "not a device file")
    return (f"{subject} {kind}, not a serial device: nothing to open as the arm's bus (name the arm's adapter, e.g. "
            "/dev/ttyUSB0, or the pseudo-terminal an emulator prints)"), False


def check_serial_port(port: str, *, allow_hardware: bool, what: str = "port") -> None:
    """Refuse a serial device the policy does not allow, before anything opens it.

    Args:
        port: the serial device (or an in-process bus's name).
        allow_hardware: whether a device that is not an emulator's (a real adapter) is allowed.
        what: the config field or option, for the message.

    Raises:
        TargetRefusedError: `port` is neither a pty an emulator serves nor an in-process bus, and hardware is not
            allowed.
    """
    if allow_hardware or is_emulated_port(port):
        return
    why, real = why_not_emulated(port)
    consent = (". To drive a real arm, set allow_hardware=True in the config (for instance "
               "DynamixelArmConfig(..., allow_hardware=True))")
    raise TargetRefusedError(f"{what} {why}{consent if real else ''}")


def announce_hardware_port(port: str, device: str) -> None:
    """Print, once per connection, the real serial device a bus is about to open (to stderr)."""
    if not is_emulated_port(port):
        print(f"wbc: {device} opening HARDWARE serial device {port} (allow_hardware=True)", file=sys.stderr,
              flush=True)
