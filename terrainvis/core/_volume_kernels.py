"""Numba loops for the volume between a grid surface and a triangulated one.

:func:`terrainvis.core.deviation.volume_error` validates its input and calls
:func:`volume_between`; the kernels here loop and never validate.

The integral of ``|coarse - fine|`` is a sum over the pieces of the overlay of the two
triangulations: on each piece both surfaces are linear, so the difference ``d`` is
linear too and ``|d|`` integrates in closed form (:func:`abs_integral_tri`). The loop
runs over the coarse triangles; each one visits the fine cells of each grid row it
crosses, and each fine triangle of such a cell is

* *inside* the coarse triangle (its three vertices on the inner side of all three
  edges): one closed-form integral, no clipping;
* *outside* (all three vertices on the outer side of one edge): skipped;
* crossed by one edge only (the common case): the corner on one side of that edge is
  integrated in closed form (:func:`inside_one_edge`);
* otherwise clipped by the coarse triangle's edges (Sutherland-Hodgman), and the convex
  polygon left over is integrated as a fan of triangles.

Two coarse triangles that share an edge evaluate the line of that edge with the same
floating-point operations (from its lower vertex id to its higher one, the sign flipped
for the triangle that runs along it the other way), so the two agree exactly on which
side of the edge each fine vertex lies and on where a fine edge crosses it.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .compiling import KERNEL_ONLY
from .stopflag import stopped

# Columns of the per-chunk result rows written by :func:`volume_between`.
VOL = 0  #: Neumaier sum of the integral of |d|
VOL_C = 1  #: its running compensation
AREA = 2  #: Neumaier sum of the area of the integrated pieces
AREA_C = 3  #: its running compensation
N_OUT = 4

# Columns of a clipping buffer row: a polygon vertex, its d and its three edge values.
PX = 0
PY = 1
PD = 2
PE = 3  # PE + k: the value of edge function k of the coarse triangle at this vertex
N_PCOL = 6
MAX_POLY = 8  # a triangle clipped by three half-planes has at most 6 vertices


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def abs_integral_tri(area, d0, d1, d2):
    """The integral of |d| over a triangle on which d is linear.

    Parameters
    ----------
    area : float
        Projected area of the triangle.
    d0, d1, d2 : float
        Values of d at its vertices.

    Notes
    -----
    When the signs differ, one vertex (value a) is alone on its side; flipping every sign
    if needed, a > 0 >= b, c. The zero line cuts the edges from it at fractions
    t1 = a / (a - b) and t2 = a / (a - c), so the positive part is a triangle of area
    ``area * t1 * t2`` with values a, 0, 0, whose integral is ``area * a * t1 * t2 / 3``,
    and ``integral |d| = 2 * positive part - integral d``.
    """
    s = d0 + d1 + d2
    lo = min(d0, d1, d2)
    hi = max(d0, d1, d2)
    if not (lo < 0.0 and hi > 0.0):
        return area * abs(s) / 3.0
    mid = max(min(d0, d1), min(max(d0, d1), d2))
    if mid <= 0.0:  # hi is alone above zero
        a = hi
        b = lo
        c = mid
    else:  # lo is alone below zero: flip every sign
        a = -lo
        b = -hi
        c = -mid
        s = -s
    pos = a * (a / (a - b)) * (a / (a - c))
    return area * (2.0 * pos - s) / 3.0


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _neumaier(s, c, x):
    """Add x to the compensated sum (s, c); returns the new (s, c)."""
    t = s + x
    if abs(s) >= abs(x):
        c += (s - t) + x
    else:
        c += (x - t) + s
    return t, c


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _cell_at_or_below(v, x, inv_step):
    """The largest cell i in [0, n-2] with v[i] <= x (0 when x < v[0])."""
    n = v.shape[0]
    i = int((x - v[0]) * inv_step) if x > v[0] else 0
    i = min(max(i, 0), n - 2)
    # a uniform axis lands on the cell or next to it; anything else searches
    if v[i] <= x and (i == n - 2 or x < v[i + 1]):
        return i
    if i > 0 and v[i - 1] <= x and x < v[i]:
        return i - 1
    if i < n - 2 and v[i + 1] <= x and (i + 1 == n - 2 or x < v[i + 2]):
        return i + 1
    return min(max(np.searchsorted(v, x, side="right") - 1, 0), n - 2)


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _cell_below(v, x, inv_step):
    """The largest cell i in [0, n-2] with v[i] < x (0 when x <= v[0])."""
    n = v.shape[0]
    i = int((x - v[0]) * inv_step) if x > v[0] else 0
    i = min(max(i, 0), n - 2)
    if v[i] < x and (i == n - 2 or x <= v[i + 1]):
        return i
    if i > 0 and v[i - 1] < x and x <= v[i]:
        return i - 1
    if i < n - 2 and v[i + 1] < x and (i + 1 == n - 2 or x <= v[i + 2]):
        return i + 1
    return min(max(np.searchsorted(v, x, side="left") - 1, 0), n - 2)


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _clip_integrate(buf):
    """Clip the triangle in ``buf[0, :3]`` by the coarse triangle's three edges and integrate.

    ``buf`` is (2, MAX_POLY, N_PCOL): two polygons used alternately. Every vertex carries
    x, y, d and the three edge values, and a new vertex on a polygon edge interpolates all
    of them (they are all linear). Returns (integral of |d|, area) of what is left.
    """
    src = 0
    n = 3
    for k in range(3):
        col = PE + k
        need = False
        for i in range(n):
            if buf[src, i, col] < 0.0:
                need = True
                break
        if not need:
            continue
        dst = 1 - src
        m = 0
        for i in range(n):
            j = i + 1 if i + 1 < n else 0
            ei = buf[src, i, col]
            ej = buf[src, j, col]
            if ei >= 0.0:
                for q in range(N_PCOL):
                    buf[dst, m, q] = buf[src, i, q]
                m += 1
            if (ei > 0.0 and ej < 0.0) or (ei < 0.0 and ej > 0.0):
                t = ei / (ei - ej)
                for q in range(N_PCOL):
                    buf[dst, m, q] = buf[src, i, q] + t * (buf[src, j, q] - buf[src, i, q])
                buf[dst, m, col] = 0.0
                m += 1
        src = dst
        n = m
        if n < 3:
            return 0.0, 0.0
    # a fan from vertex 0 of the convex polygon
    x0 = buf[src, 0, PX]
    y0 = buf[src, 0, PY]
    d0 = buf[src, 0, PD]
    vol = 0.0
    area = 0.0
    for i in range(1, n - 1):
        ux = buf[src, i, PX] - x0
        uy = buf[src, i, PY] - y0
        wx = buf[src, i + 1, PX] - x0
        wy = buf[src, i + 1, PY] - y0
        a = 0.5 * (ux * wy - wx * uy)
        vol += abs_integral_tri(a, d0, buf[src, i, PD], buf[src, i + 1, PD])
        area += a
    return vol, area


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _subtriangle(area, da, db, dc, ea, eb, ec):
    """The corner of a triangle at vertex a cut off by the zero line of e (ea > 0 >= eb, ec, or ea < 0 <= eb, ec).

    Returns (integral of |d|, area) over the part of the triangle on a's side of the
    line: a triangle with vertex a and the points where the line crosses edges ab, ac.
    """
    tb = ea / (ea - eb)
    tc = ea / (ea - ec)
    sub = area * tb * tc
    return abs_integral_tri(sub, da, da + tb * (db - da), da + tc * (dc - da)), sub


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def inside_one_edge(area, da, db, dc, ea, eb, ec):
    """The integral of |d| and the area over the part of a triangle where e >= 0.

    Both d and e are linear, with values (da, db, dc) and (ea, eb, ec) at the vertices,
    and e changes sign on the triangle (some value > 0 and some < 0). The vertex alone on
    its side is found; when it is on the inner side its corner is the answer, otherwise
    the answer is the triangle minus its corner. The two coarse triangles on either side
    of the line find the same lone vertex and the same crossing fractions, so their
    areas add up to the triangle's.
    """
    npos = 0
    if ea > 0.0:
        npos += 1
    if eb > 0.0:
        npos += 1
    if ec > 0.0:
        npos += 1
    if npos == 1:
        if ea > 0.0:
            return _subtriangle(area, da, db, dc, ea, eb, ec)
        if eb > 0.0:
            return _subtriangle(area, db, dc, da, eb, ec, ea)
        return _subtriangle(area, dc, da, db, ec, ea, eb)
    if ea < 0.0:
        v, a = _subtriangle(area, da, db, dc, ea, eb, ec)
    elif eb < 0.0:
        v, a = _subtriangle(area, db, dc, da, eb, ec, ea)
    else:
        v, a = _subtriangle(area, dc, da, db, ec, ea, eb)
    return abs_integral_tri(area, da, db, dc) - v, area - a


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _load_corner(buf, slot, x, y, d, e0, e1, e2):
    buf[0, slot, PX] = x
    buf[0, slot, PY] = y
    buf[0, slot, PD] = d
    buf[0, slot, PE] = e0
    buf[0, slot, PE + 1] = e1
    buf[0, slot, PE + 2] = e2


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def volume_faces(xs, ys, z, vx, vy, vz, faces, order, f0, f1, buf, stop):
    """Integral of |coarse - fine| and covered area over coarse faces ``order[f0 .. f1-1]``.

    Parameters
    ----------
    xs, ys : (cols,), (rows,) float64
        Fine grid coordinates (strictly increasing, in a local origin).
    z : (rows, cols) float64
        Fine heights.
    vx, vy, vz : (n,) float64
        Coarse vertices (the same local origin).
    faces : (m, 3) int
        Coarse faces, counter-clockwise; faces with area <= 0 are skipped.
    order : (m,) int64
        The order in which to visit the faces (:func:`faces_by_row`).
    f0, f1 : int
        The range of ``order`` to visit.
    buf : (2, MAX_POLY, N_PCOL) float64
        Clipping scratch.
    stop : (1,) int64
        The stop flag (:mod:`terrainvis.core.interrupt`), read before every face: when it is
        set the sums so far are returned.

    Returns
    -------
    (vol, vol_c, area, area_c) : floats
        Neumaier sums (and compensations) of the integral and of the integrated area.
    """
    nr = ys.shape[0]
    nc = xs.shape[0]
    inv_dx = (nc - 1) / (xs[nc - 1] - xs[0])
    inv_dy = (nr - 1) / (ys[nr - 1] - ys[0])
    ex_px = np.empty(3)
    ex_py = np.empty(3)
    ex_dx = np.empty(3)
    ex_dy = np.empty(3)
    ex_sg = np.empty(3)
    tx = np.empty(3)
    ty = np.empty(3)
    tid = np.empty(3, dtype=np.int64)
    # edge values at the cell corners: left/right, bottom/top
    e_lb = np.empty(3)
    e_lt = np.empty(3)
    e_rb = np.empty(3)
    e_rt = np.empty(3)
    # per row: dx_k * (y - py_k) at the bottom and top lines of the row
    a_b = np.empty(3)
    a_t = np.empty(3)
    vol = 0.0
    vol_c = 0.0
    cov = 0.0
    cov_c = 0.0
    for i_f in range(f0, f1):
        if stopped(stop):
            break
        f = order[i_f]
        for k in range(3):
            tid[k] = faces[f, k]
            tx[k] = vx[tid[k]]
            ty[k] = vy[tid[k]]
        ax = tx[0]
        ay = ty[0]
        az = vz[tid[0]]
        bdx = tx[1] - ax
        bdy = ty[1] - ay
        bdz = vz[tid[1]] - az
        cdx = tx[2] - ax
        cdy = ty[2] - ay
        cdz = vz[tid[2]] - az
        area2 = bdx * cdy - cdx * bdy
        if not area2 > 0.0:
            continue
        gx = (bdz * cdy - cdz * bdy) / area2
        gy = (bdx * cdz - cdx * bdz) / area2
        # Edge k runs from vertex k to vertex k+1 and is evaluated from its lower vertex id
        # to its higher one: e = sg * (dx * (y - py) - dy * (x - px)), > 0 inside.
        for k in range(3):
            i = k
            j = k + 1 if k < 2 else 0
            if tid[i] < tid[j]:
                p, q, sg = i, j, 1.0
            else:
                p, q, sg = j, i, -1.0
            ex_px[k] = tx[p]
            ex_py[k] = ty[p]
            ex_dx[k] = tx[q] - tx[p]
            ex_dy[k] = ty[q] - ty[p]
            ex_sg[k] = sg
        ymin = min(ty[0], ty[1], ty[2])
        ymax = max(ty[0], ty[1], ty[2])
        r0 = _cell_at_or_below(ys, ymin, inv_dy)
        r1 = _cell_below(ys, ymax, inv_dy)
        tvol = 0.0
        tvol_c = 0.0
        tcov = 0.0
        tcov_c = 0.0
        for r in range(r0, r1 + 1):
            y0 = ys[r]
            y1 = ys[r + 1]
            yb0 = max(y0, ymin)
            yb1 = min(y1, ymax)
            # the x range of the triangle inside this row
            xlo = np.inf
            xhi = -np.inf
            for k in range(3):
                j = k + 1 if k < 2 else 0
                px = tx[k]
                py = ty[k]
                qx = tx[j]
                qy = ty[j]
                ey0 = min(py, qy)
                ey1 = max(py, qy)
                if ey1 < yb0 or ey0 > yb1:
                    continue
                if qy == py:
                    xlo = min(xlo, px, qx)
                    xhi = max(xhi, px, qx)
                    continue
                for yy in (max(ey0, yb0), min(ey1, yb1)):
                    t = min(max((yy - py) / (qy - py), 0.0), 1.0)
                    xx = px + t * (qx - px)
                    xlo = min(xlo, xx)
                    xhi = max(xhi, xx)
            if not xlo < xhi:
                continue
            c0 = _cell_at_or_below(xs, xlo, inv_dx)
            c1 = _cell_below(xs, xhi, inv_dx)
            h = y1 - y0
            for k in range(3):
                a_b[k] = ex_dx[k] * (y0 - ex_py[k])
                a_t[k] = ex_dx[k] * (y1 - ex_py[k])
            plane_b = az + gy * (y0 - ay)
            plane_t = az + gy * (y1 - ay)
            x0 = xs[c0]
            for k in range(3):
                bx = ex_dy[k] * (x0 - ex_px[k])
                e_lb[k] = ex_sg[k] * (a_b[k] - bx)
                e_lt[k] = ex_sg[k] * (a_t[k] - bx)
            gxx = gx * (x0 - ax)
            d_lb = plane_b + gxx - z[r, c0]
            d_lt = plane_t + gxx - z[r + 1, c0]
            for c in range(c0, c1 + 1):
                x1 = xs[c + 1]
                inside = True
                for k in range(3):
                    bx = ex_dy[k] * (x1 - ex_px[k])
                    e_rb[k] = ex_sg[k] * (a_b[k] - bx)
                    e_rt[k] = ex_sg[k] * (a_t[k] - bx)
                    if e_lb[k] < 0.0 or e_lt[k] < 0.0 or e_rb[k] < 0.0 or e_rt[k] < 0.0:
                        inside = False
                gxx = gx * (x1 - ax)
                d_rb = plane_b + gxx - z[r, c + 1]
                d_rt = plane_t + gxx - z[r + 1, c + 1]
                w = x1 - x0
                half = 0.5 * w * h
                if inside:
                    tvol, tvol_c = _neumaier(tvol, tvol_c, abs_integral_tri(half, d_lb, d_rb, d_rt))
                    tvol, tvol_c = _neumaier(tvol, tvol_c, abs_integral_tri(half, d_lb, d_rt, d_lt))
                    tcov, tcov_c = _neumaier(tcov, tcov_c, 2.0 * half)
                else:
                    # the lower triangle (lb, rb, rt), then the upper one (lb, rt, lt)
                    for part in range(2):
                        outside = False
                        ncut = 0
                        kcut = 0
                        for k in range(3):
                            ea = e_lb[k]
                            eb = e_rb[k] if part == 0 else e_rt[k]
                            ec = e_rt[k] if part == 0 else e_lt[k]
                            if ea <= 0.0 and eb <= 0.0 and ec <= 0.0:
                                outside = True
                                break
                            if ea < 0.0 or eb < 0.0 or ec < 0.0:
                                ncut += 1
                                kcut = k
                        if outside:
                            continue
                        db = d_rb if part == 0 else d_rt
                        dc = d_rt if part == 0 else d_lt
                        if ncut == 0:
                            pv = abs_integral_tri(half, d_lb, db, dc)
                            pa = half
                        elif ncut == 1:
                            ea = e_lb[kcut]
                            eb = e_rb[kcut] if part == 0 else e_rt[kcut]
                            ec = e_rt[kcut] if part == 0 else e_lt[kcut]
                            pv, pa = inside_one_edge(half, d_lb, db, dc, ea, eb, ec)
                        else:
                            # cell-local coordinates: corners at 0 or w, 0 or h
                            _load_corner(buf, 0, 0.0, 0.0, d_lb, e_lb[0], e_lb[1], e_lb[2])
                            if part == 0:
                                _load_corner(buf, 1, w, 0.0, d_rb, e_rb[0], e_rb[1], e_rb[2])
                                _load_corner(buf, 2, w, h, d_rt, e_rt[0], e_rt[1], e_rt[2])
                            else:
                                _load_corner(buf, 1, w, h, d_rt, e_rt[0], e_rt[1], e_rt[2])
                                _load_corner(buf, 2, 0.0, h, d_lt, e_lt[0], e_lt[1], e_lt[2])
                            pv, pa = _clip_integrate(buf)
                        tvol, tvol_c = _neumaier(tvol, tvol_c, pv)
                        tcov, tcov_c = _neumaier(tcov, tcov_c, pa)
                for k in range(3):
                    e_lb[k] = e_rb[k]
                    e_lt[k] = e_rt[k]
                d_lb = d_rb
                d_lt = d_rt
                x0 = x1
        vol, vol_c = _neumaier(vol, vol_c, tvol)
        vol, vol_c = _neumaier(vol, vol_c, tvol_c)
        cov, cov_c = _neumaier(cov, cov_c, tcov)
        cov, cov_c = _neumaier(cov, cov_c, tcov_c)
    return vol, vol_c, cov, cov_c


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _volume_chunk(grid, mesh, nchunks, ch, buf, out, stop):
    """Row ``ch`` of ``out``: the compensated sums of chunk ``ch`` of ``nchunks`` equal runs
    of ``order`` (``buf`` the clipping scratch of the calling thread; ``grid`` and ``mesh``
    as :func:`volume_between` takes them)."""
    xs, ys, z = grid
    vx, vy, vz, faces, order = mesh
    nf = faces.shape[0]
    f0 = ch * nf // nchunks
    f1 = (ch + 1) * nf // nchunks
    v, vc, a, ac = volume_faces(xs, ys, z, vx, vy, vz, faces, order, f0, f1, buf, stop)
    out[ch, VOL] = v
    out[ch, VOL_C] = vc
    out[ch, AREA] = a
    out[ch, AREA_C] = ac


@nb.njit(cache=True, nogil=True)
def volume_between(grid, mesh, nchunks, out, c0, c1, stop):
    """:func:`volume_faces` over chunks ``c0 .. c1 - 1`` of ``nchunks`` equal runs of ``order``
    (:func:`terrainvis.core.interrupt.call` spreads the chunks over threads).

    ``grid`` is the fine surface ``(xs, ys, z)`` and ``mesh`` the coarse one ``(vx, vy, vz,
    faces, order)``, as :func:`volume_faces` takes them. ``out`` is (nchunks, N_OUT): row
    ch receives the compensated sums of chunk ch. The chunks depend only on ``nchunks``,
    so the result does not depend on the thread count. Every chunk reads the stop flag
    ``stop`` before each face (:mod:`terrainvis.core.interrupt`).
    """
    buf = np.empty((2, MAX_POLY, N_PCOL))
    for ch in range(c0, c1):
        _volume_chunk(grid, mesh, nchunks, ch, buf, out, stop)


@nb.njit(cache=True, nogil=True)
def faces_by_row(vy, faces, ys):
    """(m,) int64: the faces ordered by the fine grid row of their lowest vertex (a counting sort).

    Consecutive faces then read the same rows of the fine heights, and a run of faces is
    a strip of the footprint, so equal runs make balanced chunks.
    """
    nr = ys.shape[0]
    m = faces.shape[0]
    inv_dy = (nr - 1) / (ys[nr - 1] - ys[0])
    row = np.empty(m, dtype=np.int64)
    start = np.zeros(nr, dtype=np.int64)
    for f in range(m):
        ymin = min(vy[faces[f, 0]], vy[faces[f, 1]], vy[faces[f, 2]])
        r = _cell_at_or_below(ys, ymin, inv_dy)
        row[f] = r
        start[r + 1] += 1
    for r in range(nr - 1):
        start[r + 1] += start[r]
    order = np.empty(m, dtype=np.int64)
    for f in range(m):
        order[start[row[f]]] = f
        start[row[f]] += 1
    return order


@nb.njit(cache=True, nogil=True)
def face_areas(vx, vy, faces):
    """Projected areas of the faces: (compensated total, number of clockwise faces, first clockwise face or -1)."""
    s = 0.0
    sc = 0.0
    n_cw = 0
    first_cw = -1
    for f in range(faces.shape[0]):
        i0 = faces[f, 0]
        i1 = faces[f, 1]
        i2 = faces[f, 2]
        a = 0.5 * ((vx[i1] - vx[i0]) * (vy[i2] - vy[i0]) - (vx[i2] - vx[i0]) * (vy[i1] - vy[i0]))
        if a < 0.0:
            n_cw += 1
            if first_cw < 0:
                first_cw = f
        s, sc = _neumaier(s, sc, a)
    return s + sc, n_cw, first_cw
