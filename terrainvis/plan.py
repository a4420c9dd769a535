"""Planning a :func:`terrainvis.compare` run: the terrains, the settings, the tasks.

Everything here happens before any unit runs, so a mistake is reported at once:

* :func:`resolve_terrains` turns the ``terrains`` argument into named grids;
* :func:`settings_for` validates the options (:func:`terrainvis.options.validate`);
* :func:`tasks` splits the run into tasks, most expensive first; :func:`run_record` is what
  the results file stores about the run (settings and the terrains' fingerprints);
* :func:`warm_up_parts` says what a cold run must compile, in parts two workers can share.

What one unit computes is :mod:`terrainvis.units`; ordering the rows is
:mod:`terrainvis.collect`.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from ._validate import describe
from .options import CASCADE_AUTO_MIN_SAMPLES, Settings, validate
from .terrain import HeightGrid

__all__ = [
    "DEFAULT_TERRAINS", "JACKSBORO_WINDOW", "resolve_terrains", "settings_for",
    "tasks", "cascades", "run_record", "fingerprint", "warm_up_parts", "kernels_cached",
]

#: The default terrains: the five bundled 120x120 terrains and a 120x120 window of the real Jacksboro DEM.
DEFAULT_TERRAINS = ("hills", "mesas", "rough", "mountains", "ridges", "jacksboro")

#: Rows and columns of the 344x403 Jacksboro DEM used as the "jacksboro" terrain: its
#: central 120x120 window at the native 74.57 m x 92.47 m cells (8.9 km x 11.0 km). A
#: window keeps the real sampling; resampling the whole DEM to 120x120 would smooth it.
JACKSBORO_WINDOW = ((112, 232), (141, 261))


# ---------------------------------------------------------------------- terrains
def resolve_one(name, t, i):
    """``(name, HeightGrid)`` for one entry of the ``terrains`` argument (``name`` None: derived)."""
    from .synthetic import BUNDLED, bundled_terrain

    if isinstance(t, HeightGrid):
        return name or t.attrs.get("name") or f"terrain{i}", t
    if not isinstance(t, (str, Path)):
        raise TypeError(f"terrains must hold HeightGrids, names or paths, got {describe(t)}")
    text = str(t)
    known = list(BUNDLED) + ["jacksboro"]
    if text in BUNDLED:
        return name or text, bundled_terrain(text)
    if text == "jacksboro":
        return name or text, _jacksboro()
    if Path(text).suffix:
        if not Path(text).exists():
            raise ValueError(f"terrain {text!r} is neither a bundled terrain {known} nor an existing file")
        from .io import load_dem

        return name or Path(text).stem, load_dem(text)
    raise ValueError(f"terrain must be a bundled terrain {known}, a DEM file or a HeightGrid, got {text!r}")


def _jacksboro() -> HeightGrid:
    from .io import sample_dem

    (r0, r1), (c0, c1) = JACKSBORO_WINDOW
    grid = sample_dem("jacksboro").crop(rows=(r0, r1), cols=(c0, c1))
    grid.attrs["name"] = "jacksboro"
    return grid


def resolve_terrains(terrains) -> dict[str, HeightGrid]:
    """Turn the ``terrains`` argument of :func:`~terrainvis.compare` into ``{name: HeightGrid}``.

    Accepted: a HeightGrid; a bundled name (:data:`terrainvis.synthetic.BUNDLED`);
    ``"jacksboro"`` (see :data:`JACKSBORO_WINDOW`); a path to a DEM file (any format of
    :func:`terrainvis.load_dem`; named by its stem); a list of these; or a dict
    ``{name: HeightGrid or str}``. Every terrain must be free of nodata.
    """
    if isinstance(terrains, (HeightGrid, str, Path)):
        terrains = [terrains]
    if isinstance(terrains, dict):
        items = list(terrains.items())
    elif isinstance(terrains, (list, tuple)):
        items = [(None, t) for t in terrains]
    else:
        raise TypeError(
            "terrains must be a terrain (HeightGrid, bundled name or DEM path), a list of them or a dict "
            f"{{name: terrain}}, got {describe(terrains)}"
        )
    if not items:
        raise ValueError("terrains must name at least one terrain, got an empty collection")
    out: dict[str, HeightGrid] = {}
    for i, (name, t) in enumerate(items):
        name, grid = resolve_one(name, t, i)
        name = str(name)
        if name in out:
            raise ValueError(f"terrain names must be unique, got {name!r} twice")
        grid.require_finite(f"compare (terrain {name!r})")
        out[name] = grid
    return out


# ---------------------------------------------------------------------- settings
def settings_for(grids: dict, values: dict) -> Settings:
    """The options of a run (name -> value) validated into :class:`~terrainvis.options.Settings`."""
    return validate(grids, values)


def fingerprint(grid: HeightGrid) -> str:
    """A content hash of a terrain (z, xs, ys), so a resume notices a changed input."""
    h = hashlib.sha256()
    for a in (grid.z, grid.xs, grid.ys):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def run_record(settings: Settings, grids: dict) -> dict:
    """What the results file stores about a run: every option's value and the terrains' fingerprints."""
    record = settings.as_dict()
    record["terrains"] = {name: fingerprint(g) for name, g in grids.items()}
    return record


# ---------------------------------------------------------------------- tasks
def cascades(settings: Settings, grid: HeightGrid, method: str, *,
             auto_min_samples: int = CASCADE_AUTO_MIN_SAMPLES) -> bool:
    """Whether ``method``'s levels on ``grid`` run as a cascade (each from the previous level's result)."""
    from simplifiers import METHODS

    if not METHODS[method].cascades or len(settings.levels) < 2:
        return False
    if settings.cascade == "auto":
        return grid.size > auto_min_samples
    return bool(settings.cascade)


def tasks(grids: dict, settings: Settings, done=frozenset(), *,
          auto_min_samples: int = CASCADE_AUTO_MIN_SAMPLES) -> list[tuple]:
    """The tasks as (terrain, method, levels), the most expensive first so the pool stays busy to the end.

    A task is one level, or all the levels of a method that cascades (``settings.cascade``;
    a task of several levels is a cascade). Tasks whose every unit is ``done`` are left
    out; a cascade with some levels done runs them all again (each level starts from the
    previous one), and their rows are dropped.
    """
    from simplifiers import METHODS

    out = []
    for t in grids:
        for m in settings.methods:
            if cascades(settings, grids[t], m, auto_min_samples=auto_min_samples):
                groups = [tuple(sorted(settings.levels))]
            else:
                groups = [(lv,) for lv in settings.levels]
            out += [(t, m, g) for g in groups if any((t, m, lv) not in done for lv in g)]
    return sorted(out, key=lambda u: (-grids[u[0]].size, METHODS[u[1]].cost_rank, u[2]))


# ---------------------------------------------------------------------- compiling
def warm_up_parts(planned, grids: dict) -> list[tuple]:
    """What a run must compile, as parts that two workers can compile side by side.

    With a cold numba cache every worker would compile every kernel it meets (about 80 s
    of compilation each for a full run). Compiled once by whichever worker takes the part,
    a kernel is loaded from the on-disk cache by the others. The parts: each method's
    kernels, and the measurements on a grid and on a TIN (line of sight, relocation, volume,
    viewshed). Greedy cuts' kernels take the longest to compile (about 30 s) and go first,
    the rest follow in the order the pool takes them.
    """
    from simplifiers import METHODS

    methods = sorted({m for _, m, _ in planned}, key=lambda m: METHODS[m].cost_rank)
    kinds = sorted({"grid" if METHODS[m].regular else "tin" for m in methods})
    # Regular methods switch to parallel kernels above a size: warm them on a grid as
    # large as the run's largest (capped; they take milliseconds), the rest on a small one.
    largest = max(g.size for g in grids.values())
    side = min(1024, max(33, int(np.ceil(np.sqrt(largest)))))
    parts = [("method", m, side if METHODS[m].regular else 33) for m in methods]
    return parts[:1] + [("measure", k, 33) for k in kinds] + parts[1:]


def kernels_cached() -> bool | None:
    """Whether numba's on-disk cache already holds the LOS kernels (None when it cannot tell)."""
    try:
        import os

        from .visibility import _kernels

        return os.path.exists(_kernels.grid_matrix._cache._cache_file._index_path)
    except Exception:  # numba internals: a best-effort hint only
        return None

