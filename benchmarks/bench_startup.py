"""Where a command's time goes, beside the GDAL command it stands next to (issue 28, item 3).

On one DEM (by default a 3601 x 3601 float32 GeoTIFF made here: ``mountains`` at 30 m in
UTM, the size of an SRTM 1-arc-second tile), the script times, as whole processes and in
turn (A B A B ...; ratios are taken pair by pair, so a drifting machine cancels out):

* ``terrainvis viewshed DEM --observer X Y -o out.tif`` against
  ``gdal_viewshed -ox X -oy Y -oz 1.7 -cc 0 DEM out.tif`` (the same observer, a flat earth);
* ``terrainvis info DEM`` against ``gdalinfo -stats DEM`` (both read every sample; GDAL
  keeps the statistics in ``DEM.aux.xml`` after its first run, so its later runs read them
  back instead);
* ``terrainvis los DEM --from ... --to ...`` (one sight line across the tile) and
  ``terrainvis simplify DEM -m simple -l 1 -o out.tif`` (reading, the simplest method,
  writing a GeoTIFF) against ``gdal_translate -outsize 50% 50% -r near DEM out.tif`` (GDAL
  reads the tile and writes one of a quarter of its samples: the nearest thing it has to
  either; a yardstick for reading and writing, not the same work);
* ``terrainvis --help`` against ``gdalinfo --version`` (start-up alone);

and then splits each of ``viewshed``, ``los``, ``info`` and ``simplify`` into its phases, one
after the other in a fresh process per run: the interpreter (``python -c pass``), the
imports the command makes, loading the cached numba kernels (the first calls, on a 3 x 3
grid; ``viewshed``, ``los`` and ``simplify`` overlap this with reading), reading the DEM,
the per-grid tables (the sweep's for ``viewshed``, the pair engine's pyramid for ``los``),
the call and writing the output.

Usage::

    python benchmarks/bench_startup.py [--dem DEM.tif] [--repeats 5]

Without ``gdal-bin`` (``apt-get install gdal-bin``) only the terrainvis side runs. The
machine is shared: read the medians and the ratios, and the load average printed first.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

VENV_BIN = Path(sys.executable).parent
TERRAINVIS = str(VENV_BIN / "terrainvis")

PHASES = r"""
import sys, time
t = [time.perf_counter()]
marks = []
def mark(name):
    t.append(time.perf_counter())
    marks.append(name)
command, dem, out = sys.argv[1], sys.argv[2], sys.argv[3]
xy = [float(v) for v in sys.argv[4:]]
import numpy as np
from terrainvis.io import load_dem
if command == "viewshed":
    from terrainvis.cli import viewshed as _command
    from terrainvis.io import write_mask_geotiff
    from terrainvis.visibility import viewshed
    from terrainvis.visibility.viewsheds.sweep import _build_tables
    import rasterio
    mark("imports")
    _command._load_kernels(dem)  # what the command loads beside its reading (the DEM's heights' dtype)
    mark("kernel loading")
    grid = load_dem(dem)
    mark("reading")
    _build_tables(grid)
    mark("per-grid tables")
    v = viewshed(grid, (xy[0], xy[1]), observer_height=1.7)
    mark("the call")
    write_mask_geotiff(grid, v, out)
    mark("writing")
elif command == "los":
    from terrainvis.cli import los as _command
    from terrainvis.visibility import line_of_sight, min_clearance
    from terrainvis.visibility.grid import grid_accel
    from terrainvis.visibility.profile import lowest_point
    import rasterio
    mark("imports")
    _command._load_kernels()
    mark("kernel loading")
    grid = load_dem(dem)
    mark("reading")
    grid_accel(grid)
    mark("per-grid tables")
    a = np.array([[xy[0], xy[1], grid.height_at([xy[:2]])[0] + 1.7]])
    b = np.array([[xy[2], xy[3], grid.height_at([xy[2:]])[0]]])
    line_of_sight(grid, a, b), min_clearance(grid, a, b), lowest_point(grid, a[0], b[0])
    mark("the call")
elif command == "info":
    from terrainvis.cli import info as _command
    from simplifiers import METHODS, max_level, vertex_budget
    import rasterio
    mark("imports")
    grid = load_dem(dem)
    mark("reading")
    z = grid.z
    summary = (np.nanmin(z), np.nanmax(z), grid.n_nodata, [vertex_budget(grid.shape, k)
                                                           for k in range(1, max_level(grid.shape) + 1)])
    mark("the call")
else:  # simplify
    from terrainvis.cli import simplify as _command
    from terrainvis.io import save_terrain
    from simplifiers import simplify
    import rasterio
    mark("imports")
    _command._load_kernels()
    mark("kernel loading")
    grid = load_dem(dem)
    mark("reading")
    result = simplify(grid, "simple", 1)
    mark("the call")
    save_terrain(result, out, dtype="float32")
    mark("writing")
print(";".join(f"{name}={b - a:.4f}" for name, a, b in zip(marks, t, t[1:])))
"""


def _make_dem(path: Path, size: int) -> None:
    import numpy as np

    import terrainvis as tv

    g = tv.synthetic_terrain("mountains", size=size, seed=1)
    z = g.z.astype(np.float32).astype(np.float64)
    tv.save_dem(tv.HeightGrid(z, 30.0, 30.0, (500000.0, 4000000.0), attrs={"crs": "EPSG:32617"}), path,
                dtype="float32")


def _wall(cmd) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    return time.perf_counter() - t0


def _paired(name: str, a, b, repeats: int) -> None:
    _wall(a)  # warm-up: the page cache and numba's cache index, for both
    if b:
        _wall(b)
    ta, tb = [], []
    for _ in range(repeats):
        ta.append(_wall(a))
        if b:
            tb.append(_wall(b))
    line = f"{name:<22} terrainvis {statistics.median(ta):6.3f} s"
    if b:
        ratios = [x / y for x, y in zip(ta, tb)]
        line += f"   {Path(b[0]).name} {statistics.median(tb):6.3f} s   ratio {statistics.median(ratios):5.2f}"
    print(line + f"   (medians of {repeats})", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dem", help="a GeoTIFF DEM (default: a 3601x3601 one made in a temporary folder)")
    ap.add_argument("--size", type=int, default=3601, help="size of the DEM made when --dem is not given")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores", flush=True)
    with tempfile.TemporaryDirectory(prefix="tv-startup-") as tmp:
        tmp = Path(tmp)
        dem = Path(args.dem) if args.dem else tmp / "dem.tif"
        if not args.dem:
            _make_dem(dem, args.size)
        import rasterio

        with rasterio.open(dem) as src:
            t, rows, cols = src.transform, src.height, src.width
        x, y = t.c + t.a * (cols // 2 + 0.5), t.f + t.e * (rows // 2 + 0.5)  # the central sample
        print(f"DEM {dem.name}: {rows} x {cols}", flush=True)
        gdal = shutil.which("gdal_viewshed") is not None
        _paired("viewshed", [TERRAINVIS, "viewshed", str(dem), "--observer", f"{x}", f"{y}", "-o", str(tmp / "a.tif")],
                ["gdal_viewshed", "-ox", f"{x}", "-oy", f"{y}", "-oz", "1.7", "-cc", "0", str(dem), str(tmp / "b.tif")]
                if gdal else None, args.repeats)
        _paired("info", [TERRAINVIS, "info", str(dem)], ["gdalinfo", "-stats", str(dem)] if gdal else None, args.repeats)
        translate = ["gdal_translate", "-q", "-outsize", "50%", "50%", "-r", "near", str(dem), str(tmp / "t.tif")]
        x1, y1 = t.c + t.a * (cols // 8 + 0.5), t.f + t.e * (rows // 8 + 0.5)
        x2, y2 = t.c + t.a * (cols - cols // 8 - 0.5), t.f + t.e * (rows - rows // 8 - 0.5)
        _paired("los", [TERRAINVIS, "los", str(dem), "--from", f"{x1}", f"{y1}", "--to", f"{x2}", f"{y2}"],
                translate if gdal else None, args.repeats)
        _paired("simplify", [TERRAINVIS, "simplify", str(dem), "-m", "simple", "-l", "1", "-o", str(tmp / "s.tif")],
                translate if gdal else None, args.repeats)
        _paired("--help", [TERRAINVIS, "--help"], ["gdalinfo", "--version"] if gdal else None, args.repeats)
        bare = statistics.median(_wall([sys.executable, "-c", "pass"]) for _ in range(args.repeats))
        ends = {"viewshed": [f"{x}", f"{y}"], "los": [f"{x1}", f"{y1}", f"{x2}", f"{y2}"], "info": [], "simplify": []}
        for command, where in ends.items():
            runs = []
            for _ in range(args.repeats):
                out = subprocess.run([sys.executable, "-c", PHASES, command, str(dem), str(tmp / "c.tif"), *where],
                                     capture_output=True, text=True, check=True)
                runs.append(dict(item.split("=") for item in out.stdout.strip().split(";")))
            print(f"terrainvis {command}, phases (medians of {args.repeats} fresh processes; the command overlaps "
                  f"kernel loading with reading):" if "kernel loading" in runs[0] else
                  f"terrainvis {command}, phases (medians of {args.repeats} fresh processes):", flush=True)
            print(f"  {'interpreter':<16} {bare:6.3f} s")
            for name in runs[0]:
                print(f"  {name:<16} {statistics.median(float(r[name]) for r in runs):6.3f} s", flush=True)

if __name__ == "__main__":
    main()
