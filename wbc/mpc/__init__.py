"""The model-based contender: centroidal dynamics with arm momentum and the MPC that plans with them."""

from wbc.mpc.centroidal_model import CentroidalModel, CentroidalParams, SymbolicCentroidalModel
from wbc.mpc.centroidal_mpc import CentroidalMpc, DenseQp, MpcConfig, MpcProblem, MpcSolution, MpcSolveError

__all__ = [
    "CentroidalModel",
    "CentroidalMpc",
    "CentroidalParams",
    "MpcConfig",
    "MpcProblem",
    "MpcSolution",
    "MpcSolveError",
    "DenseQp",
    "SymbolicCentroidalModel",
]
