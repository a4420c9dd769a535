"""Hashes of the threshold engine's outputs: run it in two checkouts and diff, for "the same bits".

Prints one line per output (label, the first 16 hex digits of the SHA-256 of its bytes,
dtype and shape): the calibrated relocation (flat, and curved with an end radius), the
viewshed's ``min_height`` and ``angle`` outputs on the bundled terrains' LLS, GLS, QEC and
greedy-insertion levels 2 and on T, visopt (level 2, 150 training points; skipped with
``--quick``), and on 257² grids (the pyramid's descent) and their TINs threshold rows,
Gauss-Seidel sweeps and best heights with and without windows; a grid with nodata's
``min_height`` (its TIN walk)::

    PYTHONPATH=/tmp/before python benchmarks/threshold_bits.py > before.txt
    PYTHONPATH=. python benchmarks/threshold_bits.py > after.txt
    diff before.txt after.txt
"""

from __future__ import annotations

import hashlib
import sys
import time

import numpy as np

import simplifiers
import terrainvis as tv
from terrainvis.visibility.thresholds import ThresholdSurface, threshold_row, gauss_seidel, best_heights


def h(a):
    a = np.ascontiguousarray(np.asarray(a))
    return hashlib.sha256(a.tobytes() + str(a.dtype).encode() + str(a.shape).encode()).hexdigest()[:16]


def out(label, a):
    print(f"{label:60s} {h(a)}", flush=True)


quick = "--quick" in sys.argv
names = ["hills", "mesas", "mountains", "ridges", "rough"]
methods = ["lls", "gls", "qec", "greedy-insertion"]
t0 = time.time()
for name in names:
    T = tv.bundled_terrain(name)
    pts = tv.sample_points(T, 120, seed=1)
    eye = (float(T.xs[40]), float(T.ys[70]))
    for m in methods:
        S = simplifiers.simplify(T, m, 2)
        out(f"{name} {m} calibrated", tv.relocate(pts, S, "calibrated", original=T, n_partners=256))
        out(f"{name} {m} calibrated curv", tv.relocate(pts, S, "calibrated", original=T, n_partners=128,
                                                         curvature=0.85714, end_radius=1.0))
        at = None if isinstance(S, tv.HeightGrid) else T
        out(f"{name} {m} viewshed min_height", tv.viewshed(S, eye, output="min_height", at=at))
        out(f"{name} {m} viewshed angle curv", tv.viewshed(S, eye, output="angle", at=at, curvature=0.85714))
    out(f"{name} T viewshed min_height", tv.viewshed(T, eye, output="min_height"))
    if not quick:
        out(f"{name} visopt", np.asarray(simplifiers.simplify(T, "visopt", 2, n_train=150).z))
# larger grids: the pyramid walk (ltop > 7)
for size, lvl in ((513, 1), (257, 0)):
    T = tv.synthetic_terrain("mountains", size=size, seed=2)
    S = simplifiers.simplify(T, "lls", lvl) if lvl else T
    surf = ThresholdSurface(S)
    print("ltop", surf.ltop, S.shape)
    pts = tv.sample_points(T, 150, seed=3)
    out(f"synth{size} calibrated", tv.relocate(pts, S, "calibrated", original=T, n_partners=256))
    q = surf.local(np.column_stack([pts[:, :2], S.height_at(pts[:, :2]) + 1.0]))
    rows = np.array([threshold_row(surf, q[i], q, skip=i, kc=1e-7 * (i % 2), end_radius=0.5 * (i % 3)) for i in range(40)])
    out(f"synth{size} rows", rows)
    vis = (rows < q[:40, 2][:, None] + 3.0)
    qq = q[:40].copy()
    gauss_seidel(surf, qq, np.arange(40)[::-1].copy(), vis, window=5.0, kc=1e-7)
    out(f"synth{size} gauss_seidel window", qq)
    qq = q[:40].copy()
    gauss_seidel(surf, qq, np.arange(40), vis)
    out(f"synth{size} gauss_seidel", qq)
    nthr = rows[:, :6].copy(); nvis = (vis[:, :6]).astype(np.int8)
    for w in (1.0, np.inf):
        z, sc = best_heights(surf, q[:40], q[40:], vis[:, 40:].copy(), neighbour_thresholds=nthr, neighbour_verdicts=nvis,
                             weight=w, window=3.0)
        out(f"synth{size} best_heights w{w}", np.concatenate([z, sc]))
    eye = (float(T.xs[size // 3]), float(T.ys[size // 2]))
    out(f"synth{size} viewshed min_height", tv.viewshed(S, eye, output="min_height"))
    out(f"synth{size} viewshed angle", tv.viewshed(S, eye, output="angle", curvature=0.85714, at=T if lvl else None))
    tin = S.to_tin()
    out(f"synth{size} tin viewshed angle", tv.viewshed(tin, eye, output="angle", at=T))
    tsurf = ThresholdSurface(tin)
    tq = tsurf.local(np.column_stack([pts[:, :2], S.height_at(pts[:, :2]) + 1.0]))
    trows = np.array([threshold_row(tsurf, tq[i], tq, skip=i, kc=1e-7 * (i % 2)) for i in range(40)])
    out(f"synth{size} tin rows", trows)
    qq = tq[:40].copy()
    gauss_seidel(tsurf, qq, np.arange(40), vis, window=5.0)
    out(f"synth{size} tin gauss_seidel window", qq)
    z, sc = best_heights(tsurf, tq[:40], tq[40:], vis[:, 40:].copy(), neighbour_thresholds=nthr, neighbour_verdicts=nvis,
                         weight=1.0, window=3.0)
    out(f"synth{size} tin best_heights", np.concatenate([z, sc]))
# nodata grid: tin_of_grid_thresholds
g = tv.synthetic_terrain("mountains", size=200, seed=4)
z = g.z.copy(); z[50:53, 60:64] = np.nan
g2 = g.copy_with(z=z)
out("nodata viewshed min_height", tv.viewshed(g2, (float(g.xs[100]), float(g.ys[100])), output="min_height"))
print("seconds", round(time.time() - t0, 1), file=sys.stderr)
