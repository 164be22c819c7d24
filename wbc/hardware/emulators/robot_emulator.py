"""`RobotEmulator`: a whole quadruped with its arm actuated on 127.0.0.1: legs over UDP, arm over a pty, one physics.

The real robot is one body with two links, and so is this. One `SharedPlant` (the MuJoCo robot, 15 joints) runs
behind two wire-exact emulators. `UnitreeEmulator` serves the 12 legs on a UDP port of 127.0.0.1, and
`DynamixelEmulator` serves the arm's bus on a pseudo-terminal. A backend that talks to both (`UnitreeRobot` and
`DynamixelArm`, joined by `QuadrupedArmRobot`) cannot tell this from the robot.

The physics is stepped by the legs' emulator, as when it runs alone. In ``realtime`` mode its thread steps it at
wall-clock pace and answers every period. In ``lockstep`` mode each leg command steps it by one control period, so
the legs' commands set the pace, and the arm's commands act in those steps. Faults go to the emulator whose wire
they bend: a `Fault` to the legs, a `BusFault` to the arm.

Built with a `ManualClock`, the robot opens no socket and no pty and starts no thread: it hands out its two wires in
process instead, `legs_transport` (a `wbc.hardware.unitree.Transport` for `UnitreeRobot`) and `arm_handlers` (the
port handlers for `DynamixelArm`). Backends on the same clock then run in lockstep with it: the legs' link period and
the arm's bus cycle are tasks of the clock, each command is answered within the call that sends it, and the servos'
own time (watchdogs, faults) is a task of the clock too. What a test sees is the same on any machine at any load.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wbc.errors import ConfigError, UnknownNameError
from wbc.hardware.clock import ManualClock
from wbc.hardware.emulators.bus_faults import BusFault
from wbc.hardware.emulators.dynamixel import DynamixelEmulator, DynamixelEmulatorConfig
from wbc.hardware.emulators.faults import Fault
from wbc.hardware.emulators.plant import SharedPlant, SharedPlantConfig
from wbc.hardware.emulators.unitree import MODES, EmulatorTransport, UnitreeEmulator, UnitreeEmulatorConfig
from wbc.hardware.unitree.robot import LEG_WIRES
from wbc.types import BaseTruth

__all__ = ["LEG_WIRES", "RobotEmulator", "RobotEmulatorConfig"]


@dataclass(frozen=True, kw_only=True)
class RobotEmulatorConfig:
    """Configuration of an emulated robot with its arm actuated.

    Attributes:
        robot: ``a1-wx200`` or ``go1-arm``.
        mode: ``realtime`` (the physics at wall-clock pace) or ``lockstep`` (each leg command steps it).
        port: the legs' UDP port on 127.0.0.1; 0 picks a free one.
        control_period: physics time per leg command (lockstep) or per leg state (realtime) [s].
        timestep: the physics step [s].
        seed: seed of the simulation.
        held_until_driven: the robot held at its spawn pose until a leg command drives a motor
            (`UnitreeEmulatorConfig.held_until_driven`).
        legs_log_size: most recent leg commands kept (`UnitreeEmulatorConfig.log_size`; the arm's is
            ``arm.log_size``).
        arm: the arm's bus (servos, temperatures, byte timing ...).
    """

    robot: str = "a1-wx200"
    mode: str = "realtime"
    port: int = 0
    control_period: float = 0.002
    timestep: float = 0.002
    seed: int = 0
    held_until_driven: bool = False
    legs_log_size: int = 100_000
    arm: DynamixelEmulatorConfig = field(default_factory=DynamixelEmulatorConfig)

    def __post_init__(self) -> None:
        if self.robot not in LEG_WIRES:
            raise UnknownNameError("robot with an arm", self.robot, tuple(LEG_WIRES))
        if self.mode not in MODES:
            raise UnknownNameError("emulator mode", self.mode, MODES)


class RobotEmulator:
    """The whole emulated robot: one plant, two wires. A context manager (`start` / `close`).

    Args:
        config: what to emulate.
        clock: None serves the wires on 127.0.0.1 and a pty, each from a thread; a `ManualClock` serves them in
            process on that clock (`legs_transport`, `arm_handlers`; see the module docstring).
    """

    def __init__(self, config: RobotEmulatorConfig | None = None, *, clock: ManualClock | None = None) -> None:
        self.config = cfg = config if config is not None else RobotEmulatorConfig()
        if clock is not None and not isinstance(clock, ManualClock):
            raise ConfigError(f"RobotEmulator: clock must be a ManualClock (in process) or None (UDP and pty), got "
                              f"{type(clock).__name__}")
        self.clock = clock
        self.plant = SharedPlant(SharedPlantConfig(robot=cfg.robot, timestep=cfg.timestep, seed=cfg.seed))
        self.legs = UnitreeEmulator(UnitreeEmulatorConfig(robot=LEG_WIRES[cfg.robot], mode=cfg.mode, port=cfg.port,
                                                          control_period=cfg.control_period, seed=cfg.seed,
                                                          held_until_driven=cfg.held_until_driven,
                                                          log_size=cfg.legs_log_size),
                                    sim=self.plant.legs)
        if clock is None:
            self.arm = DynamixelEmulator(self.plant, cfg.arm)
        else:
            self.arm = DynamixelEmulator(self.plant, cfg.arm, clock=clock, in_process=True)
        self._legs_transport: EmulatorTransport | None = None

    # -- lifecycle ------------------------------------------------------------------------------------------------
    def prepare(self) -> RobotEmulator:
        """Build the physics at the standing pose and load its compiled code, binding, opening and starting nothing.

        Idempotent; `start` does it when it is not done. A process that asks for real-time scheduling for the
        emulator's threads calls it first (`UnitreeEmulator.prepare`).
        """
        self.plant.start()
        return self

    def start(self) -> RobotEmulator:
        """Build the physics (unless `prepare` did), bind the UDP port, open the pty, start both threads. Idempotent.

        Raises:
            PortBusyError: the configured UDP port is held by another socket.
        """
        self.plant.start()
        try:
            if self.clock is None:
                self.legs.start()  # resets the plant to its standing pose (seeded)
            elif self._legs_transport is None:
                self._legs_transport = self.legs.transport(self.clock)  # the same, in process
            self.arm.start()  # the servos power up where the plant's arm is
        except BaseException:
            self.close()
            raise
        return self

    def close(self) -> None:
        """Stop both emulators and release the physics. Idempotent."""
        self.arm.close()
        if self._legs_transport is not None:
            self._legs_transport.close()
        self.legs.close()
        self.plant.close()

    def __enter__(self) -> RobotEmulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- what a client needs ----------------------------------------------------------------------------------------
    @property
    def address(self) -> tuple[str, int]:
        """The legs' UDP address on 127.0.0.1."""
        return self.legs.address

    @property
    def port(self) -> str:
        """The arm's serial device (the pty's slave side; in process, the name its port handlers go by)."""
        return self.arm.port

    @property
    def legs_transport(self) -> EmulatorTransport:
        """The legs' wire in process, for `UnitreeRobot(config, transport, clock=...)` (once started).

        Raises:
            ConfigError: the robot serves UDP (built without a clock), or is not started.
        """
        if self._legs_transport is None:
            raise ConfigError("RobotEmulator.legs_transport: only a robot built with a ManualClock, once started, "
                              "has its wires in process; otherwise connect to `address`")
        return self._legs_transport

    def arm_handlers(self, latency_ms: float = 1.0) -> Callable[[str], tuple[Any, Any]]:
        """The arm's bus in process, for `DynamixelArm(config, handlers, clock=...)` (`config.port` = `port`).

        Args:
            latency_ms: the adapter's latency timer [ms], which sets the reply timeout.

        Raises:
            ConfigError: the robot serves a pty (built without a clock).
        """
        return self.arm.port_handlers(latency_ms)

    @property
    def failure(self) -> BaseException | None:
        """The exception that stopped one of the threads, or None while they run."""
        return self.legs.failure or self.arm.failure or self.plant.failure

    # -- test API -------------------------------------------------------------------------------------------------
    def inject(self, fault: Fault | BusFault, value: object = None) -> None:
        """Activate `fault` on the wire it belongs to (`Fault`: the legs' UDP, `BusFault`: the arm's bus)."""
        if isinstance(fault, BusFault):
            self.arm.inject(fault, value)
        else:
            self.legs.inject(fault, value)

    def clear(self, fault: Fault | BusFault | None = None) -> None:
        """Deactivate `fault`, or every fault on both wires if None."""
        if fault is None or isinstance(fault, BusFault):
            self.arm.clear(fault)
        if fault is None or isinstance(fault, Fault):
            self.legs.clear(fault)

    def reset(self, qpos: np.ndarray | None = None) -> None:
        """Put the robot back at its standing pose, or at configuration `qpos` (trunk, quaternion, 15 joints)."""
        self.plant.reset(qpos=qpos)

    def base_truth(self) -> BaseTruth:
        """The simulated trunk's true pose and velocity now."""
        return self.plant.base_truth()

    @property
    def sim_time(self) -> float:
        """Simulation time [s]."""
        return self.plant.time
