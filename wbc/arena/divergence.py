"""`DivergenceCheck`: the runner's per-tick test that a simulation has not blown up, and `SimulationDiverged`.

A physics engine pushed outside what it can integrate (a friction of 1e-10, a stiff contact at a large step) does
not stop: its state grows to 1e6 m/s, turns NaN, or the trunk falls through the floor, and MuJoCo may even reset
itself and carry on. Such a trial measures the simulator, not the controller, so the runner
(`wbc.arena.runner.run_episode`) checks the robot's state every tick and ends the episode with
`SimulationDiverged` at the first tick that is impossible; the trial is recorded with the outcome ``diverged``
(`wbc.arena.trial_record.DIVERGED`) and NaN for the metrics of its motion, so that no absurd number reaches a mean.

The limits are far beyond anything a legged robot of this size does, so a real fall or push never trips them: the
fastest quadrupeds run at about 4 m/s, a trunk dropped from 1 m lands at 4.5 m/s, a 300 N push of 0.1 s moves a
12 kg trunk at 2.5 m/s; a tumbling trunk spins at a few tens of rad/s and a free-swinging joint at a few tens more.
A check costs a few microseconds per tick, against a control period's physics of a hundred or more.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from wbc.arena.episode import Episode
from wbc.errors import WbcError
from wbc.types import BaseTruth, RobotState

__all__ = ["DivergenceCheck", "SimulationDiverged"]


@dataclass(frozen=True, kw_only=True)
class DivergenceCheck:
    """The limits past which a simulated robot's state is impossible.

    Attributes:
        max_base_speed: trunk speed, |v| of its origin in the world [m/s].
        max_base_spin: trunk angular speed, |omega| in the trunk frame [rad/s].
        max_joint_speed: the joints' speeds, as one vector's norm |dq| [rad/s].
        min_base_height: trunk origin's height in the world [m]: lower is through the floor (terrains are flat or a
            few centimetres of relief around 0).
    """

    max_base_speed: float = 20.0
    max_base_spin: float = 200.0
    max_joint_speed: float = 500.0
    min_base_height: float = -1.0

    # The per-tick tests read the trunk's few numbers as Python floats (a NumPy call on a 3-vector costs more than
    # the arithmetic) and compare with `<=`, which is False for NaN too: a non-finite value fails the same comparison
    # as a too-large one, and the words are worked out only then. A tick costs a few microseconds.

    def state(self, state: RobotState) -> str | None:
        """What is impossible in the joints the robot reports (non-finite, too fast), or None."""
        q, dq = state.q, state.dq
        if not _joints_possible(q, dq, self.max_joint_speed ** 2):
            if not (np.all(np.isfinite(q)) and np.all(np.isfinite(dq))):
                return "a joint position or speed is not finite"
            return (f"the joints turn at {math.sqrt(float(dq @ dq)):.3g} rad/s, the norm of their speeds (limit "
                    f"{self.max_joint_speed:g} rad/s)")
        return None

    def truth(self, truth: BaseTruth) -> str | None:
        """What is impossible in the trunk's true state (non-finite, too fast, through the floor), or None."""
        x, y, z = truth.base_position_in_world.tolist()
        vx, vy, vz = truth.base_linvel_in_world.tolist()
        wx, wy, wz = truth.base_angvel_in_body.tolist()
        speed2, spin2 = vx * vx + vy * vy + vz * vz, wx * wx + wy * wy + wz * wz
        if (speed2 <= self.max_base_speed ** 2 and spin2 <= self.max_base_spin ** 2 and z >= self.min_base_height
                and x + y < math.inf and sum(truth.base_quat.tolist()) < math.inf):
            return None
        position, quat = truth.base_position_in_world, truth.base_quat
        velocity, spin = truth.base_linvel_in_world, truth.base_angvel_in_body
        if not all(np.all(np.isfinite(a)) for a in (position, quat, velocity, spin)):
            return "the trunk's position, orientation or velocity is not finite"
        if speed2 > self.max_base_speed ** 2:
            return f"the trunk moves at {math.sqrt(speed2):.3g} m/s (limit {self.max_base_speed:g} m/s)"
        if spin2 > self.max_base_spin ** 2:
            return f"the trunk spins at {math.sqrt(spin2):.3g} rad/s (limit {self.max_base_spin:g} rad/s)"
        return (f"the trunk is at height {z:.3g} m, through the floor (limit "
                f"{self.min_base_height:g} m)")


@numba.njit(cache=True, nogil=True)
def _joints_possible(q: np.ndarray, dq: np.ndarray, max_speed2: float) -> bool:  # pragma: no cover - compiled
    """Every joint position finite and the joints' speeds' squared norm within `max_speed2` (False for a NaN).

    One compiled pass: two NumPy dot products and their conversions cost ~10 us a tick in the loop.
    """
    for i in range(q.shape[0]):
        if not abs(q[i]) < math.inf:
            return False
    speed2 = 0.0
    for i in range(dq.shape[0]):
        speed2 += dq[i] * dq[i]
    return speed2 <= max_speed2


_joints_possible(np.zeros(1), np.zeros(1), 1.0)  # loaded with this module (numba's cache on disk), not at a tick


class SimulationDiverged(WbcError, RuntimeError):
    """The simulation blew up during an episode: the runner ended it at the first impossible tick.

    Args:
        reason: what was impossible (`DivergenceCheck`).
        tick: the control tick (0-based) at which it was found.
        time_s: the episode time of that tick's end [s].
        episode: the episode played up to it (not a fall: ``fell`` False).

    Attributes:
        reason, tick, time_s, episode: as given.
    """

    def __init__(self, reason: str, *, tick: int, time_s: float, episode: Episode) -> None:
        self.reason = reason
        self.tick = tick
        self.time_s = time_s
        self.episode = episode
        super().__init__(self.describe())

    def describe(self) -> str:
        """One line: the tick, the time and what diverged."""
        return f"simulation diverged at tick {self.tick} (t = {self.time_s:.3f} s): {self.reason}"
