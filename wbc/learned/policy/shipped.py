"""The shipped weights: the directory inside the package that holds them, and the file a robot runs by default.

``wbc/learned/weights/<robot>-<arm mode>.npz`` (+ ``.json``) is pi3, pi2 or pi1 of the robot's task (arm actuated,
locked, none); other shipped files (baselines, the walking prior a task starts from) sit beside them. The directory
is found from this file, never from the working directory.
"""

from __future__ import annotations

from pathlib import Path

from wbc.robots.description import RobotDescription

__all__ = ["WEIGHTS_DIR", "shipped_weights"]

WEIGHTS_DIR = Path(__file__).resolve().parents[1] / "weights"
"""Where the package's weights are installed (``wbc/learned/weights``)."""


def shipped_weights(desc: RobotDescription) -> Path:
    """The shipped policy for `desc`'s robot and arm mode (``weights/<robot>-<arm mode>.npz``)."""
    return WEIGHTS_DIR / f"{desc.name}-{desc.arm_mode}.npz"
