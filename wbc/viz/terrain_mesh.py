"""The ground in meshcat: a flat slab, or the fractal heightfield of a trial around where the robot walks.

The simulated heightfield is 20 m x 20 m at 5 cm (160 000 points); the viewer draws a window of it around the
start, resampled, which is what a screen shows anyway.
"""

from __future__ import annotations

import meshcat
import meshcat.geometry as mg
import numpy as np

from wbc.scenario.terrain import TerrainConfig, fractal_heights
from wbc.viz.geometry import translation

__all__ = ["TERRAIN", "setup_terrain", "terrain_geometry", "terrain_heights"]

TERRAIN = "wbc/terrain"


def terrain_geometry(config: TerrainConfig, heights: np.ndarray | None, *, half_window: float = 4.0,
                     step: float = 0.1) -> mg.TriangularMeshGeometry | None:
    """The heightfield as a triangle mesh, world coordinates, or None for flat ground.

    Args:
        config: the trial's terrain.
        heights: its normalised heights (in [0, 1], rows along y, as `fractal_heights` gives them and the
            simulator's heightfield holds them); None computes nothing (flat ground).
        half_window: half side of the square drawn around the origin [m].
        step: sample spacing of the drawn mesh [m] (a multiple of the terrain's cell is exact).
    """
    if config.kind == "flat" or heights is None:
        return None
    heights = np.asarray(heights, dtype=np.float64) * max(config.amplitude, 1e-4)
    n = heights.shape[0]
    coords = np.linspace(-config.half_extent, config.half_extent, n)
    stride = max(1, int(round(step / config.cell)))
    keep = np.where(np.abs(coords) <= min(half_window, config.half_extent) + 1e-9)[0][::stride]
    xs = coords[keep]
    z = heights[np.ix_(keep, keep)]  # rows along y
    gx, gy = np.meshgrid(xs, xs)
    vertices = np.column_stack([gx.ravel(), gy.ravel(), z.ravel()]).astype(np.float32)
    m = len(xs)
    idx = np.arange(m * m).reshape(m, m)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])]).astype(np.uint32)
    shade = (0.35 + 0.5 * (z.ravel() - z.min()) / max(float(np.ptp(z)), 1e-9)).astype(np.float32)
    color = np.column_stack([0.55 * shade, 0.6 * shade, 0.5 * shade + 0.1]).astype(np.float32)
    return mg.TriangularMeshGeometry(vertices, faces, color=color)


def terrain_heights(config: TerrainConfig, seed: int) -> np.ndarray | None:
    """Normalised heights of a trial's ground (None when flat): the simulator's own function of the seed."""
    return None if config.kind == "flat" else fractal_heights(config, seed)


def setup_terrain(vis: meshcat.Visualizer, config: TerrainConfig, heights: np.ndarray | None) -> str:
    """Draw the ground (`heights`: see `terrain_geometry`) and return its scene path."""
    geometry = terrain_geometry(config, heights)
    if geometry is None:
        vis[TERRAIN].set_object(mg.Box([8.0, 8.0, 0.02]), mg.MeshLambertMaterial(color=0x8c969e))
        vis[TERRAIN].set_transform(translation(np.array([0.0, 0.0, -0.0101])))
    else:
        vis[TERRAIN].set_object(geometry, mg.MeshLambertMaterial(vertexColors=True))
    return TERRAIN
