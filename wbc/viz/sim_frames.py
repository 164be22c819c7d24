"""Viewer frames from a running simulation, read after each control tick through the runner's observer hook.

A frame holds the configuration, the command, the push acting now, foot contact forces and the controller's plan.
What the viewer needs of a simulator is the capability `SimulatedWorld` (`wbc.hardware.mujoco.MujocoRobot` offers
it); a robot without it is drawn from its state alone (`wbc.viz.state_frames`).

This reads simulator truth, which is fine for a viewer: nothing here goes back to the controller.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import mujoco
import numpy as np

from wbc.control.protocol import HasDebugPlan
from wbc.hardware.mujoco.fall_rule import FOOT_ZONE
from wbc.hardware.mujoco.robot import MujocoRobotConfig, SimTruth
from wbc.robots.description import FOOT_NAMES, RobotDescription
from wbc.types import VelocityCommand
from wbc.viz.frame import VizFrame

__all__ = ["SimulatedWorld", "foot_forces_in_world", "frame_from_sim"]


@runtime_checkable
class SimulatedWorld(Protocol):
    """A robot that is a MuJoCo simulation: the viewer draws its ground, contacts and pushes from the simulator."""

    @property
    def desc(self) -> RobotDescription:
        """The robot simulated."""

    @property
    def config(self) -> MujocoRobotConfig:
        """Its configuration (the terrain it stands on)."""

    @property
    def model(self) -> mujoco.MjModel:
        """The MuJoCo model (its heightfield)."""

    @property
    def data(self) -> mujoco.MjData:
        """The MuJoCo state (configuration, contacts)."""

    def sim_truth(self) -> SimTruth:
        """Ground truth now (the push acting)."""


def foot_forces_in_world(robot: SimulatedWorld) -> np.ndarray:
    """Ground reaction force on each foot, house order FR, FL, RR, RL, shape (4, 3) [N].

    A contact belongs to the foot whose centre is within `FOOT_ZONE` of it (the same rule as the fall check);
    the force is the one the ground exerts on the robot.
    """
    m, d = robot.model, robot.data
    n = d.ncon
    if n == 0:
        return np.zeros((4, 3))
    # in Python floats: a handful of contacts, where numpy's per-call cost would dominate
    centres = d.site_xpos[[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f) for f in FOOT_NAMES]].tolist()
    contacts = d.contact
    zone2 = FOOT_ZONE * FOOT_ZONE
    out = [[0.0, 0.0, 0.0] for _ in range(4)]
    wrench = np.zeros(6)
    body = m.geom_bodyid
    for i, ((px, py, pz), frame, g2) in enumerate(zip(contacts.pos[:n].tolist(), contacts.frame[:n].tolist(),
                                                       contacts.geom[:n, 1].tolist(), strict=True)):
        near = [(px - cx) * (px - cx) + (py - cy) * (py - cy) + (pz - cz) * (pz - cz) for cx, cy, cz in centres]
        k = near.index(min(near))
        if near[k] > zone2:
            continue
        mujoco.mj_contactForce(m, d, i, wrench)
        fn, f1, f2 = wrench[:3].tolist()
        sign = 1.0 if body[g2] != 0 else -1.0  # the force of geom1 on geom2: on the robot when it is geom2
        # the frame's rows are the normal and the two tangents (world): the force in the world is frame^T wrench
        foot = out[k]
        for j in range(3):
            foot[j] += sign * (frame[j] * fn + frame[3 + j] * f1 + frame[6 + j] * f2)
    return np.array(out)


_PLANNER: list[object] = [None, False]  # the last controller seen, whether it is a `HasDebugPlan` (a check: ~30 us)


def frame_from_sim(robot: SimulatedWorld, controller: object, command: VelocityCommand, t: float) -> VizFrame:
    """The frame of the simulation as it is now.

    Args:
        robot: the simulated robot.
        controller: the controller; its plan is shown when it is a `HasDebugPlan`.
        command: the command of the tick just played.
        t: time [s].
    """
    truth = robot.sim_truth()
    if _PLANNER[0] is not controller:
        _PLANNER[:] = [controller, isinstance(controller, HasDebugPlan)]
    plan = controller.debug_plan() if _PLANNER[1] else None
    if plan is not None:  # the frame's own: a recording keys it later, the controller's arrays move on
        plan = {key: np.array(value) for key, value in plan.items()}
    return VizFrame(
        t=t, qpos=robot.data.qpos.copy(), command=np.array([command.vx, command.vy, command.yaw_rate]),
        push_force_in_world=truth.external_force_in_world, push_point_in_world=truth.external_point_in_world,
        foot_force_in_world=foot_forces_in_world(robot), plan=plan,
    )
