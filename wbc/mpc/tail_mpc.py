"""`TailMpc`: the centroidal MPC with the arm as a tail, its joint accelerations the inputs the servos bound.

State x (18): CoM position c, CoM velocity v, base orientation Theta (roll, pitch, yaw; ZYX Euler), centroidal
angular momentum h, arm joint positions q_a, arm joint velocities dq_a. Input u (15): the four feet's contact forces
(world), the arm's joint accelerations ddq_a.

    dc/dt = v                         dv/dt = sum_i f_i / m + g
    dTheta/dt = E(Theta)^-1 omega,    omega = I_c^-1 (h - A_arm(q_a) dq_a)
    dh/dt = sum_i (r_i - c) x f_i     dq_a/dt = dq_a,   d dq_a/dt = ddq_a

It differs from `wbc.mpc.centroidal_mpc.CentroidalMpc` (arm velocities as inputs, A_arm frozen at the current pose)
where a tail needs it to:

- the arm's momentum matrix and its derivative along the arm's pose (`wbc.mpc.tail_model.arm_tail`) are evaluated
  at every step's planned arm pose (the previous plan's, shifted), so a swing that extends the arm is planned with
  the leverage it gains;
- the arm's accelerations are bounded by its servos: M_aa ddq_a + b_a must lie within the torque-speed line of each
  servo at the planned speed (`wbc.mpc.tail_model.servo_torque_bounds`), and its speeds and positions within their
  limits along the horizon;
- the arm is pulled towards a ready pose (chosen for its leverage by the controller) only lightly, so that the
  orientation error, not the pose, decides what the arm does.

The model is linearised per step about (x0 with that step's arm pose and speed, the gravity-compensating forces),
discretised by a zero-order hold third-order in dt and condensed (X = free + Gamma U); only the stance forces and
the arm's accelerations are variables. The QP is dense and solved by DAQP, warm-started from the previous plan.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import daqp
import numpy as np

from wbc.config_checks import check_number
from wbc.mpc.centroidal_mpc import MAX_WEIGHT, MpcProblem, MpcSolveError, arm_box, check_force_terms, friction_per_axis
from wbc.mpc.qp_solvers import RESIDUAL_TOLERANCE, constraint_violation
from wbc.mpc.tail_compiled import tail_qp
from wbc.mpc.tail_model import ArmTail, ArmTailPath
from wbc.robots.conventions import GRAVITY

__all__ = ["TNX", "TNU", "TailMpc", "TailMpcConfig", "TailPlan", "TailStep"]

TNX = 18
"""State size: c, v, Theta, h, q_a, dq_a."""
TNU = 15
"""Input size: four feet's forces, the arm's accelerations."""
ARM_Q = slice(12, 15)
ARM_DQ = slice(15, 18)
ARM_ACC = slice(12, 15)
_GRAVITY = np.ascontiguousarray(GRAVITY, dtype=np.float64)


@dataclass(frozen=True, kw_only=True)
class TailMpcConfig:
    """Settings of `TailMpc` (the force and body terms as `wbc.mpc.centroidal_mpc.MpcConfig`'s).

    Attributes:
        horizon: steps N.
        dt: step length [s].
        mu: friction coefficient of the feet's friction cone.
        pyramid: how the friction cone of `mu` becomes linear rows, as `wbc.mpc.centroidal_mpc.MpcConfig.pyramid`
            (``octagon``, the octagon inside the cone, by default).
        fz_min: smallest normal force of a stance foot [N].
        fz_max: largest normal force of a foot [N].
        force_scale: the QP's force unit [N].
        weight_com, weight_vel, weight_rpy, weight_momentum: state error weights (x, y, z or roll, pitch, yaw).
        weight_arm_q: pull of the arm towards its ready pose.
        weight_arm_dq: pull of the arm's speeds towards zero.
        weight_force: force effort [1/N^2].
        weight_arm_acc: arm acceleration effort [s^4/rad^2].
        arm_margin: keep the planned arm this far inside its joint limits [rad].
        full_weight_speed: commanded speed from which the horizontal velocity weights hold in full [m/s].
        standstill_weight_factor: their factor at a zero command.
        arm_moves: plan the arm's accelerations (off: the arm is held where it is, its accelerations fixed at zero,
            an ablation that keeps everything else of the tail MPC).

    Raises:
        ConfigError: what `MpcConfig` refuses in the settings they share (`wbc.mpc.centroidal_mpc.check_force_terms`),
            or a negative, non-finite or above `MAX_WEIGHT` (1e12) arm weight.
    """

    horizon: int = 10
    dt: float = 0.032
    mu: float = 0.4
    pyramid: str = "octagon"
    fz_min: float = 10.0
    fz_max: float = 250.0
    force_scale: float = 100.0
    weight_com: tuple[float, float, float] = (40.0, 40.0, 400.0)
    weight_vel: tuple[float, float, float] = (20.0, 20.0, 10.0)
    weight_rpy: tuple[float, float, float] = (100.0, 100.0, 100.0)
    weight_momentum: tuple[float, float, float] = (2.0, 2.0, 2.0)
    weight_arm_q: tuple[float, float, float] = (0.5, 0.5, 0.5)
    weight_arm_dq: tuple[float, float, float] = (0.02, 0.02, 0.02)
    weight_force: float = 1e-5
    weight_arm_acc: float = 1e-5
    arm_margin: float = 0.05
    full_weight_speed: float = 1.0
    standstill_weight_factor: float = 0.25
    arm_moves: bool = True

    def __post_init__(self) -> None:
        friction_per_axis(self.mu, self.pyramid, "TailMpcConfig")
        check_force_terms(self, "TailMpcConfig")
        check_number("TailMpcConfig.weight_arm_dq", self.weight_arm_dq, at_least=0.0, at_most=MAX_WEIGHT, size=3)
        check_number("TailMpcConfig.weight_arm_acc", self.weight_arm_acc, at_least=0.0, at_most=MAX_WEIGHT)

    @property
    def mu_axis(self) -> float:
        """The bound on |f_x| / f_z and |f_y| / f_z of the pyramid (`pyramid`)."""
        return friction_per_axis(self.mu, self.pyramid, "TailMpcConfig")

    def state_weights(self) -> np.ndarray:
        """The 18 state weights, in the state's order."""
        return np.concatenate([self.weight_com, self.weight_vel, self.weight_rpy, self.weight_momentum,
                               self.weight_arm_q, self.weight_arm_dq]).astype(np.float64)


@dataclass(frozen=True)
class TailStep:
    """What one step of the horizon is linearised with.

    Attributes:
        tail: the arm's momentum and dynamics at the step's planned arm pose and speed (`arm_tail`).
        arm_q: that pose [rad].
        arm_dq: that speed [rad/s].
    """

    tail: ArmTail
    arm_q: np.ndarray
    arm_dq: np.ndarray


@dataclass
class TailPlan:
    """A solved update.

    Attributes:
        states: predicted states x_1 .. x_N, shape (N, 18).
        forces: contact forces per step, foot (FR, FL, RR, RL) and axis, world, shape (N, 4, 3) [N].
        arm_acceleration: the arm's joint accelerations per step, shape (N, 3) [rad/s^2].
        iterations: the QP solver's iterations.
        setup_s: time to build the QP [s].
        solve_s: time to solve it [s].
        z: the QP's solution (scaled variables).
        variables: the full scaled input vector (N 15,), zero where no variable was.
    """

    states: np.ndarray
    forces: np.ndarray
    arm_acceleration: np.ndarray
    iterations: int
    setup_s: float
    solve_s: float
    z: np.ndarray
    variables: np.ndarray

    @property
    def arm_velocity(self) -> np.ndarray:
        """The planned arm speeds at the end of each step, shape (N, 3) [rad/s]."""
        return self.states[:, ARM_DQ]

    def warm_start(self) -> np.ndarray:
        """The plan shifted one step, as a full scaled input vector for the next update."""
        n = self.forces.shape[0]
        steps = self.variables.reshape(n, TNU)
        return np.concatenate([steps[1:], steps[-1:]]).ravel()


def euler_rate_jacobians(theta: np.ndarray, omega: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """E(Theta)^-1 (the world angular velocity to ZYX Euler rates) and d(E^-1 omega)/dTheta at `theta`."""
    _, p, y = theta
    cp, sp, cy, sy = math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    e_inv = np.array([[cy / cp, sy / cp, 0.0], [-sy, cy, 0.0], [cy * sp / cp, sy * sp / cp, 1.0]])
    d_pitch = np.array([[cy * sp / cp**2, sy * sp / cp**2, 0.0], [0.0, 0.0, 0.0], [cy / cp**2, sy / cp**2, 0.0]])
    d_yaw = np.array([[-sy / cp, cy / cp, 0.0], [-cy, -sy, 0.0], [-sy * sp / cp, cy * sp / cp, 0.0]])
    jac = np.zeros((3, 3))
    jac[:, 1] = d_pitch @ omega
    jac[:, 2] = d_yaw @ omega
    return e_inv, jac


def skew(v: np.ndarray) -> np.ndarray:
    """The cross-product matrix of a 3-vector."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def tail_dynamics(x: np.ndarray, u: np.ndarray, step: TailStep, feet: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """f(x, u) and its Jacobians df/dx (18 x 18), df/du (18 x 15).

    The arm's momentum is linearised about the step's arm pose and speed: A_arm(q_a) dq_a ~ A dq_a + J (q_a - q_bar),
    J = d(A_arm dq_bar)/dq_a there.
    """
    tail = step.tail
    c, v, theta, h = x[0:3], x[3:6], x[6:9], x[9:12]
    q_a, dq_a = x[ARM_Q], x[ARM_DQ]
    forces = u[:12].reshape(4, 3)
    inv_i = np.linalg.inv(tail.inertia_world)
    arm_h = tail.momentum_matrix @ dq_a + tail.momentum_jacobian @ (q_a - step.arm_q)
    omega = inv_i @ (h - arm_h)
    e_inv, d_theta = euler_rate_jacobians(theta, omega)
    f = np.zeros(TNX)
    a = np.zeros((TNX, TNX))
    b = np.zeros((TNX, TNU))
    f[0:3] = v
    a[0:3, 3:6] = np.eye(3)
    f[3:6] = forces.sum(axis=0) / tail.mass + GRAVITY
    for i in range(4):
        b[3:6, 3 * i:3 * i + 3] = np.eye(3) / tail.mass
    f[6:9] = e_inv @ omega
    a[6:9, 6:9] = d_theta
    rate = e_inv @ inv_i
    a[6:9, 9:12] = rate
    a[6:9, ARM_Q] = -rate @ tail.momentum_jacobian
    a[6:9, ARM_DQ] = -rate @ tail.momentum_matrix
    lever = feet - c
    f[9:12] = np.cross(lever, forces).sum(axis=0)
    a[9:12, 0:3] = skew(forces.sum(axis=0))
    for i in range(4):
        b[9:12, 3 * i:3 * i + 3] = skew(lever[i])
    f[ARM_Q] = dq_a
    a[ARM_Q, ARM_DQ] = np.eye(3)
    f[ARM_DQ] = u[ARM_ACC]
    b[ARM_DQ, ARM_ACC] = np.eye(3)
    return f, a, b


class TailMpc:
    """Builds and solves the tail MPC's QP each update (`plan`).

    Args:
        config: settings.
        arm_lower: arm joint lower limits (3,) [rad].
        arm_upper: arm joint upper limits (3,) [rad].
        arm_velocity_limit: arm joint speed limits (3,) [rad/s] (the servos' no-load speeds).
        arm_stall_torque: the arm servos' stall torques (3,) [N m].
    """

    def __init__(self, config: TailMpcConfig, arm_lower: np.ndarray, arm_upper: np.ndarray,
                 arm_velocity_limit: np.ndarray, arm_stall_torque: np.ndarray) -> None:
        self.config = config
        self._arm_lower, self._arm_upper = arm_box(arm_lower, arm_upper, config.arm_margin, "TailMpcConfig")
        self._vmax = np.asarray(arm_velocity_limit, dtype=np.float64)
        self._stall = np.asarray(arm_stall_torque, dtype=np.float64)
        self._weights = config.state_weights()

    def plan(self, x0: np.ndarray, x_ref: np.ndarray, contact: np.ndarray, feet: np.ndarray,
             steps: ArmTailPath | Sequence[TailStep], warm_start: np.ndarray | None = None) -> TailPlan:
        """Plan N steps from `x0`.

        Args:
            x0: current state (18,).
            x_ref: reference states x_1 .. x_N, shape (N, 18).
            contact: stance flags per step and foot, shape (N, 4).
            feet: foot positions per step, world, shape (N, 4, 3) [m].
            steps: the arm's pose, speed and `ArmTail` per step (N), the first the current ones: an `ArmTailPath`
                (`wbc.mpc.tail_model.arm_tail_path`), or a `TailStep` per step.
            warm_start: the previous plan's `TailPlan.warm_start()`, or None.

        Raises:
            MpcSolveError: the QP did not solve.
        """
        t0 = time.perf_counter()
        qp = self.build(x0, x_ref, contact, feet, steps)
        setup = time.perf_counter() - t0
        plan = self._solve(qp, warm_start)
        plan.setup_s = setup
        return plan

    def build(self, x0: np.ndarray, x_ref: np.ndarray, contact: np.ndarray, feet: np.ndarray,
              steps: ArmTailPath | Sequence[TailStep]) -> dict[str, np.ndarray]:
        """The update's QP (`plan`'s arguments), compiled (`wbc.mpc.tail_compiled.tail_qp`).

        Returns:
            ``H``, ``g``, ``C``, ``l``, ``u``, ``l_box``, ``u_box``, ``scale``, ``index``, ``free``, ``gamma_z``: min
            1/2 z^T H z + g^T z s.t. l <= C z <= u, l_box <= z <= u_box; the full scaled input vector is z at
            ``index`` (zero elsewhere), U[index] = scale z, and the predicted states X = free + gamma_z z.
        """
        cfg = self.config
        path = steps if isinstance(steps, ArmTailPath) else ArmTailPath.stack(
            [s.tail for s in steps], [s.arm_q for s in steps], [s.arm_dq for s in steps])
        x_ref = np.ascontiguousarray(x_ref, dtype=np.float64)
        speed = math.hypot(float(x_ref[0, 3]), float(x_ref[0, 4]))
        factor = min(1.0, max(cfg.standstill_weight_factor, speed / cfg.full_weight_speed)) \
            if cfg.full_weight_speed > 0 else 1.0
        f64 = functools.partial(np.ascontiguousarray, dtype=np.float64)
        names = ("H", "g", "C", "l", "u", "l_box", "u_box", "scale", "index", "free", "gamma_z")
        arrays = tail_qp(f64(x0), x_ref, np.ascontiguousarray(contact, dtype=np.bool_), f64(feet), f64(path.mass),
                         f64(path.inertia_world), f64(path.momentum_matrix), f64(path.momentum_jacobian),
                         f64(path.mass_matrix), f64(path.bias), f64(path.arm_q), f64(path.arm_dq), self._weights,
                         factor, self._arm_lower, self._arm_upper, self._vmax, self._stall, _GRAVITY, cfg.dt,
                         cfg.mu_axis, cfg.pyramid == "octagon", cfg.fz_min, cfg.fz_max, cfg.force_scale,
                         cfg.weight_force, cfg.weight_arm_acc, cfg.arm_moves)
        return dict(zip(names, arrays, strict=True))

    def solve(self, problem: MpcProblem, warm_start: np.ndarray | None = None) -> TailPlan:
        """Solve a saved update's QP again (the problem a `MpcSolveError` carries, ``MpcProblem.load(path)``).

        Args:
            problem: the QP, its arrays as `build` returns them.
            warm_start: the full scaled input vector (N TNU,) to start from, or None (cold start only).

        Raises:
            MpcSolveError: the QP did not solve (the problem is attached).
        """
        names = ("H", "g", "C", "l", "u", "l_box", "u_box", "scale", "index", "free", "gamma_z")
        return self._solve({name: getattr(problem, name) for name in names}, warm_start)

    def _solve(self, qp: dict[str, np.ndarray], warm_start: np.ndarray | None) -> TailPlan:
        t1 = time.perf_counter()
        problem = MpcProblem(**qp)  # the same arrays, for the constraint check and a failure's replay
        n, idx = self.config.horizon, qp["index"]
        upper = np.concatenate([qp["u_box"], qp["u"]])
        lower = np.concatenate([qp["l_box"], qp["l"]])
        sense = np.zeros(upper.size, dtype=np.int32)
        z, status, iterations = None, 0, 0
        if warm_start is not None:
            z, _, status, info = daqp.solve(qp["H"], qp["g"], qp["C"], upper, lower, sense,
                                            primal_start=np.clip(warm_start[idx], qp["l_box"], qp["u_box"]))
            iterations = int(info["iterations"])
        if status != 1 or not self._kept(problem, z):
            sense[:] = 0
            z, _, status, info = daqp.solve(qp["H"], qp["g"], qp["C"], upper, lower, sense)
            iterations += int(info["iterations"])
        solve = time.perf_counter() - t1
        if status != 1 or not self._kept(problem, z):
            broken = f", its solution breaking a constraint by {constraint_violation(problem, z):.3g}" \
                if status == 1 else ""
            raise MpcSolveError(f"tail MPC QP not solved (DAQP exit flag {status}{broken}) from a warm nor a cold "
                                "start; to investigate, save it (error.problem.save(path)) and replay it with "
                                "TailMpc.solve(MpcProblem.load(path))", problem)
        full = np.zeros(n * TNU)
        full[idx] = z
        u = np.zeros(n * TNU)
        u[idx] = z * qp["scale"]
        steps = u.reshape(n, TNU)
        states = (qp["free"] + qp["gamma_z"] @ z).reshape(n, TNX)
        return TailPlan(states=states, forces=steps[:, :12].reshape(n, 4, 3), arm_acceleration=steps[:, 12:].copy(),
                        iterations=iterations, setup_s=0.0, solve_s=solve, z=z, variables=full)

    @staticmethod
    def _kept(problem: MpcProblem, z: np.ndarray) -> bool:
        """Whether `z` is finite and keeps the boxes and rows to `wbc.mpc.qp_solvers.RESIDUAL_TOLERANCE`."""
        return constraint_violation(problem, z) <= RESIDUAL_TOLERANCE
