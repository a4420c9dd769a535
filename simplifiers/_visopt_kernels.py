"""Numba loops of the visibility-optimized regular simplifier (:mod:`simplifiers.visopt`).

Kernels loop and never validate; :mod:`simplifiers.visopt` checks the input, moves
coordinates to the coarse grid's local origin and passes plain arrays.

The coarse surface S is the grid's triangulated surface (cell (r, c) split along its
diagonal from (r, c) to (r + 1, c + 1), as :func:`terrainvis.core.surface.plane_uv`
does). Its height anywhere is a weighted sum of three coarse heights, so every quantity
below is linear in each coarse height.

Breakpoints
-----------
The sight line of a training pair (i, j) is tested over the parameter interval
``[u0, u1]`` of the LOS engines (:func:`terrainvis.visibility.thresholds.interval`: the
trim). Inside one triangle the clearance is linear in the parameter, so the pair sees
exactly when the clearance is >= ``-tol`` at every *breakpoint*: the ends of the
interval, every crossing of a grid line and of a cell diagonal. Each breakpoint is
stored once, as its parameter ``u``, its triangle (``2 * (r * ncx + c) + side``, side 1
for the triangle above the diagonal) and its local coordinates ``(a, b)`` in the cell,
from which the three vertices and weights are recomputed (:func:`_corners`).

Coordinate descent
------------------
The points ride on the surface: point i stands ``d[i]`` above S at its position, so
its height is ``d[i] + sum_t ew[i, t] c[ev[i, t]]``. With every coarse height but
``c[v]`` fixed, the clearance of pair k at each breakpoint is ``cst + alpha c[v]`` and
the pair sees exactly when ``c[v]`` lies in a closed interval ``[lo, hi]`` (empty when
lo > hi). :func:`best_value` maximises the number of pairs whose verdict on S equals
their verdict on T over ``c[v]`` exactly, by sorting the interval ends.
"""

from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from terrainvis.visibility.thresholds import interval
from terrainvis.visibility.walk import cell_diagonal, cells_next, cells_start
from terrainvis.core.compiling import KERNEL_ONLY
from terrainvis.core.stopflag import stopped
from terrainvis.core.surface import borrow, locate
from terrainvis.tolerances import VERTEX_WEIGHT_ZERO

_INF = np.inf
#: Below this magnitude a breakpoint's coefficient of the vertex height counts as zero.
_ALPHA_EPS = VERTEX_WEIGHT_ZERO

#: The kept training pairs (i = ``ii[k]``, j = ``jj[k]``) on a coarse grid of ``ncx``
#: columns of cells: pair k's breakpoints are ``ptr[k]:ptr[k + 1]`` of ``bu`` (parameter),
#: ``btri`` (triangle), ``ba``, ``bb`` (local coordinates) (see "Breakpoints"), and
#: ``items[vptr[v]:vptr[v + 1]]`` are the pairs touching coarse vertex v (:func:`incidence`).
Tracks = namedtuple("Tracks", ["ncx", "ii", "jj", "ptr", "bu", "btri", "ba", "bb", "vptr", "items"])
#: The points riding on the surface (see "Coordinate descent"): ``d`` (n,) their heights
#: above it, ``ev`` (n, 3) int64 and ``ew`` (n, 3) the vertices and weights under them.
Riders = namedtuple("Riders", ["d", "ev", "ew"])


@nb.njit(cache=True, nogil=True, inline="always")
def _local(xs, ys, r, c, x, y):
    """Local coordinates (a, b) of (x, y) in cell (r, c), clamped to [0, 1]."""
    a = (x - xs[c]) / (xs[c + 1] - xs[c])
    b = (y - ys[r]) / (ys[r + 1] - ys[r])
    a = min(max(a, 0.0), 1.0)
    b = min(max(b, 0.0), 1.0)
    return a, b


@nb.njit(cache=True, nogil=True, inline="always")
def _corners(tri, a, b, ncx, vv, ww):
    """Vertices (flat indices of the coarse z, ``ncx + 1`` columns) and weights of triangle
    ``tri`` at local coordinates (a, b)."""
    cell = tri >> 1
    r = cell // ncx
    c = cell - r * ncx
    ncol = ncx + 1
    i00 = r * ncol + c
    vv[0] = i00
    vv[2] = i00 + ncol + 1
    if (tri & 1) == 0:  # a >= b: below the diagonal
        vv[1] = i00 + 1
        ww[0] = 1.0 - a
        ww[1] = a - b
        ww[2] = b
    else:
        vv[1] = i00 + ncol
        ww[0] = 1.0 - b
        ww[1] = b - a
        ww[2] = a


@nb.njit(cache=True, nogil=True, inline="always")
def _put(xs, ys, ncx, r, c, x, y, u, n, record, out):
    """Breakpoint ``n`` at (x, y), parameter u, in cell (r, c), written into ``out = (bu,
    btri, ba, bb)`` when ``record``: its parameter, triangle and local coordinates."""
    if record:
        bu, btri, ba, bb = out
        a, b = _local(xs, ys, r, c, x, y)
        bu[n] = u
        btri[n] = 2 * (r * ncx + c) + (0 if a >= b else 1)
        ba[n] = a
        bb[n] = b


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _track(axes, ax, ay, bx, by, u0, u1, start, record, out):
    """Breakpoints of the ground track a -> b over [u0, u1] on the grid ``axes = (xs, ys,
    ixw, iyw)`` (:func:`terrainvis.visibility.walk.cells_start`: the walk every LOS engine
    takes), written from ``start`` into ``out = (bu, btri, ba, bb)`` when ``record``;
    returns their count."""
    xs, ys, ixw, iyw = axes
    dx = bx - ax
    dy = by - ay
    track = (ax, ay, dx, dy)
    ncx = xs.shape[0] - 1
    cur = cells_start(xs, ys, ixw, iyw, False, track, u0, u1)
    n = start
    _put(xs, ys, ncx, cur.r, cur.c, ax + u0 * dx, ay + u0 * dy, u0, n, record, out)
    n += 1
    while True:
        r, c, u, ue = cur.r, cur.c, cur.t, cur.tn
        td = cell_diagonal(xs, ys, ixw, iyw, r, c, track)
        if td > u and td < ue:
            _put(xs, ys, ncx, r, c, ax + td * dx, ay + td * dy, td, n, record, out)
            n += 1
        _put(xs, ys, ncx, r, c, ax + ue * dx, ay + ue * dy, ue, n, record, out)
        n += 1
        if ue >= u1:
            break
        cur = cells_next(xs, ys, cur, track, u1)
        if cur.r < 0:
            break
    return n - start


#: Pairs per iteration of the pair loops (:func:`track_counts`, :func:`track_fill`,
#: :func:`pair_visible`), which :func:`terrainvis.core.interrupt.call` spreads over threads.
PAIR_CHUNK = 256


def pair_chunks(n_pairs: int) -> int:
    """The iterations of the pair loops: chunks of :data:`PAIR_CHUNK` pairs."""
    return (n_pairs + PAIR_CHUNK - 1) // PAIR_CHUNK


@nb.njit(cache=True, nogil=True)
def track_counts(axes, p, ii, jj, delta, counts, k0, k1, stop):
    """Breakpoints of each pair (ii[k], jj[k]) of the points p (x, y, z) (0: never tested)
    on the grid ``axes = (xs, ys, ixw, iyw)``, for the pairs of chunks ``k0 .. k1 - 1``."""
    m = ii.shape[0]
    du = np.empty(0, np.float32)
    dt = np.empty(0, np.int32)
    for k in range(k0 * PAIR_CHUNK, min(m, k1 * PAIR_CHUNK)):
        if k % PAIR_CHUNK == 0 and stopped(stop):
            return
        i = ii[k]
        j = jj[k]
        u0, u1 = interval(p[j, 0], p[j, 1], p[j, 2], p[i, 0], p[i, 1], p[i, 2], delta, 0.0)
        if u0 < 0.0:
            counts[k] = 0
        else:
            counts[k] = _track(axes, p[i, 0], p[i, 1], p[j, 0], p[j, 1], u0, u1, 0, False, (du, dt, du, du))


@nb.njit(cache=True, nogil=True)
def track_fill(axes, p, ii, jj, delta, ptr, out, k0, k1, stop):
    """Write the breakpoints of each pair of chunks ``k0 .. k1 - 1`` into ``out = (bu, btri,
    ba, bb)`` from ``ptr[k]`` (counts from :func:`track_counts`)."""
    m = ii.shape[0]
    for k in range(k0 * PAIR_CHUNK, min(m, k1 * PAIR_CHUNK)):
        if k % PAIR_CHUNK == 0 and stopped(stop):
            return
        if ptr[k + 1] == ptr[k]:
            continue
        i = ii[k]
        j = jj[k]
        u0, u1 = interval(p[j, 0], p[j, 1], p[j, 2], p[i, 0], p[i, 1], p[i, 2], delta, 0.0)
        _track(axes, p[i, 0], p[i, 1], p[j, 0], p[j, 1], u0, u1, ptr[k], True, out)


@nb.njit(cache=True, nogil=True)
def incidence(nv, ncx, ptr, btri, ba, bb, stop):
    """CSR (vptr, items): for each coarse vertex, the pairs with a breakpoint where its weight is positive."""
    npair = ptr.shape[0] - 1
    mark = np.full(nv, -1, np.int64)
    deg = np.zeros(nv + 1, np.int64)
    vv = np.empty(3, np.int64)
    ww = np.empty(3)
    for k in range(npair):
        if (k & 4095) == 0 and stopped(stop):
            return deg, np.empty(0, np.int32)
        for s in range(ptr[k], ptr[k + 1]):
            _corners(btri[s], ba[s], bb[s], ncx, vv, ww)
            for t in range(3):
                if ww[t] > 0.0 and mark[vv[t]] != k:
                    mark[vv[t]] = k
                    deg[vv[t] + 1] += 1
    vptr = np.cumsum(deg)
    items = np.empty(vptr[-1], np.int32)
    pos = vptr[:-1].copy()
    mark[:] = -1
    for k in range(npair):
        for s in range(ptr[k], ptr[k + 1]):
            _corners(btri[s], ba[s], bb[s], ncx, vv, ww)
            for t in range(3):
                if ww[t] > 0.0 and mark[vv[t]] != k:
                    mark[vv[t]] = k
                    items[pos[vv[t]]] = k
                    pos[vv[t]] += 1
    return vptr, items


@nb.njit(cache=True, nogil=True)
def barycentric(xs, ys, px, py, ev, ew):
    """Vertices and weights of the coarse surface under each position (px[i], py[i])."""
    ncx = xs.shape[0] - 1
    for i in range(px.shape[0]):
        c = locate(xs, xs, 0, xs.shape[0] - 1, False, px[i])
        r = locate(ys, ys, 0, ys.shape[0] - 1, False, py[i])
        a, b = _local(xs, ys, r, c, px[i], py[i])
        tri = 2 * (r * ncx + c) + (0 if a >= b else 1)
        v3 = np.empty(3, np.int64)
        w3 = np.empty(3)
        _corners(tri, a, b, ncx, v3, w3)
        for t in range(3):
            ev[i, t] = v3[t]
            ew[i, t] = w3[t]


@nb.njit(cache=True, nogil=True)
def pair_visible(c, z, tk, tol, out, k0, k1, stop):
    """Verdict on the coarse surface ``c`` of each pair of chunks ``k0 .. k1 - 1`` of the
    :data:`Tracks` ``tk``, the points at heights ``z``."""
    ncx, ii, jj, ptr, bu, btri, ba, bb = tk.ncx, tk.ii, tk.jj, tk.ptr, tk.bu, tk.btri, tk.ba, tk.bb
    vv = np.empty(3, np.int64)
    ww = np.empty(3)
    for k in range(k0 * PAIR_CHUNK, min(ii.shape[0], k1 * PAIR_CHUNK)):
        if k % PAIR_CHUNK == 0 and stopped(stop):
            return
        zi = z[ii[k]]
        zj = z[jj[k]]
        ok = True
        for s in range(ptr[k], ptr[k + 1]):
            _corners(btri[s], ba[s], bb[s], ncx, vv, ww)
            h = ww[0] * c[vv[0]] + ww[1] * c[vv[1]] + ww[2] * c[vv[2]]
            if zi + bu[s] * (zj - zi) - h < -tol:
                ok = False
                break
        out[k] = ok


@nb.njit(cache=True, nogil=True, inline="always")
def _weight_of(v, ev, ew, i):
    s = 0.0
    for t in range(3):
        if ev[i, t] == v:
            s += ew[i, t]
    return s


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def vertex_intervals(v, c, rd, tk, tol, lo, hi):
    """For each pair of the :data:`Tracks` ``tk`` touching vertex v (``items[vptr[v]:vptr[v + 1]]``):
    the closed interval [lo, hi] of ``c[v]`` in which it sees (lo > hi: it never does), the
    points riding on the surface (:data:`Riders` ``rd``)."""
    d, ev, ew = rd.d, rd.ev, rd.ew
    ncx, ii, jj, ptr, bu, btri, ba, bb, vptr, items = tk
    vv = np.empty(3, np.int64)
    ww = np.empty(3)
    m = 0
    for s in range(vptr[v], vptr[v + 1]):
        k = items[s]
        i = ii[k]
        j = jj[k]
        zi = d[i]
        zj = d[j]
        for t in range(3):
            if ev[i, t] != v:
                zi += ew[i, t] * c[ev[i, t]]
            if ev[j, t] != v:
                zj += ew[j, t] * c[ev[j, t]]
        wi = _weight_of(v, ev, ew, i)
        wj = _weight_of(v, ev, ew, j)
        low = -_INF
        high = _INF
        for b in range(ptr[k], ptr[k + 1]):
            u = bu[b]
            _corners(btri[b], ba[b], bb[b], ncx, vv, ww)
            cst = zi + u * (zj - zi) + tol
            alpha = wi + u * (wj - wi)
            for t in range(3):
                if vv[t] == v:
                    alpha -= ww[t]
                else:
                    cst -= ww[t] * c[vv[t]]
            # visible at this breakpoint iff cst + alpha * c[v] >= 0
            if alpha > _ALPHA_EPS:
                t_ = -cst / alpha
                if t_ > low:
                    low = t_
            elif alpha < -_ALPHA_EPS:
                t_ = -cst / alpha
                if t_ < high:
                    high = t_
            elif cst < 0.0:
                low = _INF
                high = -_INF
                break
            if low > high:
                break
        lo[m] = low
        hi[m] = high
        m += 1
    return m


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def best_value(lo, hi, vis, m, cur, bmin, bmax, margin, pos, dl):
    """The value of one coarse height maximising ``#{k: (lo[k] <= x <= hi[k]) == vis[k]}``
    over x in [bmin, bmax], and that count.

    The height stays at ``cur`` unless some x agrees with strictly more pairs than ``cur``
    does; among the optimal x the one nearest ``cur`` is taken, ``margin`` away from the
    interval ends that bound it (its middle when narrower), so that the counted verdicts
    are the ones a LOS engine gives there.
    """
    base = 0.0
    at_cur = 0.0
    ne = 0
    for k in range(m):
        inside = lo[k] <= cur <= hi[k]
        if inside == vis[k]:
            at_cur += 1.0
        if not vis[k]:
            base += 1.0
        if lo[k] > hi[k]:
            continue
        sgn = 1.0 if vis[k] else -1.0
        if lo[k] == -_INF:
            base += sgn
        else:
            pos[ne] = lo[k]
            dl[ne] = sgn
            ne += 1
        if hi[k] < _INF:
            pos[ne] = hi[k]
            dl[ne] = -sgn
            ne += 1
    order = np.argsort(pos[:ne])
    best = -1.0
    best_x = cur
    best_d = _INF
    score = base
    left = -_INF
    t = 0
    while True:
        right = pos[order[t]] if t < ne else _INF
        # the open interval (left, right) has the score ``score``
        if right > left and score >= best:
            a = max(left, bmin)
            b = min(right, bmax)
            if a < b or (a == b and left < a < right):
                lo_x = a + margin if a == left else a
                hi_x = b - margin if b == right else b
                if lo_x > hi_x:
                    lo_x = 0.5 * (a + b)
                    hi_x = lo_x
                x = min(max(cur, lo_x), hi_x)
                dist = abs(x - cur)
                if score > best or dist < best_d:
                    best = score
                    best_x = x
                    best_d = dist
        if t >= ne:
            break
        p0 = pos[order[t]]
        while t < ne and pos[order[t]] == p0:
            score += dl[order[t]]
            t += 1
        left = p0
    if best > at_cur:
        return best_x, best
    return cur, at_cur


@nb.njit(cache=True, nogil=True)
def c_sweep(c, cref, rad, rd, vt, tk, tol, margin, order, stop):
    """One sweep of exact coordinate descent over the coarse heights in ``order`` (in place);
    vertex v moves within ``cref[v] +- rad[v]``; the pairs (:data:`Tracks` ``tk``, verdicts
    on T ``vt``) of the points riding on the surface (:data:`Riders` ``rd``). Returns the
    count of heights changed."""
    # views without reference counts for the per-vertex calls (the caller keeps the arrays alive)
    rd = Riders(borrow(rd.d), borrow(rd.ev), borrow(rd.ew))
    tk = Tracks(tk.ncx, borrow(tk.ii), borrow(tk.jj), borrow(tk.ptr), borrow(tk.bu), borrow(tk.btri), borrow(tk.ba),
                borrow(tk.bb), borrow(tk.vptr), borrow(tk.items))
    vptr, items = tk.vptr, tk.items
    mx = 0
    for v in range(vptr.shape[0] - 1):
        mx = max(mx, vptr[v + 1] - vptr[v])
    lo = np.empty(mx)
    hi = np.empty(mx)
    vis = np.empty(mx, np.bool_)
    pos = np.empty(2 * mx)
    dl = np.empty(2 * mx)
    changed = 0
    for v in order:
        if stopped(stop):
            return changed
        if rad[v] <= 0.0 or vptr[v + 1] == vptr[v]:
            continue
        m = vertex_intervals(v, c, rd, tk, tol, lo, hi)
        for s in range(m):
            vis[s] = vt[items[vptr[v] + s]]
        x, _ = best_value(lo, hi, vis, m, c[v], cref[v] - rad[v], cref[v] + rad[v], margin, pos, dl)
        if x != c[v]:
            c[v] = x
            changed += 1
    return changed


@nb.njit(cache=True, nogil=True)
def local_radius(zf, xf, yf, c, xs, ys, out, stop):
    """out[v] = max |T - S| over the fine samples (zf at xf, yf) where vertex v's weight is positive."""
    ncx = xs.shape[0] - 1
    vv = np.empty(3, np.int64)
    ww = np.empty(3)
    out[:] = 0.0
    for r_ in range(yf.shape[0]):
        if stopped(stop):
            return
        r = locate(ys, ys, 0, ys.shape[0] - 1, False, yf[r_])
        for c_ in range(xf.shape[0]):
            cc = locate(xs, xs, 0, xs.shape[0] - 1, False, xf[c_])
            a, b = _local(xs, ys, r, cc, xf[c_], yf[r_])
            tri = 2 * (r * ncx + cc) + (0 if a >= b else 1)
            _corners(tri, a, b, ncx, vv, ww)
            h = ww[0] * c[vv[0]] + ww[1] * c[vv[1]] + ww[2] * c[vv[2]]
            e = abs(zf[r_, c_] - h)
            for t in range(3):
                if ww[t] > 0.0 and e > out[vv[t]]:
                    out[vv[t]] = e
