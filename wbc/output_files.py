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

import fcntl
import os
from collections.abc import Iterator, Mapping
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import BinaryIO

__all__ = ["LOCK_FILE", "DirectoryInUse", "DirectoryLock", "directory_holder", "lock_directory", "replace_files",
           "replacing", "temporary_name", "write_text"]


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


LOCK_FILE = ".lock"
"""The file of a directory that the run writing it holds locked (`lock_directory`), the run's pid written inside."""


class DirectoryInUse(Exception):
    """Another process holds the directory's lock (`lock_directory`).

    Attributes:
        path: the lock file.
        pid: the holder's pid as its lock file says, or None where it is not written (yet).
    """

    def __init__(self, path: Path, pid: int | None) -> None:
        super().__init__(f"{path} is held by {'pid ' + str(pid) if pid is not None else 'another process'}")
        self.path = path
        self.pid = pid


class DirectoryLock:
    """A directory this process holds (`lock_directory`), given back by `release` or at the end of a ``with``."""

    def __init__(self, path: Path, fd: int) -> None:
        self.path = path
        self._fd: int | None = fd

    @property
    def held(self) -> bool:
        """Whether this process still holds the directory: not yet given back (`release`)."""
        return self._fd is not None

    def release(self) -> None:
        """Give the lock back (closing its file does); the pid is erased first, so a refusal never names a run gone.

        Releasing again does nothing.
        """
        if self._fd is None:
            return
        fd, self._fd = self._fd, None
        try:
            os.ftruncate(fd, 0)
        except OSError:
            pass
        os.close(fd)

    def __enter__(self) -> DirectoryLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _pid_in(fd: int) -> int | None:
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def lock_directory(directory: str | Path) -> DirectoryLock:
    """Hold `directory` for this process, or refuse it: another process holds it.

    The lock is `fcntl.flock`, exclusive and not waiting, on ``DIRECTORY/.lock`` (`LOCK_FILE`), with this process's
    pid written inside for a refusal to name. The OS releases it when the process ends, however it ends (a SIGKILL
    too), so the file a dead run leaves locks nothing. The file stays: were it removed, a run could lock a new file of
    that name while another still held the old one.

    Raises:
        DirectoryInUse: another process holds it.
        OSError: the lock file cannot be made or opened (its filename set), or its file system takes no locks.
    """
    path = Path(directory) / LOCK_FILE
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        pid = _pid_in(fd)
        os.close(fd)
        raise DirectoryInUse(path, pid) from None
    except BaseException:
        os.close(fd)
        raise
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode("ascii"))
    except OSError:
        pass  # the lock holds all the same; only the pid a refused run names is missing
    return DirectoryLock(path, fd)


def directory_holder(directory: str | Path) -> DirectoryInUse | None:
    """Whether another process holds `directory` (`lock_directory`), without holding it: a dry run's check.

    Where the directory has a lock file, its lock is taken (shared) for an instant only; nothing is written. A
    directory without one (or whose file cannot be read, or whose file system takes no locks) is not held: the run
    itself then says what stops it.

    Returns:
        The holder, as `lock_directory` would raise it; None where no process holds the directory.
    """
    path = Path(directory) / LOCK_FILE
    try:
        fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return DirectoryInUse(path, _pid_in(fd))
    except OSError:
        return None
    finally:
        os.close(fd)
    return None
