"""The paper's experiment as one call: :func:`compare`.

For every terrain T, method, level and point set P, :func:`compare` simplifies T into
S(T), computes the visibility matrix of P on T, relocates P onto S(T) in each of the
three ways, computes the visibility matrix there, and counts how many verdicts agree.
It also measures what the paper claimed but never measured: the time and memory that
S(T) saves, and how far its shape is from T.

The run goes in four stages, each in a module of its own:

1. **plan** (:mod:`terrainvis.plan`): every option is validated up front
   (:mod:`terrainvis.options` declares them: methods, levels against each terrain's size,
   relocations, engine, predicate, ...) and the work is split into tasks of one unit (one
   terrain x method x level) or, with ``cascade``, of every level of a method that
   continues from its finer result, the most expensive first;
2. **resume**: with ``out_csv`` the results go to a :class:`~terrainvis.results.ResultStore`,
   which keeps the complete units of an earlier run with the same settings and refuses
   a resume with other settings;
3. **execute**: :func:`terrainvis.runner.run_units` runs the tasks (:mod:`terrainvis.units`
   says what one computes) in this process, on a local process pool or on a dask
   cluster; each finished unit is written at once, atomically, so an interrupt (Ctrl-C,
   SIGTERM) loses no finished unit;
4. **collect** (:mod:`terrainvis.collect`): the rows, sorted (terrains as given, methods
   in the paper's order).

This module keeps every name it had before the split (users' code imports them from here).
"""

from __future__ import annotations

import inspect
import os
import sys

import pandas as pd

from .collect import COLUMNS, TIMING_COLUMNS, UNIT_KEY, order, rows_per_unit, table  # noqa: F401
from .options import (  # noqa: F401
    CASCADE_AUTO_MIN_SAMPLES, DEFAULTS, DISTANCE_UNITS, MEASURES, OPTIONS, PREDICATES, Settings,
    docstring_section, signature_parameters,
)
from .plan import DEFAULT_TERRAINS, JACKSBORO_WINDOW, cascades, fingerprint, resolve_terrains, run_record  # noqa: F401
from .plan import kernels_cached as _kernels_cached
from .plan import resolve_one as _resolve_one  # noqa: F401
from .plan import settings_for
from .plan import tasks as _plan_tasks
from .plan import warm_up_parts as _warm_up_parts
from .units import call as _call
from .units import end_radius_for, point_sets, simplified_path  # noqa: F401
from .units import observers as _observers  # noqa: F401
from .units import run_unit as _run_unit
from .units import warm_up as _warm_up
from .units import warm_up_part as _warm_up_part  # noqa: F401

__all__ = [
    "compare", "Settings", "DEFAULTS", "resolve_terrains", "point_sets", "DEFAULT_TERRAINS", "JACKSBORO_WINDOW",
    "COLUMNS", "PREDICATES", "DISTANCE_UNITS", "MEASURES", "simplified_path", "end_radius_for",
]

# Names kept for code written against the module before it was split.
_fingerprint = fingerprint
_order = order


def _settings(grids: dict, **options) -> Settings:
    """Validate the options of :func:`compare` (before any unit runs) into :class:`Settings`."""
    return settings_for(grids, options)


def _tasks(grids: dict, settings: Settings, done=frozenset()) -> list[tuple]:
    """The tasks of a run (:func:`terrainvis.plan.tasks`), cascading above :data:`CASCADE_AUTO_MIN_SAMPLES`
    as this module holds it when called."""
    return _plan_tasks(grids, settings, done, auto_min_samples=CASCADE_AUTO_MIN_SAMPLES)


# ---------------------------------------------------------------------- compare
def compare(terrains=DEFAULT_TERRAINS, *, workers: int | None = None, client=None, out_csv=None,
            resume: bool = False, save_dir=None, progress: bool = False, **options) -> pd.DataFrame:
    """Run the paper's experiment: how many LOS verdicts survive each simplification.

    Parameters
    ----------
    terrains : terrain or list or dict
        See :func:`resolve_terrains`. Default: the five bundled 120x120 terrains and the
        central 120x120 window of the Jacksboro DEM.
    <options>
    workers : int, optional
        Processes of the local pool (default: the number of CPUs; 1 runs in this process).
        Workers are started with ``spawn``, which imports the caller's ``__main__``
        module again: in a script, call :func:`compare` under
        ``if __name__ == "__main__":`` (notebooks and the CLI need nothing).
    client : dask.distributed.Client, optional
        Run the units on this cluster instead (needs the ``dask`` extra).
    out_csv : str or Path, optional
        Write each finished unit's rows to this CSV at once (atomically; the settings go
        beside it, see :class:`~terrainvis.results.ResultStore`).
    resume : bool
        With ``out_csv``: keep the units already completed there (with the same
        settings) and run only the rest.
    save_dir : str or Path, optional
        Save every simplified terrain there (:func:`simplified_path`,
        :func:`terrainvis.load_terrain`).
    progress : bool
        Show a progress bar (and a note when numba compiles its kernels) on stderr.

    The options (between ``terrains`` and ``workers``) are declared in
    :data:`terrainvis.options.OPTIONS`; their defaults are :data:`DEFAULTS`.

    Returns
    -------
    pandas.DataFrame
        One row per terrain x point set x method x level x relocation (x distance), with the columns
        :data:`COLUMNS`, sorted (terrains as given, methods in the paper's order,
        relocations identity, full, half). A unit whose simplification failed keeps its
        rows, with the message in ``error`` and NaN measurements.

    Raises
    ------
    terrainvis.runner.Interrupted
        On Ctrl-C or SIGTERM; the units finished before are in ``out_csv``.

    Examples
    --------
    >>> df = compare(["hills"], methods=["lls"], levels=[1], n_points=10, n_sets=1, workers=1)
    >>> len(df), list(df["relocation"])
    (3, ['identity', 'full', 'half'])
    """
    from .runner import check_client, check_workers

    if terrains is None:
        raise TypeError("terrains must be a terrain, a list of terrains or a dict of them, got None")
    grids = resolve_terrains(terrains)
    settings = _settings(grids, **options)
    workers = check_workers(workers)
    client = check_client(client)

    store, done = _store(out_csv, settings, grids, resume)
    tasks = _tasks(grids, settings, done)
    if save_dir is not None:
        from ._fileio import check_writable_dir

        save_dir = str(check_writable_dir(save_dir, "save_dir"))
    new_rows = _execute(tasks, grids, settings, done, store, save_dir=save_dir, workers=workers, client=client,
                        progress=progress)
    rows = store.rows() if store is not None else table(new_rows)
    df = order(rows, grids)
    if store is not None:
        store.finish(df)
    return df


def _store(out_csv, settings: Settings, grids: dict, resume: bool):
    """The results file of a run with ``out_csv`` (None without), and the units it holds already."""
    if out_csv is None:
        return None, frozenset()
    from .results import ResultStore

    per_unit = rows_per_unit(settings)
    # a settings file written before an option existed ran it at its default
    absent = {name: option.check(option.default, name) for name, option in OPTIONS.items()}
    store = ResultStore(out_csv, run_record(settings, grids), COLUMNS, UNIT_KEY, lambda key: per_unit, resume=resume,
                        absent=absent)
    return store, frozenset(store.done)


def _execute(tasks, grids, settings, done, store, *, save_dir, workers, client, progress) -> list[dict]:
    """Run the tasks (after the warm-up parts of a cold numba cache); every finished unit goes to ``store``."""
    from tqdm.auto import tqdm

    from .runner import run_units

    todo = sum(1 for t, m, levels in tasks for lv in levels if (t, m, lv) not in done)
    cold = bool(tasks) and _kernels_cached() is False
    if progress and cold:
        tqdm.write("terrainvis: compiling numba kernels (first run only, under a minute)...", file=sys.stderr)
    bar = tqdm(total=todo, desc="compare", unit="unit", file=sys.stderr, disable=not (progress and tasks))
    new_rows: list[dict] = []

    def collect(key, rows):
        if key[0] == "warm-up":
            return
        rows = [r for r in rows if (r["terrain"], r["method"], r["level"]) not in done]
        new_rows.extend(rows)
        if store is not None:
            store.add(rows)
        bar.update(len({r["level"] for r in rows}))

    work = [((t, m, g), (_run_unit, grids[t], t, m, g, settings, save_dir)) for t, m, g in tasks]
    n_local = (os.cpu_count() or 1) if workers is None else workers
    if cold and client is None and n_local > 1 and len(work) > 1:
        work = [(("warm-up", part), (_warm_up, part, settings)) for part in _warm_up_parts(tasks, grids)] + work
    try:
        run_units(work, _call, on_result=collect, workers=workers, client=client)
    finally:
        bar.close()
    return new_rows


def _signature() -> inspect.Signature:
    """:func:`compare`'s signature with every declared option as a keyword-only parameter."""
    own = inspect.signature(compare, follow_wrapped=False)
    params = [p for p in own.parameters.values() if p.kind is not inspect.Parameter.VAR_KEYWORD]
    return own.replace(parameters=params[:1] + signature_parameters() + params[1:])


compare.__doc__ = compare.__doc__.replace("    <options>", docstring_section())
compare.__signature__ = _signature()
