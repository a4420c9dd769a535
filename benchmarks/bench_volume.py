"""Volume between two surfaces: the exact overlay integral against manifold3d, in one run.

Run:  python benchmarks/bench_volume.py [--size 1024] [--repeats 5] [--ref-repeats 3]

A ``--size``² synthetic terrain (``--kind``, 30 m cells, seed 0) is simplified two ways:
``simplify(grid, "greedy-insertion", 1)`` (a TIN with 25 % of the vertices) and
``simplify(grid, "lls", 1)`` (a rectilinear coarse grid: the last gap is 3 cells wide).
For each, ``volume_error(grid, coarse)`` runs with ``method="exact"`` (ours) and
``method="manifold"`` (manifold3d's boolean volume, the reference), alternately. The
script prints median wall seconds, median process CPU seconds (all threads), the ratio
manifold / ours, both volumes and their relative difference, and the peak memory of one
call of each method, measured in a fresh interpreter above what was resident before the
call: the resident-set high-water mark (Linux ``/proc/self/clear_refs``, which sees
manifold3d's C++ allocations; NaN elsewhere) and the tracemalloc peak (Python and numpy
allocations only).

The machine is shared, so wall times are noisy: the CPU column and the load average
printed in the header tell how much of the machine the run had. Target: ours <= 1 s on
the TIN case at 1024², equal to manifold3d to ~1e-9 relative.
"""

from __future__ import annotations

import argparse
import gc
import os
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numba
import numpy as np

from simplifiers import simplify
from terrainvis import TIN, HeightGrid, synthetic_terrain
from terrainvis.core.deviation import volume_error


def _status_kb(field: str) -> int | None:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def _reset_peak_rss() -> bool:
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def peak_memory(fn) -> tuple[float, float | None]:
    """(tracemalloc peak MB, resident high-water growth MB or None) of one call of ``fn``."""
    gc.collect()
    can_rss = _reset_peak_rss()
    rss0 = _status_kb("VmRSS")
    tracemalloc.start()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    hwm = _status_kb("VmHWM")
    rss = (hwm - rss0) / 1024 if can_rss and hwm is not None and rss0 is not None else None
    return peak / 2**20, rss


def _save_case(path: Path, grid: HeightGrid, coarse) -> None:
    if isinstance(coarse, HeightGrid):
        np.savez(path, z=grid.z, xs=grid.xs, ys=grid.ys, cz=coarse.z, cxs=coarse.xs, cys=coarse.ys)
    else:
        np.savez(path, z=grid.z, xs=grid.xs, ys=grid.ys, vertices=coarse.vertices, faces=coarse.faces)


def _memory_child(method: str, path: str) -> None:
    """Measure one call in this fresh process and print ``tracemalloc_mb rss_mb``."""
    tiny = HeightGrid(np.random.default_rng(0).normal(size=(5, 5)))
    volume_error(tiny, tiny.subsample(2), method=method)  # load the numba cache / manifold3d
    with np.load(path) as data:
        grid = HeightGrid.from_coords(data["z"], data["xs"], data["ys"])
        if "faces" in data:
            coarse = TIN(data["vertices"], data["faces"])
        else:
            coarse = HeightGrid.from_coords(data["cz"], data["cxs"], data["cys"])
    tm, rss = peak_memory(lambda: volume_error(grid, coarse, method=method))
    print(f"{tm} {'nan' if rss is None else rss}")


def memory_in_fresh_process(method: str, path: Path) -> tuple[float, float]:
    """(tracemalloc peak MB, RSS high-water growth MB) of one call, in a new interpreter.

    A fresh process, because memory freed by an earlier call (manifold3d's gigabytes)
    stays resident and would hide a later call's peak.
    """
    out = subprocess.run(
        [sys.executable, __file__, "--memory-child", method, str(path)],
        check=True, capture_output=True, text=True,
    ).stdout.split()
    return float(out[-2]), float(out[-1])


def timed(fn) -> tuple[float, float, float]:
    """(wall seconds, process CPU seconds, result) of one call."""
    c0 = time.process_time()
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, time.process_time() - c0, out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--kind", default="mountains")
    ap.add_argument("--repeats", type=int, default=5, help="runs of the exact method per case")
    ap.add_argument("--ref-repeats", type=int, default=3, help="runs of manifold3d per case")
    ap.add_argument("--memory-child", nargs=2, metavar=("METHOD", "PATH"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.memory_child:
        _memory_child(*args.memory_child)
        return

    # compile or load the numba caches, import manifold3d
    tiny = HeightGrid(np.random.default_rng(0).normal(size=(5, 5)))
    volume_error(tiny, tiny.subsample(2))
    volume_error(tiny, tiny.subsample(2), method="manifold")

    grid = synthetic_terrain(args.kind, size=args.size, seed=0)
    cases = []
    for method, label in (("greedy-insertion", "TIN"), ("lls", "grid")):
        t0 = time.perf_counter()
        coarse = simplify(grid, method, 1)
        cases.append((f"{method} 1 ({label})", coarse, time.perf_counter() - t0))

    load = os.getloadavg()
    print(
        f"volume between a {args.size}x{args.size} {args.kind} grid (30 m cells) and its simplifications; "
        f"numba threads {numba.get_num_threads()}, load average {load[0]:.1f} on {os.cpu_count()} cores"
    )
    print(f"median of {args.repeats} runs (exact) and {args.ref_repeats} (manifold3d), alternated")
    print(
        f"{'case':<24} {'faces':>7} {'exact s':>8} {'cpu s':>6} {'manifold s':>10} {'cpu s':>6} "
        f"{'ratio':>6} {'volume exact':>18} {'volume manifold':>18} {'rel diff':>9}"
    )
    memory = []
    for name, coarse, _ in cases:
        tin = coarse.to_tin() if isinstance(coarse, HeightGrid) else coarse
        ours, ref = [], []
        for i in range(max(args.repeats, args.ref_repeats)):
            if i < args.repeats:
                ours.append(timed(lambda: volume_error(grid, coarse)))
            if i < args.ref_repeats:
                ref.append(timed(lambda: volume_error(grid, coarse, method="manifold")))
        a_wall = statistics.median(t[0] for t in ours)
        a_cpu = statistics.median(t[1] for t in ours)
        b_wall = statistics.median(t[0] for t in ref)
        b_cpu = statistics.median(t[1] for t in ref)
        va, vb = ours[0][2], ref[0][2]
        if any(t[2] != va for t in ours):
            raise RuntimeError(f"{name}: the exact volume changed between runs: {[t[2] for t in ours]}")
        print(
            f"{name:<24} {tin.n_faces:>7} {a_wall:>8.3f} {a_cpu:>6.2f} {b_wall:>10.2f} {b_cpu:>6.1f} "
            f"{b_wall / a_wall:>5.0f}x {va:>18.6f} {vb:>18.6f} {(va - vb) / vb:>9.1e}"
        )
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "case.npz"
            _save_case(path, grid, coarse)
            memory.append((name, memory_in_fresh_process("exact", path), memory_in_fresh_process("manifold", path)))
    print("peak memory of one call above the resident inputs, each in a fresh process (MB): "
          "RSS high-water mark / tracemalloc peak")
    inputs = (grid.nbytes + sum(c.nbytes for _, c, _ in cases)) / 2**20
    for name, (a_tm, a_rss), (b_tm, b_rss) in memory:
        print(f"{name:<24} exact {a_rss:>6.1f} / {a_tm:>5.1f}    manifold3d {b_rss:>6.0f} / {b_tm:>5.0f}")
    print(f"(inputs: {inputs:.0f} MB; simplify took " + ", ".join(f"{n} {t:.1f} s" for n, _, t in cases) + ")")


if __name__ == "__main__":
    main()
