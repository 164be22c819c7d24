"""The tail MPC's compiled QP build against a plain numpy build of the same QP, and the arm's model along a path."""

from __future__ import annotations

import math
import re
from dataclasses import replace

import daqp
import numpy as np
import pytest

from wbc.estimation.kinematics import RobotKinematics
from wbc.mpc.centroidal_model import zoh_integral
from wbc.mpc.centroidal_mpc import MpcProblem, MpcSolveError
from wbc.mpc.tail_model import ArmTailPath, arm_tail, arm_tail_path, servo_torque_bounds
from wbc.mpc.tail_mpc import ARM_DQ, ARM_Q, TNU, TNX, TailMpc, TailMpcConfig, TailStep, tail_dynamics
from wbc.robots.conventions import GRAVITY
from wbc.robots.description import ARM_JOINTS
from wbc.robots.joint_table import joint_table
from wbc.robots.registry import get_robot

READY = np.array([0.0, -1.15, -1.25])


def _oracle(mpc: TailMpc, x0, x_ref, contact, feet, steps) -> dict[str, np.ndarray]:
    """The QP built the direct way: dense condensing, Gamma^T W Gamma, rows appended one by one."""
    cfg, n = mpc.config, mpc.config.horizon
    chosen = np.zeros((n, TNU), dtype=bool)
    chosen[:, :12] = np.repeat(contact, 3, axis=1)
    chosen[:, 12:] = True
    idx = np.flatnonzero(chosen)
    kind = idx % TNU
    scale = np.where(kind < 12, cfg.force_scale, 1.0)
    free = np.empty((n, TNX))
    gamma = np.zeros((n, TNX, n * TNU))
    for k in range(n):
        u_bar = np.zeros(TNU)
        u_bar[2:12:3] = contact[k] * (steps[k].tail.mass * -GRAVITY[2] / max(1, int(contact[k].sum())))
        x_bar = x0.copy()
        x_bar[ARM_Q], x_bar[ARM_DQ] = steps[k].arm_q, steps[k].arm_dq
        f, a, b = tail_dynamics(x_bar, u_bar, steps[k], feet[k])
        phi = zoh_integral(a, cfg.dt)
        a_d, b_d, d_d = np.eye(TNX) + a @ phi, phi @ b, phi @ (f - a @ x_bar - b @ u_bar)
        free[k] = a_d @ (x0 if k == 0 else free[k - 1]) + d_d
        if k > 0:
            gamma[k] = a_d @ gamma[k - 1]
        gamma[k][:, k * TNU:(k + 1) * TNU] += b_d
    gamma_z = gamma.reshape(n * TNX, n * TNU)[:, idx] * scale
    free = free.ravel()
    w = np.tile(cfg.state_weights(), n).reshape(n, TNX)
    speed = math.hypot(float(x_ref[0, 3]), float(x_ref[0, 4]))
    w[:, 3:5] *= min(1.0, max(cfg.standstill_weight_factor, speed / cfg.full_weight_speed))
    w = w.ravel()
    weighted = gamma_z * w[:, None]
    h = gamma_z.T @ weighted + np.diag(np.where(kind < 12, cfg.weight_force, cfg.weight_arm_acc) * scale**2)
    g = weighted.T @ (free - x_ref.ravel())
    top, comp, is_force = cfg.fz_max / cfg.force_scale, kind % 3, kind < 12
    # the friction cone of mu, inside it: the octagon reaches mu cos(pi / 8) across its faces
    assert cfg.pyramid == "octagon"
    mu = cfg.mu * np.cos(np.pi / 8)
    l_box = np.where(comp == 2, cfg.fz_min / cfg.force_scale, -mu * top)
    u_box = np.where(comp == 2, top, mu * top)
    limit = 1e3 if cfg.arm_moves else 0.0
    l_box[~is_force], u_box[~is_force] = -limit, limit
    rows, lo, hi = [], [], []
    for col in np.flatnonzero(is_force & (comp == 2)):
        d = np.sqrt(0.5)
        for cx, cy in ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0), (d, d), (d, -d), (-d, d), (-d, -d)):
            row = np.zeros(idx.size)
            row[col - 2] = cx * scale[col - 2]
            row[col - 1] = cy * scale[col - 1]
            row[col] = -mu * scale[col]
            rows.append(row)
            lo.append(-np.inf)
            hi.append(0.0)
    if cfg.arm_moves:
        acc_cols = np.flatnonzero(~is_force).reshape(n, 3)
        for k in range(n):
            lower, upper = servo_torque_bounds(steps[k].arm_dq, mpc._stall, mpc._vmax)
            block = np.zeros((3, idx.size))
            block[:, acc_cols[k]] = steps[k].tail.mass_matrix
            rows.extend(block)
            lo.extend(lower - steps[k].tail.bias)
            hi.extend(upper - steps[k].tail.bias)
        states = np.arange(n)[:, None] * TNX
        for part, low, high in ((ARM_Q, np.minimum(mpc._arm_lower, x0[ARM_Q]), np.maximum(mpc._arm_upper, x0[ARM_Q])),
                                (ARM_DQ, np.minimum(-mpc._vmax, x0[ARM_DQ]), np.maximum(mpc._vmax, x0[ARM_DQ]))):
            sel = (states + np.arange(part.start, part.stop)[None]).ravel()
            rows.extend(gamma_z[sel])
            lo.extend(np.tile(low, n) - free[sel])
            hi.extend(np.tile(high, n) - free[sel])
    return {"H": h, "g": g, "C": np.array(rows), "l": np.array(lo), "u": np.array(hi), "l_box": l_box,
            "u_box": u_box, "scale": scale, "index": idx, "free": free, "gamma_z": gamma_z}


@pytest.fixture(scope="module")
def robot():
    desc = get_robot("a1-wx200", "actuated")
    return RobotKinematics(desc), joint_table(desc)


def _state(kin, rng):
    """A trotting robot's state, not at rest: its trunk tilted and turning, its arm swinging near the ready pose."""
    q = np.zeros(kin.robot.model.nq)
    q[:7] = (0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0)
    v = np.zeros(kin.robot.model.nv)
    x0 = np.zeros(TNX)
    x0[0:3] = (0.02, -0.01, 0.31)
    x0[3:6] = rng.normal(0.0, 0.4, 3)
    x0[6:9] = rng.normal(0.0, 0.15, 3)
    x0[9:12] = rng.normal(0.0, 1.0, 3)
    x0[12:15] = READY + rng.normal(0.0, 0.2, 3)
    x0[15:18] = rng.normal(0.0, 2.0, 3)
    return q, v, x0


def _case(kin, rng, n):
    q, v, x0 = _state(kin, rng)
    arm_q = x0[12:15] + np.cumsum(rng.normal(0.0, 0.05, (n, 3)), axis=0)
    arm_dq = x0[15:18] + np.cumsum(rng.normal(0.0, 0.5, (n, 3)), axis=0)
    arm_q[0], arm_dq[0] = x0[12:15], x0[15:18]
    path = arm_tail_path(kin.robot, q, v, kin.arm_v, arm_q, arm_dq)
    x_ref = np.tile(x0, (n, 1))
    x_ref[:, 3] = 1.2
    x_ref[:, 12:15] = READY
    x_ref[:, 15:18] = 0.0
    contact = rng.random((n, 4)) < 0.6
    contact[0] = (True, False, False, True)
    feet = np.array([[0.18, -0.13, 0.0], [0.18, 0.13, 0.0], [-0.2, -0.13, 0.0], [-0.2, 0.13, 0.0]])
    feet = np.tile(feet, (n, 1, 1)) + rng.normal(0.0, 0.02, (n, 4, 3))
    return x0, x_ref, contact, feet, path


@pytest.mark.parametrize("arm_moves", [True, False])
def test_the_compiled_build_is_the_plain_build(robot, arm_moves):
    kin, table = robot
    rng = np.random.default_rng(11)
    config = replace(TailMpcConfig(), arm_moves=arm_moves)
    mpc = TailMpc(config, table.lower[ARM_JOINTS], table.upper[ARM_JOINTS], table.velocity_limit[ARM_JOINTS],
                  table.torque_limit[ARM_JOINTS])
    for _ in range(4):
        x0, x_ref, contact, feet, path = _case(kin, rng, config.horizon)
        steps = [TailStep(tail=path.tail(k), arm_q=path.arm_q[k], arm_dq=path.arm_dq[k]) for k in range(len(path))]
        built = mpc.build(x0, x_ref, contact, feet, path)
        plain = _oracle(mpc, x0, x_ref, contact, feet, steps)
        assert built.keys() == plain.keys()
        np.testing.assert_array_equal(built["index"], plain["index"])
        for name in ("H", "g", "C", "l", "u", "l_box", "u_box", "scale", "free", "gamma_z"):
            a, b = built[name], plain[name]
            assert a.shape == b.shape, name
            finite = np.isfinite(b)
            np.testing.assert_array_equal(np.isfinite(a), finite, err_msg=name)
            size = max(1.0, float(np.abs(b[finite]).max())) if finite.any() else 1.0
            np.testing.assert_allclose(a[finite], b[finite], rtol=0.0, atol=1e-9 * size, err_msg=name)
        # the same QP from a list of steps as from the stacked path
        listed = mpc.build(x0, x_ref, contact, feet, steps)
        np.testing.assert_array_equal(listed["H"], built["H"])


def test_the_path_is_each_steps_own_tail(robot):
    kin, _ = robot
    rng = np.random.default_rng(5)
    q, v, x0 = _state(kin, rng)
    arm_q = READY + rng.normal(0.0, 0.3, (4, 3))
    arm_dq = rng.normal(0.0, 2.0, (4, 3))
    path = arm_tail_path(kin.robot, q, v, kin.arm_v, arm_q, arm_dq)
    assert isinstance(path, ArmTailPath) and len(path) == 4
    arm_q_idx = np.asarray(kin.arm_v) + 1
    for k in range(4):
        qk, vk = q.copy(), v.copy()
        qk[arm_q_idx], vk[kin.arm_v] = arm_q[k], arm_dq[k]
        one = arm_tail(kin.robot, qk, vk, kin.arm_v)
        got = path.tail(k)
        for name in ("inertia_world", "momentum_matrix", "momentum_jacobian", "mass_matrix", "bias"):
            np.testing.assert_allclose(getattr(got, name), getattr(one, name), rtol=1e-12, atol=1e-12,
                                       err_msg=f"step {k} {name}")
        assert got.mass == pytest.approx(one.mass)
    # the caller's q and v are not changed
    assert np.all(q[arm_q_idx] == 0.0) and np.all(v == 0.0)
    # the arm moving changes the model along the path (the test is not of four equal steps)
    assert np.abs(path.momentum_matrix[0] - path.momentum_matrix[1]).max() > 1e-3


def test_the_arm_path_rows_are_the_numpy_expressions_bit_for_bit_and_tell_a_non_finite_row():
    from wbc.mpc.tail_compiled import arm_path_rows

    rng = np.random.default_rng(5)
    for _ in range(100):
        rows = rng.normal(size=(5, 15))
        start, acc, torque, tau = rng.normal(size=6), rng.normal(0.0, 30.0, 3), rng.normal(size=3), rng.random() * 0.03
        want = rows.copy()
        want[0, ARM_JOINTS] = start[:3] + start[3:] * tau + 0.5 * acc * tau * tau
        want[1, ARM_JOINTS] = start[3:] + acc * tau
        want[4, ARM_JOINTS] = torque
        assert arm_path_rows(rows, ARM_JOINTS.start, start, acc, tau, torque)
        assert np.array_equal(rows, want)
    rows[2, ARM_JOINTS.start + 1] = np.nan  # a row the function does not write is checked too
    assert not arm_path_rows(rows, ARM_JOINTS.start, start, acc, tau, torque)
    rows[2, ARM_JOINTS.start + 1] = 0.0
    assert not arm_path_rows(rows, ARM_JOINTS.start, start, acc, tau, np.array([0.0, np.inf, 0.0]))


def _tail_mpc(table, config=None):
    return TailMpc(config or TailMpcConfig(), table.lower[ARM_JOINTS], table.upper[ARM_JOINTS],
                   table.velocity_limit[ARM_JOINTS], table.torque_limit[ARM_JOINTS])


def test_a_failed_tail_solve_carries_its_problem_which_replays_to_the_same_failure(robot, tmp_path):
    kin, table = robot
    mpc = _tail_mpc(table)
    x0, x_ref, contact, feet, path = _case(kin, np.random.default_rng(11), mpc.config.horizon)
    qp = mpc.build(x0, x_ref, contact, feet, path)
    plan = mpc.solve(MpcProblem(**qp))  # a feasible QP: the replay entry solves it as `plan` does
    np.testing.assert_array_equal(plan.z, mpc.plan(x0, x_ref, contact, feet, path).z)
    qp["l"] = qp["l"].copy()
    qp["l"][0] = 1e3  # a friction row beyond every force the boxes allow
    with pytest.raises(MpcSolveError, match="error.problem.save") as caught:
        mpc.solve(MpcProblem(**qp))
    problem = caught.value.problem
    assert problem is not None
    problem.save(str(tmp_path / "tail.npz"))
    with pytest.raises(MpcSolveError, match=re.escape("DAQP exit flag -1")):
        mpc.solve(MpcProblem.load(str(tmp_path / "tail.npz")))


def test_a_tail_optimum_that_breaks_its_rows_is_a_failed_solve(robot, monkeypatch):
    kin, table = robot
    mpc = _tail_mpc(table)
    x0, x_ref, contact, feet, path = _case(kin, np.random.default_rng(11), mpc.config.horizon)
    n = mpc.build(x0, x_ref, contact, feet, path)["H"].shape[0]
    # DAQP calling a point optimal that lies far outside the boxes (as it does on absurdly weighted QPs)
    monkeypatch.setattr(daqp, "solve", lambda *args, **kwargs: (np.full(n, 1e3), 0.0, 1, {"iterations": 1}))
    with pytest.raises(MpcSolveError, match="exit flag 1, its solution breaking a constraint by"):
        mpc.plan(x0, x_ref, contact, feet, path, np.zeros(mpc.config.horizon * TNU))
