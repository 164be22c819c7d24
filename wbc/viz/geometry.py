"""Small transform helpers for the viewer: translations, the rotation taking y onto a direction, arrows."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["arrow_transforms", "arrow_transforms_many", "rotation_y_to", "translation", "translations"]


def translation(p: np.ndarray) -> np.ndarray:
    """Homogeneous translation by `p` [m], shape (4, 4)."""
    return np.array([[1.0, 0.0, 0.0, p[0]], [0.0, 1.0, 0.0, p[1]], [0.0, 0.0, 1.0, p[2]], [0.0, 0.0, 0.0, 1.0]])


def translations(points: np.ndarray) -> np.ndarray:
    """Homogeneous translations to each row of `points` [m], shape (n, 4, 4)."""
    out = np.zeros((len(points), 4, 4))
    out[:, 0, 0] = out[:, 1, 1] = out[:, 2, 2] = out[:, 3, 3] = 1.0
    out[:, :3, 3] = points
    return out


def rotation_y_to(direction: np.ndarray) -> np.ndarray:
    """A rotation matrix whose y axis is `direction` (normalised; any unit vector if it is zero), shape (3, 3)."""
    # in scalars: the viewer poses a dozen arrows a frame, and numpy's cross of two 3-vectors costs ~30 us
    dx, dy, dz = (float(v) for v in direction)
    n = math.sqrt(dx * dx + dy * dy + dz * dz)
    y = (dx / n, dy / n, dz / n) if n > 1e-12 else (0.0, 1.0, 0.0)
    # x = y cross helper, the helper z (or x when y is near z), normalised; z = x cross y
    x = (y[1], -y[0], 0.0) if abs(y[2]) < 0.9 else (0.0, y[2], -y[1])
    nx = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])
    x = (x[0] / nx, x[1] / nx, x[2] / nx)
    z = (x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0])
    return np.array([[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]])


def arrow_transforms(start: np.ndarray, vector: np.ndarray, head_length: float) -> tuple[np.ndarray, np.ndarray]:
    """Transforms of an arrow's shaft and head.

    The shaft is a unit-height cylinder and the head a cone of height `head_length`, both along y and centred at
    their origin (meshcat's convention); the arrow runs from `start` to ``start + vector`` [m], head included.

    Returns:
        (shaft, head) homogeneous transforms, the shaft's scaled along its axis, shape (4, 4) each.
    """
    vx, vy, vz = (float(v) for v in vector)
    length = math.sqrt(vx * vx + vy * vy + vz * vz)
    rot = rotation_y_to(vector)
    axis = rot[:, 1]
    shaft_len = max(length - head_length, 1e-4)
    shaft = np.eye(4)
    shaft[:3, :3] = rot * np.array([1.0, shaft_len, 1.0])  # rot @ diag(1, shaft_len, 1)
    shaft[:3, 3] = start + 0.5 * shaft_len * axis
    head = np.eye(4)
    head[:3, :3] = rot
    head[:3, 3] = start + (shaft_len + 0.5 * head_length) * axis
    return shaft, head


def arrow_transforms_many(start: np.ndarray, vector: np.ndarray, head_length: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
    """`arrow_transforms` of n arrows at once: `start` and `vector` shape (n, 3) [m], `head_length` shape (n,) [m].

    Returns:
        (shafts, heads), shape (n, 4, 4) each.
    """
    n = len(vector)
    length = np.sqrt(np.einsum("ij,ij->i", vector, vector))
    y = np.zeros((n, 3))
    y[:, 1] = 1.0
    some = length > 1e-12
    y[some] = vector[some] / length[some, None]
    # as `rotation_y_to`: x = y cross the helper z (or x when y is near z), normalised; z = x cross y
    x = np.zeros((n, 3))
    flat = np.abs(y[:, 2]) < 0.9
    x[flat, 0], x[flat, 1] = y[flat, 1], -y[flat, 0]
    x[~flat, 1], x[~flat, 2] = y[~flat, 2], -y[~flat, 1]
    x /= np.sqrt(np.einsum("ij,ij->i", x, x))[:, None]
    z = np.cross(x, y)
    shaft_len = np.maximum(length - head_length, 1e-4)
    shafts = np.zeros((n, 4, 4))
    shafts[:, :3, 0], shafts[:, :3, 1], shafts[:, :3, 2] = x, y * shaft_len[:, None], z
    shafts[:, :3, 3] = start + (0.5 * shaft_len)[:, None] * y
    shafts[:, 3, 3] = 1.0
    heads = np.zeros((n, 4, 4))
    heads[:, :3, 0], heads[:, :3, 1], heads[:, :3, 2] = x, y, z
    heads[:, :3, 3] = start + (shaft_len + 0.5 * head_length)[:, None] * y
    heads[:, 3, 3] = 1.0
    return shafts, heads
