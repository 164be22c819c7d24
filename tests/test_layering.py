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
from import_graph import MODULE_FILES, PACKAGE, cycles, graph, imports, imports_of_text
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
know each other). The room ``wbc`` holds the package itself and the top-level modules of `TOP_LEVEL` only, by name: a
new package (``wbc/myctl/``) or top-level module falls into no room, and the test says where to add it."""

TOP_LEVEL = ("wbc._kernels", "wbc.config_checks", "wbc.input_files", "wbc.interrupts", "wbc.output_files",
             "wbc.physics_steps", "wbc.starting", "wbc.toml_lines")
"""The top-level modules (``wbc/*.py``) of the room ``wbc``: the small shared helpers every layer above may use."""

PEERS = ("wbc.mpc", "wbc.learned")
"""The two contenders: no module under one imports a module under the other, whatever their layers (`wbc.learned.env`
and `wbc.learned.train` sit above `wbc.mpc` in `LAYERS`). What both need lives below both (`wbc.estimation`); what
joins them lives above both (the DAgger teacher, `wbc.tools.dagger`)."""

WHERE = "LAYERS in tests/test_layering.py; docs/architecture.md, 'Rules that keep the house'"

_RANK = {prefix: rank for rank, rooms in enumerate(LAYERS) for prefix in rooms}


def _room(module: str) -> str:
    """The room of `module`: its longest prefix in `LAYERS` (the bare ``wbc`` only for itself and `TOP_LEVEL`)."""
    if module == "wbc" or module in TOP_LEVEL:
        return "wbc"
    parts = module.split(".")
    for n in range(len(parts), 1, -1):
        prefix = ".".join(parts[:n])
        if prefix in _RANK:
            return prefix
    if len(parts) == 2 and not (PACKAGE / parts[1]).is_dir():
        raise AssertionError(f"{module} (wbc/{parts[1]}.py) is in no room: add it to TOP_LEVEL in "
                             "tests/test_layering.py if it is a helper of the room wbc, or to its own layer of "
                             f"{WHERE}")
    package = ".".join(parts[:2])
    raise AssertionError(f"{package} (wbc/{parts[1]}/) is in no room of LAYERS: add its package to the layer it "
                         f"belongs to in {WHERE} (and name it in docs/architecture.md's source tree)")


def _imports(path: Path) -> list[tuple[int, str]]:
    return [(i.line, i.module) for i in imports(path) if i.module.split(".")[0] == "wbc"]


def _peer(module: str) -> str | None:
    return next((p for p in PEERS if module == p or module.startswith(p + ".")), None)


def import_problems(where: str, module: str, targets: list[tuple[int, str]]) -> list[str]:
    """The imports of `module` (in file `where`) that break a rule of the house, each with the rule it breaks.

    Args:
        where: the file, for the messages.
        module: the importing module's dotted name.
        targets: (line, imported module) pairs, the imports of ``wbc`` modules only.
    """
    here = _room(module)
    wrong = []
    for line, target in targets:
        there = _room(target)
        if there != here and _RANK[there] >= _RANK[here]:
            how = "a peer in its own layer" if _RANK[there] == _RANK[here] else "a room above it"
            wrong.append(f"{where}:{line}: {module} (room {here}) imports {target} (room {there}), {how}: imports run "
                         f"downward only ({WHERE})")
        mine, theirs = _peer(module), _peer(target)
        if mine is not None and theirs is not None and mine != theirs:
            wrong.append(f"{where}:{line}: {module} imports {target}: the peers {' and '.join(PEERS)} never import "
                         "each other (PEERS in tests/test_layering.py; docs/architecture.md, 'Rules that keep the "
                         "house'); put what both need below both, what joins them in wbc.tools")
    return wrong


MODULES = MODULE_FILES


def test_every_module_is_in_a_room():
    for path in MODULES:
        _room(_module_name(path))


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE.parent)))
def test_imports_run_downward_only(path):
    wrong = import_problems(str(path.relative_to(PACKAGE.parent)), _module_name(path), _imports(path))
    assert not wrong, "\n".join(wrong)


def test_a_new_package_or_top_level_module_is_in_no_room_until_added():
    with pytest.raises(AssertionError, match=r"wbc\.myctl \(wbc/myctl/\) is in no room of LAYERS: add its package "
                       r"to the layer it belongs to in LAYERS in tests/test_layering.py; docs/architecture.md"):
        _room("wbc.myctl.controller")
    with pytest.raises(AssertionError, match=r"wbc\.helpers \(wbc/helpers\.py\) is in no room: add it to TOP_LEVEL"):
        _room("wbc.helpers")
    assert _room("wbc.physics_steps") == "wbc" and _room("wbc") == "wbc" and _room("wbc.mpc.gait") == "wbc.mpc"


def test_a_violation_names_the_rule_and_where_it_is_written():
    """A synthetic module text, its imports read as the test reads every module's."""
    text = "import wbc.arena.compare\nfrom wbc.mpc import controller\n\n\ndef f():\n    import wbc.learned.policy\n"
    found = [(i.line, i.module) for i in imports_of_text(text, "wbc.learned.env")]
    assert import_problems("wbc/learned/env/synthetic.py", "wbc.learned.env.synthetic", found) == [
        "wbc/learned/env/synthetic.py:1: wbc.learned.env.synthetic (room wbc.learned.env) imports wbc.arena.compare "
        f"(room wbc.arena), a room above it: imports run downward only ({WHERE})",
        "wbc/learned/env/synthetic.py:2: wbc.learned.env.synthetic imports wbc.mpc: the peers wbc.mpc and "
        "wbc.learned never import each other (PEERS in tests/test_layering.py; docs/architecture.md, 'Rules that "
        "keep the house'); put what both need below both, what joins them in wbc.tools",
    ]
    assert import_problems("wbc/mpc/x.py", "wbc.mpc.x", [(3, "wbc.learned.policy")]) == [
        f"wbc/mpc/x.py:3: wbc.mpc.x (room wbc.mpc) imports wbc.learned.policy (room wbc.learned.policy), a peer in "
        f"its own layer: imports run downward only ({WHERE})",
        "wbc/mpc/x.py:3: wbc.mpc.x imports wbc.learned.policy: the peers wbc.mpc and wbc.learned never import each "
        "other (PEERS in tests/test_layering.py; docs/architecture.md, 'Rules that keep the house'); put what both "
        "need below both, what joins them in wbc.tools",
    ]


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
