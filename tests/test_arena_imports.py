"""The arena's finer import rules, beside the house-wide layer table of tests/test_layering.py.

Every import statement counts, function-local and ``TYPE_CHECKING`` ones included (a local import that hides an
upward arrow is still that arrow), and so does ``importlib.import_module`` with a literal name.
"""

from __future__ import annotations

from pathlib import Path

from import_graph import MODULE_FILES, imports
from import_graph import module_name as _module_name

ABOVE_ARENA = ("wbc.arena", "wbc.viz", "wbc.tools", "wbc.cli")
"""The arena and the packages allowed to import it (the viewer only in the modules that play or replay trials)."""


def _imports(path: Path) -> set[str]:
    """Every module `path` imports (``from a import b`` counts as both ``a`` and ``a.b``)."""
    return {m for i in imports(path) for m in i.modules()}


def _within(name: str, package: str) -> bool:
    return name == package or name.startswith(package + ".")


MODULES = {_module_name(p): _imports(p) for p in MODULE_FILES}


def _offenders(modules: dict[str, set[str]], forbidden: tuple[str, ...]) -> dict[str, list[str]]:
    found = {m: sorted(i for i in imports if any(_within(i, f) for f in forbidden)) for m, imports in modules.items()}
    return {m: names for m, names in found.items() if names}


def test_the_source_tree_is_found():
    assert {"wbc.arena.runner", "wbc.arena.sim_trial", "wbc.arena.trial_record", "wbc.viz.replay"} <= set(MODULES)
    assert "wbc.arena.episode" in MODULES["wbc.arena.runner"] and "wbc.arena.runner" in MODULES["wbc.arena.sim_trial"]


def test_the_viewer_imports_the_arena_only_where_it_plays_or_replays_trials():
    viz = {m: i for m, i in MODULES.items() if _within(m, "wbc.viz")}
    # ab plays both runs of an A / B trial; signals reads a played or stored episode into the page's plots
    allowed = {"wbc.viz.view", "wbc.viz.replay", "wbc.viz.live", "wbc.viz.ab", "wbc.viz.signals"}
    # the palette the page shares with the arena's plots (so that the two cannot drift) is a leaf that imports
    # nothing of wbc: any viewer module may take it
    shared = "wbc.arena.plot_style"
    assert not _offenders({shared: MODULES[shared]}, ("wbc",))
    offenders = {m: [n for n in names if not _within(n, shared)]
                 for m, names in _offenders(viz, ("wbc.arena",)).items()}
    assert {m for m, names in offenders.items() if names} <= allowed


def test_the_runner_knows_no_simulator_no_registry_and_no_trial_setup():
    # the one loop runs on any Robot: the simulator and the registry are the simulated trial's business
    forbidden = ("mujoco", "wbc.hardware.mujoco", "wbc.arena.sim_trial", "wbc.control.registry", "wbc.learned",
                 "wbc.mpc")
    assert _offenders({"wbc.arena.runner": MODULES["wbc.arena.runner"]}, forbidden) == {}
