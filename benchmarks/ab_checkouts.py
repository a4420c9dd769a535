"""Two checkouts of terrainvis on the same kernels, alternating, in the same run: is a change slower?

For a refactoring that must not slow the kernels (issue 29 asked: no kernel more than 5 %
slower), this runs each workload in a fresh process per checkout (``PYTHONPATH`` set to
the checkout, its own numba cache), one checkout after the other, for several rounds, and
prints each run's median and the ratio of the medians over the rounds:

    git worktree add /tmp/before <rev>
    python benchmarks/ab_checkouts.py /tmp/before . --rounds 3

Workloads (each warmed once in its process, then timed ``--repeats`` times):

* ``los``: ``visibility_matrix`` of 2,500 points 2 m above a 1025² mountains grid (the
  pair engine's pyramid descent, parallel);
* ``viewshed``: an eye 10 m above the centre of a 2048² hills grid (the sweep's walks);
* ``viewshed-nodata``: the same on a 1024² mountains grid with 0.2 % of its samples NaN;
* ``calibrated``: 300 points relocated onto LLS level 2 of a 257² mountains grid (the
  threshold engine);
* ``calibrated-tin``: the same onto its greedy-insertion level 2 (the threshold engine's face walk);
* ``min-height``: ``viewshed(..., output="min_height")`` of an eye on a 513² mountains grid
  (the threshold engine's one-eye loops, the pyramid's descent);
* ``angle-tin``: ``viewshed(..., output="angle")`` of the TIN of a 257² hills grid at the
  grid's samples (the one-eye loops on a TIN);
* ``visopt``: ``simplify(hills 65², "visopt", 2, n_train=300)``;
* ``greedy-cuts``: one advancing front, ``greedy_cuts(mountains 513², 1.0)`` (its three
  steps, the fallback's candidate heap included);
* ``greedy-insertion``: ``GreedyInserter(mountains 513²).run(131,072)`` (scan conversion,
  flips, the indexed heap);
* ``feature``: feature-aware reverse Faber along both axes of a 2049² mountains grid;
* ``volume``: ``volume_error`` of a 1025² mountains grid and its greedy-insertion level 1.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

WORKLOADS = ("los", "viewshed", "viewshed-nodata", "calibrated", "calibrated-tin", "min-height", "angle-tin", "visopt",
             "greedy-cuts", "greedy-insertion", "feature", "volume")


def _work(name: str):
    import numpy as np

    import simplifiers
    import terrainvis as tv

    if name == "los":
        g = tv.synthetic_terrain("mountains", size=1025)
        rng = np.random.default_rng(0)
        xy = np.column_stack([rng.uniform(0, g.xs[-1], 2500), rng.uniform(0, g.ys[-1], 2500)])
        pts = np.column_stack([xy, g.height_at(xy) + 2.0])
        return lambda: tv.visibility_matrix(g, pts)
    if name == "viewshed":
        g = tv.synthetic_terrain("hills", size=2048)
        return lambda: tv.viewshed(g, (g.xs[1024], g.ys[1024]), observer_height=10.0)
    if name == "viewshed-nodata":
        g = tv.synthetic_terrain("mountains", size=1024)
        g = g.copy_with(np.where(np.random.default_rng(3).random(g.shape) < 0.002, np.nan, g.z))
        return lambda: tv.viewshed(g, (g.xs[500], g.ys[500]), observer_height=10.0)
    if name == "calibrated":
        t = tv.synthetic_terrain("mountains", size=257)
        s = simplifiers.simplify(t, "lls", 2)
        pts = tv.sample_points(t, 300, seed=1)
        return lambda: tv.relocate(pts, s, "calibrated", original=t)
    if name == "calibrated-tin":
        t = tv.synthetic_terrain("mountains", size=257)
        s = simplifiers.simplify(t, "greedy-insertion", 2)
        pts = tv.sample_points(t, 300, seed=1)
        return lambda: tv.relocate(pts, s, "calibrated", original=t)
    if name == "min-height":
        g = tv.synthetic_terrain("mountains", size=513)
        return lambda: tv.viewshed(g, (g.xs[200], g.ys[300]), observer_height=10.0, output="min_height")
    if name == "angle-tin":
        g = tv.synthetic_terrain("hills", size=257)
        tin = g.to_tin()
        return lambda: tv.viewshed(tin, (g.xs[100], g.ys[150]), at=g, observer_height=10.0, output="angle")
    if name == "greedy-cuts":
        from simplifiers.greedy_cuts import greedy_cuts

        g = tv.synthetic_terrain("mountains", size=513)
        return lambda: greedy_cuts(g, 1.0)
    if name == "greedy-insertion":
        from simplifiers.greedy_insertion import GreedyInserter

        g = tv.synthetic_terrain("mountains", size=513)
        return lambda: GreedyInserter(g).run(131072)
    if name == "feature":
        from simplifiers import reverse_faber

        z = tv.synthetic_terrain("mountains", size=2049).z
        return lambda: (reverse_faber.feature(z, axis=0), reverse_faber.feature(z, axis=1))
    if name == "volume":
        g = tv.synthetic_terrain("mountains", size=1025)
        coarse = simplifiers.simplify(g, "greedy-insertion", 1)
        return lambda: tv.volume_error(g, coarse)
    t = tv.synthetic_terrain("hills", size=65)
    return lambda: simplifiers.simplify(t, "visopt", 2, n_train=300)


def _child(name: str, repeats: int, clock: str) -> None:
    import terrainvis

    now = time.perf_counter if clock == "wall" else time.process_time
    f = _work(name)
    f()  # compile or load the kernels, fill the per-grid caches
    times = []
    for _ in range(repeats):
        t0 = now()
        f()
        times.append(now() - t0)
    print(json.dumps({"file": terrainvis.__file__, "median": statistics.median(times)}))


def _run(checkout: str, name: str, repeats: int, clock: str) -> float:
    env = dict(os.environ, PYTHONPATH=os.path.abspath(checkout))
    cmd = [sys.executable, __file__, "--child", name, "--repeats", str(repeats), "--clock", clock]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True).stdout
    got = json.loads(out.strip().splitlines()[-1])
    expected = os.path.join(os.path.abspath(checkout), "terrainvis")
    if not got["file"].startswith(expected):
        raise SystemExit(f"the child imported {got['file']}, not the checkout {checkout}")
    return got["median"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", nargs="?", help="the checkout to compare against")
    ap.add_argument("after", nargs="?", help="the changed checkout")
    ap.add_argument("--workloads", nargs="+", choices=WORKLOADS, default=list(WORKLOADS))
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                    help="wall seconds, or the process's CPU seconds (all threads: steadier on a shared machine)")
    ap.add_argument("--child", choices=WORKLOADS, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        _child(args.child, args.repeats, args.clock)
        return
    if not (args.before and args.after):
        ap.error("give the two checkouts: BEFORE AFTER")
    print(f"load average {os.getloadavg()[0]:.2f}; {args.rounds} rounds, medians of {args.repeats} per run, "
          f"{args.clock} seconds")
    for name in args.workloads:
        runs = {"before": [], "after": []}
        for _ in range(args.rounds):
            for side in ("before", "after"):
                runs[side].append(_run(getattr(args, side), name, args.repeats, args.clock))
        b, a = statistics.median(runs["before"]), statistics.median(runs["after"])
        print(f"{name:16s} before {b:8.4f} s  after {a:8.4f} s  after / before {a / b:5.3f}   "
              f"(runs: {' '.join(f'{x:.4f}' for x in runs['before'])} | {' '.join(f'{x:.4f}' for x in runs['after'])})")
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
