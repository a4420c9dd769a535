"""What the tile writers share: the local metric frame of a tile, the record of a tile made, and the loop
that simplifies a tile's lattice within its budget."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: The radius of the local equirectangular frame (WGS84's semi-major axis, m).
EARTH_RADIUS = 6378137.0
#: Retries of a tile over its budget before it is written as its whole lattice.
RETRIES = 3


def equirectangular(lon, lat, lon0: float, lat0: float) -> tuple[np.ndarray, np.ndarray]:
    """Local metres about (lon0, lat0): ``x = R cos(lat0) (lon - lon0) pi / 180``, ``y = R (lat - lat0) pi / 180``."""
    k = EARTH_RADIUS * math.pi / 180.0
    return k * math.cos(math.radians(lat0)) * (np.asarray(lon) - lon0), k * (np.asarray(lat) - lat0)


def sample_lattice(grid, frame, lon: np.ndarray, lat: np.ndarray, name: str, lon_at=None, lat_at=None):
    """A tile's lattice sampled on ``grid``: the heights at the lon/lat points of the axes ``lon``
    (west to east) and ``lat`` (south to north), or of ``lon_at`` / ``lat_at`` where given (the points
    whose heights stand there), through ``frame`` (lon/lat to the grid's frame), rows from the south;
    the lattice's centre (lon0, lat0); and the lattice as a HeightGrid evenly spaced in the local
    metres about that centre, the simplifiers' (the points sit up to half a quantization step off
    even spacing, and uneven steps make a near-degenerate triangle of greedy cuts stall).

    Raises
    ------
    ValueError
        When a point has no height (a nodata hole inside the tileset's rectangle).
    """
    from ..core.terrain import HeightGrid

    LON, LAT = np.meshgrid(lon if lon_at is None else lon_at, lat if lat_at is None else lat_at)
    xy = frame.to_grid(LON.ravel(), LAT.ravel())
    z = np.full(xy.shape[0], np.nan)
    ok = np.isfinite(xy).all(axis=1)
    z[ok] = grid.height_at(xy[ok])
    if not np.isfinite(z).all():
        bad = int(np.flatnonzero(~np.isfinite(z))[0])
        raise ValueError(f"{name} has no height at lon {LON.ravel()[bad]:.6f}, lat {LAT.ravel()[bad]:.6f}, inside the "
                         "tileset's rectangle (a nodata hole): fill the DEM's nodata first (--fill nearest, or "
                         "HeightGrid.fill_nodata)")
    z = z.reshape(LAT.shape)
    lon0, lat0 = 0.5 * (lon[0] + lon[-1]), 0.5 * (lat[0] + lat[-1])
    xs, ys = equirectangular(lon, lat, lon0, lat0)
    even = HeightGrid.from_coords(z, np.linspace(xs[0], xs[-1], xs.size), np.linspace(ys[0], ys[-1], ys.size))
    return z, float(lon0), float(lat0), even


@dataclass
class Made:
    """A tile made (or kept by a resume): its bytes (empty when kept), its measured error, the size of its
    mesh, why it fell back to the whole lattice, the method's own error measure and, for a quantized-mesh
    tile made now, the tile as decoded again."""

    data: bytes
    error: float
    n_vertices: int
    n_triangles: int
    fallback: str | None = None
    simplify_error: float | None = None  # the method's own measure (simplify's attrs["max_error"])
    decoded: object = field(default=None, repr=False)  # a quantized_mesh.DecodedTile (None when kept)


def within_budget(grid, method: str, budget: float, encode):
    """A tile of ``grid`` (a lattice) simplified by ``method`` within ``budget``, or why it cannot be.

    ``encode(tin)`` gives the tile made of a simplified TIN with its measured error, and the
    height step of its format; or a string saying why the TIN cannot be encoded. A tile over
    the budget plus half the step is simplified again with the budget lowered by the excess and
    the step, up to :data:`RETRIES` times. Returns ``(made, None)`` (its ``simplify_error`` the
    method's own measure) or ``(None, reason)``: the caller then writes the whole lattice.
    """
    from simplifiers import simplify

    from ..core.terrain import TIN
    from ..errors import SimplificationError
    from ..tolerances import TILE_BUDGET_REL

    target, reason = budget, None
    for _ in range(RETRIES + 1):
        try:
            result = simplify(grid, method, max_error=target)
        except (SimplificationError, ValueError) as exc:
            return None, f"{method} could not simplify the lattice: {exc}"
        got = encode(result if isinstance(result, TIN) else result.to_tin())
        if isinstance(got, str):
            return None, got
        made, step = got
        allowed = budget + 0.5 * step
        if made.error <= allowed * (1 + TILE_BUDGET_REL):
            made.simplify_error = float(result.attrs["max_error"])
            return made, None
        reason = f"over its budget after {RETRIES + 1} tries (error {made.error:.4g})"
        target = max(0.0, target - (made.error - allowed) - step)
    return None, reason
