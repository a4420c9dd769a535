"""Cesium's default geographic tiling scheme (EPSG:4326, TMS rows counted from the south).

Zoom ``z`` cuts the globe into ``2**(z + 1)`` columns and ``2**z`` rows of square tiles,
each ``180 / 2**z`` degrees wide and high: zoom 0 is two tiles, the western and the
eastern hemisphere. Column ``x`` counts from the antimeridian (-180) eastwards and row ``y``
from the south pole northwards (the TMS order, Cesium's ``GeographicTilingScheme`` with
``"scheme": "tms"`` in ``layer.json``); a tile's file is ``{z}/{x}/{y}.terrain``.
"""

from __future__ import annotations

import math

from ..core.validate import as_int

__all__ = ["FORMATS", "MAX_ZOOM", "tile_count", "tile_size", "tile_bounds", "tiles_covering", "tile_ranges"]

#: The formats ``terrainvis tiles`` writes: Cesium's quantized-mesh-1.0 (this scheme) and Mapbox's
#: terrain-RGB PNG tiles (Web Mercator, XYZ rows: :mod:`terrainvis.tiles.terrain_rgb`).
FORMATS = ("quantized-mesh", "terrain-rgb")
#: The deepest zoom accepted: tiles of 180 / 2**24 degrees (about 1.2 m at the equator).
MAX_ZOOM = 24


def _zoom(z) -> int:
    z = as_int(z, "zoom")
    if not 0 <= z <= MAX_ZOOM:
        raise ValueError(f"zoom must be in [0, {MAX_ZOOM}], got {z}")
    return z


def tile_count(z) -> tuple[int, int]:
    """``(columns, rows)`` of zoom ``z``: ``(2**(z + 1), 2**z)``.

    Examples
    --------
    >>> tile_count(0), tile_count(3)
    ((2, 1), (16, 8))
    """
    z = _zoom(z)
    return 2 ** (z + 1), 2 ** z


def tile_size(z) -> float:
    """The side of every tile of zoom ``z`` in degrees: ``180 / 2**z``.

    >>> tile_size(0), tile_size(2)
    (180.0, 45.0)
    """
    return 180.0 / 2 ** _zoom(z)


def tile_bounds(z, x, y) -> tuple[float, float, float, float]:
    """``(west, south, east, north)`` in degrees of tile ``(z, x, y)`` (TMS: row 0 is southernmost).

    Examples
    --------
    >>> tile_bounds(0, 1, 0)
    (0.0, -90.0, 180.0, 90.0)
    >>> tile_bounds(2, 3, 2)
    (-45.0, 0.0, 0.0, 45.0)
    """
    nx, ny = tile_count(z)
    x = as_int(x, "x")
    y = as_int(y, "y")
    if not 0 <= x < nx:
        raise ValueError(f"x must be in [0, {nx - 1}] at zoom {z}, got {x}")
    if not 0 <= y < ny:
        raise ValueError(f"y must be in [0, {ny - 1}] at zoom {z}, got {y}")
    size = tile_size(z)
    # the eastern and northern edges as the next tile's western and southern ones, so neighbours share them exactly
    return -180.0 + x * size, -90.0 + y * size, -180.0 + (x + 1) * size, -90.0 + (y + 1) * size


def tiles_covering(z, bounds) -> tuple[int, int, int, int]:
    """``(start_x, start_y, end_x, end_y)``, inclusive: the tiles of zoom ``z`` whose area meets ``bounds``.

    Parameters
    ----------
    z : int
    bounds : (west, south, east, north)
        Degrees, ``west < east`` within [-180, 180] and ``south < north`` within [-90, 90].
        A tile that only touches the rectangle along an edge does not meet it.

    Examples
    --------
    >>> tiles_covering(1, (-10.0, 20.0, 100.0, 60.0))  # tiles of 90 degrees
    (1, 1, 3, 1)
    >>> tiles_covering(1, (0.0, 0.0, 90.0, 90.0))  # edges on tile edges: one tile
    (2, 1, 2, 1)
    """
    west, south, east, north = _bounds(bounds)
    nx, ny = tile_count(z)
    size = tile_size(z)

    def span(lo, hi, origin, n):
        first = max(0, min(math.floor((lo - origin) / size), n - 1))
        last = max(0, min(math.ceil((hi - origin) / size) - 1, n - 1))
        # the divisions round: settle against the tiles' edges as tile_bounds computes them
        while first > 0 and origin + first * size > lo:
            first -= 1
        while first < n - 1 and origin + (first + 1) * size <= lo:
            first += 1
        while last < n - 1 and origin + (last + 1) * size < hi:
            last += 1
        while last > first and origin + last * size >= hi:
            last -= 1
        return first, last

    x0, x1 = span(west, east, -180.0, nx)
    y0, y1 = span(south, north, -90.0, ny)
    return x0, y0, x1, y1


def _bounds(bounds) -> tuple[float, float, float, float]:
    try:
        west, south, east, north = (float(v) for v in bounds)
    except (TypeError, ValueError):
        raise ValueError(f"bounds must be four numbers (west, south, east, north), got {bounds!r}") from None
    if not all(math.isfinite(v) for v in (west, south, east, north)):
        raise ValueError(f"bounds must be finite, got {bounds!r}")
    if not (-180.0 <= west < east <= 180.0 and -90.0 <= south < north <= 90.0):
        raise ValueError("bounds must have -180 <= west < east <= 180 and -90 <= south < north <= 90, "
                         f"got {(west, south, east, north)}")
    return west, south, east, north


def tile_ranges(tiles) -> list[dict]:
    """The ``layer.json`` ``available`` entries of one zoom: ``tiles`` ((x, y) pairs) as rectangles.

    Each row's runs of consecutive columns are merged with the same run on the rows above
    it, so a rectangular block of tiles is one entry ``{startX, startY, endX, endY}``
    (inclusive); entries are ordered by ``startY``, then ``startX``.

    Examples
    --------
    >>> tile_ranges([(2, 1), (3, 1), (2, 2), (3, 2), (5, 2)])
    [{'startX': 2, 'startY': 1, 'endX': 3, 'endY': 2}, {'startX': 5, 'startY': 2, 'endX': 5, 'endY': 2}]
    """
    rows: dict[int, list[int]] = {}
    for x, y in sorted(set((int(x), int(y)) for x, y in tiles), key=lambda t: (t[1], t[0])):
        rows.setdefault(y, []).append(x)
    open_: dict[tuple[int, int], dict] = {}  # (startX, endX) -> the entry still growing northwards
    out = []
    for y in sorted(rows):
        runs, xs = [], rows[y]
        start = prev = xs[0]
        for x in xs[1:]:
            if x != prev + 1:
                runs.append((start, prev))
                start = x
            prev = x
        runs.append((start, prev))
        still = {}
        for run in runs:
            entry = open_.get(run)
            if entry is not None and entry["endY"] == y - 1:
                entry["endY"] = y
            else:
                entry = {"startX": run[0], "startY": y, "endX": run[1], "endY": y}
                out.append(entry)
            still[run] = entry
        open_ = still
    return sorted(out, key=lambda e: (e["startY"], e["startX"]))
