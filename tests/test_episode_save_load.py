"""`Episode.save` and `Episode.load` take the same path, and save writes nothing load would refuse."""

import dataclasses
import math

import numpy as np
import pytest

from wbc.arena import Episode, run_episode
from wbc.errors import EpisodeError, EpisodeFileError
from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
from wbc.scenario import CommandSchedule
from wbc.types import MotorCommand


class _Hold:
    rate_hz = 50.0

    def __init__(self, q):
        self.q = q

    def reset(self):
        pass

    def act(self, state, cmd):
        return MotorCommand.hold(self.q, 40.0, 1.0)


@pytest.fixture(scope="module")
def episode():
    with MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none")) as robot:
        return run_episode(robot, _Hold(robot.desc.nominal_q), CommandSchedule(), 0.1)


@pytest.mark.parametrize("name", ["ep", "ep.npz", "ep.v2"])
def test_load_takes_the_path_save_was_given(tmp_path, episode, name):
    path = str(tmp_path / name)
    episode.save(path)
    np.testing.assert_array_equal(Episode.load(path).qpos, episode.qpos)
    np.testing.assert_array_equal(Episode.load(tmp_path / name).t, episode.t)  # a Path too


def test_a_missing_file_is_still_reported_as_missing(tmp_path):
    with pytest.raises(EpisodeFileError, match="ep"):
        Episode.load(str(tmp_path / "ep"))


def test_a_damaged_file_is_still_detected_through_the_short_path(tmp_path, episode):
    episode.save(str(tmp_path / "ep"))
    (tmp_path / "ep.npz").write_bytes((tmp_path / "ep.npz").read_bytes()[:200])
    with pytest.raises(EpisodeFileError):
        Episode.load(str(tmp_path / "ep"))


@pytest.mark.parametrize(("field", "value"), [("duration_s", 700.0), ("control_dt", 2.0), ("duration_s", math.nan),
                                              ("control_dt", 0.0)])
def test_save_refuses_what_load_would_refuse_and_writes_nothing(tmp_path, episode, field, value):
    bad = dataclasses.replace(episode, **{field: value})
    with pytest.raises(EpisodeError, match=rf"Episode.save: {field} .* outside"):
        bad.save(str(tmp_path / "ep"))
    assert not list(tmp_path.iterdir())
