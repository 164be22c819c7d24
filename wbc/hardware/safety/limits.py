"""The joint ranges the safety layer checks measured positions against.

Unitree's SDK clamps commanded positions to its PositionLimit table, and its PositionProtect cuts the motors when a
measured joint leaves that range by a margin. The tables below are the SDK's (Go1 SDK 3.8, and the A1 table the
same wheel carries), per leg joint (hip, thigh, calf) in the house order; arm joints, and robots with no Unitree
table, take the robot's own `JointTable`.
"""

from __future__ import annotations

import numpy as np

from wbc.errors import UnknownNameError
from wbc.robots.joint_table import JointTable

__all__ = ["POSITION_TABLES", "UNITREE_POSITION_LIMITS", "check_position_table", "position_range"]

UNITREE_POSITION_LIMITS: dict[str, tuple[tuple[float, float], tuple[float, float], tuple[float, float]]] = {
    "go1": ((-1.047, 1.047), (-0.663, 2.966), (-2.721, -0.837)),
    "a1": ((-0.802, 0.802), (-1.05, 4.19), (-2.7, -0.916)),
}
"""Unitree's PositionLimit per leg joint (hip, thigh, calf): (lower, upper) [rad]."""

POSITION_TABLES = ("robot", *UNITREE_POSITION_LIMITS)
"""Valid `SafetyConfig.position_table` names: the robot's own `JointTable`, or a Unitree table."""

_NUM_LEG_JOINTS = 12


def check_position_table(name: str) -> str:
    """Return `name` if it names a position table, else raise an error listing the valid ones.

    Raises:
        UnknownNameError: `name` is not in `POSITION_TABLES`.
    """
    if name not in POSITION_TABLES:
        raise UnknownNameError("position table", name, POSITION_TABLES)
    return name


def position_range(name: str, limits: JointTable) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper position of every joint, shape (n,) each [rad].

    Args:
        name: one of `POSITION_TABLES`; a Unitree table replaces the ranges of the first 12 (leg) joints.
        limits: the robot's own limits (every joint not covered by the table).

    Raises:
        UnknownNameError: `name` is not in `POSITION_TABLES`.
    """
    lower, upper = limits.lower.astype(np.float64), limits.upper.astype(np.float64)
    if check_position_table(name) == "robot":
        return lower, upper
    legs = np.tile(np.array(UNITREE_POSITION_LIMITS[name]), (4, 1))  # (12, 2): FR, FL, RR, RL x hip, thigh, calf
    k = min(_NUM_LEG_JOINTS, lower.shape[0])
    lower[:k], upper[:k] = legs[:k, 0], legs[:k, 1]
    return lower, upper
