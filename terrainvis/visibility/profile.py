"""Where a line of sight comes closest to the terrain: the clearance profile of one segment.

:func:`lowest_point` lists every breakpoint of the clearance along a segment's ground
track (the crossings of grid lines and cell diagonals on a grid, of edges on a TIN,
and the two ends of the tested interval), evaluates the clearance there and returns the
lowest one with its position. Between breakpoints both the segment and the surface are
linear, so the minimum over the breakpoints is the exact minimum. Under earth curvature
the clearance is lowered by ``k L**2 t (1 - t)`` (``k = curvature / (2 R)``, L the
horizontal length), convex on each piece, so the vertex of each piece's parabola joins
the breakpoints when it falls inside the piece. It is written with numpy for a handful
of segments (the ``terrainvis los`` command); the numba engines in
:mod:`terrainvis.visibility` decide millions of them.
"""

from __future__ import annotations

import numpy as np

from ..core.validate import as_nonnegative_finite, as_points
from ..core.terrain import HeightGrid, as_terrain
from .predicate import EARTH_RADIUS, curvature_coefficient, trim_length

__all__ = ["lowest_point", "clearance_profile"]


def _interval(terrain, a, b, end_radius):
    d = b - a
    length = float(np.sqrt((d * d).sum()))
    horizontal = float(np.hypot(d[0], d[1]))
    delta = trim_length(terrain)
    if length <= 2.0 * delta or (end_radius > 0 and horizontal <= 2.0 * end_radius):
        return None
    t0 = delta / length
    t1 = 1.0 - t0
    if end_radius > 0:
        t0 = max(t0, end_radius / horizontal)
        t1 = min(t1, 1.0 - end_radius / horizontal)
    return t0, t1


def _crossings(v, a, d, t0, t1):
    """Parameters in (t0, t1) where the coordinate a + t d crosses the values v."""
    if d == 0.0:
        return np.empty(0)
    t = (v - a) / d
    return t[(t > t0) & (t < t1)]


def _grid_breakpoints(grid: HeightGrid, a, d, t0, t1):
    ts = np.concatenate([[t0, t1], _crossings(grid.xs, a[0], d[0], t0, t1), _crossings(grid.ys, a[1], d[1], t0, t1)])
    ts = np.unique(ts)
    # one diagonal crossing at most between consecutive grid-line crossings: in the cell
    # under the interval's midpoint, u - v is linear in t and the diagonal is u = v
    mid = 0.5 * (ts[:-1] + ts[1:])
    xs, ys = grid.xs, grid.ys
    c = np.clip(np.searchsorted(xs, a[0] + mid * d[0], side="right") - 1, 0, xs.size - 2)
    r = np.clip(np.searchsorted(ys, a[1] + mid * d[1], side="right") - 1, 0, ys.size - 2)
    iw = 1.0 / (xs[c + 1] - xs[c])
    ih = 1.0 / (ys[r + 1] - ys[r])
    den = d[0] * iw - d[1] * ih
    with np.errstate(divide="ignore", invalid="ignore"):
        td = ((a[1] - ys[r]) * ih - (a[0] - xs[c]) * iw) / den
    ok = (den != 0) & (td > ts[:-1]) & (td < ts[1:])
    return np.unique(np.concatenate([ts, td[ok]]))


def _tin_breakpoints(tin, a, d, t0, t1):
    v = tin.vertices
    e = np.unique(np.sort(tin.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)
    p, q = v[e[:, 0], :2], v[e[:, 1], :2]
    ev = q - p
    # a + t d = p + s ev  ->  solve for (t, s) per edge
    det = d[0] * (-ev[:, 1]) - d[1] * (-ev[:, 0])
    rx = p[:, 0] - a[0]
    ry = p[:, 1] - a[1]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (rx * (-ev[:, 1]) - ry * (-ev[:, 0])) / det
        s = (d[0] * ry - d[1] * rx) / det
    ok = (det != 0) & (s >= 0) & (s <= 1) & (t > t0) & (t < t1)
    return np.unique(np.concatenate([[t0, t1], t[ok]]))


def _with_vertices(t: np.ndarray, flat: np.ndarray, bulge: float) -> np.ndarray:
    """Breakpoints ``t`` plus, on each piece between two of them, the vertex of the convex
    clearance ``flat - bulge t (1 - t)`` (the flat clearance is linear on the piece)."""
    dt = np.diff(t)
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.diff(flat) / dt
        ts = 0.5 - slope / (2.0 * bulge)
    inside = (dt > 0) & (ts > t[:-1]) & (ts < t[1:])
    return np.unique(np.concatenate([t, ts[inside]]))


def clearance_profile(
    terrain, a, b, *, end_radius: float = 0.0, curvature: float = 0.0, earth_radius: float = EARTH_RADIUS
):
    """The clearance at every breakpoint of the segment a -> b over its tested interval.

    Parameters
    ----------
    terrain : HeightGrid or TIN
    a, b : (3,) array_like
        The segment's ends (x, y, z), inside the footprint.
    end_radius : float
        Horizontal distance around each end where the surface is not tested (see
        :func:`terrainvis.line_of_sight`).
    curvature, earth_radius : float
        Earth curvature and refraction as in :func:`terrainvis.line_of_sight` (0: flat).

    Returns
    -------
    t : (k,) float64
        Breakpoint parameters along the segment, increasing (empty when the whole
        segment is trimmed away); under curvature also the minimum of each piece.
    clearance : (k,) float64
        Segment height minus surface height there, less the curvature bulge
        ``k L**2 t (1 - t)``.
    """
    as_terrain(terrain)
    pts = as_points(np.vstack([np.asarray(a, float).reshape(1, -1), np.asarray(b, float).reshape(1, -1)]), "a, b", 3)
    a, b = pts
    r = as_nonnegative_finite(end_radius, "end_radius")
    kc = curvature_coefficient(curvature, earth_radius)
    span = _interval(terrain, a, b, r)
    if span is None:
        return np.empty(0), np.empty(0)
    d = b - a
    if isinstance(terrain, HeightGrid):
        terrain.require_finite("clearance_profile")
        t = _grid_breakpoints(terrain, a, d, *span)
    else:
        t = _tin_breakpoints(terrain, a, d, *span)
    flat = a[2] + t * d[2] - terrain.height_at(a[:2] + t[:, None] * d[:2])
    if kc == 0.0:
        return t, flat
    bulge = kc * float(d[0] * d[0] + d[1] * d[1])
    t = _with_vertices(t, flat, bulge)
    flat = a[2] + t * d[2] - terrain.height_at(a[:2] + t[:, None] * d[:2])
    return t, flat - bulge * t * (1.0 - t)


def lowest_point(
    terrain, a, b, *, end_radius: float = 0.0, curvature: float = 0.0, earth_radius: float = EARTH_RADIUS,
    sight=None,
) -> dict:
    """Where the segment a -> b comes closest to (or goes deepest below) the surface.

    ``end_radius``, ``curvature`` and ``earth_radius`` as in :func:`clearance_profile`, or
    ``sight``, a :class:`~terrainvis.visibility.Sight` holding them.

    Returns
    -------
    dict
        ``clearance`` (segment height minus surface height there, less the curvature
        bulge; ``inf`` when the segment is trimmed away entirely), ``t`` (parameter along
        the segment), ``x``, ``y`` (ground position), ``z`` (the segment's height there),
        ``distance`` (horizontal distance from a) and ``bulge`` (how far earth curvature
        raises the surface under the sight line there; 0 on a flat earth).

    Examples
    --------
    >>> g = HeightGrid([[0.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 0.0]])
    >>> low = lowest_point(g, [0.0, 1.0, 1.0], [2.0, 1.0, 1.0])
    >>> low["clearance"], low["x"], low["y"]
    (-9.0, 1.0, 1.0)
    """
    from .sight import pair_sight

    sight = pair_sight(sight, {"end_radius": end_radius, "curvature": curvature, "earth_radius": earth_radius},
                       "lowest_point")
    end_radius, curvature, earth_radius = sight.end_radius, sight.curvature, sight.earth_radius
    t, c = clearance_profile(terrain, a, b, end_radius=end_radius, curvature=curvature, earth_radius=earth_radius)
    a = np.asarray(a, float).ravel()
    b = np.asarray(b, float).ravel()
    if t.size == 0:
        return {"clearance": float("inf"), "t": float("nan"), "x": float("nan"), "y": float("nan"),
                "z": float("nan"), "distance": float("nan"), "bulge": float("nan")}
    i = int(np.nanargmin(c))
    p = a + t[i] * (b - a)
    horizontal = float(np.hypot(*(b - a)[:2]))
    kc = curvature_coefficient(curvature, earth_radius)
    return {"clearance": float(c[i]), "t": float(t[i]), "x": float(p[0]), "y": float(p[1]), "z": float(p[2]),
            "distance": float(t[i] * horizontal), "bulge": float(kc * horizontal**2 * t[i] * (1.0 - t[i]))}
