"""Writing the files of a run so that each appears whole or not at all under its name.

Each file is written to a temporary file beside it (``<name>.tmp``, in the same directory, so on the same file
system) and renamed over its name with `os.replace`, which replaces a file in one step: a process killed while it
writes (SIGKILL, an out-of-memory kill, a full disk) leaves the previous file whole, or no file, under the name, and at
most a ``<name>.tmp`` that the next write of the file replaces. A reader (``--resume``, ``load_policy``) never sees
half a file. An exception in the middle of a write removes the temporary file and leaves the name as it was.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO

__all__ = ["replace_files", "replacing", "temporary_name"]


def temporary_name(path: str | Path) -> Path:
    """Where a file is written before it is renamed over `path`: ``<name>.tmp`` beside it."""
    path = Path(path)
    return path.with_name(f"{path.name}.tmp")


@contextmanager
def replacing(path: str | Path) -> Iterator[BinaryIO]:
    """Write `path` through a temporary file beside it, renamed over `path` once the block has written it whole.

    Raises:
        OSError: the temporary file cannot be written or renamed; `path` is then as it was.
    """
    tmp = temporary_name(path)
    f = tmp.open("wb")
    try:
        with f:
            yield f
        os.replace(tmp, path)
    except BaseException:  # KeyboardInterrupt too: nothing half-written stays behind
        tmp.unlink(missing_ok=True)
        raise


def replace_files(contents: Mapping[Path, bytes]) -> None:
    """Replace several files, each whole: every temporary file is written first, then each is renamed, in order.

    A failure while writing leaves every file as it was; only a process killed between two renames leaves some files
    new and the others old, so the file that says the others are complete (a policy's JSON, which records its
    weights' sha256) goes last.

    Raises:
        OSError: a temporary file cannot be written or renamed.
    """
    written: list[Path] = []
    try:
        for path, data in contents.items():
            tmp = temporary_name(path)
            with tmp.open("wb") as f:
                written.append(tmp)
                f.write(data)
        for path, tmp in zip(contents, written, strict=True):
            os.replace(tmp, path)
    except BaseException:
        for tmp in written:
            tmp.unlink(missing_ok=True)
        raise
