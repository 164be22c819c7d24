"""Where each contender fails: success by command, each push's outcome by heading and offset, the push-recovery curve.

A success rate says how often a controller falls, not where. This module splits the records of a run:

- by command: success of the trials standing still and of those walking (or, on the turn task, per yaw rate),
  labelled from the record's commanded velocity at the trial's start and the number of its command changes
  (`command_label`: ``vx 0.5 yaw 1, then 1 change``);
- by push: every push a trial met becomes a `PushOutcome`. The push is *survived* when the robot did not fall before
  the next push began (or before the episode ended, for the last one); a fall is charged to the last push that began
  before it, and a fall before any push to none. Survival is then split by the push's heading sector (`push_sector`:
  a push steeper than 45 degrees out of the horizontal plane is ``vertical``, whatever its heading) and by the axis
  of its application point's offset (``x=y`` when the two are equal), and binned by impulse into the push-recovery
  curve (survival against |F| T, with Wilson 95 % intervals), the dose-response curve the bands' two points sample;
- falls: how many came before any push, and the median time from the charged push to the fall (a fall a second or
  more after a push is not a push knocking the robot over, but a gait losing its footing).

A record does not hold its pushes: they are a pure function of the scenario and the trial's (band, seed, index)
(`wbc.scenario.Scenario.trial`), re-drawn here from the scenario the records were played on; the record's push count,
largest force and scenario hash are checked against the trial re-drawn. The push heading is in the world frame: the
robot starts facing +x and the push scenario commands no turning, so "forward" is a push along the robot's initial
heading (up to the yaw the trunk drifts by in a trial).

Counts are per trial or per push and intervals are Wilson intervals over them (`wbc.arena.stats.wilson_interval`);
pushes of one trial are not independent of each other (the same controller on the same ground), so the per-push
intervals are somewhat too narrow.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from wbc.arena.stats import wilson_interval
from wbc.arena.trial_record import CONTROLLER_ERROR, OPERATOR_STOP, SAFETY_TRIP, TrialRecord
from wbc.errors import ConfigError, RecordError
from wbc.scenario.trial import Trial

__all__ = ["AXES", "SECTORS", "TIED_AXES", "VERTICAL", "PushOutcome", "breakdown", "breakdown_tables", "command_label",
           "heading_sector", "push_outcomes", "push_sector", "recovery_curve"]

SECTORS = ("forward", "left", "backward", "right")
"""Push heading sectors, by where the force points: 90 degrees each, centred on +x, +y, -x, -y of the world (the
robot's initial heading is +x)."""

VERTICAL = "vertical"
"""The sector of a push steeper than 45 degrees out of the horizontal plane (`push_sector`): its heading says little
of where it pushes the robot. Listed, in the tables and the breakdown, only where such a push was met."""

AXES = ("x", "y")
"""Offset axes of a push's application point (base frame)."""

TIED_AXES = "x=y"
"""The offset axis of a point offset equally along base x and y (neither axis is the larger). Listed, like
`VERTICAL`, only where such a push was met."""

_N_BINS = 8


@dataclass(frozen=True, kw_only=True)
class PushOutcome:
    """One push met by one controller in one trial, and whether the robot stood through it.

    Attributes:
        controller: the controller.
        band: the band.
        seed: the seed.
        trial: the trial index.
        push: the push's index within the trial (time order).
        start_s: when it began [s].
        force_n: its magnitude [N].
        impulse_ns: magnitude times duration [N s].
        heading_deg: where the force's horizontal part points in the world frame, in (-180, 180] [deg]; NaN for a
            force with no horizontal part.
        sector: `push_sector` of the force.
        offset_axis: the base axis its application point is offset along (``x``, ``y``; `TIED_AXES` when both are
            equal, ``none`` at the centre).
        survived: the robot did not fall before the next push began (or the episode ended).
        fall_after_s: time from this push's start to the fall, NaN when survived [s].
    """

    controller: str
    band: str
    seed: int
    trial: int
    push: int
    start_s: float
    force_n: float
    impulse_ns: float
    heading_deg: float
    sector: str
    offset_axis: str
    survived: bool
    fall_after_s: float


def heading_sector(heading_rad: float) -> str:
    """The sector of `SECTORS` a heading falls in (boundaries at +-45 and +-135 degrees belong to the side sectors)."""
    deg = math.degrees(math.atan2(math.sin(heading_rad), math.cos(heading_rad)))
    if -45.0 < deg < 45.0:
        return "forward"
    if 45.0 <= deg <= 135.0:
        return "left"
    if -135.0 <= deg <= -45.0:
        return "right"
    return "backward"


def push_sector(force_in_world: np.ndarray) -> str:
    """Where a push's force points, a sector of `SECTORS` or `VERTICAL`.

    `VERTICAL` when steeper than 45 degrees out of the horizontal plane (|F_z| above the horizontal part's length),
    else the `heading_sector` of its horizontal part.
    """
    fx, fy, fz = (float(f) for f in force_in_world)
    if abs(fz) > math.hypot(fx, fy):
        return VERTICAL
    return heading_sector(math.atan2(fy, fx))


def command_label(record: TrialRecord, changes: int = 0) -> str:
    """The trial's command in words: ``standing``, or its nonzero parts (``vx 0.3``, ``vx 1 yaw 2``).

    The record's command is the one the trial starts with; a trial whose command then changes (`changes`, its
    ``[[commands.changes]]``) says so: ``vx 0.5 yaw 1, then 1 change``, ``standing, then 2 changes``.
    """
    parts = [f"{name} {value:g}" for name, value in (("vx", record.vx_cmd), ("vy", record.vy_cmd),
                                                    ("yaw", record.yaw_rate_cmd)) if value != 0.0]
    label = " ".join(parts) if parts else "standing"
    return label if not changes else f"{label}, then {changes} change{'s' if changes > 1 else ''}"


def _offset_axis(offset: np.ndarray) -> str:
    x, y = (abs(float(v)) for v in offset[:2])
    if x == y:
        return "none" if x == 0.0 else TIED_AXES
    return AXES[0] if x > y else AXES[1]


_NOT_FALLS = (CONTROLLER_ERROR, SAFETY_TRIP, OPERATOR_STOP)
"""Outcomes that end a trial early without a fall (no ``fall_time_s``): no push is charged with them."""


def push_outcomes(records: Iterable[TrialRecord], trial_of: Callable[[str, int, int], Trial]) -> list[PushOutcome]:
    """Every push each record's trial met, with its outcome (module docstring).

    Args:
        records: arena records.
        trial_of: ``(band, seed, index) -> Trial`` of the scenario they were played on (``scenario.trial``).

    Returns:
        The outcomes, record by record in the order given, pushes in time order. A record played without its
        pushes (``--no-push``: ``n_pushes`` 0 where the trial has some) contributes none, nor does a trial ended by
        its controller's error, a safety layer's trip or an operator's stop (the robot did not fall: no push is
        charged with it; they have no fall time).

    Raises:
        RecordError: a record's scenario hash, push count or largest push differ from the trial re-drawn.
    """
    out: list[PushOutcome] = []
    for record in records:
        trial = trial_of(record.band, record.seed, record.trial)
        if record.scenario_hash and trial.scenario_hash and record.scenario_hash != trial.scenario_hash:
            raise RecordError(f"record {record.run_key} was played on scenario hash {record.scenario_hash}, not "
                              f"{trial.scenario_hash}; break down records with the scenario they were played on")
        if record.n_pushes == 0 or record.outcome in _NOT_FALLS:
            continue
        if record.n_pushes != len(trial.pushes) or not math.isclose(record.push_force_n, trial.push_force_n,
                                                                    rel_tol=1e-9, abs_tol=1e-9):
            raise RecordError(f"record {record.run_key} has {record.n_pushes} pushes of at most "
                              f"{record.push_force_n:g} N, its trial re-drawn has {len(trial.pushes)} of at most "
                              f"{trial.push_force_n:g} N; break down records with the scenario they were played on")
        fall = math.inf if record.success else record.fall_time_s
        for k, push in enumerate(trial.pushes):
            if push.start >= fall:
                break
            following = trial.pushes[k + 1].start if k + 1 < len(trial.pushes) else math.inf
            survived = fall >= following
            force = float(np.linalg.norm(push.force_in_world))
            fx, fy = float(push.force_in_world[0]), float(push.force_in_world[1])
            out.append(PushOutcome(
                controller=record.controller, band=record.band, seed=record.seed, trial=record.trial, push=k,
                start_s=push.start, force_n=force, impulse_ns=force * push.duration,
                heading_deg=math.degrees(math.atan2(fy, fx)) if fx or fy else math.nan,
                sector=push_sector(push.force_in_world),
                offset_axis=_offset_axis(push.offset_in_base), survived=survived,
                fall_after_s=math.nan if survived else fall - push.start))
    return out


def _cell(k: int, n: int) -> dict[str, Any]:
    lo, hi = wilson_interval(k, n)
    return {"k": k, "n": n, "rate": k / n if n else None,
            "ci95": [lo, hi] if n else [None, None]}


def breakdown(records: Sequence[TrialRecord], outcomes: Sequence[PushOutcome], *, controllers: Sequence[str],
              bands: Sequence[str], trial_of: Callable[[str, int, int], Trial] | None = None) -> dict[str, Any]:
    """Success by command, push survival by heading sector and offset axis, and falls, per controller and band.

    Args:
        records: the run's records.
        outcomes: their `push_outcomes` (empty for a scenario without pushes).
        controllers: the controllers, in order.
        bands: the bands, in order.
        trial_of: ``(band, seed, index) -> Trial`` of the scenario (``scenario.trial``), whose command changes the
            labels count (`command_label`); None: the records' commands alone.

    Returns:
        A JSON-serialisable dict: ``{"commands": [labels], "controllers": {NAME: {BAND: {"by_command": {label:
        cell}, "by_sector": {sector: cell}, "by_offset_axis": {axis: cell}, "falls": {"trials", "falls",
        "controller_errors", "before_first_push", "after_push", "median_s_after_push"}}}}}``, a cell being ``{"k",
        "n", "rate", "ci95"}`` (successes or pushes survived out of n, with a Wilson interval; rate and interval None
        when n is 0). The sectors are `SECTORS`, with `VERTICAL` after them where a push of the run was vertical; the
        axes `AXES`, with `TIED_AXES` where one was offset equally along both. ``falls`` counts the trials that
        ended without success and not by a controller error (those are ``controller_errors``).
    """
    def label(record: TrialRecord) -> str:
        changes = 0 if trial_of is None else len(trial_of(record.band, record.seed, record.trial).command.changes)
        return command_label(record, changes)

    label_of = {id(r): label(r) for r in records if r.controller in controllers and r.band in bands}
    labels = sorted(set(label_of.values()), key=lambda s: (not s.startswith("standing"), s))
    sectors = (*SECTORS, *((VERTICAL,) if any(o.sector == VERTICAL for o in outcomes) else ()))
    axes = (*AXES, *((TIED_AXES,) if any(o.offset_axis == TIED_AXES for o in outcomes) else ()))
    result: dict[str, Any] = {"commands": labels, "controllers": {}}
    for controller in controllers:
        per_band: dict[str, Any] = {}
        for band in bands:
            mine = [r for r in records if r.controller == controller and r.band == band]
            pushes = [o for o in outcomes if o.controller == controller and o.band == band]
            by_command = {}
            for label in labels:
                cell = [r for r in mine if label_of[id(r)] == label]
                by_command[label] = _cell(sum(r.success for r in cell), len(cell))
            by_sector = {s: _cell(sum(o.survived for o in pushes if o.sector == s),
                                  sum(1 for o in pushes if o.sector == s)) for s in sectors}
            by_axis = {a: _cell(sum(o.survived for o in pushes if o.offset_axis == a),
                                sum(1 for o in pushes if o.offset_axis == a)) for a in axes}
            charged = [o for o in pushes if not o.survived]
            errors = sum(r.outcome == CONTROLLER_ERROR for r in mine)
            # a safety layer's trip and an operator's stop are no falls either (a hardware trial's)
            falls = sum(not r.success for r in mine) - errors - sum(r.outcome in _NOT_FALLS[1:] for r in mine)
            per_band[band] = {
                "by_command": by_command, "by_sector": by_sector, "by_offset_axis": by_axis,
                "falls": {"trials": len(mine), "falls": falls, "controller_errors": errors,
                          "before_first_push": falls - len(charged),  # one charged push per fall after a push
                          "after_push": len(charged),
                          "median_s_after_push": statistics.median(o.fall_after_s for o in charged)
                          if charged else None},
            }
        result["controllers"][controller] = per_band
    return result


def _rate_text(cell: Mapping[str, Any]) -> str:
    if not cell["n"]:
        return "-"
    return f"{100.0 * cell['rate']:.0f}% {cell['k']}/{cell['n']}"


def breakdown_tables(result: Mapping[str, Any], band: str, *,
                     pushes: bool) -> list[tuple[list[str], list[list[str]]]]:
    """One band of a `breakdown` as tables (header, rows), a row per controller, cells ``rate k/n``.

    The first table: success by command (the commands played in the band), and (with pushes) the falls before any
    push and after one, with the median time from that push to the fall. The second, with pushes only: each push
    survived by heading sector and by offset axis.

    Args:
        result: the output of `breakdown`.
        band: the band.
        pushes: the scenario has pushes (else only the first table, without the fall columns).
    """
    # the commands played in this band (a band may fix part of the command: the turn task's forward speed)
    labels = [label for label in result["commands"]
              if any(per_band[band]["by_command"][label]["n"] for per_band in result["controllers"].values())]
    first_header = ["controller", *labels]
    if pushes:
        first_header += ["falls: no push / after one", "median fall delay [s]"]
    first, second = [], []
    any_band = next(iter(result["controllers"].values()), {}).get(band, {})
    sectors, axes = list(any_band.get("by_sector", SECTORS)), list(any_band.get("by_offset_axis", AXES))
    for controller, per_band in result["controllers"].items():
        cell = per_band[band]
        row = [controller, *(_rate_text(cell["by_command"][label]) for label in labels)]
        if pushes:
            falls = cell["falls"]
            delay = falls["median_s_after_push"]
            row += [f"{falls['before_first_push']} / {falls['after_push']}", "-" if delay is None else f"{delay:.2f}"]
            second.append([controller, *(_rate_text(cell["by_sector"][s]) for s in sectors),
                           *(_rate_text(cell["by_offset_axis"][a]) for a in axes)])
        first.append(row)
    tables = [(first_header, first)]
    if pushes:
        tables.append((["controller", *(f"pushed {s}" for s in sectors), *(f"offset {a}" for a in axes)], second))
    return tables


def recovery_curve(outcomes: Sequence[PushOutcome], *, controllers: Sequence[str],
                   n_bins: int = _N_BINS) -> dict[str, Any]:
    """Push survival against impulse, in `n_bins` equal bins over the impulses met, per controller, with Wilson CIs.

    Args:
        outcomes: push outcomes (all bands pooled: the bands differ only in the push magnitude).
        controllers: the controllers, in order.
        n_bins: number of impulse bins, >= 1.

    Returns:
        ``{"edges": [N s ...], "controllers": {NAME: [cell per bin]}}`` (cells as in `breakdown`); edges empty and
        no bins without outcomes.

    Raises:
        ConfigError: n_bins < 1.
    """
    if n_bins < 1:
        raise ConfigError(f"recovery_curve: n_bins must be >= 1, got {n_bins}")
    if not outcomes:
        return {"edges": [], "controllers": {c: [] for c in controllers}}
    impulses = np.array([o.impulse_ns for o in outcomes])
    lo, hi = float(impulses.min()), float(impulses.max())
    if hi - lo < 1e-9:
        lo, hi = lo - 0.5, hi + 0.5
    edges = np.linspace(lo, hi, n_bins + 1)
    curve: dict[str, list[dict[str, Any]]] = {}
    for controller in controllers:
        mine = [o for o in outcomes if o.controller == controller]
        idx = np.clip(np.searchsorted(edges, [o.impulse_ns for o in mine], side="right") - 1, 0, n_bins - 1)
        cells = []
        for i in range(n_bins):
            inside = [o for o, j in zip(mine, idx, strict=True) if j == i]
            cells.append(_cell(sum(o.survived for o in inside), len(inside)))
        curve[controller] = cells
    return {"edges": [float(e) for e in edges], "controllers": curve}
