"""`run_episode` refuses unusable arguments up front, naming them, before the robot or the controller is touched."""

import math

import numpy as np
import pytest

from wbc.arena import run_episode
from wbc.errors import ConfigError
from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
from wbc.scenario import CommandSchedule
from wbc.types import MotorCommand, VelocityCommand


class _Hold:
    """Holds the nominal pose at `rate_hz`."""

    def __init__(self, q, rate_hz=50.0):
        self.q, self.rate_hz, self.resets = q, rate_hz, 0

    def reset(self):
        self.resets += 1

    def act(self, state, cmd):
        return MotorCommand.hold(self.q, 40.0, 1.0)


@pytest.fixture(scope="module")
def robot():
    with MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none")) as r:
        yield r


@pytest.mark.parametrize("duration", [-1.0, 0.0, math.nan, math.inf, "1", None, True])
def test_a_duration_that_is_not_a_finite_positive_number_is_refused_naming_it(robot, duration):
    robot.reset(0)
    ctrl = _Hold(robot.desc.nominal_q)
    with pytest.raises(ConfigError, match=r"duration_s must be a finite positive number"):
        run_episode(robot, ctrl, CommandSchedule(), duration)
    assert ctrl.resets == 0 and robot.time == 0.0


def test_a_velocity_command_as_the_schedule_is_refused_with_the_constant_schedule_to_use(robot):
    robot.reset(0)
    ctrl = _Hold(robot.desc.nominal_q)
    with pytest.raises(ConfigError, match=r"schedule must be a CommandSchedule.*VelocityCommand.*"
                                          r"CommandSchedule\(vx=0.3, vy=0, yaw_rate=0\)"):
        run_episode(robot, ctrl, VelocityCommand(vx=0.3), 0.1)
    assert ctrl.resets == 0


def test_a_rate_whose_period_is_not_whole_physics_steps_is_refused(robot):
    # a 300 Hz loop over 2 ms steps advanced 4 ms a tick: the log said 1 s, the robot had run 1.2 s
    robot.reset(0)
    ctrl = _Hold(robot.desc.nominal_q, rate_hz=300.0)
    with pytest.raises(ConfigError, match=r"controller _Hold: its period 1/300 Hz .*whole number of physics "
                                          r"steps.*500 Hz and 250 Hz"):
        run_episode(robot, ctrl, CommandSchedule(), 1.0)
    assert ctrl.resets == 0 and robot.time == 0.0


def test_a_valid_episode_still_plays_with_numpy_arguments(robot):
    robot.reset(0)
    episode = run_episode(robot, _Hold(robot.desc.nominal_q, rate_hz=100.0), CommandSchedule(), np.float64(0.1))
    assert len(episode.t) == 10
    assert robot.time == pytest.approx(0.1)
