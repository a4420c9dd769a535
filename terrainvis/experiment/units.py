"""What one unit of a :func:`terrainvis.compare` run computes.

A *unit* is one terrain x method x level (or x budget E, in a run budgeted in maximum
vertical error: ``max_errors``): it simplifies T once into S(T), then, for each
point set (or observer) and relocation, computes the verdicts on T and on S(T) and counts
how many agree (:func:`terrainvis.agreement`, :func:`terrainvis.core.metrics.viewshed_agreement`).
A *task* (:func:`run_unit`) is one unit, or every level of a cascade. Each task returns its
rows (dicts of :data:`terrainvis.experiment.collect.COLUMNS`); a failure is recorded in the rows'
``error`` column and the run goes on.

These functions run in the worker processes; they read the run's options from
:class:`~terrainvis.experiment.options.Settings` only.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .measures import MEASURES
from .options import Settings, budgeted, sight
from ..core.terrain import HeightGrid

__all__ = [
    "end_radius_for", "nearest_level", "simplified_path", "run_unit", "measured_rows", "failed_rows", "stopped_by",
    "call", "install", "warm_up", "warm_up_part",
]


# ---------------------------------------------------------------------- the predicate and the files
def end_radius_for(simplified, original: HeightGrid, level: int | None, predicate: str) -> float:
    """The end radius of the verdicts on S(T) under ``predicate`` (0 for ``"exact"``).

    ``"paper"``: one cell of the surface under test. For a grid, its larger mean cell
    side; for a TIN, the larger cell side of the regular grid with the same vertex
    budget (the regular result at the same level; a TIN without a level, simplified to a
    maximum vertical error, takes the level whose budget is nearest its vertex count:
    :func:`nearest_level`).
    """
    if predicate == "exact":
        return 0.0
    if isinstance(simplified, HeightGrid):
        return float(max(simplified.dx, simplified.dy))
    from simplifiers.levels import coarse_shape

    if level is None or level != level:  # None, or NaN as a table holds it
        level = nearest_level(original.shape, simplified.n_vertices)
    rows, cols = coarse_shape(original.shape, level)
    xmin, xmax, ymin, ymax = original.extent
    return float(max((xmax - xmin) / max(cols - 1, 1), (ymax - ymin) / max(rows - 1, 1)))


def nearest_level(shape, n_vertices: int) -> int:
    """The level whose vertex budget (:func:`simplifiers.levels.vertex_budget`) is nearest ``n_vertices``
    on a grid of ``shape`` (in ratio; the finer of two as near)."""
    from simplifiers.levels import max_level, vertex_budget

    levels = range(0, max_level(shape) + 1)
    return min(levels, key=lambda lv: (abs(np.log(vertex_budget(shape, lv) / max(n_vertices, 1))), lv))


def simplified_path(save_dir, name: str, method: str, level: int | None, *, max_error: float | None = None) -> Path:
    """Where :func:`~terrainvis.compare` saves the simplified terrain of terrain ``name`` when given ``save_dir``.

    ``<name>__<method>__level<k>.npz``, or with ``max_error`` (a run budgeted in vertical
    error; ``level`` is then not part of the name) ``<name>__<method>__max_error<E>.npz``,
    E as Python writes the float (``2.5``, ``10.0``: distinct budgets, distinct names).
    Always a file directly in ``save_dir``: a name that would lead elsewhere (a path
    separator in it) is a ValueError. The registries refuse such method names already
    (:func:`terrainvis.core.validate.entry_name`); this check keeps any other caller in.
    """
    step = f"level{level}" if max_error is None else f"max_error{float(max_error)!r}"
    file = f"{name}__{method}__{step}.npz"
    if Path(file).name != file or any(sep and sep in file for sep in (os.sep, os.altsep)):
        raise ValueError(f"the simplified terrain's file name {file!r} (terrain {name!r}, method {method!r}) is not "
                         "a plain file name: it would be written outside the output folder")
    return Path(save_dir) / file


# ---------------------------------------------------------------------- a task
def run_unit(grid: HeightGrid, name: str, method: str, levels: tuple, settings: Settings, save_dir) -> list[dict]:
    """The rows of one task: simplify at each level, then every point set and relocation.

    A task is one level, or (a task of several levels, which the plan makes for a method
    that cascades: :func:`terrainvis.experiment.plan.cascades`) all the levels of a terrain and
    method, finest first, each simplification starting from the previous one.
    """
    sets = MEASURES[settings.measure].sets(grid, name, settings)
    if budgeted(settings):  # ``levels`` holds one budget E: the smallest result within E
        return [row for budget in levels for row in _budget_rows(grid, name, method, budget, settings, save_dir, sets)]
    cascade = len(levels) > 1
    rows, previous = [], None
    for level in levels:
        start = previous if cascade else None
        level_rows, previous = _level_rows(grid, name, method, level, settings, save_dir, sets, start)
        rows += level_rows
    return rows


def _level_rows(grid, name, method, level, settings, save_dir, sets, start):
    """The rows of one terrain x method x level, and the simplified terrain (None when it failed)."""
    from simplifiers import METHODS

    base = _base(grid, name, method, METHODS[method].kind, level, settings)
    base["cascaded"] = start is not None
    simplified = None
    try:
        simplified = _simplify_level(grid, method, level, start)
        base["cascaded"] = bool(simplified.attrs.get("cascaded", False))
        if save_dir is not None:
            _save(simplified, simplified_path(save_dir, name, method, level))
        rows = measured_rows(grid, simplified, base, settings, sets)
    except Exception as exc:  # record the failure in this unit's rows; the run goes on
        rows = failed_rows(base, exc, settings, sets)
        simplified = None
    return rows, simplified


def _budget_rows(grid, name, method, budget, settings, save_dir, sets) -> list[dict]:
    """The rows of one terrain x method x budget E: S(T) is ``simplify(grid, method, max_error=E)``.

    The rows' ``level`` is the level the method reached (None for an irregular method,
    which :func:`simplifiers.simplify` records so), ``max_error_budget`` is E and
    ``stopped_by`` says whether the result is within E (:func:`stopped_by`).
    """
    from simplifiers import METHODS, simplify

    base = _base(grid, name, method, METHODS[method].kind, None, settings)
    base["max_error_budget"] = float(budget)
    try:
        simplified = simplify(grid, method, max_error=budget)
        meta = simplified.attrs
        base["level"] = meta.get("level")
        base["stopped_by"] = stopped_by(meta, budget)
        if save_dir is not None:
            _save(simplified, simplified_path(save_dir, name, method, None, max_error=budget))
        return measured_rows(grid, simplified, base, settings, sets)
    except Exception as exc:  # record the failure in this unit's rows; the run goes on
        return failed_rows(base, exc, settings, sets)


def stopped_by(attrs: dict, budget: float) -> str:
    """What stopped a simplification to the maximum vertical error ``budget``, as a row says it.

    ``"max_error"``: the result is within ``budget`` (its measured ``attrs["max_error"]``
    is <= it, up to :data:`~terrainvis.tolerances.MAX_ERROR_TIE_REL` of it: the method's
    own error and the measured one round apart at a tie); otherwise what :func:`simplifiers.simplify` recorded (``"budget"``: the
    method could not reach the error at any size it allows, and returned its finest
    result), or ``"exceeded"`` when it recorded nothing else, or claimed the error met
    while the measured error exceeds it. A row is within its budget, or says so here.
    """
    from ..tolerances import MAX_ERROR_TIE_REL

    said = attrs.get("stopped_by")
    if float(attrs.get("max_error", np.inf)) <= budget * (1.0 + MAX_ERROR_TIE_REL):
        return "max_error"
    return str(said) if said and said != "max_error" else "exceeded"


def _base(grid: HeightGrid, name: str, method: str, kind: str, level: int | None, settings: Settings) -> dict:
    """The columns every row of a unit shares before anything is measured (``max_error_budget`` and
    ``stopped_by`` empty: a run by levels)."""
    return {
        "terrain": name, "method": method, "kind": kind, "level": level, "max_error_budget": None,
        "stopped_by": None, "measure": settings.measure,
        "predicate": settings.predicate, "n_points": MEASURES[settings.measure].n_points(settings),
        "n_vertices_original": grid.size, "nbytes_original": grid.nbytes, "seed": settings.seed,
        "distance_unit": settings.distance_unit, "offset": settings.offset, "cascaded": False, "error": None,
    }


def measured_rows(grid: HeightGrid, simplified, base: dict, settings: Settings, sets, *,
                  stored_errors: bool = True) -> list[dict]:
    """The rows of a unit whose simplified terrain is ``simplified``: its size, errors and volume, then the measure.

    ``base`` holds the unit's shared columns (terrain, method, kind, level, ...);
    ``simplified.attrs`` may hold ``seconds`` (the simplification's time) and ``backend``,
    and, with ``stored_errors``, the ``max_error`` and ``rms_error`` that
    :func:`simplifiers.simplify` measured (a comparison's own simplification). Without it
    the errors are measured here: :func:`terrainvis.evaluate` calls it with a terrain
    simplified elsewhere, whose file may record the errors of other heights.
    """
    from ..core.deviation import vertical_errors, volume_error

    meta = simplified.attrs
    n_vertices = simplified.size if isinstance(simplified, HeightGrid) else simplified.n_vertices
    if stored_errors and "max_error" in meta and "rms_error" in meta:
        err_max, err_rms = meta["max_error"], meta["rms_error"]
    else:
        err_max, err_rms = vertical_errors(grid, simplified)
    base = dict(
        base, n_vertices=int(n_vertices), size_fraction=n_vertices / grid.size, nbytes=int(simplified.nbytes),
        max_error=err_max, rms_error=err_rms, simplify_seconds=meta.get("seconds", np.nan),
        volume_error=volume_error(grid, simplified) if settings.volume else np.nan,
        end_radius=end_radius_for(simplified, grid, base["level"], settings.predicate),
        backend=str(meta.get("backend", "")),
    )
    return MEASURES[settings.measure].rows(grid, simplified, base, settings, sets, sight(settings))


def failed_rows(base: dict, exc: BaseException, settings: Settings, sets) -> list[dict]:
    """The rows of a unit that failed: every set, relocation and distance, with the message in ``error``."""
    message = f"{type(exc).__name__}: {exc}".replace("\n", " ")
    return [dict(base, set=s, relocation=how, max_distance=d, error=message)
            for s in range(len(sets)) for how in settings.relocations for d in settings.max_distance]


def _simplify_level(grid, method, level, start):
    """``simplify`` at one level, from ``start`` (a finer result of a cascade) when given.

    A cascade level that the method cannot finish (fast-simplification returned a
    non-manifold mesh from a cascaded 3601² level 2, for example) is simplified from the
    grid instead; ``attrs["cascaded"]`` says which happened.
    """
    from simplifiers import simplify

    from ..errors import SimplificationError

    if start is not None:
        try:
            out = simplify(grid, method, level, start=start)
            out.attrs["cascaded"] = True
            return out
        except SimplificationError as exc:
            cause = str(exc)
    out = simplify(grid, method, level)
    out.attrs["cascaded"] = False
    if start is not None:
        out.attrs["cascade_failed"] = cause
    return out


def _save(terrain, path: Path) -> None:
    from ..io import save_terrain

    path.parent.mkdir(parents=True, exist_ok=True)
    save_terrain(terrain, path)


# ---------------------------------------------------------------------- running in a worker
def call(extensions, fn, *args):
    """``fn(*args)`` with the run's ``extensions`` installed, then freed memory back to the OS.

    One entry point lets one pool run both units and warm-up parts. ``extensions``
    (:func:`terrainvis.experiment.plan.extensions`) are the entries registered at run time
    in the process that started the run; a worker process imported terrainvis afresh and
    has only the built-in ones, so they are registered here first.
    """
    from ..core.memory import release_freed_memory

    install(extensions)
    try:
        return fn(*args)
    finally:
        release_freed_memory()


def install(extensions) -> None:
    """Register each of ``extensions`` (methods, relocations, measures and engines registered at run time)
    unless this process has it already."""
    import simplifiers.registry as methods

    from ..relocation import registry as relocations
    from ..visibility import engines
    from . import measures

    registries = ((relocations.Relocation, relocations.RELOCATIONS, relocations.register),
                  (measures.Measure, measures.MEASURES, measures.register),
                  (engines.Engine, engines.ENGINES, engines.register))
    for entry in extensions:
        if isinstance(entry, methods.Method) and methods.METHODS.get(entry.name) != entry:
            methods.METHODS[entry.name] = entry  # an entry checked where it was registered
            continue
        for kind, table, register in registries:
            if isinstance(entry, kind) and table.get(entry.name) != entry:
                register(entry, replace=True)


def warm_up(part: tuple, settings: Settings) -> list:
    """Compile (or load) the kernels of one part by running it on a synthetic grid of the part's size.

    Best effort: a part that fails leaves its kernels to be compiled by the units that
    need them (which report their own errors).
    """
    import contextlib

    with contextlib.suppress(Exception):
        warm_up_part(part, settings)
    return []


def warm_up_part(part: tuple, settings: Settings) -> None:
    """Run one part of :func:`terrainvis.experiment.plan.warm_up_parts` (exceptions propagate).

    ``("method", m, side)`` simplifies a synthetic grid with ``m``; ``("measure", "volume", 33)``
    measures a volume; ``("measure", kind, 33)`` runs the measure of ``settings`` on a small
    grid and its simplification of that kind (a grid by "simple", or the grid's TIN),
    with every relocation.
    """
    from simplifiers import simplify

    from ..core.deviation import volume_error
    from ..core.synthetic import synthetic_terrain

    what, name, side = part
    grid = synthetic_terrain("hills", size=side, seed=0)
    if what == "method":
        simplify(grid, name, 1)
        return
    if name == "volume":  # its own part: the same kernels for a grid S(T) (as a TIN) and a TIN
        if settings.volume:
            volume_error(grid, grid.to_tin())
        return
    small = settings.replace(n_points=6, n_sets=1, n_observers=1, repeats=1)
    simplified = simplify(grid, "simple", 1) if name == "grid" else grid.to_tin()
    base = {"end_radius": end_radius_for(simplified, grid, 1, small.predicate)}
    measure = MEASURES[small.measure]
    measure.rows(grid, simplified, base, small, measure.sets(grid, "warm-up", small), sight(small))
