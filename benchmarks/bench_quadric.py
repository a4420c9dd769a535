"""Benchmark: quadric edge collapse with both backends, against the bare library calls.

For each grid size (1024² by default) and level (1-3; the budget is the regular grid's
sample count at that level) it runs ``quadric.build(grid, budget, backend=...)`` for the
pymeshlab and fast-simplification backends and, as peers in the same run, the bare library
call on the same full-resolution mesh with our first pass's face target and settings (no
boundary snapping, fold-over repair or budget passes). It prints medians over the repeats
of the time, the vertex count, the max and RMS vertical error against the grid, the time
split of ours (setup, library passes, post-processing, finishing collapses) and of the bare
pymeshlab call (building the MeshSet, the filter, reading the mesh back), and the ratios
pymeshlab / fast-simplification and ours / bare library.

Options:

``--cascade``
    also decimate each level from the previous one (``build(..., start=finer)``) and print
    time, errors and their ratios to the independent runs;
``--metres``
    also run the bare pymeshlab call on coordinates in metres (what the backend did before
    it handed pymeshlab units of the longest edge), to show VCG's error clamp at work;
``--rss``
    run every case of ours in a fresh process and print its peak resident memory (the
    grid included); use this for 3601².

Run from the repository root::

    .venv/bin/python benchmarks/bench_quadric.py                       # 1024², levels 1-3
    .venv/bin/python benchmarks/bench_quadric.py --sizes 120 512 --repeats 3 --cascade
    .venv/bin/python benchmarks/bench_quadric.py --sizes 3601 --levels 1 --rss --no-bare
    .venv/bin/python benchmarks/bench_quadric.py --sizes 3601 --levels 1 --rss --no-bare --tile-samples 99999999

Times are wall-clock seconds of this process; on a shared machine compare the ratios.
Repeats are interleaved (every contender once, then again) so that a load spike hits all
alike. The errors of a bare call are over the grid samples its mesh covers (it may leave
some uncovered; the column ``uncov`` gives the share).
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import queue as queue_module
import resource
import statistics
import threading
import time

import numpy as np

from simplifiers import quadric, vertex_budget
from terrainvis import TIN
from terrainvis.core.synthetic import synthetic_terrain

BACKENDS = quadric.BACKENDS


# --------------------------------------------------------------------------- contenders
def _errors(grid, tin):
    """(max, RMS, uncovered share) of a TIN against the grid, over the samples it covers."""
    h = tin.height_on_grid(grid.xs, grid.ys)
    ok = np.isfinite(h)
    d = h[ok] - grid.z[ok]
    return float(np.abs(d).max()), float(np.sqrt(np.mean(d**2))), float(1.0 - ok.mean())


def _ours(grid, backend, budget, start=None, **options):
    t0 = time.perf_counter()
    tin = quadric.build(grid, budget, backend=backend, start=start, **options)
    return time.perf_counter() - t0, tin


def _bare(grid, backend, budget, metres=False):
    """One library call on the full mesh with our first pass's target; (seconds, split, TIN)."""
    origin = np.array([grid.xs[0], grid.ys[0], float(np.mean(grid.z))])
    v, f = quadric._grid_mesh(grid, origin)
    target = 2 * budget - 2 - int(np.sqrt(budget))  # our first pass's face target
    split = {}
    t0 = time.perf_counter()
    if backend == "pymeshlab":
        import pymeshlab

        unit = 1.0 if metres else quadric._longest_edge(v, f)
        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=v / unit, face_matrix=f))
        t1 = time.perf_counter()
        ms.meshing_decimation_quadric_edge_collapse(
            targetfacenum=target, targetperc=0.0, preserveboundary=False, autoclean=True, selected=False,
            **quadric.PYMESHLAB_DEFAULTS,
        )
        t2 = time.perf_counter()
        m = ms.current_mesh()
        out_v, out_f = np.array(m.vertex_matrix()) * unit, np.array(m.face_matrix())
        split = {"meshset": t1 - t0, "filter": t2 - t1, "read back": time.perf_counter() - t2}
    else:
        import fast_simplification

        out_v, out_f = fast_simplification.simplify(v, f, target_count=target, **quadric.FAST_DEFAULTS)
    seconds = time.perf_counter() - t0
    out_v, out_f = quadric._compact(np.asarray(out_v, dtype=np.float64), np.asarray(out_f, dtype=np.int64))
    return seconds, split, TIN(out_v + origin, out_f)


def _memory_guard(min_available_mib: float) -> None:
    """Stop this (child) process when the machine's available memory drops below the floor."""
    def watch():
        while True:
            with open("/proc/meminfo") as fh:
                info = dict(line.split(":", 1) for line in fh)
            if int(info["MemAvailable"].split()[0]) / 1024.0 < min_available_mib:
                os._exit(3)
            time.sleep(0.5)

    threading.Thread(target=watch, daemon=True).start()


def _rss_child(kind, size, backend, budget, options, min_available_mib, queue):
    _memory_guard(min_available_mib)
    grid = synthetic_terrain(kind, size=size)
    seconds, tin = _ours(grid, backend, budget, **options)
    emax, erms, _ = _errors(grid, tin)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    queue.put((seconds, tin.n_vertices, emax, erms, dict(tin.attrs["timing"]), tin.attrs["stages"],
               tin.attrs["tiles"], peak))


def _ours_in_child(kind, size, backend, budget, options, min_available_mib):
    """Ours in a fresh process: its results and peak RSS, or None when it was stopped."""
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=_rss_child, args=(kind, size, backend, budget, options, min_available_mib, queue))
    proc.start()
    while True:
        try:
            out = queue.get(timeout=2.0)
            break
        except queue_module.Empty:
            if not proc.is_alive():
                out = None
                break
    proc.join()
    return out


# --------------------------------------------------------------------------- printing
def _row(size, level, budget, name, seconds, nv, emax, erms, uncov, note=""):
    print(f"{size:>5} {level:>3} {budget:>8} {name:<30} {seconds:>9.2f} {nv:>9} {emax:>8.2f} {erms:>8.3f} "
          f"{uncov:>7.3%}  {note}", flush=True)


def _split(d):
    return " ".join(f"{k}={v:.2f}" for k, v in d.items())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1024])
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--kind", default="mountains", help="synthetic terrain kind (terrainvis.core.synthetic.KINDS)")
    ap.add_argument("--backends", nargs="+", default=list(BACKENDS), choices=list(BACKENDS))
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--cascade", action="store_true", help="also run levels cascaded from the previous one")
    ap.add_argument("--metres", action="store_true", help="also run bare pymeshlab on coordinates in metres")
    ap.add_argument("--no-bare", action="store_true", help="skip the bare library calls")
    ap.add_argument("--rss", action="store_true", help="run ours in a fresh process per case and report peak RSS")
    ap.add_argument("--tile-samples", type=int, default=None,
                    help="build's tile_samples (default: quadric.TILE_SAMPLES); a huge value turns tiling off")
    ap.add_argument("--min-available-mib", type=float, default=2048.0,
                    help="with --rss, stop a case when the machine's available memory falls below this")
    args = ap.parse_args(argv)
    options = {} if args.tile_samples is None else {"tile_samples": args.tile_samples}

    warm = synthetic_terrain(args.kind, size=40)  # compile numba and load the libraries outside the timings
    for backend in args.backends:
        quadric.build(warm, 400, backend=backend)

    header = (f"{'size':>5} {'lvl':>3} {'budget':>8} {'contender':<30} {'median s':>9} {'vertices':>9} "
              f"{'max err':>8} {'rms err':>8} {'uncov':>7}  split / notes")
    ratios = []
    for size in args.sizes:
        t0 = time.perf_counter()
        grid = synthetic_terrain(args.kind, size=size)
        print(f"\n{args.kind} {size}x{size} ({grid.size:,} samples, made in {time.perf_counter() - t0:.1f} s), "
              f"{args.repeats} repeat(s); auto backend: {quadric.resolve_backend('auto', grid.size)}")
        print(header)
        chains = {b: None for b in args.backends}
        for level in args.levels:
            budget = vertex_budget(grid.shape, level)
            times, rows = {}, {}
            for _ in range(args.repeats):
                for backend in args.backends:
                    if args.rss:
                        out = _ours_in_child(args.kind, size, backend, budget, options, args.min_available_mib)
                        if out is None:
                            print(f"{size:>5} {level:>3} {budget:>8} ours {backend}: stopped, the machine's available "
                                  f"memory fell below {args.min_available_mib:.0f} MiB", flush=True)
                            continue
                        sec, nv, emax, erms, timing, stages, tiles, peak = out
                        note = f"tiles={tiles} stages={stages} {_split(timing)} peak RSS={peak:,.0f} MiB"
                        rows[backend] = (nv, emax, erms, 0.0, note)
                    else:
                        sec, tin = _ours(grid, backend, budget, **options)
                        emax, erms, _ = _errors(grid, tin)
                        m = tin.attrs
                        note = (f"tiles={m['tiles']} stages={m['stages']} repairs={m['repairs']} "
                                f"collapses={m['collapses']} {_split(m['timing'])}")
                        rows[backend] = (tin.n_vertices, emax, erms, 0.0, note)
                    times.setdefault(backend, []).append(sec)
                if args.no_bare:
                    continue
                for backend in args.backends:
                    for metres in ((False, True) if backend == "pymeshlab" and args.metres else (False,)):
                        name = f"bare {backend}" + (" (metres)" if metres else "")
                        sec, split, tin = _bare(grid, backend, budget, metres)
                        emax, erms, uncov = _errors(grid, tin)
                        rows[name] = (tin.n_vertices, emax, erms, uncov, _split(split))
                        times.setdefault(name, []).append(sec)
            med = {k: statistics.median(t) for k, t in times.items()}
            for name, (nv, emax, erms, uncov, note) in rows.items():
                _row(size, level, budget, ("ours " if name in BACKENDS else "") + name, med[name], nv, emax, erms,
                     uncov, note)
            if args.cascade and not args.rss:
                for backend in args.backends:
                    start = chains[backend]
                    if start is None:
                        # the finest level starts the chain
                        chains[backend] = _ours(grid, backend, budget, **options)[1]
                        continue
                    sec, tin = _ours(grid, backend, budget, start=start, **options)
                    emax, erms, _ = _errors(grid, tin)
                    ind = rows[backend]
                    _row(size, level, budget, f"cascade {backend}", sec, tin.n_vertices, emax, erms, 0.0,
                         f"vs independent: time {sec / med[backend]:.2f}x, max {emax / ind[1]:.3f}x, "
                         f"rms {erms / ind[2]:.3f}x, vertices {tin.n_vertices - ind[0]:+d}; "
                         f"{_split(tin.attrs['timing'])}")
                    chains[backend] = tin
            r = {"size": size, "level": level}
            if "pymeshlab" in med and "fast-simplification" in med:
                r["pymeshlab/fast"] = med["pymeshlab"] / med["fast-simplification"]
            for backend in args.backends:
                if f"bare {backend}" in med:
                    r[f"ours/bare {backend}"] = med[backend] / med[f"bare {backend}"]
            ratios.append(r)
    print("\nratios of median times")
    for r in ratios:
        print("  " + "  ".join(f"{k}={v:.2f}" if isinstance(v, float) else f"{k}={v}" for k, v in r.items()))
    print("\n'bare' = one library call on the full mesh with our first pass's face target and settings, without "
          "the post-processing; its errors are over the samples it covers (uncov = share left uncovered).")


if __name__ == "__main__":
    main()
