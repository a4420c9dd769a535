"""The eye surface: how much of the calibrated relocation's gain it keeps without T, for its bytes.

Two workloads:

* ``table`` (the default): per terrain, method and level, an eye surface fitted from T
  and S(T) alone (:func:`terrainvis.eye_surface`, default budget: the bytes of S(T)),
  then fresh point sets (seeds never used in the fit: the fit relocates the nodes of its
  lattice against the calibrated relocation's partners of seed 0) relocated three ways:
  full projection, calibrated (with T) and eye (without T). Prints the accuracy of each
  (mean over the sets, against T's verdicts), the share of the calibrated gain over full
  projection the eye keeps, the eye surface's bytes against S(T)'s, and its fit time
  (median of ``--repeats`` fits, each on a fresh copy of S(T) so that no cache helps);
  then the gains summed over the units.
* ``curve``: the representations tried, on the calibrated offsets at every sample of T
  (float64, computed once per unit): lattices at 1, 1/2, 1/3 and 1/4 of T's resolution
  stored as float32, int16 and int8 (uniform) or int8 mu-law (the shipped one), and an
  adaptive quadtree of mu-law codes that splits, best first, the leaf whose bilinear
  interpolation misses the offsets most, until a byte budget (0.5, 1, 2 x S(T)). Prints
  each one's bytes against S(T)'s and the share of the calibrated gain it keeps, summed
  over the units.

    python benchmarks/bench_eye_surface.py --quick            # hills and mountains; lls, gls, qec, greedy-insertion
    python benchmarks/bench_eye_surface.py                    # the bundled terrains, every method, levels 1-3
    python benchmarks/bench_eye_surface.py --workloads curve --terrains hills --methods lls qec --levels 1 3
    python benchmarks/bench_eye_surface.py --terrains green_mountains_vt jacksboro_fault_tn --methods lls qec

``--terrains`` takes the bundled terrains and the shared real DEMs (120 x 120 crops of
their middle, read from ``$TERRAINVIS_SHARED_DEMS``, default ``../shared/data/dem`` beside the repository).
"""

from __future__ import annotations

import argparse
import copy
import heapq
import os
import time
from pathlib import Path

import numpy as np

import simplifiers
import terrainvis as tv
from terrainvis.relocation.eye import HEADER_BYTES, MU, shipped_bytes

BUNDLED = ("hills", "mountains", "mesas", "ridges", "rough")
#: The shared real DEMs (read where they are, never copied): a 120 x 120 window from the
#: middle of each one's valid part, as ``studies/relocation_dems.py`` crops them.
DEMS = ("green_mountains_vt", "jacksboro_fault_tn", "mount_st_helens_wa", "west_bijou_escarpment_co")
SHARED = Path(os.environ.get("TERRAINVIS_SHARED_DEMS", Path(__file__).resolve().parents[2] / "shared" / "data" / "dem"))
QUICK = dict(terrains=["hills", "mountains"], methods=["lls", "gls", "qec", "greedy-insertion"])


def _terrain(name: str) -> tv.HeightGrid:
    if name in DEMS:
        grid = tv.load_dem(SHARED / f"{name}.npz")
        return grid.crop(*grid.valid_window(size=120))
    return tv.bundled_terrain(name)


def _fresh_sets(T, name: str, n: int, sets: int, seed: int):
    words = [int(seed), sum(name.encode())]
    return [tv.sample_points(T, n, seed=np.random.default_rng(np.random.SeedSequence(words + [s])))
            for s in range(sets)]


def _accuracy(S, truths, placed) -> float:
    return float(np.mean([tv.agreement(v, tv.visibility_matrix(S, p))["accuracy"] for v, p in zip(truths, placed)]))


def _fresh_copy(S):
    return copy.deepcopy(S)  # a new object: no partners or eye surface cached on it


def table(args) -> None:
    print("| terrain | method | level | S(T) bytes | eye bytes | eye / S(T) | lattice | fit s | full | calibrated "
          "| eye | gain kept |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    tot = {"cal": 0.0, "eye": 0.0}
    by_level: dict = {}
    for name in args.terrains:
        T = _terrain(name)
        sets = _fresh_sets(T, name, args.points, args.sets, args.fresh_seed)
        truths = [tv.visibility_matrix(T, P) for P in sets]
        for method in args.methods:
            for level in args.levels:
                S = simplifiers.simplify(T, method, level)
                times = []
                for _ in range(args.repeats):
                    fresh = _fresh_copy(S)
                    t0 = time.perf_counter()
                    eye = tv.eye_surface(T, fresh)
                    times.append(time.perf_counter() - t0)
                S = fresh  # the partners cached by the last fit serve the calibrated relocation below
                full = _accuracy(S, truths, [tv.relocate(P, S, "full") for P in sets])
                cal = _accuracy(S, truths, [tv.relocate(P, S, "calibrated", original=T) for P in sets])
                got = _accuracy(S, truths, [tv.relocate(P, S, "eye", eye=eye) for P in sets])
                sb = shipped_bytes(S)
                kept = (got - full) / (cal - full) if cal != full else float("nan")
                tot["cal"] += cal - full
                tot["eye"] += got - full
                lv = by_level.setdefault(level, {"cal": 0.0, "eye": 0.0})
                lv["cal"] += cal - full
                lv["eye"] += got - full
                print(f"| {name} | {method} | {level} | {sb:,} | {eye.nbytes:,} | {eye.nbytes / sb:.2f} | "
                      f"{eye.shape[1]}x{eye.shape[0]} | {np.median(times):.1f} | {100 * full:.2f} | {100 * cal:.2f} | "
                      f"{100 * got:.2f} | {kept:.2f} |", flush=True)
    for level, lv in sorted(by_level.items()):
        print(f"\nlevel {level}: the eye keeps {lv['eye'] / lv['cal']:.1%} of the calibrated gain over full "
              f"projection ({100 * lv['eye']:.2f} of {100 * lv['cal']:.2f} accuracy points summed over units)")
    print(f"all: the eye keeps {tot['eye'] / tot['cal']:.1%} of the calibrated gain over full projection "
          f"({100 * tot['eye']:.2f} of {100 * tot['cal']:.2f} accuracy points summed over units)")


# ---------------------------------------------------------------------- the alternatives
def _mulaw(F: np.ndarray) -> np.ndarray:
    m = float(np.max(np.abs(F)))
    if m == 0:
        return np.zeros_like(F)
    codes = np.round(np.sign(F) * np.log1p(MU * np.abs(F) / m) / np.log1p(MU) * 127)
    return np.sign(codes) * np.expm1(np.abs(codes) / 127 * np.log1p(MU)) * m / MU


def _uniform(F: np.ndarray, bits: int) -> np.ndarray:
    m = float(np.max(np.abs(F)))
    if m == 0:
        return np.zeros_like(F)
    step = m / (2 ** (bits - 1) - 1)
    return np.round(F / step) * step


def _bilinear(values: np.ndarray, xs: np.ndarray, ys: np.ndarray, q: np.ndarray) -> np.ndarray:
    from scipy.interpolate import RegularGridInterpolator

    return RegularGridInterpolator((ys, xs), values)(q[:, [1, 0]])


class _Quadtree:
    """An adaptive quadtree over the lattice of T's samples: each leaf a block of nodes whose
    offsets are bilinear between its four corners. Ships one bit per tree node (split or not)
    and one byte per distinct corner (a mu-law code)."""

    def __init__(self, F: np.ndarray, budget: float):
        self.F = F
        ny, nx = F.shape
        root = (0, nx - 1, 0, ny - 1)
        used = {(0, 0), (0, nx - 1), (ny - 1, 0), (ny - 1, nx - 1)}
        n_tree = 1
        leaves = {root}
        heap = [(-self._err(root), root)]
        while heap:
            e, box = heapq.heappop(heap)
            if e == 0:
                break
            kids = self._children(box)
            if not kids:
                continue
            corners = {(d, a) for (a, b, c, d2) in kids for d in (c, d2)} | \
                      {(d, b) for (a, b, c, d2) in kids for d in (c, d2)}
            if self._bytes(used | corners, n_tree + len(kids)) > budget:
                continue
            used |= corners
            n_tree += len(kids)
            leaves.discard(box)
            for k in kids:
                leaves.add(k)
                heapq.heappush(heap, (-self._err(k), k))
        self.leaves = np.array(sorted(leaves))
        self.nbytes = self._bytes(used, n_tree)
        self.owner = np.full((ny - 1, nx - 1), -1)
        for k, (i0, i1, j0, j1) in enumerate(self.leaves):
            self.owner[j0:j1, i0:i1] = k

    @staticmethod
    def _bytes(used, n_tree) -> int:
        return len(used) + (n_tree + 7) // 8 + HEADER_BYTES

    @staticmethod
    def _children(box):
        i0, i1, j0, j1 = box
        si, sj = i1 - i0 >= 2, j1 - j0 >= 2
        if not (si or sj):
            return []
        im, jm = (i0 + i1) // 2, (j0 + j1) // 2
        xs = [(i0, im), (im, i1)] if si else [(i0, i1)]
        ys = [(j0, jm), (jm, j1)] if sj else [(j0, j1)]
        return [(a, b, c, d) for (c, d) in ys for (a, b) in xs]

    def _err(self, box) -> float:
        i0, i1, j0, j1 = box
        u = (np.arange(i0, i1 + 1) - i0) / (i1 - i0)
        v = ((np.arange(j0, j1 + 1) - j0) / (j1 - j0))[:, None]
        F = self.F
        fit = (F[j0, i0] * (1 - u) + F[j0, i1] * u) * (1 - v) + (F[j1, i0] * (1 - u) + F[j1, i1] * u) * v
        r = F[j0:j1 + 1, i0:i1 + 1] - fit
        return float(np.sum(r * r))

    def at(self, xs, ys, q) -> np.ndarray:
        F = self.F
        ny, nx = F.shape
        fx = np.clip((q[:, 0] - xs[0]) / (xs[-1] - xs[0]) * (nx - 1), 0, nx - 1)
        fy = np.clip((q[:, 1] - ys[0]) / (ys[-1] - ys[0]) * (ny - 1), 0, ny - 1)
        k = self.owner[np.minimum(fy.astype(int), ny - 2), np.minimum(fx.astype(int), nx - 2)]
        i0, i1, j0, j1 = self.leaves[k].T
        u, v = (fx - i0) / (i1 - i0), (fy - j0) / (j1 - j0)
        return (F[j0, i0] * (1 - u) + F[j0, i1] * u) * (1 - v) + (F[j1, i0] * (1 - u) + F[j1, i1] * u) * v


def curve(args) -> None:
    rows: dict = {}
    for name in args.terrains:
        T = _terrain(name)
        sets = _fresh_sets(T, name, args.points, args.sets, args.fresh_seed)
        truths = [tv.visibility_matrix(T, P) for P in sets]
        X, Y = np.meshgrid(T.xs, T.ys)
        nodes = np.column_stack([X.ravel(), Y.ravel(), T.z.ravel()])
        for method in args.methods:
            for level in args.levels:
                S = simplifiers.simplify(T, method, level)
                sb = shipped_bytes(S)
                F = (tv.relocate(nodes, S, "calibrated", original=T)[:, 2] - S.height_at(nodes[:, :2])).reshape(X.shape)
                full = _accuracy(S, truths, [tv.relocate(P, S, "full") for P in sets])
                cal = _accuracy(S, truths, [tv.relocate(P, S, "calibrated", original=T) for P in sets])

                def gain(off):
                    placed = [np.column_stack([P[:, :2], S.height_at(P[:, :2]) + off(P[:, :2])]) for P in sets]
                    return _accuracy(S, truths, placed) - full

                for step in (1, 2, 3, 4):
                    iy = np.unique(np.round(np.linspace(0, T.shape[0] - 1, (T.shape[0] - 2) // step + 2)).astype(int))
                    ix = np.unique(np.round(np.linspace(0, T.shape[1] - 1, (T.shape[1] - 2) // step + 2)).astype(int))
                    sub = F[np.ix_(iy, ix)]
                    xs, ys = T.xs[ix], T.ys[iy]
                    for rep, values, per in (("float32", sub.astype(np.float32).astype(np.float64), 4),
                                             ("int16", _uniform(sub, 16), 2), ("int8", _uniform(sub, 8), 1),
                                             ("int8 mu-law", _mulaw(sub), 1)):
                        nb = sub.size * per + HEADER_BYTES
                        r = rows.setdefault((f"lattice 1/{step} of T, {rep}"), [0.0, 0.0, []])
                        r[0] += gain(lambda q: _bilinear(values, xs, ys, q))
                        r[1] += cal - full
                        r[2].append(nb / sb)
                D = _mulaw(F)
                for frac in (0.5, 1.0, 2.0):
                    tree = _Quadtree(D, frac * sb)
                    r = rows.setdefault(f"quadtree of mu-law int8, budget {frac:g} x S(T)", [0.0, 0.0, []])
                    r[0] += gain(lambda q: tree.at(T.xs, T.ys, q))
                    r[1] += cal - full
                    r[2].append(tree.nbytes / sb)
                print(f"{name} {method} {level}: full {100 * full:.2f}, calibrated {100 * cal:.2f}", flush=True)
    print("\n| representation | bytes / S(T) (median over units) | bytes / S(T) (range) | calibrated gain kept |")
    print("|---|---|---|---|")
    for rep, (g, c, ratios) in rows.items():
        print(f"| {rep} | {np.median(ratios):.2f} | {min(ratios):.2f}–{max(ratios):.2f} | {g / c:.1%} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--workloads", nargs="+", choices=("table", "curve"), default=["table"])
    ap.add_argument("--terrains", nargs="+", default=list(BUNDLED))
    ap.add_argument("--methods", nargs="+", default=None, help="default: compare's methods")
    ap.add_argument("--levels", nargs="+", type=int, default=[1, 2, 3])
    ap.add_argument("--points", type=int, default=50)
    ap.add_argument("--sets", type=int, default=6)
    ap.add_argument("--fresh-seed", type=int, default=4040, help="the seed of the fresh point sets")
    ap.add_argument("--repeats", type=int, default=1, help="fits timed per unit (the median is printed)")
    ap.add_argument("--quick", action="store_true", help="hills and mountains; lls, gls, qec, greedy-insertion")
    args = ap.parse_args()
    if args.quick:
        for k, v in QUICK.items():
            setattr(args, k, v)
    if args.methods is None:
        args.methods = list(simplifiers.default_methods())
    warm = tv.synthetic_terrain("hills", size=33, seed=0)
    for m in ("lls", "qec"):  # compile the walks outside the timings
        tv.eye_surface(warm, simplifiers.simplify(warm, m, 1), n_partners=16)
    for w in args.workloads:
        {"table": table, "curve": curve}[w](args)


if __name__ == "__main__":
    main()
