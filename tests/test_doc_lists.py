"""The docs' lists of registered controllers and robots name every entry of `CONTROLLERS` and `ROBOTS`.

A controller or robot added to a registry and left out of a list that claims to be complete fails here, naming the
file and the missing names; a list that names something the registry no longer holds fails too.
"""

import re
from pathlib import Path

import pytest

from wbc.control.registry import CONTROLLERS
from wbc.robots.registry import ROBOTS

ROOT = Path(__file__).resolve().parent.parent
NAME = re.compile(r"`([a-z0-9][a-z0-9-]*)`")


def _section(path: str, start: str, end: str) -> str:
    """The text of `path` from the line holding `start` up to (not including) the first later line holding `end`."""
    lines = (ROOT / path).read_text(encoding="utf-8").splitlines()
    first = next((i for i, line in enumerate(lines) if start in line), None)
    assert first is not None, f"{path}: no line holds {start!r}, where the list should start; update {__file__}"
    last = next((i for i in range(first + 1, len(lines)) if end in lines[i]), len(lines))
    return "\n".join(lines[first:last])


def list_problems(path: str, what: str, text: str, registry: dict, registry_path: str,
                  others: tuple[str, ...] = (), complete: bool = False) -> list[str]:
    """What a doc list of `what` (its `text` in `path`) lacks of `registry`, and (when `complete`) names it has extra.

    Names are the backticked lowercase words of the text; `others` are backticked names that are not registry names.
    """
    named = set(NAME.findall(text))
    out = []
    missing = [name for name in registry if name not in named]
    if missing:
        out.append(f"{path}: the list of {what} does not name {', '.join(missing)} ({registry_path}); add them there")
    extra = sorted(named - set(registry) - set(others)) if complete else []
    if extra:
        out.append(f"{path}: the list of {what} names {', '.join(extra)}, which {registry_path} does not hold; remove "
                   "them or register them")
    return out


LISTS = {
    "docs/commands.md controllers": lambda: list_problems(
        "docs/commands.md", "registered controllers", _section("docs/commands.md", "Registered controllers",
                                                               "arm mode read from the file"),
        CONTROLLERS, "wbc/control/registry.py CONTROLLERS", others=tuple(ROBOTS), complete=True),
    "README.md controllers": lambda: list_problems(
        "README.md", "controllers", _section("README.md", "| Model-based controllers |", "| Your controller |"),
        CONTROLLERS, "wbc/control/registry.py CONTROLLERS"),
    "README.md robots": lambda: list_problems(
        "README.md", "robots", _section("README.md", "| Robots |", "| The arena |"), ROBOTS,
        "wbc/robots/registry.py ROBOTS"),
    "docs/guides/robots.md robots": lambda: list_problems(
        "docs/guides/robots.md", "robots", _section("docs/guides/robots.md", "| name | quadruped |", "Arm modes:"),
        ROBOTS, "wbc/robots/registry.py ROBOTS"),
}


@pytest.mark.parametrize("where", list(LISTS))
def test_the_docs_list_every_registered_controller_and_robot(where):
    problems = LISTS[where]()
    assert not problems, "\n".join(problems)


def test_a_missing_or_stale_name_is_named_with_its_file():
    registry = {"stand": None, "mpc": None, "mpc-new": None}
    problems = list_problems("docs/commands.md", "registered controllers", "`stand`, `mpc`, `mpc-old`, `a1-wx200`",
                             registry, "wbc/control/registry.py CONTROLLERS", others=("a1-wx200",), complete=True)
    assert problems == [
        "docs/commands.md: the list of registered controllers does not name mpc-new (wbc/control/registry.py "
        "CONTROLLERS); add them there",
        "docs/commands.md: the list of registered controllers names mpc-old, which wbc/control/registry.py "
        "CONTROLLERS does not hold; remove them or register them",
    ]
