"""Hardware trials: a scenario's trial played on a real robot (or a wire-exact emulator) through the one runner loop.

`run_hardware_trial` is the hardware counterpart of `wbc.arena.sim_trial.run_trial`. It samples the trial exactly as
the arena does, builds the controller by name (its variant for the robot's arm mode) and the real robot
(`wbc.hardware.hardware_robot.build_hardware_robot`), and plays the trial's command schedule with
`wbc.arena.runner.run_episode`, paced in real time by the robot's own `advance`. The robot runs behind the safety
layer (`wbc.hardware.safety.SafeRobot`, on the wall clock) and is seen through its sensors (`EstimatedRobot`):

- what only a simulator can do is skipped and said: the trial's pushes, its terrain and its friction and payload
  randomisation (NaN in the record); an operator can mark a push given by hand with a key (`wbc.arena.operator`);
- the metrics come from the state estimator (IMU and leg kinematics), not from truth, and the record and the report
  say so (``metrics_source``);
- before the trial's clock starts, the layer ramps the robot from its measured pose into the stand hold of its
  nominal pose (`wbc.control.stand.stand_command`) and is in ``run``: the controller then starts, as in simulation,
  from a robot standing at its nominal pose, and its commands pass without a ramp (a ramp's slew would hold back a
  walking controller's swing legs);
- the episode ends at the safety layer's first trip (its tilt check, a fault, an e-stop); the robot is then held in
  the layer's damping for ``settle_s`` while it comes to rest, before the link is closed. The record's outcome tells
  them apart: ``safety_trip`` for the layer's own checks (a tilt trip among them: the event's detail says so),
  ``operator_stop`` for an e-stop (the console's key, the remote). Neither is recorded as a fall: the episode's
  ``fell`` is False and its ``fall_time_s`` NaN, and the trial counts as the arena counts one that did not complete
  (a controller's error): not a success, its TTF the share of the trial played before the trip (the episode's last
  tick);
- a robot that stopped answering (its own link's state stream stale, the legs' on a quadruped, and still so when
  the link is closed) is a lost link (`LinkLost`, in the result, ``hardware.json`` and the report): nothing then shows
  that the layer's damping reached the robot, which must be checked and powered down by hand;
- a fault the arm's bus latched (a servo's hardware error, a servo that stopped answering, the port lost) trips the
  layer (the servo's mode, or the joined state gone stale) and is recorded as the arm's (``arm_faults``, with the
  torque policy it applied), not as a lost link while the legs answer: the trial's outcome, as any trip;
- a controller that raises, or returns a command the robot refuses, ends the episode too: the layer is tripped into
  damping (a software e-stop), and the trial is recorded with the outcome ``controller_error`` and what failed;
- so does an interruption while the trial plays (Ctrl-C, SIGTERM, a hangup, the I/O process stopped by SIGTERM): the
  layer is tripped into damping at once, the robot is closed without the settle, and the episode up to the
  interruption is recorded with the outcome ``operator_stop`` and when (`Interruption`); the trial's caller gets
  `ResultsInterrupted`, as for an interruption after the trial;
- deadline misses (``controller.act`` longer than the period), the link's late advances and the process's CPU time
  go into the record and the report beside the safety layer's transitions and the operator's actions.

The robot's devices (the legs' link, the arm's bus) run in a child process by default
(`wbc.hardware.io_process.ProcessRobot`, ``io_process``), so that the controller's computing cannot starve them of
the interpreter lock; its CPU time during the episode is then reported apart (``io_cpu_s``).

The same protocol runs on the simulator (``simulate``, ``wbc hw run --sim``): a `MujocoRobot` of the robot on flat
ground, without domain randomisation, behind the same safety layer (on robot time) and seen through the same
estimator. Set beside a run over a wire, it shows what the wire, the real-time loop and the second process cost; the
robot is then neither paced nor sent anything.

The results directory has the arena's format (``trials.csv`` with ``backend``, ``run.json``, ``summary.json``,
``report.md``), the episode under ``episodes/`` and ``hardware.json`` (link counters, events, what was skipped).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

from threadpoolctl import threadpool_limits

from wbc.arena.controller_failure import ControllerFailure, read_counters
from wbc.arena.episode import Episode
from wbc.arena.error_guard import ErrorGuard
from wbc.arena.finish import finish_results
from wbc.arena.identity import MAX_SEED, MAX_TRIALS, HardwareRunIdentity, ScenarioRef
from wbc.arena.operator import OPERATOR_ACTIONS, KeySource, OperatorConsole
from wbc.arena.report import md_table, summarize
from wbc.arena.results import ResultsStore, episode_path, hold_results_dir, holds_results, unwritable
from wbc.arena.run_environment import report_lines
from wbc.arena.runner import EpisodeInterrupted, PreparingObserver, TickObserver, run_episode
from wbc.arena.trial_record import TrialRecord
from wbc.control.registry import ControllerSpec, arm_variant, get_controller
from wbc.control.stand import stand_command
from wbc.errors import ConfigError, IoProcessStopped, StandUpError, UnknownNameError
from wbc.estimation.base_estimate import BaseEstimate
from wbc.estimation.estimated_robot import EstimatedRobot
from wbc.estimation.filter import DEFAULT_CONTACT_FORCE
from wbc.hardware.capabilities import HasLinkStats, HasRealtimeGrant, LinkStatsLike, WallClock
from wbc.hardware.dynamixel.arm_fault import ArmFault
from wbc.hardware.hardware_robot import HARDWARE_ROBOTS, HardwareRobot, HardwareRobotConfig, build_hardware_robot
from wbc.hardware.interpreter import frozen_heap
from wbc.hardware.io_process import ProcessRobot, build_process_robot
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.hardware.realtime import RealtimeGrant, RealtimeRequest, controller_realtime
from wbc.hardware.safety import SafeRobot, SafetyConfig, SafetyEvent, SafetyState
from wbc.interrupts import ASKS_TO_END, DeferredInterrupts, signal_label
from wbc.output_files import DirectoryLock, write_text
from wbc.scenario import load_scenario, warn_if_unpublished
from wbc.scenario.scenario import fallback_note
from wbc.scenario.trial import Trial
from wbc.types import MotorCommand

_T = TypeVar("_T")

__all__ = ["ConnectInterrupted", "HardwareTrialConfig", "HardwareTrialResult", "Interruption", "LinkLost",
           "ResultsInterrupted", "run_hardware_trial"]

HARDWARE_JSON_CLOCKS = {
    "safety_events": "the safety layer's clock: wall-clock seconds since the robot was connected (the robot's "
                     "monotonic clock; the simulator's time with --sim); the trial began at trial_started_s",
    "trial_started_s": "the safety layer's clock",
    "operator_events": "trial time: 0 at the trial's first tick, as the episode's t",
    "episode_safety_events": "trial time: the episode file's safety_time is safety_events' time - trial_started_s",
    "arm_faults": "trial time: 0 at the trial's first tick, as the episode's t (negative: latched during the "
                  "stand-up); without this entry the file is older and stored the arm bus's clock, the host's "
                  "monotonic clock, which no other time here is on",
}
"""What ``hardware.json``'s ``clocks`` says: the clock each of its times is on (a file without it is older: its
episode's ``safety_time`` is on the safety layer's clock)."""

_STAND_UP_DT = 0.02  # [s] period of the stand hold that precedes a trial (the stand controller's 50 Hz)


@dataclass(frozen=True, kw_only=True)
class HardwareTrialConfig:
    """What to play, on which robot, and where the results go.

    Attributes:
        controller: a registry name (its variant for `arm_mode` is played: ``stand`` with the arm ``none`` is
            ``stand-noarm``), ``policy:PATH``, ``onnx:PATH`` or a plug-in (``package.module:factory``, an entry point).
        scenario: the scenario file.
        trial: trial index within (band, seed).
        band: the band (None: the scenario's first).
        seed: the seed.
        seconds: play only the first `seconds` of the trial (None: all of it) [s].
        robot: robot registry name (None: the scenario's); its command schedule is played whatever robot it was
            written for.
        arm_mode: the robot's arm mode (None: the controller's).
        target: the legs' low-level address (IPv4 literal, UDP port); None only with `simulate`.
        simulate: play on the simulator instead of a robot (the protocol's twin, for comparison); no target.
        local: the address the legs' link binds (None: 127.0.0.1:0 for a loopback target, else 0.0.0.0:0).
        allow_hardware: allow a target outside 127.0.0.0/8 (a real robot).
        rate_hz: the link's rate [Hz].
        transport: the legs' datagram channel, ``udp`` or ``sdk`` (the vendor's Go1 SDK).
        arm_port: the arm's serial device (the U2D2, or an emulator's pty); needed for an actuated arm.
        out_dir: the results directory (must not hold results yet).
        safety: the safety layer's settings (None: the defaults, with the robot's SDK position table).
        settle_s: after a trip, how long the robot is held in damping, still read, before the link closes [s].
        contact_force: foot sensor reading at which the metrics' estimator trusts a foot as standing.
        controller_config: a plug-in controller's ``--controller-config`` TOML file (None: none).
        io_file: an ``onnx:PATH`` policy's I/O file (None: beside the model).
        io_process: run the robot's devices (legs link, arm bus) in a child process with its own interpreter lock
            (`wbc.hardware.io_process.ProcessRobot`), so that the controller cannot starve them and a controller
            hung holding the lock still leaves the robot damped; False: in this process, beside the controller.
        controller_realtime: the scheduling the controller's loop (this thread) asks for from the stand-up to the
            end of the trial (`wbc.hardware.realtime.controller_realtime`), restored afterwards; None: none asked.
    """

    controller: str
    scenario: Path
    trial: int
    band: str | None = None
    seed: int = 0
    seconds: float | None = None
    robot: str | None = None
    arm_mode: str | None = None
    target: tuple[str, int] | None = None
    simulate: bool = False
    local: tuple[str, int] | None = None
    allow_hardware: bool = False
    rate_hz: float = 500.0
    transport: str = "udp"
    arm_port: str | None = None
    out_dir: Path = field(default_factory=lambda: Path("runs/hw"))
    safety: SafetyConfig | None = None
    settle_s: float = 1.0
    contact_force: float = DEFAULT_CONTACT_FORCE
    controller_config: Path | None = None
    io_file: Path | None = None
    io_process: bool = True
    controller_realtime: RealtimeRequest | None = None

    def __post_init__(self) -> None:
        # the bounds run.json's reader takes (`wbc.arena.identity`), so that the viewer finds the trial played
        if not 0 <= self.trial <= MAX_TRIALS - 1 or not 0 <= self.seed <= MAX_SEED:
            raise ConfigError(f"--trial must be in [0, {MAX_TRIALS - 1}] and --seed in [0, {MAX_SEED}], got "
                              f"{self.trial} and {self.seed}")
        if self.seconds is not None and not self.seconds > 0:
            raise ConfigError(f"--seconds must be > 0, got {self.seconds}")
        if not self.settle_s >= 0:
            raise ConfigError(f"HardwareTrialConfig.settle_s must be >= 0 s, got {self.settle_s}")
        if (self.target is None) != self.simulate:
            raise ConfigError("a hardware trial needs the robot's address (--target HOST:PORT), or --sim to play the "
                              "same protocol on the simulator; not both")


@dataclass(frozen=True)
class LinkLost:
    """The robot's state stream stopped during a hardware trial and had not come back when its link was closed.

    The safety layer then tripped on the stale stream and sent damping, but a robot that no longer answers may not
    hear it either (a cable pulled, a network down, the robot's board off): nothing shows that the damping reached it.
    The same holds for a stream that stopped during the stand-up, before the trial (`StandUpError` then says so).

    A board that froze (or restarted) still sends frames, but with a tick that does not advance: the link refuses
    them for their tick (`refused_frames`), so no state counts as come, and the robot is not seen to act on anything
    either. The sentence then says that frames still arrive with a frozen tick, not that none came.

    Attributes:
        last_state_s: when the last state came, on the safety layer's clock (seconds since the robot was connected) [s].
        silent_s: how long no state had come when the link was closed (the trip, then the damped settle) [s].
        trial_started_s: when the trial began on that clock [s]; None: it was lost during the stand-up.
        refused_frames: valid frames the legs' link refused for their tick since the trial began (to the close); None
            when not known (the stand-up, a robot without such a link).
    """

    last_state_s: float
    silent_s: float
    trial_started_s: float | None
    refused_frames: int | None = None

    def describe(self) -> str:
        """What happened and what to do, in one sentence."""
        when = ("during the stand-up" if self.trial_started_s is None
                else f"{self.last_state_s - self.trial_started_s:.3f} s into the trial")
        if self.refused_frames:
            return (f"the robot's state froze: its last fresh state came {self.last_state_s:.3f} s after it was "
                    f"connected ({when}); frames still arrive, but with a frozen tick ({self.refused_frames} refused "
                    f"for their tick since the trial began), and none advanced in the {self.silent_s:.3f} s after: "
                    "its low-level board froze or restarted, and may not act on the damping frames sent since. Check "
                    "it and power it down by hand")
        return (f"the link to the robot was lost: its last state came {self.last_state_s:.3f} s after it was connected "
                f"({when}) and none came in the {self.silent_s:.3f} s after: the damping frames sent since may not "
                "have reached the robot. Check it and power it down by hand")

    def sentence(self) -> str:
        """`describe` as a sentence of its own: capitalised, with its full stop (the report, the stand-up error)."""
        said = self.describe()
        return f"{said[0].upper()}{said[1:]}."

    def to_dict(self) -> dict[str, float | int | None]:
        """Its JSON form (``hardware.json``'s ``link_lost``)."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class Interruption:
    """The command was interrupted while the trial played: Ctrl-C, SIGTERM, a hangup, or its I/O process stopped.

    The safety layer then latched its damping at once, the robot was closed into damping, and the episode played up to
    the interruption is the trial's: its record's outcome is ``operator_stop`` (not a success), its ``error`` says when
    (`describe`), and ``hardware.json`` holds this (``interrupted``).

    Attributes:
        time_s: the trial's time at the end of its last complete tick [s].
        tick: the ticks played whole.
        by: what interrupted it: ``Ctrl-C``, ``SIGTERM``, ``SIGHUP``, or ``its I/O process stopped by SIGTERM`` (the
            I/O process then closed the robot itself).
    """

    time_s: float
    tick: int
    by: str

    @classmethod
    def of(cls, stopped: EpisodeInterrupted) -> Interruption:
        """The interruption that ended the episode, named by its cause."""
        return cls(time_s=stopped.time_s, tick=stopped.tick, by=_interrupted_by(stopped.__cause__))

    def when(self, duration_s: float) -> str:
        """``at 1.240 s of the 3 s trial (Ctrl-C)``."""
        return f"at {self.time_s:.3f} s of the {duration_s:g} s trial ({self.by})"

    def describe(self, duration_s: float) -> str:
        """The trial record's ``error``: when, and what became of the robot and the episode."""
        return (f"interrupted {self.when(duration_s)}: the robot was closed into damping, and the episode up to the "
                "interruption is recorded")

    def to_dict(self) -> dict[str, float | int | str]:
        """Its JSON form (``hardware.json``'s ``interrupted``)."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class HardwareTrialResult:
    """What a hardware trial produced.

    Attributes:
        record: the trial's results row (as stored in ``trials.csv``).
        episode: the episode log (as stored under ``episodes/``).
        out_dir: the results directory.
        controller: the controller played (the variant for the robot's arm mode).
        robot: the robot as built (description, backend, target).
        notes: what was skipped or changed against the simulated trial, one line each.
        link: the robot link's counters after the episode (None for a robot without a link).
        cpu_s: CPU time of this process during the episode, every thread (the link's included) [s].
        episode_wall_s: wall time of the episode [s].
        safety_events: every transition of the safety layer, the stand-up before the trial's included (the
            episode holds those during the trial), on its clock: the robot's seconds since it was connected.
        trial_started_s: when the trial began on that clock (after the stand-up) [s].
        io_cpu_s: CPU time of the I/O process during the episode, every thread (the link's and the arm bus's) [s];
            None when the devices ran in this process.
        controller_realtime: what the controller's loop asked for and got (`HardwareTrialConfig.controller_realtime`),
            or None when it asked for nothing.
        link_lost: the robot's state stream had stopped and not come back when the link was closed (`LinkLost`);
            None when it was live to the end (or the robot has no link: the simulator).
        arm_faults: the faults the arm's bus latched (`wbc.hardware.dynamixel.ArmFault`: a servo that stopped
            answering, its hardware error, the port lost), oldest first, as of the close, each latched at its `time`
            on the trial's clock (0 at the trial's first tick, as the episode's; negative during the stand-up, moved
            from the bus's own clock); each says which joints its
            torque policy damped and which it left limp. An arm's fault ends the trial through the safety layer (the
            servo's mode, or its frozen state); it is not a lost link while the legs still answer.
        interrupted: the command was interrupted while the trial played (`Interruption`): the episode is the part
            played up to it; None when it was not. A trial's caller does not get the result then, but its results
            directory holds it (`ResultsInterrupted`).
        stale_frames: valid leg frames the link refused for their tick (a board repeating its buffer, a robot that
            restarted), as of the close; None for a robot without such a link (the simulator).
    """

    record: TrialRecord
    episode: Episode
    out_dir: Path
    controller: ControllerSpec
    robot: HardwareRobot
    notes: tuple[str, ...]
    link: LinkStatsLike | None
    cpu_s: float
    episode_wall_s: float
    safety_events: tuple[SafetyEvent, ...]
    trial_started_s: float
    io_cpu_s: float | None = None
    controller_realtime: RealtimeGrant | None = None
    link_lost: LinkLost | None = None
    arm_faults: tuple[ArmFault, ...] = ()
    interrupted: Interruption | None = None
    stale_frames: int | None = None


def run_hardware_trial(cfg: HardwareTrialConfig, *, keys: KeySource | None = None,
                       observer: TickObserver | None = None,
                       before_connect: Callable[[HardwareRobot, ControllerSpec], None] | None = None,
                       build: Callable[[HardwareRobotConfig], HardwareRobot] | None = None,
                       ) -> HardwareTrialResult:
    """Play one trial of a scenario on a real robot (or an emulator) and write its results directory.

    Args:
        cfg: what to play and where.
        keys: the operator's keys (`wbc.arena.operator.OPERATOR_ACTIONS`); None: nobody at the keys.
        observer: called after every tick, after the keys (a live viewer).
        before_connect: called with the robot built and the controller resolved, just before the robot is
            connected (nothing was sent yet, no socket exists): a person confirms a real robot (it raises to refuse),
            a test puts its emulated robot in place.
        build: builds the robot from its config instead of `build_hardware_robot` (or `build_process_robot` with
            `io_process`): a test hands the devices a clock it moves and an emulator's in-process channel, so the
            whole trial runs in lockstep on that clock.

    Returns:
        The record, the episode and what the trial skipped.

    Raises:
        ScenarioError, UnknownNameError, PolicyFileError: bad scenario, band, controller or robot name.
        ConfigError: an arm mode the hardware cannot be built with (``actuated`` today) or the controller has no
            variant for; a controller for another robot.
        ResultsDirError: the results directory holds results, another run holds it, or it cannot be made (checked
            before the robot is built and connected; it is held until the results are written).
        TargetRefusedError: a target outside 127.0.0.0/8 without `allow_hardware` (before any socket exists).
        RobotLinkError: the robot did not answer, or its link (the I/O process) died. A robot that stops answering
            during the trial is a trip of the safety layer and a `LinkLost` in the result instead.
        StandUpError: the safety layer tripped while standing the robot up, before the trial (nothing was played).
        ConnectInterrupted: interrupted before the robot was connected (nothing was sent to it).
        ResultsInterrupted: interrupted during the trial (its robot closed into damping, the episode up to the
            interruption written, `ResultsInterrupted.during`) or after it (its results written whole, or what a
            second interruption left of them). Interrupted during the stand-up, the robot is closed into damping and
            the `KeyboardInterrupt` goes on: nothing was played.
    """
    out = Path(cfg.out_dir)
    with contextlib.ExitStack() as holding:
        try:  # nothing is connected before `_play`: an interruption until then has sent the robot nothing
            scenario = load_scenario(cfg.scenario)
            note = fallback_note(cfg.scenario, scenario)
            if note is not None:
                print(f"wbc: note: {note}", file=sys.stderr)
            cfg = dataclasses.replace(cfg, scenario=Path(scenario.path))  # the file that plays, as results record it
            band = cfg.band if cfg.band is not None else scenario.bands[0]
            trial = scenario.trial(band, cfg.seed, cfg.trial)
            if cfg.seconds is not None:
                if cfg.seconds > trial.duration_s:
                    raise ConfigError(f"--seconds must be in (0, {trial.duration_s}] s (the trial's length), got "
                                      f"{cfg.seconds}")
                trial = dataclasses.replace(trial, duration_s=cfg.seconds)
            named = get_controller(cfg.controller, config=cfg.controller_config, io=cfg.io_file)
            spec = arm_variant(named, cfg.arm_mode if cfg.arm_mode is not None else named.arm_mode)
            robot_name = cfg.robot if cfg.robot is not None else scenario.robot
            if spec.robot is not None and spec.robot != robot_name:
                raise ConfigError(f"controller {spec.name} drives {spec.robot}, not {robot_name}; choose a "
                                  f"controller for {robot_name}, or --robot {spec.robot}")
            # held from before the robot is connected until the results are written: a second run on the same
            # directory is refused before it sends anything, not once it has played its trial
            lock = holding.enter_context(hold_results_dir(out))
            if (out / "trials.csv").exists():
                raise holds_results(out, resumable=False)
            if cfg.simulate:
                hardware = _simulated(robot_name, spec.arm_mode)
            else:
                host, port = cfg.target
                local_host, local_port = cfg.local if cfg.local is not None else (None, 0)
                if build is None:
                    build = build_process_robot if cfg.io_process else build_hardware_robot
                hardware = build(HardwareRobotConfig(
                    robot=robot_name, arm_mode=spec.arm_mode, legs_host=host, legs_port=port,
                    local_host=local_host, local_port=local_port, allow_hardware=cfg.allow_hardware,
                    rate_hz=cfg.rate_hz, transport=cfg.transport, arm_port=cfg.arm_port))
            published = warn_if_unpublished(scenario)
        except KeyboardInterrupt as stopped:
            raise ConnectInterrupted(opening=False) from stopped
        with threadpool_limits(limits=1, user_api="blas"):  # as in simulation: one BLAS thread, beside the link's
            return _play(cfg, scenario_published=published, trial=trial, spec=spec, hardware=hardware, out=out,
                         lock=lock, keys=keys, observer=observer, before_connect=before_connect)


def _play(cfg: HardwareTrialConfig, *, scenario_published: bool, trial: Trial, spec: ControllerSpec,
          hardware: HardwareRobot, out: Path, lock: DirectoryLock, keys: KeySource | None,
          observer: TickObserver | None,
          before_connect: Callable[[HardwareRobot, ControllerSpec], None] | None) -> HardwareTrialResult:
    notes = _skipped(trial)
    trial = dataclasses.replace(trial, pushes=())  # no robot here can apply them
    link: LinkStatsLike | None = None
    # after the trial, Ctrl-C (or a request to end) waits for the trial's results, written whole (the trial is played
    # once), and a second one stops the writing, saying what it left; during the robot's close, every one waits for the
    # close (`Robot.close`)
    settling = [False]
    after_the_trial = DeferredInterrupts(
        lambda what: f"wbc hw run: {what}: "
                     f"{'the settle after the trip or e-stop is cut short and ' if settling[0] else ''}"
                     f"the robot is closed into damping; the trial's results are being written to {out} and the run "
                     "ends once they are (again: stop at once, leaving them incomplete)")
    io_stopped: list[IoProcessStopped] = []  # a request to end after the trial that stopped its I/O process
    with contextlib.ExitStack() as deferred:
        with contextlib.ExitStack() as stack:
            opening = False
            try:  # until the robot's connect begins nothing exists to send it anything; during it, not the controller
                desc = hardware.description
                ctrl = spec.make(desc)
                dt = 1.0 / ctrl.rate_hz
                safety = cfg.safety if cfg.safety is not None else SafetyConfig(position_table=hardware.position_table)
                # a robot on the wall clock (its own: the monotonic clock, or a test's): its layer's times in seconds
                # since it was connected; the simulator: robot time
                wall = isinstance(hardware.robot, WallClock)
                wall_time = hardware.robot.wall_time if wall else time.monotonic
                connected_at = [wall_time()]
                safe = SafeRobot(hardware.robot, safety,
                                 clock=(lambda: wall_time() - connected_at[0]) if wall else None)
                robot = EstimatedRobot(safe, desc, BaseEstimate(desc, dt, contact_force=cfg.contact_force))
                console = OperatorConsole(keys, safe.estop, then=observer)
                if isinstance(observer, PreparingObserver):
                    observer.prepare(robot)  # a viewer's meshes load now: the robot's first ticks must not wait
                scheduling = (controller_realtime(cfg.controller_realtime) if cfg.controller_realtime is not None
                              else contextlib.nullcontext(None))
                if before_connect is not None:
                    before_connect(hardware, spec)
                if wall:
                    # all is built: a full collection would stall the link and bus threads (interpreter.py); handed
                    # back to the collector once the robot is closed, for a caller that plays trial after trial
                    stack.enter_context(frozen_heap())
                connected_at[0] = wall_time()
                grant = stack.enter_context(scheduling)
                opening = True
                # stopped after the trial, the I/O process closed the robot itself (damped): its close says so again
                stack.push(lambda kind, exc, tb: bool(io_stopped) and isinstance(exc, IoProcessStopped))
                stack.enter_context(robot)
            except (KeyboardInterrupt, IoProcessStopped) as stopped:
                raise ConnectInterrupted(opening=opening) from stopped
            _stand_up(robot, safe, console, cfg.settle_s, on_wall_clock=wall)
            stale_frames_before = _stale_frames(hardware.robot)  # before the trial's clock starts
            started_s = safe.now()
            io_robot = hardware.robot if isinstance(hardware.robot, ProcessRobot) else None
            io_cpu0 = io_robot.link_stats().io["cpu_s"] if io_robot is not None else 0.0
            cpu0, wall0 = time.process_time(), time.perf_counter()
            error = ""
            interruption: Interruption | None = None

            def damp_at_once(stopped: BaseException) -> None:
                # the robot first, before the episode played is built: the layer latches its damping and sends it now
                # (the close sends it again), as soon as the unwinding to the close used to
                try:
                    safe.estop(f"the command was interrupted during the trial ({_interrupted_by(stopped)})")
                except IoProcessStopped as exc:  # stopped by the same SIGTERM: it closed the robot itself
                    io_stopped.append(exc)
                except Exception:  # noqa: BLE001 (a link failing, an event callback raising: the interruption goes
                    # on as what it is, and the robot's close sends the damping again; its results are still written)
                    pass

            try:
                # the I/O process stopped by SIGTERM (to the whole command, or to it alone) closed the robot itself:
                # a request to end, as Ctrl-C is, which keeps what was played
                episode = run_episode(robot, ctrl, trial.command, trial.duration_s, truth=robot.base_estimate,
                                      fallen=lambda: False, observer=console,
                                      stopped=lambda: safe.safety_state is SafetyState.DAMPED,
                                      stopped_by=(IoProcessStopped,), on_interrupt=damp_at_once)
            except ControllerFailure as failure:
                episode, error = failure.episode, failure.record_error(spec.name, trial)
                if safe.safety_state is not SafetyState.DAMPED:
                    safe.estop()  # the robot must not keep the broken controller's last command
            except EpisodeInterrupted as interrupted:  # the robot is damped already (`damp_at_once`)
                interruption = Interruption.of(interrupted)
                if isinstance(interrupted.__cause__, IoProcessStopped) and not io_stopped:
                    io_stopped.append(interrupted.__cause__)
                episode = interrupted.episode
            cpu_s, episode_wall_s = time.process_time() - cpu0, time.perf_counter() - wall0
            # the trial is over: from here a request to end keeps its record; the settle after a trip (its robot
            # already damped by the latched layer) is cut short, and the robot closed into damping. An interruption
            # during the trial was such a request already: a further one waits for the results, a second stops them
            deferred.enter_context(after_the_trial)

            def unless_stopped(read: Callable[[], _T], otherwise: _T) -> _T:
                # `read()`, or `otherwise` once a request to end sent to the command's whole group stopped its I/O
                # process: that closed the robot itself (damped), and answers no more
                if io_stopped:
                    return otherwise
                try:
                    return read()
                except IoProcessStopped as exc:
                    if after_the_trial.requested is None and interruption is None:
                        raise
                    io_stopped.append(exc)
                    return otherwise

            if isinstance(hardware.robot, HasLinkStats):
                link = unless_stopped(hardware.robot.link_stats, None)
            io_cpu_s = link.io["cpu_s"] - io_cpu0 if io_robot is not None and link is not None else None
            arm_faults = unless_stopped(lambda: _latched_faults(hardware.robot), ())
            stale_frames = unless_stopped(lambda: _stale_frames(hardware.robot), None)
            # no settle after an interruption: it is a request to end, which cuts any settle short; the robot is
            # damped by the latched layer already, and its close leaves it damped
            if safe.safety_state is SafetyState.DAMPED and interruption is None:
                settling[0] = True
                unless_stopped(lambda: _settle(robot, dt, cfg.settle_s,
                                               until=lambda: after_the_trial.requested is not None), None)
                settling[0] = False
            stale_frames = unless_stopped(lambda: _stale_frames(hardware.robot), stale_frames)  # the settle's too
            refused = (stale_frames - stale_frames_before if stale_frames is not None
                       and stale_frames_before is not None else None)
            link_lost = unless_stopped(lambda: _link_lost(safe, started_s, refused), None) if wall else None
            arm_faults = unless_stopped(lambda: _latched_faults(hardware.robot), arm_faults)  # the settle's too
            # from the bus's clock (the robot's wall clock, as the layer's) to the trial's, as the episode's times
            trial_zero = connected_at[0] + started_s if wall else 0.0
            arm_faults = tuple(dataclasses.replace(f, time=f.time - trial_zero) for f in arm_faults)
        # the layer's transitions on the trial's clock, as the episode's other times (the layer counts from the
        # connect, and the stand-up before the trial took `started_s` of it)
        episode = dataclasses.replace(episode, base_source="estimator", operator_events=console.log(),
                                      safety_events=episode.safety_events.shifted(-started_s))
        counters, error = read_counters(ctrl, spec.name, trial, episode, error)
        record = TrialRecord.of_trial(trial, controller=spec.name, episode=episode,
                                      counters=counters, wall_s=episode_wall_s,
                                      backend=hardware.backend, domain_applied=False, link=link, error=error,
                                      interrupted=interruption.describe(trial.duration_s) if interruption else "")
        result = HardwareTrialResult(record=record, episode=episode, out_dir=out, controller=spec, robot=hardware,
                                     notes=notes, link=link, cpu_s=cpu_s, episode_wall_s=episode_wall_s,
                                     safety_events=safe.events, trial_started_s=started_s, io_cpu_s=io_cpu_s,
                                     controller_realtime=grant, link_lost=link_lost, arm_faults=arm_faults,
                                     interrupted=interruption, stale_frames=stale_frames)
        during = interruption.when(trial.duration_s) if interruption is not None else None
        try:
            _write_results(cfg, result, trial, lock, published=scenario_published)
        except KeyboardInterrupt:
            raise ResultsInterrupted(out, during=during) from None
    if after_the_trial.requested or interruption is not None:
        raise ResultsInterrupted(out, complete=True, during=during)
    return result


class ConnectInterrupted(KeyboardInterrupt):
    """A hardware trial interrupted before its robot was connected (Ctrl-C, SIGTERM, its I/O process stopped).

    Neither the controller nor the safety layer had sent the robot anything: there was nothing to close into damping.

    Attributes:
        opening: False when it came before the robot's connect began (the confirmation, the viewer's meshes): nothing
            was opened; True when it came while the robot was being connected (its I/O process starting, its link
            waiting for the first state): what its devices had opened was closed again.
    """

    def __init__(self, *, opening: bool) -> None:
        super().__init__("while connecting the robot" if opening else "before connecting the robot")
        self.opening = opening


class ResultsInterrupted(KeyboardInterrupt):
    """A hardware trial interrupted during or after its play, its robot closed into damping and its results written.

    Interrupted during the trial, the robot was closed into damping at once, and the results hold the episode up to the
    interruption (`during` says when); after the trial (its end, a trip, an e-stop), the results hold all of it.

    Attributes:
        out_dir: the results directory.
        complete: whether the results were written whole (the interruption waited for them) or the writing was
            stopped (a second interruption): then the directory holds what was written until then.
        during: when the trial was interrupted, ``at 1.240 s of the 3 s trial (Ctrl-C)`` (`Interruption.when`);
            None when it was interrupted after it.
    """

    def __init__(self, out_dir: Path, *, complete: bool = False, during: str | None = None) -> None:
        super().__init__(str(out_dir))
        self.out_dir = out_dir
        self.complete = complete
        self.during = during


def _interrupted_by(stopped: BaseException | None) -> str:
    """What interrupted the trial (`Interruption.by`), from the interruption: ``Ctrl-C``, ``SIGTERM`` ..."""
    if isinstance(stopped, IoProcessStopped):
        return f"its I/O process stopped by {stopped.signal_name}"
    # the command's SIGTERM and SIGHUP raise `KeyboardInterrupt` with their name (`_terminate_interrupts`); Python's own
    # Ctrl-C handler raises it bare
    named = stopped.args[0] if stopped is not None and stopped.args else None
    return named if isinstance(named, str) and named in {signal_label(s) for s in ASKS_TO_END} else "Ctrl-C"


def _simulated(robot: str, arm_mode: str) -> HardwareRobot:
    """The hardware protocol's twin: the simulated robot on flat ground, its domain not randomised."""
    if robot not in HARDWARE_ROBOTS:
        raise UnknownNameError("hardware robot", robot, tuple(HARDWARE_ROBOTS))
    sim = MujocoRobot(MujocoRobotConfig(robot=robot, arm_mode=arm_mode))
    return HardwareRobot(robot=sim, description=sim.desc, backend="sim", position_table=HARDWARE_ROBOTS[robot],
                         target="simulator (flat ground, no domain randomisation, not paced)")


def _skipped(trial: Trial) -> tuple[str, ...]:
    """What of the simulated trial a robot does not play, one line each."""
    notes = []
    if trial.pushes:
        notes.append(f"pushes: the trial's {len(trial.pushes)} push(es) (largest {trial.push_force_n:.0f} N) are "
                     "the simulator's and were SKIPPED: the robot cannot apply them; an operator's push by hand is "
                     f"marked with the key {_key_for('push')!r}")
    if trial.terrain.kind != "flat":
        notes.append(f"terrain: the trial's {trial.terrain.kind} ground (amplitude {trial.terrain.amplitude} m, "
                     f"seed {trial.terrain_seed}) is the simulator's; the robot played on the ground it stood on")
    notes.append(f"domain: friction {trial.domain.friction:.3f} and payload {trial.domain.payload_mass:.2f} kg are "
                 "the simulator's randomisation, not applied (NaN in trials.csv)")
    notes.append("metrics: base velocity, yaw rate, roll, pitch and the replayed base pose come from the state "
                 "estimator (IMU and leg kinematics), not from simulator truth (metrics_source = estimator)")
    return tuple(notes)


def _key_for(action: str) -> str:
    return next(k for k, a in OPERATOR_ACTIONS.items() if a == action and k.strip())


def _stand_up(robot: EstimatedRobot, safe: SafeRobot, console: OperatorConsole, settle_s: float, *,
              on_wall_clock: bool) -> None:
    """Ramp the robot into the stand hold of its nominal pose until the safety layer is in ``run``.

    The operator's e-stop works meanwhile (`OperatorConsole.before_trial`).

    Args:
        robot: the robot, seen through its sensors.
        safe: its safety layer.
        console: the operator's keys.
        settle_s: how long a tripped robot is held damped, still read, before the error [s].
        on_wall_clock: the robot runs on the wall clock (a robot over its wire, not the simulator): a state stream
            still silent after the settle is a lost link, which the error then reports (`LinkLost`).

    Raises:
        StandUpError: the layer tripped, or the ramp did not finish within its time plus the slowest joint's travel
            at the slew rate (and a second); the robot is held damped for `settle_s` first. When the robot stopped
            answering, the message says that the damping may not have reached it, and to power it down by hand.
    """
    hold = stand_command(robot.description)
    cfg = safe.config
    budget = cfg.ramp_hold_s + cfg.ramp_time_s + math.pi / cfg.ramp_slew + 1.0  # no joint needs to travel more than pi
    for k in range(int(math.ceil(budget / _STAND_UP_DT))):
        robot.read()
        robot.write(hold)
        robot.advance(_STAND_UP_DT)
        console.before_trial((k + 1) * _STAND_UP_DT - budget)  # negative: the trial's clock has not started
        if safe.safety_state in (SafetyState.RUN, SafetyState.DAMPED):
            break
    if safe.safety_state is SafetyState.RUN:
        return
    if safe.safety_state is SafetyState.DAMPED:
        _settle(robot, _STAND_UP_DT, settle_s)
        last = safe.events[-1]
        lost = _link_lost(safe, None) if on_wall_clock else None
        # each reason its own remedy: a remote e-stop or a hot motor is not a pose out of range; a robot that stopped
        # answering may not have heard the damping either
        lost_said = f"{lost.sentence()} " if lost is not None else ""
        raise StandUpError(f"the safety layer tripped while standing the robot up, before the trial: {last.reason} "
                           f"({last.detail}); nothing was played. {lost_said}{last.remedy} Then run again")
    raise StandUpError(f"the safety layer's ramp did not reach the standing pose within {budget:.1f} s (state "
                       f"{safe.safety_state}); nothing was played")


def _link_lost(safe: SafeRobot, started_s: float | None, refused_frames: int | None = None) -> LinkLost | None:
    """A `LinkLost` when the robot's own link brought no state for longer than the layer's stale timeout, now.

    `started_s` is when the trial began on the layer's clock; None during the stand-up. `refused_frames`: the frames
    the legs' link refused for their tick since then (a frozen board's), None when not known.

    The robot's own link is the one its link counters name (`LinkStatsLike.state_age`: a quadruped's legs'), not the
    layer's fresh frames: a robot with an arm joins the arm's bus into every frame, so an arm that stopped answering, or
    whose fault froze its state, leaves the frames stale while the legs still answer and take the damping; that is the
    arm's fault (`HardwareTrialResult.arm_faults`), not a lost link. A robot without such counters is judged by the
    layer's fresh frames. A control loop that stalled trips the layer on the same timeout, but the states come again as
    soon as it reads: after the settle's reads, only a robot that stopped answering is still silent.
    """
    now = safe.now()
    age = safe.robot.link_stats().state_age if isinstance(safe.robot, HasLinkStats) else None
    last = now - age if age is not None else safe.last_fresh_time
    if now - last <= safe.config.stale_timeout_s:
        return None
    return LinkLost(last_state_s=last, silent_s=now - last, trial_started_s=started_s, refused_frames=refused_frames)


def _latched_faults(robot: object) -> tuple[ArmFault, ...]:
    """The faults the robot's devices latched (its arm's bus), before its close; none for a robot that latches none."""
    # by its class: on Python 3.11 an isinstance check of a protocol reads the property, a round trip to the I/O process
    return robot.faults if isinstance(getattr(type(robot), "faults", None), property) else ()


def _stale_frames(robot: object) -> int | None:
    """The legs' link's frames refused for their tick (`UnitreeRobot.stale_frames`, `ProcessRobot`'s), or None."""
    legs = getattr(robot, "legs", robot)  # a QuadrupedArmRobot's legs; any other robot is its own
    return legs.stale_frames if isinstance(getattr(type(legs), "stale_frames", None), property) else None


def _settle(robot: EstimatedRobot, dt: float, seconds: float, *, until: Callable[[], bool] = lambda: False) -> None:
    """Keep reading and pacing the tripped robot for `seconds` while its safety layer sends damping.

    It ends sooner once `until` is true (a request to end the command).
    """
    damping = MotorCommand.damping(robot.num_joints, 0.0)  # replaced by the layer's own damping: it is latched
    for _ in range(int(round(seconds / dt))):
        if until():
            return
        robot.read()
        robot.write(damping)
        robot.advance(dt)


def _write_results(cfg: HardwareTrialConfig, result: HardwareTrialResult, trial: Trial, lock: DirectoryLock, *,
                   published: bool) -> None:
    record, episode, hardware = result.record, result.episode, result.robot
    grant = hardware.robot.realtime_grant if isinstance(hardware.robot, HasRealtimeGrant) else None
    scenario_name, scenario_hash = trial.scenario, trial.scenario_hash
    identity = HardwareRunIdentity(
        controllers=(record.controller,),
        scenario=ScenarioRef(path=str(cfg.scenario), name=scenario_name, hash=scenario_hash, published=published),
        bands=(trial.band,), seeds=(trial.seed,), trial=trial.index, duration_s=trial.duration_s,
        robot=hardware.description.name, arm_mode=hardware.description.arm_mode, backend=hardware.backend,
        target=hardware.target,
    )
    store = ResultsStore(result.out_dir, identity, resume=False,
                         controllers={result.controller.name: result.controller.provenance()}, resumable=False,
                         lock=lock)
    try:  # the directory stays held (`lock`) until its report is written, and the trial's caller gives it back
        store.append(record)
        path = episode_path(store.dir, record.controller, trial.band, trial.seed, trial.index)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            episode.save(str(path))
        except OSError as exc:
            raise unwritable(path, exc, store.dir, stored=1, resumable=False) from exc
        guard = ErrorGuard([record.controller], 0, ())
        guard.observe(record)
        summary = summarize([record], scenario_name=scenario_name, scenario_hash=scenario_hash,
                            controllers=[record.controller], bands=[trial.band], errors=guard.report([record], 1))
        hardware_json = {
            "robot": hardware.description.name, "arm_mode": hardware.description.arm_mode, "backend": hardware.backend,
            "target": hardware.target, "control_rate_hz": 1.0 / episode.control_dt, "notes": list(result.notes),
            "episode_wall_s": result.episode_wall_s, "cpu_s": result.cpu_s, "io_cpu_s": result.io_cpu_s,
            "link": result.link.as_dict(prefix="") if result.link is not None else None,
            "stale_frames": result.stale_frames,  # leg frames refused for their tick (a frozen or restarted board)
            "trial_started_s": result.trial_started_s,
            "realtime": grant.to_dict() if grant is not None else None,  # the devices' process: asked, granted, refused
            "controller_realtime": (result.controller_realtime.to_dict() if result.controller_realtime is not None
                                    else None),  # the controller's loop
            "safety_events": [e.to_dict() for e in result.safety_events],
            "link_lost": result.link_lost.to_dict() if result.link_lost is not None else None,
            "arm_faults": [dataclasses.asdict(fault) for fault in result.arm_faults],
            "interrupted": result.interrupted.to_dict() if result.interrupted is not None else None,
            "operator_events": [{"time": t, "key": k, "action": a} for t, k, a in episode.operator_events.rows()],
            "clocks": HARDWARE_JSON_CLOCKS,
        }
        try:
            write_text(store.dir / "hardware.json", json.dumps(hardware_json, indent=2))
        except OSError as exc:
            raise unwritable(exc.filename, exc, store.dir, stored=1, resumable=False) from exc
        meta = {
            "controller": (record.controller if record.controller == cfg.controller else
                           f"{record.controller} ({cfg.controller} on a robot with arm mode "
                           f"{hardware.description.arm_mode})"),
            "robot": f"{hardware.description.name}, arm {hardware.description.arm_mode}, backend {hardware.backend}, "
                     f"{hardware.target}",
            "scenario": f"{scenario_name} ({cfg.scenario}), written for {trial.robot}",
            "scenario hash": scenario_hash,
            "published scenario": "yes" if published else "NO (results are not comparable with published ones)",
            "trial": f"band {trial.band}, seed {trial.seed}, trial {trial.index}, {trial.duration_s:g} s",
            "metrics source": "the state estimator (IMU and leg kinematics): a robot has no simulator truth",
            **report_lines(store.environment),
        }
        finish_results(store.dir, summary, [record], meta, sections=_hardware_sections(result), resumable=False)
    finally:
        store.close()


def _hardware_sections(result: HardwareTrialResult) -> list[tuple[str, list[str]]]:
    record, episode, link, events = result.record, result.episode, result.link, result.safety_events
    period_ms = episode.control_dt * 1e3
    grant = result.robot.robot.realtime_grant if isinstance(result.robot.robot, HasRealtimeGrant) else None
    rows = [
        ("devices' scheduling (I/O process)",
         grant.describe() if grant is not None else "not requested: the devices ran in the controller's process, "
                                                    "with ordinary scheduling"),
        ("controller loop's scheduling", result.controller_realtime.describe()
         if result.controller_realtime is not None else "not requested: ordinary scheduling"),
        ("ticks played", f"{len(episode.t)} of {int(round(episode.duration_s / episode.control_dt))} at "
                         f"{1.0 / episode.control_dt:g} Hz"),
        ("controller act p50 / p99 / max [ms]",
         f"{record.act_ms_p50:.3f} / {record.act_ms_p99:.3f} / {record.act_ms_max:.3f} "
         f"(period {period_ms:g} ms)"),
        ("deadline misses (act longer than the period)", f"{record.deadline_misses} of {len(episode.t)}"),
        ("write-deadline dampings ramped again (the loop stalled past a device's write deadline)",
         str(record.write_deadline_ramps)),
        *([("leg frames refused for their tick (stale_frames: a frozen or restarted board)", str(result.stale_frames))]
          if result.stale_frames is not None else []),
        ("late advances (the loop reached the robot's clock after its deadline)",
         f"{record.late_advances}, worst {record.worst_lateness_ms:.2f} ms"),
        ("process CPU during the episode", f"{result.cpu_s:.2f} s over {result.episode_wall_s:.2f} s wall "
                                           f"({100.0 * result.cpu_s / max(result.episode_wall_s, 1e-9):.0f} % of "
                                           "one core" + (", link thread included)" if result.io_cpu_s is None
                                                         else f"; the I/O process {result.io_cpu_s:.2f} s)")),
    ]
    if link is not None:
        for key, value in link.as_dict(prefix="link ").items():
            rows.append((key, f"{value:.6g}" if isinstance(value, float) else str(value)))
    sections = [("Hardware trial", ["What the simulator does and a robot does not:", "",
                                    *(f"- {n}" for n in result.notes), "", *md_table(["quantity", "value"], rows)])]
    if events:
        body = md_table(["time [s]", "from", "to", "reason", "detail"],
                        [(f"{e.time:.3f}", str(e.from_state), str(e.to_state), e.reason, e.detail) for e in events])
        trips = sum(1 for e in events if e.to_state is SafetyState.DAMPED)
        first = next((e for e in events if e.to_state is SafetyState.DAMPED), None)
        # an interruption's own trip is the command's (its section says so), not a key pressed on this computer
        remedy = f" What to do: {first.remedy}" if first is not None and result.interrupted is None else ""
        lead = (f"The safety layer tripped {trips} time(s); the episode ended at the first trip"
                f" ({first.reason}).{remedy}" if first is not None else "The safety layer did not trip.")
        sections.append(("Safety events", [f"{lead} Times are wall-clock seconds since the robot was connected; the "
                                           "robot was stood up first, and the trial began at "
                                           f"{result.trial_started_s:.3f} s.", "", *body]))
    else:
        sections.append(("Safety events", ["None recorded."]))
    if result.arm_faults:
        sections.append(("Arm faults", ["The arm's bus latched these faults (times on the trial's clock, as the "
                                        "operator's actions; negative: during the stand-up), each with the torque "
                                        "policy it applied:", "",
                                        *(f"- at {fault.time:.3f} s: {fault}" for fault in result.arm_faults)]))
    if result.link_lost is not None:
        sections.append(("Link lost", [result.link_lost.sentence()]))
    if result.interrupted is not None:
        said = result.interrupted.describe(episode.duration_s)
        sections.append(("Interrupted", [f"{said[0].upper()}{said[1:]} ({len(episode.t)} ticks); the trial counts "
                                         "as stopped (operator_stop), not as a success."]))
    actions = episode.operator_events.rows()
    sections.append(("Operator actions", md_table(["trial time [s]", "key", "action"],
                                                  [(f"{t:.3f}", repr(k), a) for t, k, a in actions])
                     if actions else ["None (keys: " + ", ".join(f"{k!r} {a}" for k, a in OPERATOR_ACTIONS.items())
                                      + ")."]))
    return sections
