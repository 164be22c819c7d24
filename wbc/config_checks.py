"""`check_number`: the one check of a settings dataclass's numeric field, with the message every config gives.

The settings dataclasses (the estimator's, the MPC's and its parts') check their numeric fields with it in
``__post_init__``, so that a value no controller can run with (a NaN gain, a zero rate, a horizon of no steps) is
refused where it is given, naming the field, instead of failing later inside the controller.
"""

from __future__ import annotations

import math
import numbers

from wbc.errors import ConfigError

__all__ = ["check_number"]


def check_number(where: str, value: object, *, at_least: float | None = None, above: float | None = None,
                 at_most: float | None = None, integer: bool = False, size: int | None = None) -> None:
    """Raise `ConfigError` unless `value` is a finite number (an integer if `integer`) within the bounds given.

    The settings dataclasses of the estimator and the MPC check their numeric fields with it in ``__post_init__``, so
    that a value no controller can run with (a NaN gain, a zero rate, a horizon of no steps) is refused where it is
    given, naming the field, instead of failing later inside the controller. A tuple `value` (a setting per axis or
    per foot) is checked element by element.

    Args:
        where: the setting, ``Dataclass.field``, as the message names it.
        value: the value given.
        at_least: the smallest valid value, or None.
        above: a bound the value must exceed, or None.
        at_most: the largest valid value, or None.
        integer: the value must be an integer (not a bool).
        size: for a tuple, the number of elements it must have (None: a single number).

    Raises:
        ConfigError: ``{where} must be {what is valid}, got {value!r}``, e.g. ``MpcConfig.horizon must be an integer
            >= 1, got 0``.
    """
    if size is None:
        values: tuple | list | None = (value,)
    else:
        values = value if isinstance(value, tuple | list) and len(value) == size else None
    if values is not None and all(_fits(v, at_least, above, at_most, integer) for v in values):
        return
    low = f"[{at_least:g}" if at_least is not None else f"({above:g}" if above is not None else None
    if low is not None and at_most is not None:
        bounds = f" in {low}, {at_most:g}]"
    elif low is not None:
        bounds = f" {'>=' if low[0] == '[' else '>'} {low[1:]}"
    else:
        bounds = f" <= {at_most:g}" if at_most is not None else ""
    kind = "integer" if integer else "finite number"
    what = (f"an {kind}" if integer else f"a {kind}") if size is None else f"{size} {kind}s"
    raise ConfigError(f"{where} must be {what}{bounds}, got {value!r}")


def _fits(value: object, at_least: float | None, above: float | None, at_most: float | None, integer: bool) -> bool:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral if integer else numbers.Real):
        return False
    x = float(value)
    return (math.isfinite(x) and (at_least is None or x >= at_least) and (above is None or x > above)
            and (at_most is None or x <= at_most))
