"""``wbc paper table1|table2|table3``: play a paper table's protocol in the arena and put our rows beside the paper's.

`run_paper_table` resolves the table's contenders (`wbc.tools.paper.tables`), plays them on the same trials of the
scenario (`wbc.arena.compare.run_arena`: resumable, every trial stored as it finishes, the arena's report with the
breakdown of where each contender fails and the push-recovery curve), then computes the table's paired comparisons
(difference, its 95 % interval, exact McNemar or Wilcoxon p-value, n80: `wbc.arena.report.compare_pair`; tracking
over the seconds both contenders survived, `PaperTableSpec.paired_metrics`) and
writes ``paper.txt`` (what the command prints, `wbc.tools.paper.format.format_paper_table`) and ``paper.json`` beside
the arena's files. The results directory is held (`wbc.arena.results.hold_results_dir`) from before the arena reads it
until both are written: a ``wbc paper --resume`` or ``wbc compare --resume`` on it meanwhile is refused, as during the
trials. Everything that can refuse the run for its input (the contenders and their files, the scenario, the options,
a directory another run holds) is checked before the directory is created (`wbc.arena.compare.plan_arena`), as
``wbc compare`` checks it: a refused ``wbc paper`` leaves no directory behind, and one refused or interrupted after,
before it stored anything, removes the directory it created.

The default size, `DEFAULT_TRIALS` trials x `DEFAULT_SEEDS` seed per band, fits a 2-core machine (the documentation's
results pages give measured run times); the paper's protocol is 5 seeds and 2000 trials: ``--seeds 5 --trials
400``. With one seed the cells show the mean's 95 % interval over trials, not a spread over seeds.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from wbc.arena.compare import ArenaConfig, plan_arena, play_arena
from wbc.arena.report import compare_pair
from wbc.arena.results import check_not_held, hold_results_dir, mark_complete, unwritable
from wbc.arena.trial_record import TrialRecord
from wbc.arena.verdict import holm_family
from wbc.errors import ConfigError, UnknownNameError
from wbc.output_files import write_text
from wbc.scenario import ScenarioError, check_published, load_scenario
from wbc.tools.paper.format import format_paper_table
from wbc.tools.paper.result import PAPER_TRIALS_PER_BAND, PaperComparison, PaperTableResult, warm_trial_wall_s
from wbc.tools.paper.tables import TABLES, paper_columns_of, resolve_contenders

__all__ = ["DEFAULT_SEEDS", "DEFAULT_TRIALS", "PAPER_TRIALS_PER_BAND", "PaperRunConfig", "PaperTableResult",
           "default_out_dir", "run_paper_table"]

DEFAULT_TRIALS = 10
"""Trials per band and seed by default: the size that fits a 2-core machine in minutes, not hours."""

DEFAULT_SEEDS = 1
"""Seeds by default."""

def default_out_dir(table: str) -> Path:
    """The results directory of a run of `table` without ``--out``: ``runs/paper-<table>-<time>``."""
    return Path("runs") / f"paper-{table}-{time.strftime('%Y%m%d-%H%M%S')}"


@dataclass(frozen=True, kw_only=True)
class PaperRunConfig:
    """What ``wbc paper TABLE`` plays.

    Attributes:
        table: ``table1``, ``table2`` or ``table3``.
        trials: trials per band and seed.
        seeds: seeds 0 .. seeds - 1.
        scenario: the scenario file (None: the table's; a later version of it, or another scenario with the same
            robot and the same number of bands, works alike).
        out_dir: results directory (None: ``runs/paper-<table>-<time>``, `default_out_dir`).
        workers: local worker processes (None: all cores).
        resume: finish an interrupted run in `out_dir`.
        drop_bad_rows: with `resume`, drop the rows of ``trials.csv`` the results store refuses and play their
            trials again (`wbc.arena.compare.ArenaConfig.drop_bad_rows`).
        progress: progress on stderr.
        contenders: ``--contender KEY=CONTROLLER`` overrides, by key.
        crouched: play the learned rows' crouched posture variants (``--crouched``; `wbc.tools.paper.tables`).
        trial_time_limit_s: the wall time a trial may take (`wbc.arena.compare.ArenaConfig.trial_time_limit_s`;
            None: no limit).
        isolated: with one worker, play in a worker process all the same (`wbc.arena.compare.ArenaConfig.isolated`).
        command_line: the command line, as ``run.json`` records it (`wbc.arena.compare.ArenaConfig.command_line`).
    """

    table: str
    trials: int = DEFAULT_TRIALS
    seeds: int = DEFAULT_SEEDS
    scenario: Path | None = None
    out_dir: Path | None = None
    workers: int | None = None
    resume: bool = False
    drop_bad_rows: bool = False
    progress: bool = True
    contenders: Mapping[str, str] = field(default_factory=dict)
    crouched: bool = False
    trial_time_limit_s: float | None = None
    isolated: bool = False
    command_line: str | None = None

    def __post_init__(self) -> None:
        if self.table not in TABLES:
            raise UnknownNameError("paper table", self.table, tuple(TABLES))
        if self.trials < 1 or self.seeds < 1:
            raise ConfigError(f"--trials and --seeds must be >= 1, got {self.trials} and {self.seeds}")


def run_paper_table(cfg: PaperRunConfig) -> PaperTableResult:
    """Play a paper table's protocol and compute its comparisons; write the arena's files, ``paper.txt/json``.

    Raises:
        UnknownNameError: an unknown table, ``--contender`` key or controller.
        PolicyFileError: a contender's ``policy:PATH`` file that is missing or malformed.
        PluginError: a contender's plug-in that cannot be imported, or whose factory raises.
        ScenarioError: the scenario file is invalid.
        ConfigError: the scenario (or a contender) is for another robot than the table's, or options out of range.
        ResultsDirError: `out_dir` holds another run (or, without `resume`, any run), or another process holds it
            (its lock, held here until ``paper.txt`` and ``paper.json`` are written).

    Every refusal but that of a directory holding another run comes before `out_dir` is created.
    """
    spec = TABLES[cfg.table]
    contenders = resolve_contenders(spec, cfg.contenders, crouched=cfg.crouched)
    scenario_path = cfg.scenario or Path(spec.scenario)
    scenario = load_scenario(scenario_path)
    if scenario.robot != spec.robot:
        raise ConfigError(f"{spec.name} is played by {spec.robot}, but {scenario_path} is a scenario for "
                          f"{scenario.robot}; pass --scenario with a {spec.robot} scenario (default {spec.scenario})")
    try:
        check_published(scenario)
        published = True
    except ScenarioError:
        published = False
    played_rows = [c for c in contenders if c.controller is not None]
    out = cfg.out_dir or default_out_dir(spec.name)
    arena_cfg = ArenaConfig(controllers=tuple(c.controller for c in played_rows), scenario=scenario_path,
                            seeds=tuple(range(cfg.seeds)), trials=cfg.trials, out_dir=out, workers=cfg.workers,
                            resume=cfg.resume, drop_bad_rows=cfg.drop_bad_rows, progress=cfg.progress,
                            trial_time_limit_s=cfg.trial_time_limit_s, isolated=cfg.isolated,
                            command=f"paper {spec.name}", command_line=cfg.command_line)
    check_not_held(out)  # before any controller is built
    # checked before the directory is created or taken: a run refused for its input leaves none behind
    plan = plan_arena(arena_cfg)
    for row in played_rows:  # a row stands for an arm mode: a controller given for it must play with that one
        mode = plan.specs[row.controller].arm_mode
        if mode != row.arm_mode:
            given = f"--contender {row.key}={row.controller}" if row.key in cfg.contenders else row.controller
            raise ConfigError(f"{given}: it plays with the arm {mode!r}, and {spec.name}'s row {row.key} "
                              f"({row.row}) stands for the arm {row.arm_mode!r}; give that row a controller of arm "
                              f"{row.arm_mode!r}")
    # held across the trials and the paper files: a resumed run on the directory must not interleave with them
    with hold_results_dir(out) as lock:
        start = time.perf_counter()
        arena = play_arena(plan, lock=lock)
        wall = time.perf_counter() - start
        records = arena.records
        by_controller: dict[str, list[TrialRecord]] = {}
        for record in records:
            by_controller.setdefault(record.controller, []).append(record)
        key_to_controller = {c.key: c.controller for c in played_rows}
        comparisons = []
        for contrast in spec.contrasts:
            a, b = key_to_controller.get(contrast.a), key_to_controller.get(contrast.b)
            if a is None or b is None:
                continue
            for band in scenario.bands:
                cell_a = [r for r in by_controller.get(a, []) if r.band == band]
                cell_b = [r for r in by_controller.get(b, []) if r.band == band]
                for metric in spec.paired_metrics:
                    pair = compare_pair(cell_a, cell_b, a=contrast.a, b=contrast.b, band=band, metric=metric)
                    comparisons.append(PaperComparison(question=contrast.question, pair=pair))
        # Holm over the table's tests that can reach alpha, the family its verdicts weigh (paper.json's p_holm)
        comparisons = [dataclasses.replace(c, pair=pair)
                       for c, pair in zip(comparisons, holm_family([c.pair for c in comparisons]), strict=True)]
        wall_by = {c: sum(r.wall_s for r in rs) / len(rs) for c, rs in by_controller.items() if rs}
        workers = cfg.workers or os.cpu_count() or 1  # the local pool's size (`wbc.arena.executors.LocalExecutor`)
        warm_by = {c: w for c, rs in by_controller.items()
                   if (w := warm_trial_wall_s([r.wall_s for r in rs], workers)) is not None}
        band_columns, columns_note = paper_columns_of(spec, scenario, published=published)
        result = PaperTableResult(
            spec=spec, contenders=contenders,
            scenario={"name": scenario.name, "version": scenario.version, "path": scenario.path,
                      "hash": scenario.hash, "published": published, "duration_s": scenario.duration_s},
            bands=scenario.bands,
            band_columns=band_columns, columns_note=columns_note,
            trials=cfg.trials, seeds=tuple(range(cfg.seeds)), summary=arena.summary,
            comparisons=tuple(comparisons), failures=arena.failures, curve=arena.curve,
            trial_wall_s=wall_by, warm_wall_s=warm_by, out_dir=arena.out_dir, played=arena.played, stored=len(records),
            wall_s=wall,
            workers=cfg.workers, controller_errors=arena.controller_errors)
        try:
            write_text(arena.out_dir / "paper.txt", format_paper_table(result))
            write_text(arena.out_dir / "paper.json", json.dumps(result.as_dict(), indent=2))
        except OSError as exc:
            raise unwritable(exc.filename or arena.out_dir, exc, arena.out_dir, stored=len(records)) from exc
        mark_complete(arena.out_dir, len(records))  # last: the paper's files are the run's too
    return result
