"""Cold compile seconds of the threshold engine's kernels in two checkouts, alternating.

Each run is a fresh process with an empty ``NUMBA_CACHE_DIR`` and ``PYTHONPATH`` the
checkout. It calls the kernels that Python calls, in a fixed order (a 65² hills grid, then
its TIN: one row of thresholds, a Gauss-Seidel sweep with a window, best heights with a
window, a viewshed's eye thresholds) and prints the seconds of each outermost numba
compile event (the kernel with every callee not compiled before it), named
``function[first argument's record]``::

    git worktree add /tmp/before <rev>
    python benchmarks/ab_compile.py /tmp/before . 2      # checkouts, rounds

The machine is shared: compare the runs of one invocation, not figures of other days.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile

from bench_cold_start import OUTERMOST

CHILD = r'''
import json, sys, time
import numpy as np
import terrainvis as tv
from terrainvis.visibility.thresholds import ThresholdSurface, threshold_row, gauss_seidel, best_heights
try:
    from terrainvis.visibility.viewsheds.output_modes import eye_thresholds
except ImportError:  # a checkout from before the viewsheds subpackage
    from terrainvis.visibility.output_modes import eye_thresholds
g = tv.synthetic_terrain("hills", size=65, seed=0)
pts = tv.sample_points(g, 40, seed=1)[:, :2]
T0 = time.perf_counter()
''' + OUTERMOST + r'''
for S in (g, g.to_tin()):
    surf = ThresholdSurface(S)
    q = surf.local(np.column_stack([pts, g.height_at(pts) + 1.0]))
    threshold_row(surf, q[0], q, skip=0)
    vis = np.ones((40, 40), dtype=bool)
    gauss_seidel(surf, q.copy(), np.arange(40), vis, window=5.0)
    best_heights(surf, q[:10], q[10:], vis[:10, 10:].copy(), neighbour_thresholds=np.full((10, 3), -np.inf),
                 neighbour_verdicts=np.ones((10, 3), dtype=np.int8), weight=0.5, window=5.0)
    eye_thresholds(S, np.array([g.xs[20], g.ys[30], 500.0]), np.column_stack([pts, g.height_at(pts)]), 0.0)
def _name(f, args):  # the kernel and its first argument's record type
    rec = getattr(args[0], "instance_class", None) if len(args) else None
    return f"{f.__qualname__}[{rec.__name__ if rec else ''}]"
events = [(_name(f, a), s) for f, a, s in compiled]
print(json.dumps({"file": tv.__file__, "events": events, "total": time.perf_counter() - T0}))
'''

def run(checkout):
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, PYTHONPATH=os.path.abspath(checkout), NUMBA_CACHE_DIR=cache, TERRAINVIS_COMPILE_NOTICE="0")
        r = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, check=True,
                           cwd=cache)  # not the current folder: it may hold another checkout
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert got["file"].startswith(os.path.abspath(checkout)), got["file"]
    return got

before, after, rounds = sys.argv[1], sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else 2
res = {"before": [], "after": []}
print(f"load average {os.getloadavg()[0]:.2f}", flush=True)
for r in range(rounds):
    for side, co in (("before", before), ("after", after)):
        got = run(co)
        res[side].append(got)
        print(side, f"total {got['total']:.2f}", " ".join(f"{n}={s:.2f}" for n, s in got["events"]), flush=True)
print(f"load average {os.getloadavg()[0]:.2f}")
for side in res:
    tot = [g["total"] for g in res[side]]
    comp = [sum(s for _, s in g["events"]) for g in res[side]]
    print(f"{side}: wall of the calls {' '.join(f'{t:.2f}' for t in tot)}; compile events summed {' '.join(f'{t:.2f}' for t in comp)}")
