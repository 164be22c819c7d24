"""Meshcat geometry for the robot's visual model: URDF meshes (simplified) and primitives, one per geometry object.

The A1's and Go1's URDF meshes are Collada files of 0.7-4.7 MB each (the Go1 trunk alone has 350 000 triangles);
sent as they are, one robot makes a 27 MB page. Pinocchio has already loaded them (with their scale) into coal BVH
models, so the triangles are read from there and merged by vertex clustering on a `cell`-sized grid: a 3 mm grid
keeps the silhouette and brings the A1's meshes (9.4 MB of Collada) to 1.1 MB of binary triangles, the Go1's to
1.3 MB. Primitives (boxes, spheres, cylinders: the arm, the feet) become meshcat primitives; coal's cylinder axis is
z, meshcat's y, hence the extra rotation.

Loading the Collada files and building their trees takes most of a viewer's start (0.3 s for the A1, 2.3 s for the
Go1), so `robot_parts` keeps what it made of a robot in a cache directory (`cache_dir`): a file per robot, arm mode
and grid, named by a hash of the robot's URDF and of each mesh file's path, size and modification time. Any change to
those, or to the file's format, makes another name; a file that cannot be read or written is rebuilt or skipped, never
an error.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path

import meshcat.geometry as mg
import numpy as np
import pinocchio as pin

from wbc.robots.description import RobotDescription
from wbc.robots.pinocchio_model import build_pinocchio
from wbc.robots.urdf import example_robot_data_share, robot_urdf

__all__ = ["CACHE_ENV", "VisualPart", "cache_dir", "robot_parts", "simplify_mesh", "visual_parts"]

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
    keys -= keys.min(axis=0)
    span = keys.max(axis=0) + 1
    # one integer per grid cell (row-major over the cells' index box): a 1-D unique instead of a row-wise one
    flat = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
    _, first, inverse = np.unique(flat, return_index=True, return_inverse=True)
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


CACHE_ENV = "WBC_CACHE_DIR"
"""Environment variable naming the cache directory (default: ``$XDG_CACHE_HOME/wbc``, else ``~/.cache/wbc``)."""

_FORMAT = 1
"""Version of the cached parts' file format (part of every file's name)."""


def cache_dir() -> Path:
    """Where `robot_parts` keeps the robots' drawable parts."""
    env = os.environ.get(CACHE_ENV)
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME")
    return (Path(base) if base else Path.home() / ".cache") / "wbc"


def robot_parts(desc: RobotDescription, model: pin.Model, *, cell: float = 0.003) -> list[VisualPart]:
    """`visual_parts` of the robot `desc` (whose kinematic model is `model`), from the cache when it holds them.

    Without a cached file the visual model is built (meshes loaded) and the parts are written to the cache for the
    next process. The cached parts are exactly those `visual_parts` returns (float32 mesh arrays, as drawn).
    """
    urdf = robot_urdf(desc)
    path = cache_dir() / f"parts-{_parts_key(urdf, cell)}.npz"
    parts = _read_parts(path, model)
    if parts is None:
        visual = build_pinocchio(desc, with_visuals=True).visual_model
        parts = visual_parts(model, visual, cell=cell)
        _write_parts(path, parts)
    return parts


def _parts_key(urdf: str, cell: float) -> str:
    """The cache name of a robot's parts: its URDF, its mesh files (path, size, time), the grid, the format."""
    digest = hashlib.sha256(f"{_FORMAT}\n{cell!r}\n{urdf}".encode())
    share = example_robot_data_share()
    for name in sorted(set(re.findall(r'filename="package://([^"]+)"', urdf))):
        file = share / name
        try:
            stat = file.stat()
            digest.update(f"\n{file}:{stat.st_size}:{stat.st_mtime_ns}".encode())
        except OSError:
            digest.update(f"\n{file}:missing".encode())
    return digest.hexdigest()[:32]


def _write_parts(path: Path, parts: list[VisualPart]) -> None:
    """Write `parts` to `path` (atomically); a cache that cannot be written is skipped."""
    meta, arrays = [], {}
    for i, p in enumerate(parts):
        g = p.geometry
        if isinstance(g, mg.TriangularMeshGeometry):
            kind, params = "mesh", []
            arrays[f"v{i}"], arrays[f"f{i}"] = np.asarray(g.vertices), np.asarray(g.faces)
        elif isinstance(g, mg.Box):
            kind, params = "box", [float(x) for x in g.lengths]
        elif isinstance(g, mg.Sphere):
            kind, params = "sphere", [float(g.radius)]
        elif isinstance(g, mg.Cylinder):
            kind, params = "cylinder", [float(g.height), float(g.radiusTop)]
        else:
            return
        meta.append({"name": p.name, "joint": p.joint, "kind": kind, "params": params, "color": p.color,
                     "arm": p.is_arm, "placement": p.placement.tolist()})
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".tmp", delete=False) as f:
            np.savez(f, **arrays)
        os.replace(f.name, path)
    except OSError:
        return


def _read_parts(path: Path, model: pin.Model) -> list[VisualPart] | None:
    """The parts cached at `path` for a robot of kinematic model `model`, or None (absent, unreadable, stale)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(z["meta"].tobytes().decode())
            parts = []
            for i, m in enumerate(meta):
                if not model.existJointName(m["joint"]):
                    return None
                kind, params = m["kind"], m["params"]
                if kind == "mesh":
                    geometry: mg.Geometry = mg.TriangularMeshGeometry(z[f"v{i}"], z[f"f{i}"])
                elif kind == "box":
                    geometry = mg.Box(params)
                elif kind == "sphere":
                    geometry = mg.Sphere(params[0])
                elif kind == "cylinder":
                    geometry = mg.Cylinder(params[0], params[1])
                else:
                    return None
                parts.append(VisualPart(name=m["name"], joint=m["joint"], joint_id=int(model.getJointId(m["joint"])),
                                        placement=np.array(m["placement"], dtype=np.float64), geometry=geometry,
                                        color=int(m["color"]), is_arm=bool(m["arm"])))
            return parts
    except (OSError, ValueError, KeyError, TypeError, json.JSONDecodeError):
        return None
