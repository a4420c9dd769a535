"""The measures of :func:`terrainvis.compare`: what one unit counts, each declared once.

A :class:`Measure` says how a unit draws its test sets from T (point sets, observers),
how it turns T, S(T) and those sets into rows of agreement counts, what those counts
count (pairs, cells), the predicates it supports and how much memory a unit needs. The
registry :data:`MEASURES` is what ``compare(measure=...)``, ``--measure``, the plan's
memory check, the rows a complete unit has and the report's wording read.

The built-in measures:

``"pairs"``
    The paper's: the visibility matrix of each point set on T and on S(T), per
    relocation (:func:`pair_rows`); a bound relocation (the oracle) is fitted to the pairs
    each distance counts, so it runs once per distance, after the practical ones.
``"viewshed"``
    Each observer's viewshed of every sample of T, on T and on S(T), per relocation
    (:func:`viewshed_rows`); a cell counts as a pair (observer, cell). Its rows also give
    the error of the minimum-visible-height raster on S(T) (``min_height_rms``,
    ``min_height_p95``) and what S(T) does to an observer siting (``siting_share``,
    ``siting_share_original``, ``siting_ratio``: :func:`siting_coverage`, once per unit);
    NaN in the other measures' rows.

A measure's functions read the run's settings by attribute and take the run's sight lines
(a :class:`~terrainvis.visibility.Sight`: engine, earth model, target height;
:func:`terrainvis.experiment.options.sight`) as an argument; they import nothing from the
rest of the experiment, which imports them.
"""

from __future__ import annotations

import dataclasses
import time
import zlib
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..core.registry import Registry
from ..core.terrain import HeightGrid, fingerprint
from ..core.validate import describe

__all__ = [
    "Measure", "MEASURES", "register", "unregister", "available", "point_sets", "observers", "pair_rows",
    "viewshed_rows", "min_height_error", "siting_coverage", "siting_candidates", "SITING_LATTICE", "COMMON_COLUMNS",
    "columns", "builtin_columns",
]

#: The siting's candidates (:func:`siting_coverage`): every ``ceil(max(rows, cols) / SITING_LATTICE)``-th
#: sample of T along rows and columns (:func:`terrainvis.candidate_grid`), at most
#: ``SITING_LATTICE`` per side: 8 x 8 = 64 candidates on a 120x120 terrain, whose viewsheds on
#: S(T) add about 13 % to the viewshed measure's CPU time on the default run.
SITING_LATTICE = 8


@dataclass(frozen=True)
class Measure:
    """Every fact about one measure of :func:`terrainvis.compare`.

    Parameters
    ----------
    name : str
        How users name it (``compare(measure=name)``, ``--measure name``).
    sets : callable
        ``sets(grid, name, settings) -> list``: the unit's test sets drawn from T (the
        terrain called ``name``), deterministic for the run's seed: each an (n, 3) array
        of points on (``offset`` above) T.
    rows : callable
        ``rows(grid, simplified, base, settings, sets, sight) -> list of dict``: for each set,
        relocation (``settings.relocations``) and distance (``settings.max_distance``), one
        row: ``dict(base, set=, relocation=, max_distance=, los_seconds=,
        los_seconds_original=)`` with the agreement counts of
        :func:`terrainvis.agreement` (``accuracy``, ``visible_kept``, ...). ``sight`` is the
        run's :class:`~terrainvis.visibility.Sight` (its engine, earth model and target
        height; end radius 0, no field of view).
    counts : str
        What its agreement counts, as the tables say it (``"pairs"``, ``"cells"``).
    summary : str
        One line for ``--help`` and the docs.
    n_points : callable
        ``n_points(settings) -> int``: the points of one set (the rows' ``n_points``).
    n_sets : callable
        ``n_sets(settings) -> int``: the sets of a unit (a complete unit has ``n_sets x
        relocations x distances`` rows).
    unit_bytes : callable
        ``unit_bytes(settings, grids) -> int``: a lower bound of the memory one unit
        allocates (the run is refused before it starts when its units cannot fit).
    predicates : tuple of str
        The predicates it supports (``"exact"``, ``"paper"``).
    tables : callable, optional
        ``tables(df) -> dict``: the report's tables of its own (title -> DataFrame with a
        ``"title"`` in its ``attrs``), printed and written to ``tables.md`` after Tables
        1-4; an empty DataFrame is left out. None: none.
    paper : bool
        Its rows compare with the paper's matrices: the report sets them beside the
        paper's published cells and checks the paper's findings on them.
    columns : tuple of str
        Columns of the results table that only this measure fills (NaN in the other
        measures' rows), placed after the agreement counts
        (:func:`terrainvis.experiment.collect.columns`): the viewshed measure's
        ``min_height_*`` and ``siting_*``. A results file without them (written before
        them, or before the measure was registered) still resumes under the other
        measures.
    """

    name: str
    sets: Callable
    rows: Callable
    counts: str
    summary: str
    n_points: Callable
    n_sets: Callable
    unit_bytes: Callable
    predicates: tuple = ("exact", "paper")
    tables: Callable | None = None
    paper: bool = False
    columns: tuple = ()


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


def observers(grid: HeightGrid, name: str, settings) -> list:
    """The observers of the viewshed measure: ``n_observers`` eyes ``offset`` above T, one per row."""
    from ..core.sampling import sample_points

    rng = np.random.default_rng(_set_seed(settings.seed, name, 10**6))  # apart from the pair sets
    return list(sample_points(grid, settings.n_observers, seed=rng, offset=settings.offset))


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


def pair_rows(grid, simplified, base, settings, sets, sight) -> list[dict]:
    """The pair measure: visibility matrices of each point set on T and on S(T), per relocation.

    The practical relocations place each set once; a bound (the oracle) is fitted to T's
    verdicts of the pairs each distance counts, so it runs once per distance, after them.
    """
    from ..core.metrics import agreement
    from ..relocation.registry import RELOCATIONS, relocate
    from ..visibility import visibility_matrix

    radius = base["end_radius"]
    test = dataclasses.replace(sight, end_radius=radius)  # the predicate of the verdicts on S(T)
    # The first query builds the acceleration structure (pyramid or Embree scene); time it apart.
    t0 = time.perf_counter()
    visibility_matrix(simplified, sets[0][:2], sight=test)
    base = dict(base, los_build_seconds=time.perf_counter() - t0)
    known = _relocation_keywords(settings, grid, radius)
    rows = []
    for s, pts in enumerate(sets):
        v_true, t_true = _timed(visibility_matrix, grid, pts, repeats=settings.repeats, sight=sight)
        masks = [(d, _pair_mask(pts, d, grid, settings.distance_unit)) for d in settings.max_distance]
        placed = {how: relocate(pts, simplified, how, **RELOCATIONS[how].keywords(known, test))
                  for how in settings.relocations if not RELOCATIONS[how].bound}
        for how in settings.relocations:
            relocation = RELOCATIONS[how]
            if relocation.bound:  # fitted to the pairs each distance counts
                for d, mask in masks:
                    fit = dict(known, reference=v_true, mask=mask, **_start(relocation, placed))
                    moved = relocate(pts, simplified, how, **relocation.keywords(fit, test))
                    v_test, t_test = _timed(visibility_matrix, simplified, moved, repeats=settings.repeats, sight=test)
                    rows.append(_row(base, s, how, d, t_test, t_true, agreement(v_true, v_test, mask)))
                continue
            v_test, t_test = _timed(visibility_matrix, simplified, placed[how], repeats=settings.repeats, sight=test)
            for d, mask in masks:
                rows.append(_row(base, s, how, d, t_test, t_true, agreement(v_true, v_test, mask)))
    return rows


def _start(relocation, placed: dict) -> dict:
    """``start=``: the heights of the first relocation a bound starts from that this set has."""
    for name in relocation.starts_from:
        if name in placed:
            return {"start": placed[name][:, 2]}
    return {}


def viewshed_rows(grid, simplified, base, settings, eyes, sight) -> list[dict]:
    """The viewshed measure: each observer's viewshed of T's samples on T and on S(T), per relocation.

    The observer is relocated onto S(T) as the points of the pair measure are; the targets
    are T's samples, standing ``target_height`` above the surface under test. A cell
    counts as a pair (observer, cell), so the agreement counts read as in the pair measure.
    Each row also says how S(T) changes the minimum visible height of the counted cells
    (:func:`min_height_error`: ``min_height_rms``, ``min_height_p95``, in z units), from
    the ``output="min_height"`` viewsheds of the same eyes (``target_height`` does not enter),
    unless ``settings.min_height`` is False (then they are left out: NaN in the table).

    With ``settings.siting`` = k > 0, the unit also sites k observers on S(T) and on T
    (:func:`siting_coverage`: ``siting_share``, ``siting_share_original``,
    ``siting_ratio``). The siting is one per unit, apart from the observers, relocations
    and distances: every row of the unit carries the same three values (its viewsheds
    have no distance limit). With ``settings.siting`` = 0 they are left out (NaN).
    """
    from ..core.metrics import viewshed_agreement
    from ..relocation.registry import RELOCATIONS, relocate
    from ..visibility import viewshed

    known = dict(_relocation_keywords(settings, grid, 0.0), target_height=settings.target_height)
    X, Y = np.meshgrid(grid.xs, grid.ys)
    siting = {}
    if settings.siting:
        siting = siting_coverage(grid, simplified, settings.siting, offset=settings.offset,
                                 target_height=settings.target_height, sight=sight)
    rows = []
    for s, eye in enumerate(eyes):
        eye = np.asarray(eye, dtype=np.float64).reshape(1, 3)
        v_true, t_true = _timed(viewshed, grid, eye[0], repeats=settings.repeats, sight=sight)
        h_true = viewshed(grid, eye[0], output="min_height", sight=sight) if settings.min_height else None
        dist = np.hypot(X - eye[0, 0], Y - eye[0, 1])
        heights = {}  # relocations that place the eye alike (often identity and half) share its raster
        for how in settings.relocations:
            moved = relocate(eye, simplified, how, **RELOCATIONS[how].keywords(known, sight))[0]
            v_test, t_test = _timed(viewshed, simplified, moved, at=grid, repeats=settings.repeats, sight=sight)
            place = np.asarray(moved, dtype=np.float64).tobytes()
            if settings.min_height and place not in heights:
                heights[place] = viewshed(simplified, moved, at=grid, output="min_height", sight=sight)
            for d in settings.max_distance:
                counted = dist <= _limit(d, grid, settings.distance_unit)
                row = _row(base, s, how, d, t_test, t_true, viewshed_agreement(v_true, v_test, counted))
                if settings.min_height:
                    row.update(min_height_error(h_true, heights[place], counted))
                row.update(siting)
                rows.append(row)
    return rows


def min_height_error(h_true: np.ndarray, h_test: np.ndarray, counted=None) -> dict:
    """How S(T) changes the minimum visible height: ``min_height_rms`` and ``min_height_p95``.

    ``h_true`` and ``h_test`` are :func:`terrainvis.viewshed`'s ``output="min_height"``
    rasters on T and on S(T) (the least height above the ground at which each sample is
    seen, in z units); the error is ``h_test - h_true`` over the ``counted`` cells (all
    when None) where both are finite. ``min_height_rms`` is its root mean square and
    ``min_height_p95`` the 95th percentile of its absolute value (linear interpolation);
    both are NaN when no cell counts.

    >>> h = np.array([[0.0, 2.0], [np.nan, 4.0]])
    >>> e = min_height_error(h, h + np.array([[0.0, 3.0], [1.0, -4.0]]))
    >>> round(e["min_height_rms"], 4), round(e["min_height_p95"], 4)
    (2.8868, 3.9)
    """
    both = np.isfinite(h_true) & np.isfinite(h_test)
    if counted is not None:
        both &= counted
    if not both.any():
        return {"min_height_rms": np.nan, "min_height_p95": np.nan}
    err = h_test[both] - h_true[both]
    return {"min_height_rms": float(np.sqrt(np.mean(err * err))),
            "min_height_p95": float(np.percentile(np.abs(err), 95))}


def siting_candidates(grid: HeightGrid) -> np.ndarray:
    """The siting's candidates on T (:func:`siting_coverage`): a lattice of its samples, at most
    :data:`SITING_LATTICE` per side (:func:`terrainvis.candidate_grid`)."""
    from ..visibility import candidate_grid

    return candidate_grid(grid, -(-max(grid.shape) // SITING_LATTICE))


def siting_coverage(grid: HeightGrid, simplified, k: int, *, offset: float = 0.0, target_height: float = 0.0,
                    sight=None) -> dict:
    """How S(T) changes an observer siting: the area of T that k observers chosen on S(T) see, against k chosen on T.

    The candidates are a lattice of T's samples (:data:`SITING_LATTICE` per side at most,
    :func:`terrainvis.candidate_grid`). :func:`terrainvis.site_observers` chooses k of them
    greedily on S(T), and k on T, each candidate's eye ``offset`` above the surface it is
    sited on (a practitioner who has only S(T) stands the mast on S(T)'s ground) and the
    targets T's samples, ``target_height`` above that surface. Then the two choices are
    built on T: each chosen position's viewshed on T (eye ``offset`` above T, targets
    ``target_height`` above T, no distance limit), and the union's area as a share of T's
    valid area (each sample weighted by its cell, :func:`terrainvis.visibility.sample_areas`).

    Parameters
    ----------
    grid : HeightGrid
        T.
    simplified : HeightGrid or TIN
        S(T), over T's footprint.
    k : int
        Observers to choose, >= 1 (all the candidates when the lattice has fewer than k).
    offset, target_height : float
        The eyes' and the targets' heights above the surface, as in the viewshed measure.
    sight : Sight, optional
        The sight lines' engine and earth model (:class:`~terrainvis.visibility.Sight`; its
        heights are ``offset`` and ``target_height``), for every siting and viewshed; by
        default ``Sight()``'s: the engine ``"auto"`` on a flat earth.

    Returns
    -------
    dict
        ``siting_share``: the share of T's area that S(T)'s choice sees on T;
        ``siting_share_original``: the same for T's own choice; ``siting_ratio``: the first
        over the second (NaN when T's choice sees nothing). All NaN when T has no
        candidate. The ratio would be at most 1 if the choice on T were the best one, but
        greedy is not optimal (it reaches at least ``1 - (1 - 1/k)**k`` > 1 - 1/e of the
        optimum), so S(T)'s choice can beat T's greedy choice: the ratio can exceed 1, by
        at most a factor ``1 / (1 - (1 - 1/k)**k)`` (1.46 for k = 4).

    Notes
    -----
    The siting on T is the same for every simplification of T: a process computes it once
    per T and set of options and keeps it by content (T's samples and coordinates), so a
    unit of a comparison pays the candidates' viewsheds on S(T) and k viewsheds on T (and
    the first unit of each T in a worker process the candidates' viewsheds on T as well).

    Examples
    --------
    S(T) = T chooses what T does:

    >>> from terrainvis import synthetic_terrain
    >>> T = synthetic_terrain("hills", size=17, seed=4)
    >>> siting_coverage(T, T, 2, offset=1.7)["siting_ratio"]
    1.0
    """
    from ..visibility import site_observers

    candidates = siting_candidates(grid)
    if candidates.shape[0] == 0:
        return {"siting_share": np.nan, "siting_share_original": np.nan, "siting_ratio": np.nan}
    k = min(int(k), candidates.shape[0])
    from ..visibility import Sight

    s = dataclasses.replace(Sight() if sight is None else sight, observer_height=offset, target_height=target_height)
    on_s = site_observers(simplified, candidates, k, workers=1, sight=s, at=grid).chosen
    share = _seen_share(grid, candidates[on_s], s)
    key = (fingerprint(grid), k, repr(s))
    share_t = _ORIGINAL_SITINGS.pop(key, None)  # popped and put back: the most recent last
    if share_t is None:
        on_t = site_observers(grid, candidates, k, workers=1, sight=s, at=grid).chosen
        share_t = _seen_share(grid, candidates[on_t], s)
    _ORIGINAL_SITINGS[key] = share_t
    while len(_ORIGINAL_SITINGS) > _ORIGINAL_SITINGS_SIZE:
        _ORIGINAL_SITINGS.pop(next(iter(_ORIGINAL_SITINGS)))
    return {"siting_share": share, "siting_share_original": share_t,
            "siting_ratio": share / share_t if share_t > 0 else np.nan}


#: T's own siting (the share its choice sees), kept across calls by content: every unit of a
#: terrain sites on the same T, in processes that receive T anew each time, so a cache on T
#: itself would not last (as :mod:`terrainvis.relocation.calibrated` keeps T's verdicts).
_ORIGINAL_SITINGS: dict = {}
_ORIGINAL_SITINGS_SIZE = 64


def _seen_share(grid: HeightGrid, positions: np.ndarray, sight) -> float:
    """The share of T's valid area that observers at ``positions`` (x, y) see together, their eyes and
    the targets as ``sight`` places them above T."""
    from ..visibility import sample_areas, viewshed

    seen = np.zeros(grid.shape, dtype=bool)
    for xy in positions:
        seen |= viewshed(grid, xy, sight=sight)
    valid = np.isfinite(grid.z)
    areas = sample_areas(grid)
    return float(areas[seen & valid].sum() / areas[valid].sum())


def _relocation_keywords(settings, grid: HeightGrid, end_radius: float) -> dict:
    """What a unit knows that a relocation may take (each takes those its entry declares,
    :meth:`terrainvis.relocation.Relocation.keywords`): the observers' offset, T, the run's
    seed, the predicate of the verdicts on S(T) (its end radius; a relocation that
    evaluates visibility gets the predicate's options as well) and the values of the run
    options the run's relocations declare (:func:`terrainvis.relocation.registry.run_options`)."""
    from ..relocation.registry import run_options

    own = {option.name: getattr(settings, option.name) for option in run_options(settings.relocations)}
    return {"offset": settings.offset, "original": grid, "end_radius": end_radius, "seed": settings.seed, **own}


def _row(base, s, how, d, t_test, t_true, counts) -> dict:
    row = dict(base, set=s, relocation=how, max_distance=d, los_seconds=t_test, los_seconds_original=t_true)
    row.update(counts)
    return row


# ---------------------------------------------------------------------- the registry
def _pair_tables(df) -> dict:
    """The pairs measure's own table: what the relocations beyond the paper's keep."""
    from . import report

    return {"beyond": report.beyond_paper(df)}


def _viewshed_tables(df) -> dict:
    """The viewshed measure's own table: the viewsheds kept, by method and level."""
    from . import report

    return {"viewsheds": report.viewshed_table(df)} if df["accuracy"].notna().any() else {}


def _pair_bytes(settings, grids) -> int:
    """The visibility matrices on T and on S(T) (a byte per ordered pair each),
    :func:`terrainvis.agreement`'s indices of the upper triangle (16 bytes per pair), and
    with ``max_distance`` a distance and a mask per distance (8 + 1 bytes per pair)."""
    n = settings.n_points
    per_pair = 2 + 16 + (0 if tuple(settings.max_distance) == (None,) else 8 + len(settings.max_distance))
    return per_pair * n * n


def _viewshed_bytes(settings, grids) -> int:
    """Eight arrays of 8 bytes per sample of the largest terrain (coordinates, distances, the two
    viewsheds, the two minimum-height rasters, a mask), and with siting the packed viewsheds of the
    candidates (a bit per sample each, :data:`SITING_LATTICE` squared of them at most)."""
    size = max(g.size for g in grids.values())
    return 8 * 8 * size + (SITING_LATTICE ** 2 * -(-size // 8) if settings.siting else 0)


def _pair_sets(grid, name, settings) -> list:
    return point_sets(grid, name, settings.n_points, settings.n_sets, settings.seed, settings.offset)


def _observer_sets(grid, name, settings) -> list:
    return [eye[None, :] for eye in observers(grid, name, settings)]


#: Every measure by name.
MEASURES: Registry = Registry("measure", {
    m.name: m for m in (
        Measure("pairs", _pair_sets, pair_rows, "pairs", "the paper's visibility matrices of random point sets",
                n_points=lambda s: s.n_points, n_sets=lambda s: s.n_sets, unit_bytes=_pair_bytes,
                tables=_pair_tables, paper=True),
        Measure("viewshed", _observer_sets, viewshed_rows, "cells",
                "each observer's viewshed of every sample of T", n_points=lambda s: 1,
                n_sets=lambda s: s.n_observers, unit_bytes=_viewshed_bytes, predicates=("exact",),
                tables=_viewshed_tables, columns=("min_height_rms", "min_height_p95", "siting_share",
                                                  "siting_share_original", "siting_ratio")),
    )
})
#: The measures terrainvis ships, which :func:`register` never replaces.
BUILTIN = MEASURES.builtin

#: Columns every results table has, in order; the measures' own (:attr:`Measure.columns`)
#: stand after ``false_blocked``, the last agreement count.
COMMON_COLUMNS = (
    "terrain", "set", "method", "kind", "level", "max_error_budget", "relocation", "measure", "predicate",
    "accuracy", "visible_kept", "blocked_kept", "accuracy_paper", "visible_area_ratio",
    "n_pairs", "agree_visible", "agree_blocked", "false_visible", "false_blocked",
    "n_points", "n_vertices", "n_vertices_original", "size_fraction", "nbytes", "nbytes_original",
    "max_error", "stopped_by", "rms_error", "volume_error", "end_radius", "backend", "cascaded",
    "simplify_seconds", "los_seconds", "los_seconds_original", "los_build_seconds",
    "seed", "max_distance", "distance_unit", "offset", "repair", "repair_max_snap", "zoom", "error",
)


def columns() -> tuple:
    """The columns of a results table, in order: :data:`COMMON_COLUMNS` with every registered
    measure's own columns (in the registry's order) after the agreement counts."""
    return _with_own(tuple(c for m in MEASURES.values() for c in m.columns))


def builtin_columns() -> tuple:
    """:func:`columns` with the measures terrainvis ships only."""
    return _with_own(tuple(c for name in MEASURES if name in BUILTIN for c in MEASURES[name].columns))


def _with_own(own: tuple) -> tuple:
    cut = COMMON_COLUMNS.index("false_blocked") + 1
    return COMMON_COLUMNS[:cut] + own + COMMON_COLUMNS[cut:]


def register(measure: Measure, *, replace: bool = False) -> Measure:
    """Add a measure to :data:`MEASURES` and return it.

    Raises
    ------
    TypeError
        ``measure`` is not a :class:`Measure`, or one of its functions is not callable.
    ValueError
        Its name is empty or taken (a built-in name always is), its predicates are unknown,
        or one of its columns is a column the results table already has.
    """
    if not isinstance(measure, Measure):
        raise TypeError(f"measure must be a terrainvis.experiment.measures.Measure, got {describe(measure)}")
    name = MEASURES.check_new(measure.name, replace=replace)
    for field in ("sets", "rows", "n_points", "n_sets", "unit_bytes"):
        if not callable(getattr(measure, field)):
            raise TypeError(f"measure {name!r}: {field} must be callable, got {describe(getattr(measure, field))}")
    if measure.tables is not None and not callable(measure.tables):
        raise TypeError(f"measure {name!r}: tables must be callable or None, got {describe(measure.tables)}")
    if not measure.predicates or any(p not in ("exact", "paper") for p in measure.predicates):
        raise ValueError(f"measure {name!r}: predicates must be some of ['exact', 'paper'], got "
                         f"{list(measure.predicates)}")
    _check_columns(measure, name, replace)
    MEASURES[name] = measure
    return measure


def _check_columns(measure: Measure, name: str, replace: bool) -> None:
    """A measure's own columns: a tuple of names the results table does not have yet (those of
    the measure it replaces aside)."""
    own = measure.columns
    if not isinstance(own, tuple) or any(not isinstance(c, str) or not c.isidentifier() for c in own):
        raise TypeError(f"measure {name!r}: columns must be a tuple of column names (identifiers), got {describe(own)}")
    replaced = MEASURES[name].columns if replace and name in MEASURES else ()
    taken = sorted((set(columns()) - set(replaced)) & set(own)) + sorted({c for c in own if own.count(c) > 1})
    if taken:
        raise ValueError(f"measure {name!r}: columns {taken} are taken (the results table has them, or they repeat)")


def unregister(name: str) -> Measure:
    """Remove a measure added with :func:`register` and return it (built-in ones stay)."""
    return MEASURES.remove(name)


def available() -> list[str]:
    """Every measure's name, in registry order."""
    return MEASURES.names()
