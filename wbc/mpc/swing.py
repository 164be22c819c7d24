"""Swing-foot trajectories: from lift-off to the planned foothold, lifted by an apex height."""

from __future__ import annotations

import numpy as np

__all__ = ["swing_point"]


def swing_point(start: np.ndarray, end: np.ndarray, s: float, duration: float, apex: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity of a swing foot at progress `s` in [0, 1].

    Horizontal: a cubic smooth step from `start` to `end` (zero velocity at both ends). Vertical: the same blend
    plus a bump 16 apex s^2 (1 - s)^2, which peaks at `apex` mid-swing and touches down with zero vertical velocity.

    Args:
        start: lift-off position, world (3,) [m].
        end: touchdown position, world (3,) [m].
        s: progress through the swing.
        duration: swing duration [s].
        apex: lift height [m].

    Returns:
        (position (3,), velocity (3,)) in the world frame.
    """
    s = min(1.0, max(0.0, float(s)))
    blend, dblend = 3 * s**2 - 2 * s**3, 6 * s - 6 * s**2
    bump, dbump = 16 * s**2 * (1 - s) ** 2, 32 * s * (1 - s) * (1 - 2 * s)
    # runs for every swing foot every tick: scalars stay Python floats, three array operations in all
    span = np.subtract(end, start)
    pos = start + span * blend
    vel = span * (dblend / duration)
    pos[2] += apex * bump
    vel[2] += apex * dbump / duration
    return pos, vel
