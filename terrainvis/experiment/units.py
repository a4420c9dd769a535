"""What one unit of a :func:`terrainvis.compare` run computes.

A *unit* is one terrain x method x level: it simplifies T once into S(T), then, for each
point set (or observer) and relocation, computes the verdicts on T and on S(T) and counts
how many agree (:func:`terrainvis.agreement`, :func:`terrainvis.core.metrics.viewshed_agreement`).
A *task* (:func:`run_unit`) is one unit, or every level of a cascade. Each task returns its
rows (dicts of :data:`terrainvis.experiment.collect.COLUMNS`); a failure is recorded in the rows'
``error`` column and the run goes on.

These functions run in the worker processes; they read the run's options from
:class:`~terrainvis.experiment.options.Settings` only.
"""

from __future__ import annotations

import time
import zlib
from pathlib import Path

import numpy as np

from .options import Settings, los_keywords
from ..relocation.registry import CALIBRATED, ORACLE
from ..core.terrain import HeightGrid

__all__ = [
    "point_sets", "observers", "end_radius_for", "simplified_path", "run_unit", "call", "warm_up", "warm_up_part",
]


# ---------------------------------------------------------------------- point sets
def _set_seed(seed: int, name: str, index: int) -> np.random.SeedSequence:
    # Keyed on the terrain's name, not its position, so adding a terrain changes nothing else.
    return np.random.SeedSequence([int(seed), zlib.crc32(name.encode()), int(index)])


def point_sets(grid: HeightGrid, name: str, n_points: int, n_sets: int, seed: int, offset: float):
    """The ``n_sets`` point sets of the terrain called ``name`` (deterministic for a seed and name)."""
    from ..core.sampling import sample_points

    return [
        sample_points(grid, n_points, seed=np.random.default_rng(_set_seed(seed, name, s)), offset=offset)
        for s in range(n_sets)
    ]


def observers(grid: HeightGrid, name: str, settings: Settings) -> list:
    """The observers of the viewshed measure: ``n_observers`` eyes ``offset`` above T, one per row."""
    from ..core.sampling import sample_points

    rng = np.random.default_rng(_set_seed(settings.seed, name, 10**6))  # apart from the pair sets
    return list(sample_points(grid, settings.n_observers, seed=rng, offset=settings.offset))


def end_radius_for(simplified, original: HeightGrid, level: int, predicate: str) -> float:
    """The end radius of the verdicts on S(T) under ``predicate`` (0 for ``"exact"``).

    ``"paper"``: one cell of the surface under test. For a grid, its larger mean cell
    side; for a TIN, the larger cell side of the regular grid with the same vertex
    budget (the regular result at the same level).
    """
    if predicate == "exact":
        return 0.0
    if isinstance(simplified, HeightGrid):
        return float(max(simplified.dx, simplified.dy))
    from simplifiers.levels import coarse_shape

    rows, cols = coarse_shape(original.shape, level)
    xmin, xmax, ymin, ymax = original.extent
    return float(max((xmax - xmin) / max(cols - 1, 1), (ymax - ymin) / max(rows - 1, 1)))


def simplified_path(save_dir, name: str, method: str, level: int) -> Path:
    """Where :func:`~terrainvis.compare` saves the simplified terrain of terrain ``name`` when given ``save_dir``."""
    return Path(save_dir) / f"{name}__{method}__level{level}.npz"


def _limit(max_distance, grid: HeightGrid, unit: str) -> float:
    """``max_distance`` (in ``unit``) in world units; None is no limit."""
    if max_distance is None:
        return np.inf
    return max_distance * (max(grid.dx, grid.dy) if unit == "cells" else 1.0)


def _pair_mask(points: np.ndarray, max_distance, grid: HeightGrid, unit: str):
    """The pairs within ``max_distance`` (in ``unit``) of each other, or None for every pair."""
    if max_distance is None:
        return None
    d = np.hypot(points[:, None, 0] - points[None, :, 0], points[:, None, 1] - points[None, :, 1])
    return d <= _limit(max_distance, grid, unit)


def _timed(fn, *args, repeats: int = 3, **kwargs):
    best = np.inf
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        best = min(best, time.perf_counter() - t0)
    return out, best


# ---------------------------------------------------------------------- a task
def run_unit(grid: HeightGrid, name: str, method: str, levels: tuple, settings: Settings, save_dir) -> list[dict]:
    """The rows of one task: simplify at each level, then every point set and relocation.

    A task is one level, or (a task of several levels, which the plan makes for a method
    that cascades: :func:`terrainvis.experiment.plan.cascades`) all the levels of a terrain and
    method, finest first, each simplification starting from the previous one.
    """
    if settings.measure == "viewshed":
        sets = observers(grid, name, settings)
    else:
        sets = point_sets(grid, name, settings.n_points, settings.n_sets, settings.seed, settings.offset)
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

    from ..core.deviation import volume_error

    base = {
        "terrain": name, "method": method, "kind": METHODS[method].kind, "level": level, "measure": settings.measure,
        "predicate": settings.predicate, "n_points": settings.n_points if settings.measure == "pairs" else 1,
        "n_vertices_original": grid.size, "nbytes_original": grid.nbytes, "seed": settings.seed,
        "distance_unit": settings.distance_unit, "offset": settings.offset, "cascaded": start is not None,
        "error": "",
    }
    simplified = None
    try:
        simplified = _simplify_level(grid, method, level, start)
        base["cascaded"] = bool(simplified.attrs.get("cascaded", False))
        if save_dir is not None:
            _save(simplified, simplified_path(save_dir, name, method, level))
        meta = simplified.attrs
        base.update(
            n_vertices=meta["n_vertices"], size_fraction=meta["n_vertices"] / grid.size, nbytes=meta["nbytes"],
            max_error=meta["max_error"], rms_error=meta["rms_error"], simplify_seconds=meta["seconds"],
            volume_error=volume_error(grid, simplified) if settings.volume else np.nan,
            end_radius=end_radius_for(simplified, grid, level, settings.predicate),
            backend=str(meta.get("backend", "")),
        )
        measure = _viewshed_rows if settings.measure == "viewshed" else _pair_rows
        rows = measure(grid, simplified, base, settings, sets)
    except Exception as exc:  # record the failure in this unit's rows; the run goes on
        message = f"{type(exc).__name__}: {exc}".replace("\n", " ")
        rows = [
            dict(base, set=s, relocation=how, max_distance=d, error=message)
            for s in range(len(sets)) for how in settings.relocations for d in settings.max_distance
        ]
        simplified = None
    return rows, simplified


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


# ---------------------------------------------------------------------- the measures
def _pair_rows(grid, simplified, base, settings, sets) -> list[dict]:
    """The pair measure: visibility matrices of each point set on T and on S(T), per relocation."""
    from ..core.metrics import agreement
    from ..relocation.registry import relocate
    from ..visibility import visibility_matrix

    radius = base["end_radius"]
    los = los_keywords(settings)
    test_kw = {**los, "end_radius": radius}
    # The first query builds the acceleration structure (pyramid or Embree scene); time it apart.
    t0 = time.perf_counter()
    visibility_matrix(simplified, sets[0][:2], **test_kw)
    base = dict(base, los_build_seconds=time.perf_counter() - t0)
    rows = []
    for s, pts in enumerate(sets):
        v_true, t_true = _timed(visibility_matrix, grid, pts, repeats=settings.repeats, **los)
        masks = [(d, _pair_mask(pts, d, grid, settings.distance_unit)) for d in settings.max_distance]
        placed = {how: relocate(pts, simplified, how, **_relocation_keywords(settings, grid, radius))
                  for how in settings.relocations if how != ORACLE}
        for how in settings.relocations:
            if how == ORACLE:  # an upper bound, optimised for the pairs each distance counts
                start = placed[CALIBRATED][:, 2] if CALIBRATED in placed else None  # never below the calibrated
                for d, mask in masks:
                    moved = relocate(pts, simplified, how, offset=settings.offset, reference=v_true,
                                     original=grid, mask=mask, end_radius=radius, start=start, **los)
                    v_test, t_test = _timed(visibility_matrix, simplified, moved, repeats=settings.repeats, **test_kw)
                    rows.append(_row(base, s, how, d, t_test, t_true, agreement(v_true, v_test, mask)))
                continue
            v_test, t_test = _timed(visibility_matrix, simplified, placed[how], repeats=settings.repeats, **test_kw)
            for d, mask in masks:
                rows.append(_row(base, s, how, d, t_test, t_true, agreement(v_true, v_test, mask)))
    return rows


def _viewshed_rows(grid, simplified, base, settings, eyes) -> list[dict]:
    """The viewshed measure: each observer's viewshed of T's samples on T and on S(T), per relocation.

    The observer is relocated onto S(T) as the points of the pair measure are; the targets
    are T's samples, standing ``target_height`` above the surface under test. A cell
    counts as a pair (observer, cell), so the agreement counts read as in the pair measure.
    """
    from ..core.metrics import viewshed_agreement
    from ..relocation.registry import relocate
    from ..visibility import viewshed

    kw = {"target_height": settings.target_height, **los_keywords(settings)}
    X, Y = np.meshgrid(grid.xs, grid.ys)
    rows = []
    for s, eye in enumerate(eyes):
        eye = eye[None, :]
        v_true, t_true = _timed(viewshed, grid, eye[0], repeats=settings.repeats, **kw)
        dist = np.hypot(X - eye[0, 0], Y - eye[0, 1])
        for how in settings.relocations:
            moved = relocate(eye, simplified, how, target_height=settings.target_height,
                             **_relocation_keywords(settings, grid, 0.0))[0]
            v_test, t_test = _timed(viewshed, simplified, moved, at=grid, repeats=settings.repeats, **kw)
            for d in settings.max_distance:
                counted = dist <= _limit(d, grid, settings.distance_unit)
                rows.append(_row(base, s, how, d, t_test, t_true, viewshed_agreement(v_true, v_test, counted)))
    return rows


def _relocation_keywords(settings: Settings, grid: HeightGrid, end_radius: float) -> dict:
    """What :func:`terrainvis.relocate` takes besides the points, S(T) and the relocation: the
    observers' offset and, for the calibrated relocation, T, the partners (from the run's
    seed) and the verdicts' predicate on S(T) (end radius, curvature)."""
    return {"offset": settings.offset, "original": grid, "end_radius": end_radius, "n_partners": settings.n_partners,
            "neighbours": settings.neighbours, "seed": settings.seed, **los_keywords(settings)}


def _row(base, s, how, d, t_test, t_true, counts) -> dict:
    row = dict(base, set=s, relocation=how, max_distance=d, los_seconds=t_test, los_seconds_original=t_true)
    row.update(counts)
    return row


def _save(terrain, path: Path) -> None:
    from ..io import save_terrain

    path.parent.mkdir(parents=True, exist_ok=True)
    save_terrain(terrain, path)


# ---------------------------------------------------------------------- running in a worker
def call(fn, *args):
    """``fn(*args)``, then freed memory back to the OS: lets one pool run both units and warm-up parts."""
    from ..core.memory import release_freed_memory

    try:
        return fn(*args)
    finally:
        release_freed_memory()


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
    if small.measure == "viewshed":
        _viewshed_rows(grid, simplified, base, small, observers(grid, "warm-up", small))
    else:
        _pair_rows(grid, simplified, base, small, point_sets(grid, "warm-up", 6, 1, small.seed, small.offset))
