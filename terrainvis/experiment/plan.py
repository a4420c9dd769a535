"""Planning a :func:`terrainvis.compare` run: the terrains, the settings, the tasks.

Everything here happens before any unit runs, so a mistake is reported at once:

* :func:`resolve_terrains` turns the ``terrains`` argument into named grids;
* :func:`settings_for` validates the options (:func:`terrainvis.experiment.options.validate`), and
  :func:`check_memory` refuses a run whose units could not fit in memory;
* :func:`tasks` splits the run into tasks, most expensive first; :func:`run_record` is what
  the results file stores about the run (settings and the terrains' fingerprints);
* :func:`warm_up_parts` says what a cold run must compile, in parts two workers can share.

What one unit computes is :mod:`terrainvis.experiment.units`; ordering the rows is
:mod:`terrainvis.experiment.collect`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.validate import describe
from .options import CASCADE_AUTO_MIN_SAMPLES, Settings, budgeted, steps, validate
from ..core.terrain import HeightGrid, fingerprint
from ..io._names import JACKSBORO_WINDOW, resolve_one  # noqa: F401  (resolve_one: the commands' reader)

__all__ = [
    "DEFAULT_TERRAINS", "JACKSBORO_WINDOW", "resolve_terrains", "settings_for", "check_memory", "unit_bytes",
    "tasks", "cascades", "run_record", "fingerprint", "warm_up_parts", "work_order", "compile_seconds",
    "kernels_cached",
]

#: The default terrains: the five bundled 120x120 terrains and a 120x120 window of the real Jacksboro DEM.
DEFAULT_TERRAINS = ("hills", "mesas", "rough", "mountains", "ridges", "jacksboro")

# ---------------------------------------------------------------------- terrains
def resolve_terrains(terrains) -> dict[str, HeightGrid]:
    """Turn the ``terrains`` argument of :func:`~terrainvis.compare` into ``{name: HeightGrid}``.

    Accepted: a HeightGrid; a bundled name (:data:`terrainvis.core.synthetic.BUNDLED`, or
    ``"cumberland"``, the bundled GeoTIFF);
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
def settings_for(grids: dict, values: dict, *, flags: bool = False) -> Settings:
    """The options of a run (name -> value) validated into :class:`~terrainvis.experiment.options.Settings`
    (``flags``: messages name the command line's flags)."""
    return validate(grids, values, flags=flags)


def unit_bytes(settings: Settings, grids: dict) -> int:
    """A lower bound of the memory one unit allocates, in bytes (on the largest terrain): the
    measure's own estimate (:attr:`terrainvis.experiment.measures.Measure.unit_bytes`) and
    each relocation's (:attr:`terrainvis.relocation.Relocation.memory`); the terrains and
    S(T) themselves are not counted."""
    from .measures import MEASURES

    need = int(MEASURES[settings.measure].unit_bytes(settings, grids))
    return need + sum(nbytes for nbytes, _ in _relocation_memory(settings))


def _relocation_memory(settings: Settings) -> list[tuple[int, str]]:
    """``(bytes, what)`` of each relocation of the run that declares its memory."""
    from ..relocation.registry import RELOCATIONS

    out = []
    for name in settings.relocations:
        estimate = RELOCATIONS[name].memory
        if estimate is not None:
            nbytes, what = estimate(settings)
            out.append((int(nbytes), str(what)))
    return out


def check_memory(settings: Settings, grids: dict, at_once: int = 1) -> None:
    """Refuse, before anything is allocated, a run whose units could not fit in the available memory.

    ``at_once`` units run side by side (the local pool's workers).

    Raises
    ------
    terrainvis.errors.NotEnoughMemoryError
        One line: what the units would need, and what the machine has available.
    """
    from ..core.memory import available_memory, format_bytes
    from ..errors import NotEnoughMemoryError

    need = unit_bytes(settings, grids) * max(1, at_once)
    have = available_memory()
    if have is None or need <= have:
        return
    alone = [what for nbytes, what in _relocation_memory(settings) if nbytes > have]
    if alone:
        what = alone[0]
    elif settings.measure == "pairs":
        what = f"n_points={settings.n_points:,} (visibility matrices of {settings.n_points:,}² pairs)"
    else:
        what = f"the {settings.measure} measure on {max(g.size for g in grids.values()):,} samples"
    side_by_side = f" with {at_once} units at once" if at_once > 1 else ""
    raise NotEnoughMemoryError(
        f"{what} needs at least {format_bytes(need)} of memory{side_by_side}, but this machine has "
        f"{format_bytes(have)} available; use fewer points or partners" + (" or fewer workers" if at_once > 1 else "")
    )


def run_record(settings: Settings, grids: dict) -> dict:
    """What the results file stores about a run: every option's value and the terrains' fingerprints."""
    record = settings.as_dict()
    record["terrains"] = {name: fingerprint(g) for name, g in grids.items()}
    return record


# ---------------------------------------------------------------------- tasks
def cascades(settings: Settings, grid: HeightGrid, method: str, *,
             auto_min_samples: int = CASCADE_AUTO_MIN_SAMPLES) -> bool:
    """Whether ``method``'s levels on ``grid`` run as a cascade (each from the previous level's result).

    Never in a run budgeted in vertical error (``max_errors``): each budget is simplified from T.
    """
    from simplifiers import METHODS

    if budgeted(settings) or not METHODS[method].cascades or len(settings.levels) < 2:
        return False
    if settings.cascade == "auto":
        return grid.size > auto_min_samples
    return bool(settings.cascade)


def extensions(settings: Settings) -> tuple:
    """The entries of the run's methods, measure, engine and relocations that were not built in.

    A worker process imports terrainvis afresh and knows only the built-in entries: these
    are sent with every task (:func:`terrainvis.experiment.units.call` installs them).
    """
    import simplifiers.registry as methods

    from ..relocation import registry as relocations
    from ..visibility import engines
    from . import measures

    out = [methods.METHODS[m] for m in settings.methods if m not in methods.BUILTIN]
    out += [relocations.RELOCATIONS[r] for r in settings.relocations if r not in relocations.BUILTIN]
    if settings.measure not in measures.BUILTIN:
        out.append(measures.MEASURES[settings.measure])
    if settings.engine != engines.AUTO and settings.engine not in engines.BUILTIN:
        out.append(engines.ENGINES[settings.engine])
    return tuple(out)


def check_sendable(entries, *, dask: bool) -> None:
    """Refuse, before anything runs, an entry whose function cannot reach the workers.

    A local pool's workers (``dask=False``) get a function by reference (its module and
    name) and import it again: a lambda, a function defined inside another, or one
    defined in an interactive session's ``__main__`` (a notebook, ``python -c``) cannot
    be. A dask cluster (``dask=True``) sends functions with cloudpickle, by value where
    needed: only what cloudpickle cannot serialise is refused.

    Raises
    ------
    TypeError
        Naming the entry, its function and the ways forward.
    """
    import pickle
    import sys

    where = "the dask cluster" if dask else "worker processes"
    for entry in entries:
        fn = next((getattr(entry, a) for a in ("function", "rows", "pairs") if getattr(entry, a, None) is not None),
                  None)
        if fn is None:  # a plugin's Method names a module and an attribute: the workers import it themselves
            continue
        what = f"{type(entry).__name__.lower()} {entry.name!r}"
        name = getattr(fn, "__qualname__", repr(fn))
        advice = ("define it at the top level of a module the workers can import (a file, not a notebook cell), or "
                  "run in this process (workers=1)")
        if dask:
            import cloudpickle

            dumps = cloudpickle.dumps
        else:
            dumps = pickle.dumps
            main = sys.modules.get("__main__")
            if getattr(fn, "__module__", None) == "__main__" and not getattr(main, "__file__", None):
                raise TypeError(f"{what}: its function {name} was defined in an interactive session, which {where} "
                                f"cannot import; {advice}")
        # the function first (the usual culprit), then the rest of the entry (a relocation's run options' checks)
        for part, label in ((fn, f"its function {name}"), (entry, "its entry (a check of its run options?)")):
            try:
                dumps(part)
            except Exception as exc:  # pickle raises PicklingError, AttributeError or TypeError, cloudpickle others
                raise TypeError(f"{what}: {label} cannot be sent to {where} ({exc}); {advice}") from None


def tasks(grids: dict, settings: Settings, done=frozenset(), *,
          auto_min_samples: int = CASCADE_AUTO_MIN_SAMPLES) -> list[tuple]:
    """The tasks as (terrain, method, levels), the most expensive first so the pool stays busy to the end.

    A task is one level, or all the levels of a method that cascades (``settings.cascade``;
    a task of several levels is a cascade). Tasks whose every unit is ``done`` are left
    out; a cascade with some levels done runs them all again (each level starts from the
    previous one), and their rows are dropped. In a run budgeted in vertical error
    (``max_errors``) the third item holds one budget instead of levels: (terrain, method,
    (E,)), and ``done`` holds (terrain, method, E).
    """
    from simplifiers import METHODS

    out = []
    for t in grids:
        for m in settings.methods:
            if cascades(settings, grids[t], m, auto_min_samples=auto_min_samples):
                groups = [tuple(sorted(settings.levels))]
            else:
                groups = [(step,) for step in steps(settings)]
            out += [(t, m, g) for g in groups if any((t, m, lv) not in done for lv in g)]
    return sorted(out, key=lambda u: (-grids[u[0]].size, METHODS[u[1]].cost_rank, u[2]))


# ---------------------------------------------------------------------- compiling
def warm_up_parts(planned, grids: dict, settings: Settings | None = None) -> list[tuple]:
    """What a run must compile, as parts that two workers can compile side by side.

    With a cold numba cache every worker would compile every kernel it meets (about 80 s
    of compilation each for a full run). Compiled once by whichever worker takes the part,
    a kernel is loaded from the on-disk cache by the others. The parts: each method's
    kernels; the measurements on a grid S(T) (which hold the grid line-of-sight engine
    that every unit uses on T), on a TIN S(T) (the rest: TIN walks and relocation) and
    the volume between T and S(T) (unless ``settings.volume`` is off). No two parts
    compile the same kernel when :func:`work_order` runs them: the TIN measure follows
    the grid one (:func:`part_needs`). They go longest first (:data:`COMPILE_SECONDS`,
    measured).
    """
    from simplifiers import METHODS

    methods = sorted({m for _, m, _ in planned}, key=lambda m: METHODS[m].cost_rank)
    kinds = sorted({"grid" if METHODS[m].regular else "tin" for m in methods})
    # Regular methods switch to parallel kernels above a size: warm them on a grid as
    # large as the run's largest (capped; they take milliseconds), the rest on a small one.
    largest = max(g.size for g in grids.values())
    side = min(1024, max(33, int(np.ceil(np.sqrt(largest)))))
    parts = [("method", m, side if METHODS[m].regular else 33) for m in methods]
    parts += [("measure", k, 33) for k in kinds]
    if methods and (settings is None or settings.volume):
        parts.append(("measure", "volume", 33))
    return sorted(parts, key=compile_weight, reverse=True)  # stable: equal weights keep this order


#: CPU seconds to compile each warm-up part's kernels with an empty numba cache, in one
#: process with one numba thread as a worker has, measured on this project's 2-core
#: machine (``python benchmarks/bench_cold_start.py``; "tin" after "grid", whose kernels
#: it then loads). Parts not listed count as the median. The weights of an estimate and
#: of the order of the work (:func:`work_order`); the progress bar rescales them as parts
#: finish.
COMPILE_SECONDS = {
    "grid": 16.2, "greedy-cuts": 9.0, "tin": 4.8, "volume": 3.7, "greedy-insertion": 3.5, "feature": 1.9,
    "gls": 1.9, "lls": 1.2, "qec": 1.1, "simple": 0.8,
}

#: A unit's weight in :func:`work_order` (only orders the units that can start before
#: the last parts are compiled; a quick run's units take about a second each).
UNIT_SECONDS = 1.0


def compile_weight(part: tuple) -> float:
    """The measured compile time of a warm-up part (:data:`COMPILE_SECONDS`; the median when unknown)."""
    known = sorted(COMPILE_SECONDS.values())
    return COMPILE_SECONDS.get(part[1], known[len(known) // 2])


def part_needs(part: tuple, parts) -> list[tuple]:
    """The parts of ``parts`` whose kernels ``part`` also runs: the TIN measure needs the grid
    measure (line of sight on T, the best heights), which it would otherwise compile again."""
    if part[:2] == ("measure", "tin"):
        return [p for p in parts if p[:2] == ("measure", "grid")]
    return []


def unit_needs(task: tuple, parts) -> list[tuple]:
    """The parts a unit of ``task`` = (terrain, method, levels) runs: its method's, the measure on
    its kind of surface (and what that needs) and the volume."""
    from simplifiers import METHODS

    kind = "grid" if METHODS[task[1]].regular else "tin"
    own = [p for p in parts if p[:2] in (("method", task[1]), ("measure", kind), ("measure", "volume"))]
    return own + [q for p in own for q in part_needs(p, parts)]


def work_order(parts, tasks, at_once: int) -> list[tuple]:
    """The warm-up parts and the tasks as one list, in the order a pool of ``at_once`` workers should take them.

    Each item is ``("part", part)`` or ``("task", task)``. A pool hands out work first in,
    first out; :func:`_simulate` plays it with the estimated durations: a worker that
    comes free takes the first item, parts longest first and then the tasks in their
    order, whose parts (:func:`part_needs`, :func:`unit_needs`) are finished by then. So
    no worker compiles a kernel that another is still compiling, and the units of the
    methods compiled first start while the others compile.
    """
    return [item for item, _ in _simulate(parts, tasks, at_once)]


def _simulate(parts, tasks, at_once: int) -> list[tuple]:
    """``(item, finish)`` in the order of :func:`work_order`, with the estimated finish times
    (:data:`COMPILE_SECONDS`, :data:`UNIT_SECONDS`). An item that nothing lets start (its
    parts still compiling on every other worker) is counted from when they are done."""
    items = [("part", p) for p in sorted(parts, key=compile_weight, reverse=True)] + [("task", t) for t in tasks]
    needs = {it: part_needs(it[1], parts) if it[0] == "part" else unit_needs(it[1], parts) for it in items}
    seconds = {it: compile_weight(it[1]) if it[0] == "part" else UNIT_SECONDS for it in items}
    free = [0.0] * max(1, at_once)
    finish: dict = {}
    out = []
    while items:
        w = free.index(min(free))
        ready = [it for it in items if all(finish.get(d, np.inf) <= free[w] for d in needs[it])]
        it = ready[0] if ready else min(items, key=lambda i: max([finish.get(d, np.inf) for d in needs[i]]))
        start = max([free[w]] + [finish.get(d, np.inf) for d in needs[it]])
        finish[it[1] if it[0] == "part" else it] = free[w] = start + seconds[it]
        items.remove(it)
        out.append((it, free[w]))
    return out


def compile_seconds(parts, at_once: int) -> float:
    """An estimate of the wall time ``parts`` take to compile on ``at_once`` workers (:data:`COMPILE_SECONDS`,
    in the order of :func:`work_order`)."""
    return max([finish for _, finish in _simulate(parts, [], at_once)], default=0.0)


def kernels_cached() -> bool | None:
    """Whether numba's on-disk cache already holds the LOS kernels (None when it cannot tell)."""
    try:
        import os

        from ..visibility import _kernels

        return os.path.exists(_kernels.grid_walks._cache._cache_file._index_path)
    except Exception:  # numba internals: a best-effort hint only
        return None

