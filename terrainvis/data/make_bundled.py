"""Regenerate the bundled terrains: python terrainvis/data/make_bundled.py

* The five 120x120 synthetic terrains. They are frozen here so that results do not drift
  with numpy or scipy versions; running this script with other versions may give
  slightly different files. Each file is written with :func:`terrainvis.io.save_terrain`
  in the terrainvis ``.npz`` format (version 1): ``z``, ``xs``, ``ys`` in HeightGrid row
  order (row 0 is the smallest y) and the attrs ``name``, ``seed``, ``synthetic`` and
  ``bundled``.
* ``cumberland.tif``: a real DEM as GIS users hold one, a projected float32 GeoTIFF: the
  USGS 3-arc-second DEM of the Jacksboro fault, Tennessee, that ships with matplotlib
  (``jacksboro_fault_dem.npz``, lon/lat in NAD83), resampled onto NAD83 / UTM zone 16N
  (EPSG:26916) at 90 m: each sample centre is taken to lon/lat exactly (PROJ) and the
  source interpolated bilinearly there (:func:`bilinear_from_source`; GDAL's warp would
  widen its bilinear kernel where the new cells are coarser than the old, smoothing); cut
  to the largest rectangle the warped footprint covers and then to 16 k + 1 samples a
  side (337 x 321, so the regular methods' levels 1-4 keep samples of its own grid);
  north-up, DEFLATE with the floating-point predictor, 256 x 256 tiles (needs rasterio,
  the ``geo`` extra).
"""

from pathlib import Path

import numpy as np

from terrainvis.io import save_terrain
from terrainvis.core.synthetic import KINDS, synthetic_terrain

#: The bundled GeoTIFF's CRS and cell size (m).
CUMBERLAND_CRS = "EPSG:26916"
CUMBERLAND_CELL = 90.0


def _largest_valid_rectangle(valid: np.ndarray) -> tuple[int, int, int, int]:
    """Rows ``r0..r1`` and columns ``c0..c1`` (inclusive) of the largest all-valid rectangle
    in a mask whose valid cells form one convex patch (a warped footprint): each row's valid
    cells are one run, so rows ``r0..r1`` share the columns from the largest first to the
    smallest last."""
    rows = np.flatnonzero(valid.any(axis=1))
    first = np.array([np.flatnonzero(valid[r])[0] for r in rows])
    last = np.array([np.flatnonzero(valid[r])[-1] for r in rows])
    if not all(valid[r, f:l + 1].all() for r, f, l in zip(rows, first, last)):
        raise ValueError("valid: expected one run of valid cells per row (a convex footprint)")
    best = (0, 0, 0, 0, 0)
    for i in range(len(rows)):
        lo, hi = first[i], last[i]
        for j in range(i, len(rows)):
            if rows[j] != rows[i] + (j - i):
                break
            lo, hi = max(lo, first[j]), min(hi, last[j])
            area = (j - i + 1) * (hi - lo + 1)
            if hi >= lo and area > best[0]:
                best = (area, rows[i], rows[j], lo, hi)
    return tuple(int(v) for v in best[1:])


def _fit_levels(first: int, last: int, step: int = 16) -> tuple[int, int]:
    """The centred sub-range of ``first..last`` whose length is ``step * m + 1``."""
    n = last - first + 1
    keep = (n - 1) // step * step + 1
    start = first + (n - keep) // 2
    return start, start + keep - 1


def cumberland_source():
    """matplotlib's Jacksboro DEM: ``(z, lon, lat)``, heights (rows north to south) and the
    longitudes and latitudes of the sample centres (NAD83, degrees)."""
    from terrainvis.io._sample import _matplotlib_sample

    with np.load(_matplotlib_sample("jacksboro_fault_dem.npz"), allow_pickle=False) as data:
        z = np.asarray(data["elevation"], dtype=np.float64)  # north-up rows
        dx, dy = float(data["dx"]), float(data["dy"])  # degrees (3 arc-seconds)
        # the file's 'ymin' holds the northern edge, 'ymax' the southern one (as sample_dem reads them);
        # xmin .. xmax and the edges span whole cells: the samples are the cells' centres
        west, north = float(data["xmin"]), max(float(data["ymin"]), float(data["ymax"]))
    rows, cols = z.shape
    return z, west + dx * (np.arange(cols) + 0.5), north - dy * (np.arange(rows) + 0.5)


def bilinear_from_source(x, y):
    """Heights at projected positions (EPSG:26916): each position taken to NAD83 exactly
    (PROJ, through rasterio) and the source interpolated bilinearly there; NaN outside it."""
    from rasterio.warp import transform as project
    from scipy.interpolate import RegularGridInterpolator

    z, lon, lat = cumberland_source()
    at = RegularGridInterpolator((lat[::-1], lon), z[::-1], method="linear", bounds_error=False, fill_value=np.nan)
    lons, lats = project(CUMBERLAND_CRS, "EPSG:4269", np.ravel(x), np.ravel(y))
    return at(np.column_stack([lats, lons])).reshape(np.shape(x))


def make_cumberland(path: Path) -> None:
    """``cumberland.tif`` from matplotlib's Jacksboro DEM (see the module docstring)."""
    import rasterio
    from rasterio.transform import from_origin
    from rasterio.warp import transform_bounds

    _, lon, lat = cumberland_source()
    west, south, east, north = transform_bounds("EPSG:4269", CUMBERLAND_CRS, lon[0], lat[-1], lon[-1], lat[0],
                                                densify_pts=101)
    # sample centres on the 90 m lattice offset by half a cell (corners on whole multiples of 90 m)
    xs = np.arange(np.ceil(west / CUMBERLAND_CELL), np.floor(east / CUMBERLAND_CELL)) * CUMBERLAND_CELL + 45.0
    ys = np.arange(np.floor(north / CUMBERLAND_CELL), np.ceil(south / CUMBERLAND_CELL), -1) * CUMBERLAND_CELL - 45.0
    out = bilinear_from_source(*np.meshgrid(xs, ys))  # rows north to south
    # the rows and columns the warped footprint does not cover in full (its rotation) are cut
    r0, r1, c0, c1 = _largest_valid_rectangle(np.isfinite(out))
    # sizes 16 k + 1: the reverse-subdivision levels 1-4 keep samples of the DEM's own grid
    # (an even-sized DEM's coarse grids fall between its samples), cut evenly from both sides
    r0, r1 = _fit_levels(r0, r1)
    c0, c1 = _fit_levels(c0, c1)
    out = np.ascontiguousarray(out[r0:r1 + 1, c0:c1 + 1], dtype=np.float32)
    transform = from_origin(xs[c0] - 45.0, ys[r0] + 45.0, CUMBERLAND_CELL, CUMBERLAND_CELL)
    profile = dict(driver="GTiff", height=out.shape[0], width=out.shape[1], count=1, dtype="float32",
                   crs=CUMBERLAND_CRS, transform=transform, nodata=-9999.0, tiled=True, blockxsize=256,
                   blockysize=256, compress="deflate", predictor=3)
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(out, 1)
        dst.update_tags(SOURCE="USGS 3-arc-second DEM of the Jacksboro fault, Tennessee (matplotlib sample data "
                               "jacksboro_fault_dem.npz), interpolated bilinearly at the sample centres of "
                               "EPSG:26916 at 90 m",
                        LICENSE="public domain (U.S. Geological Survey)")


if __name__ == "__main__":
    here = Path(__file__).resolve().parent
    for kind in KINDS:
        grid = synthetic_terrain(kind, size=120, seed=0)
        grid.attrs["bundled"] = True
        save_terrain(grid, here / f"{kind}.npz")
        print(f"{kind:10s} {grid.shape} z [{grid.z.min():.1f}, {grid.z.max():.1f}] m")
    make_cumberland(here / "cumberland.tif")
    print(f"cumberland.tif {(here / 'cumberland.tif').stat().st_size / 1024:.0f} kB")
