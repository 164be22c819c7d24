"""The ``wbc`` command line: ``run``, ``compare``, ``analyze tail``, ``bench ...``, ``train``, ``demo``."""

from __future__ import annotations

import argparse
import json
import sys

from wbc.errors import WbcError
from wbc.robots.description import ARM_MODES
from wbc.robots.registry import ROBOTS, get_robot

__all__ = ["main"]


def _analyze_tail(args: argparse.Namespace) -> int:
    from wbc.analysis import analyze_tail

    result = analyze_tail(get_robot(args.robot, "actuated"))
    if args.json:
        print(json.dumps(result.as_dict(), indent=2))
        return 0
    print(f"Arm as a tail: {result.robot}")
    print(f"  inputs: moving arm mass M_a = {result.arm_mass_moving:.3f} kg, rest M_b = {result.body_mass:.3f} kg, "
          f"arm length l = {result.arm_length:.3f} m, trunk h x w = {result.trunk_height:.3f} x "
          f"{result.trunk_width:.3f} m")
    print(f"  {'quantity':<34}{'rod model':>11}{'exact':>10}{'paper':>9}")
    print(f"  {'CoM shift by arm rotation [m]':<34}{result.ccom_shift_m:>11.4f}{result.ccom_shift_m_exact:>10.4f}"
          f"{result.paper_ccom_shift_m:>9.3f}")
    print(f"  {'body/arm angular acceleration':<34}{result.alpha_ratio:>11.3f}{result.alpha_ratio_exact:>10.3f}"
          f"{result.paper_alpha_ratio:>9.3f}")
    return 0


def _bench_sim(args: argparse.Namespace) -> int:
    from wbc.bench import bench_sim

    get_robot(args.robot, args.arm)  # validate names before any work
    result = bench_sim(args.robot, args.arm, batch=args.batch, nthread=args.threads, terrain=args.terrain)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"Simulation speed: {result['robot']} (arm {result['arm_mode']}), standing under the motor law on "
          f"{result['terrain']} ground, dt {result['timestep_s'] * 1e3:.1f} ms")
    print(f"  machine: {result['machine']}")
    print(f"  single-threaded : {result['steps_per_s']:>10,.0f} steps/s  (real-time factor "
          f"{result['realtime_factor']:.0f}x)")
    print(f"  batched rollout : {result['batched_steps_per_s']:>10,.0f} steps/s  ({result['batch']} envs, "
          f"{result['threads']} threads)")
    return 0


def _bench_train(args: argparse.Namespace) -> int:
    from wbc.learned.env_config import EnvConfig
    from wbc.learned.throughput import bench_train

    cfg = EnvConfig(arm_mode=args.arm, num_envs=args.envs, nthread=args.threads, terrain=args.terrain)
    result = bench_train(cfg, steps=args.steps)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
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
    return 0


def _train(args: argparse.Namespace) -> int:
    import dataclasses

    from wbc.learned.stages import stage_config

    env = {k: v for k, v in (("num_envs", args.envs), ("seed", args.seed), ("nthread", args.threads)) if v is not None}
    overrides = {k: v for k, v in (("max_iterations", args.iterations), ("seed", args.seed)) if v is not None}
    cfg = stage_config(args.task, args.stage, args.baseline, run_root=args.run_root, teacher=args.teacher,
                       env_overrides=env, **overrides)
    if args.dry_run:
        print(json.dumps(dataclasses.asdict(cfg), indent=2, default=list))
        return 0
    from wbc.learned.train import train

    result = train(cfg, resume=args.resume)
    print(f"trained {args.task} stage {args.stage}{' ' + args.baseline if args.baseline else ''}: "
          f"{result['iterations']} iterations, {result['env_steps']:,} env steps, {result['wall_s'] / 60:.1f} min; "
          f"policy {result['policy']}")
    return 0


def _arena(args: argparse.Namespace, controllers: tuple[str, ...]) -> int:
    import time
    from pathlib import Path

    from wbc.arena import ArenaConfig, run_arena
    from wbc.report import format_table

    seeds = tuple(range(args.seeds)) if args.seeds is not None else (0,)
    out = Path(args.out) if args.out else Path("runs") / (
        f"{Path(args.scenario).stem}-{'-'.join(controllers)}-{time.strftime('%Y%m%d-%H%M%S')}")
    cfg = ArenaConfig(controllers=controllers, scenario=Path(args.scenario), bands=tuple(args.band or ()),
                      seeds=seeds, trials=args.trials, out_dir=out, executor=args.executor, workers=args.workers,
                      address=args.address, resume=args.resume, progress=not args.json and not args.quiet)
    result = run_arena(cfg)
    if args.json:
        print(json.dumps(result.summary, indent=2))
        return 0
    print(format_table(result.summary))
    rate = result.physics_steps / result.wall_s if result.wall_s > 0 else float("nan")
    print(f"\n{result.played} trials played in {result.wall_s:.1f} s ({rate:,.0f} physics steps/s); "
          f"results in {result.out_dir}/ (trials.csv, summary.json, report.md)")
    return 0


def _run(args: argparse.Namespace) -> int:
    return _arena(args, (args.controller,))


def _compare(args: argparse.Namespace) -> int:
    return _arena(args, tuple(args.controllers))


def _add_arena_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenario", required=True, help="scenario file (e.g. scenarios/push.toml)")
    p.add_argument("--trials", type=int, default=10, help="trials per band and seed (default 10)")
    p.add_argument("--seeds", type=int, default=None, help="number of seeds: seeds 0 .. S-1 (default 1)")
    p.add_argument("--band", action="append", help="band to play (repeatable; default: all)")
    p.add_argument("--out", default=None, help="results directory (default: runs/<scenario>-<controllers>-<time>)")
    p.add_argument("--json", action="store_true", help="print summary.json instead of the table")
    p.add_argument("--executor", default="local", help="local (process pool, default) or ray")
    p.add_argument("--workers", type=int, default=None, help="local worker processes (default: all cores)")
    p.add_argument("--address", default=None, help="Ray cluster address (default: start a local Ray)")
    p.add_argument("--resume", action="store_true", help="finish an interrupted run in --out")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def _bench_mpc(args: argparse.Namespace) -> int:
    from wbc.bench import bench_mpc

    result = bench_mpc(args.robot, args.controller, seconds=args.seconds)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"MPC speed: {result['controller']} on {result['robot']} walking at 0.3 m/s, N = {result['horizon']}")
    print(f"  machine: {result['machine']}")
    print(f"  MPC QP solve   : median {result['mpc_solve_ms_median']:.2f} ms, p99 {result['mpc_solve_ms_p99']:.2f} ms "
          f"(setup median {result['mpc_setup_ms_median']:.2f} ms)")
    print(f"  whole-body tick: median {result['wbc_tick_us_median']:.0f} us (ticks without an MPC update)")
    print(f"  closed loop    : {result['realtime_factor']:.1f}x real time on one core")
    return 0


def _bench_sweep(args: argparse.Namespace) -> int:
    from wbc.bench import bench_sweep

    result = bench_sweep(args.scenario, args.controller, trials=args.trials, workers=args.workers, ray=args.ray)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
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
    return 0


def _demo(args: argparse.Namespace) -> int:
    """A short A/B: the standing baseline with the arm actuated, locked and absent, on the push scenario."""
    import time

    controllers = ("stand", "stand-locked", "stand-noarm")
    print(f"A/B demo: {', '.join(controllers)} on scenarios/push.toml, {args.trials} trials x {args.seeds} seeds "
          "per band (the same trials for every controller)\n")
    ns = argparse.Namespace(
        scenario=args.scenario, trials=args.trials, seeds=args.seeds, band=None,
        out=args.out or f"runs/demo-{time.strftime('%Y%m%d-%H%M%S')}", json=False, executor="local",
        workers=None, address=None, resume=False, quiet=args.quiet,
    )
    rc = _arena(ns, controllers)
    print()
    return rc or _analyze_tail(argparse.Namespace(robot="a1-wx200", json=False))


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="wbc", description="Whole-body control of quadrupeds that carry an arm.")
    sub = p.add_subparsers(dest="command", required=True)

    analyze = sub.add_parser("analyze", help="first-principles analyses").add_subparsers(dest="what", required=True)
    tail = analyze.add_parser("tail", help="the paper's CoM shift and body/arm acceleration ratio, from the model")
    tail.add_argument("--robot", default="a1-wx200", help=f"one of: {', '.join(ROBOTS)}")
    tail.add_argument("--json", action="store_true", help="print JSON")
    tail.set_defaults(func=_analyze_tail)

    bench = sub.add_parser("bench", help="speed figures").add_subparsers(dest="what", required=True)
    sim = bench.add_parser("sim", help="physics steps per second, single-threaded and batched")
    sim.add_argument("--robot", default="a1-wx200", help=f"one of: {', '.join(ROBOTS)}")
    sim.add_argument("--arm", default="actuated", help=f"one of: {', '.join(ARM_MODES)}")
    sim.add_argument("--batch", type=int, default=64, help="environments in the batched rollout")
    sim.add_argument("--threads", type=int, default=None, help="threads for the batched rollout (default: all)")
    sim.add_argument("--json", action="store_true", help="print JSON")
    sim.add_argument("--terrain", default="flat", help="flat or fractal")
    sim.set_defaults(func=_bench_sim)
    mpc = bench.add_parser("mpc", help="MPC solve times, whole-body tick, closed-loop real-time factor")
    mpc.add_argument("--robot", default="a1-wx200", help=f"one of: {', '.join(ROBOTS)}")
    mpc.add_argument("--controller", default="mpc")
    mpc.add_argument("--seconds", type=float, default=4.0)
    mpc.add_argument("--json", action="store_true")
    mpc.set_defaults(func=_bench_mpc)
    sweep = bench.add_parser("sweep", help="arena sweep throughput against raw physics; Ray overhead")
    sweep.add_argument("--scenario", default="scenarios/push.toml")
    sweep.add_argument("--controller", default="stand")
    sweep.add_argument("--trials", type=int, default=10, help="trials per band")
    sweep.add_argument("--workers", type=int, default=None)
    sweep.add_argument("--ray", action="store_true", help="also run on a local Ray and report its overhead")
    sweep.add_argument("--json", action="store_true")
    sweep.set_defaults(func=_bench_sweep)
    btrain = bench.add_parser("train", help="training env throughput: control steps per second, random actions")
    btrain.add_argument("--envs", type=int, default=1024, help="parallel environments")
    btrain.add_argument("--threads", type=int, default=2, help="rollout threads")
    btrain.add_argument("--arm", default="actuated", help=f"one of: {', '.join(ARM_MODES)}")
    btrain.add_argument("--terrain", default="scenario", help="scenario (the push scenario's ground) or flat")
    btrain.add_argument("--steps", type=int, default=50, help="policy steps per measurement")
    btrain.add_argument("--json", action="store_true")
    btrain.set_defaults(func=_bench_train)

    from wbc.learned.stages import BASELINES, TASKS

    tr = sub.add_parser("train", help="train a stage of the learned policy (PPO + BC, rsl-rl-lib; needs wbc[train])")
    tr.add_argument("--task", required=True, help=f"one of: {', '.join(TASKS)}")
    tr.add_argument("--stage", type=int, required=True, choices=(1, 2, 3), help="1: pi1, 2: pi2, 3: pi3")
    tr.add_argument("--baseline", default=None, help=f"stage-3 baseline, one of: {', '.join(BASELINES)}")
    tr.add_argument("--resume", action="store_true", help="continue from the newest checkpoint of the run")
    tr.add_argument("--iterations", type=int, default=None, help="PPO iterations of the whole run (default 1500)")
    tr.add_argument("--envs", type=int, default=None, help="parallel environments (default 1024)")
    tr.add_argument("--threads", type=int, default=None, help="physics threads (default 2)")
    tr.add_argument("--seed", type=int, default=None, help="seed (default 0)")
    tr.add_argument("--teacher", default=None, help="BC teacher policy file (default: the previous stage's export)")
    tr.add_argument("--run-root", default="runs/train", help="runs live in RUN_ROOT/<task>-stage<k>[-<baseline>]")
    tr.add_argument("--dry-run", action="store_true", help="print the resolved configuration and stop")
    tr.set_defaults(func=_train)

    from wbc.control import CONTROLLERS

    run = sub.add_parser("run", help="play a scenario with one controller")
    run.add_argument("controller", help=f"one of: {', '.join(CONTROLLERS)}")
    _add_arena_options(run)
    run.set_defaults(func=_run)
    compare = sub.add_parser("compare", help="play a scenario with several controllers on the same trials")
    compare.add_argument("controllers", nargs="+", help=f"two or more of: {', '.join(CONTROLLERS)}")
    _add_arena_options(compare)
    compare.set_defaults(func=_compare)

    demo = sub.add_parser("demo", help="the main job: a short A/B comparison on the push scenario; tail analysis")
    demo.add_argument("--scenario", default="scenarios/push.toml")
    demo.add_argument("--trials", type=int, default=4, help="trials per band and seed")
    demo.add_argument("--seeds", type=int, default=2)
    demo.add_argument("--out", default=None, help="results directory (default: runs/demo-<time>)")
    demo.add_argument("--quiet", action="store_true", help="no progress bar")
    demo.set_defaults(func=_demo)
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``wbc`` console script."""
    args = _parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except WbcError as exc:
        print(f"wbc: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
