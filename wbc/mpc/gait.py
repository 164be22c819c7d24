"""`GaitScheduler`: which feet are on the ground, now and over the MPC horizon (stand, or a periodic trot)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wbc.config_checks import check_number
from wbc.mpc.compiled import gait_state

__all__ = ["GaitConfig", "GaitScheduler", "TROT", "STAND", "STANCE_END_MARGIN", "gait_fits_steps"]

STANCE_END_MARGIN = 1e-12
"""A phase this close below `GaitConfig.duty` already counts as out of contact [cycles].

A round-off guard at the stance/swing boundary, where a tick's phase (t / period + offset, mod 1) can land a few ulps
either side of duty; only its being round-off-sized matters."""


@dataclass(frozen=True, kw_only=True)
class GaitConfig:
    """A periodic gait.

    Attributes:
        period: cycle length [s].
        duty: fraction of the cycle each foot is on the ground (1.0: never lifts).
        offsets: phase offset of each foot (FR, FL, RR, RL) in cycles.

    Raises:
        ConfigError: a `period` that is not a positive finite number, `duty` outside (0, 1], or offsets that are not
            four finite numbers.
    """

    period: float = 0.32
    duty: float = 0.5
    offsets: tuple[float, float, float, float] = (0.0, 0.5, 0.5, 0.0)

    def __post_init__(self) -> None:
        check_number("GaitConfig.period", self.period, above=0.0)
        check_number("GaitConfig.duty", self.duty, above=0.0, at_most=1.0)
        check_number("GaitConfig.offsets", self.offsets, size=4)

    @property
    def stance_s(self) -> float:
        """Stance duration of each foot [s]."""
        return self.duty * self.period

    @property
    def swing_s(self) -> float:
        """Swing duration of each foot [s]."""
        return (1.0 - self.duty) * self.period


TROT = GaitConfig()
"""Diagonal pairs (FR+RL, FL+RR) alternate, 0.32 s cycle, half the time on the ground (stance 0.16 s, 5 MPC steps)."""

STAND = GaitConfig(period=1.0, duty=1.0)
"""All four feet on the ground."""


def gait_fits_steps(gait: GaitConfig, step_s: float) -> bool:
    """Whether every lift-off and touchdown of `gait`, started at t = 0, falls on a boundary of steps of `step_s`.

    The MPC plans in steps that begin at multiples of `step_s` and gives each step one contact pattern (the one at
    its middle): a foot that lifts or lands inside a step would get the forces of the wrong pattern for part of it,
    and the whole-body layer would be asked for the planned net force with the wrong feet.

    Args:
        gait: the gait.
        step_s: MPC step length [s].
    """
    if gait.duty >= 1.0:
        return True
    events = [t for offset in gait.offsets for t in ((-offset) % 1.0, (gait.duty - offset) % 1.0)]
    steps = [t * gait.period / step_s for t in [*events, 1.0]]
    return all(abs(s - round(s)) < 1e-6 for s in steps)


class GaitScheduler:
    """Phase clock of a gait.

    Args:
        config: the gait.
    """

    def __init__(self, config: GaitConfig) -> None:
        self.config = config
        self._offsets = np.asarray(config.offsets, dtype=np.float64)
        self.clock = (config.period, config.duty, STANCE_END_MARGIN, self._offsets)
        """`wbc.mpc.compiled.gait_state`'s constants: period [s], duty, `STANCE_END_MARGIN`, phase offsets (4,)."""

    def phase(self, t: float) -> np.ndarray:
        """Phase of each foot in its cycle, in [0, 1): stance first (< duty), then swing."""
        return np.mod(t / self.config.period + self._offsets, 1.0)

    def contact(self, t: float) -> np.ndarray:
        """Scheduled stance flags of the four feet at time `t` [s]."""
        if self.config.duty >= 1.0:
            return np.ones(4, dtype=bool)
        return self.phase(t) < self.config.duty - STANCE_END_MARGIN

    def contact_table(self, t: float, dt: float, n: int) -> np.ndarray:
        """Stance flags over a horizon: row k is the middle of step [t + k dt, t + (k + 1) dt], shape (n, 4)."""
        times = t + (np.arange(n) + 0.5) * dt
        if self.config.duty >= 1.0:
            return np.ones((n, 4), dtype=bool)
        return np.mod(times[:, None] / self.config.period + self._offsets, 1.0) < self.config.duty - STANCE_END_MARGIN

    def swing_progress(self, t: float) -> np.ndarray:
        """For each foot, progress through its swing in [0, 1] (0 for feet in stance)."""
        c = self.config
        if c.duty >= 1.0:
            return np.zeros(4)
        ph = self.phase(t)
        return np.where(ph >= c.duty, (ph - c.duty) / (1.0 - c.duty), 0.0)

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`contact`, `swing_progress` and `time_to_touchdown` at `t` from one phase evaluation (new arrays)."""
        contact, progress, touchdown = np.empty(4, dtype=bool), np.empty(4), np.empty(4)
        self.state_into(t, contact, progress, touchdown)
        return contact, progress, touchdown

    def state_into(self, t: float, contact: np.ndarray, progress: np.ndarray, touchdown: np.ndarray) -> None:
        """`state` at `t` [s] into the caller's arrays (4,) (every control tick: one compiled call, no allocation)."""
        gait_state(t, *self.clock, contact, progress, touchdown)

    def time_to_touchdown(self, t: float) -> np.ndarray:
        """For each foot, time until its next touchdown [s] (0 for feet in stance)."""
        c = self.config
        ph = self.phase(t)
        return np.where(ph >= c.duty, (1.0 - ph) * c.period, 0.0)
