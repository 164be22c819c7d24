"""Writing the files of a run so that each appears whole or not at all under its name.

Each file is written to a temporary file beside it (``<name>.tmp``, in the same directory, so on the same file
system) and renamed over its name with `os.replace`, which replaces a file in one step: a process killed while it
writes (SIGKILL, an out-of-memory kill, a full disk) leaves the previous file whole, or no file, under the name, and at
most a ``<name>.tmp`` that the next write of the file replaces. A reader (``--resume``, ``load_policy``) never sees
half a file. An exception in the middle of a write removes the temporary file and leaves the name as it was.

The run directories of training (checkpoints, ``progress.json``, policy files) and the results directories of the arena
(``run.json``, ``summary.json``, ``failures.json``, ``report.md``, the plots, a paper table's and a hardware trial's
files) are written this way: a torn ``run.json`` would strand every trial stored beside it, since no ``--resume`` could
tell which run they belong to. Each temporary file is flushed to disk before it is renamed. ``trials.csv``, appended
row by row, has its own rules (`wbc.arena.results.ResultsStore`).
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import BinaryIO

__all__ = ["replace_files", "replacing", "temporary_name", "write_text"]


def temporary_name(path: str | Path) -> Path:
    """Where a file is written before it is renamed over `path`: ``<name>.tmp`` beside it."""
    path = Path(path)
    return path.with_name(f"{path.name}.tmp")


@contextmanager
def replacing(path: str | Path) -> Iterator[BinaryIO]:
    """Write `path` through a temporary file beside it, renamed over `path` once the block has written it whole.

    Raises:
        OSError: the temporary file cannot be written, flushed or renamed (a full disk, a quota, no permission, a
            read-only file system); `path` is then as it was. The error carries its errno and strerror, and `path`
            as its filename: the file that was not written, not its temporary name.
    """
    tmp = temporary_name(path)
    try:
        with tmp.open("wb") as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:  # KeyboardInterrupt too: nothing half-written stays behind
        with suppress(OSError):
            tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc
        raise


def write_text(path: str | Path, text: str) -> None:
    """Write `text` to `path` as UTF-8, whole or not at all (`replacing`)."""
    with replacing(path) as f:
        f.write(text.encode("utf-8"))


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
                f.flush()
                os.fsync(f.fileno())
        for path, tmp in zip(contents, written, strict=True):
            os.replace(tmp, path)
    except BaseException:
        for tmp in written:
            tmp.unlink(missing_ok=True)
        raise
