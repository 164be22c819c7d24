"""`hold_target`: one link at a time to a robot's low-level address, on this machine.

A link binds a local port of its own (port 0, the default, one the kernel picks; the vendor SDK's Go1 port is given
by the caller), and the robot answers whoever sends to it, so a second link to the same robot connects as well and
its frames reach the robot between the first's: two controllers would drive its motors in turn. Before it builds its
socket, a link therefore holds its target: an exclusive lock (`wbc.output_files.lock_directory`, ``flock``) in a
directory named after the address (``udp-HOST-PORT``), under a directory of this user's (``$XDG_RUNTIME_DIR/
wbc-targets``, or the temporary directory's ``wbc-targets-UID``, mode 0700), with the holder's pid in it for the
refusal to name. The OS releases the lock when its process ends, however it ends.

What it cannot see: a link of another user, of another machine, or one that names the robot by another address.
"""

from __future__ import annotations

from pathlib import Path

from wbc.errors import RobotLinkError, TargetInUseError
from wbc.hardware.user_dirs import is_private_dir, user_runtime_dir
from wbc.output_files import DirectoryInUse, DirectoryLock, lock_directory

__all__ = ["hold_target", "target_lock_dir"]


def target_lock_dir() -> Path:
    """The directory of the targets' locks (not created here)."""
    return user_runtime_dir("wbc-targets")


def _private_dir(path: Path) -> None:
    """Make `path` a directory of this user's that no one else may write to, or refuse it."""
    try:
        path.mkdir(mode=0o700, exist_ok=True)
    except OSError as exc:
        raise RobotLinkError(f"{path}: cannot make the directory of the robots' address locks "
                             f"({exc.strerror or exc}); set XDG_RUNTIME_DIR to a directory of yours") from None
    if not is_private_dir(path):
        raise RobotLinkError(f"{path}: not a directory of this user's that only this user may write to, so it cannot "
                             "hold the robots' address locks; remove it, or set XDG_RUNTIME_DIR to a directory of "
                             "yours")


def hold_target(host: str, port: int) -> DirectoryLock:
    """Hold the robot's address `host`:`port` for this process's link until the lock's `release`.

    Raises:
        TargetInUseError: another process holds it (the message names its pid).
        RobotLinkError: the lock's directory cannot be made, is not this user's alone, or takes no lock.
    """
    base = target_lock_dir()
    _private_dir(base)
    folder = base / f"udp-{host}-{int(port)}"
    _private_dir(folder)
    try:
        return lock_directory(folder)
    except DirectoryInUse as held:
        raise TargetInUseError(host, int(port), held.pid) from None
    except OSError as exc:
        raise RobotLinkError(f"{folder}: cannot lock the robot's address ({exc.strerror or exc})") from None
