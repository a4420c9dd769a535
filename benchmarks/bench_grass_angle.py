"""Benchmark: the viewshed's ``output="angle"`` beside GRASS ``r.viewshed``'s vertical angle.

The two rasters hold different quantities, so three things are compared, on the shared
DEMs and observers of ``bench_output_modes.py`` (its GeoTIFFs: the shared
``green_mountains_vt.tif`` as it is, the ``.npz`` DEMs written to a temporary GeoTIFF, the
lon/lat ones in local metres under a UTM label), eye ``--eye`` m above the observer's
sample, targets ``--target-height`` above theirs, curvature off (and, unless
``--no-curvature``, on: ours ``curvature=0.85714``, r.viewshed ``-c -r
refraction_coeff=0.14286``, the same drop ``0.85714 d**2 / (2 a)``):

* ours: ``viewshed(grid, (x, y), observer_height=EYE, target_height=T, output="angle",
  curvature=C)``, per sample the elevation angle of the target's sight line above (+) or
  below (-) the horizon of its ray (the sight line grazing the highest terrain between
  the eye and the target), in degrees;
* r.viewshed (GRASS 8, Debian package grass-core), default (angle) output: per *visible*
  cell the vertical angle of the sight line from the eye to the cell's target, 0 straight
  down, 90 horizontal, 180 straight up (so ``value - 90`` is the elevation angle above the
  eye's horizontal); NULL where the cell is not visible or is nodata; 180 at the
  observer's own cell, which is left out of every comparison.

Agreement, per case (cells with a height, the observer's own cell left out):

1. **Visibility**: ours ``angle >= 0`` against r.viewshed non-NULL. The cells that differ
   (split by which side sees) are expected along our visibility edges, where a ray
   grazes its horizon and the two surfaces (ours piecewise-linear, cells split along a
   diagonal; r.viewshed's cells taken at their entering, centre and exiting elevations)
   put the horizon slightly apart. The script prints the share of them within one cell of
   an edge of our viewshed and the median and 95th percentile of ``|our angle|`` there
   (how far from grazing the sight line is, by our surface), beside the median
   ``|our angle|`` of all cells. It also checks our ``angle >= 0`` against our own boolean
   viewshed (the same question asked of the other engine; expected: no cell differs).
   For the differing cells that are clearly on one side by our surface (``|our angle| >
   CLEAR_DEGREES``, 0.1 degrees), it prints which program sees them and where our sight
   line meets the terrain (:func:`terrainvis.visibility.lowest_point`): the median
   distance of that point from the eye in cells (the mean of the two spacings), and the
   median depth of the sight line below our surface there (on a DEM with nodata, on the
   grid with its nodata filled by the nearest sample, ``HeightGrid.fill_nodata()``: our
   viewshed leaves holes out instead, so near a hole this is an approximation).
2. **Sight-line angle**, at the cells both call visible: r.viewshed's ``value - 90``
   against the geometric elevation angle of the sight line from our eye to our target,
   ``atan2(z_T - k d**2 - E_z, d)`` (``terrainvis.visibility.viewsheds.field_of_view.elevation_degrees``,
   the first term of our angle: E_z the observer's sample plus the eye height, z_T the
   target's sample plus the target height, d the horizontal distance between the sample
   centres, k = curvature / (2 R), R = 6,378,137 m). It tests that both programs put the
   eye and the targets at the same heights (and apply the same drop). It is printed as the
   largest difference in degrees and as the height difference it amounts to at the
   target's distance, ``d |tan a1 - tan a2|``. r.viewshed writes float32, so about 1e-5
   degrees is its resolution near 90.
3. **Below the horizon**: r.viewshed has no counterpart of our negative angles. Its
   invisible cells are NULL (angle output), 0 (``-b``) or -1 (``-e``), and the values of
   visible cells are measured from the eye's horizontal, not from the horizon of the ray,
   so neither sign of our angle has a GRASS value to compare with; nothing is printed.

Speed, medians of ``--repeats`` runs, in the same run:

* ours: the call on the grid as loaded from the GeoTIFF (no file I/O), after a warm-up
  call; our boolean viewshed's call beside it for scale; and the command
  ``terrainvis viewshed DEM.tif --observer X Y --height EYE --target-height T
  --output-mode angle --curvature C -o OUT.tif`` (the whole process: Python's start-up,
  reading the GeoTIFF, writing a float32 GeoTIFF), after one warm-up run (numba's cache);
* r.viewshed: the module's whole process run in a prepared GRASS location
  (``r.viewshed input=dem output=vs coordinates=X,Y observer_elevation=EYE
  target_elevation=T --overwrite --quiet``, plus ``-c -r refraction_coeff=0.14286``),
  reading the GRASS raster and writing its own, with the variables a GRASS session sets
  (GISBASE from ``grass --config path``, GISRC a file naming the location and mapset,
  GISBASE/bin on PATH, GISBASE/lib on LD_LIBRARY_PATH); and the
  same module run through the launcher, ``grass LOC/PERMANENT --exec r.viewshed ...``
  (which adds GRASS's own start-up). The one-off location set-up (``grass -c DEM.tif
  LOC -e``, ``r.in.gdal``, ``g.region raster=dem``) and the export read back for the
  comparison (``r.out.gdal``) are outside the timings; the set-up time is printed once
  per DEM.

Nothing is asserted: this is a measurement (``tests/visibility/test_peers.py`` pins the
visibility agreement on one DEM). Without GRASS the script says so and times ours alone.

Example::

    python benchmarks/bench_grass_angle.py                   # all shared DEMs, 5 repeats
    python benchmarks/bench_grass_angle.py --repeats 3 --dems green_mountains_vt --no-curvature
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

from bench_output_modes import DEMS, STD_CURVATURE, _geotiff, _median_time, _observers
from terrainvis import load_dem, viewshed
from terrainvis.core.metrics import verdict_edges
from terrainvis.visibility import EARTH_RADIUS, curvature_coefficient, lowest_point
from terrainvis.visibility.viewsheds.field_of_view import elevation_degrees


#: Differing cells farther than this from our horizon (degrees) are located (see the docstring).
CLEAR_DEGREES = 0.1


class GrassLocation:
    """A temporary GRASS location holding one DEM as raster ``dem``, and two ways to run
    modules in it: the bare module process (a prepared session environment) and the
    ``grass ... --exec`` launcher."""

    def __init__(self, grass: str, dem: str, folder: str):
        self.grass = grass
        quiet = dict(os.environ, GRASS_MESSAGE_FORMAT="silent")
        t = time.perf_counter()
        loc = os.path.join(folder, "loc")
        subprocess.run([grass, "-c", dem, loc, "-e"], check=True, capture_output=True, env=quiet)
        self.launcher = [grass, os.path.join(loc, "PERMANENT"), "--exec"]
        self.launcher_env = quiet
        gisbase = subprocess.run([grass, "--config", "path"], check=True, capture_output=True,
                                 text=True).stdout.strip().splitlines()[-1]
        rc = os.path.join(folder, "gisrc")
        with open(rc, "w") as f:
            f.write(f"GISDBASE: {folder}\nLOCATION_NAME: loc\nMAPSET: PERMANENT\nGUI: text\n")
        lib = os.path.join(gisbase, "lib")
        self.env = dict(quiet, GISBASE=gisbase, GISRC=rc,
                        PATH=os.path.join(gisbase, "bin") + os.pathsep + os.environ.get("PATH", ""),
                        LD_LIBRARY_PATH=lib + (os.pathsep + os.environ["LD_LIBRARY_PATH"]
                                               if os.environ.get("LD_LIBRARY_PATH") else ""))
        self.run("r.in.gdal", f"input={dem}", "output=dem", "--quiet")
        self.run("g.region", "raster=dem")
        self.setup_seconds = time.perf_counter() - t

    def run(self, *args: str) -> None:
        subprocess.run(list(args), check=True, capture_output=True, env=self.env)

    def read(self, raster: str, out: str) -> np.ndarray:
        """The raster as float64 in terrainvis' row order (south first), NULL as NaN."""
        import rasterio

        self.run("r.out.gdal", f"input={raster}", f"output={out}", "type=Float32", "--overwrite", "--quiet", "-f")
        with rasterio.open(out) as f:
            a = f.read(1).astype(np.float64)[::-1]
            if f.nodata is not None and np.isfinite(f.nodata):
                a[a == f.nodata] = np.nan
        return a


def _r_viewshed_args(x: float, y: float, eye: float, target: float, curv: float) -> list[str]:
    args = ["r.viewshed", "input=dem", "output=vs", f"coordinates={x!r},{y!r}", f"observer_elevation={eye!r}",
            f"target_elevation={target!r}", "--overwrite", "--quiet"]
    if curv:
        args += ["-c", "-r", f"refraction_coeff={1.0 - curv:.5f}"]
    return args


def _agreement(g, r: int, c: int, eye: float, target: float, curv: float, ours: np.ndarray, ours_bool: np.ndarray,
               peer: np.ndarray) -> dict:
    valid = np.isfinite(g.z)
    valid[r, c] = False
    ours_vis = np.nan_to_num(ours, nan=-1.0) >= 0.0
    peer_vis = np.isfinite(peer)
    differ = (ours_vis != peer_vis) & valid
    out = {"cells": int(valid.sum()), "ours_visible": float(ours_vis[valid].mean()),
           "peer_visible": float(peer_vis[valid].mean()), "differ": int(differ.sum()),
           "peer_only": int((differ & peer_vis).sum()), "ours_only": int((differ & ours_vis).sum()),
           "self_differ": int(((ours_vis != ours_bool) & valid).sum()),
           "own_cell": float(peer[r, c]),
           "median_abs_all": float(np.median(np.abs(ours[valid & np.isfinite(ours)])))}
    if out["differ"]:
        a = np.abs(ours[differ])
        out.update(near_edge=float((differ & verdict_edges(ours_vis)).sum() / out["differ"]),
                   median_abs_differ=float(np.median(a)), p95_abs_differ=float(np.percentile(a, 95)))
    else:
        out.update(near_edge=float("nan"), median_abs_differ=float("nan"), p95_abs_differ=float("nan"))
    clear = differ & (np.abs(np.nan_to_num(ours)) > CLEAR_DEGREES)
    out.update(clear=int(clear.sum()), clear_peer_sees=int((clear & peer_vis).sum()),
               clear_cells=float("nan"), clear_depth=float("nan"))
    if out["clear"]:
        e = np.array([g.xs[c], g.ys[r], g.z[r, c] + eye])
        located = g.fill_nodata() if g.n_nodata else g  # lowest_point needs a grid without nodata
        spacing = 0.5 * (abs(g.xs[1] - g.xs[0]) + abs(g.ys[1] - g.ys[0]))
        dist, depth = [], []
        for tr, tc in zip(*np.nonzero(clear)):
            low = lowest_point(located, e, [g.xs[tc], g.ys[tr], g.z[tr, tc] + target], curvature=curv)
            dist.append(low["distance"] / spacing)
            depth.append(-low["clearance"])
        out.update(clear_cells=float(np.median(dist)), clear_depth=float(np.median(depth)))
    both = ours_vis & peer_vis & valid
    xs, ys = np.meshgrid(g.xs, g.ys)
    d = np.hypot(xs - g.xs[c], ys - g.ys[r])[both]
    kc = curvature_coefficient(curv, EARTH_RADIUS)
    geom = elevation_degrees(d, (g.z[both] + target) - (g.z[r, c] + eye), kc)
    peer_elev = peer[both] - 90.0
    dh = d * np.abs(np.tan(np.radians(peer_elev)) - np.tan(np.radians(geom)))
    out.update(both=int(both.sum()), angle_max=float(np.max(np.abs(peer_elev - geom))),
               angle_rms=float(np.sqrt(np.mean((peer_elev - geom) ** 2))), height_max=float(dh.max()))
    return out


def _terrainvis_command() -> str:
    return shutil.which("terrainvis") or os.path.join(os.path.dirname(os.path.abspath(sys.executable)), "terrainvis")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dems", nargs="+", default=list(DEMS), choices=DEMS)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--eye", type=float, default=10.0)
    ap.add_argument("--target-height", type=float, default=0.0)
    ap.add_argument("--no-curvature", action="store_true", help="the flat earth only")
    ap.add_argument("--no-commands", action="store_true", help="skip timing the terrainvis command")
    args = ap.parse_args(argv)
    grass = shutil.which("grass")
    if grass is None:
        print("grass not found (Debian: apt-get install grass-core): no r.viewshed, ours alone")
    tv = None if args.no_commands else _terrainvis_command()
    tmp = tempfile.mkdtemp(prefix="bench_grass_angle_")
    eye, target = args.eye, args.target_height
    curvatures = (0.0,) if args.no_curvature else (0.0, STD_CURVATURE)
    print(f"eye {eye:g} m, targets {target:g} m; viewshed(output='angle') vs r.viewshed (vertical angle); "
          f"medians of {args.repeats} runs; uptime: {os.popen('uptime').read().strip()}")
    rows = []
    for name in args.dems:
        dem = _geotiff(name, tmp)
        g = load_dem(dem)
        print(f"\n=== {name}: {g.shape[0]} x {g.shape[1]}, {g.n_nodata:,} nodata", flush=True)
        loc = None
        if grass:
            loc = GrassLocation(grass, dem, tempfile.mkdtemp(prefix=f"{name}_", dir=tmp))
            print(f"  GRASS location set up (grass -c, r.in.gdal, g.region; not timed below) in "
                  f"{loc.setup_seconds:.2f} s")
        for oname, (r, c) in _observers(g).items():
            x, y = float(g.xs[c]), float(g.ys[r])
            for curv in curvatures:
                kw = dict(observer_height=eye, target_height=target, curvature=curv)
                viewshed(g, (x, y), output="angle", **kw)  # warm-up
                viewshed(g, (x, y), **kw)
                t_ours, ours = _median_time(lambda: viewshed(g, (x, y), output="angle", **kw), args.repeats)
                t_vis, ours_bool = _median_time(lambda: viewshed(g, (x, y), **kw), args.repeats)
                row = {"dem": name, "samples": g.z.size, "nodata": g.n_nodata, "observer": oname, "curvature": curv,
                       "ours": t_ours, "visible": t_vis}
                line = (f"  {oname:7s} (sample {r}, {c}) curvature {curv:<7g} ours {t_ours:7.3f} s "
                        f"(visible mode {t_vis:6.3f} s)")
                if tv:
                    out = os.path.join(tmp, "ours.tif")
                    cmd = [tv, "viewshed", dem, "--observer", repr(x), repr(y), "--height", repr(eye),
                           "--target-height", repr(target), "--output-mode", "angle", "--curvature", repr(curv),
                           "-o", out]
                    subprocess.run(cmd, check=True, capture_output=True)  # warm-up (numba's cache)
                    row["command"], _ = _median_time(lambda: subprocess.run(cmd, check=True, capture_output=True),
                                                     args.repeats)
                    line += f"  command {row['command']:6.3f} s"
                if loc:
                    rv = _r_viewshed_args(x, y, eye, target, curv)
                    row["grass"], _ = _median_time(lambda: loc.run(*rv), args.repeats)
                    row["grass_exec"], _ = _median_time(
                        lambda: subprocess.run(loc.launcher + rv, check=True, capture_output=True,
                                               env=loc.launcher_env), args.repeats)
                    peer = loc.read("vs", os.path.join(tmp, "vs.tif"))
                    row.update(_agreement(g, r, c, eye, target, curv, ours, ours_bool, peer))
                    line += (f"  r.viewshed {row['grass']:6.3f} s (via grass --exec {row['grass_exec']:6.3f} s)"
                             f"  r.viewshed/ours {row['grass'] / t_ours:5.2f}")
                    if tv:
                        line += f"  r.viewshed/command {row['grass'] / row['command']:5.2f}"
                    line += (f"\n      visible: ours {100 * row['ours_visible']:5.1f} %  r.viewshed "
                             f"{100 * row['peer_visible']:5.1f} %  differ {row['differ']:,} of {row['cells']:,} "
                             f"({100 * row['differ'] / row['cells']:.2f} %: r.viewshed only {row['peer_only']:,}, "
                             f"ours only {row['ours_only']:,}), {100 * row['near_edge']:.0f} % of them within one cell "
                             f"of our edge; |our angle| there median {row['median_abs_differ']:.3f} deg, "
                             f"95th pct {row['p95_abs_differ']:.3f} deg (all cells: median "
                             f"{row['median_abs_all']:.2f} deg); our angle >= 0 vs our boolean viewshed: "
                             f"{row['self_differ']} cells differ"
                             f"\n      differing cells with |our angle| > {CLEAR_DEGREES:g} deg: {row['clear']:,}, "
                             f"r.viewshed sees {row['clear_peer_sees']:,} of them; our sight line meets the terrain "
                             f"a median {row['clear_cells']:.1f} cells from the eye, {row['clear_depth']:.2f} m "
                             f"under it (median)"
                             f"\n      sight-line angle at the {row['both']:,} cells both see: r.viewshed - 90 vs "
                             f"ours max {row['angle_max']:.2e} deg, RMS {row['angle_rms']:.2e} deg, as a height "
                             f"max {row['height_max']:.2e} m; r.viewshed's own cell {row['own_cell']:g}")
                print(line, flush=True)
                rows.append(row)
    if grass:
        print("\nsummary (Markdown; times in s; 'differ' = visibility verdicts, % of the cells with a height)\n")
        print("| DEM (samples) | observer | curvature | ours | ours, `visible` | ours, command | r.viewshed "
              "| r.viewshed / ours | r.viewshed / command | differ (r.viewshed only + ours only) | near our edge "
              "| median \\|angle\\| there | > 0.1° (r.viewshed sees) | their blocking point, cells from the eye "
              "| sight-line angle, max diff |")
        print("|" + "---|" * 15)
        for rw in rows:
            cmd = rw.get("command", float("nan"))
            print(f"| {rw['dem']} ({rw['samples']:,}) | {rw['observer']} | {rw['curvature']:g} | {rw['ours']:.3f} "
                  f"| {rw['visible']:.3f} | {cmd:.3f} | {rw['grass']:.3f} | {rw['grass'] / rw['ours']:.2f} "
                  f"| {rw['grass'] / cmd:.2f} | {100 * rw['differ'] / rw['cells']:.2f} % ({rw['peer_only']} + "
                  f"{rw['ours_only']}) | {100 * rw['near_edge']:.0f} % | {rw['median_abs_differ']:.3f}° "
                  f"| {rw['clear']} ({rw['clear_peer_sees']}) | {rw['clear_cells']:.1f} | {rw['angle_max']:.1e}° |")
    print(f"\nuptime at the end: {os.popen('uptime').read().strip()}")
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
