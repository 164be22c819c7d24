"""`CentroidalMpc`: a condensed convex MPC over the centroidal model with arm momentum, solved with ProxSuite.

Decision variables per step: the four feet's contact forces (world frame, in units of `force_scale` newtons so the
QP is well scaled) and the arm's joint velocities. The dynamics are linearised once per update about the current
state and the gravity-compensating reference input (`CentroidalModel.discretize`); the feet's lever arms vary along
the horizon with the planned footholds and the reference CoM. States are condensed out: X = Phi x0 + Gamma U + delta,
so the QP is dense in U only.

Constraints: friction pyramids (|f_x|, |f_y| <= mu f_z) and 0 <= f_z <= f_max on stance feet; zero force on swing
feet (box bounds, so the problem keeps one shape and is built once); arm joint velocity limits (box) and arm joint
position limits along the horizon (rows of the condensed dynamics).

Warm start: the previous solution shifted by one step is passed explicitly (ProxSuite's own "warm start with previous
result" gave wrong answers when contact bounds flipped). A solve that fails or does not converge raises
`MpcSolveError` carrying the problem, so the controller can fall back to the shifted previous plan.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import proxsuite

from wbc.errors import WbcError
from wbc.mpc.centroidal_model import NU, NX, CentroidalModel, CentroidalParams

__all__ = ["MpcConfig", "MpcProblem", "MpcSolution", "MpcSolveError", "CentroidalMpc"]


@dataclass(frozen=True, kw_only=True)
class MpcConfig:
    """MPC settings.

    Attributes:
        horizon: number of steps N.
        dt: step length [s].
        mu: friction coefficient of the pyramids.
        fz_max: largest normal force per foot [N].
        force_scale: force unit of the QP [N].
        weight_com: CoM position error weights (x, y, z).
        weight_vel: CoM velocity error weights.
        weight_rpy: orientation error weights (roll, pitch, yaw).
        weight_momentum: angular momentum error weights.
        weight_arm_q: arm position error weights (pull towards the nominal pose).
        weight_force: force effort weight [1/N^2].
        weight_arm_dq: arm velocity effort weight.
        arm_margin: keep the planned arm this far inside its joint limits [rad].
    """

    horizon: int = 10
    dt: float = 0.04
    mu: float = 0.6
    fz_max: float = 250.0
    force_scale: float = 100.0
    weight_com: tuple[float, float, float] = (40.0, 40.0, 400.0)
    weight_vel: tuple[float, float, float] = (20.0, 20.0, 10.0)
    weight_rpy: tuple[float, float, float] = (300.0, 300.0, 100.0)
    weight_momentum: tuple[float, float, float] = (2.0, 2.0, 2.0)
    weight_arm_q: tuple[float, float, float] = (1.0, 1.0, 1.0)
    weight_force: float = 1e-5
    weight_arm_dq: float = 1e-3
    arm_margin: float = 0.05


@dataclass
class MpcProblem:
    """One tick's QP in ProxSuite's form (scaled variables), kept so it can be dumped and replayed.

    min 1/2 z^T H z + g^T z  s.t.  l <= C z <= u,  l_box <= z <= u_box;  U = scale * z.
    """

    H: np.ndarray
    g: np.ndarray
    C: np.ndarray
    l: np.ndarray  # noqa: E741 - ProxSuite's name for the lower bounds
    u: np.ndarray
    l_box: np.ndarray
    u_box: np.ndarray
    scale: np.ndarray

    def save(self, path: str) -> None:
        """Write the problem to an ``.npz`` file."""
        np.savez_compressed(path, **self.__dict__)

    @classmethod
    def load(cls, path: str) -> MpcProblem:
        """Read a problem written by `save`."""
        with np.load(path, allow_pickle=False) as z:
            return cls(**{k: z[k] for k in ("H", "g", "C", "l", "u", "l_box", "u_box", "scale")})


class MpcSolveError(WbcError):
    """The QP failed; `problem` holds it for replay."""

    def __init__(self, message: str, problem: MpcProblem) -> None:
        super().__init__(message)
        self.problem = problem


@dataclass
class MpcSolution:
    """The plan of one update.

    Attributes:
        forces: contact forces per step and foot, world frame, shape (N, 4, 3) [N].
        arm_velocity: arm joint velocities per step, shape (N, 3) [rad/s].
        states: predicted states x_1 .. x_N, shape (N, 15).
        iterations: solver iterations.
        solve_s: QP solve time [s].
        setup_s: linearisation and condensing time [s].
    """

    forces: np.ndarray
    arm_velocity: np.ndarray
    states: np.ndarray
    iterations: int
    solve_s: float
    setup_s: float
    z: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))


class CentroidalMpc:
    """Build once, solve every update.

    Args:
        config: settings.
        arm_lower: arm joint lower limits (3,) [rad].
        arm_upper: arm joint upper limits (3,) [rad].
        arm_velocity_limit: arm joint speed limits (3,) [rad/s]; zeros freeze the arm (no arm, or a locked one).
    """

    def __init__(self, config: MpcConfig, arm_lower: np.ndarray, arm_upper: np.ndarray,
                 arm_velocity_limit: np.ndarray) -> None:
        self.config = config
        self.model = CentroidalModel()
        n = config.horizon
        self.n_var = n * NU
        self.n_in = n * (16 + 3)
        self._arm_lower = np.asarray(arm_lower, dtype=np.float64) + config.arm_margin
        self._arm_upper = np.asarray(arm_upper, dtype=np.float64) - config.arm_margin
        self._arm_vmax = np.asarray(arm_velocity_limit, dtype=np.float64)
        self._qp = proxsuite.proxqp.dense.QP(self.n_var, 0, self.n_in, True)
        self._qp.settings.eps_abs = 1e-6
        self._qp.settings.eps_rel = 0.0
        self._qp.settings.max_iter = 200
        self._qp.settings.initial_guess = proxsuite.proxqp.InitialGuess.WARM_START
        self._initialized = False
        scale = np.ones(NU)
        scale[:12] = config.force_scale
        self._scale = np.tile(scale, n)
        w_state = np.concatenate([config.weight_com, config.weight_vel, config.weight_rpy, config.weight_momentum,
                                  config.weight_arm_q])
        self._q_diag = np.tile(w_state, n)
        r = np.full(NU, config.weight_force)
        r[12:] = config.weight_arm_dq
        self._r_diag = np.tile(r, n)
        fric = np.zeros((16, 12))
        for i in range(4):
            for row, (axis, sign) in enumerate(((0, 1), (0, -1), (1, 1), (1, -1))):
                fric[4 * i + row, 3 * i + axis] = sign
                fric[4 * i + row, 3 * i + 2] = -config.mu
        self._fric = fric
        self._prev: np.ndarray | None = None
        self.problem: MpcProblem | None = None

    def reset(self) -> None:
        """Forget the previous solution (no warm start on the next solve)."""
        self._prev = None

    def solve(self, x0: np.ndarray, x_ref: np.ndarray, contact: np.ndarray, feet: np.ndarray,
              params: CentroidalParams) -> MpcSolution:
        """Plan N steps from `x0`.

        Args:
            x0: current state (15,).
            x_ref: reference states x_1 .. x_N, shape (N, 15).
            contact: stance flags per step and foot, shape (N, 4).
            feet: foot positions per step (planned footholds for swing feet), world, shape (N, 4, 3) [m].
            params: mass, inertia and arm momentum matrix at the current configuration.

        Raises:
            MpcSolveError: the QP did not solve.
        """
        t0 = time.perf_counter()
        cfg, n = self.config, self.config.horizon
        contact = np.asarray(contact, dtype=bool)
        # linearise once about x0 and the gravity-compensating input of the first step's stance set
        stance0 = max(1, int(contact[0].sum()))
        u_bar = np.zeros(NU)
        for i in np.flatnonzero(contact[0]):
            u_bar[3 * i + 2] = params.mass * 9.81 / stance0
        f0, a_c, b_c = self.model.linearize(x0, u_bar, params)
        d_c = f0 - a_c @ x0 - b_c @ u_bar
        integ = self._integral(a_c, cfg.dt)
        a_d = np.eye(NX) + a_c @ integ
        total_force_skew = a_c[9:12, 0:3]
        # Along the horizon the lever arms are taken about the reference CoM of each step (the current CoM for the
        # first): B's torque rows change and the affine torque term -[F]x c_ref follows.
        gamma = np.zeros((n * NX, n * NU))
        phi = np.zeros((n * NX, NX))
        delta = np.zeros(n * NX)
        for k in range(n):
            c_ref = x0[0:3] if k == 0 else x_ref[k - 1, 0:3]
            b_k = b_c.copy()
            for i in range(4):
                r = feet[k, i] - c_ref
                b_k[9:12, 3 * i:3 * i + 3] = ((0.0, -r[2], r[1]), (r[2], 0.0, -r[0]), (-r[1], r[0], 0.0))
            d_k = d_c.copy()
            d_k[9:12] -= total_force_skew @ (c_ref - x0[0:3])
            rows = slice(k * NX, (k + 1) * NX)
            if k == 0:
                phi[rows] = a_d
                delta[rows] = integ @ d_k
            else:
                prev = slice((k - 1) * NX, k * NX)
                phi[rows] = a_d @ phi[prev]
                delta[rows] = a_d @ delta[prev] + integ @ d_k
                gamma[rows, : k * NU] = a_d @ gamma[prev, : k * NU]
            gamma[rows, k * NU:(k + 1) * NU] = integ @ b_k
        free = phi @ x0 + delta
        err = free - x_ref.ravel()
        qg = self._q_diag[:, None] * gamma
        s = self._scale
        h = (gamma.T @ qg + np.diag(self._r_diag)) * np.outer(s, s)
        g = (qg.T @ err) * s
        # constraints
        c = np.zeros((self.n_in, self.n_var))
        lo = np.full(self.n_in, -np.inf)
        hi = np.zeros(self.n_in)
        l_box = np.zeros(self.n_var)
        u_box = np.zeros(self.n_var)
        fz_max = cfg.fz_max / cfg.force_scale
        for k in range(n):
            r0 = k * 16
            col = k * NU
            c[r0:r0 + 16, col:col + 12] = self._fric
            for i in range(4):
                j = col + 3 * i
                if contact[k, i]:
                    l_box[j:j + 3] = (-cfg.mu * fz_max, -cfg.mu * fz_max, 0.0)
                    u_box[j:j + 3] = (cfg.mu * fz_max, cfg.mu * fz_max, fz_max)
            l_box[col + 12:col + 15] = -self._arm_vmax
            u_box[col + 12:col + 15] = self._arm_vmax
            ra = n * 16 + 3 * k
            c[ra:ra + 3] = gamma[k * NX + 12:k * NX + 15] * s
            lo[ra:ra + 3] = np.minimum(self._arm_lower, x0[12:15]) - free[k * NX + 12:k * NX + 15]
            hi[ra:ra + 3] = np.maximum(self._arm_upper, x0[12:15]) - free[k * NX + 12:k * NX + 15]
        self.problem = MpcProblem(H=h, g=g, C=c, l=lo, u=hi, l_box=l_box, u_box=u_box, scale=s)
        setup = time.perf_counter() - t0
        z0 = np.zeros(self.n_var)
        if self._prev is not None:
            z0[: (n - 1) * NU] = self._prev[NU:]
            z0[(n - 1) * NU:] = self._prev[(n - 1) * NU:]
        z0 = np.clip(z0, l_box, u_box)
        t1 = time.perf_counter()
        qp = self._qp
        if not self._initialized:
            qp.init(h, g, None, None, c, lo, hi, l_box, u_box)
            self._initialized = True
        else:
            qp.update(h, g, None, None, c, lo, hi, l_box, u_box)
        qp.solve(z0, None, None)
        solve = time.perf_counter() - t1
        status = qp.results.info.status
        z = qp.results.x.copy()
        if status != proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED or not np.all(np.isfinite(z)):
            self._prev = None
            raise MpcSolveError(f"MPC QP not solved: {status}", self.problem)
        self._prev = z
        u = z * s
        states = (free + gamma @ u).reshape(n, NX)
        steps = u.reshape(n, NU)
        return MpcSolution(forces=steps[:, :12].reshape(n, 4, 3), arm_velocity=steps[:, 12:].copy(), states=states,
                           iterations=int(qp.results.info.iter), solve_s=solve, setup_s=setup, z=z)

    @staticmethod
    def _integral(a: np.ndarray, dt: float) -> np.ndarray:
        """Integral of exp(A s) ds over [0, dt], third order (the ZOH input matrix factor)."""
        return np.eye(NX) * dt + a * (dt**2 / 2) + (a @ a) * (dt**3 / 6)
