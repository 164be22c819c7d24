"""Viewer frames of a robot that is not a simulator, drawn from what it measures.

A real robot (or anything the runner drives without a simulator behind it) offers its configuration as a
`wbc.hardware.capabilities.ConfigurationEstimate`: the joints as measured and the base pose from a state estimator.
That is all a frame holds here, with the command and the controller's plan: no contact forces, no pushes (nobody
knows them), and flat ground under the robot (nobody knows the real one either).
"""

from __future__ import annotations

import numpy as np

from wbc.control.protocol import HasDebugPlan
from wbc.hardware.capabilities import ConfigurationEstimate
from wbc.types import VelocityCommand
from wbc.viz.frame import VizFrame

__all__ = ["frame_from_estimate"]


def frame_from_estimate(robot: ConfigurationEstimate, controller: object, command: VelocityCommand,
                        t: float) -> VizFrame:
    """The frame of a robot as its own sensors put it now.

    Args:
        robot: the robot.
        controller: the controller; its plan is shown when it is a `HasDebugPlan`.
        command: the command of the tick just played.
        t: time [s].
    """
    plan = controller.debug_plan() if isinstance(controller, HasDebugPlan) else None
    return VizFrame(t=t, qpos=np.asarray(robot.estimated_configuration(), dtype=np.float64).copy(),
                    command=np.array([command.vx, command.vy, command.yaw_rate]), plan=plan)
