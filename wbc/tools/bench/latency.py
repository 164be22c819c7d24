"""``wbc bench latency``: how late the loop is over the wire, the simulated delay that plays it, a controller's margin.

Three figures, so that a user can check a controller against latency before the robot:

1. The wire. The emulator's round trip (`bench_hw`: a command's send to the arrival of the state that answers it,
   the emulator in its own process) and the loop latency a controller meets over the wire, measured by a probe
   (`probe_ticks`): a feed-forward torque step on one motor, counted in control ticks from its ``write`` to the
   first ``read`` whose torque estimate shows it, through a `UnitreeRobot` against a `UnitreeEmulator` on 127.0.0.1
   (in this process; ``realtime`` by default: the emulated robot runs on its own clock, as a robot does, so the
   link's period and the two clocks' phase count). A simulated robot without delay counts one tick at one physics
   step per tick (the motors take the step at once; the read after the next step shows it); each physics step of
   actuation or sensing delay adds one (``1 + Na + Ns``). So the simulated delay equivalent to a count is
   ``(ticks - 1)`` control periods: the typical one from the median count, the worst from the largest; the same
   probe on the simulated robot with each checks it.
2. The margin: the largest actuation delay at which a controller still stands still for `STILL_S`, and still
   survives a push trial's first push (its trial cut `AFTER_PUSH_S` after that push), over standing trials of the
   push scenario, on the scenario's robot. A scenario without standing trials with pushes (the Go1's turns) gives
   its first trials as they are: the controller must keep walking their command for `WALK_S`, and survive their
   first push if they have one (the turns have none: no push margin). The sweep climbs `COARSE_MS` to the first
   delay that fails, then the bracket below it one physics step (`FINE_MS`) at a time: the margin is the last delay
   passed before the first failure.
3. What a user should set: ``actuation_delay_s`` + ``sensing_delay_s`` of a scenario's ``[domain]`` summing to the
   equivalent delay; a controller whose margin is not well above it will not survive the robot's loop.

The figures share this machine's cores with everything else it runs; the wire figures are those of loopback and an
emulator, not of a robot's network and firmware, which add their own latency (measure it on the robot).
"""

from __future__ import annotations

import dataclasses
import gc
import time
from dataclasses import dataclass

import numpy as np

from wbc.arena.sim_trial import run_trial
from wbc.control.registry import get_controller
from wbc.errors import BenchError
from wbc.hardware.capabilities import WallClock
from wbc.hardware.clock import Clock
from wbc.hardware.emulators import UnitreeEmulator, UnitreeEmulatorConfig
from wbc.hardware.interpreter import freeze_heap
from wbc.hardware.mujoco.physics import delay_steps
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.hardware.robot import Robot
from wbc.hardware.unitree import UnitreeRobot, UnitreeRobotConfig
from wbc.hardware.unitree.robot import DESCRIPTIONS
from wbc.scenario.domain import DomainParams
from wbc.scenario.scenario import load_scenario
from wbc.scenario.trial import Trial
from wbc.tools.bench.hw import bench_hw
from wbc.tools.bench.references import load_1min, machine_description
from wbc.types import MotorCommand

__all__ = ["COARSE_MS", "FINE_MS", "DelayMargin", "LatencyBenchResult", "WireLatency", "bench_latency", "delay_margin",
           "probe_ticks", "wire_probe"]

COARSE_MS = (0.0, 10.0, 20.0, 30.0, 40.0, 60.0, 80.0, 100.0, 150.0, 200.0)
"""The actuation delays the margin sweep climbs first [ms]."""
FINE_MS = 2.0  # [ms] the sweep's step within the bracket of the first failure: the default physics step

STILL_S = 3.0  # [s] how long a controller must stand still
WALK_S = 6.0  # [s] how long it must walk a walking trial's command (a ramp of a second or so, then the command)
AFTER_PUSH_S = 2.0  # [s] a push trial ends this long after its first push starts
PROBE_JOINT = 2  # the front right calf: it carries weight, so a torque step there is plain in its estimate
PROBE_STEP_NM = 3.0  # [N m] the feed-forward torque step
PROBE_KP, PROBE_KD = 20.0, 0.5  # the hold the probe steps from (as `bench_hw` holds)


@dataclass(frozen=True, kw_only=True)
class DelayMargin:
    """A controller's delay margin (`delay_margin`): per test, the last actuation delay passed and the first failed.

    Attributes:
        controller: controller registry name.
        robot: the robot the trials played (their scenario's).
        scenario: the scenario's name.
        standing: True for standing trials with pushes; False for the scenario's first trials as they are (it has
            no standing trials with pushes): the ``still`` test then walks their command for `WALK_S`.
        still_s: how long the ``still`` test played each trial [s] (`STILL_S`, or `WALK_S`).
        trials: the trials; each had to pass at a delay.
        push_force_n: the magnitude of each trial's first push [N]; empty when the trials have no push (then no
            push test was played: its margin and first failure are None).
        still_margin_ms: standing still (or walking the command): the last delay passed before the first failure
            [ms]; None if the first delay failed.
        still_fell_at_ms: standing still (or walking the command): the first delay that failed [ms]; None if none
            did.
        push_margin_ms: surviving the first push: the last delay passed before the first failure [ms]; None if the
            first delay failed, or no push test was played.
        push_fell_at_ms: surviving the first push: the first delay that failed [ms]; None if none did.
        runs: trials played.
        wall_s: the wall time of the sweep [s].
    """

    controller: str
    robot: str
    scenario: str
    standing: bool
    still_s: float
    trials: int
    push_force_n: tuple[float, ...]
    still_margin_ms: float | None
    still_fell_at_ms: float | None
    push_margin_ms: float | None
    push_fell_at_ms: float | None
    runs: int
    wall_s: float

    def as_dict(self) -> dict[str, object]:
        """Plain dict, keys as the attributes' names (one of ``margins`` in ``wbc bench latency``'s JSON)."""
        return {**dataclasses.asdict(self), "push_force_n": list(self.push_force_n)}


@dataclass(frozen=True, kw_only=True)
class WireLatency:
    """The wire's latency over loopback, and the simulated delay that plays it (`bench_latency` with ``wire``).

    Attributes:
        round_trip_ms_p50: median emulator round trip (`bench_hw`, lockstep) [ms].
        round_trip_ms_p99: its 99th percentile [ms].
        period_ms: the link and control period [ms].
        wire_ticks: the probe's count of each torque step against the realtime emulator [ticks].
        wire_ticks_p50: their median [ticks].
        wire_ticks_mean: their mean [ticks].
        wire_ticks_max: the largest [ticks].
        typical_delay_ms: ``p50 - 1`` periods rounded to physics steps: the total of actuation and sensing delay
            that typically plays the wire's loop [ms].
        sim_ticks_typical: the probe's median count on the simulated robot with that delay [ticks].
        worst_delay_ms: the same from ``max - 1`` periods: the loop at worst [ms].
        sim_ticks_worst: the probe's median count on the simulated robot with it [ticks].
    """

    round_trip_ms_p50: float
    round_trip_ms_p99: float
    period_ms: float
    wire_ticks: tuple[int, ...]
    wire_ticks_p50: float
    wire_ticks_mean: float
    wire_ticks_max: int
    typical_delay_ms: float
    sim_ticks_typical: float
    worst_delay_ms: float
    sim_ticks_worst: float

    def as_dict(self) -> dict[str, object]:
        """Plain dict, keys as the attributes' names (as they sit in ``wbc bench latency``'s JSON)."""
        return {**dataclasses.asdict(self), "wire_ticks": list(self.wire_ticks)}


@dataclass(frozen=True, kw_only=True)
class LatencyBenchResult:
    """What `bench_latency` measured: the wire's latency (when measured) and each controller's delay margin.

    Attributes:
        wire_robot: the Unitree robot of the wire measurements.
        scenario: the scenario of the margin trials.
        coarse_ms: the delays the margin sweep climbed first [ms].
        fine_ms: the sweep's step within the bracket of the first failure [ms].
        wire: the wire's figures, or None when the wire was not measured.
        margins: one per controller, in the order asked.
        machine: `machine_description`.
        load_1min: the machine's 1-minute load average at the end (`load_1min`; nan where the OS has none).
    """

    wire_robot: str
    scenario: str
    coarse_ms: tuple[float, ...]
    fine_ms: float
    wire: WireLatency | None
    margins: tuple[DelayMargin, ...]
    machine: str
    load_1min: float = float("nan")

    def as_dict(self) -> dict[str, object]:
        """Plain flat dict (the JSON output of ``wbc bench latency``): the wire's keys after ``fine_ms``."""
        out: dict[str, object] = {"wire_robot": self.wire_robot, "scenario": self.scenario,
                                  "coarse_ms": list(self.coarse_ms), "fine_ms": self.fine_ms}
        if self.wire is not None:
            out.update(self.wire.as_dict())
        out["margins"] = [m.as_dict() for m in self.margins]
        out["machine"] = self.machine
        out["load_1min"] = self.load_1min
        return out


def probe_ticks(robot: Robot, hold: MotorCommand, *, period: float, samples: int, joint: int = PROBE_JOINT,
                step_nm: float = PROBE_STEP_NM, settle: int = 10, timeout_ticks: int = 100) -> list[int]:
    """Control ticks from a torque step's ``write`` to the first ``read`` whose torque estimate shows it.

    On a robot that lives in wall time (`WallClock`: a wire) a tick is a period of that clock, counted from the
    step's first write, so a loop that ran late (one iteration spanning two of the link's periods) does not read as
    a shorter delay; on the simulator it is one ``advance``.

    The loop is the runner's (``write``, ``advance(period)``, ``read``). `samples` steps alternate on and off (+/-
    `step_nm` of feed-forward torque on `joint`), each after `settle` ticks of the previous command; a step shows when
    the joint's torque estimate has moved by more than half of it from the last reading before the write.

    Args:
        robot: a connected robot, standing under `hold`.
        hold: the command the steps are made from.
        period: the control period [s].
        samples: steps measured.
        joint: the motor stepped.
        step_nm: the step [N m].
        settle: ticks before each step.
        timeout_ticks: a step not seen within this many ticks is an error.

    Returns:
        The tick count of each step, in order.

    Raises:
        BenchError: a step was not seen within `timeout_ticks`.
    """
    bump = np.zeros(robot.num_joints)
    bump[joint] = step_nm
    stepped = dataclasses.replace(hold, tau=hold.tau + bump)
    current, counts = hold, []
    wall = robot.wall_time if isinstance(robot, WallClock) else None
    for i in range(samples):
        for _ in range(settle):
            robot.write(current)
            robot.advance(period)
        before = robot.read().tau_est[joint]
        current, sign = (stepped, 1.0) if i % 2 == 0 else (hold, -1.0)
        start = wall() if wall is not None else 0.0
        for k in range(1, timeout_ticks + 1):
            robot.write(current)
            robot.advance(period)
            if sign * (robot.read().tau_est[joint] - before) > 0.5 * step_nm:
                counts.append(k if wall is None else max(k, round((wall() - start) / period)))
                break
        else:
            raise BenchError(f"bench latency: a {step_nm:g} N m torque step on joint {joint} did not show in the "
                             f"torque estimate within {timeout_ticks} ticks of {period * 1e3:g} ms")
    return counts


def wire_probe(robot: str = "go1", *, samples: int = 40, period: float = 0.002, mode: str = "realtime",
               clock: Clock | None = None, sim: MujocoRobot | None = None) -> list[int]:
    """`probe_ticks` through a `UnitreeRobot` against a `UnitreeEmulator` (both in this process).

    Args:
        robot: ``a1`` or ``go1``.
        samples: steps measured.
        period: link and control period, and the emulator's period [s].
        mode: the emulator's mode, ``realtime`` (its own clock) or ``lockstep`` (one period per command).
        clock: None: the emulator serves UDP on 127.0.0.1 and the link runs its thread, in real time (what the
            bench measures); a `ManualClock`: both run on it, over the emulator's in-process channel, so the count
            is the wire's logic alone, the same on any machine.
        sim: the emulator's simulated robot (e.g. one with an actuation delay); None: the emulator builds its own.
    """
    emu = UnitreeEmulator(UnitreeEmulatorConfig(robot=robot, mode=mode, control_period=period), sim=sim)
    if clock is None:
        freeze_heap()  # as `wbc hw run` does once all is built: a full collection would stall the link's thread
        try:
            with emu:
                host, port = emu.address
                cfg = UnitreeRobotConfig(robot=robot, target_host=host, target_port=port, rate_hz=1.0 / period)
                with UnitreeRobot(cfg) as link:
                    hold = MotorCommand.hold(link.desc.nominal_q, PROBE_KP, PROBE_KD)
                    return probe_ticks(link, hold, period=period, samples=samples)
        finally:
            gc.unfreeze()  # a library call: what it kept is collected again after it
    cfg = UnitreeRobotConfig(robot=robot, target_host="127.0.0.1", target_port=9, rate_hz=1.0 / period)
    try:
        with UnitreeRobot(cfg, emu.transport(clock), clock=clock) as link:
            hold = MotorCommand.hold(link.desc.nominal_q, PROBE_KP, PROBE_KD)
            return probe_ticks(link, hold, period=period, samples=samples)
    finally:
        emu.close()


def sim_probe(robot: str, total_delay_s: float, *, samples: int = 10, period: float = 0.002) -> list[int]:
    """`probe_ticks` on the simulated legs of a Unitree robot with an actuation delay of `total_delay_s` [s]."""
    with MujocoRobot(MujocoRobotConfig(robot=DESCRIPTIONS[robot], arm_mode="none")) as sim:
        sim.reset(domain=DomainParams(actuation_delay=total_delay_s))
        hold = MotorCommand.hold(sim.desc.nominal_q, PROBE_KP, PROBE_KD)
        return probe_ticks(sim, hold, period=period, samples=samples)


def _margin_trials(scenario: str, trials: int) -> tuple[list[Trial], bool]:
    """The first `trials` standing trials with pushes of the scenario's first band, seed 0, and True.

    A scenario without so many among its first 1000 (a walking task) gives its first `trials` trials of that band as
    they are, and False.
    """
    if trials < 1:
        raise BenchError(f"bench latency: --trials must be >= 1, got {trials}")
    sc = load_scenario(scenario)
    found = []
    for index in range(1000):
        trial = sc.trial(sc.bands[0], 0, index)
        if trial.command.vx == trial.command.vy == trial.command.yaw_rate == 0.0 and trial.pushes:
            found.append(trial)
            if len(found) == trials:
                return found, True
    return [sc.trial(sc.bands[0], 0, index) for index in range(trials)], False


def delay_margin(controller: str, scenario: str = "scenarios/push.toml", *, trials: int = 2,
                 coarse_ms: tuple[float, ...] = COARSE_MS, fine_ms: float = FINE_MS) -> DelayMargin:
    """The largest actuation delay at which `controller` stands still, and survives a push, on the scenario's robot.

    Args:
        controller: controller registry name.
        scenario: a scenario with pushes and a standing command option (its standing trials are used); another (a
            walking task) gives its first trials: the controller must walk their command for `WALK_S`, and survive
            their first push if they have one.
        trials: trials; each must pass at a delay.
        coarse_ms: the delays climbed first, ascending [ms].
        fine_ms: the step within the bracket of the first coarse failure [ms].

    Returns:
        Per test (``still``: standing `STILL_S`, or walking the trials' command `WALK_S`, without pushes; ``push``:
        the trial's first push, cut `AFTER_PUSH_S` after it, when every trial has one) the last delay passed before
        the first failure and the first delay failed; the robot, the pushes' magnitudes, the trials played and the
        wall time.
    """
    spec = get_controller(controller)
    base, standing = _margin_trials(scenario, trials)
    pushed = all(t.pushes for t in base)
    forces = [round(float(np.linalg.norm(t.pushes[0].force_in_world)), 1) for t in base] if pushed else []
    found: dict[str, float | None] = {}
    runs = 0

    def passes(test: str, ms: float) -> bool:
        nonlocal runs
        for t in base:
            domain = dataclasses.replace(t.domain, actuation_delay=ms / 1e3)
            if test == "still":
                trial = dataclasses.replace(t, domain=domain, pushes=(), duration_s=STILL_S if standing else WALK_S)
            else:
                trial = dataclasses.replace(t, domain=domain, pushes=t.pushes[:1],
                                            duration_s=t.pushes[0].start + AFTER_PUSH_S)
            runs += 1
            if run_trial(trial, spec, record_errors=False)[1].fell:
                return False
        return True

    start = time.perf_counter()
    found["push_margin_ms"] = found["push_fell_at_ms"] = None
    for test in ("still", "push") if pushed else ("still",):
        margin, fell_at = None, None
        for ms in coarse_ms:
            if not passes(test, ms):
                fell_at = ms
                break
            margin = ms
        if margin is not None and fell_at is not None:
            ms = margin + fine_ms
            while ms < fell_at - 1e-9:
                if not passes(test, ms):
                    fell_at = ms
                    break
                margin = ms
                ms += fine_ms
        found[f"{test}_margin_ms"], found[f"{test}_fell_at_ms"] = margin, fell_at
    sc = load_scenario(scenario)
    return DelayMargin(controller=controller, robot=sc.robot, scenario=sc.name, standing=standing,
                       still_s=STILL_S if standing else WALK_S, trials=trials,
                       push_force_n=tuple(forces), **found, runs=runs, wall_s=time.perf_counter() - start)


def bench_latency(controllers: tuple[str, ...] = ("stand", "mpc"), *, wire_robot: str = "go1",
                  scenario: str = "scenarios/push.toml", trials: int = 2, samples: int = 40,
                  wire: bool = True) -> LatencyBenchResult:
    """The wire's latency, the simulated delay that matches it, and each controller's delay margin.

    Args:
        controllers: controllers whose margin is measured (`delay_margin`).
        wire_robot: the Unitree robot of the wire measurements (``a1`` or ``go1``).
        scenario: the scenario of the margin trials; they play its robot (`DelayMargin.robot`), which may not be
            `wire_robot`.
        trials: trials per margin test.
        samples: torque steps of the wire probe.
        wire: measure the wire (False: margins only).

    Returns:
        With `wire` the wire's figures (`WireLatency`); one `delay_margin` per controller, the sweep's delays and
        the machine.

    Raises:
        BenchError: the emulator failed, or a probe step was never seen.
        UnknownNameError: an unknown controller or robot.
    """
    figures = None
    if wire:
        period = 0.002
        hw = bench_hw(wire_robot, seconds=2.0, rate_hz=1.0 / period, stand_seconds=None)
        ticks = wire_probe(wire_robot, samples=samples, period=period)
        timestep = MujocoRobotConfig().timestep
        p50, worst = float(np.median(ticks)), int(max(ticks))
        delays, sim_ticks = {}, {}
        for name, count in (("typical", p50), ("worst", worst)):
            delay = delay_steps(max(0.0, count - 1.0) * period, timestep) * timestep
            delays[name] = delay * 1e3
            sim_ticks[name] = float(np.median(sim_probe(wire_robot, delay, period=period)))
        figures = WireLatency(round_trip_ms_p50=hw.round_trip_ms_p50, round_trip_ms_p99=hw.round_trip_ms_p99,
                              period_ms=period * 1e3, wire_ticks=tuple(ticks), wire_ticks_p50=p50,
                              wire_ticks_mean=float(np.mean(ticks)), wire_ticks_max=worst,
                              typical_delay_ms=delays["typical"], sim_ticks_typical=sim_ticks["typical"],
                              worst_delay_ms=delays["worst"], sim_ticks_worst=sim_ticks["worst"])
    margins = tuple(delay_margin(c, scenario, trials=trials) for c in controllers)
    return LatencyBenchResult(wire_robot=wire_robot, scenario=scenario, coarse_ms=COARSE_MS, fine_ms=FINE_MS,
                              wire=figures, margins=margins, machine=machine_description(), load_1min=load_1min())
