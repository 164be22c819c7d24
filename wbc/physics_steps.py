"""`nearest_rates`: the control rates nearest a refused one, among those whose period is a whole number of steps.

The simulator calls a controller every whole number of physics steps, so a control rate whose period is not such a
number cannot be played as declared. Three places refuse one: the arena (`wbc.arena.sim_trial.check_rate`), the
contract checker's ``rate`` check (`wbc.control.controller_contract`) and the rate rule of policy and ONNX I/O files
(`wbc.learned.policy.control_rate`); each ends its refusal with the rates nearest the one refused, from here.
"""

from __future__ import annotations

import math

__all__ = ["nearest_rates"]


def nearest_rates(rate_hz: float, step_s: float) -> str:
    """The rates nearest `rate_hz` whose period is a whole number of `step_s` physics steps, as a refusal says them.

    Args:
        rate_hz: the refused rate, finite and positive [Hz].
        step_s: the physics step [s].

    Returns:
        ``the nearest are 500 Hz and 250 Hz``: the rates of the whole numbers of steps just below and just above the
        period of `rate_hz` (300 Hz, 2 ms steps); ``the nearest is 500 Hz`` for a rate faster than one step, or one
        whose period is a whole number of steps already.
    """
    steps = 1.0 / (rate_hz * step_s)
    fewer, more = math.floor(steps), math.ceil(steps)
    fastest = 1.0 / step_s
    if fewer < 1:
        return f"the nearest is {fastest:g} Hz"
    if fewer == more:
        return f"the nearest is {fastest / fewer:g} Hz"
    return f"the nearest are {fastest / fewer:g} Hz and {fastest / more:g} Hz"
