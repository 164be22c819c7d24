"""`CommandRamp`: the bounded move from the measured pose into a controller's command.

The first command of a ramp holds the measured pose with the ramp's low start gains and no feed-forward, for
``hold`` seconds: a link that sends only the newest command each period (Unitree's) would otherwise replace the hold
by the next step before it reached the motors, whenever a loop wrote twice within one period. After it, each
commanded target is the controller's plus a gap that closes at no more than ``slew`` rad/s, while the gains,
target velocities and feed-forward torques are blended linearly from the start values into the controller's over
``duration`` seconds. The ramp is done once the blend is complete and the gap is closed; its last command is then
the controller's own, so handing over to it is no jump.

Closing a gap rather than chasing the target is what lets a moving controller in: a walking gait's swing legs move
their targets faster than any safe slew, so a ramp that chased them would never catch up (and the controller would
run under low gains until something tripped). For a controller that holds still, the two are the same motion.
"""

from __future__ import annotations

import numpy as np

from wbc.types import MotorCommand

__all__ = ["CommandRamp"]


class CommandRamp:
    """A ramp from the measured pose into a (possibly moving) controller command.

    Args:
        duration_s: blend time of gains and feed-forward [s].
        slew: largest speed at which the gap between the commanded targets and the controller's closes [rad/s].
        kp: position gain at the start [N m / rad].
        kd: velocity gain at the start [N m s / rad].
        hold_s: how long the first command (the measured pose) is held before the gap starts closing [s].
    """

    def __init__(self, *, duration_s: float, slew: float, kp: float, kd: float, hold_s: float = 0.0) -> None:
        self._hold = hold_s
        self._duration = duration_s
        self._slew = slew
        self._kp0 = kp
        self._kd0 = kd
        self._q: np.ndarray | None = None
        self._gap: np.ndarray | None = None
        self._t0 = 0.0
        self._t_last = 0.0

    @property
    def settings(self) -> dict[str, float]:
        """What it was built with (``CommandRamp(**settings)`` builds an unstarted twin, in another process too)."""
        return {"duration_s": self._duration, "slew": self._slew, "kp": self._kp0, "kd": self._kd0,
                "hold_s": self._hold}

    @property
    def started(self) -> bool:
        """True once `start` was called."""
        return self._q is not None

    def start(self, q_measured: np.ndarray, time: float) -> MotorCommand:
        """Begin at the measured pose; return the ramp's first command (hold `q_measured` with the start gains).

        Args:
            q_measured: the joints' measured positions, shape (n,) [rad] (already inside the allowed range).
            time: now [s].
        """
        self._q = np.array(q_measured, dtype=np.float64)
        self._gap = None
        self._t0 = self._t_last = time + self._hold  # the motion and the blend begin once the hold is over
        return MotorCommand.hold(self._q.copy(), self._kp0, self._kd0)

    def step(self, target: MotorCommand, time: float) -> tuple[MotorCommand, bool]:
        """The ramp's command at `time` towards the controller's `target`, and whether the ramp is done.

        Args:
            target: the controller's command (already clamped).
            time: now [s]; a step at the same time as the last one moves nothing.
        """
        if self._q is None:
            raise RuntimeError("CommandRamp.step before start")  # a bug in the caller, never a runtime condition
        if self._gap is None and time < self._t0:  # still holding the measured pose
            return MotorCommand.hold(self._q.copy(), self._kp0, self._kd0), False
        max_step = self._slew * max(0.0, time - self._t_last)
        self._t_last = max(self._t_last, time)
        if self._gap is None:  # the first step: the gap is where the ramp started, seen from the controller's target
            self._gap = self._q - target.q
        self._gap = self._gap - np.clip(self._gap, -max_step, max_step)
        closed = not self._gap.any()
        self._q = target.q + self._gap
        s = min(1.0, max(0.0, (time - self._t0) / self._duration))
        if closed and s >= 1.0:
            return target, True
        cmd = MotorCommand(q=self._q.copy(), dq=s * target.dq, kp=self._kp0 + s * (target.kp - self._kp0),
                           kd=self._kd0 + s * (target.kd - self._kd0), tau=s * target.tau)
        return cmd, False
