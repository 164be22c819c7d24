"""`RunIdentity`: what a results directory's run is, the ``config`` of its ``run.json``, written and read back here.

A run is one of two kinds, each its own frozen type behind the one base:

- `SimulatedRunIdentity` (``wbc run`` / ``wbc compare``): controllers, scenario, bands, seeds and trials per band and
  seed, the no-push and ground-truth switches, and the options that change what is played (the sequential stop, the
  controllers' configuration files, the consecutive-error limit), each written only when set (absent: its default),
  so that a run that names an option at its default and one that leaves it out are the same run;
- `HardwareRunIdentity` (``wbc hw run``): one trial of a scenario, played on the robot, arm mode and backend it names.

`as_json` gives the ``config`` object exactly as it is written (keys in their order, unset options absent);
`RunIdentity.from_json` and `RunIdentity.load` read a ``run.json`` as it is written (a hardware run names its
``trial``, a simulated one its ``trials``), and refuse a malformed one with a `RecordError` that names the file and
the field. The results store writes the identity and compares it with the stored one on resume
(`wbc.arena.results.ResultsStore`), files by their content's hash and not by the paths they were given by
(`compared`); the viewer reads it back to find a stored trial (`wbc.viz.replay`).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wbc.arena.error_guard import DEFAULT_MAX_CONSECUTIVE_ERRORS
from wbc.errors import InputFileError, RecordError
from wbc.input_files import read_json, short
from wbc.scenario.scenario import MAX_DURATION_S, MAX_VERSION

__all__ = ["MAX_CONSECUTIVE_ERRORS", "MAX_RUN_TRIALS", "MAX_SEED", "MAX_TRIALS", "MAX_TRIAL_TIME_LIMIT_S",
           "MIN_TRIAL_TIME_LIMIT_S", "ControllerFile", "HardwareRunIdentity", "RunIdentity", "ScenarioRef",
           "SequentialStop", "SimulatedRunIdentity", "compared", "moved_files", "publication_change"]

MAX_TRIALS = 100_000
"""Most trials per band and seed a run plays (``wbc run --trials``)."""

MAX_RUN_TRIALS = 1_000_000
"""Most trials a run plays in all (controllers x bands x seeds x trials): a million trials of a second each keep two
cores busy for eleven days; a larger study is several runs."""

MAX_SEED = 2**32 - 1
"""Largest seed (the scenario's `numpy.random.SeedSequence` takes any, the command line up to this)."""

MIN_TRIAL_TIME_LIMIT_S = 1.0
"""The shortest trial time limit [s]: below it, building the robot and the controller alone could overrun."""

MAX_TRIAL_TIME_LIMIT_S = 7 * 24 * 3600.0
"""The longest trial time limit (``--trial-time-limit``) [s]: a week. An execution setting, not part of a run's
identity: a run resumed with another limit plays on."""

MAX_CONSECUTIVE_ERRORS = MAX_RUN_TRIALS
"""Largest consecutive-error limit (``max_consecutive_errors``): a run's trials in all, a limit no run reaches."""

_FIX = ("run.json is written by `wbc run`, `wbc compare` and `wbc hw run`: restore the file as written, or play the "
        "run again with another --out")


@dataclass(frozen=True, kw_only=True)
class ScenarioRef:
    """The scenario a run played, as the run found it.

    Attributes:
        path: the scenario file, as given on the command line (that of the call that last played the run; not
            compared on ``--resume``, where `hash` names the file).
        name: the scenario's name.
        hash: the content hash of the file the run played.
        published: whether the file matched the lock of published scenarios (as the call that last played the run
            found it; not compared on ``--resume``: publishing a scenario does not change its content).
        version: the scenario's version; None in a hardware run's identity, which does not record it.
        published_at_start: whether the file was published when the run began, where that differs from
            `published` (the run was resumed after its scenario was published, or on a copy away from its lock);
            None (not written) where it does not.
    """

    path: str
    name: str
    hash: str
    published: bool
    version: int | None = None
    published_at_start: bool | None = None

    def as_json(self) -> dict[str, Any]:
        """The ``scenario`` object: path, name, version (when recorded), hash, published (and published_at_start)."""
        out: dict[str, Any] = {"path": self.path, "name": self.name}
        if self.version is not None:
            out["version"] = self.version
        out.update(hash=self.hash, published=self.published)
        if self.published_at_start is not None:
            out["published_at_start"] = self.published_at_start
        return out

    @classmethod
    def from_json(cls, data: object, *, source: str, with_version: bool) -> ScenarioRef:
        """Read a ``scenario`` object; `with_version`: a simulated run's, which records the version.

        Raises:
            RecordError: a field missing, unknown or of the wrong type; the message names `source` and the field.
        """
        keys = ("path", "name", "version", "hash", "published") if with_version else ("path", "name", "hash",
                                                                                       "published")
        table = _Table(data, source, "scenario", required=keys, optional=("published_at_start",))
        return cls(path=table.text("path"), name=table.text("name"), hash=table.text("hash"),
                   published=table.flag("published"),
                   version=table.whole("version", lo=1, hi=MAX_VERSION) if with_version else None,
                   published_at_start=table.flag("published_at_start") if "published_at_start" in table else None)


@dataclass(frozen=True, kw_only=True)
class SequentialStop:
    """A run played round by round until the sequential test settled every tested pair (``--until-significant``).

    Attributes:
        alpha: the test's family-wise significance level, in (0, 1).
        pairs: the (A, B) controller pairs it tests, in order.
    """

    alpha: float
    pairs: tuple[tuple[str, str], ...]

    def as_json(self) -> dict[str, Any]:
        """The ``until_significant`` object: alpha, and the pairs as two-element lists."""
        return {"alpha": self.alpha, "pairs": [list(p) for p in self.pairs]}

    @classmethod
    def from_json(cls, data: object, *, source: str) -> SequentialStop:
        """Read an ``until_significant`` object.

        Raises:
            RecordError: a field missing, unknown or of the wrong type; the message names `source` and the field.
        """
        table = _Table(data, source, "until_significant", required=("alpha", "pairs"))
        alpha = table.number("alpha")
        if not 0.0 < alpha < 1.0:
            raise _error(source, "until_significant.alpha", f"{alpha!r} is not in (0, 1)")
        pairs = table.read("pairs", lambda v: isinstance(v, list) and all(
            isinstance(p, list) and len(p) == 2 and all(isinstance(n, str) for n in p) for p in v),
            "a list of [controller A, controller B] pairs")
        return cls(alpha=alpha, pairs=tuple((a, b) for a, b in pairs))


@dataclass(frozen=True, kw_only=True)
class ControllerFile:
    """A configuration file a controller was built with (``--controller-config``, ``--io``).

    Attributes:
        controller: the controller's name, as played.
        path: the file, as given.
        sha256: its content hash (hex).
    """

    controller: str
    path: str
    sha256: str


@dataclass(frozen=True, kw_only=True)
class RunIdentity(ABC):
    """What a run is: the fields both kinds share, the JSON form and the loader of either kind.

    Attributes:
        controllers: controller names, in report order.
        scenario: the scenario played.
        bands: the bands played, in order.
        seeds: the seeds played, in order.
    """

    controllers: tuple[str, ...]
    scenario: ScenarioRef
    bands: tuple[str, ...]
    seeds: tuple[int, ...]

    @property
    @abstractmethod
    def trials_played(self) -> tuple[int, ...]:
        """The trial indices played in each (band, seed)."""

    @property
    @abstractmethod
    def played_on(self) -> str | None:
        """The robot the trials were played on when it is not the scenario's own (a hardware run's), else None."""

    @property
    def scenario_path(self) -> Path:
        """The scenario file, as the run was given it (relative to the directory the run started in)."""
        return Path(self.scenario.path)

    @property
    def scenario_hash(self) -> str:
        """The content hash of the scenario file the run played."""
        return self.scenario.hash

    @abstractmethod
    def as_json(self) -> dict[str, Any]:
        """The ``config`` object of ``run.json``, exactly as written: keys in order, unset options absent."""

    @classmethod
    def from_json(cls, data: object, *, source: str | Path) -> RunIdentity:
        """Read a ``config`` object as `as_json` writes it, of either kind.

        A hardware run's names its one ``trial``, a simulated run's its ``trials`` per band and seed; the options
        absent take their defaults. Called on a subclass, only that kind is accepted.

        Args:
            data: the parsed ``config`` object.
            source: where it was read from, for messages (the ``run.json`` path).

        Returns:
            The identity, of the kind the object describes.

        Raises:
            RecordError: not an object, a field missing, unknown or of the wrong type, or a run of another kind than
                asked; the message names `source` and the field.
        """
        source = str(source)
        if isinstance(data, dict) and "trial" in data:
            identity: RunIdentity = HardwareRunIdentity._read(data, source)
        elif isinstance(data, dict) and "trials" not in data:
            raise _error(source, "trials", "missing: a simulated run names its trials per band and seed (trials), a "
                                           "hardware run its one trial (trial)")
        else:
            identity = SimulatedRunIdentity._read(data, source)
        if not isinstance(identity, cls):
            raise RecordError(f"{source}: holds a {identity.kind} run's identity where a {_KIND_OF[cls]} run's is "
                              "needed; give the results directory of a run of that kind")
        return identity

    @classmethod
    def load(cls, run_json: str | Path) -> RunIdentity:
        """Read the identity of a results directory's run from its ``run.json``.

        The file is read through `wbc.input_files.read_json`: a regular file of at most 64 MiB, UTF-8, JSON nested at
        most 32 levels deep.

        Raises:
            RecordError: the file is missing, not a regular file, too large, not UTF-8 or not JSON, or its ``config``
                is malformed (a field missing, unknown, of the wrong type, out of range, or NaN or infinite); the
                message names the file and the field.
        """
        path = Path(run_json)
        if not path.exists():
            raise RecordError(f"{path}: missing; give the directory a `wbc run` or `wbc hw run` wrote")
        try:
            run = read_json(path)
        except InputFileError as exc:  # names the file, and the line where there is one
            raise RecordError(f"{exc}; {_FIX}") from None
        except ValueError as exc:  # an integer of more than 4300 digits: Python refuses to convert it
            raise RecordError(f"{path}: not valid JSON ({exc}); {_FIX}") from None
        if not isinstance(run, dict) or "config" not in run:
            raise _error(str(path), "config", "missing: the file holds no run identity")
        return cls.from_json(run["config"], source=path)

    @property
    @abstractmethod
    def kind(self) -> str:
        """``simulated`` or ``hardware``, for messages."""

    def _common(self) -> dict[str, Any]:
        return {"controllers": list(self.controllers), "scenario": self.scenario.as_json(),
                "bands": list(self.bands), "seeds": list(self.seeds)}


@dataclass(frozen=True, kw_only=True)
class SimulatedRunIdentity(RunIdentity):
    """A simulated run (``wbc run``, ``wbc compare``): every controller on the same seeded trials.

    Attributes:
        trials: trials per (band, seed); with `until_significant` the most played.
        no_push: the trials were played without their pushes.
        debug_truth: the controllers' ground-truth debug switch was thrown.
        until_significant: the sequential stop, or None for a fixed-budget run (then absent from the JSON).
        controller_files: the configuration files the controllers were built with, in the controllers' order
            (absent from the JSON when there are none).
        max_consecutive_errors: failures in a row that stop a controller, 0 for never (absent from the JSON when it
            is the default, `DEFAULT_MAX_CONSECUTIVE_ERRORS`).
    """

    trials: int
    no_push: bool
    debug_truth: bool
    until_significant: SequentialStop | None = None
    controller_files: tuple[ControllerFile, ...] = ()
    max_consecutive_errors: int = DEFAULT_MAX_CONSECUTIVE_ERRORS

    _REQUIRED = ("controllers", "scenario", "bands", "seeds", "trials", "no_push", "debug_truth")
    _OPTIONAL = ("until_significant", "controller_files", "max_consecutive_errors")

    @property
    def kind(self) -> str:
        """``simulated``."""
        return "simulated"

    @property
    def trials_played(self) -> tuple[int, ...]:
        """Trials 0 .. `trials` - 1 of each (band, seed) (a sequential run may have stopped before the last)."""
        return tuple(range(self.trials))

    @property
    def played_on(self) -> None:
        """None: a simulated run plays the scenario's own robot."""
        return None

    def as_json(self) -> dict[str, Any]:
        """The ``config`` object, as `wbc run` writes it: the options that are unset are absent."""
        out = {**self._common(), "trials": self.trials, "no_push": self.no_push, "debug_truth": self.debug_truth}
        if self.until_significant is not None:
            out["until_significant"] = self.until_significant.as_json()
        if self.controller_files:
            out["controller_files"] = {f.controller: {"path": f.path, "sha256": f.sha256}
                                       for f in self.controller_files}
        if self.max_consecutive_errors != DEFAULT_MAX_CONSECUTIVE_ERRORS:
            out["max_consecutive_errors"] = self.max_consecutive_errors
        return out

    @classmethod
    def _read(cls, data: object, source: str) -> SimulatedRunIdentity:
        table = _Table(data, source, "", required=cls._REQUIRED, optional=cls._OPTIONAL)
        until = table.get("until_significant")
        files = table.get("controller_files")
        if files is not None and not isinstance(files, dict):
            raise _error(source, "controller_files", f"expected an object of controller -> {{path, sha256}}, got "
                                                     f"{short(files)}")
        limit = (table.whole("max_consecutive_errors", lo=0, hi=MAX_CONSECUTIVE_ERRORS)
                 if "max_consecutive_errors" in table else DEFAULT_MAX_CONSECUTIVE_ERRORS)
        return cls(**_common_fields(table, source, with_version=True),
                   trials=table.whole("trials", lo=1, hi=MAX_TRIALS),
                   no_push=table.flag("no_push"), debug_truth=table.flag("debug_truth"),
                   until_significant=None if until is None else SequentialStop.from_json(until, source=source),
                   controller_files=tuple(_controller_file(name, entry, source)
                                          for name, entry in (files or {}).items()),
                   max_consecutive_errors=limit)


@dataclass(frozen=True, kw_only=True)
class HardwareRunIdentity(RunIdentity):
    """A hardware trial (``wbc hw run``): one trial of a scenario, played on a robot (or its simulated twin).

    Attributes:
        trial: the trial's index in its (band, seed).
        duration_s: how long it was played [s] (``--seconds``, at most the scenario's duration).
        robot: the robot played on (its description's name).
        arm_mode: the robot's arm mode.
        backend: the robot's backend (``unitree``, ``sim`` ...).
        target: where the robot was reached (an address, or the simulator's description).
        command: the command that wrote the run (``hw run``).
    """

    trial: int
    duration_s: float
    robot: str
    arm_mode: str
    backend: str
    target: str
    command: str = "hw run"

    _REQUIRED = ("command", "controllers", "scenario", "bands", "seeds", "trial", "duration_s", "robot", "arm_mode",
                 "backend", "target")

    @property
    def kind(self) -> str:
        """``hardware``."""
        return "hardware"

    @property
    def trials_played(self) -> tuple[int, ...]:
        """The one trial played."""
        return (self.trial,)

    @property
    def played_on(self) -> str:
        """The robot the trial was played on."""
        return self.robot

    def as_json(self) -> dict[str, Any]:
        """The ``config`` object, as `wbc hw run` writes it."""
        return {"command": self.command, **self._common(), "trial": self.trial, "duration_s": self.duration_s,
                "robot": self.robot, "arm_mode": self.arm_mode, "backend": self.backend, "target": self.target}

    @classmethod
    def _read(cls, data: object, source: str) -> HardwareRunIdentity:
        table = _Table(data, source, "", required=cls._REQUIRED)
        duration = table.number("duration_s")
        if not 0.0 < duration <= MAX_DURATION_S:
            raise _error(source, "duration_s", f"{duration!r} is not a duration in (0, {MAX_DURATION_S:g}] s (a "
                                               "scenario's longest)")
        return cls(**_common_fields(table, source, with_version=False), trial=table.whole("trial", lo=0,
                                                                                           hi=MAX_TRIALS - 1),
                   duration_s=duration, robot=table.text("robot"), arm_mode=table.text("arm_mode"),
                   backend=table.text("backend"), target=table.text("target"), command=table.text("command"))


_KIND_OF = {RunIdentity: "simulated or hardware", SimulatedRunIdentity: "simulated", HardwareRunIdentity: "hardware"}


def _file_paths(config: Mapping[str, Any]) -> dict[str, object]:
    """The paths a ``config`` object gives its files by: the scenario's and each controller file's, by what each is."""
    paths: dict[str, object] = {}
    scenario = config.get("scenario")
    if isinstance(scenario, Mapping) and "path" in scenario:
        paths["the scenario"] = scenario["path"]
    files = config.get("controller_files")
    if isinstance(files, Mapping):
        paths.update((f"{name}'s configuration file", entry["path"]) for name, entry in files.items()
                     if isinstance(entry, Mapping) and "path" in entry)
    return paths


_NOT_COMPARED = ("path", "published", "published_at_start")
"""The ``scenario`` fields ``--resume`` does not compare: where the file was given, and whether a lock listed it."""


def compared(config: Mapping[str, Any]) -> dict[str, Any]:
    """A ``config`` object as ``--resume`` compares it with the stored one: without the paths its files were given by.

    A file is the content its hash names (the scenario's ``hash``, of its parsed content; a controller file's
    ``sha256``); the path it was given by, relative to the directory the command ran in, is provenance, written but not
    compared. So a run resumes from another directory, with the path spelled otherwise, or with a copy of the file.
    Nor is the scenario's ``published`` compared: a lock that lists the file's hash since the run began (or a copy
    away from the lock) leaves its content, and so every trial, as it was (`publication_change`).
    """
    out = dict(config)
    if isinstance(out.get("scenario"), Mapping):
        out["scenario"] = {k: v for k, v in out["scenario"].items() if k not in _NOT_COMPARED}
    if isinstance(out.get("controller_files"), Mapping):
        out["controller_files"] = {name: {k: v for k, v in entry.items() if k != "path"} if isinstance(entry, Mapping)
                                   else entry for name, entry in out["controller_files"].items()}
    return out


def publication_change(stored: Mapping[str, Any], given: Mapping[str, Any]) -> bool | None:
    """Whether the scenario was published when a run began, where a resume finds it otherwise; else None.

    Args:
        stored: the stored ``config`` object.
        given: the resuming call's ``config`` object (its ``published`` as found now).

    Returns:
        The stored run's ``published_at_start`` (its ``published`` where it has none) when that differs from
        `given`'s ``published``, the value the resumed run records as its ``published_at_start``; None when the two
        agree (or either has no scenario).
    """
    before, now = stored.get("scenario"), given.get("scenario")
    if not isinstance(before, Mapping) or not isinstance(now, Mapping):
        return None
    at_start = before.get("published_at_start", before.get("published"))
    return at_start if isinstance(at_start, bool) and at_start != now.get("published") else None


def moved_files(stored: Mapping[str, Any], given: Mapping[str, Any]) -> list[tuple[str, object, object]]:
    """The files two ``config`` objects give by different paths: (what the file is, stored path, given path)."""
    before, now = _file_paths(stored), _file_paths(given)
    return [(what, before[what], path) for what, path in now.items() if what in before and before[what] != path]


def _error(source: str, field: str, reason: str) -> RecordError:
    return RecordError(f"{source}: field {field}: {reason}; {_FIX}")


class _Table:
    """One JSON object of a ``run.json``, its fields read with their types checked.

    Every failure names the file and the field (``scenario.hash``); a missing or unknown field is refused on
    construction.
    """

    def __init__(self, data: object, source: str, prefix: str, *, required: tuple[str, ...],
                 optional: tuple[str, ...] = ()) -> None:
        self.source, self.prefix = source, prefix
        if not isinstance(data, dict):
            raise _error(source, prefix or "config", f"expected an object, got {short(data)}")
        for key in required:
            if key not in data:
                raise _error(source, self._name(key), "missing")
        unknown = [key for key in data if key not in required and key not in optional]
        if unknown:
            raise _error(source, self._name(unknown[0]), f"not a field of this version's run identity (fields: "
                                                         f"{', '.join(required + optional)}); a newer version of wbc "
                                                         "may have written it: read it with that version")
        self.data: dict[str, object] = data

    def __contains__(self, key: str) -> bool:
        return key in self.data

    def _name(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def get(self, key: str) -> object:
        """The raw value of an optional field, or None when absent."""
        return self.data.get(key)

    def read(self, key: str, accept: Callable[[object], bool], expected: str) -> Any:
        """The value of `key`, refused unless `accept` holds; `expected` says what it should be."""
        value = self.data[key]
        if not accept(value):
            raise _error(self.source, self._name(key), f"expected {expected}, got {short(value)}")
        return value

    def text(self, key: str) -> str:
        return self.read(key, lambda v: isinstance(v, str), "a string")

    def flag(self, key: str) -> bool:
        return self.read(key, lambda v: isinstance(v, bool), "true or false")

    def whole(self, key: str, *, lo: int, hi: int) -> int:
        return self.read(key, lambda v: _is_int(v) and lo <= v <= hi, f"a whole number in [{lo}, {hi}]")

    def number(self, key: str) -> float:
        return self.read(key, lambda v: (_is_int(v) or isinstance(v, float)) and math.isfinite(v), "a finite number")

    def texts(self, key: str) -> tuple[str, ...]:
        return tuple(self.read(key, lambda v: isinstance(v, list) and bool(v) and all(isinstance(x, str) for x in v),
                               "a non-empty list of strings"))

    def wholes(self, key: str, *, lo: int, hi: int) -> tuple[int, ...]:
        return tuple(self.read(key, lambda v: isinstance(v, list) and bool(v) and all(
            _is_int(x) and lo <= x <= hi for x in v), f"a non-empty list of whole numbers in [{lo}, {hi}]"))


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _common_fields(table: _Table, source: str, *, with_version: bool) -> dict[str, Any]:
    return {"controllers": table.texts("controllers"),
            "scenario": ScenarioRef.from_json(table.get("scenario"), source=source, with_version=with_version),
            "bands": table.texts("bands"), "seeds": table.wholes("seeds", lo=0, hi=MAX_SEED)}


def _controller_file(name: str, entry: object, source: str) -> ControllerFile:
    table = _Table(entry, source, f"controller_files.{name}", required=("path", "sha256"))
    return ControllerFile(controller=name, path=table.text("path"), sha256=table.text("sha256"))
