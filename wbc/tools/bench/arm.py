"""``wbc bench arm``: the arm's bus loop against the emulated robot in another process: loop rate and step response.

The emulated robot (`RobotEmulator`, real time) runs in a process of its own: a real bus's servos do not share
the host's Python lock, and neither do these. This process runs the legs' `UnitreeRobot`, which holds a stand, and
a `DynamixelArm` on the emulator's pty, with dynamixel_sdk and the robot's default latency timer (1 ms).

1. Loop rate: for each requested bus rate, the arm holds its stowed pose for `seconds`. The bench reads the bus
   thread's counters: cycles per second achieved, mean and longest time the bus was busy in a cycle, failed reads.
   ``1 / busy_mean`` is the rate the bus could sustain.
2. Closed-loop step response of the elbow, at the default 200 Hz, for each (kp, kd): the arm holds its stowed
   pose, then the elbow's target steps by `step` rad, and back, twice. From the sampled elbow angle the bench
   computes the 10-90 % rise time, the overshoot, the 5 % settling time and the steady error, and reports the
   median of the four steps. The same step in pure simulation
   (`MujocoRobot`, the law applied at every 2 ms physics step) is the reference. The difference is what the bus
   loop costs: its rate, its one cycle of delay, and the quantisation of ticks, velocity units and current units.
3. Reactions, in wall time, at the default 200 Hz: how long after the controller's last write the bus thread
   damps (the write deadline); for each injected bus fault (a silent servo, corrupt answers, late answers, the
   port closed), how long until the backend latches it; and, once the port is closed, how long after the last
   packet the servos' bus watchdog zeroes their goals. The test suite checks these reactions on a `ManualClock`
   (exact, in clock time); these are the figures the real loop reaches on this machine.
4. The emulators' own real time, in this process once the robot's is stopped: the shared plant's real-time factor
   on its own thread, and a sync read's round trip over a pty, with and without ``byte_timing`` (the Return Delay
   Time and the wire time at 1 Mbit/s), against what the wire model says.
"""

from __future__ import annotations

import gc
import json
import select
import subprocess
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass

import numpy as np

from wbc.control.stand import stand_command
from wbc.errors import BenchError
from wbc.hardware.dynamixel import DynamixelArm, DynamixelArmConfig, sdk_handlers
from wbc.hardware.dynamixel.arm_robot import PING_WAITS
from wbc.hardware.emulators import (
    LEG_WIRES,
    BusFault,
    DynamixelEmulator,
    DynamixelEmulatorConfig,
    RobotEmulator,
    RobotEmulatorConfig,
    SharedPlant,
    SharedPlantConfig,
)
from wbc.hardware.interpreter import child_process_env, freeze_heap, realtime_switch_interval, wbc_interpreter_env
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.hardware.realtime import NO_REALTIME, RealtimeRequest, request_realtime
from wbc.hardware.robot import load_write_check
from wbc.hardware.unitree import UnitreeRobot, UnitreeRobotConfig
from wbc.optional import require
from wbc.robots.registry import get_robot
from wbc.tools.bench.references import load_1min, machine_description
from wbc.types import MotorCommand

__all__ = ["ArmBenchResult", "ArmReactionRow", "ArmRateRow", "ArmStepRow", "EmulatorTimingRow", "bench_arm",
           "expected_latch_s", "serve_robot_emulator_stdio", "step_metrics"]

_START_TIMEOUT = 60.0  # [s] longest wait for the emulator process to open its port and pty
_STOP_MARGIN = 60.0  # [s] the emulator process stops by itself this long after the bench should have ended
_SETTLE = 1.0  # [s] hold before a step
_RECORD = 1.0  # [s] recorded after a step
_SAMPLE = 0.002  # [s] sampling period of the step response
_ELBOW = 2
_REPEATS = 4  # steps per gain on the bus (out and back, twice); the median is reported
_DISCARDS = 2  # step series thrown away (and counted) because a bus fault latched in them, before giving up
_REACTION_TIMEOUT = 2.0  # [s] longest wait for a reaction before it is reported as none
_FAULTS = (("silent_id", 4), ("bad_crc", 4), ("late_answer", [4, 0.05]), ("port_closed", None))  # port closed last
_ROUND_TRIPS = 200  # sync reads timed over the pty
_STATUS_BYTES = 11  # what a status packet adds to its data: the SDK's reply timeout of a ping counts only these
_PRESENT_BYTES = 10  # the joints' read: present current, velocity and position
_COMMAND_TIMEOUT = 10.0  # [s] longest wait for the emulator process to answer a command


@dataclass(frozen=True, kw_only=True)
class ArmRateRow:
    """The bus loop at one requested rate.

    Attributes:
        rate_hz: requested [Hz].
        achieved_hz: cycles per second achieved [Hz].
        busy_ms_mean: mean time the bus was busy in a cycle (sync read, status read, sync write) [ms].
        busy_ms_max: longest such time [ms].
        period_ms_max: longest interval between two cycles [ms].
        failed_reads: reads that failed (retries included).
        cycles: cycles run.
        faults: bus faults latched (on the loopback emulator, only when its process was starved of CPU long
            enough for a servo to miss every retry and ping: a count above 0 says the figures are the machine's).
    """

    rate_hz: float
    achieved_hz: float
    busy_ms_mean: float
    busy_ms_max: float
    period_ms_max: float
    failed_reads: int
    cycles: int
    faults: int


@dataclass(frozen=True, kw_only=True)
class ArmReactionRow:
    """How long the real loop took to react to one event, in wall time.

    Attributes:
        event: ``write_deadline`` (the controller stopped writing), or the injected `BusFault`'s value.
        reaction: what was waited for: ``damping`` (the bus thread's first damping cycle), or the fault kind latched
            (``no_answer``, ``corrupt``, ``port_lost``; ``none`` if nothing latched within the bench's timeout).
        ms: from the event (the last write; the fault active in the emulator) to the reaction [ms].
        expected_ms: what the configuration implies, for comparison: the write deadline; for a fault, the latest
            the bus loop latches it (`expected_latch_s`: the servos' silence for the watchdog's time, then the
            failed read and the pings; what the tests check exactly on a `ManualClock`) [ms].
        watchdog_ms: port closed only: from the last packet to the servos' bus watchdog zeroing their goals, seen
            by the emulator (to within its 10 ms tick) [ms]; the watchdog is set to `DynamixelArmConfig.watchdog_s`.
    """

    event: str
    reaction: str
    ms: float
    expected_ms: float
    watchdog_ms: float | None = None


@dataclass(frozen=True, kw_only=True)
class EmulatorTimingRow:
    """One real-time figure of the emulators themselves.

    Attributes:
        what: ``plant_realtime_factor`` (simulated over wall time of `SharedPlant`'s own thread), or
            ``sync_read_round_trip`` / ``sync_read_round_trip_byte_timing`` (three joints over a pty, the SDK's
            port handler as the robot's).
        value: the factor, or the median round trip [ms].
        worst: the factor's overruns (real-time ticks late by a period or more), or the 99th percentile [ms].
        model: what the model says: 1 for the factor; for the round trip the wire time of the answers (plus their
            Return Delay Time) at 1 Mbit/s, 0 without byte timing [ms].
    """

    what: str
    value: float
    worst: float
    model: float


@dataclass(frozen=True, kw_only=True)
class ArmStepRow:
    """The elbow's response to a step of its target.

    Attributes:
        source: ``bus`` (DynamixelArm against the emulator) or ``simulation`` (the law at every physics step).
        kp: [N m / rad].
        kd: [N m s / rad].
        rate_hz: the rate the law is applied at [Hz].
        rise_ms: 10 % -> 90 % of the final change [ms].
        overshoot_pct: beyond the final value, in % of the final change.
        settle_ms: after the step, the last time the angle was more than 5 % of the change from its final value [ms].
        final_error_rad: target minus final angle (gravity's sag under kp) [rad].
        discarded: series of steps thrown away because a bus fault latched in them (on the loopback emulator: its
            process starved of CPU long enough for a servo to miss every retry and ping).
    """

    source: str
    kp: float
    kd: float
    rate_hz: float
    rise_ms: float
    overshoot_pct: float
    settle_ms: float
    final_error_rad: float
    discarded: int = 0


@dataclass(frozen=True, kw_only=True)
class ArmBenchResult:
    """What `bench_arm` measured: the arm's bus loop at each rate, the elbow's step response, the reactions.

    Attributes:
        robot: ``a1-wx200`` or ``go1-arm``.
        latency_ms: the arm's latency timer [ms].
        seconds: how long each rate ran [s].
        step_rad: the elbow target's step [rad].
        emulator_bus: the emulator process's bus counters (`BusStats` fields, as it reported them; empty if it
            reported none).
        rates: one row per requested rate, in the order asked.
        steps: the step responses: on the bus for each gain, then in simulation for each gain.
        reactions: the write deadline and each bus fault, in wall time.
        emulator: the emulators' own real-time figures.
        machine: `machine_description`.
        load_1min: the machine's 1-minute load average at the end (`load_1min`; nan where the OS has none).
        host_realtime: what the bench's own process (the bus's host side) asked the OS for and got
            (`RealtimeGrant.describe`).
    """

    robot: str
    latency_ms: float
    seconds: float
    step_rad: float
    emulator_bus: Mapping[str, object]
    rates: tuple[ArmRateRow, ...]
    steps: tuple[ArmStepRow, ...]
    reactions: tuple[ArmReactionRow, ...]
    emulator: tuple[EmulatorTimingRow, ...]
    machine: str
    load_1min: float = float("nan")
    host_realtime: str = "nothing asked"

    def as_dict(self) -> dict[str, object]:
        """Plain dict (the JSON output of ``wbc bench arm``): each row as a dict of its attributes."""
        return {"robot": self.robot, "latency_ms": self.latency_ms, "seconds": self.seconds,
                "step_rad": self.step_rad, "emulator_bus": dict(self.emulator_bus),
                "rates": [asdict(r) for r in self.rates], "steps": [asdict(s) for s in self.steps],
                "reactions": [asdict(r) for r in self.reactions], "emulator": [asdict(r) for r in self.emulator],
                "machine": self.machine, "load_1min": self.load_1min, "host_realtime": self.host_realtime}


def step_metrics(t: np.ndarray, y: np.ndarray, target: float) -> tuple[float, float, float, float]:
    """(rise [ms], overshoot [%], settling [ms], final error [rad]) of a step response.

    Args:
        t: time since the step [s], increasing; samples before the step have t < 0.
        y: the response.
        target: the step's target value.
    """
    y0 = float(np.mean(y[t < 0])) if (t < 0).any() else float(y[0])
    after = t >= 0
    ta, ya = t[after], y[after]
    y_final = float(np.mean(ya[ta >= ta[-1] - 0.2]))
    change = y_final - y0
    if abs(change) < 1e-9:
        return float("nan"), float("nan"), float("nan"), target - y_final
    frac = (ya - y0) / change
    t10 = ta[np.argmax(frac >= 0.1)]
    t90 = ta[np.argmax(frac >= 0.9)]
    overshoot = max(0.0, float(np.max(frac)) - 1.0) * 100.0
    outside = np.abs(frac - 1.0) > 0.05
    settle = float(ta[np.flatnonzero(outside)[-1]]) if outside.any() else 0.0
    return 1e3 * float(t90 - t10), overshoot, 1e3 * settle, target - y_final


def serve_robot_emulator_stdio(robot: str, seconds: float, realtime: dict | None = None) -> None:
    """The emulator process's body (``bench_arm`` starts it): a real-time `RobotEmulator`.

    It builds the emulator, then asks the OS for what `realtime` names (`RealtimeRequest`'s fields; None: nothing)
    before starting it, as ``wbc hw emulate`` does. Writes the UDP address, the pty and what the OS granted as a JSON
    line, serves until a line arrives on stdin (or `seconds` plus a margin pass), then writes any failure as a JSON
    line.
    """
    realtime_switch_interval()  # the emulated robot answers its wires promptly
    emulator = RobotEmulator(RobotEmulatorConfig(robot=robot, mode="realtime")).prepare()
    freeze_heap()  # built: its full collections must not stall the answers (as `wbc hw emulate`)
    grant = request_realtime(RealtimeRequest(**realtime) if realtime is not None else NO_REALTIME)
    with emulator as emu:
        host, port = emu.address
        print(json.dumps({"host": host, "port": port, "pty": emu.port, "realtime": grant.describe()}), flush=True)
        end = time.monotonic() + seconds + _STOP_MARGIN
        while select.select([sys.stdin], [], [], max(0.0, end - time.monotonic()))[0]:
            line = sys.stdin.readline()
            if not line or line.strip() == "stop":
                break
            print(json.dumps(_emulator_command(emu, json.loads(line))), flush=True)
        failure = repr(emu.failure) if emu.failure is not None else None
        stats = asdict(emu.arm.stats)
    print(json.dumps({"failure": failure, "arm_bus": stats}), flush=True)


def _emulator_command(emu: RobotEmulator, command: dict) -> dict:
    """One command of the bench to the emulator process: inject or clear an arm bus fault, or time a watchdog."""
    if "inject" in command:
        value = command.get("value")
        emu.inject(BusFault(command["inject"]), tuple(value) if isinstance(value, list) else value)
        return {"ok": True}
    if "clear" in command:
        emu.clear(BusFault(command["clear"]) if command["clear"] else None)
        return {"ok": True}
    if "watchdog" in command:  # how long after the last packet the servo's bus watchdog tripped
        servo_id = int(command["watchdog"])
        end = time.monotonic() + _REACTION_TIMEOUT
        while emu.arm.register(servo_id, "bus_watchdog") != -1 and time.monotonic() < end:
            time.sleep(0.0005)
        tripped = time.monotonic()
        packets = emu.arm.packets()
        if emu.arm.register(servo_id, "bus_watchdog") != -1 or not packets:
            return {"after_s": None}
        return {"after_s": tripped - packets[-1].time}
    return {"error": f"unknown command {command!r}"}


def _command(proc: subprocess.Popen[str], command: dict) -> dict:
    """Send the emulator process one command and read its answer."""
    proc.stdin.write(json.dumps(command) + "\n")
    proc.stdin.flush()
    if not select.select([proc.stdout], [], [], _COMMAND_TIMEOUT)[0]:
        raise BenchError(f"bench arm: the emulator process did not answer {command} within {_COMMAND_TIMEOUT} s")
    answer = json.loads(proc.stdout.readline())
    if "error" in answer:
        raise BenchError(f"bench arm: the emulator process: {answer['error']}")
    return answer


def _start_emulator(robot: str, seconds: float,
                    realtime: RealtimeRequest) -> tuple[subprocess.Popen[str], dict]:
    env = wbc_interpreter_env(child_process_env())  # no BLAS pool: memory the emulator would lock
    code = f"from wbc.tools.bench.arm import serve_robot_emulator_stdio; serve_robot_emulator_stdio({robot!r}, " \
           f"{seconds!r}, {asdict(realtime)!r})"
    proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            env=env)
    if not select.select([proc.stdout], [], [], _START_TIMEOUT)[0]:
        proc.kill()
        raise BenchError(f"bench arm: the emulator process did not start within {_START_TIMEOUT} s")
    line = proc.stdout.readline()
    try:
        return proc, json.loads(line)
    except json.JSONDecodeError:
        proc.kill()
        raise BenchError(f"bench arm: the emulator process wrote {line!r} (exit status {proc.poll()})") from None


class _Rig:
    """The legs holding a stand while the arm runs: both written every `period`."""

    def __init__(self, legs: UnitreeRobot, legs_hold: MotorCommand, period: float = 0.004) -> None:
        self.legs, self.legs_hold, self.period = legs, legs_hold, period

    def run(self, arm: DynamixelArm, arm_cmd: MotorCommand | None, seconds: float,
            sample: list[tuple[float, float]] | None = None, t_step: float = 0.0,
            until: Callable[[], bool] | None = None) -> None:
        """Write the legs' stand and `arm_cmd` (None: nothing to the arm) for `seconds`, or until `until()`."""
        end = time.monotonic() + seconds
        period = _SAMPLE if sample is not None else self.period
        for _ in range(int(seconds / period) + 2):
            now = time.monotonic()
            if now >= end or (until is not None and until()):
                return
            self.legs.write(self.legs_hold)
            if arm_cmd is not None:
                arm.write(arm_cmd)
            if sample is not None:
                sample.append((now - t_step, float(arm.read().q[_ELBOW])))
            arm.advance(period)


def _step_series(rig: _Rig, arm: DynamixelArm, stowed: np.ndarray, kp: float, kd: float,
                 step: float) -> list[tuple[float, float, float, float]]:
    """`_REPEATS` steps of the elbow on the bus, out and back; each one's `step_metrics`."""
    rig.run(arm, MotorCommand.hold(stowed, kp, kd), _SETTLE)
    runs = []
    for k in range(_REPEATS):
        start = stowed.copy()
        start[_ELBOW] += step * (k % 2)
        target = stowed.copy()
        target[_ELBOW] += step * (1 - k % 2)
        pre: list[tuple[float, float]] = []
        rig.run(arm, MotorCommand.hold(start, kp, kd), 0.1, sample=pre, t_step=time.monotonic() + 0.1)
        samples: list[tuple[float, float]] = []
        rig.run(arm, MotorCommand.hold(target, kp, kd), _RECORD, sample=samples, t_step=time.monotonic())
        t, y = (np.array(v) for v in zip(*(pre + samples), strict=True))
        runs.append(step_metrics(t, y, float(target[_ELBOW])))
    return runs


def _reply_timeout_s(answer_bytes: int, config: DynamixelArmConfig) -> float:
    """How long the SDK waits for an answer of `answer_bytes` on `config`'s bus [s] (its ``setPacketTimeout``).

    The bytes' time at the baud rate (10 bits each), twice the adapter's latency timer, and 2 ms.
    """
    return answer_bytes * 10.0 / config.baud_rate + (2.0 * config.latency_ms + 2.0) * 1e-3


def expected_latch_s(config: DynamixelArmConfig) -> dict[str, float]:
    """The latest each fault `wbc bench arm` injects latches after the injection, as `DynamixelArm` behaves [s].

    A read whose tries all fail is a missed cycle, not a fault, while every servo of it gave a valid answer within
    the servos' watchdog time (`DynamixelArmConfig.watchdog_s`). The first failed read that ends after a servo's
    silence reached that time pings the servos of the read and latches the silent or corrupt ones. The silence
    starts at the servo's last valid answer, up to a bus period before the injection, so these are upper bounds:

    - ``silent_id`` and ``late_answer`` (an answer later than the reply timeout is no answer): the watchdog's time;
      then one more failed read of the joints, which may have begun just before the silence reached it: its
      ``retries + 1`` tries each wait for the sync read's whole reply timeout, with `retry_wait_s` before each retry;
      then the silent servo's three pings, each waiting for its reply timeout, with `PING_WAITS` between them. A late
      answer that arrives while a later read of the same servo and length waits passes for that read's answer
      (Protocol 2.0 has no sequence number) and postpones the latch;
    - ``bad_crc``: the watchdog's time too (a corrupt answer is no valid answer); the corrupt answers come at once,
      so the failed reads end within their cycle and the check comes every bus period: one period more, and the
      retries' pauses; the corrupt answer to the ping latches at once;
    - ``port_closed``: the next bus cycle, whose transfer raises: one bus period.
    """
    period = 1.0 / config.rate_hz
    joints_read = _reply_timeout_s(len(config.joints) * (_STATUS_BYTES + _PRESENT_BYTES), config)
    failed_read = (config.retries + 1) * joints_read + config.retries * config.retry_wait_s
    pings = len(PING_WAITS) + 1
    silent = config.watchdog_s + failed_read + pings * _reply_timeout_s(_STATUS_BYTES, config) + sum(PING_WAITS)
    return {"silent_id": silent, "late_answer": silent,
            "bad_crc": config.watchdog_s + period + config.retries * config.retry_wait_s, "port_closed": period}


def _reactions(rig: _Rig, proc: subprocess.Popen[str], config: DynamixelArmConfig,
               hold: MotorCommand) -> list[ArmReactionRow]:
    """The write deadline's damping and each fault's latch, in wall time (the port closed last: it ends the pty)."""
    rows = []
    with DynamixelArm(config) as arm:
        rig.run(arm, hold, 0.3)
        before = arm.bus_stats().damping_cycles
        arm.write(hold)
        written = time.monotonic()
        rig.run(arm, None, _REACTION_TIMEOUT, until=lambda: arm.bus_stats().damping_cycles > before)
        damped = arm.bus_stats().damping_cycles > before
        rows.append(ArmReactionRow(event="write_deadline", reaction="damping" if damped else "none",
                                   ms=1e3 * (time.monotonic() - written) if damped else float("nan"),
                                   expected_ms=1e3 * config.write_deadline))
    expected = expected_latch_s(config)
    for name, value in _FAULTS:
        with DynamixelArm(config) as arm:
            rig.run(arm, hold, 0.3)
            _command(proc, {"inject": name, "value": value})
            t0 = time.monotonic()
            rig.run(arm, hold, _REACTION_TIMEOUT, until=lambda a=arm: a.fault is not None)
            latched = time.monotonic() - t0
            fault = arm.fault
            watchdog = _command(proc, {"watchdog": 4})["after_s"] if name == "port_closed" else None
            if name != "port_closed":
                _command(proc, {"clear": name})
        rows.append(ArmReactionRow(event=name, reaction=fault.kind if fault is not None else "none",
                                   ms=1e3 * latched if fault is not None else float("nan"),
                                   expected_ms=1e3 * expected[name],
                                   watchdog_ms=None if watchdog is None else 1e3 * watchdog))
    return rows


def _emulator_timing(plant: SharedPlant, seconds: float, latency_ms: float) -> list[EmulatorTimingRow]:
    """The plant's real-time factor on its own thread, and a sync read's round trip over a pty (this process).

    `plant` is built by the caller, before its real-time priority; its thread starts here and inherits it.
    """
    sdk = require("dynamixel_sdk")
    rows = []
    plant.start_realtime()
    t0, w0 = plant.time, time.monotonic()
    time.sleep(seconds)
    simulated, wall = plant.time - t0, time.monotonic() - w0
    plant.stop_realtime()
    rows.append(EmulatorTimingRow(what="plant_realtime_factor", value=simulated / wall, worst=plant.overruns,
                                  model=1.0))
    for byte_timing in (False, True):
        with DynamixelEmulator(plant, DynamixelEmulatorConfig(byte_timing=byte_timing, log_size=0)) as emu:
            port, packet = sdk_handlers(emu.port, latency_ms)
            if not port.openPort():
                raise BenchError(f"bench arm: could not open the emulator's pty {emu.port}")
            group = sdk.GroupSyncRead(port, packet, 126, 10)
            for servo_id in (1, 2, 4):
                group.addParam(servo_id)
            times = []
            for _ in range(_ROUND_TRIPS):
                start = time.perf_counter()
                ok = group.txRxPacket() == sdk.COMM_SUCCESS
                if ok:
                    times.append(time.perf_counter() - start)
                else:
                    port.clearPort()
            port.closePort()
        wire = 3 * 21 * 10 / 1e6 if byte_timing else 0.0  # three answers of 21 bytes, Return Delay Time 0
        rows.append(EmulatorTimingRow(
            what="sync_read_round_trip" + ("_byte_timing" if byte_timing else ""),
            value=1e3 * float(np.median(times)) if times else float("nan"),
            worst=1e3 * float(np.percentile(times, 99)) if times else float("nan"), model=1e3 * wire))
    return rows


def _sim_step(robot: str, q0: np.ndarray, kp: float, kd: float, step: float) -> tuple[np.ndarray, np.ndarray]:
    desc = get_robot(robot, "actuated")
    legs = stand_command(desc)
    with MujocoRobot(MujocoRobotConfig(robot=robot, arm_mode="actuated")) as sim:
        def hold(q_arm: np.ndarray) -> MotorCommand:
            rows = legs.stacked()
            rows[0, 12:], rows[1, 12:], rows[2, 12:], rows[3, 12:], rows[4, 12:] = q_arm, 0.0, kp, kd, 0.0
            return MotorCommand(q=rows[0], dq=rows[1], kp=rows[2], kd=rows[3], tau=rows[4])
        sim.write(hold(q0))
        sim.advance(_SETTLE)
        ts, ys = [], []
        for k in range(-int(0.1 / _SAMPLE), int(_RECORD / _SAMPLE)):
            if k == 0:
                target = q0.copy()
                target[_ELBOW] += step
                sim.write(hold(target))
            ts.append(k * _SAMPLE)
            ys.append(float(sim.read().q[12 + _ELBOW]))
            sim.advance(_SAMPLE)
    return np.array(ts), np.array(ys)


def bench_arm(robot: str = "a1-wx200", *, rates: tuple[float, ...] = (100.0, 200.0, 400.0, 1000.0),
              seconds: float = 2.0, latency_ms: float = 1.0, step: float = -0.05,
              gains: tuple[tuple[float, float], ...] = ((20.0, 0.5), (60.0, 1.0)),
              realtime: RealtimeRequest = NO_REALTIME, host_realtime: RealtimeRequest = NO_REALTIME) -> ArmBenchResult:
    """Measure the arm's bus loop (rates, step response) against the emulated robot in its own process.

    Args:
        robot: ``a1-wx200`` or ``go1-arm``.
        rates: bus rates to run [Hz], each in 10..1000.
        seconds: how long each rate runs [s].
        latency_ms: the arm's latency timer [ms].
        step: the elbow target's step [rad] (negative unfolds the stowed elbow).
        gains: (kp, kd) of each step response [N m / rad, N m s / rad].
        realtime: what the emulator's process asks the OS for (it stands in for the robot's processors).
        host_realtime: what this process asks the OS for before it starts the bus and the legs' link: on a robot
            they run in the I/O process, which asks for real-time scheduling (`wbc.hardware.io_process`). Asked for
            the rest of the process's life, once everything slow is built (the references in simulation, the plant
            of the emulators' timing, the legs' robot; the bus's SDK and the compiled check loaded), as the I/O
            process asks once its robot is built.

    Returns:
        The rows of each part (rates, steps on the bus and in simulation for each gain, reactions, the emulators'
        real-time figures), the emulator's bus counters, the settings and the machine.

    Raises:
        BenchError: the emulator process did not start or failed, or a setting is out of range.
    """
    if robot not in LEG_WIRES:
        raise BenchError(f"bench arm: --robot must be one of {', '.join(LEG_WIRES)}, got {robot!r}")
    if not seconds > 0:
        raise BenchError(f"bench arm: --seconds must be > 0 s, got {seconds:g}")
    out_of_range = [r for r in rates if not 10.0 <= r <= 1000.0]
    if not rates or out_of_range:
        got = ", ".join(f"{r:g}" for r in out_of_range) if out_of_range else "none"
        raise BenchError(f"bench arm: --rates: each bus rate must be in 10..1000 Hz, got {got}; give comma-separated "
                         "rates, e.g. 100,200,400,1000")
    total = len(rates) * (seconds + 1.0) + len(gains) * (_DISCARDS + 1) * (_SETTLE + _REPEATS * (_RECORD + 0.1) + 1.0) \
        + (len(_FAULTS) + 1) * (2 * _REACTION_TIMEOUT + 2.0)
    desc = get_robot(robot, "actuated")
    stand = stand_command(desc).stacked()
    stowed = desc.nominal_q[12:].copy()
    # everything slow is built before this process asks for a real-time priority, as the I/O process builds its robot
    # first: what runs at that priority holds off every other thread of it on the CPU. The references in simulation
    # (a MuJoCo model each, its compiled code loaded by the first: ~0.1-0.4 s of CPU) are played here, before the bus
    # runs, since simulating while it ran would leave the legs' link unwritten
    references = []
    for kp, kd in gains:
        t, y = _sim_step(robot, stowed, kp, kd, step)
        references.append(ArmStepRow(source="simulation", kp=kp, kd=kd, rate_hz=500.0,
                                     **dict(zip(("rise_ms", "overshoot_pct", "settle_ms", "final_error_rad"),
                                                step_metrics(t, y, float(stowed[_ELBOW] + step)), strict=True))))
    require("dynamixel_sdk")  # the bus's SDK, which the first DynamixelArm would import
    load_write_check()  # its first compiled call
    with SharedPlant(SharedPlantConfig(robot=robot)) as plant:  # the emulators' own timing's, at the end
        proc, where = _start_emulator(robot, total, realtime)
        rate_rows, step_rows, reaction_rows = [], [], []
        fault = None
        try:
            print(f"bench arm: the emulator's process: {where.get('realtime')}", file=sys.stderr, flush=True)
            # built before the request too, and connected after it: its link's thread inherits the priority
            legs = UnitreeRobot(UnitreeRobotConfig(robot=LEG_WIRES[robot], target_host=where["host"],
                                                   target_port=int(where["port"])))
            host = request_realtime(host_realtime).describe() if host_realtime != NO_REALTIME else "nothing asked"
            print(f"bench arm: this process (the bus's host side): {host}", file=sys.stderr, flush=True)
            freeze_heap()  # as `wbc hw run` does once all is built: a full collection would stall the bus's thread
            with legs:
                rig = _Rig(legs, MotorCommand._trusted(stand[:, :12].copy()))
                hold = MotorCommand.hold(stowed, 20.0, 0.5)
                for rate in rates:
                    arm = DynamixelArm(DynamixelArmConfig(robot=robot, port=where["pty"], latency_ms=latency_ms,
                                                          rate_hz=rate, write_deadline=max(0.05, 2.0 / rate)))
                    with arm:
                        rig.run(arm, hold, 0.3)
                        before = arm.bus_stats()
                        t0 = time.monotonic()
                        rig.run(arm, hold, seconds)
                        after = arm.bus_stats()
                        wall = time.monotonic() - t0
                    rate_rows.append(ArmRateRow(
                        rate_hz=rate, achieved_hz=(after.cycles - before.cycles) / wall,
                        busy_ms_mean=1e3 * after.busy_mean, busy_ms_max=1e3 * after.busy_max,
                        period_ms_max=1e3 * after.period_max,
                        failed_reads=after.failed_transfers - before.failed_transfers, cycles=after.cycles,
                        faults=len(arm.faults)))
                for kp, kd in gains:
                    runs, discarded = [], 0
                    while not runs:
                        arm = DynamixelArm(DynamixelArmConfig(robot=robot, port=where["pty"], latency_ms=latency_ms))
                        with arm:
                            series = _step_series(rig, arm, stowed, kp, kd, step)
                        if not arm.faults:
                            runs = series
                        elif discarded < _DISCARDS:
                            discarded += 1  # a servo of the emulator starved of CPU for long enough to look dead
                        else:
                            fault = f"a bus fault latched in {discarded + 1} step series at kp {kp}: {arm.faults[0]}"
                            break
                    if fault is not None:
                        break
                    median = np.median(np.array(runs), axis=0)
                    step_rows.append(ArmStepRow(source="bus", kp=kp, kd=kd, rate_hz=arm.config.rate_hz,
                                                discarded=discarded,
                                                **dict(zip(("rise_ms", "overshoot_pct", "settle_ms", "final_error_rad"),
                                                           (float(v) for v in median), strict=True))))
                if fault is None:
                    reaction_rows = _reactions(rig, proc, DynamixelArmConfig(robot=robot, port=where["pty"],
                                                                             latency_ms=latency_ms), hold)
        finally:
            gc.unfreeze()  # a library call: what it kept is collected again after it
            try:
                proc.stdin.write("stop\n")
                proc.stdin.flush()
            except OSError:
                pass
            try:
                out, _ = proc.communicate(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                out = ""
        tail = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
        if tail and tail[-1].get("failure"):
            raise BenchError(f"bench arm: the emulator failed: {tail[-1]['failure']}")
        bus = tail[-1].get("arm_bus", {}) if tail else {}
        if fault is not None:
            raise BenchError(f"bench arm: {fault} (the emulator's bus counts: {bus})")
        emulator = _emulator_timing(plant, seconds, latency_ms)
    return ArmBenchResult(robot=robot, latency_ms=latency_ms, seconds=seconds, step_rad=step, emulator_bus=bus,
                          rates=tuple(rate_rows), steps=tuple(step_rows + references), reactions=tuple(reaction_rows),
                          emulator=tuple(emulator), machine=machine_description(), load_1min=load_1min(),
                          host_realtime=host)
