"""The paper's motivating claim at SRTM scale: what does reverse subdivision buy for LOS?

``visibility_matrix`` of N observers (default 10,000: 50 M pairs) on a synthetic
3601 x 3601 grid (one SRTM 1-arc-second tile, 30 m cells), at full resolution and after
LLS levels 1 to 3, with the observers moved onto each simplification ("full"
relocation, 2 m eye height). For each level it prints the grid's bytes, the pyramid's
bytes, the time to build the pyramid, the median time of the matrix, pairs per second,
the peak memory traced during the call (numpy allocations, via tracemalloc), and the
accuracy against the full-resolution verdicts. The peer is the full-resolution run in
the same process; ratios are against it.

    python benchmarks/bench_srtm.py                  # 3601², 10,000 points, 3 repeats
    python benchmarks/bench_srtm.py --size 1201 --points 2000 --repeats 1   # a quick look
"""

from __future__ import annotations

import argparse
import time
import tracemalloc

import numpy as np

import terrainvis as tv
from simplifiers import simplify


def _pyramid_bytes(grid) -> int:
    total = 0
    for key, value in grid._cache.items():
        if key == "tin":
            continue
        arrays = value if isinstance(value, (tuple, list)) else getattr(value, "__dict__", {}).values()
        for a in arrays:
            if isinstance(a, np.ndarray):
                total += a.nbytes
    return total


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=3601)
    ap.add_argument("--points", type=int, default=10_000)
    ap.add_argument("--levels", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--offset", type=float, default=2.0)
    args = ap.parse_args()

    t0 = time.perf_counter()
    T = tv.synthetic_terrain("mountains", size=args.size, seed=0)
    print(f"terrain {T} made in {time.perf_counter() - t0:.1f} s")
    P = tv.sample_points(T, args.points, seed=0, offset=args.offset)
    n_pairs = args.points * (args.points - 1) // 2
    print(f"{args.points} observers, {n_pairs:,} pairs, eye height {args.offset} m\n")

    tv.visibility_matrix(tv.synthetic_terrain("hills", size=33), P[:2] * 0 + [[1, 1, 300], [5, 5, 300]])  # compile
    rows = []
    V0 = None
    for level in args.levels:
        t0 = time.perf_counter()
        S = simplify(T, "lls", level) if level else T
        t_simplify = time.perf_counter() - t0
        Q = tv.relocate(P, S, "full", offset=args.offset) if level else P
        t0 = time.perf_counter()
        tv.visibility_matrix(S, Q[:2])  # builds and caches the pyramid
        t_build = time.perf_counter() - t0
        times = []
        peak = 0
        V = None
        for _ in range(args.repeats):
            tracemalloc.start()
            t0 = time.perf_counter()
            V = tv.visibility_matrix(S, Q)
            times.append(time.perf_counter() - t0)
            peak = max(peak, tracemalloc.get_traced_memory()[1])
            tracemalloc.stop()
        if V0 is None:
            V0 = V
        acc = tv.agreement(V0, V)["accuracy"]
        rows.append((level, S.shape, S.nbytes, _pyramid_bytes(S), t_simplify, t_build, float(np.median(times)), peak, acc))

    base = rows[0][6]
    print(f"{'level':>5} {'grid':>11} {'grid MB':>8} {'pyr MB':>7} {'simplify s':>10} {'build s':>8} "
          f"{'matrix s':>9} {'Mpairs/s':>9} {'speedup':>8} {'peak MB':>8} {'accuracy':>9}")
    for level, shape, nbytes, pyr, t_s, t_b, t_m, peak, acc in rows:
        print(f"{level:5d} {shape[0]:5d}x{shape[1]:<5d} {nbytes / 1e6:8.1f} {pyr / 1e6:7.1f} {t_s:10.2f} {t_b:8.2f} "
              f"{t_m:9.2f} {n_pairs / t_m / 1e6:9.2f} {base / t_m:8.2f} {peak / 1e6:8.1f} {100 * acc:8.2f}%")


if __name__ == "__main__":
    main()
