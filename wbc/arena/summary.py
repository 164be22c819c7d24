"""The typed summary of an arena run: per metric, per controller and band, per pair of controllers, with one JSON form.

`wbc.arena.report.summarize` builds a `Summary` from the records; the table, the report, the plots, the verdict and
the CLI read its typed fields; ``summary.json`` is `Summary.to_json`, and `Summary.from_json` reads it back. NaN
never reaches JSON: an undefined statistic is ``None`` in both forms.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

from wbc.arena.error_guard import ControllerErrors
from wbc.arena.multiplicity import smallest_attainable_p
from wbc.errors import RecordError

__all__ = ["SIGNIFICANCE", "CellSummary", "CounterTotal", "MetricSummary", "PairSummary", "Summary", "TickWarning",
           "json_float", "p_digits"]

SIGNIFICANCE = 0.05
"""The level at which a paired test's difference is called significant (p < 0.05)."""


def p_digits(p: float) -> str:
    """A p-value to 3 significant digits, or as many more as keep it on its side of `SIGNIFICANCE`.

    0.0499832 is called significant, so it is written 0.04998, never 0.05; 0.05 itself is not, and stays 0.05.
    """
    for digits in range(3, 12):
        text = f"{p:.{digits}g}"
        if (float(text) < SIGNIFICANCE) == (p < SIGNIFICANCE):
            return text
    return repr(p)


def json_float(value: float | None) -> float | None:
    """A statistic as both forms hold it: a finite float, or None for NaN, infinity or no value."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


@dataclass(frozen=True)
class MetricSummary:
    """One metric of one controller in one band.

    Attributes:
        mean: mean across seeds (each seed's trials averaged first); None without values.
        std: sample std across seeds (0 with one seed); None without values.
        ci95: the 95 % interval of the mean over trials (Wilson for success, percentile bootstrap otherwise).
        trials: the trials that had a value (given for the common-window metrics, whose window may be empty; None
            for the others, whose count is the cell's `CellSummary.trials`).
        all_equal: the number of values (2 or more) when every one of them is the same, else None. `ci95` is then
            [value, value], which measures no uncertainty: the tables print the value and "all n equal" instead.
            A bootstrap interval needs 2 values or more: from one, `ci95` is (None, None).
    """

    mean: float | None
    std: float | None
    ci95: tuple[float | None, float | None] = (None, None)
    trials: int | None = None
    all_equal: int | None = None
    nonzero: int | None = None
    n80_holm: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "mean", json_float(self.mean))
        object.__setattr__(self, "std", json_float(self.std))
        object.__setattr__(self, "ci95", (json_float(self.ci95[0]), json_float(self.ci95[1])))

    def to_json(self) -> dict[str, Any]:
        """``{"mean", "std", "ci95": [lo, hi]}``, ``"trials"`` when counted, ``"all_equal"`` when all values are."""
        out: dict[str, Any] = {"mean": self.mean, "std": self.std, "ci95": list(self.ci95)}
        if self.trials is not None:
            out["trials"] = self.trials
        if self.all_equal is not None:
            out["all_equal"] = self.all_equal
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> MetricSummary:
        """Read back `to_json` (``trials`` absent: not counted; ``all_equal`` absent: not all equal)."""
        ci = data["ci95"]
        return cls(mean=data["mean"], std=data["std"], ci95=(ci[0], ci[1]), trials=data.get("trials"),
                   all_equal=data.get("all_equal"))


@dataclass(frozen=True)
class CounterTotal:
    """One event count a controller reported, over the trials of a band.

    Attributes:
        total: the sum over the trials.
        trials: the trials where it was above 0.
        per_trial: the mean per trial (a trial that did not report it counts 0).
    """

    total: int
    trials: int
    per_trial: float

    def to_json(self) -> dict[str, Any]:
        """``{"total", "trials", "per_trial"}``."""
        return {"total": self.total, "trials": self.trials, "per_trial": self.per_trial}


@dataclass(frozen=True)
class CellSummary:
    """One controller in one band.

    Attributes:
        trials: trials recorded.
        seeds: seeds they came from.
        metrics: summary metric name -> its statistics, in table order (`wbc.arena.report.METRICS`, then the extra
            and common-window metrics).
        ticks: control ticks played, over the trials.
        deadline_misses: ticks whose ``act`` took longer than the control period.
        clamped_ticks: ticks whose command the robot clamped to its motors' limits.
        clamped_rows: of those, ticks per command row (``q``, ``dq``, ``kp``, ``kd``, ``tau``), rows never clamped
            left out.
        counters: every event count the controller reported, by name (sorted).
        outcomes: trials per outcome (`wbc.arena.trial_record.OUTCOMES`, every one listed); None when not counted (a
            summary of records alone, before the arena adds them).
    """

    trials: int
    seeds: int
    metrics: Mapping[str, MetricSummary]
    ticks: int = 0
    deadline_misses: int = 0
    clamped_ticks: int = 0
    clamped_rows: Mapping[str, int] = field(default_factory=dict)
    counters: Mapping[str, CounterTotal] = field(default_factory=dict)
    outcomes: Mapping[str, int] | None = None

    def __getitem__(self, metric: str) -> MetricSummary:
        """The statistics of `metric`.

        Raises:
            RecordError: no such metric in this cell (the message lists those there are).
        """
        try:
            return self.metrics[metric]
        except KeyError:
            raise RecordError(f"summary cell has no metric {metric!r}; it has {', '.join(self.metrics)}") from None

    def __contains__(self, metric: object) -> bool:
        """Whether the cell holds `metric`."""
        return metric in self.metrics

    def outcome(self, name: str) -> int:
        """Trials that ended with the outcome `name` (0 when not counted)."""
        return (self.outcomes or {}).get(name, 0)

    def to_json(self) -> dict[str, Any]:
        """The ``summary.json`` form of a cell: counts, each metric by name, tick counts, counters, outcomes."""
        out: dict[str, Any] = {"trials": self.trials, "seeds": self.seeds}
        out.update({name: stat.to_json() for name, stat in self.metrics.items()})
        out.update(ticks=self.ticks, deadline_misses=self.deadline_misses, clamped_ticks=self.clamped_ticks,
                   clamped_rows=dict(self.clamped_rows),
                   counters={name: c.to_json() for name, c in self.counters.items()})
        if self.outcomes is not None:
            out["outcomes"] = dict(self.outcomes)
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> CellSummary:
        """Read back `to_json` (``outcomes`` absent: not counted)."""
        scalar = {"trials", "seeds", "ticks", "deadline_misses", "clamped_ticks", "clamped_rows", "counters",
                  "outcomes"}
        metrics = {name: MetricSummary.from_json(value) for name, value in data.items() if name not in scalar}
        return cls(trials=data["trials"], seeds=data["seeds"], metrics=metrics, ticks=data["ticks"],
                   deadline_misses=data["deadline_misses"], clamped_ticks=data["clamped_ticks"],
                   clamped_rows=dict(data["clamped_rows"]),
                   counters={name: CounterTotal(**c) for name, c in data["counters"].items()},
                   outcomes=dict(data["outcomes"]) if "outcomes" in data else None)


@dataclass(frozen=True, kw_only=True)
class PairSummary:
    """B - A on the trials both played, for one band and metric (`wbc.arena.report.paired_comparison`).

    Attributes:
        a: controller A (named first).
        b: controller B.
        band: the band.
        metric: the summary metric compared.
        diff: mean of B - A over the pairs; None without pairs.
        ci95: its 95 % interval.
        interval: how `ci95` was made: ``exact`` (success: agrees with the McNemar test) or ``bootstrap``.
        n: pairs used.
        mean_a: A's mean over the pairs (success as a fraction).
        mean_b: B's mean over the pairs.
        test: the paired test (``exact McNemar`` or ``Wilcoxon signed-rank``); None without pairs.
        p: its two-sided p-value.
        n80: pairs the test needs for 80 % power at the observed difference, at alpha = 0.05 (the test on its own);
            None when none was observed or beyond the search.
        a_only: discordant pairs A alone won (success only).
        b_only: discordant pairs B alone won (success only).
        shift: the Hodges-Lehmann estimate of B - A (the median of the nonzero differences' Walsh averages), the
            size of the shift the Wilcoxon test is about. None for success, without a nonzero difference, and in a
            ``summary.json`` written before it was recorded.
        rank_biserial: the Wilcoxon test's matched-pairs rank-biserial correlation, (R+ - R-) / (R+ + R-): its sign
            is the side the test leans to (positive: B - A tends to be positive), which the mean's may not be. None
            for success and in a ``summary.json`` written before it was recorded.
        p_holm: `p` after Holm's correction over the paired tests of the run that can reach p < 0.05 on their pairs
            (Tarone's refinement, `wbc.arena.multiplicity.tarone_holm_adjusted`): the family the verdict weighs. A
            test that cannot (`smallest_p` >= 0.05) is left out of it and has its own `p` here. None without a test,
            and in a ``summary.json`` written before it was recorded.
        all_equal: for a bootstrap interval, the number of pairs (2 or more) when every difference is the same, else
            None: `ci95` is then [diff, diff], which measures no uncertainty. From one pair `ci95` is (None, None).
        nonzero: the Wilcoxon test's nonzero differences (the pairs it ranks); None for success, and in a
            ``summary.json`` written before it was recorded.
        n80_holm: pairs the test needs for 80 % power at the observed difference at alpha / m, m = `n80_holm_tests`
            (every test the verdict weighs, those left out of its correction included: with more trials they may
            join it): at most the level of Holm's first (strictest) step, so a test that reaches it holds after the
            correction whatever the others show. None where `n80` is, beyond the search, and in a ``summary.json``
            written before it was recorded.
        n80_holm_tests: the m of `n80_holm`'s level; None where it is None, and in a ``summary.json`` written
            before it was recorded.
        n80_holm_recorded: False for an entry read from a ``summary.json`` written before `n80_holm` was recorded:
            its None then says nothing of the search (not part of the JSON form, nor of equality).
    """

    a: str
    b: str
    band: str
    metric: str
    diff: float | None
    ci95: tuple[float | None, float | None]
    interval: str | None
    n: int
    mean_a: float | None
    mean_b: float | None
    test: str | None
    p: float | None
    n80: int | None
    a_only: int | None
    b_only: int | None
    shift: float | None = None
    rank_biserial: float | None = None
    p_holm: float | None = None
    all_equal: int | None = None
    nonzero: int | None = None
    n80_holm: int | None = None
    n80_holm_tests: int | None = None
    n80_holm_recorded: bool = field(default=True, compare=False, repr=False)

    def __post_init__(self) -> None:
        for name in ("diff", "mean_a", "mean_b", "p", "shift", "rank_biserial", "p_holm"):
            object.__setattr__(self, name, json_float(getattr(self, name)))
        object.__setattr__(self, "ci95", (json_float(self.ci95[0]), json_float(self.ci95[1])))

    @property
    def significant(self) -> bool:
        """The test rejected at `SIGNIFICANCE` (0.05)."""
        return self.p is not None and self.p < SIGNIFICANCE

    @property
    def smallest_p(self) -> float | None:
        """The smallest p its exact test could give on these pairs (`wbc.arena.multiplicity.smallest_attainable_p`).

        On the discordant pairs (McNemar) or the nonzero differences (Wilcoxon); from a ``summary.json`` without
        `nonzero`, on the pairs (an upper bound of the nonzero differences), or none where they are all 0. None
        without a test.
        """
        if self.p is None or self.test is None:
            return None
        if self.test == "exact McNemar":
            informative = (self.a_only or 0) + (self.b_only or 0)
        elif self.nonzero is not None:
            informative = self.nonzero
        else:
            informative = 0 if self.diff == 0.0 and (self.all_equal is not None or self.n == 1) else self.n
        return smallest_attainable_p(informative)

    def to_json(self) -> dict[str, Any]:
        """The ``summary.json`` form (``paired`` entries)."""
        return {"a": self.a, "b": self.b, "band": self.band, "metric": self.metric, "diff": self.diff,
                "ci95": list(self.ci95), "interval": self.interval, "n": self.n, "mean_a": self.mean_a,
                "mean_b": self.mean_b, "test": self.test, "p": self.p, "n80": self.n80, "a_only": self.a_only,
                "b_only": self.b_only, "shift": self.shift, "rank_biserial": self.rank_biserial,
                "p_holm": self.p_holm, "all_equal": self.all_equal, "nonzero": self.nonzero,
                "n80_holm": self.n80_holm, "n80_holm_tests": self.n80_holm_tests}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> PairSummary:
        """Read back `to_json`."""
        ci = data["ci95"]
        return cls(a=data["a"], b=data["b"], band=data["band"], metric=data["metric"], diff=data["diff"],
                   ci95=(ci[0], ci[1]), interval=data["interval"], n=data["n"], mean_a=data["mean_a"],
                   mean_b=data["mean_b"], test=data["test"], p=data["p"], n80=data["n80"], a_only=data["a_only"],
                   b_only=data["b_only"], shift=data.get("shift"), rank_biserial=data.get("rank_biserial"),
                   p_holm=data.get("p_holm"), all_equal=data.get("all_equal"), nonzero=data.get("nonzero"),
                   n80_holm=data.get("n80_holm"), n80_holm_tests=data.get("n80_holm_tests"),
                   n80_holm_recorded="n80_holm" in data)


@dataclass(frozen=True, kw_only=True)
class TickWarning:
    """A controller whose deadline misses or clamped ticks passed 1 % of its ticks in a band.

    Attributes:
        controller: the controller.
        band: the band.
        kind: ``deadline_misses`` or ``clamped_ticks``.
        count: the ticks concerned.
        ticks: the ticks played.
        text: the warning in words, as printed.
    """

    controller: str
    band: str
    kind: str
    count: int
    ticks: int
    text: str

    def to_json(self) -> dict[str, Any]:
        """The ``summary.json`` form (``warnings`` entries)."""
        return {"controller": self.controller, "band": self.band, "kind": self.kind, "count": self.count,
                "ticks": self.ticks, "text": self.text}


@dataclass(frozen=True, kw_only=True)
class Summary:
    """An arena run summarised.

    Attributes:
        scenario_name: the scenario's name.
        scenario_hash: its content hash.
        cells: controller -> band -> its `CellSummary`, controllers and bands in table order.
        paired: every pair's comparison, in order (pair, band, metric).
        warnings: the deadline-miss and clamped-command warnings.
        controller_errors: each controller that failed on a trial, by name (`ControllerErrors`); None when not
            counted (a summary of records alone).
        sequential: the sequential test's verdict (``wbc compare --until-significant``,
            `wbc.arena.sequential.SequentialComparison.as_dict`), None otherwise.
        robots: controller -> the robot it played (its arm mode, in words), in table order; None when not known (a
            summary of records alone).
        robots_note: where the controllers played different robots, what each carried and why that matters
            (`wbc.arena.compare.arms_note`); None where they played one robot or `robots` is not known.
        mixed_environments: for a run resumed under another environment than it began under (another code among
            them), what each resume changed (`wbc.arena.run_environment.mixed`); ``summary.json`` then holds
            ``mixed_environments: true`` and these lines (``environment_changes``). None: one environment.
    """

    scenario_name: str
    scenario_hash: str
    cells: Mapping[str, Mapping[str, CellSummary]]
    paired: tuple[PairSummary, ...] = ()
    warnings: tuple[TickWarning, ...] = ()
    controller_errors: Mapping[str, ControllerErrors] | None = None
    sequential: Mapping[str, Any] | None = None
    robots: Mapping[str, str] | None = None
    robots_note: str | None = None
    mixed_environments: tuple[str, ...] | None = None

    @property
    def same_robot(self) -> bool | None:
        """Whether every controller played the same robot; None when not known."""
        return None if self.robots is None else self.robots_note is None

    @property
    def controllers(self) -> list[str]:
        """The controllers, in table order."""
        return list(self.cells)

    @property
    def bands(self) -> list[str]:
        """The bands, in table order (first appearance over the controllers)."""
        bands: list[str] = []
        for per_band in self.cells.values():
            bands += [b for b in per_band if b not in bands]
        return bands

    def cell(self, controller: str, band: str) -> CellSummary | None:
        """The cell of `controller` in `band`, None when it has none."""
        return self.cells.get(controller, {}).get(band)

    def iter_cells(self) -> Iterator[tuple[str, str, CellSummary]]:
        """Every (controller, band, cell), controllers then bands in table order."""
        for controller, per_band in self.cells.items():
            for band, cell in per_band.items():
                yield controller, band, cell

    @property
    def stored(self) -> int:
        """Trials recorded, over every cell."""
        return sum(cell.trials for _, _, cell in self.iter_cells())

    def to_json(self) -> dict[str, Any]:
        """The ``summary.json`` form (also ``wbc compare --json``)."""
        out: dict[str, Any] = {
            "scenario": {"name": self.scenario_name, "hash": self.scenario_hash},
            "controllers": {c: {"bands": {b: cell.to_json() for b, cell in per_band.items()}}
                            for c, per_band in self.cells.items()},
            "paired": [p.to_json() for p in self.paired],
            "warnings": [w.to_json() for w in self.warnings],
        }
        if self.controller_errors is not None:
            out["controller_errors"] = {name: e.as_dict() for name, e in self.controller_errors.items()}
        if self.sequential is not None:
            out["sequential"] = dict(self.sequential)
        if self.robots is not None:
            out.update(same_robot=self.same_robot, robots=dict(self.robots), robots_note=self.robots_note)
        if self.mixed_environments is not None:
            out.update(mixed_environments=True, environment_changes=list(self.mixed_environments))
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any], *, source: str = "summary") -> Summary:
        """Read back `to_json` (``summary.json``; ``controller_errors``, ``sequential`` and ``robots`` absent: none).

        Raises:
            RecordError: a field is missing or malformed (the message names `source` and the field).
        """
        try:
            cells = {c: {b: CellSummary.from_json(cell) for b, cell in entry["bands"].items()}
                     for c, entry in data["controllers"].items()}
            errors = data.get("controller_errors")
            return cls(scenario_name=data["scenario"]["name"], scenario_hash=data["scenario"]["hash"], cells=cells,
                       paired=tuple(PairSummary.from_json(p) for p in data["paired"]),
                       warnings=tuple(TickWarning(**w) for w in data["warnings"]),
                       controller_errors=None if errors is None else
                       {name: ControllerErrors.from_dict(name, e) for name, e in errors.items()},
                       sequential=data.get("sequential"), robots=data.get("robots"),
                       robots_note=data.get("robots_note"),
                       mixed_environments=(tuple(data["environment_changes"]) if data.get("mixed_environments")
                                           else None))
        except (KeyError, TypeError, AttributeError) as exc:
            raise RecordError(f"{source}: not a summary this version reads ({type(exc).__name__}: {exc}); write it "
                              "again with wbc compare --resume on its results directory") from None
