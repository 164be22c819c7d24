"""How much angular momentum the arm actually moves during push recovery: the data behind the README's tail answer.

For each trial of a scenario band, the named controller plays the trial as `wbc run` does; every tick the arm's
contribution to the centroidal angular momentum, h_arm = A_arm(q) dq_arm (A_arm: the arm's columns of Pinocchio's
centroidal momentum matrix, evaluated at the simulator's true configuration), is compared with the angular impulse
each push delivers about the CoM, |r x F| T (r: from the CoM to the push's application point). A tail that
matters must move momentum of the order of that impulse.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from wbc.arena.runner import simulated_robot
from wbc.control.registry import get_controller
from wbc.robots.conventions import quat_to_matrix, quat_wxyz_to_xyzw
from wbc.robots.pinocchio_model import build_pinocchio
from wbc.scenario.scenario import load_scenario

__all__ = ["ArmMomentumTrial", "arm_momentum_study"]


@dataclass(frozen=True)
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


def arm_momentum_study(scenario_path: str, controller: str, *, band: str, seeds: tuple[int, ...] = (0,),
                       trials: int = 5, duration_s: float | None = None) -> list[ArmMomentumTrial]:
    """Play `trials` trials per seed of `band` with `controller` and measure the arm's momentum against the pushes.

    `duration_s` shortens every trial (default: the scenario's length).

    Raises:
        ScenarioError, UnknownNameError: bad scenario, band or controller.
    """
    scenario = load_scenario(scenario_path)
    spec = get_controller(controller)
    out = []
    for trial in scenario.trials([band], list(seeds), trials):
        if duration_s is not None:
            trial = dataclasses.replace(trial, duration_s=duration_s)
        robot = simulated_robot(trial, spec.arm_mode)
        ctrl = spec.make(robot.desc)
        pinr = build_pinocchio(robot.desc)
        arm_cols = None
        if robot.num_joints == 15:
            arm_cols = 6 + pinr.joints.house_from_pin[12:15]
        robot.reset(seed=trial.terrain_seed, domain=trial.domain)
        for push in trial.pushes:
            robot.apply_push(push)
        ctrl.reset()
        dt = 1.0 / ctrl.rate_hz
        n = int(round(trial.duration_s / dt))
        h_arm = np.zeros(n)
        com = np.zeros((n, 3))
        rot = np.zeros((n, 3, 3))
        pos = np.zeros((n, 3))
        travel, last_arm, fell, played = 0.0, None, False, 0
        for k in range(n):
            state = robot.read()
            robot.write(ctrl.act(state, trial.command.at(k * dt)))
            robot.advance(dt)
            truth = robot.base_truth()
            q = np.concatenate([truth.base_position_in_world, quat_wxyz_to_xyzw(truth.base_quat),
                                state.q[pinr.joints.pin_from_house]])
            com[k] = pin.centerOfMass(pinr.model, pinr.data, q)
            rot[k] = quat_to_matrix(truth.base_quat)
            pos[k] = truth.base_position_in_world
            if arm_cols is not None:
                pin.computeCentroidalMap(pinr.model, pinr.data, q)
                h_arm[k] = float(np.linalg.norm(pinr.data.Ag[3:, arm_cols] @ state.dq[12:15]))
                if last_arm is not None:
                    travel += float(np.abs(state.q[12:15] - last_arm).sum())
                last_arm = state.q[12:15].copy()
            played = k + 1
            if robot.fallen():
                fell = True
                break
        impulses, peaks = [], []
        for push in trial.pushes:
            k0 = int(push.start / dt)
            if k0 >= played:
                continue
            lever = pos[k0] + rot[k0] @ push.offset_in_base - com[k0]
            impulses.append(float(np.linalg.norm(np.cross(lever, push.force_in_world))) * push.duration)
            peaks.append(float(h_arm[k0:min(played, k0 + int(0.5 / dt))].max()))
        out.append(ArmMomentumTrial(
            controller=controller, band=band, seed=trial.seed, trial=trial.index, survived=not fell,
            arm_travel_rad=travel, push_angular_impulse=float(np.mean(impulses)) if impulses else 0.0,
            arm_momentum_peak=float(np.mean(peaks)) if peaks else 0.0,
            arm_momentum_mean=float(h_arm[:played].mean()) if played else 0.0))
    return out
