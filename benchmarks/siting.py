"""Benchmark: observer siting on a 1024² DEM, 1,000 candidates, k = 10 (issue 30: at most 60 s on two cores).

The terrain is ``synthetic_terrain(--kind, --size)`` (30 m cells); ``--candidates`` K
candidates stand on samples drawn at random (seeded, distinct), each eye
``--observer-height`` above its sample. The script runs :func:`terrainvis.site_observers`
``--repeats`` times and prints, per run and as medians: the wall time of the K viewsheds
(packed into bits as they finish), of the lazy greedy choice, and of the whole call; the
CPU seconds of this process (and of its worker processes with ``--workers N``), which other
programs on the shared machine do not inflate; how many marginal gains the lazy greedy
evaluated against the plain greedy's k K - k (k - 1) / 2; the area covered and the run's
bound on the optimum. With ``--plain`` it also times the plain greedy (every gain
recomputed each round) over the same packed viewsheds, and checks that it chooses the same
sequence.

Timings are noisy on a shared machine: the script prints the load average before and
after each run.

Example::

    python benchmarks/siting.py                              # 1024², 1,000 candidates, k = 10, 3 runs
    python benchmarks/siting.py --size 512 --candidates 200 --repeats 1
    python benchmarks/siting.py --plain --curvature 0.85714
    python benchmarks/siting.py --threads 1                  # one numba thread (a loaded machine)
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import time

import numba
import numpy as np

from terrainvis import site_observers
from terrainvis.core.synthetic import synthetic_terrain


def _candidates(grid, k: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    flat = rng.choice(grid.size, size=k, replace=False)
    r, c = np.divmod(flat, grid.shape[1])
    return np.column_stack([grid.xs[c], grid.ys[r]])


def _cpu() -> float:
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def _plain_greedy(packed: np.ndarray, k: int) -> list[int]:
    """The plain greedy over packed viewsheds: every gain recomputed each round, ties to the lowest index."""
    uncovered = np.full(packed.shape[1], 0xFF, dtype=np.uint8)
    chosen: list[int] = []
    for _ in range(k):
        gains = np.bitwise_count(packed & uncovered).sum(axis=1, dtype=np.int64)
        gains[chosen] = -1
        best = int(np.argmax(gains))
        chosen.append(best)
        uncovered &= ~packed[best]
    return chosen


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--kind", default="mountains")
    p.add_argument("--size", type=int, default=1024)
    p.add_argument("--candidates", type=int, default=1000)
    p.add_argument("-k", type=int, default=10)
    p.add_argument("--observer-height", type=float, default=10.0)
    p.add_argument("--curvature", type=float, default=0.0)
    p.add_argument("--max-distance", type=float, default=None)
    p.add_argument("--workers", type=int, default=None, help="as site_observers(workers=...) (default 1: here)")
    p.add_argument("--threads", type=int, default=None,
                   help="numba threads of this process (default: numba's, every core); on a loaded machine one "
                        "thread can beat two (parallel regions wait for a core)")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--plain", action="store_true", help="also time the plain greedy on the same viewsheds")
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args()

    if args.threads is not None:
        numba.set_num_threads(args.threads)
    grid = synthetic_terrain(args.kind, args.size, seed=args.seed)
    cands = _candidates(grid, args.candidates, args.seed)
    opts = dict(observer_height=args.observer_height, curvature=args.curvature, max_distance=args.max_distance,
                workers=args.workers)
    print(f"{args.kind} {args.size}x{args.size} ({grid.dx:g} m cells), {args.candidates:,} candidates on random "
          f"samples, k = {args.k}, eye {args.observer_height:g} m, curvature {args.curvature:g}, max distance "
          f"{args.max_distance or 'none'}; workers {args.workers or 1}; {os.cpu_count()} CPUs, numba "
          f"{numba.get_num_threads()} threads; load average {os.getloadavg()[0]:.2f}")
    site_observers(grid, cands[:2], 1, **opts)  # load the kernels (numba's cache) outside the timings
    walls, views, greedys, cpus = [], [], [], []
    result = None
    for n in range(args.repeats):
        load = os.getloadavg()[0]
        c0, t0 = _cpu(), time.perf_counter()
        result = site_observers(grid, cands, args.k, **opts)
        wall, cpu = time.perf_counter() - t0, _cpu() - c0
        walls.append(wall)
        cpus.append(cpu)
        views.append(result.seconds["viewsheds"])
        greedys.append(result.seconds["greedy"])
        print(f"  run {n + 1}: {wall:.1f} s (viewsheds {result.seconds['viewsheds']:.1f} s, greedy "
              f"{result.seconds['greedy']:.3f} s), CPU {cpu:.1f} s; load average {load:.2f} before, "
              f"{os.getloadavg()[0]:.2f} after")
    plain_evals = args.k * args.candidates - args.k * (args.k - 1) // 2
    covered = float(result.table["covered_share"].iloc[-1])
    print(f"  median of {args.repeats}: {statistics.median(walls):.1f} s in all (viewsheds "
          f"{statistics.median(views):.1f} s, greedy {statistics.median(greedys):.3f} s), CPU "
          f"{statistics.median(cpus):.1f} s; target: <= 60 s on two cores")
    print(f"  chosen {result.chosen.tolist()}; covered {100 * covered:.2f} % of the area; this choice reaches at "
          f"least {100 * result.table['covered_area'].iloc[-1] / result.bound:.1f} % of the optimum (the run's bound)")
    print(f"  lazy greedy: {result.evaluations:,} gains evaluated (the plain greedy: {plain_evals:,})")
    if args.plain:
        from terrainvis.visibility import Sight
        from terrainvis.visibility.viewsheds.many import prepare, run_chunks
        from terrainvis.visibility.viewsheds.siting import _siting_unit

        sight = Sight.make(observer_height=args.observer_height, max_distance=args.max_distance,
                           curvature=args.curvature)
        run = prepare(grid, cands, None, sight, None, workers=args.workers, client=None, progress=False,
                      name="candidates")
        packed = np.zeros((len(cands), -(-grid.size // 8)), dtype=np.uint8)
        run_chunks(run, _siting_unit, lambda key, part: packed.__setitem__(slice(*key), part), desc="")
        t0 = time.perf_counter()
        chosen = _plain_greedy(packed, args.k)
        print(f"  plain greedy on the same packed viewsheds: {time.perf_counter() - t0:.3f} s; same sequence: "
              f"{chosen == result.chosen.tolist()}")
    print(f"  load average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
