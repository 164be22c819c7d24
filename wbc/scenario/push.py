"""`Push`: an external force on the trunk, of given magnitude and direction, at a point offset from the base."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wbc.errors import ConfigError

__all__ = ["Push"]


@dataclass(frozen=True, kw_only=True)
class Push:
    """A constant force applied to the trunk for a while.

    Attributes:
        force_in_world: force vector in the world frame, shape (3,) [N].
        offset_in_base: application point in the base (trunk) frame, shape (3,) [m]; it moves with the trunk.
        start: simulation time at which the push begins [s].
        duration: how long it acts [s].
    """

    force_in_world: np.ndarray
    offset_in_base: np.ndarray
    start: float
    duration: float

    def __post_init__(self) -> None:
        for name in ("force_in_world", "offset_in_base"):
            a = np.asarray(getattr(self, name), dtype=np.float64)
            if a.shape != (3,) or not np.all(np.isfinite(a)):
                raise ConfigError(f"Push.{name} must be 3 finite numbers, got {getattr(self, name)!r}")
            object.__setattr__(self, name, a)
        if not (np.isfinite(self.start) and self.start >= 0):
            raise ConfigError(f"Push.start must be >= 0, got {self.start}")
        if not (np.isfinite(self.duration) and self.duration > 0):
            raise ConfigError(f"Push.duration must be > 0, got {self.duration}")

    @classmethod
    def horizontal(cls, magnitude: float, heading: float, offset_in_base: np.ndarray | tuple[float, float, float],
                   start: float, duration: float) -> Push:
        """A horizontal push of `magnitude` [N] towards world heading `heading` [rad]."""
        f = magnitude * np.array([np.cos(heading), np.sin(heading), 0.0])
        return cls(force_in_world=f, offset_in_base=np.asarray(offset_in_base, dtype=np.float64), start=start,
                   duration=duration)

    @property
    def impulse(self) -> np.ndarray:
        """Linear impulse delivered [N s]."""
        return self.force_in_world * self.duration
