"""How the ``wbc`` command prints what its commands return: JSON, or the tables and lines a person reads.

One printer per result; each takes the result as the tool returned it and writes to stdout. The texts are part of
the command's interface: scripts parse the JSON, people read the tables.
"""

from __future__ import annotations

import json
import math
import os
import shlex
import shutil
import sys
import textwrap
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager, redirect_stdout
from pathlib import Path

import numpy as np

from wbc.arena.compare import ArenaConfig, ArenaResult
from wbc.arena.controller_failure import printed_error
from wbc.arena.hw_trial import HardwareTrialResult
from wbc.arena.report import format_table, format_verdict, resumed_note
from wbc.arena.summary import Summary
from wbc.arena.trial_record import CONTROLLER_ERROR, FALL, TrialRecord
from wbc.control.controller_contract import ControllerCheck
from wbc.control.registry import NAME_FORMS, ControllerListing
from wbc.hardware.capabilities import HasRealtimeGrant
from wbc.hardware.device_thread import DeviceThreadStats
from wbc.hardware.dynamixel.control_table import HARDWARE_ERROR_BITS, OperatingMode
from wbc.hardware.emulators import BusStats
from wbc.hardware.pty_registry import registry_dir
from wbc.hardware.realtime import RealtimeGrant
from wbc.hardware.safety import SafetyState
from wbc.hardware.unitree import LEG_WIRES, REJECT_REASONS
from wbc.scenario.scenario_check import ScenarioCheck
from wbc.tools.arm_momentum import ArmMomentumTrial
from wbc.tools.bench import (
    MPC_REFERENCE_TARGETS,
    REFERENCE_TARGETS,
    TRAIN_TARGET,
    ActBenchResult,
    ArmBenchResult,
    EmulatorCounts,
    HwBenchResult,
    LatencyBenchResult,
    MpcBenchResult,
    SimBenchResult,
    SweepBenchResult,
    TrainBenchResult,
)
from wbc.tools.demo import TrialToWatch
from wbc.tools.emulate import EmulatorServed, EmulatorServing
from wbc.tools.hardware_check import HardwareCheck
from wbc.tools.paper import PaperTableResult, format_paper_table
from wbc.tools.posture import PostureRow
from wbc.tools.tail import TailAnalysis

__all__ = ["print_arena", "print_arm_momentum", "print_bench_hw", "print_bench_mpc", "print_bench_sim",
           "print_bench_sweep", "print_bench_train", "print_controller_check", "print_controllers",
           "print_demo_end", "print_demo_header", "print_emulator_counts", "print_emulator_served",
           "print_emulator_serving", "print_emulator_started", "print_hw_check", "print_hw_run", "print_json",
           "print_paper_table", "print_recording", "print_scenario_check", "print_tail", "print_thread_stats",
           "print_trained",
           "print_viewed_trial", "strict_json"]


def print_json(value: object) -> None:
    """`value` as indented, strict JSON.

    Sequences of any kind are lists, and a number that is not finite (a figure that could not be measured, nan) is
    ``null``, which every JSON reader takes (``NaN`` is Python's, not JSON's). Inside `json_alone`, it goes to the
    standard output the command was given, where everything else printed goes to standard error.
    """
    print(json.dumps(strict_json(value), indent=2, allow_nan=False), file=_JSON_OUT[-1] if _JSON_OUT else sys.stdout)


_JSON_OUT: list = []
"""The standard output `print_json` writes to inside `json_alone` (innermost last)."""


@contextmanager
def json_alone(active: bool = True) -> Iterator[None]:
    """With --json (`active`), standard output carries the JSON alone: whatever else is printed goes to standard error.

    A plug-in controller that prints (``print("building")`` in its factory or ``reset``) wrote into the JSON a script
    parses. Python-level writes only: the arena's worker processes send their own standard output, C-level writes
    included, to standard error as they start (`wbc.arena.executors`).
    """
    if not active:
        yield
        return
    _JSON_OUT.append(sys.stdout)
    try:
        with redirect_stdout(sys.stderr):
            yield
    finally:
        _JSON_OUT.pop()


def strict_json(value: object) -> object:
    """`value` with every float that is not finite replaced by None, tuples and other sequences as lists."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: strict_json(v) for k, v in value.items()}
    if isinstance(value, str | bytes | int | type(None)):
        return value
    if isinstance(value, np.generic):
        return strict_json(value.item())
    if isinstance(value, np.ndarray):
        return strict_json(value.tolist())
    try:
        return [strict_json(v) for v in value]  # type: ignore[union-attr]
    except TypeError:
        return value


def print_tail(result: TailAnalysis) -> None:
    """The tail analysis: the model's inputs, then rod model, exact and paper figures side by side."""
    print(f"Arm as a tail: {result.robot}")
    print(f"  inputs: moving arm mass M_a = {result.arm_mass_moving:.3f} kg, rest M_b = {result.body_mass:.3f} kg, "
          f"arm length l = {result.arm_length:.3f} m, trunk h x w = {result.trunk_height:.3f} x "
          f"{result.trunk_width:.3f} m")
    print(f"  {'quantity':<34}{'rod model':>11}{'exact':>10}{'paper':>9}")
    print(f"  {'CoM shift by arm rotation [m]':<34}{result.ccom_shift_m:>11.4f}{result.ccom_shift_m_exact:>10.4f}"
          f"{result.paper_ccom_shift_m:>9.3f}")
    print(f"  {'body/arm angular acceleration':<34}{result.alpha_ratio:>11.3f}{result.alpha_ratio_exact:>10.3f}"
          f"{result.paper_alpha_ratio:>9.3f}")


def print_posture(rows: Sequence[PostureRow], *, duration_s: float) -> None:
    """One line per controller: trunk height and forward speed standing and walking, and any fall."""
    if not rows:
        return
    walk = next(r.vx for r in rows if r.command == "walk")
    print(f"posture on flat ground, no pushes: {rows[0].robot}, means over seconds {duration_s / 2:g}-{duration_s:g}")
    by_name: dict[str, dict[str, PostureRow]] = {}
    for r in rows:
        by_name.setdefault(r.controller, {})[r.command] = r
    w = max(len("controller"), *(len(name) for name in by_name)) + 2
    print(f"  {'controller':<{w}}{'arm':<10}{'stand h [m]':>15}{f'walk {walk:g} h [m]':>17}{'walk v [m/s]':>14}  falls")
    for name, cmds in by_name.items():
        stand, walking = cmds["stand"], cmds["walk"]
        falls = ", ".join(f"{c} at {r.fall_time_s:.1f} s" for c, r in cmds.items() if r.fell) or "-"
        falls += "".join(f"; {c}: {r.diverged}" for c, r in cmds.items() if r.diverged)
        print(f"  {name:<{w}}{stand.arm_mode:<10}{_metres(stand):>15}{_metres(walking):>17}"
              f"{walking.speed_m_s:>14.2f}  {falls}")


def _metres(row: PostureRow) -> str:
    if row.diverged:
        return "diverged"
    return "fell" if math.isnan(row.height_m) else f"{row.height_m:.3f} ± {row.height_std_m:.3f}"


def print_arm_momentum(rows: Sequence[ArmMomentumTrial], *, controller: str, scenario: str, band: str,
                       settings: str | None = None) -> None:
    """One line per trial of the arm-momentum study, then the means over the trials that reached a push.

    What cannot be measured is said in words, never as nan or 0 %: a band with no push, a controller with no arm
    that moves on its own, the trials left out of the means because they fell before their first push.
    """
    built = "" if settings is None else f" (settings {settings})"
    print(f"arm momentum during push recovery: {controller}{built}, {scenario} band {band}")
    print("  seed trial survived  arm travel [rad]  push |r x F| T [N m s]  arm |h| peak [N m s]  arm |h| mean  "
          "bound [N m s]  peak/bound  cos(h, r x F)")
    for r in rows:
        print(f"  {r.seed:4d} {r.trial:5d} {str(r.survived):8s}  {r.arm_travel_rad:16.1f}  "
              f"{_figure(r.push_angular_impulse, '22.3f')}  {_figure(r.arm_momentum_peak, '20.3f')}  "
              f"{r.arm_momentum_mean:12.3f}  {_figure(r.arm_momentum_bound, '13.3f')}  "
              f"{_figure(r.bound_fraction, '10.2f')}  {_figure(r.alignment, '+13.2f')}")
    if not rows:
        return
    if not any(r.pushes for r in rows):
        print(f"  mean: travel {np.mean([r.arm_travel_rad for r in rows]):.1f} rad, arm momentum mean "
              f"{np.mean([r.arm_momentum_mean for r in rows]):.3f} N m s")
        print(f"  band {band} of {scenario} has no push: there is no push's angular impulse to set the arm's momentum "
              "against; give a scenario and band with pushes (e.g. --scenario scenarios/push.toml --band ood)")
        return
    measured = [r for r in rows if r.pushes_measured > 0]
    early = len(rows) - len(measured)
    if early:
        print(f"  {early} of {_count(len(rows), 'trial')} fell before their first push and are left out of the "
              "means: they have no push to measure the arm against")
    if not measured:
        print("  no trial lasted to its first push: nothing to average")
        return
    mean = {k: _nanmean([getattr(r, k) for r in measured])
            for k in ("arm_travel_rad", "push_angular_impulse", "arm_momentum_peak", "arm_momentum_mean",
                      "arm_momentum_bound", "bound_fraction", "alignment")}
    over = f" over the {_count(len(measured), 'trial')} that reached a push" if early else ""
    arm_mode = rows[0].arm_mode
    if arm_mode != "actuated":
        print(f"  mean{over}: push angular impulse {mean['push_angular_impulse']:.3f} N m s")
        has = "has no arm" if arm_mode == "none" else "holds its arm locked on the trunk"
        print(f"  {controller} {has} (arm mode {arm_mode}): no arm moves to take up the pushes' angular momentum, so "
              "there is no arm momentum, bound or alignment to report; play a controller with an actuated arm "
              "(e.g. --controller mpc)")
        return
    print(f"  mean{over}: travel {mean['arm_travel_rad']:.1f} rad, push angular impulse "
          f"{mean['push_angular_impulse']:.3f} N m s, arm momentum peak {mean['arm_momentum_peak']:.3f} N m s "
          f"({100 * mean['arm_momentum_peak'] / max(mean['push_angular_impulse'], 1e-9):.0f} % of the impulse), "
          f"mean {mean['arm_momentum_mean']:.3f} N m s")
    alignment = ("undefined (the arm held no momentum at its peaks)" if math.isnan(mean["alignment"])
                 else f"{mean['alignment']:+.2f}")
    print(f"  the arm's bound from its pose at each push: {mean['arm_momentum_bound']:.3f} N m s; its peak reached "
          f"{100 * mean['bound_fraction']:.0f} % of it; alignment with the push's r x F: cos {alignment} (+1: the "
          "arm takes up the push's angular momentum)")


def _figure(value: float, spec: str) -> str:
    """`value` formatted by `spec`, or ``-`` right-aligned in its width where it is nan (not measured)."""
    if math.isnan(value):
        width = int("".join(c for c in spec.split(".")[0] if c.isdigit()) or 0)
        return f"{'-':>{width}}"
    return format(value, spec)


def _cpu_time(ms: float) -> str:
    """A CPU time per step that keeps its figures at any size: ``120 us`` below a millisecond, ``20.5 ms`` above."""
    return f"{ms * 1e3:.0f} us" if ms < 1.0 else f"{ms:,.1f} ms"


def _count(n: int, noun: str) -> str:
    """``1 trial``, ``2 trials``."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def _nanmean(values: Sequence[float]) -> float:
    """The mean of the values that are not nan; nan when none is."""
    finite = [v for v in values if not math.isnan(v)]
    return float(np.mean(finite)) if finite else math.nan


def _machine_line(machine: str, load_1min: float) -> str:
    """The benches' machine line: `machine_description`'s text and the 1-minute load average beside it."""
    return f"  machine: {machine}, load {load_1min:.2f} (1 min)"


def print_bench_sim(result: SimBenchResult) -> None:
    """`bench_sim`'s figures, and the reference's beside them when it was measured."""
    print(f"Simulation speed: {result.robot} (arm {result.arm_mode}), standing under the motor law on "
          f"{result.terrain} ground, dt {result.timestep_s * 1e3:.1f} ms")
    print(_machine_line(result.machine, result.load_1min))
    print(f"  single-threaded : {result.steps_per_s:>10,.0f} steps/s  (real-time factor "
          f"{result.realtime_factor:.0f}x)")
    print(f"  batched rollout : {result.batched_steps_per_s:>10,.0f} steps/s  ({result.batch} envs, "
          f"{result.threads} threads)")
    ref = result.reference
    if ref is not None:
        (single, single_at), (batched, batched_at) = (REFERENCE_TARGETS["steps_per_s"],
                                                      REFERENCE_TARGETS["batched_steps_per_s"])
        print(f"  bare A1 URDF, same runs (the reference the simulator targets were set against: {single_at / 1e3:.0f}k"
              f" / {batched_at / 1e3:.0f}k):")
        print(f"    single-threaded : {ref.steps_per_s:>10,.0f} steps/s  -> this robot runs at "
              f"{100 * ref.steps_ratio_to_reference:.0f} % of it (the target asks "
              f"{100 * single / single_at:.0f} %: "
              f"{ref.scaled_target_steps_per_s:,.0f} steps/s on this machine)")
        print(f"    batched rollout : {ref.batched_steps_per_s:>10,.0f} steps/s  -> "
              f"{100 * ref.batched_ratio_to_reference:.0f} % (the target asks "
              f"{100 * batched / batched_at:.0f} %: "
              f"{ref.scaled_target_batched_steps_per_s:,.0f} steps/s on this machine)")


def print_bench_train(result: TrainBenchResult) -> None:
    """`bench_train`'s figures, and the target scaled to this machine when the reference was measured."""
    print(f"Training env speed: {result.robot} (arm {result.arm_mode}), {result.num_envs} envs, "
          f"{result.threads} threads, policy at {1 / (result.timestep_s * result.decimation):.0f} Hz, "
          f"dt {result.timestep_s * 1e3:.1f} ms, random actions")
    print(_machine_line(result.machine, result.load_1min))
    print(f"  env            : {result.control_steps_per_s:>10,.0f} control steps/s "
          f"({result.physics_steps_per_s:,.0f} physics steps/s)")
    print(f"  rollout only   : {result.rollout_only_control_steps_per_s:>10,.0f} control steps/s (physics limit)")
    print(f"  env efficiency : {100 * result.env_efficiency:>9.0f} %  "
          f"({_cpu_time(result.python_ms_per_step)} of Python per policy step)")
    print(f"  CPU-time bound : {result.cpu_bound_control_steps_per_s:>10,.0f} control steps/s with the cores to "
          f"itself (physics alone {result.cpu_bound_physics_only_control_steps_per_s:,.0f}; CPU per step: "
          f"physics {_cpu_time(result.physics_cpu_ms_per_step)}, Python {_cpu_time(result.python_cpu_ms_per_step)})")
    ref = result.reference
    if ref is not None:
        target, at = TRAIN_TARGET
        print(f"  reference      : {ref.physics_limit_control_steps_per_s:>10,.0f} control steps/s "
              f"(bare A1, 64 envs, 2 ms steps at 50 Hz; the target's ~{at / 1e3:.0f}k); env at "
              f"{100 * ref.control_steps_ratio_to_reference:.0f} % of it, the target ({target / 1e3:.0f}k of "
              f"{at / 1e3:.1f}k) asks "
              f"{100 * target / at:.0f} %: {ref.scaled_target_control_steps_per_s:,.0f} control steps/s here")


def print_bench_mpc(result: MpcBenchResult) -> None:
    """`bench_mpc`'s figures, and the targets scaled to this machine when the references were measured."""
    ticks = result.ticks
    one_core = result.blas == "single-threaded"  # the spawned worker's; --threaded-blas runs with the default threads
    settings = "" if result.controller_config is None else f" (settings {result.controller_config})"
    print(f"MPC speed: {result.controller}{settings} on {result.robot} walking at 0.3 m/s, N = {result.horizon}, QP "
          f"solver {result.qp_solver}, BLAS {result.blas}")
    print(_machine_line(result.machine, result.load_1min))
    print(f"  MPC QP solve   : median {ticks.mpc_solve_ms_median:.2f} ms, p99 {ticks.mpc_solve_ms_p99:.2f} ms "
          f"(setup median {ticks.mpc_setup_ms_median:.2f} ms)")
    print(f"  whole-body layer: median {ticks.wbc_tick_us_median:.0f} us per timed tick (the leg layer's: the "
          "MPC-update ticks; PlaCo's QP: every tick)")
    print(f"  control tick: median {ticks.control_tick_us_median:.0f} us (kinematics, estimator, footholds, "
          "whole-body layer, command; ticks without an MPC update)")
    where = "on one core" if one_core else f"with the BLAS's {result.blas}"
    print(f"  closed loop    : {result.realtime_factor:.1f}x real time {where} "
          f"({result.cpu_realtime_factor:.1f}x in CPU time); the walk's physics steps "
          f"{result.walk_physics_share:.0%} of it "
          f"({result.walk_physics_realtime_factor:.0f}x real time on their own); "
          + (f"median of {len(result.rounds)} timed walks" if len(result.rounds) > 1 else "one timed walk"))
    ref = result.reference
    if ref is not None:
        tick_at = MPC_REFERENCE_TARGETS["wbc_tick_us_median"][1]
        physics_at = MPC_REFERENCE_TARGETS["realtime_factor"][1]
        print(f"  references     : bare-A1 PlaCo tick {ref.reference_placo_tick_us:.0f} us (the targets' "
              f"~{tick_at:.0f} us), bare-A1 physics {ref.reference_steps_per_s:,.0f} steps/s (the targets' "
              f"{physics_at / 1e3:.0f}k)")
        print(f"  targets scaled to this machine: whole-body tick <= {ref.scaled_target_wbc_tick_us:.0f} "
              f"us, closed loop >= {ref.scaled_target_realtime_factor:.1f}x real time")
        print(f"  against the references: control tick {ref.control_tick_over_reference_tick:.2f}x the "
              f"reference PlaCo tick (target <= 1.8); closed loop {ref.closed_loop_over_physics_rtf:.3f} of "
              f"this robot's physics alone ({ref.physics_realtime_factor:.0f}x real time; target >= 0.075), "
              f"{ref.closed_loop_over_physics_cpu:.3f} in CPU time ({ref.physics_cpu_realtime_factor:.0f}x; "
              "target >= 0.20)")
        if len(result.rounds) > 1:
            print(f"  each walk against the physics alone measured just before and after it, in CPU time: "
                  f"{', '.join(f'{r.over_physics_cpu:.3f}' for r in result.rounds)} (median "
                  f"{ref.closed_loop_over_physics_cpu:.3f}, {ref.closed_loop_over_physics_cpu_min:.3f} to "
                  f"{ref.closed_loop_over_physics_cpu_max:.3f}: how far this machine moved the figure in one run)")
    if result.qp_solvers:
        _print_qp_solvers(result)
    else:
        print(f"  QP backends not compared: {result.qp_comparison_skipped or 'no QP of the walk was kept'}")


def _print_qp_solvers(result: MpcBenchResult) -> None:
    """The QP backends on the walk's QPs, one row each (`QpSolverFigures`)."""
    rows = result.qp_solvers
    print(f"  QP backends on the same {rows[0].qps} QPs of the walk (each from the loop's warm start; the loop ran "
          f"{result.qp_solver}):")
    print(f"    {'solver':<18} {'solve ms p50':>12} {'p99':>7} {'iters p50':>9} {'max':>5} {'unsolved':>8} "
          f"{'max |dF| N':>10} {'max dJ':>9}")
    for r in rows:
        print(f"    {r.solver + ' ' + r.version:<18} {r.solve_ms_median:>12.3f} {r.solve_ms_p99:>7.3f} "
              f"{r.iterations_median:>9.0f} {r.iterations_max:>5d} {r.unsolved:>8d} {r.force_max_diff_n:>10.2g} "
              f"{r.objective_max_diff:>9.2g}")
    print("    dF: a planned force component's largest difference from DAQP's solution; dJ: the cost's largest "
          "difference from its value there")


def print_bench_sweep(result: SweepBenchResult) -> None:
    """`bench_sweep`'s figures, one line per executor measured."""
    print(f"Sweep speed: {result.controller} on {result.scenario} ({result.trials} trials, "
          f"{result.terrain} terrain)")
    print(_machine_line(result.machine, result.load_1min))
    print(f"  batched physics (bench sim, same terrain): {result.batched_physics_steps_per_s:>10,.0f} steps/s")
    for row in result.executors:
        print(f"  sweep, {row.executor:<5} executor: {row.sweep_steps_per_s:>10,.0f} steps/s "
              f"({100 * row.ratio_to_batched_physics:.0f} % of batched physics, {row.wall_s:.1f} s)")
    overhead = result.ray_overhead_per_trial_s
    if overhead is not None:
        print(f"  Ray overhead per trial: {1e3 * overhead:.0f} ms")


def print_arena(result: ArenaResult, *, verdict: bool = True) -> None:
    """The summary table of a run or comparison, then how long it took and where the results are.

    Args:
        result: the run's result.
        verdict: end the table with the verdict sentences (``wbc demo`` prints them last, after the report's path).
    """
    print(format_table(result.summary, verdict=verdict))
    if result.arms_differ is not None and not format_verdict(result.summary):  # else the verdict ends with it
        print(textwrap.fill(f"note: {result.arms_differ}", width=118, subsequent_indent="  "))
    rate = result.physics_steps / result.wall_s if result.wall_s > 0 else float("nan")
    print(f"\n{result.played} trials played in {result.wall_s:.1f} s ({rate:,.0f} physics steps/s)"
          f"{resumed_note(result.played, len(result.records))}; "
          f"results in {result.out_dir}/ (trials.csv, summary.json, failures.json, report.md)")
    if result.summary.sequential is not None:
        stored = result.summary.stored
        print(f"sequential test: {stored} of the budget's {result.budget} trials played"
              + (f" ({result.budget - stored} saved)" if stored < result.budget else ""))


def print_paper_table(result: PaperTableResult) -> None:
    """``wbc paper TABLE``: ours beside the paper's, the comparisons, where each fails, the run time."""
    print(format_paper_table(result), end="")


def print_demo_header(controllers: Sequence[str], *, scenario: str, trials: int, seeds: int) -> None:
    """The line that opens ``wbc demo``: who plays which trials."""
    print(f"A/B demo: {' against '.join(controllers)} on {scenario}, {trials} trials x {seeds} seeds "
          "per band (the same trials for every controller)\n", flush=True)


def wbc_command(script: str | None = None, *, path: str | None = None, cwd: str | None = None) -> str:
    """How to type ``wbc`` so that this shell runs this installation: what a printed command starts with.

    ``wbc`` when the shell's PATH finds the running script; else the script's path (relative to the working directory
    when it lies below it, e.g. ``.venv/bin/wbc`` after `make demo`, whose virtual environment is not activated); else
    ``python -m wbc.cli`` with this interpreter.

    Args:
        script: the running program (default ``sys.argv[0]``).
        path: the PATH to search (default the environment's).
        cwd: the working directory (default the current one).
    """
    script = sys.argv[0] if script is None else script
    cwd = os.getcwd() if cwd is None else cwd
    if Path(script).name == "wbc" and Path(script).is_file():
        found = shutil.which("wbc", path=path)
        if found is not None and Path(found).resolve() == Path(script).resolve():
            return "wbc"
        where = Path(script).resolve()
        try:
            return shlex.quote(str(where.relative_to(Path(cwd).resolve())))
        except ValueError:
            return shlex.quote(str(where))
    return f"{shlex.quote(sys.executable)} -m wbc.cli"


def print_demo_end(out_dir: Path, watch: TrialToWatch | None, *, scenario: str,
                   summary: Summary | None = None) -> None:
    """How ``wbc demo`` ends, after the table: the report and its plots, one command to watch a trial, the verdict.

    The command stands alone on its line, spelled so that it runs as printed in the shell that ran the demo
    (`wbc_command`): pasted whole, it opens the trial. The verdict sentences of `summary` close the demo: who
    survives more, who tracks better, and whether the trials played settle it.
    """
    plots = sorted(p.name for p in Path(out_dir).glob("*.png"))
    print(f"report: {Path(out_dir) / 'report.md'}; plots: {', '.join(plots) if plots else 'none'}")
    if watch is not None:
        print(f"watch it ({watch.why}; the command opens a meshcat page on 127.0.0.1):")
        print(f"  {demo_watch_command(watch, scenario=scenario)}")
        activate = Path(sys.argv[0]).resolve().parent / "activate"
        if wbc_command() != "wbc" and activate.is_file():
            try:
                activate = activate.relative_to(Path.cwd().resolve())
            except ValueError:
                pass
            print(f"  (to type `wbc` alone, activate the project's environment first: . {shlex.quote(str(activate))})")
    if summary is not None and format_verdict(summary):
        print()
        print(format_verdict(summary), end="")


def demo_watch_command(watch: TrialToWatch, *, scenario: str, wbc: str | None = None) -> str:
    """The shell command that opens `watch` in the viewer."""
    wbc = wbc_command() if wbc is None else wbc
    return (f"{wbc} view {shlex.quote(watch.controller)} --scenario {shlex.quote(str(scenario))} "
            f"--band {shlex.quote(watch.band)} --seed {watch.seed} --trial {watch.trial}")


def arena_trial_options(cfg: ArenaConfig, controllers: Sequence[str]) -> tuple[str, ...]:
    """The ``wbc view`` options that play a trial as `cfg`'s run played it for `controllers`.

    Every option of ``wbc run`` / ``wbc compare`` that changes what a trial plays: ``--no-push``,
    ``--debug-truth``, and each of `controllers`' ``--controller-config`` and ``--io`` files (as ``NAME=FILE``).
    """
    options: list[str] = []
    if cfg.no_push:
        options.append("--no-push")
    if cfg.debug_truth:
        options.append("--debug-truth")
    for option, files in (("--controller-config", cfg.controller_configs), ("--io", cfg.io_files)):
        options += [f"{option} {shlex.quote(f'{name}={path}')}" for name, path in files.items() if name in controllers]
    return tuple(options)


def ab_watch_command(watch: TrialToWatch, *, scenario: str, wbc: str | None = None,
                     options: Sequence[str] = ()) -> str:
    """The shell command that shows `watch`'s two controllers on one page (`wbc view A B`), opened at its moment.

    Args:
        watch: the trial.
        scenario: the scenario file that played it.
        wbc: how the command is called (default `wbc_command`).
        options: the options that played the trial as the run did (`arena_trial_options`), already quoted.
    """
    wbc = wbc_command() if wbc is None else wbc
    at = f" --at {watch.at_s:g}" if watch.at_s is not None else ""
    return (f"{wbc} view {shlex.quote(watch.controller)} {shlex.quote(str(watch.other))} --scenario "
            f"{shlex.quote(str(scenario))} --band {shlex.quote(watch.band)} --seed {watch.seed} --trial "
            f"{watch.trial}{''.join(f' {o}' for o in options)}{at}")


def print_compare_watch(watch: TrialToWatch | None, *, scenario: str, options: Sequence[str] = ()) -> None:
    """``wbc compare``'s last lines: the most telling trial, with the command that shows both runs of it."""
    if watch is None or watch.other is None:
        return
    print(f"watch it ({watch.why}; both runs on one page, {watch.other} as the ghost):")
    print(f"  {ab_watch_command(watch, scenario=scenario, options=options)}")


def print_scenario_check(result: ScenarioCheck) -> None:
    """``wbc scenario check``: a scenario's identity, robot, bands, trial count and publication."""
    print(f"scenario {result.name} version {result.version}  ({result.path})")
    print(f"  hash      {result.hash}")
    print(f"  robot     {result.robot}, trials of {result.duration_s:g} s")
    print("  bands:")
    width = max(len(name) for name, _ in result.bands)
    for name, settings in result.bands:
        sets = ", ".join(f"{k} {_band_value(v)}" for k, v in settings.items()) or "the drawn options only"
        print(f"    {name:<{width}}  {sets}")
    print(f"  trials    {result.trial_count}")
    if result.published:
        print(f"  published by {result.lock}")
    else:
        print(f"  not published: {result.problem}")


def _band_value(value: object) -> str:
    if isinstance(value, tuple | list):
        return "-".join(f"{v:g}" for v in value)
    return f"{value:g}" if isinstance(value, int | float) else str(value)


def print_controllers(rows: Sequence[ControllerListing]) -> None:
    """``wbc controllers``: the registry's, the name forms, installed plug-ins with their summaries."""
    def robots(r: ControllerListing) -> str:
        if not r.loaded:
            return ""
        return "any robot" if r.robots is None else ", ".join(r.robots) or "no robot"

    def table(selected: Sequence[ControllerListing], with_target: bool) -> None:
        width = max(len(r.name) for r in selected)
        robots_width = max(10, *(len(robots(r)) for r in selected))
        for r in selected:
            arms = "/".join(r.arm_modes) or "-"
            target = f"  ({r.target})" if with_target and r.target is not None else ""
            print(f"  {r.name:<{width}}  {arms:<9} {robots(r):<{robots_width}}  {r.summary}{target}")

    print("registered controllers:")
    table([r for r in rows if r.kind == "registry"], with_target=False)
    print("\nnames of other forms:")
    forms = {NAME_FORMS[0]: "an exported policy file (.npz + .json), robot and arm mode read from it",
             NAME_FORMS[1]: "an ONNX policy; its I/O file is PATH with the suffix .toml, or --io FILE",
             NAME_FORMS[2]: "a plug-in: the factory builds the controller from the robot description "
                            "(and the --controller-config table)"}
    width = max(map(len, forms))
    for form, what in forms.items():
        print(f"  {form:<{width}}  {what}")
    plugins = [r for r in rows if r.kind == "entry point"]
    print("\ninstalled plug-ins (entry points of the wbc.controllers group):")
    if plugins:
        table(plugins, with_target=True)
    else:
        print("  none installed")


def print_controller_check(result: ControllerCheck) -> None:
    """``wbc check-controller``: every check on every robot and arm mode, then the verdict."""
    marks = {True: "ok  ", False: "FAIL", None: "-   "}
    print(f"controller {result.controller}")
    where = None
    for o in result.outcomes:
        if (o.robot, o.arm_mode) != where:
            where = (o.robot, o.arm_mode)
            print(f"\n  {o.robot}, arm {o.arm_mode}")
        print(f"    {marks[o.passed]} {o.check:<8} {o.detail}")
    print(f"\n{'passed' if result.passed else _check_tally(result)}")


def _check_tally(result: ControllerCheck) -> str:
    """The verdict of a check that did not pass: the checks that failed and those not run, counted apart."""
    failed, not_run, total = len(result.failed()), len(result.not_run()), len(result.outcomes)
    if not total:
        return "FAILED: no check ran"
    if not failed:
        return f"FAILED: {not_run} of {total} checks not run"
    return f"FAILED: {failed} of {total} checks failed" + (f", {not_run} not run" if not_run else "")


def print_trained(result: Mapping[str, object], *, task: str, stage: int, baseline: str | None) -> None:
    """One line on a finished training run: its length and where its policy is."""
    print(f"trained {task} stage {stage}{' ' + baseline if baseline else ''}: "
          f"{result['iterations']} iterations, {result['env_steps']:,} env steps, {result['wall_s'] / 60:.1f} min; "
          f"policy {result['policy']}")


def print_viewed_trial(what: str, record: TrialRecord) -> None:
    """How a trial watched in the viewer ended."""
    print(f"{what}: " + ("survived" if record.success else f"ENDED by a controller error: "
                         f"{printed_error(record.error, kept_in=None)}"
                         if record.error else f"fell at {record.fall_time_s:.2f} s"))


def print_recording(what: str, frames: int, path: Path) -> None:
    """Where a recorded replay was written."""
    print(f"recorded {frames} frames of {what} to {path}")


def print_bench_hw(result: HwBenchResult) -> None:
    """``wbc bench hw``: the link's send period, round trip, CPU per tick and rejects."""
    print(f"Unitree {result.robot} low-level link over loopback ({result.transport} transport), "
          f"{result.rate_hz:.0f} Hz for {result.seconds} s; emulator: {result.emulator_process}")
    print(f"  send period     p50 {result.period_ms_p50:.3f} ms  p99 {result.period_ms_p99:.3f} ms  "
          f"max {result.period_ms_max:.3f} ms")
    print(f"  round trip      p50 {result.round_trip_ms_p50:.3f} ms  p99 {result.round_trip_ms_p99:.3f} ms "
          "(command sent -> the state answering it taken by the link thread)")
    print(f"  link thread CPU {result.cpu_us_per_tick:.0f} us per tick")
    print(f"  scheduling      link side: {result.realtime}; emulator: {result.emulator_realtime}; load "
          f"{result.load_1min:.2f} (1 min)")
    print(f"  advance(period) p50 {result.advance_ms_p50:.3f} ms  p99 {result.advance_ms_p99:.3f} ms; late "
          f"advances {result.late_advances} (worst {result.worst_lateness_ms:.2f} ms)")
    emu = result.emulator
    print(f"  frames          {result.sends} sent, {result.replies_received} states received, "
          f"{result.rejects} rejected by the robot (the link, from its start to the end of the measurement)")
    print(f"  emulator        decoded {emu.accepted}, rejected {sum(emu.rejected.values())} (its whole session: "
          "the link's damping frames at close included)")
    safety = result.safety
    if safety is not None:
        print(f"Safety layer over the wire, real-time emulator (first damping frame on the wire after the cause; link "
              f"period {safety.link_period_ms:g} ms)")
        print(f"  e-stop          {safety.estop_to_damping_ms:.2f} ms")
        print(f"  silent stream   {safety.silence_to_damping_ms:.2f} ms (stale timeout "
              f"{safety.stale_timeout_ms:g} ms)")
        print(f"  stalled loop    {safety.stall_to_damping_ms:.2f} ms (write deadline "
              f"{safety.write_deadline_ms:g} ms)")
        print(f"  hot motor       {safety.state_fault_to_damping_ms:.2f} ms")
        print(f"  stand           {safety.stand_seconds:g} s: took {safety.stand_wall_s:.2f} s of wall time, "
              f"emulated {safety.stand_sim_s:.2f} s (real-time factor {safety.stand_realtime_factor:.3f}); "
              f"safety {safety.stand_safety_state}, link period mean {safety.stand_link_period_ms_mean:.3f} ms "
              f"max {safety.stand_link_period_ms_max:.3f} ms, deadline trips {safety.stand_deadline_trips}; "
              f"act p99 {safety.stand_act_ms_p99:.3f} ms, deadline misses {safety.stand_deadline_misses}")
        for trip in safety.stand_trips:
            print(f"    trip: {trip}")
    print(f"  machine: {result.machine}")


def print_bench_act(result: ActBenchResult) -> None:
    """``wbc bench act``: each controller's act in CPU per call and per simulated second, with the ratios."""
    print(f"act on the thread's CPU clock: {result.scenario} band {result.band}, seed {result.seed}, trial "
          f"{result.trial}; {result.machine}, load {result.load_1min:.2f}")
    print(f"  {'controller':<28}{'rate [Hz]':>10}{'ticks':>8}{'per act [us] median / mean':>30}{'per sim s [ms]':>16}"
          f"{'x ref, mean act':>17}{'x ref, s':>10}")
    for cost, (_, tick, second) in zip(result.costs, result.ratios(), strict=True):
        note = f"  (fell at {cost.survived_s:.2f} s)" if cost.fell else ""
        print(f"  {cost.controller:<28}{cost.rate_hz:>10g}{cost.ticks:>8}"
              f"{f'{cost.cpu_us_per_tick_median:.1f} / {cost.cpu_us_per_tick_mean:.1f}':>30}"
              f"{cost.cpu_ms_per_s:>16.2f}{tick:>17.3f}{second:>10.3f}{note}")
    print(f"  the least CPU per simulated second of {result.costs[0].rounds} rounds each; ratios against "
          f"{result.costs[0].controller}'s mean per act and its CPU per simulated second")


def print_bench_latency(result: LatencyBenchResult) -> None:
    """``wbc bench latency``: the wire's latency beside the equivalent simulated delay, and each controller's margin."""
    wire = result.wire
    if wire is not None:
        ticks = np.bincount(wire.wire_ticks)
        spread = ", ".join(f"{k}: {n}" for k, n in enumerate(ticks) if n)
        print(f"Wire ({result.wire_robot}, loopback, {wire.period_ms:g} ms link and control period)")
        print(f"  emulator round trip   p50 {wire.round_trip_ms_p50:.3f} ms  p99 "
              f"{wire.round_trip_ms_p99:.3f} ms (command sent -> the state answering it, lockstep)")
        print(f"  loop latency probe    ticks from a torque step's write to the read showing it: p50 "
              f"{wire.wire_ticks_p50:g}, mean {wire.wire_ticks_mean:.2f}, max {wire.wire_ticks_max} "
              f"(count by ticks: {spread}); the simulator without delay: 1")
        print(f"  equivalent sim delay  typical {wire.typical_delay_ms:g} ms, worst {wire.worst_delay_ms:g} "
              f"ms (actuation + sensing); the simulator's probe with them: {wire.sim_ticks_typical:g} and "
              f"{wire.sim_ticks_worst:g} ticks")
    first = result.margins[0]  # every controller's sweep played the same trials
    trials = (f"standing trials of {result.scenario}" if first.standing else
              f"walking trials of {result.scenario} (it has no standing trials with pushes): each walks its command "
              f"{first.still_s:g} s" + ("" if first.push_force_n else ", and has no push to survive"))
    print(f"Margin: the largest actuation delay passed [ms] before the first that failed (sweep: "
          f"{', '.join(f'{x:g}' for x in result.coarse_ms)}, then {result.fine_ms:g} ms steps below the first "
          f"failure); {trials}, on the {first.robot} (the scenario {first.scenario}'s robot)")
    if result.wire is not None and LEG_WIRES.get(first.robot) != result.wire_robot:
        print(f"  (the margins are the {first.robot}'s, not the {result.wire_robot}'s of the wire above: give a "
              f"{result.wire_robot} scenario with --scenario for the {result.wire_robot}'s)")
    still = "stands still" if first.standing else "walks its command"
    print(f"  {'controller':<12}{still:<26}{'survives a push':<26}{'push [N]':<18}wall [s]")
    top = result.coarse_ms[-1]
    for m in result.margins:
        cells = []
        for margin, fell in ((m.still_margin_ms, m.still_fell_at_ms), (m.push_margin_ms, m.push_fell_at_ms)):
            passed = "none" if margin is None else f"{margin:g}"
            cells.append(f"{passed}, fell at {fell:g}" if fell is not None else f"{passed} (no fall up to {top:g})")
        if not m.push_force_n:
            cells[1] = "no push in the trials"
        forces = ", ".join(f"{f:g}" for f in m.push_force_n)
        print(f"  {m.controller:<12}{cells[0]:<26}{cells[1]:<26}{forces:<18}{m.wall_s:.0f} ({m.runs} runs)")
    print(_machine_line(result.machine, result.load_1min))


def print_bench_arm(result: ArmBenchResult) -> None:
    """``wbc bench arm``: the bus loop's rates and the elbow's step response, bus against simulation."""
    print(f"WX200 arm bus ({result.robot}) against the real-time emulated robot in its own process; latency timer "
          f"{result.latency_ms} ms, {result.seconds} s per rate")
    print(f"  this process (the bus's host side): {result.host_realtime}")
    print("  requested [Hz]  achieved [Hz]  busy mean / max [ms]  longest period [ms]  failed reads  faults")
    for r in result.rates:
        print(f"  {r.rate_hz:>14.0f}{r.achieved_hz:>15.1f}{r.busy_ms_mean:>12.2f} / {r.busy_ms_max:<7.1f}"
              f"{r.period_ms_max:>19.1f}{r.failed_reads:>14d}{r.faults:>8d}")
    print(f"  elbow step of {result.step_rad} rad (median of 4 on the bus), from the stowed pose:")
    print("  source       kp    kd   rate [Hz]  rise 10-90 [ms]  overshoot [%]  settle 5% [ms]  final error [rad]"
          "  discarded")
    for s in result.steps:
        print(f"  {s.source:<11}{s.kp:>4.0f}{s.kd:>6.1f}{s.rate_hz:>12.0f}{s.rise_ms:>17.1f}"
              f"{s.overshoot_pct:>15.1f}{s.settle_ms:>16.0f}{s.final_error_rad:>19.4f}{s.discarded:>11d}")
    print("  reactions at 200 Hz, wall time (the tests check them exactly on a clock they move):")
    print("  event            reaction    took [ms]  expected [ms]  watchdog after last packet [ms]")
    for r in result.reactions:
        watchdog = f"{r.watchdog_ms:.1f}" if r.watchdog_ms is not None else "-"
        print(f"  {r.event:<17}{r.reaction:<12}{r.ms:>9.1f}{r.expected_ms:>15.1f}  {watchdog:>10}")
    for e in result.emulator:
        if e.what == "plant_realtime_factor":
            print(f"  shared plant on its own thread: real-time factor {e.value:.3f} (overruns {e.worst:.0f})")
        else:
            label = "with byte timing" if e.what.endswith("byte_timing") else "no byte timing  "
            print(f"  sync read of 3 joints over a pty, {label}: p50 {e.value:.3f} ms, p99 {e.worst:.3f} ms "
                  f"(wire model {e.model:.2f} ms)")
    print(_machine_line(result.machine, result.load_1min))


def print_realtime_grant(who: str, grant: RealtimeGrant | None) -> None:
    """What `who` asked the OS for (real-time scheduling, a CPU, locked memory) and what it got."""
    if grant is None:
        print(f"  {who}: real-time scheduling not requested (the devices run in this process)", flush=True)
        return
    state = "REAL-TIME" if grant.realtime else "ORDINARY scheduling"
    print(f"  {who} (pid {grant.pid}): {state}: {grant.describe()}", flush=True)


def print_emulator_started(robot: str, mode: str, address: tuple[str, int], faults: Sequence[str], *,
                           seconds: float | None, held: bool = False, arm_locked: bool = False) -> None:
    """``wbc hw emulate``: where the emulator listens, and how it stops (`arm_locked`: its arm held on the trunk)."""
    host, port = address
    arm = " with its arm locked on the trunk" if arm_locked else ""
    print(f"emulated {robot}{arm} ({mode}) on {host}:{port}; faults: {', '.join(faults) or 'none'}; "
          + (f"stopping after {seconds} s" if seconds is not None else "Ctrl-C to stop"), flush=True)
    print(f"  connect with: wbc hw check --robot {robot} --target {host}:{port}", flush=True)
    _print_held(held)


def _print_held(held: bool) -> None:
    if held:
        print("  the robot is held at its standing pose until a command drives a motor (--drop: free from the start)",
              flush=True)


def print_robot_emulator_started(robot: str, mode: str, address: tuple[str, int], pty: str, faults: Sequence[str], *,
                                 seconds: float | None, held: bool = False) -> None:
    """``wbc hw emulate --arm actuated``: the legs' UDP address, the arm's pty, and how it stops."""
    host, port = address
    print(f"emulated {robot} with its arm actuated ({mode}): legs on {host}:{port} (UDP), arm on {pty} (Dynamixel "
          f"Protocol 2.0, 1 Mbps); faults: {', '.join(faults) or 'none'}; "
          + (f"stopping after {seconds} s" if seconds is not None else "Ctrl-C to stop"), flush=True)
    print(f"  legs: UnitreeRobotConfig(robot={robot.split('-')[0]!r}, target_host={host!r}, target_port={port}); "
          f"arm: DynamixelArmConfig(robot={robot!r}, port={pty!r})", flush=True)
    print(f"  a trial: wbc hw run stand --robot {robot} --arm actuated --scenario scenarios/push.toml --trial 0 "
          f"--target {host}:{port} --arm-port {pty}", flush=True)
    _print_held(held)


def print_thread_stats(name: str, stats: DeviceThreadStats) -> None:
    """One line of a device loop's statistics: cycles, period percentiles, busy time, late cycles, overruns."""
    ms = {k: 1e3 * getattr(stats, k) for k in ("period_mean", "period_p50", "period_p99", "period_max", "busy_mean",
                                               "busy_max")}
    print(f"  {name}: {stats.cycles} cycles, period mean {ms['period_mean']:.3f} ms, p50 {ms['period_p50']:.3f}, "
          f"p99 {ms['period_p99']:.3f}, max {ms['period_max']:.3f}; busy mean {ms['busy_mean']:.3f} ms, max "
          f"{ms['busy_max']:.3f}; {stats.late} late (started a period after they were due), {stats.overruns} "
          "overruns (took longer than the period)")


def print_bus_counts(stats: BusStats) -> None:
    """The arm emulator's closing line: instruction packets decoded, rejects by reason, status packets."""
    rejects = ", ".join(f"{reason} {n}" for reason, n in sorted(stats.rejected.items())) or "none"
    print(f"arm bus: packets decoded {stats.packets}; rejected {sum(stats.rejected.values())} ({rejects}); status "
          f"packets {stats.statuses}; unheard {stats.unheard}")


def print_emulator_serving(serving: EmulatorServing) -> None:
    """``wbc hw emulate``'s first lines: where the emulator serves, how to connect and stop it, its grant."""
    faults = list(serving.faults)
    if serving.arm_port is None:
        print_emulator_started(serving.robot, serving.mode, serving.address, faults, seconds=serving.seconds,
                               held=serving.held, arm_locked=serving.arm_mode == "locked")
    else:
        print_robot_emulator_started(serving.robot, serving.mode, serving.address, serving.arm_port, faults,
                                     seconds=serving.seconds, held=serving.held)
        if not serving.arm_port_shared:
            print(f"  note: {serving.arm_port} could not be registered where other processes look "
                  f"({registry_dir()} is missing, not writable, or not this user's alone): a wbc command in "
                  "another process refuses it without --allow-hardware")
    print_realtime_grant("emulator", serving.grant)


def print_emulator_served(served: EmulatorServed) -> None:
    """``wbc hw emulate``'s closing lines: the legs' wire counts, then the arm bus's when it was emulated."""
    print_emulator_counts(served.counts, last_reject=served.last_reject)
    if served.arm_bus is not None:
        print_bus_counts(served.arm_bus)
    if served.arm_thread is not None:
        print_thread_stats("arm bus thread", served.arm_thread)


def print_emulator_counts(counts: EmulatorCounts, *, last_reject: str = "") -> None:
    """``wbc hw emulate``'s closing line: commands decoded, rejects by reason, replies.

    Then why the last reject was, when there was one: a client of another model is named there.
    """
    rejects = ", ".join(f"{reason} {counts.rejected[reason]}" for reason in REJECT_REASONS)
    print(f"commands decoded {counts.accepted}; rejected {sum(counts.rejected.values())} ({rejects}); "
          f"refused (negative gain) {counts.refused}; replies {counts.replies}")
    if last_reject:
        print(f"  the last rejected: {last_reject}")


def print_hw_check(check: HardwareCheck) -> None:
    """``wbc hw check``: the robot's state as read, its limits, the safety layer's verdict, and how the links went.

    When no valid state came at all, the first line says so with the link's account of what came and what to check.
    """
    host, port = check.target
    state, extras, link = check.state, check.extras, check.link
    where = f"{check.robot} at {host}:{port}" + (f", arm on {check.arm_port}" if check.arm_port else "")
    if state is None:
        print(f"{where}: no live state stream: {check.no_state}")
        _print_refused_arm(check)
        print("  safety: waiting: no live state stream, so no verdict (a ramp starts only from a live one)")
        _print_check_link(check)
        return
    print(f"{where}: {link.valid_states} leg states received, newest {1e3 * link.state_age:.1f} ms old (since its "
          "datagram arrived here)")
    print("  latency: NOT MEASURED: what the robot took before it sent a state, and what a command takes to its "
          "motors: with damping only, no field of the state answers a command (a damped joint of a robot hanging "
          "still gives no torque), and the state's tick counts on the robot's own clock, so a constant delay reads "
          "as none. `wbc bench latency` gives the delay each controller tolerates (its margins); know your robot's "
          "own before a controller drives it")
    print("  joint                 q [rad]   dq [rad/s]   tau_est [N m]   range [rad]          mode  temp [C]")
    modes = list(extras.motor_mode) if extras is not None else []
    temps = list(extras.motor_temperature) if extras is not None else []
    if check.arm_status is not None:
        # the arm's servos in ID order; the joints read are waist (ID 1), shoulder (ID 2), elbow (ID 4)
        by_id = dict(zip(check.arm_status.ids, zip(check.arm_status.motor_mode, check.arm_status.motor_temperature,
                                                   strict=True), strict=True))
        for servo in (1, 2, 4):
            mode, temp = by_id.get(servo, (None, None))
            modes.append(mode)
            temps.append(temp)
    for i, name in enumerate(check.joint_names):
        q = state.q[i]
        row = (f"  {name:<20}{q:>9.3f}{state.dq[i]:>13.3f}{state.tau_est[i]:>16.2f}   "
               f"[{check.lower[i]:>6.3f}, {check.upper[i]:>6.3f}] {_range_mark(q, check, i):<6}")
        if i < len(modes) and modes[i] is not None:
            row += f"  0x{int(modes[i]):02X}{int(temps[i]):>10d}"
        print(row)
    if extras is not None:
        roll, pitch, _ = np.degrees(extras.imu_rpy)
        print(f"  IMU roll {roll:.1f} deg, pitch {pitch:.1f} deg")
        battery = extras.battery
        volts = None if battery is None else float(np.sum(battery.cell_voltage))
        print("  battery: " + ("none in this robot's state (A1)" if battery is None else
                               f"{battery.soc} % SOC, {battery.current:.2f} A, {volts:.2f} V over the cells"
                               + ("  (NOT REPORTED: no cell voltage in the state; an emulator, or a battery that "
                                  "does not report: check it by hand)" if volts == 0.0 else "")))
        held = extras.remote.held
        estop = "  (L2+B held: e-stop)" if extras.remote.l2_b else ""
        print(f"  remote buttons: {', '.join(held) or 'none'}{estop}")
    _print_refused_arm(check)
    if check.arm_refused is not None:
        print(f"  safety: WOULD REFUSE: the arm: {check.arm_refused}")
        _print_check_link(check)
        return
    trips = [e for e in check.safety_events if e.to_state == "damped"]
    waiting = "waiting: no live state stream"
    if check.stale_frames:
        waiting += (f": frames arrive ({check.stale_frames} refused) but their tick does not advance: a frozen board, "
                    "or a robot that restarted (refused until its tick passes the old one): reconnect")
    verdict = {"ramp": "ready: a ramp would start from this pose",
               "waiting": waiting}.get(check.safety_state, check.safety_state)
    print("  safety: " + (f"WOULD REFUSE: {trips[0].reason}: {trips[0].detail}" if trips else verdict)
          + f" (joint margin {check.margin} rad beyond each range: a joint marked margin is beyond its range and "
          "within the margin, which the layer lets pass; one marked OUT is beyond both, which it refuses)")
    if trips and trips[0].remedy:
        print(f"  what to do: {trips[0].remedy}")
    _print_check_link(check)


def _print_refused_arm(check: HardwareCheck) -> None:
    """The arm's servos as read once, nothing written, after its backend refused to drive the arm (if it did)."""
    if check.arm_refused is None:
        return
    print("  arm: not driven (its backend refused it at connect); each servo as read, nothing written:")
    print("  servo               ID  model  operating mode              hardware error          temp [C]  input [V]")
    for s in check.arm_servos:
        if s.answer:
            print(f"  {s.name:<18}{s.id:>4}  NO VALID ANSWER to its ping: {s.answer}")
            continue
        mode = "?" if s.operating_mode is None else _operating_mode(s.operating_mode)
        errors = ", ".join(n for b, n in HARDWARE_ERROR_BITS.items() if s.hardware_error & b)
        error = f"{s.hardware_error:#04x} {errors}" if s.hardware_error else "none"
        print(f"  {s.name:<18}{s.id:>4}  {s.model:>5}  {mode:<26}  {error:<22}  {s.temperature:>8.0f}  "
              f"{s.voltage:>9.1f}")


def _operating_mode(mode: int) -> str:
    """An Operating Mode register's value with its name (``0 (current)``)."""
    try:
        return f"{mode} ({OperatingMode(mode).name.lower().replace('_', '-')})"
    except ValueError:
        return f"{mode} (unknown)"


def _range_mark(q: float, check: HardwareCheck, i: int) -> str:
    """Where joint `i`'s `q` stands against its range, as the safety layer checks it with its margin.

    Returns:
        ``""`` inside the range; ``margin`` beyond it but within the layer's joint margin (which the layer lets
        pass); ``OUT`` beyond range and margin (which the layer refuses).
    """
    lower, upper = check.lower[i], check.upper[i]
    if q < lower - check.margin or q > upper + check.margin:  # the layer's own test (`SafeRobot`)
        return "OUT"
    return "margin" if q < lower or q > upper else ""


def _print_check_link(check: HardwareCheck) -> None:
    """``wbc hw check``'s closing lines: the legs' link counters, its thread, the rejected frames, the arm's bus."""
    link = check.link
    print(f"  link: {link.frames_sent} frames sent, all damping (the link's own, {link.damping_sent}, and any the "
          f"safety layer wrote on a trip); {link.foreign} foreign datagrams")
    print_thread_stats("link thread", check.link_thread)
    print(f"  rejected states: {check.decode.rejected} ("
          + ", ".join(f"{r} {getattr(check.decode, r)}" for r in REJECT_REASONS) + ")")
    print(f"  frames refused for their tick: {check.stale_frames} (valid frames whose tick did not advance: a board "
          "repeating its buffer, a replay, or a robot that restarted)")
    if check.arm_bus is not None:
        bus = check.arm_bus
        print(f"  arm bus: {bus.cycles} cycles, {bus.damping_cycles} of them damping (no servo command); "
              f"{bus.failed_transfers} failed reads, {bus.retries} retries")
        if check.arm_thread is not None:
            print_thread_stats("arm bus loop", check.arm_thread)
        for fault in check.arm_faults:
            print(f"  {fault}")


def print_hw_run(result: HardwareTrialResult) -> None:
    """``wbc hw run``: the trial's outcome, what it skipped, its timing and where its results are."""
    r, ep = result.record, result.episode
    robot = result.robot
    ended_s = float(ep.t[-1]) if len(ep.t) else 0.0  # a trip, a stop, an error is no fall: its own time, not one
    outcome = ("completed" if r.success else
               f"ENDED by a controller error: {printed_error(r.error)}" if r.outcome == CONTROLLER_ERROR else
               f"STOPPED: {printed_error(r.error)}" if r.error else
               f"ENDED at {ended_s:.2f} s by the safety layer ({ep.safety_events.reason[-1]})"
               if r.safety_trips else f"FELL at {r.fall_time_s:.2f} s" if r.outcome == FALL else
               f"ENDED at {ended_s:.2f} s ({r.outcome})")
    print(f"{r.controller} on {robot.description.name} (arm {robot.description.arm_mode}, {robot.backend}, "
          f"{robot.target}): {r.scenario} band {r.band} seed {r.seed} trial {r.trial}, {ep.duration_s:g} s: {outcome}")
    for note in result.notes:
        print(f"  {note}")
    if isinstance(robot.robot, HasRealtimeGrant):
        print_realtime_grant("I/O process", robot.robot.realtime_grant)
    if result.controller_realtime is not None:
        print_realtime_grant("controller loop", result.controller_realtime)
    print(f"  metrics ({r.metrics_source}): V_lin err {r.vlin_err:.3f} m/s, V_ang err {r.vang_err:.3f} rad/s, max "
          f"roll {r.max_roll_deg:.2f} deg, max pitch {r.max_pitch_deg:.2f} deg, energy {r.energy_j:.1f} J")
    print(f"  timing: act p50 {r.act_ms_p50:.3f} ms, p99 {r.act_ms_p99:.3f} ms, max {r.act_ms_max:.3f} ms (period "
          f"{ep.control_dt * 1e3:g} ms); "
          f"deadline misses {r.deadline_misses} of {len(ep.t)}; late advances {r.late_advances} (worst "
          f"{r.worst_lateness_ms:.2f} ms); CPU {result.cpu_s:.2f} s"
          + (f" + I/O process {result.io_cpu_s:.2f} s" if result.io_cpu_s is not None else "")
          + f" over {result.episode_wall_s:.2f} s")
    if result.link is not None:
        link = result.link.as_dict(prefix="")
        print(f"  link: {link.get('frames_sent', 0)} frames sent, {link.get('damping_sent', 0)} of them the link's own "
              "damping (before the first state, past the write deadline, closing; not the safety layer's), "
              f"{link.get('deadline_trips', 0)} write-deadline trips, {link.get('rejected_states', 0)} rejected states"
              + (f", {result.stale_frames} frames refused for their tick (a frozen or restarted board)"
                 if result.stale_frames is not None else ""))
        if "io/states_published" in link:
            print(f"  I/O process: {link['io/states_published']} states published, "
                  f"{link['io/commands_forwarded']} commands forwarded, {link['io/bells_missed']} doorbells missed")
    clock = "robot seconds" if robot.backend == "sim" else "wall seconds since connected"
    print(f"  safety: {r.safety_trips} trip(s) in the trial, {r.write_deadline_ramps} write-deadline damping(s) "
          f"ramped again; transitions ({clock}, the trial "
          f"began at {result.trial_started_s:.2f} s): "
          + ", ".join(f"{e.time:.2f} s {e.to_state} ({e.reason})" for e in result.safety_events))
    trips = [e for e in result.safety_events if e.to_state is SafetyState.DAMPED and e.time >= result.trial_started_s]
    if trips:  # the trip that ended the trial: what it was and what to do about it
        print(f"  {trips[0].reason}: {trips[0].detail}")
        if trips[0].remedy:
            print(f"  what to do: {trips[0].remedy}")
    for fault in result.arm_faults:  # the arm's own, apart from the layer's trip it caused
        print(f"  arm bus, at {fault.time:.2f} s of the trial: {fault}")
    if len(ep.operator_events):
        print("  operator: " + ", ".join(f"{t:.2f} s {a}" for t, _, a in ep.operator_events.rows()))
    print(f"  results: {result.out_dir} (trials.csv, report.md, hardware.json, episodes/)")
