"""Numba loops for greedy insertion (Garland & Heckbert 1995, Algorithm III).

Kernels loop and never validate: :mod:`simplifiers.greedy_insertion` checks the input.

Geometry is done in *index space*: a vertex is a grid sample ``(col, row)`` held as
integers, so orientation tests and scan conversion are exact integer arithmetic (points
on edges and on grid lines are detected exactly). The in-circle test of the Delaunay
flips uses the cell aspect ratio ``ratio = (dy / dx) ** 2``: with integer coordinates
relative to the query point it splits into two exact int64 determinants ``D1 + ratio *
D2``, so it is exact for square cells (``ratio == 1``) and for cocircular axis-aligned
rectangles under any ratio.

Data layout (half-edge, as in Delaunator): triangle ``t`` has half-edges ``3t, 3t+1,
3t+2``; half-edge ``e`` runs from vertex ``tri[e]`` to ``tri[next(e)]`` and every triangle
is counter-clockwise with x = column and y = row; ``half[e]`` is the twin half-edge in the
neighbouring triangle or -1 on the grid boundary.

Each triangle keeps one candidate: the non-vertex grid sample in its closure with the
largest vertical error (``cand[t]``, the flat index ``row * W + col``, or -1 when the
triangle holds no sample besides its corners) and that error ``terr[t]``. Triangles with a
candidate sit in an indexed binary max-heap (``heap`` the triangles, ``hval`` their errors,
``pos[t]`` = heap slot or -1), so a triangle's entry can be updated or removed when it
changes: the heap of :mod:`simplifiers._shared_kernels` in the order
:func:`~simplifiers._shared_kernels.larger` (equal errors in the order the sifting leaves).

Limits: the in-circle determinants are exact in int64 for grids up to about 30,000
samples per side; triangle and half-edge indices are int32 (grids below about 350 million
samples).

``counts`` holds the state that persists between calls: ``[n_vertices, n_triangles,
heap_size, n_flips, n_edge_splits]``.

The arrays travel together as one named record, :class:`State` (a named tuple, which
numba passes to a kernel as one argument and reads by field name).
"""

from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from terrainvis.core.compiling import KERNEL_ONLY
from terrainvis.core.stopflag import stopped

from ._shared_kernels import heap_remove, heap_set, larger, orient

NV, NT, NH, NFLIP, NEDGE = 0, 1, 2, 3, 4

#: Indices as int64, not literals: numba compiles a callee once per argument type, and a
#: literal (0, -1) or an int32 read from the int32 arrays is a type of its own; the
#: triangle and heap helpers get int64 only (one compilation each; the int32 arrays
#: store the same values).
_I0, _I1, _I2, _I3, _NONE = np.int64(0), np.int64(1), np.int64(2), np.int64(3), np.int64(-1)

#: The state of a greedy-insertion run (see the module docstring for each array):
#: vertices ``vx``, ``vy`` (int64 column, row); half-edge triangulation ``tri``, ``half``
#: (int32); per triangle its candidate ``cand`` (int64 flat index) and error ``terr``;
#: the indexed max-heap ``heap``, ``hval``, ``pos``; the triangles to rescan ``pend``,
#: ``pmark``; the flip ``stack``; and ``counts``.
State = namedtuple(
    "State", ["vx", "vy", "tri", "half", "cand", "terr", "heap", "hval", "pos", "pend", "pmark", "stack", "counts"]
)


# ----------------------------------------------------------------- predicates
@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _in_circle(ax, ay, bx, by, cx, cy, px, py, ratio):
    """True when p lies strictly inside the circumcircle of the counter-clockwise (a, b, c).

    Coordinates are integer grid indices; the circle is taken in the scaled space
    (col * dx, row * dy), ``ratio = (dy / dx) ** 2``.
    """
    ax -= px
    ay -= py
    bx -= px
    by -= py
    cx -= px
    cy -= py
    # det[i, j, i^2] and det[i, j, j^2] over the rows a, b, c (exact int64)
    m_ab = ax * by - bx * ay
    m_bc = bx * cy - cx * by
    m_ca = cx * ay - ax * cy
    d1 = ax * ax * m_bc + bx * bx * m_ca + cx * cx * m_ab
    d2 = ay * ay * m_bc + by * by * m_ca + cy * cy * m_ab
    if ratio == 1.0:
        return d1 + d2 > 0
    return float(d1) + ratio * float(d2) > 0.0


# ------------------------------------------------------------ scan conversion
@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _edge_span(ux, uy, vx, vy, py, lo, hi):
    """Narrow [lo, hi] to the columns px with orient(u, v, (px, py)) >= 0 (exact)."""
    a = -(vy - uy)
    b = (vx - ux) * (py - uy) + (vy - uy) * ux
    if a > 0:
        m = -(b // a)  # ceil(-b / a)
        if m > lo:
            lo = m
    elif a < 0:
        m = b // (-a)  # floor(b / -a)
        if m < hi:
            hi = m
    elif b < 0:
        hi = lo - 1
    return lo, hi


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def scan_triangle(z, W, ax, ay, bx, by, cx, cy):
    """Largest vertical error over the grid samples in the closed triangle (a, b, c).

    Parameters
    ----------
    z : (H * W,) float64
        Heights, row-major.
    W : int
        Columns.
    ax, ay, bx, by, cx, cy : int
        Counter-clockwise corners as (col, row).

    Returns
    -------
    (err, idx) : (float, int)
        The error of the worst sample other than the three corners and its flat index
        (the first in row-major order on ties), or (-1.0, -1) when the triangle holds no
        other sample.
    """
    area = float(orient(ax, ay, bx, by, cx, cy))
    za = z[ay * W + ax]
    zb = z[by * W + bx]
    zc = z[cy * W + cx]
    gx = (-(zb - za) * (ay - cy) - (zc - za) * (by - ay)) / area
    gy = ((zb - za) * (ax - cx) + (zc - za) * (bx - ax)) / area
    ymin = min(ay, by, cy)
    ymax = max(ay, by, cy)
    xmin = min(ax, bx, cx)
    xmax = max(ax, bx, cx)
    best = -1.0
    best_idx = -1
    for py in range(ymin, ymax + 1):
        lo, hi = _edge_span(ax, ay, bx, by, py, xmin, xmax)
        lo, hi = _edge_span(bx, by, cx, cy, py, lo, hi)
        lo, hi = _edge_span(cx, cy, ax, ay, py, lo, hi)
        if lo > hi:
            continue
        base = za - gx * ax + gy * (py - ay)
        row = py * W
        for px in range(lo, hi + 1):
            d = abs(base + gx * px - z[row + px])
            if d > best:
                if (px == ax and py == ay) or (px == bx and py == by) or (px == cx and py == cy):
                    continue
                best = d
                best_idx = row + px
    return best, best_idx


# ------------------------------------------------------------ triangulation
@nb.njit(cache=True, nogil=True, inline="always")
def _link(half, a, b):
    half[a] = b
    if b >= 0:
        half[b] = a


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _set_tri(tri, half, pend, pmark, npend, t, p0, p1, p2, h0, h1, h2):
    """Write triangle t = (p0, p1, p2), link its half-edges to h0, h1, h2, mark it for a rescan."""
    e = 3 * t
    tri[e] = p0
    tri[e + 1] = p1
    tri[e + 2] = p2
    _link(half, e, h0)
    _link(half, e + 1, h1)
    _link(half, e + 2, h2)
    if not pmark[t]:
        pmark[t] = True
        pend[npend] = t
        npend += 1
    return npend


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _legalize(vx, vy, tri, half, pend, pmark, npend, stack, counts, a_start, ratio):
    """Restore the Delaunay property around half-edge ``a_start`` by in-circle edge flips."""
    top = 0
    stack[top] = a_start
    top += 1
    while top > 0:
        top -= 1
        a = stack[top]
        b = half[a]
        if b < 0:
            continue
        a0 = a - a % 3
        b0 = b - b % 3
        al = a0 + (a + 1) % 3
        ar = a0 + (a + 2) % 3
        bl = b0 + (b + 2) % 3
        br = b0 + (b + 1) % 3
        p0 = tri[ar]
        pr = tri[a]
        pl = tri[al]
        p1 = tri[bl]
        if not _in_circle(vx[p0], vy[p0], vx[pr], vy[pr], vx[pl], vy[pl], vx[p1], vy[p1], ratio):
            continue
        # flip the edge pr-pl of triangles (pr, pl, p0) and (pl, pr, p1) to p0-p1
        tri[a] = p1
        tri[b] = p0
        hbl = half[bl]
        har = half[ar]
        _link(half, a, hbl)
        _link(half, b, har)
        _link(half, ar, bl)
        counts[NFLIP] += 1
        ta = a0 // 3
        tb = b0 // 3
        if not pmark[ta]:
            pmark[ta] = True
            pend[npend] = ta
            npend += 1
        if not pmark[tb]:
            pmark[tb] = True
            pend[npend] = tb
            npend += 1
        stack[top] = br
        top += 1
        stack[top] = a
        top += 1
    return npend


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _rescan(z, W, st, npend):
    """Rescan the ``npend`` triangles marked in ``st.pend``: their candidates and heap entries."""
    vx, vy, tri, cand, terr = st.vx, st.vy, st.tri, st.cand, st.terr
    heap, hval, pos, pend, pmark, counts = st.heap, st.hval, st.pos, st.pend, st.pmark, st.counts
    for k in range(npend):
        t = np.int64(pend[k])
        pmark[t] = False
        e = 3 * t
        i0 = tri[e]
        i1 = tri[e + 1]
        i2 = tri[e + 2]
        err, idx = scan_triangle(z, W, vx[i0], vy[i0], vx[i1], vy[i1], vx[i2], vy[i2])
        cand[t] = idx
        terr[t] = err
        if idx < 0:
            if pos[t] >= 0:
                heap_remove(hval, heap, pos, counts, NH, t, larger)
        else:
            heap_set(hval, heap, pos, counts, NH, t, err, larger)


@nb.njit(cache=True, nogil=True)
def init_state(z, W, H, st):
    """The two triangles over the four corners, split along (0, 0)-(W-1, H-1), scanned (``st``: a :class:`State`)."""
    vx, vy, tri, half, pend, pmark, counts = st.vx, st.vy, st.tri, st.half, st.pend, st.pmark, st.counts
    x1 = W - 1
    y1 = H - 1
    vx[0] = 0
    vy[0] = 0
    vx[1] = x1
    vy[1] = 0
    vx[2] = x1
    vy[2] = y1
    vx[3] = 0
    vy[3] = y1
    counts[NV] = 4
    counts[NT] = 2
    counts[NH] = 0
    half[:6] = -1
    npend = _set_tri(tri, half, pend, pmark, _I0, _I0, _I0, _I1, _I2, _NONE, _NONE, _NONE)
    npend = _set_tri(tri, half, pend, pmark, npend, _I1, _I0, _I2, _I3, _I2, _NONE, _NONE)
    _rescan(z, W, st, npend)


@nb.njit(cache=True, nogil=True)
def run(z, W, ratio, st, n_target, max_error, stop):
    """Insert the worst candidate until there are ``n_target`` vertices, no candidate is left,
    the worst error is <= ``max_error`` (ignored when negative) or the stop flag ``stop[0]``
    is set (:mod:`terrainvis.core.interrupt`; checked before every insertion).

    ``st`` is the :class:`State`, ``z`` the (H * W,) heights and ``ratio`` the in-circle
    aspect ``(dy / dx) ** 2``. Returns the largest vertical error of the current TIN over
    all grid samples.
    """
    vx, vy, tri, half, cand, heap, hval, pos = st.vx, st.vy, st.tri, st.half, st.cand, st.heap, st.hval, st.pos
    pend, pmark, stack, counts = st.pend, st.pmark, st.stack, st.counts
    while counts[NV] < n_target and counts[NH] > 0:
        if max_error >= 0.0 and hval[0] <= max_error:
            break
        if stopped(stop):
            break
        t = np.int64(heap[0])
        heap_remove(hval, heap, pos, counts, NH, t, larger)
        idx = cand[t]
        px = idx % W
        py = idx // W
        pn = counts[NV]
        vx[pn] = px
        vy[pn] = py
        counts[NV] = pn + 1

        e0 = 3 * t
        p0 = np.int64(tri[e0])
        p1 = np.int64(tri[e0 + 1])
        p2 = np.int64(tri[e0 + 2])
        on = -1
        if orient(vx[p0], vy[p0], vx[p1], vy[p1], px, py) == 0:
            on = e0
        elif orient(vx[p1], vy[p1], vx[p2], vy[p2], px, py) == 0:
            on = e0 + 1
        elif orient(vx[p2], vy[p2], vx[p0], vy[p0], px, py) == 0:
            on = e0 + 2
        npend = _I0
        nt = counts[NT]
        if on < 0:
            # strictly inside: split in 3
            h0 = np.int64(half[e0])
            h1 = np.int64(half[e0 + 1])
            h2 = np.int64(half[e0 + 2])
            t0 = t
            t1 = nt
            t2 = nt + 1
            counts[NT] = nt + 2
            npend = _set_tri(tri, half, pend, pmark, npend, t0, p0, p1, pn, h0, _NONE, _NONE)
            npend = _set_tri(tri, half, pend, pmark, npend, t1, p1, p2, pn, h1, _NONE, 3 * t0 + 1)
            npend = _set_tri(tri, half, pend, pmark, npend, t2, p2, p0, pn, h2, 3 * t0 + 2, 3 * t1 + 1)
            npend = _legalize(vx, vy, tri, half, pend, pmark, npend, stack, counts, 3 * t0, ratio)
            npend = _legalize(vx, vy, tri, half, pend, pmark, npend, stack, counts, 3 * t1, ratio)
            npend = _legalize(vx, vy, tri, half, pend, pmark, npend, stack, counts, 3 * t2, ratio)
        else:
            counts[NEDGE] += 1
            a = on
            an = e0 + (a + 1) % 3
            ap = e0 + (a + 2) % 3
            pa = np.int64(tri[a])
            pb = np.int64(tri[an])
            pc = np.int64(tri[ap])
            h_bc = np.int64(half[an])
            h_ca = np.int64(half[ap])
            b = np.int64(half[a])
            if b < 0:
                # on a boundary edge: split in 2
                t0 = t
                t1 = nt
                counts[NT] = nt + 1
                npend = _set_tri(tri, half, pend, pmark, npend, t0, pn, pb, pc, _NONE, h_bc, _NONE)
                npend = _set_tri(tri, half, pend, pmark, npend, t1, pn, pc, pa, 3 * t0 + 2, h_ca, _NONE)
                npend = _legalize(vx, vy, tri, half, pend, pmark, npend, stack, counts, 3 * t0 + 1, ratio)
                npend = _legalize(vx, vy, tri, half, pend, pmark, npend, stack, counts, 3 * t1 + 1, ratio)
            else:
                # on an interior edge: split both triangles, 4 in all
                b0 = b - b % 3
                bn = b0 + (b + 1) % 3
                bp = b0 + (b + 2) % 3
                pd = np.int64(tri[bp])
                h_ad = np.int64(half[bn])
                h_db = np.int64(half[bp])
                tb = b0 // 3
                if pos[tb] >= 0:
                    heap_remove(hval, heap, pos, counts, NH, tb, larger)
                t0 = t
                t1 = nt
                t2 = tb
                t3 = nt + 1
                counts[NT] = nt + 2
                npend = _set_tri(tri, half, pend, pmark, npend, t0, pn, pb, pc, _NONE, h_bc, _NONE)
                npend = _set_tri(tri, half, pend, pmark, npend, t1, pn, pc, pa, 3 * t0 + 2, h_ca, _NONE)
                npend = _set_tri(tri, half, pend, pmark, npend, t2, pn, pa, pd, 3 * t1 + 2, h_ad, _NONE)
                npend = _set_tri(tri, half, pend, pmark, npend, t3, pn, pd, pb, 3 * t2 + 2, h_db, 3 * t0)
                npend = _legalize(vx, vy, tri, half, pend, pmark, npend, stack, counts, 3 * t0 + 1, ratio)
                npend = _legalize(vx, vy, tri, half, pend, pmark, npend, stack, counts, 3 * t1 + 1, ratio)
                npend = _legalize(vx, vy, tri, half, pend, pmark, npend, stack, counts, 3 * t2 + 1, ratio)
                npend = _legalize(vx, vy, tri, half, pend, pmark, npend, stack, counts, 3 * t3 + 1, ratio)
        _rescan(z, W, st, npend)
    if counts[NH] > 0:
        return max(hval[0], 0.0)
    return 0.0
