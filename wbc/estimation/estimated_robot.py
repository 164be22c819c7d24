"""`EstimatedRobot`: a robot seen only through its own sensors, with its base state estimated from every read.

A real robot knows no truth about its base. Wrapped in this, it offers what the arena and the viewer need in its
place: `base_estimate` (the base's pose and velocity from IMU and leg kinematics, `BaseEstimate`) for the episode's
metrics, and `estimated_configuration` (that pose with the joints as measured), which makes it a
`wbc.hardware.capabilities.ConfigurationEstimate` a viewer can draw. The estimate is fed by the reads the runner
makes anyway, one per control tick, so the robot is read exactly as often as without it and a safety layer beneath
sees the same reads; the estimate is of the state the controller was handed. It is computed when the tick's command
has gone out (at the start of `advance`, whose wait for the robot's clock absorbs it) or when it is asked for, so
it never delays a command.

Everything else passes through: `write` returns what the wrapped robot sent, `advance` is its pacing, and a safety
layer's transitions are reported (`HasSafetyEvents`; none when the wrapped robot has no safety layer).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast

import numpy as np

from wbc.errors import ConfigError, RobotNotConnectedError
from wbc.estimation.base_estimate import BaseEstimate
from wbc.hardware.capabilities import HasSafetyEvents, SafetyEventLike
from wbc.hardware.robot import Robot
from wbc.robots.description import RobotDescription
from wbc.robots.joint_table import JointTable
from wbc.types import BaseTruth, MotorCommand, RobotState

__all__ = ["EstimatedRobot"]


class EstimatedRobot(Robot):
    """A robot whose base state is estimated from each state it reads.

    Args:
        robot: the robot (connected and closed with this one).
        description: what it is (its joints must be the robot's, in the same order).
        estimate: the base estimator (`BaseEstimate` of `description` at the control period).

    Raises:
        ConfigError: `description` names other joints than the robot has.
    """

    def __init__(self, robot: Robot, description: RobotDescription, estimate: BaseEstimate) -> None:
        super().__init__()
        if tuple(description.joint_names) != tuple(robot.joint_names):
            raise ConfigError(
                f"EstimatedRobot: description {description.name} ({description.arm_mode}) has joints "
                f"{', '.join(description.joint_names)}, the robot {', '.join(robot.joint_names)}; describe the robot "
                "it wraps")
        self.robot = robot
        self.estimate = estimate
        self._description = description
        self._state: RobotState | None = None
        self._pending = False  # a state was read and not yet folded into the estimate
        self._sent: MotorCommand | None = None

    # -- what it offers -------------------------------------------------------------------------------------------
    @property
    def description(self) -> RobotDescription:
        """The robot as built (a `ConfigurationEstimate`)."""
        return self._description

    def base_estimate(self) -> BaseTruth:
        """The base's estimated pose and velocity as of the last `read`.

        Raises:
            RobotNotConnectedError: nothing was read yet.
        """
        self._fold_in()
        latest = self.estimate.latest
        if latest is None:
            raise RobotNotConnectedError("EstimatedRobot.base_estimate: no state was read yet; call read() first")
        return latest

    def estimated_configuration(self) -> np.ndarray:
        """Estimated base position and IMU quaternion, then the measured joints, shape (7 + n,) [m, -, rad].

        Raises:
            RobotNotConnectedError: nothing was read yet.
        """
        base = self.base_estimate()
        return np.concatenate((base.base_position_in_world, base.base_quat, cast(RobotState, self._state).q))

    def safety_events(self) -> Sequence[SafetyEventLike]:
        """The wrapped robot's safety transitions (a `HasSafetyEvents`); none without a safety layer."""
        return self.robot.safety_events() if isinstance(self.robot, HasSafetyEvents) else ()

    # -- Robot ----------------------------------------------------------------------------------------------------
    @property
    def joint_names(self) -> tuple[str, ...]:
        """The wrapped robot's joints."""
        return self.robot.joint_names

    @property
    def limits(self) -> JointTable:
        """The wrapped robot's motor limits."""
        return self.robot.limits

    def write(self, cmd: MotorCommand) -> MotorCommand:
        """Validate, clamp and pass the command on; return what the wrapped robot sent.

        A safety layer beneath may have sent damping instead of the command.
        """
        super().write(cmd)
        return cast(MotorCommand, self._sent)

    def _connect(self) -> None:
        self.robot.connect()
        self.estimate.reset()
        self._state, self._pending = None, False

    def _close(self) -> None:
        self.robot.close()

    def _read(self) -> RobotState:
        self._fold_in()  # a state read without an advance since is still one tick of the filter
        state = self.robot.read()
        self._state, self._pending = state, True
        return state

    def _send(self, cmd: MotorCommand) -> None:
        self._sent = self.robot.write(cmd)

    def _advance(self, dt: float) -> None:
        self._fold_in()
        self.robot.advance(dt)

    def _fold_in(self) -> None:
        if self._pending:
            self.estimate.update(cast(RobotState, self._state))
            self._pending = False
