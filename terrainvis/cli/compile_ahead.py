"""``terrainvis compile``: compile every numba kernel now, into numba's cache (CI images, containers).

numba compiles a kernel on its first call and keeps it in its on-disk cache
(``NUMBA_CACHE_DIR``, else the ``__pycache__`` folders beside terrainvis's sources). A
fresh install, a new container or a CI job with an empty cache pays the compilation in
its first viewshed, comparison or regression test. This command pays it once, ahead:
run it after installing terrainvis in a container image, or in a CI job whose
``NUMBA_CACHE_DIR`` is kept between jobs (docs/user-guide.md, "First run and numba's
cache"). Each part runs the kernels it names on a small synthetic terrain; a part whose
kernels are cached already takes a fraction of a second.

numba compiles in one thread, so the parts run side by side in worker processes, one per
CPU (``--jobs``), the longest first (:data:`PARTS`' estimates): on 2 cores in 0.57-0.63
of the time of one process. A kernel that two parts share may be compiled in both; numba
writes each cache file to a temporary name and renames it, so the one kept is whole.
"""

from __future__ import annotations

import os
import sys
import time
from collections import namedtuple

from ._common import UsageError

#: The command's line in ``terrainvis --help`` (also its light sub-parser: :func:`terrainvis.cli._parser`).
HELP = "compile every numba kernel now (CI images, containers); later runs load them from numba's cache"


def _viewsheds() -> None:
    import numpy as np

    from ..core.synthetic import synthetic_terrain
    from ..core.terrain import HeightGrid
    from ..visibility import cumulative_viewshed, site_observers, viewshed

    g = synthetic_terrain("hills", size=65, seed=0)
    eye = (float(g.xs[20]), float(g.ys[30]))
    viewshed(g, eye)
    viewshed(g, eye, curvature=0.85714, max_distance=float(g.xs[40]))
    # a float32 raster's grid holds its own samples (HeightGrid.heights): the sweep's float32 kernels
    g32 = HeightGrid._from_coords(g.z.astype(np.float32), g.xs, g.ys, None, owned=True)
    g32.height_at([eye])
    viewshed(g32, eye)
    z = g.z.copy()
    z[5:8, 50:53] = np.nan  # the nodata-aware walks
    viewshed(g.copy_with(z=z), eye)
    cumulative_viewshed(g, np.array([eye, (float(g.xs[40]), float(g.ys[10]))]), progress=False)
    site_observers(g, np.array([eye, (float(g.xs[40]), float(g.ys[10]))]), 1, progress=False)


def _output_modes() -> None:
    from ..core.synthetic import synthetic_terrain
    from ..visibility import viewshed

    g = synthetic_terrain("hills", size=65, seed=0)
    eye = (float(g.xs[20]), float(g.ys[30]))
    viewshed(g, eye, output="min_height")
    viewshed(g.to_tin(), eye, at=g, output="angle")


def _lines_of_sight() -> None:
    from ..core.sampling import sample_points
    from ..core.synthetic import synthetic_terrain
    from ..visibility import fresnel_clearance, line_of_sight, lowest_point, min_clearance, visibility_matrix

    g = synthetic_terrain("hills", size=65, seed=0)
    p = sample_points(g, 20, seed=0, offset=2.0)
    for t in (g, g.to_tin()):
        visibility_matrix(t, p)
        line_of_sight(t, p[:10], p[10:])
        min_clearance(t, p[:10], p[10:], curvature=0.85714)
    lowest_point(g, p[0], p[1])
    fresnel_clearance(g, p[0], p[1], frequency=900e6)


def _methods() -> None:
    from simplifiers import METHODS, simplify

    from ..core.synthetic import synthetic_terrain

    g = synthetic_terrain("hills", size=65, seed=0)
    small = {"visopt": {"n_train": 40, "rounds": 1}}  # its kernels, not its optimisation
    for name, method in METHODS.items():
        if method.module.startswith(("simplifiers.", "terrainvis.")) and not method.module.startswith(
                "simplifiers.peers"):
            simplify(g, name, 1, **small.get(name, {}))
    simplify(g, "greedy-insertion", max_error=5.0)


def _comparison() -> None:
    from ..core.synthetic import synthetic_terrain
    from ..experiment.plan import settings_for
    from ..experiment.units import warm_up_part

    settings = settings_for({"warm-up": synthetic_terrain("hills", size=33, seed=0)}, {})  # the default run's
    for kind in ("grid", "tin", "volume"):
        warm_up_part(("measure", kind, 33), settings)


#: A part of ``terrainvis compile``: what it compiles, the function that runs its kernels, and
#: about how many seconds it compiles alone on this project's 2-core machine (an empty cache,
#: ``python -m terrainvis.cli compile PART --jobs 1``, 30 November 2026): the longest parts start first.
Part = namedtuple("Part", ["what", "run", "seconds"])

#: The parts, in the order one process runs them.
PARTS = {
    "viewshed": Part("viewsheds: the sweep, the nodata-aware walks, cumulative viewsheds, siting", _viewsheds, 24.9),
    "output-modes": Part("a viewshed's heights and angles (the threshold engine's one-eye loops)", _output_modes,
                         6.3),
    "los": Part("lines of sight on grids and TINs, clearances, profiles, Fresnel zones", _lines_of_sight, 5.6),
    "methods": Part("every built-in simplification method", _methods, 28.8),
    "compare": Part("the comparison's measures: every relocation on grids and TINs, the volume", _comparison, 20.0),
}


def add_parser(sub) -> None:
    from .cumulative import workers_arg

    c = sub.add_parser(
        "compile", help=HELP,
        description=("Compile terrainvis's numba kernels now, into numba's on-disk cache (NUMBA_CACHE_DIR, else the "
                     "__pycache__ folders beside the sources), so that the first viewshed, comparison or test of a "
                     "container or CI job does not compile them. Parts: "
                     + "; ".join(f"{k} ({v[0]})" for k, v in PARTS.items()) + "."),
    )
    c.add_argument("parts", nargs="*", metavar="PART", help=f"only these parts (default: all): {', '.join(PARTS)}")
    c.add_argument("--jobs", "-j", type=workers_arg, default=None, metavar="N",
                   help="worker processes compiling parts side by side (default: one per CPU, at most one a part; "
                        "1: in this process)")


def run(args) -> int:
    unknown = [p for p in args.parts if p not in PARTS]
    if unknown:
        raise UsageError(f"PART must be some of {', '.join(PARTS)}, got {', '.join(map(repr, unknown))}")
    names = list(dict.fromkeys(args.parts)) or list(PARTS)
    jobs = min(len(names), args.jobs or os.cpu_count() or 1)
    order = names if jobs == 1 else sorted(names, key=lambda n: -PARTS[n].seconds)  # the longest first
    print(f"terrainvis compile: numba's cache is {_cache_dir()}", file=sys.stderr)
    print(f"terrainvis compile: {', '.join(order)}"
          + (f", {jobs} processes side by side (a part's line comes when it is done)" if jobs > 1 else ""),
          file=sys.stderr, flush=True)
    t_all = time.perf_counter()
    compiled = 0.0

    def done(name, result):
        nonlocal compiled
        took, seconds = result
        compiled += seconds
        state = f"compiled in {seconds:.1f} s" if seconds >= 0.05 else "cached already"
        print(f"  {name:13s} {state} ({took:.1f} s in all): {PARTS[name].what}", flush=True)

    if jobs == 1:
        for name in order:
            done(name, compile_part(name))
    else:
        from ..core.runner import run_units

        run_units([(n, (n,)) for n in order], compile_part, on_result=done, workers=jobs)
    print(f"terrainvis compile: {compiled:.1f} s of compilation, {time.perf_counter() - t_all:.1f} s in all")
    return 0


def compile_part(name: str) -> tuple[float, float]:
    """Run the part ``name``'s kernels (in this process or a worker): its seconds in all and of compilation."""
    from ..core import compiling

    with compiling.quiet():  # the command's own lines say what it compiles
        t0 = time.perf_counter()
        c0 = compiling.seconds()
        PARTS[name].run()
        return time.perf_counter() - t0, compiling.seconds() - c0


def _cache_dir() -> str:
    import numba

    folder = numba.config.CACHE_DIR
    if folder:
        return f"{folder} (NUMBA_CACHE_DIR)"
    from pathlib import Path

    return f"the __pycache__ folders beside terrainvis's sources ({Path(__file__).resolve().parents[1]})"
