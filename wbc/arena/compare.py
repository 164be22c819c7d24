"""The arena: play every (controller, trial) pair of a scenario, store each result at once, summarise and report.

``wbc run`` and ``wbc compare`` are thin wrappers around `run_arena`. Trials are paired: every controller plays the
very same trials, so differences between controllers come with paired confidence intervals.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from wbc.arena.executors import EXECUTORS, LocalExecutor, RayExecutor, TrialTask
from wbc.arena.progress import progress
from wbc.arena.report import summarize, write_report
from wbc.arena.results import ResultsStore, episode_path
from wbc.arena.runner import TickObserver
from wbc.arena.stats import in_canonical_order
from wbc.control.registry import ControllerSpec, get_controller
from wbc.errors import ConfigError, ResultsDirError, UnknownNameError
from wbc.hardware.mujoco.robot import MujocoRobotConfig
from wbc.robots.registry import get_robot
from wbc.scenario import ScenarioError, check_published, load_scenario
from wbc.scenario.trial import Trial

__all__ = ["ArenaConfig", "ArenaResult", "run_arena"]


@dataclass(frozen=True, kw_only=True)
class ArenaConfig:
    """What to run and where.

    Attributes:
        controllers: controller registry names, in report order.
        scenario: path of the scenario file.
        bands: bands to play (empty: all).
        seeds: seeds to play.
        trials: trials per (band, seed).
        out_dir: results directory.
        executor: ``local`` or ``ray``.
        workers: local worker processes (None: all cores).
        address: Ray cluster address (None: a local Ray).
        resume: finish an interrupted run in `out_dir`.
        progress: show a progress bar on stderr.
        no_push: play the scenario's trials without their pushes (commands, terrain and domain unchanged).
        debug_truth: throw the controllers' ground-truth debug switch (base state from the simulator).
        save_episodes: also store every trial's episode log (``episodes/<controller>/<band>-s<seed>-t<i>.npz``,
            for replay with ``wbc view --episode``).
        observer: watches every tick (``wbc run --view``); trials then run one by one in this process (local
            executor only).
        controller_configs: a ``--controller-config`` TOML file for a plug-in, by controller name.
        io_files: an ``--io`` file for an ``onnx:PATH`` policy, by controller name.
    """

    controllers: tuple[str, ...]
    scenario: Path
    bands: tuple[str, ...] = ()
    seeds: tuple[int, ...] = (0,)
    trials: int = 10
    out_dir: Path = field(default_factory=lambda: Path("runs/arena"))
    executor: str = "local"
    workers: int | None = None
    address: str | None = None
    resume: bool = False
    progress: bool = True
    no_push: bool = False
    debug_truth: bool = False
    save_episodes: bool = False
    observer: TickObserver | None = None
    controller_configs: Mapping[str, Path] = field(default_factory=dict)
    io_files: Mapping[str, Path] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.controllers:
            raise ConfigError("at least one controller is needed: name one (wbc run stand) or several (wbc compare mpc "
                              "learned)")
        if len(set(self.controllers)) != len(self.controllers):
            raise ConfigError(f"controllers repeat: {', '.join(self.controllers)}; name each controller once")
        if self.executor not in EXECUTORS:
            raise UnknownNameError("executor", self.executor, EXECUTORS)
        if self.trials < 1:
            raise ConfigError(f"--trials must be >= 1, got {self.trials}; pass --trials 1 or more")
        if not self.seeds:
            raise ConfigError("at least one seed is needed; pass --seeds 1 or more")
        if self.observer is not None and self.executor != "local":
            raise ConfigError("a live view (--view) watches trials played in this process: use the local executor")
        for option, files in (("--controller-config", self.controller_configs), ("--io", self.io_files)):
            for name in files:
                if name not in self.controllers:
                    raise ConfigError(f"{option} names {name}, which is not played; controllers: "
                                      f"{', '.join(self.controllers)}")


@dataclass(frozen=True)
class ArenaResult:
    """What `run_arena` produced.

    Attributes:
        summary: the ``summary.json`` content.
        out_dir: the results directory.
        played: trials played by this call (not counting those resumed from disk).
        wall_s: wall time of this call [s].
        physics_steps: physics steps simulated by this call.
    """

    summary: dict
    out_dir: Path
    played: int
    wall_s: float
    physics_steps: int


def _resolve(cfg: ArenaConfig) -> dict[str, ControllerSpec]:
    """Each name resolved once, here: a policy or ONNX file is read and a plug-in imported in this process."""
    specs = {}
    for name in cfg.controllers:
        files = {key: path for key, path in (("config", cfg.controller_configs.get(name)),
                                             ("io", cfg.io_files.get(name))) if path is not None}
        specs[name] = get_controller(name, **files)
    return specs


def _files_of(specs: Mapping[str, ControllerSpec]) -> dict[str, dict[str, str]]:
    """The configuration files the controllers were resolved with, and their content hashes (for ``run.json``)."""
    return {name: {"path": spec.config_file,
                   "sha256": hashlib.sha256(Path(spec.config_file).read_bytes()).hexdigest()}
            for name, spec in specs.items() if spec.config_file is not None}


def run_arena(cfg: ArenaConfig) -> ArenaResult:
    """Run (or resume) a comparison and write its results directory.

    Raises:
        UnknownNameError: an unknown controller name (the message lists the valid ones).
        PolicyFileError: a ``policy:PATH`` file that is missing or malformed.
        ScenarioError: the scenario file is invalid.
        ConfigError: bad options, or a controller for another robot than the scenario's.
        ResultsDirError: a results directory that belongs to another run, or that misses trials at the end.
    """
    # each name resolved once, here; the tasks carry the spec to the workers
    specs = _resolve(cfg)
    scenario = load_scenario(cfg.scenario)
    for name, spec in specs.items():
        if not spec.drives(scenario.robot):
            robots = ", ".join(spec.robots or ())
            raise ConfigError(f"controller {name} drives {robots}, but scenario {cfg.scenario} is played by "
                              f"{scenario.robot}; choose a controller for {scenario.robot}, or a scenario for {robots}")
        if spec.kind in ("plug-in", "entry point"):
            # outside code is built once here, so a factory that raises or builds no controller fails before any
            # trial, in this process, with its own message
            spec.make(get_robot(scenario.robot, spec.arm_mode))
    bands = cfg.bands or scenario.bands
    for band in bands:
        if band not in scenario.bands:
            raise UnknownNameError("band", band, scenario.bands)
    try:
        check_published(scenario)
        published = True
    except ScenarioError as exc:
        published = False
        print(f"wbc: warning: {exc}", file=sys.stderr)
    trials = scenario.trials(bands, list(cfg.seeds), cfg.trials)
    if cfg.no_push:
        trials = [dataclasses.replace(t, pushes=()) for t in trials]
    identity = {
        "controllers": list(cfg.controllers),
        "scenario": {"path": str(cfg.scenario), "name": scenario.name, "version": scenario.version,
                     "hash": scenario.hash, "published": published},
        "bands": list(bands),
        "seeds": list(cfg.seeds),
        "trials": cfg.trials,
        "no_push": cfg.no_push,
        "debug_truth": cfg.debug_truth,
    }
    files = _files_of(specs)
    if files:  # only then, so that a run of registered controllers resumes a directory written before files existed
        identity["controller_files"] = files
    store = ResultsStore(cfg.out_dir, identity, resume=cfg.resume)
    done = store.done()
    def where(t: Trial, c: str) -> str | None:
        if not cfg.save_episodes:
            return None
        path = episode_path(store.dir, c, t.band, t.seed, t.index)
        path.parent.mkdir(parents=True, exist_ok=True)
        return str(path)

    # trial by trial, every controller in turn: pairs finish together and the progress estimate mixes fast and slow
    # controllers from the start (the order does not change a result)
    tasks = [TrialTask(trial=t, controller=specs[c], debug_truth=cfg.debug_truth, episode_path=where(t, c))
             for t in trials for c in cfg.controllers if (c, *t.key) not in done]
    total = len(cfg.controllers) * len(trials)
    executor = (RayExecutor(cfg.address) if cfg.executor == "ray" else LocalExecutor(cfg.workers, cfg.observer))
    bar = progress(total, total - len(tasks), cfg.progress)
    start = time.perf_counter()
    steps = 0
    physics_dt = MujocoRobotConfig().timestep
    try:
        for record in executor.run(tasks):
            store.append(record)
            steps += int(round(record.ttf * scenario.duration_s / physics_dt))
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
        store.close()
    wall = time.perf_counter() - start
    # in canonical order: the store holds them in the order they finished, which varies between runs
    records = in_canonical_order((r for r in store.records if r.scenario_hash == scenario.hash), cfg.controllers,
                                 scenario.bands)
    summary = summarize(records, scenario_name=scenario.name, scenario_hash=scenario.hash,
                        controllers=list(cfg.controllers), bands=list(bands))
    (store.dir / "summary.json").write_text(json.dumps(summary, indent=2), encoding="utf-8")
    meta = {
        "controllers": ", ".join(cfg.controllers),
        "scenario": f"{scenario.name} v{scenario.version} ({cfg.scenario})",
        "scenario hash": scenario.hash,
        "published scenario": "yes" if published else "NO (results are not comparable with published ones)",
        "bands": ", ".join(bands),
        "seeds": ", ".join(str(s) for s in cfg.seeds),
        "trials per band and seed": cfg.trials,
        "pushes": "REMOVED (--no-push)" if cfg.no_push else "as in the scenario",
        "state estimate": "GROUND TRUTH (--debug-truth)" if cfg.debug_truth else "estimator (as on hardware)",
        "executor": cfg.executor,
        **{k: v for k, v in store.environment.items() if k != "packages"},
        "packages": ", ".join(f"{k} {v}" for k, v in store.environment["packages"].items()),
    }
    write_report(store.dir, summary, records, meta)
    if len(records) != total:
        raise ResultsDirError(f"{store.dir}: {len(records)} of {total} trials stored; rerun with --resume to play the "
                              "rest")
    return ArenaResult(summary=summary, out_dir=store.dir, played=len(tasks), wall_s=wall, physics_steps=steps)
