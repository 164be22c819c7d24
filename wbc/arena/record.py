"""`TrialRecord`: the results of one played trial, the one record that crosses the arena's files.

The simulated-trial runner and the hardware trial build it from the trial and its episode (`TrialRecord.of_trial`),
the executors carry it back from their workers, the results store writes it to and reads it from ``trials.csv``
(`header`, `to_row`, `from_row`, `read_csv`), and the statistics and the report read its typed fields. The fields
are defined here once, in the order of the ``trials.csv`` columns. A results directory written by a version with
other columns is refused on resume with a message that says so (`read_csv`).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
import numbers
import re
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wbc.arena.episode import Episode
from wbc.arena.metrics import compute_metrics
from wbc.errors import RecordError, UnknownNameError
from wbc.hardware.capabilities import LinkStatsLike
from wbc.scenario.trial import Trial

__all__ = ["CONTROLLER_ERROR", "FALL", "MACHINE_TIMED", "OPERATOR_STOP", "OUTCOMES", "SAFETY_TRIP", "SUCCESS",
           "TrialRecord", "check_counters", "decode_counters", "encode_counters"]

SUCCESS = "success"
"""The episode reached its end."""
FALL = "fall"
"""The trunk or a non-foot link touched the ground (the simulator's fall rule)."""
SAFETY_TRIP = "safety_trip"
"""A robot's safety layer latched its damping on a check of its own (tilt, joint range, link fault ...)."""
CONTROLLER_ERROR = "controller_error"
"""The controller raised in ``reset`` or ``act``, or returned a command the robot refused (``error`` says which)."""
OPERATOR_STOP = "operator_stop"
"""An operator stopped the robot (the console's e-stop key, the remote's e-stop)."""
OUTCOMES = (SUCCESS, FALL, SAFETY_TRIP, CONTROLLER_ERROR, OPERATOR_STOP)
"""How a trial can end, one of these each; every trial is recorded with its outcome."""

_OPERATOR_REASONS = frozenset({"software_estop", "remote_estop"})
"""Safety-layer trip reasons that are an operator's stop (`wbc.hardware.safety.events`)."""

_TRUE = frozenset({"True", "true", "1"})
_FALSE = frozenset({"False", "false", "0"})


@dataclass(frozen=True, kw_only=True)
class TrialRecord:
    """One (controller, trial) result: identity, trial parameters, metrics, controller events, wall time.

    Attributes:
        controller: controller name as given to the arena (a registry name or ``policy:PATH``).
        scenario: scenario name.
        scenario_hash: content hash of the scenario file (hex).
        band: band name.
        seed: seed index.
        trial: trial index within (band, seed).
        success: the episode reached its end without a fall (`wbc.arena.metrics.success`), a trip or an error.
        outcome: how the trial ended, one of `OUTCOMES`: ``success``, ``fall``, ``safety_trip``,
            ``controller_error`` or ``operator_stop``. Built without one (a ``trials.csv`` written before the
            column), it is derived from `success` and `safety_trips` as those versions scored them.
        ttf: time to fall, the fraction of the episode survived, in (0, 1]; after a controller error, the fraction
            played before it, in [0, 1].
        fall_time_s: when the robot fell, NaN if it did not (after a controller error too) [s].
        vlin_err: mean horizontal velocity tracking error [m/s].
        vang_err: mean yaw-rate tracking error [rad/s].
        max_roll_deg: largest |roll| [deg].
        max_pitch_deg: largest |pitch| [deg].
        energy_j: mechanical work of the motors [J].
        arm_travel_rad: total arm joint travel [rad].
        push_force_n: largest push magnitude of the trial (0 without pushes) [N].
        n_pushes: number of pushes in the trial (played or not, if the robot fell first).
        vx_cmd: commanded forward velocity after the ramp [m/s].
        vy_cmd: commanded lateral velocity after the ramp [m/s].
        yaw_rate_cmd: commanded yaw rate after the ramp [rad/s].
        friction: ground friction coefficient of the trial.
        payload_kg: payload mass added to the trunk [kg].
        fallbacks: controller solves that failed and fell back to a safe command.
        wbc_failures: whole-body QP failures of the controller.
        debug_truth: the controller read the simulator's base state (``--debug-truth``), not its estimate.
        backend: what played the trial: ``sim`` (the MuJoCo simulator), or a real robot's backend (``unitree``).
        metrics_source: where the base quantities behind the tracking and tilt metrics come from: ``truth`` (the
            simulator) or ``estimator`` (the robot's IMU and leg kinematics, `wbc.estimation`).
        safety_trips: times the robot's safety layer latched its damping (0 without a safety layer).
        late_advances: control ticks that reached the robot's wall-clock pacing after their deadline (0 in
            simulation, whose robot does not wait for a clock).
        worst_lateness_ms: the latest of those, by how much [ms].
        deadline_misses: control ticks whose ``controller.act`` took longer than the control period.
        act_ms_p50: median ``controller.act`` wall time [ms].
        act_ms_p99: its 99th percentile [ms].
        wall_s: wall time the trial took to play [s]. This field, `deadline_misses`, `act_ms_p50` and `act_ms_p99`
            depend on the machine (and so, on a real robot, do `late_advances` and `worst_lateness_ms`).
        error: for a ``controller_error``, what failed: the controller, band, seed, trial, tick and time, the
            exception's type and message, and the controller's own ``file:line``; empty otherwise.
        ticks: control ticks played.
        clamped_ticks: ticks whose command lay outside the motors' limits (position range, speed, gains, torque)
            and was clamped by the robot before it was sent.
        clamped_rows: which parts of the command were clamped, as ``row=ticks`` pairs joined by ``;`` (rows q, dq,
            kp, kd, tau; a row never clamped left out): ``q=53`` is a position target beyond the joint's range on 53
            ticks.
        power_w: mean mechanical power over the time played [W] (`energy_j` per second).
        vlin_err_by_s: `vlin_err` second by second: the mean over each whole second played, space-separated
            (`wbc.arena.windows` averages it over a window every compared controller survived).
        vang_err_by_s: the same for `vang_err`.
        counters: every event count the controller reported at the end of the trial (`Controller.counters`), as
            ``name=value`` pairs separated by ``;``, names sorted (`encode_counters`, `decode_counters`);
            `fallbacks` and `wbc_failures` are two of them, kept in their own columns as well.

    A ``trials.csv`` written before a column with a default existed reads with that default (`read_csv`): 0 ticks
    and clamped ticks, NaN power and empty profiles and counters (not measured then).
    """

    controller: str
    scenario: str
    scenario_hash: str
    band: str
    seed: int
    trial: int
    success: bool
    outcome: str = ""
    ttf: float
    fall_time_s: float
    vlin_err: float
    vang_err: float
    max_roll_deg: float
    max_pitch_deg: float
    energy_j: float
    arm_travel_rad: float
    push_force_n: float
    n_pushes: int
    vx_cmd: float
    vy_cmd: float
    yaw_rate_cmd: float
    friction: float
    payload_kg: float
    fallbacks: int
    wbc_failures: int
    debug_truth: bool
    backend: str = "sim"
    metrics_source: str = "truth"
    safety_trips: int = 0
    late_advances: int = 0
    worst_lateness_ms: float = 0.0
    deadline_misses: int = 0
    act_ms_p50: float = float("nan")
    act_ms_p99: float = float("nan")
    wall_s: float
    error: str = ""
    ticks: int = 0
    clamped_ticks: int = 0
    clamped_rows: str = ""
    power_w: float = float("nan")
    vlin_err_by_s: str = ""
    vang_err_by_s: str = ""
    counters: str = ""

    def __post_init__(self) -> None:
        # values arrive as numpy scalars from metrics and sampling; storing plain Python values keeps the CSV text
        # (and equality with a record read back from it) independent of where a value came from
        for name, kind in _KINDS.items():
            object.__setattr__(self, name, _coerce(name, kind, getattr(self, name)))
        if not self.outcome:
            derived = SUCCESS if self.success else SAFETY_TRIP if self.safety_trips else FALL
            object.__setattr__(self, "outcome", derived)
        if self.outcome not in OUTCOMES:
            raise RecordError(f"TrialRecord.outcome must be one of {', '.join(OUTCOMES)}, got {self.outcome!r}")
        if self.success != (self.outcome == SUCCESS):
            raise RecordError(f"TrialRecord: success {self.success} contradicts outcome {self.outcome!r}; a trial "
                              "succeeds exactly when its outcome is success")

    @classmethod
    def of_trial(cls, trial: Trial, *, controller: str, episode: Episode, counters: Mapping[str, int],
                 wall_s: float, debug_truth: bool = False, backend: str = "sim", domain_applied: bool = True,
                 link: LinkStatsLike | None = None, error: str = "") -> TrialRecord:
        """The record of `trial` played by `controller`.

        Args:
            trial: the trial played (its pushes: those scheduled on the robot; a robot that cannot apply them plays
                the trial without, and the record says none).
            controller: the controller's name.
            episode: the episode log, from which the metrics are computed (`wbc.arena.metrics.compute_metrics`);
                its `Episode.base_source` is the record's `metrics_source`.
            counters: the controller's event counts (`Controller.counters`), every one kept (`check_counters`);
                absent `fallbacks` and `wbc_failures` are 0.
            wall_s: wall time of the trial [s].
            debug_truth: the controller's ground-truth debug switch was thrown.
            backend: what played it (``sim``, ``unitree`` ...).
            domain_applied: the trial's friction and payload were applied (simulation); False on a real robot,
                whose friction and payload nobody set: the record holds NaN for both.
            link: the robot link's counters after the episode (`wbc.hardware.capabilities.HasLinkStats`), for the
                pacing columns; None for a robot that does not pace on a wall clock.
            error: the controller failed (`wbc.arena.controller_failure.ControllerFailure`): what it did, for the
                record's `error`; the outcome is then ``controller_error`` and `episode` the part played before it.
        """
        metrics = compute_metrics(episode)
        counts = check_counters(counters)
        if error:
            played = float(episode.t[-1]) if len(episode.t) else 0.0
            metrics.update(success=False, ttf=min(1.0, played / episode.duration_s), fall_time_s=math.nan)
            outcome = CONTROLLER_ERROR
        else:
            outcome = _outcome(episode)
        return cls(
            controller=controller, scenario=trial.scenario, scenario_hash=trial.scenario_hash, band=trial.band,
            seed=trial.seed, trial=trial.index, **metrics, outcome=outcome, error=error,
            push_force_n=trial.push_force_n,
            n_pushes=len(trial.pushes), vx_cmd=trial.command.vx, vy_cmd=trial.command.vy,
            yaw_rate_cmd=trial.command.yaw_rate,
            friction=trial.domain.friction if domain_applied else math.nan,
            payload_kg=trial.domain.payload_mass if domain_applied else math.nan,
            fallbacks=counts.get("fallbacks", 0), wbc_failures=counts.get("wbc_failures", 0),
            counters=encode_counters(counts),
            debug_truth=debug_truth, backend=backend, metrics_source=episode.base_source,
            late_advances=link.late_advances if link is not None else 0,
            worst_lateness_ms=link.worst_lateness * 1e3 if link is not None else 0.0, wall_s=wall_s,
        )

    def __eq__(self, other: object) -> bool:
        """Equal when stored alike: every field's ``trials.csv`` text matches (so NaN equals NaN, bit for bit)."""
        if not isinstance(other, TrialRecord):
            return NotImplemented
        return self.to_row() == other.to_row()

    def __hash__(self) -> int:
        return hash(tuple(self.to_row()))

    # -- access ---------------------------------------------------------------------------------------------------
    @property
    def counter_values(self) -> dict[str, int]:
        """The controller's event counts (`counters` decoded), names sorted."""
        return decode_counters(self.counters)

    @property
    def pair_key(self) -> tuple[str, int, int]:
        """(band, seed, trial): identifies the trial across controllers, for paired statistics."""
        return (self.band, self.seed, self.trial)

    @property
    def run_key(self) -> tuple[str, str, int, int]:
        """(controller, band, seed, trial): identifies the record within a run."""
        return (self.controller, self.band, self.seed, self.trial)

    def __getitem__(self, name: str) -> str | int | float | bool:
        """The field `name`, for code that names fields in data (a metric key, a table column).

        Raises:
            UnknownNameError: no such field (the message lists them).
        """
        if name not in _KINDS:
            raise UnknownNameError("record field", name, FIELDS)
        return getattr(self, name)

    # -- CSV ------------------------------------------------------------------------------------------------------
    @staticmethod
    def header() -> tuple[str, ...]:
        """The ``trials.csv`` column names, in order."""
        return FIELDS

    def to_row(self) -> list[str]:
        """The record as ``trials.csv`` cells, in `header` order (floats as their shortest round-trip text)."""
        return [repr(v) if isinstance(v, float) else str(v) for v in (getattr(self, n) for n in FIELDS)]

    @classmethod
    def from_row(cls, row: Sequence[str], *, source: str = "row") -> TrialRecord:
        """Parse cells in `header` order, as `to_row` writes them.

        Args:
            row: the cells.
            source: where the row comes from, for messages (``trials.csv:12``).

        Raises:
            RecordError: the row has the wrong number of cells, or a cell does not parse as its field's type.
        """
        if len(row) != len(FIELDS):
            raise RecordError(f"{source}: {len(row)} cells, expected {len(FIELDS)} ({', '.join(FIELDS)}); write rows "
                              "with TrialRecord.to_row")
        return cls(**{name: _parse(source, name, _KINDS[name], text) for name, text in zip(FIELDS, row, strict=True)})

    @classmethod
    def read_csv(cls, path: str | Path) -> list[TrialRecord]:
        """The records of a ``trials.csv``, in file order.

        A last line without its newline (a write cut short by a kill) is dropped, and so is any row with the wrong
        number of cells; what remains is exactly what was stored. A file written before some columns existed (those
        with a default: ``backend`` and the columns after it, added with hardware trials) reads with their defaults,
        which are what those versions did (a simulated trial, metrics from truth); a results store reopened on it
        rewrites it with this version's columns.

        Raises:
            RecordError: the file's columns are neither `header` nor an earlier version's (a results directory of
                another version), or a complete row holds a value that does not parse (the message names the file,
                line and field).
        """
        text = Path(path).read_text(encoding="utf-8")
        if text and not text.endswith("\n"):
            text = text[: text.rfind("\n") + 1]
        rows = list(csv.reader(io.StringIO(text)))
        if not rows:
            return []
        columns = tuple(rows[0])
        absent = [name for name in FIELDS if name not in columns]
        if tuple(name for name in FIELDS if name in columns) != columns or any(n not in _DEFAULTS for n in absent):
            raise RecordError(f"{path}: columns {', '.join(rows[0])} are not this version's ({', '.join(FIELDS)}); "
                              "the directory was written by another version of wbc: resume it with that version, "
                              "or start afresh with another --out")
        defaults = [repr(_DEFAULTS[n]) if isinstance(_DEFAULTS[n], float) else str(_DEFAULTS[n]) for n in absent]
        return [cls.from_row(_complete(columns, row, absent, defaults), source=f"{path}:{line}")
                for line, row in enumerate(rows[1:], start=2) if len(row) == len(columns)]


_COUNTER_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.-]*")


def check_counters(counts: object) -> dict[str, int]:
    """A controller's `counters()` checked and made plain: names sorted, counts as Python ints.

    A count may be any integer (NumPy's included) or a float holding a whole number.

    Raises:
        RecordError: not a mapping, a name that is not a word (letters, digits, ``_``, ``.``, ``-``; it must not
            start with a digit), or a count that is not a whole number; the message names the entry.
    """
    if not isinstance(counts, Mapping):
        raise RecordError(f"counters() returned {type(counts).__name__} {counts!r}; return a dict of event name -> "
                          "count (int)")
    out: dict[str, int] = {}
    for name, value in counts.items():
        if not isinstance(name, str) or not _COUNTER_NAME.fullmatch(name):
            raise RecordError(f"counters() holds the name {name!r}; name each count with a word (letters, digits, "
                              "'_', '.', '-'), such as 'fallbacks'")
        if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real) or not (
                math.isfinite(value) and float(value) == int(value)):
            raise RecordError(f"counters() gives {name} = {value!r}; a count is a whole number (int)")
        out[name] = int(value)
    return dict(sorted(out.items()))


def encode_counters(counts: Mapping[str, int]) -> str:
    """Counts as the ``counters`` column stores them: ``name=value`` pairs joined by ``;``, in the given order."""
    return ";".join(f"{name}={value}" for name, value in counts.items())


def decode_counters(text: str) -> dict[str, int]:
    """The counts of a ``counters`` cell (`encode_counters`).

    Raises:
        RecordError: a pair is not ``name=integer``.
    """
    out: dict[str, int] = {}
    for pair in filter(None, text.split(";")):
        name, sep, value = pair.partition("=")
        try:
            if not sep or not _COUNTER_NAME.fullmatch(name):
                raise ValueError
            out[name] = int(value)
        except ValueError:
            raise RecordError(f"counters cell {text!r}: {pair!r} is not name=count; fix or delete that line of "
                              "trials.csv") from None
    return out


def _outcome(episode: Episode) -> str:
    """How a played episode ended: success, a fall, or the safety layer's trip (an operator's, or its own)."""
    if not episode.fell:
        return SUCCESS
    tripped = episode.safety_events.reason[episode.safety_events.to_state == "damped"]
    if len(tripped):
        return OPERATOR_STOP if str(tripped[0]) in _OPERATOR_REASONS else SAFETY_TRIP
    return FALL


_KINDS: dict[str, type] = {f.name: typing.get_type_hints(TrialRecord)[f.name] for f in dataclasses.fields(TrialRecord)}
FIELDS: tuple[str, ...] = tuple(_KINDS)

_DEFAULTS: dict[str, object] = {f.name: f.default for f in dataclasses.fields(TrialRecord)
                                if f.default is not dataclasses.MISSING}


def _complete(columns: tuple[str, ...], row: list[str], absent: list[str], defaults: list[str]) -> list[str]:
    """`row` (cells in `columns` order) as cells in `FIELDS` order, the `absent` columns' cells as `defaults`."""
    if not absent:
        return row
    cells = dict(zip(columns, row, strict=True)) | dict(zip(absent, defaults, strict=True))
    return [cells[name] for name in FIELDS]


MACHINE_TIMED = ("deadline_misses", "act_ms_p50", "act_ms_p99", "wall_s")
"""Fields timed on the machine's clock: two plays of the same simulated trial agree on every other field, to the
last bit, and differ in these."""


def _coerce(name: str, kind: type, value: object) -> object:
    if kind is str and isinstance(value, str):
        return value
    if kind is bool and isinstance(value, bool | np.bool_):
        return bool(value)
    if kind is int and isinstance(value, int | np.integer) and not isinstance(value, bool | np.bool_):
        return int(value)
    if kind is float and isinstance(value, int | float | np.integer | np.floating) and not isinstance(
            value, bool | np.bool_):
        return float(value)
    raise RecordError(f"TrialRecord.{name} must be of type {kind.__name__}, got {value!r} ({type(value).__name__}); "
                      "build records with TrialRecord.of_trial, or read them with TrialRecord.from_row")


def _parse(source: str, name: str, kind: type, text: str) -> object:
    if kind is str:
        return text
    if kind is bool:
        if text in _TRUE:
            return True
        if text in _FALSE:
            return False
    else:
        try:
            return kind(text)
        except ValueError:
            pass
    raise RecordError(f"{source}: field {name} holds {text!r}, not a {kind.__name__}; fix or delete that line "
                      "(the trial is played again on --resume)")
