"""Explicit registry of the robots this toolkit knows."""

from __future__ import annotations

from collections.abc import Callable

from wbc.errors import UnknownNameError
from wbc.robots.a1_wx200 import a1_wx200
from wbc.robots.description import RobotDescription, check_arm_mode
from wbc.robots.go1_arm import go1_arm

__all__ = ["ROBOTS", "get_robot"]

ROBOTS: dict[str, Callable[..., RobotDescription]] = {
    "a1-wx200": a1_wx200,
    "go1-arm": go1_arm,
}


def get_robot(name: str, arm_mode: str = "actuated", **options: float) -> RobotDescription:
    """Look a robot up by name.

    Args:
        name: a key of `ROBOTS`.
        arm_mode: ``none``, ``locked`` or ``actuated``.
        **options: robot-specific options (e.g. ``arm_mass_scale``).

    Raises:
        UnknownNameError: unknown robot or arm mode; the message lists the valid names.
    """
    if name not in ROBOTS:
        raise UnknownNameError("robot", name, tuple(ROBOTS))
    return ROBOTS[name](check_arm_mode(arm_mode), **options)
