"""The model-based contender: centroidal dynamics with arm momentum and the MPC that plans with them."""

from wbc.mpc.centroidal_model import CentroidalModel, CentroidalParams, SymbolicCentroidalModel
from wbc.mpc.centroidal_mpc import CentroidalMpc, MpcConfig, MpcProblem, MpcSolution, MpcSolveError
from wbc.mpc.dense_qp import DenseQp
from wbc.mpc.qp_solvers import QP_SOLVERS, DaqpSolver, ProxsuiteSolver, QpResult, QpSolver, make_qp_solver

__all__ = [
    "CentroidalModel",
    "CentroidalMpc",
    "CentroidalParams",
    "MpcConfig",
    "MpcProblem",
    "MpcSolution",
    "MpcSolveError",
    "DenseQp",
    "QP_SOLVERS",
    "DaqpSolver",
    "ProxsuiteSolver",
    "QpResult",
    "QpSolver",
    "make_qp_solver",
    "SymbolicCentroidalModel",
]
