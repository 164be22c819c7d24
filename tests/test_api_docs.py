"""The guides and docstrings say what the library does: checked against the behaviour they describe."""

import pathlib
import re

import numpy as np
import pytest

import wbc.hardware
from wbc.arena import Episode, run_episode
from wbc.arena.sim_trial import run_trial
from wbc.errors import CommandError
from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
from wbc.scenario import CommandSchedule
from wbc.types import MotorCommand

DOCS = pathlib.Path(__file__).resolve().parent.parent / "docs"


def _text(path):
    return re.sub(r"\s+", " ", (DOCS / path).read_text())


def test_the_robots_guide_says_write_refuses_a_trusted_commands_negative_gains():
    with MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none")) as robot:
        rows = np.zeros((5, 12))
        rows[0], rows[2], rows[3] = robot.desc.nominal_q, -50.0, -1.0
        with pytest.raises(CommandError, match="negative gain"):
            robot.write(MotorCommand.trusted(rows))
    guide = _text("guides/robots.md")
    assert "with negative gains is not refused by `write` but clamped" not in guide
    assert "with negative gains is refused by `write` too" in guide


def test_the_robots_guide_says_check_robot_takes_a_factory():
    assert "check_robot(lambda: MujocoRobot(" in _text("guides/robots.md")


def test_episode_arm_q_is_zeros_of_three_columns_without_an_actuated_arm_as_documented():
    class Hold:
        rate_hz = 50.0

        def reset(self):
            pass

        def act(self, state, cmd):
            return MotorCommand.hold(state.q, 40.0, 1.0)

    for arm_mode in ("none", "locked"):
        with MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode=arm_mode)) as robot:
            episode = run_episode(robot, Hold(), CommandSchedule(), 0.06)
        assert episode.arm_q.shape == (3, 3) and not episode.arm_q.any()
    doc = re.sub(r"\s+", " ", Episode.__doc__)
    assert "zero columns" not in doc
    assert "arm_q: measured arm joint positions, shape (k, 3) [rad]; zeros where the arm is not actuated" in doc


def test_the_reference_index_names_every_export_of_wbc_hardware():
    index = _text("reference/index.md")
    for name in wbc.hardware.__all__:
        assert f"`{name}`" in index, name


def test_run_trial_and_the_arena_guide_say_it_is_not_thread_safe():
    assert "Not thread-safe" in run_trial.__doc__
    guide = _text("guides/arena.md")
    assert "`run_trial` shares that robot, one per (robot, arm mode, terrain) in the process: it is not thread-safe" \
        in guide
