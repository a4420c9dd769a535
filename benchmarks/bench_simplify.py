"""Benchmark the simplifiers against peers on the same terrain, in the same run.

Regular section (reverse Faber, issue 4): one 2-D level of ``simple``, ``lls`` (paper and
derived weights), ``gls`` and ``feature`` on a synthetic 3601 x 3601 float64 terrain,
exactly as :func:`simplifiers.simplify` applies them (the operator along axis 1, then
along axis 0), plus the fused one-pass level :func:`simplifiers.reverse_faber.reduce_level`
(bitwise the same result), timed interleaved with ``numpy.copy`` of the same array (the
memory-bandwidth floor) and with plain numpy / scipy versions of LLS and GLS (peers that
also cross-check the results). It prints medians over the repeats and ratios to the
copy, the two passes separately, and whether the targets are met.

Targets: LLS <= 2x the copy, GLS <= 5x the copy, feature-aware <= 10 s.

Usage::

    python benchmarks/bench_simplify.py                      # every section
    python benchmarks/bench_simplify.py --sections regular --size 3601 --repeats 9
    python benchmarks/bench_simplify.py --methods lls gls --size 2001

Adding a section: write ``section_<name>(args) -> None`` and add it to ``SECTIONS``; it
gets the parsed arguments (``--size``, ``--repeats``, ``--seed``, ``--methods``).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time

import numpy as np


# ----------------------------------------------------------------------- inputs
def make_terrain(size: int, seed: int = 0) -> np.ndarray:
    """A (size, size) float64 fractal terrain in metres (power-law spectrum, beta = 2.2).

    Smooth at large scales and rough at small ones, with plenty of local extrema and some
    long monotone slopes, like a real DEM.
    """
    rng = np.random.default_rng(seed)
    ky = np.fft.fftfreq(size)[:, None]
    kx = np.fft.rfftfreq(size)[None, :]
    k = np.hypot(kx, ky)
    k[0, 0] = 1.0
    amp = k ** (-2.2 / 2 - 0.5)
    amp[0, 0] = 0.0
    spec = amp * (rng.standard_normal(k.shape) + 1j * rng.standard_normal(k.shape))
    z = np.fft.irfft2(spec, s=(size, size))
    z = (z - z.min()) / (z.max() - z.min()) * 1500.0 + 200.0
    return np.ascontiguousarray(z, dtype=np.float64)


# ----------------------------------------------------------------------- timing
def interleaved(funcs: dict, repeats: int) -> dict:
    """Run every function once per round, ``repeats`` rounds; return the times per name.

    Interleaving puts every candidate and the copy under the same machine load.
    """
    times = {name: [] for name in funcs}
    for _ in range(repeats):
        for name, fn in funcs.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    return times


def ratio_stats(times: dict, name: str, ref: str) -> tuple[float, float]:
    """Ratio of medians and the median of the per-round ratios (robust to load drift).

    The table also prints the ratio of the minima, the best estimate of the unloaded cost
    on a shared machine.
    """
    med = statistics.median(times[name]) / statistics.median(times[ref])
    per_round = statistics.median(a / b for a, b in zip(times[name], times[ref]))
    return med, per_round


def _print_table(rows, header):
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]
    line = "  ".join(f"{{:<{w}}}" for w in widths)
    print(line.format(*header))
    print(line.format(*("-" * w for w in widths)))
    for r in rows:
        print(line.format(*r))


# ----------------------------------------------------------------------- peers
def _peer_lls_numpy(z: np.ndarray) -> np.ndarray:
    """The paper's LLS with numpy strided slices, rows then columns (a plain-numpy peer)."""

    def along_last(f):
        m = f.shape[-1]
        n = (m + 1) // 2
        out = np.empty(f.shape[:-1] + (n,))
        out[..., 0] = f[..., 0]
        out[..., -1] = f[..., -1]
        # taps 2i-2 .. 2i+2 of the interior coarse samples i = 1 .. n-2, as strided views
        tap = [f[..., d : 2 * n - 5 + d : 2] for d in range(5)]
        out[..., 1:-1] = -1 / 6 * (tap[0] + tap[4]) + 1 / 3 * (tap[1] + tap[3]) + 2 / 3 * tap[2]
        return out

    return along_last(along_last(z).T).T


def _peer_gls_scipy(z: np.ndarray) -> np.ndarray:
    """GLS with numpy for S^T f and scipy.linalg.solve_banded (many right-hand sides)."""
    from scipy.linalg import solve_banded

    from simplifiers.reverse_faber import _faber_structure

    def along_axis0(f):
        m = f.shape[0]
        s = _faber_structure(m)
        n = s["tdiag"].size
        rhs = np.zeros((n,) + f.shape[1:])
        np.add.at(rhs, s["lo"], s["wl"][:, None] * f)
        np.add.at(rhs, s["lo"][:-1] + 1, s["wr"][:-1, None] * f[:-1])
        rhs[-1] += s["wr"][-1] * f[-1]
        ab = np.zeros((3, n))
        ab[0, 1:] = s["toff"]
        ab[1] = s["tdiag"]
        ab[2, :-1] = s["toff"]
        return solve_banded((1, 1), ab, rhs, check_finite=False)

    return along_axis0(along_axis0(z.T).T)


# ----------------------------------------------------------------------- sections
REGULAR_METHODS = ("simple", "lls", "lls-derived", "gls", "feature")


def section_regular(args) -> None:
    """Reverse Faber: one 2-D level on a size x size terrain against numpy.copy and peers."""
    from simplifiers import reverse_faber as rf

    ops = {
        "simple": lambda f, axis: rf.simple(f, axis=axis),
        "lls": lambda f, axis: rf.lls(f, axis=axis),
        "lls-derived": lambda f, axis: rf.lls(f, axis=axis, weights="derived"),
        "gls": lambda f, axis: rf.gls(f, axis=axis),
        "feature": lambda f, axis: rf.feature(f, axis=axis),
    }
    methods = [m for m in args.methods if m in ops] or list(REGULAR_METHODS)

    def level(op, z):
        return op(op(z, 1), 0)  # what simplifiers.simplify does for one level

    print(f"\n== regular: reverse Faber, one level of a {args.size}x{args.size} float64 grid ==")
    t0 = time.perf_counter()
    z = make_terrain(args.size, args.seed)
    print(f"terrain built in {time.perf_counter() - t0:.1f} s ({z.nbytes / 2**20:.0f} MiB)")
    # compile (or load from the numba cache) and fault in every code path
    small = z[:41, :40]
    for name in methods:
        level(ops[name], small)
    t0 = time.perf_counter()
    results = {name: level(ops[name], z) for name in methods}
    print(f"warm-up on the full grid: {time.perf_counter() - t0:.1f} s")

    # cross-checks against the peers (also keeps the peers honest)
    checks = []
    if "lls" in results:
        peer = _peer_lls_numpy(z)
        checks.append(("lls vs numpy slicing", float(np.abs(peer - results["lls"]).max())))
        fused = rf.reduce_level(z, rf.lls)
        checks.append(("lls fused vs two passes", float(np.abs(fused - results["lls"]).max())))
    if "gls" in results:
        peer = _peer_gls_scipy(z)
        checks.append(("gls vs scipy solve_banded", float(np.abs(peer - results["gls"]).max())))
    for what, err in checks:
        print(f"max |difference| {what}: {err:.3g} m")
    del results

    rows = []
    fast = [m for m in methods if m != "feature"]
    funcs = {"numpy.copy": lambda: np.copy(z)}
    for name in fast:
        funcs[name] = (lambda op: lambda: level(op, z))(ops[name])
    if "lls" in fast:
        funcs["lls fused (reduce_level)"] = lambda: rf.reduce_level(z, rf.lls)
    if "simple" in fast:
        funcs["simple gather (reduce_level)"] = lambda: rf.reduce_level(z, rf.simple)
    if "lls" in fast:
        funcs["peer: lls numpy slicing"] = lambda: _peer_lls_numpy(z)
    if "gls" in fast:
        funcs["peer: gls scipy banded"] = lambda: _peer_gls_scipy(z)
    times = interleaved(funcs, args.repeats)
    # the two passes separately, for the leading method
    half = {"numpy.copy": lambda: np.copy(z)}
    for name in ("lls", "gls"):
        if name in fast:
            zr = ops[name](z, 1)
            half[f"{name} rows pass (axis 1)"] = (lambda op: lambda: op(z, 1))(ops[name])
            half[f"{name} columns pass (axis 0)"] = (lambda op, zr: lambda: op(zr, 0))(ops[name], zr)
    times_half = interleaved(half, args.repeats) if len(half) > 1 else {}
    feature_times = None
    if "feature" in methods:
        fr = max(3, args.repeats // 3)
        feature_times = interleaved({"numpy.copy": lambda: np.copy(z), "feature": lambda: level(ops["feature"], z)}, fr)

    for label, tset in (("", times), (" (passes set)", times_half), (" (feature set)", feature_times)):
        if not tset:
            continue
        for name, ts in tset.items():
            med = statistics.median(ts)
            r_med, r_round = ratio_stats(tset, name, "numpy.copy")
            if name == "numpy.copy":
                name += label  # each set is timed against its own interleaved copy
            r_min = min(ts) / min(tset["numpy.copy"])
            rows.append((
                name, len(ts), f"{med * 1e3:.2f}", f"{min(ts) * 1e3:.2f}", f"{r_med:.2f}", f"{r_round:.2f}",
                f"{r_min:.2f}",
            ))
    _print_table(
        rows,
        ("operation", "runs", "median ms", "min ms", "x copy (medians)", "x copy (per-round median)", "x copy (mins)"),
    )
    targets = {"lls": 2.0, "lls fused (reduce_level)": 2.0, "gls": 5.0}
    for name, limit in targets.items():
        if name in times:
            r = ratio_stats(times, name, "numpy.copy")[0]
            print(f"target {name} <= {limit:g}x copy: {r:.2f}x -> {'met' if r <= limit else 'NOT met'}")
    if feature_times:
        med = statistics.median(feature_times["feature"])
        print(f"target feature <= 10 s: {med:.2f} s -> {'met' if med <= 10 else 'NOT met'}")


def _peer_pydelatin(z: np.ndarray, n: int):
    import pydelatin

    return pydelatin.Delatin(z, max_error=0.0, max_points=n)


def _pydelatin_tin(grid, d):
    """pydelatin's result as our TIN: its vertex (x, y) is our sample (row H-1-y, col x)."""
    from terrainvis import TIN

    cols = d.vertices[:, 0].astype(int)
    rows = grid.shape[0] - 1 - d.vertices[:, 1].astype(int)
    v = np.column_stack([grid.xs[cols], grid.ys[rows], grid.z[rows, cols]])
    f = np.asarray(d.triangles, dtype=np.int64)
    a, b, c = v[f[:, 0], :2], v[f[:, 1], :2], v[f[:, 2], :2]
    cw = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]) < 0
    f[cw] = f[cw][:, ::-1]
    return TIN(v, f)


def _peer_fast_simplification(tin, n: int):
    import fast_simplification

    origin = tin.vertices.min(axis=0)
    v = np.array(tin.vertices - origin)
    f = np.array(tin.faces, dtype=np.int32)  # a writeable C-contiguous copy
    return origin, fast_simplification.simplify(v, f, target_reduction=1.0 - n / tin.n_vertices)


def _errors_over_cover(grid, tin):
    """Max and RMS vertical error over the samples the TIN covers, and the covered share."""
    approx = tin.height_on_grid(grid.xs, grid.ys)
    ok = np.isfinite(approx)
    d = approx[ok] - grid.z[ok]
    return float(np.abs(d).max()), float(np.sqrt(np.mean(d**2))), float(ok.mean())


def section_all(args) -> None:
    """All seven methods through simplify() on 120², 512² and 1024², levels 1-3, with peers."""
    import time
    import tracemalloc

    import simplifiers
    from terrainvis import HeightGrid
    from terrainvis.core.synthetic import synthetic_terrain

    methods = args.methods or list(simplifiers.available())
    print("\n== all methods: simplify(grid, method, level) on a synthetic 'mountains' terrain ==")
    print("time: median of the runs; peak: tracemalloc peak (numpy allocations) during one run;")
    print("peers run on the same grid at the same vertex count, in the same run")
    rows = []
    warm = synthetic_terrain("mountains", size=33, seed=args.seed)
    for method in methods:  # compile and load every kernel before timing
        simplifiers.simplify(warm, method, 1)
    for size in args.all_sizes:
        grid = synthetic_terrain("mountains", size=size, seed=args.seed)
        unit = HeightGrid(grid.z)  # pydelatin works on unit spacing; errors are in z units either way
        for level in (1, 2, 3):
            n = simplifiers.vertex_budget(grid.shape, level)
            repeats = args.repeats if size <= 512 else max(1, min(args.repeats, 3))
            for method in methods + ["peer: pydelatin", "peer: fast-simplification"]:
                if method == "greedy-cuts" and size > 1024:
                    continue
                times = []
                peak = 0
                full_tin = grid.to_tin() if method == "peer: fast-simplification" else None
                for _ in range(repeats):
                    tracemalloc.start()
                    t0 = time.perf_counter()
                    if method == "peer: pydelatin":
                        out = _peer_pydelatin(unit.z, n)
                    elif method == "peer: fast-simplification":
                        out = _peer_fast_simplification(full_tin, n)
                    else:
                        out = simplifiers.simplify(grid, method, level)
                    times.append(time.perf_counter() - t0)
                    peak = max(peak, tracemalloc.get_traced_memory()[1])
                    tracemalloc.stop()
                if method == "peer: pydelatin":
                    tin = _pydelatin_tin(grid, out)
                    err, nv = _errors_over_cover(grid, tin)[:2], tin.n_vertices
                elif method == "peer: fast-simplification":
                    from terrainvis import TIN

                    origin, (pv, pf) = out
                    tin = TIN(pv + origin, pf)
                    mx, rms, cover = _errors_over_cover(grid, tin)
                    err, nv = (mx, rms), tin.n_vertices
                    method = f"{method} ({100 * cover:.1f}% covered)"
                else:
                    meta = out.attrs
                    err = (meta["max_error"], meta["rms_error"])
                    nv = meta["n_vertices"]
                rows.append((size, level, method, nv, float(np.median(times)), peak / 2**20, err[0], err[1]))
                print(f"  {size:5d} L{level} {method:40s} {nv:8d} v {np.median(times):8.3f} s "
                      f"{peak / 2**20:8.1f} MiB  max {err[0]:8.2f}  rms {err[1]:7.3f}", flush=True)
    _print_table(
        [(f"{r[0]}", f"{r[1]}", r[2], f"{r[3]}", f"{r[4]:.3f}", f"{r[5]:.1f}", f"{r[6]:.2f}", f"{r[7]:.3f}") for r in rows],
        ("size", "level", "method", "vertices", "median s", "peak MiB", "max err m", "RMS m"),
    )


SECTIONS = {"regular": section_regular, "all": section_all}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sections", nargs="+", default=list(SECTIONS), choices=list(SECTIONS))
    parser.add_argument("--size", type=int, default=3601, help="grid side (default 3601)")
    parser.add_argument("--repeats", type=int, default=9, help="timed rounds per operation (default 9)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--methods", nargs="+", default=[], help="restrict to these methods (default: all)")
    parser.add_argument("--threads", type=int, default=0, help="numba threads (default: all)")
    parser.add_argument("--all-sizes", type=int, nargs="+", default=[120, 512, 1024],
                        help="grid sides of the 'all' section (default 120 512 1024)")
    args = parser.parse_args(argv)
    import numba

    if args.threads:
        numba.set_num_threads(args.threads)

    print(
        f"python {platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}, "
        f"{os.cpu_count()} cpus, numba threads {numba.get_num_threads()}, load average {os.getloadavg()[0]:.2f}"
    )
    for name in args.sections:
        SECTIONS[name](args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
