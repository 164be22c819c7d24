"""How much angular momentum the arm actually moves during push recovery: the data behind the docs' tail answer.

For each trial of a scenario band, the named controller plays the trial as `wbc run` plays it (`run_trial`), watched
by a `WatchedController` in its place (which keeps the state each tick handed it). An observer of that loop computes,
every tick, the arm's contribution to the centroidal angular momentum, h_arm = A_arm(q) dq_arm (A_arm: the arm's
columns of Pinocchio's centroidal momentum matrix, evaluated at the simulator's true base pose and the measured joint
positions; dq_arm: the measured arm joint velocities, as the controller saw them). The per-push figures compare it with
the angular impulse each push delivers about the CoM, |r x F| T (r: from the CoM to the push's application point). A
tail that matters must move momentum of the order of that impulse.

Two more figures per push say how much of what the arm could do it did, and whether it did it the right way:

- the arm's *bound* at the push's start: the most momentum it could hold from the pose it had, max |A_arm(q) dq| over
  its joint speeds within the servos' no-load limits (a convex function on a box: its largest value is at one of the
  box's 8 corners); the peak |h_arm| after the push as a fraction of it;
- the *alignment* of the arm's momentum with the push: the cosine between h_arm at its peak and the push's angular
  impulse r x F. A tail that takes up the push's angular momentum, so that the trunk need not, has it near +1; an
  arm the trunk merely shakes has no consistent sign.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from wbc.arena.controller_failure import ControllerFailure
from wbc.arena.identity import MAX_RUN_TRIALS
from wbc.arena.sim_trial import run_trial
from wbc.control.protocol import Controller
from wbc.control.registry import get_controller
from wbc.control.spec import ControllerSpec
from wbc.errors import AnalysisError, ConfigError
from wbc.hardware.capabilities import TruthSource
from wbc.hardware.robot import Robot
from wbc.robots.conventions import quat_to_matrix, quat_wxyz_to_xyzw
from wbc.robots.description import ARM_JOINTS
from wbc.robots.joint_table import joint_table
from wbc.robots.pinocchio_model import PinocchioRobot, build_pinocchio
from wbc.scenario.scenario import load_scenario
from wbc.scenario.trial import Trial
from wbc.tools.watched_controller import WatchedController
from wbc.types import VelocityCommand

__all__ = ["ArmMomentumLog", "ArmMomentumTrial", "arm_momentum_bound", "arm_momentum_study"]

_BOX_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)


def arm_momentum_bound(a_arm: np.ndarray, speed_limit: np.ndarray) -> float:
    """The most angular momentum |A_arm dq| the arm can hold with each joint speed within +-`speed_limit`.

    A norm of a linear map is convex, so its largest value over the box of speeds is at one of the box's corners.

    Args:
        a_arm: the arm's columns of the centroidal momentum matrix's angular rows, shape (3, 3).
        speed_limit: the joints' speed limits (3,) [rad/s].
    """
    return float(np.linalg.norm((_BOX_CORNERS * speed_limit) @ np.asarray(a_arm).T, axis=1).max())


@dataclass(frozen=True, kw_only=True)
class ArmMomentumTrial:
    """One trial's figures.

    The per-push figures are means over the pushes measured: those that started before the trial ended. A trial
    that fell before its first push (or whose band has no push) has none, and its per-push figures are nan.

    Attributes:
        controller: controller name.
        arm_mode: the controller's arm mode: ``actuated``, or ``locked`` / ``none`` (no arm that moves on its own:
            its momentum figures are zero, its bound fraction and alignment nan).
        band: scenario band.
        seed: seed.
        trial: trial index.
        survived: the trial ended without a fall.
        pushes: the trial's pushes.
        pushes_measured: those that started before the trial ended (a fall ends it).
        arm_travel_rad: summed absolute arm joint motion [rad].
        push_angular_impulse: mean over the pushes measured of |r x F| T about the CoM [N m s] (nan without one).
        arm_momentum_peak: mean over pushes of the largest |h_arm| within 0.5 s of the push's start [N m s] (nan
            without a push measured).
        arm_momentum_mean: mean |h_arm| over the whole trial [N m s].
        arm_momentum_bound: mean over pushes of the most |h_arm| the arm could hold from its pose at the push's start,
            its joints at their no-load speeds [N m s] (0 without an actuated arm; nan without a push measured).
        bound_fraction: mean over pushes of the peak |h_arm| after the push over that bound (nan without an arm).
        alignment: mean over pushes of the cosine between h_arm at its peak and the push's r x F (nan without an
            arm, or where the arm held no momentum).
        controller_config: the ``--controller-config`` file the controller was built with, as given, or None.
    """

    controller: str
    arm_mode: str
    band: str
    seed: int
    trial: int
    survived: bool
    pushes: int
    pushes_measured: int
    arm_travel_rad: float
    push_angular_impulse: float
    arm_momentum_peak: float
    arm_momentum_mean: float
    arm_momentum_bound: float = 0.0
    bound_fraction: float = float("nan")
    alignment: float = float("nan")
    controller_config: str | None = None


@dataclass
class ArmMomentumLog:
    """A runner observer gathering, tick by tick, what the study needs (one row per tick played).

    The runner hands it the robot (a `TruthSource`: the simulator's base truth is read after each tick) and the
    controller it drives, a `WatchedController` (the state each tick was handed).

    Attributes:
        pin_robot: the Pinocchio model of the robot played (built at the first tick).
        h_arm: |h_arm| of each tick [N m s] (zero without an actuated arm).
        h_arm_vec: h_arm of each tick, world frame [N m s].
        bound: the most |h_arm| the arm could hold from each tick's pose, its speeds within their limits [N m s].
        com_in_world: system CoM of each tick [m].
        rotation_base_in_world: base orientation of each tick.
        position_base_in_world: base position of each tick [m].
        arm_travel_rad: summed absolute arm joint motion so far [rad].
    """

    pin_robot: PinocchioRobot | None = None
    h_arm: list[float] = field(default_factory=list)
    h_arm_vec: list[np.ndarray] = field(default_factory=list)
    bound: list[float] = field(default_factory=list)
    com_in_world: list[np.ndarray] = field(default_factory=list)
    rotation_base_in_world: list[np.ndarray] = field(default_factory=list)
    position_base_in_world: list[np.ndarray] = field(default_factory=list)
    arm_travel_rad: float = 0.0
    _last_arm: np.ndarray | None = field(default=None, init=False, repr=False)
    _speed_limit: np.ndarray | None = field(default=None, init=False, repr=False)

    def __call__(self, t: float, robot: Robot, controller: Controller, command: VelocityCommand) -> None:
        """Take the tick that just ended (the runner's `TickObserver` signature)."""
        if not isinstance(controller, WatchedController) or not isinstance(robot, TruthSource):
            raise AnalysisError("the arm-momentum log observes a WatchedController on a robot that knows its base "
                                "truth (the simulator); play the trial with `arm_momentum_study`")
        if self.pin_robot is None:
            self.pin_robot = build_pinocchio(robot.desc)
        state, pinr = controller.last_state, self.pin_robot
        truth = robot.base_truth()
        q = np.concatenate([truth.base_position_in_world, quat_wxyz_to_xyzw(truth.base_quat),
                            state.q[pinr.joints.pin_from_house]])
        self.com_in_world.append(pin.centerOfMass(pinr.model, pinr.data, q).copy())
        self.rotation_base_in_world.append(quat_to_matrix(truth.base_quat))
        self.position_base_in_world.append(truth.base_position_in_world)
        h, bound = np.zeros(3), 0.0
        if robot.num_joints == 15:
            if self._speed_limit is None:
                self._speed_limit = joint_table(robot.desc).velocity_limit[ARM_JOINTS]
            arm_cols = 6 + pinr.joints.house_from_pin[ARM_JOINTS]
            pin.computeCentroidalMap(pinr.model, pinr.data, q)
            a_arm = pinr.data.Ag[3:, arm_cols]
            h = a_arm @ state.dq[ARM_JOINTS]
            bound = arm_momentum_bound(a_arm, self._speed_limit)
            if self._last_arm is not None:
                self.arm_travel_rad += float(np.abs(state.q[ARM_JOINTS] - self._last_arm).sum())
            self._last_arm = state.q[ARM_JOINTS].copy()
        self.h_arm.append(float(np.linalg.norm(h)))
        self.h_arm_vec.append(h)
        self.bound.append(bound)


def arm_momentum_study(scenario_path: str, controller: str, *, band: str, seeds: tuple[int, ...] = (0,),
                       trials: int = 5, duration_s: float | None = None, config: str | Path | None = None,
                       io: str | Path | None = None) -> list[ArmMomentumTrial]:
    """Play `trials` trials per seed of `band` with `controller` and measure the arm's momentum against the pushes.

    Args:
        scenario_path: the scenario file (a relative path is resolved as `load_scenario` does).
        controller: controller registry name.
        band: scenario band.
        seeds: seeds to play.
        trials: trials per seed.
        duration_s: shortens every trial (default: the scenario's length) [s].
        config: a plug-in's ``--controller-config`` TOML file (as `get_controller` takes it), read once.
        io: an ``onnx:PATH`` policy's I/O file (default: beside the model).

    Returns:
        One row per trial, in the scenario's trial order.

    Raises:
        ScenarioError, UnknownNameError: bad scenario, band or controller.
        ConfigError: more trials than one run plays (`wbc.arena.identity.MAX_RUN_TRIALS`), as the arena refuses.
        AnalysisError: the controller failed in a trial (its factory, ``reset`` or ``act`` raised, or ``act``
            returned a command the robot refuses); the message names it and the trial.
    """
    if len(seeds) * trials > MAX_RUN_TRIALS:
        raise ConfigError(f"{len(seeds)} seeds x {trials} trials = {len(seeds) * trials:,} trials, more than the "
                          f"{MAX_RUN_TRIALS:,} one run plays; pass fewer --seeds or --trials")
    scenario = load_scenario(scenario_path)
    # resolved once, before the first trial is played: an unknown name or a bad file fails at once, and a plug-in's
    # settings table is read once for every trial
    spec = get_controller(controller, config=config, io=io)
    out = []
    for trial in scenario.trials([band], list(seeds), trials):
        if duration_s is not None:
            trial = dataclasses.replace(trial, duration_s=duration_s)
        row = _study_trial(trial, controller, spec)
        out.append(row if config is None else dataclasses.replace(row, controller_config=str(config)))
    return out


def _study_trial(trial: Trial, controller: str, spec: ControllerSpec) -> ArmMomentumTrial:
    watched = dataclasses.replace(spec, make=lambda desc: WatchedController(spec.make(desc)))
    log = ArmMomentumLog()
    try:
        _, episode = run_trial(trial, watched, observer=log, record_errors=False)
    except ControllerFailure as exc:  # the line names which controller failed, and in which trial
        raise AnalysisError(f"arm-momentum: controller {controller!r} failed in band {trial.band}, seed {trial.seed}, "
                            f"trial {trial.index}: {exc}") from exc
    dt, played = episode.control_dt, len(log.h_arm)
    h_arm = np.asarray(log.h_arm)
    impulses, peaks, bounds, fractions, cosines = [], [], [], [], []
    for push in trial.pushes:
        k0 = int(push.start / dt)
        if k0 >= played:
            continue
        lever = (log.position_base_in_world[k0] + log.rotation_base_in_world[k0] @ push.offset_in_base
                 - log.com_in_world[k0])
        turn = np.cross(lever, push.force_in_world)
        impulses.append(float(np.linalg.norm(turn)) * push.duration)
        window = slice(k0, min(played, k0 + int(0.5 / dt)))
        k_peak = k0 + int(np.argmax(h_arm[window]))
        peaks.append(float(h_arm[k_peak]))
        bounds.append(log.bound[k0])
        if log.bound[k0] > 0.0:
            fractions.append(peaks[-1] / log.bound[k0])
        norms = float(np.linalg.norm(turn)) * peaks[-1]
        if norms > 0.0:
            cosines.append(float(log.h_arm_vec[k_peak] @ turn) / norms)
    # a trial with no push measured (it fell before its first, or its band has none) has nothing to set the arm
    # against: nan, never a zero impulse and a zero peak that would pull the means down
    return ArmMomentumTrial(
        controller=controller, arm_mode=spec.arm_mode, band=trial.band, seed=trial.seed, trial=trial.index,
        survived=not episode.fell, pushes=len(trial.pushes), pushes_measured=len(impulses),
        arm_travel_rad=log.arm_travel_rad, push_angular_impulse=float(np.mean(impulses)) if impulses else math.nan,
        arm_momentum_peak=float(np.mean(peaks)) if peaks else math.nan,
        arm_momentum_mean=float(h_arm.mean()) if played else 0.0,
        arm_momentum_bound=float(np.mean(bounds)) if bounds else math.nan,
        bound_fraction=float(np.mean(fractions)) if fractions else float("nan"),
        alignment=float(np.mean(cosines)) if cosines else float("nan"))
