"""Seconds per level of visopt against GLS (its start) in the same run, on synthetic terrains.

    python benchmarks/visopt_cost.py SIZE LEVEL [LEVEL ...]

Prints, per level, the median of ``--repeats`` (default 1) simplifications of each method,
their ratio, and visopt's kept pairs and breakpoints. Timings are noisy on a shared machine:
compare the two methods of one run.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import simplifiers
from simplifiers.visopt import optimize
from terrainvis import synthetic_terrain


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("size", type=int)
    ap.add_argument("levels", type=int, nargs="+")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--kind", default="mountains")
    a = ap.parse_args()
    T = synthetic_terrain(a.kind, size=a.size, seed=11)
    simplifiers.simplify(synthetic_terrain("hills", size=33), "visopt", 1, n_train=20)  # compile
    for level in a.levels:
        tg, tv_ = [], []
        for _ in range(a.repeats):
            t = time.perf_counter()
            simplifiers.simplify(T, "gls", level)
            tg.append(time.perf_counter() - t)
            t = time.perf_counter()
            S, info = optimize(T, level)
            tv_.append(time.perf_counter() - t)
        g, v = float(np.median(tg)), float(np.median(tv_))
        print(f"{a.kind} {a.size}x{a.size} level {level} ({S.shape[0]}x{S.shape[1]}): gls {g:.3f} s, visopt {v:.1f} s "
              f"(x{v / g:.0f}); pairs kept {info['pairs_kept']:,} of {info['pairs']:,}, "
              f"breakpoints {info['breakpoints']:,}", flush=True)


if __name__ == "__main__":
    main()
