"""Where a warm workload's time goes, kernel by kernel: Linux ``perf`` over numba's machine code.

``perf`` cannot name the functions numba compiles (they live in memory, not in a file), so
this script tells it: after a warm-up call has compiled the workload's kernels in this
process (an empty ``NUMBA_CACHE_DIR`` of its own, so that numba keeps their LLVM modules),
it writes ``/tmp/perf-<pid>.map`` with the address and name of every function of every
compiled library, then samples itself with ``perf record -p <pid>`` over the timed part
only, and prints the share of the samples each kernel took (its own code, callees not
included; inlined helpers count in their caller), and the share outside numba's code
(Python, numpy, the allocator):

* ``viewshed``: ``--repeats`` viewsheds of a 1024² mountains grid from random observers, one
  numba thread (the sweep of ``cumulative_viewshed``'s observers);
* ``calibrated``: the calibrated relocation of 300 points onto LLS level 1 of the bundled
  ``rough`` terrain, partners included (a unit of the default comparison), one thread.

Usage::

    python benchmarks/profile_kernels.py viewshed [--repeats 200] [--frequency 999]

Needs ``perf`` (Debian's ``linux-perf``) and permission to sample this process.
"""

from __future__ import annotations

import argparse
import collections
import gc
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time


def _readable(symbol: str) -> str:
    """``module.function`` of a numba-mangled symbol (``_ZN10terrainvis...13_run_segmentsB3v62...``):
    the length-prefixed names after ``_ZN``."""
    parts, i = [], 3
    while i < len(symbol) and symbol[i].isdigit():
        j = i
        while symbol[j].isdigit():
            j += 1
        n = int(symbol[i:j])
        parts.append(symbol[j:j + n])
        i = j + n
    return ".".join(parts).replace("_3c", "<").replace("_3e", ">") or symbol


def _perf_map() -> int:
    """Write /tmp/perf-<pid>.map for every function numba compiled in this process; how many."""
    import numba

    entries = set()
    for obj in gc.get_objects():
        if not isinstance(obj, numba.core.dispatcher.Dispatcher):
            continue
        for cres in obj.overloads.values():
            lib = cres.library
            module = getattr(lib, "_final_module", None)
            if module is None:
                continue
            for fn in module.functions:
                if fn.is_declaration:
                    continue
                address = lib._codegen._engine.get_function_address(fn.name)
                if address:
                    entries.add((address, fn.name))
    ordered = sorted(entries)
    with open(f"/tmp/perf-{os.getpid()}.map", "w") as f:
        for (address, name), (following, _) in zip(ordered, ordered[1:] + [(ordered[-1][0] + 4096, "")]):
            f.write(f"{address:x} {min(following - address, 1 << 20):x} {name}\n")
    return len(ordered)


def _workload(name: str, repeats: int):
    """(warm-up, timed) callables of the workload."""
    import numpy as np

    import terrainvis as tv

    if name == "viewshed":
        g = tv.synthetic_terrain("mountains", size=1024, seed=0)
        idx = np.random.default_rng(1).integers(0, 1024, size=(repeats + 1, 2))
        obs = np.column_stack([g.xs[idx[:, 1]], g.ys[idx[:, 0]]])

        def timed():
            for o in obs[1:]:
                tv.viewshed(g, o)

        return (lambda: tv.viewshed(g, obs[0])), timed
    from simplifiers import simplify

    T = tv.bundled_terrain("rough")
    S = simplify(T, "lls", 1)
    pts = tv.sample_points(T, 300, seed=2)

    def run(seed):
        return tv.relocate(pts, S, "calibrated", original=T, seed=seed)

    return (lambda: run(0)), (lambda: [run(s) for s in range(1, 1 + max(1, repeats // 100))])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("workload", choices=["viewshed", "calibrated"])
    ap.add_argument("--repeats", type=int, default=200)
    ap.add_argument("--frequency", type=int, default=999)
    ap.add_argument("--top", type=int, default=15)
    args = ap.parse_args()
    if shutil.which("perf") is None:
        sys.exit("profile_kernels: perf is not installed (Debian: apt-get install linux-perf)")
    if not os.environ.get("PROFILE_KERNELS_CHILD"):  # an empty cache of its own: numba keeps the LLVM modules
        with tempfile.TemporaryDirectory() as cache:
            env = dict(os.environ, NUMBA_CACHE_DIR=cache, PROFILE_KERNELS_CHILD="1", TERRAINVIS_COMPILE_NOTICE="0")
            sys.exit(subprocess.run([sys.executable, *sys.argv], env=env).returncode)
    import numba

    numba.set_num_threads(1)
    warm, timed = _workload(args.workload, args.repeats)
    warm()
    n = _perf_map()
    with tempfile.TemporaryDirectory() as folder:
        data = os.path.join(folder, "perf.data")
        perf = subprocess.Popen(["perf", "record", "-q", "-F", str(args.frequency), "-p", str(os.getpid()), "-o", data],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(1.0)  # perf attaches
        t0 = time.perf_counter()
        timed()
        seconds = time.perf_counter() - t0
        perf.send_signal(signal.SIGINT)
        perf.wait()
        report = subprocess.run(["perf", "report", "-i", data, "--stdio", "--no-children", "--sort", "sym",
                                 "-F", "overhead,sym"], capture_output=True, text=True).stdout
    shares = collections.Counter()
    for line in report.splitlines():
        m = re.match(r"\s*([\d.]+)%\s+\[[.k]\]\s+(\S+)", line)
        if m:
            name = m.group(2)
            shares[_readable(name) if name.startswith("_ZN") else "(outside numba's code)"] += float(m.group(1))
    print(f"{args.workload}: {seconds:.2f} s timed, load average {os.getloadavg()[0]:.2f}; {n} compiled functions "
          f"mapped; share of the samples (a kernel's own code, inlined helpers included):")
    for name, share in shares.most_common(args.top):
        print(f"  {share:6.2f} %  {name}")


if __name__ == "__main__":
    main()
