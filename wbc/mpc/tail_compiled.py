"""The tail MPC's QP build, compiled (numba): linearisation, discretisation, condensing, cost and constraint rows.

`wbc.mpc.tail_mpc.TailMpc` re-plans every 32 ms, and at once when a push is detected; built from numpy calls, its QP
(ten linearisations of 18 states, a condensed horizon of ~150 columns, ~100 constraint rows built row by row) took
several milliseconds, most of it Python and numpy dispatch on small arrays. `tail_qp` builds the same QP in one call.

It computes what `wbc.mpc.tail_mpc.tail_dynamics` and the zero-order hold give, step by step, and the same cost and
rows in the same order; only the order of some sums differs (the tests compare it with a plain numpy build on real
states: equal to ~1e-12 relative). Two things make it cheap besides the compilation:

- the condensed dynamics are block lower triangular, Gamma[k, j] = A_k ... A_{j+1} B_j for j <= k, so only those
  blocks are computed, and only for the QP's variables (stance forces, arm accelerations);
- the Hessian Gamma^T W Gamma is summed backwards along the horizon, as a Riccati recursion does:
  H[i, j] = Gamma[j, i]^T P_j B_j for i <= j, with P_j = W_j + A_{j+1}^T P_{j+1} A_{j+1}, and the gradient likewise,
  g_i = B_i^T s_i with s_i = W_i e_i + A_{i+1}^T s_{i+1} (e: the free response's error), about a tenth of the
  products of the dense Gamma^T W Gamma.

Products with the step matrices skip their zero entries (a continuous-time A has 51 of 324 non-zero); a zero times a
finite number adds nothing, so the results are the same as the dense products'.

Compiled functions are cached on disk beside this module (numba's ``cache=True``), as `wbc.mpc.compiled`'s are; the
controller calls `tail_qp` once when it is made (`wbc.mpc.controller.MpcController._load_compiled`), so the first
real update does not load or compile it.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["arm_path_rows", "tail_qp"]

_NX = 18  # the state: c, v, Theta, h, q_a, dq_a (`wbc.mpc.tail_mpc.TNX`)
_NU = 15  # the input: four feet's forces, the arm's accelerations (`wbc.mpc.tail_mpc.TNU`)


@numba.njit(cache=True, nogil=True)
def _step_model(x0, fz, feet, mass, inertia, momentum_matrix, momentum_jacobian, arm_q, arm_dq, gravity, a, b,
                d):  # pragma: no cover
    """One step's model linearised about x0 with the step's arm pose and speed and the forces `fz`: into a, b, d.

    a = df/dx (18, 18), b = df/du (18, 15) and d = f - a x_bar - b u_bar (18,), as `wbc.mpc.tail_mpc.tail_dynamics`
    gives them at x_bar (x0, its arm at `arm_q`, `arm_dq`) and u_bar (the feet's normal forces `fz` (4,), no arm
    acceleration). `a`, `b` are zero on entry (only their non-zero entries are written).
    """
    inv_i = np.linalg.inv(inertia)
    c0, c1, c2 = x0[0], x0[1], x0[2]
    pitch, yaw = x0[7], x0[8]
    # omega = I_c^-1 (h - A_arm dq_bar): at the linearisation point the Jacobian term, J (q_a - q_bar), is zero
    rel = np.empty(3)
    for i in range(3):
        rel[i] = x0[9 + i] - (momentum_matrix[i, 0] * arm_dq[0] + momentum_matrix[i, 1] * arm_dq[1]
                              + momentum_matrix[i, 2] * arm_dq[2])
    omega = inv_i @ rel
    cp, sp, cy, sy = math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    e_inv = np.array([[cy / cp, sy / cp, 0.0], [-sy, cy, 0.0], [cy * sp / cp, sy * sp / cp, 1.0]])
    d_pitch = np.array([[cy * sp / cp**2, sy * sp / cp**2, 0.0], [0.0, 0.0, 0.0], [cy / cp**2, sy / cp**2, 0.0]])
    d_yaw = np.array([[-sy / cp, cy / cp, 0.0], [-cy, -sy, 0.0], [-sy * sp / cp, cy * sp / cp, 0.0]])
    f = np.zeros(_NX)
    # dc/dt = v
    for i in range(3):
        f[i] = x0[3 + i]
        a[i, 3 + i] = 1.0
    # dv/dt = sum f / m + g (only normal forces at u_bar)
    total = fz[0] + fz[1] + fz[2] + fz[3]
    f[3], f[4], f[5] = gravity[0], gravity[1], total / mass + gravity[2]
    for foot in range(4):
        for i in range(3):
            b[3 + i, 3 * foot + i] = 1.0 / mass
    # dTheta/dt = E^-1 omega
    rate = e_inv @ inv_i
    rate_j = rate @ momentum_jacobian
    rate_a = rate @ momentum_matrix
    for i in range(3):
        f[6 + i] = e_inv[i, 0] * omega[0] + e_inv[i, 1] * omega[1] + e_inv[i, 2] * omega[2]
        a[6 + i, 7] = d_pitch[i, 0] * omega[0] + d_pitch[i, 1] * omega[1] + d_pitch[i, 2] * omega[2]
        a[6 + i, 8] = d_yaw[i, 0] * omega[0] + d_yaw[i, 1] * omega[1] + d_yaw[i, 2] * omega[2]
        for j in range(3):
            a[6 + i, 9 + j] = rate[i, j]
            a[6 + i, 12 + j] = -rate_j[i, j]
            a[6 + i, 15 + j] = -rate_a[i, j]
    # dh/dt = sum (r_i - c) x f_i
    hx = hy = hz = 0.0
    for foot in range(4):
        lx, ly, lz = feet[foot, 0] - c0, feet[foot, 1] - c1, feet[foot, 2] - c2
        hx += ly * fz[foot]
        hy += -lx * fz[foot]
        col = 3 * foot
        b[9, col + 1], b[9, col + 2] = -lz, ly
        b[10, col], b[10, col + 2] = lz, -lx
        b[11, col], b[11, col + 1] = -ly, lx
    f[9], f[10], f[11] = hx, hy, hz
    # d/dc of sum (r_i - c) x f_i = skew(sum f_i)
    a[9, 1], a[10, 0] = -total, total
    # the arm: dq_a/dt = dq_a, d dq_a/dt = ddq_a (zero at u_bar)
    for i in range(3):
        f[12 + i] = arm_dq[i]
        a[12 + i, 15 + i] = 1.0
        b[15 + i, 12 + i] = 1.0
    # d = f - a x_bar - b u_bar
    x_bar = x0.copy()
    x_bar[12:15] = arm_q
    x_bar[15:18] = arm_dq
    for r in range(_NX):
        acc = f[r]
        for s in range(_NX):
            if a[r, s] != 0.0:
                acc -= a[r, s] * x_bar[s]
        for foot in range(4):
            acc -= b[r, 3 * foot + 2] * fz[foot]
        d[r] = acc


@numba.njit(cache=True, nogil=True)
def _sparse_left(m, x, out):  # pragma: no cover
    """The product m @ x into `out`, skipping m's zero entries (m: a step's matrix, mostly zeros)."""
    out[:] = 0.0
    for r in range(m.shape[0]):
        for s in range(m.shape[1]):
            mrs = m[r, s]
            if mrs != 0.0:
                for c in range(x.shape[1]):
                    out[r, c] += mrs * x[s, c]


@numba.njit(cache=True, nogil=True)
def tail_qp(x0, x_ref, contact, feet, mass, inertia, momentum_matrix, momentum_jacobian, mass_matrix, bias, arm_q,
            arm_dq, weights, velocity_factor, arm_lower, arm_upper, vmax, stall, gravity, dt, mu, octagon, fz_min,
            fz_max, force_scale, weight_force, weight_arm_acc, arm_moves):  # pragma: no cover
    """The tail MPC's QP: `wbc.mpc.tail_mpc.TailMpc`'s build (see there for the model, cost and rows).

    Args:
        x0: current state (18,).
        x_ref: reference states x_1 .. x_N (N, 18).
        contact: stance flags per step and foot (N, 4), bool.
        feet: foot positions per step, world (N, 4, 3) [m].
        mass: the robot's mass at each step (N,) [kg].
        inertia: the composite centroidal inertia at each step (N, 3, 3) [kg m^2].
        momentum_matrix: A_arm at each step (N, 3, 3).
        momentum_jacobian: d(A_arm dq_bar)/dq_a at each step (N, 3, 3).
        mass_matrix: M_aa at each step (N, 3, 3).
        bias: b_a at each step (N, 3) [N m].
        arm_q: the arm's pose each step is linearised about (N, 3) [rad].
        arm_dq: its speed there (N, 3) [rad/s].
        weights: the 18 state weights.
        velocity_factor: the factor of the horizontal velocity weights (the commanded speed's).
        arm_lower: the arm's lower position limits, margin included (3,) [rad].
        arm_upper: its upper limits (3,) [rad].
        vmax: the arm's speed limits (3,) [rad/s].
        stall: the arm servos' stall torques (3,) [N m].
        gravity: gravity (3,) [m/s^2].
        dt: step length [s].
        mu: the pyramid's bound per axis (`wbc.mpc.centroidal_mpc.friction_per_axis`).
        octagon: also the diagonal faces, (+-f_x +- f_y) / sqrt(2) - mu f_z <= 0 (`pyramid_faces`'s octagon).
        fz_min: smallest normal force of a stance foot [N].
        fz_max: largest normal force of a foot [N].
        force_scale: the QP's force unit [N].
        weight_force: force effort [1/N^2].
        weight_arm_acc: arm acceleration effort [s^4/rad^2].
        arm_moves: whether the arm's accelerations are planned (off: boxed to zero, no servo or arm rows).

    Returns:
        (H, g, C, l, u, l_box, u_box, scale, index, free, gamma_z), as `wbc.mpc.centroidal_mpc.MpcProblem` names
        them: min 1/2 z^T H z + g^T z s.t. l <= C z <= u, l_box <= z <= u_box, U[index] = scale z, X = free +
        gamma_z z. The rows: friction pyramids (per stance foot and step: +f_x, -f_x, +f_y, -f_y, each - mu f_z <=
        0, then with `octagon` the four diagonals), then the servos' torque-speed lines (3 per step), the arm's
        positions, then its speeds along the horizon (3 per step each); the last three only when `arm_moves`.
    """
    n = x_ref.shape[0]
    # the variables: step k's stance forces (foot by foot, x y z), then its three arm accelerations
    stance = np.zeros(n, dtype=np.int64)
    offset = np.zeros(n + 1, dtype=np.int64)
    for k in range(n):
        for foot in range(4):
            if contact[k, foot]:
                stance[k] += 1
        offset[k + 1] = offset[k] + 3 * stance[k] + 3
    nz = offset[n]
    index = np.empty(nz, dtype=np.int64)
    scale = np.empty(nz)
    for k in range(n):
        p = offset[k]
        for foot in range(4):
            if contact[k, foot]:
                for i in range(3):
                    index[p], scale[p] = k * _NU + 3 * foot + i, force_scale
                    p += 1
        for i in range(3):
            index[p], scale[p] = k * _NU + 12 + i, 1.0
            p += 1
    # per step: the discrete model x+ = A_d x + B_d u + d_d; the free response; Gamma's blocks
    a_d = np.empty((n, _NX, _NX))
    free = np.empty(n * _NX)
    gamma_z = np.zeros((n * _NX, nz))
    eye = np.eye(_NX)
    h3, h6 = dt * dt / 2, dt * dt * dt / 6
    a = np.zeros((_NX, _NX))
    b = np.zeros((_NX, _NU))
    d = np.empty(_NX)
    fz = np.empty(4)
    aa = np.empty((_NX, _NX))
    phi = np.empty((_NX, _NX))
    ap = np.empty((_NX, _NX))
    b_z = np.empty((_NX, 15))
    for k in range(n):
        share = mass[k] * -gravity[2] / max(1, stance[k])
        for foot in range(4):
            fz[foot] = share if contact[k, foot] else 0.0
        a[:] = 0.0
        b[:] = 0.0
        _step_model(x0, fz, feet[k], mass[k], inertia[k], momentum_matrix[k], momentum_jacobian[k], arm_q[k],
                    arm_dq[k], gravity, a, b, d)
        # the zero-order hold, third order in dt: Phi = I dt + A dt^2/2 + A^2 dt^3/6; A_d = I + A Phi
        _sparse_left(a, a, aa)
        for r in range(_NX):
            for s in range(_NX):
                phi[r, s] = eye[r, s] * dt + a[r, s] * h3 + aa[r, s] * h6
        _sparse_left(a, phi, ap)
        a_d[k] = eye + ap
        # the chosen columns of B_d = Phi B, scaled to the QP's units
        m = offset[k + 1] - offset[k]
        p = 0
        for foot in range(4):
            if contact[k, foot]:
                for i in range(3):
                    col = 3 * foot + i
                    for r in range(_NX):
                        acc = 0.0
                        for s in range(_NX):
                            if b[s, col] != 0.0:
                                acc += phi[r, s] * b[s, col]
                        b_z[r, p] = acc * force_scale
                    p += 1
        for i in range(3):
            for r in range(_NX):
                b_z[r, p] = phi[r, 15 + i]  # B's arm columns are unit vectors
            p += 1
        # free response and Gamma's row block k: A_d times the previous one, plus this step's own columns
        row = k * _NX
        for r in range(_NX):
            acc = 0.0
            for s in range(_NX):
                acc += phi[r, s] * d[s]
            previous = 0.0
            for s in range(_NX):
                previous += a_d[k, r, s] * (x0[s] if k == 0 else free[row - _NX + s])
            free[row + r] = previous + acc
        if k > 0:
            _sparse_left(a_d[k], gamma_z[row - _NX:row, :offset[k]], gamma_z[row:row + _NX, :offset[k]])
        gamma_z[row:row + _NX, offset[k]:offset[k] + m] = b_z[:, :m]
    # cost: sum_k ||x_k - x_ref_k||_W^2 + ||u||_R^2, summed backwards (see the module)
    w = np.empty(_NX)
    for r in range(_NX):
        w[r] = weights[r]
    w[3] *= velocity_factor
    w[4] *= velocity_factor
    h = np.zeros((nz, nz))
    g = np.zeros(nz)
    p_mat = np.zeros((_NX, _NX))
    s_vec = np.zeros(_NX)
    tmp = np.empty((_NX, _NX))
    q_blk = np.empty((_NX, 15))
    for j in range(n - 1, -1, -1):
        row = j * _NX
        if j == n - 1:
            p_mat[:] = 0.0
            s_vec[:] = 0.0
        else:
            # P_j = W_j + A_{j+1}^T P_{j+1} A_{j+1}, s_j = W_j e_j + A_{j+1}^T s_{j+1}
            _sparse_left(p_mat, a_d[j + 1], tmp)  # P A (P is dense: the zero test only costs a compare)
            nxt = a_d[j + 1]
            p_new = np.zeros((_NX, _NX))
            s_new = np.zeros(_NX)
            for s in range(_NX):
                for r in range(_NX):
                    ars = nxt[r, s]
                    if ars != 0.0:
                        s_new[s] += ars * s_vec[r]
                        for c in range(_NX):
                            p_new[s, c] += ars * tmp[r, c]
            p_mat[:] = p_new
            s_vec[:] = s_new
        for r in range(_NX):
            p_mat[r, r] += w[r]
            s_vec[r] += w[r] * (free[row + r] - x_ref[j, r])
        # Q_j = P_j B_j; g_j = B_j^T s_j; H[i, j] = Gamma[j, i]^T Q_j for the columns i <= j (upper triangle)
        m_j, o_j = offset[j + 1] - offset[j], offset[j]
        q_blk[:, :m_j] = 0.0
        for r in range(_NX):
            for s in range(_NX):
                prs = p_mat[r, s]
                for c in range(m_j):
                    q_blk[r, c] += prs * gamma_z[row + s, o_j + c]
        for r in range(_NX):
            sr = s_vec[r]
            for c in range(m_j):
                g[o_j + c] += gamma_z[row + r, o_j + c] * sr
        for r in range(_NX):
            for col in range(o_j + m_j):
                grc = gamma_z[row + r, col]
                if grc != 0.0:
                    for c in range(m_j):
                        h[col, o_j + c] += grc * q_blk[r, c]
    for i in range(nz):
        for j in range(i):
            h[i, j] = h[j, i]
        h[i, i] += (weight_force if index[i] % _NU < 12 else weight_arm_acc) * scale[i] * scale[i]
    # boxes: forces within their friction box, the arm's accelerations within what any torque allows
    l_box = np.empty(nz)
    u_box = np.empty(nz)
    top = fz_max / force_scale
    arm_limit = 1e3 if arm_moves else 0.0
    for i in range(nz):
        kind = index[i] % _NU
        if kind >= 12:
            l_box[i], u_box[i] = -arm_limit, arm_limit
        elif kind % 3 == 2:
            l_box[i], u_box[i] = fz_min / force_scale, top
        else:
            l_box[i], u_box[i] = -mu * top, mu * top
    # rows: friction pyramids, then (a moving arm) its servos, positions and speeds
    feet_total = 0
    for k in range(n):
        feet_total += stance[k]
    faces = 8 if octagon else 4
    rows = faces * feet_total + (9 * n if arm_moves else 0)
    cmat = np.zeros((rows, nz))
    lo = np.empty(rows)
    hi = np.empty(rows)
    r = 0
    for i in range(nz):
        kind = index[i] % _NU
        if kind < 12 and kind % 3 == 2:
            for axis in range(2):
                for sign in (1.0, -1.0):
                    cmat[r, i - 2 + axis] = sign * scale[i - 2 + axis]
                    cmat[r, i] = -mu * scale[i]
                    lo[r], hi[r] = -np.inf, 0.0
                    r += 1
            if octagon:  # the faces of `wbc.mpc.centroidal_mpc.pyramid_faces`' octagon, in its order
                d = 1.0 / math.sqrt(2.0)
                for sx, sy in ((d, d), (d, -d), (-d, d), (-d, -d)):
                    cmat[r, i - 2] = sx * scale[i - 2]
                    cmat[r, i - 1] = sy * scale[i - 1]
                    cmat[r, i] = -mu * scale[i]
                    lo[r], hi[r] = -np.inf, 0.0
                    r += 1
    if arm_moves:
        for k in range(n):
            first = offset[k + 1] - 3
            for i in range(3):
                upper = min(max(stall[i] * (1.0 - arm_dq[k, i] / vmax[i]), -stall[i]), stall[i])
                lower = min(max(-stall[i] * (1.0 + arm_dq[k, i] / vmax[i]), -stall[i]), stall[i])
                for j in range(3):
                    cmat[r, first + j] = mass_matrix[k, i, j]
                lo[r], hi[r] = lower - bias[k, i], upper - bias[k, i]
                r += 1
        for part in range(2):
            for k in range(n):
                for i in range(3):
                    state = k * _NX + 12 + 3 * part + i
                    if part == 0:
                        low, high = min(arm_lower[i], x0[12 + i]), max(arm_upper[i], x0[12 + i])
                    else:
                        low, high = min(-vmax[i], x0[15 + i]), max(vmax[i], x0[15 + i])
                    cmat[r, :] = gamma_z[state, :]
                    lo[r], hi[r] = low - free[state], high - free[state]
                    r += 1
    return h, g, cmat, lo, hi, l_box, u_box, scale, index, free, gamma_z


@numba.njit(cache=True, nogil=True)
def arm_path_rows(rows, first, start, acc, tau, torque):  # pragma: no cover - compiled
    """The arm's command rows on its planned path, `tau` [s] into a step; whether the arm's rows are all finite.

    Position ``q + dq tau + acc tau^2 / 2`` and speed ``dq + acc tau`` from the step's start (`start`: q (3), dq (3))
    under its constant acceleration `acc` (3,), and the feed-forward `torque` (3,), into the three columns of `rows`
    (5, n) from `first`; the same operations in the same order as the numpy expressions they replace.
    """
    for i in range(3):
        j = first + i
        rows[0, j] = start[i] + start[3 + i] * tau + 0.5 * acc[i] * tau * tau
        rows[1, j] = start[3 + i] + acc[i] * tau
        rows[4, j] = torque[i]
    for r in range(rows.shape[0]):
        for i in range(3):
            if not math.isfinite(rows[r, first + i]):
                return False
    return True
