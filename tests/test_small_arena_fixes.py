"""Edges of the arena's CLI: the robots a learned controller claims, name suggestions, one-controller reports."""

import pytest

from wbc.cli.main import main
from wbc.control import registry
from wbc.control.registry import CONTROLLERS, get_controller, list_controllers
from wbc.errors import UnknownNameError
from wbc.learned.policy import shipped
from wbc.learned.policy.controller import LearnedController
from wbc.robots.registry import ROBOTS, get_robot

LEARNED = [name for name in CONTROLLERS if name.startswith("learned")]

TINY = """
[scenario]
name = "tiny"
version = 1
description = "a short push test"
robot = "a1-wx200"
duration_s = 0.5

[terrain]
kind = "flat"

[commands]
ramp_s = 0.1
[[commands.options]]
vx = 0.0

[pushes]
first_s = [0.2, 0.3]
interval_s = [1.0, 1.5]
duration_s = 0.05
offset_m = 0.12

[[bands]]
name = "soft"
push_force_n = [50.0, 100.0]
"""


# -- 1. the robots a learned controller lists are those its weights ship for ----------------------------------------
def _robots_with_files(name: str) -> tuple[str, ...]:
    """The robots with a ``<robot>-<arm mode>[-crouched].npz`` in the weights directory, listed independently."""
    spec = CONTROLLERS[name]
    suffix = "-crouched" if name.endswith("-crouched") else ""
    return tuple(r for r in ROBOTS if (shipped.WEIGHTS_DIR / f"{r}-{spec.arm_mode}{suffix}.npz").is_file())


@pytest.mark.parametrize("name", LEARNED)
def test_a_learned_controller_lists_the_robots_its_weights_ship_for(name):
    assert LEARNED and all(CONTROLLERS[n].make is LearnedController or CONTROLLERS[n].make.func is LearnedController
                           for n in LEARNED)
    rows = {r.name: r for r in list_controllers()}
    assert rows[name].robots == _robots_with_files(name)
    assert get_controller(name).robots == _robots_with_files(name)


def test_a_robot_without_weights_is_not_listed(monkeypatch, tmp_path):
    for stem in ("go1-arm-locked", "a1-wx200-none-crouched"):
        (tmp_path / f"{stem}.npz").write_bytes(b"")
    monkeypatch.setattr(shipped, "WEIGHTS_DIR", tmp_path)
    assert registry._robots_with_weights("locked") == ("go1-arm",)
    assert registry._robots_with_weights("none", "crouched") == ("a1-wx200",)
    assert registry._robots_with_weights("actuated") == ()


def test_the_listed_robots_can_be_built():
    for name in LEARNED:
        spec = get_controller(name)
        for robot in spec.robots:
            assert spec.make(get_robot(robot, spec.arm_mode)) is not None


def test_the_controllers_command_prints_the_robots(capsys):
    assert main(["controllers"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.split()[:1] == ["learned-locked"])
    assert "any robot" not in line and all(r in line for r in _robots_with_files("learned-locked"))


# -- 2. an unknown name suggests the closest valid one --------------------------------------------------------------
def test_a_mistyped_controller_suggests_the_closest_name():
    with pytest.raises(UnknownNameError, match="did you mean 'mpc'") as err:
        get_controller("mcp")
    assert err.value.suggestion == "mpc"
    assert "valid controllers: " in str(err.value) and "stand-noarm" in str(err.value)


def test_a_name_close_to_nothing_gets_no_suggestion():
    with pytest.raises(UnknownNameError) as err:
        get_controller("zzzzzzzz")
    assert "did you mean" not in str(err.value) and err.value.suggestion is None
    assert "valid controllers: " in str(err.value)


def test_every_kind_of_unknown_name_suggests(capsys):
    with pytest.raises(UnknownNameError, match="did you mean 'go1-arm'"):
        get_robot("go1arm")
    with pytest.raises(UnknownNameError, match="did you mean 'locked'"):
        get_robot("go1-arm", "lockd")
    assert main(["run", "learnd", "--scenario", "scenarios/push.toml"]) == 2
    assert "did you mean 'learned'?" in capsys.readouterr().err


# -- 3. no empty paired-differences block with one controller ------------------------------------------------------
def _play(tmp_path, capsys, *controllers):
    scenario = tmp_path / "tiny.toml"
    scenario.write_text(TINY)
    out = tmp_path / "-".join(controllers)
    command = "compare" if len(controllers) > 1 else "run"
    assert main([command, *controllers, "--scenario", str(scenario), "--trials", "1", "--seeds", "1", "--quiet",
                 "--workers", "1", "--out", str(out)]) == 0
    return capsys.readouterr().out, (out / "report.md").read_text()


def test_one_controller_prints_and_reports_no_paired_differences(tmp_path, capsys):
    text, report = _play(tmp_path, capsys, "stand")
    assert "band soft" in text and "stand" in report
    assert "paired differences" not in text.lower() and "fewer than two" not in text
    assert "paired differences" not in report.lower() and "fewer than two" not in report


def test_two_controllers_print_and_report_paired_differences(tmp_path, capsys):
    text, report = _play(tmp_path, capsys, "stand", "stand-noarm")
    assert "paired differences (B - A, 95% CI)" in text
    assert "## Paired differences (B - A, 95% CI)" in report
