"""`MujocoRobot`'s documented edges: which readings lag the joints, what `advance`, `reset`, `apply_push` and a
closed robot refuse."""

import math

import mujoco
import numpy as np
import pytest

from wbc import MotorCommand
from wbc.errors import ConfigError, RobotNotConnectedError
from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
from wbc.hardware.mujoco.physics import foot_touch_adr, sensor_slices
from wbc.scenario import DomainParams, Push


def _forward(robot, data):
    """MuJoCo's actuator forces and sensors for a copy of `data`, computed as mj_step's forward pass does."""
    copy = mujoco.MjData(robot.model)
    mujoco.mj_copyData(copy, robot.model, data)
    mujoco.mj_forward(robot.model, copy)
    return copy


@pytest.mark.parametrize("sensing_delay", [0.0, 0.004])
def test_imu_foot_forces_and_torque_are_one_physics_step_older_than_the_joints(sensing_delay):
    # documented in the module docstring, RobotState and the robots guide; changing it moves every published result
    with MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none",
                                       domain=DomainParams(sensing_delay=sensing_delay))) as robot:
        robot.write(MotorCommand.hold(robot.desc.nominal_q, 40.0, 1.0))
        lag = robot.sensing_delay_steps
        frames = []
        for _ in range(30 + lag + 1):
            frames.append(_forward(robot, robot.data))  # what the coming step's forward pass computes
            robot.advance(robot.config.timestep)
        state = robot.read()
        # the frame read was measured at step k - lag; its joints are that step's state ...
        measured = frames[len(frames) - lag] if lag else _forward(robot, robot.data)
        np.testing.assert_array_equal(state.q, measured.qpos[7:])
        np.testing.assert_array_equal(state.dq, measured.qvel[6:])
        # ... its sensors and torque are those of the step before
        start = frames[len(frames) - lag - 1]
        sl = sensor_slices(robot.model)
        np.testing.assert_array_equal(state.imu_quat, start.sensordata[sl["imu_quat"]])
        np.testing.assert_array_equal(state.gyro_in_body, start.sensordata[sl["imu_gyro"]])
        np.testing.assert_array_equal(state.accel_in_body, start.sensordata[sl["imu_accel"]])
        np.testing.assert_array_equal(state.foot_force, start.sensordata[foot_touch_adr(robot.model)])
        np.testing.assert_array_equal(state.tau_est, start.actuator_force)
        # and they differ from the joints' instant (the robot moves: the test would pass vacuously otherwise)
        assert not np.array_equal(state.gyro_in_body, measured.sensordata[sl["imu_gyro"]])
        assert not np.array_equal(state.tau_est, measured.actuator_force)


@pytest.mark.parametrize("dt", [0.001, 0.003, 0.005, 1 / 300])
def test_advance_refuses_a_dt_that_is_not_whole_physics_steps(dt):
    with MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none")) as robot:
        with pytest.raises(ConfigError, match=r"dt .* is not a whole number of physics steps of 0.002 s.*nearest"):
            robot.advance(dt)
        assert robot.time == 0.0  # refused before any step


def test_a_period_checked_once_does_not_let_another_one_through():
    """`advance` checks a period once and reuses its step count while the period repeats (the closed loop's hot
    path): a different period, after a valid one, is still checked."""
    with MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none")) as robot:
        robot.advance(0.02)
        robot.advance(0.02)
        with pytest.raises(ConfigError, match="not a whole number of physics steps"):
            robot.advance(0.003)
        robot.advance(0.004)
        assert robot.time == pytest.approx(0.044)


@pytest.mark.parametrize("dt", [math.inf, -math.inf, math.nan, 0.0, -0.002])
def test_advance_refuses_a_non_finite_or_non_positive_dt(dt):
    with MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none")) as robot:
        with pytest.raises(ConfigError, match="dt"):
            robot.advance(dt)


def test_advance_takes_whole_steps_with_floating_point_error():
    with MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none")) as robot:
        for dt, steps in ((1 / 50, 10), (1 / 500, 1), (0.1 * 3, 150), (np.float64(0.004), 2)):
            before = robot.time
            robot.advance(dt)
            assert round((robot.time - before) / 0.002) == steps
        assert robot.physics_steps(1 / 250) == 2


@pytest.mark.parametrize("call", ["read", "sim_truth", "base_truth", "fallen", "base_rotation", "instability"])
def test_a_closed_robot_refuses_every_reading(call):
    robot = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none"))
    with robot:
        getattr(robot, call)()
    with pytest.raises(RobotNotConnectedError, match=call):
        getattr(robot, call)()


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"qpos": "nan"}, "qpos"),
    ({"qpos": np.zeros(5)}, r"qpos must have shape \(19,\)"),
    ({"qpos": np.full(19, np.nan)}, "qpos holds a non-finite value at index 0"),
    ({"seed": "a"}, "seed must be an integer"),
    ({"seed": 1.5}, "seed must be an integer"),
])
def test_reset_refuses_a_bad_qpos_or_seed_naming_it(kwargs, match):
    with MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none")) as robot:
        robot.advance(0.01)
        with pytest.raises(ConfigError, match=match):
            robot.reset(**kwargs)
        assert robot.time == pytest.approx(0.01)  # refused before anything was reset


def test_reset_takes_a_valid_qpos_as_given():
    with MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none")) as robot:
        moved = robot.data.qpos.copy()
        moved[:3] += (0.7, -0.4, 0.05)
        robot.reset(np.int64(1), qpos=list(moved))
        np.testing.assert_array_equal(robot.data.qpos, moved)


def test_apply_push_refuses_a_push_that_starts_in_the_past_and_takes_one_starting_now():
    with MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="none")) as robot:
        robot.write(MotorCommand.hold(robot.desc.nominal_q, 40.0, 1.0))
        robot.advance(0.1)
        with pytest.raises(ConfigError, match=r"starts at 0.05 s, before the robot's time 0.1 s"):
            robot.apply_push(Push.horizontal(100.0, 0.0, (0.0, 0.0, 0.0), start=0.05, duration=0.1))
        robot.apply_push(Push.horizontal(100.0, 0.0, (0.0, 0.0, 0.0), start=robot.time, duration=0.01))
        robot.advance(0.002)
        assert np.linalg.norm(robot.sim_truth().external_force_in_world) == pytest.approx(100.0)


@pytest.mark.parametrize("scale", [-1.0, 0.0, math.nan, math.inf, "2"])
def test_a_bad_arm_mass_scale_is_refused_in_the_config_naming_the_field(scale):
    with pytest.raises(ConfigError, match="MujocoRobotConfig.arm_mass_scale must be a finite positive number"):
        MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated", arm_mass_scale=scale)


def test_the_unitree_emulator_refuses_a_control_period_that_is_not_whole_physics_steps():
    from wbc.hardware.emulators.unitree import UnitreeEmulator, UnitreeEmulatorConfig

    with pytest.raises(ConfigError, match=r"UnitreeEmulatorConfig.control_period: .*dt 0.003 s is not a whole number"):
        UnitreeEmulator(UnitreeEmulatorConfig(control_period=0.003))
    UnitreeEmulator(UnitreeEmulatorConfig(control_period=0.004))  # two steps: taken
