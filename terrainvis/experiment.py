"""The paper's experiment as one call: :func:`compare`.

For every terrain T, method, level and point set P, :func:`compare` simplifies T into
S(T), computes the visibility matrix of P on T, relocates P onto S(T) in each of the
three ways, computes the visibility matrix there, and counts how many verdicts agree.
It also measures what the paper claimed but never measured: the time and memory that
S(T) saves, and how far its shape is from T.

The run goes in four stages:

1. **plan**: every argument is validated up front (methods, levels against each
   terrain's size, relocations, engine, predicate, ...) and the work is split into
   *units*, one per terrain x method x level (a unit simplifies once, then runs every
   point set and relocation), run as tasks of one unit (or, with ``cascade``, of every
   level of a method that continues from its finer result), the most expensive first;
2. **resume**: with ``out_csv`` the results go to a :class:`~terrainvis.results.ResultStore`,
   which keeps the complete units of an earlier run with the same settings and refuses
   a resume with other settings;
3. **execute**: :func:`terrainvis.runner.run_units` runs the units in this process, on a
   local process pool or on a dask cluster; each finished unit is written at once,
   atomically, so an interrupt (Ctrl-C, SIGTERM) loses no finished unit;
4. **collect**: the rows, sorted (terrains as given, methods in the paper's order).
"""

from __future__ import annotations

import hashlib
import os
import sys
import time
import zlib
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ._validate import as_float_array, as_int, choice, describe
from .relocation import ORACLE, RELOCATIONS
from .terrain import HeightGrid

__all__ = [
    "compare", "Settings", "DEFAULTS", "resolve_terrains", "point_sets", "DEFAULT_TERRAINS", "JACKSBORO_WINDOW",
    "COLUMNS", "PREDICATES", "DISTANCE_UNITS", "MEASURES", "simplified_path", "end_radius_for",
]

#: The default terrains: the five bundled 120x120 terrains and a 120x120 window of the real Jacksboro DEM.
DEFAULT_TERRAINS = ("hills", "mesas", "rough", "mountains", "ridges", "jacksboro")

#: Rows and columns of the 344x403 Jacksboro DEM used as the "jacksboro" terrain: its
#: central 120x120 window at the native 74.57 m x 92.47 m cells (8.9 km x 11.0 km). A
#: window keeps the real sampling; resampling the whole DEM to 120x120 would smooth it.
JACKSBORO_WINDOW = ((112, 232), (141, 261))

#: Units of ``max_distance``: world units (metres), or cells of the original terrain
#: (its larger cell side), so one sweep means the same on terrains of different resolution.
DISTANCE_UNITS = ("world", "cells")

#: What a run measures: ``"pairs"`` (the paper's visibility matrices of point sets) or
#: ``"viewshed"`` (each observer's viewshed of every sample of T).
MEASURES = ("pairs", "viewshed")

#: Line-of-sight predicates for the verdicts on S(T) (verdicts on T are always exact):
#: ``"exact"`` tests the whole segment; ``"paper"`` ignores the surface within one cell
#: of S(T) around each end (see :func:`end_radius_for`).
PREDICATES = ("exact", "paper")

#: Columns of the result table, in order.
COLUMNS = (
    "terrain", "set", "method", "kind", "level", "relocation", "measure", "predicate",
    "accuracy", "visible_kept", "blocked_kept", "accuracy_paper", "visible_area_ratio",
    "n_pairs", "agree_visible", "agree_blocked", "false_visible", "false_blocked",
    "n_points", "n_vertices", "n_vertices_original", "size_fraction", "nbytes", "nbytes_original",
    "max_error", "rms_error", "volume_error", "end_radius", "backend", "cascaded",
    "simplify_seconds", "los_seconds", "los_seconds_original", "los_build_seconds",
    "seed", "max_distance", "distance_unit", "offset", "error",
)
#: Columns that identify a unit.
UNIT_KEY = ("terrain", "method", "level")
#: Columns holding times (they differ between runs; everything else is deterministic).
TIMING_COLUMNS = ("simplify_seconds", "los_seconds", "los_seconds_original", "los_build_seconds")


@dataclass(frozen=True)
class Settings:
    """Everything that determines the rows of a :func:`compare` run, with the defaults.

    The defaults are the paper's protocol; the CLI takes its defaults from here too
    (:data:`DEFAULTS`). ``methods=None`` means every registered method. After
    validation ``max_distance`` is a tuple of distances (None: unlimited).
    """

    methods: tuple | None = None
    levels: tuple = (1, 2, 3)
    relocations: tuple = RELOCATIONS
    n_points: int = 50
    n_sets: int = 6
    seed: int = 0
    max_distance: float | None | tuple = None
    distance_unit: str = "world"
    offset: float = 0.0
    engine: str = "auto"
    predicate: str = "exact"
    volume: bool = True
    repeats: int = 3
    cascade: bool | str = "auto"
    measure: str = "pairs"
    n_observers: int = 20
    target_height: float = 0.0


#: The defaults of :func:`compare` and ``terrainvis compare``.
DEFAULTS = Settings()


def _resolve_one(name, t, i):
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
    """Turn the ``terrains`` argument of :func:`compare` into ``{name: HeightGrid}``.

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
        name, grid = _resolve_one(name, t, i)
        name = str(name)
        if name in out:
            raise ValueError(f"terrain names must be unique, got {name!r} twice")
        grid.require_finite(f"compare (terrain {name!r})")
        out[name] = grid
    return out


def _set_seed(seed: int, name: str, index: int) -> np.random.SeedSequence:
    # Keyed on the terrain's name, not its position, so adding a terrain changes nothing else.
    return np.random.SeedSequence([int(seed), zlib.crc32(name.encode()), int(index)])


def point_sets(grid: HeightGrid, name: str, n_points: int, n_sets: int, seed: int, offset: float):
    """The ``n_sets`` point sets of the terrain called ``name`` (deterministic for a seed and name)."""
    from .sampling import sample_points

    return [
        sample_points(grid, n_points, seed=np.random.default_rng(_set_seed(seed, name, s)), offset=offset)
        for s in range(n_sets)
    ]


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


def _pair_mask(points: np.ndarray, max_distance, grid: HeightGrid, unit: str):
    """The pairs within ``max_distance`` (in ``unit``) of each other, or None for every pair."""
    if max_distance is None:
        return None
    limit = max_distance * (max(grid.dx, grid.dy) if unit == "cells" else 1.0)
    d = np.hypot(points[:, None, 0] - points[None, :, 0], points[:, None, 1] - points[None, :, 1])
    return d <= limit


def _timed(fn, *args, repeats: int = 3, **kwargs):
    best = np.inf
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        best = min(best, time.perf_counter() - t0)
    return out, best


def simplified_path(save_dir, name: str, method: str, level: int) -> Path:
    """Where :func:`compare` saves the simplified terrain of terrain ``name`` when given ``save_dir``."""
    return Path(save_dir) / f"{name}__{method}__level{level}.npz"


def _run_unit(grid: HeightGrid, name: str, method: str, levels: tuple, settings: Settings, save_dir) -> list[dict]:
    """The rows of one task: simplify at each level, then every point set and relocation.

    A task is one level, or, with ``settings.cascade`` and a method that can continue
    from a finer result (:attr:`simplifiers.Method.cascades`), all the levels of a
    terrain and method, finest first, each simplification starting from the previous one.
    """
    from simplifiers import METHODS

    sets = _observers(grid, name, settings) if settings.measure == "viewshed" else point_sets(
        grid, name, settings.n_points, settings.n_sets, settings.seed, settings.offset)
    rows, previous = [], None
    for level in levels:
        start = previous if cascades(settings, grid, method) else None
        level_rows, previous = _level_rows(grid, name, method, level, settings, save_dir, sets, start)
        rows += level_rows
    return rows


#: ``cascade="auto"`` cascades on grids of more than this many samples (above about
#: 724²; at 1024² three independent QEC decimations take minutes and, two at once on two
#: workers, 2.9 GB; the paper's 120² terrains stay independent).
CASCADE_AUTO_MIN_SAMPLES = 1 << 19


def cascades(settings: Settings, grid: HeightGrid, method: str) -> bool:
    """Whether ``method``'s levels on ``grid`` run as a cascade (each from the previous level's result)."""
    from simplifiers import METHODS

    if not METHODS[method].cascades or len(settings.levels) < 2:
        return False
    if settings.cascade == "auto":
        return grid.size > CASCADE_AUTO_MIN_SAMPLES
    return bool(settings.cascade)


def _observers(grid: HeightGrid, name: str, settings: Settings) -> list:
    """The observers of the viewshed measure: ``n_observers`` eyes ``offset`` above T, one per row."""
    from .sampling import sample_points

    rng = np.random.default_rng(_set_seed(settings.seed, name, 10**6))  # apart from the pair sets
    return list(sample_points(grid, settings.n_observers, seed=rng, offset=settings.offset))


def _level_rows(grid, name, method, level, settings, save_dir, sets, start):
    """The rows of one terrain x method x level, and the simplified terrain (None when it failed)."""
    from simplifiers import METHODS, simplify

    from .deviation import volume_error

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

    from .errors import SimplificationError

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


def _pair_rows(grid, simplified, base, settings, sets) -> list[dict]:
    """The pair measure: visibility matrices of each point set on T and on S(T), per relocation."""
    from .metrics import agreement
    from .relocation import relocate
    from .visibility import visibility_matrix

    radius = base["end_radius"]
    test_kw = {"engine": settings.engine, "end_radius": radius}
    # The first query builds the acceleration structure (pyramid or Embree scene); time it apart.
    t0 = time.perf_counter()
    visibility_matrix(simplified, sets[0][:2], **test_kw)
    base = dict(base, los_build_seconds=time.perf_counter() - t0)
    rows = []
    for s, pts in enumerate(sets):
        v_true, t_true = _timed(visibility_matrix, grid, pts, engine=settings.engine, repeats=settings.repeats)
        masks = [(d, _pair_mask(pts, d, grid, settings.distance_unit)) for d in settings.max_distance]
        for how in settings.relocations:
            if how == ORACLE:  # an upper bound, optimised for the pairs each distance counts
                for d, mask in masks:
                    moved = relocate(pts, simplified, how, offset=settings.offset, reference=v_true,
                                     original=grid, mask=mask, end_radius=radius, engine=settings.engine)
                    v_test, t_test = _timed(visibility_matrix, simplified, moved, repeats=settings.repeats, **test_kw)
                    rows.append(_row(base, s, how, d, t_test, t_true, agreement(v_true, v_test, mask)))
                continue
            moved = relocate(pts, simplified, how, offset=settings.offset)
            v_test, t_test = _timed(visibility_matrix, simplified, moved, repeats=settings.repeats, **test_kw)
            for d, mask in masks:
                rows.append(_row(base, s, how, d, t_test, t_true, agreement(v_true, v_test, mask)))
    return rows


def _viewshed_rows(grid, simplified, base, settings, observers) -> list[dict]:
    """The viewshed measure: each observer's viewshed of T's samples on T and on S(T), per relocation.

    The observer is relocated onto S(T) as the points of the pair measure are; the targets
    are T's samples, standing ``target_height`` above the surface under test. A cell
    counts as a pair (observer, cell), so the agreement counts read as in the pair measure.
    """
    from .relocation import relocate
    from .visibility import viewshed

    kw = {"target_height": settings.target_height, "engine": settings.engine}
    X, Y = np.meshgrid(grid.xs, grid.ys)
    rows = []
    for s, eye in enumerate(observers):
        eye = eye[None, :]
        v_true, t_true = _timed(viewshed, grid, eye[0], repeats=settings.repeats, **kw)
        dist = np.hypot(X - eye[0, 0], Y - eye[0, 1])
        for how in settings.relocations:
            moved = relocate(eye, simplified, how, offset=settings.offset)[0]
            v_test, t_test = _timed(viewshed, simplified, moved, at=grid, repeats=settings.repeats, **kw)
            for d in settings.max_distance:
                limit = np.inf if d is None else d * (max(grid.dx, grid.dy) if settings.distance_unit == "cells" else 1.0)
                counted = dist <= limit
                rows.append(_row(base, s, how, d, t_test, t_true, _cell_agreement(v_true, v_test, counted)))
    return rows


def _cell_agreement(v_true, v_test, counted) -> dict:
    """How many cells of a viewshed keep their verdict (the agreement counts of one observer)."""
    t, s = v_true[counted], v_test[counted]
    av, ab = int(np.count_nonzero(t & s)), int(np.count_nonzero(~t & ~s))
    fv, fb = int(np.count_nonzero(~t & s)), int(np.count_nonzero(t & ~s))
    n = int(t.size)
    return {
        "n_pairs": n, "agree_visible": av, "agree_blocked": ab, "false_visible": fv, "false_blocked": fb,
        "accuracy": (av + ab) / n if n else np.nan, "visible_kept": av / (av + fb) if av + fb else np.nan,
        "blocked_kept": ab / (ab + fv) if ab + fv else np.nan, "accuracy_paper": np.nan,
        "visible_area_ratio": (av + fv) / (av + fb) if av + fb else np.nan,
    }


def _row(base, s, how, d, t_test, t_true, counts) -> dict:
    row = dict(base, set=s, relocation=how, max_distance=d, los_seconds=t_test, los_seconds_original=t_true)
    row.update(counts)
    return row


def _save(terrain, path: Path) -> None:
    from .io import save_terrain

    path.parent.mkdir(parents=True, exist_ok=True)
    save_terrain(terrain, path)


# ---------------------------------------------------------------------- plan
def _names(value, name: str, valid, default) -> tuple:
    """A tuple of distinct names drawn from ``valid`` (a str is one name; None the default)."""
    if value is None:
        return tuple(default)
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, (list, tuple)):
        raise TypeError(f"{name} must be a list of names, got {describe(value)}")
    out = []
    for v in value:
        if not isinstance(v, str) or v not in valid:
            raise ValueError(f"{name} must be drawn from {list(valid)}, got {v!r}")
        if v in out:
            raise ValueError(f"{name} must not repeat a name, got {v!r} twice")
        out.append(v)
    if not out:
        raise ValueError(f"{name} must name at least one of {list(valid)}, got an empty list")
    return tuple(out)


def _levels(value, grids: dict) -> tuple:
    from simplifiers import max_level

    if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
        value = [value]
    if not isinstance(value, (list, tuple)):
        raise TypeError(f"levels must be an integer or a list of integers, got {describe(value)}")
    levels = []
    for v in value:
        lv = as_int(v, "levels", minimum=1)
        if lv in levels:
            raise ValueError(f"levels must not repeat a level, got {lv} twice")
        levels.append(lv)
    if not levels:
        raise ValueError("levels must hold at least one level, got an empty list")
    for name, grid in grids.items():
        top = max_level(grid.shape)
        if max(levels) > top:
            raise ValueError(
                f"levels must be at most {top} for terrain {name!r} ({grid.shape[0]}x{grid.shape[1]}: each "
                f"level needs at least 3 samples per axis), got {max(levels)}"
            )
    return tuple(levels)


def _distances(value) -> tuple:
    """``max_distance`` as a tuple of distinct distances > 0 (None: unlimited)."""
    values = list(value) if isinstance(value, (list, tuple)) else [value]
    out = []
    for v in values:
        if v is not None:
            d = as_float_array(v, "max_distance")
            if d.ndim != 0:
                raise TypeError(f"max_distance must hold numbers or None, got {describe(v)}")
            v = float(d)
            if v == np.inf:
                v = None
            elif not np.isfinite(v) or v <= 0:
                raise ValueError(f"max_distance must be > 0 (or None / inf for every pair), got {v!r}")
        if v in out:
            raise ValueError(f"max_distance must not repeat a distance, got {v!r} twice")
        out.append(v)
    if not out:
        raise ValueError("max_distance must hold at least one distance (None: every pair), got an empty list")
    return tuple(out)


def _finite(value, name: str) -> float:
    arr = as_float_array(value, name)
    if arr.ndim != 0 or not np.isfinite(arr):
        raise ValueError(f"{name} must be a finite number, got {describe(value)}")
    return float(arr)


def _settings(grids, *, methods, levels, relocations, n_points, n_sets, seed, max_distance, distance_unit, offset,
              engine, predicate, volume, repeats, cascade, measure, n_observers, target_height) -> Settings:
    """Validate every option of :func:`compare` (before any unit runs) into :class:`Settings`."""
    from simplifiers import METHODS

    from .visibility import ENGINES

    methods = _names(methods, "methods", list(METHODS), METHODS)
    engine = choice(engine, "engine", ENGINES)
    if engine == "grid":
        tins = [m for m in methods if not METHODS[m].regular]
        if tins:
            raise ValueError(
                f"engine 'grid' works on grids only, but methods {tins} produce TINs; use engine='auto' "
                "(the grid engine on grids, Embree on TINs) or leave those methods out"
            )
    if not isinstance(volume, (bool, np.bool_)):
        raise TypeError(f"volume must be True or False, got {describe(volume)}")
    if not (isinstance(cascade, (bool, np.bool_)) or (isinstance(cascade, str) and cascade == "auto")):
        raise TypeError(f"cascade must be True, False or 'auto', got {describe(cascade)}")
    relocations = _names(relocations, "relocations", RELOCATIONS + (ORACLE,), RELOCATIONS)
    measure = choice(measure, "measure", MEASURES)
    predicate = choice(predicate, "predicate", PREDICATES)
    target_height = _finite(target_height, "target_height")
    if measure == "viewshed":
        if predicate != "exact":
            raise ValueError(f"measure 'viewshed' supports predicate 'exact' only, got {predicate!r}")
        if ORACLE in relocations:
            raise ValueError("measure 'viewshed' does not support the 'oracle' relocation (it bounds pair verdicts)")
        if target_height < 0:
            raise ValueError(f"target_height must be >= 0, got {target_height!r}")
    return Settings(
        methods=methods, levels=_levels(levels, grids), relocations=relocations,
        n_points=as_int(n_points, "n_points", minimum=2), n_sets=as_int(n_sets, "n_sets", minimum=1),
        seed=as_int(seed, "seed", minimum=0), max_distance=_distances(max_distance),
        distance_unit=choice(distance_unit, "distance_unit", DISTANCE_UNITS), offset=_finite(offset, "offset"),
        engine=engine, predicate=predicate, volume=bool(volume), repeats=as_int(repeats, "repeats", minimum=1),
        cascade=cascade if isinstance(cascade, str) else bool(cascade), measure=measure,
        n_observers=as_int(n_observers, "n_observers", minimum=1), target_height=target_height,
    )


def _fingerprint(grid: HeightGrid) -> str:
    """A content hash of a terrain (z, xs, ys), so a resume notices a changed input."""
    h = hashlib.sha256()
    for a in (grid.z, grid.xs, grid.ys):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def _tasks(grids: dict, settings: Settings, done=frozenset()) -> list[tuple]:
    """The tasks as (terrain, method, levels), the most expensive first so the pool stays busy to the end.

    A task is one level, or all the levels of a method that cascades (``settings.cascade``).
    Tasks whose every unit is ``done`` are left out; a cascade with some levels done runs
    them all again (each level starts from the previous one), and their rows are dropped.
    """
    from simplifiers import METHODS

    tasks = []
    for t in grids:
        for m in settings.methods:
            if cascades(settings, grids[t], m):
                groups = [tuple(sorted(settings.levels))]
            else:
                groups = [(lv,) for lv in settings.levels]
            tasks += [(t, m, g) for g in groups if any((t, m, lv) not in done for lv in g)]
    return sorted(tasks, key=lambda u: (-grids[u[0]].size, METHODS[u[1]].cost_rank, u[2]))


def _order(df: pd.DataFrame, grids: dict) -> pd.DataFrame:
    from simplifiers import METHODS

    rank_t = {t: i for i, t in enumerate(grids)}
    rank_m = {m: i for i, m in enumerate(METHODS)}
    rank_r = {r: i for i, r in enumerate(RELOCATIONS + (ORACLE,))}
    df = df.assign(
        _t=df["terrain"].map(rank_t), _m=df["method"].map(rank_m), _r=df["relocation"].map(rank_r),
        _d=df["max_distance"].fillna(np.inf),
    ).sort_values(["_t", "set", "_m", "level", "_r", "_d"], kind="stable")
    return df.drop(columns=["_t", "_m", "_r", "_d"]).reset_index(drop=True)


def _call(fn, *args):
    """``fn(*args)``, then freed memory back to the OS: lets one pool run both units and warm-up parts."""
    from ._memory import release_freed_memory

    try:
        return fn(*args)
    finally:
        release_freed_memory()


def _warm_up_parts(tasks, grids: dict) -> list[tuple]:
    """What a run must compile, as parts that two workers can compile side by side.

    With a cold numba cache every worker would compile every kernel it meets (about 80 s
    of compilation each for a full run). Compiled once by whichever worker takes the part,
    a kernel is loaded from the on-disk cache by the others. The parts: each method's
    kernels, and the measurements on a grid and on a TIN (line of sight, relocation, volume,
    viewshed). Greedy cuts' kernels take the longest to compile (about 30 s) and go first,
    the rest follow in the order the pool takes them.
    """
    from simplifiers import METHODS

    methods = sorted({m for _, m, _ in tasks}, key=lambda m: METHODS[m].cost_rank)
    kinds = sorted({"grid" if METHODS[m].regular else "tin" for m in methods})
    # Regular methods switch to parallel kernels above a size: warm them on a grid as
    # large as the run's largest (capped; they take milliseconds), the rest on a small one.
    largest = max(g.size for g in grids.values())
    side = min(1024, max(33, int(np.ceil(np.sqrt(largest)))))
    parts = [("method", m, side if METHODS[m].regular else 33) for m in methods]
    return parts[:1] + [("measure", k, 33) for k in kinds] + parts[1:]


def _warm_up(part: tuple, settings: Settings) -> list:
    """Compile (or load) the kernels of one part by running it on a synthetic grid of the part's size.

    Best effort: a part that fails leaves its kernels to be compiled by the units that
    need them (which report their own errors).
    """
    import contextlib

    with contextlib.suppress(Exception):
        _warm_up_part(part, settings)
    return []


def _warm_up_part(part: tuple, settings: Settings) -> None:
    from dataclasses import replace

    from simplifiers import simplify

    from .deviation import volume_error
    from .synthetic import synthetic_terrain

    what, name, side = part
    grid = synthetic_terrain("hills", size=side, seed=0)
    if what == "method":
        simplify(grid, name, 1)
        return
    small = replace(settings, n_points=6, n_sets=1, n_observers=1, repeats=1)
    simplified = simplify(grid, "simple", 1) if name == "grid" else grid.to_tin()
    if small.volume:
        volume_error(grid, simplified)
    base = {"end_radius": end_radius_for(simplified, grid, 1, small.predicate)}
    if small.measure == "viewshed":
        _viewshed_rows(grid, simplified, base, small, _observers(grid, "warm-up", small))
    else:
        _pair_rows(grid, simplified, base, small, point_sets(grid, "warm-up", 6, 1, small.seed, small.offset))


def _kernels_cached(settings: Settings) -> bool | None:
    """Whether numba's on-disk cache already holds the LOS kernels (None when it cannot tell)."""
    try:
        import os

        from .visibility import _kernels

        return os.path.exists(_kernels.grid_matrix._cache._cache_file._index_path)
    except Exception:  # numba internals: a best-effort hint only
        return None


# ---------------------------------------------------------------------- compare
def compare(
    terrains=DEFAULT_TERRAINS,
    *,
    methods=DEFAULTS.methods,
    levels=DEFAULTS.levels,
    relocations=DEFAULTS.relocations,
    n_points: int = DEFAULTS.n_points,
    n_sets: int = DEFAULTS.n_sets,
    seed: int = DEFAULTS.seed,
    max_distance=DEFAULTS.max_distance,
    distance_unit: str = DEFAULTS.distance_unit,
    offset: float = DEFAULTS.offset,
    engine: str = DEFAULTS.engine,
    predicate: str = DEFAULTS.predicate,
    volume: bool = DEFAULTS.volume,
    repeats: int = DEFAULTS.repeats,
    cascade: bool = DEFAULTS.cascade,
    measure: str = DEFAULTS.measure,
    n_observers: int = DEFAULTS.n_observers,
    target_height: float = DEFAULTS.target_height,
    workers: int | None = None,
    client=None,
    out_csv=None,
    resume: bool = False,
    save_dir=None,
    progress: bool = False,
) -> pd.DataFrame:
    """Run the paper's experiment: how many LOS verdicts survive each simplification.

    Parameters
    ----------
    terrains : terrain or list or dict
        See :func:`resolve_terrains`. Default: the five bundled 120x120 terrains and the
        central 120x120 window of the Jacksboro DEM.
    methods : list of str, optional
        Simplifiers (default: all seven, in the paper's order, :data:`simplifiers.METHODS`).
    levels : int or sequence of int
        Simplification levels; for 120x120 grids 1, 2, 3 are the paper's 25 %, 6 % and 1.5 %.
    relocations : sequence of str
        Any of ``"identity"``, ``"full"``, ``"half"`` (:func:`terrainvis.relocate`), and
        ``"oracle"``, the upper bound that needs T's verdicts (not a practical relocation;
        it costs many visibility queries per point set).
    n_points, n_sets : int
        Each terrain gets ``n_sets`` sets of ``n_points`` uniform random points; every
        method sees the same sets.
    seed : int
        The point sets depend only on ``seed`` and the terrain's name.
    max_distance : float or None or list of them, optional
        Count only the pairs whose horizontal distance is at most this (localized
        visibility tests; None or inf: every pair). A list gives one row per distance
        from the same verdicts (a sweep costs little more than one distance).
    distance_unit : {"world", "cells"}
        ``max_distance`` in world units, or in cells of the terrain (its larger cell side).
    offset : float
        Observer height above the original surface (see :mod:`terrainvis.relocation`).
    engine : {"auto", "grid", "embree"}
        Visibility engine (:func:`terrainvis.visibility_matrix`).
    predicate : {"exact", "paper"}
        The line-of-sight predicate of the verdicts on S(T) (:data:`PREDICATES`); the
        verdicts on T are always exact.
    volume : bool
        Compute the volume between T and S(T) (:func:`terrainvis.volume_error`).
    repeats : int
        Each visibility matrix is timed this many times; the fastest run is kept.
    cascade : bool or "auto"
        Simplify each level of a method that can (QEC) from the previous, finer level's
        result instead of from T: one decimation pass instead of one per level. It
        changes what those methods compute (on 1024², RMS errors 6-8 % lower and
        accuracies within 0.1 points; see the README). False simplifies every level from
        T as the paper does; ``"auto"`` (the default) cascades on grids of more than
        :data:`CASCADE_AUTO_MIN_SAMPLES` samples only. The ``cascaded`` column records
        which levels started from a finer result.
    measure : {"pairs", "viewshed"}
        ``"pairs"``: the paper's visibility matrices of the point sets. ``"viewshed"``:
        for ``n_observers`` random observers per terrain (``offset`` above T, relocated
        onto S(T) like the points), the viewshed of every sample of T on T and on S(T)
        (targets ``target_height`` above the surface under test); each row is one
        observer and counts cells as pairs (observer, cell), with the share of cells
        whose verdict survives in ``accuracy`` and the visible-area ratio S(T) / T in
        ``visible_area_ratio``. ``n_points`` and ``n_sets`` apply to pairs only.
    n_observers : int
        Observers per terrain of the viewshed measure.
    target_height : float
        Height of the viewshed measure's targets above the surface under test.
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
    from .results import ResultStore, as_table
    from .runner import check_client, check_workers, run_units

    if terrains is None:
        raise TypeError("terrains must be a terrain, a list of terrains or a dict of them, got None")
    grids = resolve_terrains(terrains)
    settings = _settings(
        grids, methods=methods, levels=levels, relocations=relocations, n_points=n_points, n_sets=n_sets, seed=seed,
        max_distance=max_distance, distance_unit=distance_unit, offset=offset, engine=engine, predicate=predicate,
        volume=volume, repeats=repeats, cascade=cascade, measure=measure, n_observers=n_observers,
        target_height=target_height,
    )
    workers = check_workers(workers)
    client = check_client(client)

    store = None
    done = frozenset()
    if out_csv is not None:
        record = asdict(settings)
        record["terrains"] = {name: _fingerprint(g) for name, g in grids.items()}
        sets = settings.n_observers if settings.measure == "viewshed" else settings.n_sets
        per_unit = sets * len(settings.relocations) * len(settings.max_distance)
        store = ResultStore(out_csv, record, COLUMNS, UNIT_KEY, lambda key: per_unit, resume=resume)
        done = frozenset(store.done)
    tasks = _tasks(grids, settings, done)
    if save_dir is not None:
        from ._fileio import check_writable_dir

        save_dir = str(check_writable_dir(save_dir, "save_dir"))

    from tqdm.auto import tqdm

    todo = sum(1 for t, m, levels in tasks for lv in levels if (t, m, lv) not in done)
    cold = bool(tasks) and _kernels_cached(settings) is False
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

    rows = store.rows() if store is not None else as_table(new_rows, COLUMNS)
    df = _order(rows[list(COLUMNS)], grids)
    if store is not None:
        store.finish(df)
    return df
