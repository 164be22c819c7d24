"""Ground for the MuJoCo backend: a flat floor or a seeded fractal heightfield.

The fractal is a sum of octaves of bilinearly interpolated value noise (each octave twice the frequency and
`persistence` times the amplitude of the previous one). The same seed gives the same terrain on every machine.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wbc.errors import ConfigError, UnknownNameError

__all__ = ["MAX_OCTAVES", "MAX_SAMPLES", "TERRAIN_KINDS", "TerrainConfig", "fractal_heights"]

TERRAIN_KINDS = ("flat", "fractal")

MAX_SAMPLES = 2001
"""Most heightfield samples along each axis: a 100 m square at the default 5 cm cell. `fractal_heights` holds about
eight (samples x samples) float64 arrays at once, ~300 MB at this size, and MuJoCo one more."""

MAX_OCTAVES = 8
"""Most noise octaves: the eighth is already 128 times finer than the first."""


@dataclass(frozen=True, kw_only=True)
class TerrainConfig:
    """Ground shape.

    Attributes:
        kind: ``flat`` or ``fractal``.
        half_extent: the heightfield covers [-half_extent, half_extent]^2 around the origin [m].
        cell: heightfield resolution [m].
        amplitude: peak-to-peak height of the fractal [m].
        octaves: number of noise octaves.
        base_cell: wavelength of the coarsest octave [m].
        persistence: amplitude ratio between successive octaves.
    """

    kind: str = "flat"
    half_extent: float = 10.0
    cell: float = 0.05
    amplitude: float = 0.05
    octaves: int = 4
    base_cell: float = 1.6
    persistence: float = 0.5

    def __post_init__(self) -> None:
        if self.kind not in TERRAIN_KINDS:
            raise UnknownNameError("terrain kind", self.kind, TERRAIN_KINDS)
        for name in ("half_extent", "cell", "base_cell"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"TerrainConfig.{name} must be a finite positive length [m], got {value}")
        if not (self.amplitude >= 0 and 0 < self.persistence <= 1 and 1 <= self.octaves <= MAX_OCTAVES):
            raise ConfigError(f"TerrainConfig: amplitude >= 0, 0 < persistence <= 1 and 1 <= octaves <= {MAX_OCTAVES} "
                              f"are required, got amplitude {self.amplitude}, persistence {self.persistence}, octaves "
                              f"{self.octaves}")
        if self.samples > MAX_SAMPLES:
            raise ConfigError(f"TerrainConfig: {self.samples} heightfield samples per axis (2 half_extent / cell + 1 "
                              f"with half_extent {self.half_extent:g} m, cell {self.cell:g} m), more than "
                              f"{MAX_SAMPLES}; shrink half_extent or coarsen cell")
        if self.finest_wavelength < self.cell:
            raise ConfigError(f"TerrainConfig: the finest octave's wavelength base_cell / 2^(octaves - 1) = "
                              f"{self.finest_wavelength:g} m is shorter than the heightfield cell {self.cell:g} m: "
                              "the grid cannot show it, and its noise lattice would outgrow the heightfield; raise "
                              f"base_cell to >= {self.cell * 2 ** (self.octaves - 1):g} m or use fewer octaves")

    @property
    def finest_wavelength(self) -> float:
        """Wavelength of the finest noise octave, ``base_cell / 2^(octaves - 1)`` [m]."""
        return self.base_cell / 2 ** (self.octaves - 1)

    @property
    def samples(self) -> int:
        """Heightfield samples along each axis."""
        return int(round(2 * self.half_extent / self.cell)) + 1


def fractal_heights(config: TerrainConfig, seed: int) -> np.ndarray:
    """Heights of the fractal terrain, shape (samples, samples), rows along y, in [0, 1] (scaled by amplitude).

    Args:
        config: terrain shape.
        seed: the terrain's seed.
    """
    n = config.samples
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x7E88]))
    coords = np.linspace(0.0, 2 * config.half_extent, n)
    total = np.zeros((n, n))
    amp, wavelength = 1.0, config.base_cell
    for _ in range(config.octaves):
        m = int(np.ceil(2 * config.half_extent / wavelength)) + 2
        lattice = rng.uniform(-1.0, 1.0, size=(m, m))
        u = coords / wavelength
        i0 = np.floor(u).astype(int)
        f = u - i0
        f = f * f * (3 - 2 * f)  # smoothstep between lattice points
        a = lattice[np.ix_(i0, i0)]
        b = lattice[np.ix_(i0, i0 + 1)]
        c = lattice[np.ix_(i0 + 1, i0)]
        d = lattice[np.ix_(i0 + 1, i0 + 1)]
        fy, fx = f[:, None], f[None, :]
        total += amp * ((a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy)
        amp *= config.persistence
        wavelength /= 2.0
    lo, hi = total.min(), total.max()
    return (total - lo) / (hi - lo) if hi > lo else np.zeros_like(total)
