"""Guarded readers for every file a user hands `wbc`: bounded, regular files only, decoding errors caught.

A scenario, an ONNX I/O file, a plug-in's configuration, a policy's JSON, a results directory's ``run.json`` and
``trials.csv``, a stored episode: each is read through one function here, which

- refuses what is not a regular file (a directory, a device such as ``/dev/zero``, a FIFO), following symbolic links
  first, so a link to a device is refused as the device;
- refuses a file larger than the limit of its kind (`LIMITS`, stated in the message), and reads at most that many
  bytes, so a file that grows while it is read cannot exhaust memory;
- decodes text as UTF-8 and names the line of a byte that is not;
- parses TOML and JSON with their nesting depth bounded (`MAX_DEPTH`): a file of 500 nested ``[`` is a clear error,
  not a `RecursionError`;
- checks the members of a NumPy ``.npz`` archive (their declared sizes against the limit, their headers) before any
  array is read, so a member that claims 2^40 floats or a deflate bomb is refused unread.

Every failure is an `InputFileError`, one line that names the file (and the line, where there is one); the CLI
prints it and exits with status 2.
"""

from __future__ import annotations

import json
import os
import stat
import sys
import tomllib
import zipfile
import zlib
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from wbc.errors import InputFileError
from wbc.toml_lines import syntax_fault

__all__ = ["LIMITS", "MAX_DEPTH", "open_npz", "read_bytes", "read_json", "read_text", "read_toml", "short"]

LIMITS: Mapping[str, int] = {
    "toml": 1 << 20,  # 1 MiB: a scenario or an I/O file is a few kB
    "json": 64 << 20,  # 64 MiB: a policy's JSON holds its normaliser and metadata, a run.json its environment
    "csv": 1 << 30,  # 1 GiB: a trials.csv of a few million rows
    "npz": 1 << 30,  # 1 GiB: a policy's weights or an episode log, uncompressed
    "onnx": 1 << 30,  # 1 GiB: a model and each of its external data files
}
"""Largest file of each kind [bytes]; a `.npz` limit applies to the sum of its members' uncompressed sizes."""

MAX_DEPTH = 32
"""Deepest nesting of tables, arrays and objects a TOML or JSON input may have."""

_SHORT = 120


def short(value: object, limit: int = _SHORT) -> str:
    """`value`'s repr, cut to `limit` characters with the length said, for messages that echo what they refuse."""
    text = repr(value)
    if len(text) <= limit:
        return text
    return f"{text[: limit - 30]}... ({len(text)} characters)"


def _mib(n: int) -> str:
    """A size as messages give it, exactly: whole MiB as such (a limit), any other in bytes (1,069,152 bytes)."""
    return f"{n >> 20} MiB" if n >= 1 << 20 and n % (1 << 20) == 0 else f"{n:,} bytes"


def _checked(path: str | os.PathLike[str], kind: str, limit: int | None) -> tuple[Path, int]:
    """The path and the byte limit, once the file is found to be a regular file within the limit."""
    p = Path(path)
    limit = LIMITS[kind] if limit is None else limit
    try:
        st = p.stat()  # follows symbolic links: a link to a device is judged as the device
    except FileNotFoundError:
        raise InputFileError(f"{p}: no such file") from None
    except OSError as exc:
        raise InputFileError(f"{p}: cannot be read ({exc.strerror or type(exc).__name__})") from None
    if stat.S_ISDIR(st.st_mode):
        raise InputFileError(f"{p}: is a directory, not a {kind} file")
    if not stat.S_ISREG(st.st_mode):
        raise InputFileError(f"{p}: not a regular file (a device, FIFO or socket); give a {kind} file")
    if st.st_size > limit:
        raise InputFileError(f"{p}: {_mib(st.st_size)}, more than the {_mib(limit)} a {kind} file may have")
    return p, limit


def read_bytes(path: str | os.PathLike[str], *, kind: str, limit: int | None = None) -> bytes:
    """The bytes of a regular file of `kind` (a `LIMITS` key), at most its limit.

    Raises:
        InputFileError: missing, unreadable, not a regular file, or larger than the limit.
    """
    p, limit = _checked(path, kind, limit)
    try:
        with p.open("rb") as f:
            data = f.read(limit + 1)
    except OSError as exc:
        raise InputFileError(f"{p}: cannot be read ({exc.strerror or type(exc).__name__})") from None
    if len(data) > limit:
        raise InputFileError(f"{p}: grew past the {_mib(limit)} a {kind} file may have while it was read")
    return data


def read_text(path: str | os.PathLike[str], *, kind: str, limit: int | None = None) -> str:
    """The UTF-8 text of a regular file of `kind`.

    Raises:
        InputFileError: as `read_bytes`, or a byte that is not UTF-8 (the message names its line).
    """
    data = read_bytes(path, kind=kind, limit=limit)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise InputFileError(f"{path}:{line}: byte {data[exc.start]:#04x} at offset {exc.start} is not UTF-8; save "
                             "the file as UTF-8 text") from None


def _depth(value: Any, limit: int, where: str) -> None:
    """Raise when `value` nests deeper than `limit` (iteratively: no recursion to exhaust)."""
    stack = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict):
            children = list(item.values())
        elif isinstance(item, list):
            children = item
        else:
            continue
        if depth > limit:
            raise InputFileError(f"{where}: nested more than {limit} levels deep; no valid file nests so deep")
        stack.extend((child, depth + 1) for child in children)


def _bracket_depth(text: str) -> int:
    """The deepest nesting of ``[`` / ``{`` outside strings and comments, roughly: a guard run before parsing."""
    depth = deepest = 0
    quote = ""
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if quote:
            if c == "\\" and quote == '"':
                i += 2
                continue
            if c == quote:
                quote = ""
        elif c in "\"'":
            quote = c
        elif c == "#":
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        elif c in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif c in "]}":
            depth = max(0, depth - 1)
        elif c == "\n":
            pass
        i += 1
    return deepest


def _parse(path: str | os.PathLike[str], text: str, *, slack: int, max_depth: int,
           parse: Callable[[str], Any], decode_error: Callable[[Exception], str | None]) -> Any:
    """`text` parsed by `parse`, every way parsing a hostile file fails turned into one `InputFileError`.

    `slack` is how many bracket levels the syntax itself adds (a TOML table header's brackets); `decode_error` turns
    the parser's own error into the message's tail (with line and column where the parser gives them), or None for
    an error that is not the parser's.
    """
    if _bracket_depth(text) > max_depth + slack:
        raise InputFileError(f"{path}: nested more than {max_depth} levels deep; no valid file nests so deep")
    try:
        data = parse(text)
    except RecursionError:
        raise InputFileError(f"{path}: nested too deep to parse; no valid file nests so deep") from None
    except ValueError as exc:
        message = decode_error(exc)
        if message is None:  # an integer of more digits than Python converts (sys.get_int_max_str_digits)
            raise InputFileError(f"{path}: holds an integer of more than {sys.get_int_max_str_digits()} digits; no "
                                 "value wbc reads is so long") from None
        raise InputFileError(f"{path}{message}") from None
    _depth(data, max_depth, str(path))
    return data


def _toml_error(text: str) -> Callable[[Exception], str | None]:
    def decode_error(exc: Exception) -> str | None:
        if not isinstance(exc, tomllib.TOMLDecodeError):
            return None
        fault = syntax_fault(text, exc)
        return "".join((f":{fault.line}" if fault.line else "", f": {fault.field}" if fault.field else "",
                        f": {fault.reason}"))

    return decode_error


def _json_error(exc: Exception) -> str | None:
    if isinstance(exc, json.JSONDecodeError):
        return f":{exc.lineno}:{exc.colno}: not valid JSON: {exc.msg}"
    return None


def read_toml(path: str | os.PathLike[str], *, limit: int | None = None, max_depth: int = MAX_DEPTH) -> dict[str, Any]:
    """A TOML file parsed, its size and nesting bounded.

    Raises:
        InputFileError: as `read_text`, nested deeper than `max_depth`, or not valid TOML: ``path:line: reason``
            with the column, or ``path:line: [table] key: reason`` for a key or table defined twice
            (`wbc.toml_lines.syntax_fault`).
    """
    # a byte-order mark (as some Windows editors write UTF-8) starts no TOML statement: it is read past
    text = read_text(path, kind="toml", limit=limit).removeprefix("\ufeff")
    # a table header's brackets count too: leave them room
    return _parse(path, text, slack=2, max_depth=max_depth, parse=tomllib.loads,
                  decode_error=_toml_error(text))


def read_json(path: str | os.PathLike[str], *, limit: int | None = None, max_depth: int = MAX_DEPTH) -> Any:
    """A JSON file parsed, its size and nesting bounded.

    Raises:
        InputFileError: as `read_text`, nested deeper than `max_depth`, or not valid JSON (line and column named).
    """
    text = read_text(path, kind="json", limit=limit)
    return _parse(path, text, slack=1, max_depth=max_depth, parse=json.loads,
                  decode_error=_json_error)


def open_npz(path: str | os.PathLike[str], *, limit: int | None = None) -> np.lib.npyio.NpzFile:
    """A NumPy ``.npz`` archive opened for reading, every member checked before any is read.

    The members' declared uncompressed sizes must sum to at most the limit, and each ``.npy`` member's header must
    declare a plain (non-object) dtype and a shape whose size matches its declared bytes; the archive is opened
    without pickle.

    Raises:
        InputFileError: as `read_bytes` for the archive's own size; not a zip archive; a member too large, with an
            object dtype, or whose header does not parse or disagrees with its size.
    """
    p, limit = _checked(path, "npz", limit)
    try:
        with zipfile.ZipFile(p) as z:
            infos = z.infolist()
            total = sum(i.file_size for i in infos)
            if total > limit:
                raise InputFileError(f"{p}: its members hold {_mib(total)} uncompressed, more than the {_mib(limit)} "
                                     "an .npz file may have")
            for info in infos:
                with z.open(info) as member:
                    _check_member(p, info, member)
    except zipfile.BadZipFile as exc:
        raise InputFileError(f"{p}: not a readable .npz archive ({exc})") from None
    except zlib.error as exc:  # a damaged compressed member
        raise InputFileError(f"{p}: a member does not decompress ({exc}); the file is damaged") from None
    except (OSError, EOFError) as exc:
        raise InputFileError(f"{p}: cannot be read ({type(exc).__name__}: {exc})") from None
    try:
        return np.load(p, allow_pickle=False)
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise InputFileError(f"{p}: not a readable .npz archive ({type(exc).__name__}: {exc})") from None


def _check_member(path: Path, info: zipfile.ZipInfo, member: Any) -> None:
    """A ``.npy`` member's header: a version, a plain dtype and a shape that fits its declared size."""
    name = info.filename
    if not name.endswith(".npy"):
        return
    try:
        version = np.lib.format.read_magic(member)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(member)
        elif version == (2, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(member)
        else:
            shape, fortran, dtype = np.lib.format._read_array_header(member, version)  # noqa: SLF001
    except (ValueError, EOFError, OSError) as exc:
        raise InputFileError(f"{path}: member {name}: not a NumPy array ({exc})") from None
    if dtype.hasobject:
        raise InputFileError(f"{path}: member {name}: holds Python objects (dtype {dtype}); wbc reads no pickles")
    count = 1
    for d in shape:
        count *= int(d)
    if count * dtype.itemsize > info.file_size:
        raise InputFileError(f"{path}: member {name}: its header claims {count} values of {dtype} "
                             f"({_mib(count * dtype.itemsize)}), more than the member's {_mib(info.file_size)}")
