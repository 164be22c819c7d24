"""Mutations of the inputs `wbc` reads: values to extremes, types swapped, keys dropped, bytes flipped, rows edited.

Each function takes the generator (``numpy.random.Generator``) and a valid input, and returns the mutated input and a
short label saying what was done (the label names the case in the campaign's table of failures). TOML documents are
mutated as data (parsed with `tomllib`, changed, written back with `dump_toml`) or as text (nesting bombs, bytes).
"""

from __future__ import annotations

import copy
import io
import json
import math
import struct
import zipfile
import zlib
from typing import Any

import numpy as np

EXTREMES: tuple[Any, ...] = (0, -1, 0.0, -1.0, 1e-300, 1e300, -1e300, math.nan, math.inf, -math.inf, 2**63, 10**30,
                             2**40, 1e-10, 1e6)
"""Numbers a field is set to: zero, negatives, tiny and huge magnitudes, not-a-number, infinities, ints past int64."""

WRONG_TYPES: tuple[Any, ...] = ("text", "", True, {"x": 1}, {"x": {"y": [1, 2]}}, [], [1.0, 2.0, 3.0], [[1.0]],
                                ["a", "b"])
"""Values of the wrong type: strings, booleans, nested tables, arrays of the wrong length and depth."""


# ----------------------------------------------------------------------------------------------------------- TOML --

def _key(k: str) -> str:
    return k if k and all(c.isalnum() or c in "_-" for c in k) else json.dumps(k)


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise TypeError(f"no TOML form for {type(v).__name__}")


def _is_table_array(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def _dump_table(out: list[str], name: str, table: dict[str, Any], *, array: bool = False) -> None:
    out.append(f"[[{name}]]" if array else f"[{name}]")
    nested = []
    for k, v in table.items():
        if isinstance(v, dict) or _is_table_array(v):
            nested.append((k, v))
        else:
            out.append(f"{_key(k)} = {_value(v)}")
    out.append("")
    for k, v in nested:
        sub = f"{name}.{_key(k)}"
        if isinstance(v, dict):
            _dump_table(out, sub, v)
        else:
            for item in v:
                _dump_table(out, sub, item, array=True)


def dump_toml(data: dict[str, Any]) -> str:
    """`data` as TOML text (top-level scalars first, then tables and arrays of tables)."""
    out: list[str] = []
    for k, v in data.items():
        if not isinstance(v, dict) and not _is_table_array(v):
            out.append(f"{_key(k)} = {_value(v)}")
    out.append("")
    for k, v in data.items():
        if isinstance(v, dict):
            _dump_table(out, _key(k), v)
        elif _is_table_array(v):
            for item in v:
                _dump_table(out, _key(k), item, array=True)
    return "\n".join(out) + "\n"


def leaves(data: Any, path: tuple = ()) -> list[tuple]:
    """Paths (keys and indices) of every scalar and array of scalars in `data`."""
    found = []
    if isinstance(data, dict):
        for k, v in data.items():
            found += leaves(v, (*path, k))
    elif _is_table_array(data):
        for i, v in enumerate(data):
            found += leaves(v, (*path, i))
    else:
        found.append(path)
        if isinstance(data, list):
            found += [(*path, i) for i, x in enumerate(data) if not isinstance(x, (list, dict))]
    return found


def _get(data: Any, path: tuple) -> Any:
    for k in path:
        data = data[k]
    return data


def set_path(data: Any, path: tuple, value: Any) -> Any:
    """A deep copy of `data` with the leaf at `path` set to `value`."""
    out = copy.deepcopy(data)
    _get(out, path[:-1])[path[-1]] = value
    return out


def _label(path: tuple) -> str:
    return ".".join(str(k) for k in path)


def mutate_data(rng: np.random.Generator, data: dict[str, Any]) -> tuple[dict[str, Any], str]:
    """One structural or value mutation of a parsed TOML / JSON document."""
    paths = [p for p in leaves(data) if p]
    path = paths[int(rng.integers(len(paths)))]
    old = _get(data, path)
    roll = rng.random()
    if roll < 0.45:
        value = EXTREMES[int(rng.integers(len(EXTREMES)))]
        if isinstance(old, list) and old and rng.random() < 0.6:
            value = [value] * len(old)  # every entry of an interval or vector
        return set_path(data, path, value), f"{_label(path)}={value!r}"
    if roll < 0.7:
        value = WRONG_TYPES[int(rng.integers(len(WRONG_TYPES)))]
        return set_path(data, path, value), f"{_label(path)}={value!r}"
    if roll < 0.82 and not isinstance(path[-1], int):
        out = copy.deepcopy(data)
        del _get(out, path[:-1])[path[-1]]
        return out, f"drop {_label(path)}"
    if roll < 0.9 and isinstance(old, (int, float)) and not isinstance(old, bool):
        scale = float(rng.choice([-1.0, 1e-6, 1e6, 1e12]))
        return set_path(data, path, old * scale), f"{_label(path)}*={scale:g}"
    out = copy.deepcopy(data)
    parent = _get(out, path[:-1])
    if isinstance(parent, dict):
        parent["unknown_key"] = 1
        return out, f"unknown key beside {_label(path)}"
    return set_path(data, path, {"nested": {"table": old if not isinstance(old, float) else [old]}}), \
        f"{_label(path)}=nested table"


def nesting_bomb(depth: int = 500, *, kind: str = "array") -> str:
    """A TOML document nested `depth` deep: arrays (``a = [[[...]]]``) or inline tables."""
    if kind == "array":
        return "a = " + "[" * depth + "]" * depth + "\n"
    return "a = " + "{ b = " * depth + "1" + " }" * depth + "\n"


def duplicate_key(text: str) -> str:
    """`text` with its first ``key = value`` line written twice (TOML forbids it)."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if "=" in line and not line.lstrip().startswith(("#", "[")):
            return "\n".join([*lines[: i + 1], line, *lines[i + 1:]]) + "\n"
    return text + text


# ---------------------------------------------------------------------------------------------------------- bytes --

def mutate_bytes(rng: np.random.Generator, data: bytes) -> tuple[bytes, str]:
    """Truncate, flip bits, insert a non-UTF-8 byte, or empty the file."""
    roll = rng.random()
    n = len(data)
    if roll < 0.3 and n:
        cut = int(rng.integers(n))
        return data[:cut], f"truncated at {cut}/{n}"
    if roll < 0.65 and n:
        out = bytearray(data)
        flips = int(rng.integers(1, 9))
        for _ in range(flips):
            i = int(rng.integers(n))
            out[i] ^= 1 << int(rng.integers(8))
        return bytes(out), f"{flips} bits flipped"
    if roll < 0.9:
        i = int(rng.integers(n + 1))
        return data[:i] + b"\xff\xfe" + data[i:], f"non-UTF-8 bytes at {i}"
    return b"", "empty"


# ------------------------------------------------------------------------------------------------------------ npz --

def _member(name: str) -> zipfile.ZipInfo:
    """A member dated 1980-01-01, so that the same arrays make the same bytes (a seeded case is the same case)."""
    info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
    info.compress_type = zipfile.ZIP_DEFLATED
    return info


def npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """An ``.npz`` archive of `arrays`, in memory (deflated at level 1: thousands are written per campaign)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as z:
        for key, a in arrays.items():
            member = io.BytesIO()
            np.save(member, np.asanyarray(a), allow_pickle=False)
            z.writestr(_member(f"{key}.npy"), member.getvalue(), compresslevel=1)
    return buf.getvalue()


def npz_huge_member(arrays: dict[str, np.ndarray], name: str, count: int = 2**40) -> bytes:
    """`arrays` with member `name` replaced by a ``.npy`` header claiming `count` float32 values (no data)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for key, a in arrays.items():
            member = io.BytesIO()
            if key == name:
                header = f"{{'descr': '<f4', 'fortran_order': False, 'shape': ({count},), }}"
                header = header + " " * (63 - len(header) % 64) + "\n"
                member.write(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode())
            else:
                np.save(member, a)
            z.writestr(_member(f"{key}.npy"), member.getvalue(), compresslevel=1)
    return buf.getvalue()


def npz_deflate_bomb(arrays: dict[str, np.ndarray], name: str, mib: int = 1200) -> bytes:
    """`arrays` with member `name` a valid float32 array of `mib` MiB of zeros (more than the 1 GiB an ``.npz``
    may hold), deflated to about a thousandth of that.

    The member is one deflate block of zeros repeated: after a full flush the compressor starts afresh, so the block
    that deflates 1 MiB of zeros is the same each time and is computed once.
    """
    header = f"{{'descr': '<f4', 'fortran_order': False, 'shape': ({mib * (1 << 20) // 4},), }}"
    header = header + " " * (63 - len(header) % 64) + "\n"
    head = b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode()
    c = zlib.compressobj(9, zlib.DEFLATED, -15)
    first = c.compress(head) + c.flush(zlib.Z_FULL_FLUSH)
    zeros = bytes(1 << 20)
    block = c.compress(zeros) + c.flush(zlib.Z_FULL_FLUSH)
    data = first + block * mib + c.flush(zlib.Z_FINISH)
    crc = zlib.crc32(head)
    big = bytes(64 << 20)
    for _ in range(mib // 64):
        crc = zlib.crc32(big, crc)
    for _ in range(mib % 64):
        crc = zlib.crc32(zeros, crc)
    size = len(head) + mib * (1 << 20)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as z:
        for key, a in arrays.items():
            if key == name:
                continue
            member = io.BytesIO()
            np.save(member, a)
            z.writestr(_member(f"{key}.npy"), member.getvalue(), compresslevel=1)
    # the bomb member is appended by hand (zipfile cannot store data deflated elsewhere): local header, data, and a
    # central directory rewritten to list it
    archive = buf.getvalue()
    end = archive.rfind(b"PK\x05\x06")
    count = int.from_bytes(archive[end + 10:end + 12], "little")
    cd_size = int.from_bytes(archive[end + 12:end + 16], "little")
    cd_offset = int.from_bytes(archive[end + 16:end + 20], "little")
    central = archive[cd_offset:cd_offset + cd_size]
    fname = f"{name}.npy".encode()
    offset = cd_offset
    common = struct.pack("<HHHHHIII", 20, 0, 8, 0, 0x21, crc, len(data), size)
    local = b"PK\x03\x04" + common + struct.pack("<HH", len(fname), 0) + fname
    entry = (b"PK\x01\x02" + struct.pack("<H", 20) + common + struct.pack("<HHHHHII", len(fname), 0, 0, 0, 0, 0, offset)
             + fname)
    body = archive[:cd_offset] + local + data
    central = central + entry
    eocd = b"PK\x05\x06" + struct.pack("<HHHHIIH", 0, 0, count + 1, count + 1, len(central), len(body), 0)
    return body + central + eocd


def mutate_array(rng: np.random.Generator, a: np.ndarray) -> tuple[np.ndarray, str]:
    """An array with non-finite or extreme entries, another shape, another dtype, or none at all."""
    roll = rng.random()
    b = np.array(a, copy=True)
    if roll < 0.25 and b.size and b.dtype.kind == "f":
        b.flat[int(rng.integers(b.size))] = float(rng.choice([np.nan, np.inf, -np.inf]))
        return b, "a non-finite entry"
    if roll < 0.4 and b.dtype.kind == "f":
        return b * float(rng.choice([0.0, -1.0, 1e30, 1e-30])), "scaled"
    if roll < 0.55:
        return b.reshape(-1)[: max(0, b.size - 1)], "one entry short, flattened"
    if roll < 0.7:
        return np.zeros((0,) + b.shape[1:], dtype=b.dtype), "empty"
    if roll < 0.85:
        if b.dtype.kind in "US":  # text: numbers in its place
            return np.zeros(b.shape), "numbers for text"
        with np.errstate(invalid="ignore"):
            return b.astype(np.int64) if b.dtype.kind == "f" else b.astype(np.float64), "other dtype"
    return np.zeros(b.shape + (2,), dtype=b.dtype), "extra axis"
