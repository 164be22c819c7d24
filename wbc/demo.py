"""The main job at this stage: the robot standing, pushed, recovering or falling; and the tail analysis.

Each arm mode of the A1 + WX200 stands under the PD hold on fractal terrain and takes one push of increasing
magnitude at the trunk's side; simulator truth says whether it recovered (no trunk or non-foot link on the ground,
feet back in contact) and how far it tilted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wbc.hardware.mujoco_robot import MujocoRobot, MujocoRobotConfig
from wbc.hardware.perturbation import Push
from wbc.hardware.terrain import TerrainConfig
from wbc.standing import stand_command

__all__ = ["PushOutcome", "push_trial"]


@dataclass(frozen=True)
class PushOutcome:
    """What one push did to the standing robot."""

    arm_mode: str
    force_n: float
    fell: bool
    fall_time_s: float | None
    max_tilt_deg: float
    displacement_m: float


def _tilt_deg(quat: np.ndarray) -> float:
    w, x, y, z = quat
    up_z = 1.0 - 2.0 * (x * x + y * y)  # world z of the body z axis
    return float(np.degrees(np.arccos(np.clip(up_z, -1.0, 1.0))))


def push_trial(robot: str, arm_mode: str, force: float, *, seed: int = 0, duration: float = 0.1,
               offset_y: float = 0.0, total: float = 3.0, control_dt: float = 0.002) -> PushOutcome:
    """Stand, take a lateral push at t = 1 s, and watch for `total` seconds."""
    sim = MujocoRobot(MujocoRobotConfig(robot=robot, arm_mode=arm_mode, terrain=TerrainConfig(kind="fractal")))
    with sim:
        sim.reset(seed)
        cmd = stand_command(sim.desc)
        sim.apply_push(Push.horizontal(force, np.pi / 2, (0.0, offset_y, 0.0), start=1.0, duration=duration))
        start = sim.sim_truth().base_position_in_world.copy()
        tilt, fall_time = 0.0, None
        for _ in range(int(round(total / control_dt))):
            sim.write(cmd)
            sim.advance(control_dt)
            truth = sim.sim_truth()
            tilt = max(tilt, _tilt_deg(truth.base_quat))
            if truth.ground_contact_bodies:
                fall_time = truth.time
                break
        moved = float(np.linalg.norm(truth.base_position_in_world[:2] - start[:2]))
    return PushOutcome(arm_mode=arm_mode, force_n=force, fell=fall_time is not None, fall_time_s=fall_time,
                       max_tilt_deg=tilt, displacement_m=moved)
