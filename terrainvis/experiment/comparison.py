"""The paper's experiment as one call: :func:`compare`.

For every terrain T, method, level and point set P, :func:`compare` simplifies T into
S(T), computes the visibility matrix of P on T, relocates P onto S(T) with each
relocation of the run (:data:`terrainvis.relocation.RELOCATIONS`), computes the
visibility matrix there, and counts how many verdicts agree (the measure,
:mod:`terrainvis.experiment.measures`, may count viewshed cells instead).
It also measures what the paper claimed but never measured: the time and memory that
S(T) saves, and how far its shape is from T.

The run goes in four stages, each in a module of its own:

1. **plan** (:mod:`terrainvis.experiment.plan`): every option is validated up front
   (:mod:`terrainvis.experiment.options` declares them: methods, levels against each terrain's size,
   relocations, engine, predicate, ...) and the work is split into tasks of one unit (one
   terrain x method x level, or x budget E with ``max_errors``) or, with ``cascade``, of
   every level of a method that continues from its finer result, the most expensive first;
2. **resume**: with ``out_csv`` the results go to a :class:`~terrainvis.experiment.results.ResultStore`,
   which keeps the complete units of an earlier run with the same settings and refuses
   a resume with other settings;
3. **execute**: :func:`terrainvis.core.runner.run_units` runs the tasks (:mod:`terrainvis.experiment.units`
   says what one computes) in this process, on a local process pool or on a dask
   cluster; each finished unit is written at once, atomically, so an interrupt (Ctrl-C,
   SIGTERM) loses no finished unit;
4. **collect** (:mod:`terrainvis.experiment.collect`): the rows, sorted (terrains as given, methods
   in the paper's order).
"""

from __future__ import annotations

import contextlib
import inspect
import os
import sys

import pandas as pd

from ..core import compiling as _compiling
from ..core._progress import progress_bar_class
from ..core.validate import describe
from ..relocation.registry import RELOCATIONS
from .measures import MEASURES
from .collect import COLUMNS, columns, optional_columns, order, rows_per_unit, table, unit_key
from .options import (
    CASCADE_AUTO_MIN_SAMPLES,
    DEFAULTS,
    DISTANCE_UNITS,
    OPTIONS,
    PREDICATES,
    Settings,
    docstring_section,
    signature_parameters,
    steps,
)
from .plan import DEFAULT_TERRAINS, JACKSBORO_WINDOW, resolve_terrains, run_record
from . import plan as _plan  # kernels_cached is read at call time: a test stands in for a fresh install
from .plan import check_memory, check_sendable, extensions, settings_for
from .plan import tasks as _plan_tasks
from .plan import warm_up_parts as _warm_up_parts
from .units import call as _call
from .measures import point_sets
from .units import end_radius_for, simplified_path
from .units import run_unit
from .units import warm_up as _warm_up

__all__ = [
    "compare", "Settings", "DEFAULTS", "resolve_terrains", "point_sets", "DEFAULT_TERRAINS", "JACKSBORO_WINDOW",
    "COLUMNS", "PREDICATES", "DISTANCE_UNITS", "MEASURES", "simplified_path", "end_radius_for",
]

def _settings(grids: dict, **options) -> Settings:
    """Validate the options of :func:`compare` (before any unit runs) into :class:`Settings`."""
    return settings_for(grids, options)


def _tasks(grids: dict, settings: Settings, done=frozenset()) -> list[tuple]:
    """The tasks of a run (:func:`terrainvis.experiment.plan.tasks`), cascading above :data:`CASCADE_AUTO_MIN_SAMPLES`
    as this module holds it when called."""
    return _plan_tasks(grids, settings, done, auto_min_samples=CASCADE_AUTO_MIN_SAMPLES)


# ---------------------------------------------------------------------- compare
def compare(terrains=DEFAULT_TERRAINS, *, workers: int | None = None, client=None, out_csv=None,
            resume: bool = False, save_dir=None, progress: bool | None = None, on_unit=None,
            **options) -> pd.DataFrame:
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
        beside it, see :class:`~terrainvis.experiment.results.ResultStore`).
    resume : bool
        With ``out_csv``: keep the units already completed there (with the same
        settings) and run only the rest.
    save_dir : str or Path, optional
        Save every simplified terrain there (:func:`simplified_path`,
        :func:`terrainvis.load_terrain`).
    progress : bool, optional
        Show the progress on stderr: on a cold numba cache, first what is being compiled
        with an estimate of how long, then the units. None (the default) shows it where
        someone watches, tqdm's convention: on a terminal (bars redrawn in place) or in
        Jupyter (a widget with ipywidgets); True shows it anywhere, as plain lines when
        stderr is a file; False never.
    on_unit : callable, optional
        ``on_unit(key, rows)``, called in this process as each unit finishes, after its
        rows are stored in ``out_csv``: ``key`` is ``(terrain, method, levels)`` (a tuple
        of the levels the unit ran: one, or several when ``cascade`` chains them; with
        ``max_errors``, ``(terrain, method, (E,))``, the unit's budget) and
        ``rows`` a DataFrame of its rows (the columns :func:`~terrainvis.experiment.collect.columns`). For live
        figures, logs, or a stop rule: an exception it raises ends the run as an
        interrupt does (the units stored so far stay in ``out_csv``; ``resume=True``
        continues).

    The options (between ``terrains`` and ``workers``) are declared in
    :data:`terrainvis.experiment.options.OPTIONS`; their defaults are :data:`DEFAULTS`.

    Budgets in maximum vertical error (``max_errors=[E, ...]``) replace the levels: each
    method is simplified to its smallest result within each E
    (:func:`simplifiers.simplify` with ``max_error=E``), a unit is terrain x method x E,
    each row has E in ``max_error_budget`` and in ``stopped_by`` whether the result met it
    (``"max_error"``), and ``cascade`` does not apply (``"auto"`` never cascades budgets;
    ``True`` is refused).

    Returns
    -------
    pandas.DataFrame
        One row per terrain x point set x method x level (or budget) x relocation (x distance), with the columns
        :func:`~terrainvis.experiment.collect.columns` (:data:`COLUMNS` with the measures terrainvis
        ships), sorted (terrains as given, methods in the paper's order,
        relocations identity, full, half). A unit whose simplification failed keeps its
        rows, with the message in ``error`` and NaN measurements; the ``error`` of a unit that did
        not fail is missing (NA), as in ``results.csv`` read back.

    Raises
    ------
    terrainvis.core.runner.Interrupted
        On Ctrl-C or SIGTERM; the units finished before are in ``out_csv``.
    terrainvis.core.fileio.OutputBusyError
        Another process is writing ``out_csv`` (a ValueError naming its pid and start time).
    MemoryError
        Before anything runs, when the units could not fit in the available memory
        (:func:`terrainvis.experiment.plan.check_memory`).

    Examples
    --------
    >>> df = compare(["hills"], methods=["lls"], levels=[1], n_points=10, n_sets=1, workers=1)
    >>> len(df), list(df["relocation"])
    (4, ['identity', 'full', 'half', 'calibrated'])
    """
    from ..core.runner import check_client, check_workers

    if terrains is None:
        raise TypeError("terrains must be a terrain, a list of terrains or a dict of them, got None")
    if resume and out_csv is None:
        raise ValueError("resume=True continues the run stored in out_csv; give out_csv (the results file to resume)")
    if on_unit is not None and not callable(on_unit):
        raise TypeError(f"on_unit must be a function of (key, rows) or None, got {describe(on_unit)}")
    grids = resolve_terrains(terrains)
    settings = _settings(grids, **options)
    workers = check_workers(workers)
    client = check_client(client)
    at_once = _at_once(settings, grids, workers, client)
    check_memory(settings, grids, at_once)
    if client is not None or at_once > 1:  # the units will run in other processes
        check_sendable(extensions(settings), dask=client is not None)

    with _lock(out_csv):
        store, done = _store(out_csv, settings, grids, resume)
        tasks = _tasks(grids, settings, done)
        if save_dir is not None:
            from ..core.fileio import check_writable_dir

            save_dir = str(check_writable_dir(save_dir, "save_dir"))
            _remove_partial_saves(save_dir)  # left by an earlier run that was killed mid-write
        try:
            new_rows = _execute(tasks, grids, settings, done, store, save_dir=save_dir, workers=workers,
                                client=client, progress=progress, on_unit=on_unit)
        finally:
            if save_dir is not None:  # a worker stopped mid-write (a full disk, a kill) leaves its temporary file
                _remove_partial_saves(save_dir)
        rows = store.rows() if store is not None else table(new_rows)
        df = order(rows, grids)
        if store is not None:
            store.finish(df)
    return df


def _remove_partial_saves(save_dir) -> list[str]:
    """Remove the temporary files of simplified terrains that were never finished in ``save_dir``.

    A save writes ``.NAME.XXXXXXXX.npz`` beside ``NAME`` (:func:`terrainvis.core.fileio.atomic_path`)
    and renames it when complete. A worker killed mid-write cannot remove it. Only names
    of that exact form whose NAME is a simplified terrain's
    (:func:`~terrainvis.experiment.units.simplified_path`) are removed; the user's own
    files are left alone. Returns the names removed.
    """
    import os
    import re

    pattern = re.compile(r"^\.(?P<target>[^/]+__[^/]+__(level\d+|max_error[0-9.e+-]+)\.npz)\.[A-Za-z0-9_]{6,}\.npz$")
    removed = []
    with os.scandir(save_dir) as entries:
        for entry in entries:
            if pattern.match(entry.name) and entry.is_file(follow_symlinks=False):
                try:
                    os.unlink(entry.path)
                    removed.append(entry.name)
                except OSError:
                    pass
    return removed


def _lock(out_csv):
    """The run's hold on ``out_csv`` (``results.lock`` beside it): a second run writing it is refused."""
    import contextlib
    from pathlib import Path

    if out_csv is None:
        return contextlib.nullcontext()
    from ..core.fileio import RunLock
    from .results import lock_path

    path = Path(out_csv)
    if not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    return RunLock(lock_path(path), f"out_csv {str(path)!r}", "compare()")


def _at_once(settings: Settings, grids: dict, workers, client) -> int:
    """How many units may run side by side on this machine (a dask cluster's workers have their own memory)."""
    if client is not None:
        return 1
    n_local = (os.cpu_count() or 1) if workers is None else workers
    return max(1, min(n_local, len(grids) * len(settings.methods) * len(steps(settings))))


def _store(out_csv, settings: Settings, grids: dict, resume: bool):
    """The results file of a run with ``out_csv`` (None without), and the units it holds already."""
    if out_csv is None:
        return None, frozenset()
    from .results import ResultStore

    per_unit = rows_per_unit(settings)
    # a settings file written before an option existed ran it at its default
    absent = {name: option.check(option.default, name) for name, option in OPTIONS.items()}
    # a results file written before a measure's columns existed resumes when this measure leaves them empty
    store = ResultStore(out_csv, run_record(settings, grids), columns(), unit_key(settings), lambda key: per_unit,
                        resume=resume, absent=absent, optional=optional_columns(settings.measure))
    return store, frozenset(store.done)


def _execute(tasks, grids, settings, done, store, *, save_dir, workers, client, progress, on_unit=None) -> list[dict]:
    """Run the tasks (after the warm-up parts of a cold numba cache); every finished unit goes to ``store``."""
    from ..core._progress import show_by_default
    from ..core.runner import run_units

    progress = show_by_default() if progress is None else bool(progress)
    from .plan import work_order

    todo = sum(1 for t, m, levels in tasks for lv in levels if (t, m, lv) not in done)
    step = unit_key(settings)[-1]  # the rows' column of a task's levels: level, or the budget
    n_local = (os.cpu_count() or 1) if workers is None else workers
    cold = bool(tasks) and client is None and _plan.kernels_cached() is False
    parts = _warm_up_parts(tasks, grids, settings) if cold and ((n_local > 1 and len(tasks) > 1) or progress) else []
    # the parts and the units interleaved so that no two workers compile the same kernels
    sent = extensions(settings)
    work = [(("warm-up", x), (sent, _warm_up, x, settings)) if kind == "part" else
            (x, (sent, run_unit, grids[x[0]], x[0], x[1], x[2], settings, save_dir))
            for kind, x in work_order(parts, tasks, min(n_local, len(parts) + len(tasks)))]
    bars = _Progress(progress and bool(tasks), parts, todo, min(n_local, len(work)))
    new_rows: list[dict] = []

    def collect(key, rows):
        if key[0] == "warm-up":
            bars.compiled(key[1])
            return
        rows = [r for r in rows if (r["terrain"], r["method"], r[step]) not in done]
        new_rows.extend(rows)
        if store is not None:
            store.add(rows)
        bars.finished(len({r[step] for r in rows}))
        if on_unit is not None and rows:
            on_unit(key, pd.DataFrame(rows, columns=list(columns())))

    # with its progress shown, compare says what it compiles itself (the parts), not kernel by kernel
    quiet = _compiling.quiet() if bars.show else contextlib.nullcontext()
    try:
        with quiet:
            run_units(work, _call, on_result=collect, workers=workers, client=client)
    finally:
        bars.close()
    return new_rows


class _Progress:
    """The progress shown on stderr: the kernels being compiled (a cold cache), then the units.

    On a terminal or in Jupyter, bars: the compile bar names each part as it finishes and
    closes when the last one has (it is not left open to the end); its first estimate
    comes from the compile times measured on this project's machine
    (:func:`terrainvis.experiment.plan.compile_seconds`), rescaled as parts finish by how
    fast this machine compiles them. Into a file (a log), plain lines instead of bars
    redrawn in place (two bars there leave cursor escapes): the compiling's start and
    end, and the units done, at most every 10 s and at the end.
    """

    #: Seconds between the plain lines of the units' progress in a log.
    LINE_EVERY = 10.0

    def __init__(self, show: bool, parts: list, units: int, at_once: int):
        import time

        from ..core._progress import in_kernel, on_a_terminal
        from .plan import compile_seconds, compile_weight

        self.show = show
        self.bars = show and (on_a_terminal() or in_kernel())
        self.compile = None
        self.units = None
        self.weight = compile_weight
        self.n_parts, self.parts_done = len(parts), 0
        self.left = sum(map(compile_weight, parts))
        self.done = 0.0
        self.total, self.count = units, 0
        self.start = self.last_line = time.perf_counter()
        tqdm = progress_bar_class()
        if show and parts:
            estimate = compile_seconds(parts, at_once)
            self._say(f"terrainvis: first run: compiling the numba kernels this run needs ({len(parts)} parts, "
                      f"about {estimate:.0f} s on this project's shared 2-core machine; later runs load them "
                      "from numba's cache)", tqdm)
            if self.bars:
                self.compile = tqdm(total=len(parts), desc="compiling", unit="part", file=sys.stderr)
        if self.bars:
            self.units = tqdm(total=units, desc="compare", unit="unit", file=sys.stderr)

    def _say(self, line: str, tqdm=None) -> None:
        if tqdm is not None:
            tqdm.write(line, file=sys.stderr)  # above any bar being drawn
        else:
            print(line, file=sys.stderr, flush=True)

    def compiled(self, part: tuple) -> None:
        import time

        if not self.show or not self.n_parts:
            return
        self.parts_done += 1
        w = self.weight(part)
        self.done, self.left = self.done + w, max(0.0, self.left - w)
        if self.compile is not None:
            rate = (time.perf_counter() - self.start) / self.done if self.done else 0.0
            note = f"{part[1]} done" + (f", about {self.left * rate:.0f} s left" if self.left else "")
            self.compile.set_postfix_str(note, refresh=False)
            self.compile.update(1)
        if self.parts_done == self.n_parts:
            if self.compile is not None:
                self.compile.close()
                self.compile = None
            else:
                self._say(f"terrainvis: compiled the kernels ({self.n_parts} parts) in "
                          f"{time.perf_counter() - self.start:.0f} s")

    def finished(self, n: int) -> None:
        import time

        self.count += n
        if self.units is not None:
            self.units.update(n)
        elif self.show:
            now = time.perf_counter()
            if self.count >= self.total or now - self.last_line >= self.LINE_EVERY:
                self.last_line = now
                self._say(f"compare: {self.count}/{self.total} units, {now - self.start:.0f} s")

    def close(self) -> None:
        for bar in (self.compile, self.units):
            if bar is not None:
                bar.close()


def _signature() -> inspect.Signature:
    """:func:`compare`'s signature with every declared option as a keyword-only parameter."""
    compare.__signature__ = None  # (the one set before would be read back)
    own = inspect.signature(compare, follow_wrapped=False)
    params = [p for p in own.parameters.values() if p.kind is not inspect.Parameter.VAR_KEYWORD]
    return own.replace(parameters=params[:1] + signature_parameters() + params[1:])


_DOC = compare.__doc__


def _describe() -> None:
    """:func:`compare`'s docstring and signature from the options declared now; again whenever a
    relocation is registered or removed (its own options are compare's keywords while it is)."""
    compare.__doc__ = _DOC.replace("    <options>", docstring_section())
    compare.__signature__ = _signature()


_describe()
RELOCATIONS.watch(_describe)
