"""Posture: how high each controller carries the trunk, standing and walking, on flat ground without pushes.

A push-recovery comparison between two controllers is only fair at the same posture: a robot that crouches has a low
centre of mass and short levers and survives pushes that topple an upright one. For each controller the robot plays
one episode per command (the arena's physics: `MujocoRobot`, nominal domain, no sensor noise, flat ground, the
runner's loop), and the study reports the mean trunk height above the ground and the mean forward speed over the
episode's second half (after the command's ramp and the start transient), so "stands at 0.28 m and walks at 0.3 m/s"
is a measured statement. Trunk height is the base frame's origin above the flat ground, from the simulator's truth.
Nothing is drawn at random (no terrain, domain or noise to draw), so the study takes no seed: its figures are the same
on every run.
An episode whose simulation blows up costs only its own row (nan, and what diverged).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from wbc.arena.controller_failure import ControllerFailure
from wbc.arena.divergence import DivergenceCheck, SimulationDiverged
from wbc.arena.runner import run_episode
from wbc.control.registry import get_controller
from wbc.control.spec import ControllerSpec
from wbc.errors import CONTROLLER_ERRORS, AnalysisError, ConfigError, UnknownNameError
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.robots.registry import ROBOTS
from wbc.scenario.trial import CommandSchedule

__all__ = ["PostureRow", "posture_study"]


@dataclass(frozen=True, kw_only=True)
class PostureRow:
    """One controller under one command.

    Attributes:
        controller: controller name.
        robot: robot registry name.
        arm_mode: the arm mode it was played with.
        command: ``stand`` or ``walk``.
        vx: commanded forward speed [m/s].
        height_m: mean trunk height above the ground over the averaging window [m] (nan if it fell: a falling
            trunk's height says nothing about its posture).
        height_std_m: its standard deviation over the window [m] (the gait's bounce; nan likewise).
        speed_m_s: mean forward speed (yaw frame) over the window [m/s] (nan likewise).
        fell: the episode ended with a fall.
        fall_time_s: when (nan if it did not fall) [s].
        diverged: what blew up if the simulation diverged (`wbc.arena.divergence.SimulationDiverged`; the
            measurements are nan), else None.
    """

    controller: str
    robot: str
    arm_mode: str
    command: str
    vx: float
    height_m: float
    height_std_m: float
    speed_m_s: float
    fell: bool
    fall_time_s: float
    diverged: str | None = None


def posture_study(controllers: Sequence[str], *, robot: str = "a1-wx200", walk_vx: float = 0.3,
                  duration_s: float = 6.0, ramp_s: float | None = None,
                  duration_option: str = "duration_s") -> list[PostureRow]:
    """Play each controller standing (zero command) and walking (`walk_vx` forward) and measure its trunk height.

    Args:
        controllers: controller names (registry names, ``policy:PATH`` ...).
        robot: robot registry name.
        walk_vx: forward speed of the walking command [m/s].
        duration_s: length of each episode [s]; the mean is taken over its second half.
        ramp_s: the walking command rises from zero over this time [s]; None: 0.5 s, or half the episode if
            shorter.
        duration_option: what the messages call `duration_s` (the command's ``--duration``).

    Returns:
        Two rows per controller (stand, walk), in the order given.

    Raises:
        ConfigError: a non-positive duration or one shorter than a controller's period, a ramp longer than half the
            episode, or a controller that cannot drive `robot`.
        AnalysisError: a controller failed (its factory, ``reset`` or ``act`` raised, or ``act`` returned a command
            the robot refuses); the message names it.
        UnknownNameError: an unknown controller or robot name.
    """
    if not duration_s > 0:
        raise ConfigError(f"posture: {duration_option} must be positive, got {duration_s}")
    if ramp_s is None:
        ramp_s = min(0.5, duration_s / 2)
    if not 0 <= ramp_s <= duration_s / 2:
        raise ConfigError(f"posture: ramp_s must lie in [0, duration_s / 2] = [0, {duration_s / 2}], got {ramp_s}")
    if robot not in ROBOTS:
        raise UnknownNameError("robot", robot, tuple(ROBOTS))
    specs = [get_controller(name) for name in controllers]
    for spec in specs:
        if (robot, spec.arm_mode) not in spec.claims():
            raise ConfigError(f"posture: controller {spec.name!r} cannot drive robot {robot!r} with arm mode "
                              f"{spec.arm_mode!r} (it drives {spec.claims()})")
    commands = (("stand", CommandSchedule()), ("walk", CommandSchedule(vx=walk_vx, ramp_s=ramp_s)))
    rows = []
    with threadpool_limits(limits=1, user_api="blas"):
        for spec in specs:
            sim = MujocoRobot(MujocoRobotConfig(robot=robot, arm_mode=spec.arm_mode))
            sim.connect()
            try:
                for name, schedule in commands:
                    rows.append(_play(sim, spec, name, schedule, duration_s=duration_s,
                                      duration_option=duration_option))
            finally:
                sim.close()
    return rows


def _play(sim: MujocoRobot, spec: ControllerSpec, name: str, schedule: CommandSchedule, *, duration_s: float,
          duration_option: str) -> PostureRow:
    try:
        controller = spec.make(sim.desc)
    except CONTROLLER_ERRORS as exc:  # the controller's code, not ours: named, as a failure in the episode is
        raise AnalysisError(f"posture: controller {spec.name!r}: building it raised {type(exc).__name__}: {exc}") \
            from exc
    sim.reset()  # a reset's seed draws the terrain and the sensor noise, and here there are neither
    try:
        episode = run_episode(sim, controller, schedule, duration_s, divergence=DivergenceCheck(),
                              duration_option=duration_option)
    except ControllerFailure as exc:  # the line names which controller failed, and in which episode
        raise AnalysisError(f"posture: controller {spec.name!r} failed {'standing' if name == 'stand' else 'walking'}"
                            f": {exc}") from exc
    except SimulationDiverged as exc:  # only this row's numbers are lost: nan, and what diverged
        return PostureRow(controller=spec.name, robot=sim.config.robot, arm_mode=spec.arm_mode, command=name,
                          vx=schedule.vx, height_m=math.nan, height_std_m=math.nan, speed_m_s=math.nan, fell=False,
                          fall_time_s=math.nan, diverged=exc.describe())
    window = episode.t > duration_s / 2
    if not episode.fell:
        z = episode.qpos[window, 2]
        height, spread = float(np.mean(z)), float(np.std(z))
        speed = float(np.mean(episode.v_base_in_yaw[window, 0]))
    else:
        height = spread = speed = math.nan
    return PostureRow(controller=spec.name, robot=sim.config.robot, arm_mode=spec.arm_mode, command=name,
                      vx=schedule.vx, height_m=height, height_std_m=spread, speed_m_s=speed, fell=episode.fell,
                      fall_time_s=episode.fall_time_s)

