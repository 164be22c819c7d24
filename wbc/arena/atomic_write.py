"""Files written whole or not at all: through a temporary file beside them, moved over them once complete.

A results directory's files (``run.json``, ``summary.json``, ``failures.json``, ``report.md``, the plots, a paper
table's and a hardware trial's) are rewritten when a run is resumed or finished. Written in place, an interruption (a
kill, Ctrl-C, a full disk) leaves half a file: a torn ``run.json`` strands every trial stored beside it, since no
``--resume`` can tell which run they belong to. Written here, the old file stays whole until the new one is complete
and on disk, and replaces it in one step (``os.replace``). ``trials.csv``, appended row by row, has its own rules
(`wbc.arena.results.ResultsStore`).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

__all__ = ["replacing", "write_text"]


@contextlib.contextmanager
def replacing(path: str | Path) -> Iterator[BinaryIO]:
    """Write `path` through ``<name>.tmp`` beside it: the block writes the file, which replaces `path` once whole.

    The temporary file is flushed to disk before it replaces `path`; if the block (or the writing) fails, it is
    removed and `path` is left as it was.

    Raises:
        OSError: the temporary file cannot be written or moved (a full disk, a quota, no permission, a read-only file
            system): its errno and strerror, and `path` as its filename (the file that was not written).
    """
    path = Path(path)
    tmp = path.with_name(f"{path.name}.tmp")
    try:
        with tmp.open("wb") as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc
        raise


def write_text(path: str | Path, text: str) -> None:
    """Write `text` to `path` as UTF-8, whole or not at all (`replacing`)."""
    with replacing(path) as f:
        f.write(text.encode("utf-8"))
