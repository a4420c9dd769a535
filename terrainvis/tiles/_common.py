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
