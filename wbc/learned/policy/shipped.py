"""The shipped weights: the directory inside the package that holds them, and the file a robot runs by default.

``wbc/learned/weights/<robot>-<arm mode>.npz`` (+ ``.json``) is pi3, pi2 or pi1 of the robot's task (arm actuated,
locked, none); other shipped files (baselines, the walking prior a task starts from) sit beside them. The directory
is found from this file, never from the working directory.

The shipped stages hold the robot's nominal trunk height (their reward's posture term, `wbc.learned.train.stages`).
A posture variant (`POSTURES`) sits beside each: ``<robot>-<arm mode>-crouched`` is the same stage as first trained,
without the posture term, crouching about 12 cm below nominal; it is kept for the comparisons measured with it (push
v2 was calibrated on the crouched pi2) and run by the registry's ``*-crouched`` names.

``<robot>-actuated-mpc-distilled`` is the MPC distilled into a policy of the same form by DAgger
(``wbc train --teacher mpc``), run by the registry's ``mpc-distilled``.
"""

from __future__ import annotations

from pathlib import Path

from wbc.errors import UnknownNameError
from wbc.robots.description import RobotDescription

__all__ = ["POSTURES", "WEIGHTS_DIR", "distilled_weights", "shipped_weights"]

WEIGHTS_DIR = Path(__file__).resolve().parents[1] / "weights"
"""Where the package's weights are installed (``wbc/learned/weights``)."""


POSTURES = ("crouched",)
"""Posture variants of the shipped weights: a suffix of the file name (``<robot>-<arm mode>-crouched.npz``)."""


def shipped_weights(desc: RobotDescription, posture: str | None = None) -> Path:
    """The shipped policy for `desc`'s robot and arm mode (``weights/<robot>-<arm mode>[-<posture>].npz``).

    Raises:
        UnknownNameError: a posture other than None or one of `POSTURES`.
    """
    if posture is None:
        return WEIGHTS_DIR / f"{desc.name}-{desc.arm_mode}.npz"
    if posture not in POSTURES:
        raise UnknownNameError("posture", posture, POSTURES)
    return WEIGHTS_DIR / f"{desc.name}-{desc.arm_mode}-{posture}.npz"


def distilled_weights(desc: RobotDescription) -> Path:
    """The shipped policy distilled from the MPC for `desc`'s robot (``weights/<robot>-actuated-mpc-distilled.npz``).

    The student drives the arm, as its expert ``mpc`` does: the file is the actuated arm's whatever `desc`'s arm mode.
    """
    return WEIGHTS_DIR / f"{desc.name}-actuated-mpc-distilled.npz"
