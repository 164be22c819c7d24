"""How the MuJoCo and Pinocchio models of one robot index the same configuration.

MuJoCo (and the robot interface):
    qpos = [p_base_in_world (3), quat_base_to_world (w, x, y, z), q_joints (house order)]
    qvel = [v_base_in_world (3), omega_base_in_body (3), dq_joints (house order)]
Pinocchio (free-flyer root):
    q = [p_base_in_world (3), quat_base_to_world (x, y, z, w), q_joints (Pinocchio order)]
    v = [v_base_in_body (3), omega_base_in_body (3), dq_joints (Pinocchio order)]

Pinocchio's URDF parser visits the trunk's children alphabetically (FL, FR, RL, RR), MuJoCo in file order (FR, FL, RR,
RL, the house order), so joint blocks are permuted by name. The linear velocity differs in frame:
v_pin = R^T v_mj with R the base rotation. Quaternions are reordered only at this boundary.
"""

from __future__ import annotations

import numpy as np

from wbc.errors import ConfigError

__all__ = ["G", "GRAVITY", "ROOT_JOINT", "JointIndexMap", "quat_to_matrices", "quat_to_matrix", "quat_wxyz_to_xyzw",
           "quat_xyzw_to_wxyz", "upside_down"]

ROOT_JOINT = "root"
G = 9.81
"""Gravity's magnitude [m/s^2] (MuJoCo's default, the simulator's)."""
GRAVITY = np.array([0.0, 0.0, -G])
"""Gravity acceleration, world frame (z up) [m/s^2]."""


def quat_wxyz_to_xyzw(q: np.ndarray) -> np.ndarray:
    """(w, x, y, z) -> (x, y, z, w)."""
    return np.array([q[1], q[2], q[3], q[0]], dtype=np.float64)


def quat_xyzw_to_wxyz(q: np.ndarray) -> np.ndarray:
    """(x, y, z, w) -> (w, x, y, z)."""
    return np.array([q[3], q[0], q[1], q[2]], dtype=np.float64)


def quat_to_matrix(q_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion (w, x, y, z)."""
    # called every control tick: one list of floats and one array, no per-element numpy scalars
    w, x, y, z = np.asarray(q_wxyz, dtype=np.float64).tolist()
    return np.array([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ]).reshape(3, 3)


def upside_down(q_wxyz: np.ndarray) -> bool:
    """Whether a trunk of orientation `q_wxyz` (a unit quaternion, body to world) is upside down.

    Upside down: its up axis points below the horizon. The up axis's height in the world is 1 - 2 (x^2 + y^2).
    """
    x, y = float(q_wxyz[1]), float(q_wxyz[2])
    return x * x + y * y > 0.5


def quat_to_matrices(quat_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) of unit quaternions (N, 4) (w, x, y, z): `quat_to_matrix` over a batch."""
    w, x, y, z = (quat_wxyz[:, i] for i in range(4))
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=1)


class JointIndexMap:
    """Permutation between the house joint order and Pinocchio's joint order.

    Args:
        house_names: joint names in the house order.
        pin_names: joint names in Pinocchio's order (``model.names[2:]``).
    """

    def __init__(self, house_names: tuple[str, ...], pin_names: tuple[str, ...]) -> None:
        if sorted(house_names) != sorted(pin_names):
            raise ConfigError(f"joint sets differ: {sorted(house_names)} vs {sorted(pin_names)}; build the Pinocchio "
                              "model from the same description as the house joint order")
        self.pin_from_house = np.array([house_names.index(n) for n in pin_names])
        self.house_from_pin = np.array([pin_names.index(n) for n in house_names])

    def q_pin(self, qpos: np.ndarray) -> np.ndarray:
        """Pinocchio configuration from a MuJoCo qpos."""
        qj = qpos[7:][self.pin_from_house]
        return np.concatenate([qpos[:3], quat_wxyz_to_xyzw(qpos[3:7]), qj])

    def v_pin(self, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        """Pinocchio velocity from a MuJoCo (qpos, qvel)."""
        rot = quat_to_matrix(qpos[3:7])
        return np.concatenate([rot.T @ qvel[:3], qvel[3:6], qvel[6:][self.pin_from_house]])

    def velocity_map(self, qpos: np.ndarray) -> np.ndarray:
        """Matrix T with v_pin = T qvel (so M_mj = T^T M_pin T)."""
        n = qpos.shape[0] - 1
        t = np.zeros((n, n))
        t[:3, :3] = quat_to_matrix(qpos[3:7]).T
        t[3:6, 3:6] = np.eye(3)
        t[6 + np.arange(n - 6), 6 + self.pin_from_house] = 1.0
        return t
