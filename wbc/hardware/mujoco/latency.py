"""The simulated robot's actuation and sensing delays: commands on their way to the motors, and past sensor frames.

A real robot's loop is late twice: a command reaches the motor drivers some time after the controller wrote it
(transport, the link thread's period, the driver's own loop), and a state reaches the controller some time after its
sensors measured it. `MujocoRobot` models both in whole physics steps (`wbc.hardware.mujoco.physics.delay_steps`):
`CommandQueue` holds each written command until the physics step it arrives at, and `SensorHistory` keeps the
sensor frames that a later `read` may still ask for.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass

import numpy as np

__all__ = ["CommandQueue", "PendingCommand", "SensorFrame", "SensorHistory"]


@dataclass(frozen=True)
class PendingCommand:
    """A motor command on its way to the motors, in the actuators' terms (`wbc.hardware.mujoco.physics`).

    Attributes:
        at: the physics step from which the motors apply it.
        kp: (nu,) position gains [N m / rad].
        kd: (nu,) velocity gains [N m s / rad].
        ctrl: (nu,) the actuators' control ``kp q* + kd dq* + tau_ff`` [N m].
    """

    at: int
    kp: np.ndarray
    kd: np.ndarray
    ctrl: np.ndarray


class CommandQueue:
    """Commands written but not yet at the motors, in arrival order (first in, first out, like a wire).

    A command never overtakes an earlier one: if the delay shrinks while commands are pending, a new command arrives
    no earlier than the last pending one. Two commands arriving at the same step: the later one wins, as a motor
    driver keeps only the newest.
    """

    def __init__(self) -> None:
        self._items: collections.deque[PendingCommand] = collections.deque()

    def __len__(self) -> int:
        return len(self._items)

    def clear(self) -> None:
        """Drop every pending command."""
        self._items.clear()

    def push(self, at: int, kp: np.ndarray, kd: np.ndarray, ctrl: np.ndarray) -> None:
        """Queue a command that arrives at physics step `at` (or with the last pending one, if that is later)."""
        items = self._items
        if items and items[-1].at >= at:
            at = items.pop().at
        items.append(PendingCommand(at, kp, kd, ctrl))

    def next_arrival(self) -> int | None:
        """The physics step at which the next pending command arrives, or None."""
        return self._items[0].at if self._items else None

    def due(self, step: int) -> PendingCommand | None:
        """Remove the commands that have arrived by physics step `step`; return the newest of them, or None."""
        items, last = self._items, None
        while items and items[0].at <= step:
            last = items.popleft()
        return last


@dataclass(frozen=True)
class SensorFrame:
    """What the sensors measured at one physics step (fresh arrays, the caller's to keep).

    Attributes:
        step: the physics step it was measured at.
        q: (nu,) joint positions [rad].
        dq: (nu,) joint velocities [rad/s].
        tau: (nu,) motor torques of the step that led to it [N m].
        sensordata: (nsensordata,) every MuJoCo sensor (IMU, foot touch).
    """

    step: int
    q: np.ndarray
    dq: np.ndarray
    tau: np.ndarray
    sensordata: np.ndarray


class SensorHistory:
    """The sensor frames of the last ``lag + 1`` physics steps, in a ring indexed by step.

    `frame(step)` returns the frame measured at ``step - lag``, or the first frame kept (`seed`) while fewer than
    `lag` steps have passed since: a sensor delay of `lag` steps. The owner records every step whose frame a later
    read may ask for, which is each step from ``end - lag`` on for a run of physics ending at step ``end`` (reads
    happen at the end of a run, at steps >= end): so only the last `lag` steps of a run need to be taken one by one.

    Args:
        lag: the delay in physics steps, >= 1.
        nu: actuated joints.
        nsensordata: the model's sensor values.
    """

    def __init__(self, lag: int, nu: int, nsensordata: int) -> None:
        self.lag = lag
        size = lag + 1
        self._q = np.zeros((size, nu))
        self._dq = np.zeros((size, nu))
        self._tau = np.zeros((size, nu))
        self._sd = np.zeros((size, nsensordata))
        self._origin = 0

    def seed(self, step: int, q: np.ndarray, dq: np.ndarray, tau: np.ndarray, sensordata: np.ndarray) -> None:
        """Start the history at `step`: until `lag` steps have passed, every read returns this frame."""
        self._origin = step
        self.record(step, q, dq, tau, sensordata)

    def record(self, step: int, q: np.ndarray, dq: np.ndarray, tau: np.ndarray, sensordata: np.ndarray) -> None:
        """Keep the frame measured at physics step `step` (copied)."""
        k = step % self._q.shape[0]
        self._q[k] = q
        self._dq[k] = dq
        self._tau[k] = tau
        self._sd[k] = sensordata

    def frame(self, step: int) -> SensorFrame:
        """The frame a read at physics step `step` gets: the one measured at ``max(step - lag, seed step)``."""
        s = max(step - self.lag, self._origin)
        k = s % self._q.shape[0]
        return SensorFrame(s, self._q[k].copy(), self._dq[k].copy(), self._tau[k].copy(), self._sd[k].copy())
