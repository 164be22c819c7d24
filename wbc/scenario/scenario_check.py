"""`check_scenario`: what a scenario file is and whether a lock publishes it, read without playing a trial.

``wbc scenario check FILE`` prints it: the identity a result records (name, version, content hash), the robot, the
bands and what each sets, how ``--trials`` and ``--seeds`` count, and the lock's verdict (published, or why not and the
lines that would publish it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wbc.errors import ScenarioError
from wbc.scenario.lock import check_published
from wbc.scenario.scenario import load_scenario

__all__ = ["TRIAL_COUNT", "ScenarioCheck", "check_scenario"]

TRIAL_COUNT = ("--trials N --seeds S plays trials 0..N-1 of every band under each seed 0..S-1 (N x S per band, the "
               "same for every controller); trial i of a band under seed s is a pure function of (scenario, seed, i)")
"""How the arena counts a scenario's trials."""


@dataclass(frozen=True, kw_only=True)
class ScenarioCheck:
    """A scenario file as the arena would play it, and its lock's verdict.

    Attributes:
        path: the file.
        name, version, hash: its identity (``[scenario] name``, ``version``; sha256 of its parsed content).
        robot: the robot it is played on.
        duration_s: a trial's length [s].
        bands: each band's name and what it sets (``push_force_n`` [N], ``vx`` [m/s], ``yaw_rate`` [rad/s]).
        lock: the lock consulted (``published.toml`` beside the file, or the one given).
        published: whether `lock` publishes (name, version) with this hash.
        problem: why it is not published, with the lines that would publish it (None when published).
    """

    path: str
    name: str
    version: int
    hash: str
    robot: str
    duration_s: float
    bands: tuple[tuple[str, dict[str, Any]], ...]
    lock: str
    published: bool
    problem: str | None = None
    trial_count: str = field(default=TRIAL_COUNT)


def check_scenario(path: str | Path, lock: str | Path | None = None) -> ScenarioCheck:
    """Load, validate and hash a scenario file and check it against its lock, playing nothing.

    Args:
        path: the scenario file.
        lock: the publish lock; default ``published.toml`` beside the file.

    Raises:
        ScenarioError: the file is missing or invalid, or the lock is malformed (the message names file, line and
            field).
    """
    scenario = load_scenario(path)
    lock_path = Path(lock) if lock is not None else Path(scenario.path).parent / "published.toml"
    try:
        check_published(scenario, lock_path)
        problem = None
    except ScenarioError as exc:
        if Path(exc.path) == lock_path:
            raise  # a malformed lock is the lock's error, not a verdict on the scenario
        problem = str(exc)
    return ScenarioCheck(path=scenario.path, name=scenario.name, version=scenario.version, hash=scenario.hash,
                         robot=scenario.robot, duration_s=scenario.duration_s,
                         bands=tuple((b, scenario.band_settings(b)) for b in scenario.bands), lock=str(lock_path),
                         published=problem is None, problem=problem)
