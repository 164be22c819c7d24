"""The runner: one loop that plays an episode on any `Robot`, and `run_trial` for simulated trials.

Every control tick: ``state = robot.read()``, ``cmd = schedule.at(t)``, ``out = controller.act(state, cmd)``,
``robot.write(out)``, ``robot.advance(dt)``; then the episode log takes one row and the fall check runs. The loop
is the same for simulation and hardware: only where truth comes from (`truth`) and how a fall is detected
(`fallen`) differ. Falls are checked at the control rate; a fall keeps the trunk on the ground for far longer than a
control period, so none is missed.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

import numpy as np
from threadpoolctl import threadpool_limits

from wbc.arena.episode import Episode, EpisodeBuffer, PushLog
from wbc.arena.record import TrialRecord
from wbc.control.protocol import Controller
from wbc.control.registry import ControllerSpec, get_controller
from wbc.errors import ConfigError
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.hardware.robot import Robot
from wbc.robots.conventions import quat_to_matrix
from wbc.scenario.trial import CommandSchedule, Trial
from wbc.types import BaseTruth, VelocityCommand

__all__ = ["TickObserver", "run_episode", "run_trial", "simulated_robot"]

TickObserver = Callable[[float, Robot, Controller, VelocityCommand], None]
"""Called after every control tick with (time after the tick [s], robot, controller, command); for viewers. It may
block (a paused viewer pauses the loop) but must not change the robot or the controller."""

_ROBOTS: dict[tuple, MujocoRobot] = {}
"""Per-process cache of simulated robots: building a model costs ~50 ms, resetting one ~0.1 ms."""


def run_episode(
    robot: Robot,
    controller: Controller,
    schedule: CommandSchedule,
    duration_s: float,
    *,
    truth: Callable[[], BaseTruth],
    fallen: Callable[[], bool],
    nq: int,
    observer: TickObserver | None = None,
) -> Episode:
    """Play one episode.

    Args:
        robot: a connected robot, already in its initial state.
        controller: the controller (reset here).
        schedule: the velocity command over time.
        duration_s: episode length [s].
        truth: returns the base's true state (simulator truth or motion capture).
        fallen: returns True when the trunk or a non-foot link touches the ground.
        nq: size of the configuration logged for replay.
        observer: called after every tick (e.g. a viewer); None costs nothing.

    Returns:
        The episode log.
    """
    dt = 1.0 / controller.rate_hz
    n = int(round(duration_s / dt))
    buf = EpisodeBuffer(capacity=n, nq=nq)
    controller.reset()
    arm = slice(12, 15) if robot.num_joints == 15 else None
    fell, fall_time = False, math.nan
    for k in range(n):
        t = k * dt
        state = robot.read()
        cmd = schedule.at(t)
        robot.write(controller.act(state, cmd))
        robot.advance(dt)
        tr = truth()
        rot = quat_to_matrix(tr.base_quat)
        yaw = math.atan2(rot[1, 0], rot[0, 0])
        c, s = math.cos(yaw), math.sin(yaw)
        v = tr.base_linvel_in_world
        i = buf.rows
        buf.t[i] = (k + 1) * dt
        buf.command[i] = (cmd.vx, cmd.vy, cmd.yaw_rate)
        buf.v_base_in_yaw[i] = (c * v[0] + s * v[1], -s * v[0] + c * v[1])
        buf.yaw_rate[i] = rot[2] @ tr.base_angvel_in_body
        buf.roll[i] = math.atan2(rot[2, 1], rot[2, 2])
        buf.pitch[i] = -math.asin(max(-1.0, min(1.0, rot[2, 0])))
        buf.power[i] = float(np.abs(state.tau_est * state.dq).sum())
        if arm is not None:
            buf.arm_q[i] = state.q[arm]
        buf.qpos[i, :3] = tr.base_position_in_world
        buf.qpos[i, 3:7] = tr.base_quat
        buf.qpos[i, 7:] = state.q
        buf.rows += 1
        if observer is not None:
            observer((k + 1) * dt, robot, controller, cmd)
        if fallen():
            fell, fall_time = True, (k + 1) * dt
            break
    return buf.finish(duration_s=duration_s, control_dt=dt, fell=fell, fall_time_s=fall_time)


def simulated_robot(trial: Trial, arm_mode: str) -> MujocoRobot:
    """The connected simulated robot for `trial`'s robot, terrain and `arm_mode`, built once per process."""
    key = (trial.robot, arm_mode, trial.terrain)
    robot = _ROBOTS.get(key)
    if robot is None:
        robot = MujocoRobot(MujocoRobotConfig(robot=trial.robot, arm_mode=arm_mode, terrain=trial.terrain))
        robot.connect()
        _ROBOTS[key] = robot
    return robot


def run_trial(trial: Trial, controller: ControllerSpec | str, *, debug_truth: bool = False,
              observer: TickObserver | None = None) -> tuple[TrialRecord, Episode]:
    """Play `trial` in simulation with `controller` (`observer`: see `run_episode`).

    With `debug_truth` the controller's ground-truth debug switch is thrown (it reads the simulator's base state
    instead of estimating it) and the record says so.

    Args:
        trial: the trial.
        controller: the resolved controller (`wbc.control.registry.get_controller`), or its name, resolved here.
        debug_truth: throw the controller's ground-truth debug switch (`wbc.control.protocol.TruthSwitch`).
        observer: called after every tick.

    Returns:
        The trial's record and the episode log.

    Raises:
        UnknownNameError: unknown controller name.
        ConfigError: the controller's period is not a whole number of physics steps.
    """
    spec = get_controller(controller) if isinstance(controller, str) else controller
    # one BLAS thread: a multi-threaded product splits its sums differently, and the same trial would differ in its
    # last bits between an in-process run and a pool worker (which starts single-threaded)
    with threadpool_limits(limits=1, user_api="blas"):
        return _run_trial(trial, spec, debug_truth=debug_truth, observer=observer)


def _run_trial(trial: Trial, spec: ControllerSpec, *, debug_truth: bool, observer: TickObserver | None,
               ) -> tuple[TrialRecord, Episode]:
    start = time.perf_counter()
    controller = spec.name
    robot = simulated_robot(trial, spec.arm_mode)
    ctrl = spec.make(robot.desc)
    ratio = (1.0 / ctrl.rate_hz) / robot.config.timestep
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        raise ConfigError(
            f"controller {controller!r}: period 1/{ctrl.rate_hz} s is not a multiple of the physics step "
            f"{robot.config.timestep} s"
        )
    if debug_truth:
        attach = getattr(ctrl, "use_ground_truth", None)
        if attach is None:
            raise ConfigError(f"controller {controller!r} has no ground-truth debug switch (--debug-truth)")
        attach(robot.base_truth)
    robot.reset(seed=trial.terrain_seed, domain=trial.domain)
    for push in trial.pushes:
        robot.apply_push(push)
    episode = run_episode(robot, ctrl, trial.command, trial.duration_s, truth=robot.base_truth,
                          fallen=robot.fallen, nq=robot.model.nq, observer=observer)
    met = PushLog.of(p for p in trial.pushes if p.start < episode.survived_s)
    episode = dataclasses.replace(episode, pushes=met)
    record = TrialRecord.of_trial(trial, controller=controller, episode=episode, counters=ctrl.counters(),
                                  wall_s=time.perf_counter() - start, debug_truth=debug_truth)
    return record, episode
