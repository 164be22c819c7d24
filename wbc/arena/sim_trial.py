"""Simulated trials: the MuJoCo robot a trial is played on, and `run_trial` (set up, play, record).

`run_trial` resets the simulated robot to the trial's terrain and physical randomisation, schedules the trial's
pushes through the robot's perturbation hook, throws the controller's ground-truth debug switch when asked
(`wbc.control.protocol.TruthSwitch`), plays the episode with the runner's one loop (`wbc.arena.runner.run_episode`,
truth and falls from the simulator's capabilities), logs the pushes the robot met, and makes the `TrialRecord`.
A controller that fails during the trial (`wbc.arena.controller_failure.ControllerFailure`: it raised in ``reset`` or
``act``, or returned a command the robot refused) does not end the run: the trial is recorded with the outcome
``controller_error`` and a message naming the controller, the trial, the tick and the controller's own file:line;
so is a controller whose period is longer than the trial, which would never be asked to act. The loop checks every
tick that the simulation has not blown up (`wbc.arena.divergence.DivergenceCheck`): a trial that diverges is
recorded with the outcome ``diverged`` and NaN for the metrics of its motion.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import random
import sys
import time

import numpy as np
from threadpoolctl import threadpool_limits

from wbc.arena.controller_failure import ControllerFailure, read_counters
from wbc.arena.divergence import DivergenceCheck, SimulationDiverged
from wbc.arena.episode import Episode, EpisodeBuffer, PushLog
from wbc.arena.runner import TickObserver, run_episode
from wbc.arena.trial_record import TrialRecord
from wbc.control.protocol import TruthSwitch
from wbc.control.registry import get_controller
from wbc.control.spec import ControllerSpec
from wbc.errors import CONTROLLER_ERRORS, ConfigError, MissingCapabilityError
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.input_files import short
from wbc.physics_steps import nearest_rates
from wbc.scenario.trial import Trial

__all__ = ["check_rate", "run_trial", "seed_global_rngs", "simulated_robot", "trial_rng_seed"]

_ROBOTS: dict[tuple, MujocoRobot] = {}
"""Per-process cache of simulated robots: building a model costs ~50 ms, resetting one ~0.1 ms."""


def simulated_robot(trial: Trial, arm_mode: str) -> MujocoRobot:
    """The connected simulated robot for `trial`'s robot, terrain and `arm_mode`, built once per process."""
    key = (trial.robot, arm_mode, trial.terrain)
    robot = _ROBOTS.get(key)
    if robot is None:
        robot = MujocoRobot(MujocoRobotConfig(robot=trial.robot, arm_mode=arm_mode, terrain=trial.terrain))
        robot.connect()
        _ROBOTS[key] = robot
    return robot


def check_rate(ctrl: object, name: str, timestep: float) -> None:
    """Refuse a controller whose ``rate_hz`` is not a positive number whose period is a whole number of steps.

    Raises:
        ConfigError: the rate is not a finite positive number, or its period is not a multiple of `timestep`.
    """
    rate = getattr(ctrl, "rate_hz", None)
    if isinstance(rate, bool) or not isinstance(rate, int | float) or not math.isfinite(rate) or rate <= 0:
        raise ConfigError(f"controller {short(name)}: rate_hz must be a positive number of Hz, got {short(rate)}; "
                          f"give it a rate that divides 1/{timestep} Hz, such as 50")
    ratio = (1.0 / rate) / timestep
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        raise ConfigError(f"controller {short(name)}: period 1/{rate:g} s is not a multiple of the physics step "
                          f"{timestep:g} s; give the controller a rate that divides {1 / timestep:g} Hz: "
                          f"{nearest_rates(rate, timestep)}")


def run_trial(trial: Trial, controller: ControllerSpec | str, *, debug_truth: bool = False,
              observer: TickObserver | None = None, record_errors: bool = True) -> tuple[TrialRecord, Episode]:
    """Play `trial` in simulation with `controller`.

    With `debug_truth` the controller's ground-truth debug switch is thrown (it reads the simulator's base state
    instead of estimating it) and the record says so.

    Not thread-safe: the trial plays on the process's cached robot for its (robot, arm mode, terrain)
    (`simulated_robot`), which two threads would reset and step at once. Play trials at once in processes of their
    own (the arena's workers), or with a `MujocoRobot` each and `wbc.arena.runner.run_episode`.

    Args:
        trial: the trial.
        controller: the resolved controller (`wbc.control.registry.get_controller`), or its name, resolved here.
        debug_truth: throw the controller's ground-truth debug switch (`wbc.control.protocol.TruthSwitch`).
        observer: called after every tick (see `wbc.arena.runner.run_episode`).
        record_errors: record a controller's failure as the trial's outcome (the arena); False: raise it (a study
            or a bench, for which a broken controller is the end of the measurement).

    Returns:
        The trial's record and the episode log, with the pushes that began before it ended. A controller that
        failed (raised, or returned a command the robot refused, or has a period longer than the trial) gives a
        record with the outcome ``controller_error`` and the episode played before the failure; a simulation that
        diverged, one with the outcome ``diverged`` and the episode up to the tick that diverged.

    Raises:
        UnknownNameError: unknown controller name.
        ConfigError: the controller's period is not a whole number of physics steps.
        MissingCapabilityError: `debug_truth` for a controller without a ground-truth debug switch.
        ControllerFailure: the controller failed, and `record_errors` is False.
        ConfigError: the controller's period is longer than the trial, and `record_errors` is False.
    """
    spec = get_controller(controller) if isinstance(controller, str) else controller
    seed_global_rngs(trial, spec.name)
    # one BLAS thread: a multi-threaded product splits its sums differently, and the same trial would differ in its
    # last bits between an in-process run and a pool worker (which starts single-threaded)
    with threadpool_limits(limits=1, user_api="blas"):
        return _run_trial(trial, spec, debug_truth=debug_truth, observer=observer, record_errors=record_errors)


def trial_rng_seed(trial: Trial, controller: str) -> int:
    """The seed of the global random generators for `controller` playing `trial` (`seed_global_rngs`).

    Derived from the trial's identity: the scenario's content hash, the band, the seed, the trial index and the
    controller's name (a 32-bit integer: what numpy's legacy ``np.random.seed`` takes).
    """
    key = f"{trial.scenario_hash}\0{trial.band}\0{trial.seed}\0{trial.index}\0{controller}".encode()
    return int.from_bytes(hashlib.sha256(key).digest()[:4], "little")


def seed_global_rngs(trial: Trial, controller: str) -> None:
    """Seed the global random generators a plug-in may draw from for this trial: numpy's, Python's and torch's.

    Numpy's is its legacy global generator (``np.random.normal`` ...), Python's is `random`, torch's is seeded where
    torch is loaded (``torch.randn`` ...). The controllers of the toolkit draw from generators of their own, but a
    plug-in may draw from the global ones; seeded here from the trial's identity (`trial_rng_seed`) before the
    controller is built and again once it is built (`run_trial`), in every executor (the local pool, this process, a
    Ray worker), such a controller plays a trial the same whatever worker plays it, and after whichever trials that
    worker played before.
    """
    value = trial_rng_seed(trial, controller)
    np.random.seed(value)  # the legacy global generator: the one a plug-in may use
    random.seed(value)
    torch = sys.modules.get("torch")  # seeded where loaded: importing it here would cost every trial a second
    if torch is not None:
        torch.manual_seed(value)


def _run_trial(trial: Trial, spec: ControllerSpec, *, debug_truth: bool, observer: TickObserver | None,
               record_errors: bool) -> tuple[TrialRecord, Episode]:
    start = time.perf_counter()
    robot = simulated_robot(trial, spec.arm_mode)
    try:
        # a plug-in's factory that raises is refused before any trial (`wbc.arena.compare`); one that raises only
        # here (in a worker, for this trial) costs this trial
        ctrl = spec.make(robot.desc)
    except CONTROLLER_ERRORS as exc:  # any: the factory's code may not be ours
        # no controller, so no control period: the physics step stands in for the episode that never began
        empty = EpisodeBuffer(nq=7 + robot.num_joints).finish(duration_s=trial.duration_s,
                                                               control_dt=robot.config.timestep, fell=False,
                                                               fall_time_s=math.nan)
        failure = ControllerFailure(None, phase="build", tick=0, time_s=0.0, exc=exc, episode=empty)
        if not record_errors:
            raise failure from exc
        record = TrialRecord.of_trial(trial, controller=spec.name, episode=empty, counters={},
                                      wall_s=time.perf_counter() - start, debug_truth=debug_truth,
                                      error=failure.record_error(spec.name, trial))
        return record, empty
    check_rate(ctrl, spec.name, robot.config.timestep)
    # again once it is built: its acts draw the same whatever its constructor drew, and a torch its constructor
    # imported (a policy's first trial on this worker) is seeded too
    seed_global_rngs(trial, spec.name)
    if debug_truth:
        if not isinstance(ctrl, TruthSwitch):
            raise MissingCapabilityError(
                f"controller {spec.name!r} has no ground-truth debug switch (wbc.control.protocol.TruthSwitch) for "
                "--debug-truth; run it without --debug-truth, or debug a controller that estimates its base state "
                "(mpc)")
        ctrl.use_ground_truth(robot.base_truth)
    robot.reset(seed=trial.terrain_seed, domain=trial.domain)
    for push in trial.pushes:
        robot.apply_push(push)
    error = diverged = ""
    if int(round(trial.duration_s * ctrl.rate_hz)) < 1:
        # the runner refuses such an episode; the arena records it against the controller, as any failure of its own
        never = (f"controller {spec.name}, band {trial.band}, seed {trial.seed}, trial {trial.index}: never asked to "
                 f"act: its period 1/{ctrl.rate_hz} Hz is longer than the {trial.duration_s:g} s trial, so no control "
                 f"tick was played; give it a rate of at least {1.0 / trial.duration_s:g} Hz, or make the trial "
                 f"at least {1.0 / ctrl.rate_hz:g} s long (the scenario's duration, or a --duration that cut it)")
        if not record_errors:
            raise ConfigError(never)
        empty = EpisodeBuffer(nq=7 + robot.num_joints).finish(duration_s=trial.duration_s,
                                                               control_dt=1.0 / ctrl.rate_hz, fell=False,
                                                               fall_time_s=math.nan)
        record = TrialRecord.of_trial(trial, controller=spec.name, episode=empty, counters={},
                                      wall_s=time.perf_counter() - start, debug_truth=debug_truth, error=never)
        return record, empty
    try:
        episode = run_episode(robot, ctrl, trial.command, trial.duration_s, observer=observer,
                              divergence=DivergenceCheck())
        played_s = episode.survived_s
    except ControllerFailure as failure:
        if not record_errors:
            raise
        episode, error, played_s = failure.episode, failure.record_error(spec.name, trial), failure.time_s
    except SimulationDiverged as blown:
        episode, played_s = blown.episode, blown.time_s
        diverged = (f"controller {spec.name}, band {trial.band}, seed {trial.seed}, trial {trial.index}: "
                    f"{blown.describe()}")
    met = PushLog.of(p for p in trial.pushes if p.start < played_s)
    episode = dataclasses.replace(episode, pushes=met)
    counters, error = read_counters(ctrl, spec.name, trial, episode, error)
    if error and not record_errors:
        raise ControllerFailure(ctrl, phase="counters", tick=len(episode.t), time_s=played_s,
                                exc=RuntimeError(error), episode=episode)
    record = TrialRecord.of_trial(trial, controller=spec.name, episode=episode, counters=counters,
                                  wall_s=time.perf_counter() - start, debug_truth=debug_truth, error=error,
                                  diverged=diverged)
    return record, episode
