"""How much angular momentum the arm actually moves during push recovery: the data behind the README's tail answer.

For each trial of a scenario band, the named controller plays the trial as `wbc run` plays it (`run_trial`), watched
by a `WatchedController` in its place (which keeps the state each tick handed it). An observer of that loop computes,
every tick, the arm's contribution to the centroidal angular momentum, h_arm = A_arm(q) dq_arm (A_arm: the arm's
columns of Pinocchio's centroidal momentum matrix, evaluated at the simulator's true base pose and the measured joint
positions; dq_arm: the measured arm joint velocities, as the controller saw them). The per-push figures compare it with
the angular impulse each push delivers about the CoM, |r x F| T (r: from the CoM to the push's application point). A
tail that matters must move momentum of the order of that impulse.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from wbc.arena.sim_trial import run_trial
from wbc.control.protocol import Controller
from wbc.control.registry import get_controller
from wbc.errors import AnalysisError
from wbc.hardware.capabilities import TruthSource
from wbc.hardware.robot import Robot
from wbc.robots.conventions import quat_to_matrix, quat_wxyz_to_xyzw
from wbc.robots.description import ARM_JOINTS
from wbc.robots.pinocchio_model import PinocchioRobot, build_pinocchio
from wbc.scenario.scenario import load_scenario
from wbc.scenario.trial import Trial
from wbc.tools.watched_controller import WatchedController
from wbc.types import VelocityCommand

__all__ = ["ArmMomentumLog", "ArmMomentumTrial", "arm_momentum_study"]


@dataclass(frozen=True, kw_only=True)
class ArmMomentumTrial:
    """One trial's figures.

    Attributes:
        controller: controller name.
        band: scenario band.
        seed: seed.
        trial: trial index.
        survived: the trial ended without a fall.
        arm_travel_rad: summed absolute arm joint motion [rad].
        push_angular_impulse: mean over the trial's pushes of |r x F| T about the CoM [N m s].
        arm_momentum_peak: mean over pushes of the largest |h_arm| within 0.5 s of the push's start [N m s].
        arm_momentum_mean: mean |h_arm| over the whole trial [N m s].
    """

    controller: str
    band: str
    seed: int
    trial: int
    survived: bool
    arm_travel_rad: float
    push_angular_impulse: float
    arm_momentum_peak: float
    arm_momentum_mean: float


@dataclass
class ArmMomentumLog:
    """A runner observer gathering, tick by tick, what the study needs (one row per tick played).

    The runner hands it the robot (a `TruthSource`: the simulator's base truth is read after each tick) and the
    controller it drives, a `WatchedController` (the state each tick was handed).

    Attributes:
        pin_robot: the Pinocchio model of the robot played (built at the first tick).
        h_arm: |h_arm| of each tick [N m s] (zero without an actuated arm).
        com_in_world: system CoM of each tick [m].
        rotation_base_in_world: base orientation of each tick.
        position_base_in_world: base position of each tick [m].
        arm_travel_rad: summed absolute arm joint motion so far [rad].
    """

    pin_robot: PinocchioRobot | None = None
    h_arm: list[float] = field(default_factory=list)
    com_in_world: list[np.ndarray] = field(default_factory=list)
    rotation_base_in_world: list[np.ndarray] = field(default_factory=list)
    position_base_in_world: list[np.ndarray] = field(default_factory=list)
    arm_travel_rad: float = 0.0
    _last_arm: np.ndarray | None = field(default=None, init=False, repr=False)

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
        h = 0.0
        if robot.num_joints == 15:
            arm_cols = 6 + pinr.joints.house_from_pin[ARM_JOINTS]
            pin.computeCentroidalMap(pinr.model, pinr.data, q)
            h = float(np.linalg.norm(pinr.data.Ag[3:, arm_cols] @ state.dq[ARM_JOINTS]))
            if self._last_arm is not None:
                self.arm_travel_rad += float(np.abs(state.q[ARM_JOINTS] - self._last_arm).sum())
            self._last_arm = state.q[ARM_JOINTS].copy()
        self.h_arm.append(h)


def arm_momentum_study(scenario_path: str, controller: str, *, band: str, seeds: tuple[int, ...] = (0,),
                       trials: int = 5, duration_s: float | None = None) -> list[ArmMomentumTrial]:
    """Play `trials` trials per seed of `band` with `controller` and measure the arm's momentum against the pushes.

    Args:
        scenario_path: the scenario file (a relative path is resolved as `load_scenario` does).
        controller: controller registry name.
        band: scenario band.
        seeds: seeds to play.
        trials: trials per seed.
        duration_s: shortens every trial (default: the scenario's length) [s].

    Returns:
        One row per trial, in the scenario's trial order.

    Raises:
        ScenarioError, UnknownNameError: bad scenario, band or controller.
    """
    scenario = load_scenario(scenario_path)
    get_controller(controller)  # an unknown name fails before the first trial is played
    out = []
    for trial in scenario.trials([band], list(seeds), trials):
        if duration_s is not None:
            trial = dataclasses.replace(trial, duration_s=duration_s)
        out.append(_study_trial(trial, controller))
    return out


def _study_trial(trial: Trial, controller: str) -> ArmMomentumTrial:
    spec = get_controller(controller)
    watched = dataclasses.replace(spec, make=lambda desc: WatchedController(spec.make(desc)))
    log = ArmMomentumLog()
    _, episode = run_trial(trial, watched, observer=log, record_errors=False)
    dt, played = episode.control_dt, len(log.h_arm)
    h_arm = np.asarray(log.h_arm)
    impulses, peaks = [], []
    for push in trial.pushes:
        k0 = int(push.start / dt)
        if k0 >= played:
            continue
        lever = (log.position_base_in_world[k0] + log.rotation_base_in_world[k0] @ push.offset_in_base
                 - log.com_in_world[k0])
        impulses.append(float(np.linalg.norm(np.cross(lever, push.force_in_world))) * push.duration)
        peaks.append(float(h_arm[k0:min(played, k0 + int(0.5 / dt))].max()))
    return ArmMomentumTrial(
        controller=controller, band=trial.band, seed=trial.seed, trial=trial.index, survived=not episode.fell,
        arm_travel_rad=log.arm_travel_rad, push_angular_impulse=float(np.mean(impulses)) if impulses else 0.0,
        arm_momentum_peak=float(np.mean(peaks)) if peaks else 0.0,
        arm_momentum_mean=float(h_arm.mean()) if played else 0.0)
