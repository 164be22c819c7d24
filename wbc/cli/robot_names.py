"""``--robot`` of every command: the names each robot goes by, and the one refusal of a name that is none of them.

A robot has two names: the registry's, which says its arm (``a1-wx200``, ``go1-arm``: `wbc.robots.registry.ROBOTS`),
and its legs' (``a1``, ``go1``: the Unitree wire's, `wbc.hardware.unitree.DESCRIPTIONS`). Every ``--robot`` takes
either for the same robot. Whether its arm takes part is said by the command's other options (``--arm``,
``--arm-port``, the controller's arm mode) or by what the command measures (``bench hw``: the legs' link alone;
``bench arm``: the arm's bus); only ``wbc hw emulate`` reads the name for it, serving the bare quadruped by default
for the legs' name. An unknown name is refused by `robot_name`, listing both names of each robot, with the closest
name suggested.
"""

from __future__ import annotations

from wbc.errors import UnknownNameError, with_aliases
from wbc.hardware.unitree import DESCRIPTIONS, LEG_WIRES
from wbc.robots.registry import ROBOTS

__all__ = ["ROBOT_ALIASES", "ROBOT_NAMES_HELP", "robot_name", "wire_name"]

ROBOT_ALIASES: dict[str, str] = {wire: name for wire, name in DESCRIPTIONS.items() if name in ROBOTS}
"""The legs' name of each robot -> its registry name: ``go1`` -> ``go1-arm``."""


ROBOT_NAMES_HELP = ", ".join(with_aliases(name, ROBOT_ALIASES) for name in ROBOTS)
"""The accepted names for a help line: ``a1-wx200 (or a1), go1-arm (or go1)``."""


def robot_name(name: str) -> str:
    """The registry name of the robot `name` names: its own (``go1-arm``) or its legs' (``go1``).

    Args:
        name: the value of ``--robot``.

    Returns:
        A key of `wbc.robots.registry.ROBOTS`.

    Raises:
        UnknownNameError: `name` is neither; the message lists each robot with its legs' name and suggests the
            closest.
    """
    if name in ROBOTS:
        return name
    if name in ROBOT_ALIASES:
        return ROBOT_ALIASES[name]
    raise UnknownNameError("robot", name, tuple(ROBOTS), aliases=ROBOT_ALIASES)


def wire_name(name: str) -> str:
    """The legs' wire (``a1``, ``go1``: `wbc.hardware.unitree.DESCRIPTIONS`) of the robot `name` names, either name.

    Raises:
        UnknownNameError: `name` names no robot (`robot_name`), or one whose legs speak no wire we emulate.
    """
    robot = robot_name(name)
    if robot not in LEG_WIRES:
        wired = tuple(r for r in ROBOTS if r in LEG_WIRES)
        raise UnknownNameError("robot with a Unitree wire", name, wired,
                               aliases={a: r for a, r in ROBOT_ALIASES.items() if r in wired})
    return LEG_WIRES[robot]
