"""A viewshed of a large float32 GeoTIFF beside ``gdal_viewshed`` on the same file: wall time and peak memory.

For each size (default 8192; ``--sizes 8192 20000``) a float32 GeoTIFF at 30 m in UTM
(DEFLATE with the floating-point predictor, 256² tiles, as GIS tools write DEMs) is made
strip by strip in a temporary folder (smooth waves and ridges: no full array in memory).
Then, in turn (ours, GDAL's, ours, ...; ``--repeats`` pairs), ``terrainvis viewshed DEM
--observer X Y -o out.tif`` and ``gdal_viewshed -ox X -oy Y -oz 1.7 -cc 0 DEM out.tif``
(the same observer, a flat earth) run as whole processes; each one's peak resident
memory is its ``ru_maxrss`` (``resource.getrusage(RUSAGE_CHILDREN)`` of a fresh child
per run). The script prints the medians, the ratios of the medians, and bytes per
sample.

Usage::

    python benchmarks/bench_large_raster.py [--sizes 8192 20000] [--repeats 3] [--folder DIR]

``--folder`` keeps the GeoTIFFs there (a 20000² one takes about a minute to make and
1 GB of disk). The machine is shared: read the medians and ratios.
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

MAKE = r"""
import sys, numpy as np, rasterio
from rasterio.transform import Affine
n = int(sys.argv[2])
prof = dict(driver="GTiff", height=n, width=n, count=1, dtype="float32", crs="EPSG:32617",
            transform=Affine(30.0, 0, 500000.0, 0, -30.0, 4000000.0 + 30.0 * n), nodata=-9999.0,
            tiled=True, blockxsize=256, blockysize=256, compress="deflate", predictor=3, BIGTIFF="YES")
x = np.arange(n, dtype=np.float64) * 30.0
rng = np.random.default_rng(1)
waves = [(rng.uniform(2e-4, 3e-3), rng.uniform(2e-4, 3e-3), rng.uniform(0, 6.3), rng.uniform(20, 120)) for _ in range(12)]
with rasterio.open(sys.argv[1], "w", **prof) as dst:
    for r0 in range(0, n, 512):
        r1 = min(n, r0 + 512)
        y = (n - 1 - np.arange(r0, r1, dtype=np.float64))[:, None] * 30.0
        z = np.full((r1 - r0, n), 500.0)
        for kx, ky, ph, a in waves:
            z += a * np.sin(kx * x[None, :] + ky * y + ph)
        z += 40.0 * np.abs(np.sin(1.7e-3 * x[None, :] - 0.9e-3 * y))
        dst.write(z.astype(np.float32), 1, window=rasterio.windows.Window(0, r0, n, r1 - r0))
"""

#: Runs one command and prints its wall seconds and its peak resident memory (KiB).
RUN = r"""
import resource, subprocess, sys, time
t0 = time.perf_counter()
out = subprocess.run(sys.argv[1:], capture_output=True, text=True)
seconds = time.perf_counter() - t0
if out.returncode:
    sys.exit(out.stderr[-2000:])
print(seconds, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
"""


def _one(cmd) -> tuple[float, int]:
    out = subprocess.run([sys.executable, "-c", RUN, *cmd], capture_output=True, text=True)
    if out.returncode:
        raise SystemExit(f"{' '.join(cmd)} failed: {out.stderr[-2000:]}")
    seconds, kib = out.stdout.split()
    return float(seconds), int(kib) * 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[8192])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--folder", default=None, help="keep the GeoTIFFs here (default: a temporary folder)")
    args = ap.parse_args()
    gdal = shutil.which("gdal_viewshed")
    terrainvis = str(Path(sys.executable).parent / "terrainvis")
    folder = Path(args.folder or tempfile.mkdtemp(prefix="bench-large-"))
    folder.mkdir(parents=True, exist_ok=True)
    with open("/proc/loadavg") as fh:
        print(f"load average {fh.read().split()[0]} on {os.cpu_count()} cores")
    try:
        for n in args.sizes:
            dem = folder / f"dem{n}.tif"
            if not dem.exists():
                t0 = time.perf_counter()
                subprocess.run([sys.executable, "-c", MAKE, str(dem), str(n)], check=True)
                print(f"made {dem.name} ({dem.stat().st_size / 2**20:.0f} MiB) in {time.perf_counter() - t0:.0f} s")
            x, y = 500000.0 + 30.0 * (0.6 * n) + 15.0, 4000000.0 + 30.0 * (0.45 * n) + 15.0
            ours = [terrainvis, "viewshed", str(dem), "--observer", str(x), str(y), "-o", str(folder / "ours.tif")]
            peer = [gdal, "-q", "-ox", str(x), "-oy", str(y), "-oz", "1.7", "-cc", "0", str(dem),
                    str(folder / "gdal.tif")] if gdal else None
            _one(ours)  # the kernels loaded once, the file in the page cache
            rows = {"terrainvis viewshed": [], "gdal_viewshed": []}
            for _ in range(args.repeats):
                rows["terrainvis viewshed"].append(_one(ours))
                if peer:
                    rows["gdal_viewshed"].append(_one(peer))
            print(f"{n}² ({n * n:,} samples), medians of {args.repeats}:")
            med = {}
            for name, vals in rows.items():
                if not vals:
                    continue
                s = statistics.median(v[0] for v in vals)
                m = statistics.median(v[1] for v in vals)
                med[name] = (s, m)
                print(f"  {name:22s} {s:7.2f} s  ({', '.join(f'{v[0]:.2f}' for v in vals)})  "
                      f"peak {m / 2**20:7.0f} MiB  ({m / (n * n):.1f} bytes a sample)")
            if len(med) == 2:
                (s1, m1), (s2, m2) = med["terrainvis viewshed"], med["gdal_viewshed"]
                print(f"  ours / GDAL: time {s1 / s2:.2f}, peak memory {m1 / m2:.2f}")
    finally:
        if args.folder is None:
            shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
