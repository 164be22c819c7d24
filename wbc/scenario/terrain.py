"""Ground for the MuJoCo backend: a flat floor or a seeded fractal heightfield.

The fractal is a sum of octaves of bilinearly interpolated value noise (each octave twice the frequency and
`persistence` times the amplitude of the previous one). The same seed gives the same terrain on every machine.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wbc.errors import ConfigError, UnknownNameError

__all__ = ["TERRAIN_KINDS", "TerrainConfig", "fractal_heights"]

TERRAIN_KINDS = ("flat", "fractal")


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
            if not getattr(self, name) > 0:
                raise ConfigError(f"TerrainConfig.{name} must be positive, got {getattr(self, name)}")
        if self.amplitude < 0 or not 0 < self.persistence <= 1 or self.octaves < 1:
            raise ConfigError("TerrainConfig: amplitude >= 0, 0 < persistence <= 1 and octaves >= 1 are required")

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
