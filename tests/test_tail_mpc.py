"""`TailMpc`: the centroidal MPC whose arm accelerations are inputs bounded by the servos."""

from __future__ import annotations

import numpy as np
import pytest

from wbc.estimation.kinematics import RobotKinematics
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.mpc.tail_model import arm_tail, servo_torque_bounds
from wbc.mpc.tail_mpc import TNU, TNX, TailMpc, TailMpcConfig, TailStep, tail_dynamics
from wbc.robots.conventions import quat_to_matrix
from wbc.robots.description import ARM_JOINTS
from wbc.robots.euler import rpy_of
from wbc.robots.joint_table import joint_table
from wbc.robots.registry import get_robot

READY = np.array([0.0, -1.15, -1.25])


@pytest.fixture(scope="module")
def standing():
    """The a1-wx200 standing in the simulator with its arm at the ready pose: kinematics, state, table."""
    desc = get_robot("a1-wx200", "actuated")
    kin = RobotKinematics(desc)
    pose = desc.nominal_q.copy()
    pose[ARM_JOINTS] = READY
    sim = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated"))
    with sim:
        sim.reset(seed=0, qpos=np.concatenate([[0.0, 0.0, 0.33, 1.0, 0.0, 0.0, 0.0], pose]))
        truth, state = sim.base_truth(), sim.read()
    kin.update(truth.base_position_in_world, truth.base_quat, state.q, state.dq, truth.base_linvel_in_world,
               truth.base_angvel_in_body, centroidal=True)
    x0 = np.zeros(TNX)
    x0[0:3], x0[3:6] = kin.com, kin.com_vel
    x0[6:9] = rpy_of(quat_to_matrix(truth.base_quat))
    x0[9:12] = kin.momentum
    x0[12:15], x0[15:18] = state.q[ARM_JOINTS], state.dq[ARM_JOINTS]
    return kin, x0, joint_table(desc)


def _problem(kin, x0, n=10):
    x_ref = np.tile(x0, (n, 1))
    x_ref[:, 3:6], x_ref[:, 6:8], x_ref[:, 9:12], x_ref[:, 15:18] = 0.0, 0.0, 0.0, 0.0
    x_ref[:, 12:15] = READY
    contact = np.ones((n, 4), dtype=bool)
    contact[:5, [0, 3]] = False  # a trot: FR and RL in swing for the first half
    feet = np.tile(kin.feet, (n, 1, 1))
    tail = arm_tail(kin.robot, kin.q_pin, kin.v_pin, kin.arm_v)
    steps = [TailStep(tail=tail, arm_q=x0[12:15].copy(), arm_dq=x0[15:18].copy()) for _ in range(n)]
    return x_ref, contact, feet, steps


def _mpc(table, *, arm_speed=None):
    speed = table.velocity_limit[ARM_JOINTS] if arm_speed is None else arm_speed
    return TailMpc(TailMpcConfig(), table.lower[ARM_JOINTS], table.upper[ARM_JOINTS], speed,
                   table.torque_limit[ARM_JOINTS])


def test_the_dynamics_jacobians_agree_with_finite_differences(standing):
    kin, x0, _ = standing
    rng = np.random.default_rng(4)
    v = np.zeros(kin.robot.model.nv)
    v[kin.arm_v] = (1.0, -2.0, 0.5)
    step = TailStep(tail=arm_tail(kin.robot, kin.q_pin, v, kin.arm_v), arm_q=x0[12:15].copy(),
                    arm_dq=np.array([1.0, -2.0, 0.5]))
    x = x0 + rng.normal(0.0, 0.1, TNX)
    u = rng.normal(0.0, 30.0, TNU)
    f, a, b = tail_dynamics(x, u, step, kin.feet)
    eps = 1e-6
    for i in range(TNX):
        e = np.zeros(TNX)
        e[i] = eps
        numeric = (tail_dynamics(x + e, u, step, kin.feet)[0] - tail_dynamics(x - e, u, step, kin.feet)[0]) / (2 * eps)
        np.testing.assert_allclose(a[:, i], numeric, atol=1e-6, err_msg=f"df/dx column {i}")
    for i in range(TNU):
        e = np.zeros(TNU)
        e[i] = eps
        numeric = (tail_dynamics(x, u + e, step, kin.feet)[0] - tail_dynamics(x, u - e, step, kin.feet)[0]) / (2 * eps)
        np.testing.assert_allclose(b[:, i], numeric, atol=1e-6, err_msg=f"df/du column {i}")


def test_standing_the_stance_feet_carry_the_weight_and_the_arm_stays_within_its_servos(standing):
    kin, x0, table = standing
    x_ref, contact, feet, steps = _problem(kin, x0)
    plan = _mpc(table).plan(x0, x_ref, contact, feet, steps)
    weight = steps[0].tail.mass * 9.81
    for k in range(10):
        assert plan.forces[k, ~contact[k]].tolist() == [[0.0, 0.0, 0.0]] * int((~contact[k]).sum())
        assert plan.forces[k, :, 2].sum() == pytest.approx(weight, rel=0.15)
    # M ddq + b within every servo's torque-speed line at the speeds the plan linearised about
    lower, upper = servo_torque_bounds(steps[0].arm_dq, table.torque_limit[ARM_JOINTS],
                                       table.velocity_limit[ARM_JOINTS])
    torque = plan.arm_acceleration @ steps[0].tail.mass_matrix.T + steps[0].tail.bias
    assert np.all(torque >= lower - 1e-6) and np.all(torque <= upper + 1e-6)
    assert np.all(np.abs(plan.arm_velocity) <= table.velocity_limit[ARM_JOINTS] + 1e-6)


def test_a_pitching_trunk_is_caught_by_the_arm_sooner_than_with_the_arm_held(standing):
    kin, x0, table = standing
    x_ref, contact, feet, steps = _problem(kin, x0)
    pitched = x0.copy()
    pitched[9:12] = steps[0].tail.inertia_world @ np.array([0.0, 1.5, 0.0])  # the trunk pitching at 1.5 rad/s
    tail = _mpc(table).plan(pitched, x_ref, contact, feet, steps)
    held = _mpc(table, arm_speed=np.full(3, 1e-9)).plan(pitched, x_ref, contact, feet, steps)
    # the arm takes momentum from the trunk: its planned momentum change has the sign of the trunk's excess
    arm_momentum = steps[0].tail.momentum_matrix @ tail.arm_velocity[2]
    assert arm_momentum[1] > 0.05
    # so the trunk's pitch error over the horizon is 30 % smaller than with the arm held (its first-step peak, 6 %:
    # the servos' torque caps what the arm takes in 32 ms)
    assert np.abs(tail.states[:, 7]).sum() < 0.8 * np.abs(held.states[:, 7]).sum()
    assert np.abs(tail.states[:, 7]).max() < np.abs(held.states[:, 7]).max()
