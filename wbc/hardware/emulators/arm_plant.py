"""`ArmPlant`: the physics behind an emulated arm bus, seen from the bus: three joints read and commanded.

The Dynamixel emulator turns its servos' registers into one `MotorCommand` for the model's three arm joints (waist,
shoulder, elbow; house joints 12..14) each time they change. It reads the joints back to fill the present
registers. `SharedPlant` (`wbc.hardware.emulators.plant`) is the implementation: one MuJoCo robot whose legs
another emulator drives.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from wbc.types import MotorCommand

__all__ = ["ArmPlant"]


@runtime_checkable
class ArmPlant(Protocol):
    """Three arm joints in the model's convention (`wbc.hardware.dynamixel.WX200_ARM_JOINTS`), thread-safe."""

    def read_arm(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q [rad], dq [rad/s], tau_est [N m]) of waist, shoulder and elbow, each shape (3,)."""
        ...

    def write_arm(self, cmd: MotorCommand, tau_max: np.ndarray | None = None) -> None:
        """Apply a 3-joint command with Unitree semantics until the next one.

        Args:
            cmd: tau = kp (q - q_measured) + kd (dq - dq_measured) + tau, per joint.
            tau_max: (3,) a further bound on each joint's |tau| [N m] (a servo's current limit), inf for none;
                None: the joints' own torque limits only.
        """
        ...
