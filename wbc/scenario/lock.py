"""The publish lock: ``scenarios/published.toml`` maps each published scenario's (name, version) to its content hash.

A comparison is comparable with published ones only if its scenario is in the lock with the same hash; a published
file that changes must bump its version and add a new entry, never edit one.
"""

from __future__ import annotations

import sys
from pathlib import Path

from wbc.errors import ScenarioError
from wbc.scenario.scenario import Scenario
from wbc.scenario.toml_fields import read_toml, show

__all__ = ["check_published", "warn_if_unpublished"]


def check_published(scenario: Scenario, lock_path: Path | None = None) -> None:
    """Refuse a scenario whose (name, version) is unpublished or was published with different content.

    The lock (``published.toml``) maps name -> version -> hash: ``[push]`` then ``"1" = "<sha256 hex>"``.

    Args:
        scenario: a loaded scenario.
        lock_path: the lock file; default ``published.toml`` next to the scenario file.

    Raises:
        ScenarioError: the lock does not list (name, version) (the message gives the lines to add), lists it with
            another hash (the file changed without a version bump), or is missing or malformed.
    """
    lock = Path(lock_path) if lock_path is not None else Path(scenario.path).parent / "published.toml"
    name, version = scenario.name, str(scenario.version)
    publish = f'to publish it, add\n    [{name}]\n    "{version}" = "{scenario.hash}"\nto {lock}'
    if not lock.exists():
        raise ScenarioError(scenario.path, f"unpublished: the lock file {lock} does not exist; {publish}",
                            field="[scenario] version")
    data, lines = read_toml(lock, str(lock), ScenarioError)
    entry = data.get(name)
    if entry is not None and not isinstance(entry, dict):
        raise ScenarioError(lock, f'expected a table of "version" = "hash", got {show(entry)}',
                            line=lines.key(("", 0), name), field=f"[{name}]")
    locked = None if entry is None else entry.get(version)
    if locked is None:
        raise ScenarioError(scenario.path, f"unpublished: {lock} does not list {name!r} version {version}; {publish}",
                            field="[scenario] version")
    if not isinstance(locked, str):
        raise ScenarioError(lock, f"expected a sha256 hex string, got {show(locked)}",
                            line=lines.key((name, 0), version), field=f'[{name}] "{version}"')
    if locked != scenario.hash:
        raise ScenarioError(
            scenario.path,
            f"{name!r} version {version} is published with hash {locked} but the file now hashes to "
            f"{scenario.hash}: the file changed without a version bump; restore it, or bump [scenario] version and "
            f"add the new hash to {lock}",
            field="[scenario] version",
        )


def warn_if_unpublished(scenario: Scenario) -> bool:
    """`check_published`, as a warning: print why the scenario is not the published one on stderr, and go on.

    A command that plays a scenario (the arena, an analysis, a bench, the viewer) calls it before it plays, so that an
    edited copy of a published file is never taken for it in silence; the warning is ``wbc: warning: `` and
    `check_published`'s message (the lines that would publish it, or the hash it was published with).

    Args:
        scenario: a loaded scenario.

    Returns:
        True when the lock beside the file lists the scenario with its hash.
    """
    try:
        check_published(scenario)
    except ScenarioError as exc:
        print(f"wbc: warning: {exc}", file=sys.stderr)
        return False
    return True
