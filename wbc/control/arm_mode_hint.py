"""`arm_mode_hint`: what a command of the wrong number of joints says about the arm mode its controller meant.

A controller is built for the arm mode it claims, and the robot it drives has that mode's joints: the 12 of the legs
with the arm absent or locked, 15 with it actuated (the arm's 3 after the legs'). A plain callable factory claims
``actuated``, so a controller of the legs alone made by one commands 12 joints of a 15-joint robot; it declares the
arm modes it drives with a `wbc.control.ControllerPlugin`. The contract checker and the arena add this hint to their
refusal of such a command.
"""

from __future__ import annotations

from wbc.robots.description import ARM_JOINTS, LEG_JOINTS

__all__ = ["arm_mode_hint"]

_LEGS = LEG_JOINTS.stop - LEG_JOINTS.start
_WITH_ARM = ARM_JOINTS.stop


def arm_mode_hint(commanded: int, robot_joints: int) -> str | None:
    """How to declare the arm mode a command of `commanded` joints was meant for, on a robot of `robot_joints`.

    Args:
        commanded: the joints the controller commanded.
        robot_joints: the joints of the robot it was built for.

    Returns:
        A clause for a refusal's message where the command fits the legs alone on a robot with its arm actuated, or
        the legs and the arm on a robot without an actuated arm; None otherwise.
    """
    if commanded == _LEGS and robot_joints == _WITH_ARM:
        return (f"{_LEGS} joints are the legs alone, and this robot's arm is actuated ({_WITH_ARM} joints, the arm "
                "mode a plain factory claims): a controller of the legs declares the arm modes it drives, "
                'ControllerPlugin(make=..., arm_modes=("none",)) (add "locked" to drive a robot whose arm is rigid '
                f"too), or commands the arm's {_WITH_ARM - _LEGS} joints after the legs'")
    if commanded == _WITH_ARM and robot_joints == _LEGS:
        return (f"{_WITH_ARM} joints are the legs and the arm, and this robot has no actuated arm ({_LEGS} joints, "
                'arm mode "none" or "locked"): a controller that drives the arm declares it, '
                f'ControllerPlugin(make=..., arm_modes=("actuated",)), or commands the legs\' {_LEGS} joints only')
    return None
