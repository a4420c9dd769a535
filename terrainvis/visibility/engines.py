"""The line-of-sight engines: one interface, one registry.

An :class:`Engine` answers the predicate of :mod:`terrainvis.visibility` for pairs of
points (``pairs``: one verdict per segment) and for every pair of a point set
(``matrix``); a viewshed of targets other than a grid's own samples asks it for the
segments from the eye to each target. Each engine says which terrains it runs on and
whether it models earth curvature. :data:`ENGINES` holds them; ``engine="auto"`` (the
default everywhere) picks the exact grid walk on a HeightGrid and, on a TIN, Embree on a
flat earth or the exact TIN clipper under curvature. ``line_of_sight``,
``visibility_matrix``, ``viewshed``, ``cumulative_viewshed``, ``compare(engine=...)``
and ``--engine`` all take a name of :data:`ENGINES`, and a new engine is one
:func:`register` call.

The built-in engines:

``"grid"``
    The exact walk over a HeightGrid's surface, accelerated by a min/max pyramid
    (:mod:`terrainvis.visibility.grid`).
``"tin"``
    The exact clip of each segment's ground track against the faces of a TIN
    (:mod:`terrainvis.visibility.tin`); any curvature.
``"embree"``
    Embree's occlusion rays in float32 on the terrain's TIN (:mod:`terrainvis.visibility.embree`);
    flat earth only; within :func:`terrainvis.visibility.embree_tolerance` of the exact
    answer.
``"exact"``
    The exact predicate on any terrain: ``"grid"`` on a HeightGrid, ``"tin"`` on a TIN
    (for ``compare`` and ``evaluate``, which ask one engine for T, a grid, and for S(T),
    often a TIN: ``"auto"`` answers on TINs with Embree on a flat earth).
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np

from ..core.registry import Registry
from ..core.terrain import HeightGrid
from ..core.validate import describe

__all__ = ["Engine", "Predicate", "ENGINES", "AUTO", "register", "unregister", "available", "engine_names",
           "check_name", "choose", "verdicts_text"]

#: The engine name that picks one by terrain and curvature (see the module docstring).
AUTO = "auto"
#: The kinds of terrain an engine may run on.
TERRAIN_KINDS = ("grid", "tin")


class Predicate(NamedTuple):
    """The predicate an engine answers, with every length resolved for the terrain.

    ``delta`` is the trim length and ``tol`` the clearance tolerance of the terrain
    (:func:`terrainvis.visibility.trim_length`, :func:`~terrainvis.visibility.clearance_tolerance`);
    ``end_radius`` the horizontal distance around each end that is not tested; ``kc``
    the curvature coefficient ``curvature / (2 R)`` (0: a flat earth).
    """

    delta: float
    tol: float
    end_radius: float
    kc: float


@dataclass(frozen=True)
class Engine:
    """Every fact about one line-of-sight engine.

    Parameters
    ----------
    name : str
        How users name it (``engine=name``, ``--engine name``).
    pairs : callable
        ``pairs(terrain, a, b, predicate) -> (m,) bool``: whether each segment
        ``a[i] -> b[i]`` (checked (m, 3) float64 arrays inside the footprint) is visible
        under ``predicate`` (a :class:`Predicate`).
    matrix : callable
        ``matrix(terrain, points, predicate) -> (n, n) bool``: the symmetric visibility
        matrix of checked (n, 3) points, True on the diagonal.
    summary : str
        One line for ``--help`` and the docs.
    terrains : tuple of str
        The terrains it runs on: ``"grid"`` (HeightGrid), ``"tin"`` (TIN).
    curvature : bool
        Whether it models earth curvature (``predicate.kc`` > 0).
    exact : bool
        Whether its verdicts are the exact predicate's (Embree's float32 rays are not).
    """

    name: str
    pairs: Callable
    matrix: Callable
    summary: str
    terrains: tuple = TERRAIN_KINDS
    curvature: bool = True
    exact: bool = True

    def runs_on(self, terrain) -> bool:
        """Whether the engine runs on ``terrain`` (a HeightGrid or a TIN)."""
        return _kind(terrain) in self.terrains


def _kind(terrain) -> str:
    return "grid" if isinstance(terrain, HeightGrid) else "tin"


# ---------------------------------------------------------------------- the built-in engines
def _grid_pairs(terrain, a, b, p: Predicate) -> np.ndarray:
    from .grid import grid_clearance

    return grid_clearance(terrain, a, b, delta=p.delta, tol=p.tol, los=True, end_radius=p.end_radius, kc=p.kc) >= -p.tol


def _grid_matrix(terrain, points, p: Predicate) -> np.ndarray:
    from .grid import grid_matrix

    return grid_matrix(terrain, points, delta=p.delta, tol=p.tol, end_radius=p.end_radius, kc=p.kc)


def _tin_pairs(terrain, a, b, p: Predicate) -> np.ndarray:
    from .tin import tin_clearance

    return tin_clearance(terrain, a, b, delta=p.delta, end_radius=p.end_radius, kc=p.kc) >= -p.tol


def _tin_matrix(terrain, points, p: Predicate) -> np.ndarray:
    from .tin import tin_matrix

    return tin_matrix(terrain, points, delta=p.delta, tol=p.tol, end_radius=p.end_radius, kc=p.kc)


def _embree_pairs(terrain, a, b, p: Predicate) -> np.ndarray:
    from .embree import embree_visible

    return embree_visible(terrain, a, b, delta=p.delta, end_radius=p.end_radius)


def _embree_matrix(terrain, points, p: Predicate) -> np.ndarray:
    from .embree import embree_matrix

    return embree_matrix(terrain, points, delta=p.delta, end_radius=p.end_radius)


def _exact_pairs(terrain, a, b, p: Predicate) -> np.ndarray:
    return (_grid_pairs if isinstance(terrain, HeightGrid) else _tin_pairs)(terrain, a, b, p)


def _exact_matrix(terrain, points, p: Predicate) -> np.ndarray:
    return (_grid_matrix if isinstance(terrain, HeightGrid) else _tin_matrix)(terrain, points, p)


#: Every engine by name.
ENGINES: Registry = Registry("engine", {
    e.name: e for e in (
        Engine("grid", _grid_pairs, _grid_matrix, "the exact walk over a HeightGrid's surface", terrains=("grid",)),
        Engine("tin", _tin_pairs, _tin_matrix, "the exact clip of each segment against a TIN's faces",
               terrains=("tin",)),
        Engine("embree", _embree_pairs, _embree_matrix, "Embree's float32 rays on the terrain's TIN (flat earth)",
               curvature=False, exact=False),
        Engine("exact", _exact_pairs, _exact_matrix,
               "the exact predicate on any terrain: the grid walk on a HeightGrid, the TIN clipper on a TIN"),
    )
})
#: The engines terrainvis ships, which :func:`register` never replaces.
BUILTIN = ENGINES.builtin


def verdicts_text(engine: str, tins: bool, kc: float = 0.0) -> str:
    """Which engine decides the verdicts of a run, in a phrase for its summary: the exact
    grid walk on grids, and on TINs (``tins``) what ``engine`` picks there."""
    if not tins:
        return "verdicts exact"
    on_tin = ENGINES["embree" if kc == 0.0 else "tin"] if engine == AUTO else ENGINES[engine]
    if on_tin.exact:
        return "verdicts exact"
    return f"verdicts on TINs by engine {on_tin.name!r}, not exact (--engine exact: the exact TIN clipper)"


def engine_names() -> list[str]:
    """Every value the ``engine`` argument takes: ``"auto"`` and the registered engines."""
    return [AUTO, *ENGINES]


def check_name(engine) -> str:
    """``engine`` if it is ``"auto"`` or a registered engine's name, else a ValueError listing them."""
    if not isinstance(engine, str) or (engine != AUTO and engine not in ENGINES):
        raise ValueError(f"engine must be one of {engine_names()}, got {engine!r}")
    return engine


def choose(engine, terrain, kc: float = 0.0) -> Engine:
    """The engine that answers on ``terrain``: ``engine`` by name, or the one ``"auto"`` picks.

    Raises
    ------
    ValueError
        An unknown name, an engine that does not run on this terrain, or one that cannot
        model the curvature asked for; the message says what to use instead.
    """
    check_name(engine)
    if engine == AUTO:
        if isinstance(terrain, HeightGrid):
            return ENGINES["grid"]
        return ENGINES["embree"] if kc == 0.0 else ENGINES["tin"]
    chosen = ENGINES[engine]
    if not chosen.runs_on(terrain):
        kinds = " or ".join("a HeightGrid" if k == "grid" else "a TIN" for k in chosen.terrains)
        raise ValueError(f"engine {engine!r} needs {kinds}, got {describe(terrain)}; use engine='auto' or one of "
                         f"{[n for n, e in ENGINES.items() if e.runs_on(terrain)]}")
    if kc != 0.0 and not chosen.curvature:
        raise ValueError(
            f"engine {engine!r} cannot model earth curvature (its straight rays meet one fixed mesh, and the "
            "curvature bulge depends on each pair); use engine='auto' (exact: the grid walk on a HeightGrid, "
            "the TIN clipper on a TIN) or curvature=0"
        )
    return chosen


def register(engine: Engine, *, replace: bool = False) -> Engine:
    """Add an engine to :data:`ENGINES` and return it.

    Raises
    ------
    TypeError
        ``engine`` is not an :class:`Engine`, or ``pairs``/``matrix`` are not callable.
    ValueError
        Its name is empty, ``"auto"`` or taken (a built-in name always is), or its
        terrains are not among ``"grid"`` and ``"tin"``.
    """
    if not isinstance(engine, Engine):
        raise TypeError(f"engine must be a terrainvis.visibility.Engine, got {describe(engine)}")
    name = engine.name
    if name == AUTO:
        raise ValueError("engine.name must not be 'auto' (it means: choose an engine for the terrain)")
    ENGINES.check_new(name, replace=replace)
    for field in ("pairs", "matrix"):
        fn = getattr(engine, field)
        if not callable(fn):
            raise TypeError(f"engine {name!r}: {field} must be callable, got {describe(fn)}")
        _check_arity(name, field, fn, 4 if field == "pairs" else 3)
    if not engine.terrains or any(k not in TERRAIN_KINDS for k in engine.terrains):
        raise ValueError(f"engine {name!r}: terrains must be some of {list(TERRAIN_KINDS)}, got "
                         f"{list(engine.terrains)}")
    ENGINES[name] = engine
    return engine


def _check_arity(name: str, field: str, fn, n: int) -> None:
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):
        return
    try:
        sig.bind(*range(n))
    except TypeError:
        args = "(terrain, a, b, predicate)" if n == 4 else "(terrain, points, predicate)"
        raise TypeError(f"engine {name!r}: {field} must take {args}, but its signature is {sig}") from None


def unregister(name: str) -> Engine:
    """Remove an engine added with :func:`register` and return it (built-in ones stay)."""
    return ENGINES.remove(name)


def available() -> list[str]:
    """Every engine's name, in registry order (``"auto"`` chooses among them)."""
    return ENGINES.names()
