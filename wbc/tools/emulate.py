"""`emulate`: serve an emulated robot on 127.0.0.1 until its time is up or a signal stops it; count what it served.

The procedure behind ``wbc hw emulate``. Without the arm's bus it serves a `UnitreeEmulator` (the legs' low-level UDP
wire, with the arm locked or absent); with the arm actuated a `RobotEmulator` (legs over UDP and the arm's Dynamixel
bus on a pseudo-terminal, one physics). It builds the emulator at the caller's priority, then asks the OS for
real-time scheduling and starts it (the emulator stands in for the robot's own processors, and its threads inherit the
scheduling), injects the faults asked for, says where it serves (`EmulatorServing`, handed to the caller once it
does), and returns the counts (`EmulatorServed`) when it stops: after `EmulateConfig.seconds`, on SIGINT or SIGTERM,
or when its thread fails.
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from wbc.errors import ConfigError
from wbc.hardware.device_thread import DeviceThreadStats
from wbc.hardware.emulators import (
    BusFault,
    BusStats,
    DynamixelEmulatorConfig,
    Fault,
    RobotEmulator,
    RobotEmulatorConfig,
    UnitreeEmulator,
    UnitreeEmulatorConfig,
)
from wbc.hardware.interpreter import freeze_heap
from wbc.hardware.realtime import RealtimeGrant, RealtimeRequest, request_realtime
from wbc.hardware.unitree import DESCRIPTIONS
from wbc.tools.bench import EmulatorCounts

__all__ = ["BUS_FAULTS", "FAULTS", "EmulateConfig", "EmulatorServed", "EmulatorServing", "emulate"]

FAULTS: dict[str, Fault] = {f.value: f for f in Fault}
"""The legs' emulator's faults by name (``wbc hw emulate --fault NAME``)."""

BUS_FAULTS: dict[str, BusFault] = {f"arm_{f.value}": f for f in BusFault}
"""The arm bus's faults by name (``--fault arm_NAME``; ``arm_`` keeps them apart from the legs' faults: both have an
``over_temperature``)."""

POLL_S = 0.05  # [s] how often a serving emulator's clock and health are looked at


@dataclass(frozen=True, kw_only=True)
class EmulateConfig:
    """Which robot to emulate, and how.

    Attributes:
        robot: the legs' wire, one of `wbc.hardware.unitree.DESCRIPTIONS` (``go1``, ``a1``).
        arm_mode: ``none``, ``locked`` or ``actuated`` (the arm on its own bus, on a pseudo-terminal).
        mode: ``realtime`` (a reply per period) or ``lockstep`` (one physics step and one reply per command).
        port: UDP port on 127.0.0.1 (0: a free one).
        faults: faults injected, at their default values unless `fault_values` gives one; bus faults only with the arm
            actuated.
        fault_values: (fault, value) of the faults injected at a value of their own (`wbc.hardware.emulators.faults.
            FAULT_VALUES`, `fault_value`).
        seconds: stop after this long [s] (None: at SIGINT or SIGTERM).
        held: the robot is held at its standing pose, as in a harness, until a command drives a motor.
        realtime: what to ask the OS for before the emulator's threads start.
    """

    robot: str
    arm_mode: str
    mode: str
    port: int = 0
    faults: tuple[Fault | BusFault, ...] = ()
    fault_values: tuple[tuple[Fault, float], ...] = ()
    seconds: float | None = None
    held: bool = True
    realtime: RealtimeRequest

    def __post_init__(self) -> None:
        if self.arm_mode != "actuated" and any(isinstance(f, BusFault) for f in self.faults):
            raise ConfigError("the arm's bus faults need the arm's bus: emulate it with arm_mode actuated")
        if any(fault not in self.faults for fault, _ in self.fault_values):
            raise ConfigError("EmulateConfig.fault_values: give a value only to a fault in `faults`")

    def value(self, fault: Fault | BusFault) -> object:
        """The value `fault` is injected at (None: its default)."""
        return dict(self.fault_values).get(fault)

    def names(self) -> tuple[str, ...]:
        """The faults by name (`FAULTS`, `BUS_FAULTS`), each with its own value where it has one (``drop=0.3``)."""
        return tuple((f"arm_{f.value}" if isinstance(f, BusFault) else f.value)
                     + ("" if self.value(f) is None else f"={self.value(f):g}") for f in self.faults)


@dataclass(frozen=True)
class EmulatorServing:
    """Where an emulator serves, once it does.

    Attributes:
        robot: the robot's name: the legs' wire (``go1``) without the arm's bus, else the robot's (``go1-arm``).
        mode: ``realtime`` or ``lockstep``.
        address: the legs' UDP address.
        arm_port: the arm's pseudo-terminal, or None (no arm bus).
        faults: the faults injected, by name (`FAULTS`, `BUS_FAULTS`).
        seconds: when it stops [s], or None (at a signal).
        held: held at its standing pose until a command drives a motor.
        grant: what the OS granted of the real-time request.
        arm_mode: the arm's mode in the physics (``none``, ``locked``, ``actuated``).
        arm_port_shared: whether other processes know `arm_port` as an emulator's
            (`wbc.hardware.pty_registry`): if not, they refuse it without ``--allow-hardware``.
    """

    robot: str
    mode: str
    address: tuple[str, int]
    arm_port: str | None
    faults: tuple[str, ...]
    seconds: float | None
    held: bool
    grant: RealtimeGrant
    arm_mode: str = "none"
    arm_port_shared: bool = True


@dataclass(frozen=True)
class EmulatorServed:
    """What an emulator counted once it stopped.

    Attributes:
        counts: the legs' wire: commands decoded, rejected by reason, refused, replies.
        last_reject: why the last rejected command was rejected ("" when none was).
        arm_bus: the arm's bus counts, or None (no arm bus).
        arm_thread: the arm bus thread's statistics, or None.
        failure: what ended the emulator's thread, or None when it stopped as asked.
    """

    counts: EmulatorCounts
    last_reject: str
    arm_bus: BusStats | None = None
    arm_thread: DeviceThreadStats | None = None
    failure: BaseException | None = None


class _Stop(Exception):
    """SIGINT or SIGTERM arrived while an emulator served."""


@contextmanager
def _stopped_by_signals() -> Iterator[None]:
    """End the block cleanly on Ctrl-C, SIGINT or SIGTERM, so that the emulator still reports its counts.

    Both are set explicitly: a shell starts a background job with SIGINT ignored, and a script stops it with ``kill``.
    """
    if threading.current_thread() is not threading.main_thread():
        yield  # signals reach the main thread only; a caller on another thread stops by its seconds
        return

    def stop(signum: int, frame: object) -> None:
        raise _Stop(signum)

    previous = {sig: signal.signal(sig, stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    except (_Stop, KeyboardInterrupt):
        pass
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _serve(emulator: UnitreeEmulator | RobotEmulator, seconds: float | None) -> None:
    """Wait while `emulator` serves: until `seconds` have passed, a signal arrives, or its thread fails."""
    end = time.monotonic() + seconds if seconds is not None else float("inf")
    with _stopped_by_signals():
        while time.monotonic() < end and emulator.failure is None:
            time.sleep(min(POLL_S, max(0.0, end - time.monotonic())))


def emulate(cfg: EmulateConfig, *,
            serving: Callable[[EmulatorServing], None] = lambda serving: None) -> EmulatorServed:
    """Serve the emulated robot `cfg` names until it stops; return what it counted.

    Args:
        cfg: which robot, its arm mode, faults, and for how long.
        serving: called once the emulator serves (``wbc hw emulate`` prints where, and how to connect).

    Returns:
        The counts, and the failure of the emulator's thread if one ended it.
    """
    names = cfg.names()
    if cfg.arm_mode == "actuated":
        return _emulate_with_arm(cfg, names, serving)
    # no log: nobody reads it here, and a long one stalls the replies in each full garbage collection
    emulator = UnitreeEmulator(UnitreeEmulatorConfig(robot=cfg.robot, arm_mode=cfg.arm_mode, mode=cfg.mode,
                                                     port=cfg.port, held_until_driven=cfg.held, log_size=0))
    grant = _built_then_asked(emulator, cfg)
    with emulator:
        freeze_heap()  # built and serving: its full collections must not stall the answers
        for fault in cfg.faults:
            emulator.inject(fault, cfg.value(fault))
        serving(EmulatorServing(robot=cfg.robot, mode=cfg.mode, address=emulator.address, arm_port=None,
                                faults=names, seconds=cfg.seconds, held=cfg.held, grant=grant, arm_mode=cfg.arm_mode))
        _serve(emulator, cfg.seconds)
    return EmulatorServed(counts=EmulatorCounts.of(emulator), last_reject=emulator.last_reject,
                          failure=emulator.failure)


def _built_then_asked(emulator: UnitreeEmulator | RobotEmulator, cfg: EmulateConfig) -> RealtimeGrant:
    """Build `emulator` (`prepare`), then ask the OS for `cfg`'s real-time scheduling; before its threads start.

    It stands in for the robot's own processors, and its threads inherit the scheduling. The build comes first: some
    0.3 s of CPU, which at a real-time priority would hold off every other thread of that priority on the CPU.
    """
    emulator.prepare()
    return request_realtime(cfg.realtime)


def _emulate_with_arm(cfg: EmulateConfig, names: tuple[str, ...],
                      serving: Callable[[EmulatorServing], None]) -> EmulatorServed:
    """The arm actuated: one `RobotEmulator`, legs over UDP and arm over a pty, one physics."""
    robot = DESCRIPTIONS[cfg.robot]
    # no logs: nobody reads them here, and long ones stall the answers in each full garbage collection
    emulator = RobotEmulator(RobotEmulatorConfig(robot=robot, mode=cfg.mode, port=cfg.port, held_until_driven=cfg.held,
                                                 legs_log_size=0, arm=DynamixelEmulatorConfig(log_size=0)))
    grant = _built_then_asked(emulator, cfg)
    with emulator:
        freeze_heap()  # built and serving: its full collections must not stall the answers
        for fault in cfg.faults:
            emulator.inject(fault, cfg.value(fault))
        serving(EmulatorServing(robot=robot, mode=cfg.mode, address=emulator.address, arm_port=emulator.port,
                                faults=names, seconds=cfg.seconds, held=cfg.held, grant=grant, arm_mode=cfg.arm_mode,
                                arm_port_shared=emulator.arm.registered_everywhere))
        _serve(emulator, cfg.seconds)
    return EmulatorServed(counts=EmulatorCounts.of(emulator.legs), last_reject=emulator.legs.last_reject,
                          arm_bus=emulator.arm.stats, arm_thread=emulator.arm.thread_stats(),
                          failure=emulator.failure)
