"""First contact: each entry point with an empty numba cache (cold) and again on the cache it filled (warm).

Every cold run gets its own empty ``NUMBA_CACHE_DIR``, so numba compiles every kernel it
meets, as on a fresh install; the warm run follows at once on the same cache. The script
prints, per entry point, the medians over ``--repeats`` of the cold and warm wall times,
their ratio, and whether the cold run printed its compile line (``terrainvis: compiling
...``, :mod:`terrainvis.core.compiling`) and the warm one did not:

* ``viewshed``: ``terrainvis viewshed DEM.tif --observer X Y -o out.tif`` on a 1024² float32
  GeoTIFF (30 m cells, made in a temporary folder), beside ``gdal_viewshed`` on the same
  file when it is installed (its median, and ours over it, warm);
* ``assert_visibility_kept``: ``terrainvis.testing.assert_visibility_kept`` of a bundled
  terrain and its LLS level 2, 200 points (a user's regression test in a fresh CI job);
* ``compare --quick``: ``terrainvis compare --quick --no-plots --workers 2``;
* ``los``: ``terrainvis los`` of one pair on the same GeoTIFF.

``--kernels`` also prints, for each part of ``terrainvis compile`` run alone with an empty
cache, the seconds each kernel that Python calls took to compile with everything it calls
(numba's compile events): the figures behind :data:`terrainvis.core.compiling.KERNELS`.

Usage::

    python benchmarks/bench_cold_start.py [--repeats 3] [--only viewshed assert_visibility_kept] [--kernels]

The machine is shared: run it when it is otherwise idle, and read the medians and ratios.
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

AVK = """
import simplifiers, terrainvis as tv
from terrainvis.testing import assert_visibility_kept
T = tv.bundled_terrain("hills")
assert_visibility_kept(T, simplifiers.simplify(T, "lls", 2), min_accuracy=0.5)
"""

MAKE_DEM = """
import sys, numpy as np, terrainvis as tv
g = tv.synthetic_terrain("mountains", size=int(sys.argv[2]), seed=1)
z = g.z.astype(np.float32).astype(np.float64)
tv.save_dem(tv.HeightGrid(z, 30.0, 30.0, (500000.0, 4000000.0), attrs={"crs": "EPSG:32617"}), sys.argv[1],
            dtype="float32")
"""

#: Child-script source that, from where it stands on, records each outermost numba compile (a
#: kernel called from Python, with every callee not compiled before it) in ``compiled`` as
#: (the kernel's Python function, its argument types, wall seconds). ``ab_compile.py`` uses it too.
OUTERMOST = """
import time as _time
from numba.core import event as _event
_depth, _t0, compiled = [0], [0.0], []
class _Outermost(_event.Listener):
    def on_start(self, ev):
        if _depth[0] == 0:
            _t0[0] = _time.perf_counter()
        _depth[0] += 1
    def on_end(self, ev):
        _depth[0] -= 1
        if _depth[0] == 0:
            compiled.append((ev.data["dispatcher"].py_func, ev.data["args"], _time.perf_counter() - _t0[0]))
_event.register("numba:compile", _Outermost())
"""

#: Prints each outermost compile of one part of ``terrainvis compile`` and its seconds.
KERNELS = OUTERMOST + """
import sys
from terrainvis.cli.compile_ahead import PARTS
PARTS[sys.argv[1]][1]()
for f, _, s in compiled:
    print(f"{s:8.2f}  {f.__module__}.{f.__qualname__}")
"""


def _run(cmd, cache: str, cwd: str) -> tuple[float, str]:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache)
    t0 = time.perf_counter()
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=cwd)
    seconds = time.perf_counter() - t0
    if out.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({out.returncode}): {out.stderr[-2000:]}")
    return seconds, out.stderr


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--size", type=int, default=1024, help="the GeoTIFF's side (default 1024)")
    ap.add_argument("--only", nargs="+", default=None, help="entry points to run (default: all)")
    ap.add_argument("--kernels", action="store_true", help="also time each kernel's compilation, part by part")
    args = ap.parse_args()
    py = sys.executable
    tv = [py, "-m", "terrainvis.cli"]
    work = tempfile.mkdtemp(prefix="bench-cold-")
    try:
        dem = os.path.join(work, "dem.tif")
        subprocess.run([py, "-c", MAKE_DEM, dem, str(args.size)], check=True)
        mid = 500000.0 + 30.0 * (args.size // 2)
        observer = [f"{mid + 15.0:.1f}", f"{4000000.0 + 30.0 * (args.size // 3) + 15.0:.1f}"]
        entries = {
            "viewshed": tv + ["viewshed", dem, "--observer", *observer, "-o", "out.tif"],
            "assert_visibility_kept": [py, "-c", AVK],
            "compare --quick": tv + ["compare", "--quick", "--no-plots", "--workers", "2", "--out", "run"],
            "los": tv + ["los", dem, "--from", *observer, "--to", f"{mid + 9000:.1f}", f"{4000000.0 + 9000:.1f}"],
        }
        chosen = args.only or list(entries)
        rows = []
        for name in chosen:
            cold, warm, lines = [], [], []
            for _ in range(args.repeats):
                with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as cwd:
                    seconds, err = _run(entries[name], cache, cwd)
                    cold.append(seconds)
                    said = [ln for ln in err.splitlines() if ln.startswith("terrainvis: compiling")
                            or ln.startswith("terrainvis: first run: compiling")]
                    shutil.rmtree(os.path.join(cwd, "run"), ignore_errors=True)
                    seconds, err2 = _run(entries[name], cache, cwd)
                    warm.append(seconds)
                    again = [ln for ln in err2.splitlines() if "compiling" in ln]
                    lines.append((said, again))
            c, w = statistics.median(cold), statistics.median(warm)
            said, again = lines[0]
            rows.append((name, c, w, c / w, bool(said) and not again))
            print(f"{name}: cold {', '.join(f'{v:.1f}' for v in cold)} s, warm {', '.join(f'{v:.2f}' for v in warm)} s",
                  file=sys.stderr)
            for ln in said:
                print(f"    {ln}", file=sys.stderr)
        gdal = shutil.which("gdal_viewshed")
        if gdal and "viewshed" in chosen:
            times = []
            for _ in range(max(3, args.repeats)):
                t0 = time.perf_counter()
                subprocess.run([gdal, "-q", "-ox", observer[0], "-oy", observer[1], "-oz", "1.7", dem,
                                os.path.join(work, "gdal.tif")], check=True, capture_output=True)
                times.append(time.perf_counter() - t0)
            g = statistics.median(times)
            rows.append(("gdal_viewshed (the same file)", float("nan"), g, float("nan"), None))
        print(f"\n{'entry point':32s} {'cold s':>8s} {'warm s':>8s} {'cold/warm':>10s}  compile line")
        for name, c, w, r, said in rows:
            note = "" if said is None else ("printed (cold only)" if said else "MISSING or repeated warm")
            print(f"{name:32s} {c:8.1f} {w:8.2f} {r:10.1f}  {note}")
        if gdal and "viewshed" in chosen:
            ours = next(w for n, _, w, _, _ in rows if n == "viewshed")
            print(f"{'viewshed warm / gdal_viewshed':32s} {ours / g:8.2f}")
        if args.kernels:
            from terrainvis.cli.compile_ahead import PARTS

            print("\nseconds to compile each kernel called from Python (with what it calls), part by part:")
            for part in PARTS:
                with tempfile.TemporaryDirectory() as cache:
                    env = dict(os.environ, NUMBA_CACHE_DIR=cache, TERRAINVIS_COMPILE_NOTICE="0")
                    out = subprocess.run([py, "-c", KERNELS, part], env=env, capture_output=True, text=True,
                                         check=True)
                print(f"  {part}:")
                for line in out.stdout.splitlines():
                    print(f"    {line}")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
