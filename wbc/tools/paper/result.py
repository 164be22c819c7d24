"""A played paper table (`PaperTableResult`) and its comparisons.

What `wbc.tools.paper.paper_table` produces and `wbc.tools.paper.format` prints, in a module of its own so that
neither of the two imports the other.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wbc.arena.error_guard import ControllerErrors
from wbc.arena.summary import PairSummary, Summary
from wbc.tools.paper.tables import Contender, PaperTableSpec

__all__ = ["PAPER_TRIALS_PER_BAND", "PaperComparison", "PaperTableResult", "warm_trial_wall_s"]

PAPER_TRIALS_PER_BAND = 2000
"""The paper's trials per band and contender (over its 5 seeds), for the run-time estimate printed with each table."""


def warm_trial_wall_s(walls: Sequence[float], workers: int) -> float | None:
    """The mean wall time per trial of one controller, each worker's first trial of it left out [s].

    A process's first trial of a controller builds it, and on a fresh machine compiles its numba code (tens of
    seconds, against seconds for a trial that loads the compiled code); a worker plays that trial once, not once per
    trial, so the run-time estimate leaves it out. Which trial a worker played first is not recorded; the compiling
    one is the slowest, so the `workers` slowest are left out (at most one per worker).

    Args:
        walls: the wall time of each of the controller's trials [s].
        workers: worker processes that played them.

    Returns:
        The mean of the others, or None when no trial is left (every one may have been a worker's first).
    """
    rest = sorted(walls)[:len(walls) - max(workers, 1)]
    return sum(rest) / len(rest) if rest else None


@dataclass(frozen=True)
class PaperComparison:
    """One of a paper table's comparisons in one band and metric.

    Attributes:
        question: what the comparison asks (the contrast's question).
        pair: B - A on the same trials, A and B named by the contenders' keys.
    """

    question: str
    pair: PairSummary

    def to_json(self) -> dict[str, Any]:
        """``paper.json``'s form: ``{"a", "b", "question", "band", "metric", ...}`` with the pair's fields."""
        pair = self.pair.to_json()
        return {"a": pair.pop("a"), "b": pair.pop("b"), "question": self.question, **pair}


@dataclass(frozen=True, kw_only=True)
class PaperTableResult:
    """A played paper table.

    Attributes:
        spec: the table.
        contenders: our rows as played (missing ones with controller None).
        scenario: name, version, path, hash and whether it is published.
        bands: the scenario's bands, in file order.
        band_columns: each band's column of the paper's table (an index into ``spec.paper_columns``,
            `wbc.tools.paper.tables.paper_columns_of`), None for a band the paper has no figure for.
        columns_note: why no band stands in a paper column (another scenario than the table's, or an unpublished
            copy of it), or None.
        trials: trials per band and seed.
        seeds: the seeds.
        summary: the arena's summary.
        comparisons: one per (contrast, band, metric), its pair named by the contenders' keys.
        failures: the arena's breakdown of where each contender fails (`wbc.arena.breakdown.breakdown`).
        curve: the push-recovery curve (`wbc.arena.breakdown.recovery_curve`).
        trial_wall_s: each controller's mean wall time per trial [s].
        warm_wall_s: each controller's mean wall time per trial without each worker's first (`warm_trial_wall_s`),
            for the run-time estimate; a controller left out played no trial beside those [s].
        out_dir: the results directory.
        played: trials played by this call.
        stored: trials in the results, this call's and those of the run it resumed.
        wall_s: wall time of this call [s].
        workers: worker processes used.
        controller_errors: each contender that failed on a trial (`wbc.arena.compare.ArenaResult.controller_errors`);
            its failed trials count against its success, and the command exits 1 naming it.
    """

    spec: PaperTableSpec
    contenders: tuple[Contender, ...]
    scenario: dict[str, Any]
    bands: tuple[str, ...]
    band_columns: tuple[int | None, ...]
    trials: int
    seeds: tuple[int, ...]
    summary: Summary
    comparisons: tuple[PaperComparison, ...]
    failures: dict[str, Any]
    curve: dict[str, Any]
    trial_wall_s: dict[str, float]
    warm_wall_s: dict[str, float]
    out_dir: Path
    played: int
    wall_s: float
    stored: int = 0
    workers: int | None
    controller_errors: tuple[ControllerErrors, ...] = ()
    columns_note: str | None = None

    @property
    def paper_protocol_cpu_h(self) -> float:
        """CPU hours the paper's protocol (`PAPER_TRIALS_PER_BAND` per band and contender) would take here.

        Estimated from this run's mean wall time per trial of each controller, each worker's first trial of it
        left out: that one compiles the numba code on a fresh machine, once per worker and not once per trial
        (`warm_wall_s`). A controller that played no other trial counts with its mean over all, compiling included
        (`estimate_includes_compile`). One core per trial; a trial that falls ends early, so a controller that falls
        less costs more.
        """
        walls = [self.warm_wall_s.get(c, s) for c, s in self.trial_wall_s.items()]
        return sum(walls) * PAPER_TRIALS_PER_BAND * len(self.bands) / 3600.0

    @property
    def estimate_includes_compile(self) -> bool:
        """Whether `paper_protocol_cpu_h` counts first trials, which may include compiling (an overestimate)."""
        return any(c not in self.warm_wall_s for c in self.trial_wall_s)

    def as_dict(self) -> dict[str, Any]:
        """JSON-serialisable (``paper.json``)."""
        return {
            "table": self.spec.name, "title": self.spec.title,
            "contenders": [{"key": c.key, "row": c.row, "family": c.family, "controller": c.controller,
                            "note": c.note} for c in self.contenders],
            "scenario": self.scenario, "bands": list(self.bands), "paper_columns": list(self.spec.paper_columns),
            "band_columns": {band: None if col is None else self.spec.paper_columns[col]
                             for band, col in zip(self.bands, self.band_columns, strict=True)},
            "columns_note": self.columns_note,
            "trials": self.trials, "seeds": list(self.seeds),
            "comparisons": [c.to_json() for c in self.comparisons],
            "trial_wall_s": self.trial_wall_s, "warm_wall_s": self.warm_wall_s, "wall_s": self.wall_s,
            "played": self.played, "stored": self.stored,
            "workers": self.workers, "paper_protocol_cpu_h": self.paper_protocol_cpu_h,
            # the paper's n beside its figures, and each figure as the paper prints it (its precision; success in %)
            "paper_protocol": self.spec.paper_protocol.to_json(),
            "paper": {row: {m: [{"mean": v.mean, "std": v.std, "printed": v.text} for v in values]
                            for m, values in cells.items()}
                      for row, cells in self.spec.paper.items()},
            # our rows, by controller (the contenders map their keys to it): summary.json's form, the table's cells
            # with each cell's n (``trials``, ``seeds``), the failing controllers (``controller_errors``) among them,
            # so that a script reads what the table shows
            "ours": self.summary.to_json(),
        }
