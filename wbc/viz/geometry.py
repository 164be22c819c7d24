"""Small transform helpers for the viewer: translations, the rotation taking y onto a direction, arrows."""

from __future__ import annotations

import numpy as np

__all__ = ["arrow_transforms", "rotation_y_to", "translation"]


def translation(p: np.ndarray) -> np.ndarray:
    """Homogeneous translation by `p` [m], shape (4, 4)."""
    return np.array([[1.0, 0.0, 0.0, p[0]], [0.0, 1.0, 0.0, p[1]], [0.0, 0.0, 1.0, p[2]], [0.0, 0.0, 0.0, 1.0]])


def rotation_y_to(direction: np.ndarray) -> np.ndarray:
    """A rotation matrix whose y axis is `direction` (normalised; any unit vector if it is zero), shape (3, 3)."""
    n = float(np.linalg.norm(direction))
    y = np.asarray(direction, dtype=np.float64) / n if n > 1e-12 else np.array([0.0, 1.0, 0.0])
    helper = np.array([0.0, 0.0, 1.0]) if abs(y[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(y, helper)
    x /= np.linalg.norm(x)
    z = np.cross(x, y)
    return np.column_stack([x, y, z])


def arrow_transforms(start: np.ndarray, vector: np.ndarray, head_length: float) -> tuple[np.ndarray, np.ndarray]:
    """Transforms of an arrow's shaft and head.

    The shaft is a unit-height cylinder and the head a cone of height `head_length`, both along y and centred at
    their origin (meshcat's convention); the arrow runs from `start` to ``start + vector`` [m], head included.

    Returns:
        (shaft, head) homogeneous transforms, the shaft's scaled along its axis, shape (4, 4) each.
    """
    length = float(np.linalg.norm(vector))
    rot = rotation_y_to(vector)
    axis = rot[:, 1]
    shaft_len = max(length - head_length, 1e-4)
    shaft = np.eye(4)
    shaft[:3, :3] = rot @ np.diag([1.0, shaft_len, 1.0])
    shaft[:3, 3] = start + 0.5 * shaft_len * axis
    head = np.eye(4)
    head[:3, :3] = rot
    head[:3, 3] = start + (shaft_len + 0.5 * head_length) * axis
    return shaft, head
