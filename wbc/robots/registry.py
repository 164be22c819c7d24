"""Explicit registry of the robots this toolkit knows.

A robot is a name and a factory: ``factory(arm_mode, *, arm_mass_scale=1.0, ...) -> RobotDescription``, with
``arm_mode`` one of ``none``, ``locked``, ``actuated`` (checked before the call) and keyword options (the simulator
passes ``arm_mass_scale``, `MujocoRobotConfig`). The description's ``name`` is its key here: shipped weights, the
controllers' claims and every result are looked up by that name, so `get_robot` refuses a description named otherwise
(a variant made from a copied factory would otherwise play as the robot it was copied from).
"""

from __future__ import annotations

from collections.abc import Callable

from wbc.errors import ConfigError, UnknownNameError
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
        ConfigError: the factory's description has another name than `name` (its key in `ROBOTS`).
    """
    if name not in ROBOTS:
        raise UnknownNameError("robot", name, tuple(ROBOTS))
    desc = ROBOTS[name](check_arm_mode(arm_mode), **options)
    if desc.name != name:
        factory = getattr(ROBOTS[name], "__qualname__", repr(ROBOTS[name]))
        raise ConfigError(f"robot {name!r}: its factory {factory} returned a description named {desc.name!r}; a "
                          f"description's name must be its key in ROBOTS (wbc/robots/registry.py), since weights, "
                          f"claims and results are looked up by it: give it name={name!r}")
    return desc
