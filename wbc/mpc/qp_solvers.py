"""The MPC's QP backends: one protocol (`QpSolver`), DAQP and ProxSuite behind it, and their registry `QP_SOLVERS`.

`wbc.mpc.centroidal_mpc.CentroidalMpc` solves each update's `DenseQp` with the backend its configuration names
(`MpcConfig.qp_solver`); ``wbc bench mpc`` solves the QPs a closed loop made with every backend, side by side.
Both backends take the problem as built: its force variables are already in units of `MpcConfig.force_scale`
(100 N), so its Hessian is well conditioned in forces and arm velocities alike and a solution is scaled back by the
problem's own ``scale``. Each solve is a function of the problem and the warm start alone: no solver object outlives
a call, so no scaling, factorisation or active set of an earlier QP leaks into a later one.

- ``daqp`` (`DaqpSolver`, the default): a dual active-set method for small dense QPs; the warm start seeds its active
  set. On the MPC's QPs (a trot's: 90 variables, 190 rows; standing: 150 and 350) most solves take one or two
  iterations, and the C library gives the same bits whatever its buffers' addresses (the arena's reproducibility
  rests on that).
- ``proxsuite`` (`ProxsuiteSolver`): ProxQP's dense proximal augmented Lagrangian method (the solver the design
  card names). The warm start is handed in explicitly (``InitialGuess.WARM_START``), never taken from the solver's
  previous result, which was wrong when the contact set changed between updates. No Ruiz equilibration: the problem
  is already scaled, and equilibrating took about two thirds of each solve. Its tolerance is absolute, 1e-9 on the
  primal and dual residuals (relative 0), near DAQP's exact active-set optimum: the cost is flat along some force
  directions, and at 1e-7 one QP of a push recovery stopped 25 N from that optimum with its dual residual within
  tolerance. Its outer iterations are capped at 200 (the MPC's QPs take at most ~50 iterations in all); the cap does
  not bound the inner ones (up to ProxQP's 1,500 an outer iteration), so an infeasible QP, which the MPC's boxes and
  rows do not make, costs it seconds: its infeasibility thresholds are 1e-9 here, so a feasible QP is never called
  infeasible, and the A1's standing QP with a friction row pushed beyond the boxes took ~16,000 iterations over its
  two attempts, ~30 s, before ProxQP called it infeasible (DAQP: microseconds). The registry's wheel runs an AVX
  build whose last bits can depend on its buffers' addresses, so the arena's bit-for-bit reproducibility holds with
  DAQP only.

A warm-started solve that fails is followed by a cold start; the iterations of both are counted and the time covers
both. A solution counts as solved only if the backend reports an optimum, it is finite, and it keeps every bound and
row to `RESIDUAL_TOLERANCE` (`constraint_violation`): on absurdly weighted problems (weights near 1e20) DAQP reports
an optimum whose friction rows are broken by ~1 (95 N), where sane problems' solutions keep them to round-off
(~1e-15), so the check is never what decides a normal solve. It is one product C z and four reductions, ~10 us on a
trot's QP (a DAQP solve takes ~0.1 ms).
"""

from __future__ import annotations

import importlib.metadata
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import daqp
import numpy as np
from proxsuite import proxqp

from wbc.errors import ConfigError
from wbc.mpc.dense_qp import DenseQp

__all__ = ["QP_SOLVERS", "RESIDUAL_TOLERANCE", "DaqpSolver", "ProxsuiteSolver", "QpResult", "QpSolver",
           "check_qp_solver", "constraint_violation", "make_qp_solver"]

RESIDUAL_TOLERANCE = 1e-4
"""The most a solution may break a bound or row by (in the problem's scaled units: 0.01 N on a force) and still count
as solved; a hundred times DAQP's primal tolerance, far above the round-off (~1e-15) of sane problems' solutions."""


def constraint_violation(qp: DenseQp, z: np.ndarray) -> float:
    """How far `z` breaks the problem's boxes and rows: the largest of l_box - z, z - u_box, l - C z, C z - u, or 0.

    Not finite when `z` is not.
    """
    cz = qp.C @ z
    # a NaN in z makes the first term NaN, which Python's max keeps (no comparison with it is true)
    worst = float(max((qp.l_box - z).max(), (z - qp.u_box).max(), (qp.l - cz).max(), (cz - qp.u).max(), 0.0))
    return worst if math.isfinite(worst) else math.inf


def _kept(qp: DenseQp, z: np.ndarray | None) -> bool:
    """Whether `z` is finite and keeps `qp`'s boxes and rows to `RESIDUAL_TOLERANCE`."""
    return z is not None and constraint_violation(qp, z) <= RESIDUAL_TOLERANCE


@dataclass(frozen=True, kw_only=True)
class QpResult:
    """One solve of a `DenseQp`.

    Attributes:
        z: the solution (n,), in the problem's own (scaled) variables; meaningful only when `solved`.
        solved: whether the backend reports an optimum, every entry of `z` is finite and `z` keeps the boxes and rows
            to `RESIDUAL_TOLERANCE`.
        status: the backend's own verdict, as it spells it (``exit flag 1``, ``PROXQP_SOLVED`` ...).
        iterations: the backend's iterations, warm and cold attempt together.
        solve_s: wall time of the call, warm and cold attempt together [s].
        warm: whether the returned solution came from the warm-started attempt.
    """

    z: np.ndarray
    solved: bool
    status: str
    iterations: int
    solve_s: float
    warm: bool


@runtime_checkable
class QpSolver(Protocol):
    """A QP backend: solves a `DenseQp` from an optional warm start, keeping no state between calls.

    Attributes:
        name: its registry name (`QP_SOLVERS`).
        label: its name in messages (``DAQP``, ``ProxSuite``).
    """

    name: str
    label: str

    def version(self) -> str:
        """The installed version of the backend's package."""
        ...

    def solve(self, qp: DenseQp, warm_start: np.ndarray | None = None) -> QpResult:
        """Solve `qp`, from `warm_start` (n,) when given (within the boxes), then cold if that failed."""
        ...


_DAQP_FLAGS = {1: "optimal", 2: "soft optimal", -1: "infeasible", -2: "cycling", -3: "unbounded",
               -4: "iteration limit", -5: "nonconvex", -6: "overdetermined initial active set"}


class DaqpSolver:
    """DAQP (dual active set), with its default tolerances (primal 1e-6, dual 1e-12)."""

    name = "daqp"
    label = "DAQP"

    def version(self) -> str:
        """DAQP's installed version."""
        return importlib.metadata.version("daqp")

    def solve(self, qp: DenseQp, warm_start: np.ndarray | None = None) -> QpResult:
        """Solve `qp` (see `QpSolver.solve`); only DAQP's exit flag 1 (optimal) with the constraints kept is solved.

        Args:
            qp: the problem.
            warm_start: initial primal point (n,), within the boxes; it seeds the active set. None: cold start.
        """
        t0 = time.perf_counter()
        # DAQP's bounds: the variables' boxes first, then the rows'
        upper = np.concatenate([qp.u_box, qp.u])
        lower = np.concatenate([qp.l_box, qp.l])
        sense = np.zeros(upper.size, dtype=np.int32)
        z, flag, iterations, warm = None, 0, 0, warm_start is not None
        if warm_start is not None:
            z, _, flag, info = daqp.solve(qp.H, qp.g, qp.C, upper, lower, sense, primal_start=warm_start)
            iterations = int(info["iterations"])
        if flag != 1 or not _kept(qp, z):  # no warm start, or one that went astray: a cold start
            warm = False
            sense[:] = 0
            z, _, flag, info = daqp.solve(qp.H, qp.g, qp.C, upper, lower, sense)
            iterations += int(info["iterations"])
        solved = flag == 1 and _kept(qp, z)
        status = f"exit flag {flag} ({_DAQP_FLAGS.get(flag, 'unknown')})"
        if flag == 1 and not solved:
            status += f", its solution breaking a constraint by {constraint_violation(qp, z):.3g}"
        return QpResult(z=np.asarray(z, dtype=np.float64), solved=solved, status=status, iterations=iterations,
                        solve_s=time.perf_counter() - t0, warm=warm)


class ProxsuiteSolver:
    """ProxSuite's dense ProxQP, a new solver object per attempt (no state kept), without equilibration.

    Args:
        eps_abs: absolute tolerance on the primal and dual residuals (the relative one is 0).
        eps_infeasible: ProxQP's primal and dual infeasibility thresholds. At ProxQP's own default, 1e-4, it
            declared 12 of 1,184 attempts on feasible QPs of pushed and turning walks infeasible; at 1e-9 none,
            and an infeasible QP (which the MPC's boxes and rows do not make) takes it seconds to declare (15-20 s
            an attempt on the A1's standing QP with a friction row pushed beyond the boxes, where DAQP takes
            microseconds).
        max_iter: ProxQP's iteration limit of one attempt (its outer iterations).
        mu_in: ProxQP's initial proximal parameter of the inequality rows (its ``default_mu_in``; ProxQP's own
            default is 0.1). Warm-started on the MPC's octagonal friction pyramids (eight rows a stance foot) with
            the default, ProxQP took up to 1,200 iterations where a start from rest took 12; at 1e-3 the previous
            solution saves iterations again, on the four-row pyramids too (tests/test_qp_solvers.py). A small
            parameter lets ProxQP stop on small residuals short of the optimum (2e-6 off in objective on a pushed
            robot's QP), so it also checks the duality gap, to `eps_abs`.
    """

    name = "proxsuite"
    label = "ProxSuite"

    def __init__(self, *, eps_abs: float = 1e-9, eps_infeasible: float = 1e-9, max_iter: int = 200,
                 mu_in: float = 1e-3) -> None:
        self.eps_abs = eps_abs
        self.mu_in = mu_in
        self.eps_infeasible = eps_infeasible
        self.max_iter = max_iter

    def version(self) -> str:
        """ProxSuite's installed version."""
        return importlib.metadata.version("proxsuite")

    def solve(self, qp: DenseQp, warm_start: np.ndarray | None = None) -> QpResult:
        """Solve `qp` (see `QpSolver.solve`); only ``PROXQP_SOLVED`` with the constraints kept counts as solved.

        Args:
            qp: the problem.
            warm_start: initial primal point (n,), handed to ProxQP as its warm start (the dual starts at zero).
                None: cold start (ProxQP's default initial guess, the box- and row-free optimum).
        """
        t0 = time.perf_counter()
        iterations, warm = 0, warm_start is not None
        x, status = None, None
        if warm_start is not None:
            x, status, its = self._attempt(qp, warm_start)
            iterations += its
        if status != proxqp.PROXQP_SOLVED or not _kept(qp, x):
            warm = False
            x, status, its = self._attempt(qp, None)
            iterations += its
        solved = status == proxqp.PROXQP_SOLVED and _kept(qp, x)
        name = status.name
        if status == proxqp.PROXQP_SOLVED and not solved:
            name += f", its solution breaking a constraint by {constraint_violation(qp, x):.3g}"
        return QpResult(z=x, solved=solved, status=name, iterations=iterations,
                        solve_s=time.perf_counter() - t0, warm=warm)

    def _attempt(self, qp: DenseQp, x0: np.ndarray | None) -> tuple[np.ndarray, proxqp.QPSolverOutput, int]:
        n, m = qp.H.shape[0], qp.C.shape[0]
        solver = proxqp.dense.QP(n, 0, m, True)  # True: box constraints on the variables, apart from the rows
        settings = solver.settings
        settings.eps_abs = self.eps_abs
        settings.eps_rel = 0.0
        settings.eps_primal_inf = self.eps_infeasible
        settings.eps_dual_inf = self.eps_infeasible
        settings.max_iter = self.max_iter
        settings.default_mu_in = self.mu_in
        settings.check_duality_gap = True
        settings.eps_duality_gap_abs = self.eps_abs
        settings.eps_duality_gap_rel = 0.0
        settings.initial_guess = (proxqp.InitialGuess.WARM_START if x0 is not None
                                  else proxqp.InitialGuess.EQUALITY_CONSTRAINED_INITIAL_GUESS)
        solver.init(qp.H, qp.g, None, None, qp.C, qp.l, qp.u, qp.l_box, qp.u_box, compute_preconditioner=False)
        if x0 is not None:
            solver.solve(np.asarray(x0, dtype=np.float64), None, None)
        else:
            solver.solve()
        results = solver.results
        return results.x.copy(), results.info.status, int(results.info.iter)


QP_SOLVERS: dict[str, Callable[[], QpSolver]] = {"daqp": DaqpSolver, "proxsuite": ProxsuiteSolver}
"""The QP backends by name (`MpcConfig.qp_solver`, ``wbc bench mpc --qp-solver``), the default first."""


def make_qp_solver(name: str) -> QpSolver:
    """The backend registered as `name`.

    Raises:
        ConfigError: `name` is not registered (the message lists the valid names).
    """
    check_qp_solver(name)
    return QP_SOLVERS[name]()


def check_qp_solver(name: str, what: str = "qp_solver") -> None:
    """Refuse a name that is not in `QP_SOLVERS`.

    Args:
        name: the name.
        what: what the name was given as, for the message (``MpcConfig.qp_solver``, ``--qp-solver``).

    Raises:
        ConfigError: `name` is not registered (the message lists the valid names).
    """
    if name not in QP_SOLVERS:
        raise ConfigError(f"{what} {name!r} is not a QP solver; valid QP solvers: {', '.join(QP_SOLVERS)}")
