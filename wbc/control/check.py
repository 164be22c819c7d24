"""`check_controller`: the contract every controller must meet before it enters the arena (like Gymnasium's check_env).

For every robot and arm mode the controller claims (`ControllerSpec.claims`), on the simulated robot:

- ``build``: its `make` builds an object that satisfies `wbc.control.Controller`;
- ``rate``: ``rate_hz`` is a finite positive number whose period is a whole number of physics steps (as the arena
  requires), and it stays the same after `reset` and `act`;
- ``output``: every `act` returns a `MotorCommand` with one entry per joint of the robot, finite, gains >= 0, and
  `counters` returns ``dict[str, int]``;
- ``reset``: determinism. The states of a closed-loop run are fed again, open loop: after `reset` twice (the
  commands must be equal to the last bit) and to a freshly built controller (reset must forget the run before it);
- ``truth``: it never reads simulator truth. No truth accessor of the simulator (`sim_truth`, `base_truth`,
  `fallen`, `base_rotation`) may be called while `act` runs, and the commands for the same states must not change
  when only the simulator's hidden state does (the robot moved away between the replays);
- ``timing``: `act`'s wall time against its period: the median must fit the period (the p99 too with
  ``strict_timing``); p50, p99 and the share of late ticks are reported either way.

A check that cannot be judged because an earlier one failed is reported as not run. The result is a
`ControllerCheck`; ``wbc check-controller NAME`` prints it, and the test suite runs it on every registered controller.
The simulator and the registry are imported when a check runs, so ``import wbc.control`` stays light.
"""

from __future__ import annotations

import math
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field, fields

import numpy as np

from wbc.control.errors import ControllerCheckError
from wbc.control.plugin import controller_problems
from wbc.control.protocol import Controller
from wbc.control.spec import ControllerSpec
from wbc.robots.registry import get_robot
from wbc.scenario.trial import CommandSchedule
from wbc.types import MotorCommand, RobotState, VelocityCommand

__all__ = ["CHECKS", "ActTiming", "CheckConfig", "CheckOutcome", "ControllerCheck", "check_controller"]

CHECKS = ("build", "rate", "output", "reset", "truth", "timing")
"""The checks, in the order they are run and reported."""

@dataclass(frozen=True, kw_only=True)
class CheckConfig:
    """How `check_controller` exercises a controller.

    Attributes:
        seconds: length of the closed-loop run on each (robot, arm mode) [s]; the replays feed the same states.
        command: the velocity command over the run (default: from standing to 0.3 m/s forward).
        strict_timing: also fail when act's p99 exceeds the period.
        robots: check only these robots (None: every robot it claims).
    """

    seconds: float = 0.5
    command: CommandSchedule = field(default_factory=lambda: CommandSchedule(vx=0.3, ramp_s=0.4))
    strict_timing: bool = False
    robots: tuple[str, ...] | None = None


@dataclass(frozen=True, kw_only=True)
class CheckOutcome:
    """One check on one (robot, arm mode).

    Attributes:
        check: one of `CHECKS`.
        robot: robot name.
        arm_mode: arm mode.
        passed: True, False, or None when it could not be run.
        detail: what was measured, or what is wrong and how to fix it.
    """

    check: str
    robot: str
    arm_mode: str
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

    @property
    def passed(self) -> bool:
        """Every check ran and passed."""
        return all(o.passed is True for o in self.outcomes)

    def failed(self, check: str | None = None) -> list[CheckOutcome]:
        """The outcomes that failed (of `check` only, if given)."""
        return [o for o in self.outcomes if o.passed is False and check in (None, o.check)]

    def raise_if_failed(self) -> None:
        """Raise `ControllerCheckError` listing every failed check, if any failed or could not run."""
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

    Args:
        controller: a resolved controller, or a name (`wbc.control.registry.get_controller` resolves it).
        config: how long to run and what to command.

    Returns:
        The outcomes; ``result.raise_if_failed()`` turns failures into a `ControllerCheckError`.

    Raises:
        WbcError: the name cannot be resolved (unknown name, unreadable file, plug-in that cannot be imported).
    """
    from threadpoolctl import threadpool_limits  # single-threaded BLAS, as in the arena's workers

    cfg = config if config is not None else CheckConfig()
    if isinstance(controller, str):
        from wbc.control.registry import get_controller  # every controller's code loads only when a name is checked

        spec = get_controller(controller)
    else:
        spec = controller
    outcomes: list[CheckOutcome] = []
    timings: list[ActTiming] = []
    with threadpool_limits(limits=1, user_api="blas"):
        for robot, arm_mode in spec.claims():
            if cfg.robots is not None and robot not in cfg.robots:
                continue
            found, timing = _check_one(spec, robot, arm_mode, cfg)
            outcomes += found
            if timing is not None:
                timings.append(timing)
    return ControllerCheck(controller=spec.name, outcomes=tuple(outcomes), timings=tuple(timings))


# -- one (robot, arm mode) -------------------------------------------------------------------------------------------
class _Verdicts:
    """The outcomes of one (robot, arm mode), filled check by check."""

    def __init__(self, robot: str, arm_mode: str) -> None:
        self.robot, self.arm_mode = robot, arm_mode
        self.found: dict[str, CheckOutcome] = {}

    def set(self, check: str, passed: bool | None, detail: str) -> None:
        if check not in self.found:  # the first verdict of a check stands
            self.found[check] = CheckOutcome(check=check, robot=self.robot, arm_mode=self.arm_mode, passed=passed,
                                             detail=detail)

    def ok(self, check: str) -> bool:
        return check not in self.found or self.found[check].passed is True

    def outcomes(self, reason: str) -> list[CheckOutcome]:
        for check in CHECKS:
            self.set(check, None, f"not run: {reason}")
        return [self.found[c] for c in CHECKS]


def _describe(exc: BaseException) -> str:
    frames = traceback.extract_tb(exc.__traceback__)
    where = f" at {frames[-1].filename}:{frames[-1].lineno}" if frames else ""
    return f"{type(exc).__name__}: {exc}{where}"


def _build(spec: ControllerSpec, desc) -> tuple[Controller | None, str]:
    """The built controller, or None and what went wrong."""
    try:
        ctrl = spec.make(desc)
    except Exception as exc:  # noqa: BLE001 (any failure of the controller's code is the finding)
        return None, f"make raised {_describe(exc)}"
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
              f"arena refuses it: choose a rate that divides {1 / physics_dt:g} Hz (e.g. 500, 250, 100, 50)")
    return float(rate)


def _stack(cmd: MotorCommand) -> np.ndarray:
    return np.stack([cmd.q, cmd.dq, cmd.kp, cmd.kd, cmd.tau])


def _output_problem(out: object, n: int) -> str | None:
    if not isinstance(out, MotorCommand):
        return f"act returned a {type(out).__name__}, not a wbc.types.MotorCommand"
    for name in ("q", "dq", "kp", "kd", "tau"):
        a = getattr(out, name)
        if a.shape != (n,):
            return f"MotorCommand.{name} has shape {a.shape}; the robot has {n} joints (house order)"
        if not np.all(np.isfinite(a)):
            return f"MotorCommand.{name} is not finite"
    if (out.kp < 0).any() or (out.kd < 0).any():
        return "negative gains"
    return None


def _counters_problem(ctrl: Controller) -> str | None:
    try:
        counts = ctrl.counters()
    except Exception as exc:  # noqa: BLE001
        return f"counters() raised {_describe(exc)}"
    if not isinstance(counts, dict) or not all(isinstance(k, str) and isinstance(c, int) and not isinstance(c, bool)
                                               for k, c in counts.items()):
        return f"counters() returned {counts!r}; return a dict of event name -> count (int)"
    return None


def _copy(state: RobotState) -> RobotState:
    return RobotState(**{f.name: (getattr(state, f.name).copy() if isinstance(getattr(state, f.name), np.ndarray)
                                  else getattr(state, f.name)) for f in fields(state)})


class _Pass:
    """One pass of `act` over a sequence: the stacked outputs and the times, or the failure."""

    def __init__(self) -> None:
        self.outputs: list[np.ndarray] = []
        self.times: list[float] = []
        self.failure: str | None = None


def _act(ctrl: Controller, state: RobotState, cmd: VelocityCommand, n: int, p: _Pass, k: int,
         watch: Callable[[bool], None]) -> MotorCommand | None:
    watch(True)
    start = time.perf_counter()
    try:
        out = ctrl.act(state, cmd)
    except Exception as exc:  # noqa: BLE001
        p.failure = f"act raised {_describe(exc)} at tick {k}"
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
    ctrl.reset()
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


def _check_one(spec: ControllerSpec, robot: str, arm_mode: str, cfg: CheckConfig,
               ) -> tuple[list[CheckOutcome], ActTiming | None]:
    # the simulator loads only when a check runs
    from wbc.control.watched_robot import WatchedRobot
    from wbc.hardware.mujoco.robot import MujocoRobotConfig

    v = _Verdicts(robot, arm_mode)
    desc = get_robot(robot, arm_mode)
    ctrl, error = _build(spec, desc)
    if ctrl is None:
        v.set("build", False, error)
        return v.outcomes("the controller was not built"), None
    v.set("build", True, f"{type(ctrl).__name__}")
    sim = WatchedRobot(MujocoRobotConfig(robot=robot, arm_mode=arm_mode))
    sim.connect()
    try:
        return _exercise(spec, ctrl, desc, sim, cfg, v)
    finally:
        sim.close()


def _exercise(spec: ControllerSpec, ctrl: Controller, desc, sim, cfg: CheckConfig, v: _Verdicts,
              ) -> tuple[list[CheckOutcome], ActTiming | None]:
    n = desc.num_joints
    rate = _rate(ctrl, sim.config.timestep, v)
    if rate is None:
        return v.outcomes("no usable control rate"), None
    period = 1.0 / rate
    ticks = max(2, int(round(cfg.seconds * rate)))
    # A: the closed loop, whose states and commands the replays feed again
    sim.reset(seed=0)
    a, states, cmds = _Pass(), [], []
    ctrl.reset()
    for k in range(ticks):
        state = _copy(sim.read())
        cmd = cfg.command.at(k * period)
        out = _act(ctrl, state, cmd, n, a, k, sim.watch)
        if out is None:
            break
        states.append(state)
        cmds.append(cmd)
        sim.write(out)
        sim.advance(period)
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
    failure = next((p.failure for p in (b1, b2, d, c) if p is not None and p.failure is not None), None)
    problem = _counters_problem(ctrl)
    if failure is not None or problem is not None:
        v.set("output", False, failure or problem)
    else:
        v.set("output", True, f"{len(states)} ticks x 5 passes: {n} joints, finite, gains >= 0; counters "
              f"{ctrl.counters()}")
    if failure is None and d is not None:
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
