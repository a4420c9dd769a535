"""The numba kernels give back every array they allocate (numba's NRT allocation counters).

The viewshed's sweep and the calibrated relocation's threshold rows hand their arrays to
the walks as views without reference counts (``terrainvis.core.surface.borrow``,
built from numba internals): a numba release that treated those views differently could
leak or free the arrays. The counters
of numba's runtime (on with ``NUMBA_NRT_STATS=1``, read before and after repeated calls)
tell: after a first call (caches filled), more calls must leave no allocation alive. The
script runs in a subprocess because the counters are switched on when numba is imported.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

_SCRIPT = textwrap.dedent("""
    import numpy as np
    import simplifiers
    import terrainvis as tv
    from numba.core.runtime import rtsys

    def live():
        s = rtsys.get_allocation_stats()
        return s.alloc - s.free, s.mi_alloc - s.mi_free

    g = tv.synthetic_terrain("mountains", size=129, seed=1)
    P = tv.sample_points(g, 40, seed=2, offset=2.0)
    S = simplifiers.simplify(g, "lls", 2)
    Q = simplifiers.simplify(g, "greedy-insertion", 2)
    calls = {
        "viewshed": lambda k: tv.viewshed(g, P[k, :2], observer_height=2.0),
        "viewshed curved": lambda k: tv.viewshed(g, P[k, :2], observer_height=2.0, curvature=0.85714),
        "visibility_matrix": lambda k: tv.visibility_matrix(g, P[k:]),
        "min_clearance": lambda k: tv.min_clearance(g, P[:20], P[20 - k:40 - k]),
        "calibrated on a grid": lambda k: tv.relocate(P[k:k + 10], S, "calibrated", original=g, offset=2.0,
                                                      n_partners=64),
        "calibrated on a TIN": lambda k: tv.relocate(P[k:k + 10], Q, "calibrated", original=g, offset=2.0,
                                                     n_partners=64),
    }
    for name, call in calls.items():
        call(0)
        before = live()
        for k in range(1, 4):
            call(k)
        print(name, "|", before, "|", live())
""")


def test_repeated_kernel_calls_leave_no_allocation_alive():
    env = dict(os.environ, NUMBA_NRT_STATS="1")
    out = subprocess.run([sys.executable, "-c", _SCRIPT], capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    lines = [line.split(" | ") for line in out.stdout.strip().splitlines()]
    assert len(lines) == 6, out.stdout
    for name, before, after in lines:
        assert before == after, f"{name}: live NRT allocations {before} after the first call, {after} after three more"
