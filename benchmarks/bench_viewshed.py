"""Benchmark: exact viewsheds against xarray-spatial's viewshed and the pair engine, in one run.

For each size, ``synthetic_terrain(--kind, size)`` (30 m cells) is built and an observer
stands on the sample nearest the centre, ``--observer-height`` above it (xarray-spatial
snaps its observer to a cell, so both programs answer the same question from the same
eye). The script prints, per size, the median over ``--repeats`` runs of

* ours: :func:`terrainvis.visibility.viewsheds.sweep.viewshed` (grid engine, exact), with how
  its samples were decided (the sweep's lower bound, its upper bound plus the exact walk
  of the last ring, or the pair engine for the rest);
* the pair engine: ``grid_clearance`` from the eye to all samples (its own pyramid), which
  must agree with ours on every sample;
* xarray-spatial 0.5.3 ``viewshed`` (a port of GRASS r.viewshed's radial sweep, numba);

and the ratios, and how many samples ours and xarray-spatial disagree on.

Conventions mapped for xarray-spatial
-------------------------------------
* Input: a DataArray with dims ``("y", "x")`` whose coordinates are the grid's ``ys``
  (increasing, so row r of the data is our row r) and ``xs``. r.viewshed measures
  distances from row/column offsets times the resolutions, so the orientation of the y
  axis does not change its answer (checked with ``--check-flip``: the flipped raster gives
  the flipped viewshed).
* ``observer_elev`` is added to the raster value at the observer's cell: the same eye as
  ours on that sample. ``target_elev`` (0 here) is added to each cell's value, as our
  ``target_height``.
* Output: a visible cell holds its vertical angle (0..180 degrees), an invisible one -1;
  visible = ``values >= 0``.
* xarray-spatial converts the raster to float64 in place and keeps a 3 x cells event list
  of 7 float64 (about 2.3 GB at 3601 x 3601, 7.6 GB peak RSS measured).

Why the answers differ: r.viewshed decides a cell by the gradient to its centre against
the largest gradient of the cells closer to the eye within the cell's angular span, each
cell modelled by the elevations at its entering, centre and exiting angles; ours evaluates
the piecewise-linear surface (cells split along a diagonal) exactly along each ray. The
disagreements cluster on the horizon lines, where the two models' horizons cross: the
script reports how many disagreeing samples have a sample of the other verdict among
their 8 neighbours (in our viewshed), and the split by direction.

GIS peers (``--peers``)
----------------------
``synthetic_terrain(--kind, --peer-size)`` (30 m cells) is written as a float32 GeoTIFF in
UTM zone 18N and loaded back with ``terrainvis.load_dem`` (so all three read the same
heights). From the highest and the lowest sample of the central half, eye ``--eye`` m
up, targets on the ground, curvature off and on (standard refraction, 0.85714), it times

* ours: the exact viewshed call on the loaded grid (no file I/O);
* ``gdal_viewshed`` (Debian package gdal-bin), the whole command with reading and writing
  the GeoTIFF: ``-ox X -oy Y -oz EYE -tz 0 -cc C -vv 1 -iv 0``. GDAL 3.6's ``-cc 0``
  is a flat earth (its output is identical to ``-cc 1e-9``'s); its default is 0.85714.
  Its earth radius is the ellipsoid's semi-major axis (WGS84: 6,378,137 m), as ours;
* ``r.viewshed`` (Debian package grass-core) in a temporary GRASS location made from the
  GeoTIFF (``grass -c DEM.tif DIR/loc -e``, then ``grass DIR/loc/PERMANENT --exec
  r.in.gdal input=DEM.tif output=dem`` and ``g.region raster=dem``), the whole
  ``grass ... --exec r.viewshed input=dem output=vs coordinates=X,Y observer_elevation=EYE
  target_elevation=0 memory=4000 -b`` command (plus ``-c -r refraction_coeff=0.14286``
  with curvature);

and prints the medians, the ratios peer / ours, and how many cells each peer answers
differently, split by direction, with the share of them within one cell of a visibility
edge of ours. Last, ``terrainvis viewshed DEM --observer X Y --height EYE -o out.tif``
against the gdal_viewshed command, command to command (curvature off: the command has no
curvature option yet). Peers that are not installed are skipped with a message.

Example::

    python benchmarks/bench_viewshed.py                                  # 1024, 2048, 3601
    python benchmarks/bench_viewshed.py --sizes 512 1024 --repeats 1     # quick
    python benchmarks/bench_viewshed.py --sizes 3601 --no-xrspatial      # ours vs the pair engine
    python benchmarks/bench_viewshed.py --sizes 1024 --kind noisy-plane  # a grazing worst case
    python benchmarks/bench_viewshed.py --peers --repeats 5              # GDAL and GRASS, 3601^2
"""

from __future__ import annotations

import argparse
import gc
import statistics
import time

import numpy as np

from terrainvis.core.metrics import verdict_edges
from terrainvis.core.synthetic import synthetic_terrain
from terrainvis.visibility import clearance_tolerance, trim_length
from terrainvis.visibility.grid import grid_accel, grid_clearance
from terrainvis.visibility.viewsheds.sweep import _viewshed


def _terrain(kind: str, n: int, seed: int = 0):
    """``synthetic_terrain(kind, n)``, or a tilted plane (optionally with 0.5 m of noise):
    the worst case for any exact viewshed, every ray grazing the ground it crosses."""
    if kind in ("tilted-plane", "noisy-plane"):
        from terrainvis import HeightGrid

        y, x = np.mgrid[0:n, 0:n] * 30.0
        z = 100.0 + 0.05 * x + 0.02 * y
        if kind == "noisy-plane":
            z = z + np.random.default_rng(seed).normal(0.0, 0.5, z.shape)
        return HeightGrid(z, dx=30.0, dy=30.0)
    return synthetic_terrain(kind, n)


def _time(fn, repeats: int):
    times = []
    out = None
    for _ in range(repeats):
        gc.collect()
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def _xrs_array(grid, flip: bool = False):
    import xarray as xr

    z = np.array(grid.z)
    ys = np.array(grid.ys)
    if flip:
        z = z[::-1].copy()
        ys = ys[::-1].copy()
    return xr.DataArray(z, dims=("y", "x"), coords={"y": ys, "x": np.array(grid.xs)})


def _xrs_viewshed(da, x: float, y: float, h: float) -> np.ndarray:
    from xrspatial import viewshed as xrs_viewshed

    return np.asarray(xrs_viewshed(da, x=x, y=y, observer_elev=h, target_elev=0.0).values) >= 0


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1024, 2048, 3601])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--kind", default="mountains",
                    help="a synthetic_terrain kind, or tilted-plane / noisy-plane (grazing worst cases)")
    ap.add_argument("--observer-height", type=float, default=2.0)
    ap.add_argument("--no-xrspatial", action="store_true", help="skip xarray-spatial")
    ap.add_argument("--no-pair", action="store_true", help="skip the pair engine")
    ap.add_argument("--check-flip", action="store_true", help="also run xarray-spatial on the y-flipped raster")
    ap.add_argument("--peers", action="store_true",
                    help="ours against gdal_viewshed and r.viewshed instead (see 'GIS peers' above)")
    ap.add_argument("--peer-size", type=int, default=3601, help="--peers: grid size (default 3601)")
    ap.add_argument("--eye", type=float, default=10.0, help="--peers: eye height (default 10 m)")
    ap.add_argument("--grass-repeats", type=int, default=1, help="--peers: runs of r.viewshed (about 25 s each)")
    ap.add_argument("--no-grass", action="store_true", help="--peers: skip r.viewshed")
    ap.add_argument("--no-commands", action="store_true", help="--peers: skip the command-to-command timing")
    args = ap.parse_args(argv)
    if args.peers:
        peers(args)
        return
    h = args.observer_height

    # compile (or load) every kernel on a small grid first: no JIT time in the figures
    small = _terrain(args.kind, 64)
    _viewshed(small, (small.xs[32], small.ys[32]), observer_height=h)
    if not args.no_xrspatial:
        t = time.perf_counter()
        _xrs_viewshed(_xrs_array(small), float(small.xs[32]), float(small.ys[32]), h)
        print(f"xarray-spatial warm-up (numba JIT) {time.perf_counter() - t:.1f} s")

    rows_out = []
    for n in args.sizes:
        t = time.perf_counter()
        g = _terrain(args.kind, n)
        gen = time.perf_counter() - t
        r0 = c0 = n // 2
        x0, y0 = float(g.xs[c0]), float(g.ys[r0])
        print(f"\n=== {args.kind} {n} x {n} (generated in {gen:.1f} s), observer on sample ({r0}, {c0}), "
              f"eye {h} m up, {g.z.size:,} targets")
        _viewshed(g, (x0, y0), observer_height=h)  # per-grid caches (max slope), as for any repeated use
        t_ours, (ours, info) = _time(lambda: _viewshed(g, (x0, y0), observer_height=h), args.repeats)
        swept = info["lb"] + info["ub"] + info["walk"]
        print(f"ours            {t_ours:8.3f} s   visible {int(ours.sum()):,} "
              f"({100 * ours.mean():.3f} %); decided by the sweep: {swept:,} "
              f"({100 * swept / info['targets']:.2f} %: lower bound {info['lb']:,}, upper bound + last ring "
              f"{info['ub']:,} (of which the last ring bounded, not walked, {info['ub_bound']:,}), walks of the "
              f"blocks above the bound {info['walk']:,}); "
              f"pair engine for the rest: {info['exact']:,}")
        row = {"n": n, "ours": t_ours, "decided": swept / info["targets"]}

        if not args.no_pair:
            delta = trim_length(g)
            tol = clearance_tolerance(g)
            grid_accel(g)
            X, Y = np.meshgrid(g.xs, g.ys)
            b = np.column_stack([X.ravel(), Y.ravel(), g.z.ravel()])
            del X, Y
            a = np.empty_like(b)
            a[:] = (x0, y0, g.z[r0, c0] + h)
            t_pair, clear = _time(lambda: grid_clearance(g, a, b, delta=delta, tol=tol, los=True), args.repeats)
            pair = (clear >= -tol).reshape(g.shape)
            del a, b, clear
            pair[r0, c0] = True
            same = int((pair != ours).sum())
            print(f"pair engine     {t_pair:8.3f} s   ratio pair / ours {t_pair / t_ours:6.2f} x; "
                  f"samples differing from ours: {same}")
            row.update(pair=t_pair, pair_ratio=t_pair / t_ours, pair_diff=same)

        if not args.no_xrspatial:
            da = _xrs_array(g)
            t_xrs, xvis = _time(lambda: _xrs_viewshed(da, x0, y0, h), args.repeats)
            del da
            gc.collect()
            differ = xvis != ours
            nd = int(differ.sum())
            near = int((differ & verdict_edges(ours)).sum())
            print(f"xarray-spatial  {t_xrs:8.3f} s   ratio xrs / ours {t_xrs / t_ours:6.2f} x; visible "
                  f"{int(xvis.sum()):,} ({100 * xvis.mean():.3f} %)")
            print(f"  disagreements {nd:,} ({100 * nd / g.z.size:.4f} % of samples): xrs visible / ours hidden "
                  f"{int((xvis & ~ours).sum()):,}, xrs hidden / ours visible {int((~xvis & ours).sum()):,}; "
                  f"{near:,} ({100 * near / max(nd, 1):.1f} %) within one sample of a visibility edge of ours")
            row.update(xrs=t_xrs, xrs_ratio=t_xrs / t_ours, xrs_diff=nd, xrs_near=near)
            if args.check_flip:
                flipped = _xrs_viewshed(_xrs_array(g, flip=True), x0, y0, h)[::-1]
                print(f"  y-flipped raster: {int((flipped != xvis).sum())} samples differ from the unflipped answer")
        rows_out.append(row)
        del g, ours
        gc.collect()

    print("\nsummary (medians of", args.repeats, "runs; ratios = peer time / ours)")
    heads = ("size", "ours s", "sweep %", "pair s", "pair x", "xrs s", "xrs x", "xrs diff")
    print(" ".join(f"{h:>{w}}" for h, w in zip(heads, (6, 9, 8, 9, 7, 9, 7, 9))))
    for r in rows_out:
        print(f"{r['n']:>6} {r['ours']:>9.3f} {100 * r['decided']:>8.2f} "
              f"{r.get('pair', float('nan')):>9.3f} {r.get('pair_ratio', float('nan')):>7.2f} "
              f"{r.get('xrs', float('nan')):>9.3f} {r.get('xrs_ratio', float('nan')):>7.2f} "
              f"{r.get('xrs_diff', -1):>9}")


# ------------------------------------------------------------------ GIS peers (--peers)
#: Standard refraction in GDAL's convention (-cc) and r.viewshed's (-r refraction_coeff).
STD_CURVATURE = 0.85714


def _write_geotiff(grid, path) -> None:
    """The grid as a float32 GeoTIFF in UTM zone 18N (30 m cells, north up): both peers
    need a projected CRS; ours then loads the same float32 heights back."""
    import rasterio
    from rasterio.transform import from_origin

    rows, cols = grid.shape
    dx = float(grid.xs[1] - grid.xs[0])
    with rasterio.open(path, "w", driver="GTiff", width=cols, height=rows, count=1, dtype="float32",
                       crs="EPSG:32618", transform=from_origin(500000.0, 5000000.0 + rows * dx, dx, dx)) as ds:
        ds.write(np.asarray(grid.z, dtype=np.float32)[::-1], 1)


def _read_mask(path) -> np.ndarray:
    """A peer's 0/1 raster in our row order (south up)."""
    import rasterio

    with rasterio.open(path) as ds:
        return ds.read(1)[::-1] == 1


def _run_times(cmd, repeats: int, env=None) -> float:
    """Median wall time of a command (its whole process: start-up, reading, writing)."""
    import subprocess

    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def _observers_high_low(g):
    """The highest and the lowest sample of the grid's central half (rows, cols)."""
    rows, cols = g.shape
    r0, c0 = rows // 4, cols // 4
    sub = g.z[r0 : rows - r0, c0 : cols - c0]
    hi = np.unravel_index(int(np.nanargmax(sub)), sub.shape)
    lo = np.unravel_index(int(np.nanargmin(sub)), sub.shape)
    return {"high": (hi[0] + r0, hi[1] + c0), "low": (lo[0] + r0, lo[1] + c0)}


def _differences(name, peer, ours, n_cells) -> dict:
    differ = peer != ours
    nd = int(differ.sum())
    near1 = int((differ & verdict_edges(ours)).sum())
    print(f"    {name}: {nd:,} cells differ ({100 * nd / n_cells:.3f} %): {name} visible / ours hidden "
          f"{int((peer & ~ours).sum()):,}, {name} hidden / ours visible {int((~peer & ours).sum()):,}; "
          f"{100 * near1 / max(nd, 1):.1f} % of them within one cell of a visibility edge of ours")
    return {"diff": nd, "share": nd / n_cells, "near": near1 / max(nd, 1)}


def peers(args) -> None:
    """Ours against gdal_viewshed and r.viewshed on the same GeoTIFF, observers, heights,
    curvature off and on (see the module docstring, 'GIS peers')."""
    import os
    import shutil
    import subprocess
    import tempfile

    from terrainvis.io import load_dem

    gdal = shutil.which("gdal_viewshed")
    grass = shutil.which("grass") if not args.no_grass else None
    if gdal is None:
        print("gdal_viewshed not found (Debian: apt-get install gdal-bin): ours alone")
    if grass is None and not args.no_grass:
        print("grass not found (Debian: apt-get install grass-core): no r.viewshed")
    tmp = tempfile.mkdtemp(prefix="bench_viewshed_")
    dem = os.path.join(tmp, "dem.tif")
    n = args.peer_size
    _write_geotiff(synthetic_terrain(args.kind, n), dem)
    g = load_dem(dem)
    eye = args.eye
    print(f"=== {args.kind} {n} x {n}, 30 m cells, float32 GeoTIFF (EPSG:32618) loaded back; eye {eye} m, "
          f"targets on the ground; medians of {args.repeats} runs (r.viewshed: {args.grass_repeats})")
    small = synthetic_terrain(args.kind, 64)
    for c in (0.0, STD_CURVATURE):
        _viewshed(small, (small.xs[32], small.ys[32]), observer_height=eye, curvature=c)
    _viewshed(g, (g.xs[1], g.ys[1]), observer_height=eye)  # per-grid caches, as for any repeated use
    genv = None
    if grass:
        genv = dict(os.environ, GRASS_MESSAGE_FORMAT="silent")
        loc = os.path.join(tmp, "grass", "loc")
        subprocess.run([grass, "-c", dem, loc, "-e"], check=True, capture_output=True, env=genv)
        gx = [grass, os.path.join(loc, "PERMANENT"), "--exec"]
        subprocess.run(gx + ["r.in.gdal", "input=" + dem, "output=dem", "--quiet"], check=True,
                       capture_output=True, env=genv)
        subprocess.run(gx + ["g.region", "raster=dem"], check=True, capture_output=True, env=genv)
    rows = []
    for oname, (r, c) in _observers_high_low(g).items():
        x, y = float(g.xs[c]), float(g.ys[r])
        for curv in (0.0, STD_CURVATURE):
            label = f"{oname} observer (sample {r}, {c}; x {x:.0f} y {y:.0f}, ground {g.z[r, c]:.1f} m), " \
                    f"curvature {curv:g}"
            t_ours, (ours, info) = _time(lambda: _viewshed(g, (x, y), observer_height=eye, curvature=curv),
                                         args.repeats)
            print(f"\n{label}\n  ours           {t_ours:7.3f} s  visible {100 * ours.mean():.3f} %  "
                  f"(lower bound {info['lb']:,}, upper bound + last ring {info['ub']:,} (last ring bounded "
                  f"{info['ub_bound']:,}), block walks {info['walk']:,}, pair engine {info['exact']:,})")
            row = {"observer": oname, "curvature": curv, "ours": t_ours, "visible": ours.mean()}
            if gdal:
                out = os.path.join(tmp, "gdal.tif")
                cmd = [gdal, "-q", "-ox", repr(x), "-oy", repr(y), "-oz", repr(eye), "-tz", "0",
                       "-cc", repr(curv), "-vv", "1", "-iv", "0", dem, out]
                t_g = _run_times(cmd, args.repeats)
                peer = _read_mask(out)
                print(f"  gdal_viewshed  {t_g:7.3f} s  (whole command)  ratio GDAL / ours {t_g / t_ours:5.2f}")
                row.update(gdal=t_g, gdal_ratio=t_g / t_ours, **{"gdal_" + k: v for k, v in
                                                                  _differences("GDAL", peer, ours, g.z.size).items()})
            if grass:
                flags = ["-b"] + (["-c", "-r", "refraction_coeff=0.14286"] if curv else [])
                cmd = gx + ["r.viewshed", "input=dem", "output=vs", f"coordinates={x!r},{y!r}",
                            f"observer_elevation={eye!r}", "target_elevation=0", "memory=4000",
                            "--overwrite", "--quiet"] + flags
                t_r = _run_times(cmd, args.grass_repeats, env=genv)
                out = os.path.join(tmp, "grass.tif")
                subprocess.run(gx + ["r.out.gdal", "input=vs", "output=" + out, "type=Byte", "--overwrite",
                                     "--quiet", "-f"], check=True, capture_output=True, env=genv)
                peer = _read_mask(out)
                print(f"  r.viewshed     {t_r:7.3f} s  (whole command)  ratio GRASS / ours {t_r / t_ours:5.2f}")
                row.update(grass=t_r, grass_ratio=t_r / t_ours, **{"grass_" + k: v for k, v in
                                                                    _differences("r.viewshed", peer, ours,
                                                                                 g.z.size).items()})
            rows.append(row)
    if gdal and not args.no_commands:
        # command to command (curvature off: `terrainvis viewshed` has no curvature option yet)
        print("\ncommand to command (whole processes: start-up, reading the GeoTIFF, writing the mask), "
              "curvature off")
        tv = shutil.which("terrainvis") or os.path.join(os.path.dirname(os.path.abspath(__import__("sys").executable)),
                                                        "terrainvis")
        for oname, (r, c) in _observers_high_low(g).items():
            x, y = float(g.xs[c]), float(g.ys[r])
            ours_cmd = [tv, "viewshed", dem, "--observer", repr(x), repr(y), "--height", repr(eye),
                        "-o", os.path.join(tmp, "ours.tif")]
            gdal_cmd = [gdal, "-q", "-ox", repr(x), "-oy", repr(y), "-oz", repr(eye), "-tz", "0", "-cc", "0",
                        dem, os.path.join(tmp, "gdal_cmd.tif")]
            subprocess.run(ours_cmd, check=True, capture_output=True)  # warm the numba cache
            t_o = _run_times(ours_cmd, args.repeats)
            t_g = _run_times(gdal_cmd, args.repeats)
            print(f"  {oname}: terrainvis viewshed {t_o:6.3f} s, gdal_viewshed {t_g:6.3f} s, "
                  f"ratio GDAL / ours {t_g / t_o:5.2f}")
    print(f"\nsummary ({args.kind} {n}^2, eye {eye} m; medians; ratios = peer / ours)")
    heads = ("observer", "curv", "ours s", "GDAL s", "GDAL x", "GDAL diff %", "near %", "GRASS s", "GRASS x",
             "GRASS diff %", "near %")
    print(" ".join(f"{h:>12}" for h in heads))
    nan = float("nan")
    for rw in rows:
        vals = (rw["observer"], f"{rw['curvature']:g}", f"{rw['ours']:.3f}", f"{rw.get('gdal', nan):.3f}",
                f"{rw.get('gdal_ratio', nan):.2f}", f"{100 * rw.get('gdal_share', nan):.3f}",
                f"{100 * rw.get('gdal_near', nan):.1f}", f"{rw.get('grass', nan):.3f}",
                f"{rw.get('grass_ratio', nan):.2f}", f"{100 * rw.get('grass_share', nan):.3f}",
                f"{100 * rw.get('grass_near', nan):.1f}")
        print(" ".join(f"{v:>12}" for v in vals))
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
