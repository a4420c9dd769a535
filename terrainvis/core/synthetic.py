"""Synthetic terrains, from smooth hills to terraced mesas with cliffs.

The paper tested five 120x120 height maps "with varying levels of sharp features". The
generators here span that range:

============  ==========================================================  ==========
kind          what it looks like                                          relief (m)
============  ==========================================================  ==========
hills         smooth rolling hills: 3 octaves of cubic value noise         150
mountains     fBm mountains: 6 octaves, persistence 0.5                    700
rough         rough high-frequency fBm: 7 octaves, persistence 0.7         300
ridges        ridged multifractal with sharp crests                        800
mesas         terraced mesas: smooth fBm quantised into steps with cliffs  300
============  ==========================================================  ==========

Cells are 30 m (SRTM 1 arc-second), so a 120x120 map covers 3.57 km x 3.57 km; the
reliefs are those of real terrain of that extent (mean slopes at 120x120, seed 0: hills 4°,
mesas 8°, rough 20°, mountains 22°, ridges 30°) (compare the shared DEMs: 117 m for the
Colorado plains, 840 m around the Jacksboro fault, 1861 m at Mount St. Helens).

The project's five default terrains are frozen in ``terrainvis/data/*.npz`` (written by
``synthetic_terrain(kind, size=120, seed=0)``; see ``terrainvis/data/README.md``) so that results do
not drift with numpy or scipy versions. :func:`bundled_terrain` loads them.
"""

from __future__ import annotations

import numpy as np

from .validate import as_int
from .terrain import HeightGrid

__all__ = ["KINDS", "CELL_SIZE", "synthetic_terrain", "BUNDLED"]

#: Names accepted by :func:`synthetic_terrain`, smooth to sharp.
KINDS = ("hills", "mountains", "rough", "ridges", "mesas")
#: Names of the five frozen 120x120 terrains in ``terrainvis/data/`` (one per kind, seed 0).
BUNDLED = KINDS
#: Cell size of the synthetic terrains in metres.
CELL_SIZE = 30.0

_RELIEF = {"hills": 150.0, "mountains": 700.0, "rough": 300.0, "ridges": 800.0, "mesas": 300.0}
_BASE_ELEVATION = {"hills": 220.0, "mountains": 1200.0, "rough": 600.0, "ridges": 1500.0, "mesas": 1700.0}


def _octave(rng: np.random.Generator, size: int, cells: int) -> np.ndarray:
    """Cubic value noise with ``cells`` lattice cells across the map, roughly in [-1, 1]."""
    lattice = rng.uniform(-1.0, 1.0, size=(cells + 4, cells + 4))
    t = np.linspace(0.0, cells, size) + 1.5  # stay clear of the lattice edge for the spline
    yy, xx = np.meshgrid(t, t, indexing="ij")
    from scipy import ndimage  # here, not at import: every command that resolves a DEM imports this module

    return ndimage.map_coordinates(lattice, [yy, xx], order=3, mode="nearest")


def _fbm(rng, size: int, octaves: int, persistence: float, base_cells: int) -> np.ndarray:
    total = np.zeros((size, size))
    amp = 1.0
    for k in range(octaves):
        total += amp * _octave(rng, size, base_cells * 2**k)
        amp *= persistence
    return total


def _ridged(rng, size: int, octaves: int, base_cells: int) -> np.ndarray:
    """Ridged multifractal: sharp crests where the noise crosses zero."""
    total = np.zeros((size, size))
    weight = np.ones((size, size))
    amp = 1.0
    for k in range(octaves):
        signal = (1.0 - np.abs(_octave(rng, size, base_cells * 2**k))) ** 2
        signal *= weight
        weight = np.clip(signal * 2.0, 0.0, 1.0)
        total += amp * signal
        amp *= 0.5
    return total


def _terraces(h: np.ndarray, steps: int, cliff: float) -> np.ndarray:
    """Quantise ``h`` in [0, 1] into ``steps`` flat terraces joined by cliffs of width ``cliff``."""
    t = h * steps
    k = np.floor(t)
    frac = t - k
    rise = np.clip((frac - (1.0 - cliff)) / cliff, 0.0, 1.0)
    rise = rise * rise * (3.0 - 2.0 * rise)
    return (k + rise) / steps


def _unit(a: np.ndarray) -> np.ndarray:
    lo, hi = a.min(), a.max()
    return (a - lo) / (hi - lo) if hi > lo else np.zeros_like(a)


def synthetic_terrain(kind: str, size: int = 120, seed: int = 0) -> HeightGrid:
    """A synthetic terrain of ``size`` x ``size`` samples with 30 m cells.

    Parameters
    ----------
    kind : str
        One of :data:`KINDS`: ``"hills"``, ``"mountains"``, ``"rough"``, ``"ridges"``,
        ``"mesas"`` (smooth to sharp).
    size : int
        Samples per side (at least 2).
    seed : int
        Seed; the same kind, size and seed give the same terrain.

    Returns
    -------
    HeightGrid
        Uniform grid with ``dx = dy = 30`` m and origin (0, 0); heights in metres.

    Examples
    --------
    >>> g = synthetic_terrain("hills", size=64, seed=1)
    >>> g.shape, g.dx
    ((64, 64), 30.0)
    """
    if not isinstance(kind, str) or kind not in KINDS:
        raise ValueError(f"kind must be one of {list(KINDS)}, got {kind!r}")
    size = as_int(size, "size", minimum=2)
    seed = as_int(seed, "seed", minimum=0)
    rng = np.random.default_rng([int(seed), KINDS.index(kind)])
    scale = max(1, round(size / 120))  # keep the features' size in cells as the map grows
    if kind == "hills":
        h = _fbm(rng, size, 3, 0.45, 2 * scale)
    elif kind == "mountains":
        h = _fbm(rng, size, 6, 0.5, 2 * scale)
    elif kind == "rough":
        h = _fbm(rng, size, 7, 0.7, 3 * scale)
    elif kind == "ridges":
        h = _ridged(rng, size, 6, 2 * scale)
    else:  # mesas
        base = _unit(_fbm(rng, size, 4, 0.45, 2 * scale))
        h = _terraces(base, 5, 0.15) + 0.02 * _fbm(rng, size, 3, 0.5, 8 * scale)
    z = _BASE_ELEVATION[kind] + _RELIEF[kind] * _unit(h)
    return HeightGrid(z, dx=CELL_SIZE, dy=CELL_SIZE, attrs={"name": kind, "seed": int(seed), "synthetic": True})
