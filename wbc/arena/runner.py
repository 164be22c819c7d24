"""The runner: the one loop that plays an episode on any `Robot`, the same for simulation and hardware.

Every control tick: ``state = robot.read()``, ``cmd = schedule.at(t)``, ``out = controller.act(state, cmd)``,
``robot.write(out)``, ``robot.advance(dt)``; then the episode log takes one row, the observer sees the tick and the
fall check runs. The runner owns timing: it times every ``act`` call and logs it (`Episode.act_s`), so a bench, or a
hardware trial, reads deadline misses from the episode instead of re-writing the loop. It also counts the ticks whose
command lay outside the robot's motor limits, which the robot clamped before sending (`Episode.clamped_ticks`): a
controller that asks for 1e5 N m is told so in the results, not silently saturated.

Where the base's true state comes from and how a fall is detected are capabilities of the robot
(`wbc.hardware.capabilities.TruthSource`, `FallDetector`: the simulator has both, a real robot may have motion capture),
or are handed in by the caller. Falls are checked at the control rate; a fall keeps the trunk on the ground for far
longer than a control period, so none is missed. An episode that ends with the trunk upside down (flung into the air by
a push, not yet landed) ends in a fall at its last tick. Setting a simulated trial up (robot, terrain, pushes) and
turning its episode into a record is `wbc.arena.sim_trial`. A robot behind a safety layer (`HasSafetyEvents`) has the
layer's transitions during the episode logged in it (`Episode.safety_events`). A controller that raises, or returns a
command the robot refuses, ends the episode with a `ControllerFailure` that says where (and, for a command of the joints
of another arm mode, how to declare that mode: `wbc.control.arm_mode_hint`) and carries the episode so far. Given a
`DivergenceCheck` (a simulated trial's), the loop checks the joints the robot reports before each ``act``, the trunk's
truth and the simulator's own warnings (`SimulatorHealth`) after each step, and ends an episode whose simulation blew up
with `SimulationDiverged` (its own outcome, never numbers in the means). An interruption while the episode plays
(Ctrl-C, or SIGTERM and SIGHUP where the command raises `KeyboardInterrupt` for them) ends it with
`EpisodeInterrupted`, a `KeyboardInterrupt` that carries the episode played up to the last complete tick: a caller
that catches `KeyboardInterrupt` stops as before, and a hardware trial damps its robot and keeps what was played. A
controller whose period is longer than the episode would never be asked to act: that is refused before the episode
starts.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Protocol, runtime_checkable

import numpy as np

from wbc.arena.controller_failure import ControllerFailure
from wbc.arena.divergence import DivergenceCheck, SimulationDiverged
from wbc.arena.episode import Episode, EpisodeBuffer, SafetyLog
from wbc.control.arm_mode_hint import arm_mode_hint
from wbc.control.protocol import Controller
from wbc.errors import CONTROLLER_ERRORS, CommandError, ConfigError, MissingCapabilityError
from wbc.hardware.capabilities import FallDetector, HasSafetyEvents, SimulatorHealth, TruthSource
from wbc.hardware.robot import Robot, command_bounds, exceeded_rows, within_bounds
from wbc.physics_steps import nearest_rates
from wbc.robots.conventions import upside_down
from wbc.robots.description import ARM_JOINTS
from wbc.scenario.trial import CommandSchedule
from wbc.types import BaseTruth, MotorCommand, VelocityCommand

__all__ = ["EpisodeInterrupted", "PreparingObserver", "TickObserver", "forget_played", "played_s", "run_episode"]

_playing: list[tuple[EpisodeBuffer, float] | None] = [None]
"""The log of the episode this process plays, and its control period: what `played_s` reads."""


def played_s() -> float | None:
    """The simulated time the episode in progress in this process has logged [s]: its whole control ticks played.

    For a thread that watches the trial from beside it (the arena's trial time limit, `wbc.arena.executors`), which
    records how far a trial got when it has to end the process. None before an episode begins in this process, or
    after `forget_played`.
    """
    playing = _playing[0]
    return None if playing is None else playing[0].rows * playing[1]


def forget_played() -> None:
    """Forget the episode `played_s` reads (called before a trial starts, so that the last one is not read for it)."""
    _playing[0] = None

TickObserver = Callable[[float, Robot, Controller, VelocityCommand], None]
"""Called after every control tick with (time after the tick [s], robot, controller, command); for viewers, benches
and studies. It may block (a paused viewer pauses the loop) but must not change the robot or the controller."""


@runtime_checkable
class PreparingObserver(Protocol):
    """A tick observer whose setup for a robot is slow (a viewer loading its meshes) and can be done beforehand.

    On a real robot the first ticks of an episode cannot wait for it: a hardware trial calls `prepare` before the
    robot is connected.
    """

    def __call__(self, t: float, robot: Robot, controller: Controller, command: VelocityCommand) -> None:
        """One tick (the `TickObserver` signature)."""

    def prepare(self, robot: Robot) -> None:
        """Set up for the next episode, played on `robot` (not necessarily connected yet)."""


class EpisodeInterrupted(KeyboardInterrupt):
    """An episode interrupted while it played, with the part played (`run_episode`).

    A `KeyboardInterrupt`, so that whoever catches one (a simulated run, an arena's worker) stops as before; a
    hardware trial catches this one to damp its robot and record the episode up to the interruption.

    Args:
        episode: the episode up to the last complete tick (not a fall: ``fell`` False).
        tick: the ticks complete: the index of the tick that was interrupted.
        time_s: the episode time at the end of the last complete tick [s].
        duration_s: the episode's whole length [s].

    Attributes:
        episode, tick, time_s, duration_s: as given.
    """

    def __init__(self, *, episode: Episode, tick: int, time_s: float, duration_s: float) -> None:
        super().__init__(f"interrupted at tick {tick}, {time_s:.3f} s of the {duration_s:g} s episode")
        self.episode = episode
        self.tick = tick
        self.time_s = time_s
        self.duration_s = duration_s

    def __reduce__(self) -> tuple[object, ...]:
        """Rebuild without calling the constructor (its arguments are keywords): an arena's worker may carry it."""
        return _rebuild_interrupted, (type(self), self.args), self.__dict__


def _rebuild_interrupted(cls: type[EpisodeInterrupted], args: tuple[object, ...]) -> EpisodeInterrupted:
    err = cls.__new__(cls, *args)
    err.args = args
    return err


def _check_arguments(schedule: object, duration_s: object) -> None:
    """Refuse a `duration_s` that is not a finite positive number and a `schedule` without ``at``, naming them.

    Raises:
        ConfigError: either is unusable (caught here, before the robot or the controller is touched, rather than
            as a bare ValueError or AttributeError from inside the loop).
    """
    if (isinstance(duration_s, bool) or not isinstance(duration_s, int | float | np.integer | np.floating)
            or not math.isfinite(duration_s) or duration_s <= 0):
        raise ConfigError(f"run_episode: duration_s must be a finite positive number of seconds, got {duration_s!r}")
    if not callable(getattr(schedule, "at", None)):
        hint = ""
        if isinstance(schedule, VelocityCommand):
            hint = (f"; for a constant command, pass CommandSchedule(vx={schedule.vx:g}, vy={schedule.vy:g}, "
                    f"yaw_rate={schedule.yaw_rate:g}) (wbc.scenario)")
        raise ConfigError(f"run_episode: schedule must be a CommandSchedule (anything with at(t) -> VelocityCommand), "
                          f"got a {type(schedule).__name__}{hint}")


def run_episode(
    robot: Robot,
    controller: Controller,
    schedule: CommandSchedule,
    duration_s: float,
    *,
    truth: Callable[[], BaseTruth] | None = None,
    fallen: Callable[[], bool] | None = None,
    stopped: Callable[[], bool] | None = None,
    observer: TickObserver | None = None,
    divergence: DivergenceCheck | None = None,
    duration_option: str | None = None,
    clock: Callable[[], float] = time.perf_counter,
    stopped_by: tuple[type[Exception], ...] = (),
    on_interrupt: Callable[[BaseException], None] | None = None,
) -> Episode:
    """Play one episode.

    Args:
        robot: a connected robot, already in its initial state.
        controller: the controller (reset here).
        schedule: the velocity command over time.
        duration_s: episode length [s].
        truth: returns the base's true state (motion capture, say); default: the robot's own, if it is a
            `TruthSource`.
        fallen: returns True when the trunk or a non-foot link touches the ground; default: the robot's own, if it
            is a `FallDetector`. (The truth's trunk upside down at the last tick is a fall there too.)
        stopped: returns True when the robot was stopped without a fall (a hardware trial's safety layer latched its
            damping: a trip or an e-stop); checked after `fallen`, it ends the episode at that tick, which is not a
            fall (``fell`` False, the ticks played kept: `Episode.stopped`). None: never.
        observer: called after every tick (e.g. a viewer); None costs nothing.
        divergence: check every tick that the simulation has not blown up (a few NumPy reductions per tick), and,
            if the robot is a `SimulatorHealth`, that the simulator did not reset itself after a failed step;
            None: no check (a real robot, whose safety layer watches it).
        duration_option: the caller's option that set `duration_s` (``--duration``): an episode shorter than the
            controller's period is then blamed on it, not on the controller's rate.
        clock: what times each ``act`` call (the episode's ``act_s``) [s]: the wall clock, or a clock a test moves.
        stopped_by: errors of the robot that mean the command was asked to end, not that the robot failed (a
            hardware trial's `wbc.errors.IoProcessStopped`: its devices' process stopped by SIGTERM, closing the robot
            into damping): they end the episode as an interruption does (`EpisodeInterrupted`, which carries them).
        on_interrupt: called with the interruption (the `KeyboardInterrupt`, or the error of `stopped_by`) as soon as
            it comes, before the partial episode is built (tens of milliseconds for a long episode): a hardware trial
            latches its robot's damping there. What it raises goes on instead of `EpisodeInterrupted`.

    Returns:
        The episode log (no pushes: whoever applied them adds them, see `wbc.arena.sim_trial.run_trial`), with the
        safety layer's transitions during the episode if the robot is a `HasSafetyEvents`.

    Raises:
        MissingCapabilityError: no `truth` or `fallen` given and the robot does not offer it.
        ConfigError: `duration_s` is not a finite positive number, `schedule` has no ``at``, the controller's period
            is longer than the episode (it would never be asked to act), or, on a robot that advances whole
            physics steps (``physics_steps``: `MujocoRobot`), not a whole number of them.
        ControllerFailure: the controller's ``reset`` or ``act`` raised, or ``act`` returned a command the robot
            refused (`wbc.errors.CommandError`); it carries the episode played up to that tick. The robot keeps the
            last command it accepted.
        SimulationDiverged: `divergence` found an impossible state; it carries the episode played up to that tick
            (the tick that stepped into it included).
        EpisodeInterrupted: a `KeyboardInterrupt` came while the episode played (the robot, the controller, the
            observer ...), or one of `stopped_by`; it carries the episode up to the last complete tick, and the
            interruption as its ``__cause__``. Should the partial episode fail to be built (an interruption that cut
            a tick's row in half), the interruption itself is raised, unchanged; a subclass of `KeyboardInterrupt`
            (an interruption that means something else) always is.
    """
    _check_arguments(schedule, duration_s)
    truth = _truth_of(robot) if truth is None else truth
    fallen = _fall_detector_of(robot) if fallen is None else fallen
    health = robot if divergence is not None and isinstance(robot, SimulatorHealth) else None
    dt = 1.0 / controller.rate_hz
    steps_of = getattr(robot, "physics_steps", None)  # a simulator's: it advances whole physics steps only
    if callable(steps_of):
        try:
            steps_of(dt)
        except ConfigError as e:
            step = getattr(getattr(robot, "config", None), "timestep", None)
            rates = f": {nearest_rates(controller.rate_hz, step)}" if isinstance(step, float) else ""
            raise ConfigError(f"controller {type(controller).__name__}: its period 1/{controller.rate_hz:g} Hz cannot "
                              f"be played ({e}); give it a rate whose period is a whole number of physics "
                              f"steps{rates}") from None
    n = int(round(duration_s / dt))
    if n < 1 and duration_option is not None:
        raise ConfigError(f"{duration_option} {duration_s:g} s is shorter than one control period of controller "
                          f"{type(controller).__name__} (1/{controller.rate_hz} Hz = {dt:g} s), so it would never be "
                          f"asked to act; give {duration_option} of at least {dt:g} s")
    if n < 1:
        raise ConfigError(f"controller {type(controller).__name__}: its period 1/{controller.rate_hz} Hz = {dt:g} s is "
                          f"longer than the {duration_s:g} s episode, so it would never be asked to act; give it a "
                          f"rate of at least {1.0 / duration_s:g} Hz")
    arm = slice(ARM_JOINTS.start, ARM_JOINTS.stop) if robot.num_joints == 15 else None
    buf = EpisodeBuffer(nq=7 + robot.num_joints, arm=arm)
    _playing[0] = (buf, dt)  # once an episode: nothing is added to a tick
    safety = robot if isinstance(robot, HasSafetyEvents) else None
    events_before = len(safety.safety_events()) if safety is not None else 0
    bounds = command_bounds(robot.limits, *robot.gain_limits)
    lower, upper = bounds
    clamped = 0
    clamped_rows = np.zeros(5, dtype=np.int64)  # per command row (q, dq, kp, kd, tau): ticks it was clamped

    def failure(phase: str, tick: int, exc: Exception, hint: str | None = None) -> ControllerFailure:
        events = SafetyLog.of(safety.safety_events()[events_before:]) if safety is not None else None
        played = buf.finish(duration_s=duration_s, control_dt=dt, fell=False, fall_time_s=math.nan,
                            safety_events=events, clamped_ticks=clamped, clamped_rows=tuple(clamped_rows))
        return ControllerFailure(controller, phase=phase, tick=tick, time_s=tick * dt, exc=exc, episode=played,
                                 hint=hint)

    def diverged(reason: str, tick: int) -> SimulationDiverged:
        events = SafetyLog.of(safety.safety_events()[events_before:]) if safety is not None else None
        played = buf.finish(duration_s=duration_s, control_dt=dt, fell=False, fall_time_s=math.nan,
                            safety_events=events, clamped_ticks=clamped, clamped_rows=tuple(clamped_rows))
        return SimulationDiverged(reason, tick=tick, time_s=buf.rows * dt, episode=played)

    def interrupted(exc: BaseException) -> EpisodeInterrupted | None:
        if on_interrupt is not None:
            on_interrupt(exc)  # first: a robot's damping must not wait for the episode to be built
        # what was played, built from memory alone; None where it cannot be
        try:
            events = SafetyLog.of(safety.safety_events()[events_before:]) if safety is not None else None
            # a tick cut between its clamp count and its row is not held: it is not counted either
            rows = buf.rows
            played = buf.finish(duration_s=duration_s, control_dt=dt, fell=False, fall_time_s=math.nan,
                                safety_events=events, clamped_ticks=min(clamped, rows),
                                clamped_rows=tuple(min(int(c), rows) for c in clamped_rows))
            ticks = len(played.t)
            return EpisodeInterrupted(episode=played, tick=ticks, time_s=ticks * dt, duration_s=duration_s)
        except Exception:  # any: the interruption must go on as itself, never masked by a failure to keep its episode
            return None

    try:
        try:
            controller.reset()
        except CONTROLLER_ERRORS as exc:  # any: the controller's code is not ours, and the trial must still be recorded
            raise failure("reset", 0, exc) from exc
        fell, fall_time = False, math.nan
        for k in range(n):
            t = k * dt
            state = robot.read()
            if divergence is not None and (reason := divergence.state(state)) is not None:
                raise diverged(reason, k)
            cmd = schedule.at(t)
            measured = buf.measured(state)  # before the controller, which could change the arrays it is given
            started = clock()
            try:
                out = controller.act(state, cmd)
            except CONTROLLER_ERRORS as exc:
                raise failure("act", k, exc) from exc
            act_s = clock() - started
            try:
                robot.write(out)
            except CommandError as exc:  # refused before reaching a motor: NaN, wrong length, not a MotorCommand
                hint = arm_mode_hint(out.num_joints, robot.num_joints) if isinstance(out, MotorCommand) else None
                raise failure("command", k, exc, hint) from exc
            if not within_bounds(out.rows, lower, upper):  # one compiled pass; the rows are told apart only when needed
                over = exceeded_rows(out, bounds)
                if over.any():
                    clamped += 1
                    clamped_rows += over
            robot.advance(dt)
            # the raw row only: the metrics derived from it are computed for all ticks at the end (`finish`)
            now = truth()
            buf.add((k + 1) * dt, cmd, act_s, now, measured)
            if health is not None and (reason := health.instability()) is not None:
                raise diverged(reason, k)
            if divergence is not None and (reason := divergence.truth(now)) is not None:
                raise diverged(reason, k)
            if observer is not None:
                observer((k + 1) * dt, robot, controller, cmd)
            if fallen():
                fell, fall_time = True, (k + 1) * dt
                break
            if stopped is not None and stopped():
                break
        else:
            # a trunk upside down at the end has not survived, touching the ground or not (flung into the air by a push,
            # the trial ended before it landed): a fall at the last tick
            if upside_down(now.base_quat):
                fell, fall_time = True, n * dt
    except KeyboardInterrupt as exc:
        # a subclass is an interruption that means something else: it goes on as it is
        stop = interrupted(exc) if type(exc) is KeyboardInterrupt else None
        if stop is None:
            raise
        raise stop from exc
    except stopped_by as exc:
        stop = interrupted(exc)
        if stop is None:
            raise
        raise stop from exc
    events = SafetyLog.of(safety.safety_events()[events_before:]) if safety is not None else None
    return buf.finish(duration_s=duration_s, control_dt=dt, fell=fell, fall_time_s=fall_time, safety_events=events,
                      clamped_ticks=clamped, clamped_rows=tuple(clamped_rows))


def _truth_of(robot: Robot) -> Callable[[], BaseTruth]:
    if not isinstance(robot, TruthSource):
        raise MissingCapabilityError(
            f"{type(robot).__name__} does not know its base's true state (it is not a "
            "wbc.hardware.capabilities.TruthSource), which the episode log needs; pass run_episode(truth=...), e.g. "
            "motion capture or the state estimator's base state")
    return robot.base_truth


def _fall_detector_of(robot: Robot) -> Callable[[], bool]:
    if not isinstance(robot, FallDetector):
        raise MissingCapabilityError(
            f"{type(robot).__name__} cannot tell when it has fallen (it is not a "
            "wbc.hardware.capabilities.FallDetector); pass run_episode(fallen=...), e.g. an operator's stop switch, "
            "or fallen=lambda: False to always play the whole episode")
    return robot.fallen
