"""`CurrentLaw`: Unitree motor semantics on current-mode servos, as the host evaluates them every bus cycle.

A `MotorCommand` asks each joint for ``tau = kp (q* - q) + kd (dq* - dq) + tau_ff``. A Unitree leg motor evaluates
that law itself, about 10 kHz. The arm's servos run in current mode (Operating Mode 0), so the host evaluates it,
once per bus cycle, from the positions and velocities the cycle's sync read returned. It then asks each servo for
the current that gives that torque:

    goal current [A] = sign * tau / (servos * TORQUE_CONSTANT)

Here `servos` counts the motors that drive the joint: the shoulder has two, and its shadow takes ID 2's goal through
its Secondary ID, in its own reversed direction, so both push the same way. The torque is clamped twice. First to
the joint's limit, which is the model's effort limit and the current bound times the torque constant, whichever is
lower. Then the goal current is rounded to register units and clamped to the bound, because a Goal Current beyond
Current Limit is refused by the servo. A sync write carries no answer, so a refused goal would go unnoticed.

The present registers map back the same way: q and dq through `ArmJointMap` (ticks, velocity units), and
tau_est = sign * current * servos * TORQUE_CONSTANT. The torque constant is the datasheet's stall ratio, a
linear approximation (see `wbc.hardware.dynamixel.units`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from wbc.hardware.dynamixel.units import CENTER_TICKS, CURRENT_UNIT, RAD_PER_TICK, TORQUE_CONSTANT, VELOCITY_UNIT
from wbc.hardware.dynamixel.wx200_bus import ArmJointMap

__all__ = ["CurrentLaw"]


class CurrentLaw:
    """The torque law and its current units for the model's arm joints.

    Args:
        joints: the joints on the bus (sign, offset, servos per joint).
        torque_limit: each joint's torque limit [N m], shape (n,).
        current_limit_a: the largest current asked of one servo [A].
    """

    def __init__(self, joints: Sequence[ArmJointMap], torque_limit: np.ndarray, current_limit_a: float) -> None:
        self.joints = tuple(joints)
        self.sign = np.array([j.sign for j in joints], dtype=np.float64)
        self.offset = np.array([j.offset for j in joints], dtype=np.float64)
        self.servos = np.array([len(j.servo_ids) for j in joints], dtype=np.float64)
        self.limit_units = int(round(current_limit_a / CURRENT_UNIT))
        self.torque_limit = np.minimum(np.asarray(torque_limit, dtype=np.float64),
                                       self.limit_units * CURRENT_UNIT * TORQUE_CONSTANT * self.servos)

    def torque(self, rows: np.ndarray, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """The law's torque per joint, clamped to the joints' limits [N m].

        Args:
            rows: the command's rows (q, dq, kp, kd, tau), shape (5, n).
            q: measured positions [rad].
            dq: measured velocities [rad/s].
        """
        tau = rows[2] * (rows[0] - q) + rows[3] * (rows[1] - dq) + rows[4]
        return np.clip(tau, -self.torque_limit, self.torque_limit)

    def goal_units(self, tau: np.ndarray) -> np.ndarray:
        """Goal Current register values (int) for joint torques `tau` [N m], within the current bound."""
        amps = self.sign * tau / (self.servos * TORQUE_CONSTANT)
        units = np.rint(amps / CURRENT_UNIT)
        return np.clip(units, -self.limit_units, self.limit_units).astype(np.int64)

    def state(self, ticks: np.ndarray, velocity: np.ndarray, current: np.ndarray) -> tuple[np.ndarray, ...]:
        """(q [rad], dq [rad/s], tau_est [N m]) from the primaries' Present Position, Velocity and Current."""
        q = self.sign * (np.asarray(ticks, dtype=np.float64) - CENTER_TICKS) * RAD_PER_TICK + self.offset
        dq = self.sign * np.asarray(velocity, dtype=np.float64) * VELOCITY_UNIT
        tau = self.sign * np.asarray(current, dtype=np.float64) * CURRENT_UNIT * self.servos * TORQUE_CONSTANT
        return q, dq, tau
