"""Which pseudo-terminals our emulators serve: the serial-port policy lets only those through without consent.

A pseudo-terminal is not proof of an emulator. A terminal session, or a ``socat`` bridge to a real USB adapter, is a
``/dev/pts/N`` too, and the start-up of an arm writes EEPROM and torque to whatever answers on it. So a
`DynamixelEmulator` registers the pty it opens, and `is_served_pty` accepts a pty only while a live emulator holds it.

Two registers, both keyed by the pty's device number (``st_rdev``, unique while the pty exists):

- in this process, a dictionary, which an emulator started here fills and empties (tests, ``wbc hw run`` beside its
  own emulator);
- across processes (``wbc hw emulate`` in one terminal, ``wbc hw run`` in another), one small JSON file per pty in a
  directory of this user's (``$XDG_RUNTIME_DIR/wbc-ptys`` or the temporary directory's ``wbc-ptys-UID``, mode 0700).
  A file names the emulator's process and its start time, so that a file left by an emulator that was killed, or a
  process id reused since, registers nothing (and the stale file is removed).

A directory that another user owns, or that others may write to, is not trusted: nothing in it registers a pty, and
an emulator does not write there (its pty then needs consent in other processes; it says so).
"""

from __future__ import annotations

import json
import os
import stat
import threading
from pathlib import Path

from wbc.hardware.user_dirs import is_private_dir, user_runtime_dir

__all__ = ["is_served_pty", "register_pty", "registry_dir", "unregister_pty"]

_LOCAL: dict[int, str] = {}
_LOCK = threading.Lock()


def registry_dir() -> Path:
    """The directory of the cross-process register (not created here)."""
    return user_runtime_dir("wbc-ptys")


def _device(port: str) -> int | None:
    """The pty's device number, or None if `port` does not name a character device."""
    try:
        info = os.stat(os.path.realpath(port))
    except OSError:
        return None
    return info.st_rdev if stat.S_ISCHR(info.st_mode) else None


def _process_start(pid: int) -> int | None:
    """When process `pid` started (clock ticks since boot, from /proc), or None where /proc does not say."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    try:
        return int(text.rpartition(")")[2].split()[19])  # field 22; the name in parentheses may hold spaces
    except (IndexError, ValueError):
        return None


def _alive(pid: int, start: int | None) -> bool:
    """True if process `pid` runs and is the one that started at `start` (when that is known)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass  # it exists (another user's: its file would not be trusted anyway)
    except OSError:
        return False
    return start is None or _process_start(pid) in (start, None)


def register_pty(port: str) -> bool:
    """Register `port`, a pty this process's emulator has just opened and holds.

    Returns:
        True if other processes can see it too; False if only this process can (the register's directory could not
        be made, or is not trusted).
    """
    rdev = _device(port)
    if rdev is None:
        return False
    with _LOCK:
        _LOCAL[rdev] = port
    folder = registry_dir()
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
    except OSError:
        return False
    if not is_private_dir(folder):
        return False
    record = {"port": port, "rdev": rdev, "pid": os.getpid(), "start": _process_start(os.getpid())}
    target = folder / f"pty-{rdev}.json"
    part = folder / f".pty-{rdev}.{os.getpid()}.part"
    try:
        part.write_text(json.dumps(record))
        os.replace(part, target)
    except OSError:
        return False
    return True


def unregister_pty(port: str) -> None:
    """Forget `port` (the emulator is about to close it); call before closing it, while its device number is known."""
    rdev = _device(port)
    with _LOCK:
        if rdev is None:
            rdev = next((k for k, v in _LOCAL.items() if v == port), None)
        if rdev is None:
            return
        _LOCAL.pop(rdev, None)
    target = registry_dir() / f"pty-{rdev}.json"
    try:
        record = json.loads(target.read_text())
    except (OSError, ValueError):
        return
    if isinstance(record, dict) and record.get("pid") == os.getpid():
        try:
            target.unlink()
        except OSError:
            pass


def is_served_pty(port: str) -> bool:
    """True if `port` is a pty that a live emulator of ours holds (in this process or another of this user's).

    Reads the pty's ``stat`` and the register (never the device itself).
    """
    rdev = _device(port)
    if rdev is None:
        return False
    with _LOCK:
        if rdev in _LOCAL:
            return True
    folder = registry_dir()
    if not is_private_dir(folder):
        return False
    target = folder / f"pty-{rdev}.json"
    try:
        record = json.loads(target.read_text())
        pid, start = record["pid"], record.get("start")
        if record["rdev"] != rdev or not isinstance(pid, int) or isinstance(pid, bool):
            return False
    except (OSError, ValueError, KeyError, TypeError):
        return False
    if _alive(pid, start):
        return True
    try:
        target.unlink()  # the emulator is gone: its pty may now be anyone's
    except OSError:
        pass
    return False
