"""Centroidal dynamics with the arm's momentum: the model the MPC plans with.

State x (15): CoM position c (world, 3), CoM velocity v (world, 3), base orientation Theta = (roll, pitch, yaw)
(ZYX Euler, 3), centroidal angular momentum h (about the CoM, world axes, 3), arm joint positions q_a (3).
Input u (15): contact forces f_i at the four feet FR, FL, RR, RL (world, 3 each), arm joint velocities dq_a (3).

    dc/dt     = v
    dv/dt     = sum_i f_i / m + g
    dTheta/dt = E(Theta)^-1 omega,   omega = I_c^-1 (h - A_arm dq_a)
    dh/dt     = sum_i (r_i - c) x f_i
    dq_a/dt   = dq_a

I_c is the composite centroidal inertia and A_arm the arm's columns of the angular rows of Pinocchio's centroidal
momentum matrix (h = I_c omega + A_arm dq_a + legs), both in world axes and refreshed at every MPC update from the
current configuration (`CentroidalParams.from_pinocchio`); r_i are the foot positions. The legs' own momentum is
neglected (stance legs barely move relative to the body). Because the arm's momentum appears in the orientation
equation, an arm swing turns the body at constant h: the optimiser can use the arm like a tail.

`CentroidalModel` evaluates f and its analytic Jacobians, compiled (`wbc.mpc.condensing.linearize`; the MPC
linearises once per update about the current state), and discretises them. The same dynamics are also built once as
a CasADi expression from numeric parameters (the registry's Pinocchio wheels have no ``pinocchio.casadi``): the tests
check the analytic Jacobians against CasADi's and against finite differences.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from wbc.estimation.kinematics import CentroidalParams
from wbc.mpc.condensing import linearize as _linearize
from wbc.robots.conventions import GRAVITY

__all__ = ["NX", "NU", "NF", "COM", "COM_VEL", "RPY", "MOMENTUM", "ARM_Q", "FORCES", "ARM_DQ",
           "CentroidalParams", "CentroidalModel", "SymbolicCentroidalModel", "euler_rates_matrix", "expm", "skew",
           "zoh_integral"]

NX = 15
NU = 15
NF = 12  # force inputs
COM = slice(0, 3)
"""CoM position c in the state x [m]."""
COM_VEL = slice(3, 6)
"""CoM velocity v in the state x [m/s]."""
RPY = slice(6, 9)
"""Base orientation Theta (roll, pitch, yaw; ZYX Euler) in the state x [rad]."""
MOMENTUM = slice(9, 12)
"""Centroidal angular momentum h in the state x [kg m^2/s]."""
ARM_Q = slice(12, 15)
"""Arm joint positions q_a in the state x [rad]."""
FORCES = slice(0, 12)
"""Contact forces f_FR, f_FL, f_RR, f_RL in the input u [N]."""
ARM_DQ = slice(12, 15)
"""Arm joint velocities dq_a in the input u [rad/s]."""


def euler_rates_matrix(theta: np.ndarray) -> np.ndarray:
    """E(Theta) with omega_world = E(Theta) dTheta/dt for ZYX Euler angles (roll, pitch, yaw)."""
    _, p, y = theta
    cp, sp, cy, sy = np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([[cy * cp, -sy, 0.0], [sy * cp, cy, 0.0], [-sp, 0.0, 1.0]])


def skew(v: np.ndarray) -> np.ndarray:
    """The cross-product matrix of a 3-vector: multiplying by it is the cross product with that vector."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def zoh_integral(a: np.ndarray, dt: float) -> np.ndarray:
    """Integral of exp(A s) ds over [0, dt], third order in dt: the zero-order-hold input factor."""
    return np.eye(a.shape[0]) * dt + a * (dt**2 / 2) + (a @ a) * (dt**3 / 6)


def expm(a: np.ndarray) -> np.ndarray:
    """Matrix exponential by scaling and squaring with a 12-term Taylor series (small dense matrices)."""
    norm = np.linalg.norm(a, 1)
    s = max(0, int(np.ceil(np.log2(norm))) + 1) if norm > 0.5 else 0
    x = a / (2.0**s)
    term = np.eye(a.shape[0])
    out = term.copy()
    for k in range(1, 13):
        term = term @ x / k
        out = out + term
    for _ in range(s):
        out = out @ out
    return out


class CentroidalModel:
    """The continuous dynamics f(x, u; params), their analytic Jacobians and a fast discretisation."""

    def dynamics(self, x: np.ndarray, u: np.ndarray, params: CentroidalParams) -> np.ndarray:
        """dx/dt at (x, u)."""
        return self.linearize(x, u, params, jacobians=False)[0]

    def linearize(self, x: np.ndarray, u: np.ndarray, params: CentroidalParams, *, jacobians: bool = True
                  ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """f(x, u), df/dx (15 x 15) and df/du (15 x 15) (compiled: `wbc.mpc.condensing.linearize`)."""
        f, a, b = np.empty(NX), np.empty((NX, NX)), np.empty((NX, NU))
        _linearize(np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(u, dtype=np.float64),
                   params.inverse_inertia, params.arm_momentum_matrix, params.feet_world, float(params.mass), f, a, b)
        return (f, a, b) if jacobians else (f, None, None)

    def discretize(self, x: np.ndarray, u: np.ndarray, params: CentroidalParams, dt: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Zero-order-hold discretisation of the linearisation about (x, u), third-order in dt.

        Returns (A_d, B_d, d_d) with x_next ~= A_d x + B_d u + d_d. The force-to-position chain (c <- v <- f) is
        second order and so exact; the neglected terms are O(dt^4).
        """
        f, a, b = self.linearize(x, u, params)
        d = f - a @ x - b @ u
        phi = zoh_integral(a, dt)
        return np.eye(NX) + a @ phi, phi @ b, phi @ d


class SymbolicCentroidalModel:
    """The same dynamics as a CasADi expression with its automatic Jacobians (a reference for tests)."""

    def __init__(self) -> None:
        x = ca.SX.sym("x", NX)
        u = ca.SX.sym("u", NU)
        p = ca.SX.sym("p", 1 + 9 + 9 + 12)
        mass = p[0]
        inv_i = ca.reshape(p[1:10], 3, 3).T  # row-major ravel in numpy
        a_arm = ca.reshape(p[10:19], 3, 3).T
        feet = ca.reshape(p[19:31], 3, 4).T
        c, v, th, h = x[0:3], x[3:6], x[6:9], x[9:12]
        forces = ca.reshape(u[0:12], 3, 4).T
        dqa = u[12:15]
        total_force = ca.sum1(forces).T
        torque = ca.SX.zeros(3)
        for i in range(4):
            torque += ca.cross(feet[i, :].T - c, forces[i, :].T)
        omega = inv_i @ (h - a_arm @ dqa)
        cp, sp, cy, sy = ca.cos(th[1]), ca.sin(th[1]), ca.cos(th[2]), ca.sin(th[2])
        e = ca.vertcat(ca.horzcat(cy * cp, -sy, 0), ca.horzcat(sy * cp, cy, 0), ca.horzcat(-sp, 0, 1))
        theta_dot = ca.solve(e, omega)
        xdot = ca.vertcat(v, total_force / mass + ca.DM(GRAVITY), theta_dot, torque, dqa)
        self._f = ca.Function("centroidal_dynamics", [x, u, p], [xdot])
        self._jac = ca.Function("f_jacobians", [x, u, p], [xdot, ca.jacobian(xdot, x), ca.jacobian(xdot, u)])

    def linearize(self, x: np.ndarray, u: np.ndarray, params: CentroidalParams
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """f(x, u), df/dx and df/du by CasADi's automatic differentiation."""
        f, a, b = self._jac(x, u, params.vector())
        return np.asarray(f).ravel(), np.asarray(a), np.asarray(b)

    @staticmethod
    def exact_discretization(a: np.ndarray, b: np.ndarray, d: np.ndarray, dt: float
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Zero-order hold by the matrix exponential of [[A, B, d], [0, 0, 0]] dt (the reference)."""
        n, m = a.shape[0], b.shape[1]
        big = np.zeros((n + m + 1, n + m + 1))
        big[:n, :n] = a
        big[:n, n:n + m] = b
        big[:n, -1] = d
        e = expm(big * dt)
        return e[:n, :n], e[:n, n:n + m], e[:n, -1]
