"""What the tile writers share: the local metric frame of a tile and the record of a tile made."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: The radius of the local equirectangular frame (WGS84's semi-major axis, m).
EARTH_RADIUS = 6378137.0


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
