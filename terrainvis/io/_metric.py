"""A lon/lat grid resampled onto a metric grid (a local transverse Mercator), so distances are right across it."""

from __future__ import annotations

import math

import numpy as np

from ..core._georef import GEOREF_KEYS, IDENTITY, native_axes, parse_crs, transform_xy, xy_to_native
from ..core.validate import as_positive_finite, describe
from ..core.terrain import HeightGrid
from ..tolerances import METRIC_EDGE_MARGIN

#: Target samples transformed per block (bounds the temporary arrays to a few tens of MB).
_BLOCK = 1 << 20
#: Points per edge of the footprint's boundary when its extent in the projection is found.
_EDGE_POINTS = 256
#: What the metric grid covers.
FOOTPRINTS = ("inside", "cover")


def _tm_scale(lon: np.ndarray, lat: np.ndarray, lon_c: float) -> float:
    """The largest ``(dlambda cos phi)^2 / 2`` over the footprint: the transverse Mercator's scale excess there."""
    half = math.radians(max(abs(float(lon[0]) - lon_c), abs(float(lon[-1]) - lon_c)))
    lo, hi = float(lat[0]), float(lat[-1])
    nearest_equator = 0.0 if lo <= 0.0 <= hi else min(abs(lo), abs(hi))
    return 0.5 * (half * math.cos(math.radians(nearest_equator))) ** 2


def metric_crs(source: str, lon_c: float, lat_c: float, k0: float) -> str:
    """A PROJ string: the transverse Mercator centred on (lon_c, lat_c) with scale k0 on the datum of ``source``."""
    crs = parse_crs(source, "grid.attrs['crs']")
    params = crs.to_dict()
    if params.get("proj") != "longlat" or "init" in params:
        raise ValueError(
            f"grid.attrs['crs'] {source!r} is not a lon/lat CRS that PROJ describes by its datum "
            f"(got {params}); resample the DEM with gdalwarp instead"
        )
    datum = " ".join(
        f"+{key}" if value is True else f"+{key}={value}"
        for key, value in params.items() if key not in ("proj", "no_defs", "type", "units", "axis")
    )
    text = (f"+proj=tmerc +lat_0={lat_c!r} +lon_0={lon_c!r} +k={k0!r} +x_0=0 +y_0=0 {datum} "
            "+units=m +no_defs").replace("  ", " ")
    parse_crs(text, "the transverse Mercator")  # PROJ reads it, or a clear error now
    return text


def _cell(cell, grid: HeightGrid) -> tuple[float, float]:
    if cell is None:
        return grid.dx, grid.dy
    if isinstance(cell, (tuple, list, np.ndarray)):
        if len(cell) != 2:
            raise ValueError(f"cell must be one size or a pair (dx, dy) in metres, got {cell!r}")
        return as_positive_finite(cell[0], "cell[0]"), as_positive_finite(cell[1], "cell[1]")
    size = as_positive_finite(cell, "cell")
    return size, size


def to_metric(grid: HeightGrid, *, cell=None, footprint: str = "inside") -> HeightGrid:
    """A lon/lat grid resampled onto a metric grid, so that distances are right across it.

    A lon/lat DEM is read into local metres with the east-west scale of its centre
    latitude for every row (:mod:`terrainvis.core._georef`): on a 1 x 1 degree tile at 45 N,
    east-west lengths along its northern and southern edges are then 0.88 % too long
    and 0.86 % too short, and sight lines follow rhumb lines instead of geodesics
    (docs/user-guide.md, Georeferencing). This resamples the grid onto a transverse Mercator
    centred on it (scale factor chosen to halve the largest scale error): distances,
    ``max_distance``, curvature's drop and cell sizes are then right to ``2e-5`` on such
    a tile, but the samples change.

    Parameters
    ----------
    grid : HeightGrid
        A lon/lat grid as read by :func:`load_dem` (``attrs`` with ``geographic`` True,
        ``crs`` and ``xy_to_native``).
    cell : float or (float, float), optional
        The new cell size in metres (one for both axes, or ``(dx, dy)``). Default: the
        grid's own spacing in its local frame, so the sample count stays about the same.
    footprint : {"inside", "cover"}
        The meridians converge, so the DEM's footprint is not a rectangle in the
        projection. ``"inside"`` (default): the largest axis-aligned rectangle inside it,
        so no nodata is added (the wedges between it and the footprint's edges are left
        out: at 45 N, about ``0.35 * height`` of the tile wide at most, a few cells on a
        1-degree tile). ``"cover"``: every sample over the footprint's bounding box,
        nodata outside the footprint (as ``gdalwarp`` does).

    Returns
    -------
    HeightGrid
        A uniform grid in the projection's metres: samples at multiples of the cell
        size over ``footprint``; heights read from ``grid``'s surface
        (:meth:`HeightGrid.height_at`), NaN (nodata) on its nodata and, with
        ``"cover"``, outside it. ``attrs``
        are ``grid``'s, with ``crs`` the projection (a PROJ string), ``geographic``
        False, ``source_crs`` the lon/lat CRS (so :meth:`HeightGrid.from_native` still
        takes lon/lat) and ``metric_resampling``, a note of what was done.

    Raises
    ------
    ValueError
        ``grid`` is not a lon/lat grid, or its CRS cannot be described to PROJ.
    ImportError
        rasterio (the ``geo`` extra) is not installed.

    Examples
    --------
    >>> from terrainvis import sample_dem
    >>> g = sample_dem()
    >>> m = to_metric(g)
    >>> m.attrs["geographic"], m.attrs["source_crs"], m.is_uniform
    (False, 'EPSG:4326 (assumed; lon/lat degrees)', True)
    >>> lon, lat = -84.25, 36.6
    >>> bool(abs(m.height_at([m.from_native([lon, lat])])[0] - g.height_at([g.from_native([lon, lat])])[0]) < 5.0)
    True
    """
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
    source = grid.attrs.get("crs")
    if not grid.attrs.get("geographic") or grid.attrs.get("source_crs"):
        what = "a grid resampled onto a metric grid already" if grid.attrs.get("source_crs") else (
            f"projected ({source})" if source else "without a CRS")
        raise ValueError(f"to_metric needs a lon/lat grid (attrs['geographic'] True); this one is {what}")
    if not isinstance(source, str) or not source.strip():
        raise ValueError(f"grid.attrs['crs'] must name the lon/lat CRS, got {source!r}")
    affine = xy_to_native(grid.attrs)
    if affine is None:
        raise ValueError("grid.attrs say the grid is geographic but hold no 'xy_to_native'; its lon/lat are unknown")
    dx, dy = _cell(cell, grid)
    if footprint not in FOOTPRINTS:
        raise ValueError(f"footprint must be one of {list(FOOTPRINTS)}, got {footprint!r}")
    lon, lat = native_axes(grid.xs, grid.ys, affine)
    lon_c = 0.5 * (float(lon[0]) + float(lon[-1]))
    lat_c = 0.5 * (float(lat[0]) + float(lat[-1]))
    excess = _tm_scale(lon, lat, lon_c)
    k0 = 1.0 / (1.0 + 0.5 * excess)  # scale in [k0, k0 (1 + excess)]: the error is split evenly about 1
    tm = metric_crs(source, lon_c, lat_c, k0)

    # The footprint (sample centres) in the projection: its edges are curves there.
    t = np.linspace(0.0, 1.0, _EDGE_POINTS)
    bl = np.concatenate([lon[0] + (lon[-1] - lon[0]) * t, np.full(t.size, lon[-1]),
                         lon[-1] - (lon[-1] - lon[0]) * t, np.full(t.size, lon[0])])
    bp = np.concatenate([np.full(t.size, lat[0]), lat[0] + (lat[-1] - lat[0]) * t,
                         np.full(t.size, lat[-1]), lat[-1] - (lat[-1] - lat[0]) * t])
    bx, by = transform_xy(source, tm, bl, bp)
    if footprint == "cover":
        x0, x1, y0, y1 = bx.min(), bx.max(), by.min(), by.max()
    else:  # inside every edge: the south edge is bl[:n], the east one bl[n:2n], the north bl[2n:3n], the west bl[3n:]
        n = t.size
        x0, x1 = bx[3 * n:].max() + METRIC_EDGE_MARGIN, bx[n:2 * n].min() - METRIC_EDGE_MARGIN
        y0, y1 = by[:n].max() + METRIC_EDGE_MARGIN, by[2 * n:3 * n].min() - METRIC_EDGE_MARGIN
    i0, i1 = math.ceil(x0 / dx), math.floor(x1 / dx)
    j0, j1 = math.ceil(y0 / dy), math.floor(y1 / dy)
    if i1 - i0 < 1 or j1 - j0 < 1:
        raise ValueError(
            f"cell ({dx:g} x {dy:g} m) leaves fewer than 2 samples across the grid's footprint "
            f"({x1 - x0:.6g} x {y1 - y0:.6g} m, footprint={footprint!r})"
        )
    xs = dx * np.arange(i0, i1 + 1, dtype=np.float64)
    ys = dy * np.arange(j0, j1 + 1, dtype=np.float64)

    sx, ox, sy, oy = affine
    z = np.empty((ys.size, xs.size))
    rows_per_block = max(1, _BLOCK // xs.size)
    for r0 in range(0, ys.size, rows_per_block):
        r1 = min(ys.size, r0 + rows_per_block)
        X, Y = np.meshgrid(xs, ys[r0:r1])
        plon, plat = transform_xy(tm, source, X.ravel(), Y.ravel())
        local = np.column_stack([(plon - ox) / sx, (plat - oy) / sy])
        z[r0:r1] = grid.height_at(local).reshape(r1 - r0, xs.size)
    n_out = int(np.isnan(z).sum())
    attrs = {k: v for k, v in grid.attrs.items() if k not in GEOREF_KEYS}
    attrs.update(
        crs=tm, geographic=False, xy_to_native=IDENTITY, source_crs=source,
        metric_resampling=(
            f"resampled from the {grid.shape[0]}x{grid.shape[1]} lon/lat grid ({source}) onto a transverse Mercator "
            f"centred on it (lon_0 {lon_c:.6f}, lat_0 {lat_c:.6f}, k {k0:.8f}) with {dx:.6g} x {dy:.6g} m cells; "
            f"{'inside' if footprint == 'inside' else 'covering'} its footprint; heights read from its surface; "
            f"{n_out:,} of {z.size:,} samples are nodata"
        ),
    )
    return HeightGrid.from_coords(z, xs, ys, attrs=attrs)
