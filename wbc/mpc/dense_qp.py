"""`DenseQp`: a dense QP as the MPC builds it and every QP backend (`wbc.mpc.qp_solvers`) takes it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["DenseQp"]


@dataclass
class DenseQp:
    """A dense QP: min 1/2 z^T H z + g^T z s.t. l <= C z <= u, l_box <= z <= u_box.

    An `wbc.mpc.centroidal_mpc.MpcProblem` is one, with what turns its solution into a plan.

    Attributes:
        H: its Hessian, shape (n, n).
        g: its gradient (n,).
        C: its inequality rows, shape (m, n).
        l: its row lower bounds (m,) (-inf where one-sided).
        u: its row upper bounds (m,).
        l_box: its variable lower bounds (n,).
        u_box: its variable upper bounds (n,).
    """

    H: np.ndarray
    g: np.ndarray
    C: np.ndarray
    l: np.ndarray  # noqa: E741 - the usual name for the lower bounds
    u: np.ndarray
    l_box: np.ndarray
    u_box: np.ndarray

    def objective(self, z: np.ndarray) -> float:
        """The cost 1/2 z^T H z + g^T z at `z`."""
        return float(0.5 * z @ self.H @ z + self.g @ z)
