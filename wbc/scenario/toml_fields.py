"""Typed, located access to TOML files: every bad value is an error naming the file, the line and the field.

`tomllib` parses but reports no line numbers, so `TomlLines` (`wbc.toml_lines`) scans the raw text for table headers
and ``key =`` lines; `TomlTable` reads typed values (strings, booleans, bounded integers and numbers, intervals,
vectors, arrays of tables) and raises the caller's `FileFieldError` subclass, whose text reads ``path:line: [table]
key: what is wrong and how to fix it``. Scenario files use it (`ScenarioError`); any other declarative TOML input
of the toolkit can.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

from wbc.errors import FileFieldError, InputFileError
from wbc.input_files import MAX_DEPTH, read_bytes
from wbc.toml_lines import TableId, TomlLines, syntax_fault

__all__ = ["MISSING", "Range", "TableId", "TomlLines", "TomlTable", "is_number", "read_toml", "show", "toml_type"]

MISSING: Any = object()


@dataclass(frozen=True, kw_only=True)
class Range:
    """An allowed range of numbers, printed the way messages need it."""

    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = False

    def __contains__(self, x: float) -> bool:
        above = x > self.lo if self.lo_open else x >= self.lo
        below = x < self.hi if self.hi_open else x <= self.hi
        return above and below

    def __str__(self) -> str:
        lo, hi = _bound(self.lo), _bound(self.hi)
        if self.hi == math.inf:
            return f"{'>' if self.lo_open else '>='} {lo}"
        if self.lo == -math.inf:
            return f"{'<' if self.hi_open else '<='} {hi}"
        return f"in {'(' if self.lo_open else '['}{lo}, {hi}{')' if self.hi_open else ']'}"


def _bound(x: float) -> str:
    """A range's end as a message prints it: a whole number in full (1000000, not 1e+06), any other shortest."""
    return str(int(x)) if math.isfinite(x) and float(x).is_integer() and abs(x) < 2**53 else f"{x:g}"


def toml_type(value: object) -> str:
    """The TOML name of a parsed value's type."""
    names = {bool: "boolean", int: "integer", float: "float", str: "string", list: "array", dict: "table"}
    return names.get(type(value), "date/time" if hasattr(value, "isoformat") else type(value).__name__)


def show(value: object) -> str:
    """A parsed value as a message shows it: its TOML type and a short rendering."""
    if isinstance(value, bool):
        return f"boolean {str(value).lower()}"
    if isinstance(value, dict):
        return "a table"
    text = repr(value)
    return f"{toml_type(value)} {text if len(text) <= 40 else text[:37] + '...'}"


def is_number(value: object) -> bool:
    """True for an integer or float (a boolean is not a number here)."""
    return isinstance(value, int | float) and not isinstance(value, bool)


class TomlTable:
    """One parsed TOML table with the location information its error messages need."""

    def __init__(self, path: str, lines: TomlLines, data: dict[str, Any], label: str, table: TableId,
                 header_line: int | None = None, *, error: type[FileFieldError] = FileFieldError) -> None:
        self.error = error  # the subclass raised for this file's kind (ScenarioError for scenario files)
        self.path = path
        self.lines = lines
        self.data = data
        self.label = label  # "[terrain]", "[[bands]] #2"; "" at top level
        self.table = table
        self.header_line = header_line if header_line is not None else lines.header(table)  # or `key = {...}` line

    def fail(self, key: str | None, reason: str, *, at_header: bool = False) -> NoReturn:
        """Raise a ScenarioError about `key` of this table (the table itself when `key` is None)."""
        line = None if key is None or at_header else self.lines.key(self.table, key)
        if line is None and key is not None and not at_header:
            # a sub-table written with its own header (`[scenario.x]`, `[[bands.x]]`): that header's line
            name = f"{self.table[0]}.{key}" if self.table[0] else key
            line = self.lines.header((name, 0)) or self.lines.header((name, 1))
        if line is None:
            line = self.header_line
        name = self.label if key is None else f"{self.label} {key}".strip()
        raise self.error(self.path, reason, line=line, field=name)

    def check_keys(self, valid: Sequence[str]) -> None:
        """Refuse keys outside `valid`, listing the valid ones."""
        for key in self.data:
            if key not in valid:
                kind = self.label.split(" #")[0]  # "[[bands]] #2" -> "[[bands]]"
                self.fail(key, f"unknown key; valid keys of {kind}: {', '.join(valid)}")

    def _get(self, key: str, default: Any) -> Any:
        if key in self.data:
            return self.data[key]
        if default is MISSING:
            self.fail(key, f"missing required key; add `{key} = ...` to {self.label}", at_header=True)
        return default

    def string(self, key: str, default: str = MISSING) -> str:
        """A string value."""
        value = self._get(key, default)
        if not isinstance(value, str):
            self.fail(key, f"expected a string, got {show(value)}")
        return value

    def boolean(self, key: str, default: bool = MISSING) -> bool:
        """A boolean value (true / false)."""
        value = self._get(key, default)
        if not isinstance(value, bool):
            self.fail(key, f"expected a boolean (true or false), got {show(value)}")
        return value

    def integer(self, key: str, allowed: Range, default: int = MISSING) -> int:
        """An integer value (a boolean or a float is refused) within `allowed`."""
        value = self._get(key, default)
        if not isinstance(value, int) or isinstance(value, bool):
            self.fail(key, f"expected an integer, got {show(value)}")
        if value not in allowed:
            self.fail(key, f"must be {allowed}, got {value}")
        return value

    def number(self, key: str, allowed: Range, default: float = MISSING) -> float:
        """A finite number (integer or float) within `allowed`, as a float."""
        value = self._get(key, default)
        if not is_number(value):
            self.fail(key, f"expected a number, got {show(value)}")
        if not math.isfinite(value):
            self.fail(key, f"must be a finite number, got {value}")
        if value not in allowed:
            self.fail(key, f"must be {allowed}, got {value}")
        return float(value)

    def optional_number(self, key: str, allowed: Range) -> float | None:
        """Like `number`, None when the key is absent."""
        return self.number(key, allowed) if key in self.data else None

    def interval(self, key: str, allowed: Range, default: tuple[float, float] = MISSING) -> tuple[float, float]:
        """An interval ``[lo, hi]``: two finite numbers, lo <= hi, both within `allowed`."""
        value = self._get(key, default)
        if isinstance(value, tuple):
            return value
        if not isinstance(value, list):
            self.fail(key, f"expected an interval [lo, hi] (an array of 2 numbers), got {show(value)}")
        if len(value) != 2:
            self.fail(key, f"expected an interval [lo, hi] of 2 numbers, got an array of {len(value)}")
        for position, x in enumerate(value, start=1):
            if not is_number(x):
                self.fail(key, f"expected an interval [lo, hi] of 2 numbers, got {show(x)} at position {position}")
            if not math.isfinite(x):
                self.fail(key, f"interval ends must be finite numbers, got {x} at position {position}")
        lo, hi = float(value[0]), float(value[1])
        if lo > hi:
            self.fail(key, f"interval [lo, hi] needs lo <= hi, got [{value[0]}, {value[1]}]; swap the two ends")
        if lo not in allowed or hi not in allowed:
            self.fail(key, f"both ends must be {allowed}, got [{value[0]}, {value[1]}]")
        return lo, hi

    def vector(self, key: str, size: int, allowed: Range, default: tuple[float, ...] = MISSING) -> tuple[float, ...]:
        """A vector ``[x, y, ...]``: `size` finite numbers, each within `allowed`."""
        value = self._get(key, default)
        if isinstance(value, tuple):
            return value
        if not isinstance(value, list):
            self.fail(key, f"expected an array of {size} numbers, got {show(value)}")
        if len(value) != size:
            self.fail(key, f"expected an array of {size} numbers, got an array of {len(value)}")
        for position, x in enumerate(value, start=1):
            if not is_number(x):
                self.fail(key, f"expected an array of {size} numbers, got {show(x)} at position {position}")
            if not math.isfinite(x):
                self.fail(key, f"must hold finite numbers, got {x} at position {position}")
            if x not in allowed:
                self.fail(key, f"each number must be {allowed}, got {x} at position {position}")
        return tuple(float(x) for x in value)

    def optional_interval(self, key: str, allowed: Range) -> tuple[float, float] | None:
        """Like `interval`, None when the key is absent (so that a caller can tell absent from any default)."""
        return self.interval(key, allowed) if key in self.data else None

    def table_array(self, key: str, label: str) -> list[TomlTable]:
        """A non-empty array of tables ``[[key]]`` (key relative to this table), each labelled ``label #k``."""
        field_name = f"{self.label} {key}" if self.label else label
        name = ".".join(p for p in (self.table[0], key) if p)
        # `key = ...`, else the first header that writes it as tables (`[bands.in]` where `[[bands]]` was meant)
        line = self.lines.key(self.table, key) or self.lines.first_header(name) or self.header_line
        if key not in self.data:
            raise self.error(self.path, f"missing; add at least one {label} table", field=field_name,
                                line=self.header_line)
        value = self.data[key]
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.error(self.path, f"expected an array of tables ({label}), got {show(value)}",
                                field=field_name, line=line)
        if not value:
            raise self.error(self.path, f"must hold at least one {label} table", field=field_name, line=line)
        # a table of an inline array (`bands = [{...}, {...}]`) has no header: its errors name the array's line
        return [TomlTable(self.path, self.lines, v, f"{label} #{k}", (name, k), self.lines.header((name, k)) or line,
                          error=self.error) for k, v in enumerate(value, start=1)]

    def sub_table(self, key: str, valid: Sequence[str], *, required: bool) -> TomlTable:
        """Sub-table ``[key]`` of this table, its keys checked against `valid`; empty when absent and optional."""
        if key not in self.data:
            if required:
                raise self.error(self.path, f"missing required table; add a [{key}] table (keys: {', '.join(valid)})",
                                    field=f"[{key}]")
            return TomlTable(self.path, self.lines, {}, f"[{key}]", (key, 0), error=self.error)
        value = self.data[key]
        line = self.lines.header((key, 0)) or self.lines.key(("", 0), key)
        if not isinstance(value, dict):
            raise self.error(self.path, f"expected a table, got {show(value)}", line=line, field=f"[{key}]")
        table = TomlTable(self.path, self.lines, value, f"[{key}]", (key, 0), line, error=self.error)
        table.check_keys(valid)
        return table


def _nesting(value: Any) -> int:
    """How deep tables and arrays nest in parsed TOML (iteratively: a deep file cannot exhaust the stack)."""
    deepest = 0
    stack = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        children = item.values() if isinstance(item, dict) else item if isinstance(item, list) else None
        if children is None:
            continue
        deepest = max(deepest, depth)
        if deepest > MAX_DEPTH:
            break
        stack.extend((child, depth + 1) for child in children)
    return deepest


def read_toml(path: Path, shown: str, error: type[FileFieldError] = FileFieldError, *,
              missing: str = "check the path") -> tuple[dict[str, Any], TomlLines]:
    """Read and parse a TOML file through `wbc.input_files.read_bytes`; every failure is an `error` naming `shown`.

    The file must be a regular file of at most ``LIMITS["toml"]`` bytes (1 MiB), UTF-8, valid TOML, and nest at
    most `wbc.input_files.MAX_DEPTH` levels deep.

    Args:
        path: the file.
        shown: the file as messages name it.
        error: the `FileFieldError` subclass raised.
        missing: the hint given when the file does not exist.

    Returns:
        The parsed table and the lines of its keys and headers.

    Raises:
        FileFieldError: (`error`) missing, not a regular file, too large, not UTF-8 (the line named), not TOML (the
            line and column named; a key or table defined twice by its ``[table] key``: `wbc.toml_lines.syntax_fault`),
            or nested too deep.
    """
    try:
        raw = read_bytes(path, kind="toml")
    except InputFileError as exc:
        if not path.exists():
            raise error(shown, f"file not found; {missing}") from None
        raise error(shown, f"cannot read the file: {str(exc).removeprefix(f'{path}: ')}") from None
    try:
        # a byte-order mark (as some Windows editors write UTF-8) starts no TOML statement: it is read past
        text = raw.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise error(shown, "the file is not valid UTF-8; save it as UTF-8", line=line) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        fault = syntax_fault(text, exc)
        raise error(shown, fault.reason, line=fault.line, field=fault.field) from None
    except RecursionError:
        raise error(shown, f"arrays or inline tables nested too deep to parse; no valid file nests more than "
                    f"{MAX_DEPTH} levels") from None
    except ValueError as exc:  # an integer of more than 4300 digits: Python refuses to convert it
        raise error(shown, f"invalid TOML value: {exc}") from None
    if _nesting(data) > MAX_DEPTH:
        raise error(shown, f"tables and arrays nested more than {MAX_DEPTH} levels deep; no valid file nests so deep")
    return data, TomlLines(text)
