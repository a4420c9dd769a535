"""What the calibrated relocation costs, against the visibility matrices it serves.

Two workloads, each timing the relocation and the visibility matrices in the same run:

* ``scale``: N points (default 10,000, 2 m above the ground) relocated onto LLS
  simplifications of a synthetic 3601 x 3601 tile (30 m cells) at the given levels. It
  prints the partners' calibration (once per simplification), the points' relocation,
  their sum against the issue's 60 s, and the ratio to ``visibility_matrix`` of the same
  points on S(T) (N(N-1)/2 pairs) and on T, with the accuracy of full projection and of
  the calibrated relocation against T's verdicts.
* ``default``: the default experiment's work (6 terrains x 7 methods x 3 levels, 6 sets
  of 50 points): per unit, the calibrated relocation (partners once, then every set) and
  the visibility matrices the relocation serves (each set's matrix on T and on S(T)
  once); totals and their ratio, and the accuracies.

    python benchmarks/bench_relocation.py                       # both
    python benchmarks/bench_relocation.py --workloads scale --size 1201 --points 2000
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import simplifiers
import terrainvis as tv
from terrainvis.relocation import calibrated


def _timed(fn, *args, **kwargs):
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t0


def scale(args) -> None:
    T, t_make = _timed(tv.synthetic_terrain, "mountains", size=args.size, seed=0)
    print(f"terrain {T} made in {t_make:.1f} s")
    P = tv.sample_points(T, args.points, seed=0, offset=args.offset)
    warm = tv.synthetic_terrain("hills", size=65, seed=0)
    tv.relocate(tv.sample_points(warm, 5, seed=1), simplifiers.simplify(warm, "lls", 1), "calibrated",
                original=warm, n_partners=16)  # compile outside the timings
    V_T, t_vt = _timed(tv.visibility_matrix, T, P)
    print(f"{args.points:,} points, eye {args.offset} m: visibility_matrix on T {t_vt:.1f} s\n")
    print("| level | S(T) | partners | points | relocation | vs 60 s | matrix on S(T) | relocation / matrix "
          "| accuracy full | accuracy calibrated |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for level in args.levels:
        S = simplifiers.simplify(T, "lls", level)
        _, t_part = _timed(calibrated.partners, T, S, height=args.offset, move=True)
        moved, t_points = _timed(tv.relocate, P, S, "calibrated", original=T, offset=args.offset)
        full = tv.relocate(P, S, "full", offset=args.offset)
        V_S, t_vs = _timed(tv.visibility_matrix, S, moved)
        acc_c = tv.agreement(V_T, V_S)["accuracy"]
        acc_f = tv.agreement(V_T, tv.visibility_matrix(S, full))["accuracy"]
        total = t_part + t_points
        print(f"| {level} | {S.shape[0]}² | {t_part:.1f} s | {t_points:.1f} s | **{total:.1f} s** | "
              f"{total / 60:.2f} | {t_vs:.1f} s | {total / t_vs:.2f} | {100 * acc_f:.3f} | {100 * acc_c:.3f} |",
              flush=True)


def default(args) -> None:
    from terrainvis.experiment import DEFAULT_TERRAINS, point_sets, resolve_terrains

    grids = resolve_terrains(list(DEFAULT_TERRAINS))
    methods = simplifiers.default_methods()  # compare's
    totals = {"relocation": 0.0, "matrices": 0.0}
    acc = {}
    warm = tv.synthetic_terrain("hills", size=65, seed=0)
    for m in ("lls", "qec"):
        tv.relocate(tv.sample_points(warm, 5, seed=1), simplifiers.simplify(warm, m, 1), "calibrated",
                    original=warm, n_partners=16)
    for name, T in grids.items():
        sets = point_sets(T, name, 50, 6, 0, 0.0)
        for method in methods:
            for level in (1, 2, 3):
                S = simplifiers.simplify(T, method, level)
                t_rel = t_mat = 0.0
                for P in sets:
                    V_T, t = _timed(tv.visibility_matrix, T, P)
                    t_mat += t
                    moved, t = _timed(tv.relocate, P, S, "calibrated", original=T)
                    t_rel += t
                    V_S, t = _timed(tv.visibility_matrix, S, moved)
                    t_mat += t
                    acc.setdefault((method, level), []).append(tv.agreement(V_T, V_S)["accuracy"])
                totals["relocation"] += t_rel
                totals["matrices"] += t_mat
        print(f"{name}: relocation {totals['relocation']:.1f} s, matrices {totals['matrices']:.1f} s so far",
              flush=True)
    print(f"\ndefault experiment, calibrated relocation of 6 x 50 points per unit "
          f"({len(grids) * len(methods) * 3} units): "
          f"{totals['relocation']:.1f} s; the visibility matrices it serves (T and S(T), once each): "
          f"{totals['matrices']:.1f} s; ratio {totals['relocation'] / totals['matrices']:.1f}")
    print("\n| method | level 1 | level 2 | level 3 |\n|---|---|---|---|")
    for method in methods:
        cells = " | ".join(f"{100 * np.mean(acc[(method, lv)]):.2f}" for lv in (1, 2, 3))
        print(f"| {method} | {cells} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--workloads", nargs="+", default=["scale", "default"], choices=["scale", "default"])
    ap.add_argument("--size", type=int, default=3601)
    ap.add_argument("--points", type=int, default=10_000)
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 3])
    ap.add_argument("--offset", type=float, default=2.0)
    args = ap.parse_args()
    if "scale" in args.workloads:
        scale(args)
    if "default" in args.workloads:
        default(args)


if __name__ == "__main__":
    main()
