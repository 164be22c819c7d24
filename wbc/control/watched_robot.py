"""`WatchedRobot`: the simulated robot of the contract checker, which notes every truth read made from inside `act`.

The checker (`wbc.control.controller_contract`) says when `act` runs (`watch`); a call of any of the simulator's truth
accessors in that window is counted by name, and a controller that made one fails the ``truth`` check.
"""

from __future__ import annotations

import numpy as np

from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig, SimTruth
from wbc.types import BaseTruth

__all__ = ["WatchedRobot"]


class WatchedRobot(MujocoRobot):
    """A `MujocoRobot` whose truth accessors (`sim_truth`, `base_truth`, `fallen`, `base_rotation`) are watched.

    Args:
        config: what to simulate.
    """

    def __init__(self, config: MujocoRobotConfig | None = None) -> None:
        super().__init__(config)
        self._in_act = False
        self._reads: dict[str, int] = {}

    def watch(self, inside_act: bool) -> None:
        """Say that `act` starts (True) or has returned (False)."""
        self._in_act = inside_act

    def reads(self) -> dict[str, int]:
        """Truth accessors called while `act` ran, with their call counts."""
        return dict(self._reads)

    def _seen(self, name: str) -> None:
        if self._in_act:
            self._reads[name] = self._reads.get(name, 0) + 1

    def sim_truth(self) -> SimTruth:
        """`MujocoRobot.sim_truth`, watched."""
        self._seen("sim_truth")
        return super().sim_truth()

    def base_truth(self) -> BaseTruth:
        """`MujocoRobot.base_truth`, watched."""
        self._seen("base_truth")
        return super().base_truth()

    def fallen(self) -> bool:
        """`MujocoRobot.fallen`, watched."""
        self._seen("fallen")
        return super().fallen()

    def base_rotation(self) -> np.ndarray:
        """`MujocoRobot.base_rotation`, watched."""
        self._seen("base_rotation")
        return super().base_rotation()
