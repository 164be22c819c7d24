"""The control rates a file may declare for a policy: a period that is a whole number of physics steps, 2 ms to 1 s.

The arena steps the simulator by `PHYSICS_DT` (`wbc.hardware.mujoco.MujocoRobotConfig.timestep`'s default) and calls
a controller every ``round(period / PHYSICS_DT)`` steps, so a period that is not a whole number of steps cannot be
played as declared. The bounds keep a trial sane: faster than `MAX_RATE_HZ` would ask for more than one action per
physics step; slower than `MIN_RATE_HZ` leaves a 20 s trial with fewer than 20 actions, and a period longer than the
trial with none at all, so a controller that never acts would be scored on the robot standing still. A policy file's
``policy_dt`` and an ONNX I/O file's ``rate_hz`` are both checked here, and their errors state the rule.
"""

from __future__ import annotations

import math

from wbc.physics_steps import nearest_rates

__all__ = ["MAX_RATE_HZ", "MIN_RATE_HZ", "PHYSICS_DT", "RATE_RULE", "period_problem", "rate_problem"]

PHYSICS_DT = 0.002  # [s]
"""The physics step the arena plays every controller on [s]."""

MIN_RATE_HZ = 1.0
"""Slowest control rate a policy file may declare [Hz] (a period of at most 1 s)."""

MAX_RATE_HZ = 1.0 / PHYSICS_DT
"""Fastest control rate [Hz]: one action per physics step (500 Hz)."""

RATE_RULE = (f"the control period must be a whole number of the {PHYSICS_DT * 1e3:g} ms physics steps, from "
             f"{1e3 / MAX_RATE_HZ:g} ms to {1 / MIN_RATE_HZ:g} s (a rate of {MIN_RATE_HZ:g} to {MAX_RATE_HZ:g} Hz "
             "that divides 500 Hz: 500, 250, 100, 50, 25, 10 Hz ...)")
"""The rule `period_problem` and `rate_problem` check, as their messages state it."""

_TOLERANCE = 1e-9  # relative to one step: 0.02 s is 10.000000000000002 steps in floating point


def period_problem(period_s: float) -> str | None:
    """Why a control period cannot be played, or None when it can.

    Args:
        period_s: the period [s].

    Returns:
        None for a finite period of k whole physics steps, 1 <= k <= 1 / (`MIN_RATE_HZ` `PHYSICS_DT`); else the
        reason, which states `RATE_RULE`.
    """
    if not math.isfinite(period_s) or period_s <= 0.0:
        return f"{period_s!r} s is not a positive finite period; {RATE_RULE}"
    steps = period_s / PHYSICS_DT
    if steps < 1.0 - _TOLERANCE or period_s > 1.0 / MIN_RATE_HZ * (1.0 + _TOLERANCE):
        return f"{period_s!r} s is out of range; {RATE_RULE}"
    if abs(steps - round(steps)) > _TOLERANCE * max(1.0, steps):
        return (f"{period_s!r} s is {steps:.6g} physics steps, not a whole number; {RATE_RULE}; the nearest are "
                f"{math.floor(steps) * PHYSICS_DT:g} s and {math.ceil(steps) * PHYSICS_DT:g} s")
    return None


def rate_problem(rate_hz: float) -> str | None:
    """Why a control rate cannot be played, or None when it can (`period_problem` of its period).

    Args:
        rate_hz: the rate [Hz].

    Returns:
        None, or the reason, which states `RATE_RULE`.
    """
    if not math.isfinite(rate_hz) or rate_hz <= 0.0:
        return f"{rate_hz!r} Hz is not a positive finite rate; {RATE_RULE}"
    problem = period_problem(1.0 / rate_hz)
    if problem is None:
        return None
    if rate_hz < MIN_RATE_HZ or rate_hz > MAX_RATE_HZ * (1.0 + _TOLERANCE):
        return f"{rate_hz!r} Hz is out of range; {RATE_RULE}"
    steps = MAX_RATE_HZ / rate_hz
    return (f"{rate_hz!r} Hz has a period of {steps:.6g} physics steps, not a whole number; {RATE_RULE}; "
            f"{nearest_rates(rate_hz, PHYSICS_DT)}")
