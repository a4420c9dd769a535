"""The line-of-sight predicate's definitions: trim, tolerance, scale, engines, argument checks.

Every visibility entry point (:mod:`~terrainvis.visibility.los`, the viewshed sweep, the
clearance profile) takes these from here, so the predicate is defined once; the package
docstring of :mod:`terrainvis.visibility` states it.
"""

from __future__ import annotations

import numpy as np

from ..core.validate import as_nonnegative_finite, as_points, as_positive_finite, describe, height_limit
from ..errors import OutsideFootprintError
from ..core.terrain import HeightGrid, as_terrain, height_range
from ..tolerances import CLEARANCE_REL, EXTENT_INSIDE_REL

__all__ = [
    "TRIM_REL", "TOL_REL", "EARTH_RADIUS", "STANDARD_REFRACTION", "terrain_scale", "trim_length",
    "clearance_tolerance", "curvature_coefficient",
]

#: Trim length as a fraction of the horizontal diagonal (see :func:`trim_length`).
TRIM_REL = 1e-5
#: Clearance tolerance as a fraction of :func:`terrain_scale`.
TOL_REL = CLEARANCE_REL
#: Default earth radius (metres): WGS84's semi-major axis, as GDAL's ``gdal_viewshed`` takes it.
EARTH_RADIUS = 6378137.0
#: The curvature coefficient of standard refraction, ``1 - 1/7`` (GDAL's default ``-cc``).
STANDARD_REFRACTION = 0.85714


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
        zr = height_range(terrain)
        s = max(_extent_diagonal(terrain), zr[1] - zr[0] if zr is not None else 0.0)
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


def curvature_coefficient(curvature: float = 0.0, earth_radius: float = EARTH_RADIUS) -> float:
    """``k = curvature / (2 earth_radius)``: the sight line between p and q must clear the
    surface raised by ``k d1 d2`` (d1, d2 the horizontal distances to p and q).

    ``curvature`` is GDAL's ``-cc`` coefficient: 0 a flat earth, 1 the geometric curvature,
    ``1 - 1/7`` (:data:`STANDARD_REFRACTION`) curvature with standard refraction.
    ``earth_radius`` is in the terrain's x/y units (metres on a georeferenced DEM).

    Examples
    --------
    The earth's drop 10 km from an observer with standard refraction, ``k d**2``:

    >>> round(curvature_coefficient(STANDARD_REFRACTION) * 10_000.0**2, 2)
    6.72
    """
    c = as_nonnegative_finite(curvature, "curvature", "0 flat earth, 1 geometric, 0.85714 standard refraction")
    r = as_positive_finite(earth_radius, "earth_radius")
    return c / (2.0 * r)


# ----------------------------------------------------------------- validation
def _check_end_radius(end_radius) -> float:
    if isinstance(end_radius, (str, bytes)):
        raise TypeError(f"end_radius must be a real number, got {describe(end_radius)}")
    return as_nonnegative_finite(end_radius, "end_radius", "a horizontal distance in the terrain's x/y units")


def _check_inside(terrain, pts: np.ndarray, name: str) -> None:
    """Every point inside the footprint, and at a height float64 resolves against the terrain."""
    if pts.shape[0] == 0:
        return
    _check_heights(terrain, pts, name)
    if isinstance(terrain, HeightGrid):
        xmin, xmax, ymin, ymax = terrain.extent
        slack = EXTENT_INSIDE_REL * _extent_diagonal(terrain)
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


def _check_heights(terrain, pts: np.ndarray, name: str) -> None:
    """Refuse heights whose rounding exceeds the predicate's tolerance (:func:`~terrainvis.core.validate.height_limit`).

    An end at height H is known to 2^-52 |H| only; past the limit the verdict would be
    rounding noise (a line seen at 1e16 m turned blocked at 1e20 m).
    """
    limit = height_limit(terrain_scale(terrain))
    z = pts[:, 2]
    bad = ~(np.abs(z) <= limit)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"{name} has {int(bad.sum())} point(s) at heights float64 cannot resolve against this terrain (first at "
            f"index {k}: z = {z[k]:.6g}); heights must be within +-{limit:.3g} (float64 keeps 2^-52 of a height, and "
            f"line of sight compares clearances to {CLEARANCE_REL:g} x the terrain's scale "
            f"{terrain_scale(terrain):.6g})"
        )


def _height_above(value, name: str, terrain) -> float:
    """A height above the surface (an eye, a target), >= 0 and within what float64 resolves on ``terrain``."""
    from ..core.validate import as_height

    as_nonnegative_finite(value, name, "z units")  # the plain mistakes first, in their own words
    zr = height_range(terrain)
    ground = max(-zr[0], zr[1]) if zr is not None else 0.0
    return as_height(value, name, scale=terrain_scale(terrain), ground=ground, minimum=0.0)


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


def target_grid(terrain, at) -> HeightGrid:
    """The grid whose samples are a viewshed's targets: ``at``, or the terrain itself when it
    is a HeightGrid; ``at`` must be a HeightGrid over the terrain's footprint (required for a TIN).

    The one check of ``at`` behind :func:`terrainvis.viewshed`, the runs of many observers and
    :func:`terrainvis.visibility.field_of_view_mask`.
    """
    if at is not None and not isinstance(at, HeightGrid):
        raise TypeError(f"at must be a terrainvis.HeightGrid (the grid of target samples) or None, got {describe(at)}")
    if at is None:
        if not isinstance(terrain, HeightGrid):
            raise ValueError(
                "at is required for a TIN: pass the HeightGrid whose samples are the targets "
                "(normally the original terrain the TIN simplifies)"
            )
        return terrain
    _check_overlap(terrain, at)
    return at


def _check_overlap(terrain, at: HeightGrid) -> None:
    xmin, xmax, ymin, ymax = terrain.extent
    axmin, axmax, aymin, aymax = at.extent
    if axmax < xmin or axmin > xmax or aymax < ymin or aymin > ymax:
        raise ValueError(
            f"at covers {at.extent}, which does not overlap the terrain's footprint {terrain.extent}; "
            "pass a grid over the same area (same coordinate system)"
        )
