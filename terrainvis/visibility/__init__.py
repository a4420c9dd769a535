"""Exact line of sight (LOS) on height grids and TINs.

Definition
----------
Points p and q see each other when the open segment pq nowhere passes below the
terrain surface: the *clearance*

    c(t) = z_seg(t) - surface(x(t), y(t)),   x(t), y(t), z_seg(t) = p + t (q - p),

is at least ``-tol`` for every t in [tau, 1 - tau].

* ``tau = delta / |q - p|`` trims the length ``delta`` (3-D) off both ends, so that end
  points lying on the surface do not block themselves. ``delta`` is
  :func:`trim_length`: ``1e-5`` times the horizontal diagonal of the terrain's extent
  (3.6 cm on a 120 x 120 grid of 30 m cells). A segment not longer than ``2 delta`` is
  trimmed away entirely and is visible (a point sees itself); its clearance is ``inf``.
* ``tol`` is :func:`clearance_tolerance`: ``1e-9`` times :func:`terrain_scale`, the
  larger of the horizontal diagonal and the elevation range. It absorbs float64
  rounding, so that a segment grazing the surface (clearance exactly 0) is visible. It
  does not depend on the absolute elevation, so adding a constant to the terrain and to
  the points does not change the answer.
* A segment whose ends sit on the surface can run underground and meet the surface only
  at its ends. It is **blocked** (its clearance is negative inside the interval). This is
  common after simplification, where points often sit below the simplified surface.

The surface of a HeightGrid is the piecewise-linear surface with every cell split along
the (r, c)-(r+1, c+1) diagonal, identical to ``grid.to_tin()``.

End radius
----------
``end_radius`` r >= 0 (default 0) is a horizontal distance. Around each end of a segment
the surface is not tested within horizontal distance r of that end; the rest of the
segment is tested exactly as above, including the underground rule at the ends of the
tested part (a tested part that starts below the surface is blocked). With ``L_h`` the
segment's horizontal length, the tested interval is

    [max(tau, r / L_h), min(1 - tau, 1 - r / L_h)].

A segment with ``L_h <= 2 r`` (for r > 0), or no longer than ``2 delta``, is visible and
its clearance is ``inf``. ``end_radius = 0`` is the exact predicate above, bit for bit.
This is the predicate of DEM ray casters that test only the cells strictly between
observer and target (r = one cell). It matters for points lying below the surface under
test (common after simplification): such a point can see over the surface once r covers
the part of the segment that runs underground.

Engines
-------
``"grid"`` (HeightGrid only)
    An exact walk of the ground track across grid lines and cell diagonals (the
    clearance is linear between crossings, so checking every crossing is exact),
    accelerated by a min/max pyramid, compiled with numba and parallel over pairs.
``"embree"`` (any terrain; a HeightGrid goes through ``grid.to_tin()``)
    Embree occlusion rays in float32 plus upward vertical rays from both ends of the
    tested part (the underground fix). It agrees with the exact answer on every pair whose minimum
    clearance is farther than :func:`~terrainvis.visibility.embree.embree_tolerance`
    from zero.
``"auto"``
    ``"grid"`` for a HeightGrid, ``"embree"`` for a TIN.

:func:`min_clearance` is always exact: the grid walk on a HeightGrid, and on a TIN a
clip of the ground track (over the tested interval) against every face it crosses.

References
----------
B. Duvenhage, "Using an implicit min/max KD-tree for doing efficient terrain line of
sight calculations", AFRIGRAPH 2009, doi:10.1145/1503454.1503465.
"""

from __future__ import annotations

import numpy as np

from .._validate import as_nonnegative_finite, as_points, describe
from ..errors import OutsideFootprintError
from ..terrain import HeightGrid, as_terrain

__all__ = [
    "ENGINES",
    "TRIM_REL",
    "TOL_REL",
    "min_clearance",
    "line_of_sight",
    "visibility_matrix",
    "trim_length",
    "clearance_tolerance",
    "terrain_scale",
    "embree_tolerance",
    "viewshed",
    "lowest_point",
]

#: Valid values of the ``engine`` argument.
ENGINES = ("auto", "grid", "embree")
#: Trim length as a fraction of the horizontal diagonal (see :func:`trim_length`).
TRIM_REL = 1e-5
#: Clearance tolerance as a fraction of :func:`terrain_scale`.
TOL_REL = 1e-9


# ----------------------------------------------------------------- definitions
def _extent_diagonal(terrain) -> float:
    xmin, xmax, ymin, ymax = terrain.extent
    return float(np.hypot(xmax - xmin, ymax - ymin))


def terrain_scale(terrain) -> float:
    """``max(horizontal diagonal of the extent, elevation range)`` of the terrain.

    Parameters
    ----------
    terrain : HeightGrid or TIN

    Returns
    -------
    float
    """
    as_terrain(terrain)
    s = terrain._cache.get("visibility_scale")
    if s is None:
        z = terrain.z if isinstance(terrain, HeightGrid) else terrain.vertices[:, 2]
        zr = float(np.nanmax(z) - np.nanmin(z)) if np.isfinite(z).any() else 0.0
        s = max(_extent_diagonal(terrain), zr)
        terrain._cache["visibility_scale"] = s
    return s


def trim_length(terrain) -> float:
    """Length ``delta`` trimmed off both ends of every segment: ``TRIM_REL`` x diagonal.

    Examples
    --------
    >>> from terrainvis import HeightGrid
    >>> trim_length(HeightGrid(np.zeros((2, 2)), dx=3.0, dy=4.0))
    5e-05
    """
    as_terrain(terrain)
    return TRIM_REL * _extent_diagonal(terrain)


def clearance_tolerance(terrain) -> float:
    """Clearance ``tol`` down to which a segment still counts as visible: ``TOL_REL`` x scale."""
    return TOL_REL * terrain_scale(terrain)


def embree_tolerance(terrain) -> float:
    """Band of minimum clearances around 0 where Embree (float32) may disagree with the exact answer."""
    from .embree import embree_tolerance as _et

    as_terrain(terrain)
    return _et(terrain)


# ----------------------------------------------------------------- validation
def _check_engine(engine, terrain) -> str:
    if not isinstance(engine, str) or engine not in ENGINES:
        raise ValueError(f"engine must be one of {list(ENGINES)}, got {engine!r}")
    if engine == "auto":
        return "grid" if isinstance(terrain, HeightGrid) else "embree"
    if engine == "grid" and not isinstance(terrain, HeightGrid):
        raise ValueError(
            f"engine 'grid' needs a HeightGrid, got {describe(terrain)}; use engine='embree' or 'auto' for a TIN"
        )
    return engine


def _check_end_radius(end_radius) -> float:
    if isinstance(end_radius, (str, bytes)):
        raise TypeError(f"end_radius must be a real number, got {describe(end_radius)}")
    return as_nonnegative_finite(end_radius, "end_radius", "a horizontal distance in the terrain's x/y units")


def _check_inside(terrain, pts: np.ndarray, name: str) -> None:
    if pts.shape[0] == 0:
        return
    if isinstance(terrain, HeightGrid):
        xmin, xmax, ymin, ymax = terrain.extent
        slack = 1e-9 * _extent_diagonal(terrain)
        x = pts[:, 0]
        y = pts[:, 1]
        out = (x < xmin - slack) | (x > xmax + slack) | (y < ymin - slack) | (y > ymax + slack)
    else:
        out = np.isnan(terrain.height_at(pts[:, :2]))
    if out.any():
        bad = np.flatnonzero(out)
        raise OutsideFootprintError(
            f"{name} has {bad.size} point(s) outside the terrain's footprint {terrain.extent} "
            f"(first at index {int(bad[0])}: {pts[bad[0], :2].tolist()})"
        )


def _prepare_terrain(terrain, operation: str):
    as_terrain(terrain)
    if isinstance(terrain, HeightGrid):
        terrain.require_finite(operation)


def _prepare_segments(terrain, a, b, operation: str):
    _prepare_terrain(terrain, operation)
    a = as_points(a, "a", 3)
    b = as_points(b, "b", 3)
    if a.shape != b.shape:
        raise ValueError(f"a and b must have the same shape (m, 3), got {a.shape} and {b.shape}")
    _check_inside(terrain, a, "a")
    _check_inside(terrain, b, "b")
    return np.ascontiguousarray(a, dtype=np.float64), np.ascontiguousarray(b, dtype=np.float64)


# ----------------------------------------------------------------- public API
def min_clearance(terrain, a, b, *, end_radius: float = 0.0) -> np.ndarray:
    """Exact minimum clearance of each segment a[i] -> b[i] over its tested interval.

    The tested interval is [tau, 1 - tau], narrowed by ``end_radius`` (see the module
    docstring).

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
        from .grid import grid_clearance

        return grid_clearance(
            terrain, a, b, delta=delta, tol=clearance_tolerance(terrain), los=False, end_radius=end_radius
        )
    from .tin import tin_clearance

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
        the module docstring); 0 gives the exact predicate.

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
        from .grid import grid_clearance

        tol = clearance_tolerance(terrain)
        return grid_clearance(terrain, a, b, delta=delta, tol=tol, los=True, end_radius=end_radius) >= -tol
    from .embree import embree_visible

    return embree_visible(terrain, a, b, delta=delta, end_radius=end_radius)


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
        the module docstring); 0 gives the exact predicate.

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
        from .grid import grid_matrix

        return grid_matrix(terrain, pts, delta=delta, tol=clearance_tolerance(terrain), end_radius=end_radius)
    from .embree import embree_matrix

    return embree_matrix(terrain, pts, delta=delta, end_radius=end_radius)


# Region visibility and the clearance profile build on the definitions above.
from .profile import lowest_point  # noqa: E402
from .viewshed import viewshed  # noqa: E402
