"""Numba loops of the threshold engine (:mod:`terrainvis.visibility.thresholds`).

Kernels loop and never validate; :mod:`terrainvis.visibility.thresholds` builds their
state, and its callers (:mod:`terrainvis.relocation.calibrated`, :mod:`simplifiers.visopt`)
check the input, move coordinates to the terrain's local origin and pass plain arrays.

Thresholds
----------
A point p standing at height z sees a target q (fixed, at height ``qz``) on a surface s
exactly when the segment between them clears s (within ``-tol``) over its tested
interval. Measured from q, the segment's height at parameter u is ``qz + u (z - qz)``,
so the segment clears the surface at u exactly when

    z >= qz + (s(u) - tol - qz) / u,

and p sees q exactly when z is at least the *threshold*
``qz + max_u (s(u) - tol - qz) / u`` over the tested interval ``[u0, u1]``. Inside one
triangle s is linear in u, so ``(s(u) - tol - qz) / u`` is monotone there and the
maximum is reached at a breakpoint of the ground track (a crossing of a grid line, a
cell diagonal or a TIN edge) or at an end of the interval: the thresholds below visit
exactly the breakpoints the exact LOS engines visit.

Under earth curvature (``kc = curvature / (2 R)``, :func:`terrainvis.visibility.curvature_coefficient`)
the segment must clear the surface raised by ``kc d1 d2 = B u (1 - u)`` with
``B = kc L**2`` (L the horizontal length), so the threshold is
``qz + max_u [(s(u) - tol - qz) / u + B (1 - u)]``. On a piece where s is linear,
``A / u + beta + B (1 - u)`` with ``A < 0`` is concave and can peak inside the piece,
at ``u* = sqrt(-A / B)``: :func:`_piece_max` checks it.

Kernel arguments
----------------
The kernels read the surface as the core's :data:`~terrainvis.core.surface.SurfaceGrid`
(with the pair engine's pyramid) or :data:`~terrainvis.core.surface.SurfaceTin` (with
the faces' neighbours ``nbr``), in local coordinates; the predicate and the choice of a
height as :data:`Rules`; one track as a :data:`Track`; the neighbours of the points as
:data:`Neighbours`; a point as the 3-tuple ``(x, y, z)``. No function takes more than
twelve positional arguments (``tests/visibility/test_visibility_layout.py``).

The walks
---------
* :func:`grid_max_slope` walks a HeightGrid with the visibility engine's min/max
  pyramid: a node whose maximum height ``H`` gives
  ``(H - tol - qz) / u <= best`` over its parameter range cannot raise the threshold
  and is skipped.
* :func:`tin_max_slope` walks the TIN from face to face across the edges the track
  crosses (the faces' neighbours), from the face under the interval's start.

One driver for both surfaces
----------------------------
Each driver above the walks (the threshold, the clamped threshold, the rows, the best
heights, the loops Python calls, the eye's spans and thresholds) is written once, in a
factory ``_make_x(kind)``, and made for each surface, ``GRID`` and ``TIN``
(:func:`terrainvis.core.compiling.kernel_of`): ``grid_row, tin_row = _make_entry_row(GRID),
_make_entry_row(TIN)``. Its body branches on ``kind`` only where the surfaces differ (the
walk and the probes it calls, a grid's walk stack ``st``, a TIN's face under the point
``fp``); ``kind`` is a constant of the closure, so numba drops the other branch before
typing, and each made driver is compiled as one written for its surface alone: against
the twins they replaced, the same bits, no slower and compiled no longer
(docs/performance.md, "Threshold kernels written once, per kind"). Every driver takes
the stack (None on a TIN) and the clamped walks take ``fp`` (-1 on a grid), so that one
signature serves both. The walks themselves (:func:`grid_max_slope`,
:func:`grid_dda_max_slope`, :func:`tin_max_slope`) and the probes stay per surface: they
are different algorithms.

One row, the clamped walk inlined in it
---------------------------------------
Every threshold the engine's loops need goes through one row kernel, :func:`_grid_row`
(:func:`_tin_row`): a point's thresholds for many targets, clamped to a window or exact
(the window (-inf, inf)), or only those a window left as bounds (``redo``). The clamped
walk (:func:`grid_clamped`) and its probes are inlined there by numba (``inline="always"``),
its only call site in the package: as kernels of their own, called once per target, they
received the surface's record (a grid's: 13 arrays and scalars, flattened into about a
hundred arguments) and the track's at every call, and the calibrated relocation on a grid
ran about three times slower, for the same bits (docs/performance.md, "The clamped walk
inlined in its row"). :func:`grid_threshold` (the clamped walk over (-inf, inf)) is kept for
tests; no loop calls it.

Threads
-------
The loops over points (:func:`grid_heights`, :func:`tin_heights`) and over chunks of
targets (:func:`grid_eye_thresholds`, :func:`tin_eye_thresholds`) are serial kernels over
a range of their iterations; :func:`terrainvis.core.interrupt.call` runs them on numba's
number of threads, one kernel for any number of threads (a ``prange`` loop cost about
1.5 s of CPU to compile however small its body, and a serial twin for one thread).

Best heights
------------
Given the thresholds ``thr[k]`` of one point against K partners and the partners'
verdicts ``vis[k]`` on the original terrain, the agreement of the point's verdicts at
height z is ``#{k: vis[k] and z >= thr[k]} + #{k: not vis[k] and z < thr[k]}``, a step
function of z that changes only at the thresholds. :func:`best_height` sorts them and
returns the height in an optimal interval closest to a reference height, kept a margin
away from the interval's ends so that the verdicts it counted are the verdicts a LOS
engine will give there.

Windows
-------
The best height almost always lies near the reference height, and only the thresholds
near it need be known exactly. With ``rules.window`` = w finite, a point's thresholds are
first walked in the window (lo, hi) = (zref - w, zref + w) (:func:`grid_clamped`,
:func:`tin_clamped`): the walk starts from lo, so the pyramid skips every node that
cannot exceed it (a threshold below lo is known only as "at most lo"), and stops as soon
as its maximum reaches hi ("at least hi"); a few probes near the point, where a sight
line from the ground is often blocked, can show that before any walk (on a grid at
a few cells from it, :func:`_grid_probes_reach`; on a TIN where the track leaves the
first faces from the point's own, :func:`_tin_probes_reach`). Each threshold is then exact, or a bound on one side. The
bounds are replaced by the most favourable thresholds they allow (:func:`optimistic`:
each partner agrees at every height at least as well as with its exact threshold, and
exactly as well inside the window), and :func:`best_height_kept` chooses from those. If
the choice lies inside the window, more than the margin from its ends, it is the choice
the exact thresholds give, bit for bit: the favourable agreement is exact inside the
window and no lower than the exact one outside, so an optimum outside it would at best
tie, farther from the reference height; the intervals the choice is clamped to are the
same inside. Otherwise the thresholds known only by a bound are walked whole (those the
window walked exactly stand). A window only saves work.
"""

from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from ..core.compiling import KERNEL_ONLY, kernel_of
from ..core.stopflag import stopped
from ..core.surface import borrow, borrow_grid, borrow_tin, cell_height, face_at, face_height, locate
from ..tolerances import TRACK_EDGE_SLACK, TRACK_PROBE_REL, TRACK_STEP_MIN
from ._kernels import WalkStack, new_stack
from .walk import cell_diagonal, cells_next, cells_start, mid_height, node_pop, node_push, node_root, node_split

_INF = np.inf
#: ``skip`` of the row loops when no partner is skipped: an int64, not a literal -1 (numba
#: would compile the row loop once more for the literal).
_NO_SKIP = np.int64(-1)
#: ``fp`` of the clamped walks when no face is known (on a grid, always): an int64, as ``_NO_SKIP``.
_NO_FACE = np.int64(-1)
#: The surfaces the drivers below are made for (:func:`terrainvis.core.compiling.kernel_of`:
#: each driver is written once and branches on its kind, which numba resolves before typing).
GRID = 0
TIN = 1

#: The predicate and the choice of a height: the trim ``delta``, the ``end_radius``, the
#: clearance tolerance ``tol``, the curvature coefficient ``kc`` (``curvature / (2 R)``,
#: 0: flat), the height ``margin`` kept from thresholds and the least gain ``min_gain``
#: (an int) that moves a point (:func:`best_height_kept`), and the half-width ``window``
#: of the heights around a point's reference height inside which its thresholds are
#: walked exactly first (inf: every threshold exactly; see "Windows" above).
Rules = namedtuple("Rules", ["delta", "end_radius", "tol", "kc", "margin", "min_gain", "window"])
#: The neighbours of each point p[i] (:func:`best_height_kept`): their thresholds
#: ``lthr`` (n, L) float64, T's verdicts ``lvis`` (n, L) int8 and the ``weight`` of one.
Neighbours = namedtuple("Neighbours", ["lthr", "lvis", "weight"])
#: One track seen from the target q = (``qx``, ``qy``) at height ``qz``: the direction
#: (``dx``, ``dy``) = p - q, the tested interval [``u0``, ``u1``], the clearance tolerance
#: ``tol``, the ``bulge`` ``kc (dx**2 + dy**2)`` of earth curvature (0: flat), and the
#: ``floor`` and ``cap`` of the walk's maximum (-inf, inf: none): the walk starts from
#: ``floor`` (so it skips whatever cannot exceed it) and stops as soon as it reaches ``cap``.
Track = namedtuple("Track", ["qx", "qy", "qz", "dx", "dy", "u0", "u1", "tol", "bulge", "floor", "cap"])


# --------------------------------------------------------------------------- grid
@nb.njit(cache=True, nogil=True, inline="always")
def _value(h, u, qz, tol, bulge):
    """``(h - tol - qz) / u + bulge (1 - u)``: the height a point needs to clear the surface height h at u."""
    return (h - tol - qz) / u + bulge * (1.0 - u)


@nb.njit(cache=True, nogil=True, inline="always")
def _piece_max(ua, ha, ub, hb, qz, tol, bulge):
    """Max of :func:`_value` inside (ua, ub) where the surface is linear (its ends are
    evaluated by the caller): ``-inf`` unless the concave case peaks inside."""
    if bulge <= 0.0 or ub <= ua:
        return -_INF
    beta = (hb - ha) / (ub - ua)
    a = ha - tol - qz - beta * ua
    if a >= 0.0:
        return -_INF
    us = np.sqrt(-a / bulge)
    if us <= ua or us >= ub:
        return -_INF
    return beta + bulge - 2.0 * np.sqrt(-a * bulge)


@nb.njit(cache=True, nogil=True, inline="always")
def _leaf(g, r, c, tr, a0, a1, with_a0):
    """Max of :func:`_value` over cell (r, c)'s part [a0, a1] of the :data:`Track` ``tr``: at
    its breakpoints (a0 unless ``with_a0`` is False, the diagonal, a1) and, under
    curvature, inside its pieces."""
    z, xs, ys, ixw, iyw = g.z, g.xs, g.ys, g.ixw, g.iyw
    qx, qy, qz, dx, dy, tol, bulge = tr.qx, tr.qy, tr.qz, tr.dx, tr.dy, tr.tol, tr.bulge
    h1 = cell_height(z, xs, ys, ixw, iyw, r, c, qx + a1 * dx, qy + a1 * dy)
    best = _value(h1, a1, qz, tol, bulge)
    if with_a0 or bulge > 0.0:
        h0 = cell_height(z, xs, ys, ixw, iyw, r, c, qx + a0 * dx, qy + a0 * dy)
        if with_a0:
            v = _value(h0, a0, qz, tol, bulge)
            if v > best:
                best = v
    td = -1.0
    t = cell_diagonal(xs, ys, ixw, iyw, r, c, (qx, qy, dx, dy))
    if t > a0 and t < a1:
        td = t
        hd = cell_height(z, xs, ys, ixw, iyw, r, c, qx + td * dx, qy + td * dy)
        v = _value(hd, td, qz, tol, bulge)
        if v > best:
            best = v
    if bulge > 0.0:
        if td > 0.0:
            v = max(_piece_max(a0, h0, td, hd, qz, tol, bulge), _piece_max(td, hd, a1, h1, qz, tol, bulge))
        else:
            v = _piece_max(a0, h0, a1, h1, qz, tol, bulge)
        if v > best:
            best = v
    return best


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def grid_max_slope(g, tr, st):
    """Max of :func:`_value` over the :data:`Track` ``tr``, q + u d for u in [u0, u1] (u0 > 0):
    the threshold less qz.

    ``g`` is the grid engine's :data:`~terrainvis.core.surface.SurfaceGrid` (local
    coordinates, with its pyramid), ``st`` a scratch stack
    (:func:`~terrainvis.visibility._kernels.new_stack`).
    The descent visits children nearest to q first, so that the large values near q
    are found before the far nodes they prune.
    """
    z, xs, ys, ixw, iyw = g.z, g.xs, g.ys, g.ixw, g.iyw
    pyr, off, nxl, uniform = g.pyr, g.off, g.nxl, g.uniform
    qx, qy, qz, dx, dy, u0, u1, tol, bulge, floor, cap = tr
    track = (qx, qy, dx, dy)
    best = floor
    stk = (st.level, st.row, st.col, st.t)
    sp = node_root(stk, g.ltop, u0, u1)
    last = -_INF
    while sp > 0:
        if best >= cap:
            return best
        sp, L, R, C, a0, a1 = node_pop(stk, sp)
        if L == 0:
            v = _leaf(g, R, C, tr, a0, a1, a0 != last)
            last = a1
            if v > best:
                best = v
            continue
        k = off[L] + 2 * (R * nxl[L] + C)
        num = np.float64(pyr[k + 1]) - tol - qz
        bound = (num / a0 if num > 0.0 else num / a1) + bulge * (1.0 - a0)
        if bound <= best:
            continue
        node = (L, R, C, a0, a1)
        split = node_split(xs, ys, node, track)
        cm, rm, tx, ty = split
        if L >= 2:  # probe the surface where the track crosses the mid lines
            if tx < _INF:
                e = _value(mid_height(z, xs, ys, ixw, iyw, uniform, node, True, cm, qy + tx * dy), tx, qz, tol, bulge)
                if e > best:
                    best = e
            if ty < _INF:
                e = _value(mid_height(z, xs, ys, ixw, iyw, uniform, node, False, rm, qx + ty * dx), ty, qz, tol, bulge)
                if e > best:
                    best = e
        sp = node_push(stk, sp, xs, ys, node, split, track)  # near pieces pop first
    return best


#: Grids with a pyramid of at most this many levels (up to 128 cells a side) are walked
#: cell by cell: there the pyramid's bookkeeping costs more than the cells it skips
#: (docs/relocation.md, "The best height, exactly").
DDA_MAX_LEVELS = 7


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def grid_dda_max_slope(g, tr):
    """:func:`grid_max_slope` by visiting every cell the track crosses (small grids; ``g``'s
    pyramid is not read).

    Each cell's part of the track is evaluated as :func:`_leaf` does, written out here:
    calling the inlined :func:`_leaf` (or a function taking the grid's arrays) at every
    cell made this walk 3 times slower on the default experiment's grids, for the same
    thresholds bit for bit (docs/relocation.md, "Cost")."""
    z, xs, ys, ixw, iyw, uniform = g.z, g.xs, g.ys, g.ixw, g.iyw, g.uniform
    qx, qy, qz, dx, dy, u0, u1, tol, bulge, floor, cap = tr
    track = (qx, qy, dx, dy)
    curved = bulge > 0.0
    best = floor
    first = True
    cur = cells_start(xs, ys, ixw, iyw, uniform, track, u0, u1)
    while True:
        r, c, a, b = cur.r, cur.c, cur.t, cur.tn
        # the cell's part [a, b] of the track: its breakpoints a (first cell only), the diagonal, b
        h1 = cell_height(z, xs, ys, ixw, iyw, r, c, qx + b * dx, qy + b * dy)
        v = _value(h1, b, qz, tol, bulge)
        h0 = 0.0
        if first or curved:
            h0 = cell_height(z, xs, ys, ixw, iyw, r, c, qx + a * dx, qy + a * dy)
            if first:
                v0 = _value(h0, a, qz, tol, bulge)
                if v0 > v:
                    v = v0
        td = -1.0
        hd = 0.0
        t = cell_diagonal(xs, ys, ixw, iyw, r, c, track)
        if t > a and t < b:
            td = t
            hd = cell_height(z, xs, ys, ixw, iyw, r, c, qx + td * dx, qy + td * dy)
            vd = _value(hd, td, qz, tol, bulge)
            if vd > v:
                v = vd
        if curved:
            if td > 0.0:
                vp = max(_piece_max(a, h0, td, hd, qz, tol, bulge), _piece_max(td, hd, b, h1, qz, tol, bulge))
            else:
                vp = _piece_max(a, h0, b, h1, qz, tol, bulge)
            if vp > v:
                v = vp
        first = False
        if v > best:
            best = v
        if b >= u1 or best >= cap:
            break
        cur = cells_next(xs, ys, cur, track, u1)
        if cur.r < 0:
            break
    return best


@nb.njit(cache=True, nogil=True)
def interval(px, py, pz, qx, qy, qz, delta, end_radius):
    """The tested interval ``(u0, u1)`` of the segment p-q (the LOS engines' trim and end
    radius), or ``(-1, -1)`` when nothing of it is tested (it is then visible)."""
    dx = px - qx
    dy = py - qy
    dz = pz - qz
    lh = np.sqrt(dx * dx + dy * dy)
    length = np.sqrt(lh * lh + dz * dz)
    if length <= 2.0 * delta:
        return -1.0, -1.0
    u0 = delta / length
    if end_radius > 0.0:
        if lh <= 2.0 * end_radius:
            return -1.0, -1.0
        if end_radius / lh > u0:
            u0 = end_radius / lh
    return u0, 1.0 - u0


def _make_threshold(kind):
    @kernel_of(kind, "grid_threshold", "tin_threshold", **KERNEL_ONLY)
    def threshold(s, st, p, q, rules):
        """The threshold height of the point p = (px, py, pz) for the target q = (qx, qy, qz)
        on the surface ``s`` (``st``: a grid's walk stack, None on a TIN) under the
        :data:`Rules` ``rules``; ``pz`` (a height near the answer) only sets the trim.
        ``-inf`` when the segment is not tested."""
        if kind == GRID:
            return grid_clamped(s, st, p, q, rules, -_INF, _INF, _NO_FACE)[0]
        else:
            return tin_clamped(s, st, p, q, rules, -_INF, _INF, _NO_FACE)[0]

    return threshold


def _make_clamped(kind):
    @kernel_of(kind, "grid_clamped", "tin_clamped", inline="always")
    def clamped(s, st, p, q, rules, zlo, zhi, fp):
        """:func:`grid_threshold` known exactly only inside (``zlo``, ``zhi``): ``(z, state)``
        with state 0 (z is the threshold, bit for bit), -1 (the threshold is at most z, about
        ``zlo``) or 1 (it is at least z, about ``zhi`` or above). The walk stops at ``zhi``
        and, on a grid, skips what cannot exceed ``zlo`` (a face walk has nothing to skip;
        see "Windows"); with (-inf, inf) it is the exact threshold, state 0 (-inf when the
        segment is not tested). ``fp``: on a TIN, the face that holds p (-1: unknown, no
        probes)."""
        px, py, pz = p
        qx, qy, qz = q
        u0, u1 = interval(px, py, pz, qx, qy, qz, rules.delta, rules.end_radius)
        if u0 < 0.0:
            return -_INF, 0
        dx = px - qx
        dy = py - qy
        floor = zlo - qz
        cap = zhi - qz
        tr = Track(qx, qy, qz, dx, dy, u0, u1, rules.tol, rules.kc * (dx * dx + dy * dy), floor, cap)
        if kind == GRID:
            if _grid_probes_reach(s, tr, rules.margin):
                return zhi, 1
            if s.ltop <= DDA_MAX_LEVELS:
                m = grid_dda_max_slope(s, tr)
            else:
                m = grid_max_slope(s, tr, st)
        else:
            if _tin_probes_reach(s, tr, fp, rules.margin):
                return zhi, 1
            m = tin_max_slope(s, tr)
        return _clamped(qz, m, floor, cap)

    return clamped


grid_threshold, tin_threshold = _make_threshold(GRID), _make_threshold(TIN)
grid_clamped, tin_clamped = _make_clamped(GRID), _make_clamped(TIN)


#: Where :func:`_grid_probes_reach` probes a track first: these many cells of the grid
#: (its first spacing) from the point's end.
PROBE_CELLS = (0.5, 1.5, 3.0, 6.0)


@nb.njit(cache=True, nogil=True, inline="always")
def _grid_probes_reach(g, tr, margin):
    """Whether the track's value at a few places near the point's end (:data:`PROBE_CELLS`)
    exceeds its cap by more than ``margin``: the maximum, at least as large as any value
    of the track, then reaches the cap, without a walk. For a point on the ground a sight
    line is often blocked right there."""
    qx, qy, qz, dx, dy, u0, u1, tol, bulge, floor, cap = tr
    if cap == _INF:
        return False
    z, xs, ys, ixw, iyw, uniform = g.z, g.xs, g.ys, g.ixw, g.iyw, g.uniform
    length = np.sqrt(dx * dx + dy * dy)
    cell = xs[1] - xs[0]
    for k in range(len(PROBE_CELLS)):
        u = u1 - PROBE_CELLS[k] * cell / length
        if u <= u0:
            break
        x = qx + u * dx
        y = qy + u * dy
        c = locate(xs, ixw, 0, xs.shape[0] - 1, uniform, x)
        r = locate(ys, iyw, 0, ys.shape[0] - 1, uniform, y)
        if _value(cell_height(z, xs, ys, ixw, iyw, r, c, x, y), u, qz, tol, bulge) > cap + margin:
            return True
    return False


@nb.njit(cache=True, nogil=True, inline="always")
def _clamped(qz, m, floor, cap):
    """The ``(z, state)`` of :func:`grid_clamped` from a walk's maximum ``m`` (floor: nothing
    exceeded ``floor``; at least ``cap``: the walk may have stopped there). Rounding is
    monotone, so ``qz + floor`` is at least the threshold ``qz + max`` as the exact walk
    rounds it, and ``qz + m`` at most it."""
    if m <= floor:
        return qz + floor, -1
    if m >= cap:
        return qz + m, 1
    return qz + m, 0


# --------------------------------------------------------------------------- TIN
#: The TIN as the threshold walk reads it: the core's :data:`~terrainvis.core.surface.SurfaceTin`
#: in local coordinates (the bucket grid's corner at the origin), faces counter-clockwise,
#: with the neighbours ``nbr`` across each edge.


@nb.njit(cache=True, nogil=True, inline="always")
def _exit(w, f, entry, qx, qy, dx, dy, u):
    """Where the track q + u' d leaves face f after ``u``: (u', edge, height there), or (inf, -1, 0).

    ``entry`` is the edge the walk came in by (-1: not known); it is not tested, as the
    track meets it at ``u`` itself (the exit must lie past ``u`` by more than
    :data:`~terrainvis.tolerances.TRACK_STEP_MIN`): a third fewer edges per face.
    Inlined in :func:`tin_max_slope`'s loop: called there at every face, it made the walk
    1.3-1.5 times slower (same thresholds, bit for bit)."""
    best_u = _INF
    best_e = -1
    best_s = 0.0
    for e in range(3):
        if e == entry:
            continue
        a = w.faces[f, e]
        b = w.faces[f, (e + 1) % 3]
        ex = w.vx[b] - w.vx[a]
        ey = w.vy[b] - w.vy[a]
        den = dx * ey - dy * ex
        if den == 0.0:
            continue
        rx = w.vx[a] - qx
        ry = w.vy[a] - qy
        we = (rx * dy - ry * dx) / den
        if we < -TRACK_EDGE_SLACK or we > 1.0 + TRACK_EDGE_SLACK:  # the track misses the edge
            continue
        ue = (rx * ey - ry * ex) / den
        if ue <= u + TRACK_STEP_MIN or ue >= best_u:
            continue
        we = min(max(we, 0.0), 1.0)
        best_u = ue
        best_e = e
        best_s = w.vz[a] + we * (w.vz[b] - w.vz[a])
    return best_u, best_e, best_s


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _face_ahead(w, f, qx, qy, dx, dy, u, u1):
    """A face other than f that holds the track a little after u (steps growing tenfold), and
    that position of the track: (face, u'), or (-1, u1)."""
    step = TRACK_PROBE_REL * (u1 - u) + TRACK_STEP_MIN
    while u + step < u1:
        g = face_at(w, qx + (u + step) * dx, qy + (u + step) * dy)
        if g >= 0 and g != f:
            return g, u + step
        step *= 10.0
    return -1, u1


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def tin_max_slope(w, tr):
    """Max of :func:`_value` over the :data:`Track` ``tr`` (q -> p, u in [u0, u1]) on a TIN
    (:data:`~terrainvis.core.surface.SurfaceTin` with its neighbours).

    Walks from face to face across the edges the track crosses, so the breakpoints come
    in order (the pieces between them are where the value can peak under curvature).
    Where the walk cannot go on (through a vertex into the wrong face, across a hole), it
    locates the next face a step further along the track.
    """
    qx, qy, qz, dx, dy, u0, u1, tol, bulge, floor, cap = tr
    u = u0
    f = face_at(w, qx + u * dx, qy + u * dy)
    if f < 0:
        return _INF  # the start is outside the TIN: not a valid query
    su = face_height(w.vx, w.vy, w.vz, w.faces, f, qx + u * dx, qy + u * dy)
    best = max(_value(su, u, qz, tol, bulge), floor)
    if dx * dx + dy * dy == 0.0:  # a vertical segment: one ground point (as interval() sees it: a
        # subnormal offset squares to 0 and is too short for the walk to step across)
        return max(best, _value(su, u1, qz, tol, bulge))
    nf = w.faces.shape[0]
    entry = -1
    for _ in range(4 * nf + 16):
        ue, e, se = _exit(w, f, entry, qx, qy, dx, dy, u)
        if e < 0:  # stuck (through a vertex into a face the track does not enter): step ahead
            g, ug = _face_ahead(w, f, qx, qy, dx, dy, u, u1)
            if g < 0:
                return best
            # go on from the probe on g, so that u grows at every step (faces around a vertex
            # could otherwise hand the walk back and forth); the piece skipped is ~1e-9 long
            f = g
            entry = -1
            u = ug
            su = face_height(w.vx, w.vy, w.vz, w.faces, f, qx + u * dx, qy + u * dy)
            v = _value(su, u, qz, tol, bulge)
            if v > best:
                best = v
            continue
        if ue >= u1:
            s1 = face_height(w.vx, w.vy, w.vz, w.faces, f, qx + u1 * dx, qy + u1 * dy)
            v = max(_value(s1, u1, qz, tol, bulge), _piece_max(u, su, u1, s1, qz, tol, bulge))
            return max(best, v)
        v = max(_value(se, ue, qz, tol, bulge), _piece_max(u, su, ue, se, qz, tol, bulge))
        if v > best:
            best = v
            if best >= cap:
                return best
        u = ue
        su = se
        g = w.nbr[f, e]
        entry = -1
        if g < 0:
            g = face_at(w, qx + (u + TRACK_PROBE_REL) * dx, qy + (u + TRACK_PROBE_REL) * dy)
            if g < 0:
                return best
        else:
            for k in range(3):
                if w.nbr[g, k] == f:
                    entry = k
                    break
        f = g
    return best


#: :func:`_tin_probes_reach` looks at the track where it leaves this many faces, walking
#: from the point's face towards the target.
PROBE_FACES = 8


@nb.njit(cache=True, nogil=True, inline="always")
def _tin_probes_reach(w, tr, fp, margin):
    """:func:`_grid_probes_reach` on a TIN: the track's value where it crosses the edges of
    the first :data:`PROBE_FACES` faces from the point's end, walked from the face ``fp``
    that holds the point (found once per row) towards the target; only the crossings
    inside the tested interval count."""
    qx, qy, qz, dx, dy, u0, u1, tol, bulge, floor, cap = tr
    if cap == _INF or fp < 0:
        return False
    px = qx + dx
    py = qy + dy
    f = fp
    entry = -1
    v = 0.0
    for _ in range(PROBE_FACES):
        ve, e, se = _exit(w, f, entry, px, py, -dx, -dy, v)
        if e < 0:
            return False
        u = 1.0 - ve
        if u < u0:
            return False
        if u <= u1 and _value(se, u, qz, tol, bulge) > cap + margin:
            return True
        g = w.nbr[f, e]
        if g < 0:
            return False
        entry = -1
        for k in range(3):
            if w.nbr[g, k] == f:
                entry = k
                break
        f = g
        v = ve
    return False


# --------------------------------------------------------------------------- best heights
@nb.njit(cache=True, nogil=True)
def best_height(thr, vis, zref, margin, min_gain):
    """The height z maximising the agreement of a point's verdicts with ``vis`` (see the
    module docstring), and that agreement.

    The point stays at ``zref`` when the best agreement exceeds the agreement there by
    less than ``min_gain`` (>= 1; 1 is the plain maximum): a few partners' verdicts are
    not evidence enough to move it.

    Among the optimal intervals of z, the one nearest ``zref`` is taken, and in it the
    point nearest ``zref`` that keeps ``margin`` (> 0: an interval holds its lower end,
    not its upper one) from the interval's ends (its middle when it is narrower than
    twice the margin). ``thr`` = -inf marks partners seen at any height. This is
    :func:`best_height_kept` without neighbours.
    """
    return best_height_kept(thr, vis, np.empty(0), np.empty(0, dtype=np.int8), 0.0, zref, margin, min_gain)


@nb.njit(cache=True, nogil=True)
def best_height_kept(thr, vis, lthr, lvis, weight, zref, margin, min_gain):
    """:func:`best_height` with the point's *neighbours* counted too.

    ``lthr``, ``lvis`` are the thresholds and T's verdicts (1 seen, 0 not, -1 no
    neighbour there) of the neighbours, probes close to the point: the partners spread
    over the terrain say little about short sight lines. The height maximises the
    partners' agreement plus ``weight`` times the neighbours' agreement (both step
    functions of z); ``weight`` = inf keeps the neighbours' agreement at least as high as
    at ``zref`` and maximises the partners' among those heights. The returned score is
    the partners' agreement; ``min_gain`` applies to the combined one. With no
    neighbours this is :func:`best_height`.
    """
    K = thr.shape[0]
    L = lthr.shape[0]
    hard = weight == _INF
    keep = 0  # the neighbours' agreement at zref
    for k in range(L):
        if lvis[k] >= 0 and (zref >= lthr[k]) == (lvis[k] == 1):
            keep += 1
    t = np.empty(K + L)
    dg = np.zeros(K + L, dtype=np.int64)  # the change of the partners' agreement on crossing t
    dl = np.zeros(K + L, dtype=np.int64)  # ... and of the neighbours'
    g = 0  # agreements below every threshold: only thresholds of -inf are seen
    loc = 0
    for k in range(K):
        t[k] = thr[k]
        if thr[k] == -_INF:
            g += 1 if vis[k] else 0
        else:
            g += 0 if vis[k] else 1
            dg[k] = 1 if vis[k] else -1
    for k in range(L):
        t[K + k] = lthr[k]
        if lvis[k] < 0:
            continue
        if lthr[k] == -_INF:
            loc += 1 if lvis[k] == 1 else 0
        else:
            loc += 0 if lvis[k] == 1 else 1
            dl[K + k] = 1 if lvis[k] == 1 else -1
    w = 0.0 if hard else weight
    order = np.argsort(t)
    n = K + L
    best = -_INF
    best_g = -1
    best_z = zref
    best_d = _INF
    at_ref = -_INF
    at_ref_g = -1
    lo = -_INF
    j = 0
    while j <= n:
        # z in [lo, hi) sees exactly the partners and neighbours with a threshold <= lo
        hi = _INF if j == n else t[order[j]]
        sc = g + w * loc
        if lo <= zref < hi:
            at_ref = sc
            at_ref_g = g
        if hi > lo and (not hard or loc >= keep) and sc >= best:
            if sc > best:
                best = sc
                best_g = g
                best_d = _INF
            m = margin
            if hi - lo < 2.0 * m:
                m = 0.5 * (hi - lo)
            zc = zref
            if zc < lo + m:
                zc = lo + m
            if zc > hi - m:
                zc = hi - m
            d = abs(zc - zref)
            if d < best_d:
                best_d = d
                best_z = zc
                best_g = g
        if j == n:
            break
        while j < n and t[order[j]] == hi:
            k = order[j]
            if t[k] > -_INF:
                g += dg[k]
                loc += dl[k]
            j += 1
        lo = hi
    if best - at_ref < min_gain:
        return zref, at_ref_g
    return best_z, best_g


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def optimistic(thr, state, vis):
    """Turn a window's thresholds (``state``: see :func:`grid_clamped`) into the most
    favourable ones they allow, in place, and return the window ``(lo, hi)`` inside which
    those give every verdict exactly (see "Windows").

    A threshold known to be at most ``thr[k]`` becomes -inf when the partner is seen on T
    (it agrees at every height then) and stays ``thr[k]`` otherwise (agreeing below it,
    as it may); one known to be at least ``thr[k]`` becomes +inf when the partner is not
    seen on T and stays otherwise. No partner then agrees at any height less than with
    its exact threshold, and inside (``lo``, ``hi``), the largest of the first bounds and
    the least of the second, every one agrees exactly as with it.
    """
    lo = -_INF
    hi = _INF
    for k in range(thr.shape[0]):
        if state[k] < 0:
            lo = max(lo, thr[k])
            if vis[k]:
                thr[k] = -_INF
        elif state[k] > 0:
            hi = min(hi, thr[k])
            if not vis[k]:
                thr[k] = _INF
    return lo, hi


# --------------------------------------------------------------------------- loops
def _make_row(kind):
    @kernel_of(kind, "_grid_row", "_tin_row", **KERNEL_ONLY)
    def row(s, st, p, q, rules, skip, out, state, zlo, zhi, redo):
        """The thresholds of the point p = (x, y, z) for the targets q on the surface ``s``
        (``st``: a grid's walk stack, None on a TIN), known exactly only inside (``zlo``,
        ``zhi``): :func:`grid_clamped`'s ``(z, state)`` into ``out[k]`` and ``state[k]``
        (-inf and 0 for k = ``skip``); with (-inf, inf) every threshold exactly. ``redo``:
        only the targets whose ``state`` is not 0 (their bounds walked again, the others
        stand).

        The one place the clamped walk is compiled in (it is inlined here, and its probes
        in it): as a kernel of its own, called once per target, it took the surface's and
        the track's records as arguments at every call, and the calibrated relocation ran
        about three times slower (docs/performance.md, "The clamped walk inlined in its row")."""
        # views without reference counts (the caller keeps the arrays alive): every walk
        # would otherwise count references to each array of the surface (5-20 % of the row)
        if kind == GRID:
            s = borrow_grid(s)
            st = WalkStack(borrow(st.level), borrow(st.row), borrow(st.col), borrow(st.t))
            fp = _NO_FACE
        else:
            s = borrow_tin(s)
            fp = face_at(s, p[0], p[1])
        for k in range(q.shape[0]):
            if k == skip:
                out[k] = -_INF
                state[k] = 0
            elif redo and state[k] == 0:
                continue
            elif kind == GRID:
                out[k], state[k] = grid_clamped(s, st, p, (q[k, 0], q[k, 1], q[k, 2]), rules, zlo, zhi, fp)
            else:
                out[k], state[k] = tin_clamped(s, st, p, (q[k, 0], q[k, 1], q[k, 2]), rules, zlo, zhi, fp)

    return row


def _make_best(kind):
    @kernel_of(kind, "_grid_best", "_tin_best", **KERNEL_ONLY)
    def best(s, st, p, q, vis, near, rules, skip, thr, state):
        """The best height of the point p = (x, y, reference height) against the partners q
        (but ``skip``) whose verdicts on T are ``vis``, with its neighbours ``near`` = (their
        thresholds, verdicts, weight): :func:`best_height_kept`'s ``(z, agreement)``. The
        thresholds are walked in the window first (``thr``, ``state``: scratch rows), and those
        known only by a bound exactly when the window's choice might not stand (see "Windows")."""
        lthr, lvis, weight = near
        if rules.window < _INF:
            zlo = p[2] - rules.window
            zhi = p[2] + rules.window
        else:
            zlo = -_INF
            zhi = _INF
        if kind == GRID:
            _grid_row(s, st, p, q, rules, skip, thr, state, zlo, zhi, False)
        else:
            _tin_row(s, st, p, q, rules, skip, thr, state, zlo, zhi, False)
        if rules.window < _INF:
            lo, hi = optimistic(thr, state, vis)
            z, a = best_height_kept(thr, vis, lthr, lvis, weight, p[2], rules.margin, rules.min_gain)
            if z > lo + rules.margin and z < hi - rules.margin:
                return z, a
            # the window's exact thresholds stand; the bounds are walked whole
            if kind == GRID:
                _grid_row(s, st, p, q, rules, skip, thr, state, -_INF, _INF, True)
            else:
                _tin_row(s, st, p, q, rules, skip, thr, state, -_INF, _INF, True)
        return best_height_kept(thr, vis, lthr, lvis, weight, p[2], rules.margin, rules.min_gain)

    return best


def _make_entry_row(kind):
    @kernel_of(kind, "grid_row", "tin_row")
    def entry_row(s, p, q, rules, skip, out):
        """``out[k]`` = the threshold of the point p = (x, y, z) for the target q[k] (-inf for
        k = ``skip``): :func:`_grid_row` with every threshold exact (one row, called from Python)."""
        state = np.empty(q.shape[0], dtype=np.int8)
        if kind == GRID:
            _grid_row(s, new_stack(s.ltop), p, q, rules, skip, out, state, -_INF, _INF, False)
        else:
            _tin_row(s, None, p, q, rules, skip, out, state, -_INF, _INF, False)

    return entry_row


def _make_heights(kind):
    @kernel_of(kind, "grid_heights", "tin_heights")
    def heights(s, p, q, vis, near, rules, out, score, i0, i1, stop):
        """Best height of each point p[i], i in ``i0 .. i1 - 1``, = (x, y, reference height)
        against the partners q (x, y, height on the surface ``s``), whose verdicts on T are
        ``vis[i]``, keeping its agreement with its :data:`Neighbours` ``near`` (thresholds
        ``near.lthr[i]``, verdicts ``near.lvis[i]``: :func:`best_height_kept`);
        :func:`terrainvis.core.interrupt.call` spreads the points over threads."""
        if kind == GRID:
            st = new_stack(s.ltop)
        else:
            st = None
        thr = np.empty(q.shape[0])
        state = np.empty(q.shape[0], dtype=np.int8)
        for i in range(i0, i1):
            if stopped(stop):
                return
            pi = (p[i, 0], p[i, 1], p[i, 2])
            ni = (near.lthr[i], near.lvis[i], near.weight)
            if kind == GRID:
                out[i], score[i] = _grid_best(s, st, pi, q, vis[i], ni, rules, _NO_SKIP, thr, state)
            else:
                out[i], score[i] = _tin_best(s, st, pi, q, vis[i], ni, rules, _NO_SKIP, thr, state)

    return heights


def _make_sweep(kind):
    @kernel_of(kind, "grid_sweep", "tin_sweep")
    def sweep(s, q, order, vis, rules, stop):
        """One Gauss-Seidel sweep: each partner q[order[j]] in turn takes its best height
        (column 2 of ``q``, updated in place) against the others at their current heights.

        Serial: each step depends on the previous one (a compare runs units side by side).
        """
        thr = np.empty(q.shape[0])
        state = np.empty(q.shape[0], dtype=np.int8)
        if kind == GRID:
            st = new_stack(s.ltop)
        else:
            st = None
        none = (np.empty(0), np.empty(0, dtype=np.int8), 0.0)
        for j in range(order.shape[0]):
            if stopped(stop):
                return
            i = order[j]
            qi = (q[i, 0], q[i, 1], q[i, 2])
            if kind == GRID:
                q[i, 2], _ = _grid_best(s, st, qi, q, vis[i], none, rules, i, thr, state)
            else:
                q[i, 2], _ = _tin_best(s, st, qi, q, vis[i], none, rules, i, thr, state)

    return sweep


_grid_row, _tin_row = _make_row(GRID), _make_row(TIN)
_grid_best, _tin_best = _make_best(GRID), _make_best(TIN)
grid_row, tin_row = _make_entry_row(GRID), _make_entry_row(TIN)
grid_heights, tin_heights = _make_heights(GRID), _make_heights(TIN)
grid_sweep, tin_sweep = _make_sweep(GRID), _make_sweep(TIN)


# --------------------------------------------------------------------------- one eye, many targets
#: Targets per chunk of the eye kernels' parallel loops (each chunk reads the stop flag once).
EYE_CHUNK = 256


def _make_span(kind):
    @kernel_of(kind, "_grid_span", "_tin_span", **KERNEL_ONLY)
    def span(s, st, tr, u0, u1):
        """Max of :func:`_value` over [u0, u1] of the track ``tr`` on the surface ``s`` (the
        walk of :func:`grid_threshold`, on that part of the track)."""
        t = Track(tr.qx, tr.qy, tr.qz, tr.dx, tr.dy, u0, u1, tr.tol, tr.bulge, -_INF, _INF)
        if kind == GRID:
            if s.ltop <= DDA_MAX_LEVELS:
                return grid_dda_max_slope(s, t)
            return grid_max_slope(s, t, st)
        else:
            return tin_max_slope(s, t)

    return span


_grid_span, _tin_span = _make_span(GRID), _make_span(TIN)


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _eye_track(eye, tx, ty, rules):
    """The :data:`Track` from the eye to the target point (tx, ty) (its interval is set by
    the callers, per part)."""
    qx, qy, qz = eye
    dx = tx - qx
    dy = ty - qy
    return Track(qx, qy, qz, dx, dy, 0.0, 1.0, rules.tol, rules.kc * (dx * dx + dy * dy), -_INF, _INF)


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _trim(eye, tx, ty, tz, rules):
    """The start of the tested interval of the segment eye - (tx, ty, tz) (-1: not tested)."""
    return interval(tx, ty, tz, eye[0], eye[1], eye[2], rules.delta, rules.end_radius)[0]


def _make_eye_one(kind):
    @kernel_of(kind, "_grid_eye_one", "_tin_eye_one", **KERNEL_ONLY)
    def eye_one(s, st, eye, tx, ty, tz, rules):
        """The threshold of the target point (tx, ty) for the fixed ``eye`` on the surface
        ``s``, under the trim of a target at the answer itself.

        Walked first with the target at ``tz`` (which only sets the trim): ``t`` over
        ``[ua, 1 - ua]``. When ``t`` differs from ``tz`` (above it: the target is hidden; below
        it: the horizon the angle output needs), the trim ``ub`` of a target at ``t`` differs
        slightly, and only the two slivers between ``ua`` and ``ub`` (at the eye, at the target)
        are walked: a grown interval takes their maximum too; a shrunk one keeps ``t`` when
        their maximum is below it (the maximum then lies in the part both share), and is
        walked whole again otherwise. Near the eye, where a segment is short, this matters:
        without it a horizon 1.3 m from the eye was 1.3e-6 m off the pair engine's.
        """
        ua = _trim(eye, tx, ty, tz, rules)
        if ua < 0.0:
            return -_INF
        tr = _eye_track(eye, tx, ty, rules)
        if kind == GRID:
            t = tr.qz + _grid_span(s, st, tr, ua, 1.0 - ua)
        else:
            t = tr.qz + _tin_span(s, st, tr, ua, 1.0 - ua)
        if not (t != tz and abs(t) < _INF):
            return t
        ub = _trim(eye, tx, ty, t, rules)
        if ub < 0.0:
            return -_INF
        if ub == ua:
            return t
        lo = min(ua, ub)
        hi = max(ua, ub)
        if kind == GRID:
            m = tr.qz + max(_grid_span(s, st, tr, lo, hi), _grid_span(s, st, tr, 1.0 - hi, 1.0 - lo))
        else:
            m = tr.qz + max(_tin_span(s, st, tr, lo, hi), _tin_span(s, st, tr, 1.0 - hi, 1.0 - lo))
        if ub < ua:
            return max(t, m)
        if m < t:
            return t
        if kind == GRID:
            return tr.qz + _grid_span(s, st, tr, ub, 1.0 - ub)
        else:
            return tr.qz + _tin_span(s, st, tr, ub, 1.0 - ub)

    return eye_one


def _make_eye_thresholds(kind):
    @kernel_of(kind, "grid_eye_thresholds", "tin_eye_thresholds")
    def eye_thresholds(s, eye, t, rules, out, k0, k1, stop):
        """``out[i]`` = the threshold height of the target point ``t[i]`` = (x, y, z) (local; z
        sets the trim) for the fixed ``eye`` = (x, y, z) on the surface ``s``: the least height
        at which it sees the eye (-inf: the segment is not tested), for the targets of chunks
        ``k0 .. k1 - 1`` of :data:`EYE_CHUNK` targets (:func:`eye_chunks` of them;
        :func:`terrainvis.core.interrupt.call` spreads them over threads)."""
        n = t.shape[0]
        if kind == GRID:
            sb = borrow_grid(s)
            st = new_stack(s.ltop)
        else:
            sb = borrow_tin(s)
            st = None
        for k in range(k0, k1):
            if stopped(stop):
                return
            for i in range(k * EYE_CHUNK, min(n, (k + 1) * EYE_CHUNK)):
                if kind == GRID:
                    out[i] = _grid_eye_one(sb, st, eye, t[i, 0], t[i, 1], t[i, 2], rules)
                else:
                    out[i] = _tin_eye_one(sb, st, eye, t[i, 0], t[i, 1], t[i, 2], rules)

    return eye_thresholds


_grid_eye_one, _tin_eye_one = _make_eye_one(GRID), _make_eye_one(TIN)
grid_eye_thresholds, tin_eye_thresholds = _make_eye_thresholds(GRID), _make_eye_thresholds(TIN)


def eye_chunks(n_targets: int) -> int:
    """The chunks of :data:`EYE_CHUNK` targets of :func:`grid_eye_thresholds` and :func:`tin_eye_thresholds`."""
    return (n_targets + EYE_CHUNK - 1) // EYE_CHUNK
