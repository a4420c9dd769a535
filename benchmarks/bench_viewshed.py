"""Benchmark: exact viewsheds against xarray-spatial's viewshed and the pair engine, in one run.

For each size, ``synthetic_terrain(--kind, size)`` (30 m cells) is built and an observer
stands on the sample nearest the centre, ``--observer-height`` above it (xarray-spatial
snaps its observer to a cell, so both programs answer the same question from the same
eye). The script prints, per size, the median over ``--repeats`` runs of

* ours: :func:`terrainvis.visibility.sweep.viewshed` (grid engine, exact), with how
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

Example::

    python benchmarks/bench_viewshed.py                                  # 1024, 2048, 3601
    python benchmarks/bench_viewshed.py --sizes 512 1024 --repeats 1     # quick
    python benchmarks/bench_viewshed.py --sizes 3601 --no-xrspatial      # ours vs the pair engine
    python benchmarks/bench_viewshed.py --sizes 1024 --kind noisy-plane  # a grazing worst case
"""

from __future__ import annotations

import argparse
import gc
import statistics
import time

import numpy as np

from terrainvis.synthetic import synthetic_terrain
from terrainvis.visibility import clearance_tolerance, trim_length
from terrainvis.visibility.grid import grid_accel, grid_clearance
from terrainvis.visibility.sweep import _viewshed


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


def _near_edge(vis: np.ndarray) -> np.ndarray:
    """Samples with a sample of the other verdict among their 8 neighbours."""
    p = np.pad(vis, 1, mode="edge")
    rows, cols = vis.shape
    edge = np.zeros(vis.shape, dtype=bool)
    for dr in (0, 1, 2):
        for dc in (0, 1, 2):
            edge |= p[dr : dr + rows, dc : dc + cols] != vis
    return edge


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
    args = ap.parse_args(argv)
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
              f"({100 * swept / info['targets']:.2f} %: lower bound {info['lb']:,}, upper bound + last-ring "
              f"walk {info['ub']:,}, walks of the blocks above the bound {info['walk']:,}); "
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
            near = int((differ & _near_edge(ours)).sum())
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


if __name__ == "__main__":
    main()
