"""`MujocoRobot`'s documented edges: which readings lag the joints, what `advance`, `reset`, `apply_push` and a
closed robot refuse."""

import mujoco
import numpy as np
import pytest

from wbc import MotorCommand
from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
from wbc.hardware.mujoco.physics import foot_touch_adr, sensor_slices
from wbc.scenario import DomainParams


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
