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
        fused = rf.reduce_level(z, "lls")
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
        funcs["lls fused (reduce_level)"] = lambda: rf.reduce_level(z, "lls")
    if "simple" in fast:
        funcs["simple gather (reduce_level)"] = lambda: rf.reduce_level(z, "simple")
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


SECTIONS = {"regular": section_regular}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sections", nargs="+", default=list(SECTIONS), choices=list(SECTIONS))
    parser.add_argument("--size", type=int, default=3601, help="grid side (default 3601)")
    parser.add_argument("--repeats", type=int, default=9, help="timed rounds per operation (default 9)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--methods", nargs="+", default=[], help="restrict to these methods (default: all)")
    parser.add_argument("--threads", type=int, default=0, help="numba threads (default: all)")
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
