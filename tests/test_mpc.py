"""The centroidal model with arm momentum and the MPC QP."""

import dataclasses

import casadi as ca
import mujoco
import numpy as np
import pinocchio as pin
import pytest

from wbc.errors import MpcProblemFileError
from wbc.estimation.kinematics import RobotKinematics
from wbc.hardware.mujoco.scene import build_scene
from wbc.mpc import CentroidalModel, CentroidalMpc, CentroidalParams, MpcConfig, MpcProblem, SymbolicCentroidalModel
from wbc.mpc.centroidal_model import euler_rates_matrix
from wbc.mpc.gait import STAND, TROT, GaitConfig, GaitScheduler
from wbc.robots import get_robot, joint_table
from wbc.robots.conventions import quat_to_matrix
from wbc.robots.description import FOOT_NAMES, LEG_NAMES
from wbc.robots.pinocchio_model import build_pinocchio
from wbc.robots.urdf import foot_radii
from wbc.scenario.terrain import TerrainConfig

FEET = ("FR_foot", "FL_foot", "RR_foot", "RL_foot")


def _random_params(rng):
    a = rng.normal(size=(3, 3))
    return CentroidalParams(mass=15.0, inertia_world=np.diag([0.1, 0.3, 0.35]) + 0.01 * (a @ a.T),
                            arm_momentum_matrix=0.02 * rng.normal(size=(3, 3)), feet_world=rng.normal(size=(4, 3)))


def test_analytic_jacobians_match_autodiff_and_finite_differences():
    model, ref = CentroidalModel(), SymbolicCentroidalModel()
    rng = np.random.default_rng(1)
    for _ in range(5):
        p = _random_params(rng)
        x = rng.normal(size=15) * 0.4
        u = rng.normal(size=15) * 20
        f, a, b = model.linearize(x, u, p)
        f_ref, a_ref, b_ref = ref.linearize(x, u, p)
        np.testing.assert_allclose(f, f_ref, atol=1e-12)
        np.testing.assert_allclose(a, a_ref, atol=1e-10)
        np.testing.assert_allclose(b, b_ref, atol=1e-10)
        eps = 1e-6
        a_fd = np.column_stack([(model.dynamics(x + eps * e, u, p) - model.dynamics(x - eps * e, u, p)) / (2 * eps)
                                for e in np.eye(15)])
        b_fd = np.column_stack([(model.dynamics(x, u + eps * e, p) - model.dynamics(x, u - eps * e, p)) / (2 * eps)
                                for e in np.eye(15)])
        np.testing.assert_allclose(a, a_fd, atol=1e-6)
        np.testing.assert_allclose(b, b_fd, atol=1e-6)


def test_discretization_matches_the_matrix_exponential():
    model = CentroidalModel()
    rng = np.random.default_rng(2)
    p = _random_params(rng)
    x, u = rng.normal(size=15) * 0.2, rng.normal(size=15) * 20
    f, a, b = model.linearize(x, u, p)
    ad, bd, dd = model.discretize(x, u, p, 0.04)
    ae, be, de = SymbolicCentroidalModel.exact_discretization(a, b, f - a @ x - b @ u, 0.04)
    np.testing.assert_allclose(ad, ae, atol=1e-3)
    np.testing.assert_allclose(bd, be, atol=1e-4)
    np.testing.assert_allclose(dd, de, atol=1e-3)


def _arm_indices(pr):
    return 6 + np.array([list(pr.joints.pin_from_house).index(i) for i in (12, 13, 14)])


def test_pure_arm_swing_turns_the_body_as_the_model_predicts_and_mujoco_agrees():
    """Free-floating robot, no gravity, zero momentum: swinging the waist turns the body the other way."""
    desc = get_robot("a1-wx200")
    pr = build_pinocchio(desc)
    arm_v = _arm_indices(pr)
    model = build_scene(desc, TerrainConfig())
    model.opt.gravity[:] = 0
    model.dof_damping[:] = 0
    model.dof_frictionloss[:] = 0
    data = mujoco.MjData(model)
    data.qpos[:7] = [0, 0, 2.0, 1, 0, 0, 0]
    data.qpos[7:] = desc.nominal_q
    data.qpos[7 + 13] = 0.3  # shoulder raised so the waist swing sweeps inertia
    data.qpos[7 + 14] = 0.0
    # drive the waist along a smooth profile with stiff motors; hold every other joint
    kp, kd = 400.0, 20.0
    model.actuator_biasprm[:, 1] = -kp
    model.actuator_biasprm[:, 2] = -kd
    model.actuator_forcerange[:] = [-1e4, 1e4]
    q0 = data.qpos[7:].copy()
    dt, steps = model.opt.timestep, 400
    theta = np.zeros(3)  # model prediction of roll, pitch, yaw
    cmodel = CentroidalModel()
    mujoco.mj_forward(model, data)
    for k in range(steps):
        t = k * dt
        target = q0.copy()
        target[12] = 1.2 * (1 - np.cos(np.pi * t / (steps * dt))) / 2
        data.ctrl[:] = kp * target
        qpos_before = data.qpos.copy()
        mujoco.mj_step(model, data)
        dqa = (data.qpos[7 + 12:7 + 15] - qpos_before[7 + 12:7 + 15]) / dt
        q_pin = pr.joints.q_pin(qpos_before)
        params = CentroidalParams.from_pinocchio(pr, q_pin, np.zeros((4, 3)), arm_v)
        x = np.zeros(15)
        x[6:9] = theta
        u = np.zeros(15)
        u[12:] = dqa
        theta = theta + dt * cmodel.dynamics(x, u, params)[6:9]
    quat = data.qpos[3:7]
    yaw_mj = np.arctan2(2 * (quat[0] * quat[3] + quat[1] * quat[2]), 1 - 2 * (quat[2] ** 2 + quat[3] ** 2))
    assert data.qpos[7 + 12] == pytest.approx(1.2, abs=0.05)  # the waist swung (PD lag aside)
    assert yaw_mj < -0.02  # the body turned against the arm
    assert theta[2] == pytest.approx(yaw_mj, rel=0.05)


def _standing_problem(desc_name="a1-wx200"):
    desc = get_robot(desc_name)
    pr = build_pinocchio(desc)
    table = joint_table(desc)
    q = np.r_[0, 0, 0.28, 0, 0, 0, 1, desc.nominal_q[pr.joints.pin_from_house]]
    pin.framesForwardKinematics(pr.model, pr.data, q)
    feet = np.array([pr.data.oMf[pr.model.getFrameId(f)].translation for f in FEET])
    params = CentroidalParams.from_pinocchio(pr, q, feet, _arm_indices(pr))
    x0 = np.zeros(15)
    x0[0:3] = pin.centerOfMass(pr.model, pr.data, q)
    x0[12:15] = desc.arm.nominal_q
    mpc = CentroidalMpc(MpcConfig(), table.lower[12:], table.upper[12:], table.velocity_limit[12:])
    return mpc, x0, feet, params


def _second_solver(problem):
    """Solve a recorded problem with qpOASES through CasADi (box bounds as extra rows)."""
    n = problem.H.shape[0]
    a = np.vstack([problem.C, np.eye(n)])
    lba = np.concatenate([np.maximum(problem.l, -1e20), problem.l_box])
    uba = np.concatenate([np.minimum(problem.u, 1e20), problem.u_box])
    solver = ca.conic("S", "qpoases", {"h": ca.DM(problem.H).sparsity(), "a": ca.DM(a).sparsity()},
                      {"printLevel": "none", "error_on_fail": True})
    sol = solver(h=ca.DM(problem.H), g=ca.DM(problem.g), a=ca.DM(a), lba=ca.DM(lba), uba=ca.DM(uba))
    return np.asarray(sol["x"]).ravel()


@pytest.mark.parametrize("gait", ["stand", "trot", "pushed"])
def test_mpc_plan_is_feasible_and_agrees_with_a_second_solver(gait):
    mpc, x0, feet, params = _standing_problem()
    n = mpc.config.horizon
    x_ref = np.tile(x0, (n, 1))
    contact = np.ones((n, 4), bool)
    if gait == "trot":
        contact = np.array([[1, 0, 0, 1]] * 5 + [[0, 1, 1, 0]] * 5, bool)
    x = x0.copy()
    if gait == "pushed":
        x[3:6] = (0.0, 0.8, 0.0)  # a sideways kick
        x[6] = 0.15
    problem = mpc.build(x, x_ref, contact, np.tile(feet, (n, 1, 1)), params)
    sol = mpc.solve(problem)
    f = sol.forces
    mu = mpc.config.mu
    assert np.all(f[..., 2] >= -1e-4) and np.all(f[..., 2] <= mpc.config.fz_max + 1e-3)
    assert np.all(np.abs(f[..., :2]) <= mu * f[..., 2:3] + 1e-3)
    assert np.allclose(f[~contact], 0.0, atol=1e-3)  # swing feet push nothing (solver tolerance: 1e-5 N)
    assert np.all(np.abs(sol.arm_velocity) <= joint_table(get_robot("a1-wx200")).velocity_limit[12:] + 1e-6)
    if gait == "stand":
        assert f[0, :, 2].sum() == pytest.approx(params.mass * 9.81, rel=0.05)
    z_ref = _second_solver(problem)
    np.testing.assert_allclose(sol.z, z_ref, atol=2e-3)
    # the previous solution, shifted, warm-starts the next solve to the same answer as a cold start
    warm = mpc.plan(x, x_ref, contact, np.tile(feet, (n, 1, 1)), params, sol.warm_start())
    cold = mpc.plan(x, x_ref, contact, np.tile(feet, (n, 1, 1)), params)
    np.testing.assert_allclose(warm.z, cold.z, atol=2e-3)
    assert warm.setup_s > 0 and warm.solve_s > 0


def _same_plan(a, b):
    for name in ("forces", "arm_velocity", "states", "z", "variables"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.iterations == b.iterations


@pytest.mark.parametrize("gait", ["stand", "trot"])
def test_a_saved_problem_loads_and_solves_to_the_live_plan_bit_for_bit(gait, tmp_path):
    mpc, x0, feet, params = _standing_problem()
    n = mpc.config.horizon
    contact = np.ones((n, 4), bool)
    if gait == "trot":
        contact = np.array([[1, 0, 0, 1]] * 4 + [[0, 1, 1, 0]] * 5 + [[1, 0, 0, 1]], bool)
    x = x0.copy()
    x[3:6] = (0.1, 0.3, 0.0)
    args = (np.tile(x0, (n, 1)), contact, np.tile(feet, (n, 1, 1)), params)
    first = mpc.solve(mpc.build(x, *args))  # the live loop: a cold start, then warm starts from the shifted plan
    x[3:6] = (0.12, 0.25, 0.0)
    problem = mpc.build(x, *args)
    live = mpc.solve(problem, first.warm_start())
    problem.save(tmp_path / "problem.npz")
    loaded = MpcProblem.load(tmp_path / "problem.npz")
    for name in ("H", "g", "C", "l", "u", "l_box", "u_box", "scale", "index", "free", "gamma_z"):
        assert np.array_equal(getattr(loaded, name), getattr(problem, name)), name
    # the solve holds no state between updates: a fresh solver (as in another process) and the live one replay it
    # to the same bits, warm and cold
    fresh, _, _, _ = _standing_problem()
    _same_plan(fresh.solve(loaded, first.warm_start()), live)
    _same_plan(mpc.solve(loaded, first.warm_start()), live)
    _same_plan(fresh.solve(loaded), mpc.solve(problem))


def test_the_horizontal_velocity_weights_hold_in_full_at_speed_and_relax_towards_standstill():
    mpc, x0, feet, params = _standing_problem()
    cfg = mpc.config
    x_ref = np.tile(x0, (cfg.horizon, 1))
    table = joint_table(get_robot("a1-wx200"))

    def made(**config):
        return CentroidalMpc(dataclasses.replace(cfg, **config), table.lower[12:], table.upper[12:],
                             table.velocity_limit[12:])

    def factor(vx, vy=0.0, **config):
        ref = x_ref.copy()
        ref[:, 3:5] = (vx, vy)
        return made(**config).velocity_weight_factor(ref)

    assert factor(0.0) == cfg.standstill_weight_factor == 0.25
    assert factor(0.3) == pytest.approx(0.3 / cfg.full_weight_speed) and factor(0.3, 0.4) == pytest.approx(0.5)
    assert factor(1.0) == factor(-1.5) == factor(0.0, 1.2) == 1.0  # the turn task's speeds track in full
    assert factor(0.0, full_weight_speed=0.0) == 1.0  # switched off
    # the condensed problem carries the scaled weights: at standstill the velocity part of the Hessian shrinks
    contact = np.ones((cfg.horizon, 4), bool)
    feet = np.tile(feet, (cfg.horizon, 1, 1))
    still = mpc.build(x0, x_ref, contact, feet, params)
    full = made(full_weight_speed=0.0).build(x0, x_ref, contact, feet, params)
    assert not np.allclose(still.H, full.H)


def test_the_condensed_prediction_equals_stepping_the_discretised_dynamics_one_step_at_a_time():
    """X = free + gamma_z z (the compiled condensing) against the model stepped N times in plain numpy: linearised
    about x0, each step's lever arms about that step's reference CoM (the current CoM for the first) with the matching
    affine torque term, zero-order hold third order in dt."""
    rng = np.random.default_rng(3)
    mpc, x0, feet, params = _standing_problem()
    n, dt = mpc.config.horizon, mpc.config.dt
    x = x0.copy()
    x[3:12] += rng.normal(scale=0.2, size=9)  # moving, tilted, spinning
    contact = np.array([[1, 0, 0, 1]] * 4 + [[0, 1, 1, 0]] * 5 + [[1, 0, 0, 1]], bool)
    x_ref = np.tile(x0, (n, 1)) + rng.normal(scale=0.05, size=(n, 15))
    step_feet = np.tile(feet, (n, 1, 1)) + rng.normal(scale=0.05, size=(n, 4, 3))
    problem = mpc.build(x, x_ref, contact, step_feet, params)
    u = rng.normal(scale=20.0, size=(n, 15))
    u[:, 12:] = rng.normal(scale=0.5, size=(n, 3))
    u[:, :12] *= np.repeat(contact, 3, axis=1)  # swing feet have no force variables
    z = u.ravel()[problem.index] / problem.scale
    assert np.array_equal(np.flatnonzero(u.ravel()), problem.index)
    predicted = (problem.free + problem.gamma_z @ z).reshape(n, 15)
    # the QP's cost is the tracking error and effort of that plan: 1/2 z H z + g z = 1/2 |X - X_ref|_Q^2 + effort + c
    cfg = mpc.config
    factor = mpc.velocity_weight_factor(x_ref)  # a slow reference: the horizontal velocity weights are scaled
    assert factor < 1
    weight_vel = (factor * cfg.weight_vel[0], factor * cfg.weight_vel[1], cfg.weight_vel[2])
    q = np.tile(np.concatenate([cfg.weight_com, weight_vel, cfg.weight_rpy, cfg.weight_momentum,
                                cfg.weight_arm_q]), n)
    r = np.tile(np.r_[np.full(12, cfg.weight_force), np.full(3, cfg.weight_arm_dq)], n)
    err = predicted.ravel() - x_ref.ravel()
    err0 = problem.free - x_ref.ravel()
    cost = 0.5 * z @ problem.H @ z + problem.g @ z
    assert cost == pytest.approx(0.5 * (err @ (q * err) - err0 @ (q * err0)) + 0.5 * u.ravel() @ (r * u.ravel()),
                                 rel=1e-9)

    u_bar = np.zeros(15)
    stance = contact[0]
    u_bar[2:12:3] = stance * params.mass * 9.81 / stance.sum()
    f0, a_c, b_c = CentroidalModel().linearize(x, u_bar, params)
    d_c = f0 - a_c @ x - b_c @ u_bar
    integ = np.eye(15) * dt + a_c * dt**2 / 2 + a_c @ a_c * dt**3 / 6
    a_d = np.eye(15) + a_c @ integ
    state = x.copy()
    for k in range(n):
        c_ref = x[0:3] if k == 0 else x_ref[k - 1, 0:3]
        b_k = b_c.copy()
        for i in range(4):
            r = step_feet[k, i] - c_ref
            b_k[9:12, 3 * i:3 * i + 3] = [[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]]
        d_k = d_c.copy()
        d_k[9:12] -= np.cross(u_bar[:12].reshape(4, 3).sum(axis=0), c_ref - x[0:3])
        state = a_d @ state + integ @ (b_k @ u[k] + d_k)
        np.testing.assert_allclose(predicted[k], state, rtol=1e-9, atol=1e-9, err_msg=f"step {k}")


def test_a_problem_file_missing_arrays_is_refused_with_what_is_missing(tmp_path):
    mpc, x0, feet, params = _standing_problem()
    n = mpc.config.horizon
    problem = mpc.build(x0, np.tile(x0, (n, 1)), np.ones((n, 4), bool), np.tile(feet, (n, 1, 1)), params)
    old = {k: getattr(problem, k) for k in ("H", "g", "C", "l", "u", "l_box", "u_box", "scale", "index")}
    np.savez(tmp_path / "old.npz", **old)  # a dump from before the problem carried its condensed dynamics
    with pytest.raises(MpcProblemFileError, match="missing free, gamma_z"):
        MpcProblem.load(tmp_path / "old.npz")


def test_the_optimiser_swings_the_arm_to_right_the_body_when_arm_terms_are_on():
    mpc, x0, feet, params = _standing_problem()
    n = mpc.config.horizon
    x = x0.copy()
    x[9:12] = (0.0, 0.0, 0.8)  # a yaw spin imparted by a push: the body must be stopped
    args = (np.tile(x0, (n, 1)), np.ones((n, 4), bool), np.tile(feet, (n, 1, 1)))
    with_arm = mpc.plan(x, *args, params)
    assert np.abs(with_arm.arm_velocity).max() > 0.03
    # with the arm momentum matrix zeroed the arm has no effect on the body and stays still
    no_arm = CentroidalParams(mass=params.mass, inertia_world=params.inertia_world,
                              arm_momentum_matrix=np.zeros((3, 3)), feet_world=params.feet_world)
    still = mpc.plan(x, *args, no_arm)
    assert np.abs(still.arm_velocity).max() < 1e-3
    assert euler_rates_matrix(np.zeros(3)) == pytest.approx(np.eye(3))


@pytest.mark.parametrize("gait", [TROT, STAND, GaitConfig(period=0.5, duty=0.7, offsets=(0.1, 0.3, 0.6, 0.9))])
def test_gait_state_and_contact_table_agree_with_the_per_time_queries(gait):
    # the per-tick and per-horizon fast paths must give exactly what the plain queries give, at phase boundaries too
    sched = GaitScheduler(gait)
    for t in np.r_[np.arange(0.0, 3.0, 0.002), np.random.default_rng(0).random(200) * 50.0]:
        contact, progress, touchdown = sched.state(t)
        assert contact.dtype == bool and np.array_equal(contact, sched.contact(t))
        assert np.array_equal(progress, sched.swing_progress(t))
        assert np.array_equal(touchdown, sched.time_to_touchdown(t))
        table = sched.contact_table(t, 0.04, 10)
        assert np.array_equal(table, np.array([sched.contact(t + (k + 0.5) * 0.04) for k in range(10)]))


@pytest.mark.parametrize(("robot", "arm"), [("a1-wx200", "actuated"), ("a1-wx200", "locked"), ("a1-wx200", "none"),
                                           ("go1-arm", "actuated"), ("go1-arm", "none")])
def test_the_per_tick_kinematics_placed_at_a_base_state_agree_with_pinocchio_there(robot, arm):
    # one compiled pass with the base at the origin, then placed: what the estimator and the leg layer read every
    # tick, against Pinocchio's own algorithms at the placed state, over random configurations far from the stand
    desc = get_robot(robot).with_arm_mode(arm)
    rng = np.random.default_rng(4)
    kin = RobotKinematics(desc)
    model, data = kin.robot.model, kin.robot.data
    frame = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    cols = 6 + kin.robot.joints.house_from_pin[:12].reshape(4, 3)  # each leg's columns of the velocity
    feet = [model.getFrameId(name) for name in FOOT_NAMES]
    radii = foot_radii(desc)
    assert np.all(radii == 0.02)  # both robots' URDF feet
    n = desc.num_joints
    for _ in range(20):
        quat = rng.standard_normal(4)
        quat /= np.linalg.norm(quat)
        q, dq = desc.nominal_q + 0.5 * rng.standard_normal(n), rng.standard_normal(n)
        p, v, w = rng.standard_normal(3), rng.standard_normal(3), rng.standard_normal(3)
        kin.update(p, quat, q, dq, v, w, centroidal=True)
        assert np.array_equal(kin.rot, quat_to_matrix(quat))  # the pass's rotation is the conversion's, to the bit
        q_pin, v_pin = kin.q_pin, kin.v_pin
        pin.forwardKinematics(model, data, q_pin, v_pin)
        pin.computeJointJacobians(model, data, q_pin)
        pin.updateFramePlacements(model, data)
        for i, fid in enumerate(feet):
            np.testing.assert_allclose(kin.feet[i], data.oMf[fid].translation, atol=1e-12)
            twist = pin.getFrameVelocity(model, data, fid, frame)
            np.testing.assert_allclose(kin.feet_vel[i], twist.linear, atol=1e-12)
            # the point of the foot's sphere right below its centre, fixed to the foot, relative to the base
            below = twist.linear + np.cross(twist.angular, [0.0, 0.0, -radii[i]])
            np.testing.assert_allclose(kin.contact_vel_rel[i] + v, below, atol=1e-12)
            jac = pin.getFrameJacobian(model, data, fid, frame)[:3]
            np.testing.assert_allclose(kin.leg_jacobians[i], jac[:, cols[i]], atol=1e-12)
            assert np.abs(np.delete(jac[:, 6:], cols[i] - 6, axis=1)).max() < 1e-12  # no other joint moves it
        hips = [data.oMi[model.getJointId(f"{leg}_thigh_joint")].translation for leg in LEG_NAMES]
        np.testing.assert_allclose(kin.hip_positions(), np.array(hips), atol=1e-12)
        np.testing.assert_allclose(kin.omega_world, quat_to_matrix(quat) @ w, atol=1e-12)
        gravity = pin.computeGeneralizedGravity(model, data, q_pin)[6 + kin.robot.joints.house_from_pin]
        np.testing.assert_allclose(kin.gravity, gravity, atol=1e-10)
        pin.centerOfMass(model, data, q_pin, v_pin)
        np.testing.assert_allclose(kin.com, data.com[0], atol=1e-12)
        np.testing.assert_allclose(kin.com_vel, data.vcom[0], atol=1e-12)
        # between MPC updates the CoM rides with the trunk at its last offset
        kin.tick(quat, q, dq, w)
        kin.place(p + 0.01, v)
        np.testing.assert_allclose(kin.com, data.com[0] + 0.01, atol=1e-12)


def test_leg_jacobians_match_finite_differences_of_the_feet():
    desc = get_robot("go1-arm")
    rng = np.random.default_rng(7)
    quat = np.array([0.97, -0.08, 0.12, 0.2])
    quat /= np.linalg.norm(quat)
    q = desc.nominal_q + 0.2 * rng.standard_normal(15)
    kin = RobotKinematics(desc)
    kin.tick(quat, q, np.zeros(15), np.zeros(3))
    jac, feet = kin.leg_jacobians.copy(), kin.feet_rel.copy()
    eps = 1e-6
    for j in range(12):
        dq = np.zeros(15)
        dq[j] = eps
        kin.tick(quat, q + dq, np.zeros(15), np.zeros(3))
        leg, col = divmod(j, 3)
        np.testing.assert_allclose((kin.feet_rel[leg] - feet[leg]) / eps, jac[leg][:, col], atol=1e-5)

