"""The arena: play every (controller, trial) pair of a scenario, store each result at once, summarise and report.

``wbc run`` and ``wbc compare`` are thin wrappers around `run_arena`: `plan_arena` (every check that needs no results
directory; the controllers resolved), then `play_arena`. ``wbc paper`` calls the two itself and takes the directory
between them, so that a refused run leaves no directory behind. Trials are paired: every controller plays the
very same trials, so differences between controllers come with paired confidence intervals and paired tests.

With ``until_significant`` (``wbc compare --until-significant``) the trials are played round by round (a round: one
trial index and seed, in every band, by every controller) and the run stops at the end of the first round after
which the sequential test (`wbc.arena.sequential`) has settled every pair's success difference in every band; the
trial budget (bands x seeds x trials) is the most it plays. The report breaks the records down by where each
controller fails (`wbc.arena.breakdown`), with the pushes re-drawn from the scenario.

A controller that fails on a trial (raises, or returns a command the robot refuses) has that trial recorded with the
outcome ``controller_error`` and the run goes on; one that fails on ``max_consecutive_errors`` trials in a row is
stopped while the others finish (`wbc.arena.error_guard`). The result lists each failing controller
(`ArenaResult.controller_errors`), and ``summary.json`` counts every outcome per controller and band.
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import hashlib
import itertools
import os
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wbc.arena.breakdown import breakdown, push_outcomes, recovery_curve
from wbc.arena.controller_settings import ControllerSettings, identical_settings
from wbc.arena.error_guard import DEFAULT_MAX_CONSECUTIVE_ERRORS, ControllerErrors, ErrorGuard
from wbc.arena.executors import EXECUTORS, VIEWED_TIME_LIMIT, LocalExecutor, RayExecutor, TrialTask
from wbc.arena.finish import finish_results
from wbc.arena.identity import (
    MAX_CONSECUTIVE_ERRORS,
    MAX_RUN_TRIALS,
    MAX_SEED,
    MAX_TRIAL_TIME_LIMIT_S,
    MAX_TRIALS,
    MIN_TRIAL_TIME_LIMIT_S,
    ControllerFile,
    ScenarioRef,
    SequentialStop,
    SimulatedRunIdentity,
)
from wbc.arena.progress import progress
from wbc.arena.report import summarize
from wbc.arena.results import ResultsStore, check_out_dir, episode_path, file_name_part, mark_complete, unwritable
from wbc.arena.run_environment import mixed, report_lines
from wbc.arena.runner import TickObserver
from wbc.arena.sequential import SequentialComparison
from wbc.arena.sim_trial import check_rate
from wbc.arena.stats import in_canonical_order
from wbc.arena.summary import Summary
from wbc.arena.trial_record import TrialRecord
from wbc.control.protocol import Controller, HasSettings
from wbc.control.registry import ControllerSpec, check_shipped_weights, get_controller
from wbc.errors import ClusterError, ConfigError, ResultsDirError, UnknownNameError
from wbc.hardware.mujoco.robot import MujocoRobotConfig
from wbc.output_files import DirectoryLock
from wbc.robots.registry import get_robot
from wbc.scenario import Scenario, load_scenario, warn_if_unpublished
from wbc.scenario.scenario import fallback_note
from wbc.scenario.trial import Trial

__all__ = ["VIEWED_TIME_LIMIT", "ArenaConfig", "ArenaPlan", "ArenaResult", "arms_note", "arms_played", "play_arena",
           "plan_arena", "run_arena"]



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
        workers: local worker processes, or with the Ray executor and no `address` the CPUs of the Ray it starts
            on this machine (None: all cores).
        address: Ray cluster address (None: a Ray started on this machine); Ray executor only.
        resume: finish an interrupted run in `out_dir`.
        drop_bad_rows: with `resume`, drop the rows of ``trials.csv`` the results store refuses (edited, corrupted,
            repeated, of another scenario file; `wbc.arena.trial_record.scan_csv`) and play their trials again;
            off: such a row stops the run with its file and line.
        progress: show a progress bar on stderr.
        no_push: play the scenario's trials without their pushes (commands, terrain and domain unchanged).
        debug_truth: throw the controllers' ground-truth debug switch (base state from the simulator).
        save_episodes: also store every trial's episode log (``episodes/<controller>/<band>-s<seed>-t<i>.npz``,
            for replay with ``wbc view --episode``).
        observer: watches every tick (``wbc run --view``); trials then run one by one in this process (local
            executor only).
        controller_configs: a ``--controller-config`` TOML file for a plug-in, by controller name.
        io_files: an ``--io`` file for an ``onnx:PATH`` policy, by controller name.
        until_significant: play round by round and stop once the sequential test has settled every tested success
            difference (local executor only; `trials` is then the most played per band and seed).
        alpha: the sequential test's family-wise significance level.
        sequential_pairs: the (A, B) controller pairs the sequential test watches (empty: every pair).
        max_consecutive_errors: a controller that fails (raises, or returns an invalid command) on this many trials
            in a row is stopped, its remaining trials not played; 0: never stopped.
        trial_time_limit_s: the wall time a trial may take in its worker [s]; a trial still playing then (a
            controller that hangs) has its worker ended and is recorded as its controller's error, and the run goes
            on (None: no limit). Results then depend on the machine's speed, so a run's results are reproducible only
            where no trial comes near the limit: it is a guard against hangs, not a deadline. Trials then play in
            worker processes even with one worker; not with a live view.
        isolated: with the local executor and one worker, play the trials in a worker process all the same (the
            command line's default; ``--in-process`` turns it off): a controller that ends its process
            (``os._exit``, a crash in native code) then costs only its own trial. False plays them in this process,
            where such a controller ends the run (the trials recorded before it are kept for ``resume``). Ignored with
            an observer, whose trials play in this process.
        command: the wbc command that plays the run (``compare``, ``paper table1`` ...), recorded in ``run.json``:
            a resume by another is refused (None: not recorded, nothing compared).
        command_line: the command line, as ``run.json``'s ``sessions`` record it (``wbc compare ...``).
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
    drop_bad_rows: bool = False
    progress: bool = True
    no_push: bool = False
    debug_truth: bool = False
    save_episodes: bool = False
    observer: TickObserver | None = None
    controller_configs: Mapping[str, Path] = field(default_factory=dict)
    io_files: Mapping[str, Path] = field(default_factory=dict)
    until_significant: bool = False
    alpha: float = 0.05
    sequential_pairs: tuple[tuple[str, str], ...] = ()
    max_consecutive_errors: int = DEFAULT_MAX_CONSECUTIVE_ERRORS
    trial_time_limit_s: float | None = None
    isolated: bool = False
    command: str | None = None
    command_line: str | None = None

    def __post_init__(self) -> None:
        if not self.controllers:
            raise ConfigError("at least one controller is needed: name one (wbc run stand) or several (wbc compare mpc "
                              "learned)")
        if len(set(self.controllers)) != len(self.controllers):
            raise ConfigError(f"controllers repeat: {', '.join(self.controllers)}; name each controller once")
        if self.save_episodes:
            folders: dict[str, str] = {}
            for name in self.controllers:
                # case-folded: on a case-insensitive file system (macOS, Windows) H8 and h8 are one folder
                other = folders.setdefault(file_name_part(name).casefold(), name)
                if other != name:  # one would overwrite the other's episodes
                    same = ("" if file_name_part(other) == file_name_part(name) else
                            f" and episodes/{file_name_part(other)}, one folder where case is not told apart")
                    raise ConfigError(
                        f"{other} and {name} would store their episodes in one folder, "
                        f"episodes/{file_name_part(name)}{same} (a character other than a letter, a digit, '.', '_' "
                        "or '-' is written '_'): name a plug-in apart with a label (package.module:factory@LABEL) "
                        "that differs in more than case, or save the episodes of one of them in a run of its own")
        if self.executor not in EXECUTORS:
            raise UnknownNameError("executor", self.executor, EXECUTORS)
        # the bounds run.json's reader takes (`wbc.arena.identity`): a run it could not resume is refused unplayed
        if not 1 <= self.trials <= MAX_TRIALS:
            raise ConfigError(f"--trials must be in [1, {MAX_TRIALS}], got {self.trials}; pass --trials 1 or more, or "
                              "split the study")
        if not self.seeds:
            raise ConfigError("at least one seed is needed; pass --seeds 1 or more")
        bad_seeds = [seed for seed in self.seeds if not 0 <= seed <= MAX_SEED]
        if bad_seeds:
            raise ConfigError(f"seeds must be in [0, {MAX_SEED}], got {bad_seeds[0]}")
        if self.address is not None and self.executor != "ray":
            raise ConfigError(f"--address {self.address} names a Ray cluster, which the {self.executor} executor "
                              "does not use: add --executor ray, or leave --address out")
        if self.address is not None and self.workers is not None:
            raise ConfigError(f"--workers {self.workers} with --address {self.address}: a Ray cluster's CPUs are its "
                              "own; --workers sizes the local pool, or the Ray started on this machine without "
                              "--address")
        if self.observer is not None and self.executor != "local":
            raise ConfigError("a live view (--view) watches trials played in this process: use the local executor")
        if self.until_significant:
            if len(self.controllers) < 2:
                raise ConfigError("--until-significant compares controllers: name two or more (wbc compare A B ...)")
            if self.executor != "local":
                raise ConfigError("--until-significant plays trials round by round as the test asks for them: use the "
                                  "local executor")
        if self.drop_bad_rows and not self.resume:
            raise ConfigError("--drop-bad-rows drops refused rows of a results directory being resumed: pass it with "
                              "--resume")
        if not 0.0 < self.alpha < 1.0:
            raise ConfigError(f"alpha must be in (0, 1), got {self.alpha}; pass a significance level such as 0.05")
        if not 0 <= self.max_consecutive_errors <= MAX_CONSECUTIVE_ERRORS:
            raise ConfigError(f"--max-consecutive-errors must be in [0, {MAX_CONSECUTIVE_ERRORS}] (0: never stop a "
                              f"controller), got {self.max_consecutive_errors}")
        if self.trial_time_limit_s is not None:
            limit = self.trial_time_limit_s
            number = isinstance(limit, (int, float)) and not isinstance(limit, bool)
            if not number or not MIN_TRIAL_TIME_LIMIT_S <= limit <= MAX_TRIAL_TIME_LIMIT_S:
                raise ConfigError(f"--trial-time-limit must be a number of seconds from {MIN_TRIAL_TIME_LIMIT_S:g} to "
                                  f"{MAX_TRIAL_TIME_LIMIT_S:g} (a week), got {limit!r}: it guards against a "
                                  "controller that hangs, far above what a trial takes")
            if self.observer is not None:
                raise ConfigError(VIEWED_TIME_LIMIT)
            if self.executor != "local":
                raise ConfigError("--trial-time-limit is enforced in the local pool's workers, not on Ray: use the "
                                  "local executor, or leave --trial-time-limit out")
        for a, b in self.sequential_pairs:
            if a not in self.controllers or b not in self.controllers or a == b:
                raise ConfigError(f"sequential pair ({a}, {b}) must name two different controllers played; "
                                  f"controllers: {', '.join(self.controllers)}")
        for option, files in (("--controller-config", self.controller_configs), ("--io", self.io_files)):
            for name in files:
                if name not in self.controllers:
                    raise ConfigError(f"{option} names {name}, which is not played; controllers: "
                                      f"{', '.join(self.controllers)}")


@dataclass(frozen=True)
class ArenaResult:
    """What `run_arena` produced.

    Attributes:
        summary: the run's summary (``summary.json`` is its `Summary.to_json`).
        records: every record of the run, this call's and those resumed from disk, in canonical order (controllers
            as named, bands, seeds, trials): what the summary was computed from, so that nothing re-reads
            ``trials.csv``.
        failures: where each controller fails (``failures.json``'s ``breakdown``, `wbc.arena.breakdown.breakdown`).
        curve: the push-recovery curve (``failures.json``'s ``push_recovery``).
        out_dir: the results directory.
        played: trials played by this call (not counting those resumed from disk).
        wall_s: wall time of this call [s].
        physics_steps: physics steps simulated by this call.
        arms_differ: the controllers played different arm modes: what each carried (`arms_note`); None when they
            played the same robot.
        budget: trials the run could have played (controllers x bands x seeds x trials); more than the trials stored
            when the sequential test stopped it early, or a controller was stopped for its errors.
        controller_errors: each controller that failed on at least one trial (stored ones included, on resume), in
            the order the controllers were named; empty when none did.
    """

    summary: Summary
    records: tuple[TrialRecord, ...]
    failures: dict[str, Any]
    curve: dict[str, Any]
    out_dir: Path
    played: int
    wall_s: float
    physics_steps: int
    budget: int = 0
    controller_errors: tuple[ControllerErrors, ...] = ()
    arms_differ: str | None = None


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


@dataclass(frozen=True, kw_only=True)
class ArenaPlan:
    """A run checked and resolved, its results directory not touched yet (`plan_arena`): what `play_arena` plays.

    Attributes:
        cfg: what to play, and where to store it.
        specs: each controller, resolved once, by name.
        scenario: the scenario, loaded.
        published: the scenario is the published version of its file (`wbc.scenario.warn_if_unpublished`).
        bands: the bands played.
        trials: every trial of the run, in order (without their pushes with `ArenaConfig.no_push`).
        identity: what the run is (``run.json``'s ``config``).
        arms: what each controller's robot carries (`arms_played`), by name.
        arms_differ: `arms_note` when the controllers play different arm modes, else None.
        settings: the settings of each plug-in built from a ``--controller-config`` file, by name (recorded in
            ``run.json``'s ``controllers.NAME.settings`` and listed in the report).
        identical: the groups of controllers that run one class with identical settings on one robot
            (`identical_settings`), warned of and listed in the report.
    """

    cfg: ArenaConfig
    specs: Mapping[str, ControllerSpec]
    scenario: Scenario
    published: bool
    bands: tuple[str, ...]
    trials: tuple[Trial, ...]
    identity: SimulatedRunIdentity
    arms: Mapping[str, str] = field(default_factory=dict)
    arms_differ: str | None = None
    settings: Mapping[str, ControllerSettings] = field(default_factory=dict)
    identical: tuple[tuple[str, ...], ...] = ()


def run_arena(cfg: ArenaConfig, *, lock: DirectoryLock | None = None) -> ArenaResult:
    """Run (or resume) a comparison and write its results directory: `plan_arena`, then `play_arena`.

    Args:
        cfg: what to play, and where to store it.
        lock: as `play_arena`'s.

    It raises what `plan_arena` raises (the input refused, before the directory is touched), then what `play_arena`
    raises (the directory refused, a file of it that cannot be written, a ``trials.csv`` row refused). A controller's
    failure on a trial is not raised: it is recorded (outcome ``controller_error``) and reported in
    `ArenaResult.controller_errors`.
    """
    return play_arena(plan_arena(cfg), lock=lock)


def plan_arena(cfg: ArenaConfig) -> ArenaPlan:
    """Check a run and resolve what it plays, before its results directory is created, locked or read.

    Every refusal that does not depend on what the directory holds comes from here: a command that takes the
    directory itself (``wbc paper``, `wbc.arena.results.hold_results_dir`) plans first, so that a run refused for its
    input leaves no directory behind, as `run_arena` leaves none.

    Raises:
        UnknownNameError: an unknown controller name or band (the message lists the valid ones).
        ResultsDirError: `ArenaConfig.out_dir` is a file, or a file the run writes there is a directory.
        PolicyFileError: a ``policy:PATH`` file that is missing or malformed, or shipped weights a registry
            controller plays that are (changed since their export: their checksum).
        PluginError: a plug-in that cannot be imported, or whose factory raises or builds no controller.
        ScenarioError: the scenario file is invalid.
        ConfigError: a controller for another robot than the scenario's, a plug-in's rate that is no whole number of
            physics steps, or more trials than a run plays (`MAX_RUN_TRIALS`).
    """
    check_out_dir(cfg.out_dir)  # before any controller is built or trial played: the run could not store its results
    # each name resolved once, here; the tasks carry the spec to the workers
    specs = _resolve(cfg)
    scenario = load_scenario(cfg.scenario)
    settings: dict[str, ControllerSettings] = {}
    built: dict[str, tuple[str, Controller]] = {}
    for name, spec in specs.items():
        if not spec.drives(scenario.robot):
            robots = ", ".join(spec.robots or ())
            raise ConfigError(f"controller {name} drives {robots}, but scenario {cfg.scenario} is played by "
                              f"{scenario.robot}; choose a controller for {scenario.robot}, or a scenario for {robots}")
        # shipped weights are read in each trial's worker: a damaged file is refused here, before any trial and
        # before the results directory exists, as a policy:PATH file is, not recorded as every trial's error
        check_shipped_weights(spec)
        if spec.kind in ("plug-in", "entry point"):
            # outside code is built once here, so a factory that raises or builds no controller fails before any
            # trial, in this process, with its own message
            # and its rate is checked there too: a rate of 0 or a period that is no whole number of physics steps is
            # refused before any trial, not in each one
            ctrl = spec.make(get_robot(scenario.robot, spec.arm_mode))
            built[name] = (spec.arm_mode, ctrl)
            check_rate(ctrl, name, MujocoRobotConfig().timestep)
            recorded = ControllerSettings.of(spec, ctrl)  # what its file set, and what it runs with
            if recorded is not None:
                settings[name] = recorded
    identical = _identical_settings(specs, built, scenario.robot)
    for names in identical:  # said before anything plays
        print(f"wbc: warning: {identical_line(names)}", file=sys.stderr)
    bands = cfg.bands or scenario.bands
    for band in bands:
        if band not in scenario.bands:
            raise UnknownNameError("band", band, scenario.bands)
    budget = len(cfg.controllers) * len(bands) * len(cfg.seeds) * cfg.trials
    if budget > MAX_RUN_TRIALS:  # before the trials are listed: a list of billions would fill the memory first
        raise ConfigError(f"this run would play {budget:,} trials ({len(cfg.controllers)} controllers x "
                          f"{len(bands)} bands x {len(cfg.seeds)} seeds x {cfg.trials} trials), more than the "
                          f"{MAX_RUN_TRIALS:,} one run plays; pass fewer --seeds or --trials, or split the study")
    note = fallback_note(cfg.scenario, scenario)
    if note is not None:
        print(f"wbc: note: {note}", file=sys.stderr)
    arms = {name: arms_played(scenario.robot, spec.arm_mode) for name, spec in specs.items()}
    arms_differ = arms_note(scenario.robot, {name: spec.arm_mode for name, spec in specs.items()})
    if arms_differ is not None:
        print(f"wbc: note: {arms_differ}", file=sys.stderr)
    published = warn_if_unpublished(scenario)
    trials = scenario.trials(bands, list(cfg.seeds), cfg.trials)
    if cfg.no_push:
        trials = [dataclasses.replace(t, pushes=()) for t in trials]
    # the options left unset are absent from run.json: a run naming one at its default resumes a run that did not
    identity = SimulatedRunIdentity(
        controllers=tuple(cfg.controllers),
        scenario=ScenarioRef(path=scenario.path, name=scenario.name, version=scenario.version,
                             hash=scenario.hash, published=published),
        bands=tuple(bands), seeds=tuple(cfg.seeds), trials=cfg.trials, no_push=cfg.no_push,
        debug_truth=cfg.debug_truth,
        until_significant=(SequentialStop(alpha=cfg.alpha, pairs=_tested_pairs(cfg)) if cfg.until_significant
                           else None),
        controller_files=tuple(ControllerFile(controller=name, path=f["path"], sha256=f["sha256"])
                               for name, f in _files_of(specs).items()),
        max_consecutive_errors=cfg.max_consecutive_errors,
    )
    return ArenaPlan(cfg=cfg, specs=specs, scenario=scenario, published=published, bands=tuple(bands),
                     trials=tuple(trials), identity=identity, arms=arms, arms_differ=arms_differ,
                     settings=settings, identical=tuple(identical))


def identical_line(names: Sequence[str]) -> str:
    """What a run says of controllers that play with identical settings (`identical_settings`)."""
    return (f"{' and '.join(names)} run the same controller with identical settings on the same robot: they play "
            "bit-identical trials and only add tests to the verdict's family; drop all but one, or give each other "
            "settings")


def _identical_settings(specs: Mapping[str, ControllerSpec], built: dict[str, tuple[str, Controller]],
                        robot: str) -> list[tuple[str, ...]]:
    """The groups of `specs` that would play bit-identical trials (`identical_settings`).

    `built` holds the plug-ins built to check them; when one of them says its settings, the registry's controllers
    that can say theirs are built too (the registry's ``mpc`` beside a variant of it with no file).
    """
    if any(isinstance(ctrl, HasSettings) for _, ctrl in built.values()):
        for name, spec in specs.items():
            factory = getattr(spec.make, "func", spec.make)
            if (name not in built and spec.kind == "registry" and isinstance(factory, type)
                    and issubclass(factory, HasSettings)):
                built[name] = (spec.arm_mode, spec.make(get_robot(robot, spec.arm_mode)))
    return identical_settings({name: built[name] for name in specs if name in built})


def arms_played(robot: str, arm_mode: str) -> str:
    """What `robot` carries in `arm_mode`, for a run's report: the mode and the whole robot's mass."""
    mass = _robot_mass(robot, arm_mode)
    what = {"none": "no arm", "locked": "its arm locked", "actuated": "its arm actuated"}[arm_mode]
    return f"{robot} with {what} ({mass:.2f} kg)"


def arms_note(robot: str, arm_modes: Mapping[str, str]) -> str | None:
    """A note for controllers that play `robot` in different arm modes (controller name -> mode); None if they do not.

    The arena gives every controller the same trials (pushes, ground, commands, domain), each on the robot its arm
    mode builds: a controller without an arm plays a lighter robot than one with it, and a locked arm is carried
    where an actuated one can also be swung. Such a comparison is legitimate (the paper's tables rank all three), but
    its differences are the robots' as much as the controllers', and the pairing does not remove that.
    """
    if len(set(arm_modes.values())) < 2:
        return None
    groups: dict[str, list[str]] = {}
    for name, mode in arm_modes.items():
        groups.setdefault(mode, []).append(name)
    said = "; ".join(f"{', '.join(names)}: {arms_played(robot, mode)}" for mode, names in groups.items())
    return (f"the controllers play different robots: {said}. Every trial's pushes, ground and commands are the same "
            "for each, the robot is not: a difference between them can come from the arm (its mass, where it is "
            "held, whether it moves) as much as from the controller. To compare the controllers alone, play them in "
            "one arm mode (the -locked and -noarm variants; arm_mode in an ONNX policy's I/O file)")


@functools.cache
def _robot_mass(robot: str, arm_mode: str) -> float:
    # imported here: only a run's plan needs the model, and the trials' workers import this module
    import pinocchio as pin

    from wbc.robots.pinocchio_model import build_pinocchio

    return float(pin.computeTotalMass(build_pinocchio(get_robot(robot, arm_mode)).model))


def play_arena(plan: ArenaPlan, *, lock: DirectoryLock | None = None) -> ArenaResult:
    """Play a planned run (`plan_arena`), or resume it, and write its results directory.

    Args:
        plan: the run, checked and resolved.
        lock: `ArenaConfig.out_dir`'s lock, already held by the caller (`wbc.arena.results.hold_results_dir`), who
            writes files of its own there after the run, marks it complete (`wbc.arena.results.mark_complete`) and
            then gives it back; None: the run takes the lock, marks the run complete once its files are written
            (``run.json``'s ``complete``, written last) and gives the lock back.

    Raises:
        ResultsDirError: a results directory that belongs to another run, or that misses trials at the end (other
            than those of a controller stopped for its errors), or that another run holds
            (`wbc.arena.results.LOCK_FILE`), or a file of it that cannot be written (a full disk, a quota, no
            permission: the message names it, and says that the trials stored are kept for ``--resume``).
        RecordError: a ``trials.csv`` row refused on `ArenaConfig.resume` without `ArenaConfig.drop_bad_rows`, or
            a malformed ``run.json``.
        ClusterError: on Ray, a cluster that cannot be reached (before the results directory is touched), or a
            worker that runs another wbc, packages or controller files, or a cluster that keeps failing a task (the
            trials stored are kept for ``--resume``; `wbc.arena.executors.RayExecutor`).

    A controller's failure on a trial is not raised: it is recorded (outcome ``controller_error``) and reported in
    `ArenaResult.controller_errors`.
    """
    cfg, specs, scenario, published, bands = plan.cfg, plan.specs, plan.scenario, plan.published, plan.bands
    trials = list(plan.trials)
    # before the results directory: a refused executor leaves none
    executor = (RayExecutor(cfg.address, cfg.workers) if cfg.executor == "ray" else
                LocalExecutor(cfg.workers, cfg.observer, isolated=cfg.isolated))
    if isinstance(executor, RayExecutor):
        executor.connect()  # before the results directory: a cluster that cannot be reached leaves none
    session = {"command": cfg.command, "command_line": cfg.command_line, "cwd": os.getcwd(),
               "executor": _described(executor, cfg), "workers": _workers(executor),
               "trial_time_limit_s": cfg.trial_time_limit_s}
    inputs = {"scenario": Path(scenario.path), **{f"controller-config {name}": path
                                           for name, path in cfg.controller_configs.items()}}
    try:
        store = ResultsStore(cfg.out_dir, plan.identity, resume=cfg.resume,
                             controllers={name: _recorded(spec, plan.settings.get(name))
                                          for name, spec in specs.items()},
                             drop_bad_rows=cfg.drop_bad_rows, lock=lock, session=session, inputs=inputs)
    except BaseException:
        if isinstance(executor, RayExecutor):
            executor.close()
        raise
    try:  # the directory stays locked until its summary and report are written (and after, with a caller's lock)
        done = store.done()
        rounds = _Rounds(trials, cfg, bands) if cfg.until_significant else None
        # a controller's errors in a row are counted in the order its trials are handed out
        order = [t.key for t in trials] if rounds is None else rounds.trial_order()
        guard = ErrorGuard(cfg.controllers, cfg.max_consecutive_errors, order)
        guard.observe_all(store.records)  # a controller stopped before stays stopped

        def where(t: Trial, c: str) -> str | None:
            if not cfg.save_episodes:
                return None
            path = episode_path(store.dir, c, t.band, t.seed, t.index)
            path.parent.mkdir(parents=True, exist_ok=True)
            return str(path)

        def task(t: Trial, c: str) -> TrialTask:
            return TrialTask(trial=t, controller=specs[c], debug_truth=cfg.debug_truth, episode_path=where(t, c),
                             time_limit_s=cfg.trial_time_limit_s)

        total = len(cfg.controllers) * len(trials)
        if rounds is not None:
            rounds.advance(store.records, guard.counted)  # a resumed run's complete rounds count before any new trial
            tasks = rounds.tasks(task, done, guard.stopped)
            todo = total - len(done & {(c, *t.key) for t in trials for c in cfg.controllers})
        else:
            # trial by trial, every controller in turn: pairs finish together and the progress estimate mixes fast and
            # slow controllers from the start (the order does not change a result); handed out lazily, so that a
            # controller stopped for its errors gets no more
            keys = [(t, c) for t in trials for c in cfg.controllers if (c, *t.key) not in done]
            tasks = (task(t, c) for t, c in keys if not guard.stopped(c))
            todo = len(keys)
        bar = progress(total, total - todo, cfg.progress)
        start = time.perf_counter()
        steps = 0
        played = 0
        physics_dt = MujocoRobotConfig().timestep
        try:
            for record in executor.run(tasks):
                store.append(record)
                guard.observe(record)
                played += 1
                steps += int(round(record.ttf * scenario.duration_s / physics_dt))
                if rounds is not None:
                    rounds.advance(store.records, guard.counted)
                if bar is not None:
                    bar.update(1)
        except ClusterError as exc:
            # the cluster's fault, not a controller's: no trial recorded for it, those stored kept for --resume
            raise ClusterError(f"{exc} ({len(store.records)} trial(s) stored in {store.dir})") from None
        except OSError as exc:
            # an episode's file or folder (--save-episodes) that could not be written: said as trials.csv's would be
            if not exc.filename or not Path(exc.filename).resolve().is_relative_to(store.dir.resolve()):
                raise
            raise unwritable(exc.filename, exc, store.dir, stored=len(store.records)) from exc
        finally:
            if bar is not None:
                bar.close()
        wall = time.perf_counter() - start
        # in canonical order: the store holds them in the order they finished, which varies between runs; a stopped
        # controller's trials beyond its stop, under way then in a pool, are stored and not counted
        mine = [r for r in store.records if r.scenario_hash == scenario.hash]
        records = in_canonical_order((r for r in mine if guard.counted(r)), cfg.controllers, scenario.bands)
        per_controller = len(trials) if rounds is None else rounds.played * len(bands)
        errors = guard.report(mine, per_controller)
        summary = summarize(records, scenario_name=scenario.name, scenario_hash=scenario.hash,
                            controllers=list(cfg.controllers), bands=list(bands), errors=errors,
                            sequential=rounds.comparison.as_dict() if rounds is not None else None,
                            robots=plan.arms, robots_note=plan.arms_differ)
        changed = mixed(store.environment)
        if changed is not None:
            summary = dataclasses.replace(summary, mixed_environments=tuple(changed))
        outcomes = push_outcomes(records, scenario.trial)
        failures = breakdown(records, outcomes, controllers=cfg.controllers, bands=bands, trial_of=scenario.trial)
        curve = recovery_curve(outcomes, controllers=cfg.controllers)
        meta = {
            "controllers": ", ".join(cfg.controllers),
            "robots": "; ".join(f"{name}: {arm}" for name, arm in plan.arms.items())
            + ("" if plan.arms_differ is None else " (NOT the same robot for every controller)"),
            "scenario": f"{scenario.name} v{scenario.version} ({scenario.path})",
            "scenario hash": scenario.hash,
            "published scenario": ("yes" if published else "NO (results are not comparable with published ones)")
            + {None: "", False: "; not when the run began (published at a resume; the same content)",
               True: "; it was when the run began (the same content)"}[store.identity.scenario.published_at_start],
            **({"settings files": {name: recorded.report_line() for name, recorded in plan.settings.items()}}
               if plan.settings else {}),
            **({"identical settings": "; ".join(identical_line(names) for names in plan.identical)}
               if plan.identical else {}),
            "bands": ", ".join(bands),
            "seeds": ", ".join(str(s) for s in cfg.seeds),
            "trials per band and seed": cfg.trials if rounds is None else rounds.trials_text(cfg.trials, cfg.seeds),
            "pushes": "REMOVED (--no-push)" if cfg.no_push else "as in the scenario",
            "state estimate": "GROUND TRUTH (--debug-truth)" if cfg.debug_truth else "estimator (as on hardware)",
            "executor": _described(executor, cfg),
            **({} if cfg.trial_time_limit_s is None else {
                "trial time limit": f"{cfg.trial_time_limit_s:g} s (--trial-time-limit: a trial past it is its "
                                    "controller's error, kept on --resume)"}),
            **report_lines(store.environment),
        }
        finish_results(store.dir, summary, records, meta, failures=failures, curve=curve,
                       scenario=f"{scenario.name} v{scenario.version}")
        expected = ({(c, *t.key) for t in trials for c in cfg.controllers} if rounds is None else
                    {key for i in rounds.begun for key in rounds.keys(i)})
        missing = expected - {r.run_key for r in records}
        if any(not guard.stopped(key[0]) for key in missing):
            raise ResultsDirError(f"{store.dir}: {len(expected) - len(missing)} of {len(expected)} trials stored; "
                                  "rerun with --resume to play the rest")
        if lock is None:  # a caller holding the lock writes files of its own after, and marks the run then
            mark_complete(store.dir, len(store.records))
        return ArenaResult(summary=summary, records=tuple(records), failures=failures, curve=curve, out_dir=store.dir,
                           played=played, wall_s=wall, physics_steps=steps, budget=total,
                           controller_errors=tuple(errors), arms_differ=plan.arms_differ)
    finally:
        if isinstance(executor, RayExecutor):
            executor.close()  # its run closes it too: this covers a run that ended before its first trial
        store.close()


def _recorded(spec: ControllerSpec, settings: ControllerSettings | None) -> dict[str, object]:
    """What ``run.json`` records of a controller: its provenance, and the settings its file gave it (if any)."""
    out = spec.provenance()
    if settings is not None:
        out["settings"] = settings.as_json()
    return out


def _described(executor: LocalExecutor | RayExecutor, cfg: ArenaConfig) -> str:
    """Where the trials play (`LocalExecutor.describe`, `RayExecutor.describe`), as the report and run.json say it."""
    if isinstance(executor, RayExecutor):
        return executor.describe()
    return executor.describe(time_limit=cfg.trial_time_limit_s is not None)


def _workers(executor: LocalExecutor | RayExecutor) -> int | None:
    """The trials a run plays at once: the local executor's workers, the CPUs given a Ray it starts.

    None where Ray chose them: a cluster's, or a Ray started here without ``--workers`` (every CPU).
    """
    return executor.workers if isinstance(executor, LocalExecutor) else executor.num_cpus


def _tested_pairs(cfg: ArenaConfig) -> tuple[tuple[str, str], ...]:
    return cfg.sequential_pairs or tuple(itertools.combinations(cfg.controllers, 2))


class _Rounds:
    """A sequential run's rounds (trial index, then seed), fed to the sequential test in that order as they complete.

    The test sees complete rounds in their fixed order, never trials in the order they finish (which depends on
    when robots fall; `wbc.arena.sequential`). The task generator checks the test before each new round: once every
    difference is settled it hands out no more, and the rounds already begun finish.
    """

    def __init__(self, trials: list[Trial], cfg: ArenaConfig, bands: Sequence[str]) -> None:
        self.controllers = cfg.controllers
        order = sorted({(t.index, t.seed) for t in trials})
        self.trials = {key: [t for t in trials if (t.index, t.seed) == key] for key in order}
        self.order = order
        self.comparison = SequentialComparison(_tested_pairs(cfg), bands, alpha=cfg.alpha)
        self.next = 0  # rounds fed to the test so far
        self.begun: set[int] = set()  # rounds with a task handed out or a record stored
        self._round_of = {key: i for i in range(len(order)) for key in self.keys(i)}
        self._by_key: dict[tuple[str, str, int, int], TrialRecord] = {}
        self._read = 0  # records of the store read so far

    @property
    def played(self) -> int:
        """Rounds begun: the results directory holds them in full when the run ends."""
        return len(self.begun)

    def trials_text(self, most: int, seeds: Sequence[int]) -> str:
        """The report's "trials per band and seed" of a sequential run: those played per seed, and why it stopped."""
        comparison = self.comparison
        if not comparison.settled:
            return f"{most} (the sequential test did not settle every difference)"
        per_seed = collections.Counter(self.order[i][1] for i in self.begun)
        played = (", ".join(f"{per_seed[s]} (seed {s})" for s in seeds) if len(seeds) > 1
                  else str(per_seed[seeds[0]]))
        after = comparison.settled_after or comparison.rounds
        text = f"{played} of at most {most}: the sequential test settled every difference after {after} rounds"
        extra = self.played - after
        if extra > 0:
            text += f" ({extra} more {'round was' if extra == 1 else 'rounds were'} under way then, and are played)"
        return text

    def keys(self, i: int) -> list[tuple[str, str, int, int]]:
        """The run keys (controller, band, seed, trial) of round `i`."""
        return [(c, *t.key) for t in self.trials[self.order[i]] for c in self.controllers]

    def trial_order(self) -> list[tuple[str, int, int]]:
        """The trials' keys (band, seed, trial) in the order `tasks` hands them out, round after round."""
        return [t.key for key in self.order for t in self.trials[key]]

    def advance(self, stored: Sequence[TrialRecord], counted: Callable[[TrialRecord], bool]) -> None:
        """Feed the test every round, from the next one on, that `stored` now holds complete.

        `stored` is the store's list of records, which only grows: each call reads the records added since the last.
        A record not `counted` (`ErrorGuard.counted`: beyond a stopped controller's stop) does not complete a round.
        By the time a round is complete up to it, every round before it is fed, so the trial that stopped its
        controller is known, and whether the record counts with it.
        """
        for record in stored[self._read:]:
            self._by_key[record.run_key] = record
            if record.run_key in self._round_of:
                self.begun.add(self._round_of[record.run_key])
        self._read = len(stored)
        while self.next < len(self.order):
            keys = self.keys(self.next)
            if not all(k in self._by_key and counted(self._by_key[k]) for k in keys):
                return
            self.comparison.add_round(self._by_key[k] for k in keys)
            self.next += 1

    def tasks(self, make: Callable[[Trial, str], TrialTask], done: set,
              stopped: Callable[[str], bool]) -> Iterator[TrialTask]:
        """The tasks not yet `done`, round by round, until the test has settled every difference.

        A round begun before (an interrupted run's) is finished even after the test has settled, so that the
        directory holds whole rounds only. A controller `stopped` for its errors gets no more tasks (its rounds then
        stay incomplete, and the test is not fed them).
        """
        for i in range(len(self.order)):
            if self.comparison.settled and i not in self.begun:
                continue
            self.begun.add(i)
            for t in self.trials[self.order[i]]:
                for c in self.controllers:
                    if (c, *t.key) not in done and not stopped(c):
                        yield make(t, c)
