"""Scenarios: hashed TOML files that declare a family of trials, their validation and their seeded sampling.

A scenario file (``scenarios/*.toml``) names the robot, the terrain, the domain randomisation, the velocity commands
and the pushes of an episode, and splits its trials into *bands* (for example in- and out-of-distribution push
forces). `load_scenario` parses and validates a file and returns a `Scenario`; every problem in a file is a
`ScenarioError` that names the file, the line and the field (``[table] key``, or ``[[bands]] #2 key`` for the
second table of an array). `Scenario.trial` turns (band, seed, index) into a fully determined
`wbc.scenario.trial.Trial`; `check_published` refuses a published scenario whose content changed without a version bump.

Schema (every other key is an error):

- ``[scenario]``: ``name`` (``^[a-z0-9][a-z0-9_-]*$``), ``version`` (int in [1, `MAX_VERSION`]), ``description``,
  ``notes`` (optional), ``robot`` (a key of `wbc.robots.registry.ROBOTS`), ``duration_s`` ([0.1, 600]).
- ``[terrain]``: ``kind`` (``flat`` | ``fractal``), ``amplitude_m`` [0, 0.3], ``octaves`` [1, 8], ``half_extent_m``
  (1, 50] (at most 2001 heightfield samples of 5 cm per axis), ``base_wavelength_m`` [0.05 * 2^(octaves - 1), 20]
  (the finest octave spans at least one heightfield cell: a finer one is invisible on the grid and its noise
  lattice outgrows memory), ``seed`` (optional, an integer in [0, 2^31 - 1]: every trial's terrain seed, where
  without it each trial draws its own).
- ``[domain]`` (optional), intervals ``[lo, hi]`` drawn uniformly: ``friction`` [0.05, 2], ``payload_kg`` [-1, 10],
  ``motor_strength`` [0.1, 2] (`wbc.scenario.domain` says why), and the optional ``actuation_delay_s`` and
  ``sensing_delay_s`` [0, 0.2] (the robot's loop latency, `DomainParams`; a simulator rounds them to its physics step).
- ``[commands]``: ``ramp_s`` [0, duration_s] and ``[[commands.options]]`` (``vx`` |.| <= 3, ``vy`` |.| <= 2,
  ``yaw_rate`` |.| <= 4, ``random_sign``), one drawn uniformly per trial; optionally ``[[commands.changes]]``
  (``at_s`` in [0, duration_s), each later than the one before; ``vx``, ``vy``, ``yaw_rate`` bounded as an
  option's): from ``at_s`` on, every trial's command is that one, held without a ramp until the next change
  (`wbc.scenario.trial.CommandChange`; the commands a person set while a trial played live, replayed).
- ``[pushes]`` (optional): ``first_s`` (an interval ending before ``duration_s``) and ``interval_s`` (an interval in
  (0, 600], its lower end >= the push duration, at most 1000 pushes per trial), ``duration_s`` [0.01, 1],
  ``offset_m`` [0, 0.5].
- ``[[fixed_pushes]]`` (optional): pushes that every trial of every band meets, besides those ``[pushes]`` draws,
  each exactly a `wbc.scenario.push.Push`: ``start_s`` [0, duration_s), ``duration_s`` [0.01, 1], ``force_n``
  (3 numbers: the force in the world frame [N], its magnitude in (0, 2000] and times ``duration_s`` at most
  200 N s), ``offset_m`` (3 numbers: the application point in the base frame [m], each in [-0.5, 0.5]; default
  the base origin). A trial played live with pushes from the browser is exported as such a file
  (``wbc view --export-scenario``).
- ``[[bands]]``: ``name``, ``push_force_n`` (an interval in [0, 2000], its upper end above 0 and, times ``[pushes]
  duration_s``, at most 200 N s; required with ``[pushes]``, forbidden without: a scenario without pushes leaves out
  both), ``vx`` and ``yaw_rate`` (optional overrides of the
  drawn option's vx and yaw rate; the option's sign flip applies to an overridden yaw rate too, so a band of
  ``vx = 0``, ``yaw_rate = 0`` stands whatever option is drawn).

Sampling. Trial ``index`` under ``seed`` draws from
``np.random.default_rng(SeedSequence([seed, index, int(hash[:8], 16)]))`` in this fixed order:

1. ``terrain_seed = rng.integers(2**31)`` (drawn with a ``[terrain] seed`` too, which then replaces it);
2. friction, payload mass, motor strength: one ``rng.random()`` each, mapped into the ``[domain]`` interval; then
   actuation delay and sensing delay, one ``rng.random()`` each, only for those the file declares: a file without
   them draws nothing for them, so it samples the trials it sampled before they existed;
3. the command option: ``rng.integers(len(options))``, then one ``rng.random()`` for the yaw sign flip (drawn even
   when ``random_sign`` is false; the sign flips when it is below 1/2);
4. with ``[pushes]``: ``start`` from ``first_s``; then, while ``start < duration_s``: the magnitude's ``u``, the
   heading (``2 pi rng.random()``), the offset axis (``rng.integers(2)``: 0 = base x, 1 = base y), the offset
   (``rng.random()`` mapped into [-offset_m, offset_m]), then the next start (``start += `` a draw from
   ``interval_s``);
5. with ``[[fixed_pushes]]``: nothing drawn; they join the trial's pushes, which are then ordered by start time
   (a stable sort: pushes of equal start keep drawn-then-file order).

A file without ``seed``, ``[[commands.changes]]`` and ``[[fixed_pushes]]`` hashes and samples exactly as it did
before they existed (absent keys are not in the parsed content, and nothing is drawn for them).

The band never enters the seed and every band draws the same numbers, so trials with the same (seed, index) in two
bands share terrain, domain, command and push times, headings and offsets; only the band's values differ (the push
magnitude is ``lo + u (hi - lo)`` of the band's ``push_force_n``, and the band's ``vx`` and ``yaw_rate`` overrides).
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wbc.errors import ConfigError, ScenarioError, UnknownNameError
from wbc.robots.registry import ROBOTS
from wbc.scenario.domain import (
    FRICTION_RANGE,
    MAX_DELAY_S,
    MOTOR_STRENGTH_RANGE,
    PAYLOAD_KG_RANGE,
    DomainParams,
)
from wbc.scenario.push import Push
from wbc.scenario.terrain import MAX_OCTAVES, MAX_SAMPLES, TERRAIN_KINDS, TerrainConfig
from wbc.scenario.toml_fields import Range, TomlTable, read_toml
from wbc.scenario.trial import CommandChange, CommandSchedule, Trial
from wbc.types import VelocityCommand

__all__ = ["MAX_VERSION", "Scenario", "ScenarioError", "content_hash", "fallback_note", "load_scenario",
           "resolve_scenario_path"]

_NAME_RE = re.compile(r"^[a-z0-9][a-z0-9_-]*$")
_BAND_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
_MAX_PUSHES = 1000  # per trial: bounds the sampling loop whatever interval_s says
_MAX_CHANGES = 1000  # command changes per file
MAX_VERSION = 1_000_000
"""Largest ``[scenario] version``: a scenario bumped once a day for a thousand years stays below it. A run's
``run.json`` records the version, and its reader (`wbc.arena.identity`) refuses a larger one: the loader refuses the
file first, so that no run writes a ``run.json`` it cannot resume."""
MAX_TERRAIN_SEED = 2**31 - 1
"""Largest ``[terrain] seed``: the range the trials' own terrain seeds are drawn from."""
MAX_PUSH_OFFSET_M = 0.5
"""Farthest application point of a fixed push from the base origin, per axis [m] (``[pushes] offset_m``'s bound)."""

MIN_DURATION_S = 0.1
"""Shortest episode [s]: five 50 Hz control ticks, the fewest from which the metrics mean anything."""

MAX_DURATION_S = 600.0
"""Longest episode [s]: ten minutes, thirty times the shipped scenarios' 20 s."""

MIN_PUSH_S = 0.01
"""Shortest push [s]: half a 50 Hz control tick and five 2 ms physics steps; a shorter one is not resolved."""

MAX_PUSH_FORCE_N = 2000.0
"""Strongest push [N]: about 14 times the robots' weight (~140 N); the shipped bands reach 400 N."""

MAX_PUSH_IMPULSE_NS = 200.0
"""Largest push impulse, force x duration [N s]: it changes a ~14 kg robot's speed by ~14 m/s, far past any fall
(the shipped scenarios deliver at most 40 N s, a test that topples a controller 143 N s). More only flings the robot,
and the simulator with it."""


# --------------------------------------------------------------------------------------------------------------------
# The parsed scenario.


@dataclass(frozen=True, kw_only=True)
class _DomainRanges:
    """``[domain]``: intervals drawn uniformly per trial."""

    friction: tuple[float, float]
    payload_kg: tuple[float, float]  # [kg]
    motor_strength: tuple[float, float]
    actuation_delay_s: tuple[float, float] | None  # [s]; None: absent, nothing drawn
    sensing_delay_s: tuple[float, float] | None  # [s]; None: absent, nothing drawn


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
    yaw_rate: float | None = None  # [rad/s]


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
        hash: sha256 (hex) of the canonical JSON of the parsed file: comments and layout do not change it; every
            key and value as written does, an integer against a float of the same value (``20`` and ``20.0``) and a
            key left out against the same key written with its default included.
        path: the file it was loaded from: as given, or, for a relative path not found from the working directory,
            the file under the source checkout that played (`resolve_scenario_path`), as an absolute path.
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
    _terrain_seed: int | None = field(default=None, repr=False)
    _changes: tuple[CommandChange, ...] = field(default=(), repr=False)
    _fixed_pushes: tuple[Push, ...] = field(default=(), repr=False)

    def _band(self, band: str) -> _Band:
        for spec in self._bands:
            if spec.name == band:
                return spec
        raise UnknownNameError("band", band, self.bands, where=f"scenario {self.name!r}")

    def band_settings(self, band: str) -> dict[str, Any]:
        """What `band` sets, as its ``[[bands]]`` table writes it: the keys it gives besides its name.

        ``push_force_n`` as ``(lo, hi)`` [N], ``vx`` [m/s], ``yaw_rate`` [rad/s]; a key the band leaves out (the drawn
        option's value plays) is absent.

        Raises:
            UnknownNameError: `band` is not a band of this scenario; the message lists the valid ones.
        """
        spec = self._band(band)
        return {key: value for key, value in (("push_force_n", spec.push_force_n), ("vx", spec.vx),
                                              ("yaw_rate", spec.yaw_rate)) if value is not None}

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

        terrain_seed = int(rng.integers(2**31))  # drawn even when the file fixes it: the draws after keep their order
        if self._terrain_seed is not None:
            terrain_seed = self._terrain_seed
        ranges = self._domain
        friction = _uniform(rng, ranges.friction)
        payload_mass = _uniform(rng, ranges.payload_kg)
        motor_strength = _uniform(rng, ranges.motor_strength)
        # an absent delay range must not draw: every trial of a file without one would change
        actuation_delay = 0.0 if ranges.actuation_delay_s is None else _uniform(rng, ranges.actuation_delay_s)
        sensing_delay = 0.0 if ranges.sensing_delay_s is None else _uniform(rng, ranges.sensing_delay_s)
        domain = DomainParams(friction=friction, payload_mass=payload_mass, motor_strength=motor_strength,
                              actuation_delay=actuation_delay, sensing_delay=sensing_delay)

        option = self._options[int(rng.integers(len(self._options)))]
        flip = bool(rng.random() < 0.5)
        yaw_rate = option.yaw_rate if spec.yaw_rate is None else spec.yaw_rate
        yaw_rate = -yaw_rate if option.random_sign and flip and yaw_rate != 0.0 else yaw_rate
        command = CommandSchedule(vx=option.vx if spec.vx is None else spec.vx, vy=option.vy, yaw_rate=yaw_rate,
                                  ramp_s=self._ramp_s, changes=self._changes)

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
        if self._fixed_pushes:
            pushes = sorted(pushes + list(self._fixed_pushes), key=lambda push: push.start)

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


def content_hash(data: dict[str, Any]) -> str:
    """sha256 (hex) of the canonical JSON of parsed TOML content."""
    return hashlib.sha256(json.dumps(data, sort_keys=True, separators=(",", ":")).encode("utf-8")).hexdigest()


SOURCE_ROOT = Path(__file__).resolve().parents[2]
"""The source checkout's root (holding ``scenarios/``) when `wbc` runs from one."""


def resolve_scenario_path(path: str | Path) -> Path:
    """Where a scenario path points: as given when it exists, else (relative) under `SOURCE_ROOT`, else as given.

    So ``scenarios/push.toml``, every default of the toolkit, names the shipped file from any working directory.
    """
    given = Path(path)
    if given.exists() or given.is_absolute():
        return given
    under_root = SOURCE_ROOT / given
    return under_root if under_root.exists() else given


def fallback_note(given: str | Path, scenario: Scenario) -> str | None:
    """What a command says when `given` played a file other than the one it names from the working directory.

    A relative path not found from the working directory is looked up under the source checkout
    (`resolve_scenario_path`): ``scenarios/turn.toml`` given in another directory plays the shipped file. The note
    names the file that plays (`scenario.path`, which results record); None when `given` is that file.
    """
    if scenario.path == str(given):
        return None
    return (f"{given} is not found from the working directory ({Path.cwd()}): it plays {scenario.path}, the file "
            "under the source checkout, and the results record that path")


def load_scenario(path: str | Path) -> Scenario:
    """Load, validate and hash a scenario file.

    Args:
        path: the TOML file (see the module docstring for its schema); a relative path that does not exist from the
            working directory is looked up under the source checkout (`resolve_scenario_path`).

    Returns:
        The scenario.

    Raises:
        ScenarioError: the file is missing, unreadable, not TOML, or breaks the schema; the message names the file,
            the line (where known) and the field, and says how to fix it. Nothing else is raised for a bad file.
    """
    resolved = resolve_scenario_path(path)
    shown = str(path) if resolved == Path(path) else str(resolved)
    data, lines = read_toml(resolved, shown, ScenarioError, missing=(
        f"check the path (a relative path is looked up from the working directory, then from {SOURCE_ROOT})"))
    top = TomlTable(shown, lines, data, "", ("", 0), error=ScenarioError)
    valid_tables = ("scenario", "terrain", "domain", "commands", "pushes", "fixed_pushes", "bands")
    for key in data:
        if key not in valid_tables:
            tables = "[scenario], [terrain], [domain], [commands], [pushes], [[fixed_pushes]], [[bands]]"
            if not isinstance(data[key], dict | list):  # `foo = 1` above the first header, or under a deleted one
                raise ScenarioError(shown, f"a key outside every table; each key belongs to one of {tables} (is "
                                    "a table's header missing above it?)", line=lines.key(("", 0), key), field=key)
            raise ScenarioError(shown, f"unknown table; valid tables: {tables}",
                                line=lines.first_header(key) or lines.key(("", 0), key), field=f"[{key}]")

    head = top.sub_table("scenario", ("name", "version", "description", "notes", "robot", "duration_s"),
                      required=True)
    name = head.string("name")
    if not _NAME_RE.match(name):
        head.fail("name", f"must match {_NAME_RE.pattern} (lower-case letters, digits, '_', '-'), got {name!r}")
    version = head.integer("version", Range(lo=1, hi=MAX_VERSION))
    description = head.string("description")
    if not description.strip():
        head.fail("description", "must not be empty; say in a sentence what the scenario tests")
    notes = head.string("notes", "")
    robot = head.string("robot")
    if robot not in ROBOTS:
        head.fail("robot", f"unknown robot {robot!r}; valid robots: {', '.join(sorted(ROBOTS))}")
    duration_s = head.number("duration_s", Range(lo=MIN_DURATION_S, hi=MAX_DURATION_S))

    ter = top.sub_table("terrain", ("kind", "amplitude_m", "base_wavelength_m", "octaves", "half_extent_m", "seed"),
                     required=True)
    terrain_seed = ter.integer("seed", Range(lo=0, hi=MAX_TERRAIN_SEED)) if "seed" in ter.data else None
    kind = ter.string("kind")
    if kind not in TERRAIN_KINDS:
        ter.fail("kind", f"must be one of {', '.join(map(repr, TERRAIN_KINDS))}, got {kind!r}")
    cell = TerrainConfig.cell  # the heightfield's resolution [m]: not a scenario key
    amplitude = ter.number("amplitude_m", Range(lo=0.0, hi=0.3), 0.05)
    octaves = ter.integer("octaves", Range(lo=1, hi=MAX_OCTAVES), 4)
    half_extent = ter.number("half_extent_m", Range(lo=1.0, hi=(MAX_SAMPLES - 1) * cell / 2, lo_open=True), 10.0)
    wavelength = ter.number("base_wavelength_m", Range(lo=0.0, hi=20.0, lo_open=True), 1.6)
    shortest = cell * 2 ** (octaves - 1)  # the finest octave, wavelength / 2^(octaves - 1), must span one cell
    if wavelength < shortest:
        lattice = math.ceil(2 * half_extent * 2 ** (octaves - 1) / wavelength) + 2
        ter.fail("base_wavelength_m", f"must be in [{shortest:g}, 20] m with octaves = {octaves}, got "
                 f"{wavelength:g}: the finest octave (base_wavelength_m / 2^(octaves - 1)) must span at least one "
                 f"{cell:g} m heightfield cell, and this one's noise lattice would be {lattice} x {lattice} floats "
                 f"({lattice * lattice * 8 / 2**30:.3g} GiB); raise base_wavelength_m or lower octaves")
    terrain = TerrainConfig(kind=kind, amplitude=amplitude, base_cell=wavelength, octaves=octaves,
                            half_extent=half_extent)

    dom = top.sub_table("domain", ("friction", "payload_kg", "motor_strength", "actuation_delay_s",
                                   "sensing_delay_s"), required=False)
    delay = Range(lo=0.0, hi=MAX_DELAY_S)
    domain = _DomainRanges(
        friction=dom.interval("friction", Range(lo=FRICTION_RANGE[0], hi=FRICTION_RANGE[1]), (1.0, 1.0)),
        payload_kg=dom.interval("payload_kg", Range(lo=PAYLOAD_KG_RANGE[0], hi=PAYLOAD_KG_RANGE[1]), (0.0, 0.0)),
        motor_strength=dom.interval("motor_strength", Range(lo=MOTOR_STRENGTH_RANGE[0], hi=MOTOR_STRENGTH_RANGE[1]),
                                    (1.0, 1.0)),
        actuation_delay_s=dom.optional_interval("actuation_delay_s", delay),
        sensing_delay_s=dom.optional_interval("sensing_delay_s", delay),
    )

    com = top.sub_table("commands", ("ramp_s", "options", "changes"), required=True)
    ramp_s = com.number("ramp_s", Range(lo=0.0), 0.0)
    if ramp_s > duration_s:
        com.fail("ramp_s", f"must be <= [scenario] duration_s ({duration_s:g}), got {ramp_s:g}")
    options = []
    for opt in com.table_array("options", "[[commands.options]]"):
        opt.check_keys(("vx", "vy", "yaw_rate", "random_sign"))
        options.append(_CommandOption(
            vx=opt.number("vx", Range(lo=-3.0, hi=3.0), 0.0),
            vy=opt.number("vy", Range(lo=-2.0, hi=2.0), 0.0),
            yaw_rate=opt.number("yaw_rate", Range(lo=-4.0, hi=4.0), 0.0),
            random_sign=opt.boolean("random_sign", False),
        ))
    changes: list[CommandChange] = []
    if "changes" in com.data:
        for chg in com.table_array("changes", "[[commands.changes]]"):
            chg.check_keys(("at_s", "vx", "vy", "yaw_rate"))
            at_s = chg.number("at_s", Range(lo=0.0, hi=duration_s, hi_open=True))
            if changes and at_s <= changes[-1].at_s:
                chg.fail("at_s", f"must be later than the change before it ({changes[-1].at_s:g} s), got {at_s:g}; "
                         "list the changes in time order")
            if len(changes) == _MAX_CHANGES:
                chg.fail(None, f"more than {_MAX_CHANGES} command changes; keep at most {_MAX_CHANGES}")
            changes.append(CommandChange(at_s=at_s, command=VelocityCommand(
                vx=chg.number("vx", Range(lo=-3.0, hi=3.0), 0.0), vy=chg.number("vy", Range(lo=-2.0, hi=2.0), 0.0),
                yaw_rate=chg.number("yaw_rate", Range(lo=-4.0, hi=4.0), 0.0))))

    pushes = None
    psh = top.sub_table("pushes", ("first_s", "interval_s", "duration_s", "offset_m"), required=False)
    if "pushes" in data:
        first_s = psh.interval("first_s", Range(lo=0.0))
        if first_s[1] >= duration_s:
            psh.fail("first_s", f"must end before [scenario] duration_s ({duration_s:g}) so that every trial is "
                     f"pushed, got [{first_s[0]:g}, {first_s[1]:g}]")
        push_duration = psh.number("duration_s", Range(lo=MIN_PUSH_S, hi=1.0))
        interval_s = psh.interval("interval_s", Range(lo=0.0, hi=MAX_DURATION_S, lo_open=True))
        if interval_s[0] < push_duration:
            psh.fail("interval_s", f"lower end must be >= [pushes] duration_s ({push_duration:g}) so that pushes "
                     f"do not overlap, got [{interval_s[0]:g}, {interval_s[1]:g}]")
        if duration_s / interval_s[0] > _MAX_PUSHES:
            psh.fail("interval_s", f"allows more than {_MAX_PUSHES} pushes per trial; raise its lower end")
        pushes = _Pushes(first_s=first_s, interval_s=interval_s, duration_s=push_duration,
                         offset_m=psh.number("offset_m", Range(lo=0.0, hi=0.5)))

    fixed: list[Push] = []
    if "fixed_pushes" in data:
        for fix in top.table_array("fixed_pushes", "[[fixed_pushes]]"):
            fix.check_keys(("start_s", "duration_s", "force_n", "offset_m"))
            if len(fixed) == _MAX_PUSHES:
                fix.fail(None, f"more than {_MAX_PUSHES} fixed pushes; keep at most {_MAX_PUSHES}")
            start = fix.number("start_s", Range(lo=0.0, hi=duration_s, hi_open=True))
            held = fix.number("duration_s", Range(lo=MIN_PUSH_S, hi=1.0))
            force = fix.vector("force_n", 3, Range(lo=-MAX_PUSH_FORCE_N, hi=MAX_PUSH_FORCE_N))
            magnitude = math.sqrt(sum(f * f for f in force))
            if not 0.0 < magnitude <= MAX_PUSH_FORCE_N:
                fix.fail("force_n", f"its magnitude must be in (0, {MAX_PUSH_FORCE_N:g}] N, got {magnitude:g}")
            if magnitude * held > MAX_PUSH_IMPULSE_NS:
                fix.fail("force_n", f"a push of {magnitude:g} N for {held:g} s delivers {magnitude * held:g} N s, more "
                         f"than {MAX_PUSH_IMPULSE_NS:g} N s (it would throw the robot at over 14 m/s); lower the "
                         "force or the duration")
            offset = fix.vector("offset_m", 3, Range(lo=-MAX_PUSH_OFFSET_M, hi=MAX_PUSH_OFFSET_M), (0.0, 0.0, 0.0))
            fixed.append(Push(force_in_world=np.array(force), offset_in_base=np.array(offset), start=start,
                              duration=held))

    bands: list[_Band] = []
    seen: dict[str, str] = {}
    for bnd in top.table_array("bands", "[[bands]]"):
        bnd.check_keys(("name", "push_force_n", "vx", "yaw_rate"))
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
        force = bnd.interval("push_force_n", Range(lo=0.0, hi=MAX_PUSH_FORCE_N)) if pushes is not None else None
        if force is not None and force[1] == 0.0:
            bnd.fail("push_force_n", "[0, 0] makes every push of the band 0 N, a push that pushes nothing (a trial "
                     "of it cannot be written as a scenario: a fixed push needs a force above 0 N); give an upper end "
                     "above 0 N, or, to play no pushes, leave out [pushes] and every band's push_force_n (`wbc run` "
                     "and `wbc compare` play any scenario's trials without their pushes with --no-push)")
        if force is not None and pushes is not None and force[1] * pushes.duration_s > MAX_PUSH_IMPULSE_NS:
            bnd.fail("push_force_n", f"a push of {force[1]:g} N for [pushes] duration_s {pushes.duration_s:g} s "
                     f"delivers {force[1] * pushes.duration_s:g} N s, more than {MAX_PUSH_IMPULSE_NS:g} N s (it "
                     "would throw the robot at over 14 m/s); lower the force or the push duration")
        bands.append(_Band(name=band_name, push_force_n=force, vx=bnd.optional_number("vx", Range(lo=-3.0, hi=3.0)),
                           yaw_rate=bnd.optional_number("yaw_rate", Range(lo=-4.0, hi=4.0))))

    return Scenario(
        name=name, version=version, description=description, notes=notes, robot=robot, duration_s=duration_s,
        hash=content_hash(data), path=shown, bands=tuple(b.name for b in bands), _terrain=terrain, _domain=domain,
        _ramp_s=ramp_s, _options=tuple(options), _pushes=pushes, _bands=tuple(bands), _terrain_seed=terrain_seed,
        _changes=tuple(changes), _fixed_pushes=tuple(fixed),
    )
