"""Directories of this user's that its processes share on this machine (the ptys' register, the address locks).

`user_runtime_dir` names one under ``$XDG_RUNTIME_DIR`` (a directory of this user's that the system removes at
logout), or under the temporary directory with the user's id in its name where there is none; `is_private_dir` tells
whether a directory may be trusted: a real directory of this user's that no one else may write to.
"""

from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path

__all__ = ["is_private_dir", "user_runtime_dir"]


def user_runtime_dir(name: str) -> Path:
    """``$XDG_RUNTIME_DIR/NAME`` where that is a directory, else ``TMP/NAME-UID`` (not created here)."""
    runtime = os.environ.get("XDG_RUNTIME_DIR", "")
    if runtime and os.path.isabs(runtime) and os.path.isdir(runtime):
        return Path(runtime) / name
    uid = os.getuid() if hasattr(os, "getuid") else 0
    return Path(tempfile.gettempdir()) / f"{name}-{uid}"


def is_private_dir(path: Path) -> bool:
    """True if `path` is a real directory (not a link) of this user's that neither group nor others may write to."""
    try:
        info = os.lstat(path)
    except OSError:
        return False
    owner = os.getuid() if hasattr(os, "getuid") else info.st_uid
    return stat.S_ISDIR(info.st_mode) and info.st_uid == owner and not info.st_mode & 0o022
