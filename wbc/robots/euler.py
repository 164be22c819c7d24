"""ZYX Euler angles (roll, pitch, yaw), to and from rotation matrices.

R = Rz(yaw) Ry(pitch) Rx(roll), body to world: the orientation of the MPC's state and of the runner's logged roll,
pitch and yaw. They run every tick on a handful of scalars, so they work in Python floats.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["rotation_from_rpy", "rpy_of", "yaw_of"]


def yaw_of(rot: np.ndarray) -> float:
    """Yaw of a rotation matrix (body to world), in (-pi, pi] [rad]."""
    return math.atan2(rot.item(1, 0), rot.item(0, 0))


def rpy_of(rot: np.ndarray) -> np.ndarray:
    """Roll, pitch and yaw of a rotation matrix (body to world) [rad]; pitch clamped to [-pi/2, pi/2]."""
    return np.array([math.atan2(rot[2, 1], rot[2, 2]), -math.asin(max(-1.0, min(1.0, rot[2, 0]))), yaw_of(rot)])


def rotation_from_rpy(rpy: np.ndarray) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll) from (roll, pitch, yaw) [rad]."""
    roll, pitch, yaw = rpy.tolist()
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])
