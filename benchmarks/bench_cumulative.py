"""Benchmark: a cumulative viewshed of many observers, ours against gdal_viewshed in a loop, in one run.

The terrain is ``synthetic_terrain(--kind, --size)`` (30 m cells); ``--observers`` K
observers stand on samples drawn at random (seeded), each eye ``--observer-height`` above
its sample (gdal_viewshed snaps its observer to a cell, so both programs answer the same
question from the same eyes). The script prints

* one viewshed, one thread: the median time of :func:`terrainvis.viewshed` per observer
  with numba on one thread (over the peer's observers), and what K of them cost on all
  cores with no overhead at all (the floor);
* ours: :func:`terrainvis.cumulative_viewshed` on all K observers with ``workers=1``
  (in this process, one viewshed per numba thread at a time) and ``workers=2`` (two worker
  processes, one numba thread each; their start-up included), in seconds and observers
  per second, and the ratio to the floor;
* the peer: ``gdal_viewshed`` (Debian package ``gdal-bin``; skipped with a note when it is
  absent) run once per observer on a GeoTIFF of the same grid for ``--peer-observers`` of
  the observers, its whole command each time (reading the DEM, writing the viewshed, as a
  user's loop would), the median per observer and that times K (its loop in one process;
  it has no cumulative mode), with the ratio to ours; and how many cells of the summed
  counts differ between it and us on those observers (gdal_viewshed is an approximation,
  see docs/visibility.md), curvature off on both sides unless ``--curvature`` is given
  (gdal ``-cc``);
* with ``--dask``: the same call on a local dask cluster (``LocalCluster``, 2 worker
  processes of one thread; the cluster's start-up and the workers' first kernel load are
  excluded, as a user's long-lived cluster would have them);
* with ``--cli``: the whole ``terrainvis cumulative DEM.tif --observers OBS.csv -o
  counts.tif`` command on a GeoTIFF of the grid and a CSV of the observers (start-up,
  reading, the counts on the default workers, writing the GeoTIFF), and whether the counts
  it wrote equal the call's.

Timings are noisy on a shared machine: the script prints the load average before and
after, and the CPU seconds each run used (this process and its worker processes), which
other programs on the machine do not inflate: CPU seconds / cores is the wall time the run
would take on idle cores. Run it on a quiet machine for wall times to quote (``--repeats``
gives medians).

Example::

    python benchmarks/bench_cumulative.py                                   # 1,000 observers on 1024²
    python benchmarks/bench_cumulative.py --observers 100 --size 512        # quick
    python benchmarks/bench_cumulative.py --curvature 0.85714 --max-distance 10000
    python benchmarks/bench_cumulative.py --workers 1 --dask --cli          # the call, dask and the command
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from terrainvis import cumulative_viewshed, save_dem, viewshed
from terrainvis.core.synthetic import synthetic_terrain

GDAL = shutil.which("gdal_viewshed")


def _observers(grid, k: int, seed: int) -> np.ndarray:
    """K distinct samples drawn at random, as (x, y) (on samples, so GDAL's cell is the same eye)."""
    rng = np.random.default_rng(seed)
    flat = rng.choice(grid.size, size=k, replace=k > grid.size)
    r, c = np.divmod(flat, grid.shape[1])
    return np.column_stack([grid.xs[c], grid.ys[r]])


def _single_thread(grid, obs, args) -> tuple[float, float]:
    """Median wall and CPU seconds of one viewshed with numba on one thread."""
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        times, cpus = [], []
        for o in obs:
            c = time.process_time()
            t = time.perf_counter()
            viewshed(grid, o, **_options(args))
            times.append(time.perf_counter() - t)
            cpus.append(time.process_time() - c)
    finally:
        numba.set_num_threads(before)
    return statistics.median(times), statistics.median(cpus)


def _options(args) -> dict:
    return {"observer_height": args.observer_height, "target_height": args.target_height,
            "max_distance": args.max_distance, "curvature": args.curvature}


def _cpu() -> float:
    """CPU seconds of this process (all its threads) and of its finished children (the pool's workers)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _ours(grid, obs, workers: int, args):
    """Median wall seconds and CPU seconds of the cumulative viewshed, and its counts."""
    times, cpus = [], []
    counts = None
    for _ in range(args.repeats):
        c = _cpu()
        t = time.perf_counter()
        counts = cumulative_viewshed(grid, obs, workers=workers, **_options(args))
        times.append(time.perf_counter() - t)
        cpus.append(_cpu() - c)
    return statistics.median(times), statistics.median(cpus), counts


def _on_dask(grid, obs, args):
    """Wall seconds, workers' CPU seconds and counts of the cumulative viewshed on a local dask cluster
    (2 worker processes of one thread; the cluster is started and warmed up before the clock starts)."""
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        cumulative_viewshed(grid, obs[:4], client=client, **_options(args))  # workers import and load the kernels

        def cpu():
            return sum(client.run(lambda: sum(resource.getrusage(resource.RUSAGE_SELF)[:2])).values())

        c = cpu()
        t = time.perf_counter()
        counts = cumulative_viewshed(grid, obs, client=client, **_options(args))
        seconds = time.perf_counter() - t
        return seconds, cpu() - c, counts


def _command(grid, obs, args):
    """Wall and CPU seconds of ``terrainvis cumulative`` on a GeoTIFF of ``grid`` and a CSV of ``obs``."""
    import csv

    with tempfile.TemporaryDirectory(prefix="bench_cumulative_cli_") as tmp:
        folder = Path(tmp)
        dem = folder / "dem.tif"
        save_dem(grid, dem)
        table = folder / "observers.csv"
        with open(table, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["x", "y"])
            w.writerows([[repr(float(x)), repr(float(y))] for x, y in obs])
        exe = Path(sys.executable).with_name("terrainvis")
        cmd = [str(exe), "cumulative", str(dem), "--observers", str(table), "-o", str(folder / "counts.tif"),
               "--observer-height", repr(args.observer_height), "--target-height", repr(args.target_height),
               "--curvature", repr(args.curvature)]
        if args.max_distance is not None:
            cmd += ["--max-distance", repr(args.max_distance)]
        c = _cpu()
        t = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        seconds, cpu = time.perf_counter() - t, _cpu() - c
        import rasterio

        with rasterio.open(folder / "counts.tif") as src:
            counts = src.read(1)[::-1].astype(np.int64)  # north-up file, rows of the grid south-up
        return seconds, cpu, counts


def _gdal(grid, obs, args, folder: Path):
    """Wall and CPU seconds per gdal_viewshed command (medians) and the sum of its viewsheds (rows south-up, as ours)."""
    dem = folder / "dem.tif"
    save_dem(grid, dem)
    import rasterio

    total = np.zeros(grid.shape, dtype=np.int64)
    times, cpus = [], []
    for i, (x, y) in enumerate(obs):
        out = folder / f"v{i}.tif"
        cmd = [GDAL, "-q", "-ox", repr(float(x)), "-oy", repr(float(y)), "-oz", repr(args.observer_height),
               "-tz", repr(args.target_height), "-cc", repr(args.curvature), "-vv", "1", "-iv", "0", "-ov", "0"]
        if args.max_distance is not None:
            cmd += ["-md", repr(args.max_distance)]
        c = _cpu()
        t = time.perf_counter()
        subprocess.run(cmd + [str(dem), str(out)], check=True)
        times.append(time.perf_counter() - t)
        cpus.append(_cpu() - c)
        with rasterio.open(out) as src:
            total += src.read(1)[::-1] == 1  # north-up file, rows of the grid south-up
        out.unlink()
    return statistics.median(times), statistics.median(cpus), total


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--size", type=int, default=1024)
    p.add_argument("--kind", default="mountains")
    p.add_argument("--observers", type=int, default=1000)
    p.add_argument("--peer-observers", type=int, default=20, help="observers run through gdal_viewshed (default 20)")
    p.add_argument("--observer-height", type=float, default=1.7)
    p.add_argument("--target-height", type=float, default=0.0)
    p.add_argument("--max-distance", type=float, default=None)
    p.add_argument("--curvature", type=float, default=0.0)
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    p.add_argument("--repeats", type=int, default=1)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--dask", action="store_true",
                   help="also run on a local dask cluster (2 worker processes, one thread each; needs the dask extra)")
    p.add_argument("--cli", action="store_true",
                   help="also time `terrainvis cumulative` on a GeoTIFF of the grid and a CSV of the observers "
                        "(the whole command: start-up, reading, the counts, writing the GeoTIFF)")
    args = p.parse_args()

    grid = synthetic_terrain(args.kind, args.size)
    obs = _observers(grid, args.observers, args.seed)
    k = args.observers
    peer = obs[: min(args.peer_observers, k)]
    cores = os.cpu_count() or 1
    print(f"{args.kind} {args.size}x{args.size} (30 m cells), {k:,} observers on random samples, eye "
          f"{args.observer_height:g} m, target {args.target_height:g} m, curvature {args.curvature:g}, max distance "
          f"{args.max_distance or 'none'}; {cores} CPUs, numba {numba.get_num_threads()} threads, load average "
          f"{os.getloadavg()[0]:.2f}")
    viewshed(grid, obs[0], **_options(args))  # compile / load the kernels
    single, single_cpu = _single_thread(grid, peer, args)
    floor = k * single / cores
    print(f"  one viewshed, one thread       {single:8.3f} s per observer (median of {len(peer)}; CPU "
          f"{single_cpu:.3f} s); {k:,} on {cores} cores with no overhead: {floor:.1f} s")
    ours, ours_cpu = {}, {}
    counts = None
    for w in args.workers:
        seconds, cpu, counts = _ours(grid, obs, w, args)
        ours[w] = seconds
        ours_cpu[w] = cpu
        print(f"  ours, workers={w:<2}              {seconds:8.1f} s  {k / seconds:7.1f} observers/s  "
              f"({seconds / floor:.2f} x the floor; CPU {cpu:.1f} s = {cpu / k:.3f} s per observer, "
              f"{cpu / (k * single_cpu):.2f} x one thread's; {cpu / cores:.1f} s on {cores} idle cores); "
              f"seen by any {100 * (counts > 0).mean():.1f} %, max count {int(counts.max())}")
    if args.dask:
        seconds, cpu, counts = _on_dask(grid, obs, args)
        print(f"  ours, dask LocalCluster 2x1     {seconds:8.1f} s  {k / seconds:7.1f} observers/s  (cluster start-up "
              f"excluded; CPU of the workers {cpu:.1f} s); seen by any {100 * (counts > 0).mean():.1f} %, "
              f"max count {int(counts.max())}")
    if args.cli:
        seconds, cpu, from_file = _command(grid, obs, args)
        same = "the same counts" if counts is not None and np.array_equal(from_file, counts) else "COUNTS DIFFER"
        print(f"  terrainvis cumulative (command) {seconds:7.1f} s  {k / seconds:7.1f} observers/s  (whole process with "
              f"its workers: start-up, reading the GeoTIFF and the CSV, writing the counts; CPU {cpu:.1f} s); {same}")
    if GDAL is None:
        print("  gdal_viewshed: not installed (Debian: apt-get install gdal-bin); peer skipped")
    else:
        with tempfile.TemporaryDirectory(prefix="bench_cumulative_") as tmp:
            per, per_cpu, theirs = _gdal(grid, peer, args, Path(tmp))
        mine = cumulative_viewshed(grid, peer, workers=1, **_options(args)).astype(np.int64)
        extrapolated = k * per
        best = min(ours.values())
        print(f"  gdal_viewshed, one per command {per:8.3f} s per observer (median of {len(peer)}, whole command; CPU "
              f"{per_cpu:.3f} s); {k:,} in a loop: {extrapolated:.1f} s  ({k / extrapolated:.1f} observers/s); "
              f"{k * per_cpu / cores:.1f} s of CPU on {cores} idle cores if run {cores} at a time")
        print(f"  ratio gdal loop / ours (best)  {extrapolated / best:8.2f} (wall); CPU per observer, gdal / ours: "
              + ", ".join(f"workers={w} {per_cpu / (cpu / k):.2f}" for w, cpu in ours_cpu.items()))
        diff = mine != theirs
        print(f"  counts of those {len(peer)} observers: cells differing {100 * diff.mean():.2f} % (mean |difference| "
              f"{np.abs(mine - theirs).mean():.4f} observers; gdal_viewshed is an approximation)")
    print(f"  load average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
