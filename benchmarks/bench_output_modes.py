"""Benchmark: the viewshed's ``output="min_height"`` against ``gdal_viewshed -om GROUND``.

On each shared DEM (``../shared/data/dem``: the GeoTIFF ``green_mountains_vt.tif``; the
``.npz`` ones written to a temporary GeoTIFF with :func:`terrainvis.save_dem`), for two
observers (the sample at the grid's centre and the highest sample), an eye 10 m above the
ground, curvature off (``-cc 0``) and on (standard refraction, ``-cc 0.85714``), it runs in
the same process:

* ours: ``viewshed(grid, (x, y), observer_height=10, output="min_height", curvature=c)`` on
  the DEM as loaded back from the GeoTIFF (no file I/O in the timing), after a warm-up
  call (numba's compilation and the grid's caches);
* ``gdal_viewshed -om GROUND -ox X -oy Y -oz 10 -cc C DEM.tif OUT.tif`` (Debian package
  gdal-bin), the whole command with reading and writing, whose cells hold the height above
  the ground a target needs to be visible (GDAL's own approximation: a reference plane
  interpolated per cell).

It prints the medians of ``--repeats`` runs, the ratio GDAL / ours, and the agreement on the
cells both answer (the observer's own cell left out): the share of cells within 1 m, within
10 m, the RMS and the largest difference, and the share whose "ground visible" verdict
(0) differs. GDAL is approximate, so nothing is asserted.

A lon/lat DEM (``geographic``) is written in the local metres terrainvis reads it in (x, y
from its south-west sample) under a UTM CRS label (EPSG:32617, an offset of 500 km east
and 4,000 km north), so that GDAL measures distances in metres as we do; the heights are
the DEM's.

Example::

    python benchmarks/bench_output_modes.py                 # all shared DEMs, 5 repeats
    python benchmarks/bench_output_modes.py --repeats 3 --dems green_mountains_vt
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from terrainvis import HeightGrid, load_dem, save_dem, viewshed

DEM_DIR = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "dem"
DEMS = ("green_mountains_vt", "jacksboro_fault_tn", "mount_st_helens_wa", "west_bijou_escarpment_co")
STD_CURVATURE = 0.85714


def _geotiff(name: str, tmp: str) -> str:
    """A GeoTIFF of the shared DEM ``name`` (the shared one when there is one)."""
    tif = DEM_DIR / f"{name}.tif"
    if tif.exists():
        return str(tif)
    g = load_dem(DEM_DIR / f"{name}.npz")
    if g.attrs.get("geographic"):
        g = HeightGrid.from_coords(g.z, 500000.0 + g.xs, 4000000.0 + g.ys, attrs={"crs": "EPSG:32617"})
    out = os.path.join(tmp, f"{name}.tif")
    save_dem(g, out)
    return out


def _observers(g: HeightGrid) -> dict:
    rows, cols = g.shape
    r0, c0 = rows // 2, cols // 2
    if not np.isfinite(g.z[r0, c0]):
        r0, c0 = np.unravel_index(np.nanargmin(np.abs(g.z - np.nanmedian(g.z))), g.shape)
    rh, ch = np.unravel_index(np.nanargmax(g.z), g.shape)
    return {"centre": (int(r0), int(c0)), "highest": (int(rh), int(ch))}


def _median_time(fn, repeats: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def _gdal(gdal: str, dem: str, out: str, x: float, y: float, eye: float, curv: float, repeats: int):
    cmd = [gdal, "-q", "-om", "GROUND", "-ox", repr(x), "-oy", repr(y), "-oz", repr(eye), "-tz", "0",
           "-cc", repr(curv), dem, out]

    def run():
        subprocess.run(cmd, check=True, capture_output=True)

    t, _ = _median_time(run, repeats)
    import rasterio

    with rasterio.open(out) as f:
        a = f.read(1).astype(np.float64)[::-1]  # north-up rows -> terrainvis' rows (south first)
        if f.nodata is not None and np.isfinite(f.nodata):
            a[a == f.nodata] = np.nan
    return t, a


def _agreement(ours: np.ndarray, peer: np.ndarray, own: tuple) -> dict:
    both = np.isfinite(ours) & np.isfinite(peer)
    both[own] = False
    d = np.abs(ours[both] - peer[both])
    return {"cells": int(both.sum()), "within_1m": float((d <= 1.0).mean()), "within_10m": float((d <= 10.0).mean()),
            "rms": float(np.sqrt(np.mean(d * d))), "max": float(d.max()),
            "verdict_differs": float(((ours[both] == 0) != (peer[both] == 0)).mean())}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dems", nargs="+", default=list(DEMS), choices=DEMS)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--eye", type=float, default=10.0)
    args = ap.parse_args(argv)
    gdal = shutil.which("gdal_viewshed")
    if gdal is None:
        print("gdal_viewshed not found (Debian: apt-get install gdal-bin): ours alone")
    tmp = tempfile.mkdtemp(prefix="bench_output_modes_")
    print(f"eye {args.eye:g} m, min_height (ours) vs gdal_viewshed -om GROUND; medians of {args.repeats} runs; "
          f"uptime: {os.popen('uptime').read().strip()}")
    for name in args.dems:
        dem = _geotiff(name, tmp)
        g = load_dem(dem)
        print(f"\n=== {name}: {g.shape[0]} x {g.shape[1]}, {g.n_nodata:,} nodata")
        for oname, (r, c) in _observers(g).items():
            x, y = float(g.xs[c]), float(g.ys[r])
            for curv in (0.0, STD_CURVATURE):
                viewshed(g, (x, y), observer_height=args.eye, output="min_height", curvature=curv)  # warm-up
                t_ours, ours = _median_time(lambda: viewshed(g, (x, y), observer_height=args.eye, output="min_height",
                                                             curvature=curv), args.repeats)
                t_vis, _ = _median_time(lambda: viewshed(g, (x, y), observer_height=args.eye, curvature=curv),
                                        args.repeats)
                line = (f"  {oname:7s} (sample {r}, {c}) cc {curv:<7g} ours {t_ours:7.3f} s "
                        f"(visible mode {t_vis:6.3f} s)")
                if gdal:
                    t_g, peer = _gdal(gdal, dem, os.path.join(tmp, "gdal.tif"), x, y, args.eye, curv, args.repeats)
                    a = _agreement(ours, peer, (r, c))
                    line += (f"  gdal {t_g:6.3f} s  GDAL/ours {t_g / t_ours:5.2f}  within 1 m {100 * a['within_1m']:5.1f} %"
                             f"  within 10 m {100 * a['within_10m']:5.1f} %  RMS {a['rms']:7.2f} m  max {a['max']:7.1f} m"
                             f"  ground-visible verdict differs {100 * a['verdict_differs']:4.1f} %")
                print(line, flush=True)
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
