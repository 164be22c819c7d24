"""`check_hardware`: read a robot through the safety layer for a while, sending only damping; say what was read.

The procedure behind ``wbc hw check``. It builds the robot (the legs' `UnitreeRobot`, and the arm's `DynamixelArm`
when its serial port is given), lets the caller confirm a real robot before anything connects, then reads states
through `SafeRobot` without ever writing to it: the layer's checks judge each state, and a trip only sends damping.
The result, a `HardwareCheck`, holds the newest state, the limits the layer checks, its verdict and the links'
counters; the command prints it. A robot that sends no valid state at all within the link's connect timeout is a
result too: no state, the link's account of what came (`HardwareCheck.no_state`), the layer still waiting.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from wbc.errors import ArmRefusedError, NoStateStreamError
from wbc.hardware.capabilities import SafetyEventLike, WallClock
from wbc.hardware.device_thread import DeviceThreadStats
from wbc.hardware.dynamixel import ArmBusStats, ArmMotorStatus, DynamixelArm, DynamixelArmConfig, ServoReading
from wbc.hardware.hardware_robot import HardwareRobot, HardwareRobotConfig, build_hardware_robot
from wbc.hardware.interpreter import frozen_heap
from wbc.hardware.quadruped_arm_robot import QuadrupedArmRobot
from wbc.hardware.safety import SafeRobot, SafetyConfig, SafetyEvent
from wbc.hardware.unitree import DecodeStats, LinkStats, LowStateExtras
from wbc.types import RobotState

__all__ = ["CHECK_STEP_S", "HardwareCheck", "HardwareCheckConfig", "check_hardware"]

CHECK_STEP_S = 0.01
"""How far the robot's clock advances between two reads of a check [s]."""


@dataclass(frozen=True, kw_only=True)
class HardwareCheckConfig:
    """Which robot to check, where it is, and for how long.

    The addresses and the serial port are taken as given: the policy (loopback, a pseudo-terminal, or
    ``allow_hardware`` and a confirmation) is the caller's, before this runs.

    Attributes:
        robot: the robot registry's name (``go1-arm``, ``a1-wx200``).
        label: the robot's name as the person gave it (``go1`` or ``go1-arm``), for the printout.
        target: the legs' address (host, port).
        local: the address to bind (host, port).
        seconds: how long to read states, on the robot's clock [s].
        transport: the legs' datagram channel (`wbc.hardware.unitree.TRANSPORTS`).
        arm_port: the arm's serial device, or None (legs only).
        allow_hardware: a real robot may be reached (an address outside 127.0.0.0/8, a real serial device).
        safety: the safety layer's settings (its stale timeout, limits, ramp); its position table is the robot's
            and its events are the check's, whatever this one says.
    """

    robot: str
    label: str
    target: tuple[str, int]
    local: tuple[str, int]
    seconds: float
    transport: str = "udp"
    arm_port: str | None = None
    allow_hardware: bool = False
    safety: SafetyConfig = field(default_factory=SafetyConfig)


@dataclass(frozen=True)
class HardwareCheck:
    """What ``wbc hw check`` read: the state through the safety layer, the limits it checks, the links' counters.

    Attributes:
        robot: the robot's name as given (``go1``, ``go1-arm``).
        target: the legs' address.
        joint_names: the joints read, house order (the arm's last, when its port was given).
        state: the newest state; None when no valid state came at all (`no_state` says why).
        lower: each joint's lower limit as the safety layer checks it [rad].
        upper: each joint's upper limit [rad].
        margin: how far beyond a limit the layer lets a measured joint go [rad].
        extras: the legs' newest frame's extras (motor modes, temperatures, remote, battery).
        link: the legs' link counters.
        link_thread: the legs' link thread's statistics (period, late sends, overruns).
        decode: the legs' rejected frames by reason.
        safety_state: the layer's state at the end (``ramp`` when a ramp would start from here).
        safety_events: the layer's transitions during the check.
        arm_port: the arm's serial device, or None (legs only).
        arm_status: the arm servos' status (modes, temperatures), or None.
        arm_faults: the arm's latched bus faults.
        arm_bus: the arm's bus counters, or None.
        arm_thread: the arm's bus loop's statistics, or None.
        stale_frames: valid frames the link refused for their tick (it did not advance past the newest taken: a
            frozen board repeating its buffer, or a robot that restarted, whose tick starts below the old one).
        no_state: why no live state stream came (the link's message: what came, and what to check), or None when
            states came; the layer then stays ``waiting`` and the limits are empty.
        arm_refused: why the arm's backend refused to drive the arm when it connected (a servo's hardware error, a
            servo that did not answer its ping: `ArmRefusedError`'s message, with what to do), or None. The legs were
            then read alone (`joint_names`, `state` and the layer's verdict are theirs) and the arm surveyed
            (`arm_servos`); the check's verdict is a refusal either way.
        arm_servos: each servo of the arm as a read-only pass found it after that refusal (`DynamixelArm.survey`);
            empty when the arm was driven.
    """

    robot: str
    target: tuple[str, int]
    joint_names: Sequence[str]
    state: RobotState | None
    lower: np.ndarray
    upper: np.ndarray
    margin: float
    extras: LowStateExtras | None
    link: LinkStats
    link_thread: DeviceThreadStats
    decode: DecodeStats
    safety_state: str
    safety_events: Sequence[SafetyEventLike]
    arm_port: str | None = None
    arm_status: ArmMotorStatus | None = None
    arm_faults: Sequence[object] = ()
    arm_bus: ArmBusStats | None = None
    arm_thread: DeviceThreadStats | None = None
    no_state: str | None = None
    arm_refused: str | None = None
    arm_servos: tuple[ServoReading, ...] = ()
    stale_frames: int = 0

    @property
    def ready(self) -> bool:
        """True when the safety layer would start a ramp from the state read and the arm (if any) was driven."""
        return self.safety_state == "ramp" and self.arm_refused is None


def check_hardware(cfg: HardwareCheckConfig, *,
                   build: Callable[[HardwareRobotConfig], HardwareRobot] = build_hardware_robot,
                   confirm: Callable[[HardwareRobot], None] | None = None) -> HardwareCheck:
    """Read the robot through the safety layer for `cfg.seconds` of its clock, sending only damping.

    Args:
        cfg: which robot, where, and for how long.
        build: builds the robot from its config (a test hands its devices a clock it moves and an emulator's
            in-process channel; the seconds are then the robot's clock's).
        confirm: called with the built robot before anything connects; it raises to refuse (the command asks the
            person at the terminal about a real robot here).

    Returns:
        What was read: the newest state, the layer's verdict, the links' counters; when no valid state came within
        the link's connect timeout, no state and why (`HardwareCheck.no_state`); when the arm's backend refused a
        servo at connect (`ArmRefusedError`), the legs read alone, the arm's servos surveyed without driving them
        and why (`HardwareCheck.arm_refused`).
    """
    host, port = cfg.target
    local_host, local_port = cfg.local
    # the wrist and gripper, which no model joint moves, are held where they are: a check moves nothing
    arm = None
    if cfg.arm_port:
        arm = DynamixelArmConfig(robot=cfg.robot, port=cfg.arm_port, allow_hardware=cfg.allow_hardware)
        arm = replace(arm, held_ticks=(None,) * len(arm.held_servos))
    hardware = build(HardwareRobotConfig(
        robot=cfg.robot, arm_mode="actuated" if cfg.arm_port else "none", legs_host=host,
        legs_port=port, local_host=local_host, local_port=local_port, allow_hardware=cfg.allow_hardware,
        transport=cfg.transport, arm=arm))
    if confirm is not None:
        confirm(hardware)
    # all is built: a full collection of the start-up heap would stall the link and bus threads for 100 ms or more,
    # long enough for the layer to call a live state stale (`wbc.hardware.interpreter`); a library call, the check
    # hands the heap back to the collector when it returns
    with frozen_heap():
        return _check_built(cfg, hardware)


def _check_built(cfg: HardwareCheckConfig, hardware: HardwareRobot) -> HardwareCheck:
    """`check_hardware` once the robot is built and the heap frozen: connect, read, close."""
    events: list[SafetyEvent] = []
    # Read through the safety layer, never written to: its checks judge each state, and a trip only sends damping.
    safe = SafeRobot(hardware.robot, replace(cfg.safety, position_table=hardware.position_table,
                                             on_event=events.append))
    legs = hardware.robot.legs if isinstance(hardware.robot, QuadrupedArmRobot) else hardware.robot
    arm = hardware.robot.arm if isinstance(hardware.robot, QuadrupedArmRobot) else None
    clock = hardware.robot.wall_time if isinstance(hardware.robot, WallClock) else time.monotonic
    try:
        safe.connect()
    except NoStateStreamError as exc:  # nothing to judge: a result of the check, not a failure of the command
        empty = np.zeros(0)
        return HardwareCheck(
            robot=cfg.label, target=cfg.target, joint_names=(), state=None, lower=empty, upper=empty,
            margin=safe.config.joint_margin, extras=None, link=legs.link_stats(), link_thread=legs.thread_stats(),
            decode=legs.decode_stats,
            stale_frames=legs.stale_frames, safety_state=safe.safety_state.value, safety_events=tuple(events),
            arm_port=cfg.arm_port, no_state=str(exc))
    except ArmRefusedError as refused:  # a servo's state, read at connect: a result of the check, with what answers
        if not isinstance(arm, DynamixelArm):
            raise
        return _legs_beside_a_refused_arm(cfg, hardware, arm, str(refused), clock)
    with safe:
        state = _read_for(safe, clock, cfg.seconds)
        return HardwareCheck(
            robot=cfg.label, target=cfg.target, joint_names=safe.joint_names, state=state,
            lower=safe.position_lower, upper=safe.position_upper, margin=safe.config.joint_margin,
            extras=legs.extras, link=legs.link_stats(), link_thread=legs.thread_stats(), decode=legs.decode_stats,
            stale_frames=legs.stale_frames,
            safety_state=safe.safety_state.value, safety_events=tuple(events), arm_port=cfg.arm_port,
            arm_status=arm.motor_status() if arm is not None else None,
            arm_faults=arm.faults if arm is not None else (), arm_bus=arm.bus_stats() if arm is not None else None,
            arm_thread=arm.thread_stats() if arm is not None else None)


def _read_for(safe: SafeRobot, clock: Callable[[], float], seconds: float) -> RobotState:
    """Read `safe` (connected) for `seconds` of `clock`, never writing to it; the newest state."""
    end = clock() + seconds
    for _ in range(int(seconds / CHECK_STEP_S) + 2):
        if clock() >= end:
            break
        safe.read()
        safe.advance(CHECK_STEP_S)
    return safe.read()


def _legs_beside_a_refused_arm(cfg: HardwareCheckConfig, hardware: HardwareRobot, arm: DynamixelArm, refused: str,
                               clock: Callable[[], float]) -> HardwareCheck:
    """The legs read alone through their own safety layer, then the arm's servos surveyed without driving them.

    The robot's connect refused the arm (`ArmRefusedError`, its bus closed again) and closed the legs with it
    (connect both or neither); the check connects the legs again on their own, as ``hw check`` without
    ``--arm-port`` would.
    """
    legs = hardware.robot.legs
    events: list[SafetyEvent] = []
    safe = SafeRobot(legs, replace(cfg.safety, position_table=hardware.position_table, on_event=events.append))
    try:
        safe.connect()
    except NoStateStreamError as exc:
        empty = np.zeros(0)
        return HardwareCheck(
            robot=cfg.label, target=cfg.target, joint_names=(), state=None, lower=empty, upper=empty,
            margin=safe.config.joint_margin, extras=None, link=legs.link_stats(), link_thread=legs.thread_stats(),
            decode=legs.decode_stats,
            stale_frames=legs.stale_frames, safety_state=safe.safety_state.value, safety_events=tuple(events),
            arm_port=cfg.arm_port, no_state=str(exc), arm_refused=refused, arm_servos=arm.survey())
    with safe:
        state = _read_for(safe, clock, cfg.seconds)
        check = HardwareCheck(
            robot=cfg.label, target=cfg.target, joint_names=safe.joint_names, state=state,
            lower=safe.position_lower, upper=safe.position_upper, margin=safe.config.joint_margin,
            extras=legs.extras, link=legs.link_stats(), link_thread=legs.thread_stats(), decode=legs.decode_stats,
            stale_frames=legs.stale_frames,
            safety_state=safe.safety_state.value, safety_events=tuple(events), arm_port=cfg.arm_port,
            arm_refused=refused)
    return replace(check, arm_servos=arm.survey())
