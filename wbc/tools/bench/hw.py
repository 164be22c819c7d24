"""``wbc bench hw``: the Unitree low-level link's timing over loopback, against an emulator in another process.

A `UnitreeRobot` talks to a `UnitreeEmulator` (lockstep: one state answers each command, so a reply can be paired
with the command that caused it) that runs in a process of its own, as the robot is another machine on a real
link. The robot's transport is wrapped (`TimedTransport`) to timestamp every send and every received datagram in
the link thread itself, and to read that thread's CPU clock at each send: `LinkStats` keeps only the mean, std,
min and max of the send period, and neither percentiles nor round trips. While the link runs, the bench writes a
standing hold every link period, as a control loop would. Both processes share this machine's cores, so the
figures include that contention; a real robot's firmware would not.
"""

from __future__ import annotations

import json
import os
import select
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

import wbc
from wbc.errors import BenchError
from wbc.hardware.emulators import UnitreeEmulator, UnitreeEmulatorConfig
from wbc.hardware.interpreter import realtime_switch_interval
from wbc.hardware.unitree import (
    REJECT_REASONS,
    SdkTransport,
    Transport,
    UdpTransport,
    UnitreeRobot,
    UnitreeRobotConfig,
)
from wbc.tools.bench.references import machine_description
from wbc.types import MotorCommand

__all__ = ["EmulatorCounts", "TimedTransport", "bench_hw", "serve_emulator_stdio"]

_START_TIMEOUT = 60.0  # [s] longest wait for the emulator process to bind its port (it imports MuJoCo first)
_STOP_MARGIN = 30.0  # [s] the emulator process stops by itself this long after the bench should have ended


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


def serve_emulator_stdio(robot: str, seconds: float) -> None:
    """The emulator process's body (``bench_hw`` starts it): lockstep emulator on a free loopback port.

    Writes the address as a JSON line, serves until a line arrives on stdin (or `seconds` plus a margin pass:
    never longer), then writes the counts (`EmulatorCounts`) and any failure as a JSON line.
    """
    realtime_switch_interval()  # the emulated robot answers its wires promptly
    with UnitreeEmulator(UnitreeEmulatorConfig(robot=robot, mode="lockstep")) as emu:
        host, port = emu.address
        print(json.dumps({"host": host, "port": port}), flush=True)
        select.select([sys.stdin], [], [], seconds + _STOP_MARGIN)
        counts = EmulatorCounts.of(emu)
        failure = repr(emu.failure) if emu.failure is not None else None
    print(json.dumps({"counts": counts.as_dict(), "failure": failure}), flush=True)


def _start_emulator_process(robot: str, seconds: float) -> subprocess.Popen[str]:
    # a fresh interpreter rather than multiprocessing: its spawn re-imports the parent's __main__, which for
    # ``python -m wbc.cli`` would run the command again
    root = str(Path(wbc.__file__).resolve().parents[1])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p))
    code = f"from wbc.tools.bench.hw import serve_emulator_stdio; serve_emulator_stdio({robot!r}, {seconds!r})"
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
             transport: str = "udp") -> dict[str, object]:
    """Time the low-level link over loopback against an emulator in its own process.

    Args:
        robot: ``a1`` or ``go1``.
        seconds: how long the link runs while measured [s].
        rate_hz: the link thread's rate, 200..1000 [Hz].
        transport: ``udp`` (our socket) or ``sdk`` (the vendor's Go1 SDK), see `UnitreeRobotConfig.transport`.

    Returns:
        ``period_ms_p50`` / ``_p99`` / ``_max`` (the interval between two sends of the link thread [ms]),
        ``round_trip_ms_p50`` / ``_p99`` (a command's send to the arrival of the state the emulator answered it
        with, paired in order [ms]), ``cpu_us_per_tick`` (the link thread's CPU time per period [us]), ``rejects``
        (state frames the robot rejected), ``emulator`` (the emulator's counts), the link's own counters
        (``link``), the settings and ``machine``.

    Raises:
        UnknownNameError: `robot` is not ``a1`` or ``go1``, or `transport` is not a transport's name.
        ConfigError: `rate_hz` is out of range, or the vendor SDK was asked for an A1 or is not installed.
        BenchError: the emulator process did not start, or failed.
    """
    UnitreeRobotConfig(robot=robot, target_host="127.0.0.1", target_port=1, rate_hz=rate_hz,
                       transport=transport)  # validate first
    if not seconds > 0:
        raise BenchError(f"bench hw: --seconds must be > 0, got {seconds}")
    proc = _start_emulator_process(robot, seconds)
    try:
        address = _read_json_line(proc, _START_TIMEOUT, "bind a port")
        host, port = address["host"], int(address["port"])
        cfg = UnitreeRobotConfig(robot=robot, target_host=host, target_port=port, rate_hz=rate_hz,
                                 transport=transport)
        channel = SdkTransport if transport == "sdk" else UdpTransport
        timed = TimedTransport(channel((cfg.local_host, 0), (host, port)))
        link = UnitreeRobot(cfg, transport=timed)
        try:
            with link:
                hold = MotorCommand.hold(link.desc.nominal_q, 20.0, 0.5)
                period = 1.0 / rate_hz
                end = time.monotonic() + seconds
                for _ in range(int(seconds * rate_hz) + 2):
                    if time.monotonic() >= end:
                        break
                    link.write(hold)
                    link.advance(period)
                timed.recording = False
                stats = link.link_stats()
                rejects = link.decode_stats.rejected
        finally:
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
    return {
        "robot": robot,
        "seconds": seconds,
        "rate_hz": rate_hz,
        "transport": transport,
        "emulator_process": "separate process, lockstep",
        "sends": int(sends.size),
        "replies_received": int(receives.size),
        "period_ms_p50": _percentile_ms(periods, 50),
        "period_ms_p99": _percentile_ms(periods, 99),
        "period_ms_max": float(1e3 * periods.max()) if periods.size else float("nan"),
        "round_trip_ms_p50": _percentile_ms(round_trips, 50),
        "round_trip_ms_p99": _percentile_ms(round_trips, 99),
        "cpu_us_per_tick": cpu_per_tick,
        "rejects": int(rejects),
        "emulator": counts.as_dict(),
        "link": asdict(stats),
        "machine": machine_description(),
    }
