"""The ``wbc`` argument parser: every command, its options and their defaults; nothing runs here.

One builder per command (``_add_run_parser``, ``_add_hw_check_parser`` ...) adds its parser and options;
`build_parser` calls them in the order of the help's list. Each command's parser sets ``handler`` to the command's
name (``"bench mpc"``); `wbc.cli.main` dispatches on it and `wbc.cli.printers` prints what the command returns.
Scenario paths are kept as given: `load_scenario` resolves them.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from wbc.arena.error_guard import DEFAULT_MAX_CONSECUTIVE_ERRORS
from wbc.arena.identity import MAX_SEED, MAX_TRIAL_TIME_LIMIT_S, MAX_TRIALS, MIN_TRIAL_TIME_LIMIT_S
from wbc.cli.robot_names import ROBOT_NAMES_HELP
from wbc.control.registry import CONTROLLERS
from wbc.hardware.emulators import BusFault, Fault
from wbc.hardware.emulators.faults import FAULT_VALUES
from wbc.hardware.hardware_robot import HARDWARE_ARM_MODES
from wbc.hardware.realtime import DEFAULT_RT_PRIORITY
from wbc.hardware.unitree import TRANSPORTS
from wbc.input_files import short
from wbc.learned.train.stages import BASELINES, RECIPE_VARIANTS, TASKS
from wbc.mpc.qp_solvers import QP_SOLVERS
from wbc.robots.description import ARM_MODES
from wbc.scenario.scenario import MAX_DURATION_S
from wbc.tools.bench.mpc import DEFAULT_ROUNDS, MAX_ROUNDS
from wbc.tools.paper import DEFAULT_SEEDS as PAPER_DEFAULT_SEEDS
from wbc.tools.paper import DEFAULT_TRIALS as PAPER_DEFAULT_TRIALS
from wbc.tools.paper import TABLES as PAPER_TABLES

__all__ = ["MAX_SEEDS", "MAX_THREADS", "MAX_WORKERS", "add_arena_options", "add_controller_file_options",
           "build_parser", "bounded_float", "bounded_int", "results_dir"]

MAX_WORKERS = 256
"""Most worker processes (``--workers``): each holds a simulator and a controller; more than any one machine runs."""

MAX_THREADS = 256
"""Most threads of a batched rollout (``--threads``)."""

MAX_SEEDS = 10_000
"""Most seeds (``--seeds``): seeds 0 .. S-1, each a full set of trials per band."""

MAX_HOURS_S = 4 * 3600.0
"""Longest a measurement or an emulator may be asked to run (``--seconds``) [s]: four hours."""

_TRANSPORT_HELP = (f"the link's datagram channel, one of: {', '.join(TRANSPORTS)} (default udp: our socket; sdk: "
                   "the vendor's Go1 SDK, installed with the hardware extra, carrying the same checked frames)")


def bounded_int(lo: int, hi: int) -> Callable[[str], int]:
    """An argparse ``type=``: a whole number in [lo, hi]; anything else is a usage error that states the range.

    Args:
        lo: smallest value accepted.
        hi: largest value accepted.

    Returns:
        The parser of one option value.
    """
    def whole(text: str) -> int:
        try:
            value = int(text)
        except ValueError:  # also an integer of more than 4300 digits
            raise argparse.ArgumentTypeError(f"expected a whole number in [{lo}, {hi}], got {short(text)}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be in [{lo}, {hi}], got {short(text)}")
        return value

    return whole


def bounded_float(lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False,
                  unit: str = "") -> Callable[[str], float]:
    """An argparse ``type=``: a finite number in [lo, hi] (an end excluded when open); the error states the range.

    Args:
        lo: lower end.
        hi: upper end.
        lo_open: exclude `lo`.
        hi_open: exclude `hi`.
        unit: the unit, for messages (``s``, ``Hz``).

    Returns:
        The parser of one option value.
    """
    span = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}{' ' + unit if unit else ''}"

    def number(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number in {span}, got {short(text)}") from None
        inside = (value > lo if lo_open else value >= lo) and (value < hi if hi_open else value <= hi)
        if not (math.isfinite(value) and inside):
            raise argparse.ArgumentTypeError(f"must be a finite number in {span}, got {short(text)}")
        return value

    return number


def layer_sizes(text: str) -> tuple[int, ...]:
    """An argparse ``type=``: hidden layer sizes as comma-separated whole numbers, each in [1, 4096] (``256,128,64``).

    Returns:
        The sizes, in order.
    """
    parts = text.split(",")
    try:
        sizes = tuple(int(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected layer sizes as whole numbers separated by commas (256,128,64), "
                                         f"got {short(text)}") from None
    if not sizes or not all(1 <= n <= 4096 for n in sizes):
        raise argparse.ArgumentTypeError(f"every layer size must be in [1, 4096], got {short(text)}")
    return sizes


def results_dir(text: str) -> str:
    """An argparse ``type=`` for ``--out``: a results directory, new or existing, never an existing file.

    Refused here, before any trial is played, rather than after the first trial's results cannot be written.
    """
    if not text:
        raise argparse.ArgumentTypeError("expected a directory, got an empty path")
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{short(text)} exists and is not a directory; give a new directory, or the "
                                         "results directory of a run to --resume")
    return text


class _AppendOnce(argparse.Action):
    """``action="append"`` that keeps each value once and warns about a repeat.

    A band named twice (``--band in --band in``) would otherwise play, and count, its trials twice: the repeat is
    dropped with a warning rather than refused, since what was meant is clear.
    """

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: str | Sequence[Any] | None, option_string: str | None = None) -> None:
        items = list(getattr(namespace, self.dest) or [])
        if values in items:
            print(f"wbc: warning: {option_string} {short(values)} given more than once; using it once",
                  file=sys.stderr)
        else:
            items.append(values)
        setattr(namespace, self.dest, items)


_TRIALS = bounded_int(1, MAX_TRIALS)
_TRIAL = bounded_int(0, MAX_TRIALS - 1)
_SEEDS = bounded_int(1, MAX_SEEDS)
_SEED = bounded_int(0, MAX_SEED)
_WORKERS = bounded_int(1, MAX_WORKERS)
_THREADS = bounded_int(1, MAX_THREADS)
_SPEED = bounded_float(0.0, 100.0)  # 0: as fast as possible; 100 times real time is already a blur
_EPISODE_S = bounded_float(0.0, MAX_DURATION_S, lo_open=True, unit="s")
_MEASURE_S = bounded_float(0.0, MAX_HOURS_S, lo_open=True, unit="s")
_ROUNDS = bounded_int(1, MAX_ROUNDS)
_LINK_RATE = bounded_float(200.0, 1000.0, unit="Hz")  # the Unitree link's (UnitreeRobotConfig.rate_hz)


def _add_resume_options(p: argparse.ArgumentParser) -> None:
    """``--resume`` and ``--drop-bad-rows``: finishing a run stored in --out (``wbc run``, ``compare``, ``paper``)."""
    p.add_argument("--resume", action="store_true", help="finish an interrupted run in --out")
    p.add_argument("--drop-bad-rows", action="store_true",
                   help="with --resume: drop the rows of trials.csv that are refused (edited, corrupted, repeated, of "
                        "another scenario file), one warning each, and play their trials again")


def add_arena_options(p: argparse.ArgumentParser) -> None:
    """The options ``run`` and ``compare`` share: which trials, where the results go, how they are played."""
    p.add_argument("--scenario", required=True, help="scenario file (e.g. scenarios/push.toml)")
    p.add_argument("--trials", type=_TRIALS, default=10,
                   help=f"trials per band and seed, 1..{MAX_TRIALS} (default 10)")
    p.add_argument("--seeds", type=_SEEDS, default=None,
                   help=f"number of seeds: seeds 0 .. S-1, S in 1..{MAX_SEEDS} (default 1)")
    p.add_argument("--band", action=_AppendOnce, help="band to play (repeatable, each once; default: all)")
    p.add_argument("--out", type=results_dir, default=None,
                   help="results directory (default: runs/<scenario>-<controllers>-<time>)")
    p.add_argument("--json", action="store_true", help="print summary.json instead of the table")
    p.add_argument("--executor", default="local", help="local (process pool, default) or ray")
    p.add_argument("--workers", type=_WORKERS, default=None,
                   help=f"worker processes, 1..{MAX_WORKERS}, or with --executor ray the CPUs of the Ray it starts "
                        "(default: all cores)")
    p.add_argument("--address", default=None,
                   help="with --executor ray: the cluster's address (default: start a Ray on this machine)")
    _add_resume_options(p)
    p.add_argument("--max-consecutive-errors", type=bounded_int(0, MAX_TRIALS), default=DEFAULT_MAX_CONSECUTIVE_ERRORS,
                   metavar="K",
                   help="stop a controller that fails (raises, or returns an invalid command) on K trials in a row; "
                        f"the others finish (default {DEFAULT_MAX_CONSECUTIVE_ERRORS}; 0: never stop one)")
    add_trial_time_limit_option(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--no-push", action="store_true", help="play the trials without their pushes")
    p.add_argument("--debug-truth", action="store_true",
                   help="debug: controllers read the simulator's base state instead of estimating it (recorded)")
    p.add_argument("--save-episodes", action="store_true",
                   help="also store every trial's episode log under OUT/episodes/ (for `wbc view --episode`)")
    p.add_argument("--view", action="store_true",
                   help="watch the trials live in the browser (meshcat); they then play one by one in this process")
    p.add_argument("--host", default=None, help="with --view: address to listen on (default 127.0.0.1)")
    p.add_argument("--speed", type=_SPEED, default=None,
                   help="with --view: 1 real time (default), 0.25 slow motion, 0 flat out (0..100)")
    add_controller_file_options(p, repeatable=True)


def add_trial_time_limit_option(p: argparse.ArgumentParser) -> None:
    """``--trial-time-limit S`` and ``--in-process``: where and how long a trial plays (run, compare, paper)."""
    p.add_argument("--in-process", action="store_true",
                   help="with --workers 1: play the trials in this process (for a debugger or a profiler), where a "
                        "controller that ends its process ends the run; by default even one worker is a process of "
                        "its own, so that such a controller costs only its trial")
    p.add_argument("--trial-time-limit", type=bounded_float(MIN_TRIAL_TIME_LIMIT_S, MAX_TRIAL_TIME_LIMIT_S),
                   default=None, metavar="S",
                   help="end a trial still playing after S seconds of wall time (a controller that hangs) and record "
                        "it as its controller's error; the run goes on (default: no limit; local executor only; trials "
                        "then play in worker processes, even with --workers 1)")


def add_controller_file_options(p: argparse.ArgumentParser, *, repeatable: bool, named: bool = False) -> None:
    """``--controller-config`` (a plug-in's table) and ``--io`` (an ONNX policy's I/O file).

    `named`: a one-controller command that takes ``NAME=FILE`` too, NAME its ``--controller``, as ``wbc compare``
    writes it.
    """
    which = (" (NAME=FILE names the controller when several could take it; repeatable)" if repeatable else
             " (NAME=, as wbc compare takes it, names the --controller)" if named else "")
    kw = ({"action": "append", "metavar": "[NAME=]FILE.toml"} if repeatable else
          {"metavar": "[NAME=]FILE.toml" if named else "FILE.toml"})
    p.add_argument("--controller-config", default=None, **kw,
                   help=f"a TOML file whose table a plug-in's factory is called with{which}")
    p.add_argument("--io", default=None, **kw,
                   help=f"the I/O file of an onnx:PATH policy (default: PATH with the suffix .toml){which}")


_Commands = argparse._SubParsersAction
"""The subparsers of `build_parser` or of a command group (``analyze``, ``bench``, ``hw``): each command's builder adds
its parser to one."""

_NAMES_HELP = (f"{', '.join(CONTROLLERS)}; policy:PATH (an exported policy file), onnx:PATH (an ONNX policy), "
               "package.module:factory (a plug-in; package.module:factory@LABEL names it again, for a second setting), "
               "or an installed plug-in's name (`wbc controllers` lists them)")


def add_realtime_options(p: argparse.ArgumentParser, *, who: str, cpu: str) -> None:
    """``--rt-priority``, ``--rt-cpu``, ``--no-realtime``: what `who` asks the OS for (`wbc.hardware.realtime`)."""
    p.add_argument("--rt-priority", type=bounded_int(1, 99), default=None, metavar="N",
                   help=f"real-time priority (SCHED_FIFO) of {who}, 1..99 (default {DEFAULT_RT_PRIORITY}); refused "
                   "without CAP_SYS_NICE or an rtprio limit, and then it runs with ordinary scheduling and says so")
    p.add_argument("--rt-cpu", type=bounded_int(0, 4095), default=None, metavar="CPU",
                   help=f"the CPU {who} runs on (default: the {cpu} CPU where there are several)")
    p.add_argument("--no-realtime", action="store_true",
                   help=f"run {who} with ordinary scheduling, on any CPU, memory not locked (then --rt-priority "
                   "and --rt-cpu are refused)")


def build_parser() -> argparse.ArgumentParser:
    """The ``wbc`` argument parser; every command sets ``handler``, the name `wbc.cli.main` dispatches on."""
    p = argparse.ArgumentParser(prog="wbc", description="Whole-body control of quadrupeds that carry an arm.")
    sub = p.add_subparsers(dest="command", required=True)
    # one builder per command, in the order of the help's list
    analyze = sub.add_parser("analyze", help="first-principles analyses").add_subparsers(dest="what", required=True)
    _add_analyze_tail_parser(analyze)
    _add_analyze_arm_momentum_parser(analyze)
    _add_analyze_posture_parser(analyze)
    bench = sub.add_parser("bench", help="speed figures").add_subparsers(dest="what", required=True)
    _add_bench_sim_parser(bench)
    _add_bench_mpc_parser(bench)
    _add_bench_sweep_parser(bench)
    _add_bench_train_parser(bench)
    _add_bench_hw_parser(bench)
    _add_bench_latency_parser(bench)
    _add_bench_act_parser(bench)
    _add_bench_arm_parser(bench)
    hw = sub.add_parser("hw", help="real robots: an emulator, a read-only check, a trial on the robot")
    hws = hw.add_subparsers(dest="what", required=True)
    _add_hw_emulate_parser(hws)
    _add_hw_check_parser(hws)
    _add_hw_run_parser(hws)
    _add_train_parser(sub)
    _add_run_parser(sub)
    _add_compare_parser(sub)
    _add_paper_parser(sub)
    _add_view_parser(sub)
    _add_demo_parser(sub)
    _add_controllers_parser(sub)
    _add_check_controller_parser(sub)
    _add_scenario_parser(sub)
    return p


def _add_scenario_parser(sub: _Commands) -> None:
    """``wbc scenario check``: a scenario file's identity, bands and publication, without playing a trial."""
    scen = sub.add_parser("scenario", help="scenario files: check one without playing it").add_subparsers(
        dest="what", required=True)
    chk = scen.add_parser("check", help="print a scenario's name, version, hash, robot, bands and trial count, and "
                          "whether its lock publishes it (with the lines that would); plays nothing",
                          description="Load and validate a scenario file and print what a result records of it (name, "
                          "version, content hash), its robot and duration, each band and what it sets, how --trials "
                          "and --seeds count its trials, and whether the lock beside it (or --lock) publishes it; "
                          "when it does not, the message gives the lines that would. Exit status 1 when unpublished.")
    chk.add_argument("file", help="the scenario file (TOML)")
    chk.add_argument("--lock", default=None, metavar="FILE", help="the publish lock (default: published.toml beside "
                     "the file)")
    chk.add_argument("--json", action="store_true", help="print JSON")
    chk.set_defaults(handler="scenario check")


def _add_analyze_tail_parser(analyze: _Commands) -> None:
    """``wbc analyze tail``: the tail analysis of the model."""
    tail = analyze.add_parser("tail", help="the paper's CoM shift and body/arm acceleration ratio, from the model")
    tail.add_argument("--robot", default="a1-wx200",
                      help=f"one of: {ROBOT_NAMES_HELP}; its arm is analysed either way (default a1-wx200)")
    tail.add_argument("--json", action="store_true", help="print JSON")
    tail.set_defaults(handler="analyze tail")


def _add_analyze_arm_momentum_parser(analyze: _Commands) -> None:
    """``wbc analyze arm-momentum``: the arm's momentum against the pushes'."""
    arm = analyze.add_parser("arm-momentum", help="the arm's angular momentum against the pushes' angular impulse")
    arm.add_argument("--scenario", default="scenarios/push.toml",
                     help="scenario file whose pushes are measured (default scenarios/push.toml)")
    arm.add_argument("--band", default="ood", help="the scenario's band to play (default ood)")
    arm.add_argument("--controller", default="mpc", help="the controller that plays the trials (default mpc)")
    arm.add_argument("--trials", type=_TRIALS, default=5, help=f"trials per seed, 1..{MAX_TRIALS} (default 5)")
    arm.add_argument("--seeds", type=_SEEDS, default=1, help=f"seeds 0 .. S-1, S in 1..{MAX_SEEDS} (default 1)")
    arm.add_argument("--json", action="store_true", help="print JSON (a list, one object per trial)")
    add_controller_file_options(arm, repeatable=False, named=True)
    arm.set_defaults(handler="analyze arm-momentum")


def _add_analyze_posture_parser(analyze: _Commands) -> None:
    """``wbc analyze posture``: the controllers' trunk height and speed."""
    posture = analyze.add_parser("posture", help="trunk height and speed of controllers standing and walking, flat "
                                 "ground, no pushes (is the comparison at the same posture?)")
    posture.add_argument("controllers", nargs="+", help=_NAMES_HELP)
    posture.add_argument("--robot", default="a1-wx200",
                         help=f"one of: {ROBOT_NAMES_HELP}; the controllers' arm modes say whether its arm is there "
                         "(default a1-wx200)")
    posture.add_argument("--walk", type=bounded_float(-3.0, 3.0, unit="m/s"), default=0.3,
                         help="forward speed of the walking command, -3..3 [m/s] (a scenario's vx range; default "
                         "0.3)")
    posture.add_argument("--duration", type=_EPISODE_S, default=6.0,
                         help=f"episode length, up to {MAX_DURATION_S:g} [s]; the means cover its second half "
                         "(default 6)")
    posture.add_argument("--json", action="store_true", help="print JSON")
    posture.set_defaults(handler="analyze posture")


def _add_bench_sim_parser(bench: _Commands) -> None:
    """``wbc bench sim``: physics steps per second."""
    sim = bench.add_parser("sim", help="physics steps per second, single-threaded and batched")
    sim.add_argument("--robot", default="a1-wx200",
                     help=f"one of: {ROBOT_NAMES_HELP}; --arm says whether its arm is there (default a1-wx200)")
    sim.add_argument("--arm", default="actuated", help=f"one of: {', '.join(ARM_MODES)} (default actuated)")
    sim.add_argument("--batch", type=bounded_int(1, 65_536), default=64,
                     help="environments in the batched rollout, 1..65536, as many as half the available memory holds "
                          "(each keeps every step's state; default 64)")
    sim.add_argument("--threads", type=_THREADS, default=None,
                     help=f"threads for the batched rollout, 1..{MAX_THREADS} (default: all)")
    sim.add_argument("--json", action="store_true", help="print JSON")
    sim.add_argument("--terrain", default="flat", help="flat or fractal (default flat)")
    sim.add_argument("--no-reference", action="store_true", help="skip the bare-A1 reference measured alongside")
    sim.set_defaults(handler="bench sim")


def _add_bench_mpc_parser(bench: _Commands) -> None:
    """``wbc bench mpc``: the MPC's solve times and closed-loop speed."""
    mpc = bench.add_parser("mpc", help="MPC solve times, whole-body tick, closed-loop real-time factor")
    mpc.add_argument("--robot", default="a1-wx200",
                     help=f"one of: {ROBOT_NAMES_HELP}; the controller's arm mode says whether its arm is there "
                     "(default a1-wx200)")
    mpc.add_argument("--controller", default="mpc",
                     help="the MPC controller timed: mpc, one of its variants or a plug-in's (default mpc)")
    mpc.add_argument("--seconds", type=_MEASURE_S, default=4.0,
                     help="closed-loop time measured [s] (default 4, at most 4 h)")
    mpc.add_argument("--rounds", type=_ROUNDS, default=DEFAULT_ROUNDS,
                     help=f"timed walks, each between two measurements of the references (1..{MAX_ROUNDS}; "
                          f"default {DEFAULT_ROUNDS}): the ratios are their medians, with their spread")
    mpc.add_argument("--threaded-blas", action="store_true",
                     help="run in this process with the BLAS's default threads (default: a single-threaded worker)")
    mpc.add_argument("--json", action="store_true", help="print JSON")
    mpc.add_argument("--no-reference", action="store_true", help="skip the reference measurements")
    mpc.add_argument("--qp-solver", default=None, choices=tuple(QP_SOLVERS),
                     help="the closed loop's QP backend (default: the controller's own, the --controller-config "
                          "file's [mpc] qp_solver or daqp; a file that sets another is refused; mpc-tail solves its "
                          "own QP with daqp only); the walk's QPs are then solved by every backend and compared")
    mpc.add_argument("--controller-config", default=None, metavar="[NAME=]FILE.toml",
                     help="a TOML file whose table a plug-in's factory is called with (e.g. wbc.mpc.config_table:make "
                          "with an MPC's settings); NAME=, as wbc compare takes it, names the --controller")
    mpc.set_defaults(handler="bench mpc")


def _add_bench_sweep_parser(bench: _Commands) -> None:
    """``wbc bench sweep``: an arena sweep's throughput."""
    sweep = bench.add_parser("sweep", help="arena sweep throughput against raw physics; Ray overhead")
    sweep.add_argument("--scenario", default="scenarios/push.toml",
                       help="scenario file of the sweep (default scenarios/push.toml)")
    sweep.add_argument("--controller", default="stand", help="the controller of every trial (default stand)")
    sweep.add_argument("--trials", type=_TRIALS, default=10, help=f"trials per band, 1..{MAX_TRIALS} (default 10)")
    sweep.add_argument("--workers", type=_WORKERS, default=None,
                       help=f"worker processes of the arena, and threads of the physics rollout measured beside it, "
                       f"1..{MAX_WORKERS} (default: all cores)")
    sweep.add_argument("--ray", action="store_true", help="also run on a local Ray and report its overhead")
    sweep.add_argument("--json", action="store_true", help="print JSON")
    sweep.set_defaults(handler="bench sweep")


def _add_bench_train_parser(bench: _Commands) -> None:
    """``wbc bench train``: the training env's throughput."""
    btrain = bench.add_parser("train", help="training env throughput: control steps per second, random actions")
    btrain.add_argument("--envs", type=bounded_int(1, 65_536), default=1024,
                        help="parallel environments, 1..65536 (default 1024)")
    btrain.add_argument("--threads", type=_THREADS, default=2, help=f"rollout threads, 1..{MAX_THREADS} (default 2)")
    btrain.add_argument("--arm", default="actuated", help=f"one of: {', '.join(ARM_MODES)} (default actuated)")
    btrain.add_argument("--terrain", default="scenario", choices=("scenario", "flat"),
                        help="scenario (the push scenario's ground) or flat (default scenario)")
    btrain.add_argument("--steps", type=bounded_int(1, 1_000_000), default=50,
                        help="policy steps per measurement, 1..1000000 (default 50)")
    btrain.add_argument("--no-reference", action="store_true", help="skip the bare-A1 reference measurement")
    btrain.add_argument("--json", action="store_true", help="print JSON")
    btrain.set_defaults(handler="bench train")


def _add_bench_hw_parser(bench: _Commands) -> None:
    """``wbc bench hw``: the Unitree link's timing over loopback."""
    bhw = bench.add_parser("hw", help="Unitree low-level link over loopback: send-period jitter, round trip, CPU",
                           description="Run a UnitreeRobot against a UnitreeEmulator (lockstep) in its own process "
                           "on 127.0.0.1 and time the link: the interval between sends, a command's round trip to "
                           "the state that answers it, the link thread's CPU time per period, rejected frames.")
    bhw.add_argument("--robot", default="go1",
                     help=f"one of: {ROBOT_NAMES_HELP}; either name measures its legs' link alone (bench arm "
                     "measures the arm's bus; default go1)")
    bhw.add_argument("--seconds", type=_MEASURE_S, default=3.0,
                     help="how long the link is measured [s] (default 3, at most 4 h)")
    bhw.add_argument("--rate", type=_LINK_RATE, default=500.0, help="link rate, 200..1000 [Hz] (default 500)")
    bhw.add_argument("--transport", default="udp", help=_TRANSPORT_HELP)
    bhw.add_argument("--stand", type=bounded_float(0.0, MAX_HOURS_S, unit="s"), default=None,
                     help="then time the safety layer's reactions (e-stop, silence, stall, hot motor -> damping on "
                     "the wire) and a stand of this many seconds through it, in real time [s] (default 10)")
    bhw.add_argument("--no-safety", action="store_true", help="the link's timing only (no safety reactions, no stand)")
    bhw.add_argument("--json", action="store_true", help="print JSON")
    add_realtime_options(bhw, who="the emulator's process (on the first CPU) and the link's side in the bench's own "
                         "(on the last, as the I/O process on a robot)", cpu="first")
    bhw.set_defaults(handler="bench hw")


def _add_bench_act_parser(bench: _Commands) -> None:
    """``wbc bench act``: each controller's act in CPU per call and per simulated second."""
    bact = bench.add_parser("act", help="controllers' act in CPU per call and per simulated second, same trial",
                            description="Play the same trial with each controller, taking turns, and time every act "
                            "call on the thread's CPU clock: CPU per call (a control tick at the controller's own "
                            "rate) and per simulated second, with both ratios against the first controller.")
    bact.add_argument("controllers", nargs="+", help="controller names; the first is the reference of the ratios")
    bact.add_argument("--scenario", default="scenarios/push.toml", help="scenario file (default scenarios/push.toml)")
    bact.add_argument("--band", default="in", help="the trial's band (default in)")
    bact.add_argument("--seed", type=bounded_int(0, 2**32 - 1), default=0, help="the trial's seed (default 0)")
    bact.add_argument("--trial", type=bounded_int(0, 1_000_000), default=0, help="the trial's index (default 0)")
    bact.add_argument("--repeats", type=bounded_int(1, 100), default=3,
                      help="rounds, each controller one trial a round; the least CPU per second is kept (default 3)")
    bact.add_argument("--json", action="store_true", help="print JSON")
    bact.set_defaults(handler="bench act")


def _add_bench_latency_parser(bench: _Commands) -> None:
    """``wbc bench latency``: the wire's loop latency and the controllers' margin."""
    blat = bench.add_parser("latency", help="the wire's loop latency, the sim delay that plays it, controllers' margin",
                            description="Measure the loop latency over the wire (the emulator's round trip, and a "
                            "torque-step probe through a UnitreeRobot against an emulator on 127.0.0.1), the "
                            "simulated actuation + sensing delay equivalent to it, and the largest actuation delay "
                            "at which each controller stands still and survives a push.")
    blat.add_argument("--controllers", nargs="+", default=["stand", "mpc"], help="controllers (default stand mpc)")
    blat.add_argument("--robot", default=None,
                      help=f"the wire's robot, one of: {ROBOT_NAMES_HELP}; either name measures its legs' wire "
                      "alone (default go1)")
    blat.add_argument("--scenario", default="scenarios/push.toml",
                      help="scenario of the margin trials, which play its robot (default scenarios/push.toml, the "
                      "a1-wx200's; scenarios/turn.toml for the go1-arm: its walking trials, no push)")
    blat.add_argument("--trials", type=bounded_int(1, 1000), default=2,
                      help="trials per margin test, 1..1000 (default 2): standing trials with pushes, or the first "
                      "trials of a scenario that has none")
    blat.add_argument("--no-wire", action="store_true", help="margins only (no emulator)")
    blat.add_argument("--json", action="store_true", help="print JSON")
    blat.set_defaults(handler="bench latency")


def _add_bench_arm_parser(bench: _Commands) -> None:
    """``wbc bench arm``: the arm's bus loop against the emulated robot."""
    barm = bench.add_parser("arm", help="the arm's Dynamixel bus loop against the emulated robot: rate, step "
                            "response, reactions (about 20 s more than its rates)",
                            description="Run a DynamixelArm (and the legs' UnitreeRobot holding a stand) against a "
                            "real-time RobotEmulator in its own process: the bus loop's achieved rate at each of "
                            "--rates, for --seconds each. Then, whatever --rates and --seconds say: the elbow's "
                            "closed-loop step response at 200 Hz for two gains, four steps each, beside the same step "
                            "in pure simulation (about 12 s); the reactions at 200 Hz (the write deadline, four bus "
                            "faults, the servos' watchdog; a few seconds); and the emulators' own timing (the shared "
                            "plant on its own thread for --seconds, pty round trips). The whole takes about 20 s "
                            "more than the rates' own time (each rate --seconds and 0.3 s): --seconds 1 --rates 100 "
                            "about 22 s.")
    barm.add_argument("--robot", default="a1-wx200",
                      help=f"one of: {ROBOT_NAMES_HELP}; either name measures its arm, the legs holding a stand "
                      "(default a1-wx200)")
    barm.add_argument("--seconds", type=_MEASURE_S, default=2.0,
                      help="how long each rate runs, and the shared plant's measurement [s] (default 2, at most 4 h)")
    barm.add_argument("--rates", default="100,200,400,1000",
                      help="bus rates to run, comma-separated, each 10..1000 Hz (default 100,200,400,1000); the step "
                      "responses and the reactions run at 200 Hz whatever it says")
    barm.add_argument("--latency", type=bounded_float(0.0, 255.0, lo_open=True, unit="ms"), default=1.0,
                      help="the adapter's latency timer, up to 255 [ms] (the FTDI chip's largest; default 1)")
    barm.add_argument("--json", action="store_true", help="print JSON")
    add_realtime_options(barm, who="the emulator's process (on the first CPU) and the bench's own, which holds the "
                         "bus as the I/O process would (on the last)", cpu="first")
    barm.set_defaults(handler="bench arm")


def _add_hw_emulate_parser(hws: _Commands) -> None:
    """``wbc hw emulate``: serve an emulated robot on 127.0.0.1."""
    emulate = hws.add_parser("emulate", help="serve an emulated A1 / Go1 (and its arm) on 127.0.0.1, backed by the "
                             "simulator",
                             description="Speak the robot's low-level UDP wire on 127.0.0.1 (never another "
                             "address), with the MuJoCo simulator behind it; with --arm actuated, also the arm's "
                             "Dynamixel bus on a pseudo-terminal, over the same physics. Print the UDP address (and "
                             "the pty), and the counts (commands decoded, rejects by reason, replies; the arm's "
                             "packets) when it stops (Ctrl-C or --seconds).")
    emulate.add_argument("--robot", default="go1",
                         help=f"one of: {ROBOT_NAMES_HELP}; the legs' name (a1, go1) serves the bare quadruped unless "
                         "--arm says otherwise, the arm's name (a1-wx200, go1-arm) needs --arm locked or actuated "
                         "(default go1)")
    emulate.add_argument("--arm", default=None,
                         help="none (the bare quadruped; the default with a1 and go1), locked (its arm on the trunk, "
                         "held) or actuated (the arm on its own bus: a pty speaking Dynamixel Protocol 2.0); a1-wx200 "
                         "and go1-arm need locked or actuated")
    emulate.add_argument("--port", type=bounded_int(0, 65_535), default=0,
                         help="UDP port on 127.0.0.1, 0..65535 (default 0: a free one)")
    emulate.add_argument("--fault", action="append", default=None, metavar="NAME[=VALUE]",
                         help="inject a fault from the start (repeatable): "
                         f"{', '.join(f.value for f in Fault)}; with --arm actuated also the arm's bus faults "
                         f"{', '.join('arm_' + f.value for f in BusFault)}; each at its default value, or at VALUE for "
                         + ", ".join(f"{f.value} ({unit})" for f, (unit, *_) in FAULT_VALUES.items())
                         + " (drop=0.3: each reply dropped with probability 0.3)")
    emulate.add_argument("--lockstep", action="store_true",
                         help="one physics step and one reply per command (default: real time, a reply per period)")
    emulate.add_argument("--seconds", type=_MEASURE_S, default=None,
                         help="stop after S seconds, at most 4 h (default: Ctrl-C)")
    emulate.add_argument("--drop", action="store_true",
                         help="start with the robot free: left alone with its motors off it folds to its joint stops "
                         "(default: held at its standing pose, as in a harness, until a command drives a motor)")
    add_realtime_options(emulate, who="the emulator (it stands in for the robot's own processors)", cpu="first")
    emulate.set_defaults(handler="hw emulate")


def _add_hw_check_parser(hws: _Commands) -> None:
    """``wbc hw check``: read a robot, sending only damping."""
    check = hws.add_parser("check", help="connect to a robot, damping only, and print its state (never moves it)",
                           description="Connect the robot (the legs' UnitreeRobot, and the arm's DynamixelArm with "
                           "--arm-port), read states for a while through the safety layer, sending only damping "
                           "(legs Kp 0, the arm's joints damped; no controller's command is sent; connecting the arm "
                           "switches its joint servos to current mode in EEPROM, torque off first, which after a close "
                           "is every connect, as the close parks them in a hold that needs no host), and print the "
                           "state: joints with their ranges (marked margin beyond one but within the layer's joint "
                           "margin, OUT beyond both), motor modes and temperatures, IMU roll and pitch, battery, "
                           "remote buttons, the layer's verdict (would a ramp start from here, or what it refuses), "
                           "link and bus statistics, rejected frames. An arm with a servo in fault at connect (a "
                           "latched hardware error, no valid answer to its ping) is not driven: the legs are read "
                           "alone and each servo once, nothing written, and the verdict says what to do (exit 1). "
                           "A target outside 127.0.0.0/8, or an --arm-port "
                           "that is not a pseudo-terminal, needs --allow-hardware and a typed confirmation (or --yes).")
    check.add_argument("--robot", default="go1",
                       help=f"one of: {ROBOT_NAMES_HELP}; either name reads the arm only with --arm-port (default "
                       "go1)")
    check.add_argument("--target", required=True, metavar="HOST:PORT",
                       help="the robot's (or an emulator's) IPv4 address and UDP port, e.g. 127.0.0.1:PORT")
    check.add_argument("--local", default=None, metavar="HOST:PORT",
                       help="address to bind (default 127.0.0.1:0 for a loopback target, else 0.0.0.0:0)")
    check.add_argument("--seconds", type=_MEASURE_S, default=1.0,
                       help="how long to read states [s] (default 1, at most 4 h)")
    check.add_argument("--transport", default="udp", help=_TRANSPORT_HELP)
    check.add_argument("--arm-port", default=None, metavar="DEVICE",
                       help="also read the arm: its serial device (the U2D2, e.g. /dev/ttyUSB0, or the emulator's pty)")
    check.add_argument("--allow-hardware", action="store_true",
                       help="allow a real robot: a target outside 127.0.0.0/8, an --arm-port that is not a pty")
    check.add_argument("--yes", action="store_true",
                       help="with --allow-hardware: do not ask for confirmation (needed when stdin is not a terminal)")
    check.set_defaults(handler="hw check")


def _add_hw_run_parser(hws: _Commands) -> None:
    """``wbc hw run``: play a scenario's trial on a robot."""
    hwrun = hws.add_parser("run", help="play a scenario's trial on a real robot (or an emulator), under SafeRobot",
                           description="Play trial I of a scenario's band and seed with a controller on a robot over "
                           "its wire, through the arena's runner, paced in real time, behind SafeRobot. The trial's "
                           "pushes, terrain and friction are the simulator's and are skipped (the report says so); "
                           "metrics come from the state estimator. Keys during the trial: e or space e-stop "
                           "(damping, latched: the trial ends), p marks a push given by hand. Results go to a "
                           "results directory of the arena's format. A target outside 127.0.0.0/8, or an --arm-port "
                           "that is not a pseudo-terminal, needs --allow-hardware and a typed confirmation (or --yes). "
                           "Exit status: 0 once the results are written; 1 when the controller failed in the trial, or "
                           "the robot stopped answering (its legs' link was lost: the last line says when, and that "
                           "the damping sent since may not have reached the robot) - the results are written either "
                           "way (a safety trip, an arm's bus fault among them, is the trial's outcome: 0); "
                           "2 for an error; 130 when interrupted (Ctrl-C, SIGTERM, a closed terminal).")
    hwrun.add_argument("ctrl", help=f"controller (its variant for --arm is played): one of {_NAMES_HELP}")
    hwrun.add_argument("--robot", default=None,
                       help=f"one of: {ROBOT_NAMES_HELP}; --arm says whether its arm is there, either name "
                       "(default: the scenario's robot)")
    hwrun.add_argument("--arm", default=None,
                       help=f"arm mode on the robot: {', '.join(HARDWARE_ARM_MODES)} (default: the controller's; "
                       "actuated needs --arm-port; locked with --arm-port holds the arm by its servos)")
    hwrun.add_argument("--arm-port", default=None, metavar="DEVICE",
                       help="the arm's serial device: the U2D2 (e.g. /dev/ttyUSB0) or `wbc hw emulate`'s pty")
    hwrun.add_argument("--scenario", required=True, help="scenario file (e.g. scenarios/push.toml)")
    hwrun.add_argument("--trial", type=_TRIAL, required=True,
                       help=f"trial index within (band, seed), 0..{MAX_TRIALS - 1}")
    hwrun.add_argument("--band", default=None, help="band (default: the scenario's first)")
    hwrun.add_argument("--seed", type=_SEED, default=0, help=f"seed, 0..{MAX_SEED} (default 0)")
    hwrun.add_argument("--seconds", type=_EPISODE_S, default=None,
                       help=f"play only the first S seconds of the trial (S up to {MAX_DURATION_S:g})")
    hwrun.add_argument("--target", default=None, metavar="HOST:PORT",
                       help="the legs' low-level address: the robot's, or an emulator's (127.0.0.1:PORT)")
    hwrun.add_argument("--sim", action="store_true",
                       help="instead of a robot, play the same protocol (stand-up, safety layer, estimator metrics, "
                       "no pushes) on the simulator, to set beside a run over the wire")
    hwrun.add_argument("--local", default=None, metavar="HOST:PORT",
                       help="address to bind (default 127.0.0.1:0 for a loopback target, else 0.0.0.0:0)")
    hwrun.add_argument("--allow-hardware", action="store_true",
                       help="allow a real robot, which the controller will move: a target outside 127.0.0.0/8, an "
                       "--arm-port that is not a pty")
    hwrun.add_argument("--yes", action="store_true",
                       help="with --allow-hardware: do not ask for confirmation (needed when stdin is not a terminal)")
    hwrun.add_argument("--rate", type=_LINK_RATE, default=None, help="link rate, 200..1000 [Hz] (default 500)")
    hwrun.add_argument("--transport", default=None, help=_TRANSPORT_HELP)
    hwrun.add_argument("--io-process", action=argparse.BooleanOptionalAction, default=None,
                       help="run the robot's devices (legs link, arm bus) in a child process with its own interpreter "
                       "lock, so that the controller cannot starve them, and that damps the legs when this process "
                       "dies (default; --no-io-process: in this process, for debugging: if it dies, the legs' motors "
                       "keep the last command they got, as the robot has no watchdog)")
    add_realtime_options(hwrun, who="the I/O process (the devices' threads; the controller's loop asks for 10 below "
                         "it, on any CPU, from the stand-up to the trial's end)", cpu="last")
    hwrun.add_argument("--settle", type=bounded_float(0.0, 60.0, unit="s"), default=1.0,
                       help="after a safety trip, hold the robot damped and read for S seconds, 0..60 (default 1)")
    hwrun.add_argument("--out", type=results_dir, default=None,
                       help="results directory (default: runs/hw-<scenario>-<ctrl>-<time>)")
    hwrun.add_argument("--view", action="store_true",
                       help="watch the robot live in the browser (meshcat), drawn from its own sensors")
    hwrun.add_argument("--host", default=None, help="with --view: address to listen on (default 127.0.0.1)")
    add_controller_file_options(hwrun, repeatable=False)
    hwrun.set_defaults(handler="hw run")


def _add_train_parser(sub: _Commands) -> None:
    """``wbc train``: train a stage of the learned policy."""
    tr = sub.add_parser("train", help="train a stage of the learned policy (PPO + BC, rsl-rl-lib; needs wbc[train])")
    tr.add_argument("--task", required=True, help=f"one of: {', '.join(TASKS)}")
    tr.add_argument("--stage", type=int, default=None, choices=(1, 2, 3),
                    help="1: pi1, 2: pi2, 3: pi3 (required unless --teacher names a controller, or with --fine-tune)")
    tr.add_argument("--baseline", default=None, help=f"stage-3 baseline, one of: {', '.join(BASELINES)}")
    tr.add_argument("--variant", default=None,
                    help=f"a one-change variant of the method's stage 3, one of: {', '.join(RECIPE_VARIANTS)}")
    tr.add_argument("--resume", action="store_true",
                    help="continue from the newest checkpoint of the run (without it, a run directory that already "
                         "holds a run is refused)")
    tr.add_argument("--iterations", type=bounded_int(1, 1_000_000), default=None,
                    help="PPO iterations of the whole run, 1..1000000 (default 1500; with --fine-tune 200)")
    tr.add_argument("--envs", type=bounded_int(1, 65_536), default=None,
                    help="parallel environments, 1..65536 (default 1024)")
    tr.add_argument("--threads", type=_THREADS, default=None, help=f"physics threads, 1..{MAX_THREADS} (default 2)")
    tr.add_argument("--seed", type=_SEED, default=None, help=f"seed, 0..{MAX_SEED} (default 0)")
    tr.add_argument("--rma-iterations", type=bounded_int(0, 1_000_000), default=None,
                    help="RMA phase-2 rounds after PPO (default 200; 0 skips phase 2)")
    tr.add_argument("--teacher", default=None,
                    help="stages 2 and 3 (and the baselines that start from a policy): the teacher's policy file "
                         "(default: the previous stage's export); or a controller of the "
                         "arena (e.g. mpc): distil it into a policy by DAgger (--rounds, --episodes)")
    tr.add_argument("--fine-tune", default=None, metavar="STUDENT",
                    help="fine-tune a student distilled with --teacher CONTROLLER (its policy file, or 'shipped' for "
                         "the task robot's mpc-distilled weights) by PPO + BC towards itself on stage 3's conditions "
                         "(--iterations, default 200); the run is RUN_ROOT/<task>-fine-tune")
    tr.add_argument("--expert-data", default=None, metavar="DATA.npz",
                    help="with --fine-tune: the BC term pulls towards the expert's actions in a DAgger run's "
                         "data.npz instead of towards the student (the run is RUN_ROOT/<task>-fine-tune-expert)")
    tr.add_argument("--rounds", type=bounded_int(1, 10_000), default=None,
                    help="with a controller as --teacher: DAgger rounds, the expert-driven first one included "
                         "(default 8)")
    tr.add_argument("--episodes", type=bounded_int(1, 1_000_000), default=None,
                    help="with a controller as --teacher: episodes per DAgger round (default 20)")
    tr.add_argument("--episode-s", type=_EPISODE_S, default=None,
                    help="with a controller as --teacher: play only the first seconds of each episode")
    tr.add_argument("--history", type=bounded_int(0, 200), default=None,
                    help="with a controller as --teacher: observations (policy ticks) the student's adaptation "
                         "module reads, 0 for a memoryless student (default 25)")
    tr.add_argument("--student-layers", type=layer_sizes, default=None,
                    help="with a controller as --teacher: the student actor's hidden layer sizes (default 256,128,64)")
    tr.add_argument("--memory-layers", type=layer_sizes, default=None,
                    help="with a controller as --teacher: the hidden layer sizes of the student's adaptation module, "
                         "which reads its --history (default 128)")
    tr.add_argument("--expert-noise", type=bounded_float(0.0, 10.0), default=None,
                    help="with a controller as --teacher: DART's action noise while the expert drives, standard "
                         "deviation in action units (default 0)")
    tr.add_argument("--average-labels", action="store_true", default=None,
                    help="with a controller as --teacher: label each sample with the expert's actions averaged over "
                         "its policy period")
    tr.add_argument("--expert-follows", action="store_true", default=None,
                    help="with mpc as --teacher: the expert's CoM and yaw targets follow the robot (it tracks the "
                         "commanded velocity, not a position the student cannot observe)")
    tr.add_argument("--takeover", type=bounded_float(0.0, 100.0, lo_open=True), default=None,
                    help="with a controller as --teacher: the expert takes a student's episode over once their "
                         "actions differ by more than this (rms, action units, smoothed over 0.2 s)")
    tr.add_argument("--expert-truth", action="store_true", default=None,
                    help="with a controller as --teacher: the expert reads the simulator's base state instead of "
                         "estimating it (the student never does)")
    tr.add_argument("--run-root", default="runs/train",
                    help="runs live in RUN_ROOT/<task>-stage<k>[-<baseline>][-<variant>], a DAgger run (a controller "
                         "as --teacher) in RUN_ROOT/<task>-dagger-<controller>, a fine-tune in "
                         "RUN_ROOT/<task>-fine-tune[-expert] (default runs/train)")
    tr.add_argument("--dry-run", action="store_true",
                    help="make every check the run makes before it trains (the run directory, the files it reads, "
                         "the checkpoint it resumes from), print the resolved configuration and stop; a previous "
                         "stage's policy that is not trained yet is noted, not refused, so that a chain of stages can "
                         "be checked before any trains (default: off)")
    tr.set_defaults(handler="train")


def _add_run_parser(sub: _Commands) -> None:
    """``wbc run``: play a scenario with one controller."""
    run = sub.add_parser("run", help="play a scenario with one controller")
    run.add_argument("controller", help=f"one of: {_NAMES_HELP}")
    add_arena_options(run)
    run.set_defaults(handler="run")


def _add_compare_parser(sub: _Commands) -> None:
    """``wbc compare``: play a scenario with several controllers on the same trials."""
    compare = sub.add_parser("compare", help="play a scenario with several controllers on the same trials")
    compare.add_argument("controllers", nargs="+", help=f"two or more of: {_NAMES_HELP}")
    add_arena_options(compare)
    compare.add_argument("--until-significant", action="store_true",
                         help="play round by round (a trial index and seed, every band, every controller) and stop "
                         "once an anytime-valid sequential test has settled every pair's success difference in every "
                         "band (family-wise error <= --alpha at any stop); --trials is then the most played")
    compare.add_argument("--alpha", type=bounded_float(0.0, 1.0, lo_open=True, hi_open=True), default=None,
                         help="with --until-significant: the family-wise significance level (default 0.05)")
    compare.set_defaults(handler="compare")


def _add_paper_parser(sub: _Commands) -> None:
    """``wbc paper``: play one of the paper's tables."""
    paper = sub.add_parser("paper", help="play one of the paper's results tables; print ours beside the paper's",
                           description="Play the protocol of the paper's Table I (pushes; arm actuated, locked, "
                           "absent), II (fast turns; the same) or III (the staged method and its baselines) for the "
                           "learned and the model-based family on the same trials, and print our rows beside the "
                           "paper's, the paired comparisons (exact or bootstrap intervals, exact McNemar / Wilcoxon "
                           "p-values, n80, verdicts), where each contender fails, and the run time. The paper played "
                           "5 seeds x 2000 trials: --seeds 5 --trials 400.")
    paper.add_argument("table", choices=tuple(PAPER_TABLES), help="which table")
    paper.add_argument("--trials", type=_TRIALS, default=PAPER_DEFAULT_TRIALS,
                       help=f"trials per band and seed (default {PAPER_DEFAULT_TRIALS})")
    paper.add_argument("--seeds", type=_SEEDS, default=PAPER_DEFAULT_SEEDS,
                       help=f"seeds 0 .. S-1 (default {PAPER_DEFAULT_SEEDS})")
    paper.add_argument("--scenario", default=None,
                       help="scenario file (default: the table's, scenarios/push.toml or scenarios/turn.toml); a "
                       "later version of it plays the same protocol")
    paper.add_argument("--out", type=results_dir, default=None,
                       help="results directory (default: runs/paper-<table>-<time>)")
    paper.add_argument("--workers", type=_WORKERS, default=None,
                       help=f"local worker processes, 1..{MAX_WORKERS} (default: all cores)")
    _add_resume_options(paper)
    add_trial_time_limit_option(paper)
    paper.add_argument("--contender", action="append", default=None, metavar="KEY=CONTROLLER",
                       help="play CONTROLLER in row KEY (repeatable): e.g. learned=policy:PATH for a retrained pi3, "
                       "ppo=policy:PATH for a Table III baseline trained anew")
    paper.add_argument("--crouched", action="store_true",
                       help="play the learned rows' crouched variants where weights for them ship (the same stages "
                       "trained without the posture term: learned-crouched ..., <baseline>-crouched weights); "
                       "mpc-distilled and rows given by --contender play as they are")
    paper.add_argument("--quiet", action="store_true", help="no progress output")
    paper.add_argument("--json", action="store_true", help="print paper.json instead of the table")
    paper.set_defaults(handler="paper")


def _add_view_parser(sub: _Commands) -> None:
    """``wbc view``: watch a trial in the browser, live or replayed."""
    view = sub.add_parser("view", help="watch a trial in the browser (meshcat), live or replayed; record it to HTML",
                          description="Play CTRL on trial I of a scenario and stream it to a meshcat page (robot, "
                          "arm, terrain, push arrow, contact forces, command, MPC plan), or replay a stored "
                          "episode (--episode). With --record only, nothing is served: the trial is written as one "
                          "self-contained HTML file. Keys while live (then Enter): p pause, s step, + / - speed, q.")
    view.add_argument("ctrl", nargs="*", default=[], metavar="CTRL",
                      help=f"controller: one of {_NAMES_HELP}; two (A B) for an A / B view of the same trial, B "
                      "drawn as a ghost (with --episode: two of the run's controllers)")
    view.add_argument("--scenario", default=None, help="scenario file (e.g. scenarios/push.toml)")
    view.add_argument("--trial", type=_TRIAL, required=True,
                      help=f"trial index within (band, seed), 0..{MAX_TRIALS - 1}")
    view.add_argument("--seed", type=_SEED, default=None, help="seed (default 0, or the run's first)")
    view.add_argument("--band", default=None, help="band (default: the first)")
    view.add_argument("--duration", type=_EPISODE_S, default=None,
                      help=f"play only the first D seconds (D up to {MAX_DURATION_S:g})")
    view.add_argument("--episode", default=None, metavar="RESULTS_DIR",
                      help="replay a stored episode from a `wbc run --save-episodes` results directory")
    view.add_argument("--controller", default=None, help="with --episode: whose episode (default: the only one)")
    view.add_argument("--host", default=None,
                      help="address the live viewer listens on (default 127.0.0.1: this machine only)")
    view.add_argument("--speed", type=_SPEED, default=None,
                      help="live: 1 real time (the default), 0.25 slow motion, 0 flat out (0..100)")
    view.add_argument("--pause-at", type=bounded_float(0.0, MAX_DURATION_S, unit="s"), action="append", metavar="T",
                      help="live: pause at trial time T (repeatable)")
    view.add_argument("--paused", action="store_true", help="live: start paused (then s to step, p to play)")
    view.add_argument("--step", type=bounded_float(0.0, 10.0, lo_open=True, unit="s"), default=None,
                      help="live: trial time of one single step, up to 10 [s] (default 0.02)")
    view.add_argument("--record", default=None, metavar="FILE.html", help="write a self-contained HTML replay")
    view.add_argument("--fps", type=bounded_float(0.0, 240.0, lo_open=True), default=50.0,
                      help="frames per second of the trial page's replay (recorded, or the live trial page), up "
                      "to 240 (default 50)")
    view.add_argument("--live", action="store_true", help="with --record: also stream live")
    view.add_argument("--save-episode", default=None, metavar="FILE.npz",
                      help="write the episode played, with the pushes and commands set from the live page")
    view.add_argument("--export-scenario", default=None, metavar="FILE.toml",
                      help="write a scenario (unpublished) whose trials replay this one as played, with the pushes "
                      "and commands set from the live page, for every controller")
    view.add_argument("--at", type=bounded_float(0.0, MAX_DURATION_S, unit="s"), default=None, metavar="T",
                      help="with --record: open the recorded page at trial time T (its URL ends #t=T)")
    view.add_argument("--open", action="store_true",
                      help="open the page in the default browser (the live one, or else the recorded one)")
    view.add_argument("--wait", action="store_true", help="live: start once a browser has opened the page")
    view.add_argument("--no-push", action="store_true",
                      help="play the trial without its pushes (as `wbc run --no-push` plays it)")
    view.add_argument("--debug-truth", action="store_true",
                      help="debug: controllers read the simulator's base state instead of estimating it (as `wbc run "
                      "--debug-truth`)")
    add_controller_file_options(view, repeatable=True)
    view.set_defaults(handler="view")


def _add_demo_parser(sub: _Commands) -> None:
    """``wbc demo``: mpc against learned on push trials."""
    demo = sub.add_parser("demo", help="the main job: mpc against learned on push trials, paired; tail analysis",
                          description="The A/B the arena is for: the model-based controller (mpc) and the learned "
                          "policy (learned) play the same push trials; the table, the paired differences with 95 % "
                          "intervals, the report directory with its plots, and how to watch a trial in the browser.")
    demo.add_argument("--scenario", default="scenarios/push.toml",
                      help="scenario file the two controllers meet on (default scenarios/push.toml)")
    demo.add_argument("--trials", type=_TRIALS, default=4,
                      help=f"trials per band and seed, 1..{MAX_TRIALS} (default 4)")
    demo.add_argument("--seeds", type=_SEEDS, default=2, help=f"seeds, 1..{MAX_SEEDS} (default 2)")
    demo.add_argument("--workers", type=_WORKERS, default=None,
                      help=f"local worker processes, 1..{MAX_WORKERS} (default: all cores)")
    demo.add_argument("--out", type=results_dir, default=None, help="results directory (default: runs/demo-<time>)")
    demo.add_argument("--quiet", action="store_true", help="no progress output")
    _add_resume_options(demo)
    demo.set_defaults(handler="demo")


def _add_controllers_parser(sub: _Commands) -> None:
    """``wbc controllers``: list the controllers."""
    ctrls = sub.add_parser("controllers", help="list the controllers: the registry's, the name forms, installed "
                           "plug-ins (entry points of the wbc.controllers group) with their summaries")
    ctrls.add_argument("--json", action="store_true", help="print JSON")
    ctrls.set_defaults(handler="controllers")


def _add_check_controller_parser(sub: _Commands) -> None:
    """``wbc check-controller``: check a controller against the contract."""
    chk = sub.add_parser("check-controller", help="check a controller against the controller contract",
                         description="Build the controller for every robot and arm mode it claims and check its "
                         "rate, its outputs (shape, finiteness, within the motors' limits on most ticks), reset "
                         "determinism, that it never reads simulator truth, and act()'s time against its period "
                         "(p50 / p99). With --scenario the closed loop plays that scenario's first trial (its "
                         "terrain, command and pushes) and must stay up; with --replay the recorded robot states are "
                         "fed to the controller and its observation (term by term) and actions compared with the "
                         "recorded ones. Exit status 1 if a check fails.")
    chk.add_argument("name", help=f"the controller: {_NAMES_HELP}")
    add_controller_file_options(chk, repeatable=False)
    chk.add_argument("--robot", action=_AppendOnce, default=None, help=f"check on this robot only (repeatable; one of: "
                     f"{ROBOT_NAMES_HELP}; default: every robot it claims)")
    chk.add_argument("--seconds", type=_EPISODE_S, default=None, help="closed-loop run per robot and arm mode [s], "
                     f"up to {MAX_DURATION_S:g} (default 0.5; with --scenario the trial's duration)")
    chk.add_argument("--scenario", default=None, metavar="FILE", help="play this scenario's first trial (first band, "
                     "seed 0) in the closed loop, on the scenario's robot, with its command and pushes; the "
                     "'scenario' check passes if the robot is still up at the end")
    chk.add_argument("--replay", default=None, metavar="FILE.npz", help="a replay file (observation / action pairs "
                     "and robot states recorded by the trainer: wbc train writes policy.replay.npz); the 'replay' "
                     "check compares the controller's observation, term by term, and actions with the recording")
    chk.add_argument("--strict-timing", action="store_true", help="also fail when act's p99 exceeds the period")
    chk.add_argument("--in-process", action="store_true",
                     help="run the checks in this process (for a debugger or a profiler), where a controller that "
                          "ends its process ends the command with its status; by default they run in a worker "
                          "process of their own, and such a controller fails the check")
    chk.add_argument("--time-limit", type=bounded_float(MIN_TRIAL_TIME_LIMIT_S, MAX_TRIAL_TIME_LIMIT_S),
                     default=None, metavar="S",
                     help="fail the check of a controller that has not finished after S seconds of wall time (one "
                          "that hangs), ending its worker process; the seconds count from the worker's start, its "
                          "imports and compiling included: give a first run minutes (default: no limit; not with "
                          "--in-process)")
    chk.add_argument("--json", action="store_true", help="print JSON")
    chk.set_defaults(handler="check-controller")
