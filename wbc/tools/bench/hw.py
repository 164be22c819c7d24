"""``wbc bench hw``: the Unitree low-level link's timing over loopback, against an emulator in another process.

A `UnitreeRobot` talks to a `UnitreeEmulator` (lockstep: one state answers each command, so a reply can be paired
with the command that caused it) that runs in a process of its own, as the robot is another machine on a real
link. The robot's transport is wrapped (`TimedTransport`) to timestamp every send and every received datagram in
the link thread itself, and to read that thread's CPU clock at each send: the link thread's own statistics
(`UnitreeRobot.thread_stats`) cover the whole connection, start-up included, and keep no round trips, so the bench
times the measured seconds itself. While the link runs, the bench writes a standing hold every link period, as a
control loop would. Both processes share this machine's cores, so the figures include that contention; a real
robot's firmware would not.

`bench_safety` times what the test suite checks in link periods on a clock it moves (`tests/test_hardware_faults.py`,
`tests/test_unitree_robot.py`, `tests/test_hw_run.py`), here in real time: SafeRobot(UnitreeRobot) against a
real-time `UnitreeEmulator` on 127.0.0.1 (its UDP server thread, in this process, as those tests' realtime twins
run it). Each reaction is timed from its cause to the first damping frame the emulator decoded off the wire: a
software e-stop, a silent state stream (the layer's stale timeout), a stalled control loop (the link's write
deadline), a state fault (a hot motor); and a stand through the whole stack, with the real-time factor it achieved
(simulated seconds per wall-clock second) and the link's period over it.
"""

from __future__ import annotations

import gc
import json
import select
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, fields

import numpy as np

from wbc.control.stand import StandController, stand_command
from wbc.errors import BenchError
from wbc.hardware.emulators import Fault, UnitreeEmulator, UnitreeEmulatorConfig
from wbc.hardware.interpreter import child_process_env, freeze_heap, realtime_switch_interval, wbc_interpreter_env
from wbc.hardware.realtime import NO_REALTIME, RealtimeRequest, controller_realtime, request_realtime
from wbc.hardware.robot import load_write_check
from wbc.hardware.safety import SafeRobot, SafetyConfig, SafetyState
from wbc.hardware.unitree import (
    REJECT_REASONS,
    LinkStats,
    SdkTransport,
    Transport,
    UdpTransport,
    UnitreeRobot,
    UnitreeRobotConfig,
)
from wbc.tools.bench.references import load_1min, machine_description
from wbc.types import MotorCommand

__all__ = ["EmulatorCounts", "HwBenchResult", "SafetyBenchResult", "TimedTransport", "bench_hw", "bench_safety",
           "serve_emulator_stdio"]

_START_TIMEOUT = 60.0  # [s] longest wait for the emulator process to bind its port (it imports MuJoCo first)
_STOP_MARGIN = 30.0  # [s] the emulator process stops by itself this long after the bench should have ended
_SAFETY_LOOP = 0.004  # [s] the control loop's period while a safety reaction is timed (the tests' PERIOD)
_REACTION_TIMEOUT = 2.0  # [s] longest wait for a reaction's damping frame on the wire


@dataclass(frozen=True, kw_only=True)
class EmulatorCounts:
    """What an emulator counted on its side of the wire.

    Attributes:
        accepted: command frames decoded.
        rejected: command frames rejected, by reason (`REJECT_REASONS`).
        refused: valid frames whose gains a motor cannot apply (negative): no torque was applied.
        replies: state datagrams sent.
    """

    accepted: int
    rejected: dict[str, int]
    refused: int
    replies: int

    @classmethod
    def of(cls, emulator: UnitreeEmulator) -> EmulatorCounts:
        """The counts of `emulator` now."""
        return cls(accepted=emulator.stats.accepted,
                   rejected={r: getattr(emulator.stats, r) for r in REJECT_REASONS},
                   refused=emulator.refused, replies=emulator.replies)

    def as_dict(self) -> dict[str, object]:
        """The counts as a plain dict (for JSON)."""
        return asdict(self)


@dataclass(frozen=True, kw_only=True)
class SafetyBenchResult:
    """What `bench_safety` timed: SafeRobot(UnitreeRobot)'s reactions on the wire, and a stand, in real time.

    Attributes:
        robot: ``a1`` or ``go1``.
        write_deadline_ms: the link's write deadline [ms].
        link_period_ms: the link's period [ms].
        stale_timeout_ms: the safety layer's stale-state timeout [ms].
        estop_to_damping_ms: a software e-stop to the first damping frame on the wire [ms].
        silence_to_damping_ms: the state stream stopped -> damping [ms] (judged by `stale_timeout_ms`).
        stall_to_damping_ms: the control loop's last write -> the link's damping [ms] (by `write_deadline_ms`).
        state_fault_to_damping_ms: a motor reported hot -> damping [ms].
        stand_seconds: how long the stand was asked to run [s].
        stand_wall_s: the wall time it took [s].
        stand_sim_s: the emulated robot's time meanwhile [s].
        stand_realtime_factor: `stand_sim_s` over `stand_wall_s` (nan if no wall time passed).
        stand_safety_state: the layer's state at the end (``run`` unless it tripped).
        stand_trips: the layer's trips during the stand, with their detail.
        stand_link_period_ms_mean: the link's mean send period over the stand [ms].
        stand_link_period_ms_max: its longest send period [ms].
        stand_deadline_trips: times the link's write deadline expired.
        stand_act_ms_p99: 99th percentile of the stand controller's ``act`` [ms].
        stand_deadline_misses: ``act`` calls longer than the controller's period.
    """

    robot: str
    write_deadline_ms: float
    link_period_ms: float
    stale_timeout_ms: float
    estop_to_damping_ms: float
    silence_to_damping_ms: float
    stall_to_damping_ms: float
    state_fault_to_damping_ms: float
    stand_seconds: float
    stand_wall_s: float
    stand_sim_s: float
    stand_realtime_factor: float
    stand_safety_state: str
    stand_trips: tuple[str, ...]
    stand_link_period_ms_mean: float
    stand_link_period_ms_max: float
    stand_deadline_trips: int
    stand_act_ms_p99: float
    stand_deadline_misses: int

    def as_dict(self) -> dict[str, object]:
        """Plain dict, keys as the attributes' names (``safety`` in ``wbc bench hw``'s JSON)."""
        return {**asdict(self), "stand_trips": list(self.stand_trips)}


@dataclass(frozen=True, kw_only=True)
class HwBenchResult:
    """What `bench_hw` measured: the Unitree link's timing over loopback, against an emulator in its own process.

    Attributes:
        robot: ``a1`` or ``go1``.
        seconds: how long the link ran while measured [s].
        rate_hz: the link thread's rate [Hz].
        transport: ``udp`` or ``sdk``.
        emulator_process: how the emulator ran.
        sends: command frames the link thread sent from its start (the connection's start-up included) to the end
            of the measurement; the frames it sends as it closes are not counted.
        replies_received: state datagrams it took over the same window.
        period_ms_p50: median interval between two sends of the link thread [ms].
        period_ms_p99: its 99th percentile [ms].
        period_ms_max: the longest such interval [ms].
        round_trip_ms_p50: median time from a command's send to the arrival of the state the emulator answered it
            with, paired in order [ms].
        round_trip_ms_p99: its 99th percentile [ms].
        cpu_us_per_tick: the link thread's CPU time per period [us].
        advance_ms_p50: median time the control loop's ``advance(period)`` took (pacing plus the wait for a fresh
            state) [ms].
        advance_ms_p99: its 99th percentile [ms].
        late_advances: advance calls that found their deadline past.
        worst_lateness_ms: by how much the latest of them was late [ms].
        rejects: state frames the robot rejected, over the same window as `sends`.
        emulator: the emulator's counts over its whole session: every frame the link sent, the damping frames it
            sends as it closes (`UnitreeRobotConfig.close_damping`) included, so more than `sends`.
        link: the link's own counters.
        safety: `bench_safety`'s figures, or None when they were not measured.
        machine: `machine_description`.
        load_1min: the 1-minute load average at the end of the measurement (nan where the OS has none).
        realtime: what the bench's own process (the link's side, as the I/O process on a robot) asked the OS for
            and got, in words (`wbc.hardware.realtime`).
        emulator_realtime: the same for the emulator's process (it stands in for the robot's own processors).
    """

    robot: str
    seconds: float
    rate_hz: float
    transport: str
    emulator_process: str
    sends: int
    replies_received: int
    period_ms_p50: float
    period_ms_p99: float
    period_ms_max: float
    round_trip_ms_p50: float
    round_trip_ms_p99: float
    cpu_us_per_tick: float
    advance_ms_p50: float
    advance_ms_p99: float
    late_advances: int
    worst_lateness_ms: float
    rejects: int
    emulator: EmulatorCounts
    link: LinkStats
    safety: SafetyBenchResult | None
    machine: str
    load_1min: float = float("nan")
    realtime: str = "nothing asked"
    emulator_realtime: str = "nothing asked"

    def as_dict(self) -> dict[str, object]:
        """Plain dict (the JSON output of ``wbc bench hw``): ``emulator``, ``link`` and ``safety`` nested."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out.update(emulator=self.emulator.as_dict(), link=asdict(self.link),
                   safety=self.safety.as_dict() if self.safety is not None else None)
        return out


class TimedTransport:
    """A `Transport` that passes everything through and timestamps it, in the thread that calls it (the link's).

    Args:
        inner: the transport that really sends.
    """

    def __init__(self, inner: Transport) -> None:
        self._inner = inner
        self.recording = True
        self.send_times: list[float] = []  # [s] time.perf_counter at each send
        self.send_cpu: list[float] = []  # [s] time.thread_time of the calling thread at each send
        self.receive_times: list[float] = []  # [s] time.perf_counter when each datagram was taken

    @property
    def foreign(self) -> int:
        """Datagrams the inner transport dropped as foreign."""
        return self._inner.foreign

    def send(self, frame: bytes) -> None:
        """Send through the inner transport, recording when and at what thread CPU time."""
        if self.recording:
            self.send_times.append(time.perf_counter())
            self.send_cpu.append(time.thread_time())
        self._inner.send(frame)

    def receive(self) -> list[bytes]:
        """Every queued datagram, each timestamped."""
        out = self._inner.receive()
        if out and self.recording:
            now = time.perf_counter()
            self.receive_times.extend([now] * len(out))
        return out

    def wait_readable(self, timeout: float) -> bool:
        """Wait on the inner transport."""
        return self._inner.wait_readable(timeout)

    def close(self) -> None:
        """Close the inner transport."""
        self._inner.close()


def serve_emulator_stdio(robot: str, seconds: float, realtime: dict | None = None) -> None:
    """The emulator process's body (``bench_hw`` starts it): lockstep emulator on a free loopback port.

    It builds the emulator, then asks the OS for what `realtime` names (`RealtimeRequest`'s fields; None: nothing)
    before starting it, as ``wbc hw emulate`` does. Writes the address and that grant as a JSON line, serves until a
    line arrives on stdin (or `seconds` plus a margin pass: never longer), then writes the counts (`EmulatorCounts`)
    and any failure as a JSON line.
    """
    realtime_switch_interval()  # the emulated robot answers its wires promptly
    emulator = UnitreeEmulator(UnitreeEmulatorConfig(robot=robot, mode="lockstep")).prepare()
    freeze_heap()  # built: its full collections must not stall the answers (as `wbc hw emulate`)
    grant = request_realtime(RealtimeRequest(**realtime) if realtime is not None else NO_REALTIME)
    with emulator as emu:
        host, port = emu.address
        print(json.dumps({"host": host, "port": port, "realtime": grant.describe()}), flush=True)
        select.select([sys.stdin], [], [], seconds + _STOP_MARGIN)
        counts = EmulatorCounts.of(emu)
        failure = repr(emu.failure) if emu.failure is not None else None
    print(json.dumps({"counts": counts.as_dict(), "failure": failure}), flush=True)


def _start_emulator_process(robot: str, seconds: float, realtime: RealtimeRequest) -> subprocess.Popen[str]:
    # a fresh interpreter rather than multiprocessing: its spawn re-imports the parent's __main__, which for
    # ``python -m wbc.cli`` would run the command again
    env = wbc_interpreter_env(child_process_env())  # no BLAS pool: memory the emulator would lock
    code = (f"from wbc.tools.bench.hw import serve_emulator_stdio; serve_emulator_stdio({robot!r}, {seconds!r}, "
            f"{asdict(realtime)!r})")
    return subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            env=env)


def _read_json_line(proc: subprocess.Popen[str], timeout: float, what: str) -> dict:
    if not select.select([proc.stdout], [], [], timeout)[0]:
        raise BenchError(f"bench hw: the emulator process did not {what} within {timeout} s")
    line = proc.stdout.readline()
    try:
        return json.loads(line)
    except json.JSONDecodeError:
        raise BenchError(f"bench hw: the emulator process did not {what} (it wrote {line!r}; exit status "
                         f"{proc.poll()})") from None


def _percentile_ms(values: np.ndarray, q: float) -> float:
    return float(1e3 * np.percentile(values, q)) if values.size else float("nan")


def bench_hw(robot: str = "go1", *, seconds: float = 3.0, rate_hz: float = 500.0,
             transport: str = "udp", stand_seconds: float | None = 10.0, realtime: RealtimeRequest = NO_REALTIME,
             emulator_realtime: RealtimeRequest = NO_REALTIME) -> HwBenchResult:
    """Time the low-level link over loopback against an emulator in its own process.

    Args:
        robot: ``a1`` or ``go1``.
        seconds: how long the link runs while measured [s].
        rate_hz: the link thread's rate, 200..1000 [Hz].
        transport: ``udp`` (our socket) or ``sdk`` (the vendor's Go1 SDK), see `UnitreeRobotConfig.transport`.
        stand_seconds: the stand of `bench_safety`, whose figures go under ``safety`` [s]; None: none of them.
        realtime: what this thread asks the OS for while the link is measured (restored afterwards; the link thread
            it starts inherits it), as the I/O process does on a robot.
        emulator_realtime: what the emulator's process asks for.

    Returns:
        The send period's and round trip's percentiles, the link thread's CPU per tick, the control loop's advance
        times and lateness, the rejects, the emulator's counts and the link's own counters, `bench_safety`'s figures
        (with `stand_seconds`), the settings and the machine.

    Raises:
        UnknownNameError: `robot` is not ``a1`` or ``go1``, or `transport` is not a transport's name.
        ConfigError: `rate_hz` is out of range, or the vendor SDK was asked for an A1 or is not installed.
        BenchError: the emulator process did not start, or failed.
    """
    UnitreeRobotConfig(robot=robot, target_host="127.0.0.1", target_port=1, rate_hz=rate_hz,
                       transport=transport)  # validate first
    if not seconds > 0:
        raise BenchError(f"bench hw: --seconds must be > 0, got {seconds}")
    proc = _start_emulator_process(robot, seconds, emulator_realtime)
    try:
        address = _read_json_line(proc, _START_TIMEOUT, "bind a port")
        emulator_grant = str(address.get("realtime", "nothing asked"))
        host, port = address["host"], int(address["port"])
        cfg = UnitreeRobotConfig(robot=robot, target_host=host, target_port=port, rate_hz=rate_hz,
                                 transport=transport)
        channel = SdkTransport if transport == "sdk" else UdpTransport
        timed = TimedTransport(channel((cfg.local_host, 0), (host, port)))
        link = UnitreeRobot(cfg, transport=timed)
        load_write_check()  # its first compiled call, before a real-time priority: as the I/O process does
        freeze_heap()  # as `wbc hw run` does once all is built: a full collection would stall the link's thread
        try:
            with controller_realtime(realtime) as grant, link:
                hold = MotorCommand.hold(link.desc.nominal_q, 20.0, 0.5)
                period = 1.0 / rate_hz
                end = time.monotonic() + seconds
                advances = []
                for _ in range(int(seconds * rate_hz) + 2):
                    if time.monotonic() >= end:
                        break
                    link.write(hold)
                    before = time.perf_counter()
                    link.advance(period)
                    advances.append(time.perf_counter() - before)
                timed.recording = False
                stats = link.link_stats()
                rejects = link.decode_stats.rejected
                load = load_1min()
        finally:
            gc.unfreeze()  # a library call: what it kept is collected again after it
            timed.close()
        proc.stdin.write("stop\n")
        proc.stdin.flush()
        report = _read_json_line(proc, 10.0, "report its counts")
        if report["failure"] is not None:
            raise BenchError(f"bench hw: the emulator failed: {report['failure']}")
        counts = EmulatorCounts(**report["counts"])
    finally:
        if not proc.stdin.closed:
            proc.stdin.close()  # end of input: the emulator process stops at once, whatever went wrong here
        try:
            proc.wait(timeout=10.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5.0)
    sends = np.asarray(timed.send_times)
    receives = np.asarray(timed.receive_times)
    periods = np.diff(sends)
    n = min(sends.size, receives.size)
    round_trips = receives[:n] - sends[:n]
    cpu = np.asarray(timed.send_cpu)
    cpu_per_tick = float(1e6 * (cpu[-1] - cpu[0]) / (cpu.size - 1)) if cpu.size > 1 else float("nan")
    safety = bench_safety(robot, stand_seconds=stand_seconds) if stand_seconds is not None else None
    return HwBenchResult(
        robot=robot,
        seconds=seconds,
        rate_hz=rate_hz,
        transport=transport,
        emulator_process="separate process, lockstep",
        sends=int(sends.size),
        replies_received=int(receives.size),
        period_ms_p50=_percentile_ms(periods, 50),
        period_ms_p99=_percentile_ms(periods, 99),
        period_ms_max=float(1e3 * periods.max()) if periods.size else float("nan"),
        round_trip_ms_p50=_percentile_ms(round_trips, 50),
        round_trip_ms_p99=_percentile_ms(round_trips, 99),
        cpu_us_per_tick=cpu_per_tick,
        advance_ms_p50=_percentile_ms(np.asarray(advances), 50),
        advance_ms_p99=_percentile_ms(np.asarray(advances), 99),
        late_advances=stats.late_advances,
        worst_lateness_ms=stats.worst_lateness * 1e3,
        rejects=int(rejects),
        emulator=counts,
        link=stats,
        safety=safety,
        machine=machine_description(),
        load_1min=load,
        realtime=grant.describe() if realtime != NO_REALTIME else "nothing asked",
        emulator_realtime=emulator_grant,
    )


def _drive_to_run(safe: SafeRobot, cmd: MotorCommand) -> None:
    for _ in range(int(5.0 / _SAFETY_LOOP)):
        safe.read()
        safe.write(cmd)
        safe.advance(_SAFETY_LOOP)
        if safe.safety_state is SafetyState.RUN:
            return
    raise BenchError(f"bench hw: the safety layer did not reach run ({[str(e) for e in safe.events]})")


def _first_damping_after(emu: UnitreeEmulator, since: float) -> float:
    """When the first damping frame after `since` arrived at the emulator (its monotonic clock) [s]."""
    end = time.monotonic() + _REACTION_TIMEOUT
    while True:
        found = next((c.time for c in emu.commands() if c.time > since and c.damping), None)
        if found is not None:
            return found
        if time.monotonic() > end:
            raise BenchError(f"bench hw: no damping frame on the wire within {_REACTION_TIMEOUT} s")
        time.sleep(0.0005)


def _estop(emu: UnitreeEmulator, safe: SafeRobot, cmd: MotorCommand) -> float:
    started = time.monotonic()
    safe.estop()
    return started


def _silence(emu: UnitreeEmulator, safe: SafeRobot, cmd: MotorCommand) -> float:
    emu.inject(Fault.SILENCE)
    started = time.monotonic()
    _loop_until_damped(safe, cmd)
    return started


def _stall(emu: UnitreeEmulator, safe: SafeRobot, cmd: MotorCommand) -> float:
    safe.read()
    safe.write(cmd)
    started = time.monotonic()  # the last write: nothing is written after it
    time.sleep(3 * safe.robot.config.write_deadline)
    return started


def _hot_motor(emu: UnitreeEmulator, safe: SafeRobot, cmd: MotorCommand) -> float:
    emu.inject(Fault.OVER_TEMPERATURE)
    started = time.monotonic()
    _loop_until_damped(safe, cmd)
    return started


def _loop_until_damped(safe: SafeRobot, cmd: MotorCommand) -> None:
    for _ in range(int(_REACTION_TIMEOUT / _SAFETY_LOOP)):
        safe.read()
        safe.write(cmd)
        safe.advance(_SAFETY_LOOP)
        if safe.safety_state is SafetyState.DAMPED:
            return


_REACTIONS = {"estop_to_damping_ms": _estop, "silence_to_damping_ms": _silence, "stall_to_damping_ms": _stall,
              "state_fault_to_damping_ms": _hot_motor}
"""What each timed reaction does to the running stack, returning when its cause began."""


def bench_safety(robot: str = "go1", *, stand_seconds: float = 10.0, rate_hz: float = 500.0) -> SafetyBenchResult:
    """Time the safety reactions and a stand of SafeRobot(UnitreeRobot) against a real-time emulator, in real time.

    Args:
        robot: ``a1`` or ``go1``.
        stand_seconds: how long the stand runs [s] (the suite's acceptance stand is 10 s of robot time).
        rate_hz: the link's rate [Hz].

    Returns:
        Each reaction's time from its cause to the first damping frame on the wire, beside the timeouts that judge
        it, and the stand's wall and emulated time, trips, link period and ``act`` times.

    Raises:
        BenchError: the layer never reached ``run`` for a reaction, or a reaction's damping never reached the wire.
    """
    reactions: dict[str, float] = {}
    with UnitreeEmulator(UnitreeEmulatorConfig(robot=robot, mode="realtime")) as emu:
        host, port = emu.address
        cfg = UnitreeRobotConfig(robot=robot, target_host=host, target_port=port, rate_hz=rate_hz)
        for key, cause in _REACTIONS.items():
            emu.clear()
            emu.reset()
            safety = SafetyConfig(on_event=lambda event: None, ramp_time_s=0.2)
            stale_timeout_ms = safety.stale_timeout_s * 1e3
            with SafeRobot(UnitreeRobot(cfg), safety) as safe:
                cmd = stand_command(safe.robot.desc)
                _drive_to_run(safe, cmd)
                started = cause(emu, safe, cmd)
                reactions[key] = 1e3 * (_first_damping_after(emu, started) - started)
        emu.clear()
        emu.reset()
        trips: list[str] = []
        safety = SafetyConfig(on_event=lambda e: trips.append(str(e)) if e.to_state is SafetyState.DAMPED else None)
        freeze_heap()  # as `wbc hw run` does once all is built: a full collection would stall the threads
        try:
            with SafeRobot(UnitreeRobot(cfg), safety) as safe:
                ctrl = StandController(safe.robot.desc)
                sim0, wall0 = emu.sim_time, time.monotonic()
                acts = []
                for _ in range(int(round(stand_seconds * ctrl.rate_hz))):
                    state = safe.read()
                    before = time.perf_counter()
                    cmd = ctrl.act(state, None)
                    acts.append(time.perf_counter() - before)
                    safe.write(cmd)
                    safe.advance(1.0 / ctrl.rate_hz)
                wall, sim = time.monotonic() - wall0, emu.sim_time - sim0
                state, stats = safe.safety_state.value, safe.robot.link_stats()
        finally:
            gc.unfreeze()
        if emu.failure is not None:
            raise BenchError(f"bench hw: the emulator failed: {emu.failure!r}")
    return SafetyBenchResult(
        robot=robot, write_deadline_ms=cfg.write_deadline * 1e3, link_period_ms=1e3 / rate_hz,
        stale_timeout_ms=stale_timeout_ms, **reactions, stand_seconds=stand_seconds,
        stand_wall_s=wall, stand_sim_s=sim, stand_realtime_factor=sim / wall if wall > 0 else float("nan"),
        stand_safety_state=state, stand_trips=tuple(trips), stand_link_period_ms_mean=stats.period_mean * 1e3,
        stand_link_period_ms_max=stats.period_max * 1e3, stand_deadline_trips=stats.deadline_trips,
        stand_act_ms_p99=_percentile_ms(np.asarray(acts), 99),
        stand_deadline_misses=int(sum(a > 1.0 / ctrl.rate_hz for a in acts)))
