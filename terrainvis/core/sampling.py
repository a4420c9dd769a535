"""Random test points on a terrain."""

from __future__ import annotations

import numpy as np

from .memory import check_memory
from .validate import as_finite_scalar, as_int, describe
from .terrain import TIN, HeightGrid, as_terrain

__all__ = ["sample_points"]


def sample_points(terrain, n: int, seed=0, offset: float = 0.0) -> np.ndarray:
    """``n`` points drawn uniformly over the terrain's valid footprint.

    Parameters
    ----------
    terrain : HeightGrid or TIN
    n : int
        Number of points.
    seed : int >= 0, None or numpy.random.Generator
        Seed of the generator (the same seed gives the same points; None: fresh entropy).
    offset : float
        Height added to the surface height (an observer's eye height).

    Returns
    -------
    (n, 3) float64
        x and y uniform over the footprint (triangles with a nodata vertex excluded), z on
        the surface plus ``offset``.

    Examples
    --------
    >>> from terrainvis import HeightGrid
    >>> pts = sample_points(HeightGrid(np.zeros((3, 3))), 4, seed=1, offset=2.0)
    >>> pts.shape, bool((pts[:, 2] == 2.0).all())
    ((4, 3), True)
    """
    as_terrain(terrain)
    n = as_int(n, "n", minimum=0)
    offset = as_finite_scalar(offset, "offset")
    rng = _generator(seed)
    # the draws, the positions, the heights and the result: about 128 bytes a point
    check_memory(128 * n, f"sample_points of {n:,} points")
    if isinstance(terrain, TIN):
        xy = _sample_tin(terrain, n, rng)
    else:
        xy = _sample_grid(terrain, n, rng)
    z = terrain.height_at(xy) + offset
    return np.column_stack([xy, z])


def _generator(seed) -> np.random.Generator:
    """``seed`` as a numpy Generator (numpy's own message for a bad seed names nothing)."""
    if isinstance(seed, np.random.Generator):
        return seed
    if isinstance(seed, (bool, np.bool_)):
        raise TypeError(f"seed must be an integer >= 0, None or a numpy Generator, got {describe(seed)}")
    if isinstance(seed, (int, np.integer)) and seed < 0:
        raise ValueError(f"seed must be >= 0 (or a numpy Generator), got {int(seed)}")
    try:
        return np.random.default_rng(seed)
    except (TypeError, ValueError):
        raise TypeError(f"seed must be an integer >= 0, None or a numpy Generator, got {describe(seed)}") from None


def _sample_grid(grid: HeightGrid, n: int, rng) -> np.ndarray:
    xmin, xmax, ymin, ymax = grid.extent
    if not grid.n_nodata:
        return np.column_stack([rng.uniform(xmin, xmax, n), rng.uniform(ymin, ymax, n)])
    # Rejection sampling over the extent: uniform over the valid part of the footprint.
    out = np.empty((0, 2))
    valid_fraction = np.isfinite(grid.z).mean()
    if valid_fraction == 0:
        raise ValueError("terrain has no valid (non-nodata) cell to sample from")
    for _ in range(1000):
        need = n - out.shape[0]
        if need <= 0:
            break
        m = int(need / max(valid_fraction, 1e-3) * 1.3) + 16
        cand = np.column_stack([rng.uniform(xmin, xmax, m), rng.uniform(ymin, ymax, m)])
        ok = np.isfinite(grid.height_at(cand))
        out = np.vstack([out, cand[ok][:need]])
    if out.shape[0] < n:
        raise ValueError("could not place the points: the valid part of the footprint is too small")
    return out


def _sample_tin(tin: TIN, n: int, rng) -> np.ndarray:
    # Area-weighted choice of a face, then a uniform point inside it.
    area = np.abs(tin.face_areas())
    total = area.sum()
    if not total > 0:
        raise ValueError("terrain has a zero footprint area")
    face = rng.choice(tin.n_faces, size=n, p=area / total)
    r1 = rng.random(n)
    r2 = rng.random(n)
    flip = r1 + r2 > 1
    r1[flip] = 1 - r1[flip]
    r2[flip] = 1 - r2[flip]
    v = tin.vertices[:, :2]
    f = tin.faces[face]
    a = v[f[:, 0]]
    return a + r1[:, None] * (v[f[:, 1]] - a) + r2[:, None] * (v[f[:, 2]] - a)
