"""`ControllerSpec`: a controller resolved from its name, ready to be built for a robot (and pickled to a worker).

Every name the arena accepts (a registry name, ``policy:PATH``, ``onnx:PATH``, ``package.module:factory``, an entry
point) resolves to one of these (`wbc.control.registry.get_controller`). The spec says which robots and arm modes the
controller claims, and its `make` builds it for a robot description. `make` must pickle: the local pool and Ray
workers receive the spec, not the name, so a name is resolved (and any file it names is read) once, in the parent.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from wbc.control.protocol import Controller
from wbc.robots.description import RobotDescription, check_arm_mode
from wbc.robots.registry import ROBOTS

__all__ = ["ControllerSpec"]


@dataclass(frozen=True)
class ControllerSpec:
    """A resolved controller.

    Attributes:
        name: the name it was given by (a registry name, ``policy:PATH``, ``module:factory`` ...).
        arm_mode: the arm mode the arena plays it with (``none``, ``locked``, ``actuated``).
        make: builds the controller for a robot description.
        summary: one line for listings and reports.
        robots: the robots it can drive, or None for every robot of `wbc.robots.registry.ROBOTS`.
        arm_modes: every arm mode it can drive, `arm_mode` first (default: `arm_mode` only).
        kind: where the name came from: ``registry``, ``policy file``, ``onnx``, ``plug-in`` or ``entry point``.
        config_file: the configuration file it was built with (``--controller-config``, ``--io``), or None.
    """

    name: str
    arm_mode: str
    make: Callable[[RobotDescription], Controller]
    summary: str
    robots: tuple[str, ...] | None = field(default=None, kw_only=True)
    arm_modes: tuple[str, ...] = field(default=(), kw_only=True)
    kind: str = field(default="registry", kw_only=True)
    config_file: str | None = field(default=None, kw_only=True)

    def __post_init__(self) -> None:
        check_arm_mode(self.arm_mode)
        modes = tuple(dict.fromkeys((self.arm_mode, *self.arm_modes)))  # arm_mode first, no repeats
        for mode in modes:
            check_arm_mode(mode)
        object.__setattr__(self, "arm_modes", modes)
        if self.robots is not None:
            object.__setattr__(self, "robots", tuple(self.robots))

    @property
    def robot(self) -> str | None:
        """The only robot it can drive (a policy file's), or None when it drives several or every robot."""
        return self.robots[0] if self.robots is not None and len(self.robots) == 1 else None

    def claims(self) -> list[tuple[str, str]]:
        """Every (robot, arm mode) this controller says it can drive, robots in registry order."""
        robots = self.robots if self.robots is not None else tuple(ROBOTS)
        return [(robot, mode) for robot in robots for mode in self.arm_modes]

    def drives(self, robot: str) -> bool:
        """Whether it claims `robot` (a registry name)."""
        return self.robots is None or robot in self.robots
