"""Numba loops for greedy cuts (Silva, Mitchell & Kaufman 1995): the advancing front.

Kernels loop and never validate; :mod:`simplifiers.greedy_cuts` checks the input.

Geometry works in a *plane space* ``(gx[c], gy[r])``: for a uniform grid the wrapper passes
the column and row indices themselves (an affine image of the world coordinates with a
positive determinant, so orientation signs, barycentric coordinates and "which samples lie
in a triangle" are the same as in world coordinates, and every orientation test is exact
integer arithmetic in float64); for a rectilinear grid it passes the world coordinates
shifted to a local origin.

Data structures
---------------
* ``occ`` (rows, cols) int8: ``FREE`` (strictly inside the untriangulated region and not a
  vertex), ``COVERED`` (in a finished triangle or on the interior of a front edge) or
  ``VERTEX``. A bite may only reach a FREE sample; a COVERED one would overlap the
  finished region or make a T-junction.
* The front is a set of closed counter-clockwise loops of *nodes* (a doubly linked list:
  ``vert``, ``nxt``, ``prv``, ``alive``, ``ver``); one vertex may own several nodes when
  the front touches itself. The free region lies to the left of every front edge
  ``vert[n] -> vert[nxt[n]]``.
* A bucket grid (``BS`` x ``BS`` samples per bucket) lists, per bucket, the nodes whose
  edge's bounding box overlaps it (entries go stale when an edge changes and are skipped).
* A FIFO queue of ``(node, version)``: every edge made or changed is pushed once; an entry
  whose version no longer matches is skipped.
"""

from __future__ import annotations

import numba as nb
import numpy as np

FREE = 0
COVERED = 1
VERTEX = 2

BS = 8  # bucket side in samples

OK = 0
ERR = 1
GEO = 2
BAD = 3


@nb.njit(cache=True, nogil=True)
def _orient(ax, ay, bx, by, cx, cy):
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@nb.njit(cache=True, nogil=True)
def _grow(arr, n):
    """``arr`` itself when it holds index ``n``, else a copy twice as long."""
    if n < arr.shape[0]:
        return arr
    new = np.empty(max(2 * arr.shape[0], n + 1), dtype=arr.dtype)
    new[: arr.shape[0]] = arr
    return new


@nb.njit(cache=True, nogil=True)
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


@nb.njit(cache=True, nogil=True)
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


@nb.njit(cache=True, nogil=True)
def _scan(ia, ib, ic, gx, gy, zf, cols, eps, occ, mark):
    """Scan-convert triangle (ia, ib, ic) (counter-clockwise) over the samples.

    With ``mark`` False: True when every sample s in the closed triangle lies within
    ``eps[s]`` of it (samples on an edge are measured against that edge, the same way from either side;
    the others against the plane), stopping at the first failure. With ``mark`` True: set
    every FREE sample of the closed triangle to COVERED and return True.
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
    area2 = _orient(xa, ya, xb, yb, xc, yc)
    ncols = gx.shape[0]
    r0 = min(ra, rb, rc)
    r1 = max(ra, rb, rc)
    for r in range(r0, r1 + 1):
        y = gy[r]
        lo, hi = _row_range(y, xa, ya, xb, yb, xc, yc)
        if lo > hi:
            continue
        c0 = np.searchsorted(gx, lo) - 1
        c1 = np.searchsorted(gx, hi) + 1
        if c0 < 0:
            c0 = 0
        if c1 > ncols - 1:
            c1 = ncols - 1
        for c in range(c0, c1 + 1):
            x = gx[c]
            o1 = _orient(xa, ya, xb, yb, x, y)  # edge ab
            if o1 < 0.0:
                continue
            o2 = _orient(xb, yb, xc, yc, x, y)  # edge bc
            if o2 < 0.0:
                continue
            o3 = _orient(xc, yc, xa, ya, x, y)  # edge ca
            if o3 < 0.0:
                continue
            s = r * cols + c
            if mark:
                if occ[r, c] == FREE:
                    occ[r, c] = COVERED
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
                return False
    return True


@nb.njit(cache=True, nogil=True)
def _cone_contains(e, wx, wy, vert, nxt, prv, gx, gy, cols):
    """True when direction (wx, wy) lies strictly inside the free angle at node e."""
    v = vert[e]
    q = vert[nxt[e]]
    p = vert[prv[e]]
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


@nb.njit(cache=True, nogil=True)
def _node_at(P, ia, ib, vert, nxt, prv, alive, bhead, pool_node, pool_next, nbx, gx, gy, cols):
    """The front node of vertex P whose free angle holds triangle (ia, ib, P), or -1."""
    cp = P % cols
    rp = P // cols
    b = (rp // BS) * nbx + cp // BS
    xp = gx[cp]
    yp = gy[rp]
    wx = gx[ia % cols] + gx[ib % cols] - 2.0 * xp
    wy = gy[ia // cols] + gy[ib // cols] - 2.0 * yp
    k = bhead[b]
    while k >= 0:
        e = pool_node[k]
        k = pool_next[k]
        if alive[e] == 0 or vert[e] != P:
            continue
        if _cone_contains(e, wx, wy, vert, nxt, prv, gx, gy, cols):
            return e
    return -1


@nb.njit(cache=True, nogil=True)
def _geom(ia, ib, ic, vert, nxt, alive, bhead, pool_node, pool_next, nbx, stamp, qid, gx, gy, cols, out):
    """True when triangle (ia, ib, ic) lies in the free region without touching the front.

    Rejects the triangle when a front edge meets its open interior (separating-axis test,
    touching allowed) or a front vertex other than its corners lies in the closed
    triangle. ``out[0]`` receives the blocking node closest to edge ab in the Delaunay
    sense (the best vertex to connect to), or -1.
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
    out[0] = -1
    for by in range(r0 // BS, r1 // BS + 1):
        for bx in range(c0 // BS, c1 // BS + 1):
            k = bhead[by * nbx + bx]
            while k >= 0:
                e = pool_node[k]
                k = pool_next[k]
                if alive[e] == 0 or stamp[e] == qid:
                    continue
                stamp[e] = qid
                iu = vert[e]
                iw = vert[nxt[e]]
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
                        _orient(xa, ya, xb, yb, ux, uy) >= 0.0
                        and _orient(xb, yb, xc, yc, ux, uy) >= 0.0
                        and _orient(xc, yc, xa, ya, ux, uy) >= 0.0
                    ):
                        blocked = True
                if not blocked:
                    sep = False
                    if _orient(xa, ya, xb, yb, ux, uy) <= 0.0 and _orient(xa, ya, xb, yb, wx, wy) <= 0.0:
                        sep = True
                    elif _orient(xb, yb, xc, yc, ux, uy) <= 0.0 and _orient(xb, yb, xc, yc, wx, wy) <= 0.0:
                        sep = True
                    elif _orient(xc, yc, xa, ya, ux, uy) <= 0.0 and _orient(xc, yc, xa, ya, wx, wy) <= 0.0:
                        sep = True
                    else:
                        o1 = _orient(ux, uy, wx, wy, xa, ya)
                        o2 = _orient(ux, uy, wx, wy, xb, yb)
                        o3 = _orient(ux, uy, wx, wy, xc, yc)
                        if (o1 >= 0.0 and o2 >= 0.0 and o3 >= 0.0) or (o1 <= 0.0 and o2 <= 0.0 and o3 <= 0.0):
                            sep = True
                    blocked = not sep
                if blocked:
                    ok = False
                    for j in range(2):
                        if j == 0:
                            node = e
                            px = ux
                            py = uy
                            pid = iu
                        else:
                            node = nxt[e]
                            px = wx
                            py = wy
                            pid = iw
                        if pid == ia or pid == ib:
                            continue
                        den = (px - mx) * nx + (py - my) * ny
                        if den <= 0.0:
                            continue
                        key = ((px - mx) ** 2 + (py - my) ** 2 - half2) / (2.0 * den)
                        if key < best_key:
                            best_key = key
                            out[0] = node
    return ok


@nb.njit(cache=True, nogil=True)
def _evaluate(ia, ib, P, occ, zf, eps, vert, nxt, prv, alive, bhead, pool_node, pool_next, nbx, stamp, qid,
              gx, gy, cols, out):
    """Status of triangle (ia, ib, P) on front edge ia -> ib.

    Returns OK, ERR (a sample is farther than eps), GEO (it leaves the free region or
    touches the front; ``out[0]`` holds a node to connect to or -1) or BAD (not
    counter-clockwise). On OK, ``out[1]`` holds the apex node, or -1 for a free sample.
    """
    out[0] = -1
    out[1] = -1
    if P == ia or P == ib:
        return BAD
    if _orient(gx[ia % cols], gy[ia // cols], gx[ib % cols], gy[ib // cols], gx[P % cols], gy[P // cols]) <= 0.0:
        return BAD
    state = occ[P // cols, P % cols]
    if not _scan(ia, ib, P, gx, gy, zf, cols, eps, occ, False):
        return ERR
    node = -1
    if state == VERTEX:
        node = _node_at(P, ia, ib, vert, nxt, prv, alive, bhead, pool_node, pool_next, nbx, gx, gy, cols)
    geo = _geom(ia, ib, P, vert, nxt, alive, bhead, pool_node, pool_next, nbx, stamp, qid, gx, gy, cols, out)
    if not geo or state == COVERED or (state == VERTEX and node < 0):
        return GEO
    out[1] = node
    return OK


@nb.njit(cache=True, nogil=True)
def _apex_at(mc, mr, nc, nr, t, rows, cols):
    pc = int(np.floor(mc + t * nc + 0.5))
    pr = int(np.floor(mr + t * nr + 0.5))
    if pc < 0 or pc >= cols or pr < 0 or pr >= rows:
        return -1
    return pr * cols + pc


@nb.njit(cache=True, nogil=True)
def greedy_cuts_front(gx, gy, z, eps, boundary, max_dt_window):
    """Triangulate the grid with the greedy-cuts advancing front for a fixed eps.

    Parameters
    ----------
    gx, gy : (cols,), (rows,) float64
        Plane-space coordinates of the columns and rows (see the module docstring).
    z : (rows, cols) float64
    eps : (rows * cols,) float64
        Largest allowed vertical distance between each sample and the triangle over it.
    boundary : (k,) int64
        The initial front: linear sample indices around the grid, counter-clockwise,
        starting at a corner, each boundary segment eps-valid.
    max_dt_window : int
        Largest window half-width (samples) searched by the fallback step.

    Returns
    -------
    tris : (m, 3) int64
        Counter-clockwise triangles of linear sample indices ``r * cols + c``.
    counts : (8,) int64
        Triangles adding no vertex (ears and connections to the front), triangles adding
        a vertex (bites and fallback insertions), fallback insertions, a status (0 = done,
        1 = stuck: an edge found no valid triangle, 2 = step limit), then the number of
        triangles evaluated by ear cutting, by biting and by the fallback, and the number
        of fallback candidates gathered.
    """
    rows, cols = z.shape
    zf = z.ravel()
    occ = np.zeros((rows, cols), dtype=np.int8)
    occ[0, :] = COVERED
    occ[rows - 1, :] = COVERED
    occ[:, 0] = COVERED
    occ[:, cols - 1] = COVERED
    nb0 = boundary.shape[0]
    cap = max(1024, 4 * nb0)
    vert = np.empty(cap, dtype=np.int64)
    nxt = np.empty(cap, dtype=np.int64)
    prv = np.empty(cap, dtype=np.int64)
    alive = np.zeros(cap, dtype=np.int64)
    ver = np.zeros(cap, dtype=np.int64)
    stamp = np.zeros(cap, dtype=np.int64)
    for i in range(nb0):
        vert[i] = boundary[i]
        nxt[i] = (i + 1) % nb0
        prv[i] = (i - 1 + nb0) % nb0
        alive[i] = 1
        occ[boundary[i] // cols, boundary[i] % cols] = VERTEX
    nn = nb0
    nbx = (cols - 1) // BS + 1
    nby = (rows - 1) // BS + 1
    bhead = np.full(nbx * nby, -1, dtype=np.int64)
    pool_node = np.empty(16 * cap, dtype=np.int64)
    pool_next = np.empty(16 * cap, dtype=np.int64)
    npool = 0
    qn = np.empty(4 * cap, dtype=np.int64)
    qv = np.empty(4 * cap, dtype=np.int64)
    qhead = 0
    qtail = 0
    tris = np.empty(3 * cap, dtype=np.int64)
    ntri = 0
    qid = 0
    out = np.empty(2, dtype=np.int64)
    counts = np.zeros(8, dtype=np.int64)
    changed = np.empty(3, dtype=np.int64)
    # register and queue the initial edges
    for e in range(nb0):
        iu = vert[e]
        iw = vert[nxt[e]]
        for by in range(min(iu // cols, iw // cols) // BS, max(iu // cols, iw // cols) // BS + 1):
            for bx in range(min(iu % cols, iw % cols) // BS, max(iu % cols, iw % cols) // BS + 1):
                pool_node = _grow(pool_node, npool)
                pool_next = _grow(pool_next, npool)
                pool_node[npool] = e
                pool_next[npool] = bhead[by * nbx + bx]
                bhead[by * nbx + bx] = npool
                npool += 1
        qn = _grow(qn, qtail)
        qv = _grow(qv, qtail)
        qn[qtail] = e
        qv[qtail] = 0
        qtail += 1
    max_steps = 8 * rows * cols + 64
    steps = 0
    cand_key = np.empty(64, dtype=np.float64)
    cand_id = np.empty(64, dtype=np.int64)
    while qhead < qtail:
        steps += 1
        if steps > max_steps:
            counts[3] = 2
            break
        e = qn[qhead]
        v = qv[qhead]
        qhead += 1
        if alive[e] == 0 or ver[e] != v:
            continue
        na = e
        nb_ = nxt[na]
        ia = vert[na]
        ib = vert[nb_]
        apex = -1  # chosen apex sample
        apex_node = -1  # its node (-1: a new vertex)
        # 1. ear cutting: the neighbours of the edge
        for side in range(2):
            nk = prv[na] if side == 0 else nxt[nb_]
            counts[4] += 1
            qid += 1
            st = _evaluate(ia, ib, vert[nk], occ, zf, eps, vert, nxt, prv, alive, bhead, pool_node, pool_next,
                           nbx, stamp, qid, gx, gy, cols, out)
            if st == OK:
                apex = vert[nk]
                apex_node = out[1]
                break
        # 2. greedy biting along the inward normal of the edge's midpoint
        if apex < 0:
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
                    counts[5] += 1
                    qid += 1
                    st = _evaluate(ia, ib, P, occ, zf, eps, vert, nxt, prv, alive, bhead, pool_node, pool_next,
                                   nbx, stamp, qid, gx, gy, cols, out)
                    if st == OK:
                        best = P
                        best_node = out[1]
                        lo = t
                    elif st == BAD and best < 0:
                        prev_p = P
                        t += 1.0
                        continue
                    else:
                        hi = t
                        if st == GEO and out[0] >= 0 and alt < 0:
                            ob = vert[out[0]]
                            qid += 1
                            st2 = _evaluate(ia, ib, ob, occ, zf, eps, vert, nxt, prv, alive, bhead, pool_node,
                                            pool_next, nbx, stamp, qid, gx, gy, cols, out)
                            if st2 == OK:
                                alt = ob
                                alt_node = out[1]
                        break
                prev_p = P
                t *= 2.0
            if best >= 0 and hi > lo:
                for _ in range(8):
                    tm = 0.5 * (lo + hi)
                    P = _apex_at(mc, mr, nc, nr, tm, rows, cols)
                    if P < 0 or P == best or P == _apex_at(mc, mr, nc, nr, hi, rows, cols):
                        break
                    qid += 1
                    st = _evaluate(ia, ib, P, occ, zf, eps, vert, nxt, prv, alive, bhead, pool_node, pool_next,
                                   nbx, stamp, qid, gx, gy, cols, out)
                    if st == OK:
                        best = P
                        best_node = out[1]
                        lo = tm
                    else:
                        hi = tm
                        if st == GEO and out[0] >= 0 and alt < 0:
                            ob = vert[out[0]]
                            qid += 1
                            st2 = _evaluate(ia, ib, ob, occ, zf, eps, vert, nxt, prv, alive, bhead, pool_node,
                                            pool_next, nbx, stamp, qid, gx, gy, cols, out)
                            if st2 == OK:
                                alt = ob
                                alt_node = out[1]
            if alt >= 0:
                apex = alt
                apex_node = alt_node
            elif best >= 0:
                apex = best
                apex_node = best_node
        # 3. edge splitting (fallback): the sample or front vertex left of the edge with
        #    the smallest circumcircle through a and b (constrained-Delaunay choice)
        if apex < 0:
            xa = gx[ia % cols]
            ya = gy[ia // cols]
            xb = gx[ib % cols]
            yb = gy[ib // cols]
            mx = 0.5 * (xa + xb)
            my = 0.5 * (ya + yb)
            nx = -(yb - ya)
            ny = xb - xa
            half2 = 0.25 * ((xb - xa) ** 2 + (yb - ya) ** 2)
            ca = ia % cols
            ra = ia // cols
            cb = ib % cols
            rb = ib // cols
            w = 2
            while apex < 0:
                c0 = max(0, min(ca, cb) - w)
                c1 = min(cols - 1, max(ca, cb) + w)
                r0 = max(0, min(ra, rb) - w)
                r1 = min(rows - 1, max(ra, rb) + w)
                m = 0
                for r in range(r0, r1 + 1):
                    for c in range(c0, c1 + 1):
                        if occ[r, c] == COVERED:
                            continue
                        px = gx[c]
                        py = gy[r]
                        den = (px - mx) * nx + (py - my) * ny
                        if den <= 0.0:
                            continue
                        if m >= cand_key.shape[0]:
                            cand_key = _grow(cand_key, m)
                            cand_id = _grow(cand_id, m)
                        cand_key[m] = ((px - mx) ** 2 + (py - my) ** 2 - half2) / (2.0 * den)
                        cand_id[m] = r * cols + c
                        m += 1
                counts[7] += m
                order = np.argsort(cand_key[:m], kind="mergesort")
                for j in range(m):
                    P = cand_id[order[j]]
                    counts[6] += 1
                    qid += 1
                    st = _evaluate(ia, ib, P, occ, zf, eps, vert, nxt, prv, alive, bhead, pool_node, pool_next,
                                   nbx, stamp, qid, gx, gy, cols, out)
                    if st == OK:
                        apex = P
                        apex_node = out[1]
                        break
                if apex >= 0:
                    break
                if w >= max_dt_window or (c0 == 0 and r0 == 0 and c1 == cols - 1 and r1 == rows - 1):
                    break
                w *= 2
            if apex >= 0:
                counts[2] += 1
        if apex < 0:
            counts[3] = 1
            break
        # apply: emit the triangle, update the front
        tris = _grow(tris, 3 * ntri + 2)
        tris[3 * ntri] = ia
        tris[3 * ntri + 1] = ib
        tris[3 * ntri + 2] = apex
        ntri += 1
        _scan(ia, ib, apex, gx, gy, zf, cols, eps, occ, True)
        nch = 0
        if apex_node < 0:
            # bite: a -> P -> b
            counts[1] += 1
            occ[apex // cols, apex % cols] = VERTEX
            vert = _grow(vert, nn)
            nxt = _grow(nxt, nn)
            prv = _grow(prv, nn)
            alive = _grow(alive, nn)
            ver = _grow(ver, nn)
            stamp = _grow(stamp, nn)
            npn = nn
            nn += 1
            vert[npn] = apex
            alive[npn] = 1
            ver[npn] = 0
            stamp[npn] = 0
            nxt[na] = npn
            prv[npn] = na
            nxt[npn] = nb_
            prv[nb_] = npn
            changed[0] = na
            changed[1] = npn
            nch = 2
        elif apex_node == prv[na]:
            counts[0] += 1
            k = apex_node
            alive[na] = 0
            nxt[k] = nb_
            prv[nb_] = k
            if nxt[nb_] == k:
                alive[k] = 0
                alive[nb_] = 0
            else:
                changed[0] = k
                nch = 1
        elif apex_node == nxt[nb_]:
            counts[0] += 1
            k = apex_node
            alive[nb_] = 0
            nxt[na] = k
            prv[k] = na
            if nxt[k] == na:
                alive[k] = 0
                alive[na] = 0
            else:
                changed[0] = na
                nch = 1
        else:
            counts[0] += 1
            k = apex_node
            vert = _grow(vert, nn)
            nxt = _grow(nxt, nn)
            prv = _grow(prv, nn)
            alive = _grow(alive, nn)
            ver = _grow(ver, nn)
            stamp = _grow(stamp, nn)
            n2 = nn
            nn += 1
            y = nxt[k]
            vert[n2] = vert[k]
            alive[n2] = 1
            ver[n2] = 0
            stamp[n2] = 0
            nxt[na] = n2
            prv[n2] = na
            nxt[n2] = y
            prv[y] = n2
            nxt[k] = nb_
            prv[nb_] = k
            changed[0] = na
            changed[1] = n2
            changed[2] = k
            nch = 3
        for j in range(nch):
            e2 = changed[j]
            ver[e2] += 1
            iu = vert[e2]
            iw = vert[nxt[e2]]
            for by in range(min(iu // cols, iw // cols) // BS, max(iu // cols, iw // cols) // BS + 1):
                for bx in range(min(iu % cols, iw % cols) // BS, max(iu % cols, iw % cols) // BS + 1):
                    pool_node = _grow(pool_node, npool)
                    pool_next = _grow(pool_next, npool)
                    pool_node[npool] = e2
                    pool_next[npool] = bhead[by * nbx + bx]
                    bhead[by * nbx + bx] = npool
                    npool += 1
            qn = _grow(qn, qtail)
            qv = _grow(qv, qtail)
            qn[qtail] = e2
            qv[qtail] = ver[e2]
            qtail += 1
    return tris[: 3 * ntri].reshape(ntri, 3).copy(), counts
