"""Fixtures shared by several test modules."""

from __future__ import annotations

import json
import os
import shutil
import signal
import sys
import tempfile
import textwrap
from collections.abc import Callable
from dataclasses import dataclass

import pytest
from golden_recording import recording_refusal

import wbc  # noqa: F401  (first: it pins the numeric kernels before numpy loads, wbc/_kernels.py)
from wbc.hardware.clock import ManualClock
from wbc.hardware.emulators import RobotEmulator, RobotEmulatorConfig, UnitreeEmulator
from wbc.hardware.hardware_robot import HardwareRobot, HardwareRobotConfig, build_hardware_robot

_CACHE: list[str] = []


def pytest_configure(config: pytest.Config) -> None:
    """The suite keeps the robots' drawable parts (`wbc.viz.meshes.robot_parts`) in a cache of its own, and the locks
    its links take on the emulators' addresses (`wbc.hardware.unitree.target_lock`, one per port) in a runtime
    directory of its own, removed at its end; the parallel workers, started after, inherit both. It refuses to
    re-record the goldens under parallel workers (`golden_recording.recording_refusal`)."""
    if os.environ.get("WBC_RECORD_GOLDEN") == "1":
        problem = recording_refusal(getattr(config.option, "numprocesses", None), os.environ.get("PYTEST_XDIST_WORKER"))
        if problem is not None:
            raise pytest.UsageError(problem)
    if not os.environ.get("WBC_CACHE_DIR"):
        _CACHE.append(tempfile.mkdtemp(prefix="wbc-test-cache-"))
        os.environ["WBC_CACHE_DIR"] = _CACHE[-1]
    if not os.environ.get("WBC_TEST_RUNTIME_DIR"):
        _CACHE.append(tempfile.mkdtemp(prefix="wbc-test-runtime-"))  # mode 0700, as a runtime directory is
        os.environ["WBC_TEST_RUNTIME_DIR"] = os.environ["XDG_RUNTIME_DIR"] = _CACHE[-1]


def pytest_unconfigure(config: pytest.Config) -> None:
    for path in _CACHE:
        shutil.rmtree(path, ignore_errors=True)


LIMP = '''
    """A controller that switches its motors off: the robot folds and falls within a second."""
    import numpy as np

    from wbc.types import MotorCommand


    class Limp:
        rate_hz = 50.0

        def __init__(self, desc):
            self.command = MotorCommand.damping(desc.num_joints, 0.0)

        def reset(self):
            pass

        def act(self, state, command):
            return self.command

        def counters(self):
            return {}


    def make(desc):
        return Limp(desc)
'''


HOLD_PLUGIN = '''"""A plug-in that holds the nominal pose."""
import numpy as np

from wbc.robots.description import joint_gains
from wbc.types import MotorCommand

GAIN = 60.0


class Hold:
    rate_hz = 50.0

    def __init__(self, desc, leg_kp):
        kp, kd = joint_gains(desc.num_joints, leg_kp, 2.0, 20.0, 0.5)
        self.command = MotorCommand.hold(desc.nominal_q, kp, kd)

    def reset(self):
        pass

    def act(self, state, command):
        return self.command

    def counters(self):
        return {}


def make(desc, config=None):
    """Hold the nominal pose (a test plug-in)."""
    config = config or {}
    if set(config) - {"leg_kp"}:
        raise ValueError(f"unknown keys {sorted(set(config) - {'leg_kp'})}; valid: leg_kp")
    return Hold(desc, config.get("leg_kp", GAIN))


def no_config(desc):
    return Hold(desc, GAIN)


def no_args():
    return None
'''
"""A plug-in module's source: the PD hold of the nominal pose, its leg gain from an optional table
(``make(desc, config)``; ``no_config`` takes none); an unknown key in the table raises; ``no_args`` is no
factory."""


SHORT_SCENARIO = """
[scenario]
name = "short"
version = 1
description = "one second of standing, a gentle push"
robot = "a1-wx200"
duration_s = 1.0

[terrain]
kind = "fractal"
amplitude_m = 0.02

[commands]
[[commands.options]]
vx = 0.0

[pushes]
first_s = [0.3, 0.5]
interval_s = [0.6, 0.9]
duration_s = 0.05
offset_m = 0.1

[[bands]]
name = "soft"
push_force_n = [50.0, 100.0]
"""
"""A one-second scenario of the a1-wx200 standing through gentle pushes (``stand`` survives every trial): the arena
tests' smallest real run (`from conftest import SHORT_SCENARIO`)."""

STAND_PLUGIN = '''
    """{doc}"""
    import numpy as np

    from wbc.control.stand import StandController
    from wbc.types import MotorCommand


    class Wrapped:
        def __init__(self, desc):
            self.inner = StandController(desc)
            self.rate_hz = self.inner.rate_hz
            self.ticks = 0

        def reset(self):
            self.inner.reset()
            self.ticks = 0
            {reset}

        def act(self, state, command):
            self.ticks += 1
            out = self.inner.act(state, command)
            {act}
            return out

        def counters(self):
            {counters}


    def make(desc):
        return Wrapped(desc)
'''
"""A plug-in module's source: the stand controller with a body added to its ``reset`` and ``act`` and its own
``counters``; fill with ``STAND_PLUGIN.format(doc=..., reset="pass", act="pass", counters="return {{}}")``."""


def untimed_summary(path) -> str:
    """A summary.json's text without what the machine's clock decided: each cell's deadline misses, and the warnings
    about them (a busy machine misses more); everything else must match to the byte."""
    data = json.loads(path.read_text(encoding="utf-8"))
    for entry in data["controllers"].values():
        for cell in entry["bands"].values():
            cell.pop("deadline_misses")
    data["warnings"] = [w for w in data["warnings"] if w["kind"] != "deadline_misses"]
    return json.dumps(data, indent=2)


@pytest.fixture
def plugin_package(tmp_path, monkeypatch):
    """Writes a package of plug-in modules on sys.path, forgotten afterwards: ``plugin_package("pkg", {"mod": src})``.

    Returns the function; each call returns the package's root directory (its modules are ``root/pkg/mod.py``).
    """
    packages = []

    def write(package: str, modules: dict[str, str]):
        root = tmp_path / f"{package}root"
        (root / package).mkdir(parents=True)
        (root / package / "__init__.py").write_text(f'"""Test plug-ins: {package}."""\n')
        for name, source in modules.items():
            (root / package / f"{name}.py").write_text(textwrap.dedent(source).lstrip(), encoding="utf-8")
        monkeypatch.syspath_prepend(str(root))
        packages.append(package)
        return root

    yield write
    for name in [m for m in sys.modules if m.split(".")[0] in packages]:
        del sys.modules[name]


def _scheduling() -> tuple[object, ...]:
    """This process's scheduling policy, its CPU set, and whether its memory is locked (VmLck in /proc)."""
    locked = 0
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            locked = next((line.split()[1] for line in f if line.startswith("VmLck:")), "0")
    except OSError:
        pass
    policy = os.sched_getscheduler(0) if hasattr(os, "sched_getscheduler") else None
    cpus = frozenset(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    return policy, cpus, int(locked) > 0


@pytest.fixture(autouse=True)
def _keeps_ordinary_scheduling():
    """Every test leaves the test process as it found it: no real-time policy, no CPU pinning, no locked memory.

    The commands that stand in for a robot's processors (`wbc hw emulate`) ask for real-time scheduling for their
    process; called in this process (``main([...])``), they must be told ``--no-realtime``, or every later test would
    run pinned to one CPU under SCHED_FIFO with its memory locked.
    """
    before = _scheduling()
    yield
    after = _scheduling()
    assert after == before, (f"this test changed the test process's scheduling (policy, CPUs, memory locked) from "
                             f"{before} to {after}; pass --no-realtime to commands run in this process")


@pytest.fixture
def limp(plugin_package):
    plugin_package("limppkg", {"limp": LIMP})
    return "limppkg.limp:make"


@dataclass
class Stepped:
    """An emulated robot in process, the clock it runs on, and the builder that puts a command's or a trial's robot
    on both (`from conftest import Stepped`)."""

    clock: ManualClock
    emu: UnitreeEmulator

    def build(self, config: HardwareRobotConfig) -> HardwareRobot:
        """The robot `config` names, its legs on the clock over the emulator's in-process channel."""
        return build_hardware_robot(config, clock=self.clock, legs_transport=self.emu.transport(self.clock))


def hw_run_arm_in_lockstep(scenario: str, out: str, seconds: float,
                           inject: Callable[[RobotEmulator], None] | None = None,
                           inject_at: float = 0.0) -> tuple[int, RobotEmulator]:
    """``wbc hw run stand --robot a1-wx200 --arm actuated --no-io-process``, legs and arm emulated in process on one
    manual clock, the trial's devices (the legs' link, the arm's bus) on that clock too; (its exit status, the
    emulator, closed: its logs are kept). `inject`, if given, is called with the emulator `inject_at` seconds of that
    clock after the robot is built (the stand-up before the trial takes about 1.06 s)."""
    from wbc.cli.main import hw_run
    from wbc.cli.parser import build_parser

    clock = ManualClock()
    with RobotEmulator(RobotEmulatorConfig(robot="a1-wx200", mode="realtime"), clock=clock) as emu:
        def build(config: HardwareRobotConfig) -> HardwareRobot:
            if inject is not None:
                clock.call_at(clock.now() + inject_at, lambda: inject(emu))
            return build_hardware_robot(config, clock=clock, legs_transport=emu.legs_transport,
                                        arm_handlers=emu.arm_handlers())

        args = build_parser().parse_args(["hw", "run", "stand", "--robot", "a1-wx200", "--arm", "actuated",
                                          "--scenario", scenario, "--trial", "0", "--target", "127.0.0.1:9",
                                          "--arm-port", emu.port, "--seconds", str(seconds), "--out", out,
                                          "--no-io-process"])
        code = hw_run(args, build=build)
    return code, emu


_TERMINAL_DISPOSITIONS = {signal.SIGINT: signal.default_int_handler, signal.SIGTERM: signal.SIG_DFL,
                          signal.SIGHUP: signal.SIG_DFL}
"""How a command started from a terminal handles Ctrl-C, SIGTERM and the hangup (Python's own for SIGINT)."""


@pytest.fixture
def terminal_signals():
    """Ctrl-C, SIGTERM and the hangup handled, for the test's duration, as in a command started from a terminal.

    A suite started in the background of a script inherits SIGINT ignored, and one started under ``nohup`` SIGHUP
    ignored; the tests of what a command does on those signals must not depend on how the suite was started.
    """
    before = {signum: signal.signal(signum, handler) for signum, handler in _TERMINAL_DISPOSITIONS.items()}
    try:
        yield
    finally:
        for signum, handler in before.items():
            signal.signal(signum, signal.SIG_DFL if handler is None else handler)


def terminal_signals_in_child() -> None:
    """A child process's Ctrl-C, SIGTERM and hangup as a terminal's command has them (``Popen(preexec_fn=...)``)."""
    for signum in _TERMINAL_DISPOSITIONS:
        signal.signal(signum, signal.SIG_DFL)  # Python installs its own SIGINT handler over the default at start


def ctrl_c_in_adaptation_round(train_module, monkeypatch, round_: int) -> None:
    """Have `train_module.train_adaptation` (RMA's phase 2) be interrupted by SIGINT as it logs round `round_`."""
    import signal

    real = train_module.train_adaptation

    def interrupted(policy, env, config):
        def log(line: str) -> None:
            if line.startswith(f"RMA phase 2 iteration {round_}/"):
                signal.raise_signal(signal.SIGINT)

        return real(policy, env, config, log=log)

    monkeypatch.setattr(train_module, "train_adaptation", interrupted)
