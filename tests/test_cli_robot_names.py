"""``--robot`` across the commands: each robot by either of its names, and one refusal of any other name.

Each command's tool is replaced by a stub that records the robot it was handed and stops the command there: what is
checked is the name that reaches the tool, not the tool's work (no emulator, no simulator, no socket).
"""

from __future__ import annotations

import argparse
import importlib
import pickle

import pytest

from wbc.cli import main
from wbc.cli.parser import build_parser
from wbc.cli.robot_names import ROBOT_NAMES_HELP, robot_name, wire_name
from wbc.errors import UnknownNameError

NAMES = {"a1": ("a1-wx200", "a1"), "a1-wx200": ("a1-wx200", "a1"), "go1": ("go1-arm", "go1"),
         "go1-arm": ("go1-arm", "go1")}
"""Each accepted name -> (the registry's name, the legs' wire) it stands for."""

CLI = importlib.import_module("wbc.cli.main")  # the module (the package's name `main` is the function)

REFUSAL = "valid robots: a1-wx200 (or a1), go1-arm (or go1)"


class Reached(Exception):
    """Raised by a stub tool: the command got as far as the tool, with `robot`."""

    def __init__(self, robot: object) -> None:
        super().__init__(robot)
        self.robot = robot


def _stub(monkeypatch: pytest.MonkeyPatch, name: str, robot_of) -> None:
    """Replace `wbc.cli.main`'s `name` by a stub that raises `Reached` with what `robot_of` reads from its call."""
    def reached(*args: object, **kwargs: object) -> None:
        raise Reached(robot_of(args, kwargs))

    monkeypatch.setattr(CLI, name, reached)


SCENARIO = "scenarios/push.toml"
COMMANDS = {
    # command line (ROBOT is the name given), the tool stubbed, what it is handed, which name it must get
    "analyze tail": (["analyze", "tail", "--robot", "ROBOT"], "analyze_tail", lambda a, k: a[0].name, "registry"),
    "analyze posture": (["analyze", "posture", "stand", "--robot", "ROBOT"], "posture_study",
                        lambda a, k: k["robot"], "registry"),
    "bench sim": (["bench", "sim", "--robot", "ROBOT"], "bench_sim", lambda a, k: a[0], "registry"),
    "bench mpc": (["bench", "mpc", "--robot", "ROBOT"], "bench_mpc", lambda a, k: a[0], "registry"),
    "bench arm": (["bench", "arm", "--robot", "ROBOT"], "bench_arm", lambda a, k: a[0], "registry"),
    "bench hw": (["bench", "hw", "--robot", "ROBOT"], "bench_hw", lambda a, k: a[0], "wire"),
    "bench latency": (["bench", "latency", "--robot", "ROBOT", "--controllers", "stand"], "bench_latency",
                      lambda a, k: k["wire_robot"], "wire"),
    "hw emulate": (["hw", "emulate", "--robot", "ROBOT", "--arm", "locked"], "emulate", lambda a, k: a[0].robot,
                   "wire"),
    "hw check": (["hw", "check", "--robot", "ROBOT", "--target", "127.0.0.1:9"], "check_hardware",
                 lambda a, k: a[0].robot, "registry"),
    "hw run": (["hw", "run", "stand", "--robot", "ROBOT", "--scenario", SCENARIO, "--trial", "0", "--target",
                "127.0.0.1:9"], "run_hardware_trial", lambda a, k: a[0].robot, "registry"),
    # the checks run in a worker process (`_check_apart`), which is handed the robots as `check_controller` is
    "check-controller": (["check-controller", "stand", "--robot", "ROBOT"], "_check_apart",
                         lambda a, k: a[1].robots, "registries"),
}


def _argv(command: str, robot: str) -> list[str]:
    return [robot if word == "ROBOT" else word for word in COMMANDS[command][0]]


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("command", COMMANDS)
def test_every_robot_option_takes_both_names_of_each_robot(command: str, name: str,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    _, tool, robot_of, expected = COMMANDS[command]
    _stub(monkeypatch, tool, robot_of)
    with pytest.raises(Reached) as reached:
        main(_argv(command, name))
    registry, wire = NAMES[name]
    assert reached.value.robot == {"registry": registry, "wire": wire, "registries": (registry,)}[expected]


@pytest.mark.parametrize(("given", "hint"), [("go2", "; did you mean 'go1'?"), ("a1-wx250", "; did you mean "
                                                                                            "'a1-wx200'?"),
                                             ("b1", "")])
@pytest.mark.parametrize("command", COMMANDS)
def test_every_robot_option_refuses_an_unknown_name_in_the_same_words(command: str, given: str, hint: str,
                                                                      monkeypatch: pytest.MonkeyPatch,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    _, tool, robot_of, _ = COMMANDS[command]
    _stub(monkeypatch, tool, robot_of)  # reached only if the name were taken
    assert main(_argv(command, given)) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"wbc: error: unknown robot '{given}'{hint}; {REFUSAL}\n"), err


def test_the_refusal_suggests_an_alias_and_lists_each_robot_with_its_legs_name() -> None:
    with pytest.raises(UnknownNameError) as refused:
        robot_name("go2")
    assert refused.value.suggestion == "go1" and refused.value.valid == ("a1-wx200", "go1-arm")
    assert refused.value.aliases == {"a1": "a1-wx200", "go1": "go1-arm"}
    assert str(refused.value) == f"unknown robot 'go2'; did you mean 'go1'?; {REFUSAL}"
    again = pickle.loads(pickle.dumps(refused.value))  # as a worker process hands it back
    assert again.aliases == refused.value.aliases and str(again) == str(refused.value)
    assert [wire_name(n) for n in NAMES] == [wire for _, wire in NAMES.values()]


def test_every_robot_option_says_the_same_names_in_its_help() -> None:
    def robot_options(parser: argparse.ArgumentParser, path: str) -> list[tuple[str, str]]:
        found = []
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    found += robot_options(sub, f"{path} {name}".strip())
            elif "--robot" in action.option_strings:
                found.append((path, action.help or ""))
        return found

    helps = robot_options(build_parser(), "")
    assert {path for path, _ in helps} == set(COMMANDS)  # every --robot is tested above
    for path, text in helps:
        assert f"one of: {ROBOT_NAMES_HELP}" in text and ROBOT_NAMES_HELP == "a1-wx200 (or a1), go1-arm (or go1)", path


def test_emulate_reads_the_legs_name_as_the_bare_quadruped_and_the_arms_as_the_robot_with_it(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    _stub(monkeypatch, "emulate", lambda a, k: (a[0].robot, a[0].arm_mode))
    for name, wire in (("a1", "a1"), ("go1", "go1")):
        with pytest.raises(Reached) as reached:
            main(["hw", "emulate", "--robot", name])
        assert reached.value.robot == (wire, "none")
    assert main(["hw", "emulate", "--robot", "a1-wx200"]) == 2
    assert "--robot a1-wx200 names the robot with its arm: add --arm locked" in capsys.readouterr().err
