"""How the ``wbc`` command prints what its commands return: JSON, or the tables and lines a person reads.

One printer per result; each takes the result as the tool returned it and writes to stdout. The texts are part of
the command's interface: scripts parse the JSON, people read the tables.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from wbc.arena.compare import ArenaResult
from wbc.arena.record import TrialRecord
from wbc.arena.report import format_table
from wbc.hardware.unitree import REJECT_REASONS, DecodeStats, LinkStats, LowStateExtras
from wbc.tools.arm_momentum import ArmMomentumTrial
from wbc.tools.bench.hw import EmulatorCounts
from wbc.tools.bench.references import MPC_REFERENCE_TARGETS, REFERENCE_TARGETS, TRAIN_TARGET
from wbc.tools.tail import TailAnalysis
from wbc.types import RobotState

__all__ = ["print_arena", "print_arm_momentum", "print_bench_hw", "print_bench_mpc", "print_bench_sim",
           "print_bench_sweep", "print_bench_train", "print_demo_header", "print_emulator_counts",
           "print_emulator_started", "print_hw_check", "print_json", "print_recording", "print_tail",
           "print_trained", "print_viewed_trial"]


def print_json(value: object) -> None:
    """`value` as indented JSON (sequences of any kind as lists; NaN as ``NaN``, as `json` writes it)."""
    print(json.dumps(value, indent=2, default=list))


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


def print_arm_momentum(rows: Sequence[ArmMomentumTrial], *, controller: str, scenario: str, band: str) -> None:
    """One line per trial of the arm-momentum study, then the means."""
    print(f"arm momentum during push recovery: {controller}, {scenario} band {band}")
    print("  seed trial survived  arm travel [rad]  push |r x F| T [N m s]  arm |h| peak [N m s]  arm |h| mean")
    for r in rows:
        print(f"  {r.seed:4d} {r.trial:5d} {str(r.survived):8s}  {r.arm_travel_rad:16.1f}  "
              f"{r.push_angular_impulse:22.3f}  {r.arm_momentum_peak:20.3f}  {r.arm_momentum_mean:12.3f}")
    if rows:
        mean = {k: float(np.mean([getattr(r, k) for r in rows])) for k in
                ("arm_travel_rad", "push_angular_impulse", "arm_momentum_peak", "arm_momentum_mean")}
        print(f"  mean: travel {mean['arm_travel_rad']:.1f} rad, push angular impulse "
              f"{mean['push_angular_impulse']:.3f} N m s, arm momentum peak {mean['arm_momentum_peak']:.3f} N m s "
              f"({100 * mean['arm_momentum_peak'] / max(mean['push_angular_impulse'], 1e-9):.0f} % of the impulse), "
              f"mean {mean['arm_momentum_mean']:.3f} N m s")


def print_bench_sim(result: Mapping[str, object]) -> None:
    """`bench_sim`'s figures, and the reference's beside them when it was measured."""
    print(f"Simulation speed: {result['robot']} (arm {result['arm_mode']}), standing under the motor law on "
          f"{result['terrain']} ground, dt {result['timestep_s'] * 1e3:.1f} ms")
    print(f"  machine: {result['machine']}")
    print(f"  single-threaded : {result['steps_per_s']:>10,.0f} steps/s  (real-time factor "
          f"{result['realtime_factor']:.0f}x)")
    print(f"  batched rollout : {result['batched_steps_per_s']:>10,.0f} steps/s  ({result['batch']} envs, "
          f"{result['threads']} threads)")
    if "reference_steps_per_s" in result:
        (single, single_at), (batched, batched_at) = (REFERENCE_TARGETS["steps_per_s"],
                                                      REFERENCE_TARGETS["batched_steps_per_s"])
        print(f"  bare A1 URDF, same runs (the reference the simulator targets were set against: {single_at / 1e3:.0f}k"
              f" / {batched_at / 1e3:.0f}k):")
        print(f"    single-threaded : {result['reference_steps_per_s']:>10,.0f} steps/s  -> this robot runs at "
              f"{100 * result['steps_ratio_to_reference']:.0f} % of it (the target asks "
              f"{100 * single / single_at:.0f} %: "
              f"{result['scaled_target_steps_per_s']:,.0f} steps/s on this machine)")
        print(f"    batched rollout : {result['reference_batched_steps_per_s']:>10,.0f} steps/s  -> "
              f"{100 * result['batched_ratio_to_reference']:.0f} % (the target asks "
              f"{100 * batched / batched_at:.0f} %: "
              f"{result['scaled_target_batched_steps_per_s']:,.0f} steps/s on this machine)")


def print_bench_train(result: Mapping[str, object]) -> None:
    """`bench_train`'s figures, and the target scaled to this machine when the reference was measured."""
    print(f"Training env speed: {result['robot']} (arm {result['arm_mode']}), {result['num_envs']} envs, "
          f"{result['threads']} threads, policy at {1 / (result['timestep_s'] * result['decimation']):.0f} Hz, "
          f"dt {result['timestep_s'] * 1e3:.1f} ms, random actions")
    print(f"  machine: {result['machine']}")
    print(f"  env            : {result['control_steps_per_s']:>10,.0f} control steps/s "
          f"({result['physics_steps_per_s']:,.0f} physics steps/s)")
    print(f"  rollout only   : {result['rollout_only_control_steps_per_s']:>10,.0f} control steps/s (physics limit)")
    print(f"  env efficiency : {100 * result['env_efficiency']:>9.0f} %  "
          f"({result['python_ms_per_step']:.1f} ms of Python per policy step)")
    print(f"  CPU-time bound : {result['cpu_bound_control_steps_per_s']:>10,.0f} control steps/s with the cores to "
          f"itself (physics alone {result['cpu_bound_physics_only_control_steps_per_s']:,.0f}; CPU per step: "
          f"physics {result['physics_cpu_ms_per_step']:.0f} ms, Python {result['python_cpu_ms_per_step']:.1f} ms)")
    if "reference_physics_limit_control_steps_per_s" in result:
        target, at = TRAIN_TARGET
        print(f"  reference      : {result['reference_physics_limit_control_steps_per_s']:>10,.0f} control steps/s "
              f"(bare A1, 64 envs, 2 ms steps at 50 Hz; the target's ~{at / 1e3:.0f}k); env at "
              f"{100 * result['control_steps_ratio_to_reference']:.0f} % of it, the target ({target / 1e3:.0f}k of "
              f"{at / 1e3:.1f}k) asks "
              f"{100 * target / at:.0f} %: {result['scaled_target_control_steps_per_s']:,.0f} control steps/s here")


def print_bench_mpc(result: Mapping[str, object]) -> None:
    """`bench_mpc`'s figures, and the targets scaled to this machine when the references were measured."""
    print(f"MPC speed: {result['controller']} on {result['robot']} walking at 0.3 m/s, N = {result['horizon']}")
    print(f"  machine: {result['machine']}")
    print(f"  MPC QP solve   : median {result['mpc_solve_ms_median']:.2f} ms, p99 {result['mpc_solve_ms_p99']:.2f} ms "
          f"(setup median {result['mpc_setup_ms_median']:.2f} ms)")
    print(f"  whole-body layer: median {result['wbc_tick_us_median']:.0f} us per tick")
    print(f"  control tick: median {result['control_tick_us_median']:.0f} us (kinematics, estimator, footholds, "
          "whole-body layer, command; ticks without an MPC update)")
    print(f"  closed loop    : {result['realtime_factor']:.1f}x real time on one core")
    if "reference_placo_tick_us" in result:
        tick_at = MPC_REFERENCE_TARGETS["wbc_tick_us_median"][1]
        physics_at = MPC_REFERENCE_TARGETS["realtime_factor"][1]
        print(f"  references     : bare-A1 PlaCo tick {result['reference_placo_tick_us']:.0f} us (the targets' "
              f"~{tick_at:.0f} us), bare-A1 physics {result['reference_steps_per_s']:,.0f} steps/s (the targets' "
              f"{physics_at / 1e3:.0f}k)")
        print(f"  targets scaled to this machine: whole-body tick <= {result['scaled_target_wbc_tick_us']:.0f} "
              f"us, closed loop >= {result['scaled_target_realtime_factor']:.1f}x real time")
        print(f"  against the references: control tick {result['control_tick_over_reference_tick']:.2f}x the "
              f"reference PlaCo tick (target <= 1.8); closed loop {result['closed_loop_over_physics_rtf']:.3f} of "
              f"this robot's physics alone ({result['physics_realtime_factor']:.0f}x real time; target >= 0.075)")


def print_bench_sweep(result: Mapping[str, object]) -> None:
    """`bench_sweep`'s figures, one line per executor measured."""
    print(f"Sweep speed: {result['controller']} on {result['scenario']} ({result['trials']} trials, "
          f"{result['terrain']} terrain)")
    print(f"  machine: {result['machine']}")
    print(f"  batched physics (bench sim, same terrain): {result['batched_physics_steps_per_s']:>10,.0f} steps/s")
    for name in ("local", "ray"):
        if f"{name}_wall_s" in result:
            print(f"  sweep, {name:<5} executor: {result[f'{name}_sweep_steps_per_s']:>10,.0f} steps/s "
                  f"({100 * result[f'{name}_ratio_to_batched_physics']:.0f} % of batched physics, "
                  f"{result[f'{name}_wall_s']:.1f} s)")
    if "ray_overhead_per_trial_s" in result:
        print(f"  Ray overhead per trial: {1e3 * result['ray_overhead_per_trial_s']:.0f} ms")


def print_arena(result: ArenaResult) -> None:
    """The summary table of a run or comparison, then how long it took and where the results are."""
    print(format_table(result.summary))
    rate = result.physics_steps / result.wall_s if result.wall_s > 0 else float("nan")
    print(f"\n{result.played} trials played in {result.wall_s:.1f} s ({rate:,.0f} physics steps/s); "
          f"results in {result.out_dir}/ (trials.csv, summary.json, report.md)")


def print_demo_header(controllers: Sequence[str], *, scenario: str, trials: int, seeds: int) -> None:
    """The line that opens ``wbc demo``: who plays which trials."""
    print(f"A/B demo: {', '.join(controllers)} on {scenario}, {trials} trials x {seeds} seeds "
          "per band (the same trials for every controller)\n")


def print_trained(result: Mapping[str, object], *, task: str, stage: int, baseline: str | None) -> None:
    """One line on a finished training run: its length and where its policy is."""
    print(f"trained {task} stage {stage}{' ' + baseline if baseline else ''}: "
          f"{result['iterations']} iterations, {result['env_steps']:,} env steps, {result['wall_s'] / 60:.1f} min; "
          f"policy {result['policy']}")


def print_viewed_trial(what: str, record: TrialRecord) -> None:
    """How a trial watched in the viewer ended."""
    print(f"{what}: " + ("survived" if record.success else f"fell at {record.fall_time_s:.2f} s"))


def print_recording(what: str, frames: int, path: Path) -> None:
    """Where a recorded replay was written."""
    print(f"recorded {frames} frames of {what} to {path}")


def print_bench_hw(result: Mapping[str, object]) -> None:
    """``wbc bench hw``: the link's send period, round trip, CPU per tick and rejects."""
    print(f"Unitree {result['robot']} low-level link over loopback ({result['transport']} transport), "
          f"{result['rate_hz']:.0f} Hz for {result['seconds']} s; emulator: {result['emulator_process']}")
    print(f"  send period     p50 {result['period_ms_p50']:.3f} ms  p99 {result['period_ms_p99']:.3f} ms  "
          f"max {result['period_ms_max']:.3f} ms")
    print(f"  round trip      p50 {result['round_trip_ms_p50']:.3f} ms  p99 {result['round_trip_ms_p99']:.3f} ms "
          "(command sent -> the state answering it taken by the link thread)")
    print(f"  link thread CPU {result['cpu_us_per_tick']:.0f} us per tick")
    emu = result["emulator"]
    print(f"  frames          {result['sends']} sent, {result['replies_received']} states received, "
          f"{result['rejects']} rejected by the robot; emulator decoded {emu['accepted']}, rejected "
          f"{sum(emu['rejected'].values())}")
    print(f"  machine: {result['machine']}")


def print_emulator_started(robot: str, mode: str, address: tuple[str, int], faults: Sequence[str], *,
                           seconds: float | None) -> None:
    """``wbc hw emulate``: where the emulator listens, and how it stops."""
    host, port = address
    print(f"emulated {robot} ({mode}) on {host}:{port}; faults: {', '.join(faults) or 'none'}; "
          + (f"stopping after {seconds} s" if seconds is not None else "Ctrl-C to stop"), flush=True)
    print(f"  connect with: wbc hw check --robot {robot} --target {host}:{port}", flush=True)


def print_emulator_counts(counts: EmulatorCounts) -> None:
    """``wbc hw emulate``'s closing line: commands decoded, rejects by reason, replies."""
    rejects = ", ".join(f"{reason} {counts.rejected[reason]}" for reason in REJECT_REASONS)
    print(f"commands decoded {counts.accepted}; rejected {sum(counts.rejected.values())} ({rejects}); "
          f"refused (negative gain) {counts.refused}; replies {counts.replies}")


def print_hw_check(robot: str, target: tuple[str, int], joint_names: Sequence[str], state: RobotState,
                   extras: LowStateExtras | None, link: LinkStats, decode: DecodeStats) -> None:
    """``wbc hw check``: the robot's state as read, and how the link went."""
    host, port = target
    print(f"{robot} at {host}:{port}: {link.valid_states} states received, newest {1e3 * link.state_age:.1f} ms old")
    print("  joint                 q [rad]   dq [rad/s]   tau_est [N m]" + ("   mode  temp [C]" if extras else ""))
    for i, name in enumerate(joint_names):
        row = f"  {name:<20}{state.q[i]:>9.3f}{state.dq[i]:>13.3f}{state.tau_est[i]:>16.2f}"
        if extras is not None:
            row += f"   0x{int(extras.motor_mode[i]):02X}{int(extras.motor_temperature[i]):>10d}"
        print(row)
    if extras is not None:
        roll, pitch, _ = np.degrees(extras.imu_rpy)
        print(f"  IMU roll {roll:.1f} deg, pitch {pitch:.1f} deg")
        battery = extras.battery
        print("  battery: " + ("none in this robot's state (A1)" if battery is None else
                               f"{battery.soc} % SOC, {battery.current:.2f} A, "
                               f"{float(np.sum(battery.cell_voltage)):.2f} V over the cells"))
        held = extras.remote.held
        estop = "  (L2+B held: e-stop)" if extras.remote.l2_b else ""
        print(f"  remote buttons: {', '.join(held) or 'none'}{estop}")
    print(f"  link: {link.frames_sent} frames sent, {link.damping_sent} of them damping (Kp 0); period mean "
          f"{1e3 * link.period_mean:.3f} ms, std {1e3 * link.period_std:.3f} ms, max "
          f"{1e3 * link.period_max:.3f} ms; {link.overruns} overruns; {link.foreign} foreign datagrams")
    print(f"  rejected states: {decode.rejected} (" + ", ".join(f"{r} {getattr(decode, r)}" for r in REJECT_REASONS)
          + ")")
