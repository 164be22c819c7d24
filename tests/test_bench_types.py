"""The benches' typed results: their JSON (``wbc bench ... --json``) keeps the keys and their order, and the printers
read the typed attributes.

The key lists below are the JSON contract users' scripts read. They were recorded from the dict-returning benches
this module's types replaced (each bench's cheap path run once, its ``--json`` keys written down), so a test here
fails if a type renames, drops, adds or reorders a key. The results are built from small made-up figures; only
`bench_sim`'s cheapest run is measured for real, and none of its figures is asserted.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import math
import re
import sys
from collections.abc import Iterator

import numpy as np
import pytest

from wbc.cli import printers
from wbc.cli.main import main
from wbc.hardware.unitree import LinkStats
from wbc.tools.bench import (
    ActBenchResult,
    ActCost,
    ArmBenchResult,
    ArmRateRow,
    ArmReactionRow,
    ArmStepRow,
    DelayMargin,
    EmulatorCounts,
    EmulatorTimingRow,
    HwBenchResult,
    LatencyBenchResult,
    MpcBenchResult,
    MpcReference,
    MpcRound,
    MpcTickFigures,
    SafetyBenchResult,
    SimBenchResult,
    SimReference,
    SweepBenchResult,
    SweepExecutorRow,
    TrainBenchResult,
    TrainReference,
    WireLatency,
    bench_sim,
)

SIM_KEYS = ["robot", "arm_mode", "terrain", "timestep_s", "steps_per_s", "batched_steps_per_s", "realtime_factor",
            "batch", "threads", "final_base_height_m", "machine", "load_1min"]
SIM_REFERENCE_KEYS = ["reference_steps_per_s", "reference_batched_steps_per_s", "steps_ratio_to_reference",
                      "batched_ratio_to_reference", "scaled_target_steps_per_s", "scaled_target_batched_steps_per_s"]
TRAIN_KEYS = ["control_steps_per_s", "physics_steps_per_s", "rollout_only_control_steps_per_s", "env_efficiency",
              "python_ms_per_step", "python_cpu_ms_per_step", "physics_cpu_ms_per_step",
              "cpu_bound_control_steps_per_s", "cpu_bound_physics_only_control_steps_per_s", "resets_per_step",
              "num_envs", "threads", "decimation", "timestep_s", "robot", "arm_mode", "terrain", "mujoco", "machine",
              "load_1min"]
TRAIN_REFERENCE_KEYS = ["reference_physics_limit_control_steps_per_s", "control_steps_ratio_to_reference",
                        "scaled_target_control_steps_per_s"]
MPC_KEYS = ["robot", "controller", "horizon", "mpc_solve_ms_median", "mpc_solve_ms_p99", "mpc_setup_ms_median",
            "wbc_tick_us_median", "control_tick_us_median", "realtime_factor", "cpu_realtime_factor",
            "walk_physics_realtime_factor", "walk_physics_share", "warmup_episode_s", "fell", "blas",
            "qp_solver", "machine", "load_1min", "rounds", "qp_comparison_skipped", "controller_config"]
MPC_REFERENCE_KEYS = ["reference_placo_tick_us", "reference_steps_per_s", "physics_realtime_factor",
                      "control_tick_over_reference_tick", "closed_loop_over_physics_rtf", "scaled_target_wbc_tick_us",
                      "scaled_target_realtime_factor", "physics_cpu_realtime_factor", "closed_loop_over_physics_cpu",
                      "closed_loop_over_physics_cpu_min", "closed_loop_over_physics_cpu_max"]
SWEEP_KEYS = ["scenario", "controller", "terrain", "trials", "batched_physics_steps_per_s", "machine", "load_1min"]
SWEEP_EXECUTOR_KEYS = ["{}_wall_s", "{}_sweep_steps_per_s", "{}_ratio_to_batched_physics"]
HW_KEYS = ["robot", "seconds", "rate_hz", "transport", "emulator_process", "sends", "replies_received",
           "period_ms_p50", "period_ms_p99", "period_ms_max", "round_trip_ms_p50", "round_trip_ms_p99",
           "cpu_us_per_tick", "advance_ms_p50", "advance_ms_p99", "late_advances", "worst_lateness_ms", "rejects",
           "emulator", "link", "safety", "machine", "load_1min", "realtime", "emulator_realtime"]
HW_EMULATOR_KEYS = ["accepted", "rejected", "refused", "replies"]
HW_LINK_KEYS = ["frames_sent", "damping_sent", "deadline_trips", "valid_states", "rejected_states", "foreign", "unsent",
                "state_age", "period_mean", "period_std", "period_min", "period_max", "overruns", "late_advances",
                "worst_lateness"]
HW_SAFETY_KEYS = ["robot", "write_deadline_ms", "link_period_ms", "stale_timeout_ms", "estop_to_damping_ms",
                  "silence_to_damping_ms", "stall_to_damping_ms", "state_fault_to_damping_ms", "stand_seconds",
                  "stand_wall_s", "stand_sim_s", "stand_realtime_factor", "stand_safety_state", "stand_trips",
                  "stand_link_period_ms_mean", "stand_link_period_ms_max", "stand_deadline_trips", "stand_act_ms_p99",
                  "stand_deadline_misses"]
LATENCY_KEYS = ["wire_robot", "scenario", "coarse_ms", "fine_ms"]
LATENCY_WIRE_KEYS = ["round_trip_ms_p50", "round_trip_ms_p99", "period_ms", "wire_ticks", "wire_ticks_p50",
                     "wire_ticks_mean", "wire_ticks_max", "typical_delay_ms", "sim_ticks_typical", "worst_delay_ms",
                     "sim_ticks_worst"]
LATENCY_MARGIN_KEYS = ["controller", "robot", "scenario", "standing", "still_s", "trials", "push_force_n",
                       "still_margin_ms", "still_fell_at_ms", "push_margin_ms", "push_fell_at_ms", "runs", "wall_s"]
ARM_KEYS = ["robot", "latency_ms", "seconds", "step_rad", "emulator_bus", "rates", "steps", "reactions", "emulator",
            "machine", "load_1min", "host_realtime"]
ARM_RATE_KEYS = ["rate_hz", "achieved_hz", "busy_ms_mean", "busy_ms_max", "period_ms_max", "failed_reads", "cycles",
                 "faults"]
ARM_STEP_KEYS = ["source", "kp", "kd", "rate_hz", "rise_ms", "overshoot_pct", "settle_ms", "final_error_rad",
                 "discarded"]
ARM_REACTION_KEYS = ["event", "reaction", "ms", "expected_ms", "watchdog_ms"]
ARM_EMULATOR_KEYS = ["what", "value", "worst", "model"]

MACHINE = "a test machine, 2 cores"


def _json(value: object) -> dict:
    """`value` as ``--json`` writes it, read back."""
    return json.loads(json.dumps(value, default=list))


def _sim(reference: bool = True) -> SimBenchResult:
    ref = SimReference(steps_per_s=110_000.0, batched_steps_per_s=200_000.0, steps_ratio_to_reference=0.75,
                       batched_ratio_to_reference=0.7, scaled_target_steps_per_s=80_000.0,
                       scaled_target_batched_steps_per_s=137_614.7)
    return SimBenchResult(robot="a1-wx200", arm_mode="actuated", terrain="flat", timestep_s=0.002,
                          steps_per_s=82_500.0, batched_steps_per_s=140_000.0, realtime_factor=165.0, batch=64,
                          threads=2, final_base_height_m=0.29, machine=MACHINE, load_1min=1.5,
                          reference=ref if reference else None)


def _train(reference: bool = True) -> TrainBenchResult:
    ref = TrainReference(physics_limit_control_steps_per_s=21_000.0, control_steps_ratio_to_reference=0.6,
                         scaled_target_control_steps_per_s=14_449.5)
    return TrainBenchResult(control_steps_per_s=12_600.0, physics_steps_per_s=126_000.0,
                            rollout_only_control_steps_per_s=18_000.0, env_efficiency=0.7, python_ms_per_step=24.4,
                            python_cpu_ms_per_step=20.5, physics_cpu_ms_per_step=95.0,
                            cpu_bound_control_steps_per_s=15_000.0, cpu_bound_physics_only_control_steps_per_s=21_558.0,
                            resets_per_step=0.5, num_envs=1024, threads=2, decimation=10, timestep_s=0.002,
                            robot="a1-wx200", arm_mode="actuated", terrain="scenario", mujoco="3.0.0", machine=MACHINE,
                            load_1min=1.5,
                            reference=ref if reference else None)


def _mpc(reference: bool = True) -> MpcBenchResult:
    ticks = MpcTickFigures(mpc_solve_ms_median=1.25, mpc_solve_ms_p99=3.5, mpc_setup_ms_median=0.75,
                           wbc_tick_us_median=80.0, control_tick_us_median=150.0)
    ref = MpcReference(reference_placo_tick_us=40.0, reference_steps_per_s=110_000.0, physics_realtime_factor=200.0,
                       control_tick_over_reference_tick=3.75, closed_loop_over_physics_rtf=0.03,
                       scaled_target_wbc_tick_us=100.0, scaled_target_realtime_factor=5.0,
                       physics_cpu_realtime_factor=210.0, closed_loop_over_physics_cpu=0.035,
                       closed_loop_over_physics_cpu_min=0.025, closed_loop_over_physics_cpu_max=0.04)
    nan = math.nan
    rounds = tuple(MpcRound(realtime_factor=6.0, cpu_realtime_factor=cpu, walk_physics_realtime_factor=20.0,
                            walk_physics_share=0.3, physics_realtime_factor=200.0 if reference else nan,
                            physics_cpu_realtime_factor=210.0 if reference else nan) for cpu in (5.25, 7.35, 8.4))
    return MpcBenchResult(robot="a1-wx200", controller="mpc", horizon=10, ticks=ticks, realtime_factor=6.0,
                          cpu_realtime_factor=7.35, walk_physics_realtime_factor=20.0, walk_physics_share=0.3,
                          warmup_episode_s=1.5, fell=False, blas="single-threaded", qp_solver="daqp 0.5.1",
                          machine=MACHINE, load_1min=1.5, reference=ref if reference else None, rounds=rounds)


def _sweep(ray: bool = True) -> SweepBenchResult:
    rows = [SweepExecutorRow(executor="local", wall_s=2.0, sweep_steps_per_s=4000.0, ratio_to_batched_physics=0.1)]
    if ray:
        rows.append(SweepExecutorRow(executor="ray", wall_s=6.0, sweep_steps_per_s=1333.3,
                                     ratio_to_batched_physics=0.0333))
    return SweepBenchResult(scenario="push", controller="stand", terrain="fractal", trials=8,
                            batched_physics_steps_per_s=40_000.0, machine=MACHINE, load_1min=1.5,
                            executors=tuple(rows))


def _hw(safety: bool = True) -> HwBenchResult:
    figures = SafetyBenchResult(
        robot="go1", write_deadline_ms=50.0, link_period_ms=2.0, stale_timeout_ms=100.0, estop_to_damping_ms=1.75,
        silence_to_damping_ms=101.86, stall_to_damping_ms=50.74, state_fault_to_damping_ms=5.14, stand_seconds=0.5,
        stand_wall_s=0.51, stand_sim_s=0.5, stand_realtime_factor=0.98, stand_safety_state="run",
        stand_trips=("0.40 s run -> damped (stale): no state for 0.12 s",), stand_link_period_ms_mean=2.001,
        stand_link_period_ms_max=2.352, stand_deadline_trips=0, stand_act_ms_p99=0.004, stand_deadline_misses=1)
    return HwBenchResult(
        robot="go1", seconds=0.5, rate_hz=500.0, transport="udp", emulator_process="separate process, lockstep",
        sends=250, replies_received=249, period_ms_p50=2.0, period_ms_p99=2.08, period_ms_max=2.15,
        round_trip_ms_p50=0.4, round_trip_ms_p99=2.87, cpu_us_per_tick=204.0, advance_ms_p50=1.93,
        advance_ms_p99=2.2, late_advances=1, worst_lateness_ms=0.25, rejects=0,
        emulator=EmulatorCounts(accepted=300, rejected={"length": 0, "header": 0, "crc": 1, "non_finite": 0},
                                refused=0, replies=300),
        link=LinkStats(frames_sent=250, damping_sent=3), safety=figures if safety else None, machine=MACHINE,
        load_1min=2.5, realtime="asked SCHED_FIFO 50; got SCHED_FIFO 50", emulator_realtime="nothing asked")


def _latency(wire: bool = True) -> LatencyBenchResult:
    on = {"robot": "a1-wx200", "scenario": "push", "standing": True, "still_s": 3.0}
    stand = DelayMargin(controller="stand", **on, trials=1, push_force_n=(233.2,), still_margin_ms=200.0,
                        still_fell_at_ms=None, push_margin_ms=None, push_fell_at_ms=0.0, runs=3, wall_s=0.62)
    mpc = DelayMargin(controller="mpc", **on, trials=1, push_force_n=(233.2,), still_margin_ms=18.0,
                      still_fell_at_ms=20.0, push_margin_ms=10.0, push_fell_at_ms=12.0, runs=9, wall_s=30.0)
    figures = WireLatency(round_trip_ms_p50=0.4, round_trip_ms_p99=0.82, period_ms=2.0, wire_ticks=(2, 3, 2, 5),
                          wire_ticks_p50=2.0, wire_ticks_mean=3.0, wire_ticks_max=5, typical_delay_ms=2.0,
                          sim_ticks_typical=2.0, worst_delay_ms=8.0, sim_ticks_worst=5.0)
    return LatencyBenchResult(wire_robot="go1", scenario="scenarios/push.toml", coarse_ms=(0.0, 10.0, 20.0),
                              fine_ms=2.0, wire=figures if wire else None, margins=(stand, mpc), machine=MACHINE,
                              load_1min=1.5)


ACT_KEYS = ["scenario", "band", "seed", "trial", "costs", "machine", "load_1min", "ratios"]
ACT_COST_KEYS = ["controller", "rate_hz", "ticks", "survived_s", "fell", "cpu_us_per_tick_median",
                 "cpu_us_per_tick_mean", "cpu_ms_per_s", "rounds"]


def _act() -> ActBenchResult:
    mpc = ActCost(controller="mpc", rate_hz=500.0, ticks=10000, survived_s=20.0, fell=False,
                  cpu_us_per_tick_median=18.0, cpu_us_per_tick_mean=50.0, cpu_ms_per_s=25.0, rounds=3)
    student = ActCost(controller="policy:student", rate_hz=50.0, ticks=400, survived_s=8.0, fell=True,
                      cpu_us_per_tick_median=60.0, cpu_us_per_tick_mean=62.5, cpu_ms_per_s=3.125, rounds=3)
    return ActBenchResult(scenario="scenarios/push.toml", band="ood", seed=1, trial=2, costs=(mpc, student),
                          machine=MACHINE, load_1min=1.5)


def _arm() -> ArmBenchResult:
    return ArmBenchResult(
        robot="a1-wx200", latency_ms=1.0, seconds=0.3, step_rad=-0.05,
        emulator_bus={"packets": 4414, "rejected": {}, "dropped_bytes": 0, "statuses": 8100, "unheard": 3},
        rates=(ArmRateRow(rate_hz=200.0, achieved_hz=196.6, busy_ms_mean=0.9, busy_ms_max=2.6, period_ms_max=5.1,
                          failed_reads=0, cycles=121, faults=0),),
        steps=(ArmStepRow(source="bus", kp=20.0, kd=0.5, rate_hz=200.0, rise_ms=63.0, overshoot_pct=14.8,
                          settle_ms=249.7, final_error_rad=-0.048),
               ArmStepRow(source="simulation", kp=20.0, kd=0.5, rate_hz=500.0, rise_ms=68.0, overshoot_pct=11.6,
                          settle_ms=242.0, final_error_rad=-0.0459)),
        reactions=(ArmReactionRow(event="write_deadline", reaction="damping", ms=3.98, expected_ms=50.0),
                   ArmReactionRow(event="port_closed", reaction="port_lost", ms=1.5, expected_ms=5.0,
                                  watchdog_ms=100.4)),
        emulator=(EmulatorTimingRow(what="plant_realtime_factor", value=0.999, worst=0.0, model=1.0),
                  EmulatorTimingRow(what="sync_read_round_trip_byte_timing", value=1.234, worst=2.5, model=0.63)),
        machine=MACHINE, load_1min=1.5)


def _printed(printer, result: object, capsys: pytest.CaptureFixture[str]) -> str:
    printer(result)
    return capsys.readouterr().out


# -- the JSON keys, bench by bench -----------------------------------------------------------------------------------
def test_sim_json_keeps_its_keys_and_puts_the_reference_after_them():
    out = _json(_sim().as_dict())
    assert list(out) == SIM_KEYS + SIM_REFERENCE_KEYS
    assert (out["steps_per_s"], out["reference_steps_per_s"], out["steps_ratio_to_reference"]) == \
        (82_500.0, 110_000.0, 0.75)
    assert list(_json(_sim(reference=False).as_dict())) == SIM_KEYS


def test_the_cheapest_real_bench_sim_writes_the_recorded_keys():
    """A real run (a few physics steps): the keys the bench itself fills, with and without the reference."""
    with_ref = bench_sim(seconds=0.01, batch=2, nthread=1, batch_steps=5, repeats=1)
    assert list(_json(with_ref.as_dict())) == SIM_KEYS + SIM_REFERENCE_KEYS
    assert with_ref.batch == 2 and with_ref.threads == 1 and with_ref.reference is not None
    without = bench_sim(seconds=0.01, batch=2, nthread=1, batch_steps=5, repeats=1, reference=False)
    assert list(_json(without.as_dict())) == SIM_KEYS and without.reference is None


def test_train_json_keeps_its_keys_and_names_the_reference_limit_as_before():
    out = _json(_train().as_dict())
    assert list(out) == TRAIN_KEYS + TRAIN_REFERENCE_KEYS
    assert out["reference_physics_limit_control_steps_per_s"] == 21_000.0
    assert (out["num_envs"], out["decimation"]) == (1024, 10)
    assert list(_json(_train(reference=False).as_dict())) == TRAIN_KEYS


def test_mpc_json_keeps_its_keys_with_the_tick_figures_flat_after_the_horizon():
    out = _json(_mpc().as_dict())
    assert list(out) == MPC_KEYS + MPC_REFERENCE_KEYS
    assert (out["horizon"], out["mpc_solve_ms_median"], out["fell"], out["reference_placo_tick_us"]) == \
        (10, 1.25, False, 40.0)
    assert list(_json(_mpc(reference=False).as_dict())) == MPC_KEYS
    # the spawned worker's result is relabelled: the key keeps its place
    relabelled = dataclasses.replace(_mpc(), blas="default threads").as_dict()
    assert list(relabelled) == MPC_KEYS + MPC_REFERENCE_KEYS and relabelled["blas"] == "default threads"


def test_tick_figures_are_nan_where_no_tick_was_filed():
    nan = MpcTickFigures(mpc_solve_ms_median=math.nan, mpc_solve_ms_p99=math.nan, mpc_setup_ms_median=math.nan,
                         wbc_tick_us_median=math.nan, control_tick_us_median=math.nan)
    assert list(nan.as_dict()) == MPC_KEYS[3:8]
    assert json.dumps(nan.as_dict()).count("NaN") == 5  # as the dict-returning bench wrote them


def test_sweep_json_prefixes_each_executor_and_ends_with_rays_overhead():
    result = _sweep()
    out = _json(result.as_dict())
    executors = [k.format(name) for name in ("local", "ray") for k in SWEEP_EXECUTOR_KEYS]
    assert list(out) == SWEEP_KEYS + executors + ["ray_overhead_per_trial_s"]
    assert out["ray_overhead_per_trial_s"] == pytest.approx((6.0 - 2.0) / 8)
    assert (out["local_wall_s"], out["ray_sweep_steps_per_s"]) == (2.0, 1333.3)
    local_only = _sweep(ray=False)
    assert local_only.ray_overhead_per_trial_s is None and local_only.executor("ray") is None
    assert list(_json(local_only.as_dict())) == SWEEP_KEYS + executors[:3]


def test_hw_json_keeps_its_keys_and_nests_the_emulator_link_and_safety():
    out = _json(_hw().as_dict())
    assert list(out) == HW_KEYS
    assert list(out["emulator"]) == HW_EMULATOR_KEYS and out["emulator"]["rejected"]["crc"] == 1
    assert list(out["link"]) == HW_LINK_KEYS and out["link"]["frames_sent"] == 250
    assert list(out["safety"]) == HW_SAFETY_KEYS
    assert out["safety"]["stand_trips"] == ["0.40 s run -> damped (stale): no state for 0.12 s"]
    assert _json(_hw(safety=False).as_dict())["safety"] is None


def test_latency_json_puts_the_wire_between_the_sweep_and_the_margins():
    out = _json(_latency().as_dict())
    assert list(out) == LATENCY_KEYS + LATENCY_WIRE_KEYS + ["margins", "machine", "load_1min"]
    assert out["wire_ticks"] == [2, 3, 2, 5] and out["coarse_ms"] == [0.0, 10.0, 20.0]
    assert [list(m) for m in out["margins"]] == [LATENCY_MARGIN_KEYS] * 2
    assert (out["margins"][0]["still_fell_at_ms"], out["margins"][0]["push_margin_ms"]) == (None, None)
    assert list(_json(_latency(wire=False).as_dict())) == LATENCY_KEYS + ["margins", "machine", "load_1min"]


def test_act_json_has_one_dict_per_controller_and_the_ratios_against_the_first():
    out = _json(_act().as_dict())
    assert list(out) == ACT_KEYS
    assert [list(c) for c in out["costs"]] == [ACT_COST_KEYS] * 2
    assert out["ratios"] == [{"controller": "mpc", "per_tick": 1.0, "per_simulated_s": 1.0},
                             {"controller": "policy:student", "per_tick": 1.25, "per_simulated_s": 0.125}]


def test_print_bench_act_shows_both_ratios_and_where_a_controller_fell(capsys):
    printers.print_bench_act(_act())
    text = capsys.readouterr().out
    assert "band ood, seed 1, trial 2" in text
    assert "  mpc " in text and "18.0 / 50.0" in text and "25.00" in text
    assert "1.250" in text and "0.125" in text and "(fell at 8.00 s)" in text
    # the per-call ratio is of the means (62.5 / 50), and its label says so beside the median / mean column
    header = text.splitlines()[1]
    assert "x ref, mean act" in header and "x ref, tick" not in header
    assert "ratios against mpc's mean per act and its CPU per simulated second" in text


def test_bench_act_times_each_controllers_act_on_the_same_trial(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo may write its log file here
    from pathlib import Path

    from wbc.tools.bench import bench_act

    scenario = str(Path(__file__).resolve().parent.parent / "scenarios/push.toml")
    result = bench_act(["stand", "stand"], scenario=scenario, band="in", seed=0, trial=0, repeats=2)
    assert [c.controller for c in result.costs] == ["stand", "stand"]
    for cost in result.costs:
        assert cost.rounds == 2 and cost.rate_hz > 0
        if not cost.fell:
            assert cost.ticks == round(cost.survived_s * cost.rate_hz)
        assert 0 < cost.cpu_us_per_tick_median and 0 < cost.cpu_ms_per_s
    assert result.ratios()[0][1:] == (1.0, 1.0)


def test_arm_json_keeps_its_keys_and_one_dict_per_row():
    out = _json(_arm().as_dict())
    assert list(out) == ARM_KEYS
    assert [list(r) for r in out["rates"]] == [ARM_RATE_KEYS]
    assert [list(r) for r in out["steps"]] == [ARM_STEP_KEYS] * 2
    assert [list(r) for r in out["reactions"]] == [ARM_REACTION_KEYS] * 2
    assert [list(r) for r in out["emulator"]] == [ARM_EMULATOR_KEYS] * 2
    assert out["emulator_bus"]["statuses"] == 8100 and out["reactions"][0]["watchdog_ms"] is None


# -- the printers read the typed results -----------------------------------------------------------------------------
def test_print_bench_sim_shows_the_reference_only_when_measured(capsys):
    text = _printed(printers.print_bench_sim, _sim(), capsys)
    assert "82,500 steps/s  (real-time factor 165x)" in text and "140,000 steps/s  (64 envs, 2 threads)" in text
    assert "110,000 steps/s  -> this robot runs at 75 % of it" in text and "80,000 steps/s on this machine" in text
    assert "bare A1" not in _printed(printers.print_bench_sim, _sim(reference=False), capsys)


def test_print_bench_train_shows_the_scaled_target_only_when_measured(capsys):
    text = _printed(printers.print_bench_train, _train(), capsys)
    assert "policy at 50 Hz" in text and "12,600 control steps/s (126,000 physics steps/s)" in text
    assert "env efficiency :        70 %" in text and "env at 60 % of it" in text
    assert "14,450 control steps/s here" in text
    assert "reference      :" not in _printed(printers.print_bench_train, _train(reference=False), capsys)


def test_print_bench_train_keeps_a_small_cpu_time_per_step(capsys):
    text = _printed(printers.print_bench_train, _train(), capsys)
    assert "CPU per step: physics 95.0 ms, Python 20.5 ms)" in text and "(24.4 ms of Python per policy step)" in text
    few = dataclasses.replace(_train(), physics_cpu_ms_per_step=0.12, python_cpu_ms_per_step=0.4,
                              python_ms_per_step=0.45)  # two envs: rounded to ms, the physics read 0
    text = _printed(printers.print_bench_train, few, capsys)
    assert "CPU per step: physics 120 us, Python 400 us)" in text and "(450 us of Python per policy step)" in text


def test_print_bench_mpc_shows_the_tick_and_the_references(capsys):
    text = _printed(printers.print_bench_mpc, _mpc(), capsys)
    assert "N = 10" in text and "median 1.25 ms, p99 3.50 ms (setup median 0.75 ms)" in text
    assert "median 80 us per timed tick (the leg layer's: the MPC-update ticks; PlaCo's QP: every tick)" in text
    assert "control tick: median 150 us" in text and "6.0x real time" in text
    assert text.splitlines()[0].endswith("QP solver daqp 0.5.1, BLAS single-threaded")
    assert "control tick 3.75x the reference PlaCo tick" in text and "closed loop 0.030 of" in text
    assert "6.0x real time on one core (7.3x in CPU time); the walk's physics steps 30% of it (20x" in text
    assert "0.035 in CPU time (210x; target >= 0.20)" in text
    # each round against its own references, with the spread the machine made
    assert "median of 3 timed walks" in text
    assert "just before and after it, in CPU time: 0.025, 0.035, 0.040 (median 0.035, 0.025 to 0.040" in text
    without = _printed(printers.print_bench_mpc, _mpc(reference=False), capsys)
    assert "references" not in without and "just before and after" not in without
    one = dataclasses.replace(_mpc(), rounds=_mpc().rounds[:1])
    assert "on their own); one timed walk\n" in _printed(printers.print_bench_mpc, one, capsys)
    assert "just before and after" not in _printed(printers.print_bench_mpc, one, capsys)


def test_print_bench_mpc_says_how_blas_was_threaded_and_claims_one_core_only_when_it_was(capsys):
    threaded = _printed(printers.print_bench_mpc, dataclasses.replace(_mpc(), blas="default threads"), capsys)
    assert threaded.splitlines()[0].endswith(", BLAS default threads")
    assert "6.0x real time with the BLAS's default threads (7.3x in CPU time)" in threaded
    assert "one core" not in threaded


def test_print_bench_mpc_says_why_the_qp_backends_were_not_compared(capsys):
    tail = dataclasses.replace(_mpc(), controller="mpc-tail", qp_comparison_skipped="mpc-tail solves its own QP")
    assert "  QP backends not compared: mpc-tail solves its own QP\n" in _printed(printers.print_bench_mpc, tail,
                                                                                    capsys)
    assert _json(tail.as_dict())["qp_comparison_skipped"] == "mpc-tail solves its own QP"


@pytest.mark.parametrize(("printer", "build"), [
    (printers.print_bench_sim, lambda: _sim()), (printers.print_bench_train, lambda: _train()),
    (printers.print_bench_mpc, lambda: _mpc()), (printers.print_bench_sweep, lambda: _sweep()),
    (printers.print_bench_latency, lambda: _latency()), (printers.print_bench_latency, lambda: _latency(wire=False)),
    (printers.print_bench_arm, lambda: _arm()),
], ids=["sim", "train", "mpc", "sweep", "latency", "latency-no-wire", "arm"])
def test_each_bench_prints_the_machine_and_its_load(printer, build, capsys):
    assert f"  machine: {MACHINE}, load 1.50 (1 min)\n" in _printed(printer, build(), capsys)


def test_print_bench_sweep_prints_one_line_per_executor_then_rays_overhead(capsys):
    lines = _printed(printers.print_bench_sweep, _sweep(), capsys).splitlines()
    assert "  sweep, local executor:      4,000 steps/s (10 % of batched physics, 2.0 s)" in lines
    assert "  sweep, ray   executor:      1,333 steps/s (3 % of batched physics, 6.0 s)" in lines
    assert lines[-1] == "  Ray overhead per trial: 500 ms"
    assert "Ray overhead" not in _printed(printers.print_bench_sweep, _sweep(ray=False), capsys)


def test_print_bench_hw_shows_the_counts_and_the_safety_figures(capsys):
    text = _printed(printers.print_bench_hw, _hw(), capsys)
    # the two counts cover different windows, and each line says which
    assert ("  frames          250 sent, 249 states received, 0 rejected by the robot (the link, from its start to the "
            "end of the measurement)\n") in text
    assert ("  emulator        decoded 300, rejected 1 (its whole session: the link's damping frames at close "
            "included)\n") in text
    assert "e-stop          1.75 ms" in text and "stale timeout 100 ms" in text and "deadline misses 1" in text
    assert "    trip: 0.40 s run -> damped (stale): no state for 0.12 s" in text
    assert ("scheduling      link side: asked SCHED_FIFO 50; got SCHED_FIFO 50; emulator: nothing asked; load "
            "2.50") in text
    assert "Safety layer" not in _printed(printers.print_bench_hw, _hw(safety=False), capsys)


def test_print_bench_latency_shows_the_wire_and_each_margin(capsys):
    text = _printed(printers.print_bench_latency, _latency(), capsys)
    assert "max 5 (count by ticks: 2: 2, 3: 1, 5: 1)" in text and "typical 2 ms, worst 8 ms" in text
    assert "(sweep: 0, 10, 20, then 2 ms steps" in text
    assert "none, fell at 0" in text and "200 (no fall up to 20)" in text and "18, fell at 20" in text
    assert "(9 runs)" in text
    assert "Wire (" not in _printed(printers.print_bench_latency, _latency(wire=False), capsys)


def test_print_bench_latency_names_the_robot_and_the_trials_of_the_margins(capsys):
    """The margins play the scenario's robot, which may not be the wire's: the a1-wx200 of the default push scenario
    beside a go1 wire was not named; a Go1 scenario's walking trials, without pushes, are said to be so."""
    text = _printed(printers.print_bench_latency, _latency(), capsys)
    assert "standing trials of scenarios/push.toml, on the a1-wx200 (the scenario push's robot)" in text
    assert "the margins are the a1-wx200's, not the go1's of the wire above" in text
    walking = DelayMargin(controller="mpc", robot="go1-arm", scenario="turn", standing=False, still_s=6.0, trials=2,
                          push_force_n=(), still_margin_ms=30.0, still_fell_at_ms=40.0, push_margin_ms=None,
                          push_fell_at_ms=None, runs=5, wall_s=40.0)
    go1 = dataclasses.replace(_latency(), scenario="scenarios/turn.toml", margins=(walking,))
    text = _printed(printers.print_bench_latency, go1, capsys)
    assert ("walking trials of scenarios/turn.toml (it has no standing trials with pushes): each walks its command "
            "6 s, and has no push to survive, on the go1-arm (the scenario turn's robot)") in text
    assert "not the go1's" not in text
    assert re.search(r"mpc +30, fell at 40 +no push in the trials", text), text


def test_print_bench_arm_shows_every_row(capsys):
    text = _printed(printers.print_bench_arm, _arm(), capsys)
    assert "196.6" in text and "elbow step of -0.05 rad" in text
    assert "  bus          20   0.5         200             63.0" in text
    assert "port_closed      port_lost         1.5            5.0       100.4" in text
    assert "real-time factor 0.999 (overruns 0)" in text and "with byte timing: p50 1.234 ms" in text


# -- the command: --json is `as_dict`, the table is the printer's ----------------------------------------------------
@pytest.fixture
def switch_interval() -> Iterator[None]:
    """The hardware benches shorten the interpreter's switch interval; put it back for the tests after."""
    before = sys.getswitchinterval()
    yield
    sys.setswitchinterval(before)


BENCHES = [
    (["bench", "sim"], "bench_sim", _sim, printers.print_bench_sim),
    (["bench", "train"], "bench_train", _train, printers.print_bench_train),
    (["bench", "mpc"], "bench_mpc", _mpc, printers.print_bench_mpc),
    (["bench", "sweep"], "bench_sweep", _sweep, printers.print_bench_sweep),
    (["bench", "hw"], "bench_hw", _hw, printers.print_bench_hw),
    (["bench", "latency"], "bench_latency", _latency, printers.print_bench_latency),
    (["bench", "arm"], "bench_arm", _arm, printers.print_bench_arm),
    (["bench", "act", "mpc"], "bench_act", _act, printers.print_bench_act),
]


@pytest.mark.parametrize(("argv", "bench", "build", "printer"), BENCHES, ids=[b[1] for b in BENCHES])
def test_each_bench_command_prints_its_result_as_json_or_as_its_table(argv, bench, build, printer, monkeypatch,
                                                                      capsys, switch_interval):
    result = build()
    # the module, not the `main` function `wbc.cli` re-exports under the same name
    monkeypatch.setattr(importlib.import_module("wbc.cli.main"), bench, lambda *args, **kwargs: result)
    assert main([*argv, "--json"]) == 0
    out = capsys.readouterr().out
    assert out == json.dumps(printers.strict_json(result.as_dict()), indent=2) + "\n"
    # strict JSON: a figure that could not be measured (nan) is null, which any JSON reader takes
    json.loads(out, parse_constant=lambda name: pytest.fail(f"{name} in --json output"))
    assert main(argv) == 0
    assert capsys.readouterr().out == _printed(printer, result, capsys)


def test_json_output_is_strict_json_with_null_for_a_figure_not_measured(capsys):
    value = {"a": math.nan, "b": (1.0, math.inf, -math.inf), "c": [np.float64(np.nan), np.int64(3)],
             "d": {"e": np.array([1.5, np.nan])}, "f": "NaN", "g": None, "h": True}
    printers.print_json(value)
    out = capsys.readouterr().out
    assert json.loads(out, parse_constant=lambda name: pytest.fail(name)) == {
        "a": None, "b": [1.0, None, None], "c": [None, 3], "d": {"e": [1.5, None]}, "f": "NaN", "g": None, "h": True}
