"""The arm as a tail (`wbc.mpc.tail_model`): the momentum Jacobian against finite differences, and the trunk's
answer to an arm swing against the simulator."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from wbc.estimation.kinematics import RobotKinematics
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.mpc.tail_model import arm_tail, servo_torque_bounds, trunk_rate_change
from wbc.robots.conventions import quat_to_matrix
from wbc.robots.description import ARM_JOINTS
from wbc.robots.registry import get_robot
from wbc.types import MotorCommand


@pytest.fixture(scope="module")
def kin():
    return RobotKinematics(get_robot("a1-wx200", "actuated"))


def _configuration(kin, rng):
    """A tilted, turned base and an arm away from its stowed pose, the legs near nominal; a random velocity."""
    model = kin.robot.model
    q = pin.neutral(model)
    q[0:3] = (0.2, -0.1, 0.3)
    q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.2, -0.15, 0.8)).coeffs()
    q[7:] = rng.normal(0.0, 0.3, model.nq - 7)
    return q, rng.normal(0.0, 1.0, model.nv)


def test_the_momentum_jacobian_agrees_with_finite_differences(kin):
    rng = np.random.default_rng(31)
    model, data = kin.robot.model, kin.robot.data
    arm = kin.arm_v
    for _ in range(3):
        q, v = _configuration(kin, rng)
        tail = arm_tail(kin.robot, q, v, arm)
        eps = 1e-6
        numeric = np.empty((3, 3))
        for j, index in enumerate(arm):
            step = np.zeros(model.nv)
            step[index] = eps
            plus = pin.computeCentroidalMap(model, data, pin.integrate(model, q, step))[3:, arm] @ v[arm]
            minus = pin.computeCentroidalMap(model, data, pin.integrate(model, q, -step))[3:, arm] @ v[arm]
            numeric[:, j] = (plus - minus) / (2 * eps)
        np.testing.assert_allclose(tail.momentum_jacobian, numeric, atol=1e-7 * max(1.0, np.abs(numeric).max()))
        assert np.abs(numeric).max() > 1e-3  # the pose matters: a derivative of zero would test nothing
        # the rest of the tail: A_arm as A_G's arm columns, the mass matrix's arm block symmetric positive definite
        np.testing.assert_allclose(tail.momentum_matrix, pin.computeCentroidalMap(model, data, q)[3:, arm])
        np.testing.assert_allclose(tail.mass_matrix, tail.mass_matrix.T)
        assert np.all(np.linalg.eigvalsh(tail.mass_matrix) > 0)


def test_the_servo_torque_falls_with_speed_to_zero_at_no_load():
    lower, upper = servo_torque_bounds(np.array([0.0, 2.4, 4.8, -2.4, 9.6]), np.full(5, 4.0), np.full(5, 4.8))
    np.testing.assert_allclose(upper, [4.0, 2.0, 0.0, 4.0, -4.0])
    np.testing.assert_allclose(lower, [-4.0, -4.0, -4.0, -2.0, -4.0])


def test_an_arm_swing_turns_the_floating_trunk_as_the_model_predicts(kin, tmp_path, monkeypatch):
    """In zero gravity, touching nothing, the robot holds its legs and swings its waist at up to 3 rad/s: the trunk
    turns the other way at the rate I_c^-1 A_arm dq_a says, to within 2 % (the legs' own small motion is the
    model's neglect)."""
    monkeypatch.chdir(tmp_path)
    desc = get_robot("a1-wx200", "actuated")
    sim = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated"))
    measured, predicted = [], []
    with sim:
        extended = desc.nominal_q.copy()
        extended[ARM_JOINTS] = 0.0  # the arm held straight forward: its most leverage (stowed, a fifth of it)
        qpos = np.concatenate([[0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0], extended])
        sim.reset(seed=0, qpos=qpos)
        sim.model.opt.gravity[:] = 0.0
        kp = np.full(desc.num_joints, 60.0)
        kd = np.full(desc.num_joints, 2.0)
        kp[ARM_JOINTS], kd[ARM_JOINTS] = 30.0, 1.0
        rest = None
        for k in range(150):
            t = k * 0.002
            speed = 3.0 * min(t / 0.1, 1.0)  # the waist ramps to 3 rad/s in 0.1 s, then swings on
            target = extended.copy()
            target[ARM_JOINTS.start] = 1.5 * t * min(t / 0.1, 1.0) if t < 0.1 else 0.15 + speed * (t - 0.1)
            dq = np.zeros(desc.num_joints)
            dq[ARM_JOINTS.start] = speed
            sim.write(MotorCommand(q=target, dq=dq, kp=kp, kd=kd, tau=np.zeros(desc.num_joints)))
            sim.advance(0.002)
            truth, state = sim.base_truth(), sim.read()
            kin.update(truth.base_position_in_world, truth.base_quat, state.q, state.dq,
                       truth.base_linvel_in_world, truth.base_angvel_in_body, centroidal=True)
            omega_world = quat_to_matrix(truth.base_quat) @ truth.base_angvel_in_body
            tail = arm_tail(kin.robot, kin.q_pin, kin.v_pin, kin.arm_v)
            if rest is None:
                rest = (omega_world, state.dq[ARM_JOINTS].copy())
            measured.append(omega_world - rest[0])
            predicted.append(trunk_rate_change(tail, rest[1], state.dq[ARM_JOINTS]))
    measured, predicted = np.array(measured), np.array(predicted)
    swinging = np.abs(predicted[:, 2]) > 0.1  # yaw: the waist turns about the trunk's vertical
    assert swinging.sum() > 50 and np.all(predicted[swinging, 2] < 0)  # the trunk turns against the arm
    error = np.linalg.norm(measured[swinging] - predicted[swinging], axis=1)
    assert np.all(error <= 0.02 * np.linalg.norm(predicted[swinging], axis=1))  # measured: 0.4 %


def test_the_ready_pose_raises_the_arm_like_a_tail_and_holds_five_times_the_stowed_leverage(kin):
    from wbc.mpc.tail_model import arm_leverage, choose_ready_pose
    from wbc.robots.joint_table import joint_table

    desc = get_robot("a1-wx200", "actuated")
    table = joint_table(desc)
    lo, hi = table.lower[ARM_JOINTS] + 0.05, table.upper[ARM_JOINTS] - 0.05
    q = pin.neutral(kin.robot.model)
    q[2] = 0.3
    q[7:] = desc.nominal_q[kin.robot.joints.pin_from_house]
    grid = [desc.arm.nominal_q, *(np.array([0.0, s, e]) for s in np.arange(lo[1], hi[1], 0.05)
                                  for e in np.arange(lo[2], hi[2], 0.05))]
    poses = arm_leverage(kin.robot, q, kin.arm_v, np.array(grid), table.velocity_limit[ARM_JOINTS],
                         table.torque_limit[ARM_JOINTS])
    stowed, ready = poses[0], choose_ready_pose(poses)
    # stowed, the arm holds 0.04 / 0.14 / 0.05 N m s about roll / pitch / yaw at its speed limits
    np.testing.assert_allclose(stowed.momentum_capacity, [0.041, 0.139, 0.048], atol=0.002)
    # ready: upper arm leaning back, forearm raised behind the trunk; 9x the roll and 5x the pitch leverage, held
    # with under a quarter of each servo's stall torque, the CoM 1 cm back
    np.testing.assert_allclose(ready.arm_q, [0.0, -1.15, -1.25], atol=0.06)
    assert np.all(ready.momentum_capacity[:2] >= 5 * stowed.momentum_capacity[:2])
    assert np.all(ready.holding <= 0.25) and np.linalg.norm(ready.com_shift) < 0.015
    with pytest.raises(ValueError, match="no arm pose of 1 holds with at most 10% of stall torque"):
        choose_ready_pose([stowed], max_holding=0.1)  # its elbow needs 23 %
