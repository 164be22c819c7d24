"""Scenarios: hashed TOML files that declare a family of trials, their validation and their seeded sampling.

A scenario file (``scenarios/*.toml``) names the robot, the terrain, the domain randomisation, the velocity commands
and the pushes of an episode, and splits its trials into *bands* (for example in- and out-of-distribution push
forces). `load_scenario` parses and validates a file and returns a `Scenario`; every problem in a file is a
`ScenarioError` that names the file, the line and the field (``[table] key``, or ``[[bands]] #2 key`` for the
second table of an array). `Scenario.trial` turns (band, seed, index) into a fully determined
`wbc.scenario.trial.Trial`; `check_published` refuses a published scenario whose content changed without a version bump.

Schema (every other key is an error):

- ``[scenario]``: ``name`` (``^[a-z0-9][a-z0-9_-]*$``), ``version`` (int >= 1), ``description``, ``notes``
  (optional), ``robot`` (a key of `wbc.robots.registry.ROBOTS`), ``duration_s`` (in (0, 600]).
- ``[terrain]``: ``kind`` (``flat`` | ``fractal``), ``amplitude_m`` [0, 0.3], ``base_wavelength_m`` (0, 20],
  ``octaves`` [1, 8], ``half_extent_m`` (1, 50].
- ``[domain]`` (optional), intervals ``[lo, hi]`` drawn uniformly: ``friction`` (0, 5], ``payload_kg`` [-1, 20],
  ``motor_strength`` (0, 2].
- ``[commands]``: ``ramp_s`` [0, duration_s] and ``[[commands.options]]`` (``vx`` |.| <= 3, ``vy`` |.| <= 2,
  ``yaw_rate`` |.| <= 4, ``random_sign``), one drawn uniformly per trial.
- ``[pushes]`` (optional): ``first_s`` and ``interval_s`` intervals, ``duration_s`` (0, 1], ``offset_m`` [0, 0.5].
- ``[[bands]]``: ``name``, ``push_force_n`` (an interval in [0, 5000]; required with ``[pushes]``, forbidden
  without), ``vx`` (optional override of the drawn option's vx).

Sampling. Trial ``index`` under ``seed`` draws from
``np.random.default_rng(SeedSequence([seed, index, int(hash[:8], 16)]))`` in this fixed order:

1. ``terrain_seed = rng.integers(2**31)``;
2. friction, payload mass, motor strength: one ``rng.random()`` each, mapped into the ``[domain]`` interval;
3. the command option: ``rng.integers(len(options))``, then one ``rng.random()`` for the yaw sign flip (drawn even
   when ``random_sign`` is false; the sign flips when it is below 1/2);
4. with ``[pushes]``: ``start`` from ``first_s``; then, while ``start < duration_s``: the magnitude's ``u``, the
   heading (``2 pi rng.random()``), the offset axis (``rng.integers(2)``: 0 = base x, 1 = base y), the offset
   (``rng.random()`` mapped into [-offset_m, offset_m]), then the next start (``start += `` a draw from
   ``interval_s``).

The band never enters the seed and every band draws the same numbers, so trials with the same (seed, index) in two
bands share terrain, domain, command and push times, headings and offsets; only the band's values differ (the push
magnitude is ``lo + u (hi - lo)`` of the band's ``push_force_n``, and the band's ``vx`` override).
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from wbc.errors import ConfigError, UnknownNameError, WbcError
from wbc.robots.registry import ROBOTS
from wbc.scenario.domain import DomainParams
from wbc.scenario.push import Push
from wbc.scenario.terrain import TERRAIN_KINDS, TerrainConfig
from wbc.scenario.trial import CommandSchedule, Trial

__all__ = ["Scenario", "ScenarioError", "check_published", "load_scenario"]

_NAME_RE = re.compile(r"^[a-z0-9][a-z0-9_-]*$")
_BAND_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
_MAX_PUSHES = 1000  # per trial: bounds the sampling loop whatever interval_s says


class ScenarioError(WbcError, ValueError):
    """A scenario file (or the lock of published scenarios) is missing, unreadable or invalid.

    ``str(err)`` reads ``path:line: [table] key: what is wrong``; the line and the field are left out when unknown.

    Attributes:
        path: the file at fault, as given.
        line: 1-based line of the offending key or table header, or None.
        field: ``[table] key`` (``[[bands]] #2 key`` in arrays of tables, 1-based), ``[table]``, or None.
        reason: what is wrong and how to fix it, without the location.
    """

    def __init__(self, path: str | Path, reason: str, *, line: int | None = None, field: str | None = None) -> None:
        self.path = str(path)
        self.line = line
        self.field = field
        self.reason = reason
        where = self.path if line is None else f"{self.path}:{line}"
        super().__init__(f"{where}: {field}: {reason}" if field else f"{where}: {reason}")


# --------------------------------------------------------------------------------------------------------------------
# Line numbers: tomllib reports none, so the raw text is scanned for table headers and `key =` lines.

_HEADER_RE = re.compile(r"^\s*(\[\[|\[)\s*([^\[\]#]+?)\s*(\]\]|\])\s*(?:#.*)?$")
_KEY_PART = r"(?:\"[^\"]*\"|'[^']*'|[A-Za-z0-9_-]+)"
_KEY_RE = re.compile(rf"^\s*({_KEY_PART}(?:\s*\.\s*{_KEY_PART})*)\s*=")

_TableId = tuple[str, int]  # (dotted table name, occurrence: 0 for [x], k >= 1 for the k-th [[x]])


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


class _Lines:
    """Where table headers and keys sit in a TOML text (1-based lines)."""

    def __init__(self, text: str) -> None:
        self._headers: dict[_TableId, int] = {}
        self._keys: dict[tuple[_TableId, str], int] = {}
        counts: dict[str, int] = {}
        table: _TableId = ("", 0)
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
                    continue
                key = _KEY_RE.match(line)
                if key:
                    parts = _split_key(key.group(1))
                    self._keys.setdefault((table, ".".join(parts)), lineno)
                    if len(parts) > 1 and table[1] == 0:  # `terrain.kind = ...` at top level, or similar
                        prefix = ".".join(p for p in (table[0], *parts[:-1]) if p)
                        self._keys.setdefault(((prefix, 0), parts[-1]), lineno)
            state, depth = _scan_line(line, state, depth)

    def header(self, table: _TableId) -> int | None:
        """Line of the header of `table`, or None."""
        return self._headers.get(table)

    def key(self, table: _TableId, key: str) -> int | None:
        """Line of ``key =`` in `table`, or None."""
        return self._keys.get((table, key))


# --------------------------------------------------------------------------------------------------------------------
# Typed access to parsed tables, raising ScenarioError with the file, line and field.

_MISSING: Any = object()


@dataclass(frozen=True, kw_only=True)
class _Range:
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
        if self.hi == math.inf:
            return f"{'>' if self.lo_open else '>='} {self.lo:g}"
        if self.lo == -math.inf:
            return f"{'<' if self.hi_open else '<='} {self.hi:g}"
        return f"in {'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'}"


def _toml_type(value: object) -> str:
    """The TOML name of a parsed value's type."""
    names = {bool: "boolean", int: "integer", float: "float", str: "string", list: "array", dict: "table"}
    return names.get(type(value), "date/time" if hasattr(value, "isoformat") else type(value).__name__)


def _show(value: object) -> str:
    """A parsed value as a message shows it: its TOML type and a short rendering."""
    if isinstance(value, bool):
        return f"boolean {str(value).lower()}"
    if isinstance(value, dict):
        return "a table"
    text = repr(value)
    return f"{_toml_type(value)} {text if len(text) <= 40 else text[:37] + '...'}"


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


class _Table:
    """One parsed TOML table with the location information its error messages need."""

    def __init__(self, path: str, lines: _Lines, data: dict[str, Any], label: str, table: _TableId,
                 header_line: int | None = None) -> None:
        self.path = path
        self.lines = lines
        self.data = data
        self.label = label  # "[terrain]", "[[bands]] #2"; "" at top level
        self.table = table
        self.header_line = header_line if header_line is not None else lines.header(table)  # or `key = {...}` line

    def fail(self, key: str | None, reason: str, *, at_header: bool = False) -> NoReturn:
        """Raise a ScenarioError about `key` of this table (the table itself when `key` is None)."""
        line = None if key is None or at_header else self.lines.key(self.table, key)
        if line is None:
            line = self.header_line
        name = self.label if key is None else f"{self.label} {key}".strip()
        raise ScenarioError(self.path, reason, line=line, field=name)

    def check_keys(self, valid: Sequence[str]) -> None:
        """Refuse keys outside `valid`, listing the valid ones."""
        for key in self.data:
            if key not in valid:
                kind = self.label.split(" #")[0]  # "[[bands]] #2" -> "[[bands]]"
                self.fail(key, f"unknown key; valid keys of {kind}: {', '.join(valid)}")

    def _get(self, key: str, default: Any) -> Any:
        if key in self.data:
            return self.data[key]
        if default is _MISSING:
            self.fail(key, f"missing required key; add `{key} = ...` to {self.label}", at_header=True)
        return default

    def string(self, key: str, default: str = _MISSING) -> str:
        """A string value."""
        value = self._get(key, default)
        if not isinstance(value, str):
            self.fail(key, f"expected a string, got {_show(value)}")
        return value

    def boolean(self, key: str, default: bool = _MISSING) -> bool:
        """A boolean value (true / false)."""
        value = self._get(key, default)
        if not isinstance(value, bool):
            self.fail(key, f"expected a boolean (true or false), got {_show(value)}")
        return value

    def integer(self, key: str, allowed: _Range, default: int = _MISSING) -> int:
        """An integer value (a boolean or a float is refused) within `allowed`."""
        value = self._get(key, default)
        if not isinstance(value, int) or isinstance(value, bool):
            self.fail(key, f"expected an integer, got {_show(value)}")
        if value not in allowed:
            self.fail(key, f"must be {allowed}, got {value}")
        return value

    def number(self, key: str, allowed: _Range, default: float = _MISSING) -> float:
        """A finite number (integer or float) within `allowed`, as a float."""
        value = self._get(key, default)
        if not _is_number(value):
            self.fail(key, f"expected a number, got {_show(value)}")
        if not math.isfinite(value):
            self.fail(key, f"must be a finite number, got {value}")
        if value not in allowed:
            self.fail(key, f"must be {allowed}, got {value}")
        return float(value)

    def optional_number(self, key: str, allowed: _Range) -> float | None:
        """Like `number`, None when the key is absent."""
        return self.number(key, allowed) if key in self.data else None

    def interval(self, key: str, allowed: _Range, default: tuple[float, float] = _MISSING) -> tuple[float, float]:
        """An interval ``[lo, hi]``: two finite numbers, lo <= hi, both within `allowed`."""
        value = self._get(key, default)
        if isinstance(value, tuple):
            return value
        if not isinstance(value, list):
            self.fail(key, f"expected an interval [lo, hi] (an array of 2 numbers), got {_show(value)}")
        if len(value) != 2:
            self.fail(key, f"expected an interval [lo, hi] of 2 numbers, got an array of {len(value)}")
        for position, x in enumerate(value, start=1):
            if not _is_number(x):
                self.fail(key, f"expected an interval [lo, hi] of 2 numbers, got {_show(x)} at position {position}")
            if not math.isfinite(x):
                self.fail(key, f"interval ends must be finite numbers, got {x} at position {position}")
        lo, hi = float(value[0]), float(value[1])
        if lo > hi:
            self.fail(key, f"interval [lo, hi] needs lo <= hi, got [{value[0]}, {value[1]}]; swap the two ends")
        if lo not in allowed or hi not in allowed:
            self.fail(key, f"both ends must be {allowed}, got [{value[0]}, {value[1]}]")
        return lo, hi

    def table_array(self, key: str, label: str) -> list[_Table]:
        """A non-empty array of tables ``[[key]]`` (key relative to this table), each labelled ``label #k``."""
        field_name = f"{self.label} {key}" if self.label else label
        line = self.lines.key(self.table, key) or self.header_line
        if key not in self.data:
            raise ScenarioError(self.path, f"missing; add at least one {label} table", field=field_name,
                                line=self.header_line)
        value = self.data[key]
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise ScenarioError(self.path, f"expected an array of tables ({label}), got {_show(value)}",
                                field=field_name, line=line)
        if not value:
            raise ScenarioError(self.path, f"must hold at least one {label} table", field=field_name, line=line)
        name = ".".join(p for p in (self.table[0], key) if p)
        return [_Table(self.path, self.lines, v, f"{label} #{k}", (name, k)) for k, v in enumerate(value, start=1)]


def _sub_table(top: _Table, key: str, valid: Sequence[str], *, required: bool) -> _Table:
    """Top-level table ``[key]``, its keys checked against `valid`; an empty one when absent and optional."""
    if key not in top.data:
        if required:
            raise ScenarioError(top.path, f"missing required table; add a [{key}] table (keys: {', '.join(valid)})",
                                field=f"[{key}]")
        return _Table(top.path, top.lines, {}, f"[{key}]", (key, 0))
    value = top.data[key]
    line = top.lines.header((key, 0)) or top.lines.key(("", 0), key)
    if not isinstance(value, dict):
        raise ScenarioError(top.path, f"expected a table, got {_show(value)}", line=line, field=f"[{key}]")
    table = _Table(top.path, top.lines, value, f"[{key}]", (key, 0), line)
    table.check_keys(valid)
    return table


# --------------------------------------------------------------------------------------------------------------------
# The parsed scenario.


@dataclass(frozen=True, kw_only=True)
class _DomainRanges:
    """``[domain]``: intervals drawn uniformly per trial."""

    friction: tuple[float, float]
    payload_kg: tuple[float, float]  # [kg]
    motor_strength: tuple[float, float]


@dataclass(frozen=True, kw_only=True)
class _CommandOption:
    """One ``[[commands.options]]`` table."""

    vx: float  # [m/s]
    vy: float  # [m/s]
    yaw_rate: float  # [rad/s]
    random_sign: bool


@dataclass(frozen=True, kw_only=True)
class _Pushes:
    """``[pushes]``: timing and application point of the pushes."""

    first_s: tuple[float, float]  # [s]
    interval_s: tuple[float, float]  # [s]
    duration_s: float  # [s]
    offset_m: float  # [m]


@dataclass(frozen=True, kw_only=True)
class _Band:
    """One ``[[bands]]`` table."""

    name: str
    push_force_n: tuple[float, float] | None  # [N]
    vx: float | None  # [m/s]


def _uniform(rng: np.random.Generator, interval: tuple[float, float]) -> float:
    """One draw of ``rng.random()`` mapped into `interval` (exactly lo when lo == hi)."""
    lo, hi = interval
    return float(lo + rng.random() * (hi - lo))


def _check_count(name: str, value: object) -> int:
    """A seed, index or count: a non-negative integer."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
        raise ConfigError(f"{name} must be a non-negative integer, got {value!r}")
    return int(value)


@dataclass(frozen=True, kw_only=True)
class Scenario:
    """A validated scenario file; `trial` samples its trials.

    Attributes:
        name: scenario name (``[scenario] name``).
        version: scenario version; bump it whenever a published file changes.
        description: one-paragraph summary.
        notes: calibration reasoning and evidence.
        robot: robot registry name.
        duration_s: episode length [s].
        hash: sha256 (hex) of the canonical JSON of the parsed file: comments and layout do not change it, any value
            does.
        path: the file it was loaded from, as given.
        bands: band names, in file order.
    """

    name: str
    version: int
    description: str
    notes: str
    robot: str
    duration_s: float
    hash: str
    path: str
    bands: tuple[str, ...]
    _terrain: TerrainConfig = field(repr=False)
    _domain: _DomainRanges = field(repr=False)
    _ramp_s: float = field(repr=False)
    _options: tuple[_CommandOption, ...] = field(repr=False)
    _pushes: _Pushes | None = field(repr=False)
    _bands: tuple[_Band, ...] = field(repr=False)

    def _band(self, band: str) -> _Band:
        for spec in self._bands:
            if spec.name == band:
                return spec
        raise UnknownNameError(f"band of scenario {self.name!r}", band, self.bands)

    def trial(self, band: str, seed: int, index: int) -> Trial:
        """Trial `index` of `band` under `seed`: a pure function of the file's content, band, seed and index.

        Args:
            band: a name in `bands`.
            seed: seed (non-negative integer).
            index: trial index within (band, seed) (non-negative integer).

        Returns:
            The fully determined trial; the draw order is given in the module docstring.

        Raises:
            UnknownNameError: `band` is not a band of this scenario; the message lists the valid ones.
            ConfigError: `seed` or `index` is not a non-negative integer.
        """
        spec = self._band(band)
        seed = _check_count("seed", seed)
        index = _check_count("index", index)
        rng = np.random.default_rng(np.random.SeedSequence([seed, index, int(self.hash[:8], 16)]))

        terrain_seed = int(rng.integers(2**31))
        domain = DomainParams(
            friction=_uniform(rng, self._domain.friction),
            payload_mass=_uniform(rng, self._domain.payload_kg),
            motor_strength=_uniform(rng, self._domain.motor_strength),
        )

        option = self._options[int(rng.integers(len(self._options)))]
        flip = bool(rng.random() < 0.5)
        yaw_rate = -option.yaw_rate if option.random_sign and flip else option.yaw_rate
        command = CommandSchedule(vx=option.vx if spec.vx is None else spec.vx, vy=option.vy, yaw_rate=yaw_rate,
                                  ramp_s=self._ramp_s)

        pushes: list[Push] = []
        if self._pushes is not None:
            p = self._pushes
            force_lo, force_hi = spec.push_force_n if spec.push_force_n is not None else (0.0, 0.0)
            start = _uniform(rng, p.first_s)
            while start < self.duration_s:
                u = float(rng.random())
                heading = float(2.0 * np.pi * rng.random())
                axis = int(rng.integers(2))
                offset = np.zeros(3)
                offset[axis] = _uniform(rng, (-p.offset_m, p.offset_m))
                pushes.append(Push.horizontal(magnitude=force_lo + u * (force_hi - force_lo), heading=heading,
                                              offset_in_base=offset, start=start, duration=p.duration_s))
                start += _uniform(rng, p.interval_s)

        return Trial(scenario=self.name, scenario_hash=self.hash, robot=self.robot, band=spec.name, seed=seed,
                     index=index, duration_s=self.duration_s, terrain=self._terrain, terrain_seed=terrain_seed,
                     domain=domain, pushes=tuple(pushes), command=command)

    def trials(self, bands: Sequence[str] | None, seeds: Sequence[int], n: int) -> list[Trial]:
        """Trials 0..n-1 of every (band, seed), ordered by band, then seed, then index.

        Args:
            bands: band names (a single name is accepted too); None for all bands in file order.
            seeds: seeds.
            n: trials per (band, seed).

        Returns:
            ``len(bands) * len(seeds) * n`` trials, each equal to ``trial(band, seed, index)``.

        Raises:
            UnknownNameError: a band is not in `bands`; the message lists the valid ones.
            ConfigError: a seed or `n` is not a non-negative integer.
        """
        names = self.bands if bands is None else ((bands,) if isinstance(bands, str) else tuple(bands))
        for name in names:
            self._band(name)
        n = _check_count("n", n)
        return [self.trial(band, seed, i) for band in names for seed in seeds for i in range(n)]


# --------------------------------------------------------------------------------------------------------------------
# Loading.


def _read_toml(path: Path, shown: str) -> tuple[dict[str, Any], _Lines]:
    """Read and parse a TOML file; every failure is a ScenarioError naming `shown`."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ScenarioError(shown, "file not found; check the path (scenario files live in scenarios/)") from None
    except OSError as exc:
        raise ScenarioError(shown, f"cannot read the file: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise ScenarioError(shown, "the file is not valid UTF-8; save it as UTF-8", line=line) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        message = str(exc)
        where = re.search(r"\s*\(at line (\d+), column (\d+)\)$", message)
        if where:
            line: int | None = int(where.group(1))
            message = f"{message[: where.start()]} (column {where.group(2)})"
        else:
            line = text.count("\n") + 1 if message.endswith("(at end of document)") else None
            message = re.sub(r"\s*\(at end of document\)$", "", message)
        raise ScenarioError(shown, f"invalid TOML: {message}; fix the syntax (https://toml.io)", line=line) from None
    return data, _Lines(text)


def _content_hash(data: dict[str, Any]) -> str:
    """sha256 (hex) of the canonical JSON of parsed TOML content."""
    return hashlib.sha256(json.dumps(data, sort_keys=True, separators=(",", ":")).encode("utf-8")).hexdigest()


def load_scenario(path: str | Path) -> Scenario:
    """Load, validate and hash a scenario file.

    Args:
        path: the TOML file (see the module docstring for its schema).

    Returns:
        The scenario.

    Raises:
        ScenarioError: the file is missing, unreadable, not TOML, or breaks the schema; the message names the file,
            the line (where known) and the field, and says how to fix it. Nothing else is raised for a bad file.
    """
    shown = str(path)
    data, lines = _read_toml(Path(path), shown)
    top = _Table(shown, lines, data, "", ("", 0))
    valid_tables = ("scenario", "terrain", "domain", "commands", "pushes", "bands")
    for key in data:
        if key not in valid_tables:
            raise ScenarioError(shown, "unknown table; valid tables: [scenario], [terrain], [domain], [commands], "
                                "[pushes], [[bands]]", line=lines.header((key, 0)) or lines.key(("", 0), key),
                                field=f"[{key}]")

    head = _sub_table(top, "scenario", ("name", "version", "description", "notes", "robot", "duration_s"),
                      required=True)
    name = head.string("name")
    if not _NAME_RE.match(name):
        head.fail("name", f"must match {_NAME_RE.pattern} (lower-case letters, digits, '_', '-'), got {name!r}")
    version = head.integer("version", _Range(lo=1))
    description = head.string("description")
    if not description.strip():
        head.fail("description", "must not be empty; say in a sentence what the scenario tests")
    notes = head.string("notes", "")
    robot = head.string("robot")
    if robot not in ROBOTS:
        head.fail("robot", f"unknown robot {robot!r}; valid robots: {', '.join(sorted(ROBOTS))}")
    duration_s = head.number("duration_s", _Range(lo=0.0, hi=600.0, lo_open=True))

    ter = _sub_table(top, "terrain", ("kind", "amplitude_m", "base_wavelength_m", "octaves", "half_extent_m"),
                     required=True)
    kind = ter.string("kind")
    if kind not in TERRAIN_KINDS:
        ter.fail("kind", f"must be one of {', '.join(map(repr, TERRAIN_KINDS))}, got {kind!r}")
    terrain = TerrainConfig(
        kind=kind,
        amplitude=ter.number("amplitude_m", _Range(lo=0.0, hi=0.3), 0.05),
        base_cell=ter.number("base_wavelength_m", _Range(lo=0.0, hi=20.0, lo_open=True), 1.6),
        octaves=ter.integer("octaves", _Range(lo=1, hi=8), 4),
        half_extent=ter.number("half_extent_m", _Range(lo=1.0, hi=50.0, lo_open=True), 10.0),
    )

    dom = _sub_table(top, "domain", ("friction", "payload_kg", "motor_strength"), required=False)
    domain = _DomainRanges(
        friction=dom.interval("friction", _Range(lo=0.0, hi=5.0, lo_open=True), (1.0, 1.0)),
        payload_kg=dom.interval("payload_kg", _Range(lo=-1.0, hi=20.0), (0.0, 0.0)),
        motor_strength=dom.interval("motor_strength", _Range(lo=0.0, hi=2.0, lo_open=True), (1.0, 1.0)),
    )

    com = _sub_table(top, "commands", ("ramp_s", "options"), required=True)
    ramp_s = com.number("ramp_s", _Range(lo=0.0), 0.0)
    if ramp_s > duration_s:
        com.fail("ramp_s", f"must be <= [scenario] duration_s ({duration_s:g}), got {ramp_s:g}")
    options = []
    for opt in com.table_array("options", "[[commands.options]]"):
        opt.check_keys(("vx", "vy", "yaw_rate", "random_sign"))
        options.append(_CommandOption(
            vx=opt.number("vx", _Range(lo=-3.0, hi=3.0), 0.0),
            vy=opt.number("vy", _Range(lo=-2.0, hi=2.0), 0.0),
            yaw_rate=opt.number("yaw_rate", _Range(lo=-4.0, hi=4.0), 0.0),
            random_sign=opt.boolean("random_sign", False),
        ))

    pushes = None
    psh = _sub_table(top, "pushes", ("first_s", "interval_s", "duration_s", "offset_m"), required=False)
    if "pushes" in data:
        first_s = psh.interval("first_s", _Range(lo=0.0))
        if first_s[1] >= duration_s:
            psh.fail("first_s", f"must end before [scenario] duration_s ({duration_s:g}) so that every trial is "
                     f"pushed, got [{first_s[0]:g}, {first_s[1]:g}]")
        push_duration = psh.number("duration_s", _Range(lo=0.0, hi=1.0, lo_open=True))
        interval_s = psh.interval("interval_s", _Range(lo=0.0, lo_open=True))
        if interval_s[0] < push_duration:
            psh.fail("interval_s", f"lower end must be >= [pushes] duration_s ({push_duration:g}) so that pushes "
                     f"do not overlap, got [{interval_s[0]:g}, {interval_s[1]:g}]")
        if duration_s / interval_s[0] > _MAX_PUSHES:
            psh.fail("interval_s", f"allows more than {_MAX_PUSHES} pushes per trial; raise its lower end")
        pushes = _Pushes(first_s=first_s, interval_s=interval_s, duration_s=push_duration,
                         offset_m=psh.number("offset_m", _Range(lo=0.0, hi=0.5)))

    bands: list[_Band] = []
    seen: dict[str, str] = {}
    for bnd in top.table_array("bands", "[[bands]]"):
        bnd.check_keys(("name", "push_force_n", "vx"))
        band_name = bnd.string("name")
        if not _BAND_RE.match(band_name):
            bnd.fail("name", f"must match {_BAND_RE.pattern} (letters, digits, '_', '.', '-'), got {band_name!r}")
        if band_name in seen:
            bnd.fail("name", f"duplicate band name {band_name!r} (also {seen[band_name]}); band names must be unique")
        seen[band_name] = bnd.label
        if pushes is None and "push_force_n" in bnd.data:
            bnd.fail("push_force_n", "not allowed without a [pushes] table; add [pushes] or remove push_force_n")
        if pushes is not None and "push_force_n" not in bnd.data:
            bnd.fail("push_force_n", "missing required key (the scenario has a [pushes] table); add "
                     "`push_force_n = [lo, hi]` [N]", at_header=True)
        force = bnd.interval("push_force_n", _Range(lo=0.0, hi=5000.0)) if pushes is not None else None
        bands.append(_Band(name=band_name, push_force_n=force, vx=bnd.optional_number("vx", _Range(lo=-3.0, hi=3.0))))

    return Scenario(
        name=name, version=version, description=description, notes=notes, robot=robot, duration_s=duration_s,
        hash=_content_hash(data), path=shown, bands=tuple(b.name for b in bands), _terrain=terrain, _domain=domain,
        _ramp_s=ramp_s, _options=tuple(options), _pushes=pushes, _bands=tuple(bands),
    )


def check_published(scenario: Scenario, lock_path: Path | None = None) -> None:
    """Refuse a scenario whose (name, version) is unpublished or was published with different content.

    The lock (``published.toml``) maps name -> version -> hash: ``[push]`` then ``"1" = "<sha256 hex>"``.

    Args:
        scenario: a loaded scenario.
        lock_path: the lock file; default ``published.toml`` next to the scenario file.

    Raises:
        ScenarioError: the lock does not list (name, version) (the message gives the lines to add), lists it with
            another hash (the file changed without a version bump), or is missing or malformed.
    """
    lock = Path(lock_path) if lock_path is not None else Path(scenario.path).parent / "published.toml"
    name, version = scenario.name, str(scenario.version)
    publish = f'to publish it, add\n    [{name}]\n    "{version}" = "{scenario.hash}"\nto {lock}'
    if not lock.exists():
        raise ScenarioError(scenario.path, f"unpublished: the lock file {lock} does not exist; {publish}",
                            field="[scenario] version")
    data, lines = _read_toml(lock, str(lock))
    entry = data.get(name)
    if entry is not None and not isinstance(entry, dict):
        raise ScenarioError(lock, f'expected a table of "version" = "hash", got {_show(entry)}',
                            line=lines.key(("", 0), name), field=f"[{name}]")
    locked = None if entry is None else entry.get(version)
    if locked is None:
        raise ScenarioError(scenario.path, f"unpublished: {lock} does not list {name!r} version {version}; {publish}",
                            field="[scenario] version")
    if not isinstance(locked, str):
        raise ScenarioError(lock, f"expected a sha256 hex string, got {_show(locked)}",
                            line=lines.key((name, 0), version), field=f'[{name}] "{version}"')
    if locked != scenario.hash:
        raise ScenarioError(
            scenario.path,
            f"{name!r} version {version} is published with hash {locked} but the file now hashes to "
            f"{scenario.hash}: the file changed without a version bump; restore it, or bump [scenario] version and "
            f"add the new hash to {lock}",
            field="[scenario] version",
        )
