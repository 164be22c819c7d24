"""`WireCommand`: what a LowCmd frame asks of the 12 leg motors, exactly as the wire holds it.

`decode_command` returns it; an emulator applies it, and a fault-injection test reads it to check what reached the
wire. It is not a `MotorCommand`: a frame written by the vendor SDK may hold what a `MotorCommand` refuses (a
negative gain after the SDK's int16 wrap), and the motor drivers would apply it, so the record keeps it as sent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wbc.hardware.unitree.remote import Remote
from wbc.types import MotorCommand

__all__ = ["WireCommand"]


@dataclass(frozen=True, kw_only=True)
class WireCommand:
    """The leg motors' part of one LowCmd, dequantised (house joint order = SDK order), arrays of shape (12,).

    Attributes:
        mode: motor modes as sent (0x0A servo, 0 damping/off), uint8.
        q: target positions [rad], float32 values (PosStopF 2.146e9 = no position target).
        dq: target velocities [rad/s], float32 values (VelStopF 16000 = no velocity target).
        kp: position gains [N m / rad], multiples of 1/32 (negative only if the sender wrapped).
        kd: velocity gains [N m s / rad], multiples of 1/16.
        tau: feed-forward torques [N m], multiples of 1/256.
        remote: the frame's wireless-remote block.
    """

    mode: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    tau: np.ndarray
    remote: Remote

    def motor_command(self) -> MotorCommand:
        """The same targets and gains as a `MotorCommand` (the mode is dropped).

        Raises:
            CommandError: the frame holds a negative gain, which a `MotorCommand` cannot carry.
        """
        return MotorCommand(q=self.q, dq=self.dq, kp=self.kp, kd=self.kd, tau=self.tau)
