"""The publish lock: ``scenarios/published.toml`` maps each published scenario's (name, version) to its content hash.

A comparison is comparable with published ones only if its scenario is in the lock with the same hash; a published
file that changes must bump its version and add a new entry, never edit one.
"""

from __future__ import annotations

import sys
from pathlib import Path

from wbc.errors import ScenarioError
from wbc.scenario.scenario import SOURCE_ROOT, Scenario, content_hash, resolve_scenario_path
from wbc.scenario.toml_fields import read_toml, show

__all__ = ["TOOLKIT_LOCK", "check_published", "warn_if_unpublished"]

TOOLKIT_LOCK = SOURCE_ROOT / "scenarios" / "published.toml"
"""The toolkit's own lock: the scenarios it publishes (``push`` version 2 ...) and their hashes, when `wbc` runs from
its source checkout."""


def check_published(scenario: Scenario, lock_path: Path | None = None) -> None:
    """Refuse a scenario whose (name, version) is unpublished or was published with different content.

    The lock (``published.toml``) maps name -> version -> hash: ``[push]`` then ``"1" = "<sha256 hex>"``.

    Args:
        scenario: a loaded scenario.
        lock_path: the lock file; default ``published.toml`` next to the scenario file.

    Raises:
        ScenarioError: the lock does not list (name, version) (the message gives the lines to add; for a
            (name, version) the toolkit publishes with other content, a name of its own and the lines for that),
            lists it with another hash (the file changed without a version bump), or is missing or malformed.
    """
    lock = Path(lock_path) if lock_path is not None else Path(scenario.path).parent / "published.toml"
    name, version = scenario.name, str(scenario.version)
    publish = f'to publish it, add\n    [{name}]\n    "{version}" = "{scenario.hash}"\nto {lock}'
    if not lock.exists():
        _refuse_the_toolkits_name(scenario, lock)
        raise ScenarioError(scenario.path, f"unpublished: the lock file {lock} does not exist; {publish}",
                            field="[scenario] version")
    data, lines = read_toml(lock, str(lock), ScenarioError)
    entry = data.get(name)
    if entry is not None and not isinstance(entry, dict):
        raise ScenarioError(lock, f'expected a table of "version" = "hash", got {show(entry)}',
                            line=lines.key(("", 0), name), field=f"[{name}]")
    locked = None if entry is None else entry.get(version)
    if locked is None:
        _refuse_the_toolkits_name(scenario, lock)
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
    _check_against_the_toolkit(scenario, lock)


def _toolkit_hash(scenario: Scenario, lock: Path) -> str | None:
    """The hash the toolkit's lock publishes the scenario's (name, version) with, when `lock` is another lock."""
    if not TOOLKIT_LOCK.is_file() or lock.resolve() == TOOLKIT_LOCK.resolve():
        return None
    try:
        data, _ = read_toml(TOOLKIT_LOCK, str(TOOLKIT_LOCK), ScenarioError)
    except ScenarioError:
        return None  # the toolkit's own lock is checked where it is used; a broken one must not block another's
    entry = data.get(scenario.name)
    ours = entry.get(str(scenario.version)) if isinstance(entry, dict) else None
    return ours if isinstance(ours, str) else None


def _renamed_hash(scenario: Scenario, name: str) -> str | None:
    """The hash the scenario's file would have with ``[scenario] name`` set to `name` (None if it cannot be read)."""
    try:
        data, _ = read_toml(resolve_scenario_path(scenario.path), scenario.path, ScenarioError)
    except ScenarioError:
        return None
    table = data.get("scenario")
    if not isinstance(table, dict):
        return None
    return content_hash({**data, "scenario": {**table, "name": name}})


def _refuse_the_toolkits_name(scenario: Scenario, lock: Path) -> None:
    """Refuse an unpublished scenario under a (name, version) the toolkit publishes with other content.

    The lines that would publish it under that name in `lock` would be refused (`_check_against_the_toolkit`), so the
    message gives a name of its own and the lines that publish the file under it. Any other scenario: nothing.
    """
    ours = _toolkit_hash(scenario, lock)
    if ours is None or ours == scenario.hash:
        return
    name, version = scenario.name, str(scenario.version)
    mine = f"my-{name}"
    renamed = _renamed_hash(scenario, mine)
    lines = (f'\n    [{mine}]\n    "{version}" = "{renamed}"\n' if renamed is not None
             else f" [{mine}] and the hash this check then prints ")
    raise ScenarioError(
        scenario.path,
        f"unpublished: {name!r} version {version} is the toolkit's published scenario, with hash {ours} "
        f"({TOOLKIT_LOCK}), and this file hashes to {scenario.hash}; no other lock can publish other content under "
        f"the toolkit's name and version: give your scenario a name of its own, e.g. [scenario] name = \"{mine}\", "
        f"and to publish it, add{lines}to {lock}",
        field="[scenario] name",
    )


def _check_against_the_toolkit(scenario: Scenario, lock: Path) -> None:
    """Refuse a scenario that another lock publishes under a (name, version) the toolkit publishes with other content.

    A lock beside any file publishes what it lists: a copy of ``push.toml`` with one force changed, beside a lock
    that lists its hash as push version 2, was played and reported as the published push v2. The toolkit's names and
    versions are its own: results under them must be comparable with the toolkit's published results.
    """
    ours = _toolkit_hash(scenario, lock)
    if ours is not None and ours != scenario.hash:
        raise ScenarioError(
            scenario.path,
            f"{scenario.name!r} version {scenario.version} is the toolkit's published scenario, with hash {ours} "
            f"({TOOLKIT_LOCK}), and this file hashes to {scenario.hash}: {lock} cannot publish other content under "
            "the toolkit's name and version; give your scenario a name of its own ([scenario] name) and publish that",
            field="[scenario] name",
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
