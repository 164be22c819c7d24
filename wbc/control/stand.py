"""The standing PD hold: the nominal pose held by joint PD (legs stiff, arm compliant).

This is the simplest controller there is and the baseline every other controller is measured against; the arena
registers it as ``stand``.
"""

from __future__ import annotations

from dataclasses import dataclass

from wbc.robots.description import RobotDescription, joint_gains
from wbc.types import MotorCommand

__all__ = ["StandController", "StandGains", "stand_command"]


@dataclass(frozen=True, kw_only=True)
class StandGains:
    """Joint PD gains of the standing hold.

    Attributes:
        leg_kp: [N m / rad].
        leg_kd: [N m s / rad].
        arm_kp: [N m / rad].
        arm_kd: [N m s / rad].
    """

    leg_kp: float = 60.0
    leg_kd: float = 2.0
    arm_kp: float = 20.0
    arm_kd: float = 0.5


def stand_command(desc: RobotDescription, gains: StandGains | None = None) -> MotorCommand:
    """PD hold of `desc`'s nominal pose."""
    g = gains if gains is not None else StandGains()
    kp, kd = joint_gains(desc.num_joints, g.leg_kp, g.leg_kd, g.arm_kp, g.arm_kd)
    return MotorCommand.hold(desc.nominal_q, kp, kd)


class StandController:
    """The ``stand`` controller: the PD hold of `stand_command`, at 50 Hz (the motors' PD runs every physics step).

    Args:
        desc: the robot it drives.
        gains: PD gains.
    """

    rate_hz = 50.0

    def __init__(self, desc: RobotDescription, gains: StandGains | None = None) -> None:
        self._command = stand_command(desc, gains)

    def reset(self) -> None:
        """Nothing to forget."""

    def act(self, state: object, command: object) -> MotorCommand:
        """Hold the nominal pose whatever the state and command."""
        return self._command

    def counters(self) -> dict[str, int]:
        """No events."""
        return {}
