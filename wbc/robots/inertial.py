"""Rigid-body inertial parameters and the arithmetic to lump several bodies into one."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Inertial", "rpy_to_matrix", "lump"]


def rpy_to_matrix(rpy: tuple[float, float, float] | np.ndarray) -> np.ndarray:
    """URDF roll-pitch-yaw (fixed axes X, then Y, then Z) to a rotation matrix R = Rz(y) Ry(p) Rx(r)."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


@dataclass(frozen=True, kw_only=True)
class Inertial:
    """Mass properties of one link, expressed in the link frame.

    Attributes:
        mass: [kg].
        com: centre of mass in the link frame, shape (3,) [m].
        inertia: inertia tensor about the centre of mass, axes of the link frame, shape (3, 3) [kg m^2].
    """

    mass: float
    com: np.ndarray = field(default_factory=lambda: np.zeros(3))
    inertia: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))

    @classmethod
    def from_urdf(
        cls,
        mass: float,
        xyz: tuple[float, float, float],
        rpy: tuple[float, float, float],
        ixx: float, iyy: float, izz: float, ixy: float, ixz: float, iyz: float,
    ) -> Inertial:
        """Build from a URDF <inertial> block (inertia given in the frame rotated by `rpy`)."""
        i_frame = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]], dtype=np.float64)
        r = rpy_to_matrix(rpy)
        return cls(mass=float(mass), com=np.asarray(xyz, dtype=np.float64), inertia=r @ i_frame @ r.T)

    def transformed(self, rotation: np.ndarray, translation: np.ndarray) -> Inertial:
        """The same body seen from a parent frame in which this link frame sits at (rotation, translation)."""
        return Inertial(
            mass=self.mass,
            com=rotation @ self.com + np.asarray(translation, dtype=np.float64),
            inertia=rotation @ self.inertia @ rotation.T,
        )

    def scaled(self, factor: float) -> Inertial:
        """Same geometry, mass and inertia multiplied by `factor` (a lighter or heavier build of one link)."""
        return Inertial(mass=self.mass * factor, com=self.com.copy(), inertia=self.inertia * factor)


def lump(parts: list[Inertial]) -> Inertial:
    """Combine bodies given in one common frame into a single rigid body (parallel-axis theorem)."""
    mass = sum(p.mass for p in parts)
    com = sum(p.mass * p.com for p in parts) / mass
    inertia = np.zeros((3, 3))
    for p in parts:
        d = p.com - com
        inertia += p.inertia + p.mass * (np.dot(d, d) * np.eye(3) - np.outer(d, d))
    return Inertial(mass=mass, com=com, inertia=inertia)
