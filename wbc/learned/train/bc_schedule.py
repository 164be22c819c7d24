"""`BCSchedule`: the annealed weight lambda of the paper's behaviour-cloning term (eq. 3).

The paper anneals lambda "to decrease the imitation constraint in the later stages of training" and gives no schedule.
Ours: hold `initial` for `hold_iterations`, then decay to `final` over `anneal_iterations`, linearly or exponentially
(geometric interpolation, reaching `final` exactly at the end); `final` afterwards. ``constant`` keeps `initial`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from wbc.errors import ConfigError

__all__ = ["BCSchedule", "BC_KINDS"]

BC_KINDS = ("constant", "linear", "exponential")


@dataclass(frozen=True, kw_only=True)
class BCSchedule:
    """The BC weight as a function of the PPO iteration.

    Attributes:
        initial: lambda at the start.
        final: lambda after the annealing (>= 0; > 0 for ``exponential``).
        hold_iterations: iterations at `initial` before the decay starts.
        anneal_iterations: length of the decay.
        kind: ``constant``, ``linear`` or ``exponential``.
    """

    initial: float = 1.0
    final: float = 0.0
    hold_iterations: int = 0
    anneal_iterations: int = 1000
    kind: str = "linear"

    def __post_init__(self) -> None:
        if self.kind not in BC_KINDS:
            raise ConfigError(f"BCSchedule.kind must be one of {', '.join(BC_KINDS)}, got {self.kind!r}")
        if self.initial < 0 or self.final < 0:
            raise ConfigError("BCSchedule: initial and final must be >= 0")
        if self.kind == "exponential" and (self.initial <= 0 or self.final <= 0):
            raise ConfigError("BCSchedule: an exponential decay needs initial > 0 and final > 0")
        if self.hold_iterations < 0 or self.anneal_iterations < 1:
            raise ConfigError("BCSchedule: hold_iterations >= 0 and anneal_iterations >= 1 are required")

    def weight(self, iteration: int) -> float:
        """Lambda at PPO iteration `iteration` (0-based)."""
        if self.kind == "constant":
            return self.initial
        s = min(1.0, max(0.0, (iteration - self.hold_iterations) / self.anneal_iterations))
        if self.kind == "linear":
            return self.initial + s * (self.final - self.initial)
        return math.exp(math.log(self.initial) + s * (math.log(self.final) - math.log(self.initial)))
