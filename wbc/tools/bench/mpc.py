"""``wbc bench mpc``: the MPC controller's speed in closed loop on one core, played through the runner's one loop.

The walk is an ordinary `run_episode`: the runner times every `act` (the episode's ``act_s``), and an observer reads,
after every tick, the controller's own breakdown of it (`HasTickTimings`), outside the timed call. A controller that
reports no breakdown still walks; the figures that need one are then nan. Another observer keeps the QP of every MPC
update of the walk (`QpLog`); after the walk each is solved again by every QP backend (`wbc.mpc.qp_solvers`), from
the warm start the loop gave it, and the backends are compared on the same QPs (`QpSolverFigures`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from wbc.arena.divergence import DivergenceCheck
from wbc.arena.episode import Episode
from wbc.arena.executors import spawn_pool, worker_environment
from wbc.arena.runner import run_episode
from wbc.control.plugin import read_controller_config
from wbc.control.protocol import Controller, HasTickTimings
from wbc.control.registry import CONTROLLERS, get_controller
from wbc.control.stand import stand_command
from wbc.errors import BenchError, ConfigError
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.hardware.robot import Robot
from wbc.mpc.centroidal_model import NU
from wbc.mpc.centroidal_mpc import MpcProblem
from wbc.mpc.controller import MpcController
from wbc.mpc.qp_solvers import QP_SOLVERS, QpResult, check_qp_solver
from wbc.mpc.tail_controller import TailMpcController
from wbc.robots.registry import get_robot
from wbc.scenario.trial import CommandSchedule
from wbc.tools.bench.references import (
    MPC_REFERENCE_TARGETS,
    load_1min,
    machine_description,
    reference_a1_steps_per_s,
    reference_placo_tick_us,
    scaled_target,
)
from wbc.types import VelocityCommand

__all__ = ["DEFAULT_ROUNDS", "MAX_RECORDED_QPS", "MAX_ROUNDS", "WARMUP_S", "MpcBenchResult", "MpcReference",
           "MpcRound", "MpcTickFigures", "PhysicsTimedRobot", "QpLog", "QpSolverFigures", "TickTimingLog", "bench_mpc",
           "compare_qp_solvers", "physics_realtime_factors"]

WARMUP_S = 0.2
"""Length of the untimed episode played before the timed walk [s] (its wall time is reported as
``warmup_episode_s``: it holds the compiled code's first load)."""


DEFAULT_ROUNDS = 3
"""Timed walks of `bench_mpc`, each between two measurements of the references."""

MAX_ROUNDS = 20
"""The most timed walks `bench_mpc` plays."""


MAX_RECORDED_QPS = 1000
"""The most MPC updates of the timed walk kept for the backends' comparison (a 32 s walk at one update per 32 ms)."""


def _median(values: Sequence[float], scale: float) -> float:
    return scale * float(np.median(values)) if values else math.nan


@dataclass(frozen=True, kw_only=True)
class MpcTickFigures:
    """The controller's tick, by what ran in it (`TickTimingLog.figures`); nan where no tick was filed.

    Attributes:
        mpc_solve_ms_median: median QP solve time of the MPC updates [ms].
        mpc_solve_ms_p99: 99th percentile of that time [ms].
        mpc_setup_ms_median: median setup time (linearisation, condensing) of the MPC updates [ms].
        wbc_tick_us_median: median time of the whole-body layer over the ticks it was timed on [us]: the leg layer
            (the default) is timed apart only on the MPC-update ticks and an episode's first (on the others it runs
            inside the tick's one compiled call), PlaCo's whole-body QP (``mpc-wbqp``) on every tick.
        control_tick_us_median: median whole control tick without an MPC update [us].
    """

    mpc_solve_ms_median: float
    mpc_solve_ms_p99: float
    mpc_setup_ms_median: float
    wbc_tick_us_median: float
    control_tick_us_median: float

    def as_dict(self) -> dict[str, float]:
        """Plain dict, keys as the attributes' names."""
        return asdict(self)


@dataclass(frozen=True, kw_only=True)
class MpcReference:
    """The references of the MPC targets (`MPC_REFERENCE_TARGETS`), measured beside the closed loop.

    Attributes:
        reference_placo_tick_us: a bare-A1 PlaCo whole-body tick, mean of the measurements [us].
        reference_steps_per_s: the bare A1's single-threaded physics, best of the measurements [steps/s].
        physics_realtime_factor: the same robot's physics alone (`physics_realtime_factors`), best.
        control_tick_over_reference_tick: the control tick's median over the reference PlaCo tick (target <= 1.8).
        closed_loop_over_physics_rtf: the closed loop's real-time factor over the physics-only one, the median of
            the rounds' (`MpcRound`; target >= 0.075).
        physics_cpu_realtime_factor: the same robot's physics alone, simulated seconds per second of the thread's CPU
            time, best of the measurements.
        closed_loop_over_physics_cpu: the closed loop's CPU real-time factor over the physics-only one, the median
            of the rounds' (the same ratio in CPU time, which the machine's other jobs move less than wall time;
            target >= 0.20).
        closed_loop_over_physics_cpu_min: the lowest of the rounds' CPU ratios.
        closed_loop_over_physics_cpu_max: the highest of them: with the median, how far the machine moved the figure
            within one run.
        scaled_target_wbc_tick_us: 100 us times the reference tick over 40 us [us].
        scaled_target_realtime_factor: 5x times the reference physics over 110k steps/s.
    """

    reference_placo_tick_us: float
    reference_steps_per_s: float
    physics_realtime_factor: float
    control_tick_over_reference_tick: float
    closed_loop_over_physics_rtf: float
    scaled_target_wbc_tick_us: float
    scaled_target_realtime_factor: float
    physics_cpu_realtime_factor: float = math.nan
    closed_loop_over_physics_cpu: float = math.nan
    closed_loop_over_physics_cpu_min: float = math.nan
    closed_loop_over_physics_cpu_max: float = math.nan

    def as_dict(self) -> dict[str, float]:
        """Plain dict, keys as the attributes' names."""
        return asdict(self)


@dataclass(frozen=True, kw_only=True)
class MpcRound:
    """One round of `bench_mpc`: the timed walk, and the physics-alone references measured just before and after it.

    A machine shared with others (a cloud VM) changes speed over seconds, by up to 2x here: a ratio is only read
    against references taken around the same walk, and the rounds' spread says how much the machine moved.

    Attributes:
        realtime_factor: the walk's simulated seconds per wall-clock second.
        cpu_realtime_factor: the walk's simulated seconds per second of the thread's CPU time.
        walk_physics_realtime_factor: the walk's simulated seconds per wall-clock second of its physics steps.
        walk_physics_share: the part of the walk's wall time spent in its physics steps.
        physics_realtime_factor: the robot's physics alone, the better of the two measurements around the walk
            (nan without references).
        physics_cpu_realtime_factor: the same in CPU time (nan without references).
    """

    realtime_factor: float
    cpu_realtime_factor: float
    walk_physics_realtime_factor: float
    walk_physics_share: float
    physics_realtime_factor: float = math.nan
    physics_cpu_realtime_factor: float = math.nan

    @property
    def over_physics(self) -> float:
        """The walk's real-time factor over the physics-alone one around it (nan without references)."""
        return self.realtime_factor / self.physics_realtime_factor

    @property
    def over_physics_cpu(self) -> float:
        """The same in CPU time (nan without references)."""
        return self.cpu_realtime_factor / self.physics_cpu_realtime_factor


@dataclass(frozen=True, kw_only=True)
class QpSolverFigures:
    """One QP backend on the QPs of the walk (`compare_qp_solvers`), against DAQP's solutions of the same QPs.

    Attributes:
        solver: the backend's registry name (`wbc.mpc.qp_solvers.QP_SOLVERS`).
        version: its package's version.
        qps: how many QPs it was given.
        unsolved: how many of them it did not solve (left out of the differences).
        solve_ms_median: median solve time [ms].
        solve_ms_p99: 99th percentile of the solve time [ms].
        iterations_median: median iterations.
        iterations_max: most iterations.
        force_max_diff_n: largest difference of a planned contact force component from DAQP's, over every step of
            every QP both solved [N]; 0 for DAQP itself.
        objective_max_diff: largest difference of the QP's cost at its solution from the cost at DAQP's (the
            cost's own units; positive: above DAQP's optimum).
    """

    solver: str
    version: str
    qps: int
    unsolved: int
    solve_ms_median: float
    solve_ms_p99: float
    iterations_median: float
    iterations_max: int
    force_max_diff_n: float
    objective_max_diff: float

    def as_dict(self) -> dict[str, float | int | str]:
        """The figures under their keys in `MpcBenchResult.as_dict` (``qp_<solver>_solve_ms_median`` ...)."""
        return {f"qp_{self.solver}_{key}": value for key, value in asdict(self).items() if key != "solver"}


@dataclass(frozen=True, kw_only=True)
class MpcBenchResult:
    """What `bench_mpc` measured: the MPC controller's tick and closed loop, and the references when measured.

    Attributes:
        robot: robot registry name.
        controller: the MPC controller's registry name.
        horizon: the MPC's horizon N [steps].
        ticks: the tick's breakdown (nan for a controller that reports none).
        realtime_factor: simulated seconds per wall-clock second of the whole closed loop (the median of the
            rounds', as are the three figures below).
        cpu_realtime_factor: simulated seconds per second of the thread's CPU time (`time.thread_time`) over the
            same closed loop.
        walk_physics_realtime_factor: simulated seconds per wall-clock second spent in the simulator's steps during
            the closed loop: the walk's own physics, which costs more than a standing robot's (its contacts change
            and the contact solver iterates more).
        walk_physics_share: the part of the closed loop's wall time spent in those steps (the closed loop's
            real-time factor over the walk's own physics).
        warmup_episode_s: wall time of the untimed warm-up walk [s].
        fell: whether the robot fell during the timed walk.
        blas: ``single-threaded`` (run in a spawned process with one BLAS thread) or ``default threads``.
        qp_solver: the closed loop's QP backend and its version.
        machine: `machine_description`.
        load_1min: the machine's load average over the minute before the walk ended (nan where the system does not
            tell): what else ran beside the bench.
        reference: the references' figures, or None when they were not measured.
        qp_solvers: every QP backend on the QPs of the timed walk, DAQP first (`compare_qp_solvers`); empty when
            none was recorded.
        qp_comparison_skipped: why `qp_solvers` is empty (the tail MPC solves a QP of its own, or the walk made no
            MPC update), or None when the backends were compared.
        rounds: each timed walk with the references around it, in order (`MpcRound`).
        controller_config: the ``--controller-config`` file the controller was built with, as given, or None.
    """

    robot: str
    controller: str
    horizon: int
    ticks: MpcTickFigures
    realtime_factor: float
    warmup_episode_s: float
    fell: bool
    blas: str
    qp_solver: str
    machine: str
    load_1min: float = math.nan
    cpu_realtime_factor: float = math.nan
    walk_physics_realtime_factor: float = math.nan
    walk_physics_share: float = math.nan
    reference: MpcReference | None = None
    qp_solvers: tuple[QpSolverFigures, ...] = ()
    rounds: tuple[MpcRound, ...] = ()
    qp_comparison_skipped: str | None = None
    controller_config: str | None = None

    def as_dict(self) -> dict[str, float | str | int | bool | None]:
        """Plain flat dict (the JSON output of ``wbc bench mpc``).

        The references' figures follow when measured, then each QP backend's (``qp_<solver>_...``);
        ``qp_comparison_skipped`` says why there are none (null when there are).
        """
        out: dict[str, float | str | int | bool | None] = {
            "robot": self.robot, "controller": self.controller, "horizon": self.horizon, **self.ticks.as_dict(),
            "realtime_factor": self.realtime_factor, "cpu_realtime_factor": self.cpu_realtime_factor,
            "walk_physics_realtime_factor": self.walk_physics_realtime_factor,
            "walk_physics_share": self.walk_physics_share, "warmup_episode_s": self.warmup_episode_s,
            "fell": self.fell, "blas": self.blas, "qp_solver": self.qp_solver, "machine": self.machine,
            "load_1min": self.load_1min, "rounds": len(self.rounds),
            "qp_comparison_skipped": self.qp_comparison_skipped, "controller_config": self.controller_config}
        if self.reference is not None:
            out.update(self.reference.as_dict())
        for figures in self.qp_solvers:
            out.update(figures.as_dict())
        return out


@dataclass
class TickTimingLog:
    """A runner observer that files each tick by what ran in it, from the controller's breakdown [s].

    Ticks with an MPC update (the breakdown has ``mpc_solve_s``) give the MPC's solve and setup times; the others are
    plain control ticks, whose durations `figures` takes from the episode (``act_s``). Every tick whose whole-body
    layer the controller timed apart gives ``whole_body_s`` (`MpcController.tick_timings`: the MPC-update ticks and an
    episode's first for the leg layer, every tick for PlaCo's QP). Without a breakdown a tick cannot be filed.

    Attributes:
        mpc_solve_s: QP solve time of each MPC update [s].
        mpc_setup_s: setup time (linearisation, condensing) of each MPC update [s].
        whole_body_s: the whole-body layer's time on each tick it was timed on [s].
        plain_ticks: indices of the ticks filed without an MPC update.
    """

    mpc_solve_s: list[float] = field(default_factory=list)
    mpc_setup_s: list[float] = field(default_factory=list)
    whole_body_s: list[float] = field(default_factory=list)
    plain_ticks: list[int] = field(default_factory=list)
    _ticks: int = field(default=0, init=False, repr=False)

    def __call__(self, t: float, robot: Robot, controller: Controller, command: VelocityCommand) -> None:
        """File the tick that just ended (the runner's `TickObserver` signature)."""
        tick, self._ticks = self._ticks, self._ticks + 1
        if not isinstance(controller, HasTickTimings):
            return
        timings = controller.tick_timings()
        if "mpc_solve_s" in timings:
            self.mpc_solve_s.append(timings["mpc_solve_s"])
            if "mpc_setup_s" in timings:
                self.mpc_setup_s.append(timings["mpc_setup_s"])
        else:
            self.plain_ticks.append(tick)
        if "whole_body_s" in timings:
            self.whole_body_s.append(timings["whole_body_s"])

    def figures(self, episode: Episode) -> MpcTickFigures:
        """Medians (and the solve's 99th percentile) in the units of their names; nan where no tick was filed.

        Args:
            episode: the episode the observer watched (its per-tick ``act_s``).
        """
        solves = self.mpc_solve_s
        control_s = episode.act_s[self.plain_ticks].tolist()
        return MpcTickFigures(
            mpc_solve_ms_median=_median(solves, 1e3),
            mpc_solve_ms_p99=1e3 * float(np.percentile(solves, 99)) if solves else math.nan,
            mpc_setup_ms_median=_median(self.mpc_setup_s, 1e3),
            wbc_tick_us_median=_median(self.whole_body_s, 1e6),
            control_tick_us_median=_median(control_s, 1e6),
        )


@dataclass
class QpLog:
    """A runner observer that keeps the QP of each MPC update (and the warm start it was given), up to `limit`.

    Only an `MpcController` has one: after a tick that made an MPC update (its breakdown has ``mpc_solve_s``) the
    problem its MPC last solved is kept by reference (each update builds a new one).

    Attributes:
        limit: the most QPs kept.
        qps: (problem, warm start as the full scaled input vector or None) of each update, in order.
    """

    limit: int = MAX_RECORDED_QPS
    qps: list[tuple[MpcProblem, np.ndarray | None]] = field(default_factory=list)

    def __call__(self, t: float, robot: Robot, controller: Controller, command: VelocityCommand) -> None:
        """Keep the tick's QP, if it made one (the runner's `TickObserver` signature)."""
        if len(self.qps) >= self.limit or not isinstance(controller, MpcController):
            return
        if "mpc_solve_s" in controller.tick_timings() and controller.mpc.last_problem is not None:
            self.qps.append((controller.mpc.last_problem, controller.mpc.last_warm_start))


def compare_qp_solvers(qps: Sequence[tuple[MpcProblem, np.ndarray | None]]) -> tuple[QpSolverFigures, ...]:
    """Solve every QP with every backend of `QP_SOLVERS`, from the warm start the loop gave it, and compare.

    The backends take turns on each QP (all of them on the first, then on the second ...), so a change of the
    machine's load between the start and the end of the run falls on all of them alike. Differences are taken
    against DAQP's solution of the same QP.

    Args:
        qps: (problem, warm start as the full scaled input vector or None) pairs, as `QpLog` keeps them.

    Returns:
        One `QpSolverFigures` per backend, in `QP_SOLVERS` order (DAQP first); empty when `qps` is.
    """
    if not qps:
        return ()
    solvers = [make() for make in QP_SOLVERS.values()]
    results: list[list[QpResult]] = [[] for _ in solvers]
    for problem, warm in qps:
        z0 = None if warm is None else np.clip(warm[problem.index], problem.l_box, problem.u_box)
        for solver, out in zip(solvers, results, strict=True):
            out.append(solver.solve(problem, z0))
    reference = results[list(QP_SOLVERS).index("daqp")]
    figures = []
    for solver, out in zip(solvers, results, strict=True):
        force_diff, cost_diff = [], []
        for (problem, _), mine, ref in zip(qps, out, reference, strict=True):
            if not (mine.solved and ref.solved):
                continue
            forces = problem.index % NU < 12
            force_diff.append(float(np.max(np.abs((mine.z - ref.z) * problem.scale)[forces], initial=0.0)))
            cost_diff.append(problem.objective(mine.z) - problem.objective(ref.z))
        times = [r.solve_s for r in out]
        iterations = [r.iterations for r in out]
        figures.append(QpSolverFigures(
            solver=solver.name, version=solver.version(), qps=len(out), unsolved=sum(not r.solved for r in out),
            solve_ms_median=_median(times, 1e3), solve_ms_p99=1e3 * float(np.percentile(times, 99)),
            iterations_median=float(np.median(iterations)), iterations_max=int(max(iterations)),
            force_max_diff_n=max(force_diff) if force_diff else math.nan,
            objective_max_diff=max(cost_diff, key=abs) if cost_diff else math.nan))
    return tuple(figures)


def physics_realtime_factors(sim: MujocoRobot, seconds: float = 1.0) -> tuple[float, float]:
    """Real-time factors of `sim`'s physics alone: the robot standing under the motor law, no controller in the loop.

    The closed loop's real-time factor is stated against these, measured on the same robot in the same process: they
    are what the loop would reach if the controller and the runner took no time and the walk's contacts cost what
    standing ones do.

    Args:
        sim: a connected simulated robot (reset here, and left standing).
        seconds: simulated time measured [s].

    Returns:
        (wall, CPU) real-time factors: simulated seconds per second of wall time and of the thread's CPU time
        (`time.thread_time`), from one run.
    """
    sim.reset(seed=0)
    sim.write(stand_command(sim.desc))
    sim.advance(0.2)
    # whole physics steps: advance takes no part of one
    seconds = max(1, round(seconds / sim.config.timestep)) * sim.config.timestep
    c0, t0 = time.thread_time(), time.perf_counter()
    sim.advance(seconds)
    wall, cpu = time.perf_counter() - t0, time.thread_time() - c0
    return seconds / wall, seconds / max(cpu, 1e-9)


class PhysicsTimedRobot(MujocoRobot):
    """A simulated robot that adds up the wall time of its physics steps (`physics_s`), for `bench_mpc`'s walk.

    Two ``time.perf_counter`` calls an advance (~0.1 us): the closed loop it times is slowed by less than 0.1 %.
    """

    physics_s: float = 0.0

    def _advance(self, dt: float) -> None:
        t0 = time.perf_counter()
        super()._advance(dt)
        self.physics_s += time.perf_counter() - t0


def _check_tail_qp_solver(factory: object, controller: str, qp_solver: str | None) -> None:
    """Refuse a QP backend other than DAQP for a tail MPC controller (`factory`: its class, or any factory).

    The tail controller plans with `wbc.mpc.tail_mpc.TailMpc`, whose QP (the arm's accelerations and the servos'
    bounds besides the forces) DAQP solves directly; the backends of `QP_SOLVERS` take the centroidal MPC's QP only.

    Raises:
        ConfigError: `factory` is a `TailMpcController` class and `qp_solver` is not ``daqp``.
    """
    if qp_solver not in (None, "daqp") and isinstance(factory, type) and issubclass(factory, TailMpcController):
        raise ConfigError(f"--qp-solver {qp_solver}: {controller} solves its tail MPC's QP with daqp only (the other "
                          "backends take the centroidal MPC's QP, which it does not build); leave --qp-solver out "
                          "or give daqp")


def _check_file_qp_solver(config: str | Path, qp_solver: str) -> None:
    """Refuse a `qp_solver` other than the one the ``--controller-config`` file `config` sets in ``[mpc] qp_solver``.

    The file's variant is timed as the arena plays it, on its own backend; a file that sets none leaves the
    backend to ``--qp-solver``.

    Raises:
        ConfigError: the file sets ``[mpc] qp_solver`` to another backend than `qp_solver`.
    """
    mpc = read_controller_config(config).get("mpc")
    own = mpc.get("qp_solver") if isinstance(mpc, Mapping) else None
    if own is not None and own != qp_solver:
        raise ConfigError(f"--qp-solver {qp_solver}: {config} sets [mpc] qp_solver = {own!r}, and bench mpc times "
                          "the variant as the arena plays it; leave --qp-solver out to time it on "
                          f"{own}, or set [mpc] qp_solver = {qp_solver!r} in {config}")


def bench_mpc(robot: str = "a1-wx200", controller: str = "mpc", *, seconds: float = 4.0, vx: float = 0.3,
              single_thread: bool = True, reference: bool = True, qp_solver: str | None = None,
              rounds: int = DEFAULT_ROUNDS, config: str | Path | None = None) -> MpcBenchResult:
    """Speed of the MPC controller in closed loop on one core: MPC solves, whole-body ticks, real-time factor.

    With `single_thread` (the default) it runs in a spawned process whose BLAS is single-threaded, as every arena
    worker is: a BLAS that spreads the MPC's condensing products over the cores is no faster on an idle machine and
    many times slower on a busy one.

    The robot walks at `vx` on flat ground for `seconds` (or until it falls) through `run_episode`, after an untimed
    walk of `WARMUP_S` (the compiled parts of the tick load at their first call; ``warmup_episode_s`` is that walk's
    wall time). The timed walk is played `rounds` times (the same walk each time), with the references measured before
    the first and after each (`MpcRound`): each round's ratio is read against the references just around it, and the
    result gives the rounds' medians and the ratio's spread. From the controller's breakdown of each tick
    (`HasTickTimings`): every MPC update's QP solve time (the `qp_solver` backend's) and setup time (linearisation and
    condensing), and ``wbc_tick_us_median``, the whole-body layer's median time over the ticks it is timed on (the leg
    layer's: the MPC-update ticks; PlaCo's QP, every tick: kinematics, dynamics, tasks, QP, plus setting its targets
    from Python). ``control_tick_us_median`` is the whole control tick without an MPC update
    (estimator, kinematics, footholds, swing targets, whole-body QP, motor command). These are nan for a controller that
    reports no breakdown. The real-time factor covers everything: physics, controller, MPC updates and the runner's
    episode log; it is given in wall time and in the thread's CPU time (``cpu_realtime_factor``), and the simulator's
    steps are timed within the walk (``walk_physics_realtime_factor``, ``walk_physics_share``): a walking robot's
    physics costs more than the standing robot's that the reference measures. These come from a walk that nothing but
    the runner watches; the breakdown and the QPs come from the same walk played again (same seed, the same ticks) with
    the bench's observers, whose own cost (10-20 % of a tick) would otherwise count as the loop's.

    The QPs of the walk's MPC updates (up to `MAX_RECORDED_QPS`) are then solved again by every QP backend, from the
    warm starts the loop gave them (`compare_qp_solvers`): ``qp_solvers`` holds their solve times, iterations and
    distance from DAQP's solutions.

    With `reference`, the references of the MPC targets (`MPC_REFERENCE_TARGETS`) are measured around every timed walk
    in the same process: a bare-A1 PlaCo tick (`reference_placo_tick_us`), the bare A1's single-threaded physics
    (`reference_a1`) and the same robot's physics alone (`physics_realtime_factors`). The result then holds them
    (`MpcReference`) with the ratios the targets are set on, ``control_tick_over_reference_tick`` (the control tick's
    median over the reference PlaCo tick; target <= 1.8) and ``closed_loop_over_physics_rtf`` (the closed loop's
    real-time factor over the same robot's physics-only one, the median of the rounds' ratios; target >= 0.075; in CPU
    time ``closed_loop_over_physics_cpu``, target >= 0.20, with the rounds' lowest and highest), and the older targets
    scaled by the references to this machine: ``scaled_target_wbc_tick_us`` (100 us times the reference tick over 40 us)
    and ``scaled_target_realtime_factor`` (5x times the reference physics over 110k steps/s).

    Args:
        robot: robot registry name.
        controller: an MPC controller's registry name (``mpc``, ``mpc-tail``, ``mpc-locked``, ``mpc-noarm`` ...).
        seconds: length of the walk [s].
        vx: forward velocity command [m/s].
        single_thread: run in a spawned process with a single-threaded BLAS.
        reference: also measure the references.
        qp_solver: the closed loop's QP backend (`wbc.mpc.qp_solvers.QP_SOLVERS`); the comparison runs them all.
            None: the controller's own (the `config` file's ``[mpc] qp_solver``, else DAQP). Given, it replaces
            the controller's own, except that a `config` file that sets ``[mpc] qp_solver`` to another backend is
            refused: the variant is timed as the arena plays it. A tail controller (``mpc-tail``) solves its own QP
            with DAQP: it takes ``daqp`` only, and its result
            holds no comparison (``qp_comparison_skipped`` says why).
        rounds: how many times the timed walk is played (1 to `MAX_ROUNDS`).
        config: a plug-in's ``--controller-config`` TOML file (e.g. `wbc.mpc.config_table`'s settings of a variant),
            as `get_controller` takes it.

    Returns:
        The figures above with the horizon, whether the robot fell, the BLAS threading and the machine.

    Raises:
        UnknownNameError: unknown robot or controller.
        PluginConfigError: `config` for a controller that is not a plug-in.
        SimulationDiverged: the simulation blew up during the walk (no figure of a blown-up walk is reported).
        BenchError: the controller is not an MPC controller, or a reference failed.
        ConfigError: `qp_solver` is not a QP backend (the message lists them), or is not ``daqp`` for the tail MPC
            controller (``mpc-tail``, which solves its own QP with DAQP), or differs from the ``[mpc] qp_solver``
            that the `config` file sets (the message names the file and the field), or `rounds` is out of its range, or
            `seconds` is shorter than one control tick.
    """
    if qp_solver is not None:
        check_qp_solver(qp_solver, "--qp-solver")
    if isinstance(rounds, bool) or not isinstance(rounds, int) or not 1 <= rounds <= MAX_ROUNDS:
        raise ConfigError(f"--rounds must be a whole number of timed walks from 1 to {MAX_ROUNDS}, got {rounds!r}")
    # the names are checked here, before the worker is spawned: a mistyped name is refused at once, and its message
    # does not depend on the error travelling back from the worker
    spec = get_controller(controller, config=config)
    get_robot(robot, spec.arm_mode)
    if config is not None and qp_solver is not None:
        _check_file_qp_solver(config, qp_solver)
    _check_tail_qp_solver(getattr(spec.make, "func", spec.make), controller, qp_solver)
    if single_thread:
        with worker_environment(), spawn_pool(1) as pool:
            result = pool.submit(bench_mpc, robot, controller, seconds=seconds, vx=vx, single_thread=False,
                                 reference=reference, qp_solver=qp_solver, rounds=rounds,
                                 config=config).result()
        return replace(result, blas="single-threaded")
    sim = PhysicsTimedRobot(MujocoRobotConfig(robot=robot, arm_mode=spec.arm_mode))
    ctrl = spec.make(sim.desc)
    if not isinstance(ctrl, MpcController):
        valid = [name for name, s in CONTROLLERS.items() if isinstance(getattr(s.make, "func", s.make), type)
                 and issubclass(getattr(s.make, "func", s.make), MpcController)]  # mpc-tail's is a subclass
        raise BenchError(f"bench mpc times an MPC controller, and {controller!r} is not one; use one of: "
                         f"{', '.join(valid)}")
    _check_tail_qp_solver(type(ctrl), controller, qp_solver)  # a plug-in's factory may return a tail controller
    period = 1.0 / ctrl.rate_hz
    if int(round(seconds / period)) < 1:  # the runner would refuse the walk, naming the controller's rate
        raise ConfigError(f"--seconds {seconds:g}: the walk must hold at least one control tick of {controller} "
                          f"({period:g} s at {ctrl.rate_hz:g} Hz); give --seconds {period:g} or more")
    if qp_solver is not None and ctrl.config.mpc.qp_solver != qp_solver:
        # the file (if any) leaves the backend to its default: the one asked for replaces it
        ctrl = type(ctrl)(sim.desc, replace(ctrl.config, mpc=replace(ctrl.config.mpc, qp_solver=qp_solver)))
    ref_ticks, ref_rates, physics, physics_cpu = [], [], [], []

    def measure_references() -> None:
        ref_ticks.append(reference_placo_tick_us(500))
        ref_rates.append(reference_a1_steps_per_s(1000))
        wall, cpu = physics_realtime_factors(sim)
        physics.append(wall)
        physics_cpu.append(cpu)

    log, qps = TickTimingLog(), QpLog()

    def observe(t: float, robot: Robot, controller: Controller, command: VelocityCommand) -> None:
        log(t, robot, controller, command)
        qps(t, robot, controller, command)

    with sim:
        # a short episode first, untimed: the compiled parts of the tick load (or compile, on a machine's first run)
        # at their first call, once per process; an arena worker pays that once for all its trials
        sim.reset(seed=0)
        warm_start = time.perf_counter()
        run_episode(sim, ctrl, CommandSchedule(vx=vx), WARMUP_S, divergence=DivergenceCheck())
        warmup_wall = time.perf_counter() - warm_start
        if reference:
            measure_references()
        # the timed walk runs without the bench's own observers (they cost 10-20 % of a tick); the same walk again,
        # observed, gives the breakdown of its ticks and the QPs (the loop is deterministic: same seed, same walk)
        timed_rounds, fell = [], False
        for _ in range(rounds):
            sim.reset(seed=0)
            sim.physics_s = 0.0
            cpu_start, start = time.thread_time(), time.perf_counter()
            timed = run_episode(sim, ctrl, CommandSchedule(vx=vx), seconds, divergence=DivergenceCheck())
            wall, cpu = time.perf_counter() - start, time.thread_time() - cpu_start
            walk_physics_s = sim.physics_s
            fell = fell or timed.fell
            if reference:
                measure_references()
            timed_rounds.append(MpcRound(
                realtime_factor=timed.survived_s / wall, cpu_realtime_factor=timed.survived_s / max(cpu, 1e-9),
                walk_physics_realtime_factor=timed.survived_s / max(walk_physics_s, 1e-9),
                walk_physics_share=walk_physics_s / wall,
                physics_realtime_factor=max(physics[-2:]) if reference else math.nan,
                physics_cpu_realtime_factor=max(physics_cpu[-2:]) if reference else math.nan))
        load = load_1min()
        sim.reset(seed=0)
        episode = run_episode(sim, ctrl, CommandSchedule(vx=vx), seconds, observer=observe,
                              divergence=DivergenceCheck())
    figures = log.figures(episode)

    def median(values: Sequence[float]) -> float:
        return float(np.median(values))

    realtime = median([r.realtime_factor for r in timed_rounds])
    refs = None
    if reference:
        tick_ref, rate_ref, physics_rtf = float(np.mean(ref_ticks)), max(ref_rates), max(physics)
        cpu_ratios = [r.over_physics_cpu for r in timed_rounds]
        refs = MpcReference(
            reference_placo_tick_us=tick_ref, reference_steps_per_s=rate_ref, physics_realtime_factor=physics_rtf,
            control_tick_over_reference_tick=figures.control_tick_us_median / tick_ref,
            closed_loop_over_physics_rtf=median([r.over_physics for r in timed_rounds]),
            physics_cpu_realtime_factor=max(physics_cpu), closed_loop_over_physics_cpu=median(cpu_ratios),
            closed_loop_over_physics_cpu_min=min(cpu_ratios), closed_loop_over_physics_cpu_max=max(cpu_ratios),
            scaled_target_wbc_tick_us=scaled_target(MPC_REFERENCE_TARGETS["wbc_tick_us_median"], tick_ref),
            scaled_target_realtime_factor=scaled_target(MPC_REFERENCE_TARGETS["realtime_factor"], rate_ref))
    solver = ctrl.mpc.qp_solver
    skipped = None
    if isinstance(ctrl, TailMpcController):
        skipped = (f"{controller} solves its tail MPC's QP with DAQP directly, and the backends take the centroidal "
                   "MPC's QP, which it does not build")
    elif not qps.qps:
        skipped = "the walk made no MPC update whose QP could be kept"
    return MpcBenchResult(robot=robot, controller=controller, horizon=int(ctrl.config.mpc.horizon), ticks=figures,
                          controller_config=None if config is None else str(config),
                          realtime_factor=realtime,
                          cpu_realtime_factor=median([r.cpu_realtime_factor for r in timed_rounds]),
                          walk_physics_realtime_factor=median([r.walk_physics_realtime_factor for r in timed_rounds]),
                          walk_physics_share=median([r.walk_physics_share for r in timed_rounds]),
                          warmup_episode_s=warmup_wall, fell=bool(fell or episode.fell), rounds=tuple(timed_rounds),
                          blas="default threads", qp_solver=f"{solver.name} {solver.version()}",
                          machine=machine_description(), load_1min=load, reference=refs,
                          qp_solvers=compare_qp_solvers(qps.qps), qp_comparison_skipped=skipped)
