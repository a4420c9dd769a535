"""Greedy cuts on terrains it was not tuned on: how often a budget search fails, and how.

Two workloads, each run at levels 1-3 with ``simplifiers.simplify(grid, "greedy-cuts", level)``:

* ``faber``: the S(T) grids of the regular methods (simple, LLS, GLS, feature; levels 1 and 2)
  of the five bundled terrains and the four shared DEMs' 120 x 120 crops: rectilinear grids,
  their last step longer than the others;
* ``crops``: random windows of the four shared DEMs (``--sides``, ``--seeds``: three per DEM
  and seed).

Each failure is counted by kind ("stuck": the advancing front found no valid triangle;
"search": no ε gave the budget within 1 %; or the exception's type) and listed::

    python benchmarks/greedy_cuts_robustness.py                 # both workloads
    python benchmarks/greedy_cuts_robustness.py --workloads crops --sides 64 120 200 --seeds 0 1 2 3 4

The DEMs are read where they are (``../shared/data/dem``, or ``TERRAINVIS_SHARED_DEMS``).
"""

from __future__ import annotations

import argparse
import collections
import os
import time
from pathlib import Path

import numpy as np

import simplifiers
import terrainvis as tv

BUNDLED = ("hills", "mountains", "mesas", "ridges", "rough")
DEMS = ("green_mountains_vt", "jacksboro_fault_tn", "mount_st_helens_wa", "west_bijou_escarpment_co")
SHARED = Path(os.environ.get("TERRAINVIS_SHARED_DEMS", Path(__file__).resolve().parents[2] / "shared" / "data" / "dem"))


def _valid(name: str) -> tv.HeightGrid:
    grid = tv.load_dem(SHARED / f"{name}.npz")
    return grid.crop(*grid.valid_window())


def _middle(grid: tv.HeightGrid, side: int) -> tv.HeightGrid:
    """``side`` x ``side`` (at most) from the middle of a NaN-free grid (written out, not
    ``valid_window(size=)``, so that checkouts from before it run this script too)."""
    (rows, cols), n_r, n_c = grid.shape, min(side, grid.shape[0]), min(side, grid.shape[1])
    r0, c0 = (rows - n_r) // 2, (cols - n_c) // 2
    return grid.crop(rows=(r0, r0 + n_r), cols=(c0, c0 + n_c))


def _kind(exc: Exception) -> str:
    text = str(exc)
    return "stuck" if "got stuck" in text else "search" if "no epsilon gave" in text else type(exc).__name__


def _run(cases) -> None:
    """Greedy cuts at levels 1-3 on each (label, grid); the counts and the failures."""
    counts, failures, t0 = collections.Counter(), [], time.perf_counter()
    for label, grid in cases:
        for level in (1, 2, 3):
            try:
                simplifiers.simplify(grid, "greedy-cuts", level)
                counts["ok"] += 1
            except Exception as exc:  # noqa: BLE001 (counted and listed: the point of the script)
                counts[_kind(exc)] += 1
                failures.append(f"{label} level {level}: {str(exc)[:110]}")
    runs = sum(counts.values())
    print(f"  {runs} runs, {dict(counts)}, {time.perf_counter() - t0:.0f} s")
    for line in failures:
        print("   ", line)


def faber_cases():
    terrains = {name: tv.bundled_terrain(name) for name in BUNDLED}
    terrains.update({name: _middle(_valid(name), 120) for name in DEMS})
    for name, T in terrains.items():
        for method in ("simple", "lls", "gls", "feature"):
            for level in (1, 2):
                S = simplifiers.simplify(T, method, level)
                if not S.is_uniform:
                    yield f"{name} {method} L{level}", S


def crop_cases(sides, seeds):
    for seed in seeds:
        rng = np.random.default_rng(seed)
        for side in sides:
            for name in DEMS:
                grid = _valid(name)
                for _ in range(3):
                    r0 = int(rng.integers(0, max(1, grid.shape[0] - side)))
                    c0 = int(rng.integers(0, max(1, grid.shape[1] - side)))
                    yield (f"{name} {side}² at ({r0}, {c0}) seed {seed}",
                           grid.crop(rows=(r0, r0 + side), cols=(c0, c0 + side)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workloads", nargs="+", choices=["faber", "crops"], default=["faber", "crops"])
    ap.add_argument("--sides", nargs="+", type=int, default=[64, 120, 200])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    args = ap.parse_args()
    if "faber" in args.workloads:
        print("faber: the regular methods' S(T) grids (rectilinear)")
        _run(faber_cases())
    if "crops" in args.workloads:
        print(f"crops: random windows of the shared DEMs, sides {args.sides}, seeds {args.seeds}")
        _run(crop_cases(args.sides, args.seeds))


if __name__ == "__main__":
    main()
