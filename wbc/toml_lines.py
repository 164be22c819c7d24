"""Where the statements of a TOML text sit, and a parser's error told at the statement it is about.

`tomllib` parses but reports no line numbers for values, so `TomlLines` scans the raw text for table headers and
``key =`` lines (outside strings and multi-line arrays); `syntax_fault` turns a `tomllib.TOMLDecodeError` into the
line, the ``[table] key`` and the reason a message gives, naming the key or table that a file defines twice. Every
TOML input is read through one of two readers, `wbc.input_files.read_toml` and `wbc.scenario.toml_fields.read_toml`,
and both take their messages from here.
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["TableId", "TomlLines", "SyntaxFault", "syntax_fault", "table_label", "toml_key", "toml_keys"]

_HEADER_RE = re.compile(r"^\s*(\[\[|\[)\s*([^\[\]#]+?)\s*(\]\]|\])\s*(?:#.*)?$")
_KEY_PART = r"(?:\"[^\"]*\"|'[^']*'|[A-Za-z0-9_-]+)"
_KEY_RE = re.compile(rf"^\s*({_KEY_PART}(?:\s*\.\s*{_KEY_PART})*)\s*=")

TableId = tuple[str, int]  # (dotted table name, occurrence: 0 for [x], k >= 1 for the k-th [[x]])


def _split_key(key: str) -> list[str]:
    """Parts of a dotted TOML key, quotes removed (a dot inside quotes is not handled: best effort)."""
    return [part.strip().strip("\"'") for part in key.split(".")]


def _scan_line(line: str, state: str | None, depth: int) -> tuple[str | None, int]:
    """Advance the string state and bracket depth of the TOML lexer over one line.

    Args:
        line: the line, without its newline.
        state: None outside strings, else the open string's delimiter (``"``, ``'``, ``\"\"\"``, ``'''``).
        depth: open ``[``/``{`` brackets (arrays and inline tables spanning several lines).

    Returns:
        The state and depth at the end of the line.
    """
    i, n = 0, len(line)
    while i < n:
        if state is None:
            c = line[i]
            if c == "#":
                break
            if line.startswith('"""', i) or line.startswith("'''", i):
                state = line[i : i + 3]
                i += 3
                continue
            if c in "\"'":
                state = c
            elif c in "[{":
                depth += 1
            elif c in "]}":
                depth = max(depth - 1, 0)
            i += 1
        elif state in ('"', '"""') and line[i] == "\\":
            i += 2
        elif line.startswith(state, i):
            i += len(state)
            state = None
        else:
            i += 1
    if state in ('"', "'"):  # single-line strings cannot span lines
        state = None
    return state, depth


class TomlLines:
    """Where table headers and keys sit in a TOML text (1-based lines)."""

    def __init__(self, text: str) -> None:
        self._headers: dict[TableId, int] = {}
        self._keys: dict[tuple[TableId, str], int] = {}
        self._statements: list[tuple[int, TableId, str | None]] = []  # (line, table, key; None for a header)
        counts: dict[str, int] = {}
        table: TableId = ("", 0)
        state: str | None = None
        depth = 0
        for lineno, line in enumerate(text.splitlines(), start=1):
            if state is None and depth == 0:
                header = _HEADER_RE.match(line)
                if header:
                    name = ".".join(_split_key(header.group(2)))
                    if header.group(1) == "[[":
                        counts[name] = counts.get(name, 0) + 1
                        table = (name, counts[name])
                    else:
                        table = (name, 0)
                    self._headers.setdefault(table, lineno)
                    self._statements.append((lineno, table, None))
                    continue
                key = _KEY_RE.match(line)
                if key:
                    parts = _split_key(key.group(1))
                    self._keys.setdefault((table, ".".join(parts)), lineno)
                    self._statements.append((lineno, table, ".".join(parts)))
                    if len(parts) > 1 and table[1] == 0:  # `terrain.kind = ...` at top level, or similar
                        prefix = ".".join(p for p in (table[0], *parts[:-1]) if p)
                        self._keys.setdefault(((prefix, 0), parts[-1]), lineno)
            state, depth = _scan_line(line, state, depth)

    def header(self, table: TableId) -> int | None:
        """Line of the header of `table`, or None."""
        return self._headers.get(table)

    def key(self, table: TableId, key: str) -> int | None:
        """Line of ``key =`` in `table`, or None."""
        return self._keys.get((table, key))

    def first_header(self, name: str) -> int | None:
        """Line of the first header of table `name` or of a table inside it (``[name.x]``), or None."""
        return min((line for (table, _), line in self._headers.items()
                    if table == name or table.startswith(f"{name}.")), default=None)

    def statement_at(self, line: int) -> tuple[int, TableId, str | None] | None:
        """The statement that spans `line`, as (its line, its table, its key or None for a header), or None.

        That is the last header or ``key =`` begun on `line` or before it (a value may span lines).
        """
        found = None
        for statement in self._statements:
            if statement[0] > line:
                break
            found = statement
        return found



def table_label(table: TableId) -> str:
    """A table as messages name it: ``[terrain]``, ``[[bands]] #2`` (the k-th of an array), "" at top level."""
    name, occurrence = table
    if not name:
        return ""
    return f"[[{name}]] #{occurrence}" if occurrence else f"[{name}]"


def toml_key(path: Sequence[str]) -> str:
    """A key by its path of names, as a file writes it: ``[mpc] horizon``, ``[base.mpc] mu``, top-level ``ready_q``."""
    *table, key = path
    return f"[{'.'.join(table)}] {key}" if table else key


def toml_keys(table: Mapping[str, Any], path: tuple[str, ...] = ()) -> list[str]:
    """Every key a parsed TOML table sets, in its order, by `toml_key` (a sub-table's keys, not the sub-table)."""
    out: list[str] = []
    for key, value in table.items():
        if isinstance(value, Mapping):
            out += toml_keys(value, (*path, key))
        else:
            out.append(toml_key((*path, key)))
    return out


@dataclass(frozen=True)
class SyntaxFault:
    """What a message says of a file `tomllib` refused.

    Attributes:
        line: 1-based line of the fault, or None.
        field: ``[table] key`` (or ``[table]``, or a top-level ``key``) that a redefinition is about, else None.
        reason: what is wrong and how to fix it, beginning "invalid TOML: ".
    """

    line: int | None
    field: str | None
    reason: str


_AT = re.compile(r"\s*\(at line (\d+), column (\d+)\)$")
_END = re.compile(r"\s*\(at end of document\)$")
_KEY_TUPLE = re.compile(r"\(((?:'[^']*'|\"[^\"]*\")(?:, (?:'[^']*'|\"[^\"]*\"))*),?\)")
_REDEFINITIONS = ("Cannot overwrite a value", "Cannot declare", "Duplicate inline table key",
                  "Cannot mutate immutable namespace", "Cannot redefine namespace")


def _dotted(message: str) -> str:
    """The parser's keys written as TOML writes them: ``('a', 'b')`` -> ``a.b``."""
    return _KEY_TUPLE.sub(lambda m: ".".join(part.strip().strip("'\"") for part in m.group(1).split(",")), message)


def syntax_fault(text: str, exc: tomllib.TOMLDecodeError) -> SyntaxFault:
    """The line, field and reason of a message about `text`, which `tomllib` refused with `exc`.

    A key or table defined twice (``Cannot overwrite a value`` and its kin, which name neither) is told at the
    statement the parser stopped in: its ``[table] key`` and the line it begins on, with the line of the first
    definition where the scan finds one. Any other fault keeps the parser's words, line and column.
    """
    message = str(exc)
    where = _AT.search(message)
    if where:
        line: int | None = int(where.group(1))
        column = where.group(2)
        message = message[: where.start()]
    else:
        line, column = (text.count("\n") + 1, None) if _END.search(message) else (None, None)
        message = _END.sub("", message)
    message = _dotted(message)
    lines = TomlLines(text)
    statement = lines.statement_at(line) if line is not None and message.startswith(_REDEFINITIONS) else None
    if statement is None:
        at = f" (column {column})" if column else ""
        return SyntaxFault(line, None, f"invalid TOML: {message}{at}; fix the syntax (https://toml.io)")
    begun, table, key = statement
    label = table_label(table)
    if key is None and message.startswith(("Cannot overwrite a value", "Cannot declare")):
        # a header: `[x]` twice, or `[x]` where `x = ...` was set
        parent, _, last = table[0].rpartition(".")
        first = next((n for n in (lines.header(table), lines.key((parent, 0), last)) if n is not None and n < begun),
                     None)
        again = f" (first at line {first})" if first else ""
        return SyntaxFault(begun, label, f"invalid TOML: {label} names what is defined already{again}, as a table, "
                                         "an array of tables or a value; define it once, in one form "
                                         "(https://toml.io)")
    field = f"{label} {key or ''}".strip()
    first = None if key is None else lines.key(table, key)
    if message.startswith("Duplicate inline table key"):
        return SyntaxFault(begun, field, f"invalid TOML: its inline table sets {message.rpartition(' ')[2]} twice; "
                                         "keep one (https://toml.io)")
    if message.startswith("Cannot overwrite a value"):
        again = f" (first at line {first})" if first is not None and first < begun else ""
        return SyntaxFault(begun, field, f"invalid TOML: {key} is set twice{again}; keep one (https://toml.io)")
    return SyntaxFault(begun, field, f"invalid TOML: {message}: a table written whole (an inline table, or by dotted "
                                     "keys) cannot be extended elsewhere; define it in one place (https://toml.io)")
