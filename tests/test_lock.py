"""The lock matches pyproject.toml: `make test` and `make demo` install exactly requirements/wbc.lock and no-deps.lock.

pyproject.toml keeps compatible ranges for people who install `wbc` as a library; the lock, resolved from those ranges
and requirements/lock.in by uv (`make lock`), pins one version of every package with its hashes; no-deps.lock pins the
packages installed without their dependencies (no-deps.in). Three ways the lock can fall out of step, each a failure
here: a requirement it does not satisfy (a range moved, a dependency was added), a package it holds for a requirement
that is gone (a dependency was removed), and a package pinned without hashes (a hand edit).

The environment the tests run in is held to the lock too: a package that changes results (`wbc.provenance.
RESULT_PACKAGES`) installed at another version than its pin fails here, naming each, since results then do not
reproduce to the bit; the golden tests compare only the trials they play and can pass all the same. Outside the locked
environment (a venv of one's own), this is the failure to read: `make test` runs the suite in the locked one.
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Callable
from importlib import metadata
from pathlib import Path

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import InvalidVersion, Version

from wbc.provenance import RESULT_PACKAGES

ROOT = Path(__file__).resolve().parent.parent
LOCK = ROOT / "requirements" / "wbc.lock"
LOCK_IN = ROOT / "requirements" / "lock.in"
NO_DEPS = ROOT / "requirements" / "no-deps.lock"
NO_DEPS_IN = ROOT / "requirements" / "no-deps.in"
MAKEFILE = ROOT / "Makefile"
PIN = re.compile(r"^([A-Za-z0-9][A-Za-z0-9._-]*)==([^\s\\]+)")


def _lock(path: Path = LOCK) -> tuple[dict[str, str], dict[str, set[str]], dict[str, int]]:
    """A lock's pins (name -> version), what each pin is there for (its ``# via`` lines) and its hash count."""
    pins: dict[str, str] = {}
    via: dict[str, set[str]] = {}
    hashes: dict[str, int] = {}
    current = None
    in_via = False
    for line in path.read_text(encoding="utf-8").splitlines():
        match = PIN.match(line)
        if match:
            current = canonicalize_name(match.group(1))
            pins[current], via[current], hashes[current] = match.group(2), set(), 0
            in_via = False
        elif current is None:
            continue
        elif "--hash=sha256:" in line:
            hashes[current] += 1
        elif line.strip().startswith("# via"):
            rest = line.strip()[len("# via"):].strip()
            if rest:
                via[current].add(rest)
            in_via = True
        elif in_via and line.strip().startswith("#   "):
            via[current].add(line.strip()[1:].strip())
        else:
            in_via = False
    return pins, via, hashes


def _locked_extras() -> tuple[str, ...]:
    """The extras the Makefile's install and `make lock` name (``dev,train,onnx``)."""
    match = re.search(r"LOCKED_EXTRAS\s*:?=\s*(\S+)", MAKEFILE.read_text(encoding="utf-8"))
    assert match, "Makefile: LOCKED_EXTRAS is not set"
    return tuple(match.group(1).split(","))


def _in_file(path: Path) -> list[tuple[Requirement, str]]:
    out = []
    for line in path.read_text(encoding="utf-8").splitlines():
        text = line.split("#", 1)[0].strip()
        if text:
            out.append((Requirement(text), f"requirements/{path.name}"))
    return out


def _requirements() -> list[tuple[Requirement, str]]:
    """Every requirement wbc.lock must satisfy, with where it comes from."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    out = [(Requirement(r), "pyproject.toml [project] dependencies") for r in project["dependencies"]]
    for extra in _locked_extras():
        assert extra in project["optional-dependencies"], f"Makefile LOCKED_EXTRAS names an unknown extra {extra!r}"
        out += [(Requirement(r), f"pyproject.toml extra {extra!r}") for r in project["optional-dependencies"][extra]]
    return out + _in_file(LOCK_IN)


def _unsatisfied(requirements: list[tuple[Requirement, str]], pins: dict[str, str]) -> list[str]:
    problems = []
    for req, source in requirements:
        if req.marker is not None and not req.marker.evaluate({"extra": ""}):
            continue
        name = canonicalize_name(req.name)
        if name not in pins:
            problems.append(f"{req} ({source}) is not locked")
        elif not req.specifier.contains(pins[name], prereleases=True):
            problems.append(f"{req} ({source}): the lock pins {name}=={pins[name]}")
    return problems


def test_every_requirement_is_satisfied_by_the_lock():
    pins, _, _ = _lock()
    problems = _unsatisfied(_requirements(), pins)
    no_deps, _, _ = _lock(NO_DEPS)
    problems += _unsatisfied(_in_file(NO_DEPS_IN), no_deps)
    assert set(no_deps) == {canonicalize_name(r.name) for r, _ in _in_file(NO_DEPS_IN)}, \
        "requirements/no-deps.lock pins something no-deps.in does not name"
    # the hardware extra, which users install by hand, is covered by the two together
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    hardware = [(Requirement(r), "pyproject.toml extra 'hardware'")
                for r in project["optional-dependencies"]["hardware"]]
    problems += _unsatisfied(hardware, {**pins, **no_deps})
    assert not problems, "the lock no longer matches its inputs; run `make lock`:\n  " + "\n  ".join(problems)


def test_the_lock_holds_nothing_for_a_requirement_that_is_gone():
    _, via, _ = _lock()
    direct = {canonicalize_name(req.name) for req, source in _requirements() if source.startswith("pyproject")}
    pinned_in = {canonicalize_name(req.name) for req, _ in _in_file(LOCK_IN)}
    stale = [name for name, why in via.items()
             if (any(w.startswith("wbc") and "pyproject.toml" in w for w in why) and name not in direct)
             or ("-r requirements/lock.in" in why and name not in pinned_in)]
    assert not stale, f"requirements/wbc.lock pins {stale} for requirements that are gone; run `make lock`"
    orphans = [name for name, why in via.items() if not why and name not in direct | pinned_in]
    assert not orphans, f"requirements/wbc.lock pins {orphans} with no reason (# via); run `make lock`"


def test_every_pin_carries_hashes():
    pins, _, hashes = _lock()
    assert len(pins) > 50  # the whole tree, not just the direct requirements
    no_deps, _, no_deps_hashes = _lock(NO_DEPS)
    unhashed = [name for name in pins if hashes[name] == 0] + [n for n in no_deps if no_deps_hashes[n] == 0]
    assert not unhashed, f"requirements/wbc.lock pins {unhashed} without a hash: the lock is written by `make lock`"


def _installed_differences(pins: dict[str, str], version: Callable[[str], str] = metadata.version) -> list[str]:
    """The packages that change results (`wbc.provenance.RESULT_PACKAGES`) installed at another version than pinned.

    A package not installed is not compared: nothing played here used it (a run that needs it cannot start).
    """
    out = []
    for name in RESULT_PACKAGES:
        try:
            installed = version(name)
        except metadata.PackageNotFoundError:
            continue
        locked = pins[canonicalize_name(name)]
        try:
            same = Version(installed) == Version(locked)
        except InvalidVersion:
            same = installed == locked
        if not same:
            out.append(f"{name} {installed} (locked {locked})")
    return out


def _not_locked_message(differences: list[str]) -> str:
    return ("the installed versions of packages that change results are not requirements/wbc.lock's: "
            + "; ".join(differences) + ". Results will not reproduce to the bit: those played here (the golden "
            "tests' rows, a run's trials) can differ in their last bits from the locked environment's, in which "
            "the goldens were recorded and results are published, and the golden tests compare only the few "
            "trials they play, so they can pass all the same. Run the tests in the locked environment: `make test` "
            "installs requirements/wbc.lock into .venv and runs them there.")


def test_every_package_that_changes_results_is_locked():
    pins, _, _ = _lock()
    missing = [name for name in RESULT_PACKAGES if canonicalize_name(name) not in pins]
    assert not missing, f"requirements/wbc.lock pins no version of {missing}, which change results"


def test_the_installed_packages_that_change_results_are_the_locked_versions():
    differences = _installed_differences(_lock()[0])
    assert not differences, _not_locked_message(differences)


def test_a_version_other_than_the_lock_is_named_with_why_it_matters():
    pins, _, _ = _lock()

    def faked(name: str) -> str:  # numpy's metadata edited, torch not installed
        if name == "torch":
            raise metadata.PackageNotFoundError(name)
        return "9.9.9" if name == "numpy" else pins[canonicalize_name(name)]
    differences = _installed_differences(pins, faked)
    assert differences == [f"numpy 9.9.9 (locked {pins['numpy']})"]
    message = _not_locked_message(differences)
    assert "will not reproduce to the bit" in message and "`make test`" in message
