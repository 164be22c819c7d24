"""What the safety layer can read from a robot beyond `RobotState`, as protocols a backend may offer.

A wireless remote (`RemoteSource`: its L2 + B is an e-stop, and a reset needs it idle) and the motors' own status
(`MotorStatusSource`: temperatures and modes). The Unitree backend's `Remote` and `LowStateExtras` have exactly the
attributes asked for, so it offers both by returning them; the simulator offers neither, and the checks that need
them are then skipped.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["MotorNames", "MotorStatus", "MotorStatusSource", "RemoteButtons", "RemoteSource"]


class RemoteButtons(Protocol):
    """The buttons of a wireless remote at one instant (`wbc.hardware.unitree.Remote` is one)."""

    @property
    def l2_b(self) -> bool:
        """L2 and B held together: Unitree's "go passive" request."""

    @property
    def held(self) -> tuple[str, ...]:
        """Names of the buttons held (empty when the remote is idle)."""


@runtime_checkable
class RemoteSource(Protocol):
    """A robot that reports its wireless remote."""

    def remote(self) -> RemoteButtons | None:
        """The remote's buttons as of the latest state; None if the robot has no remote after all.

        (A composite robot offers the method whether or not its part that would carry a remote has one.)
        """


class MotorStatus(Protocol):
    """The motors' own status at one instant (`wbc.hardware.unitree.LowStateExtras` is one)."""

    @property
    def motor_mode(self) -> np.ndarray:
        """Each motor's reported mode (0x0A servo, 0 damping/off, anything else an error code)."""

    @property
    def motor_temperature(self) -> np.ndarray:
        """Each motor's temperature [degC]."""


@runtime_checkable
class MotorNames(Protocol):
    """A robot that names the motors of its `MotorStatus`, so that a trip names the motor (``elbow (ID 4)``)."""

    @property
    def motor_names(self) -> tuple[str, ...]:
        """One name per entry of `MotorStatusSource.motor_status`, in its order."""


@runtime_checkable
class MotorStatusSource(Protocol):
    """A robot that reports its motors' temperatures and modes."""

    def motor_status(self) -> MotorStatus | None:
        """The motors' status as of the latest state; None if none of its motors report one."""
