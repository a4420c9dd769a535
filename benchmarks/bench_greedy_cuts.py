"""Greedy cuts: terrainvis (numba advancing front + ε search) against greedy insertion and pydelatin.

Run:  python benchmarks/bench_greedy_cuts.py [--repeats 3] [--kinds hills mountains ...] [--big-size 1024]
      [--big-kinds mountains rough] [--no-big] [--scale-repeats 3] [--no-scale] [--only-scale]

Part 1, 120x120: for each bundled terrain, ``build`` at levels 1, 2, 3 (budgets 3,600, 900
and 225 vertices, including the whole search on ε), ``repeats`` times; it prints the
median seconds per level and for the three levels together (target <= 5 s), the runs
(triangulations) the search needed, the ε reached (= our guaranteed max error) and the
measured max error, and pydelatin (greedy insertion, C++) at the same vertex count: its
median seconds and its max error. Part 2: level 2 of a ``--big-size`` synthetic terrain
(budget (size/4)^2 = 65,536 for 1024; target <= 60 s), once, with the same columns.

Part 3, the scale target (greedy cuts within 5x greedy insertion's time at the same
budget): ``simplify(grid, "greedy-cuts", level)`` and ``simplify(grid,
"greedy-insertion", level)`` at levels 1-3, alternately ``--scale-repeats`` times, on a
1024x1024 ``mountains`` tile (30 m cells, seed 0), on ``mount_st_helens_wa`` (its
NaN-free ``valid_window()``, 460x317) and on ``jacksboro_fault_tn`` (344x403) from
``../shared/data/dem`` (skipped when absent). It prints, per input and level, the median
wall seconds of each method (the registry's ``seconds``: the simplification alone), the
ratio of the medians, the median process-CPU seconds of the simplification (the call's
CPU time less that of the error measurement ``simplify`` adds) and their ratio (steadier
on a shared machine), the runs of the ε search and the stage that landed (``bracket``,
``mixed``, ``probe``), and both methods' vertex counts and max errors.

Greedy cuts is not expected to beat greedy insertion on max error at a fixed count: it
guarantees ε by construction but grows the front greedily from the boundary, while
greedy insertion always fixes the worst sample. The comparison shows the price. Timings
on a shared machine are noisy: medians, and ratios measured in the same run.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np

from simplifiers import simplify, vertex_budget
from simplifiers.greedy_cuts import build, greedy_cuts
from terrainvis import TIN, HeightGrid, bundled_terrain, load_dem, synthetic_terrain
from terrainvis.core.deviation import vertical_errors
from terrainvis.core.synthetic import KINDS

SHARED_DEM = Path(__file__).resolve().parents[2] / "shared" / "data" / "dem"


def pydelatin_max_error(z: np.ndarray, n: int) -> tuple[float, float]:
    """Seconds and max vertical error of pydelatin's TIN with ``n`` vertices on the unit grid of ``z``."""
    import pydelatin

    t0 = time.perf_counter()
    d = pydelatin.Delatin(np.ascontiguousarray(z), max_error=0.0, max_points=int(n))
    seconds = time.perf_counter() - t0
    xy = np.rint(d.vertices[:, :2]).astype(np.int64)
    c, r = xy[:, 0], z.shape[0] - 1 - xy[:, 1]  # pydelatin's y is H - 1 - row
    v = np.column_stack([c, r, z[r, c]]).astype(np.float64)
    f = d.triangles.astype(np.int64)
    e = v[f]
    nz = (e[:, 1, 0] - e[:, 0, 0]) * (e[:, 2, 1] - e[:, 0, 1]) - (e[:, 2, 0] - e[:, 0, 0]) * (e[:, 1, 1] - e[:, 0, 1])
    tin = TIN(v, np.where((nz < 0)[:, None], f[:, ::-1], f))
    return seconds, vertical_errors(HeightGrid(z), tin)[0]


def one(grid: HeightGrid, budget: int):
    t0 = time.perf_counter()
    tin = build(grid, budget)
    return time.perf_counter() - t0, tin


def small_terrains(args) -> None:
    print(f"greedy cuts, 120x120 bundled terrains, levels 1-3, median of {args.repeats} runs each")
    head = (
        f"{'terrain':<10} {'lvl':>3} {'budget':>6} {'verts':>6} {'runs':>4} {'ours s':>7} "
        f"{'eps':>9} {'max err':>9} {'delatin s':>9} {'delatin err':>11} {'err ratio':>9}"
    )
    print(head)
    totals = []
    for kind in args.kinds:
        grid = bundled_terrain(kind)
        per_level = []
        for level in (1, 2, 3):
            budget = vertex_budget(grid.shape, level)
            times, tin = [], None
            for _ in range(args.repeats):
                s, tin = one(grid, budget)
                times.append(s)
            dt = [pydelatin_max_error(grid.z, tin.n_vertices) for _ in range(args.repeats)]
            d_s = statistics.median(t for t, _ in dt)
            d_err = dt[0][1]
            err = vertical_errors(grid, tin)[0]
            per_level.append(times)
            print(
                f"{kind:<10} {level:>3} {budget:>6} {tin.n_vertices:>6} {tin.attrs['runs']:>4} "
                f"{statistics.median(times):>7.3f} {tin.attrs['epsilon']:>9.4g} {err:>9.4g} {d_s:>9.4f} "
                f"{d_err:>11.4g} {err / d_err if d_err else float('nan'):>9.2f}"
            )
        total = [sum(ts) for ts in zip(*per_level)]
        totals.append(statistics.median(total))
        print(f"{kind:<10} all three levels: median {statistics.median(total):.3f} s (target <= 5 s)")
    print(f"worst terrain, all three levels: {max(totals):.3f} s")


def big_terrains(args) -> None:
    size = args.big_size
    for kind in args.big_kinds:
        grid = synthetic_terrain(kind, size=size, seed=0)
        budget = vertex_budget(grid.shape, 2)
        s, tin = one(grid, budget)
        err = vertical_errors(grid, tin)[0]
        d_s, d_err = pydelatin_max_error(grid.z, tin.n_vertices)
        print(
            f"{kind} {size}x{size} level 2: budget {budget}, {tin.n_vertices} vertices, {tin.attrs['runs']} runs, "
            f"{s:.2f} s (target <= 60 s), eps {tin.attrs['epsilon']:.4g}, max err {err:.4g}; "
            f"pydelatin {d_s:.3f} s, max err {d_err:.4g} (ratio ours/pydelatin: time {s / d_s:.1f}, "
            f"error {err / d_err:.2f})"
        )


def scale_inputs() -> list[tuple[str, HeightGrid]]:
    """The inputs of the scale target: a 1024^2 synthetic tile and two real DEMs at full size."""
    out = [("mountains 1024^2", synthetic_terrain("mountains", 1024, seed=0))]
    helens, jacksboro = SHARED_DEM / "mount_st_helens_wa.npz", SHARED_DEM / "jacksboro_fault_tn.npz"
    if helens.exists():
        g = load_dem(helens)
        rows, cols = g.valid_window()
        out.append(("st_helens valid window", g.crop(rows, cols)))
    else:
        print(f"(skipping mount_st_helens_wa: {helens} is absent)")
    if jacksboro.exists():
        out.append(("jacksboro_fault_tn", load_dem(jacksboro)))
    else:
        print(f"(skipping jacksboro_fault_tn: {jacksboro} is absent)")
    return out


def timed(grid: HeightGrid, method: str, level: int):
    """The TIN, its registry seconds (the simplification alone) and its process CPU seconds.

    ``simplify`` also measures the TIN's vertical errors; their CPU time, measured again
    right after, is taken off the call's.
    """
    c0 = time.process_time()
    tin = simplify(grid, method, level)
    c1 = time.process_time()
    vertical_errors(grid, tin)
    c2 = time.process_time()
    return tin, tin.attrs["seconds"], max((c1 - c0) - (c2 - c1), 0.0)


def scale(args) -> None:
    print(
        f"\ngreedy cuts (gc) against greedy insertion (gi) at the same budget, levels 1-3, alternately "
        f"{args.scale_repeats} times; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores "
        f"(target: gc <= 5 x gi)"
    )
    head = (
        f"{'input':<24} {'lvl':>3} {'budget':>7} {'gc s':>7} {'gi s':>7} {'ratio':>6} {'gc cpu':>7} {'gi cpu':>7} "
        f"{'ratio':>6} {'runs':>4} {'stage':>7} {'gc verts':>8} {'gi verts':>8} {'gc maxerr':>9} {'gi maxerr':>9}"
    )
    print(head)
    for name, grid in scale_inputs():
        simplify(grid.crop(rows=(0, 20), cols=(0, 20)), "greedy-cuts", 1)  # load the numba caches
        simplify(grid.crop(rows=(0, 20), cols=(0, 20)), "greedy-insertion", 1)
        for level in (1, 2, 3):
            gc_wall, gc_cpu, gi_wall, gi_cpu = [], [], [], []
            for _ in range(args.scale_repeats):
                gc_tin, w, c = timed(grid, "greedy-cuts", level)
                gc_wall.append(w)
                gc_cpu.append(c)
                gi_tin, w, c = timed(grid, "greedy-insertion", level)
                gi_wall.append(w)
                gi_cpu.append(c)
            a, b = gc_tin.attrs, gi_tin.attrs
            mw, mwi = statistics.median(gc_wall), statistics.median(gi_wall)
            mc, mci = statistics.median(gc_cpu), statistics.median(gi_cpu)
            print(
                f"{name:<24} {level:>3} {a['budget']:>7} {mw:>7.2f} {mwi:>7.2f} {mw / mwi:>6.2f} {mc:>7.2f} "
                f"{mci:>7.2f} {mc / mci:>6.2f} {a['runs']:>4} {a.get('search_stage', '-'):>7} "
                f"{gc_tin.n_vertices:>8} {gi_tin.n_vertices:>8} {a['max_error']:>9.4g} {b['max_error']:>9.4g}"
            )


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--kinds", nargs="+", default=list(KINDS))
    ap.add_argument("--big-size", type=int, default=1024)
    ap.add_argument("--big-kinds", nargs="+", default=["mountains", "rough"])
    ap.add_argument("--no-big", action="store_true")
    ap.add_argument("--scale-repeats", type=int, default=3)
    ap.add_argument("--no-scale", action="store_true", help="leave out part 3")
    ap.add_argument("--only-scale", action="store_true", help="run part 3 alone")
    args = ap.parse_args(argv)

    greedy_cuts(HeightGrid(np.random.default_rng(0).normal(size=(9, 9))), 0.5)  # compile / load the numba cache
    if not args.only_scale:
        small_terrains(args)
        if not args.no_big:
            big_terrains(args)
    if not args.no_scale:
        scale(args)


if __name__ == "__main__":
    main()
