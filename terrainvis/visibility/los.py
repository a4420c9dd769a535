"""Line of sight between pairs of points: the public functions over the grid, TIN and Embree engines.

See the package docstring of :mod:`terrainvis.visibility` for the predicate and the engines.
"""

from __future__ import annotations

import numpy as np

from ..core.memory import check_memory
from ..core.validate import as_points, describe
from ..core.terrain import HeightGrid, as_terrain
from . import embree as _embree
from .engines import Predicate, choose
from .grid import grid_clearance
from .predicate import (
    EARTH_RADIUS,
    _check_inside,
    _prepare_segments,
    _prepare_terrain,
    clearance_tolerance,
    trim_length,
)
from .sight import Sight, pair_sight
from .tin import tin_clearance

__all__ = ["min_clearance", "line_of_sight", "visibility_matrix", "embree_tolerance"]


def embree_tolerance(terrain) -> float:
    """Band of minimum clearances around 0 where Embree (float32) may disagree with the exact answer."""
    as_terrain(terrain)
    return _embree.embree_tolerance(terrain)


# ----------------------------------------------------------------- public API
def min_clearance(
    terrain, a, b, *, end_radius: float = 0.0, curvature: float = 0.0, earth_radius: float = EARTH_RADIUS,
    sight: Sight | None = None,
) -> np.ndarray:
    """Exact minimum clearance of each segment a[i] -> b[i] over its tested interval.

    The tested interval is [tau, 1 - tau], narrowed by ``end_radius`` (see the package
    docstring of :mod:`terrainvis.visibility`).

    Parameters
    ----------
    terrain : HeightGrid or TIN
        A HeightGrid must be free of nodata.
    a, b : (m, 3) array_like
        Segment ends (x, y, z), inside the terrain's footprint.
    end_radius : float, default 0.0
        Horizontal distance (x/y units) around each end inside which the surface is not
        tested. 0 gives the exact predicate.
    curvature : float, default 0.0
        Earth curvature and refraction, GDAL's ``-cc`` coefficient: 0 a flat earth, 1
        the geometric curvature, 0.85714 (``1 - 1/7``) curvature with standard
        refraction. The sight line must then clear the surface raised by
        ``curvature * d1 * d2 / (2 * earth_radius)``, d1 and d2 the horizontal
        distances to its two ends (symmetric in a and b).
    earth_radius : float, default 6378137.0
        Radius of the earth in the terrain's x/y units (WGS84's semi-major axis in
        metres, as GDAL takes it).
    sight : Sight, optional
        The predicate as one value (:class:`~terrainvis.visibility.Sight`: its end radius,
        curvature and earth radius; the clearance is exact whatever its engine), instead of
        the keywords above.

    Returns
    -------
    (m,) float64
        ``min_t z_seg(t) - surface(x(t), y(t)) - k L**2 t (1 - t)`` over the tested
        interval (``k = curvature / (2 earth_radius)``, L the horizontal length; the last
        term is 0 on a flat earth); ``inf`` for segments no longer than twice
        :func:`trim_length` or (for ``end_radius > 0``) with a horizontal length of at
        most ``2 * end_radius``. The segment is visible when this is
        ``>= -clearance_tolerance(terrain)``.

    Raises
    ------
    OutsideFootprintError
        When points lie outside the footprint.
    NodataError
        When the grid holds NaN.

    Examples
    --------
    >>> from terrainvis import HeightGrid
    >>> g = HeightGrid([[0.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 0.0]])
    >>> float(min_clearance(g, [[0.0, 1.0, 1.0]], [[2.0, 1.0, 1.0]])[0])
    -9.0

    A point 1 below a slope (the surface falls from 2 at x = 0 to 0 at x = 1) looking
    over flat ground: the segment is underground for x < 0.5, so it is blocked unless
    the end radius covers that part. A radius of 1 leaves nothing to test.

    >>> g = HeightGrid([[2.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    >>> a, b = [[0.0, 0.5, 1.0]], [[2.0, 0.5, 1.0]]
    >>> [round(float(min_clearance(g, a, b, end_radius=r)[0]), 4) for r in (0.0, 0.25, 0.75, 1.0)]
    [-1.0, -0.5, 0.5, inf]

    Two towers 10 m high, 20 km apart on flat ground: the earth rises
    ``0.85714 * 10 km * 10 km / (2 R) = 6.72 m`` between them, under the 10 m sight line.

    >>> g = HeightGrid(np.zeros((2, 3)), dx=10_000.0, dy=10_000.0)
    >>> round(float(min_clearance(g, [[0.0, 0.0, 10.0]], [[20_000.0, 0.0, 10.0]], curvature=0.85714)[0]), 2)
    3.28
    """
    s = pair_sight(sight, {"end_radius": end_radius, "curvature": curvature, "earth_radius": earth_radius},
                   "min_clearance")
    a, b = _prepare_segments(terrain, a, b, "min_clearance")
    return segment_clearances(terrain, a, b, end_radius=s.end_radius, kc=s.kc)


def segment_clearances(terrain, a: np.ndarray, b: np.ndarray, *, end_radius: float, kc: float) -> np.ndarray:
    """:func:`min_clearance` of checked input: ``a``, ``b`` (m, 3) float64 contiguous, inside
    the footprint, ``end_radius`` >= 0 and ``kc`` the curvature coefficient. For callers
    that know their segments are inside (the calibrated relocation's neighbours: on a TIN
    the checks locate every end: about a third of the cost of short segments)."""
    delta = trim_length(terrain)
    if isinstance(terrain, HeightGrid):
        return grid_clearance(
            terrain, a, b, delta=delta, tol=clearance_tolerance(terrain), los=False, end_radius=end_radius, kc=kc
        )
    return tin_clearance(terrain, a, b, delta=delta, end_radius=end_radius, kc=kc)


def line_of_sight(
    terrain, a, b, *, engine: str = "auto", end_radius: float = 0.0, curvature: float = 0.0,
    earth_radius: float = EARTH_RADIUS, sight: Sight | None = None, eye=None,
) -> np.ndarray:
    """Whether each pair of points a[i], b[i] sees each other.

    Parameters
    ----------
    terrain : HeightGrid or TIN
    a, b : (m, 3) array_like
        Segment ends inside the footprint.
    engine : str
        A name of :data:`terrainvis.visibility.ENGINES`: ``"grid"``, the exact grid walk
        (HeightGrid only); ``"tin"``, the exact TIN clipper (TIN only); ``"embree"``,
        Embree rays in float32 on the terrain's TIN (flat earth only); or one registered
        with :func:`terrainvis.visibility.register_engine`. ``"auto"``: grid for a
        HeightGrid; for a TIN Embree, or the exact TIN clipper under earth curvature.
    end_radius : float, default 0.0
        Horizontal distance around each end inside which the surface is not tested (see
        :mod:`terrainvis.visibility`); 0 gives the exact predicate.
    curvature : float, default 0.0
        Earth curvature and refraction, GDAL's ``-cc`` coefficient: 0 a flat earth, 1
        the geometric curvature, 0.85714 (``1 - 1/7``) curvature with standard
        refraction. The sight line must then clear the surface raised by
        ``curvature * d1 * d2 / (2 * earth_radius)``, d1 and d2 the horizontal
        distances to its two ends (symmetric in a and b).
    earth_radius : float, default 6378137.0
        Radius of the earth in the terrain's x/y units (WGS84's semi-major axis in
        metres, as GDAL takes it).
    sight : Sight, optional
        The predicate as one value (:class:`~terrainvis.visibility.Sight`: engine, end
        radius, curvature, earth radius), instead of the keywords above; the points carry
        their own heights (the Sight's are not used) and a Sight with a field of view is
        refused (a viewshed's).
    eye : EyeSurface, optional
        The eye surface shipped with ``terrain`` as S(T) (:func:`terrainvis.eye_surface`):
        each point then stands where it places it, ``terrain(x, y)`` plus its eye height
        plus its offset there, as ``relocate(points, terrain, "eye", eye=eye)`` places
        them (the given heights are not read).

    Returns
    -------
    (m,) bool

    Examples
    --------
    >>> from terrainvis import HeightGrid
    >>> g = HeightGrid([[0.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 0.0]])
    >>> line_of_sight(g, [[0.0, 1.0, 1.0], [0.0, 0.0, 0.0]], [[2.0, 1.0, 1.0], [2.0, 0.0, 0.0]]).tolist()
    [False, True]
    """
    s = pair_sight(sight, {"engine": engine, "end_radius": end_radius, "curvature": curvature,
                           "earth_radius": earth_radius}, "line_of_sight")
    a, b = _prepare_segments(terrain, a, b, "line_of_sight")
    if eye is not None:
        a, b = _eye_heights(eye, terrain, a), _eye_heights(eye, terrain, b)
    chosen = choose(s.engine, terrain, s.kc)
    return np.asarray(chosen.pairs(terrain, a, b, _predicate(terrain, s)), dtype=bool)


def visibility_matrix(
    terrain, points, *, engine: str = "auto", end_radius: float = 0.0, curvature: float = 0.0,
    earth_radius: float = EARTH_RADIUS, sight: Sight | None = None, eye=None,
) -> np.ndarray:
    """Mutual visibility of every pair of points.

    Pairs are computed once (i < j) without building per-pair coordinate arrays on the
    grid engine (a parallel kernel loops over the pairs) and in bounded chunks on Embree
    and on the TIN clipper.

    Parameters
    ----------
    terrain : HeightGrid or TIN
    points : (n, 3) array_like
        Points inside the footprint.
    engine : str
        As in :func:`line_of_sight`.
    end_radius : float, default 0.0
        Horizontal distance around each end inside which the surface is not tested (see
        :mod:`terrainvis.visibility`); 0 gives the exact predicate.
    curvature : float, default 0.0
        Earth curvature and refraction, GDAL's ``-cc`` coefficient: 0 a flat earth, 1
        the geometric curvature, 0.85714 (``1 - 1/7``) curvature with standard
        refraction. The sight line must then clear the surface raised by
        ``curvature * d1 * d2 / (2 * earth_radius)``, d1 and d2 the horizontal
        distances to its two ends (symmetric in a and b).
    earth_radius : float, default 6378137.0
        Radius of the earth in the terrain's x/y units (WGS84's semi-major axis in
        metres, as GDAL takes it).
    sight : Sight, optional
        As in :func:`line_of_sight`.
    eye : EyeSurface, optional
        The eye surface shipped with ``terrain`` as S(T) (:func:`terrainvis.eye_surface`):
        each point then stands where it places it, ``terrain(x, y)`` plus its eye height
        plus its offset there, as ``relocate(points, terrain, "eye", eye=eye)`` places
        them (the given heights are not read).

    Returns
    -------
    (n, n) bool
        Symmetric, True on the diagonal.

    Examples
    --------
    >>> from terrainvis import HeightGrid
    >>> g = HeightGrid([[0.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 0.0]])
    >>> visibility_matrix(g, [[0.0, 1.0, 1.0], [2.0, 1.0, 1.0], [0.0, 0.0, 0.0]]).astype(int)
    array([[1, 0, 1],
           [0, 1, 0],
           [1, 0, 1]])
    """
    s = pair_sight(sight, {"engine": engine, "end_radius": end_radius, "curvature": curvature,
                           "earth_radius": earth_radius}, "visibility_matrix")
    _prepare_terrain(terrain, "visibility_matrix")
    pts = np.ascontiguousarray(as_points(points, "points", 3), dtype=np.float64)
    n = pts.shape[0]
    check_memory(n * n, f"visibility_matrix of {n:,} points (a {n:,} x {n:,} boolean matrix)")
    _check_inside(terrain, pts, "points")
    if eye is not None:
        pts = _eye_heights(eye, terrain, pts)
    chosen = choose(s.engine, terrain, s.kc)
    return np.asarray(chosen.matrix(terrain, pts, _predicate(terrain, s)), dtype=bool)


def _predicate(terrain, s: Sight) -> Predicate:
    """The engines' predicate of a Sight on ``terrain`` (its trim length and clearance tolerance)."""
    return Predicate(trim_length(terrain), clearance_tolerance(terrain), s.end_radius, s.kc)


def _eye_heights(eye, terrain, points: np.ndarray) -> np.ndarray:
    """``points`` (checked, inside the footprint) at the heights ``eye`` gives them on ``terrain``
    (a new array). ``eye`` is anything with ``heights(points, terrain)``: an EyeSurface of
    :mod:`terrainvis.relocation.eye`, which this layer does not import."""
    heights = getattr(eye, "heights", None)
    if not callable(heights):
        raise TypeError(f"eye must be an EyeSurface (terrainvis.eye_surface), got {describe(eye)}")
    out = np.array(points, dtype=np.float64, copy=True)
    if out.shape[0]:
        out[:, 2] = heights(out, terrain)
    return np.ascontiguousarray(out)
