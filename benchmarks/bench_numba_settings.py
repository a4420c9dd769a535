"""The first viewshed under numba's code-generation settings: its compilation, and the viewsheds' speed after.

For each setting (numba's environment variables), with its own empty ``NUMBA_CACHE_DIR``,
two fresh processes run one after the other:

1. the first ``viewshed`` of a 65² float32 hills grid: the CPU seconds of that call, which
   are its compilation (``time.process_time()``);
2. on the cache the first filled, ``--viewsheds`` viewsheds of a 1024² mountains grid from
   random observers on one numba thread (one more first, untimed: it compiles the float64
   kernels): their median, and a hash of every result (the settings must not change a
   verdict).

It prints one line per setting and each one's ratio to the default's, for the question
"would numba, told to optimise less or to make code for any x86-64 CPU, compile a first
viewshed fast enough, and at what price?" (docs/performance.md, "The first viewshed:
levers measured and not kept")::

    python benchmarks/bench_numba_settings.py [--viewsheds 40] [--settings default opt2 opt1 generic]

The machine is shared: run it when it is otherwise idle, and read the ratios.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

SETTINGS = {
    "default": {},
    "opt2": {"NUMBA_OPT": "2"},
    "opt1": {"NUMBA_OPT": "1"},
    "generic": {"NUMBA_CPU_NAME": "generic"},
}

FIRST = r"""
import time
import numpy as np
import terrainvis as tv
from terrainvis.core.terrain import HeightGrid
g = tv.synthetic_terrain("hills", size=65, seed=0)
g32 = HeightGrid._from_coords(g.z.astype(np.float32), g.xs, g.ys, None, owned=True)
t = time.process_time()
tv.viewshed(g32, (float(g.xs[20]), float(g.ys[30])))
print(time.process_time() - t)
"""

MANY = r"""
import hashlib, sys, time
import numba
import numpy as np
import terrainvis as tv
numba.set_num_threads(1)
n = int(sys.argv[1])
g = tv.synthetic_terrain("mountains", size=1024, seed=0)
idx = np.random.default_rng(1).integers(0, 1024, size=(n + 1, 2))
obs = np.column_stack([g.xs[idx[:, 1]], g.ys[idx[:, 0]]])
tv.viewshed(g, obs[0])
h = hashlib.sha256()
ts = []
for o in obs[1:]:
    t = time.perf_counter()
    v = tv.viewshed(g, o)
    ts.append(time.perf_counter() - t)
    h.update(v.tobytes())
print(float(np.median(ts)), h.hexdigest()[:16])
"""


def _run(code: str, env: dict, *args) -> list[str]:
    out = subprocess.run([sys.executable, "-c", code, *args], env=env, capture_output=True, text=True, check=True)
    return out.stdout.split()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--viewsheds", type=int, default=40)
    ap.add_argument("--settings", nargs="+", choices=list(SETTINGS), default=list(SETTINGS))
    args = ap.parse_args()
    base = {k: v for k, v in os.environ.items() if k not in ("NUMBA_OPT", "NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES")}
    base["TERRAINVIS_COMPILE_NOTICE"] = "0"
    print(f"load average {os.getloadavg()[0]:.2f}; {args.viewsheds} viewsheds of 1024² per setting")
    print(f"{'setting':10s} {'compile s':>10s} {'viewshed ms':>12s} {'compile/default':>16s} "
          f"{'viewshed/default':>17s}  hash")
    first = None
    for name in args.settings:
        with tempfile.TemporaryDirectory() as cache:
            env = dict(base, NUMBA_CACHE_DIR=cache, **SETTINGS[name])
            compile_s = float(_run(FIRST, env)[0])
            median, digest = _run(MANY, env, str(args.viewsheds))
        ms = float(median) * 1e3
        first = first or (compile_s, ms)
        print(f"{name:10s} {compile_s:10.2f} {ms:12.2f} {compile_s / first[0]:16.3f} {ms / first[1]:17.3f}  {digest}",
              flush=True)
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
