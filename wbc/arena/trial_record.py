"""`TrialRecord`: the results of one played trial, the one record that crosses the arena's files.

The simulated-trial runner and the hardware trial build it from the trial and its episode (`TrialRecord.of_trial`),
the executors carry it back from their workers, the results store writes it to and reads it from ``trials.csv``
(`header`, `to_row`, `from_row`, `read_csv`, `scan_csv`), and the statistics and the report read its typed fields.
The fields are defined here once, in the order of the ``trials.csv`` columns. A results directory written by a
version with other columns is refused on resume with a message that says so (`read_csv`).

Every row written carries a last ``checksum`` cell (`checksum_of`): the first 16 hex digits of the SHA-256 of the
other cells. A row read back is trusted only if its checksum matches, its cells parse, and its values are possible
(`TrialRecord` checks them on construction: a time to fall in [0, 1], no infinite number, no negative count);
otherwise it is refused with its file and line (`scan_csv`). The checksum finds a hand edit or a corrupted byte; it is
no signature (anyone can recompute it).
"""

from __future__ import annotations

import csv
import dataclasses
import difflib
import hashlib
import io
import json
import math
import numbers
import re
import typing
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wbc.arena.episode import Episode
from wbc.arena.metrics import compute_metrics
from wbc.errors import RecordError, UnknownNameError
from wbc.hardware.capabilities import LinkStatsLike
from wbc.input_files import read_bytes, short
from wbc.scenario.trial import Trial

__all__ = ["CHECKSUM", "CONTROLLER_ERROR", "DIVERGED", "FALL", "MACHINE_TIMED", "OPERATOR_STOP", "OUTCOMES",
           "SAFETY_TRIP", "SUCCESS", "RefusedRow", "StoredRows", "TrialRecord", "check_counters", "checksum_of",
           "decode_counters", "encode_counters", "episode_outcome", "scan_csv"]

SUCCESS = "success"
"""The episode reached its end."""
FALL = "fall"
"""The trunk or a non-foot link touched the ground (the simulator's fall rule)."""
SAFETY_TRIP = "safety_trip"
"""A robot's safety layer latched its damping on a check of its own (tilt, joint range, link fault ...)."""
CONTROLLER_ERROR = "controller_error"
"""The controller raised in ``reset`` or ``act``, or returned a command the robot refused (``error`` says which)."""
OPERATOR_STOP = "operator_stop"
"""An operator stopped the robot (the console's e-stop key, the remote's e-stop), or interrupted the hardware trial's
command while it played (Ctrl-C, SIGTERM, a hangup; ``error`` then says when)."""
DIVERGED = "diverged"
"""The simulation blew up (a non-finite state, an impossible speed, the trunk far below the ground;
`wbc.arena.divergence`): no controller's result, so the metrics that would be absurd are NaN."""
OUTCOMES = (SUCCESS, FALL, SAFETY_TRIP, CONTROLLER_ERROR, OPERATOR_STOP, DIVERGED)
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
            ``controller_error``, ``operator_stop`` or ``diverged``.
        ttf: time to fall, the fraction of the episode survived, in (0, 1]; after a controller error, a divergence,
            a safety layer's trip, an e-stop or an interruption, none of them a fall, the fraction played before it,
            in [0, 1].
        fall_time_s: when the robot fell (outcome ``fall``), NaN if it did not: a controller error, a divergence, a
            safety trip, an operator's stop and an interruption are not falls (when they came is `ttf` times the
            trial's length, and the episode's last tick) [s].
        vlin_err: mean horizontal velocity tracking error [m/s]; this and the other episode metrics down to
            `arm_travel_rad`, `power_w` and the per-second profiles are NaN (empty) for a diverged trial.
        vang_err: mean yaw-rate tracking error [rad/s].
        max_roll_deg: largest |roll| [deg].
        max_pitch_deg: largest |pitch| [deg].
        energy_j: mechanical work of the motors [J].
        arm_travel_rad: total arm joint travel [rad].
        push_force_n: largest magnitude of the trial's pushes that start within the episode's duration (0 without
            any) [N].
        n_pushes: number of the trial's pushes that start within the episode's duration (played or not, if the robot
            fell first); those after the end of a shortened episode are not counted.
        vx_cmd: commanded forward velocity after the ramp [m/s]: the command the trial starts with, held until the
            scenario's first ``[[commands.changes]]`` if it has any (the changes are the scenario's, not a column).
        vy_cmd: commanded lateral velocity after the ramp [m/s], likewise the starting command.
        yaw_rate_cmd: commanded yaw rate after the ramp [rad/s], likewise the starting command.
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
        act_ms_max: its largest [ms].
        write_deadline_ramps: times during the trial a robot's device damped itself on its write deadline (the
            control loop stalled past it, not past the stale timeout) and the safety layer ramped the robot again from
            its measured pose (its ``write_deadline`` events); not a trip, and the trial goes on (0 without a
            safety layer). Timed by the wall clock, as the deadline misses are.
        wall_s: wall time the trial took to play [s]: in simulation from its robot's and controller's build to its
            last tick; on a robot (``wbc hw run``) its episode alone, from its first tick to its last, without the
            controller's build, the connect, the stand-up and the settle (``hardware.json``'s ``episode_wall_s``).
            This field, `deadline_misses`, `act_ms_p50`, `act_ms_p99`, `act_ms_max` and `write_deadline_ramps`
            depend on the machine (and so, on a real
            robot, do `late_advances` and `worst_lateness_ms`).
        error: for a ``controller_error``, what failed: the controller, band, seed, trial, tick and time, the
            exception's type and message, and the controller's own ``file:line``; for a ``diverged`` trial, what
            diverged, at which tick; for an ``operator_stop`` that interrupted a hardware trial's command, when
            (``interrupted at 1.240 s of the 3 s trial ...``); empty otherwise.
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

    Raises:
        RecordError: a field of the wrong type, an unknown outcome, one that contradicts `success`, or an impossible
            value: `ttf` outside [0, 1], an infinite number, a negative count or index.
    """

    controller: str
    scenario: str
    scenario_hash: str
    band: str
    seed: int
    trial: int
    success: bool
    outcome: str
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
    act_ms_max: float = float("nan")
    write_deadline_ramps: int = 0
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
        if self.outcome not in OUTCOMES:
            raise RecordError(f"TrialRecord.outcome must be one of {', '.join(OUTCOMES)}, got {self.outcome!r}")
        if self.success != (self.outcome == SUCCESS):
            raise RecordError(f"TrialRecord: success {self.success} contradicts outcome {self.outcome!r}; a trial "
                              "succeeds exactly when its outcome is success")
        if not 0.0 <= self.ttf <= 1.0:
            raise RecordError(f"TrialRecord.ttf must be a fraction of the episode in [0, 1], got {self.ttf!r}")
        for name, kind in _KINDS.items():
            value = getattr(self, name)
            if kind is float and math.isinf(value):
                raise RecordError(f"TrialRecord.{name} is {value!r}; a measured value is finite (NaN: not measured)")
            if kind is int and value < 0 and name not in _REPORTED:
                raise RecordError(f"TrialRecord.{name} is {value!r}; a count or an index is >= 0")

    @classmethod
    def of_trial(cls, trial: Trial, *, controller: str, episode: Episode, counters: Mapping[str, int],
                 wall_s: float, debug_truth: bool = False, backend: str = "sim", domain_applied: bool = True,
                 link: LinkStatsLike | None = None, error: str = "", diverged: str = "",
                 interrupted: str = "") -> TrialRecord:
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
            diverged: the simulation diverged (`wbc.arena.divergence.SimulationDiverged`): what diverged and when,
                for the record's `error`; the outcome is then ``diverged``, `episode` the part played up to the tick
                that diverged, and the metrics computed from the robot's motion are NaN, so that no absurd number
                reaches a mean. A controller error found first wins.
            interrupted: the hardware trial's command was interrupted while it played (Ctrl-C, SIGTERM, a hangup;
                `wbc.arena.runner.EpisodeInterrupted`): when, for the record's `error`; the outcome is then
                ``operator_stop``, `episode` the part played up to the interruption (its `ttf` the fraction
                played; `fall_time_s` NaN). Not a success, though the robot did not fall.
        """
        metrics = compute_metrics(episode)
        counts = check_counters(counters)
        # the pushes of the episode's length: a trial cut short (`duration_s` replaced) never plays those after it
        pushes = [p for p in trial.pushes if p.start < episode.duration_s]
        if error or diverged:
            played = float(episode.t[-1]) if len(episode.t) else 0.0
            metrics.update(success=False, ttf=min(1.0, played / episode.duration_s), fall_time_s=math.nan)
            outcome = CONTROLLER_ERROR if error else DIVERGED
            if not error:
                metrics.update({name: math.nan for name in _MOTION_METRICS}, vlin_err_by_s="", vang_err_by_s="")
                error = diverged
        elif interrupted:
            played = float(episode.t[-1]) if len(episode.t) else 0.0
            metrics.update(success=False, ttf=min(1.0, played / episode.duration_s), fall_time_s=math.nan)
            outcome, error = OPERATOR_STOP, interrupted
        else:
            outcome = _outcome(episode)
        return cls(
            controller=controller, scenario=trial.scenario, scenario_hash=trial.scenario_hash, band=trial.band,
            seed=trial.seed, trial=trial.index, **metrics, outcome=outcome, error=error,
            push_force_n=max((float(np.linalg.norm(p.force_in_world)) for p in pushes), default=0.0),
            n_pushes=len(pushes), vx_cmd=trial.command.vx, vy_cmd=trial.command.vy,
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
        return self._cells() == other._cells()

    def __hash__(self) -> int:
        return hash(tuple(self._cells()))

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

    @property
    def checksum(self) -> str:
        """The row's ``checksum`` cell: `checksum_of` its other cells."""
        return checksum_of(self._cells())

    def __getitem__(self, name: str) -> str | int | float | bool:
        """The field `name` (or the ``checksum`` column), for code that names fields in data (a metric key, a column).

        Raises:
            UnknownNameError: no such field (the message lists them).
        """
        if name == CHECKSUM:
            return self.checksum
        if name not in _KINDS:
            raise UnknownNameError("record field", name, FIELDS)
        return getattr(self, name)

    # -- CSV ------------------------------------------------------------------------------------------------------
    @staticmethod
    def header() -> tuple[str, ...]:
        """The ``trials.csv`` column names, in order: the fields, then ``checksum``."""
        return COLUMNS

    def _cells(self) -> list[str]:
        """The fields as ``trials.csv`` cells, in `FIELDS` order (floats as their shortest round-trip text)."""
        return [repr(v) if isinstance(v, float) else str(v) for v in (getattr(self, n) for n in FIELDS)]

    def to_row(self) -> list[str]:
        """The record as ``trials.csv`` cells, in `header` order: its fields, then their checksum."""
        cells = self._cells()
        return [*cells, checksum_of(cells)]

    @classmethod
    def from_row(cls, row: Sequence[str], *, source: str = "row") -> TrialRecord:
        """Parse cells in `header` order, as `to_row` writes them, the checksum verified.

        Args:
            row: the cells.
            source: where the row comes from, for messages (``trials.csv:12``).

        Raises:
            RecordError: the row has the wrong number of cells, a cell does not parse as its field's type, a value is
                impossible (`TrialRecord`), or the checksum does not match the other cells (an edited or corrupted
                row).
        """
        if len(row) != len(COLUMNS):
            raise RecordError(f"{source}: {len(row)} cells, expected {len(COLUMNS)} ({', '.join(COLUMNS)}); write "
                              "rows with TrialRecord.to_row")
        record = cls._parsed(row[:-1], source)
        if checksum_of(row[:-1]) != row[-1]:
            raise RecordError(f"{source}: checksum {row[-1]!r} does not match the row's cells (expected "
                              f"{checksum_of(row[:-1])!r}): the row was edited or corrupted after wbc wrote it")
        return record

    @classmethod
    def _parsed(cls, cells: Sequence[str], source: str) -> TrialRecord:
        """The record of `cells` in `FIELDS` order, its values checked (no checksum)."""
        values = {name: _parse(source, name, _KINDS[name], text) for name, text in zip(FIELDS, cells, strict=True)}
        try:
            return cls(**values)
        except RecordError as exc:
            raise RecordError(f"{source}: {exc}") from None

    @classmethod
    def read_csv(cls, path: str | Path) -> list[TrialRecord]:
        """The records of a ``trials.csv``, in file order, every row trusted or the file refused.

        A last line without its newline (a write cut short by a kill) is dropped: what remains is exactly what was
        stored.

        Raises:
            InputFileError: the file is missing, not a regular file, or too large.
            RecordError: the file's columns are not `header` (a results directory of another version), or a
                complete row is refused (`scan_csv`: the message names the file, line and what is wrong).
        """
        stored = scan_csv(path)
        if stored.refused:
            raise RecordError(stored.refusal(path, "fix or delete those lines"))
        return list(stored.records)


@dataclass(frozen=True)
class RefusedRow:
    """A ``trials.csv`` row that is not trusted.

    Attributes:
        line: its first line in the file (the header is line 1).
        reason: what is wrong with it, in words.
    """

    line: int
    reason: str


@dataclass(frozen=True)
class StoredRows:
    """What `scan_csv` found in a ``trials.csv``.

    Attributes:
        records: the trusted rows' records, in file order.
        lines: the line of each of `records`.
        refused: the rows refused, in file order.
    """

    records: tuple[TrialRecord, ...]
    lines: tuple[int, ...]
    refused: tuple[RefusedRow, ...]

    def refusal(self, path: str | Path, way_out: str) -> str:
        """One message for the refused rows: the first one's file, line and reason, the other lines, `way_out`."""
        first, rest = self.refused[0], self.refused[1:]
        more = (f" (and {len(rest)} more refused row(s), line(s) {', '.join(str(r.line) for r in rest[:10])}"
                f"{' ...' if len(rest) > 10 else ''})") if rest else ""
        return f"{path}:{first.line}: {first.reason}{more}; {way_out}"


_NOT_UTF8 = re.compile("[\udc80-\udcff]")
"""A byte that is not UTF-8, as ``surrogateescape`` decoding leaves it."""


def scan_csv(path: str | Path, *, scenario_hash: str | None = None,
             outside: Callable[[TrialRecord], str | None] | None = None) -> StoredRows:
    """Read a ``trials.csv`` and sort its rows into trusted and refused ones.

    A last line without its newline (a write cut short by a kill) is dropped silently: that is how a killed run
    leaves the file. Every other row is refused, with its line and the reason, when it

    - holds a byte that is not UTF-8;
    - has another number of cells than the header;
    - has a cell that does not parse, or an impossible value (`TrialRecord`);
    - fails its checksum (`checksum_of`);
    - was played on another scenario file than `scenario_hash` (when given);
    - is not a trial of the run (`outside` says why, when given);
    - repeats the run key (controller, band, seed, trial) of another row: every copy is refused, since which one
      to trust cannot be told.

    Args:
        path: the ``trials.csv``.
        scenario_hash: the run's scenario hash; None: not checked.
        outside: why a record is not one of the run's trials (None: it is); None: not checked.

    Raises:
        InputFileError: the file is missing, not a regular file, or too large (`wbc.input_files.read_bytes`).
        RecordError: the header is not `header` (a file of another version), or is not UTF-8.
    """
    data = read_bytes(path, kind="csv")
    if data and not data.endswith(b"\n"):
        data = data[: data.rfind(b"\n") + 1]
    reader = csv.reader(io.StringIO(data.decode("utf-8", errors="surrogateescape"), newline=""))
    rows: list[tuple[int, list[str]]] = []
    start = 1
    for row in reader:
        rows.append((start, row))
        start = reader.line_num + 1
    if not rows:
        return StoredRows(records=(), lines=(), refused=())
    columns = tuple(rows[0][1])
    if columns == PREVIOUS_COLUMNS:  # the version before the last columns: its rows checked on their own, then filled
        rows = [rows[0], *[(line, _upgraded(row)) for line, row in rows[1:]]]
        columns = COLUMNS
    if columns != COLUMNS:
        raise RecordError(f"{path}: columns not this version's ({_column_changes(columns)}); "
                          "the directory was written by another version of wbc: resume it with that version, "
                          "or start afresh with another --out")
    good: list[tuple[int, TrialRecord]] = []
    refused: list[RefusedRow] = []
    for line, row in rows[1:]:
        bad = next((m for c in row for m in [_NOT_UTF8.search(c)] if m), None)
        if bad is not None:
            byte = ord(bad.group()) - 0xDC00
            refused.append(RefusedRow(line, f"byte {byte:#04x} is not UTF-8 (a corrupted row)"))
            continue
        if len(row) != len(columns):
            refused.append(RefusedRow(line, f"{len(row)} cells, expected {len(columns)} (a damaged row)"))
            continue
        try:
            record = TrialRecord.from_row(row, source="row")
        except RecordError as exc:
            refused.append(RefusedRow(line, str(exc).removeprefix("row: ")))
            continue
        if scenario_hash is not None and record.scenario_hash != scenario_hash:
            refused.append(RefusedRow(line, f"played on scenario hash {record.scenario_hash!r}, not this run's "
                                            f"{scenario_hash!r}"))
            continue
        why = outside(record) if outside is not None else None
        if why is not None:
            refused.append(RefusedRow(line, why))
            continue
        good.append((line, record))
    first: dict[tuple[str, str, int, int], int] = {}
    repeated: set[tuple[str, str, int, int]] = set()
    for line, record in good:
        if record.run_key in first:
            repeated.add(record.run_key)
        first.setdefault(record.run_key, line)
    for line, record in good:
        if record.run_key in repeated:
            others = [str(n) for n, r in good if r.run_key == record.run_key and n != line]
            refused.append(RefusedRow(line, f"repeats the trial {_key_text(record)} of line(s) {', '.join(others)}"))
    refused.sort(key=lambda r: r.line)
    kept = [(line, r) for line, r in good if r.run_key not in repeated]
    return StoredRows(records=tuple(r for _, r in kept), lines=tuple(line for line, _ in kept), refused=tuple(refused))


def _upgraded(row: list[str]) -> list[str]:
    """A row of `PREVIOUS_COLUMNS` in this version's `COLUMNS`, its checksum verified first and written anew.

    A row of another length is left as it is, and one whose cells do not match its checksum keeps that checksum, for
    the row checks to refuse them as they refuse any damaged or edited row.
    """
    if len(row) != len(PREVIOUS_COLUMNS):
        return row
    cells = dict(zip(PREVIOUS_COLUMNS[:-1], row[:-1], strict=True))
    new = [cells.get(name, ADDED_COLUMNS.get(name, "")) for name in FIELDS]
    return [*new, checksum_of(new) if checksum_of(row[:-1]) == row[-1] else row[-1]]


def _column_changes(columns: Sequence[str], *, most: int = 8) -> str:
    """How a ``trials.csv`` header differs from this version's `COLUMNS`, each kind listing at most `most` names.

    The kinds are the columns missing, extra, repeated and out of place. Out of place are the columns both have whose
    order differs, fewest first: those outside the longest run of them in the same order (a swap names one of the
    two, one column moved names that one), each with its column and this version's.
    """

    def names(found: Sequence[str]) -> str:
        more = f" and {len(found) - most} more" if len(found) > most else ""
        return ", ".join(short(name, 60) for name in found[:most]) + more

    unique = list(dict.fromkeys(columns))
    missing = [c for c in COLUMNS if c not in unique]
    extra = [c for c in unique if c not in COLUMNS]
    repeated = [c for c in unique if columns.count(c) > 1]
    stored = [c for c in unique if c in COLUMNS]
    wanted = [c for c in COLUMNS if c in unique]
    blocks = difflib.SequenceMatcher(a=stored, b=wanted, autojunk=False).get_matching_blocks()
    in_order = {c for block in blocks for c in stored[block.a: block.a + block.size]}
    moved = [c for c in stored if c not in in_order]
    parts = [f"{kind} {names(found)}" for kind, found in (("missing", missing), ("extra", extra),
                                                            ("repeated", repeated)) if found]
    if moved:
        shown = [f"{short(c, 60)} (column {columns.index(c) + 1}, this version's {COLUMNS.index(c) + 1})"
                 for c in moved[:most]]
        parts.append(f"out of place {', '.join(shown)}" + (f" and {len(moved) - most} more" if len(moved) > most
                                                          else ""))
    return "; ".join(parts)


def checksum_of(cells: Sequence[str]) -> str:
    """The ``checksum`` cell of a row's other cells: the first 16 hex digits of the SHA-256 of their JSON list.

    JSON keeps the cells apart whatever they hold (a comma, a quote, a newline), so two rows that differ in any
    cell, or split the same text into other cells, differ in checksum.
    """
    text = json.dumps(list(cells), ensure_ascii=False)
    return hashlib.sha256(text.encode("utf-8", errors="surrogatepass")).hexdigest()[:16]


def _key_text(record: TrialRecord) -> str:
    return f"(controller {record.controller}, band {record.band}, seed {record.seed}, trial {record.trial})"


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


def episode_outcome(episode: Episode) -> str:
    """How a played episode ended, as far as the episode says: a fall, a trip, an operator's stop or success.

    A controller's error, an interruption or a divergence is the trial record's to say (its ``outcome``).
    """
    return _outcome(episode)


def _outcome(episode: Episode) -> str:
    """How a played episode ended: success, a fall, or the safety layer's trip (an operator's, or its own).

    A trip ends a hardware trial's episode without a fall (`Episode.stopped`); an episode written before that was
    so stored the trip as a fall (``fell`` True), which its trip still tells apart.
    """
    tripped = episode.safety_events.reason[episode.safety_events.to_state == "damped"]
    if len(tripped):
        return OPERATOR_STOP if str(tripped[0]) in _OPERATOR_REASONS else SAFETY_TRIP
    return FALL if episode.fell else SUCCESS


_KINDS: dict[str, type] = {f.name: typing.get_type_hints(TrialRecord)[f.name] for f in dataclasses.fields(TrialRecord)}
FIELDS: tuple[str, ...] = tuple(_KINDS)
"""The record's fields, in the order of their ``trials.csv`` columns."""
CHECKSUM = "checksum"
"""The last ``trials.csv`` column: `checksum_of` the row's other cells."""
COLUMNS: tuple[str, ...] = (*FIELDS, CHECKSUM)
"""The ``trials.csv`` columns."""

ADDED_COLUMNS: dict[str, str] = {"act_ms_max": "nan", "write_deadline_ramps": "0"}
"""The columns this version added to ``trials.csv``, with the cell a row of the version before takes for each: no
act time's maximum was kept (NaN, as for a trial that never acted), and no trial of it counted a write deadline's
damping (a simulated trial has none; a hardware trial is never resumed)."""

PREVIOUS_COLUMNS: tuple[str, ...] = tuple(c for c in COLUMNS if c not in ADDED_COLUMNS)
"""The ``trials.csv`` columns of the version before (`ADDED_COLUMNS`): a resume reads its rows and writes them in
this version's."""

_REPORTED = ("fallbacks", "wbc_failures")
"""Integer fields whose values the controller reports (`Controller.counters`): any whole number, not checked here."""

_MOTION_METRICS = ("vlin_err", "vang_err", "max_roll_deg", "max_pitch_deg", "energy_j", "arm_travel_rad", "power_w")
"""The metrics computed from the robot's motion: NaN for a diverged trial, whose motion is the simulator's blow-up."""

MACHINE_TIMED = ("deadline_misses", "act_ms_p50", "act_ms_p99", "act_ms_max", "write_deadline_ramps", "wall_s",
                 CHECKSUM)
"""The ``trials.csv`` columns that depend on the machine's clock: two plays of the same simulated trial agree on every
other column, to the last bit, and differ in these (the checksum covers the timed fields, so it differs with them)."""


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
    raise RecordError(f"{source}: field {name} holds {text!r}, not a {kind.__name__}")
