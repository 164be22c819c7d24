"""`check_controller`: the contract every controller must meet before it enters the arena (like Gymnasium's check_env).

For every robot and arm mode the controller claims (`ControllerSpec.claims`), on the simulated robot:

- ``build``: its `make` builds an object that satisfies `wbc.control.Controller`;
- ``rate``: ``rate_hz`` is a finite positive number whose period is a whole number of physics steps (as the arena
  requires), and it stays the same after `reset` and `act`;
- ``output``: every `act` returns a `MotorCommand` with one entry per joint of the robot, finite, gains >= 0, and
  `counters` returns ``dict[str, int]``; the closed loop's commands beyond the robot's motor limits (positions,
  velocities, gains, torques: the bounds the robot clamps to, whose ticks the arena counts as clamped) are reported,
  each row's joints and by how much, and fail the check where more than half the ticks lie beyond a limit by more
  than the whole interval it limits (`CLAMPED_SHARE`: a target past a stop may be meant; that far, it is not);
- ``reset``: determinism. The states of a closed-loop run are fed again, open loop: after `reset` twice (the
  commands must be equal to the last bit) and to a freshly built controller (reset must forget the run before it);
- ``truth``: it never reads simulator truth. No truth accessor of the simulator (`sim_truth`, `base_truth`,
  `fallen`, `base_rotation`) may be called while `act` runs, and the commands for the same states must not change
  when only the simulator's hidden state does (the robot moved away between the replays);
- ``timing``: `act`'s wall time against its period: the median must fit the period (the p99 too with
  ``strict_timing``); p50, p99 and the share of late ticks are reported either way.

A failure of the controller's code is named at its own ``file:line`` (`wbc.control.failure_site`, as the arena names
it), not at the house's line that refused what it returned. A check that cannot be judged because an earlier one
failed is reported as not run. The result is a `ControllerCheck`; ``wbc check-controller NAME`` prints it, and the
test suite runs it on every registered controller. The simulator and the registry are imported when a check runs, so
``import wbc.control`` stays light.

Two more checks run when asked for (`EXTRA_CHECKS`), because a controller can meet the contract and still mean
something else than its author thinks:

- ``scenario`` (`CheckConfig.scenario`, ``--scenario FILE``): the closed loop plays the scenario's first trial (first
  band, seed 0, trial 0) instead of the default command on flat ground: its terrain, physical randomisation, command
  and pushes, for the trial's duration (or `CheckConfig.seconds`), on the scenario's robot only, ending at a fall as
  in the arena. It passes when the robot is still up at the end; the outcome says how long it stood, the pushes it met
  and any error of the controller.
- ``replay`` (`CheckConfig.replay`, ``--replay FILE.npz``): the robot states and commands of a replay file
  (`wbc.learned.policy.replay_file`, observation / action pairs recorded by the trainer) are fed, in order after a
  reset, to a freshly built controller. A controller that says what it observes (`ObservesTerms`: the learned
  policies and ONNX policies do) has its observation frame compared with the recorded one, entry by entry, and every
  term whose entries differ is named, with the term the controller puts there (two terms swapped in an I/O file show
  as each in the other's place; per-joint terms that equal the recording in another joint order show as that order,
  whose fix is the joint list, an ONNX policy's ``[policy] joints``). Its actions, read from the motor targets
  through the recording's motor law (``action = (q* - default_q) / action_scale``), are compared with the recorded
  actions. Within `CheckConfig.replay_atol` it passes.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from wbc.control.arm_mode_hint import arm_mode_hint
from wbc.control.errors import ControllerCheckError
from wbc.control.failure_site import failure_site, own_frame
from wbc.control.plugin import controller_problems
from wbc.control.protocol import Controller
from wbc.control.spec import ControllerSpec
from wbc.errors import CONTROLLER_ERRORS, ConfigError
from wbc.physics_steps import nearest_rates
from wbc.robots.registry import get_robot
from wbc.scenario.scenario import load_scenario
from wbc.scenario.trial import CommandSchedule, Trial
from wbc.types import MotorCommand, RobotState, VelocityCommand

if TYPE_CHECKING:
    from wbc.learned.policy.replay_file import Replay

__all__ = ["CHECKS", "CLAMPED_SHARE", "DEFAULT_SECONDS", "EXTRA_CHECKS", "ActTiming", "CheckConfig", "CheckOutcome",
           "ControllerCheck", "EstimatesTerms", "ObservesTerms", "check_controller"]

CHECKS = ("build", "rate", "output", "reset", "truth", "timing")
"""The checks, in the order they are run and reported."""

EXTRA_CHECKS = ("scenario", "replay")
"""Checks run when their input is given (`CheckConfig.scenario`, `CheckConfig.replay`), reported after `CHECKS`."""

DEFAULT_SECONDS = 0.5
"""The closed loop's length without a scenario [s]."""


@runtime_checkable
class ObservesTerms(Protocol):
    """A policy controller that says what it observes, so a recording can be compared with it term by term."""

    def observation_terms(self, state: RobotState, command: VelocityCommand) -> list[tuple[str, np.ndarray]]:
        """This tick's observation frame as (term name, values) in the order the network sees them.

        Term names are those of `wbc.control.onnx_io.TERMS`; calling it leaves what `act` does on the same state
        unchanged (`act` then feeds the network the same frame).
        """


@runtime_checkable
class EstimatesTerms(Protocol):
    """A policy controller that estimates some of its observation terms from the states.

    An ONNX policy's ``base_lin_vel`` (``source = "estimator"``) is one: a trainer recorded the simulator's truth
    there, which no estimate equals, so a replay feeds those terms the recorded values and checks the rest of the
    policy exactly.

    Attributes:
        estimated_terms: the names of the estimated terms (`wbc.control.onnx_io.ESTIMATED`).
    """

    estimated_terms: tuple[str, ...]

    def feed_recorded(self, values: Mapping[int, np.ndarray]) -> None:
        """For the next `act` only, the network sees `values` in place of the estimated terms'.

        `values` are by the term's position in the frame, scaled and clipped as the network saw them;
        ``observation_terms`` still reports the estimate.
        """


@dataclass(frozen=True, kw_only=True)
class CheckConfig:
    """How `check_controller` exercises a controller.

    Attributes:
        seconds: length of the closed-loop run on each (robot, arm mode) [s]; the replays feed the same states.
            None: `DEFAULT_SECONDS`, or with a scenario its trial's duration.
        command: the velocity command over the run (default: from standing to 0.3 m/s forward); a scenario's trial
            brings its own.
        strict_timing: also fail when act's p99 exceeds the period.
        robots: check only these robots (None: every robot it claims).
        scenario: a scenario file whose first trial the closed loop plays (the ``scenario`` check), or None.
        replay: a replay file (`wbc.learned.policy.replay_file`) to feed the controller (the ``replay`` check), or
            None.
        replay_atol: largest absolute difference of an observation entry or an action from the recording that
            passes. The same network run in float32 (onnxruntime) and in float64 (numpy) differs by up to about
            3e-4 in pi3's actions (magnitude 5); a term out of place differs by ~1.
    """

    seconds: float | None = None
    command: CommandSchedule = field(default_factory=lambda: CommandSchedule(vx=0.3, ramp_s=0.4))
    strict_timing: bool = False
    robots: tuple[str, ...] | None = None
    scenario: str | Path | None = None
    replay: str | Path | None = None
    replay_atol: float = 1e-3


@dataclass(frozen=True, kw_only=True)
class CheckOutcome:
    """One check on one (robot, arm mode).

    Attributes:
        check: one of `CHECKS`.
        robot: robot name; None for the ``build`` of a controller whose name could not be resolved into one
            (`ControllerCheck.unbuilt`), for which no robot is known.
        arm_mode: arm mode; None where `robot` is.
        passed: True, False, or None when it could not be run.
        detail: what was measured, or what is wrong and how to fix it.
    """

    check: str
    robot: str | None
    arm_mode: str | None
    passed: bool | None
    detail: str


@dataclass(frozen=True, kw_only=True)
class ActTiming:
    """Wall time of `act` on one (robot, arm mode), over every tick of the run and the replays.

    Attributes:
        robot: robot name.
        arm_mode: arm mode.
        period_s: the control period [s].
        p50_s: median [s].
        p99_s: 99th percentile [s].
        max_s: longest call [s].
        late: share of calls longer than the period.
        ticks: calls timed.
    """

    robot: str
    arm_mode: str
    period_s: float
    p50_s: float
    p99_s: float
    max_s: float
    late: float
    ticks: int


@dataclass(frozen=True, kw_only=True)
class ControllerCheck:
    """What `check_controller` found.

    Attributes:
        controller: the controller's name.
        outcomes: every check on every (robot, arm mode), in order.
        timings: act's timing on each (robot, arm mode) that ran.
    """

    controller: str
    outcomes: tuple[CheckOutcome, ...]
    timings: tuple[ActTiming, ...]

    @classmethod
    def unbuilt(cls, controller: str, detail: str) -> ControllerCheck:
        """The check of a controller whose name could not be resolved into one: a failed ``build``, for no robot.

        Its model, I/O file or policy file is invalid, or its plug-in's module cannot be imported, so neither the
        controller nor the robots it claims are known; ``wbc check-controller --json`` prints this, so that a script
        reads every controller that cannot be built as a failed build, whatever failed.
        """
        return cls(controller=controller, outcomes=(CheckOutcome(check="build", robot=None, arm_mode=None,
                                                                 passed=False, detail=detail),), timings=())

    @classmethod
    def ended(cls, controller: str, detail: str) -> ControllerCheck:
        """The check of a controller whose checks did not finish: its worker process ended, or ran past its time.

        A failed ``process`` check, for no robot: what the checks had found went with the process
        (``wbc check-controller`` runs them in a worker process of their own, so that a controller that ends its
        process, or hangs, fails its check instead of ending or stalling the command).
        """
        return cls(controller=controller, outcomes=(CheckOutcome(check="process", robot=None, arm_mode=None,
                                                                 passed=False, detail=detail),), timings=())

    @property
    def passed(self) -> bool:
        """Some check ran, and every check ran and passed (nothing checked is not a pass)."""
        return bool(self.outcomes) and all(o.passed is True for o in self.outcomes)

    def failed(self, check: str | None = None) -> list[CheckOutcome]:
        """The outcomes that failed (of `check` only, if given)."""
        return [o for o in self.outcomes if o.passed is False and check in (None, o.check)]

    def not_run(self) -> list[CheckOutcome]:
        """The outcomes that could not be judged because an earlier check failed (``passed`` None)."""
        return [o for o in self.outcomes if o.passed is None]

    def raise_if_failed(self) -> None:
        """Raise `ControllerCheckError` listing every failed check, if any failed or could not run, or none ran."""
        if not self.outcomes:
            raise ControllerCheckError(f"controller {self.controller}: no check ran (no robot and arm mode to check it "
                                       "on), so it has not met its contract")
        bad = [o for o in self.outcomes if o.passed is not True]
        if bad:
            lines = "; ".join(f"{o.check} on {o.robot}/{o.arm_mode}: {o.detail}" for o in bad)
            raise ControllerCheckError(f"controller {self.controller} fails its contract: {lines}")

    def as_dict(self) -> dict:
        """JSON-friendly form."""
        return {"controller": self.controller, "passed": self.passed,
                "outcomes": [{f.name: getattr(o, f.name) for f in fields(o)} for o in self.outcomes],
                "timings": [{f.name: getattr(t, f.name) for f in fields(t)} for t in self.timings]}


def check_controller(controller: ControllerSpec | str, config: CheckConfig | None = None) -> ControllerCheck:
    """Check `controller` against the controller contract on every robot and arm mode it claims.

    With a scenario the checks run on the scenario's robot only, its closed loop playing the scenario's first
    trial; with a replay file the ``replay`` check runs on the recording's robot and arm mode.

    Args:
        controller: a resolved controller, or a name (`wbc.control.registry.get_controller` resolves it).
        config: how long to run and what to command; a scenario, a replay file.

    Returns:
        The outcomes; ``result.raise_if_failed()`` turns failures into a `ControllerCheckError`.

    Raises:
        WbcError: the name cannot be resolved (unknown name, unreadable file, plug-in that cannot be imported).
        ScenarioError: the scenario file is missing or invalid (the message names the file and field).
        ReplayFileError: the replay file is missing or invalid (the message names the file and field).
        ConfigError: `seconds` is not positive; `robots` names no robot the controller claims, or it claims none
            (the message names the controller, the robots it drives and those asked for); the scenario or the replay
            is for a robot or arm mode the controller does not claim or `robots` leaves out (the message names the
            file).
    """
    from threadpoolctl import threadpool_limits  # single-threaded BLAS, as in the arena's workers

    cfg = config if config is not None else CheckConfig()
    if cfg.seconds is not None and not (math.isfinite(cfg.seconds) and cfg.seconds > 0):
        raise ConfigError(f"CheckConfig.seconds must be a positive number of seconds, got {cfg.seconds}")
    if isinstance(controller, str):
        from wbc.control.registry import get_controller  # every controller's code loads only when a name is checked

        spec = get_controller(controller)
    else:
        spec = controller
    claims = [(robot, mode) for robot, mode in spec.claims() if cfg.robots is None or robot in cfg.robots]
    if not claims:  # no check would run, and a check of nothing must not read as a pass
        raise ConfigError(_nothing_to_check(spec, cfg.robots))
    trial = _first_trial(cfg.scenario, spec, claims, cfg.robots) if cfg.scenario is not None else None
    if trial is not None:
        claims = [(robot, mode) for robot, mode in claims if robot == trial.robot]
    replay = _replay_for(cfg.replay, spec, claims) if cfg.replay is not None else None
    outcomes: list[CheckOutcome] = []
    timings: list[ActTiming] = []
    with threadpool_limits(limits=1, user_api="blas"):
        for robot, arm_mode in claims:
            recorded = replay if replay is not None and (replay.robot, replay.arm_mode) == (robot, arm_mode) else None
            found, timing = _check_one(spec, robot, arm_mode, cfg, trial, recorded)
            outcomes += found
            if timing is not None:
                timings.append(timing)
    return ControllerCheck(controller=spec.name, outcomes=tuple(outcomes), timings=tuple(timings))


def _claimed(spec: ControllerSpec, robots: tuple[str, ...] | None) -> str:
    have = sorted({robot for robot, _ in spec.claims()})
    text = f"controller {spec.name} drives {', '.join(have)}"
    return text + (f" (checked here: {', '.join(robots)}, as --robot asks)" if robots is not None else "")


def _nothing_to_check(spec: ControllerSpec, robots: tuple[str, ...] | None) -> str:
    """Why no (robot, arm mode) is left to check: the controller claims none, or none that `robots` asks for."""
    have = sorted({robot for robot, _ in spec.claims()})
    if not have:
        return (f"controller {spec.name} claims no robot, so there is nothing to check; a ControllerPlugin's (or "
                "ControllerSpec's) robots must name at least one robot, or be None for every robot")
    asked = ", ".join(robots or ())
    return (f"--robot {asked}: controller {spec.name} drives {', '.join(have)}, not {asked}; check it on a robot it "
            f"drives (--robot {have[0]}), or leave --robot out to check every robot it drives")


def _first_trial(path: str | Path, spec: ControllerSpec, claims: list[tuple[str, str]],
                 robots: tuple[str, ...] | None) -> Trial:
    """The scenario's first trial (first band, seed 0, trial 0), for a robot the check covers."""
    scenario = load_scenario(path)
    trial = scenario.trials(None, (0,), 1)[0]
    if not any(robot == trial.robot for robot, _ in claims):
        raise ConfigError(f"--scenario {path}: the scenario is for {trial.robot} ([scenario] robot), and "
                          f"{_claimed(spec, robots)}; check it with a scenario for a robot it drives")
    return trial


def _replay_for(path: str | Path, spec: ControllerSpec, claims: list[tuple[str, str]]) -> Replay:
    """The replay file, for a robot and arm mode the check covers."""
    from wbc.learned.policy.replay_file import load_replay  # the policies' package loads only when a replay is asked

    replay = load_replay(path)
    if (replay.robot, replay.arm_mode) not in claims:
        covered = ", ".join(f"{robot} (arm {mode})" for robot, mode in claims) or "nothing"
        raise ConfigError(f"--replay {path}: robot, arm_mode: recorded on {replay.robot} with arm {replay.arm_mode}; "
                          f"controller {spec.name} is checked here on {covered}; replay a recording made for a "
                          "robot and arm mode it drives (and that --scenario and --robot leave in)")
    return replay


# -- one (robot, arm mode) -------------------------------------------------------------------------------------------
class _Verdicts:
    """The outcomes of one (robot, arm mode), filled check by check (`extras`: the extra checks asked for)."""

    def __init__(self, robot: str, arm_mode: str, extras: tuple[str, ...] = ()) -> None:
        self.robot, self.arm_mode = robot, arm_mode
        self.extras = extras
        self.found: dict[str, CheckOutcome] = {}

    def set(self, check: str, passed: bool | None, detail: str) -> None:
        if check not in self.found:  # the first verdict of a check stands
            self.found[check] = CheckOutcome(check=check, robot=self.robot, arm_mode=self.arm_mode, passed=passed,
                                             detail=detail)

    def ok(self, check: str) -> bool:
        return check not in self.found or self.found[check].passed is True

    def outcomes(self, reason: str) -> list[CheckOutcome]:
        checks = (*CHECKS, *self.extras)
        for check in checks:
            self.set(check, None, f"not run: {reason}")
        return [self.found[c] for c in checks]


def _describe(exc: BaseException, ctrl: Controller | None = None, method: str = "") -> str:
    """The exception and the controller's own ``file:line`` where it arose, as the arena names it.

    `ctrl` is None for a failure of `make` (no controller yet): the place is the factory's own innermost frame, as
    the arena names a build's failure, and none for a plug-in's error, which `wbc.control.plugin.build_plugin`
    raises from the house's code with the plug-in's place in its message.
    """
    site = own_frame(exc) if ctrl is None else failure_site(exc, ctrl, method)
    return f"{type(exc).__name__}: {exc}{f' at {site}' if site else ''}"


def _build(spec: ControllerSpec, desc) -> tuple[Controller | None, str]:
    """The built controller, or None and what went wrong."""
    try:
        ctrl = spec.make(desc)
    except CONTROLLER_ERRORS as exc:  # noqa: BLE001 (any failure of the controller's code is the finding)
        return None, f"make raised {_describe(exc)}"
    if isinstance(ctrl, type):
        return None, f"make returned the class {ctrl.__name__}, not an instance: return {ctrl.__name__}(...)"
    problems = controller_problems(ctrl)
    if problems:
        return None, f"built a {type(ctrl).__name__}, not a wbc.control.Controller: {'; '.join(problems)}"
    return ctrl, ""


def _rate(ctrl: Controller, physics_dt: float, v: _Verdicts) -> float | None:
    rate = ctrl.rate_hz
    if isinstance(rate, bool) or not isinstance(rate, int | float) or not math.isfinite(rate) or rate <= 0:
        v.set("rate", False, f"rate_hz is {rate!r}; give a finite positive control rate [Hz]")
        return None
    ratio = (1.0 / rate) / physics_dt
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        v.set("rate", False, f"period 1/{rate:g} s is not a whole number of physics steps of {physics_dt} s; the "
              f"arena refuses it: choose a rate that divides {1 / physics_dt:g} Hz: "
              f"{nearest_rates(rate, physics_dt)}")
    return float(rate)


def _stack(cmd: MotorCommand) -> np.ndarray:
    return np.stack([cmd.q, cmd.dq, cmd.kp, cmd.kd, cmd.tau])


def _output_problem(out: object, n: int) -> str | None:
    if not isinstance(out, MotorCommand):
        return f"act returned a {type(out).__name__}, not a wbc.types.MotorCommand"
    for name in ("q", "dq", "kp", "kd", "tau"):
        a = getattr(out, name)
        if a.shape != (n,):
            hint = arm_mode_hint(a.shape[0], n) if a.ndim == 1 else None
            return (f"MotorCommand.{name} has shape {a.shape}; the robot has {n} joints (house order)"
                    + (f": {hint}" if hint else ""))
        if not np.all(np.isfinite(a)):
            return f"MotorCommand.{name} is not finite"
    if (out.kp < 0).any() or (out.kd < 0).any():
        return "negative gains"
    return None


CLAMPED_SHARE = 0.5
"""The ``output`` check fails when more than this share of the closed loop's ticks command far beyond the motors'
limits: beyond a bound by more than the width of the interval it bounds (`_clamped`).

A controller may command past a limit, and the robot clamps it: a PD policy's target past a joint's stop presses the
joint against it (the shipped pi3 asks its calves for up to 0.27 rad past their stop on most ticks of a walk), a
torque peaks at a push. The arena counts those ticks (`Episode.clamped_ticks`) and the check reports them, each row's
joints and by how much, and passes. A command beyond by more than the whole interval (a target further past a stop
than the joint's range, a speed or a torque more than twice the motor's) is not one the controller can mean: a
network that answers far outside its range, an action scale or a default pose off. On most ticks, as a median
``act`` beyond its period fails ``timing``, it fails ``output``: the robot does not play what the controller
commands."""


def _clamped(outputs: list[np.ndarray], bounds: tuple[np.ndarray, np.ndarray], joints: tuple[str, ...]
             ) -> tuple[bool, str] | None:
    """The commands beyond the robot's motor limits (`bounds`, as the arena counts clamped ticks), or None if none.

    Returns whether that fails the ``output`` check (more than `CLAMPED_SHARE` of the ticks far beyond: by more
    than the width of a bound's interval) and what was found: per row, the joints beyond their limit, on how many
    ticks and by how much at most.
    """
    from wbc.hardware.robot import COMMAND_ROWS  # the hardware package loads only when a check runs

    rows = np.asarray(outputs)  # (ticks, 5, n)
    lower, upper = bounds
    excess = np.maximum(lower - rows, rows - upper)  # > 0 beyond a bound, by that much
    beyond = excess > 0
    ticks = beyond.any(axis=(1, 2))
    if not ticks.any():
        return None
    far = (excess > upper - lower).any(axis=(1, 2))
    units = {"q": "rad", "dq": "rad/s", "kp": "N m/rad", "kd": "N m s/rad", "tau": "N m"}
    parts = []
    for r, row in enumerate(COMMAND_ROWS):
        hit = np.flatnonzero(beyond[:, r, :].any(axis=0))
        if not hit.size:
            continue
        worst = sorted(hit, key=lambda j: -excess[:, r, j].max())
        named = []
        for j in worst[:3]:
            k = int(np.argmax(excess[:, r, j]))
            above = rows[k, r, j] > upper[r, j]
            side, limit = ("above its upper", upper[r, j]) if above else ("below its lower", lower[r, j])
            on = int(beyond[:, r, j].sum())
            named.append(f"{joints[j]} {rows[k, r, j]:.3g} {side} limit {limit:.3g} (by {excess[k, r, j]:.3g} "
                         f"{units[row]}) on {on} tick{'s' if on != 1 else ''}")
        more = f" and {len(worst) - 3} more joints" if len(worst) > 3 else ""
        parts.append(f"MotorCommand.{row}: {', '.join(named)}{more}")
    count, total = int(ticks.sum()), len(outputs)
    fails = int(far.sum()) > CLAMPED_SHARE * total
    text = (f"{count} of {total} closed-loop ticks command beyond the robot's motor limits, which the robot clamps "
            f"before sending (the arena counts them as clamped ticks): {'; '.join(parts)}")
    if fails:
        text += (f"; on {int(far.sum())} of them a command lies further beyond its limit than the whole interval it "
                 "limits (a target further past a stop than the joint's range), so the robot does not play what the "
                 "controller commands: keep the targets near the joints' range and the velocities, gains and "
                 "torques within the motors' limits (an ONNX policy: its action scale, default pose and the "
                 "network's outputs)")
    return fails, text


def _counters_problem(ctrl: Controller) -> str | None:
    try:
        counts = ctrl.counters()
    except CONTROLLER_ERRORS as exc:  # noqa: BLE001
        return f"counters() raised {_describe(exc, ctrl, 'counters')}"
    if not isinstance(counts, dict) or not all(isinstance(k, str) and isinstance(c, int) and not isinstance(c, bool)
                                               for k, c in counts.items()):
        return f"counters() returned {counts!r}; return a dict of event name -> count (int)"
    return None


def _copy(state: RobotState) -> RobotState:
    return RobotState(**{f.name: (getattr(state, f.name).copy() if isinstance(getattr(state, f.name), np.ndarray)
                                  else getattr(state, f.name)) for f in fields(state)})


class _Pass:
    """One pass of `act` over a sequence: the stacked outputs and the times, or the failure.

    `reset_failure` is set instead of `failure` when the `reset` before the pass raised (the ``reset`` check's
    finding, not the ``output`` check's).
    """

    def __init__(self) -> None:
        self.outputs: list[np.ndarray] = []
        self.times: list[float] = []
        self.failure: str | None = None
        self.reset_failure: str | None = None


def _reset(ctrl: Controller, before: str) -> str | None:
    """Call `ctrl.reset()`; what it raised, as a finding that says when (`before`), or None."""
    try:
        ctrl.reset()
    except CONTROLLER_ERRORS as exc:  # noqa: BLE001 (any failure of the controller's code is the finding)
        return (f"reset() raised {_describe(exc, ctrl, 'reset')} {before}; reset() must put the controller back in "
                "its initial state")
    return None


def _act(ctrl: Controller, state: RobotState, cmd: VelocityCommand, n: int, p: _Pass, k: int,
         watch: Callable[[bool], None]) -> MotorCommand | None:
    watch(True)
    start = time.perf_counter()
    try:
        out = ctrl.act(state, cmd)
    except CONTROLLER_ERRORS as exc:  # noqa: BLE001
        p.failure = f"act raised {_describe(exc, ctrl, 'act')} at tick {k}"
        return None
    finally:
        p.times.append(time.perf_counter() - start)
        watch(False)
    problem = _output_problem(out, n)
    if problem is not None:
        p.failure = f"{problem} (tick {k})"
        return None
    p.outputs.append(_stack(out))
    return out


def _replay(ctrl: Controller, states: list[RobotState], cmds: list[VelocityCommand], n: int,
            watch: Callable[[bool], None]) -> _Pass:
    p = _Pass()
    p.reset_failure = _reset(ctrl, "before a replay of the closed loop's states")
    if p.reset_failure is not None:
        return p
    for k, (state, cmd) in enumerate(zip(states, cmds, strict=True)):
        if _act(ctrl, state, cmd, n, p, k, watch) is None:
            break
    return p


def _difference(a: _Pass, b: _Pass) -> str | None:
    """Where two passes' commands first differ, or None when they are equal to the last bit."""
    for k, (x, y) in enumerate(zip(a.outputs, b.outputs, strict=True)):
        if not np.array_equal(x, y):
            row = int(np.argmax(np.abs(x - y).max(axis=1)))
            name = ("q", "dq", "kp", "kd", "tau")[row]
            return f"tick {k}, MotorCommand.{name}, max |difference| {np.abs(x - y).max():.3g}"
    return None


def _check_one(spec: ControllerSpec, robot: str, arm_mode: str, cfg: CheckConfig, trial: Trial | None,
               replay: Replay | None) -> tuple[list[CheckOutcome], ActTiming | None]:
    # the simulator loads only when a check runs
    from wbc.control.watched_robot import WatchedRobot
    from wbc.hardware.mujoco.robot import MujocoRobotConfig

    extras = tuple(c for c, given in zip(EXTRA_CHECKS, (trial, replay), strict=True) if given is not None)
    v = _Verdicts(robot, arm_mode, extras)
    desc = get_robot(robot, arm_mode)
    ctrl, error = _build(spec, desc)
    if ctrl is None:
        v.set("build", False, error)
        return v.outcomes("the controller was not built"), None
    v.set("build", True, f"{type(ctrl).__name__}")
    if replay is not None:  # a controller of its own, fed the recording: independent of the closed loop's checks
        passed, detail = _check_replay(spec, desc, replay, cfg.replay_atol)
        v.set("replay", passed, detail)
    config = MujocoRobotConfig(robot=robot, arm_mode=arm_mode)
    if trial is not None:
        config = MujocoRobotConfig(robot=robot, arm_mode=arm_mode, terrain=trial.terrain)
    sim = WatchedRobot(config)
    sim.connect()
    try:
        return _exercise(spec, ctrl, desc, sim, cfg, v, trial)
    finally:
        sim.close()


def _exercise(spec: ControllerSpec, ctrl: Controller, desc, sim, cfg: CheckConfig, v: _Verdicts,
              trial: Trial | None) -> tuple[list[CheckOutcome], ActTiming | None]:
    n = desc.num_joints
    rate = _rate(ctrl, sim.config.timestep, v)
    if rate is None:
        return v.outcomes("no usable control rate"), None
    period = 1.0 / rate
    # the robot advances whole physics steps: a rate the `rate` check refused still runs, as the nearest whole number
    # of them (at least one), so the other checks report too
    step_dt = max(1, round(period / sim.config.timestep)) * sim.config.timestep
    seconds = cfg.seconds if cfg.seconds is not None else trial.duration_s if trial is not None else DEFAULT_SECONDS
    ticks = max(2, int(round(seconds * rate)))
    # A: the closed loop, whose states and commands the replays feed again
    if trial is not None:
        sim.reset(seed=trial.terrain_seed, domain=trial.domain)
        for push in trial.pushes:
            sim.apply_push(push)
        schedule = trial.command
    else:
        sim.reset(seed=0)
        schedule = cfg.command
    a, states, cmds = _Pass(), [], []
    fell_at: float | None = None
    reset_failure = _reset(ctrl, "before the closed loop")
    if reset_failure is not None:
        v.set("reset", False, reset_failure)
        v.set("rate", True, f"{rate:g} Hz (whether it stays constant was not checked: reset() failed)")
        return v.outcomes("reset() failed before the closed loop"), None
    for k in range(ticks):
        state = _copy(sim.read())
        cmd = schedule.at(k * period)
        out = _act(ctrl, state, cmd, n, a, k, sim.watch)
        if out is None:
            break
        states.append(state)
        cmds.append(cmd)
        sim.write(out)
        sim.advance(step_dt)
        if trial is not None and sim.fallen():  # as in the arena, the trial ends at a fall
            fell_at = (k + 1) * period
            break
    if trial is not None:
        v.set("scenario", *_scenario_verdict(trial, seconds, len(states) * period, fell_at, a.failure, period))
    if a.failure is not None:
        v.set("output", False, a.failure)
        v.set("rate", True, f"{rate:g} Hz (whether it stays constant was not checked: act failed)")
        return v.outcomes("act failed in the closed loop"), None
    if ctrl.rate_hz != rate:
        v.set("rate", False, f"rate_hz changed from {rate:g} to {ctrl.rate_hz!r} while running; keep it constant")
    # B1, B2: reset and replay twice, the simulator frozen where the loop left it
    b1 = _replay(ctrl, states, cmds, n, sim.watch)
    b2 = _replay(ctrl, states, cmds, n, sim.watch)
    if ctrl.rate_hz != rate:
        v.set("rate", False, f"rate_hz changed from {rate:g} to {ctrl.rate_hz!r} after reset(); keep it constant")
    v.set("rate", True, f"{rate:g} Hz, period {1e3 * period:g} ms = {round(period / sim.config.timestep)} physics "
          "steps")
    # D: a fresh controller on the same states; C: the same after reset, the simulator moved elsewhere
    fresh, error = _build(spec, desc)
    if fresh is None:
        v.set("reset", False, f"building the controller a second time failed: {error}")
    d = _replay(fresh, states, cmds, n, sim.watch) if fresh is not None else None
    c = None
    if fresh is not None and d.failure is None:
        moved = sim.data.qpos.copy()
        moved[:3] += (0.7, -0.4, 0.05)
        moved[7:] += 0.1
        sim.reset(seed=1, qpos=moved)
        c = _replay(fresh, states, cmds, n, sim.watch)
    reset_failure = next((p.reset_failure for p in (b1, b2, d, c) if p is not None and p.reset_failure), None)
    if reset_failure is not None:
        v.set("reset", False, reset_failure)
    failure = next((p.failure for p in (b1, b2, d, c) if p is not None and p.failure is not None), None)
    problem = _counters_problem(ctrl)
    from wbc.hardware.robot import command_bounds

    clamped = _clamped(a.outputs, command_bounds(sim.limits, *sim.gain_limits), desc.joint_names)
    if failure is not None or problem is not None:
        v.set("output", False, failure or problem)
    elif clamped is not None and clamped[0]:
        v.set("output", False, clamped[1])
    elif reset_failure is None:  # else a replay did not run: the output over every pass was not seen
        limits = clamped[1] if clamped is not None else "within the motor limits on every tick"
        v.set("output", True, f"{len(states)} ticks x 5 passes: {n} joints, finite, gains >= 0, {limits}; counters "
              f"{ctrl.counters()}")
    if failure is None and reset_failure is None and d is not None:
        same = _difference(b1, b2)
        fresh_diff = _difference(b1, d) if same is None else None
        if same is not None:
            v.set("reset", False, f"after reset() the same states and commands gave different motor commands ({same}): "
                  "act() depends on more than its inputs and the state reset() restores (a random generator not "
                  "reseeded by reset, a clock, memory kept across resets)")
        elif fresh_diff is not None:
            v.set("reset", False, f"after reset() the motor commands differ from a freshly built controller's on the "
                  f"same states ({fresh_diff}): reset() does not forget the previous episode")
        else:
            v.set("reset", True, f"{len(states)} ticks replayed twice after reset() and once fresh: equal to the "
                  "last bit")
    reads = sim.reads()
    if reads:
        seen = ", ".join(f"MujocoRobot.{name} x{calls}" for name, calls in reads.items())
        v.set("truth", False, f"act() read the simulator's truth ({seen}); a controller gets RobotState and "
              "VelocityCommand only, as on a real robot")
    elif reset_failure is not None:  # a replay did not run: no finding either way, reported as not run
        v.set("truth", None, "not run: reset() failed, so the replays that move the simulator did not all run")
    elif c is not None and c.failure is None and v.ok("reset"):
        shift = _difference(d, c)
        if shift is not None:
            v.set("truth", False, f"the motor commands changed when only the simulator's hidden state did (same "
                  f"states and commands, the robot moved 0.8 m away: {shift}): act() reads the simulator")
        else:
            v.set("truth", True, "no truth accessor called from act(); commands unchanged when the simulator's "
                  "hidden state moved")
    else:
        v.set("truth", None, "not run: no truth accessor was called, but the commands are not reproducible, so "
              "an influence of the simulator's state cannot be told apart")
    times = np.asarray([t for p in (a, b1, b2, d, c) if p is not None for t in p.times])
    timing = ActTiming(robot=v.robot, arm_mode=v.arm_mode, period_s=period, p50_s=float(np.percentile(times, 50)),
                       p99_s=float(np.percentile(times, 99)), max_s=float(times.max()),
                       late=float(np.mean(times > period)), ticks=int(times.size))
    text = (f"act p50 {1e3 * timing.p50_s:.3g} ms, p99 {1e3 * timing.p99_s:.3g} ms, max {1e3 * timing.max_s:.3g} ms "
            f"against a {1e3 * period:g} ms period; {100 * timing.late:.1f} % of {timing.ticks} calls late")
    if timing.p50_s > period:
        v.set("timing", False, f"{text}: the median call does not fit the period, so the controller cannot run at "
              f"{rate:g} Hz; make act() faster or lower rate_hz")
    elif cfg.strict_timing and timing.p99_s > period:
        v.set("timing", False, f"{text}: the p99 does not fit the period (strict timing)")
    else:
        v.set("timing", True, text)
    return v.outcomes("an earlier check failed"), timing


# -- the extra checks ------------------------------------------------------------------------------------------------
def _scenario_verdict(trial: Trial, seconds: float, played_s: float, fell_at: float | None, failure: str | None,
                      period: float) -> tuple[bool, str]:
    """The ``scenario`` outcome: whether the robot was still up at the end, the pushes it met, any error."""
    cmd = trial.command
    moves = ", ".join(f"{label} {value:g} {unit}" for label, value, unit in
                      (("vx", cmd.vx, "m/s"), ("vy", cmd.vy, "m/s"), ("yaw rate", cmd.yaw_rate, "rad/s")) if value)
    what = (f"{trial.scenario} trial (band {trial.band}, seed {trial.seed}, #{trial.index}) for {seconds:g} s, "
            f"{trial.terrain.kind} ground, command {moves or 'stand still'}")
    met = [p for p in trial.pushes if p.start < played_s]
    pushes = f"{len(met)} of {len(trial.pushes)} pushes met"
    if met:
        pushes += " (" + ", ".join(f"{np.linalg.norm(p.force_in_world):.0f} N at {p.start:.2f} s" for p in met) + ")"
    if failure is not None:
        return False, f"{what}: the controller failed at {played_s:.2f} s: {failure}; {pushes}"
    if fell_at is not None:
        return False, f"{what}: FELL at {fell_at:.2f} s; {pushes}"
    return True, f"{what}: survived; {pushes}"


def _spans(names_sizes: tuple[tuple[str, int], ...]) -> list[tuple[str, int, int]]:
    out, at = [], 0
    for name, size in names_sizes:
        out.append((name, at, at + size))
        at += size
    return out


def _layout_text(spans: list[tuple[str, int, int]]) -> str:
    return ", ".join(f"{name} {stop - start}" for name, start, stop in spans)


def _entries(start: int, stop: int) -> str:
    return f"entry {start}" if stop - start == 1 else f"entries {start}-{stop - 1}"


@dataclass(frozen=True)
class _TermFinding:
    """A recorded term whose entries the controller's frame does not reproduce."""

    first: int
    text: str
    name: str


def _observation_findings(frames: np.ndarray, layout: tuple[tuple[str, int], ...], replay: Replay,
                          atol: float, fed: frozenset[str] = frozenset()
                          ) -> tuple[list[_TermFinding], str | None, float]:
    """The terms that differ (earliest first), a layout-size problem, and the largest difference.

    The recorded terms named in `fed` (estimated by the controller, the network fed the recorded values) are not
    findings, and their entries are left out of the largest difference.
    """
    mine = _spans(layout)
    recorded = [(name, a, b) for name, (a, b) in zip(replay.obs_terms, replay.obs_slices, strict=True)
                if name not in fed]
    width = replay.obs.shape[1]
    if frames.shape[1] != width:
        missing = [n for n, _, _ in recorded if n not in {name for name, _ in layout}]
        extra = [n for n, _ in layout if n not in replay.obs_terms]
        also = (f"; the recording has {', '.join(missing)} and the controller does not" if missing else "") + \
               (f"; the controller has {', '.join(extra)} and the recording does not" if extra else "")
        return [], (f"the controller's observation frame has {frames.shape[1]} entries ({_layout_text(mine)}), the "
                    f"recording's {width} ({_layout_text(recorded)}){also}"), math.inf
    diff = np.abs(frames - replay.obs)
    for name, (a, b) in zip(replay.obs_terms, replay.obs_slices, strict=True):
        if name in fed:
            diff[:, a:b] = 0.0
    bad = diff > atol
    found = []
    for name, a, b in recorded:
        rows = bad[:, a:b].any(axis=1)
        if not rows.any():
            continue
        first = int(np.argmax(rows))
        block = diff[:, a:b]
        worst = float(block.max())
        theirs = [m for m, c, d in mine if c < b and d > a]
        where = ""
        if b - a == len(replay.action_joints) and name.startswith(("joint_", "last_action")):
            where = f" at {replay.action_joints[int(np.argmax(block.max(axis=0)))]}"
        if theirs == [name] and (name, a, b) in mine:
            text = (f"{name} ({_entries(a, b)}) differs from tick {first}, max |difference| {worst:.3g}{where}: the "
                    "same place, other values (its scale, clip, joint order or source differ)")
        else:
            text = (f"{_entries(a, b)} hold {name} in the recording but {' + '.join(theirs)} in the controller's "
                    f"frame (from tick {first}, max |difference| {worst:.3g})")
        found.append(_TermFinding(first=first, text=text, name=name))
    found.sort(key=lambda f: f.first)
    return found, None, float(diff.max())


_JOINT_TERMS = ("joint_pos_rel", "joint_vel")
"""The per-joint terms read from the states alone, which a joint order permutes (``last_action`` is the controller's
own, and differs once an action does)."""


def _joint_permutation(frames: np.ndarray, replay: Replay, found: list[_TermFinding], atol: float
                       ) -> list[int] | None:
    """The joint order that explains every per-joint term found to differ, or None.

    For each such term (`_JOINT_TERMS`, one entry per joint), each recorded entry is matched with the controller's
    entry of the same term that it equals on every tick (within `atol`); where every differing term's entries are
    the controller's in one other order, the same for all, that order is returned: ``order[k]`` is the controller's
    entry that the recording's entry k holds.
    """
    n = len(replay.action_joints)
    terms = [f.name for f in found if f.name in _JOINT_TERMS]
    if not terms:
        return None
    order: list[int] | None = None
    for name in terms:
        a, b = replay.obs_slices[replay.obs_terms.index(name)]
        if b - a != n:
            return None
        mine, theirs = frames[:, a:b], replay.obs[:, a:b]
        gap = np.abs(theirs[:, :, None] - mine[:, None, :]).max(axis=0)  # [recorded entry, controller's entry]
        match = [int(j) for j in gap.argmin(axis=1)]
        if sorted(match) != list(range(n)) or gap[np.arange(n), match].max() > atol:
            return None
        if order is not None and match != order:
            return None
        order = match
    return order


def _joint_order_hint(order: list[int], terms: list[str], ctrl: Controller) -> str:
    """What a joint order that explains the differing joint terms says, with the joints named where known."""
    io = getattr(ctrl, "io", None)  # an ONNX policy: its frame's joints are its I/O file's [policy] joints
    joints = getattr(io, "joints", None)
    where = "[policy] joints"
    if joints is not None and len(joints) == len(order):
        mine = ", ".join(joints)
        trained = ", ".join(joints[j] for j in order)
        where = f"{getattr(io, 'path', 'the I/O file')} [policy] joints"
        text = (f"the recording holds the joints in the order {trained}; the controller's frame in the order {mine}")
    else:
        text = f"the recording's joint entries are the controller's entries {', '.join(map(str, order))}"
    return (f"{', '.join(terms)} equal the recording with the joints in another order: {text}. The network was "
            f"trained in another joint order than the controller uses: list the network's joints in its training "
            f"order (an ONNX policy's I/O file: {where})")


def _estimate_text(frames: np.ndarray, replay: Replay, fed: set[str]) -> str:
    """What the replay says of the estimated terms: fed the recorded values, and how far the estimate lies from them."""
    parts = []
    for name, (a, b) in zip(replay.obs_terms, replay.obs_slices, strict=True):
        if name in fed:
            diff = frames[:, a:b] - replay.obs[:, a:b]
            parts.append(f"{name} is estimated by the controller, and the network was fed the recorded values (its "
                         f"estimate from the recorded states lies rms {float(np.sqrt(np.mean(diff ** 2))):.3g}, max "
                         f"{float(np.abs(diff).max()):.3g} from them, in the network's units)")
    return "; ".join(parts)


ESTIMATE_SCALE_RANGE = (2.0 / 3.0, 1.5)
"""The recorded values of an estimated term may lie within this factor of the controller's estimate (a least-squares
gain, `_estimate_scale_problem`): an estimate is not the truth, but a term whose scale or frame is wrong lies 2x or
-1x from it."""

_ESTIMATE_CORRELATION = 0.8
"""Below this correlation between the recording and the estimate, their gain says nothing (a robot standing still)."""


def _estimate_scale_problem(frames: np.ndarray, replay: Replay, fed: set[str]) -> str | None:
    """An estimated term whose recording follows the controller's estimate at another scale or sign, or None.

    The replay feeds the network the recorded values of an estimated term, so a wrong ``scale`` (or a frame whose
    axes differ) in the I/O file would pass it unseen and show only in the arena. Where the recording and the
    estimate move together (correlation at least `_ESTIMATE_CORRELATION`, in magnitude), their least-squares gain
    must lie in `ESTIMATE_SCALE_RANGE`.
    """
    lo, hi = ESTIMATE_SCALE_RANGE
    for name, (a, b) in zip(replay.obs_terms, replay.obs_slices, strict=True):
        if name not in fed:
            continue
        est, rec = frames[:, a:b].ravel(), replay.obs[:, a:b].ravel()
        if np.std(est) == 0.0 or np.std(rec) == 0.0:
            continue
        corr = float(np.corrcoef(est, rec)[0, 1])
        gain = float(est @ rec / (est @ est))
        if abs(corr) >= _ESTIMATE_CORRELATION and not lo <= gain <= hi:
            return (f"{name}: the recorded values follow the controller's estimate at {gain:.2f} times it "
                    f"(correlation {corr:.2f}): the term's scale{' or sign' if gain < 0 else ''} in the I/O file is "
                    f"not the trainer's (within {lo:.2f}..{hi:.2f} passes)")
    return None


def _check_replay(spec: ControllerSpec, desc, replay: Replay, atol: float) -> tuple[bool, str]:
    """The ``replay`` outcome: a fresh controller fed the recorded states; its observation and actions compared."""
    label = f"{len(replay)} recorded ticks of {replay.path}"
    ctrl, error = _build(spec, desc)
    if ctrl is None:
        return False, f"building a second controller to replay {replay.path} failed: {error}"
    rate = ctrl.rate_hz
    if not isinstance(rate, int | float) or not math.isclose(float(rate), replay.rate_hz, rel_tol=1e-9):
        return False, (f"{replay.path}: rate_hz: recorded at {replay.rate_hz:g} Hz, the controller runs at "
                       f"{rate!r} Hz; replay a recording of this controller's policy")
    observes = isinstance(ctrl, ObservesTerms)
    estimated = frozenset(ctrl.estimated_terms) if observes and isinstance(ctrl, EstimatesTerms) else frozenset()
    recorded_spans = {(name, a, b) for name, (a, b) in zip(replay.obs_terms, replay.obs_slices, strict=True)}
    fed: set[str] = set()  # the estimated terms the network was fed the recording's values of
    index = replay.action_index()
    frames: list[np.ndarray] = []
    layout: tuple[tuple[str, int], ...] | None = None
    implied = np.empty_like(replay.actions)
    try:
        ctrl.reset()
    except CONTROLLER_ERRORS as exc:  # noqa: BLE001 (any failure of the controller's code is the finding)
        return False, f"reset() raised {_describe(exc, ctrl, 'reset')} before the replay"
    for k in range(len(replay)):
        state, cmd = replay.state(k), replay.velocity_command(k)
        step = "observation_terms"
        try:
            if observes:
                terms = ctrl.observation_terms(state, cmd)  # type: ignore[attr-defined]
                here = tuple((str(name), int(np.size(values))) for name, values in terms)
                if layout is not None and here != layout:
                    return False, (f"observation_terms changed its layout at recorded tick {k}: "
                                   f"{_layout_text(_spans(here))} after {_layout_text(_spans(layout))}")
                layout = here
                frames.append(np.concatenate([np.asarray(v, dtype=np.float64).reshape(-1) for _, v in terms]))
                # an estimated term where the recording holds the same term: the network gets the recorded values
                recorded = {i: replay.obs[k, a:b] for i, (name, a, b) in enumerate(_spans(here))
                            if name in estimated and (name, a, b) in recorded_spans}
                if recorded:
                    step = "feed_recorded"
                    ctrl.feed_recorded(recorded)  # type: ignore[attr-defined]
                    fed.update(here[i][0] for i in recorded)
            step = "act"
            out = ctrl.act(state, cmd)
        except CONTROLLER_ERRORS as exc:  # noqa: BLE001
            return False, f"{step} raised {_describe(exc, ctrl, step)} at recorded tick {k} of {replay.path}"
        problem = _output_problem(out, desc.num_joints)
        if problem is not None:
            return False, f"{problem} (recorded tick {k} of {replay.path})"
        implied[k] = (out.q[index] - replay.default_q) / replay.action_scale
    adiff = np.abs(implied - replay.actions)
    action_bad = (adiff > atol).any(axis=1)
    act_first = int(np.argmax(action_bad)) if action_bad.any() else None
    act_text = (f"the actions differ from tick {act_first}, max |difference| {adiff.max():.3g} at "
                f"{replay.action_joints[int(np.argmax(adiff.max(axis=0)))]}" if act_first is not None else
                f"the actions within {atol:g} (max |difference| {adiff.max():.2g})")
    if not observes:
        if act_first is None:
            return True, (f"{label}: {act_text}; the observation was not compared: {type(ctrl).__name__} does not "
                          "say what it observes (observation_terms)")
        return False, (f"{label}: {act_text}; {type(ctrl).__name__} does not say what it observes "
                       "(observation_terms), so the difference cannot be traced to an observation term")
    found, size_problem, worst = _observation_findings(np.asarray(frames), layout or (), replay, atol,
                                                       frozenset(fed))
    if size_problem is not None:
        return False, f"{label}: {size_problem}; {act_text}"
    compared = [name for name in replay.obs_terms if name not in fed]
    if fed:
        act_text += "; " + _estimate_text(np.asarray(frames), replay, fed)
        scale_problem = _estimate_scale_problem(np.asarray(frames), replay, fed)
        if scale_problem is not None:
            return False, f"{label}: {scale_problem}; {act_text}"
    if not found:
        if act_first is None:
            return True, (f"{label}: the observation equals the recording term by term "
                          f"({', '.join(compared)}; max |difference| {worst:.2g}), {act_text}")
        return False, (f"{label}: the observation equals the recording term by term, but {act_text}: the network, "
                       "its action scale or its default pose are not the recorded policy's")
    # the previous action is the controller's own: once its actions differ, so does that term, as a consequence
    causes = [f for f in found if not (f.name == "last_action" and act_first is not None and f.first > act_first)]
    follows = "" if len(causes) == len(found) else " (last_action differs too, after the actions did)"
    if not causes:
        return False, (f"{label}: the observation equals the recording term by term up to the first action that "
                       f"differs{follows}, but {act_text}: the network, its action scale or its default pose are "
                       "not the recorded policy's")
    text = "; ".join(f.text for f in causes) + follows
    # a joint order that is not the trainer's permutes the per-joint terms alone: the fix is the joint list, not
    # the terms' order, scales or sources
    order = _joint_permutation(np.asarray(frames), replay, causes, atol)
    joint_terms = [f.name for f in causes if f.name in _JOINT_TERMS]
    names = sorted({f.name for f in causes if order is None or f.name not in _JOINT_TERMS})
    hints = [_joint_order_hint(order, joint_terms, ctrl)] if order is not None else []
    if names:
        first = "the joint order (an ONNX policy's I/O file: [policy] joints), then " if (
            order is None and joint_terms and set(names) <= set(_JOINT_TERMS)) else ""
        hints.append(f"Check {first}the order, scales and sources of {', '.join(names)} (an ONNX policy's I/O "
                     "file: [[observation.terms]])")
    return False, f"{label}: the observation differs from the recording: {text}; {act_text}. {'; '.join(hints)}"
