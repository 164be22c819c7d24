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
    # runs for every swing foot every tick: Python floats, two arrays built at the end
    x0, y0, z0 = np.asarray(start, dtype=np.float64).tolist()
    x1, y1, z1 = np.asarray(end, dtype=np.float64).tolist()
    dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
    rate = dblend / duration
    pos = np.array([x0 + dx * blend, y0 + dy * blend, z0 + dz * blend + apex * bump])
    vel = np.array([dx * rate, dy * rate, dz * rate + apex * dbump / duration])
    return pos, vel
