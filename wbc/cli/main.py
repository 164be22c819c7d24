"""The ``wbc`` command: ``run``, ``compare``, ``view``, ``controllers``, ``analyze ...``, ``bench ...``, ``hw ...``.

Also ``check-controller``, ``train``, ``demo`` and ``paper``. `main` parses the command line (`wbc.cli.parser`),
calls the tool the command names and hands its result to a printer (`wbc.cli.printers`). A `WbcError` ends the
command with its message and exit status 2; anything else is a bug and keeps its traceback. A ``run`` or
``compare`` in which a controller failed on some trials (`wbc.arena.error_guard`) finishes, then exits with status 1
after one line per failing controller. Ctrl-C, SIGTERM and SIGHUP (the terminal closed) interrupt a command alike:
status 130, and one line that says what a run stored and how to finish it (or that a robot was closed into damping,
and what of its trial was written).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import select
import shlex
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import TimeoutError as FuturesTimeout
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager, redirect_stdout
from pathlib import Path
from typing import Any

from wbc.arena.compare import VIEWED_TIME_LIMIT, ArenaConfig, run_arena
from wbc.arena.controller_failure import printed_error
from wbc.arena.executors import shut_down_pool, spawn_pool
from wbc.arena.hw_trial import ConnectInterrupted, HardwareTrialConfig, ResultsInterrupted, run_hardware_trial
from wbc.arena.operator import OPERATOR_ACTIONS
from wbc.arena.results import derived_files_present
from wbc.cli import printers
from wbc.cli.parser import build_parser
from wbc.cli.robot_names import robot_name, wire_name
from wbc.cli.terminal_keys import TerminalKeys
from wbc.control.controller_contract import CheckConfig, ControllerCheck, check_controller
from wbc.control.errors import OnnxIoError, OnnxModelError, PluginAttributeError, PluginImportError
from wbc.control.onnx_policy import ONNX_PREFIX
from wbc.control.plugin import LABEL_MAX, plugin_target
from wbc.control.registry import (
    CONTROLLERS,
    ControllerSpec,
    get_controller,
    list_controllers,
    takes_controller_config,
)
from wbc.errors import (
    ConfigError,
    IoProcessStopped,
    ResultsDirError,
    RobotLinkError,
    TargetRefusedError,
    UnknownNameError,
    WbcError,
)
from wbc.hardware.emulators import BusFault, Fault
from wbc.hardware.emulators.faults import fault_value
from wbc.hardware.hardware_robot import HardwareRobot, HardwareRobotConfig, build_hardware_robot
from wbc.hardware.interpreter import realtime_switch_interval
from wbc.hardware.io_process import build_process_robot
from wbc.hardware.realtime import AUTO_CPU, CONTROLLER_PRIORITY_BELOW, DEFAULT_RT_PRIORITY, NO_REALTIME, RealtimeRequest
from wbc.hardware.safety import SafetyConfig
from wbc.hardware.serial_port_policy import is_emulated_port, why_not_emulated
from wbc.hardware.unitree import DESCRIPTIONS, TRANSPORTS, check_target, is_loopback
from wbc.hardware.unitree.sdk_transport import SDK_ROBOTS
from wbc.interrupts import signal_label
from wbc.learned.env.env_config import EnvConfig
from wbc.learned.policy.policy_file import PolicyFileError
from wbc.learned.policy.shipped import distilled_weights
from wbc.learned.train.adaptation_config import AdaptationConfig
from wbc.learned.train.stages import TASKS, fine_tune_config, stage_config
from wbc.robots.description import ARM_MODES
from wbc.robots.registry import get_robot
from wbc.scenario import load_scenario, resolve_scenario_path, warn_if_unpublished
from wbc.scenario.scenario_check import check_scenario
from wbc.scenario.trial import Trial
from wbc.tools.arm_momentum import arm_momentum_study
from wbc.tools.bench import (
    bench_act,
    bench_arm,
    bench_hw,
    bench_latency,
    bench_mpc,
    bench_sim,
    bench_sweep,
    bench_train,
)
from wbc.tools.demo import DEMO_CONTROLLERS, trial_to_watch
from wbc.tools.emulate import BUS_FAULTS, FAULTS, EmulateConfig, emulate
from wbc.tools.hardware_check import HardwareCheckConfig, check_hardware
from wbc.tools.paper import PaperRunConfig, default_out_dir, run_paper_table
from wbc.tools.posture import posture_study
from wbc.tools.tail import analyze_tail

__all__ = ["HANDLERS", "hw_check", "hw_run", "main"]

def _analyze_tail(args: argparse.Namespace) -> int:
    result = analyze_tail(get_robot(robot_name(args.robot), "actuated"))
    if args.json:
        printers.print_json(result.as_dict())
    else:
        printers.print_tail(result)
    return 0


def _scenario_played(path: str) -> None:
    """Load the scenario a command plays and warn, as the arena does, when it is not the published one.

    An edited copy of a published file (push.toml) must not be taken for it in silence: the warning says whether the
    lock beside it lists it, or lists another hash.
    """
    warn_if_unpublished(load_scenario(path))


def _analyze_arm_momentum(args: argparse.Namespace) -> int:
    _scenario_played(args.scenario)
    config = _the_controllers_file(args.controller_config, args.controller, "--controller-config")
    io = _the_controllers_file(args.io, args.controller, "--io")
    rows = arm_momentum_study(args.scenario, args.controller, band=args.band, seeds=tuple(range(args.seeds)),
                              trials=args.trials, config=config, io=io)
    if args.json:
        printers.print_json([dataclasses.asdict(r) for r in rows])
    else:
        printers.print_arm_momentum(rows, controller=args.controller, scenario=args.scenario, band=args.band,
                                    settings=config)
    return 0


def _analyze_posture(args: argparse.Namespace) -> int:
    rows = posture_study(args.controllers, robot=robot_name(args.robot), walk_vx=args.walk, duration_s=args.duration,
                         duration_option="--duration")
    if args.json:
        printers.print_json([dataclasses.asdict(r) for r in rows])
    else:
        printers.print_posture(rows, duration_s=args.duration)
    return 0


def _bench_sim(args: argparse.Namespace) -> int:
    robot = robot_name(args.robot)
    get_robot(robot, args.arm)  # validate names before any work
    result = bench_sim(robot, args.arm, batch=args.batch, nthread=args.threads, terrain=args.terrain,
                       reference=not args.no_reference)
    if args.json:
        printers.print_json(result.as_dict())
    else:
        printers.print_bench_sim(result)
    return 0


def _bench_mpc(args: argparse.Namespace) -> int:
    result = bench_mpc(robot_name(args.robot), args.controller, seconds=args.seconds,
                       single_thread=not args.threaded_blas, reference=not args.no_reference,
                       qp_solver=args.qp_solver, rounds=args.rounds,
                       config=_the_controllers_file(args.controller_config, args.controller, "--controller-config"))
    if args.json:
        printers.print_json(result.as_dict())
    else:
        printers.print_bench_mpc(result)
    return 0


def _bench_sweep(args: argparse.Namespace) -> int:
    result = bench_sweep(args.scenario, args.controller, trials=args.trials, workers=args.workers, ray=args.ray)
    if args.json:
        printers.print_json(result.as_dict())
    else:
        printers.print_bench_sweep(result)
    return 0


def _bench_train(args: argparse.Namespace) -> int:
    cfg = EnvConfig(arm_mode=args.arm, num_envs=args.envs, nthread=args.threads, terrain=args.terrain)
    result = bench_train(cfg, steps=args.steps, reference=not args.no_reference)
    if args.json:
        printers.print_json(result.as_dict())
    else:
        printers.print_bench_train(result)
    return 0


def _bench_hw(args: argparse.Namespace) -> int:
    realtime_switch_interval()  # the link and bus threads must not wait 5 ms for the interpreter
    if args.no_safety and args.stand is not None:
        raise ConfigError("--stand times a stand through the safety layer, which --no-safety leaves out; leave one "
                          "of them out")
    stand = 10.0 if args.stand is None else args.stand
    if not stand > 0:
        raise ConfigError(f"--stand must be > 0 s, got {stand}")
    _check_transport(args)
    result = bench_hw(wire_name(args.robot), seconds=args.seconds, rate_hz=args.rate, transport=args.transport,
                      stand_seconds=None if args.no_safety else stand,
                      realtime=realtime_request(args, place="last"),
                      emulator_realtime=realtime_request(args, place="first"))
    if args.json:
        printers.print_json(result.as_dict())
    else:
        printers.print_bench_hw(result)
    return 0


def _bench_latency(args: argparse.Namespace) -> int:
    realtime_switch_interval()  # the link and bus threads must not wait 5 ms for the interpreter
    if args.no_wire and args.robot is not None:
        raise ConfigError("--robot names the wire's robot, and --no-wire measures no wire (the margins play the "
                          "scenario's robot); leave one of them out")
    _scenario_played(args.scenario)
    result = bench_latency(tuple(args.controllers), wire_robot="go1" if args.robot is None else wire_name(args.robot),
                           scenario=args.scenario, trials=args.trials, wire=not args.no_wire)
    if args.json:
        printers.print_json(result.as_dict())
    else:
        printers.print_bench_latency(result)
    return 0


def _bench_act(args: argparse.Namespace) -> int:
    _scenario_played(args.scenario)
    result = bench_act(tuple(args.controllers), scenario=args.scenario, band=args.band, seed=args.seed,
                       trial=args.trial, repeats=args.repeats)
    if args.json:
        printers.print_json(result.as_dict())
    else:
        printers.print_bench_act(result)
    return 0


def _bench_arm(args: argparse.Namespace) -> int:
    realtime_switch_interval()  # the link and bus threads must not wait 5 ms for the interpreter
    try:
        rates = tuple(float(r) for r in args.rates.split(","))
    except ValueError:
        raise ConfigError(f"--rates {args.rates!r}: give comma-separated numbers in Hz, e.g. 100,200,400") from None
    result = bench_arm(robot_name(args.robot), rates=rates, seconds=args.seconds, latency_ms=args.latency,
                       realtime=realtime_request(args, place="first"),
                       host_realtime=realtime_request(args, place="last"))
    if args.json:
        printers.print_json(result.as_dict())
    else:
        printers.print_bench_arm(result)
    return 0


def _address(text: str, option: str) -> tuple[str, int]:
    """``HOST:PORT`` as (host, port); the policy (`check_target`) is the caller's."""
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise ConfigError(f"{option} {text!r}: give HOST:PORT with an IPv4 address, e.g. 127.0.0.1:9000")
    return host, int(port)


def _hw_emulate(args: argparse.Namespace) -> int:
    realtime_switch_interval()  # the link and bus threads must not wait 5 ms for the interpreter
    wire = wire_name(args.robot)
    with_arm = args.robot == robot_name(args.robot)  # a1-wx200, go1-arm: the registry's name says the arm is there
    if with_arm and args.arm in (None, "none"):
        raise ConfigError(f"--robot {args.robot} names the robot with its arm: add --arm locked (the arm held on the "
                          f"trunk) or --arm actuated (the arm on its own bus, a pty), or emulate the bare quadruped "
                          f"with --robot {wire}")
    args.arm = "none" if args.arm is None else args.arm
    if args.arm not in ARM_MODES:
        raise UnknownNameError("arm mode", args.arm, ARM_MODES)
    actuated = args.arm == "actuated"
    faults: list[Fault | BusFault] = []
    values: list[tuple[Fault, float]] = []
    for given in args.fault or ():
        name, _, value = given.partition("=")
        key = name.lower().replace("-", "_")
        if key in BUS_FAULTS and not actuated:
            raise ConfigError(f"--fault {name}: the arm's bus is emulated only with --arm actuated")
        if key not in FAULTS and key not in BUS_FAULTS:
            raise UnknownNameError("fault", name, tuple(FAULTS) + (tuple(BUS_FAULTS) if actuated else ()))
        fault = FAULTS[key] if key in FAULTS else BUS_FAULTS[key]
        if fault in faults:
            raise ConfigError(f"--fault {key} is given twice; give each fault once")
        faults.append(fault)
        if "=" in given:
            if isinstance(fault, BusFault):
                raise ConfigError(f"--fault {given}: the arm's bus faults take no value from the command line (each "
                                  "runs at its default)")
            values.append((fault, fault_value(fault, value)))
    if args.seconds is not None and not args.seconds > 0:
        raise ConfigError(f"--seconds must be > 0, got {args.seconds}")
    served = emulate(EmulateConfig(robot=wire, arm_mode=args.arm,
                                   mode="lockstep" if args.lockstep else "realtime", port=args.port,
                                   faults=tuple(faults), fault_values=tuple(values), seconds=args.seconds,
                                   held=not args.drop,
                                   realtime=realtime_request(args, place="first")),
                     serving=printers.print_emulator_serving)
    printers.print_emulator_served(served)
    if served.failure is not None:
        raise RobotLinkError(f"the emulator's thread failed: {served.failure!r}") from served.failure
    return 0


def _real_devices(host: str, port: int, arm_port: str | None) -> list[tuple[str, str]]:
    """The devices of a command that are real hardware: the legs' address outside 127.0.0.0/8, a real serial port."""
    real = [] if is_loopback(host) else [(f"{host}:{port}", "outside 127.0.0.0/8")]
    if arm_port is not None and not is_emulated_port(arm_port):
        real.append((arm_port, "the arm's serial device, not a pty an emulator serves"))
    return real


# Said in the confirmation itself: no device is opened before the person at the terminal confirms, so the arm's pose
# is read (and an arm found raised named, joint by joint) only by `DynamixelArm.connect`, after the confirmation.
ARM_RAISED_NOTE = ("An arm parked raised sags when connecting releases its joints (torque off, then the host's "
                   "damping only): support it, or lower it to its stowed pose, before you confirm.")


def _confirm_hardware(command: str, robot: str, devices: list[tuple[str, str]], what: str, *, yes: bool) -> None:
    """Show the real robot's devices and what will happen to it; have the person at the terminal type ``yes``.

    Args:
        command: the command asking (``hw check``), for the message.
        robot: the robot's name.
        devices: its real devices, each with why it is real (`_real_devices`).
        what: what the command will send it, and what to do first.
        yes: confirmed on the command line (``--yes``): do not ask.

    Raises:
        TargetRefusedError: not confirmed, or nobody at a terminal to confirm without ``--yes``.
    """
    where = " and ".join(device for device, _ in devices)
    why = "; ".join(reason for _, reason in devices)
    print(f"wbc {command}: {robot} at {where} is a REAL ROBOT ({why}). {what}", file=sys.stderr, flush=True)
    if yes:
        return
    if not sys.stdin.isatty():
        raise TargetRefusedError(f"{where}: a real robot, and stdin is not a terminal, so nobody can confirm; run it "
                                 "from a terminal, or add --yes to confirm on the command line")
    try:
        answer = input("type yes to connect: ")
    except EOFError:
        answer = ""
    if answer.strip() != "yes":
        raise TargetRefusedError(f"not confirmed (got {answer.strip()!r}, not 'yes'): nothing was sent to {where}")


def _hardware_address(text: str, option: str, purpose: str, allow_hardware: bool, *,
                      binds: bool = False) -> tuple[str, int]:
    """An address option (``HOST:PORT``) as (host, port), refused unless loopback or ``--allow-hardware``.

    The policy is checked here, before any socket exists (the viewer's included), so that the refusal names the
    command's own switch.

    Args:
        text: the option's value.
        option: ``--target`` or ``--local``, for the messages.
        purpose: what a real robot would be used for (``check a real robot``).
        allow_hardware: the command's ``--allow-hardware``.
        binds: an address to bind (``--local``): port 0 (any free port) is valid.

    Raises:
        ConfigError: not HOST:PORT.
        TargetRefusedError: not an IPv4 literal, a bad port, or a real network without ``--allow-hardware``.
    """
    host, port = _address(text, option)
    if binds and port > 65535:
        raise TargetRefusedError(f"{option} port {port} is out of range 0..65535 (0: any free port)")
    check_target(host, max(port, 1) if binds else port, allow_hardware=True, what=option)  # an IPv4 literal
    if not allow_hardware and not is_loopback(host):
        refusing = "bind a real network's interface" if binds else "send to a real network"
        raise TargetRefusedError(
            f"{option} {host}:{port} is outside 127.0.0.0/8: refusing to {refusing}. To {purpose}, add "
            "--allow-hardware (you will be asked to type yes; --yes confirms when stdin is not a terminal)")
    return host, port


def _hardware_target(args: argparse.Namespace, purpose: str) -> tuple[str, int]:
    """``--target`` as (host, port), through `_hardware_address`; ``--yes`` is refused without ``--allow-hardware``."""
    if args.yes and not args.allow_hardware:
        raise ConfigError("--yes confirms using real hardware, which --allow-hardware asks for: without it nothing "
                          "asks to be confirmed; add --allow-hardware, or leave --yes out")
    return _hardware_address(args.target, "--target", purpose, args.allow_hardware)


def _hardware_local(args: argparse.Namespace, purpose: str) -> tuple[str, int] | None:
    """``--local`` as (host, port) through `_hardware_address`, or None when not given (a bound interface is used)."""
    if args.local is None:
        return None
    return _hardware_address(args.local, "--local", purpose, args.allow_hardware, binds=True)


def unpowered_arm_warning(controller: str, arm_mode: str, arm_port: str | None, *, real: bool) -> str | None:
    """The warning of a trial on a real robot whose arm plays locked with no ``--arm-port``, or None.

    Nothing then drives the arm's servos: on the robot the arm must be fixed mechanically. An emulator's arm
    (`real` False) is held by its physics, so nothing is said.
    """
    if not real or arm_mode != "locked" or arm_port is not None:
        return None
    return (f"{controller} plays the arm locked and no --arm-port is given: nothing drives the arm's servos, so the "
            "arm must be fixed mechanically at its stowed pose (an unpowered arm falls and swings, which the "
            "controller does not model)")


def _check_transport(args: argparse.Namespace, *, scenario: str | None = None) -> None:
    """Check ``--transport`` against ``--robot``, then with ``sdk`` say that the vendor SDK listens on every interface.

    The link's config refuses the same (`UnitreeRobotConfig`), naming its own field; here the options are named.

    Args:
        args: the command's arguments (``transport``, ``robot``).
        scenario: the scenario file whose robot is played when ``--robot`` is left out (``hw run``); that robot is
            checked then, and the refusal names the file and ``--robot``.

    Raises:
        UnknownNameError: ``--transport`` names no transport.
        ConfigError: ``--transport sdk`` for a robot whose wire the vendor SDK does not speak (the A1's).
    """
    transport = getattr(args, "transport", None)
    if transport is not None and transport not in TRANSPORTS:
        raise UnknownNameError("Unitree transport", transport, TRANSPORTS, where="--transport")
    robot = getattr(args, "robot", None)
    named, otherwise = f"--robot {robot}", ""
    if robot is None and scenario is not None and transport == "sdk":
        robot = load_scenario(scenario).robot
        named = f"the {robot}, {scenario}'s robot, played as no --robot is given"
        otherwise = (f", or give --robot {' or '.join(DESCRIPTIONS[w] for w in SDK_ROBOTS)} to play it on the "
                     f"{' or '.join(SDK_ROBOTS)}")
    wire = wire_name(robot) if robot is not None else None
    if transport == "sdk" and wire is not None and wire not in SDK_ROBOTS:
        raise ConfigError(f"--transport sdk: the vendor SDK speaks only the {' and '.join(SDK_ROBOTS)}'s wire, not "
                          f"the {wire}'s ({named}); leave --transport out for it (udp, our own socket){otherwise}")
    if transport == "sdk":
        print("wbc: note: --transport sdk: the vendor SDK binds its port on every interface (it takes no local "
              "address); its socket is connected to the target, so only the target's datagrams reach it",
              file=sys.stderr)


def _hardware_arm_port(args: argparse.Namespace, purpose: str) -> str | None:
    """``--arm-port``, refused unless an emulator's (a pty) or ``--allow-hardware`` (before anything opens it).

    The device is not opened here: the decision reads its name and at most resolves and stats it
    (`wbc.hardware.serial_port_policy.is_pseudo_terminal`).

    Args:
        args: the command's arguments (``arm_port``, ``allow_hardware``).
        purpose: what a real arm would be used for, for the refusal (``check a real robot``).

    Raises:
        TargetRefusedError: a device that is not a pseudo-terminal without ``--allow-hardware``.
    """
    port = args.arm_port
    if port is not None and not args.allow_hardware and not is_emulated_port(port):
        why, real = why_not_emulated(port)
        raise TargetRefusedError(f"--arm-port {why}" + (f". To {purpose}, add --allow-hardware (you will be asked to "
                                                        "type yes; --yes confirms when stdin is not a terminal)"
                                                        if real else ""))
    return port


def _hw_check(args: argparse.Namespace) -> int:
    realtime_switch_interval()  # the link and bus threads must not wait 5 ms for the interpreter
    return hw_check(args)


def hw_check(args: argparse.Namespace, *,
             build: Callable[[HardwareRobotConfig], HardwareRobot] = build_hardware_robot,
             safety: SafetyConfig | None = None) -> int:
    """``wbc hw check``: read the robot through the safety layer for ``--seconds`` of its clock, sending only damping.

    The addresses and the arm's port are checked here, and a real robot confirmed, before anything connects; the
    reading is `wbc.tools.hardware_check.check_hardware`'s.

    Args:
        args: the parsed command line.
        build: builds the robot from its config (a test hands its devices a clock it moves and an emulator's
            in-process channel; the seconds are then the robot's clock's).
        safety: the safety layer's settings instead of the defaults (a test over a real wire on a busy machine hands
            a stale timeout that only a hung emulator misses).

    Returns:
        0 when the safety layer would start a ramp from the state read ("ready"); 1 when it would refuse (a trip:
        an e-stop held, a joint out of range, a motor fault ...), when the arm's backend refused a servo at connect
        (a hardware error latched in it, a servo that did not answer its ping: the legs and the servos that answer
        are read all the same, and the line says what to do), or saw no live state stream (nothing valid came
        within the link's connect timeout: the line says so, with what did come and what to check), so that a
        bring-up script can stop there. The state (when one came), the link's counters and the verdict are printed
        either way. A refusal of the options or of the target raises instead (status 2).
    """
    host, port = _hardware_target(args, "check a real robot")
    local = _hardware_local(args, "check a real robot") or (("127.0.0.1", 0) if is_loopback(host) else ("0.0.0.0", 0))
    arm_port = _hardware_arm_port(args, "check a real arm")
    _check_transport(args)
    if not args.seconds > 0:
        raise ConfigError(f"--seconds must be > 0, got {args.seconds}")
    robot = robot_name(args.robot)

    def confirm(hardware: HardwareRobot) -> None:
        real = _real_devices(host, port, arm_port)
        if not real:
            return
        if arm_port:
            _confirm_hardware("hw check", robot, real, "Only damping will be sent (Kp 0, on the arm too). The arm's "
                              "joint servos are switched to current mode (an EEPROM write, with their torque off) and "
                              "damped; its wrist and gripper are torqued and held where they are. " + ARM_RAISED_NOTE
                              + " Hang the robot in its harness first.", yes=args.yes)
        else:  # the legs alone: the arm, if the robot carries one, is sent nothing
            _confirm_hardware("hw check", wire_name(robot), real, "Only damping will be sent to its legs (Kp 0); "
                              "no arm is driven (no --arm-port). Hang the robot in its harness first.", yes=args.yes)

    check = check_hardware(HardwareCheckConfig(robot=robot, label=args.robot, target=(host, port), local=local,
                                               seconds=args.seconds, transport=args.transport, arm_port=arm_port,
                                               allow_hardware=args.allow_hardware,
                                               safety=SafetyConfig() if safety is None else safety),
                           build=build, confirm=confirm)
    printers.print_hw_check(check)
    return 0 if check.ready else 1


def realtime_request(args: argparse.Namespace, *, place: str) -> RealtimeRequest:
    """The `RealtimeRequest` of ``--rt-priority``, ``--rt-cpu`` and ``--no-realtime`` (`place`: the default CPU)."""
    if args.no_realtime:
        _refuse((("--rt-priority", args.rt_priority), ("--rt-cpu", args.rt_cpu)),
                "with --no-realtime: ordinary scheduling has no priority and no CPU of its own",
                otherwise=", or --no-realtime")
        return NO_REALTIME
    return RealtimeRequest(priority=_rt_priority(args), cpu=AUTO_CPU if args.rt_cpu is None else args.rt_cpu,
                           place=place)


def _refuse(options: Iterable[tuple[str, object]], why: str, *, join: str = " and ", otherwise: str = "") -> None:
    """Refuse the options given (their value not None) that would do nothing: ``NAMES WHY; leave it out``.

    Args:
        options: (option, value) pairs; a flag passes ``value or None``.
        why: what the message says after the options' names.
        join: between the names.
        otherwise: what else the user may do, after ``leave them out``.

    Raises:
        ConfigError: one of `options` was given.
    """
    given = [name for name, value in options if value is not None]
    if given:
        raise ConfigError(f"{join.join(given)} {why}; leave {'them' if len(given) > 1 else 'it'} out{otherwise}")


def _rt_priority(args: argparse.Namespace) -> int:
    """``--rt-priority``, or its default."""
    return DEFAULT_RT_PRIORITY if args.rt_priority is None else args.rt_priority


def _hw_run(args: argparse.Namespace) -> int:
    realtime_switch_interval()  # the link and bus threads must not wait 5 ms for the interpreter
    return hw_run(args)


def hw_run(args: argparse.Namespace, *, build: Callable[[HardwareRobotConfig], HardwareRobot] | None = None,
           safety: SafetyConfig | None = None) -> int:
    """``wbc hw run``: play a scenario's trial on a robot (`run_hardware_trial`) and print what it did.

    Args:
        args: the parsed command line.
        build: builds the robot from its config instead of the default (`run_hardware_trial`'s `build`: a test's
            clock and an emulator's in-process channel).
        safety: the safety layer's settings instead of the defaults (`HardwareTrialConfig.safety`; a test over a real
            wire on a busy machine hands a stale timeout that only a hung emulator misses).

    Returns:
        0 once the trial's results are written; 1 when its controller failed in it (the results are written too,
        the outcome ``controller_error``), or when the robot stopped answering and its link (the legs') was lost
        (the results are written too, the outcome ``safety_trip``; the last line says when, and that the damping
        sent since may not have reached the robot: check it and power it down by hand); a fault of the arm's bus is
        a trip like any other, printed as the arm's (0); 130 when interrupted (Ctrl-C, SIGTERM,
        SIGHUP: the robot is closed into damping first), SIGTERM to the command's group or to its I/O process
        included (`IoProcessStopped`, the robot closed by the I/O process). Interrupted during the trial, the
        safety layer damps the robot at once, the results hold the episode up to the interruption (the record's
        outcome ``operator_stop``, its ``error`` saying when), and the last line says so and where
        (`ResultsInterrupted.during`); after it, the results are written whole; before the robot was connected, the
        line says that nothing was sent to it (`ConnectInterrupted`); during the stand-up, that no results were
        written (nothing was played).
    """
    _view_options(args)
    if args.sim == (args.target is not None):
        raise ConfigError("wbc hw run: give the robot's address (--target HOST:PORT), or --sim to play the same "
                          "protocol on the simulator; not both")
    if args.sim:
        _refuse((("--local", args.local), ("--arm-port", args.arm_port), ("--rate", args.rate),
                 ("--transport", args.transport),
                 ("--io-process" if args.io_process else "--no-io-process", args.io_process),
                 ("--rt-priority", args.rt_priority), ("--rt-cpu", args.rt_cpu),
                 ("--no-realtime", args.no_realtime or None), ("--allow-hardware", args.allow_hardware or None),
                 ("--yes", args.yes or None)),
                "with --sim: the simulator plays the trial in this process, with no link, devices, ports or real-time "
                "scheduling to set", join=", ", otherwise=", or give --target")
    args.rate = 500.0 if args.rate is None else args.rate
    args.transport = "udp" if args.transport is None else args.transport
    args.io_process = True if args.io_process is None else args.io_process
    host, port = _hardware_target(args, "run a trial on a real robot") if not args.sim else (None, None)
    local = _hardware_local(args, "run a trial on a real robot")
    arm_port = _hardware_arm_port(args, "run a trial on a real arm")
    _check_transport(args, scenario=args.scenario)
    if not args.sim and not args.io_process:
        print("wbc: warning: --no-io-process: the robot's devices run in this process; if it dies, nothing damps the "
              "legs, whose motors keep the last command they got (the robot has no watchdog). For debugging only",
              file=sys.stderr)
    robot = robot_name(args.robot) if args.robot is not None else None
    out = Path(args.out) if args.out else Path("runs") / (
        f"hw-{Path(args.scenario).stem}-{args.ctrl.replace(':', '_').replace('/', '_')}-"
        f"{time.strftime('%Y%m%d-%H%M%S')}")
    cfg = HardwareTrialConfig(controller=args.ctrl, scenario=Path(args.scenario), trial=args.trial, band=args.band,
                              seed=args.seed, seconds=args.seconds, robot=robot, arm_mode=args.arm,
                              target=None if args.sim else (host, port), simulate=args.sim, local=local,
                              allow_hardware=args.allow_hardware, rate_hz=args.rate, transport=args.transport,
                              arm_port=arm_port, out_dir=out, settle_s=args.settle,
                              io_process=args.io_process, safety=safety,
                              controller_config=Path(args.controller_config) if args.controller_config else None,
                              io_file=Path(args.io) if args.io else None)

    if build is None:
        request = realtime_request(args, place="last")
        make = build_process_robot if args.io_process else build_hardware_robot
        if not args.sim and not args.no_realtime:
            # the controller's loop below the devices, on any CPU: it must write before their deadline, never
            # pre-empt them (`controller_realtime`)
            cfg = dataclasses.replace(cfg, controller_realtime=RealtimeRequest(
                priority=max(1, _rt_priority(args) - CONTROLLER_PRIORITY_BELOW), cpu=None, lock_memory=False))

        def build(config: HardwareRobotConfig) -> HardwareRobot:
            return make(dataclasses.replace(config, realtime=request))

    def confirm(hardware: HardwareRobot, spec: ControllerSpec) -> None:
        real_legs = host is not None and bool(_real_devices(host, port, None))
        warning = unpowered_arm_warning(spec.name, spec.arm_mode, arm_port, real=real_legs)
        if warning is not None:
            print(f"wbc: warning: {warning}", file=sys.stderr)
        real = _real_devices(host, port, arm_port) if host is not None else []
        if real:
            _confirm_hardware("hw run", hardware.description.name, real, f"The controller {spec.name} will MOVE it: "
                              "hang it in its harness first, keep the remote (L2+B) and the power switch within "
                              "reach." + (" " + ARM_RAISED_NOTE if arm_port else ""), yes=args.yes)

    live = keys = None
    try:
        try:  # the viewer's server and the terminal's keys come before the trial, which connects the robot
            live = _hw_live_observer(args) if args.view else None
            keys = TerminalKeys(announce="keys: " + ", ".join(f"{'space' if k == ' ' else k} {a}" for k, a in
                                                              OPERATOR_ACTIONS.items()) + " (no Enter needed)")
        except KeyboardInterrupt as stopped:
            raise ConnectInterrupted(opening=False) from stopped
        result = run_hardware_trial(cfg, keys=keys, observer=live[1] if live is not None else None,
                                    before_connect=confirm, build=build)
    except ResultsInterrupted as stopped:
        if stopped.complete:
            said = (f"the results up to the interruption are complete in {stopped.out_dir}" if stopped.during
                    else f"its results are complete in {stopped.out_dir}")
        else:
            said = (f"the writing of its results was stopped: {stopped.out_dir} holds what was written until then, "
                    "and a hardware trial is played once (no --resume)")
        when = stopped.during if stopped.during is not None else "after the trial"
        _say(f"wbc hw run: interrupted {when}; the robot was closed into damping; {said}")
        return 130
    except ConnectInterrupted as stopped:
        if stopped.opening:
            said = ("while the robot was being connected, before the controller or the safety layer sent it anything: "
                    "nothing was played")
        else:
            said = "before the robot was connected: nothing was sent to it"
        _say(f"wbc hw run: interrupted {said}; no results were written")
        return 130
    except (KeyboardInterrupt, IoProcessStopped):
        # during the stand-up, before anything was played (an interruption during the trial writes what was played:
        # `ResultsInterrupted`); a second one that came before the played episode's results began to be written; or
        # an I/O process stopped by a SIGTERM of its own after the trial, with no request to end.
        # SIGTERM to the command's whole group reaches its I/O process too, which closes the robot itself; it is
        # raised only once the I/O process has said that the robot is closed, and reads as the stop it is
        _say("wbc hw run: interrupted; the robot was closed into damping; no results were written")
        return 130
    finally:
        if keys is not None:
            keys.close()
        if live is not None:
            live[1].close()
            live[0].stop()
    printers.print_hw_run(result)
    failed = False
    if result.record.error:  # played and stored, but its controller broke in it
        print(f"wbc: {printed_error(result.record.error)}", file=sys.stderr)
        failed = True
    if result.link_lost is not None:  # last: what the operator must do now, by the robot
        _say(f"wbc hw run: {result.link_lost.describe()}")
        failed = True
    return 1 if failed else 0


def _hw_live_observer(args: argparse.Namespace):
    """(server, observer) drawing a hardware trial in the browser (``wbc hw run --view``).

    The robot paces the loop, which must never wait for the viewer: it draws on a thread of its own, its scene built
    before the robot is connected, and it reads no keys (the operator's keys are the trial's).
    """
    from wbc.viz.live import LiveObserver, LiveViewer
    from wbc.viz.server import MeshcatServer, ServerConfig

    server = MeshcatServer(ServerConfig(host=args.host)).start()
    print(f"viewer: {server.web_url}  (listening on {server.listening})", file=sys.stderr)
    return server, LiveObserver(LiveViewer(server), background=True)


def _train(args: argparse.Namespace) -> int:
    if args.fine_tune is not None:
        return _fine_tune(args)
    if args.expert_data is not None:
        raise ConfigError("--expert-data: only with --fine-tune STUDENT")
    if args.teacher is not None and args.teacher in CONTROLLERS:
        return _distil(args)
    dagger_only = [f"--{n.replace('_', '-')}" for n in ("rounds", "episodes", "episode_s", "history", "expert_noise",
                                                              "average_labels", "expert_truth", "expert_follows",
                                                              "takeover", "student_layers", "memory_layers")
                   if getattr(args, n) is not None]
    from wbc.learned.train.preflight import names_a_file

    if dagger_only:
        if args.teacher is not None and not names_a_file(args.teacher):  # a mistyped controller: said as such
            raise _train_not_a_teacher(args.teacher)
        raise ConfigError(f"{', '.join(dagger_only)}: only with a controller as --teacher (DAgger), e.g. "
                          "--teacher mpc")

    if args.teacher is not None and args.stage is None and not names_a_file(args.teacher):
        raise _train_not_a_teacher(args.teacher)
    if args.stage is None:
        raise ConfigError("wbc train: --stage 1|2|3 is required (or --teacher CONTROLLER to distil a controller, or "
                          "--fine-tune STUDENT to fine-tune a distilled one)")
    env = {k: v for k, v in (("num_envs", args.envs), ("seed", args.seed), ("nthread", args.threads)) if v is not None}
    overrides = {k: v for k, v in (("max_iterations", args.iterations), ("seed", args.seed)) if v is not None}
    if args.rma_iterations is not None:
        overrides["rma"] = AdaptationConfig(iterations=args.rma_iterations)
    cfg = stage_config(args.task, args.stage, args.baseline, run_root=args.run_root, teacher=args.teacher,
                       env_overrides=env, variant=args.variant, **overrides)
    if args.resume and _inherit_saved(args, cfg.run_dir, env, overrides, adapts=cfg.extrinsics_dim > 0):
        cfg = stage_config(args.task, args.stage, args.baseline, run_root=args.run_root, teacher=args.teacher,
                           env_overrides=env, variant=args.variant, **overrides)
    if args.rma_iterations is not None and cfg.extrinsics_dim == 0:
        what = f"stage {args.stage}" + (f" --baseline {args.baseline}" if args.baseline else "")
        raise ConfigError(f"--rma-iterations sets the adaptation phase (RMA) of a policy that observes extrinsics, "
                          f"and {what} observes none, so it has no such phase: leave --rma-iterations out")
    if args.teacher is not None:
        if args.teacher not in (cfg.teacher, cfg.init_from, cfg.frozen_legs):
            what = f"stage {args.stage}" + (f" --baseline {args.baseline}" if args.baseline else "")
            raise ConfigError(f"--teacher does not apply to {what}: it learns from no teacher policy and starts from "
                              "none (--teacher applies to stages 2 and 3 and the baselines one-stage-demo, "
                              "finetune-pi2, curriculum after stage 1 and decoupled)")
        if not names_a_file(args.teacher):
            raise _train_not_a_teacher(args.teacher)
    # the inputs --teacher set (a stage's teacher, the policy a baseline starts from, the frozen legs): a refusal of
    # one names the option, not the previous stage that is its default
    options = {field: "--teacher" for field in ("teacher", "init_from", "frozen_legs")
               if args.teacher is not None and getattr(cfg, field) == args.teacher}
    return _train_run(args, cfg, stage=args.stage, baseline=args.variant or args.baseline, options=options)


def _inherit_saved(args: argparse.Namespace, run_dir: str, env: dict[str, Any], overrides: dict[str, Any], *,
                   adapts: bool) -> bool:
    """Fill `env` and `overrides` with a resumed run's saved settings that its command line leaves out.

    A resumed run is the run it continues: its PPO iterations, RMA phase, environments, threads and seeds are the
    ones its ``config.json`` records unless an option is given (a changed one that may not change is then refused
    by `check_run_dir`, naming the field). ``args.resume_note`` says what it takes, printed once the run is checked.

    Args:
        args: the command line.
        run_dir: the run directory.
        env: `EnvConfig` overrides, filled in place.
        overrides: `TrainConfig` overrides, filled in place.
        adapts: whether the run has an adaptation phase (RMA) to take the settings of.

    Returns:
        Whether anything was taken (the config is then built again).
    """
    from wbc.learned.train.preflight import saved_train_config

    saved = saved_train_config(run_dir)
    if saved is None:  # nothing to take from; check_run_dir says what is wrong
        return False
    saved_env = saved.get("env") if isinstance(saved.get("env"), dict) else {}

    def whole(value: object) -> bool:
        return isinstance(value, int) and not isinstance(value, bool)

    taken: dict[str, object] = {}
    for option, given, key, value, into in (
            ("--iterations", args.iterations, "max_iterations", saved.get("max_iterations"), overrides),
            ("--seed", args.seed, "seed", saved.get("seed"), overrides),
            ("--envs", args.envs, "num_envs", saved_env.get("num_envs"), env),
            ("--threads", args.threads, "nthread", saved_env.get("nthread"), env),
            ("--seed", args.seed, "seed", saved_env.get("seed"), env)):
        if given is None and whole(value):
            into[key] = value
            taken.setdefault(option, value)
    rma = saved.get("rma")
    if adapts and args.rma_iterations is None and isinstance(rma, dict):
        try:
            overrides["rma"] = AdaptationConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in rma.items()})
        except (TypeError, ValueError, WbcError):
            pass  # a damaged entry: the run's default phase, as before
        else:
            rounds = _adapted_rounds(Path(run_dir))
            if rounds is not None and rounds != overrides["rma"].iterations:
                # a run resumed before config.json recorded a resume's settings: its export's module is the newest
                overrides["rma"] = dataclasses.replace(overrides["rma"], iterations=rounds)
                taken["--rma-iterations"] = f"{rounds} (policy.json adaptation.iterations)"
            else:
                taken["--rma-iterations"] = overrides["rma"].iterations
    if taken:
        given = ", ".join(f"{option} {value}" for option, value in taken.items())
        args.resume_note = f"--resume: {Path(run_dir) / 'config.json'} gave the options not given: {given}"
    return bool(taken)


def _export_state(run_dir: Path, checkpoint: Path) -> str:
    """Whether an interrupted run's export is playable and how to finish it (the end of its message), or ``""``.

    A policy that observes RMA's extrinsics plays only with its adaptation module, which the run's phase 2 fits after
    its last iteration: an export of a checkpoint has none (`wbc.learned.train.preflight.PPO_EXPORT`).
    """
    from wbc.learned.train.preflight import PPO_EXPORT, checkpoint_iteration, lacks_module

    try:
        meta = json.loads((run_dir / "policy.json").read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return ""
    if not isinstance(meta, dict) or meta.get("extrinsics") is None:
        return ""
    it = checkpoint_iteration(checkpoint)
    finish = (f"the same command with --resume and --iterations {it + 1} fits the module on {checkpoint.name} without "
              "training further (with --resume alone, once it has trained on to its --iterations)")
    if lacks_module(meta):
        return f"; its export, policy.json, has no adaptation module yet, so it is not playable: {finish}"
    training = meta.get("training")
    exported = training.get("iteration") if isinstance(training, dict) else None
    if isinstance(exported, int) and exported < it:
        return (f"; its export, policy.json, is playable and of iteration {exported} ({checkpoint.name}'s, without "
                f"the module, is {PPO_EXPORT}.json): {finish}")
    return ""


def _exported_rounds(run_dir: Path) -> int | None:
    """The rounds of the adaptation module in a run's export (``policy.json`` adaptation.iterations), or None."""
    try:
        rounds = json.loads((run_dir / "policy.json").read_text())["adaptation"]["iterations"]
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError):
        return None
    return rounds if isinstance(rounds, int) and not isinstance(rounds, bool) and rounds > 0 else None


def _adapted_rounds(run_dir: Path) -> int | None:
    """The rounds of the adaptation module in the export of a run begun before config.json recorded resumes, or None.

    Such a run's config.json kept the settings it began with, however a resume changed them: its export's module
    (``policy.json`` adaptation.iterations) is the newest phase 2. A later run's config.json holds its current
    settings (its ``segments``), which a resume takes as they are.
    """
    try:
        if "segments" in json.loads((run_dir / "config.json").read_text()):
            return None
    except (OSError, UnicodeDecodeError, ValueError, TypeError):
        return None
    return _exported_rounds(run_dir)


_DAGGER_OPTIONS = {"rounds": "--rounds", "episodes": "--episodes", "episode_s": "--episode-s", "seed": "--seed",
                   "expert_noise": "--expert-noise", "average_labels": "--average-labels",
                   "expert_truth": "--expert-truth", "expert_follows": "--expert-follows", "takeover": "--takeover"}
"""A DAgger run's `DaggerConfig` fields that options set, with the option."""

_FIT_OPTIONS = {"history": "--history", "hidden_dims": "--student-layers", "adaptation_dims": "--memory-layers"}
"""The student's `FitConfig` fields that options set, with the option."""


def _dest(option: str) -> str:
    """The parsed arguments' attribute of `option` (``--episode-s`` -> ``episode_s``)."""
    return option.removeprefix("--").replace("-", "_")


def _inherit_saved_dagger(args: argparse.Namespace, run_dir: Path, fields: dict[str, Any],
                          fit: dict[str, Any]) -> None:
    """Fill `fields` and `fit` with a resumed DAgger run's saved settings that its command line leaves out.

    As a stage's resume does (`_inherit_saved`): a resumed run is the run it continues, so an option left out takes
    its ``config.json``'s value, said in ``args.resume_note``. A saved setting no option sets (the student's fit
    beyond its sizes, DAgger's beta) is taken too. A file that cannot be read gives nothing: the run's own check
    then says what is wrong with it.
    """
    try:
        saved = json.loads((run_dir / "config.json").read_text(encoding="utf-8"))["dagger_config"]
    except (OSError, ValueError, KeyError, TypeError):
        return
    if not isinstance(saved, dict):
        return
    taken: dict[str, object] = {}
    for key, option in _DAGGER_OPTIONS.items():
        if key not in fields and key in saved and saved[key] is not None:
            fields[key] = saved[key]
            taken[option] = saved[key]
    if "beta" in saved:
        fields["beta"] = saved["beta"]
    saved_fit = saved.get("fit")
    if isinstance(saved_fit, dict):
        given_fit = set(fit)
        for key, value in saved_fit.items():
            if key not in given_fit:
                fit[key] = tuple(value) if isinstance(value, list) else value
        for key, option in _FIT_OPTIONS.items():
            if key not in given_fit and key in saved_fit:
                value = saved_fit[key]
                taken[option] = ",".join(str(v) for v in value) if isinstance(value, list) else value
    # a flag is said as given (or not at all, when it was off), as the command line would give it
    said = [option if value is True else f"{option} {value}" for option, value in taken.items() if value is not False]
    if said:
        args.resume_note = f"--resume: {run_dir / 'config.json'} gave the options not given: {', '.join(said)}"


def _print_resume_note(args: argparse.Namespace) -> None:
    """Say which options a resumed run took from its config.json (`_inherit_saved`), if any; once."""
    note = getattr(args, "resume_note", None)
    if note:
        print(f"wbc: note: {note}", file=sys.stderr)
        args.resume_note = None


def _train_not_a_teacher(name: str) -> ConfigError:
    """The error for a --teacher that names neither a controller nor a file."""
    return ConfigError(f"--teacher {name} is neither a controller nor a file; give a policy file (a stage's "
                       f"policy.npz) or a controller to distil: {', '.join(CONTROLLERS)}")


def _train_run(args: argparse.Namespace, cfg, *, stage: int, baseline: str | None, options: dict[str, str]) -> int:
    """Check a stage's or fine-tune's run (--dry-run: print its configuration), then train it.

    `options` maps each input file's `TrainConfig` field to the option that set it, named when it is refused.
    """
    from wbc.learned.train.preflight import check_checkpoint, check_run, check_run_dir, check_unlocked, unstarted_run

    check_unlocked(cfg.run_dir)  # another run on it: refused before anything is said of it (the run then locks it)
    if unstarted_run(cfg.run_dir):
        print(f"wbc: note: {cfg.run_dir} holds a run interrupted before its first checkpoint (config.json, no "
              "model_<it>.pt): it starts afresh from iteration 0", file=sys.stderr)
    point = check_run_dir(cfg, resume=args.resume)
    if point is not None:  # a checkpoint the run refuses: refused before its progress is reconciled to it
        check_checkpoint(point.checkpoint, cfg)
    if point is not None and point.note:
        print(f"wbc: note: --resume: {point.note}", file=sys.stderr)
    if args.dry_run:
        given = args.teacher is not None or args.fine_tune is not None or args.expert_data is not None

        def default_input_missing(exc: ConfigError) -> None:
            # a default input (the previous stage's export) may be trained after this dry run
            print(f"wbc: note: {exc}", file=sys.stderr)

        # every check the run makes before it trains (the checkpoint's too)
        check_run(cfg, resume=args.resume, options=options,
                  default_input_missing=None if given else default_input_missing)
        _print_resume_note(args)
        printers.print_json(dataclasses.asdict(cfg))
        return 0
    # torch and rsl-rl-lib (the train extra) load only when a run really trains
    from wbc.learned.train.train import train

    args.training = ("ppo", cfg.run_dir)  # what an interruption keeps (`_interrupted_training`)

    result = train(cfg, resume=args.resume, options=options, checked=lambda: _print_resume_note(args),
                   command=args.command_line)
    if result.get("trained", 1) == 0:
        kept = ("its export, whose adaptation module this phase 2 already fitted on it, is kept (rma.json)"
                if result.get("adaptation") == "kept" else "its newest checkpoint is exported as it is")
        print(f"{result['run_dir']} already holds {result['iterations']} iterations, no fewer than --iterations "
              f"{cfg.max_iterations}: nothing new trained; {kept} (pass a larger --iterations to train on)")
    printers.print_trained(result, task=args.task, stage=stage, baseline=baseline)
    if cfg.extrinsics_dim > 0 and cfg.rma.iterations == 0:
        print(f"wbc: note: --rma-iterations 0: {result['policy']} observes extrinsics (RMA's z) and has no adaptation "
              "module to estimate them, so it is not playable (the arena and check-controller refuse it, and no "
              "replay was recorded); the same command with --resume --rma-iterations K (K > 0, default 200) adds the "
              "module without training PPO further", file=sys.stderr)
    return 0


def _fine_tune(args: argparse.Namespace) -> int:
    """``wbc train --fine-tune STUDENT``: PPO + BC on a distilled student."""
    dagger_only = ("rounds", "episodes", "episode_s", "history", "expert_noise", "average_labels", "expert_truth",
                   "expert_follows", "takeover", "student_layers", "memory_layers")
    for name in ("stage", "baseline", "variant", "teacher", "rma_iterations", *dagger_only):
        if getattr(args, name) is not None:
            raise ConfigError(f"--{name.replace('_', '-')} does not apply to --fine-tune (the student is the actor, "
                              "trained on stage 3's conditions); its options are --expert-data, --iterations, --envs, "
                              "--threads, --seed, --run-root, --resume and --dry-run")
    if args.task not in TASKS:
        raise UnknownNameError("task", args.task, tuple(TASKS))
    student = args.fine_tune
    from wbc.learned.train.preflight import names_a_file

    if student == "shipped":
        student = str(distilled_weights(get_robot(TASKS[args.task].robot, "actuated")))
    elif not names_a_file(student):
        raise ConfigError(f"--fine-tune {student}: no such file; give a student's policy file (a DAgger run's "
                          "policy.npz) or 'shipped'")
    if args.expert_data is not None and not Path(args.expert_data).is_file():
        raise ConfigError(f"--expert-data {args.expert_data}: no such file; give a DAgger run's data.npz")
    env = {k: v for k, v in (("num_envs", args.envs), ("seed", args.seed), ("nthread", args.threads)) if v is not None}
    overrides = {k: v for k, v in (("max_iterations", args.iterations), ("seed", args.seed)) if v is not None}
    cfg = fine_tune_config(args.task, student, run_root=args.run_root, expert_data=args.expert_data,
                           env_overrides=env, **overrides)
    if args.resume and _inherit_saved(args, cfg.run_dir, env, overrides, adapts=False):
        cfg = fine_tune_config(args.task, student, run_root=args.run_root, expert_data=args.expert_data,
                               env_overrides=env, **overrides)
    # the student is the BC term's teacher too, unless the expert's samples are
    options = {"student": "--fine-tune", "teacher": "--fine-tune", "expert_data": "--expert-data"}
    return _train_run(args, cfg, stage=3, baseline="fine-tune", options=options)


def _distil(args: argparse.Namespace) -> int:
    """``wbc train --teacher CONTROLLER``: DAgger with that controller as the expert."""
    for flag, value in (("--stage", args.stage), ("--baseline", args.baseline), ("--variant", args.variant),
                        ("--rma-iterations", args.rma_iterations), ("--iterations", args.iterations),
                        ("--envs", args.envs), ("--threads", args.threads)):
        if value is not None:
            raise ConfigError(f"{flag} does not apply to DAgger (--teacher {args.teacher}); its options are --rounds, "
                              "--episodes, --episode-s, --history, --student-layers, --memory-layers, --expert-noise, "
                              "--average-labels, --expert-follows, --takeover, --expert-truth, --seed, --run-root and "
                              "--resume")
    # torch loads only when a run really trains
    from wbc.tools.dagger import DaggerConfig, check_dagger_run, run_dagger

    fields, fit = ({key: getattr(args, _dest(option)) for key, option in options.items()
                    if getattr(args, _dest(option)) is not None} for options in (_DAGGER_OPTIONS, _FIT_OPTIONS))
    run_dir = Path(args.run_root) / f"{args.task}-dagger-{args.teacher}"
    if args.resume:
        _inherit_saved_dagger(args, run_dir, fields, fit)
    if fit:
        from wbc.learned.train.distill import FitConfig

        fields["fit"] = FitConfig(**fit)
    cfg = DaggerConfig(task=args.task, expert=args.teacher, run_dir=str(run_dir), **fields)
    from wbc.learned.train.preflight import check_unlocked

    check_unlocked(cfg.run_dir)  # another run on it: refused, by the dry run too (the run itself then locks it)
    if args.dry_run:
        check_dagger_run(cfg, resume=args.resume)  # every check the run makes before its first round
        _print_resume_note(args)
        printers.print_json(dataclasses.asdict(cfg))
        return 0
    args.training = ("dagger", cfg.run_dir)  # what an interruption keeps (`_interrupted_training`)
    # the note is said once the run is checked, before its rounds (which may take hours)
    result = run_dagger(cfg, resume=args.resume, log=print, checked=lambda: _print_resume_note(args),
                        command=args.command_line)
    if result["trained"] == 0:
        done = result["rounds"]
        print(f"{result['run_dir']} already holds {done} DAgger round{'s' if done != 1 else ''}, no fewer than "
              f"--rounds {cfg.rounds}: nothing new trained; its policy is its last round's student, unchanged (pass a "
              "larger --rounds to train on)")
    print(f"distilled {args.teacher} into a policy by DAgger: {result['rounds']} rounds, {result['samples']:,} "
          f"samples, {result['wall_s'] / 60:.1f} min; policy {result['policy']}")
    return 0


def _interrupted_run(args: argparse.Namespace) -> str:
    """What an interrupted ``run``, ``compare``, ``paper`` or ``demo`` stored, and how to go on: the end of its message.

    The directory is the one the run wrote: ``--out``'s, or the default the command chose (``args.results_dir``), which
    the ``--resume`` it suggests then names, as a rerun would choose another.
    """
    out = getattr(args, "results_dir", None) or (Path(args.out) if getattr(args, "out", None) else None)
    if out is None:
        return ""  # interrupted before it chose one
    if not (Path(out) / "trials.csv").is_file():
        return f"; no trial was stored yet ({out} holds no trials.csv): the same command starts the run afresh"
    again = "--resume" if getattr(args, "out", None) else f"--resume --out {out}"
    stored = _stored_trials(Path(out))
    if stored == "all":
        written = derived_files_present(Path(out))
        which = ("its summary and report are not yet written" if not written else
                 f"of the files derived from them only {', '.join(written)} {'is' if len(written) == 1 else 'are'} "
                 "written (run.json holds no complete mark)")
        return f"; every trial is stored in {out}, {which}: the same command with {again} writes them"
    if stored == "none":
        return f"; no trial had finished ({out} holds the run's plan only): the same command with {again} plays it"
    return f"; the trials finished are stored in {out}: the same command with {again} plays the rest"


def _stored_trials(out: Path) -> str:
    """How much of its planned run `out`'s ``trials.csv`` holds in trusted rows: ``none``, ``all`` or ``some``.

    ``some`` where unsure (a file that cannot be read).
    """
    from wbc.arena.identity import RunIdentity
    from wbc.arena.trial_record import scan_csv

    try:
        stored = {(r.controller, r.band, r.seed, r.trial) for r in scan_csv(out / "trials.csv").records}
        if not stored:
            return "none"
        run = RunIdentity.load(out / "run.json")
    except (WbcError, OSError):
        return "some"
    planned = {(c, b, s, t) for c in run.controllers for b in run.bands for s in run.seeds for t in run.trials_played}
    return "all" if planned <= stored else "some"


def _interrupted_training(args: argparse.Namespace) -> str:
    """What an interrupted ``wbc train`` keeps in its run directory, and how to go on: the end of its message."""
    kind, run_dir = getattr(args, "training", (None, None))
    if kind == "ppo":
        from wbc.learned.train.preflight import latest_checkpoint

        checkpoint = latest_checkpoint(run_dir)
        if checkpoint is None:
            return f"; {run_dir} holds no checkpoint yet (model_<it>.pt): the same command starts the run afresh"
        rounds = _exported_rounds(Path(run_dir))
        # an interrupted adaptation phase writes nothing: the export keeps the module it had, which a user who
        # stopped a longer phase 2 would otherwise take for lost
        module = (f", and its export the adaptation module it had ({rounds} round{'s' if rounds > 1 else ''}, "
                  "policy.json)") if rounds else ""
        return (f"; {run_dir} keeps its newest checkpoint, {checkpoint.name}{module}: the same command with --resume "
                f"continues from it{_export_state(Path(run_dir), checkpoint)}")
    if kind == "dagger":
        try:
            rounds = json.loads((Path(run_dir) / "progress.json").read_text())["rounds"]
        except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError):
            rounds = None
        if not isinstance(rounds, list) or not rounds:
            return (f"; {run_dir} holds no finished DAgger round: the same command, without --resume, starts the run "
                    "afresh")
        return (f"; {run_dir} keeps {len(rounds)} finished DAgger round{'s' if len(rounds) > 1 else ''} (its data, "
                "student and progress): the same command with --resume continues after them")
    return ""


def _play_arena(cfg: ArenaConfig, *, as_json: bool) -> int:
    result = run_arena(cfg)
    if as_json:
        printers.print_json(result.summary.to_json())
    else:
        printers.print_arena(result)
        if len(set(cfg.controllers)) > 1:
            watch = trial_to_watch(result.records, list(cfg.controllers))
            shown = () if watch is None else (watch.controller, str(watch.other))
            # the file that played and every option that changed the trial: the command plays the trial measured
            printers.print_compare_watch(watch, scenario=str(resolve_scenario_path(cfg.scenario)),
                                         options=printers.arena_trial_options(cfg, shown))
    # a controller's errors cost its own trials only, but the command says so and fails: one line per controller
    for errors in result.controller_errors:
        print(f"wbc: {errors.line()}", file=sys.stderr)
    return 1 if result.controller_errors else 0


def _controller_files(values: list[str] | None, controllers: tuple[str, ...], option: str,
                      takes: Callable[[str], bool], kind: str) -> dict[str, Path]:
    """``--controller-config`` / ``--io`` values (``[NAME=]FILE``) assigned to the controllers that take them."""
    out: dict[str, Path] = {}
    eligible = [c for c in controllers if takes(c)]
    for value in values or ():
        name, sep, file = value.partition("=")
        if sep and name not in controllers and not Path(value).exists():
            # NAME=FILE whose NAME is no controller of this run (a path holding '=' exists as it is)
            raise ConfigError(f"{option} {value}: {name} is not a controller of this run; NAME= names one of: "
                              f"{', '.join(controllers)}")
        if not sep or name not in controllers:  # no NAME= (a path may hold '=' too): the only one that takes it
            if len(eligible) != 1:
                raise ConfigError(f"{option} {value}: " + (
                    f"no controller here is {kind}" if not eligible else
                    f"several controllers are {kind} ({', '.join(eligible)}); write NAME=FILE"))
            name, file = eligible[0], value
        if not takes(name):
            raise ConfigError(f"{option} {value}: {name} is not {kind}; those here: {', '.join(eligible) or 'none'}")
        if name in out:
            raise ConfigError(f"{option}: {name} is given two files ({out[name]}, {file}); give one")
        out[name] = Path(file)
    return out


def _the_controllers_file(value: str | None, controller: str, option: str) -> str | None:
    """A one-controller command's ``--controller-config`` / ``--io`` value (``[NAME=]FILE``): the file.

    ``NAME=FILE`` is taken when NAME is the command's controller, as ``wbc compare`` writes it; a path that exists as
    given is a file, '=' or not.

    Raises:
        ConfigError: ``NAME=FILE`` whose NAME is not `controller` (and no such path exists).
    """
    if value is None:
        return None
    name, sep, file = value.partition("=")
    if not sep or Path(value).exists():
        return value
    if name != controller:
        raise ConfigError(f"{option} {value}: {name} is not the controller here ({controller}); write {option} "
                          f"{controller}={file}, or {option} {file}")
    return file


def _check_resumable(args: argparse.Namespace) -> None:
    """``--resume`` needs the results directory of a run: a misspelt ``--out`` would start a whole new study.

    Raises:
        ResultsDirError: ``--resume`` without ``--out``, or with an ``--out`` that does not exist.
    """
    if not args.resume:
        return
    if not args.out:
        raise ResultsDirError("--resume finishes the run in --out: give its results directory")
    if not Path(args.out).exists():
        raise ResultsDirError(f"--resume --out {args.out}: no such results directory, so nothing to finish; check the "
                              "path, or start the run without --resume")


_VIEW_OPTIONS = {"host": "127.0.0.1", "speed": 1.0}
"""The options that say how ``--view`` shows a run, and their values with ``--view`` when not given."""


def _view_options(args: argparse.Namespace) -> None:
    """Fill in ``--host`` / ``--speed``'s defaults, or refuse them without ``--view``, where they would do nothing.

    Raises:
        ConfigError: either is given without ``--view``, or ``--host`` is no IP address or host name.
    """
    names = [name for name in _VIEW_OPTIONS if hasattr(args, name)]
    given = [f"--{name}" for name in names if getattr(args, name) is not None]
    if given and not args.view:
        raise ConfigError(f"{' and '.join(given)} {'set' if len(given) > 1 else 'sets'} how --view shows the run, "
                          f"and nothing is viewed: add --view, or leave {'them' if len(given) > 1 else 'it'} out")
    for name in names:
        if getattr(args, name) is None:
            setattr(args, name, _VIEW_OPTIONS[name])
    if args.view and "host" in names:
        _check_host(args.host)


def _arena(args: argparse.Namespace, controllers: tuple[str, ...], *, until_significant: bool = False,
           alpha: float = 0.05) -> int:
    seeds = tuple(range(args.seeds)) if args.seeds is not None else (0,)
    _view_options(args)
    _check_in_process(args)
    if args.view and args.workers not in (None, 1):
        raise ConfigError(f"--workers {args.workers} with --view: a viewed run plays its trials one by one in this "
                          "process, where the viewer draws them; leave --workers out (or 1)")
    if args.view and args.trial_time_limit is not None:
        raise ConfigError(VIEWED_TIME_LIMIT)  # before the viewer's server starts
    _check_resumable(args)
    out = Path(args.out) if args.out else Path("runs") / (
        f"{Path(args.scenario).stem}-{'-'.join(controllers)}-{time.strftime('%Y%m%d-%H%M%S')}")
    args.results_dir = out  # what an interruption names (`main`)
    live = _live_observer(args) if args.view else None
    cfg = ArenaConfig(controllers=controllers, scenario=Path(args.scenario), bands=tuple(args.band or ()),
                      seeds=seeds, trials=args.trials, out_dir=out, executor=args.executor, workers=args.workers,
                      address=args.address, resume=args.resume, drop_bad_rows=args.drop_bad_rows,
                      progress=not args.json and not args.quiet,
                      no_push=args.no_push, debug_truth=args.debug_truth, save_episodes=args.save_episodes,
                      observer=live[1] if live is not None else None,
                      controller_configs=_controller_files(args.controller_config, controllers, "--controller-config",
                                                           takes_controller_config, "a plug-in"),
                      io_files=_controller_files(args.io, controllers, "--io", _is_onnx, "an onnx:PATH policy"),
                      until_significant=until_significant, alpha=alpha,
                      max_consecutive_errors=args.max_consecutive_errors,
                      trial_time_limit_s=args.trial_time_limit, isolated=not args.in_process,
                      command=args.command, command_line=_command_line())
    try:
        return _play_arena(cfg, as_json=args.json)
    finally:
        if live is not None:
            live[0].stop()


def _is_onnx(name: str) -> bool:
    return name.startswith(ONNX_PREFIX)


def _live_observer(args: argparse.Namespace):
    """(server, observer) streaming every trial of a run to the browser (``wbc run --view``)."""
    # meshcat's server loads only when a run is watched
    from wbc.viz.live import LiveObserver, LiveViewer
    from wbc.viz.player import KeyboardControls, Player, PlayerConfig
    from wbc.viz.server import MeshcatServer, ServerConfig

    server = MeshcatServer(ServerConfig(host=args.host)).start()
    print(f"viewer: {server.web_url}  (listening on {server.listening}; trials play one by one in this process)",
          file=sys.stderr)
    player = Player(PlayerConfig(speed=args.speed), KeyboardControls().start())
    return server, LiveObserver(LiveViewer(server), player)


def _run(args: argparse.Namespace) -> int:
    return _arena(args, (args.controller,))


def _compare(args: argparse.Namespace) -> int:
    named = list(dict.fromkeys(args.controllers))
    if len(named) < len(args.controllers):
        twice = [c for c in named if args.controllers.count(c) > 1]
        raise ConfigError(f"wbc compare: {', '.join(twice)} named more than once; name each controller once"
                          + _label_hint(twice))
    if len(named) < 2:
        raise ConfigError(f"wbc compare needs two or more controllers to compare, got {named[0]}; to play one "
                          "controller, use wbc run")
    if args.alpha is not None and not args.until_significant:
        raise ConfigError("--alpha sets the significance level at which --until-significant stops, and a comparison "
                          "of a fixed number of trials has no stop (its report gives each test's p-value): add "
                          "--until-significant, or leave --alpha out")
    return _arena(args, tuple(args.controllers), until_significant=args.until_significant,
                  alpha=0.05 if args.alpha is None else args.alpha)


def _label_hint(names: list[str]) -> str:
    """How to play two settings of the first plug-in among `names` in one run (labels), or '' when none is one."""
    plugin = next((target for target in map(plugin_target, names) if target is not None), None)
    if plugin is None:
        return ""
    return (f"; to compare two settings of the plug-in {plugin}, give each a label (a letter or digit, then letters, "
            f"digits, '_', '.' or '-', at most {LABEL_MAX} characters) and its own file: wbc compare {plugin}@A "
            f"{plugin}@B --controller-config {plugin}@A=a.toml --controller-config {plugin}@B=b.toml ...")


def _command_line() -> str:
    """This process's command line as ``run.json`` records it: ``wbc`` and its arguments, quoted for a shell."""
    return shlex.join(["wbc", *sys.argv[1:]])


def _check_in_process(args: argparse.Namespace) -> None:
    """``--in-process`` needs trials played here: one local worker, and no time limit (which ends a worker)."""
    if not args.in_process:
        return
    if getattr(args, "executor", "local") != "local":
        raise ConfigError("--in-process plays the trials in this process, which the ray executor does not: leave one "
                          "of them out")
    if args.trial_time_limit is not None:
        raise ConfigError("--in-process with --trial-time-limit: the limit ends a trial's worker process, and "
                          "in process there is none to end; leave one of them out")
    if args.workers not in (None, 1):
        raise ConfigError(f"--in-process plays one trial at a time in this process: leave --workers {args.workers} "
                          "out, or give --workers 1")
    args.workers = 1


def _paper(args: argparse.Namespace) -> int:
    _check_in_process(args)
    overrides: dict[str, str] = {}
    for value in args.contender or ():
        key, sep, name = value.partition("=")
        if not sep or not key or not name:
            raise ConfigError(f"--contender {value}: write KEY=CONTROLLER (e.g. learned=policy:runs/x/policy)")
        if key in overrides:
            raise ConfigError(f"--contender: {key} is given twice ({overrides[key]}, {name}); give it once")
        overrides[key] = name
    _check_resumable(args)
    args.results_dir = Path(args.out) if args.out else default_out_dir(args.table)  # what an interruption names
    result = run_paper_table(PaperRunConfig(
        table=args.table, trials=args.trials, seeds=args.seeds,
        scenario=Path(args.scenario) if args.scenario else None, out_dir=args.results_dir,
        workers=args.workers, resume=args.resume, drop_bad_rows=args.drop_bad_rows,
        progress=not (args.quiet or args.json), contenders=overrides,
        crouched=args.crouched, trial_time_limit_s=args.trial_time_limit, isolated=not args.in_process,
        command_line=_command_line()))
    if args.json:
        printers.print_json(result.as_dict())
    else:
        printers.print_paper_table(result)
    # a contender's errors cost its own trials, but the command says so and fails, as wbc compare does
    for errors in result.controller_errors:
        print(f"wbc: {errors.line()}", file=sys.stderr)
    return 1 if result.controller_errors else 0


def _view(args: argparse.Namespace) -> int:
    # meshcat's server loads only when something is viewed
    from wbc.viz.errors import ViewerError
    from wbc.viz.player import PlayerConfig
    from wbc.viz.view import ViewConfig, replay_episode, view_trial

    _view_refusals(args)
    _check_host(args.host)
    record = Path(args.record) if args.record else None
    if record is not None and record.is_dir():  # checked before the trial plays, as the other paths
        raise ViewerError(f"--record {record} is a directory: give an .html file in it, e.g. {record / 'view.html'}")
    if record is not None and (record.suffix.lower() not in (".html", ".htm") or not record.parent.is_dir()):
        raise ViewerError(f"--record {record}: give an .html file in an existing directory")
    save = Path(args.save_episode) if args.save_episode else None
    if save is not None and (save.suffix.lower() != ".npz" or save.is_dir() or not save.parent.is_dir()):
        # checked before the trial plays (numpy would add .npz to any other name, or fail after the trial)
        raise ViewerError(f"--save-episode {save}: give an .npz file in an existing directory")
    cfg = ViewConfig(
        live=record is None or args.live, host=args.host or "127.0.0.1", record=record, record_fps=args.fps,
        player=PlayerConfig(speed=1.0 if args.speed is None else args.speed, pause_at=tuple(args.pause_at or ()),
                            step_s=0.02 if args.step is None else args.step, start_paused=args.paused),
        open_browser=args.open, wait_for_browser=args.wait,
        save_episode=save,
        export_scenario=Path(args.export_scenario) if args.export_scenario else None,
        debug_truth=args.debug_truth,
    )
    ctrls = list(args.ctrl or [])
    if len(ctrls) > 2:
        raise ConfigError(f"wbc view takes one controller, or two for an A / B view; got {len(ctrls)}: "
                          f"{' '.join(ctrls)}")
    if len(ctrls) == 2:
        return _view_ab(args, ctrls, cfg)
    args.ctrl = ctrls[0] if ctrls else None
    if args.episode is not None:
        from wbc.viz.replay import load_stored_episode

        stored = load_stored_episode(args.episode, args.trial, controller=args.controller or args.ctrl,
                                     band=args.band, seed=args.seed)
        warn_if_unpublished(stored.scenario)  # the run's content, replayed as any other command plays a scenario
        _check_at(args.at, stored.trial.duration_s)
        result = replay_episode(stored, cfg)
        what = f"{stored.path}"
    else:
        if args.ctrl is None or args.scenario is None:
            raise ConfigError("wbc view needs CTRL --scenario FILE --trial I (play a trial), or --episode "
                              "RESULTS_DIR --trial I (replay a stored one)")
        (spec,) = _view_controllers(args, (args.ctrl,))
        trial = _view_trial(args)
        _check_at(args.at, trial.duration_s, cut=args.duration is not None)
        result = view_trial(trial, spec, cfg)
        what = f"{args.ctrl} on {trial.scenario} band {trial.band} seed {trial.seed} trial {trial.index}"
        printers.print_viewed_trial(what, result.trial_record)
        if result.exported is not None:
            print(result.exported.line(args.ctrl))
        if save is not None:
            print(f"saved the episode played to {save}")
    if result.recording is not None:
        printers.print_recording(what, result.frames_recorded, result.recording)
        if result.timing is not None:
            print(result.timing.line())
        if args.at is not None:
            print(f"open: {result.recording.resolve().as_uri()}#t={args.at:g}")
    return 0


def _view_refusals(args: argparse.Namespace) -> None:
    """Refuse the ``wbc view`` options that this view would not use, naming what each needs, before anything plays."""
    ab, stored = len(args.ctrl or []) == 2, args.episode is not None
    live = not ab and (args.record is None or args.live)
    if not stored:
        _refuse((("--controller", args.controller),),
                "picks whose stored run --episode replays: without --episode, name the controller as CTRL")
    elif args.controller is not None and (ab or (args.ctrl and args.ctrl[0] != args.controller)):
        named = " ".join(args.ctrl)
        raise ConfigError(f"--controller {args.controller} and {named}: " + (
            "an A / B view replays the two controllers it names (wbc view A B --episode DIR); leave --controller out"
            if ab else "two controllers named for one replay; give one, as CTRL or as --controller"))
    if stored:
        # a stored episode replays as it was run: its trial and its controller's run come from the results directory
        _refuse((("--scenario", args.scenario), ("--duration", args.duration),
                 ("--controller-config", args.controller_config), ("--io", args.io),
                 ("--save-episode", args.save_episode), ("--no-push", args.no_push or None),
                 ("--debug-truth", args.debug_truth or None)),
                "with --episode: a stored episode replays the run stored, whole (--pause-at T or --at T reach a "
                "moment)")
    if ab:
        _refuse((("--save-episode", args.save_episode), ("--live", args.live or None)),
                "with two controllers: an A / B view is written to one page, never streamed, and saves no episode "
                "(view one controller for those)")
    if args.live and args.record is None:
        raise ConfigError("--live streams a recorded view as well (with --record); without --record the view is "
                          "live already: leave --live out")
    if not live:
        _refuse((("--host", args.host), ("--speed", args.speed), ("--step", args.step), ("--pause-at", args.pause_at),
                 ("--paused", args.paused or None), ("--wait", args.wait or None)),
                "plays no part here: this view is only recorded (with one controller, --live streams it too)")
    elif args.record is None and args.at is not None:
        raise ConfigError("--at opens a recorded page at a moment: add --record FILE.html, or use --pause-at T live")


def _check_at(at: float | None, duration_s: float, *, cut: bool = False) -> None:
    """Refuse an ``--at`` past the end of the trial shown, before it plays: the page would open at no moment of it.

    Args:
        at: ``--at`` [s], or None.
        duration_s: how long the trial shown lasts [s].
        cut: `duration_s` is ``--duration``'s, for the message.
    """
    if at is not None and at > duration_s:
        lasts = f"{duration_s:g} s (its --duration)" if cut else f"{duration_s:g} s"
        raise ConfigError(f"--at {at:g} s is past the end of the trial, which lasts {lasts}: give --at in "
                          f"[0, {duration_s:g}]")


def _check_host(host: str | None) -> None:
    """Refuse a ``--host`` that is no IP address or host name (`host_problem`), before any server or trial starts.

    Only its syntax is checked (nothing is looked up); which addresses a viewer may listen on is left as it is.
    """
    from wbc.viz.server import host_problem

    problem = None if host is None else host_problem(host)
    if problem is not None:
        raise ConfigError(f"--host {host or repr(host)} {problem}")


def _view_trial(args: argparse.Namespace) -> Trial:
    """The trial ``wbc view`` plays: ``--scenario``'s band (its first by default), seed and trial, cut short.

    Without its pushes with ``--no-push``, as ``wbc run --no-push`` plays it.
    """
    scenario = load_scenario(args.scenario)
    warn_if_unpublished(scenario)
    trial = scenario.trial(args.band or scenario.bands[0], 0 if args.seed is None else args.seed, args.trial)
    if args.no_push:
        trial = dataclasses.replace(trial, pushes=())
    if args.duration is not None:
        if not 0 < args.duration <= trial.duration_s:
            raise ConfigError(f"--duration must be in (0, {trial.duration_s}] s, got {args.duration}")
        trial = dataclasses.replace(trial, duration_s=args.duration)
    return trial


def _view_controllers(args: argparse.Namespace, ctrls: tuple[str, ...]) -> tuple[ControllerSpec, ...]:
    """The controllers ``wbc view`` plays, each with its ``--controller-config`` / ``--io`` file (``[NAME=]FILE``)."""
    configs = _controller_files(args.controller_config, ctrls, "--controller-config", takes_controller_config,
                                "a plug-in")
    ios = _controller_files(args.io, ctrls, "--io", _is_onnx, "an onnx:PATH policy")
    return tuple(get_controller(c, config=configs.get(c), io=ios.get(c)) for c in ctrls)


def _view_ab(args: argparse.Namespace, ctrls: list[str], cfg: object) -> int:
    """``wbc view A B``: both controllers' runs of one trial in one recorded page, B as a ghost."""
    from wbc.arena.results import file_name_part
    from wbc.viz.view import replay_ab, view_ab

    def page_path(trial: Trial) -> Path:
        """``--record``, else a name of its own for each pair of controllers and trial (scenario, band, seed)."""
        if args.record:
            return Path(args.record)
        return Path(f"ab-{file_name_part(ctrls[0])}-{file_name_part(ctrls[1])}-{file_name_part(trial.scenario)}-"
                    f"{file_name_part(trial.band)}-s{trial.seed}-t{trial.index}.html")

    if args.episode is not None:
        from wbc.viz.replay import load_stored_episode

        first, second = (load_stored_episode(args.episode, args.trial, controller=c, band=args.band, seed=args.seed)
                         for c in ctrls)
        warn_if_unpublished(first.scenario)  # one run's, so both controllers': said once
        _check_at(args.at, first.trial.duration_s)
        result = replay_ab(first, second, cfg, page_path(first.trial))
    else:
        if args.scenario is None:
            raise ConfigError("wbc view A B needs --scenario FILE --trial I (play the trial with both), or "
                              "--episode RESULTS_DIR --trial I (their stored runs)")
        trial = _view_trial(args)
        _check_at(args.at, trial.duration_s, cut=args.duration is not None)
        specs = _view_controllers(args, tuple(ctrls))
        result = view_ab(trial, specs, cfg, page_path(trial))
    for name, fall in zip(result.names, result.fall_s, strict=True):
        print(f"{name}: " + ("survived" if fall is None else f"fell at {fall:.2f} s"))
    if result.divergence_s is not None:
        print(f"first divergence at {result.divergence_s:.2f} s")
    at = args.at if args.at is not None else result.divergence_s
    print(f"recorded {result.frames[0]} + {result.frames[1]} frames of {result.names[0]} vs {result.names[1]} "
          f"(ghost) to {result.recording}")
    print(f"open: {result.recording.resolve().as_uri()}" + (f"#t={at:g}" if at is not None else ""))
    return 0


def _demo(args: argparse.Namespace) -> int:
    """The A/B the arena is for: mpc against learned on the same push trials, paired; the tail analysis first."""
    _check_resumable(args)
    if args.out and not args.resume and (Path(args.out) / "trials.csv").exists():
        # said before the tail analysis, not after it
        raise ResultsDirError(f"{args.out}: already holds results; pass --resume to finish that run, or choose "
                              "another --out")
    robot = load_scenario(args.scenario).robot
    printers.print_demo_header(DEMO_CONTROLLERS, scenario=args.scenario, trials=args.trials, seeds=args.seeds)
    printers.print_tail(analyze_tail(get_robot(robot, "actuated")))  # the scenario's robot's arm
    print(flush=True)
    args.results_dir = Path(args.out or f"runs/demo-{time.strftime('%Y%m%d-%H%M%S')}")  # what an interruption names
    cfg = ArenaConfig(controllers=DEMO_CONTROLLERS, scenario=Path(args.scenario), seeds=tuple(range(args.seeds)),
                      trials=args.trials, out_dir=args.results_dir,
                      workers=args.workers, progress=not args.quiet, resume=args.resume,
                      drop_bad_rows=args.drop_bad_rows, command="demo", command_line=_command_line())
    result = run_arena(cfg)
    printers.print_arena(result, verdict=False)
    printers.print_demo_end(result.out_dir, trial_to_watch(result.records, DEMO_CONTROLLERS), scenario=args.scenario,
                            summary=result.summary)
    for errors in result.controller_errors:
        print(f"wbc: {errors.line()}", file=sys.stderr)
    return 1 if result.controller_errors else 0


def _scenario_check(args: argparse.Namespace) -> int:
    result = check_scenario(args.file, args.lock)
    if args.json:
        printers.print_json(dataclasses.asdict(result))
    else:
        printers.print_scenario_check(result)
    return 0 if result.published else 1


def _controllers(args: argparse.Namespace) -> int:
    rows = list_controllers()
    if args.json:
        printers.print_json([dataclasses.asdict(r) for r in rows])
    else:
        printers.print_controllers(rows)
    return 0


_UNBUILT = (OnnxIoError, OnnxModelError, PolicyFileError, PluginImportError, PluginAttributeError)
"""What resolving a name raises when the controller it names cannot be built: its model, I/O file or policy file is
invalid, or its plug-in's module does not import or lacks its factory (not an unknown or malformed name, nor an option
given to the wrong controller, which are the command line's errors)."""


def _check_controller(args: argparse.Namespace) -> int:
    if args.seconds is not None and not args.seconds > 0:
        raise ConfigError(f"--seconds must be > 0, got {args.seconds}")
    robots = tuple(dict.fromkeys(robot_name(r) for r in args.robot)) if args.robot else None  # a1 and a1-wx200: once
    try:
        spec = get_controller(args.name, config=args.controller_config, io=args.io)
    except _UNBUILT as exc:  # the name's files or module: a failed build, which --json prints as one
        if args.json:
            printers.print_json(ControllerCheck.unbuilt(args.name, str(exc)).as_dict())
        raise  # the same line and status as without --json: nothing was checked
    if args.scenario is not None:
        _scenario_played(args.scenario)  # checked on an edited copy of a published file: said so
    cfg = CheckConfig(seconds=args.seconds, strict_timing=args.strict_timing, robots=robots, scenario=args.scenario,
                      replay=args.replay)
    if args.in_process:
        if args.time_limit is not None:
            raise ConfigError("--time-limit ends the checks' worker process, which --in-process does not start: "
                              "leave one of them out")
        result = check_controller(spec, cfg)
    else:
        result = _check_apart(spec, cfg, args.time_limit)
    if args.json:
        printers.print_json(result.as_dict())
    else:
        printers.print_controller_check(result)
    return 0 if result.passed else 1


def _check_apart(spec: ControllerSpec, cfg: CheckConfig, time_limit_s: float | None) -> ControllerCheck:
    """`check_controller` in a worker process of its own, as the arena plays trials.

    A controller that ends its process (``os._exit``, a crash in native code) ended the command with its own status,
    0 included, and printed nothing: a CI job read a pass. In a worker, that ends the worker only, and the check
    fails, saying so; with `time_limit_s`, so does a controller that hangs. The checks' own errors (a scenario or a
    replay file refused) come back as they are raised.
    """
    pool = spawn_pool(1)
    try:
        future = pool.submit(check_controller, spec, cfg)
        worker = list((getattr(pool, "_processes", None) or {}).values())  # started by the submit
        try:
            return future.result(timeout=time_limit_s)
        except BrokenProcessPool:
            for process in worker:
                process.join(timeout=5.0)  # ended already: reaped for its status
            codes = [process.exitcode for process in worker]
            status = f" (exit status {codes[0]})" if len(codes) == 1 and codes[0] is not None else ""
            return ControllerCheck.ended(spec.name, f"the checks' worker process ended before they finished{status}, "
                                                    "or could not hand back what they found: the controller ended its "
                                                    "process (os._exit, a crash in native code), which on a robot ends "
                                                    "the control loop, or made a result that cannot be sent back")
        except FuturesTimeout:
            return ControllerCheck.ended(spec.name, f"the checks had not finished after {time_limit_s:g} s "
                                                    "(--time-limit): the controller hangs, or is far too slow; its "
                                                    "worker process was ended")
    finally:
        shut_down_pool(pool, broken=True)  # its one task is done, or its worker dead or hung: nothing to wait for


HANDLERS: dict[str, Callable[[argparse.Namespace], int]] = {
    "analyze tail": _analyze_tail,
    "analyze arm-momentum": _analyze_arm_momentum,
    "analyze posture": _analyze_posture,
    "bench sim": _bench_sim,
    "bench mpc": _bench_mpc,
    "bench sweep": _bench_sweep,
    "bench train": _bench_train,
    "bench hw": _bench_hw,
    "bench latency": _bench_latency,
    "bench act": _bench_act,
    "bench arm": _bench_arm,
    "hw emulate": _hw_emulate,
    "hw check": _hw_check,
    "hw run": _hw_run,
    "train": _train,
    "run": _run,
    "compare": _compare,
    "paper": _paper,
    "view": _view,
    "demo": _demo,
    "controllers": _controllers,
    "check-controller": _check_controller,
    "scenario check": _scenario_check,
}
"""What each command does, by the ``handler`` name its parser sets."""


_RESUMABLE = ("run", "compare", "paper", "demo")
"""The commands whose results directory ``--resume`` finishes after an interruption."""


@contextmanager
def _terminate_interrupts() -> Iterator[None]:
    """SIGTERM and SIGHUP end the command as Ctrl-C does (`KeyboardInterrupt`); the handlers before are restored after.

    A batch scheduler, ``timeout`` or ``docker stop`` ends a command with SIGTERM, and a terminal that is closed hangs
    up the command with SIGHUP: the run then stops its workers and says what it stored and how to finish it, and a
    hardware command closes its robot into damping, where it ended without a word (status -15, -1) and left the legs
    holding their last command. A SIGHUP ignored when the command starts (``nohup``) stays ignored. Signals reach the
    main thread only: a command run from another thread keeps the handlers it has.

    The `KeyboardInterrupt` names its signal (``SIGTERM``, ``SIGHUP``), so that a hardware trial interrupted while it
    plays records what stopped it; Ctrl-C's, raised by Python's own handler, names none.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt(signal_label(signum))  # named: a hardware trial's record says what stopped it

    wanted = (signal.SIGTERM,) + (() if signal.getsignal(signal.SIGHUP) is signal.SIG_IGN else (signal.SIGHUP,))
    previous = {signum: signal.signal(signum, interrupt) for signum in wanted}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, signal.SIG_DFL if handler is None else handler)


def _say(text: str) -> None:
    """Print `text` on standard error, where a terminal that was closed (or a pipe nobody reads) is no failure.

    A command's last words after SIGHUP meet a terminal that is gone (OSError, BrokenPipeError): they are dropped, and
    standard output and error then go to the null device, so that neither a later line nor the flush at exit fails.
    """
    try:
        print(text, file=sys.stderr, flush=True)
    except OSError:
        _to_the_null_device(sys.stdout, sys.stderr)


def _stdout_reader_gone() -> bool:
    """Whether standard output is a pipe whose reader has closed it (``wbc ... | head``, once `head` has its lines)."""
    try:
        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & select.POLLERR for _, events in poller.poll(0))
    except (OSError, ValueError, AttributeError):  # closed, or not a file (a test's capture)
        return False


class StdoutUnwritable(Exception):
    """Standard output refused a write or a flush (a full disk, ``/dev/full``, an I/O error): its `__cause__` says how.

    Told apart from any other OSError, which is the command's own (a file it reads or writes) or a bug's.
    """


class _CheckedStdout:
    """A command's standard output whose failures, other than a reader that closed it, raise `StdoutUnwritable`.

    A full disk under ``wbc ... > FILE`` printed an OSError traceback and exited 1, the status that says a controller
    errored. A closed reader's BrokenPipeError goes on as it is (status 141, `main`).
    """

    def __init__(self, stream: Any) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            raise
        except OSError as exc:
            raise StdoutUnwritable from exc

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            raise
        except OSError as exc:
            raise StdoutUnwritable from exc

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


def _stored_run(args: argparse.Namespace) -> str:
    """The end of the message for a run whose output could not be written: where its results are, if it wrote any."""
    out = getattr(args, "results_dir", None) or (Path(args.out) if getattr(args, "out", None) else None)
    if out is None or not Path(out).is_dir():
        return ""
    return f"; the run's results are stored in {out}"


def _to_the_null_device(*streams: Any) -> None:
    """`streams` to the null device: what is left in their buffers, and the flush at exit, then go nowhere."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        for stream in streams:
            try:
                os.dup2(devnull, stream.fileno())
            except (OSError, ValueError, AttributeError):  # closed, or not a file (a test's capture)
                pass
    finally:
        os.close(devnull)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``wbc`` console script.

    Args:
        argv: the arguments after the program name (default: ``sys.argv[1:]``).

    Returns:
        The exit status: 0 on success, 1 when a controller errored on some trials of a run or comparison (outcome
        ``controller_error``, one line each on stderr; a fall is a result, not a failure), a hardware trial's
        controller errored or its robot's link was lost (`hw_run`), a controller check did not pass, or the safety
        layer would refuse the state `hw_check` read (or no state came), 2 for a `WbcError` (its message printed to
        stderr), 130 when interrupted (Ctrl-C, SIGTERM, or SIGHUP when its terminal is closed; a run's
        finished trials are stored, and the message says how to finish it; a training run's says which checkpoint,
        or which DAgger rounds, its run directory keeps), 141 without a word when the reader of its standard output
        closed it (``| head``), as for a command that SIGPIPE ends. A standard output that cannot be written (closed,
        ``>&-``: refused before anything runs; a full disk, an I/O error) exits 2, in one line that says so, and for
        a run where its results are stored. A usage error exits with status 2 from the parser, after its usage
        message. An unexpected exception propagates (the console script, `wbc.cli.main`, exits 70 on it).
    """
    try:
        args = build_parser().parse_args(argv)
        # what a run records as its command: pasteable, whichever way wbc was started (`python -m wbc.cli`, a test)
        args.command_line = ["wbc", *(sys.argv[1:] if argv is None else argv)]
    except KeyboardInterrupt:
        _say("wbc: interrupted while starting: nothing was done")
        return 130
    if sys.stdout is None:  # started with its standard output closed (``>&-``): what it prints would go nowhere
        _say("wbc: error: standard output cannot be written: it is closed; give the command one (> FILE, "
             "> /dev/null): nothing was done")
        return 2
    try:
        with _terminate_interrupts(), redirect_stdout(_CheckedStdout(sys.stdout)):
            with printers.json_alone(bool(getattr(args, "json", False))):
                code = int(HANDLERS[args.handler](args) or 0)
            sys.stdout.flush()  # here, where a reader that closed the output is told apart; not at the exit
            return code
    except StdoutUnwritable as exc:
        _to_the_null_device(sys.stdout)  # what is left in its buffer would fail again at the exit
        _say(f"wbc: error: standard output cannot be written: {exc.__cause__}"
             + (_stored_run(args) if args.handler in _RESUMABLE or args.handler == "hw run" else ""))
        return 2
    except WbcError as exc:
        _say(f"wbc: error: {exc}")
        return 2
    except KeyboardInterrupt:
        _say("wbc: interrupted" + (_interrupted_run(args) if args.handler in _RESUMABLE else
                                   _interrupted_training(args)))
        return 130
    except BrokenPipeError:
        if not _stdout_reader_gone():
            raise  # another pipe's: a fault to see
        _to_the_null_device(sys.stdout)
        return 128 + signal.SIGPIPE


if __name__ == "__main__":
    sys.exit(main())
