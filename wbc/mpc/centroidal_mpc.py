"""`CentroidalMpc`: a condensed convex MPC over the centroidal model with arm momentum, solved with DAQP or ProxSuite.

Decision variables per step: the four feet's contact forces (world frame, in units of `force_scale` newtons so the
QP is well scaled) and the arm's joint velocities. The dynamics are linearised once per update about the current
state and the gravity-compensating reference input (`CentroidalModel.discretize`); the feet's lever arms vary along
the horizon with the planned footholds and the reference CoM. States are condensed out: X = Phi x0 + Gamma U + delta,
so the QP is dense in U only.

Constraints: friction pyramids inside the cone of the controller's friction setting `MpcConfig.mu`, never the
simulator's (`MpcConfig.pyramid`: by default the inscribed octagon, |f_x|, |f_y| and |f_x +- f_y| / sqrt(2) <=
0.924 mu f_z, eight rows a stance foot) and f_min <= f_z <= f_max on stance feet; swing feet carry
no force (their variables are dropped); arm joint velocity limits (box) and arm joint position limits along the horizon
(rows of the condensed dynamics). A frozen arm (locked, absent, or momentum terms off) has no variables.

Solver: the backend `MpcConfig.qp_solver` names (`wbc.mpc.qp_solvers`): DAQP by default, a dual active-set method
for small dense QPs (its Python package; a plain C library, so a solve does not depend on where its buffers were
allocated), or ProxSuite's ProxQP. On this problem (a trot's: 90 variables, 190 rows; standing: 150 and 350) DAQP
solves in about 0.4 of the time ProxSuite takes (median 0.105-0.108 ms against 0.256-0.263 ms), to the same optimum
(``wbc bench mpc`` solves the closed loop's QPs with both; docs/mpc-notes.md).
The solve is a function of the problem and the warm start alone (the previous plan shifted by one step, which seeds
DAQP's active set or starts ProxQP's iterations); if a warm-started solve fails a cold start follows, and a solve that
still fails raises `MpcSolveError` naming the backend and its status and carrying the problem, so the controller can
fall back to the shifted previous plan and the problem can be replayed.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wbc.config_checks import check_number
from wbc.errors import ConfigError, MpcProblemFileError, WbcError
from wbc.mpc.centroidal_model import NU, NX, CentroidalModel, CentroidalParams
from wbc.mpc.condensing import condense
from wbc.mpc.dense_qp import DenseQp
from wbc.mpc.qp_solvers import check_qp_solver, make_qp_solver
from wbc.robots.conventions import G

__all__ = ["MpcConfig", "MpcProblem", "MpcSolution", "MpcSolveError", "CentroidalMpc"]


@dataclass(frozen=True, kw_only=True)
class MpcConfig:
    """MPC settings.

    Attributes:
        horizon: number of steps N.
        dt: step length [s].
        mu: friction coefficient of the feet's friction cone.
        pyramid: how the friction cone of `mu` becomes linear rows (`pyramid_faces`): ``octagon`` (the octagon
            inside the cone: |f_x|, |f_y| and |f_x +- f_y| / sqrt(2) <= 0.924 mu f_z, eight rows a foot),
            ``inscribed`` (the square inside it: |f_x|, |f_y| <= mu / sqrt(2) f_z) or ``outer`` (the square around
            it: |f_x|, |f_y| <= mu f_z, up to sqrt(2) mu along a diagonal). The pyramid's axes are the world's: the
            outer square planned a push or a turn at 45 degrees to them 41 % past the cone, and on push-low-friction's
            ground (0.4-0.5) those forces slid; the inscribed square keeps them but gives up 29 % of the grip along
            the axes, which fast turns need (docs/mpc-notes.md).
        fz_min: smallest normal force per stance foot [N]: a stance foot keeps pressing. Without it, a pushed
            robot whose stance feet stood badly for the moments it needed was planned to fall freely until the next
            pair landed (docs/mpc-notes.md).
        fz_max: largest normal force per foot [N].
        force_scale: force unit of the QP [N].
        weight_com: CoM position error weights (x, y, z).
        weight_vel: CoM velocity error weights.
        weight_rpy: orientation error weights (roll, pitch, yaw).
        weight_momentum: angular momentum error weights.
        weight_arm_q: arm position error weights (pull towards the nominal pose).
        weight_force: force effort weight [1/N^2].
        weight_arm_dq: arm velocity effort weight; high enough that small orientation corrections do not keep the
            arm moving fast.
        arm_margin: keep the planned arm this far inside its joint limits [rad].
        full_weight_speed: commanded horizontal speed [m/s] at and above which the horizontal velocity weights hold
            in full; below it they scale with the speed, down to `standstill_weight_factor` at rest (0: always in
            full). A robot standing or walking slowly has little speed to hold, and a stiff velocity target makes
            it brake a push with its stance feet, which friction cannot do (it removes at most mu g T = 1.3 m/s
            over the horizon against the 2 m/s of a push v2 band ood push) and which pitches or rolls the trunk
            over those feet; with the weight low it steps under its CoM (the footholds' capture term) and the
            position leash brings it back. At speed the weights track the command (turns unchanged).
            Measured: docs/mpc-notes.md, strong pushes.
        standstill_weight_factor: the factor on those weights at a zero command.
        qp_solver: the QP backend, a name of `wbc.mpc.qp_solvers.QP_SOLVERS`: ``daqp`` (the default: the faster
            on these QPs, and the same bits whatever the heap held before) or ``proxsuite``.

    Raises:
        ConfigError: an unknown `qp_solver` (the message lists the valid names), a `horizon` below one step, a
            number that is not finite, a step, force or scale that is not positive, a weight negative or above
            `MAX_WEIGHT` (1e12), a negative margin, `fz_max` not above `fz_min`, or a `standstill_weight_factor`
            outside [0, 1].
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
    weight_arm_q: tuple[float, float, float] = (5.0, 5.0, 5.0)
    weight_force: float = 1e-5
    weight_arm_dq: float = 0.05
    arm_margin: float = 0.05
    full_weight_speed: float = 1.0
    standstill_weight_factor: float = 0.25
    qp_solver: str = "daqp"

    def __post_init__(self) -> None:
        check_qp_solver(self.qp_solver, "MpcConfig.qp_solver")
        friction_per_axis(self.mu, self.pyramid, "MpcConfig")
        check_force_terms(self, "MpcConfig")
        check_number("MpcConfig.weight_arm_dq", self.weight_arm_dq, at_least=0.0, at_most=MAX_WEIGHT)

    @property
    def mu_axis(self) -> float:
        """The bound on |f_x| / f_z and |f_y| / f_z of the pyramid (`pyramid`)."""
        return friction_per_axis(self.mu, self.pyramid, "MpcConfig")


PYRAMIDS = ("octagon", "inscribed", "outer")
"""Valid values of `MpcConfig.pyramid` (and the tail MPC's)."""


_OCTAGON = math.cos(math.pi / 8.0)
"""The octagon inscribed in a circle of radius mu reaches mu cos(pi / 8) = 0.924 mu across its faces."""


def pyramid_faces(pyramid: str) -> tuple[tuple[float, float], ...]:
    """The pyramid's faces as (c_x, c_y): each a row c_x f_x + c_y f_y - mu_axis f_z <= 0 (`friction_per_axis`)."""
    axes = ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0))
    if pyramid != "octagon":
        return axes
    d = 1.0 / math.sqrt(2.0)
    return (*axes, (d, d), (d, -d), (-d, d), (-d, -d))


MAX_HORIZON = 100
"""The most steps an MPC horizon may have: its dense QP grows with the square of the steps (100 steps of the default
0.032 s, 3.2 s, is ten times the default and beyond any horizon a push or a turn needs)."""

MAX_WEIGHT = 1e12
"""The largest cost weight an MPC setting may have: the shipped ones are at most 400. Weights near 1e20 make the QP so
ill-conditioned that DAQP returned an "optimal" solution breaking the friction pyramids by 95 N (the solve's
constraint check, `wbc.mpc.qp_solvers.RESIDUAL_TOLERANCE`, now refuses such solutions too)."""


def arm_box(lower: np.ndarray, upper: np.ndarray, margin: float, where: str) -> tuple[np.ndarray, np.ndarray]:
    """The arm joints' limits, `margin` inside `lower` and `upper` (all in rad).

    Raises:
        ConfigError: a margin that leaves a joint no room (named in `where`).
    """
    lo = np.asarray(lower, dtype=np.float64) + margin
    hi = np.asarray(upper, dtype=np.float64) - margin
    if not np.all(lo < hi):
        room = float(np.min(np.asarray(upper) - np.asarray(lower))) / 2.0
        raise ConfigError(f"{where}.arm_margin must be below half the narrowest arm joint's range ({room:.3f} rad), "
                          f"got {margin!r}: it leaves that joint no room")
    return lo, hi


def check_force_terms(config: Any, where: str) -> None:
    """Check the settings `MpcConfig` and the tail MPC's `TailMpcConfig` share (the horizon, forces and body terms).

    Args:
        config: an `MpcConfig` or a `TailMpcConfig` (`wbc.mpc.tail_mpc`, which imports this module).
        where: the class name, for the messages.

    Raises:
        ConfigError: `horizon` not an integer in [1, `MAX_HORIZON`], `dt`, `force_scale` not positive, `fz_min`
            negative, `fz_max` not above it, a weight negative or above `MAX_WEIGHT`, a negative `arm_margin` or
            `full_weight_speed`,
            `standstill_weight_factor` outside [0, 1], or any of them not finite (named in `where`).
    """
    check_number(f"{where}.horizon", config.horizon, at_least=1, at_most=MAX_HORIZON, integer=True)
    check_number(f"{where}.dt", config.dt, above=0.0)
    check_number(f"{where}.fz_min", config.fz_min, at_least=0.0)
    check_number(f"{where}.fz_max", config.fz_max, above=0.0)
    if not config.fz_max > config.fz_min:
        raise ConfigError(f"{where}.fz_max must be above fz_min ({config.fz_min}), got {config.fz_max}")
    check_number(f"{where}.force_scale", config.force_scale, above=0.0)
    for name in ("weight_com", "weight_vel", "weight_rpy", "weight_momentum", "weight_arm_q"):
        check_number(f"{where}.{name}", getattr(config, name), at_least=0.0, at_most=MAX_WEIGHT, size=3)
    check_number(f"{where}.weight_force", config.weight_force, at_least=0.0, at_most=MAX_WEIGHT)
    for name in ("arm_margin", "full_weight_speed"):
        check_number(f"{where}.{name}", getattr(config, name), at_least=0.0)
    check_number(f"{where}.standstill_weight_factor", config.standstill_weight_factor, at_least=0.0, at_most=1.0)


def friction_per_axis(mu: float, pyramid: str, where: str) -> float:
    """The pyramid's bound on |f_x| / f_z and |f_y| / f_z (the octagon's on |f_x +- f_y| / (sqrt(2) f_z) too).

    `pyramid` is one of `PYRAMIDS`, for the friction cone of coefficient `mu`.

    Raises:
        ConfigError: `mu` not a positive finite number, or an unknown `pyramid` (named in `where`).
    """
    if not (math.isfinite(mu) and mu > 0.0):
        raise ConfigError(f"{where}.mu must be a positive friction coefficient, got {mu!r}")
    if pyramid not in PYRAMIDS:
        raise ConfigError(f"{where}.pyramid must be one of {', '.join(PYRAMIDS)}, got {pyramid!r}")
    return mu * _OCTAGON if pyramid == "octagon" else mu / math.sqrt(2.0) if pyramid == "inscribed" else mu


@dataclass
class MpcProblem(DenseQp):
    """One update's QP (scaled variables) and what turns its solution into a plan.

    min 1/2 z^T H z + g^T z  s.t.  l <= C z <= u,  l_box <= z <= u_box;  U[index] = scale * z, other entries of
    the full input vector U (N NU: swing forces, a frozen arm's velocities) are zero. The predicted states are
    X = free + gamma_z z (the condensed dynamics). Everything `CentroidalMpc.solve` needs is here, so a problem
    written by `save` and read back by `load` solves on its own to the same plan.

    Attributes:
        H: Hessian, shape (n, n) for the n = index.size decision variables.
        g: gradient (n,).
        C: inequality rows (friction pyramids, then arm position limits along the horizon), shape (m, n).
        l: lower bounds of the rows (m,) (-inf where one-sided).
        u: upper bounds of the rows (m,).
        l_box: lower bounds of the variables (n,) [force_scale N, rad/s].
        u_box: upper bounds of the variables (n,).
        scale: unit of each variable (n,): U[index] = scale * z [N or 1].
        index: position of each variable in the full input vector U (n,).
        free: predicted states with zero input, x_1 .. x_N stacked, shape (N NX,).
        gamma_z: the condensed dynamics' columns of the decision variables, d X / d z, shape (N NX, n).
    """

    scale: np.ndarray
    index: np.ndarray
    free: np.ndarray
    gamma_z: np.ndarray

    @property
    def horizon(self) -> int:
        """Number of steps N."""
        return self.free.size // NX

    def save(self, path: str) -> None:
        """Write the problem to an ``.npz`` file (compressed, no pickles)."""
        np.savez_compressed(path, **{name: getattr(self, name) for name in _ARRAYS})

    @classmethod
    def load(cls, path: str) -> MpcProblem:
        """Read a problem written by `save`.

        Raises:
            MpcProblemFileError: the file lacks some of the problem's arrays (an older dump, or not a problem).
        """
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in _ARRAYS if k not in z.files]
            if missing:
                raise MpcProblemFileError(str(path), missing)
            return cls(**{k: z[k] for k in _ARRAYS})


_ARRAYS = ("H", "g", "C", "l", "u", "l_box", "u_box", "scale", "index", "free", "gamma_z")  # `MpcProblem`'s arrays


class MpcSolveError(WbcError):
    """The QP failed; `problem` holds it for replay (``error.problem.save(path)``, then `CentroidalMpc.solve`)."""

    def __init__(self, message: str, problem: MpcProblem) -> None:
        super().__init__(message)
        self.problem = problem


@dataclass(kw_only=True)
class MpcSolution:
    """The plan of one update.

    Attributes:
        forces: contact forces per step and foot, world frame, shape (N, 4, 3) [N].
        arm_velocity: arm joint velocities per step, shape (N, 3) [rad/s].
        states: predicted states x_1 .. x_N, shape (N, 15).
        iterations: solver iterations.
        solve_s: QP solve time [s].
        setup_s: linearisation and condensing time [s] (0 when the problem was built elsewhere, e.g. loaded).
        z: the QP's solution, the problem's decision variables only (scaled).
        variables: the full scaled input vector, zeros where the problem had no variable, shape (N NU,).
    """

    forces: np.ndarray
    arm_velocity: np.ndarray
    states: np.ndarray
    iterations: int
    solve_s: float
    setup_s: float = 0.0
    z: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    variables: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))

    def warm_start(self) -> np.ndarray:
        """This plan shifted one step earlier, its last step repeated: the initial guess for the next update.

        Returns:
            The full scaled input vector (N NU,) that `CentroidalMpc.solve` takes as ``warm_start``.
        """
        prev = self.variables
        n = prev.size // NU
        full0 = np.zeros(prev.size)
        full0[: (n - 1) * NU] = prev[NU:]
        full0[(n - 1) * NU:] = prev[(n - 1) * NU:]
        return full0


class CentroidalMpc:
    """Constant parts built once; every update `build` makes the QP and `solve` solves it (`plan` does both).

    Args:
        config: settings.
        arm_lower: arm joint lower limits (3,) [rad].
        arm_upper: arm joint upper limits (3,) [rad].
        arm_velocity_limit: arm joint speed limits (3,) [rad/s]; zeros freeze the arm (no arm, or a locked one).

    Attributes:
        qp_solver: the QP backend (`MpcConfig.qp_solver`).
        last_problem: the problem the last `solve` was given (None before the first), solved or not.
        last_warm_start: the warm start it was given (None: none).
    """

    def __init__(self, config: MpcConfig, arm_lower: np.ndarray, arm_upper: np.ndarray,
                 arm_velocity_limit: np.ndarray) -> None:
        self.config = config
        self.model = CentroidalModel()
        self.qp_solver = make_qp_solver(config.qp_solver)
        # what the last `solve` was given, for observers (``wbc bench mpc`` re-solves it with every backend); the
        # solve itself never reads them
        self.last_problem: MpcProblem | None = None
        self.last_warm_start: np.ndarray | None = None
        n = config.horizon
        self._arm_lower, self._arm_upper = arm_box(arm_lower, arm_upper, config.arm_margin, "MpcConfig")
        self._arm_vmax = np.asarray(arm_velocity_limit, dtype=np.float64)
        scale = np.ones(NU)
        scale[:12] = config.force_scale
        self._scale = np.tile(scale, n)
        w_state = np.concatenate([config.weight_com, config.weight_vel, config.weight_rpy, config.weight_momentum,
                                  config.weight_arm_q])
        self._q_root = np.sqrt(np.tile(w_state, n))
        self._q_root_scaled = self._q_root.copy()  # rewritten by `build` when the velocity weights are scaled
        self._vel_xy_rows = (np.arange(n)[:, None] * NX + np.arange(3, 5)[None]).ravel()
        self._patterns: dict[bytes, tuple[np.ndarray, ...]] = {}
        r = np.full(NU, config.weight_force)
        r[12:] = config.weight_arm_dq
        self._r_diag = np.tile(r, n)
        self._arm_free = bool(np.any(self._arm_vmax > 0))
        self._arm_rows = (np.arange(n)[:, None] * NX + np.arange(12, 15)[None]).ravel()  # arm rows of the states

    def plan(self, x0: np.ndarray, x_ref: np.ndarray, contact: np.ndarray, feet: np.ndarray,
             params: CentroidalParams, warm_start: np.ndarray | None = None) -> MpcSolution:
        """Plan N steps from `x0`: `build`, then `solve`, with the build's time in ``setup_s``.

        Args:
            x0: current state (15,).
            x_ref: reference states x_1 .. x_N, shape (N, 15).
            contact: stance flags per step and foot, shape (N, 4).
            feet: foot positions per step (planned footholds for swing feet), world, shape (N, 4, 3) [m].
            params: mass, inertia and arm momentum matrix at the current configuration.
            warm_start: initial guess, usually the previous plan's `MpcSolution.warm_start()`; None: cold start.

        Raises:
            MpcSolveError: the QP did not solve (the problem is attached).
        """
        t0 = time.perf_counter()
        problem = self.build(x0, x_ref, contact, feet, params)
        setup = time.perf_counter() - t0
        solution = self.solve(problem, warm_start)
        solution.setup_s = setup
        return solution

    def build(self, x0: np.ndarray, x_ref: np.ndarray, contact: np.ndarray, feet: np.ndarray,
              params: CentroidalParams) -> MpcProblem:
        """The QP of one update: linearise about `x0`, condense the states out, add the constraints.

        Args:
            x0: current state (15,).
            x_ref: reference states x_1 .. x_N, shape (N, 15).
            contact: stance flags per step and foot, shape (N, 4).
            feet: foot positions per step (planned footholds for swing feet), world, shape (N, 4, 3) [m].
            params: mass, inertia and arm momentum matrix at the current configuration.

        Returns:
            The problem, complete: `solve` needs nothing else.
        """
        cfg, n = self.config, self.config.horizon
        contact = np.asarray(contact, dtype=bool)
        # linearise once about x0 and the gravity-compensating input of the first step's stance set
        stance0 = contact[0].tolist()
        u_bar = np.zeros(NU)
        u_bar[2:12:3] = stance0
        u_bar[2:12:3] *= params.mass * G / max(1, sum(stance0))
        f0, a_c, b_c = self.model.linearize(x0, u_bar, params)
        d_c = f0 - a_c @ x0 - b_c @ u_bar
        # Condensed, x_{k+1} = A^(k+1) x0 + sum_{j<=k} A^(k-j) (B_j u_j + d_j), with each step's lever arms taken
        # about the reference CoM of that step (the current CoM for the first), and the QP's Hessian and gradient:
        # one compiled call (`wbc.mpc.condensing.condense`; in numpy it was dozens of batched products and scatters).
        # Only stance forces (and the arm's velocities when it may move) are decision variables: swing forces are
        # zero and a frozen arm does not move, so their columns are never formed rather than boxed to zero. The QP
        # keeps one shape per contact pattern count.
        arm_free = self._arm_free
        idx, s, l_box, u_box, friction = self._pattern(contact)
        nv = idx.size
        gamma_z, free = np.empty((n * NX, nv)), np.empty(n * NX)
        h, g = np.empty((nv, nv)), np.empty(nv)
        condense(a_c, b_c, d_c, cfg.dt, np.ascontiguousarray(x0, dtype=np.float64),
                 np.ascontiguousarray(x_ref, dtype=np.float64), np.ascontiguousarray(feet, dtype=np.float64),
                 idx, s, self._state_weights(x_ref), self._r_diag, gamma_z, free, h, g)
        m4 = friction.shape[0]
        n_arm = 3 * n if arm_free else 0
        c = np.empty((m4 + n_arm, idx.size))
        c[:m4] = friction
        lo = np.full(m4 + n_arm, -np.inf)
        hi = np.zeros(m4 + n_arm)
        if arm_free:
            arm_rows = self._arm_rows
            c[m4:] = gamma_z[arm_rows]
            lo[m4:] = (np.minimum(self._arm_lower, x0[12:15]) - free[arm_rows].reshape(n, 3)).ravel()
            hi[m4:] = (np.maximum(self._arm_upper, x0[12:15]) - free[arm_rows].reshape(n, 3)).ravel()
        return MpcProblem(H=h, g=g, C=c, l=lo, u=hi, l_box=l_box, u_box=u_box, scale=s, index=idx, free=free,
                          gamma_z=gamma_z)

    def velocity_weight_factor(self, x_ref: np.ndarray) -> float:
        """The factor on the horizontal velocity weights for this update (`MpcConfig.full_weight_speed`).

        Args:
            x_ref: reference states, shape (N, 15); the commanded speed is the first step's.
        """
        cfg = self.config
        if cfg.full_weight_speed <= 0:
            return 1.0
        speed = math.hypot(x_ref[0, 3].item(), x_ref[0, 4].item())
        return min(1.0, max(cfg.standstill_weight_factor, speed / cfg.full_weight_speed))

    def _state_weights(self, x_ref: np.ndarray) -> np.ndarray:
        """Square roots of the state weights over the horizon, the horizontal velocity ones scaled by the speed."""
        factor = self.velocity_weight_factor(x_ref)
        if factor == 1.0:
            return self._q_root
        out = self._q_root_scaled
        out[:] = self._q_root
        out[self._vel_xy_rows] *= math.sqrt(factor)
        return out

    def _pattern(self, contact: np.ndarray) -> tuple[np.ndarray, ...]:
        """What depends only on the contact table: variables, their units and boxes, the friction pyramid rows.

        A periodic gait has a handful of distinct tables, so each is built once and kept (read-only).

        Returns:
            idx (positions of the variables in the full input vector), s (their units), l_box, u_box, and the
            friction rows (per stance foot and step, 8 for the octagon and 4 for the other pyramids; in the scaled
            variables).
        """
        key = contact.tobytes()
        cached = self._patterns.get(key)
        if cached is not None:
            return cached
        cfg, n = self.config, self.config.horizon
        chosen = np.zeros((n, NU), dtype=bool)
        chosen[:, :12] = np.repeat(contact, 3, axis=1)
        chosen[:, 12:] = self._arm_free
        idx = np.flatnonzero(chosen)
        s = self._scale[idx]
        fz_max = cfg.fz_max / cfg.force_scale
        l_box = np.empty(idx.size)
        u_box = np.empty(idx.size)
        kind = idx % NU  # 0..11 force components, 12..14 arm
        is_force = kind < 12
        comp = kind % 3
        mu = cfg.mu_axis
        l_box[is_force] = np.where(comp[is_force] == 2, cfg.fz_min / cfg.force_scale, -mu * fz_max)
        u_box[is_force] = np.where(comp[is_force] == 2, fz_max, mu * fz_max)
        arm_cols = ~is_force
        l_box[arm_cols] = -self._arm_vmax[kind[arm_cols] - 12]
        u_box[arm_cols] = self._arm_vmax[kind[arm_cols] - 12]
        # friction pyramid rows for every stance foot: +-f_x - mu f_z <= 0 and +-f_y - mu f_z <= 0 (mu per axis), and
        # for the octagon (+-f_x +- f_y) / sqrt(2) - mu f_z <= 0
        fz_cols = np.flatnonzero(is_force & (comp == 2))  # one per stance foot and step, preceded by its x, y
        m = fz_cols.size
        faces = pyramid_faces(cfg.pyramid)
        friction = np.zeros((len(faces) * m, idx.size))
        fric = friction.reshape(m, len(faces), idx.size)
        steps = np.arange(m)
        for r, (cx, cy) in enumerate(faces):
            fric[steps, r, fz_cols - 2] = cx * s[fz_cols - 2]
            fric[steps, r, fz_cols - 1] = cy * s[fz_cols - 1]
            fric[steps, r, fz_cols] = -mu * s[fz_cols]
        out = (idx, s, l_box, u_box, friction)
        for a in out:
            a.setflags(write=False)
        self._patterns[key] = out
        return out

    def solve(self, problem: MpcProblem, warm_start: np.ndarray | None = None) -> MpcSolution:
        """Solve a problem from `build` (or `MpcProblem.load`) into a plan.

        The warm start is tried first; if that solve fails (or there is none) a cold start follows. The plan depends
        on the problem and the warm start only, bit for bit.

        Args:
            problem: the QP and what rebuilds the states from its solution.
            warm_start: initial guess as a full scaled input vector (N NU,), usually the previous plan's
                `MpcSolution.warm_start()`; clipped to the variables' bounds. None: cold start only.

        Returns:
            The plan (``setup_s`` 0: the build is not timed here).

        Raises:
            MpcSolveError: the QP did not solve (the problem is attached).
        """
        self.last_problem, self.last_warm_start = problem, warm_start
        idx, n = problem.index, problem.horizon
        z0 = None if warm_start is None else np.clip(warm_start[idx], problem.l_box, problem.u_box)
        result = self.qp_solver.solve(problem, z0)
        if not result.solved:
            solver = self.qp_solver
            raise MpcSolveError(f"MPC QP not solved ({solver.label} {result.status}) from a warm nor a cold start; "
                                "to investigate, save it (error.problem.save(path)) and replay it with "
                                "CentroidalMpc.solve(MpcProblem.load(path)) under "
                                f"MpcConfig(qp_solver={solver.name!r})", problem)
        z = result.z
        full = np.zeros(n * NU)
        full[idx] = z
        u = np.zeros(full.size)
        u[idx] = z * problem.scale  # = full * the full scale vector: entries without a variable stay 0
        states = (problem.free + problem.gamma_z @ z).reshape(n, NX)
        steps = u.reshape(n, NU)
        return MpcSolution(forces=steps[:, :12].reshape(n, 4, 3), arm_velocity=steps[:, 12:].copy(), states=states,
                           iterations=result.iterations, solve_s=result.solve_s, z=z, variables=full)
