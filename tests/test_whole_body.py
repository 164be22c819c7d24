"""The whole-body QP (PlaCo): statics, swing tracking, torque limits; the estimator's steady-state gains."""

import numpy as np
import pinocchio as pin
import pytest

from wbc.estimation.filter import BaseEstimator, EstimatorConfig, _measurement_matrix, _noise, _steady_gain
from wbc.estimation.kinematics import RobotKinematics
from wbc.mpc.whole_body import WholeBodyConfig, WholeBodyQp
from wbc.robots.joint_table import joint_table
from wbc.robots.registry import get_robot


def _standing(desc):
    kin = RobotKinematics(desc)
    q = desc.nominal_q.copy()
    kin.update(np.array([0.0, 0.0, 0.3]), np.array([1.0, 0.0, 0.0, 0.0]), q, np.zeros(desc.num_joints),
               np.zeros(3), np.zeros(3), centroidal=True)
    return kin


def _solve(wbc, kin, stance, *, com_acc=None, feet_pos=None):
    com_acc = np.zeros(3) if com_acc is None else com_acc
    return wbc.solve(kin.q_pin, kin.v_pin, stance, com=kin.com, com_vel=np.zeros(3), com_acc=com_acc,
                     rot=np.eye(3), omega_world=np.zeros(3), domega_world=np.zeros(3),
                     feet_pos=kin.feet if feet_pos is None else feet_pos, feet_vel=np.zeros((4, 3)),
                     arm_q=kin.desc.nominal_q[12:15] if kin.desc.arm_mode == "actuated" else None)


@pytest.mark.parametrize(("robot", "arm"), [("a1-wx200", "actuated"), ("a1-wx200", "none"), ("go1-arm", "locked")])
def test_standing_forces_carry_the_weight_and_torques_balance_them(robot, arm):
    desc = get_robot(robot, arm)
    kin = _standing(desc)
    wbc = WholeBodyQp(desc)
    res = _solve(wbc, kin, np.ones(4, dtype=bool))
    assert res.success
    mass = kin.params.mass
    assert res.forces.sum(axis=0) == pytest.approx([0.0, 0.0, 9.81 * mass], abs=0.5)
    # statics (nothing moves): each stance leg's torque holds its own weight and its contact force,
    # tau = g(q) - J^T f
    jac = kin.compute_jacobians()
    gravity = pin.computeGeneralizedGravity(kin.robot.model, kin.robot.data, kin.q_pin)[kin._house_cols]
    for i in range(4):
        legs = slice(3 * i, 3 * i + 3)
        expected = gravity[legs] - jac[i][:, legs].T @ res.forces[i]
        assert res.tau[legs] == pytest.approx(expected, abs=0.3)


def test_net_force_follows_the_feed_forward_com_acceleration():
    desc = get_robot("a1-wx200", "actuated")
    kin = _standing(desc)
    wbc = WholeBodyQp(desc)
    res = _solve(wbc, kin, np.ones(4, dtype=bool), com_acc=np.array([1.0, 0.0, 0.0]))
    assert res.success
    assert res.forces.sum(axis=0)[0] == pytest.approx(kin.params.mass * 1.0, rel=0.15)


def test_swing_foot_carries_no_force_and_contacts_stay_in_their_friction_pyramid():
    desc = get_robot("a1-wx200", "actuated")
    kin = _standing(desc)
    cfg = WholeBodyConfig(friction=0.5)
    wbc = WholeBodyQp(desc, cfg)
    stance = np.array([False, True, True, False])
    target = kin.feet.copy()
    target[0, 2] += 0.05
    res = _solve(wbc, kin, stance, feet_pos=target, com_acc=np.array([0.0, 2.0, 0.0]))
    assert res.success
    assert np.all(res.forces[~stance] == 0.0)
    f = res.forces[stance]
    assert np.all(f[:, 2] >= -1e-6)
    assert np.all(np.abs(f[:, 0]) <= cfg.friction * f[:, 2] + 1e-6)
    assert np.all(np.abs(f[:, 1]) <= cfg.friction * f[:, 2] + 1e-6)


def test_torques_stay_within_the_motor_limits_when_the_tasks_ask_too_much():
    desc = get_robot("a1-wx200", "actuated")
    kin = _standing(desc)
    wbc = WholeBodyQp(desc)
    res = _solve(wbc, kin, np.ones(4, dtype=bool), com_acc=np.array([0.0, 0.0, 60.0]))
    limit = joint_table(desc).torque_limit
    assert res.success
    assert np.all(np.abs(res.tau) <= limit + 1e-6)
    assert np.abs(res.tau).max() > 0.9 * limit.min()  # the limits were actually reached


@pytest.mark.parametrize("pattern", [0b1111, 0b1001, 0b0110])
def test_steady_state_gain_is_the_limit_of_the_time_varying_filter(pattern):
    dt, cfg = 0.002, EstimatorConfig(gain="full")
    est = BaseEstimator(dt, cfg)
    est.reset(np.zeros(3), np.zeros((4, 3)))
    trust = np.array([(pattern >> i) & 1 for i in range(4)], dtype=float)
    for _ in range(20000):
        est.update(np.eye(3), np.array([0.0, 0.0, 9.81]), np.zeros((4, 3)), np.zeros((4, 3)), trust)
    q, r = _noise(dt, cfg, trust)
    c = _measurement_matrix()
    a = np.eye(18)
    a[0:3, 3:6] = dt * np.eye(3)
    p_pred = a @ est.P @ a.T + np.diag(q)
    gain = np.linalg.solve(c @ p_pred @ c.T + np.diag(r), c @ p_pred).T
    assert _steady_gain(dt, EstimatorConfig(), pattern) == pytest.approx(gain, abs=1e-4)


def test_steady_and_full_filters_agree_on_a_noisy_walk():
    rng = np.random.default_rng(0)
    dt = 0.002
    ests = [BaseEstimator(dt, EstimatorConfig(gain=g)) for g in ("steady", "full")]
    feet = np.array([[0.2, -0.13, 0.0], [0.2, 0.13, 0.0], [-0.2, -0.13, 0.0], [-0.2, 0.13, 0.0]])
    base = np.array([0.0, 0.0, 0.3])
    for e in ests:
        e.reset(base, feet)
    v = np.array([0.5, 0.0, 0.0])
    out = []
    for k in range(3000):
        base = base + v * dt
        trust = np.array([1, 0, 0, 1.0]) if (k // 90) % 2 else np.array([0, 1, 1, 0.0])
        rel = feet - base + rng.normal(0, 0.003, (4, 3))
        vel = np.tile(-v, (4, 1)) + rng.normal(0, 0.03, (4, 3))
        for e in ests:
            e.update(np.eye(3), np.array([0.0, 0.0, 9.81]) + rng.normal(0, 0.3, 3), rel, vel, trust)
        out.append([e.velocity for e in ests])
    out = np.array(out)[1000:]
    assert np.abs(out[:, 0] - v).mean() < 0.05
    assert np.abs(out[:, 0] - out[:, 1]).mean() < 0.02
