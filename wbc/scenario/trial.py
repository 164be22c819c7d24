"""`Trial`: one fully determined episode of a scenario (terrain, randomisation, commands, pushes, duration).

A scenario (`wbc.scenario.scenario`) samples trials; the runner (`wbc.arena.runner`) plays them. Trial i of a scenario
under seed s is a pure function of (scenario content, band, seed, i): the same whatever the controller, worker or order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wbc.scenario.domain import DomainParams
from wbc.scenario.push import Push
from wbc.scenario.terrain import TerrainConfig
from wbc.types import VelocityCommand

__all__ = ["CommandChange", "CommandSchedule", "Trial"]


@dataclass(frozen=True, kw_only=True)
class CommandChange:
    """From `at_s` on, the command is `command`, held (no ramp) until the next change.

    Attributes:
        at_s: when it takes effect [s]: the first control tick at or after it plays it.
        command: the velocity command from then on.
    """

    at_s: float
    command: VelocityCommand


@dataclass(frozen=True, kw_only=True)
class CommandSchedule:
    """A constant velocity command reached by a linear ramp, then changed at fixed times (if any).

    Attributes:
        vx: forward velocity [m/s].
        vy: lateral velocity [m/s].
        yaw_rate: yaw rate [rad/s].
        ramp_s: the command rises linearly from zero over this time from t = 0 [s] (0: a step).
        changes: later commands, in increasing time order, each held from its time on (none: the constant command
            throughout).
    """

    vx: float = 0.0
    vy: float = 0.0
    yaw_rate: float = 0.0
    ramp_s: float = 0.0
    changes: tuple[CommandChange, ...] = ()

    def at(self, t: float) -> VelocityCommand:
        """The command at time `t` [s]."""
        for change in reversed(self.changes):
            if t >= change.at_s:
                return change.command
        s = 1.0 if self.ramp_s <= 0.0 else min(1.0, max(0.0, t / self.ramp_s))
        return VelocityCommand(vx=s * self.vx, vy=s * self.vy, yaw_rate=s * self.yaw_rate)


@dataclass(frozen=True, kw_only=True)
class Trial:
    """One episode to play.

    Attributes:
        scenario: scenario name.
        scenario_hash: content hash of the scenario file (hex).
        robot: robot registry name.
        band: band name.
        seed: seed index.
        index: trial index within (band, seed).
        duration_s: episode length [s].
        terrain: ground shape.
        terrain_seed: seed of the terrain heights.
        domain: physical randomisation.
        pushes: pushes, in time order.
        command: the velocity command schedule.
    """

    scenario: str
    scenario_hash: str
    robot: str
    band: str
    seed: int
    index: int
    duration_s: float
    terrain: TerrainConfig
    terrain_seed: int
    domain: DomainParams
    pushes: tuple[Push, ...]
    command: CommandSchedule

    @property
    def key(self) -> tuple[str, int, int]:
        """(band, seed, index): identifies the trial within its scenario."""
        return (self.band, self.seed, self.index)

    @property
    def push_force_n(self) -> float:
        """Largest push magnitude in the trial [N] (0 without pushes)."""
        return max((float(np.linalg.norm(p.force_in_world)) for p in self.pushes), default=0.0)
