"""The house's import rules: packages import only the rooms below them, and the light rooms stay light.

Static: every import statement of every module, function-local ones included (a local import that hides an upward
arrow is still that arrow), is checked against the layer table below. Dynamic: importing a room in a fresh
interpreter pulls in only what the rules promise (no MuJoCo behind the scenario files, no torch behind the shipped
policies).
"""

import subprocess
import sys
from pathlib import Path

import pytest
from import_graph import MODULE_FILES, PACKAGE, cycles, graph, imports
from import_graph import module_name as _module_name

LAYERS = (
    ("wbc.errors",),
    ("wbc.types",),
    ("wbc",),
    ("wbc.optional", "wbc.provenance"),
    ("wbc.robots",),
    ("wbc.scenario",),
    ("wbc.hardware",),
    ("wbc.hardware.mujoco", "wbc.estimation"),
    ("wbc.hardware.emulators",),
    ("wbc.mpc", "wbc.learned", "wbc.learned.policy"),
    ("wbc.learned.env",),
    ("wbc.learned.train",),
    ("wbc.control",),
    ("wbc.arena",),
    ("wbc.viz",),
    ("wbc.tools",),
    ("wbc.cli",),
    ("wbc.command",),
    ("wbc.__main__", "wbc.cli.__main__"),
)
"""Rooms from the bottom up. A module belongs to the room of its longest prefix here; it may import its own room and
any room of a lower layer, never a room of its own layer or above (peers such as `wbc.mpc` and `wbc.learned` do not
know each other)."""

_RANK = {prefix: rank for rank, rooms in enumerate(LAYERS) for prefix in rooms}


def _room(module: str) -> str:
    parts = module.split(".")
    for n in range(len(parts), 0, -1):
        prefix = ".".join(parts[:n])
        if prefix in _RANK:
            return prefix
    raise AssertionError(f"{module} is in no room of LAYERS; add its package there")


def _imports(path: Path) -> list[tuple[int, str]]:
    return [(i.line, i.module) for i in imports(path) if i.module.split(".")[0] == "wbc"]


MODULES = MODULE_FILES


def test_every_module_is_in_a_room():
    for path in MODULES:
        _room(_module_name(path))


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE.parent)))
def test_imports_run_downward_only(path):
    here = _room(_module_name(path))
    wrong = []
    for line, target in _imports(path):
        there = _room(target)
        if there != here and _RANK[there] >= _RANK[here]:
            wrong.append(f"{path.relative_to(PACKAGE.parent)}:{line}: {here} imports {target} ({there})")
    assert not wrong, "\n".join(wrong)


def _loaded_after(code: str) -> set[str]:
    probe = code + "\nimport sys\nprint('\\n'.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True,
                         cwd=PACKAGE.parent).stdout
    return set(out.split())


def test_core_types_and_errors_import_nothing_else_of_wbc():
    loaded = {m for m in _loaded_after("import wbc.types, wbc.errors") if m.split(".")[0] == "wbc"}
    assert loaded == {"wbc", "wbc._kernels", "wbc.types", "wbc.errors"}  # _kernels: numpy's, pinned before it loads


def test_scenario_files_load_without_any_backend_or_mujoco():
    loaded = _loaded_after("import wbc.scenario; wbc.scenario.load_scenario('scenarios/push.toml')")
    assert "mujoco" not in loaded
    assert not {m for m in loaded if m.startswith("wbc.hardware")}


def test_the_robot_interface_imports_without_mujoco():
    assert "mujoco" not in _loaded_after("import wbc.hardware")


def test_shipped_policies_run_without_torch():
    code = """
import sys
sys.modules["torch"] = None  # an import of torch now raises ImportError
from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
from wbc.learned.policy import LearnedController
from wbc.types import VelocityCommand
robot = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated"))
robot.connect()
robot.reset(seed=0)
ctrl = LearnedController(robot.desc)
ctrl.reset()
robot.write(ctrl.act(robot.read(), VelocityCommand(vx=0.3)))
import wbc.learned.env
"""
    assert "wbc.learned.policy.controller" in _loaded_after(code)


def test_the_loop_and_the_controller_protocol_load_no_simulator_and_no_controller():
    loaded = _loaded_after("import wbc.arena.runner, wbc.control.protocol, wbc.hardware.capabilities")
    heavy = {m for m in loaded if m.split(".")[0] in ("mujoco", "pinocchio", "placo", "casadi", "torch")
             or m.startswith(("wbc.mpc", "wbc.learned", "wbc.hardware.mujoco", "wbc.control.registry"))}
    assert not heavy, sorted(heavy)


REFEREE = "wbc.arena"
CONTENDERS = ("wbc.mpc", "wbc.learned")


@pytest.mark.parametrize("path", [p for p in MODULES if _module_name(p).startswith(REFEREE + ".")
                                  or _module_name(p) == REFEREE], ids=lambda p: str(p.relative_to(PACKAGE.parent)))
def test_the_referee_imports_no_contender(path):
    """The arena judges the controllers; it must not depend on one of them. What both need (kinematics, the base
    estimate) lives below both, in `wbc.estimation`; the arena reaches controllers only by name, through the
    registry of `wbc.control`."""
    wrong = [f"{path.relative_to(PACKAGE.parent)}:{line}: imports {target}" for line, target in _imports(path)
             if target == CONTENDERS or target.startswith(tuple(c + "." for c in CONTENDERS)) or target in CONTENDERS]
    assert not wrong, "\n".join(wrong)


def test_the_estimation_package_loads_no_contender_and_no_simulator():
    loaded = _loaded_after("import wbc.estimation.base_estimate, wbc.estimation.estimated_robot")
    assert not {m for m in loaded if m.startswith(("wbc.mpc", "wbc.learned", "wbc.arena", "wbc.hardware.mujoco"))}


def test_no_module_is_in_an_import_cycle():
    """Modules that import each other (even for type hints only) cannot be understood, tested or moved apart."""
    assert cycles(graph()) == []


@pytest.mark.parametrize("path", [p for p in MODULES if not _module_name(p).startswith(("wbc.cli", "wbc.command"))],
                         ids=lambda p: str(p.relative_to(PACKAGE.parent)))
def test_the_cli_is_on_top_and_nothing_imports_it(path):
    """The `wbc` command parses and prints; what its commands do lives in `wbc.tools` and below, which never reach back
    into the command (its parser, printers or terminal keys). Only the console script's entry (`wbc.command`), above
    it, loads it."""
    wrong = [f"{path.relative_to(PACKAGE.parent)}:{line}: imports {target}" for line, target in _imports(path)
             if target == "wbc.cli" or target.startswith("wbc.cli.")]
    assert not wrong, "\n".join(wrong)
