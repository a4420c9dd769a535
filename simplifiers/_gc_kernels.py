"""Numba loops for greedy cuts (Silva, Mitchell & Kaufman 1995): the advancing front.

Kernels loop and never validate; :mod:`simplifiers.greedy_cuts` checks the input.

Geometry works in a *plane space* ``(gx[c], gy[r])``: for a uniform grid the wrapper passes
the column and row indices themselves (an affine image of the world coordinates with a
positive determinant, so orientation signs, barycentric coordinates and "which samples lie
in a triangle" are the same as in world coordinates, and every orientation test is exact
integer arithmetic in float64); for a rectilinear grid whose coordinates are whole
multiples of one unit per axis, those whole numbers (the same, exact); for any other
rectilinear grid the world coordinates shifted to a local origin, where orientation tests
round (``simplifiers.greedy_cuts._plane_coords``).

Data structures
---------------
* ``occ`` (rows, cols) int8: ``FREE`` (strictly inside the untriangulated region and not a
  vertex), ``COVERED`` (in a finished triangle or on the interior of a front edge) or
  ``VERTEX``. A bite may only reach a FREE sample; a COVERED one would overlap the
  finished region or make a T-junction.
* ``nodes`` (n, 6) int64, one row per front node, columns ``VERT`` (its sample), ``NXT``
  and ``PRV`` (the doubly linked loop), ``ALIVE``, ``VER`` (how often its edge changed)
  and ``STAMP`` (the last query that met it). The front is a set of closed
  counter-clockwise loops; one vertex may own several nodes when the front touches
  itself. The free region lies to the left of every front edge ``VERT[n] ->
  VERT[NXT[n]]``.
* A bucket grid (``BS`` x ``BS`` samples per bucket): ``bhead[b]`` starts a linked list
  in ``pool`` (n, 3) int64 (columns ``P_NODE``, ``P_NEXT``, ``P_VER``) of the nodes
  whose edge's bounding box overlaps bucket b. An entry records the edge version it was
  made for; an entry whose node died or whose edge changed since is unlinked when a
  query meets it, and its row goes to a free list for reuse.
* A FIFO queue of ``(node, version)``: every edge made or changed is pushed once; an entry
  whose version no longer matches is skipped.
* ``scr`` (``N_SCR``,) int64: the pool's used rows and free list (``S_USED``,
  ``S_FREE``), the query counter for the stamps (``S_QID``) and two outputs of an
  evaluation (``S_BLOCKER``, ``S_APEX_NODE``).

Counters
--------
``counts`` (``N_COUNTS``,) int64, read through the named indices: ``N_EARS`` (triangles
adding no vertex: ears and connections to the front), ``N_BITES`` (triangles adding a
vertex, fallback insertions included), ``N_SPLITS`` (fallback insertions), ``STATUS``
(``DONE``; ``STUCK``: an edge found no valid triangle; ``STEP_LIMIT``; ``OVER_BUDGET``:
stopped early because the vertex count passed ``max_vertices``; ``INTERRUPTED``: the stop
flag was set, see :mod:`terrainvis.core.interrupt`), ``N_EVAL_EAR``,
``N_EVAL_BITE``, ``N_EVAL_SPLIT`` (triangles evaluated by each step), ``N_CANDIDATES``
(fallback candidates gathered), ``N_VERTICES`` (vertices so far: the initial front's
plus one per bite) and ``N_COVERED`` (samples no longer free: in a finished triangle or
on the front).

Speed
-----
The helpers called in the inner loops allocate nothing and are compiled without the
Numba runtime (``_nrt=False``): a function that takes arrays otherwise increments and
decrements an atomic reference count per array on every call, which took half of the
run time. Only :func:`greedy_cuts_front` and the rarely called growth helpers allocate.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numba as nb
import numpy as np

from terrainvis.core.compiling import KERNEL_ONLY
from terrainvis.core.stopflag import stopped
from terrainvis.tolerances import ROW_SPAN_SNAP  # frozen into the kernels when they compile

from ._shared_kernels import heap_pop, heapify, orient, smaller_then_item

FREE = 0
COVERED = 1
VERTEX = 2

BS = 8  # bucket side in samples

# evaluation results
OK = 0
ERR = 1
GEO = 2
BAD = 3

# columns of ``nodes``
VERT, NXT, PRV, ALIVE, VER, STAMP = range(6)
# columns of ``pool``
P_NODE, P_NEXT, P_VER = range(3)
# scalar state (indices into ``scr``)
S_USED, S_FREE, S_QID, S_BLOCKER, S_APEX_NODE = range(5)
N_SCR = 5

# counters (indices into ``counts``)
(N_EARS, N_BITES, N_SPLITS, STATUS, N_EVAL_EAR, N_EVAL_BITE, N_EVAL_SPLIT, N_CANDIDATES, N_VERTICES,
 N_COVERED) = range(10)
N_COUNTS = 10

# values of counts[STATUS]
DONE = 0
STUCK = 1
STEP_LIMIT = 2
OVER_BUDGET = 3
INTERRUPTED = 4

_HOT = {"cache": True, "nogil": True, "_nrt": False}  # helpers that allocate nothing

#: The samples as the three steps read them: ``occ``, the flat heights ``zf``, ``eps``, the
#: plane-space coordinates ``gx``, ``gy``, ``index_space`` and ``cols`` (see "Data structures").
Samples = namedtuple("Samples", ["occ", "zf", "eps", "gx", "gy", "index_space", "cols"])
#: The front as the three steps read it: ``nodes``, the bucket lists ``pool``, ``bhead``
#: (``nbx`` buckets a row) and ``scr`` (see "Data structures").
Front = namedtuple("Front", ["nodes", "pool", "bhead", "nbx", "scr"])

#: 0 as an int64 (not a literal): numba compiles a callee again for every literal argument.
_ZERO = np.int64(0)


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _grow(arr, n):
    """``arr`` itself when it has a row ``n``, else a copy with twice the rows.

    The copy loops over the flat data (both arrays are C-contiguous with the same rows,
    so ``arr``'s data is the start of ``new``'s): a slice assignment would compile
    numba's shape-mismatch message (string formatting), about 2 s per cold start.
    """
    if n < arr.shape[0]:
        return arr
    shape = (max(2 * arr.shape[0], n + 1),) + arr.shape[1:]
    new = np.empty(shape, dtype=arr.dtype)
    src = arr.ravel()
    dst = new.ravel()
    for i in range(src.shape[0]):
        dst[i] = src[i]
    return new


@nb.njit(**_HOT, **KERNEL_ONLY)
def _edge_value(u, w, s, gx, gy, zf, cols):
    """Height at sample ``s`` of the segment u-w, computed the same way from either side."""
    p = min(u, w)
    q = max(u, w)
    xp = gx[p % cols]
    yp = gy[p // cols]
    xq = gx[q % cols]
    yq = gy[q // cols]
    if abs(xq - xp) >= abs(yq - yp):
        t = (gx[s % cols] - xp) / (xq - xp)
    else:
        t = (gy[s // cols] - yp) / (yq - yp)
    return zf[p] + t * (zf[q] - zf[p])


@nb.njit(cache=True, nogil=True)
def boundary_chain(ids, gx, gy, zf, cols, eps):
    """Greedy longest eps-valid segments along one side of the grid.

    Parameters
    ----------
    ids : (m,) int64
        Linear sample indices along the side, in order (m >= 2).
    gx, gy : (cols,), (rows,) float64
        Plane-space coordinates.
    zf : (rows * cols,) float64
        The heights, row-major.
    cols : int
    eps : (rows * cols,) float64
        Allowed vertical error at each sample.

    Returns
    -------
    (k,) int64
        The kept samples (first and last included): from each kept sample the segment
        reaches the farthest sample such that every sample between them lies within
        ``eps`` of the segment (tested with the same edge interpolation as the triangles).
    """
    m = ids.shape[0]
    keep = np.empty(m, dtype=np.int64)
    k = 0
    i = 0
    keep[k] = ids[0]
    k += 1
    while i < m - 1:
        best = i + 1
        j = i + 2
        while j < m:
            good = True
            for t in range(i + 1, j):
                zt = _edge_value(ids[i], ids[j], ids[t], gx, gy, zf, cols)
                if abs(zt - zf[ids[t]]) > eps[ids[t]]:
                    good = False
                    break
            if not good:
                break
            best = j
            j += 1
        keep[k] = ids[best]
        k += 1
        i = best
    return keep[:k].copy()


@nb.njit(**_HOT, **KERNEL_ONLY)
def _chain_segments(z, line, along_rows, coord, eps):
    """Segments of the greedy longest eps-valid chain along one row (or column) of z.

    The same greedy rule as :func:`boundary_chain`, in O(length): the slopes from the
    chain's last vertex that keep every sample so far within ``eps`` form an interval,
    narrowed sample by sample, and the chain ends where the next sample leaves it.
    """
    m = coord.shape[0]
    count = 0
    i = 0
    while i < m - 1:
        zi = z[line, i] if along_rows else z[i, line]
        smin = -np.inf
        smax = np.inf
        j = i + 1
        while j < m:
            zj = z[line, j] if along_rows else z[j, line]
            d = coord[j] - coord[i]
            s = (zj - zi) / d
            if s < smin or s > smax:
                break
            smin = max(smin, (zj - eps - zi) / d)
            smax = min(smax, (zj + eps - zi) / d)
            j += 1
        i = j - 1
        count += 1
    return count


@nb.njit(cache=True, nogil=True)
def line_segments(z, gx, gy, rows, cols, eps):
    """Total segments of the greedy 1-D eps-chains along the given rows and columns of z.

    Parameters
    ----------
    z : (R, C) float64
    gx, gy : (C,), (R,) float64
        Plane-space coordinates of the columns and rows.
    rows, cols : (p,), (q,) int64
        The rows and the columns to follow.
    eps : float
        Allowed vertical error.

    Returns
    -------
    (int, int)
        Segments along the rows, and along the columns. Divided by the lengths walked
        they are 1-D vertex densities: the estimate of the triangulation's density that
        :mod:`simplifiers.greedy_cuts` starts its search on ε from.
    """
    along_r = 0
    for k in range(rows.shape[0]):
        along_r += _chain_segments(z, rows[k], True, gx, eps)
    along_c = 0
    for k in range(cols.shape[0]):
        along_c += _chain_segments(z, cols[k], False, gy, eps)
    return along_r, along_c


# ----------------------------------------------------------------- scan conversion
@nb.njit(**_HOT, **KERNEL_ONLY)
def _row_range(y, xa, ya, xb, yb, xc, yc):
    """x-interval of triangle abc on the horizontal line at y (lo > hi when empty)."""
    lo = np.inf
    hi = -np.inf
    for k in range(3):
        if k == 0:
            x0, y0, x1, y1 = xa, ya, xb, yb
        elif k == 1:
            x0, y0, x1, y1 = xb, yb, xc, yc
        else:
            x0, y0, x1, y1 = xc, yc, xa, ya
        if y < min(y0, y1) or y > max(y0, y1):
            continue
        if y0 == y1:
            lo = min(lo, x0, x1)
            hi = max(hi, x0, x1)
        else:
            x = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
            lo = min(lo, x)
            hi = max(hi, x)
    return lo, hi


@nb.njit(**_HOT, **KERNEL_ONLY)
def _first_at_least(gx, v, lo, hi):
    """The first index i in [lo, hi] with gx[i] >= v (hi + 1 when none); gx increasing."""
    hi += 1
    while lo < hi:
        mid = (lo + hi) // 2
        if gx[mid] < v:
            lo = mid + 1
        else:
            hi = mid
    return lo


@nb.njit(**_HOT, **KERNEL_ONLY)
def _scan(ia, ib, ic, gx, gy, index_space, zf, cols, eps, occ, mark):
    """Scan-convert triangle (ia, ib, ic) (counter-clockwise) over the samples.

    With ``mark`` False: 0 when every sample s in the closed triangle lies within
    ``eps[s]`` of it (samples on an edge are measured against that edge, the same way
    from either side; the others against the plane), -1 at the first that does not.
    With ``mark`` True: set every FREE sample of the closed triangle to COVERED and
    return how many there were. A row's candidate columns come from its x-interval,
    widened by a rounding margin (index space) or by one column (world space); exact
    orientation tests then decide.
    """
    ca = ia % cols
    ra = ia // cols
    cb = ib % cols
    rb = ib // cols
    cc = ic % cols
    rc = ic // cols
    xa = gx[ca]
    ya = gy[ra]
    xb = gx[cb]
    yb = gy[rb]
    xc = gx[cc]
    yc = gy[rc]
    za = zf[ia]
    zb = zf[ib]
    zc = zf[ic]
    area2 = orient(xa, ya, xb, yb, xc, yc)
    cmin = min(ca, cb, cc)
    cmax = max(ca, cb, cc)
    newly = 0
    for r in range(min(ra, rb, rc), max(ra, rb, rc) + 1):
        y = gy[r]
        lo, hi = _row_range(y, xa, ya, xb, yb, xc, yc)
        if lo > hi:
            continue
        if index_space:
            c0 = max(cmin, int(math.ceil(lo - ROW_SPAN_SNAP)))
            c1 = min(cmax, int(math.floor(hi + ROW_SPAN_SNAP)))
        else:
            c0 = max(cmin, _first_at_least(gx, lo, cmin, cmax) - 1)
            c1 = min(cmax, _first_at_least(gx, hi, cmin, cmax))
        for c in range(c0, c1 + 1):
            x = gx[c]
            o1 = orient(xa, ya, xb, yb, x, y)  # edge ab
            if o1 < 0.0:
                continue
            o2 = orient(xb, yb, xc, yc, x, y)  # edge bc
            if o2 < 0.0:
                continue
            o3 = orient(xc, yc, xa, ya, x, y)  # edge ca
            if o3 < 0.0:
                continue
            s = r * cols + c
            if mark:
                if occ[r, c] == FREE:
                    occ[r, c] = COVERED
                    newly += 1
                continue
            if s == ia or s == ib or s == ic:
                continue
            if o1 == 0.0:
                zt = _edge_value(ia, ib, s, gx, gy, zf, cols)
            elif o2 == 0.0:
                zt = _edge_value(ib, ic, s, gx, gy, zf, cols)
            elif o3 == 0.0:
                zt = _edge_value(ic, ia, s, gx, gy, zf, cols)
            else:
                zt = (o2 * za + o3 * zb + o1 * zc) / area2
            if abs(zt - zf[s]) > eps[s]:
                return -1
    return newly


# ----------------------------------------------------------------- front queries
@nb.njit(**_HOT, **KERNEL_ONLY)
def _cone_contains(e, wx, wy, nodes, gx, gy, cols):
    """True when direction (wx, wy) lies strictly inside the free angle at node e."""
    v = nodes[e, VERT]
    q = nodes[nodes[e, NXT], VERT]
    p = nodes[nodes[e, PRV], VERT]
    vx = gx[v % cols]
    vy = gy[v // cols]
    d1x = gx[q % cols] - vx
    d1y = gy[q // cols] - vy
    d2x = gx[p % cols] - vx
    d2y = gy[p // cols] - vy
    cr = d1x * d2y - d1y * d2x
    c1 = d1x * wy - d1y * wx
    c2 = wx * d2y - wy * d2x
    if cr > 0.0:
        return c1 > 0.0 and c2 > 0.0
    if cr < 0.0:
        return c1 > 0.0 or c2 > 0.0
    if d1x * d2x + d1y * d2y > 0.0:
        return True
    return c1 > 0.0


@nb.njit(**_HOT, **KERNEL_ONLY)
def _next_live(b, prev, k, nodes, pool, bhead, scr):
    """The first live entry of bucket b from entry ``k`` on (-1 at the end).

    ``prev`` is the live entry before ``k`` (-1: k is the head). Stale entries met on
    the way (their node died or its edge changed since) are unlinked and freed.
    """
    while k >= 0:
        e = pool[k, P_NODE]
        if nodes[e, ALIVE] != 0 and pool[k, P_VER] == nodes[e, VER]:
            return k
        nk = pool[k, P_NEXT]
        if prev < 0:
            bhead[b] = nk
        else:
            pool[prev, P_NEXT] = nk
        pool[k, P_NEXT] = scr[S_FREE]
        scr[S_FREE] = k
        k = nk
    return -1


@nb.njit(**_HOT, **KERNEL_ONLY)
def _node_at(P, ia, ib, nodes, pool, bhead, nbx, scr, gx, gy, cols):
    """The front node of vertex P whose free angle holds triangle (ia, ib, P), or -1."""
    cp = P % cols
    rp = P // cols
    b = (rp // BS) * nbx + cp // BS
    xp = gx[cp]
    yp = gy[rp]
    wx = gx[ia % cols] + gx[ib % cols] - 2.0 * xp
    wy = gy[ia // cols] + gy[ib // cols] - 2.0 * yp
    prev = -1
    k = _next_live(b, -1, bhead[b], nodes, pool, bhead, scr)
    while k >= 0:
        e = pool[k, P_NODE]
        if nodes[e, VERT] == P and _cone_contains(e, wx, wy, nodes, gx, gy, cols):
            return e
        prev = k
        k = _next_live(b, prev, pool[k, P_NEXT], nodes, pool, bhead, scr)
    return -1


@nb.njit(**_HOT, **KERNEL_ONLY)
def _geom(ia, ib, ic, nodes, pool, bhead, nbx, scr, gx, gy, cols):
    """True when triangle (ia, ib, ic) lies in the free region without touching the front.

    Rejects the triangle when a front edge meets its open interior (separating-axis test,
    touching allowed) or a front vertex other than its corners lies in the closed
    triangle. ``scr[S_BLOCKER]`` receives the blocking node closest to edge ab in the
    Delaunay sense (the best vertex to connect to; ties go to the smaller sample index,
    then the smaller node), or -1.
    """
    ca = ia % cols
    ra = ia // cols
    cb = ib % cols
    rb = ib // cols
    cc = ic % cols
    rc = ic // cols
    xa = gx[ca]
    ya = gy[ra]
    xb = gx[cb]
    yb = gy[rb]
    xc = gx[cc]
    yc = gy[rc]
    mx = 0.5 * (xa + xb)
    my = 0.5 * (ya + yb)
    nx = -(yb - ya)
    ny = xb - xa
    half2 = 0.25 * ((xb - xa) ** 2 + (yb - ya) ** 2)
    c0 = min(ca, cb, cc)
    c1 = max(ca, cb, cc)
    r0 = min(ra, rb, rc)
    r1 = max(ra, rb, rc)
    ok = True
    best_key = np.inf
    best_pid = -1
    best_node = -1
    scr[S_QID] += 1
    qid = scr[S_QID]
    for by in range(r0 // BS, r1 // BS + 1):
        for bx in range(c0 // BS, c1 // BS + 1):
            b = by * nbx + bx
            prev = -1
            k = _next_live(b, -1, bhead[b], nodes, pool, bhead, scr)
            while k >= 0:
                e = pool[k, P_NODE]
                prev = k
                k = _next_live(b, prev, pool[k, P_NEXT], nodes, pool, bhead, scr)
                if nodes[e, STAMP] == qid:
                    continue
                nodes[e, STAMP] = qid
                iu = nodes[e, VERT]
                iw = nodes[nodes[e, NXT], VERT]
                cu = iu % cols
                ru = iu // cols
                cw = iw % cols
                rw = iw // cols
                if max(cu, cw) < c0 or min(cu, cw) > c1 or max(ru, rw) < r0 or min(ru, rw) > r1:
                    continue
                ux = gx[cu]
                uy = gy[ru]
                wx = gx[cw]
                wy = gy[rw]
                blocked = False
                # the start vertex inside the closed triangle (other than a corner)
                if iu != ia and iu != ib and iu != ic:
                    if (
                        orient(xa, ya, xb, yb, ux, uy) >= 0.0
                        and orient(xb, yb, xc, yc, ux, uy) >= 0.0
                        and orient(xc, yc, xa, ya, ux, uy) >= 0.0
                    ):
                        blocked = True
                if not blocked:
                    sep = False
                    if orient(xa, ya, xb, yb, ux, uy) <= 0.0 and orient(xa, ya, xb, yb, wx, wy) <= 0.0:
                        sep = True
                    elif orient(xb, yb, xc, yc, ux, uy) <= 0.0 and orient(xb, yb, xc, yc, wx, wy) <= 0.0:
                        sep = True
                    elif orient(xc, yc, xa, ya, ux, uy) <= 0.0 and orient(xc, yc, xa, ya, wx, wy) <= 0.0:
                        sep = True
                    else:
                        o1 = orient(ux, uy, wx, wy, xa, ya)
                        o2 = orient(ux, uy, wx, wy, xb, yb)
                        o3 = orient(ux, uy, wx, wy, xc, yc)
                        if (o1 >= 0.0 and o2 >= 0.0 and o3 >= 0.0) or (o1 <= 0.0 and o2 <= 0.0 and o3 <= 0.0):
                            sep = True
                    blocked = not sep
                if not blocked:
                    continue
                ok = False
                for j in range(2):
                    if j == 0:
                        node = e
                        px = ux
                        py = uy
                        pid = iu
                    else:
                        node = nodes[e, NXT]
                        px = wx
                        py = wy
                        pid = iw
                    if pid == ia or pid == ib:
                        continue
                    den = (px - mx) * nx + (py - my) * ny
                    if den <= 0.0:
                        continue
                    key = ((px - mx) ** 2 + (py - my) ** 2 - half2) / (2.0 * den)
                    tie = key == best_key and (pid < best_pid or (pid == best_pid and node < best_node))
                    if key < best_key or tie:
                        best_key = key
                        best_pid = pid
                        best_node = node
    scr[S_BLOCKER] = best_node
    return ok


@nb.njit(**_HOT)
def _evaluate(ia, ib, P, sm, fr):
    """Status of triangle (ia, ib, P) on front edge ia -> ib.

    Returns OK, ERR (a sample is farther than eps), GEO (it leaves the free region or
    touches the front; ``scr[S_BLOCKER]`` holds a node to connect to or -1) or BAD (not
    counter-clockwise). On OK, ``scr[S_APEX_NODE]`` holds the apex node, or -1 for a
    free sample. ``sm`` is the :data:`Samples`, ``fr`` the :data:`Front`.
    """
    occ, zf, eps, gx, gy, index_space, cols = sm
    nodes, pool, bhead, nbx, scr = fr
    scr[S_BLOCKER] = -1
    scr[S_APEX_NODE] = -1
    if P == ia or P == ib:
        return BAD
    if orient(gx[ia % cols], gy[ia // cols], gx[ib % cols], gy[ib // cols], gx[P % cols], gy[P // cols]) <= 0.0:
        return BAD
    state = occ[P // cols, P % cols]
    if _scan(ia, ib, P, gx, gy, index_space, zf, cols, eps, occ, False) < 0:
        return ERR
    node = -1
    if state == VERTEX:
        node = _node_at(P, ia, ib, nodes, pool, bhead, nbx, scr, gx, gy, cols)
    geo = _geom(ia, ib, P, nodes, pool, bhead, nbx, scr, gx, gy, cols)
    if not geo or state == COVERED or (state == VERTEX and node < 0):
        return GEO
    scr[S_APEX_NODE] = node
    return OK


# ----------------------------------------------------------------- the three steps
@nb.njit(**_HOT, **KERNEL_ONLY)
def _ear(na, sm, fr, counts):
    """Step 1, ear cutting on the edge of node ``na``: the apex sample or -1.

    The apex's node is left in ``scr[S_APEX_NODE]``.
    """
    nodes = fr.nodes
    nb_ = nodes[na, NXT]
    ia = nodes[na, VERT]
    ib = nodes[nb_, VERT]
    for side in range(2):
        nk = nodes[na, PRV] if side == 0 else nodes[nb_, NXT]
        counts[N_EVAL_EAR] += 1
        P = nodes[nk, VERT]
        if _evaluate(ia, ib, P, sm, fr) == OK:
            return P
    return -1


@nb.njit(**_HOT, **KERNEL_ONLY)
def _apex_at(mc, mr, nc, nr, t, rows, cols):
    pc = int(np.floor(mc + t * nc + 0.5))
    pr = int(np.floor(mr + t * nr + 0.5))
    if pc < 0 or pc >= cols or pr < 0 or pr >= rows:
        return -1
    return pr * cols + pc


@nb.njit(**_HOT, **KERNEL_ONLY)
def _bite(na, sm, fr, rows, counts):
    """Step 2, greedy biting on the edge of node ``na``: the apex sample or -1.

    The apex walks the inward normal through the edge's midpoint, galloping (t = 1, 2, 4,
    ...) while the triangle stays valid and then bisecting (8 halvings) between the last
    valid and the first invalid t. When a triangle is blocked by the front, the blocking
    front vertex nearest the edge (Delaunay sense) is tried once as the apex; it wins
    when valid, since connecting to the front adds no vertex. The apex's node is left in
    ``scr[S_APEX_NODE]``.
    """
    cols = sm.cols
    nodes = fr.nodes
    scr = fr.scr
    ia = nodes[na, VERT]
    ib = nodes[nodes[na, NXT], VERT]
    ca = ia % cols
    ra = ia // cols
    cb = ib % cols
    rb = ib // cols
    mc = 0.5 * (ca + cb)
    mr = 0.5 * (ra + rb)
    dl = np.sqrt(float((cb - ca) ** 2 + (rb - ra) ** 2))
    nc = -(rb - ra) / dl
    nr = (cb - ca) / dl
    tmax = float(rows + cols)
    best = -1
    best_node = -1
    lo = 0.0
    hi = -1.0
    alt = -1
    alt_node = -1
    t = 1.0
    prev_p = -1
    while t <= tmax:
        P = _apex_at(mc, mr, nc, nr, t, rows, cols)
        if P < 0:
            hi = t
            break
        if P != prev_p:
            counts[N_EVAL_BITE] += 1
            st = _evaluate(ia, ib, P, sm, fr)
            if st == OK:
                best = P
                best_node = scr[S_APEX_NODE]
                lo = t
            elif st == BAD and best < 0:
                prev_p = P
                t += 1.0
                continue
            else:
                hi = t
                if st == GEO and scr[S_BLOCKER] >= 0 and alt < 0:
                    alt = _blocker_apex(ia, ib, sm, fr)
                    alt_node = scr[S_APEX_NODE]
                break
        prev_p = P
        t *= 2.0
    if best >= 0 and hi > lo:
        for _ in range(8):
            tm = 0.5 * (lo + hi)
            P = _apex_at(mc, mr, nc, nr, tm, rows, cols)
            if P < 0 or P == best or P == _apex_at(mc, mr, nc, nr, hi, rows, cols):
                break
            st = _evaluate(ia, ib, P, sm, fr)
            if st == OK:
                best = P
                best_node = scr[S_APEX_NODE]
                lo = tm
            else:
                hi = tm
                if st == GEO and scr[S_BLOCKER] >= 0 and alt < 0:
                    alt = _blocker_apex(ia, ib, sm, fr)
                    alt_node = scr[S_APEX_NODE]
    if alt >= 0:
        scr[S_APEX_NODE] = alt_node
        return alt
    scr[S_APEX_NODE] = best_node
    return best


@nb.njit(**_HOT, **KERNEL_ONLY)
def _blocker_apex(ia, ib, sm, fr):
    """The vertex that blocked the last evaluation (``scr[S_BLOCKER]``) as the apex, when
    that evaluates OK (``scr[S_APEX_NODE]`` is then its node); -1 otherwise."""
    ob = fr.nodes[fr.scr[S_BLOCKER], VERT]
    if _evaluate(ia, ib, ob, sm, fr) == OK:
        return ob
    return -1


@nb.njit(**_HOT, **KERNEL_ONLY)
def _split(na, window, sm, fr, counts, cand):
    """Step 3, edge splitting (fallback) on the edge of node ``na``, in the window
    ``(r0, r1, c0, c1)`` (rows r0..r1, cols c0..c1), on the :data:`Samples` ``sm`` and the
    :data:`Front` ``fr``, with the candidate buffers ``cand = (cand_key, cand_id)``.

    Candidates are the free samples and front vertices left of the edge in the window,
    tried in order of the circumcircle through the edge's ends
    (smallest first, ties by sample index: the constrained-Delaunay choice) through the
    heap of :mod:`simplifiers._shared_kernels` in the order
    :func:`~simplifiers._shared_kernels.smaller_then_item`, built and popped only (not
    indexed). Returns the apex (its node in ``scr[S_APEX_NODE]``) or -1. The
    candidate buffers must hold the window's samples.
    """
    r0, r1, c0, c1 = window
    occ, zf, eps, gx, gy, index_space, cols = sm
    nodes, pool, bhead, nbx, scr = fr
    cand_key, cand_id = cand
    ia = nodes[na, VERT]
    ib = nodes[nodes[na, NXT], VERT]
    xa = gx[ia % cols]
    ya = gy[ia // cols]
    xb = gx[ib % cols]
    yb = gy[ib // cols]
    mx = 0.5 * (xa + xb)
    my = 0.5 * (ya + yb)
    nx = -(yb - ya)
    ny = xb - xa
    half2 = 0.25 * ((xb - xa) ** 2 + (yb - ya) ** 2)
    m = np.int64(0)  # int64 from the start: a literal 0 reaching heapify would compile the heap once more
    for r in range(r0, r1 + 1):
        for c in range(c0, c1 + 1):
            if occ[r, c] == COVERED:
                continue
            px = gx[c]
            py = gy[r]
            den = (px - mx) * nx + (py - my) * ny
            if den <= 0.0:
                continue
            cand_key[m] = ((px - mx) ** 2 + (py - my) ** 2 - half2) / (2.0 * den)
            cand_id[m] = r * cols + c
            m += 1
    counts[N_CANDIDATES] += m
    heapify(cand_key, cand_id, None, m, smaller_then_item)
    while m > 0:
        P = cand_id[0]
        counts[N_EVAL_SPLIT] += 1
        if _evaluate(ia, ib, P, sm, fr) == OK:
            return P
        m = heap_pop(cand_key, cand_id, None, m, smaller_then_item)
    return -1


# ----------------------------------------------------------------- front updates
@nb.njit(**_HOT, **KERNEL_ONLY)
def _register(e, nodes, pool, bhead, nbx, scr, cols):
    """List node e's current edge in every bucket its bounding box overlaps.

    ``pool`` must have room for :func:`_n_buckets` new rows past ``scr[S_USED]``.
    """
    iu = nodes[e, VERT]
    iw = nodes[nodes[e, NXT], VERT]
    for by in range(min(iu // cols, iw // cols) // BS, max(iu // cols, iw // cols) // BS + 1):
        for bx in range(min(iu % cols, iw % cols) // BS, max(iu % cols, iw % cols) // BS + 1):
            k = scr[S_FREE]
            if k >= 0:
                scr[S_FREE] = pool[k, P_NEXT]
            else:
                k = scr[S_USED]
                scr[S_USED] += 1
            b = by * nbx + bx
            pool[k, P_NODE] = e
            pool[k, P_VER] = nodes[e, VER]
            pool[k, P_NEXT] = bhead[b]
            bhead[b] = k


@nb.njit(**_HOT, **KERNEL_ONLY)
def _n_buckets(iu, iw, cols):
    """Buckets overlapped by the bounding box of the segment between samples iu and iw."""
    nr = max(iu // cols, iw // cols) // BS - min(iu // cols, iw // cols) // BS + 1
    nc = max(iu % cols, iw % cols) // BS - min(iu % cols, iw % cols) // BS + 1
    return nr * nc


@nb.njit(cache=True, nogil=True)
def greedy_cuts_front(gx, gy, index_space, z, eps, boundary, max_window, max_vertices, stop):
    """Triangulate the grid with the greedy-cuts advancing front for a fixed eps.

    Parameters
    ----------
    gx, gy : (cols,), (rows,) float64
        Plane-space coordinates of the columns and rows (see the module docstring).
    index_space : bool
        True when ``gx`` and ``gy`` are the column and row indices themselves.
    z : (rows, cols) float64
    eps : (rows * cols,) float64
        Largest allowed vertical distance between each sample and the triangle over it.
    boundary : (k,) int64
        The initial front: linear sample indices around the grid, counter-clockwise,
        starting at a corner, each boundary segment eps-valid.
    max_window : int
        Largest window half-width (samples) searched by the fallback step.
    max_vertices : int
        Stop (``counts[STATUS] = OVER_BUDGET``) as soon as the vertex count exceeds this.
    stop : (1,) int64
        The stop flag (:mod:`terrainvis.core.interrupt`), read before every step; when it is
        set the run ends with ``counts[STATUS] = INTERRUPTED``.

    Returns
    -------
    tris : (m, 3) int64
        Counter-clockwise triangles of linear sample indices ``r * cols + c``.
    counts : (N_COUNTS,) int64
        The counters (module docstring).
    """
    rows, cols = z.shape
    zf = z.ravel()
    counts = np.zeros(N_COUNTS, dtype=np.int64)
    occ = np.zeros((rows, cols), dtype=np.int8)
    occ[0, :] = COVERED
    occ[rows - 1, :] = COVERED
    occ[:, 0] = COVERED
    occ[:, cols - 1] = COVERED
    counts[N_COVERED] = rows * cols - (rows - 2) * (cols - 2)
    nb0 = boundary.shape[0]
    cap = max(1024, 4 * nb0)
    nodes = np.zeros((cap, 6), dtype=np.int64)
    nbx = (cols - 1) // BS + 1
    nby = (rows - 1) // BS + 1
    bhead = np.full(nbx * nby, -1, dtype=np.int64)
    pool = np.empty((4 * cap, 3), dtype=np.int64)
    scr = np.zeros(N_SCR, dtype=np.int64)
    scr[S_FREE] = -1
    queue = np.empty((4 * cap, 2), dtype=np.int64)  # (node, version)
    qhead = 0
    qtail = _ZERO  # typed int64 from the start: a literal 0 would compile _grow once more for it
    tris = np.empty((2 * cap, 3), dtype=np.int64)
    ntri = 0
    changed = np.empty(3, dtype=np.int64)
    cand_key = np.empty(64, dtype=np.float64)
    cand_id = np.empty(64, dtype=np.int64)
    sm = Samples(occ, zf, eps, gx, gy, index_space, cols)
    # the initial front: one loop, every edge registered and queued
    for i in range(nb0):
        nodes[i, VERT] = boundary[i]
        nodes[i, NXT] = (i + 1) % nb0
        nodes[i, PRV] = (i - 1 + nb0) % nb0
        nodes[i, ALIVE] = 1
        occ[boundary[i] // cols, boundary[i] % cols] = VERTEX
    counts[N_VERTICES] = nb0
    nn = nb0
    for e in range(nb0):
        pool = _grow(pool, scr[S_USED] + _n_buckets(nodes[e, VERT], nodes[nodes[e, NXT], VERT], cols))
        _register(e, nodes, pool, bhead, nbx, scr, cols)
        queue = _grow(queue, qtail)
        queue[qtail, 0] = e
        queue[qtail, 1] = 0
        qtail += 1
    max_steps = 8 * rows * cols + 64
    steps = 0
    while qhead < qtail:
        steps += 1
        if steps > max_steps:
            counts[STATUS] = STEP_LIMIT
            break
        if counts[N_VERTICES] > max_vertices:
            counts[STATUS] = OVER_BUDGET
            break
        if stopped(stop):
            counts[STATUS] = INTERRUPTED
            break
        na = queue[qhead, 0]
        v = queue[qhead, 1]
        qhead += 1
        if nodes[na, ALIVE] == 0 or nodes[na, VER] != v:
            continue
        nb_ = nodes[na, NXT]
        ia = nodes[na, VERT]
        ib = nodes[nb_, VERT]
        fr = Front(nodes, pool, bhead, nbx, scr)  # nodes and pool are replaced when they grow
        apex = _ear(na, sm, fr, counts)
        if apex < 0:
            apex = _bite(na, sm, fr, rows, counts)
        if apex < 0:
            w = 2
            while True:  # windows of half-width 2, 4, 8, ... around the edge
                c0 = max(0, min(ia % cols, ib % cols) - w)
                c1 = min(cols - 1, max(ia % cols, ib % cols) + w)
                r0 = max(0, min(ia // cols, ib // cols) - w)
                r1 = min(rows - 1, max(ia // cols, ib // cols) + w)
                span = (r1 - r0 + 1) * (c1 - c0 + 1)
                if span > cand_key.shape[0]:
                    cand_key = _grow(cand_key, span)
                    cand_id = _grow(cand_id, span)
                apex = _split(na, (r0, r1, c0, c1), sm, fr, counts, (cand_key, cand_id))
                if apex >= 0 or w >= max_window or (c0 == 0 and r0 == 0 and c1 == cols - 1 and r1 == rows - 1):
                    break
                w *= 2
            if apex >= 0:
                counts[N_SPLITS] += 1
        if apex < 0:
            counts[STATUS] = STUCK
            break
        apex_node = scr[S_APEX_NODE]
        # emit the triangle and cover its samples
        if ntri >= tris.shape[0]:
            tris = _grow(tris, ntri)
        tris[ntri, 0] = ia
        tris[ntri, 1] = ib
        tris[ntri, 2] = apex
        ntri += 1
        counts[N_COVERED] += _scan(ia, ib, apex, gx, gy, index_space, zf, cols, eps, occ, True)
        # update the front
        if nn >= nodes.shape[0]:
            nodes = _grow(nodes, nn)
        nch = 0
        if apex_node < 0:  # a bite: a -> P -> b, one new vertex
            counts[N_BITES] += 1
            counts[N_VERTICES] += 1
            occ[apex // cols, apex % cols] = VERTEX
            npn = nn
            nn += 1
            nodes[npn, VERT] = apex
            nodes[npn, ALIVE] = 1
            nodes[na, NXT] = npn
            nodes[npn, PRV] = na
            nodes[npn, NXT] = nb_
            nodes[nb_, PRV] = npn
            changed[0] = na
            changed[1] = npn
            nch = 2
        elif apex_node == nodes[na, PRV]:  # an ear with the previous vertex
            counts[N_EARS] += 1
            k = apex_node
            nodes[na, ALIVE] = 0
            nodes[k, NXT] = nb_
            nodes[nb_, PRV] = k
            if nodes[nb_, NXT] == k:  # the loop was this triangle: it closes
                nodes[k, ALIVE] = 0
                nodes[nb_, ALIVE] = 0
            else:
                changed[0] = k
                nch = 1
        elif apex_node == nodes[nb_, NXT]:  # an ear with the next vertex
            counts[N_EARS] += 1
            k = apex_node
            nodes[nb_, ALIVE] = 0
            nodes[na, NXT] = k
            nodes[k, PRV] = na
            if nodes[k, NXT] == na:
                nodes[k, ALIVE] = 0
                nodes[na, ALIVE] = 0
            else:
                changed[0] = na
                nch = 1
        else:  # a connection to another front vertex: the loop splits in two
            counts[N_EARS] += 1
            k = apex_node
            n2 = nn
            nn += 1
            y = nodes[k, NXT]
            nodes[n2, VERT] = nodes[k, VERT]
            nodes[n2, ALIVE] = 1
            nodes[na, NXT] = n2
            nodes[n2, PRV] = na
            nodes[n2, NXT] = y
            nodes[y, PRV] = n2
            nodes[k, NXT] = nb_
            nodes[nb_, PRV] = k
            changed[0] = na
            changed[1] = n2
            changed[2] = k
            nch = 3
        need = scr[S_USED]
        for j in range(nch):
            need += _n_buckets(nodes[changed[j], VERT], nodes[nodes[changed[j], NXT], VERT], cols)
        if need > pool.shape[0]:
            pool = _grow(pool, need)
        if qtail + nch > queue.shape[0]:
            if 2 * qhead >= queue.shape[0]:  # the live part fits below qhead: move it down
                m = qtail - qhead
                for j in range(m):  # a loop, not a slice assignment (see _grow)
                    queue[j, 0] = queue[qhead + j, 0]
                    queue[j, 1] = queue[qhead + j, 1]
                qhead = 0
                qtail = m
            else:
                queue = _grow(queue, qtail + nch)
        for j in range(nch):
            e2 = changed[j]
            nodes[e2, VER] += 1
            _register(e2, nodes, pool, bhead, nbx, scr, cols)
            queue[qtail, 0] = e2
            queue[qtail, 1] = nodes[e2, VER]
            qtail += 1
    return tris[:ntri].copy(), counts
