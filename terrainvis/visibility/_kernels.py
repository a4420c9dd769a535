"""Numba loops for line of sight (grid walk, TIN clipping).

Kernels loop and never validate: the public functions in ``terrainvis.visibility``
check their input, shift coordinates to a local origin and pass plain arrays.

Kernel arguments
----------------
The grid walk reads one grid through a :data:`~terrainvis.core.surface.SurfaceGrid` (the
core's named tuple of a grid's arrays, with the min/max pyramid of "Pyramid layout",
built by ``terrainvis.visibility.grid``), keeps its descent on a
:data:`WalkStack` (scratch arrays, one per thread, from :func:`new_stack`) and takes a
segment as the 6-tuple ``seg = (ax, ay, az, dx, dy, dz)``, the points ``a + t * d``.
The per-cell and per-pair functions (``_cell_min``, :func:`segment_min`, ``_pair_min``)
are inlined at numba IR level (``inline="always"``) into the pair loop. As
separate calls they cost 1-4 % of the LOS throughput against the earlier kernels that
took two dozen positional arrays (every call updates the reference counts of the named
tuples' arrays); inlined, ``line_of_sight`` is 9-17 % faster than with those kernels,
with the same bits (docs/visibility.md, "Performance"). The TIN clipper reads its mesh
and bucket grid through a :data:`~terrainvis.core.surface.SurfaceTin` (local coordinates:
the bucket grid's corner at the origin). The surface itself (the cell height, ``locate``,
the triangle plane) is :mod:`terrainvis.core.surface`'s.

Threads and compile time
------------------------
The pair loops (:func:`grid_walks`, :func:`tin_pairs`) are serial kernels over a range
of their iterations; :func:`terrainvis.core.interrupt.call` runs them on numba's number
of threads, each thread taking the next chunk when done, one kernel for any number of
threads. The walk inlined into a ``prange`` loop was the costliest compilation of a
first run (numba's inlining and parfor passes over the whole walk: 11.6 s of the 13.7 s
that ``assert_visibility_kept`` compiled on a bundled terrain); the range kernel compiles
in about half that. Its arrays are :func:`~terrainvis.core.surface.borrow` ed once: a
``prange`` body's arrays carry no reference counts, and without the views the serial
loop spent half its time in atomic counts; with them a visibility matrix runs 20-30 %
faster than the ``prange`` loop did (same bits; ``docs/performance.md``, "First run").
A walk whose per-cell and per-node functions are plain calls instead of inlined ones
compiles in 4 s, but runs 3.5 times slower: numba passes a named tuple of arrays as
dozens of scalars, and LLVM does not inline the walk's larger functions.

Tested interval
---------------
A segment of 3-D length ``length`` and horizontal length ``lh`` is tested over
``[t0, 1 - t0]`` with ``t0 = max(delta / length, end_radius / lh)``
(:func:`interval_start`); it is not tested at all (clearance ``inf``) when
``length <= 2 delta`` or, for ``end_radius > 0``, when ``lh <= 2 end_radius``.

Earth curvature
---------------
With the coefficient ``kc = curvature / (2 R)`` (0 for a flat earth), the sight line
clears the surface raised by ``kc d1 d2`` (d1, d2 the horizontal distances to its two
ends): at parameter t of a segment of horizontal length L the clearance is the flat one
less ``bulge t (1 - t)``, ``bulge = kc L**2``, symmetric in the two ends. On one piece
of the walk (one triangle) that is a convex quadratic, so its minimum is at an end of the
piece or at the quadratic's vertex inside it (:func:`curved_min`). With ``kc = 0`` every
kernel takes the flat code path, bit for bit.

Pyramid layout
--------------
Level 0 is the cell itself (never stored: its surface is evaluated exactly from ``z``).
Level ``L >= 1`` node ``(R, C)`` covers cells ``[R*2**L, (R+1)*2**L) x [C*2**L, (C+1)*2**L)``
(clipped to the grid) and stores ``(min, max)`` of the height samples at the corners of
those cells as float32, rounded outwards so the bounds stay conservative. Level ``L``
starts at ``pyr[off[L]]`` and holds ``nyl[L] x nxl[L]`` nodes, two floats each.
"""

from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from ..core.compiling import KERNEL_ONLY
from ..core.stopflag import stopped
from ..core.surface import barycentric, borrow, borrow_grid, borrow_tin, cell_height, keep_alive, weighted
from ..tolerances import BUCKET_SLACK_REL
from .walk import cell_diagonal
from .walk import mid_height_inline as mid_height
from .walk import node_pop_inline as node_pop
from .walk import node_push_inline as node_push
from .walk import node_root_inline as node_root
from .walk import node_split_inline as node_split

_INF = np.inf

#: Scratch stack of the pyramid descent: per entry the node's ``level``, ``row`` and
#: ``col`` ((ns,) int64 each) and its parameter interval ``t`` ((2 ns,) float64).
WalkStack = namedtuple("WalkStack", ["level", "row", "col", "t"])


# --------------------------------------------------------------------------- float32 rounding
@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _f32_up(v):
    f = np.float32(v)
    if np.float64(f) < v:
        f = np.nextafter(f, np.float32(np.inf))
    return f


# --------------------------------------------------------------------------- grid walk
@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _vertex_min(fa, fb, ta, tb, bulge):
    """Curved clearance at the interior minimum of one piece, or inf when it has none there.

    On a piece [ta, tb] where the flat clearance is linear (``fa``, ``fb`` at its ends),
    the clearance under earth curvature is ``flat(t) - bulge * t * (1 - t)``, a convex
    quadratic (``bulge = k L**2 > 0``, L the segment's horizontal length) whose minimum
    is at ``t* = 1/2 - B / (2 bulge)``, B the flat slope. ``flat(t*)`` is interpolated
    from the ends: ``|B (t* - ta)| <= |fb - fa|``, so its error is that of fa and fb.
    """
    if not tb > ta:
        return _INF
    b_ = (fb - fa) / (tb - ta)
    ts = 0.5 - b_ / (2.0 * bulge)
    if not (ts > ta and ts < tb):
        return _INF
    return fa + b_ * (ts - ta) - bulge * ts * (1.0 - ts)


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def curved_min(fa, fb, ta, tb, bulge):
    """Exact minimum over [ta, tb] of ``flat(t) - bulge t (1 - t)``, the flat clearance
    linear with ``fa``, ``fb`` at the ends; ``min(fa, fb)`` (the same bits) for bulge 0."""
    if bulge == 0.0:
        return min(fa, fb)
    m = min(fa - bulge * ta * (1.0 - ta), fb - bulge * tb * (1.0 - tb))
    return min(m, _vertex_min(fa, fb, ta, tb, bulge))


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _tt_range(a0, a1):
    """(min, max) of t (1 - t) over [a0, a1] (the bulge's shape, largest at t = 1/2)."""
    f0 = a0 * (1.0 - a0)
    f1 = a1 * (1.0 - a1)
    hi = 0.25 if (a0 <= 0.5 and a1 >= 0.5) else max(f0, f1)
    return min(f0, f1), hi


@nb.njit(cache=True, nogil=True, inline="always")
def _cell_min(g, r, c, seg, t0, t1, with_t0, bulge):
    """Exact minimum clearance of the segment ``seg`` over [t0, t1] inside cell (r, c).

    The flat clearance is linear on each side of the cell diagonal, so its minimum is at
    t0, t1 or the diagonal crossing. ``with_t0`` False skips t0 (already evaluated as
    the end of the previous cell: the surface is continuous). With ``bulge > 0`` (earth
    curvature, see "Earth curvature") each side's convex clearance may also have its
    minimum inside (:func:`curved_min`), and every end is evaluated.

    Inlined into the walk (numba IR), like the walk itself into the pair loops (see
    "Kernel arguments").
    """
    z, xs, ys, ixw, iyw = g.z, g.xs, g.ys, g.ixw, g.iyw
    ax, ay, az, dx, dy, dz = seg
    td = cell_diagonal(xs, ys, ixw, iyw, r, c, (ax, ay, dx, dy))
    if bulge > 0.0:
        f0 = az + t0 * dz - cell_height(z, xs, ys, ixw, iyw, r, c, ax + t0 * dx, ay + t0 * dy)
        f1 = az + t1 * dz - cell_height(z, xs, ys, ixw, iyw, r, c, ax + t1 * dx, ay + t1 * dy)
        if td > t0 and td < t1:
            fd = az + td * dz - cell_height(z, xs, ys, ixw, iyw, r, c, ax + td * dx, ay + td * dy)
            return min(curved_min(f0, fd, t0, td, bulge), curved_min(fd, f1, td, t1, bulge))
        return curved_min(f0, f1, t0, t1, bulge)
    m = az + t1 * dz - cell_height(z, xs, ys, ixw, iyw, r, c, ax + t1 * dx, ay + t1 * dy)
    if with_t0:
        e = az + t0 * dz - cell_height(z, xs, ys, ixw, iyw, r, c, ax + t0 * dx, ay + t0 * dy)
        if e < m:
            m = e
    if td > t0 and td < t1:
        e = az + td * dz - cell_height(z, xs, ys, ixw, iyw, r, c, ax + td * dx, ay + td * dy)
        if e < m:
            m = e
    return m


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def new_stack(ltop):
    """A :data:`WalkStack` deep enough for a pyramid whose root level is ``ltop``.

    The descent pushes at most 3 children per level, so ``3 * ltop + 4`` entries suffice;
    ``3 * ltop + 8`` are allocated.
    """
    ns = 3 * ltop + 8
    return WalkStack(
        np.empty(ns, dtype=np.int64),
        np.empty(ns, dtype=np.int64),
        np.empty(ns, dtype=np.int64),
        np.empty(2 * ns, dtype=np.float64),
    )


@nb.njit(cache=True, nogil=True, inline="always")
def segment_min(g, seg, t0, t1, los, tol, bulge, st):
    """Minimum clearance of the segment ``seg`` = (ax, ay, az, dx, dy, dz), i.e. a + t*d, over [t0, t1].

    ``g`` is a :data:`~terrainvis.core.surface.SurfaceGrid`, ``st`` a :data:`WalkStack` (see :func:`new_stack`).
    With ``los`` False the result is the exact minimum (nodes that cannot lower the
    current best are skipped). With ``los`` True the walk stops as soon as the
    clearance is known to drop below ``-tol`` and skips every node whose lower bound is
    at least ``-tol``; the result is then only meaningful as ``result >= -tol``. The
    interval's ends t0 and t1 count like every crossing (the first and last cell
    evaluate them unless a bound already decides), so an interval that starts or ends
    underground is blocked.

    Every internal node of level >= 2 also probes the (true) clearance where the
    segment crosses the node's two mid lines (the surface is linear along a grid line):
    in ``los`` mode a mountain between the ends is found before the walk reaches it, and
    for the exact minimum the probes lower ``best`` early so that more nodes are pruned.

    ``bulge`` is ``k L**2`` (earth curvature, see "Earth curvature"; 0 for a flat earth):
    the clearance at t is lowered by ``bulge t (1 - t)``, and a node's bounds by the
    bulge's largest (skip test) or smallest (block test) value over its interval.
    """
    z, xs, ys, ixw, iyw = g.z, g.xs, g.ys, g.ixw, g.iyw
    pyr, off, nxl, uniform = g.pyr, g.off, g.nxl, g.uniform
    ax, ay, az, dx, dy, dz = seg
    track = (ax, ay, dx, dy)
    best = _INF
    stk = (st.level, st.row, st.col, st.t)
    sp = node_root(stk, g.ltop, t0, t1)
    last_t = -_INF
    while sp > 0:
        sp, L, R, C, a0, a1 = node_pop(stk, sp)
        if L == 0:
            m = _cell_min(g, R, C, seg, a0, a1, a0 != last_t, bulge)
            last_t = a1
            if m < best:
                best = m
                if los and best < -tol:
                    return best
            continue
        za0 = az + a0 * dz
        za1 = az + a1 * dz
        lo = min(za0, za1)
        k = off[L] + 2 * (R * nxl[L] + C)
        thr = -tol if los else best
        if bulge > 0.0:
            b_lo, b_hi = _tt_range(a0, a1)
            if lo - pyr[k + 1] - bulge * b_hi >= thr:
                continue
            if los:
                hi = max(za0, za1)
                if hi - pyr[k] - bulge * b_lo < -tol:
                    return hi - pyr[k] - bulge * b_lo
        else:
            if lo - pyr[k + 1] >= thr:
                continue
            if los:
                hi = max(za0, za1)
                if hi - pyr[k] < -tol:
                    return hi - pyr[k]
        node = (L, R, C, a0, a1)
        split = node_split(xs, ys, node, track)
        cm, rm, tx, ty = split
        if L >= 2:
            # probe the clearance where the track crosses the mid lines (the surface is
            # linear along a grid line)
            if tx < _INF:
                e = az + tx * dz - mid_height(z, xs, ys, ixw, iyw, uniform, node, True, cm, ay + tx * dy)
                if bulge > 0.0:
                    e -= bulge * tx * (1.0 - tx)
                if e < best:
                    best = e
                    if los and best < -tol:
                        return best
            if ty < _INF:
                e = az + ty * dz - mid_height(z, xs, ys, ixw, iyw, uniform, node, False, rm, ax + ty * dx)
                if bulge > 0.0:
                    e -= bulge * ty * (1.0 - ty)
                if e < best:
                    best = e
                    if los and best < -tol:
                        return best
        sp = node_push(stk, sp, xs, ys, node, split, track)
    return best


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _canonical(a, b):
    """The segment between the points ``a``, ``b`` (3-tuples) as (ax, ay, az, dx, dy, dz)
    walked from its lexicographically smaller end, so that (a, b) and (b, a) give
    identical bits, and its 3-D length."""
    ax, ay, az = a
    bx, by, bz = b
    if (bx < ax) or (bx == ax and (by < ay or (by == ay and bz < az))):
        ax, bx = bx, ax
        ay, by = by, ay
        az, bz = bz, az
    dx = bx - ax
    dy = by - ay
    dz = bz - az
    return (ax, ay, az, dx, dy, dz), np.sqrt(dx * dx + dy * dy + dz * dz)


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def interval_start(seg, length, delta, end_radius):
    """Start t0 of the tested interval [t0, 1 - t0] of a segment, or -1.0 when it has none.

    ``t0 = max(delta / length, end_radius / horizontal length)``. Nothing is tested (the
    segment is visible, its clearance ``inf``) when ``length <= 2 delta`` or, for
    ``end_radius > 0``, when the horizontal length is at most ``2 end_radius``. With
    ``end_radius = 0`` this is exactly the trim ``tau = delta / length``.
    """
    if length <= 2.0 * delta:
        return -1.0
    t0 = delta / length
    if end_radius > 0.0:
        dx = seg[3]
        dy = seg[4]
        lh = np.sqrt(dx * dx + dy * dy)
        if lh <= 2.0 * end_radius:
            return -1.0
        tr = end_radius / lh
        if tr > t0:
            t0 = tr
    return t0


@nb.njit(cache=True, nogil=True, inline="always")
def _pair_min(g, a, b, delta, end_radius, los, tol, kc, st):
    """Clearance of the segment between the points ``a``, ``b`` (3-tuples): canonical
    direction, tested interval from the trim and the end radius, earth curvature ``kc``
    (see "Earth curvature")."""
    seg, length = _canonical(a, b)
    t0 = interval_start(seg, length, delta, end_radius)
    if t0 < 0.0:
        return _INF
    return segment_min(g, seg, t0, 1.0 - t0, los, tol, kc * (seg[3] * seg[3] + seg[4] * seg[4]), st)


#: Segments per iteration of :func:`grid_walks` (segment mode).
PAIR_CHUNK = 512


def grid_walk_iterations(n_points: int, n_segments: int, matrix: bool) -> int:
    """The iterations of :func:`grid_walks`'s loop: pairs of rows of a matrix of ``n_points``,
    or chunks of :data:`PAIR_CHUNK` of ``n_segments`` segments."""
    return (n_points + 1) // 2 if matrix else (n_segments + PAIR_CHUNK - 1) // PAIR_CHUNK


@nb.njit(cache=True, nogil=True, error_model="numpy")
def grid_walks(g, a, b, index, pred, clear, vis, it0, it1, stop):
    """Iterations ``it0 .. it1 - 1`` of the pair loops of the grid walk: segments or a
    visibility matrix (see "Compile time"); :func:`terrainvis.core.interrupt.call` spreads
    the :func:`grid_walk_iterations` iterations over threads.

    ``g`` is a :data:`~terrainvis.core.surface.SurfaceGrid`; ``a``, ``b`` (m, 3) float64 in
    its local coordinates; ``pred`` the predicate ``(delta, end_radius, los, tol, kc)``:
    trim, end radius, the LOS mode of :func:`segment_min`, tolerance and the curvature
    coefficient over twice the earth's radius (0: flat). ``stop`` is the stop flag of
    :mod:`terrainvis.core.interrupt`, read at the start of every iteration (the loop
    returns when it is set; the partial result is then never used).

    * Segments, ``vis`` empty (shape (0, 0)): ``clear[index[k]]`` = clearance of the
      segment ``a[index[k]] -> b[index[k]]`` (``los`` as in :func:`segment_min`; ``index``
      the order to walk them in), :data:`PAIR_CHUNK` segments per iteration.
    * Matrix, ``vis`` (n, n) bool: the verdict of every pair of the points ``a`` (already
      in walk order; ``b`` is ``a``; ``los`` True, ``clear`` unused). Row k and row n-1-k
      are handled by the same iteration so every iteration has n-1 pairs (balanced load).
      Result (i, j) of the ordered points goes to ``vis[index[i], index[j]]`` and its
      mirror (``index`` the permutation that ordered them); the diagonal is set True.
    """
    delta, end_radius, los, tol, kc = pred
    matrix = vis.shape[0] > 0
    n = a.shape[0]
    m = index.shape[0]
    # views without reference counts, made once (see terrainvis.core.surface.borrow): a
    # prange body's arrays had none, and this loop's atomic counts took half its time
    g = borrow_grid(g)
    a = borrow(a)
    b = borrow(b)
    index = borrow(index)
    clear = borrow(clear)
    vis = borrow(vis)
    st_own = new_stack(g.ltop)
    st = WalkStack(borrow(st_own.level), borrow(st_own.row), borrow(st_own.col), borrow(st_own.t))
    for it in range(it0, it1):
        if stopped(stop):
            return
        kk = np.int64(it)
        for h in range(2 if matrix else 1):
            i = kk
            pi = 0
            if matrix:
                if h == 1:
                    i = np.int64(n - 1) - kk
                    if i == kk:
                        break
                lo = i + 1
                hi = n
                pi = index[i]
                vis[pi, pi] = True
            else:
                lo = kk * PAIR_CHUNK
                hi = min(m, lo + PAIR_CHUNK)
            for j in range(lo, hi):
                ia = i if matrix else index[j]
                ib = j if matrix else ia
                c = _pair_min(g, (a[ia, 0], a[ia, 1], a[ia, 2]), (b[ib, 0], b[ib, 1], b[ib, 2]), delta, end_radius,
                              los, tol, kc, st)
                if matrix:
                    seen = c >= -tol
                    pj = index[j]
                    vis[pi, pj] = seen
                    vis[pj, pi] = seen
                else:
                    clear[ia] = c
    keep_alive(st_own)


# --------------------------------------------------------------------------- TIN
@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _face_clip_min(mesh, f, seg, t0, t1, eps, bulge):
    """Min clearance of the segment over the part of [t0, t1] whose ground track is in face f
    (with ``bulge > 0``, the earth-curvature term: see :func:`curved_min`)."""
    vx, vy, vz = mesh.vx, mesh.vy, mesh.vz
    i0 = mesh.faces[f, 0]
    i1 = mesh.faces[f, 1]
    i2 = mesh.faces[f, 2]
    ax, ay, az, dx, dy, dz = seg
    x0 = vx[i0]
    y0 = vy[i0]
    x1 = vx[i1]
    y1 = vy[i1]
    x2 = vx[i2]
    y2 = vy[i2]
    det = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
    if det == 0.0:
        return _INF
    sgn = 1.0 if det > 0.0 else -1.0
    lo = t0
    hi = t1
    for e in range(3):
        if e == 0:
            px = x0
            py = y0
            qx = x1
            qy = y1
        elif e == 1:
            px = x1
            py = y1
            qx = x2
            qy = y2
        else:
            px = x2
            py = y2
            qx = x0
            qy = y0
        ex = qx - px
        ey = qy - py
        # f(t) = cross(e, A + t D - p) * sgn >= -eps * |e|
        f0 = sgn * (ex * (ay - py) - ey * (ax - px)) + eps * (abs(ex) + abs(ey))
        f1 = sgn * (ex * dy - ey * dx)
        if f1 == 0.0:
            if f0 < 0.0:
                return _INF
        elif f1 > 0.0:
            t = -f0 / f1
            if t > lo:
                lo = t
        else:
            t = -f0 / f1
            if t < hi:
                hi = t
        if lo > hi:
            return _INF
    best = _INF
    f_lo = _INF
    for q in range(2):
        t = lo if q == 0 else hi
        _, l1, l2 = barycentric(vx, vy, i0, i1, i2, ax + t * dx, ay + t * dy)
        zs = weighted(vz, i0, i1, i2, l1, l2)
        c = az + t * dz - zs
        if q == 0:
            f_lo = c
        if c < best:
            best = c
    if bulge > 0.0:
        return curved_min(f_lo, c, lo, hi, bulge)
    return best


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _tin_segment_min(mesh, seg, t0, t1, eps, bulge):
    """Exact minimum clearance of the segment ``seg`` over [t0, t1] on the :data:`~terrainvis.core.surface.SurfaceTin`.

    The buckets the ground track passes through are visited (widened by
    :data:`~terrainvis.tolerances.BUCKET_SLACK_REL` of a bucket, far more than rounding
    and the clip's ``eps``): a face holds the part of the track it is crossed by, so its
    bounding box, and so one of its buckets, holds a point of the track. Every face in
    them is clipped against the track and the clearance is evaluated at the clip points
    (the minimum of a piecewise-linear function is at a breakpoint; under earth
    curvature, ``bulge > 0``, at a breakpoint or at the vertex of one face's convex
    clearance). A face in several of the buckets is clipped once per bucket (the same
    value: the minimum does not change).
    """
    x0, y0, bw, bh, nbx, nby = mesh.x0, mesh.y0, mesh.bw, mesh.bh, mesh.nbx, mesh.nby
    starts, items = mesh.starts, mesh.items
    ax, ay, dx, dy = seg[0], seg[1], seg[3], seg[4]
    sx = BUCKET_SLACK_REL * bw
    sy = BUCKET_SLACK_REL * bh
    ya = ay + t0 * dy
    yb = ay + t1 * dy
    by0 = max(int(np.floor((min(ya, yb) - sy - y0) / bh)), 0)
    by1 = min(int(np.floor((max(ya, yb) + sy - y0) / bh)), nby - 1)
    best = _INF
    for rb in range(by0, by1 + 1):
        # the part of the track inside this bucket row (widened by the slack)
        lo = t0
        hi = t1
        if dy != 0.0:
            ta = (y0 + rb * bh - sy - ay) / dy
            tb = (y0 + (rb + 1) * bh + sy - ay) / dy
            if ta > tb:
                ta, tb = tb, ta
            lo = max(lo, ta)
            hi = min(hi, tb)
            if lo > hi:
                continue
        xa = ax + lo * dx
        xb = ax + hi * dx
        bx0 = max(int(np.floor((min(xa, xb) - sx - x0) / bw)), 0)
        bx1 = min(int(np.floor((max(xa, xb) + sx - x0) / bw)), nbx - 1)
        for cb in range(bx0, bx1 + 1):
            bk = rb * nbx + cb
            for s in range(starts[bk], starts[bk + 1]):
                c = _face_clip_min(mesh, items[s], seg, t0, t1, eps, bulge)
                if c < best:
                    best = c
    return best


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _tin_pair(mesh, a, b, i, delta, end_radius, eps, kc):
    """Exact minimum clearance of segment ``i`` (rows of ``a``, ``b``) over the TIN, as
    :func:`tin_pairs` gives it (infinite when the segment is shorter than its end radii)."""
    seg, length = _canonical((a[i, 0], a[i, 1], a[i, 2]), (b[i, 0], b[i, 1], b[i, 2]))
    t0 = interval_start(seg, length, delta, end_radius)
    if t0 < 0.0:
        return _INF
    return _tin_segment_min(mesh, seg, t0, 1.0 - t0, eps, kc * (seg[3] * seg[3] + seg[4] * seg[4]))


#: Segments per iteration of :func:`tin_pairs`.
TIN_CHUNK = 64


@nb.njit(cache=True, nogil=True)
def tin_pairs(mesh, a, b, delta, end_radius, eps, kc, out, k0, k1, stop):
    """Exact minimum clearance of each segment over a TIN (clip against every face crossed),
    for the segments of chunks ``k0 .. k1 - 1`` of :data:`TIN_CHUNK`
    (:func:`terrainvis.core.interrupt.call` spreads the chunks over threads).

    ``mesh`` is a :data:`~terrainvis.core.surface.SurfaceTin`; ``a``, ``b`` (m, 3) float64 in its local coordinates;
    ``kc`` the curvature coefficient over twice the earth's radius (0: flat). The segment
    is tested over the interval of :func:`interval_start` (see :func:`_tin_segment_min`).
    The loop returns once the stop flag ``stop`` is set (:mod:`terrainvis.core.interrupt`).
    """
    m = a.shape[0]
    # views without reference counts (see grid_walks): each face clipped read the mesh's arrays
    mesh = borrow_tin(mesh)
    a = borrow(a)
    b = borrow(b)
    out = borrow(out)
    for k in range(k0, k1):
        if stopped(stop):
            return
        for i in range(k * TIN_CHUNK, min(m, (k + 1) * TIN_CHUNK)):
            out[i] = _tin_pair(mesh, a, b, i, delta, end_radius, eps, kc)
