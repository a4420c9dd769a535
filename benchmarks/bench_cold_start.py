"""What the first run of ``terrainvis compare --quick`` spends, with an empty numba cache.

Every run below gets its own empty ``NUMBA_CACHE_DIR``, so numba compiles every kernel
it meets, as on a fresh install. The script prints (medians over ``--repeats``):

* ``import``: ``python -c "import terrainvis.experiment, simplifiers, terrainvis.visibility"``
  (numba, pymeshlab, embreex, trimesh; nothing compiled);
* ``cold quick``: ``terrainvis compare --quick --no-plots`` with an empty cache (the
  warm-up parts compiled side by side on the pool, then the units);
* ``warm quick``: the same command again on the filled cache;
* one line per warm-up part of that run (:func:`terrainvis.experiment.plan.warm_up_parts`): the part
  alone, in one process with an empty cache and one numba thread (as a worker), minus
  the import time: what compiling its kernels costs on one core (a part that follows others, :func:`terrainvis.experiment.plan.part_needs`,
  is timed after them, on the cache they filled, as the run takes it).

Usage::

    python benchmarks/bench_cold_start.py [--repeats 1] [--workers 2]

The machine is shared: run it when it is otherwise idle, and read the medians.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

PART = """
import sys
import numba
numba.set_num_threads(1)  # as in a worker of a 2-worker run on 2 cores (terrainvis.core.runner)
from terrainvis.experiment.plan import part_needs, resolve_terrains, settings_for, tasks, warm_up_parts
from terrainvis.experiment.units import warm_up_part
grids = resolve_terrains(["hills", "ridges"])
settings = settings_for(grids, dict(levels=[1, 3], n_points=20, n_sets=2))
parts = warm_up_parts(tasks(grids, settings), grids, settings)
if sys.argv[1] == "list":
    print(repr(parts))
else:
    import time
    part = eval(sys.argv[1])
    for before in part_needs(part, parts):
        warm_up_part(before, settings)
    t0 = time.perf_counter()
    warm_up_part(part, settings)
    print(time.perf_counter() - t0)
"""


def _run(cmd, cache: str) -> tuple[float, str]:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache)
    t0 = time.perf_counter()
    out = subprocess.run(cmd, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if out.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({out.returncode}): {out.stderr[-2000:]}")
    return seconds, out.stdout + out.stderr


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    py = sys.executable
    rows = {"import": [], "cold quick": [], "warm quick": []}
    parts = None
    part_rows: dict[str, list[float]] = {}
    for _ in range(args.repeats):
        with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as out:
            rows["import"].append(_run([py, "-c", "import terrainvis.experiment, simplifiers, terrainvis.visibility"],
                                       cache)[0])
            cmd = [py, "-m", "terrainvis.cli", "compare", "--quick", "--no-plots", "--workers", str(args.workers),
                   "--out", out]
            seconds, text = _run(cmd, cache)
            rows["cold quick"].append(seconds)
            print(text[-600:], file=sys.stderr)
            rows["warm quick"].append(_run(cmd[:-1] + [os.path.join(out, "warm")], cache)[0])
        with tempfile.TemporaryDirectory() as cache:
            parts = parts or eval(_run([py, "-c", PART, "list"], cache)[1].strip().splitlines()[-1])
        for part in parts:
            with tempfile.TemporaryDirectory() as cache:
                seconds, text = _run([py, "-c", PART, repr(part)], cache)
                part_rows.setdefault(f"part {part[0]} {part[1]} ({part[2]}²)", []).append(
                    float(text.strip().splitlines()[-1]))
    print(f"{'what':40s} {'median s':>9s}")
    for name, values in {**rows, **part_rows}.items():
        print(f"{name:40s} {statistics.median(values):9.1f}")
    total = sum(statistics.median(v) for v in part_rows.values())
    print(f"{'sum of the parts (one core)':40s} {total:9.1f}")


if __name__ == "__main__":
    main()
