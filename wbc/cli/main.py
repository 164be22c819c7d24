"""The ``wbc`` command line: ``run``, ``compare``, ``view``, ``analyze ...``, ``bench ...``, ``train``, ``demo``."""

from __future__ import annotations

import argparse
import json
import sys

from wbc.errors import WbcError
from wbc.robots.description import ARM_MODES
from wbc.robots.registry import ROBOTS, get_robot

__all__ = ["main"]


def _analyze_tail(args: argparse.Namespace) -> int:
    from wbc.tools.tail import analyze_tail

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


def _analyze_arm_momentum(args: argparse.Namespace) -> int:
    from dataclasses import asdict

    import numpy as np

    from wbc.tools.arm_momentum import arm_momentum_study

    rows = arm_momentum_study(args.scenario, args.controller, band=args.band, seeds=tuple(range(args.seeds)),
                              trials=args.trials)
    if args.json:
        print(json.dumps([asdict(r) for r in rows], indent=2))
        return 0
    print(f"arm momentum during push recovery: {args.controller}, {args.scenario} band {args.band}")
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
    return 0


def _bench_sim(args: argparse.Namespace) -> int:
    from wbc.tools.bench import bench_sim

    get_robot(args.robot, args.arm)  # validate names before any work
    result = bench_sim(args.robot, args.arm, batch=args.batch, nthread=args.threads, terrain=args.terrain,
                       reference=not args.no_reference)
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
    if "reference_steps_per_s" in result:
        print("  bare A1 URDF, same runs (the reference issue 2's targets were set against: 110k / 218k):")
        print(f"    single-threaded : {result['reference_steps_per_s']:>10,.0f} steps/s  -> this robot runs at "
              f"{100 * result['steps_ratio_to_reference']:.0f} % of it (the target asks 73 %: "
              f"{result['scaled_target_steps_per_s']:,.0f} steps/s on this machine)")
        print(f"    batched rollout : {result['reference_batched_steps_per_s']:>10,.0f} steps/s  -> "
              f"{100 * result['batched_ratio_to_reference']:.0f} % (the target asks 69 %: "
              f"{result['scaled_target_batched_steps_per_s']:,.0f} steps/s on this machine)")
    return 0


def _bench_train(args: argparse.Namespace) -> int:
    from wbc.learned.env.env_config import EnvConfig
    from wbc.tools.bench import TRAIN_TARGET, bench_train

    cfg = EnvConfig(arm_mode=args.arm, num_envs=args.envs, nthread=args.threads, terrain=args.terrain)
    result = bench_train(cfg, steps=args.steps, reference=not args.no_reference)
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
    if "reference_physics_limit_control_steps_per_s" in result:
        target, at = TRAIN_TARGET
        print(f"  reference      : {result['reference_physics_limit_control_steps_per_s']:>10,.0f} control steps/s "
              f"(bare A1, 64 envs, 2 ms steps at 50 Hz; the target's ~22k); env at "
              f"{100 * result['control_steps_ratio_to_reference']:.0f} % of it, the target (15k of 21.8k) asks "
              f"{100 * target / at:.0f} %: {result['scaled_target_control_steps_per_s']:,.0f} control steps/s here")
    return 0


def _train(args: argparse.Namespace) -> int:
    import dataclasses

    from wbc.learned.train.stages import stage_config

    env = {k: v for k, v in (("num_envs", args.envs), ("seed", args.seed), ("nthread", args.threads)) if v is not None}
    overrides = {k: v for k, v in (("max_iterations", args.iterations), ("seed", args.seed)) if v is not None}
    if args.rma_iterations is not None:
        from wbc.learned.train.adaptation_config import AdaptationConfig

        overrides["rma"] = AdaptationConfig(iterations=args.rma_iterations)
    cfg = stage_config(args.task, args.stage, args.baseline, run_root=args.run_root, teacher=args.teacher,
                       env_overrides=env, **overrides)
    if args.dry_run:
        print(json.dumps(dataclasses.asdict(cfg), indent=2, default=list))
        return 0
    from wbc.learned.train.train import train

    result = train(cfg, resume=args.resume)
    print(f"trained {args.task} stage {args.stage}{' ' + args.baseline if args.baseline else ''}: "
          f"{result['iterations']} iterations, {result['env_steps']:,} env steps, {result['wall_s'] / 60:.1f} min; "
          f"policy {result['policy']}")
    return 0


def _arena(args: argparse.Namespace, controllers: tuple[str, ...]) -> int:
    import time
    from pathlib import Path

    from wbc.arena.compare import ArenaConfig, run_arena
    from wbc.arena.report import format_table

    seeds = tuple(range(args.seeds)) if args.seeds is not None else (0,)
    out = Path(args.out) if args.out else Path("runs") / (
        f"{Path(args.scenario).stem}-{'-'.join(controllers)}-{time.strftime('%Y%m%d-%H%M%S')}")
    live = _live_observer(args) if getattr(args, "view", False) else None
    cfg = ArenaConfig(controllers=controllers, scenario=Path(args.scenario), bands=tuple(args.band or ()),
                      seeds=seeds, trials=args.trials, out_dir=out, executor=args.executor, workers=args.workers,
                      address=args.address, resume=args.resume, progress=not args.json and not args.quiet,
                      no_push=getattr(args, "no_push", False), debug_truth=getattr(args, "debug_truth", False),
                      save_episodes=getattr(args, "save_episodes", False),
                      observer=live[1] if live is not None else None)
    try:
        result = run_arena(cfg)
    finally:
        if live is not None:
            live[0].stop()
    if args.json:
        print(json.dumps(result.summary, indent=2))
        return 0
    print(format_table(result.summary))
    rate = result.physics_steps / result.wall_s if result.wall_s > 0 else float("nan")
    print(f"\n{result.played} trials played in {result.wall_s:.1f} s ({rate:,.0f} physics steps/s); "
          f"results in {result.out_dir}/ (trials.csv, summary.json, report.md)")
    return 0


def _live_observer(args: argparse.Namespace):
    """(server, observer) streaming every trial of a run to the browser (``wbc run --view``)."""
    from wbc.viz.live import LiveObserver, LiveViewer
    from wbc.viz.player import KeyboardControls, Player, PlayerConfig
    from wbc.viz.server import MeshcatServer, ServerConfig

    server = MeshcatServer(ServerConfig(host=args.host)).start()
    print(f"viewer: {server.web_url}  (listening on {args.host} only; trials play one by one in this process)",
          file=sys.stderr)
    player = Player(PlayerConfig(speed=args.speed), KeyboardControls().start())
    return server, LiveObserver(LiveViewer(server), player)


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
    p.add_argument("--no-push", action="store_true", help="play the trials without their pushes")
    p.add_argument("--debug-truth", action="store_true",
                   help="debug: controllers read the simulator's base state instead of estimating it (recorded)")
    p.add_argument("--save-episodes", action="store_true",
                   help="also store every trial's episode log under OUT/episodes/ (for `wbc view --episode`)")
    p.add_argument("--view", action="store_true",
                   help="watch the trials live in the browser (meshcat); they then play one by one in this process")
    p.add_argument("--host", default="127.0.0.1", help="with --view: address to listen on (default 127.0.0.1)")
    p.add_argument("--speed", type=float, default=1.0, help="with --view: 1 real time, 0.25 slow motion, 0 flat out")


def _view(args: argparse.Namespace) -> int:
    import dataclasses
    from pathlib import Path

    from wbc.errors import ConfigError
    from wbc.viz.errors import ViewerError
    from wbc.viz.player import PlayerConfig
    from wbc.viz.view import ViewConfig, replay_episode, view_trial

    record = Path(args.record) if args.record else None
    if record is not None and (record.suffix.lower() not in (".html", ".htm") or not record.parent.is_dir()):
        raise ViewerError(f"--record {record}: give an .html file in an existing directory")
    cfg = ViewConfig(
        live=record is None or args.live, host=args.host, record=record, record_fps=args.fps,
        player=PlayerConfig(speed=args.speed, pause_at=tuple(args.pause_at or ()), step_s=args.step,
                            start_paused=args.paused),
        open_browser=args.open, wait_for_browser=args.wait,
    )
    if args.episode is not None:
        from wbc.viz.replay import load_stored_episode

        stored = load_stored_episode(args.episode, args.trial, controller=args.controller or args.ctrl,
                                     band=args.band, seed=args.seed)
        result = replay_episode(stored, cfg)
        what = f"{stored.path}"
    else:
        from wbc.control.registry import get_controller
        from wbc.scenario.scenario import load_scenario

        if args.ctrl is None or args.scenario is None:
            raise ConfigError("wbc view needs CTRL --scenario FILE --trial I (play a trial), or --episode "
                              "RESULTS_DIR --trial I (replay a stored one)")
        get_controller(args.ctrl)
        scenario = load_scenario(args.scenario)
        trial = scenario.trial(args.band or scenario.bands[0], 0 if args.seed is None else args.seed, args.trial)
        if args.duration is not None:
            if not 0 < args.duration <= trial.duration_s:
                raise ConfigError(f"--duration must be in (0, {trial.duration_s}] s, got {args.duration}")
            trial = dataclasses.replace(trial, duration_s=args.duration)
        result = view_trial(trial, args.ctrl, cfg)
        what = f"{args.ctrl} on {trial.scenario} band {trial.band} seed {trial.seed} trial {trial.index}"
        row = result.row
        print(f"{what}: " + ("survived" if row["success"] else f"fell at {float(row['fall_time_s']):.2f} s"))
    if result.recording is not None:
        print(f"recorded {result.frames_recorded} frames of {what} to {result.recording}")
    return 0


def _bench_mpc(args: argparse.Namespace) -> int:
    from wbc.tools.bench import bench_mpc

    result = bench_mpc(args.robot, args.controller, seconds=args.seconds, single_thread=not args.threaded_blas,
                       reference=not args.no_reference)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"MPC speed: {result['controller']} on {result['robot']} walking at 0.3 m/s, N = {result['horizon']}")
    print(f"  machine: {result['machine']}")
    print(f"  MPC QP solve   : median {result['mpc_solve_ms_median']:.2f} ms, p99 {result['mpc_solve_ms_p99']:.2f} ms "
          f"(setup median {result['mpc_setup_ms_median']:.2f} ms)")
    print(f"  whole-body QP tick: median {result['wbc_tick_us_median']:.0f} us (PlaCo, every tick)")
    print(f"  control tick: median {result['control_tick_us_median']:.0f} us (estimator + footholds + QP + command, "
          "ticks without an MPC update)")
    print(f"  closed loop    : {result['realtime_factor']:.1f}x real time on one core")
    if "reference_placo_tick_us" in result:
        print(f"  references     : bare-A1 PlaCo tick {result['reference_placo_tick_us']:.0f} us (the targets' "
              f"~40 us), bare-A1 physics {result['reference_steps_per_s']:,.0f} steps/s (the targets' 110k)")
        print(f"  targets scaled to this machine: whole-body tick <= {result['scaled_target_wbc_tick_us']:.0f} "
              f"us, closed loop >= {result['scaled_target_realtime_factor']:.1f}x real time")
    return 0


def _bench_sweep(args: argparse.Namespace) -> int:
    from wbc.tools.bench import bench_sweep

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
    arm = analyze.add_parser("arm-momentum", help="the arm's angular momentum against the pushes' angular impulse")
    arm.add_argument("--scenario", default="scenarios/push.toml")
    arm.add_argument("--band", default="ood")
    arm.add_argument("--controller", default="mpc")
    arm.add_argument("--trials", type=int, default=5, help="trials per seed")
    arm.add_argument("--seeds", type=int, default=1)
    arm.add_argument("--json", action="store_true")
    arm.set_defaults(func=_analyze_arm_momentum)

    bench = sub.add_parser("bench", help="speed figures").add_subparsers(dest="what", required=True)
    sim = bench.add_parser("sim", help="physics steps per second, single-threaded and batched")
    sim.add_argument("--robot", default="a1-wx200", help=f"one of: {', '.join(ROBOTS)}")
    sim.add_argument("--arm", default="actuated", help=f"one of: {', '.join(ARM_MODES)}")
    sim.add_argument("--batch", type=int, default=64, help="environments in the batched rollout")
    sim.add_argument("--threads", type=int, default=None, help="threads for the batched rollout (default: all)")
    sim.add_argument("--json", action="store_true", help="print JSON")
    sim.add_argument("--terrain", default="flat", help="flat or fractal")
    sim.add_argument("--no-reference", action="store_true", help="skip the bare-A1 reference measured alongside")
    sim.set_defaults(func=_bench_sim)
    mpc = bench.add_parser("mpc", help="MPC solve times, whole-body tick, closed-loop real-time factor")
    mpc.add_argument("--robot", default="a1-wx200", help=f"one of: {', '.join(ROBOTS)}")
    mpc.add_argument("--controller", default="mpc")
    mpc.add_argument("--seconds", type=float, default=4.0)
    mpc.add_argument("--threaded-blas", action="store_true",
                     help="run in this process with the BLAS's default threads (default: a single-threaded worker)")
    mpc.add_argument("--json", action="store_true")
    mpc.add_argument("--no-reference", action="store_true", help="skip the reference measurements")
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
    btrain.add_argument("--no-reference", action="store_true", help="skip the bare-A1 reference measurement")
    btrain.add_argument("--json", action="store_true")
    btrain.set_defaults(func=_bench_train)

    from wbc.learned.train.stages import BASELINES, TASKS

    tr = sub.add_parser("train", help="train a stage of the learned policy (PPO + BC, rsl-rl-lib; needs wbc[train])")
    tr.add_argument("--task", required=True, help=f"one of: {', '.join(TASKS)}")
    tr.add_argument("--stage", type=int, required=True, choices=(1, 2, 3), help="1: pi1, 2: pi2, 3: pi3")
    tr.add_argument("--baseline", default=None, help=f"stage-3 baseline, one of: {', '.join(BASELINES)}")
    tr.add_argument("--resume", action="store_true", help="continue from the newest checkpoint of the run")
    tr.add_argument("--iterations", type=int, default=None, help="PPO iterations of the whole run (default 1500)")
    tr.add_argument("--envs", type=int, default=None, help="parallel environments (default 1024)")
    tr.add_argument("--threads", type=int, default=None, help="physics threads (default 2)")
    tr.add_argument("--seed", type=int, default=None, help="seed (default 0)")
    tr.add_argument("--rma-iterations", type=int, default=None,
                    help="RMA phase-2 rounds after PPO (default 200; 0 skips phase 2)")
    tr.add_argument("--teacher", default=None, help="BC teacher policy file (default: the previous stage's export)")
    tr.add_argument("--run-root", default="runs/train", help="runs live in RUN_ROOT/<task>-stage<k>[-<baseline>]")
    tr.add_argument("--dry-run", action="store_true", help="print the resolved configuration and stop")
    tr.set_defaults(func=_train)

    from wbc.control.registry import CONTROLLERS

    run = sub.add_parser("run", help="play a scenario with one controller")
    run.add_argument("controller", help=f"one of: {', '.join(CONTROLLERS)}, or policy:PATH (an exported policy file)")
    _add_arena_options(run)
    run.set_defaults(func=_run)
    compare = sub.add_parser("compare", help="play a scenario with several controllers on the same trials")
    compare.add_argument("controllers", nargs="+",
                         help=f"two or more of: {', '.join(CONTROLLERS)}, policy:PATH (an exported policy file)")
    _add_arena_options(compare)
    compare.set_defaults(func=_compare)

    view = sub.add_parser("view", help="watch a trial in the browser (meshcat), live or replayed; record it to HTML",
                          description="Play CTRL on trial I of a scenario and stream it to a meshcat page (robot, "
                          "arm, terrain, push arrow, contact forces, command, MPC plan), or replay a stored "
                          "episode (--episode). With --record only, nothing is served: the trial is written as one "
                          "self-contained HTML file. Keys while live (then Enter): p pause, s step, + / - speed, q.")
    view.add_argument("ctrl", nargs="?", default=None,
                      help=f"controller: one of {', '.join(CONTROLLERS)}, or policy:PATH")
    view.add_argument("--scenario", default=None, help="scenario file (e.g. scenarios/push.toml)")
    view.add_argument("--trial", type=int, required=True, help="trial index within (band, seed)")
    view.add_argument("--seed", type=int, default=None, help="seed (default 0, or the run's first)")
    view.add_argument("--band", default=None, help="band (default: the first)")
    view.add_argument("--duration", type=float, default=None, help="play only the first D seconds")
    view.add_argument("--episode", default=None, metavar="RESULTS_DIR",
                      help="replay a stored episode from a `wbc run --save-episodes` results directory")
    view.add_argument("--controller", default=None, help="with --episode: whose episode (default: the only one)")
    view.add_argument("--host", default="127.0.0.1",
                      help="address the viewer listens on (default 127.0.0.1: this machine only)")
    view.add_argument("--speed", type=float, default=1.0, help="1 real time, 0.25 slow motion, 0 flat out")
    view.add_argument("--pause-at", type=float, action="append", metavar="T", help="pause at trial time T (repeatable)")
    view.add_argument("--paused", action="store_true", help="start paused (then s to step, p to play)")
    view.add_argument("--step", type=float, default=0.02, help="trial time of one single step [s] (default 0.02)")
    view.add_argument("--record", default=None, metavar="FILE.html", help="write a self-contained HTML replay")
    view.add_argument("--fps", type=float, default=50.0, help="with --record: frames per second (default 50)")
    view.add_argument("--live", action="store_true", help="with --record: also stream live")
    view.add_argument("--open", action="store_true", help="open the page in the default browser")
    view.add_argument("--wait", action="store_true", help="start once a browser has opened the page")
    view.set_defaults(func=_view)

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
