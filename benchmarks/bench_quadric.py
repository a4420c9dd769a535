"""Benchmark: quadric edge collapse with both backends, against the bare library calls.

For each grid size (120², 512², 1024² by default) and level (1-3, the budget being the
regular grid's sample count at that level) it runs ``simplify(grid, "qec", level,
backend=...)`` for the pymeshlab and fast-simplification backends, and as peers the bare
library call on the same full-resolution mesh with the same first face target and the same
settings (what our first decimation pass asks for, without the boundary snapping,
fold-over repair and budget passes). It prints medians over the repeats of the time, the vertex count, the max
and RMS vertical error against the grid, and the ratios pymeshlab / fast-simplification
and ours / bare library. Our time is ``attrs["seconds"]``: the whole build (all passes,
post-processing and our own validity check), without the registry's error metrics.

Run from the repository root::

    /work/venv/bin/python benchmarks/bench_quadric.py
    /work/venv/bin/python benchmarks/bench_quadric.py --sizes 120 512 --repeats 3

The machine may be shared: the repeats are interleaved (pymeshlab, fast, bare pymeshlab,
bare fast, then again) so that a load spike hits every contender alike.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

import simplifiers
from simplifiers import quadric
from simplifiers import vertex_budget
from terrainvis.deviation import vertical_errors
from terrainvis.synthetic import synthetic_terrain

BACKENDS = ("pymeshlab", "fast-simplification")
DEFAULT_REPEATS = {120: 5, 512: 3, 1024: 1}


def _bare(grid, backend, target):
    """The library alone: decimate the full mesh to ``target`` faces; (seconds, vertices, faces)."""
    fine = grid.to_tin()
    origin = np.array([grid.xs[0], grid.ys[0], float(np.mean(grid.z))])
    v = fine.vertices - origin
    f = np.array(fine.faces, dtype=np.int32)
    t0 = time.perf_counter()
    if backend == "pymeshlab":
        import pymeshlab

        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=v, face_matrix=f))
        ms.meshing_decimation_quadric_edge_collapse(
            targetfacenum=target, preserveboundary=False, **quadric.PYMESHLAB_DEFAULTS
        )
        m = ms.current_mesh()
        out_v, out_f = m.vertex_matrix(), m.face_matrix()
    else:
        import fast_simplification

        out_v, out_f = fast_simplification.simplify(v, f, target_count=target, **quadric.FAST_DEFAULTS)
    return time.perf_counter() - t0, out_v + origin, out_f


def _footprint(v, f, grid):
    """(signed projected area / extent area, number of faces folded over in projection)."""
    a, b, c = v[f[:, 0], :2], v[f[:, 1], :2], v[f[:, 2], :2]
    area2 = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    xmin, xmax, ymin, ymax = grid.extent
    return 0.5 * area2.sum() / ((xmax - xmin) * (ymax - ymin)), int((area2 <= 0).sum())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[120, 512, 1024])
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--kind", default="mountains", help="synthetic terrain kind (terrainvis.synthetic.KINDS)")
    ap.add_argument("--repeats", type=int, default=None, help="repeats per case (default 5 / 3 / 1 by size)")
    args = ap.parse_args(argv)

    # warm up numba and the libraries once, outside the timings
    warm = synthetic_terrain(args.kind, size=40)
    for backend in BACKENDS:
        simplifiers.simplify(warm, "qec", 1, backend=backend)

    header = (
        f"{'size':>5} {'lvl':>3} {'budget':>7} {'contender':<26} {'median s':>9} {'vertices':>9} "
        f"{'max err':>8} {'rms err':>8} {'footprint':>9} {'folds':>5}"
    )
    ratios = []
    for size in args.sizes:
        grid = synthetic_terrain(args.kind, size=size)
        repeats = args.repeats or DEFAULT_REPEATS.get(size, 1)
        print(f"\n{args.kind} {size}x{size}, {repeats} repeat(s)")
        print(header)
        for level in args.levels:
            budget = vertex_budget(grid.shape, level)
            target = 2 * budget - 2 - int(math.sqrt(budget))  # our first pass's face target
            times = {k: [] for k in ("pymeshlab", "fast-simplification", "bare pymeshlab", "bare fast-simplification")}
            rows = {}
            for _ in range(repeats):
                for backend in BACKENDS:
                    tin = simplifiers.simplify(grid, "qec", level, backend=backend)
                    times[backend].append(tin.attrs["seconds"])  # the build alone, as for the bare calls
                    m = tin.attrs
                    share, folds = _footprint(tin.vertices, tin.faces, grid)
                    rows[backend] = (tin.n_vertices, m["max_error"], m["rms_error"], share, folds,
                                     f"stages={m['stages']} repairs={m['repairs']} collapses={m['collapses']}")
                for backend in BACKENDS:
                    seconds, v, f = _bare(grid, backend, target)
                    times["bare " + backend].append(seconds)
                    share, folds = _footprint(v, f, grid)
                    try:
                        from terrainvis import TIN

                        emax, erms = vertical_errors(grid, TIN(v, f))
                    except ValueError:  # the bare mesh does not cover the grid
                        emax = erms = float("nan")
                    rows["bare " + backend] = (v.shape[0], emax, erms, share, folds, "")
            med = {k: statistics.median(t) for k, t in times.items()}
            for name in ("pymeshlab", "fast-simplification", "bare pymeshlab", "bare fast-simplification"):
                nv, emax, erms, share, folds, note = rows[name]
                print(
                    f"{size:>5} {level:>3} {budget:>7} {name:<26} {med[name]:>9.3f} {nv:>9} "
                    f"{emax:>8.2f} {erms:>8.3f} {share:>9.4%} {folds:>5}  {note}"
                )
            ratios.append((size, level, med["pymeshlab"] / med["fast-simplification"],
                           med["pymeshlab"] / med["bare pymeshlab"],
                           med["fast-simplification"] / med["bare fast-simplification"]))
    print("\nratios of median times")
    print(f"{'size':>5} {'lvl':>3} {'pymeshlab/fast':>15} {'ours/bare (pymeshlab)':>22} {'ours/bare (fast)':>17}")
    for size, level, r_backends, r_pm, r_fs in ratios:
        print(f"{size:>5} {level:>3} {r_backends:>15.2f} {r_pm:>22.2f} {r_fs:>17.2f}")
    print("\n'bare' = one library call with our first pass's face target and our settings, without the "
          "post-processing. footprint = signed projected area / extent area; folds = faces with a "
          "non-positive projected area; errors are NaN when the mesh leaves grid samples uncovered.")


if __name__ == "__main__":
    main()
