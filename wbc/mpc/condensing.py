"""The MPC update's arithmetic, compiled (numba): the centroidal model's linearisation and the condensed dynamics.

Every MPC update linearises the centroidal model once, discretises it and condenses the states out of the horizon
(X = free + Gamma U). In numpy that was a few dozen small array operations (batched products, scatters, fancy
indexing) costing ~0.5-0.9 ms per update, more than the QP solve. Here each is one compiled call: the products are
15 x 15 by 15 x 16 blocks, written as loops whose innermost runs along a contiguous row, which the compiler
vectorises.

`linearize` is the only implementation of the model's f and its analytic Jacobians (`CentroidalModel` calls it; the
tests check it against CasADi's automatic derivatives and finite differences). `condense` is the condensing of
`CentroidalMpc.build`; the tests check its prediction against stepping the discretised dynamics one step at a time.

Compiled functions are cached on disk beside this module (numba's ``cache=True``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from wbc.robots.conventions import G

__all__ = ["condense", "linearize"]

_NX = 15
_NU = 15


@numba.njit(cache=True, nogil=True)
def linearize(x, u, inv_i, a_arm, feet, mass, f, a, b):  # pragma: no cover - compiled
    """f(x, u) into `f` (15,), df/dx into `a` (15, 15) and df/du into `b` (15, 15), every entry written.

    Args:
        x: state (15,).
        u: input (15,).
        inv_i: inverse composite inertia, world axes (3, 3).
        a_arm: arm momentum matrix (3, 3).
        feet: foot positions (4, 3) [m].
        mass: total mass [kg].
        f: out, (15,).
        a: out, (15, 15).
        b: out, (15, 15).
    """
    pitch, yaw = x[7], x[8]
    cp, sp, cy, sy = math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    e_inv = np.empty((3, 3))
    e_inv[0, 0], e_inv[0, 1], e_inv[0, 2] = cy / cp, sy / cp, 0.0
    e_inv[1, 0], e_inv[1, 1], e_inv[1, 2] = -sy, cy, 0.0
    e_inv[2, 0], e_inv[2, 1], e_inv[2, 2] = cy * sp / cp, sy * sp / cp, 1.0
    # omega = I^-1 (h - A_arm dq_a)
    hh = np.empty(3)
    for r in range(3):
        hh[r] = x[9 + r] - (a_arm[r, 0] * u[12] + a_arm[r, 1] * u[13] + a_arm[r, 2] * u[14])
    omega = np.empty(3)
    for r in range(3):
        omega[r] = inv_i[r, 0] * hh[0] + inv_i[r, 1] * hh[1] + inv_i[r, 2] * hh[2]
    total = np.zeros(3)
    for i in range(4):
        for c in range(3):
            total[c] += u[3 * i + c]
    a[:, :] = 0.0
    b[:, :] = 0.0
    for c in range(3):
        f[c] = x[3 + c]
        f[3 + c] = total[c] / mass
        f[6 + c] = e_inv[c, 0] * omega[0] + e_inv[c, 1] * omega[1] + e_inv[c, 2] * omega[2]
        f[12 + c] = u[12 + c]
        a[c, 3 + c] = 1.0
        b[12 + c, 12 + c] = 1.0
    f[5] -= G
    s_ = omega[0] * cy + omega[1] * sy
    ds = -omega[0] * sy + omega[1] * cy
    # d(E^-1 omega)/d(pitch, yaw); roll does not enter
    a[6, 7], a[7, 7], a[8, 7] = s_ * sp / cp**2, 0.0, s_ / cp**2
    a[6, 8], a[7, 8], a[8, 8] = ds / cp, -s_, ds * sp / cp
    for r in range(3):
        for c in range(3):
            ei = e_inv[r, 0] * inv_i[0, c] + e_inv[r, 1] * inv_i[1, c] + e_inv[r, 2] * inv_i[2, c]
            a[6 + r, 9 + c] = ei
    for r in range(3):
        for c in range(3):
            b[6 + r, 12 + c] = -(a[6 + r, 9] * a_arm[0, c] + a[6 + r, 10] * a_arm[1, c] + a[6 + r, 11] * a_arm[2, c])
    # dh/dc = [sum f]x ; dh/df_i = [r_i - c]x
    a[9, 1], a[9, 2] = -total[2], total[1]
    a[10, 0], a[10, 2] = total[2], -total[0]
    a[11, 0], a[11, 1] = -total[1], total[0]
    inv_m = 1.0 / mass
    for i in range(4):
        for c in range(3):
            b[3 + c, 3 * i + c] = inv_m
        rx, ry, rz = feet[i, 0] - x[0], feet[i, 1] - x[1], feet[i, 2] - x[2]
        col = 3 * i
        b[9, col + 1], b[9, col + 2] = -rz, ry
        b[10, col], b[10, col + 2] = rz, -rx
        b[11, col], b[11, col + 1] = -ry, rx
    for r in range(3):
        acc = 0.0
        for j in range(12):
            acc += b[9 + r, j] * u[j]
        f[9 + r] = acc


@numba.njit(cache=True, nogil=True)
def _matmul_into(out, left, right):  # pragma: no cover - compiled
    """Into `out`, left @ right, for small C-contiguous matrices; the innermost loop runs along rows (vectorised)."""
    n, m = left.shape
    p = right.shape[1]
    for i in range(n):
        for j in range(p):
            out[i, j] = 0.0
        for k in range(m):
            lik = left[i, k]
            if lik != 0.0:
                for j in range(p):
                    out[i, j] += lik * right[k, j]


@numba.njit(cache=True, nogil=True)
def condense(a_c, b_c, d_c, dt, x0, x_ref, feet, idx, scale, q_root, r_diag, gamma_z, free, h,
             g):  # pragma: no cover - compiled
    """The condensed QP of one update: ``X = free + gamma_z z`` over the horizon, its Hessian and gradient.

    The model is linearised once (about x0): x' = A_c x + B_k u + d_k, where each step's B_k has its own lever arms
    (each foot's planned position about the step's reference CoM, the current CoM for the first) and d_k the
    matching affine torque term -[sum f]x (c_ref_k - c_0); discretised by a zero-order hold third-order in dt. Only the
    decision variables' columns of the condensed input matrix are formed (`idx`, in the QP's units `scale`), and the
    Hessian ``gamma_z^T Q gamma_z + diag(r scale^2)`` skips the rows where a column is zero: a variable of step j
    moves the states from step j on only.

    Args:
        a_c: df/dx (15, 15).
        b_c: df/du (15, 15) at x0 (its lever arms are replaced per step).
        d_c: the affine term f0 - A_c x0 - B_c u_bar (15,).
        dt: step length [s].
        x0: current state (15,).
        x_ref: reference states x_1 .. x_N (N, 15).
        feet: foot positions per step, world (N, 4, 3) [m].
        idx: the decision variables' positions in the full input vector (n,), ascending.
        scale: their units (n,).
        q_root: square roots of the state weights, stacked over the horizon (N 15,).
        r_diag: input weights, stacked over the horizon (N 15,).
        gamma_z: out, (N 15, n).
        free: out, the states under zero input (N 15,).
        h: out, the Hessian (n, n).
        g: out, the gradient (n,).
    """
    n = x_ref.shape[0]
    nv = idx.shape[0]
    # integ = int_0^dt exp(A s) ds (third order), A_d = I + A_c integ
    a2 = np.empty((_NX, _NX))
    _matmul_into(a2, a_c, a_c)
    integ = np.empty((_NX, _NX))
    for i in range(_NX):
        for j in range(_NX):
            integ[i, j] = a_c[i, j] * (dt * dt / 2.0) + a2[i, j] * (dt * dt * dt / 6.0)
        integ[i, i] += dt
    a_d = np.empty((_NX, _NX))
    _matmul_into(a_d, a_c, integ)
    for i in range(_NX):
        a_d[i, i] += 1.0
    # x0's own propagation: A_d^(k+1) x0
    p = x0.copy()
    q = np.empty(_NX)
    for k in range(n):
        for i in range(_NX):
            acc = 0.0
            for j in range(_NX):
                acc += a_d[i, j] * p[j]
            q[i] = acc
        p[:] = q
        free[k * _NX:(k + 1) * _NX] = q
    # the variables of each step: columns first[j] .. first[j + 1] - 1 (idx ascends)
    first = np.empty(n + 1, dtype=np.int64)
    c = 0
    for j in range(n):
        while c < nv and idx[c] < j * _NU:
            c += 1
        first[j] = c
    first[n] = nv
    gamma_z[:, :] = 0.0
    aug = np.empty((_NX, _NU + 1))
    cur = np.empty((_NX, _NU + 1))
    nxt = np.empty((_NX, _NU + 1))
    for j in range(n):
        # the step's input matrix with its affine term as one more column, then through the hold
        for r in range(_NX):
            for col in range(_NU):
                aug[r, col] = b_c[r, col]
            aug[r, _NU] = d_c[r]
        cx = x0[0] if j == 0 else x_ref[j - 1, 0]
        cy = x0[1] if j == 0 else x_ref[j - 1, 1]
        cz = x0[2] if j == 0 else x_ref[j - 1, 2]
        for i in range(4):
            rx, ry, rz = feet[j, i, 0] - cx, feet[j, i, 1] - cy, feet[j, i, 2] - cz
            col = 3 * i
            aug[9, col], aug[9, col + 1], aug[9, col + 2] = 0.0, -rz, ry
            aug[10, col], aug[10, col + 1], aug[10, col + 2] = rz, 0.0, -rx
            aug[11, col], aug[11, col + 1], aug[11, col + 2] = -ry, rx, 0.0
        dx, dy, dz = cx - x0[0], cy - x0[1], cz - x0[2]
        for r in range(3):  # -[sum f]x (c_ref - c0), with [sum f]x = a_c[9:12, 0:3]
            aug[9 + r, _NU] -= a_c[9 + r, 0] * dx + a_c[9 + r, 1] * dy + a_c[9 + r, 2] * dz
        _matmul_into(cur, integ, aug)
        # block (k, j) = A_d^(k - j) B_j for k >= j
        for k in range(j, n):
            if k > j:
                _matmul_into(nxt, a_d, cur)
                cur[:, :] = nxt
            for r in range(_NX):
                row = k * _NX + r
                for cc in range(first[j], first[j + 1]):
                    gamma_z[row, cc] = cur[r, idx[cc] - j * _NU] * scale[cc]
                free[row] += cur[r, _NU]
    # H = gamma_z^T Q gamma_z + diag(r scale^2), g = gamma_z^T Q (free - x_ref), accumulated row by row over the
    # columns that live in the row (those of steps up to the row's): each update runs along a contiguous row, with
    # no reduction in the innermost loop, so it vectorises with the rounding of plain sums
    h[:, :] = 0.0
    g[:] = 0.0
    wrow = np.empty(nv)
    for k in range(n):
        live = first[k + 1]
        for r in range(k * _NX, (k + 1) * _NX):
            w = q_root[r]
            e = w * w * (free[r] - x_ref[k, r - k * _NX])
            for a in range(live):
                wrow[a] = w * gamma_z[r, a]
                g[a] += gamma_z[r, a] * e
            for a in range(live):
                wa = wrow[a]
                if wa != 0.0:
                    for b in range(a, live):
                        h[a, b] += wa * wrow[b]
    for b in range(nv):
        h[b, b] += r_diag[idx[b]] * scale[b] * scale[b]
        for a in range(b):
            h[b, a] = h[a, b]
