"""Meshcat geometry for the robot's visual model: URDF meshes (simplified) and primitives, one per geometry object.

The A1's and Go1's URDF meshes are Collada files of 0.7-4.7 MB each (the Go1 trunk alone has 350 000 triangles);
sent as they are, one robot makes a 27 MB page. Pinocchio has already loaded them (with their scale) into coal BVH
models, so the triangles are read from there and merged by vertex clustering on a `cell`-sized grid: a 3 mm grid
keeps the silhouette and brings the A1's meshes (9.4 MB of Collada) to 1.1 MB of binary triangles, the Go1's to
1.3 MB. Primitives (boxes, spheres, cylinders: the arm, the feet) become meshcat primitives; coal's cylinder axis is
z, meshcat's y, hence the extra rotation.
"""

from __future__ import annotations

from dataclasses import dataclass

import meshcat.geometry as mg
import numpy as np
import pinocchio as pin

__all__ = ["VisualPart", "simplify_mesh", "visual_parts"]

_Y_TO_Z = np.array([[1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])
"""Rotation taking meshcat's cylinder axis (y) onto coal's (z)."""


@dataclass(frozen=True)
class VisualPart:
    """One visual geometry object ready for meshcat.

    Attributes:
        name: the geometry object's name (``FL_calf_0``, ``arm_forearm_link_0`` ...).
        joint: name of the Pinocchio joint it moves with (``root_joint`` for the trunk).
        joint_id: that joint's index in the Pinocchio model.
        placement: its pose in the joint frame, including the primitive's axis fix, shape (4, 4).
        geometry: the meshcat geometry.
        color: RGB as 0xRRGGBB.
        is_arm: True for the arm's links.
    """

    name: str
    joint: str
    joint_id: int
    placement: np.ndarray
    geometry: mg.Geometry
    color: int
    is_arm: bool


def simplify_mesh(vertices: np.ndarray, faces: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices that fall in the same `cell` [m] grid cell; drop triangles that collapse.

    Args:
        vertices: shape (n, 3) [m].
        faces: vertex indices, shape (m, 3).
        cell: grid size [m]; 0 returns the mesh unchanged.

    Returns:
        (vertices, faces) of the simplified mesh; each kept vertex is the mean of its cluster.
    """
    if cell <= 0:
        return vertices, faces
    keys = np.floor(vertices / cell).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    counts = np.bincount(inverse, minlength=first.size)[:, None]
    merged = np.zeros((first.size, 3))
    np.add.at(merged, inverse, vertices)
    merged /= counts
    f = inverse[faces]
    keep = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
    return merged, f[keep]


_MESHES: dict[tuple[str, tuple[float, ...], float], tuple[np.ndarray, np.ndarray]] = {}
"""Simplified meshes by (file, scale, cell): a robot's four calves share one entry."""


def _mesh_arrays(g: pin.GeometryObject, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Simplified (vertices, faces) of a mesh object, read from the BVH Pinocchio loaded."""
    key = (g.meshPath, tuple(float(s) for s in g.meshScale), cell)
    if key not in _MESHES:
        bvh = g.geometry
        vertices = np.asarray(bvh.vertices(), dtype=np.float64)
        faces = np.array([[t[0], t[1], t[2]] for t in (bvh.tri_indices(i) for i in range(bvh.num_tris))],
                         dtype=np.int64)
        _MESHES[key] = simplify_mesh(vertices, faces, cell)
    return _MESHES[key]


def _color(rgba: np.ndarray) -> int:
    r, g, b = (int(round(255 * float(np.clip(c, 0.0, 1.0)))) for c in rgba[:3])
    return (r << 16) | (g << 8) | b


def visual_parts(model: pin.Model, visual_model: pin.GeometryModel, *, cell: float = 0.003) -> list[VisualPart]:
    """Meshcat geometry for every object of `visual_model`.

    Args:
        model: the kinematic model the geometry hangs on.
        visual_model: Pinocchio's visual geometry (URDF meshes and primitives).
        cell: mesh simplification grid [m] (0: full meshes).

    Returns:
        One part per geometry object, in the visual model's order; objects of unknown shape and sub-millimetre
        placeholders (the URDFs' 1 mm ``base`` and ``imu_link`` boxes) are left out.
    """
    parts = []
    for g in visual_model.geometryObjects:
        geo = g.geometry
        placement = g.placement.homogeneous.copy()
        kind = type(geo).__name__
        if g.meshPath and kind.startswith("BVH"):
            v, f = _mesh_arrays(g, cell)
            geometry: mg.Geometry = mg.TriangularMeshGeometry(v.astype(np.float32), f.astype(np.uint32))
        elif kind == "Box":
            size = 2.0 * np.asarray(geo.halfSide)
            if size.max() < 0.002:
                continue
            geometry = mg.Box(size.tolist())
        elif kind == "Sphere":
            geometry = mg.Sphere(float(geo.radius))
        elif kind == "Cylinder":
            geometry = mg.Cylinder(2.0 * float(geo.halfLength), float(geo.radius))
            placement = placement @ _Y_TO_Z
        else:
            continue
        joint = model.names[g.parentJoint]
        parts.append(VisualPart(name=g.name, joint=joint, joint_id=int(g.parentJoint), placement=placement,
                                geometry=geometry, color=_color(g.meshColor), is_arm=g.name.startswith("arm_")))
    return parts
