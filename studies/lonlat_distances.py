"""How far distances on a lon/lat DEM are off, in the local frame it is read into and on its metric grid.

Not a timing: the measurement behind docs/user-guide.md (Georeferencing). A 1 x 1 degree tile of
3-arc-second samples (1201 x 1201) at 45 N and at 60 N is written as a lon/lat GeoTIFF and
read with ``load_dem`` (the local frame: metres with the centre latitude's east-west scale
for every row), and resampled with ``terrainvis.io.to_metric`` (a transverse Mercator
centred on the tile). Every figure is against geodesic distances on the WGS84 ellipsoid
(``pyproj.Geod``, Karney's algorithm), an independent reference:

* distances between named points (edges, diagonals) and over random pairs across the tile;
* the cell width at the southern and northern rows;
* ``max_distance``: the samples within 20 km of an observer near the northern edge,
  counted in the frame against the geodesic truth;
* curvature's drop ``c d1 d2 / (2 R)`` (c = 0.85714, R = 6,378,137 m) at the middle of a
  60 km east-west sight line along the northern edge;
* how far the geodesic between two points runs from the frame's straight segment (the
  line the engines walk).

    python studies/lonlat_distances.py
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pyproj
import rasterio
from rasterio.transform import from_origin

import terrainvis as tv
from terrainvis.io import to_metric

GEOD = pyproj.Geod(ellps="WGS84")
CELL = 3.0 / 3600.0  # 3 arc-seconds
N = 1201  # samples per side: a 1-degree tile, both edges included
CURVATURE, RADIUS = 0.85714, 6378137.0


def tile(lat_s: float, folder: Path) -> Path:
    """A 1 x 1 degree lon/lat GeoTIFF whose sample centres run from (0, lat_s) to (1, lat_s + 1)."""
    path = folder / f"tile_{lat_s:g}.tif"
    transform = from_origin(-0.5 * CELL, lat_s + 1.0 + 0.5 * CELL, CELL, CELL)
    z = np.zeros((N, N), dtype=np.float32)
    with rasterio.open(path, "w", driver="GTiff", height=N, width=N, count=1, dtype="float32", crs="EPSG:4326",
                       transform=transform) as dst:
        dst.write(z, 1)
    return path


def geodesic(a, b) -> np.ndarray:
    a, b = np.atleast_2d(a), np.atleast_2d(b)
    return GEOD.inv(a[:, 0], a[:, 1], b[:, 0], b[:, 1])[2]


def frame_distance(grid, a, b) -> np.ndarray:
    pa, pb = grid.from_native(np.atleast_2d(a)), grid.from_native(np.atleast_2d(b))
    return np.hypot(*(pb - pa).T)


def offset_from_chord(grid, a, b, n: int = 199) -> float:
    """The largest distance (m, in the frame) of the geodesic a-b from the frame's straight segment a-b."""
    pts = np.array(GEOD.npts(a[0], a[1], b[0], b[1], n))
    p = grid.from_native(pts)
    pa, pb = grid.from_native(np.array([a, b]))
    d = pb - pa
    return float(np.abs((p[:, 0] - pa[0]) * d[1] - (p[:, 1] - pa[1]) * d[0]).max() / np.hypot(*d))


def report(name: str, grid, lat_s: float) -> None:
    lat_n, lat_c = lat_s + 1.0, lat_s + 0.5
    print(f"\n{name}")
    pairs = {
        "east-west, southern edge": ((0.0, lat_s), (1.0, lat_s)),
        "east-west, centre": ((0.0, lat_c), (1.0, lat_c)),
        "east-west, northern edge": ((0.0, lat_n), (1.0, lat_n)),
        "north-south, western edge": ((0.0, lat_s), (0.0, lat_n)),
        "diagonal SW-NE": ((0.0, lat_s), (1.0, lat_n)),
        "10 km east-west at the northern edge": ((0.5, lat_n), (0.5 + 10000.0 / tv.io.metres_per_degree(lat_n)[0], lat_n)),
    }
    for label, (a, b) in pairs.items():
        g, f = geodesic(a, b)[0], frame_distance(grid, a, b)[0]
        print(f"  {label:38s} geodesic {g:10.1f} m  frame {f:10.1f} m  error {f - g:+8.2f} m ({100 * (f / g - 1):+.4f} %)")
    rng = np.random.default_rng(0)
    a = np.column_stack([rng.uniform(0, 1, 100_000), rng.uniform(lat_s, lat_n, 100_000)])
    b = np.column_stack([rng.uniform(0, 1, 100_000), rng.uniform(lat_s, lat_n, 100_000)])
    g, f = geodesic(a, b), frame_distance(grid, a, b)
    keep = g > 1000.0
    rel = np.abs(f[keep] / g[keep] - 1)
    print(f"  random pairs (100,000, > 1 km)        relative error: max {100 * rel.max():.4f} %, "
          f"99th percentile {100 * np.quantile(rel, 0.99):.4f} %, median {100 * np.median(rel):.4f} %")
    # cell widths at the southern and northern rows (in the frame: the grid's own dx)
    for label, lat in (("southern", lat_s), ("northern", lat_n)):
        true = geodesic((0.5, lat), (0.5 + CELL, lat))[0]
        here = frame_distance(grid, (0.5, lat), (0.5 + CELL, lat))[0]
        print(f"  cell width at the {label} row         true {true:.3f} m  frame {here:.3f} m  "
              f"({100 * (here / true - 1):+.3f} %)")
    # max_distance 20 km from an observer near the northern edge
    obs = np.array([0.5, lat_n - 0.01])
    xy = grid.sample_xy()
    lonlat = grid.to_native(xy)
    o = grid.from_native(obs)
    d_frame = np.hypot(xy[:, 0] - o[0], xy[:, 1] - o[1])
    d_true = GEOD.inv(np.full(len(xy), obs[0]), np.full(len(xy), obs[1]), lonlat[:, 0], lonlat[:, 1])[2]
    r = 20000.0
    inside_f, inside_t = d_frame <= r, d_true <= r
    print(f"  max_distance 20 km (observer 0.01 deg south of the northern edge): {int(inside_t.sum()):,} samples within "
          f"it; {int((inside_f & ~inside_t).sum()):,} wrongly in, {int((~inside_f & inside_t).sum()):,} wrongly out; "
          f"farthest taken {d_true[inside_f].max():.1f} m, nearest left out {d_true[~inside_f].min():.1f} m")
    # curvature's drop in the middle of a 60 km east-west line along the northern edge
    half = 30000.0 / tv.io.metres_per_degree(lat_n)[0]
    a, b, m = (0.5 - half, lat_n), (0.5 + half, lat_n), (0.5, lat_n)
    k = CURVATURE / (2 * RADIUS)
    drop_true = k * geodesic(a, m)[0] * geodesic(m, b)[0]
    drop_frame = k * frame_distance(grid, a, m)[0] * frame_distance(grid, m, b)[0]
    print(f"  curvature drop, middle of 60 km E-W   true {drop_true:.2f} m  frame {drop_frame:.2f} m  "
          f"error {drop_frame - drop_true:+.2f} m ({100 * (drop_frame / drop_true - 1):+.3f} %)")
    for label, (a, b) in (("east-west, northern edge", ((0.0, lat_n), (1.0, lat_n))),
                          ("diagonal SW-NE", ((0.0, lat_s), (1.0, lat_n)))):
        print(f"  geodesic off the frame's straight line, {label}: {offset_from_chord(grid, a, b):.2f} m "
              f"(cells {grid.dx:.1f} x {grid.dy:.1f} m)")


def main() -> None:
    with tempfile.TemporaryDirectory() as folder:
        for lat_s in (44.5, 59.5):
            grid = tv.load_dem(tile(lat_s, Path(folder)))
            lat_c = lat_s + 0.5
            report(f"== {lat_c:g} N, local frame as read (east-west scale of {lat_c:g} N for every row)", grid, lat_s)
            metric = to_metric(grid)
            report(f"== {lat_c:g} N, to_metric: {metric.attrs['crs']}, {metric.shape[0]}x{metric.shape[1]}",
                   metric, lat_s)
            # the best single east-west scale (minimax relative error: the harmonic mean of the edges' scales)
            ms, mn = (tv.io.metres_per_degree(lat)[0] for lat in (lat_s, lat_s + 1.0))
            best = 2.0 / (1.0 / ms + 1.0 / mn)
            print(f"\n  one east-west scale for all rows, chosen for the least largest error: {best:.1f} m/deg, "
                  f"edges {100 * (best / ms - 1):+.3f} % / {100 * (best / mn - 1):+.3f} % "
                  f"(centre latitude's {tv.io.metres_per_degree(lat_c)[0]:.1f} m/deg: "
                  f"{100 * (tv.io.metres_per_degree(lat_c)[0] / ms - 1):+.3f} % / "
                  f"{100 * (tv.io.metres_per_degree(lat_c)[0] / mn - 1):+.3f} %)")


if __name__ == "__main__":
    main()
