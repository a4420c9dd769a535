"""The viewshed sweep's exact walk of a ray over the grid's cells (numba).

:func:`walk_min` is the least clearance of the ray ``E + t d`` over ``[t0, t1]`` on the
grid's surface, crossing the grid lines and cell diagonals the ray meets
(:mod:`terrainvis.visibility.walk`'s one cursor) and, on a grid with nodata, only the
triangles present (:func:`_walk_cells`). The sector sweep (:mod:`._sector_kernels`)
walks the parts of a target's ray its bounds cannot decide; :func:`walk_targets` gives
the exact least clearance of whole segments eye -> target for the few targets the sweep
leaves undecided. Records and constants: :mod:`._geometry_kernels`.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ...core.compiling import KERNEL_ONLY
from ...core.surface import cell_height, line_height
from ...tolerances import DIAGONAL_SLACK
from .._kernels import _canonical, curved_min, interval_start
from ..walk import cell_diagonal, cells_next, cells_start
from ._geometry_kernels import HORIZONTAL, INF, LOWER, UPPER, VERTICAL, plane_height, tri_present


# --------------------------------------------------------------------------- exact walk
@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _clear(g, r, c, upper, ray, t):
    """Clearance of the ray at t over the plane of one triangle of cell (r, c)."""
    ex, ey, ez, dx, dy, dz = ray
    return ez + t * dz - plane_height(g, r, c, upper, ex + t * dx, ey + t * dy)


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _edge_clear(g, kind, r, c, ray, t):
    """Clearance on a grid line (kind 0: x = xs[c], rows r..r+1; kind 1: y = ys[r])."""
    z = g.z
    ex, ey, ez, dx, dy, dz = ray
    x = ex + t * dx
    y = ey + t * dy
    if kind == 0:
        v = (y - g.ys[r]) * g.iyw[r]
        return ez + t * dz - line_height(z, r, c, True, v)
    u = (x - g.xs[c]) * g.ixw[c]
    return ez + t * dz - line_height(z, r, c, False, u)


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _absent_piece(g, r, c, upper, ray, ta, tb, bulge):
    """Min clearance of a piece lying in an absent triangle: only where the piece runs
    along a boundary shared with a present triangle (a ray exactly on a grid line or a
    cell diagonal); inf otherwise. ``bulge`` as in :func:`walk_min`."""
    z, xs, ys = g.z, g.xs, g.ys
    ex, ey, ez, dx, dy, dz = ray
    nr, nc = z.shape
    best = INF
    if dx == 0.0:
        if ex == xs[c] and (tri_present(z, r, c, UPPER) or (c > 0 and tri_present(z, r, c - 1, LOWER))):
            best = curved_min(_edge_clear(g, VERTICAL, r, c, ray, ta), _edge_clear(g, VERTICAL, r, c, ray, tb), ta, tb, bulge)
        elif ex == xs[c + 1] and (tri_present(z, r, c, LOWER) or (c + 1 < nc - 1 and tri_present(z, r, c + 1, UPPER))):
            best = curved_min(_edge_clear(g, VERTICAL, r, c + 1, ray, ta), _edge_clear(g, VERTICAL, r, c + 1, ray, tb), ta, tb,
                              bulge)
    if dy == 0.0:
        if ey == ys[r] and (tri_present(z, r, c, LOWER) or (r > 0 and tri_present(z, r - 1, c, UPPER))):
            best = min(best, curved_min(_edge_clear(g, HORIZONTAL, r, c, ray, ta), _edge_clear(g, HORIZONTAL, r, c, ray, tb), ta, tb,
                                        bulge))
        elif ey == ys[r + 1] and (tri_present(z, r, c, UPPER) or (r + 1 < nr - 1 and tri_present(z, r + 1, c, LOWER))):
            best = min(best, curved_min(_edge_clear(g, HORIZONTAL, r + 1, c, ray, ta), _edge_clear(g, HORIZONTAL, r + 1, c, ray, tb),
                                        ta, tb, bulge))
    other = not upper
    if tri_present(z, r, c, other):
        # on the diagonal (both ends), the other triangle's plane is the surface there
        ua = (ex + ta * dx - xs[c]) * g.ixw[c]
        va = (ey + ta * dy - ys[r]) * g.iyw[r]
        ub = (ex + tb * dx - xs[c]) * g.ixw[c]
        vb = (ey + tb * dy - ys[r]) * g.iyw[r]
        if abs(ua - va) <= DIAGONAL_SLACK and abs(ub - vb) <= DIAGONAL_SLACK:
            best = min(best, curved_min(_clear(g, r, c, other, ray, ta), _clear(g, r, c, other, ray, tb), ta, tb,
                                        bulge))
    return best


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _cell_piece(g, r, c, ray, ta, tb, with_ta, bulge):
    """Exact min clearance over [ta, tb] inside cell (r, c) (ends and diagonal crossing;
    with ``bulge > 0`` also each side's interior minimum, see :func:`walk_min`)."""
    xs, ys, ixw, iyw = g.xs, g.ys, g.ixw, g.iyw
    ex, ey, ez, dx, dy, dz = ray
    td = INF
    t = cell_diagonal(xs, ys, ixw, iyw, r, c, (ex, ey, dx, dy))
    if t > ta and t < tb:
        td = t
    if not g.has_nan and bulge == 0.0:
        tm = 0.5 * (ta + tb) if td == INF else 0.5 * (ta + td)
        u = (ex + tm * dx - xs[c]) * ixw[c]
        v = (ey + tm * dy - ys[r]) * iyw[r]
        up = v > u
        if td == INF:
            m = _clear(g, r, c, up, ray, tb)
            if with_ta:
                m = min(m, _clear(g, r, c, up, ray, ta))
            return m
        m = _clear(g, r, c, up, ray, td)
        if with_ta:
            m = min(m, _clear(g, r, c, up, ray, ta))
        # the second piece's own triangle (a track touching the diagonal only at a cell
        # corner stays in the same triangle)
        tm = 0.5 * (td + tb)
        u = (ex + tm * dx - xs[c]) * ixw[c]
        v = (ey + tm * dy - ys[r]) * iyw[r]
        m = min(m, _clear(g, r, c, v > u, ray, tb))
        return m
    best = INF
    npc = 1 if td == INF else 2
    for k in range(npc):
        if npc == 1:
            a = ta
            b = tb
        elif k == 0:
            a = ta
            b = td
        else:
            a = td
            b = tb
        tm = 0.5 * (a + b)
        u = (ex + tm * dx - xs[c]) * ixw[c]
        v = (ey + tm * dy - ys[r]) * iyw[r]
        up = v > u
        if not g.has_nan or tri_present(g.z, r, c, up):
            e = curved_min(_clear(g, r, c, up, ray, a), _clear(g, r, c, up, ray, b), a, b, bulge)
        else:
            e = _absent_piece(g, r, c, up, ray, a, b, bulge)
        if e < best:
            best = e
    return best


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def walk_min(g, ray, t0, t1, stop, bulge):
    """Exact minimum clearance of the ray E + t d over [t0, t1] on the :data:`~terrainvis.core.surface.SurfaceGrid` ``g``
    (:func:`_walk_edges` on a grid without nodata, :func:`_walk_cells` otherwise)."""
    if g.has_nan:
        return _walk_cells(g, ray, t0, t1, stop, bulge)
    return _walk_edges(g, ray, t0, t1, stop, bulge)


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _walk_edges(g, ray, t0, t1, stop, bulge):
    """Exact minimum clearance of the ray E + t d over [t0, t1] on a grid without nodata.

    Cell by cell (a DDA): the clearance is evaluated where the ground track leaves the
    cell, on the grid line it crosses (the surface there is the interpolation along that
    edge), and where it crosses the cell's diagonal (along the diagonal); between those
    points it is linear (under earth curvature, ``bulge > 0``, linear less ``bulge t (1 -
    t)``, whose minimum on each piece :func:`curved_min` adds). The start is evaluated in
    its cell. Returns as soon as the minimum falls below ``stop``.
    """
    if t1 < t0:
        return INF
    xs, ys, ixw, iyw, z = g.xs, g.ys, g.ixw, g.iyw, g.z
    ex, ey, ez, dx, dy, dz = ray
    track = (ex, ey, dx, dy)
    cur = cells_start(xs, ys, ixw, iyw, g.uniform, track, t0, t1)
    t = t0
    fa = ez + t * dz - cell_height(z, xs, ys, ixw, iyw, cur.r, cur.c, ex + t * dx, ey + t * dy)
    best = fa if bulge == 0.0 else fa - bulge * t * (1.0 - t)
    if best < stop:
        return best
    while True:
        r, c, tn = cur.r, cur.c, cur.tn
        # the diagonal (r, c)-(r+1, c+1) inside (t, tn)
        td = cell_diagonal(xs, ys, ixw, iyw, r, c, track)
        if td > t and td < tn:
            u = (ex + td * dx - xs[c]) * ixw[c]
            fd = ez + td * dz - (np.float64(z[r, c]) + u * (np.float64(z[r + 1, c + 1]) - np.float64(z[r, c])))
            e = fd if bulge == 0.0 else curved_min(fa, fd, t, td, bulge)
            if e < best:
                best = e
                if best < stop:
                    return best
            fa = fd
            t = td
        # where the track leaves the cell (or the interval ends). Which line it crosses
        # is told by tx <= ty, not by tn == tx: rounding can put a start on a grid line a
        # hair inside the cell it leaves, and tn is then raised from tx (or ty) to t
        if tn >= t1:
            fn = ez + t1 * dz - cell_height(z, xs, ys, ixw, iyw, r, c, ex + t1 * dx, ey + t1 * dy)
        elif cur.tx <= cur.ty:
            cn = c + 1 if dx > 0.0 else c
            v = min(max((ey + tn * dy - ys[r]) * iyw[r], 0.0), 1.0)
            fn = ez + tn * dz - line_height(z, r, cn, True, v)
        else:
            rn = r + 1 if dy > 0.0 else r
            u = min(max((ex + tn * dx - xs[c]) * ixw[c], 0.0), 1.0)
            fn = ez + tn * dz - line_height(z, rn, c, False, u)
        e = fn if bulge == 0.0 else curved_min(fa, fn, t, tn, bulge)
        if e < best:
            best = e
            if best < stop:
                return best
        if tn >= t1:
            break
        cur = cells_next(xs, ys, cur, track, t1)
        if cur.r < 0:
            break
        fa = fn
        t = tn
    return best


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _walk_cells(g, ray, t0, t1, stop, bulge):
    """Exact minimum clearance of the ray E + t d over [t0, t1] on the :data:`~terrainvis.core.surface.SurfaceGrid` ``g``.

    ``ray`` is ``(ex, ey, ez, dx, dy, dz)`` in local coordinates. The ground track is
    walked cell by cell; in each cell the clearance is evaluated at the entry, the exit
    and the diagonal crossing (it is linear between them; under earth curvature,
    ``bulge = kc (dx**2 + dy**2) > 0``, it is lowered by ``bulge t (1 - t)`` and each
    side's convex minimum counts too). On a grid with nodata, triangles touching a NaN
    sample are absent and do not block. The walk returns as soon as the minimum falls
    below ``stop``.
    """
    if t1 < t0:
        return INF
    ex, ey, ez, dx, dy, dz = ray
    cur = cells_start(g.xs, g.ys, g.ixw, g.iyw, g.uniform, (ex, ey, dx, dy), t0, t1)
    best = INF
    first = True
    while True:
        m = _cell_piece(g, cur.r, cur.c, ray, cur.t, cur.tn, first or g.has_nan, bulge)
        first = False
        if m < best:
            best = m
            if best < stop:
                return best
        if cur.tn >= t1:
            break
        cur = cells_next(g.xs, g.ys, cur, (ex, ey, dx, dy), t1)
        if cur.r < 0:
            break
    return best


@nb.njit(cache=True, nogil=True, error_model="numpy")
def walk_targets(g, eye, tx, ty, tz, delta, tol, kc, out):
    """``out[i]`` = exact minimum clearance of the segment eye -> target i (canonical
    direction, length trim and earth curvature ``kc`` as in the pair engine; returns early
    below ``-tol``).

    ``eye`` is ``(ex, ey, ez)``. Serial: it answers the few targets the sweep leaves
    undecided (about 16 a viewshed, around the eye) and, on a grid with nodata, which the
    pair engine cannot walk, all of them."""
    m = tx.shape[0]
    for i in range(m):
        seg, length = _canonical(eye, (tx[i], ty[i], tz[i]))
        tau = interval_start(seg, length, delta, 0.0)
        if tau < 0.0:
            out[i] = INF
            continue
        out[i] = _walk_cells(g, seg, tau, 1.0 - tau, -tol, kc * (seg[3] * seg[3] + seg[4] * seg[4]))

