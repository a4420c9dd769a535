"""Benchmark: the grid LOS engine against Embree on the same pairs, in one run.

For each size, an fBm-like synthetic terrain (spectral synthesis, 30 m cells, about
600 m of relief) and ``--pairs`` random pairs (half spanning the whole map, half at
most 100 cells long; both ends 1 m above the surface) are built. The script prints

* build times: the grid engine's min/max pyramid, Embree's scene (buffer fill plus the
  BVH build, which embreex defers to the first query);
* memory: the pyramid's bytes (and tracemalloc peak of its build) against the height
  array; the resident-set growth of the Embree scene;
* median pairs per second over ``--repeats`` runs for both engines and their ratio,
  and how many answers differ (and how many of those are outside the float32 band);
* optionally (``--matrix N``) ``visibility_matrix`` of N points on the largest size.

Example::

    python benchmarks/bench_visibility.py --sizes 1024 3601 --pairs 1000000 --matrix 10000
    python benchmarks/bench_visibility.py --sizes 512 --pairs 100000       # quick
"""

from __future__ import annotations

import argparse
import gc
import statistics
import time
import tracemalloc

import numpy as np

from terrainvis import HeightGrid
from terrainvis.visibility import (
    clearance_tolerance,
    embree_tolerance,
    line_of_sight,
    min_clearance,
    visibility_matrix,
)
from terrainvis.visibility.embree import embree_scene
from terrainvis.visibility.grid import grid_accel


def rss_bytes() -> int:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    return 0


def fbm_terrain(size: int, *, seed: int = 0, cell: float = 30.0, relief: float = 600.0, beta: float = 3.2) -> HeightGrid:
    """Spectral-synthesis fBm: power spectrum ~ f**-beta, scaled to ``relief`` metres."""
    rng = np.random.default_rng(seed)
    fy = np.fft.fftfreq(size)[:, None]
    fx = np.fft.rfftfreq(size)[None, :]
    f = np.sqrt(fx * fx + fy * fy)
    f[0, 0] = 1.0
    amp = f ** (-beta / 2.0)
    amp[0, 0] = 0.0
    spec = amp * (rng.standard_normal(amp.shape) + 1j * rng.standard_normal(amp.shape))
    z = np.fft.irfft2(spec, s=(size, size))
    z = (z - z.min()) / (z.max() - z.min()) * relief + 500.0
    return HeightGrid(z, dx=cell, dy=cell, origin=(500000.0, 4_000_000.0))


def random_pairs(grid: HeightGrid, n: int, *, seed: int = 1, offset: float = 1.0):
    """Half whole-map pairs, half pairs at most 100 cells long, ``offset`` above the surface."""
    rng = np.random.default_rng(seed)
    xmin, xmax, ymin, ymax = grid.extent
    lo = np.array([xmin, ymin])
    hi = np.array([xmax, ymax])
    a = lo + rng.random((n, 2)) * (hi - lo)
    b = lo + rng.random((n, 2)) * (hi - lo)
    short = np.arange(n) >= n // 2
    k = int(short.sum())
    ang = rng.random(k) * 2 * np.pi
    length = rng.random(k) * 100.0 * grid.dx
    b[short] = np.clip(a[short] + np.column_stack([np.cos(ang), np.sin(ang)]) * length[:, None], lo, hi)
    za = grid.height_at(a) + offset
    zb = grid.height_at(b) + offset
    return np.column_stack([a, za]), np.column_stack([b, zb])


def median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def bench_size(size: int, n_pairs: int, repeats: int, embree: bool):
    print(f"\n=== {size} x {size} grid, {n_pairs:,} pairs ===")
    grid = fbm_terrain(size)
    print(f"terrain: z [{grid.z.min():.0f}, {grid.z.max():.0f}] m, height array {grid.z.nbytes / 2**20:.1f} MiB")
    a, b = random_pairs(grid, n_pairs)

    # warm up numba (compilation or cache load) on a tiny grid
    small = fbm_terrain(16)
    sa, sb = random_pairs(small, 10)
    line_of_sight(small, sa, sb, engine="grid")

    gc.collect()
    tracemalloc.start()
    t = time.perf_counter()
    acc = grid_accel(grid)
    t_pyr = time.perf_counter() - t
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    print(
        f"grid pyramid: build {t_pyr:.3f} s, {acc.nbytes / 2**20:.1f} MiB = {acc.nbytes / grid.z.nbytes:.2f} x height array "
        f"(tracemalloc peak during build {peak / 2**20:.1f} MiB = {peak / grid.z.nbytes:.2f} x)"
    )

    t_grid = median_time(lambda: line_of_sight(grid, a, b, engine="grid"), repeats)
    vis_grid = line_of_sight(grid, a, b, engine="grid")
    print(f"grid engine : median {t_grid:.3f} s -> {n_pairs / t_grid:,.0f} pairs/s (visible {vis_grid.mean():.3f})")

    t_min = median_time(lambda: min_clearance(grid, a[: n_pairs // 10], b[: n_pairs // 10]), repeats)
    print(f"min_clearance (exact, {n_pairs // 10:,} pairs): median {t_min:.3f} s -> {n_pairs // 10 / t_min:,.0f} pairs/s")

    if not embree:
        return grid, None
    gc.collect()
    rss0 = rss_bytes()
    t = time.perf_counter()
    tin = grid.to_tin()
    t_tin = time.perf_counter() - t
    rss1 = rss_bytes()
    t = time.perf_counter()
    sc = embree_scene(tin)
    t_fill = time.perf_counter() - t
    t = time.perf_counter()
    line_of_sight(grid, a[:1], b[:1], engine="embree")  # the first query builds the BVH
    t_bvh = time.perf_counter() - t
    rss2 = rss_bytes()
    print(
        f"embree scene: to_tin {t_tin:.2f} s (+{(rss1 - rss0) / 2**20:.0f} MiB), buffer fill {t_fill:.2f} s "
        f"(embreex's own {sc.build_seconds:.2f} s), BVH on first query {t_bvh:.2f} s; "
        f"RSS growth of the scene {(rss2 - rss1) / 2**20:.0f} MiB = {(rss2 - rss1) / sc.n_faces:.0f} B/triangle "
        f"= {(rss2 - rss1) / grid.z.nbytes:.1f} x height array"
    )
    t_emb = median_time(lambda: line_of_sight(grid, a, b, engine="embree"), repeats)
    vis_emb = line_of_sight(grid, a, b, engine="embree")
    print(f"embree      : median {t_emb:.3f} s -> {n_pairs / t_emb:,.0f} pairs/s (3 rays per pair)")
    print(f"RATIO grid / embree throughput: {t_emb / t_grid:.2f} x")
    diff = np.flatnonzero(vis_grid != vis_emb)
    if diff.size:
        m = min_clearance(grid, a[diff], b[diff])
        outside = int((np.abs(m) > embree_tolerance(grid)).sum())
    else:
        outside = 0
    print(
        f"answers differing: {diff.size} of {n_pairs:,}; outside the float32 band "
        f"(|min clearance| > {embree_tolerance(grid):.2e} m): {outside}; tol {clearance_tolerance(grid):.1e} m"
    )
    del sc
    tin._cache.clear()
    grid._cache.pop("tin", None)
    del tin
    gc.collect()
    return grid, (t_grid, t_emb)


def bench_matrix(grid: HeightGrid, n: int, repeats: int):
    rng = np.random.default_rng(7)
    xmin, xmax, ymin, ymax = grid.extent
    xy = np.column_stack([xmin + rng.random(n) * (xmax - xmin), ymin + rng.random(n) * (ymax - ymin)])
    pts = np.column_stack([xy, grid.height_at(xy) + 1.0])
    visibility_matrix(grid, pts[:50])  # warm-up
    t = median_time(lambda: visibility_matrix(grid, pts), repeats)
    vm = visibility_matrix(grid, pts)
    pairs = n * (n - 1) // 2
    print(
        f"\nvisibility_matrix: {n:,} points on {grid.shape[0]}x{grid.shape[1]} ({pairs:,} pairs): median {t:.1f} s "
        f"-> {pairs / t:,.0f} pairs/s; visible fraction {vm.mean():.3f}; symmetric {bool((vm == vm.T).all())}"
    )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[1024, 3601])
    ap.add_argument("--pairs", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--matrix", type=int, default=10_000, help="points for visibility_matrix on the largest size (0: skip)")
    ap.add_argument("--matrix-repeats", type=int, default=1)
    ap.add_argument("--no-embree", action="store_true")
    args = ap.parse_args(argv)
    import numba

    print(f"numba threads: {numba.get_num_threads()}")
    grid = None
    for size in args.sizes:
        grid, _ = bench_size(size, args.pairs, args.repeats, not args.no_embree)
    if args.matrix and grid is not None:
        bench_matrix(grid, args.matrix, args.matrix_repeats)


if __name__ == "__main__":
    main()
