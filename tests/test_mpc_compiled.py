"""The control tick's compiled pieces against plain NumPy statements of the same laws (the kinematics pass is checked
against Pinocchio in test_mpc.py)."""

import numpy as np
import pytest

from wbc.estimation import BaseEstimator, EstimatorConfig
from wbc.mpc.compiled import contact_trust, swing_targets
from wbc.mpc.kinematics import RobotKinematics
from wbc.mpc.leg_layer import LegLayer
from wbc.robots import get_robot, joint_table
from wbc.robots.conventions import quat_to_matrix


def _leg_torques_numpy(kin, contact, forces, pos, vel, kp, kd, stance_kd, limit):
    """The leg layer's law: stance -J^T (f + c v), swing J^T (kp e + kd de), plus gravity; a stance leg past a limit
    is scaled along its own push by the largest s in [0, 1] that keeps every joint within."""
    stance = contact[:, None]
    swing = kp * (pos - kin.feet) + kd * (vel - kin.feet_vel)
    cart = np.where(stance, -forces - stance_kd * kin.feet_vel, swing)
    legs = np.einsum("iam,ia->im", kin.leg_jacobians, cart)
    hold = kin.gravity[:12].reshape(4, 3)
    lim = limit.reshape(4, 3)
    scale = np.ones(4)
    for i in range(4):
        if contact[i] and np.any(np.abs(legs[i] + hold[i]) > lim[i]):
            # bisection on s: the oracle does not share the closed form
            lo, hi = 0.0, 1.0
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                ok = np.all(np.abs(mid * legs[i] + hold[i]) <= lim[i] + 1e-12)
                lo, hi = (mid, hi) if ok else (lo, mid)
            scale[i] = lo
    tau = kin.gravity.copy()
    tau[:12] += (legs * scale[:, None]).ravel()
    return tau, scale


@pytest.mark.parametrize("robot", ["a1-wx200", "go1-arm"])
def test_the_leg_layer_applies_its_law_and_scales_only_stance_legs_past_their_limits(robot):
    desc = get_robot(robot)
    limit = joint_table(desc).torque_limit
    layer = LegLayer(swing_kp=700.0, swing_kd=20.0, torque_limit=limit, stance_kd=10.0)
    kin = RobotKinematics(desc)
    rng = np.random.default_rng(1)
    scaled = 0
    for k in range(200):
        quat = np.array([1.0, 0.0, 0.0, 0.0]) + 0.1 * rng.standard_normal(4)
        quat /= np.linalg.norm(quat)
        kin.update(rng.standard_normal(3), quat, desc.nominal_q + 0.2 * rng.standard_normal(15),
                   rng.standard_normal(15), rng.standard_normal(3), rng.standard_normal(3), centroidal=False,
                   rot=quat_to_matrix(quat))
        contact = rng.random(4) < 0.6
        forces = rng.normal([0, 0, 60], [30, 30, 60], (4, 3)) * (4.0 if k % 3 == 0 else 1.0)
        pos, vel = kin.feet + 0.05 * rng.standard_normal((4, 3)), rng.standard_normal((4, 3))
        tau = layer.torques(kin, contact, forces, pos, vel)
        want, scale = _leg_torques_numpy(kin, contact, forces, pos, vel, 700.0, 20.0, 10.0, limit[:12])
        np.testing.assert_allclose(layer.scale, scale, atol=1e-9)
        np.testing.assert_allclose(tau, want, atol=1e-6)
        assert np.all(layer.scale[~contact] == 1.0)
        scaled += int(np.any(layer.scale < 1.0))
        stance_legs = np.repeat(contact, 3)
        leg_tau = tau[:12][stance_legs].reshape(-1, 3)
        hold = kin.gravity[:12][stance_legs].reshape(-1, 3)
        lim = limit[:12][stance_legs].reshape(-1, 3)
        # a scaled stance leg is within its limits, or pushes nothing when even gravity alone is past them
        for t, h, m, s in zip(leg_tau, hold, lim, layer.scale[contact], strict=True):
            assert np.all(np.abs(t) <= m + 1e-9) or (s == 0.0 and np.allclose(t, h))
    assert scaled > 20  # the strong forces really reached the limits


def test_before_a_plan_each_stance_foot_pushes_a_quarter_of_the_weight():
    desc = get_robot("a1-wx200")
    layer = LegLayer(swing_kp=700.0, swing_kd=20.0, torque_limit=np.full(15, 1e3))
    kin = RobotKinematics(desc)
    kin.update(np.zeros(3), np.array([1.0, 0, 0, 0]), desc.nominal_q, np.zeros(15), np.zeros(3), np.zeros(3),
               centroidal=False)
    contact = np.ones(4, dtype=bool)
    tau = layer.torques(kin, contact, None, np.zeros((4, 3)), np.zeros((4, 3)))
    want, _ = _leg_torques_numpy(kin, contact, np.tile([0.0, 0.0, 35.0], (4, 1)), 0, 0, 700.0, 20.0, 0.0,
                                 np.full(12, 1e3))
    np.testing.assert_allclose(tau, want, atol=1e-9)


def test_swing_targets_leave_and_land_at_rest_and_peak_at_the_apex_mid_swing():
    liftoff = np.array([[0.2, -0.1, 0.01], [0.2, 0.1, 0.0], [-0.2, -0.1, 0.02], [-0.2, 0.1, 0.0]])
    footholds = liftoff + [0.1, 0.03, -0.01]
    contact = np.array([False, True, False, False])
    pos, vel = np.empty((4, 3)), np.empty((4, 3))
    for s, check in [(0.0, "start"), (0.5, "apex"), (1.0, "end"), (-0.2, "start"), (1.3, "end")]:
        swing_targets(contact, np.full(4, s), liftoff, footholds, 0.02, 0.2, 0.07, pos, vel)
        assert np.all(pos[1] == 0.0) and np.all(vel[1] == 0.0)  # a stance foot has none
        swing = ~contact
        if check == "start":
            np.testing.assert_allclose(pos[swing], liftoff[swing], atol=1e-15)
        elif check == "end":
            np.testing.assert_allclose(pos[swing], footholds[swing] - [0.0, 0.0, 0.02], atol=1e-15)
        else:
            mid = 0.5 * (liftoff + footholds - [0.0, 0.0, 0.02])
            np.testing.assert_allclose(pos[swing], mid[swing] + [0.0, 0.0, 0.07], atol=1e-15)
        if check != "apex":
            np.testing.assert_allclose(vel[swing], 0.0, atol=1e-12)
    # the velocity is the derivative of the position over the swing's duration
    a, b = np.empty((4, 3)), np.empty((4, 3))
    eps = 1e-7
    swing_targets(contact, np.full(4, 0.3), liftoff, footholds, 0.02, 0.2, 0.07, pos, vel)
    swing_targets(contact, np.full(4, 0.3 + eps), liftoff, footholds, 0.02, 0.2, 0.07, a, b)
    np.testing.assert_allclose((a - pos) / (eps * 0.2), vel, atol=1e-5)


def test_the_estimator_trusts_loaded_stance_feet_and_drops_sliding_ones():
    contact = np.array([True, True, True, False])
    force = np.array([30.0, 7.5, 30.0, 50.0])
    vel_rel = np.array([[-0.5, 0.0, 0.0], [-0.5, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    trust, slipping = np.empty(4), np.empty(4, dtype=bool)
    # the base moves at 0.5 m/s: feet 0 and 1 stand still in the world, foot 2 moves with the base (slides)
    contact_trust(contact, force, vel_rel, 0.5, 0.0, 1.0 / 15.0, 0.3**2, trust, slipping)
    np.testing.assert_allclose(trust, [1.0, 0.5, 0.0, 0.0])
    assert slipping.tolist() == [False, False, True, False]


def test_the_compiled_steady_step_is_the_stored_matrices_applied():
    dt = 0.002
    est = BaseEstimator(dt, EstimatorConfig())
    rng = np.random.default_rng(3)
    est.reset(rng.standard_normal(3), rng.standard_normal((4, 3)))
    for _ in range(50):
        x = est.x.copy()
        trust = rng.random(4)
        pattern = sum(1 << i for i in range(4) if trust[i] >= 0.5)
        rot = quat_to_matrix(np.array([0.9, 0.1, -0.2, 0.3]) / np.linalg.norm([0.9, 0.1, -0.2, 0.3]))
        accel, rel, vel = rng.standard_normal(3), rng.standard_normal((4, 3)), rng.standard_normal((4, 3))
        keep_a, keep_b, keep_g, gain = (m[pattern] for m in est._steady)
        want = keep_a @ x + keep_b @ (rot @ accel) + gain @ np.concatenate([rel.ravel(), vel.ravel()]) + keep_g
        est.update(rot, accel, rel, vel, trust.tolist() if pattern % 2 else trust)
        np.testing.assert_allclose(est.x, want, atol=1e-12)
