"""Line of sight between pairs of points: the public functions over the grid, TIN and Embree engines.

See the package docstring of :mod:`terrainvis.visibility` for the predicate and the engines.
"""

from __future__ import annotations

import numpy as np

from .._validate import as_points
from ..terrain import HeightGrid, as_terrain
from . import embree as _embree
from .grid import grid_clearance, grid_matrix
from .predicate import (
    _check_end_radius,
    _check_engine,
    _check_inside,
    _prepare_segments,
    _prepare_terrain,
    clearance_tolerance,
    trim_length,
)
from .tin import tin_clearance

__all__ = ["min_clearance", "line_of_sight", "visibility_matrix", "embree_tolerance"]


def embree_tolerance(terrain) -> float:
    """Band of minimum clearances around 0 where Embree (float32) may disagree with the exact answer."""
    as_terrain(terrain)
    return _embree.embree_tolerance(terrain)


# ----------------------------------------------------------------- public API
def min_clearance(terrain, a, b, *, end_radius: float = 0.0) -> np.ndarray:
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

    Returns
    -------
    (m,) float64
        ``min_t z_seg(t) - surface(x(t), y(t))`` over the tested interval; ``inf`` for
        segments no longer than twice :func:`trim_length` or (for ``end_radius > 0``)
        with a horizontal length of at most ``2 * end_radius``. The segment is visible
        when this is ``>= -clearance_tolerance(terrain)``.

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
    """
    a, b = _prepare_segments(terrain, a, b, "min_clearance")
    end_radius = _check_end_radius(end_radius)
    delta = trim_length(terrain)
    if isinstance(terrain, HeightGrid):
        return grid_clearance(
            terrain, a, b, delta=delta, tol=clearance_tolerance(terrain), los=False, end_radius=end_radius
        )
    return tin_clearance(terrain, a, b, delta=delta, end_radius=end_radius)


def line_of_sight(terrain, a, b, *, engine: str = "auto", end_radius: float = 0.0) -> np.ndarray:
    """Whether each pair of points a[i], b[i] sees each other.

    Parameters
    ----------
    terrain : HeightGrid or TIN
    a, b : (m, 3) array_like
        Segment ends inside the footprint.
    engine : {"auto", "grid", "embree"}
        ``"grid"``: exact grid walk (HeightGrid only). ``"embree"``: Embree rays in
        float32 on the terrain's TIN. ``"auto"``: grid for a HeightGrid, Embree for a TIN.
    end_radius : float, default 0.0
        Horizontal distance around each end inside which the surface is not tested (see
        :mod:`terrainvis.visibility`); 0 gives the exact predicate.

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
    a, b = _prepare_segments(terrain, a, b, "line_of_sight")
    engine = _check_engine(engine, terrain)
    end_radius = _check_end_radius(end_radius)
    delta = trim_length(terrain)
    if engine == "grid":
        tol = clearance_tolerance(terrain)
        return grid_clearance(terrain, a, b, delta=delta, tol=tol, los=True, end_radius=end_radius) >= -tol
    return _embree.embree_visible(terrain, a, b, delta=delta, end_radius=end_radius)


def visibility_matrix(terrain, points, *, engine: str = "auto", end_radius: float = 0.0) -> np.ndarray:
    """Mutual visibility of every pair of points.

    Pairs are computed once (i < j) without building per-pair coordinate arrays on the
    grid engine (a parallel kernel loops over the pairs) and in bounded chunks on Embree.

    Parameters
    ----------
    terrain : HeightGrid or TIN
    points : (n, 3) array_like
        Points inside the footprint.
    engine : {"auto", "grid", "embree"}
    end_radius : float, default 0.0
        Horizontal distance around each end inside which the surface is not tested (see
        :mod:`terrainvis.visibility`); 0 gives the exact predicate.

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
    _prepare_terrain(terrain, "visibility_matrix")
    pts = np.ascontiguousarray(as_points(points, "points", 3), dtype=np.float64)
    _check_inside(terrain, pts, "points")
    engine = _check_engine(engine, terrain)
    end_radius = _check_end_radius(end_radius)
    delta = trim_length(terrain)
    if engine == "grid":
        return grid_matrix(terrain, pts, delta=delta, tol=clearance_tolerance(terrain), end_radius=end_radius)
    return _embree.embree_matrix(terrain, pts, delta=delta, end_radius=end_radius)
