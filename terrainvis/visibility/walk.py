"""The walk along a sight line over a grid, written once: the cell-by-cell cursor and the
pyramid descent's bookkeeping (numba primitives).

Every kernel that follows a ground track across a grid visits the same *breakpoints*:
the ends of its tested interval, its crossings of grid lines and its crossings of cell
diagonals (between two breakpoints the surface along the track is linear). The walks
here find them; each consumer keeps only its own reduction of the surface there:

* the pair engine (:mod:`terrainvis.visibility._kernels`): the least clearance;
* the viewshed sweep (:mod:`terrainvis.visibility.viewsheds._walk_kernels`): the least clearance,
  on grids with nodata too;
* the threshold engine (:mod:`terrainvis.visibility._threshold_kernels`): the largest
  height a point needs;
* visopt (:mod:`simplifiers._visopt_kernels`): the breakpoints themselves.

A track is the 4-tuple ``seg = (ax, ay, dx, dy)`` of the ground points ``a + t d``; the
grid is read through its coordinates ``xs``, ``ys`` (local, from 0), inverse widths
``ixw``, ``iyw`` and ``uniform`` (as in :data:`~terrainvis.core.surface.SurfaceGrid`).
Every crossing parameter is computed one way, ``(line - a) / d``, so the consumers'
breakpoints are the same numbers bit for bit (``tests/visibility/test_one_walk.py``).

The cell-by-cell cursor
-----------------------
:func:`cells_start` puts a :data:`Cells` cursor on the first cell of the track, with its
piece ``[t, tn]``; :func:`cells_next` moves it to the next cell (``r`` = -1 once the
track leaves the grid). A consumer's loop::

    cur = cells_start(xs, ys, ixw, iyw, uniform, seg, t0, t1)
    while True:
        ...  # the piece [cur.t, cur.tn] in cell (cur.r, cur.c); cell_diagonal() inside it
        if cur.tn >= t1:
            break
        cur = cells_next(xs, ys, cur, seg, t1)
        if cur.r < 0:
            break

The helpers are plain numba functions compiled without numba's runtime (``_nrt=False``:
they allocate nothing), which LLVM inlines into the consumers' loops: no allocation and
no reference count. Inlined at numba IR level instead (``inline="always"``), each step
bound the grid's arrays to the helper's parameters anew, with a reference-count
increment and decrement per array, and the walks were slower than the copies they
replace. The pair engine's parallel loop is the exception: there the plain calls stay
calls, so it takes the descent helpers' IR-inlined twins (``node_pop_inline``, ...),
compiled from the same source.

The pyramid descent
-------------------
The min/max pyramid (``pyr``, ``off``, ``nxl``, ``ltop``: see
:mod:`terrainvis.visibility._kernels`) is descended near-first with an explicit stack (the arrays
``stk = (level, row, col, t)`` of a :data:`~terrainvis.visibility._kernels.WalkStack`). A consumer pops a node
(:func:`node_pop`), decides from the node's bounds whether to skip it (its own test),
splits its interval where the track crosses the node's two mid lines
(:func:`node_split`), may probe the surface there (:func:`mid_height`) and pushes the
children far-first (:func:`node_push`), so that the near ones pop first; at level 0 it
evaluates the cell (its own reduction).

Two pieces stay with their consumers: the loop of the descent (the pair engine's
``segment_min``, the threshold engine's ``grid_max_slope``) and a cell's least clearance
(the pair engine's ``_cell_min``, the viewshed walk's ``_cell_piece``, which evaluate the
surface with different rounding). Written once here, with each consumer's functions
passed in, they gave the same bits and run times but compiled the pair engine 10-30 %
longer (numba inlines each function passed at every call site; docs/performance.md,
"Cell clearance and descent written once: tried, not kept").
"""

from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from ..core.compiling import KERNEL_ONLY
from ..core.surface import line_height, locate

_INF = np.inf
#: The walk's helpers allocate nothing and are compiled without numba's runtime (no
#: reference counts on the arrays they take), as plain calls that LLVM inlines.
_STEP = {"cache": True, "nogil": True, "_nrt": False}

#: The cell-by-cell cursor: the cell ``(r, c)`` (``r`` = -1: the track left the grid), its
#: piece ``[t, tn]`` of the track, and the parameters ``tx``, ``ty`` at which the track
#: crosses the cell's far vertical and horizontal grid lines (inf: never).
Cells = namedtuple("Cells", ["r", "c", "t", "tn", "tx", "ty"])


# --------------------------------------------------------------------------- cells
@nb.njit(**_STEP, **KERNEL_ONLY)
def _piece(xs, ys, r, c, seg, t, t1):
    """The cursor on cell (r, c) entered at t."""
    ax, ay, dx, dy = seg
    tx = _INF
    ty = _INF
    if dx > 0.0:
        tx = (xs[c + 1] - ax) / dx
    elif dx < 0.0:
        tx = (xs[c] - ax) / dx
    if dy > 0.0:
        ty = (ys[r + 1] - ay) / dy
    elif dy < 0.0:
        ty = (ys[r] - ay) / dy
    tn = min(tx, ty, t1)
    if tn < t:
        tn = t
    return Cells(r, c, t, tn, tx, ty)


@nb.njit(**_STEP, **KERNEL_ONLY)
def cells_start(xs, ys, ixw, iyw, uniform, seg, t0, t1):
    """The cursor on the cell of the track ``seg`` at t0 (on a grid line while the track
    moves backwards, the cell behind the line: the one it enters), over [t0, t1]."""
    ax, ay, dx, dy = seg
    x = ax + t0 * dx
    y = ay + t0 * dy
    c = locate(xs, ixw, 0, xs.shape[0] - 1, uniform, x)
    r = locate(ys, iyw, 0, ys.shape[0] - 1, uniform, y)
    if dx < 0.0 and c > 0 and x <= xs[c]:
        c -= 1
    if dy < 0.0 and r > 0 and y <= ys[r]:
        r -= 1
    return _piece(xs, ys, r, c, seg, t0, t1)


@nb.njit(**_STEP, **KERNEL_ONLY)
def cells_next(xs, ys, cur, seg, t1):
    """The cursor on the cell after ``cur`` (across the grid lines the track crosses at
    ``cur.tn``, both at a corner), or with ``r`` = -1 when the track leaves the grid."""
    dx = seg[2]
    dy = seg[3]
    c = cur.c
    r = cur.r
    if cur.tx <= cur.tn:
        c += 1 if dx > 0.0 else -1
    if cur.ty <= cur.tn:
        r += 1 if dy > 0.0 else -1
    if c < 0 or c > xs.shape[0] - 2 or r < 0 or r > ys.shape[0] - 2:
        return Cells(-1, c, cur.tn, cur.tn, _INF, _INF)
    return _piece(xs, ys, r, c, seg, cur.tn, t1)


@nb.njit(**_STEP, **KERNEL_ONLY)
def cell_diagonal(xs, ys, ixw, iyw, r, c, seg):
    """The parameter at which the track crosses the diagonal of cell (r, c) (its line from
    (r, c) to (r + 1, c + 1)), or -inf when the track runs parallel to it."""
    ax, ay, dx, dy = seg
    den = dx * ixw[c] - dy * iyw[r]
    if den == 0.0:
        return -_INF
    return ((ay - ys[r]) * iyw[r] - (ax - xs[c]) * ixw[c]) / den


# --------------------------------------------------------------------------- pyramid
def _node_pop(stk, sp):
    """The node on top of the stack ``stk = (level, row, col, t)`` (the arrays of a
    :data:`~terrainvis.visibility._kernels.WalkStack`) of ``sp`` entries: (sp - 1, level,
    row, col, a0, a1)."""
    sL, sR, sC, sT = stk
    sp -= 1
    return sp, sL[sp], sR[sp], sC[sp], sT[2 * sp], sT[2 * sp + 1]


def _node_root(stk, ltop, t0, t1):
    """Push the root (level ``ltop``) over [t0, t1] on the empty stack ``stk``; returns its size, 1."""
    sL, sR, sC, sT = stk
    sL[0] = ltop
    sR[0] = 0
    sC[0] = 0
    sT[0] = t0
    sT[1] = t1
    return 1


def _node_split(xs, ys, node, seg):
    """Where the track crosses the mid lines of ``node = (L, R, C, a0, a1)`` (L >= 1) inside
    (a0, a1): ``(cm, rm, tx, ty)``, the mid column and row and their crossing parameters
    (inf where there is no such crossing: no mid line, parallel, or outside)."""
    L, R, C, a0, a1 = node
    ax, ay, dx, dy = seg
    half = 1 << (L - 1)
    cm = (C << L) + half
    rm = (R << L) + half
    tx = _INF
    ty = _INF
    if cm < xs.shape[0] - 1 and dx != 0.0:
        t = (xs[cm] - ax) / dx
        if t > a0 and t < a1:
            tx = t
    if rm < ys.shape[0] - 1 and dy != 0.0:
        t = (ys[rm] - ay) / dy
        if t > a0 and t < a1:
            ty = t
    return cm, rm, tx, ty


def _mid_height(z, xs, ys, ixw, iyw, uniform, node, vertical, m, w):
    """The surface height on a mid line of ``node`` at the coordinate ``w`` along it: the
    vertical line x = xs[m] (``vertical``; w a y) or the horizontal line y = ys[m]."""
    L, R, C, a0, a1 = node
    if vertical:
        r = locate(ys, iyw, R << L, min((R + 1) << L, ys.shape[0] - 1), uniform, w)
        v = min(max((w - ys[r]) * iyw[r], 0.0), 1.0)
        return line_height(z, r, m, True, v)
    c = locate(xs, ixw, C << L, min((C + 1) << L, xs.shape[0] - 1), uniform, w)
    u = min(max((w - xs[c]) * ixw[c], 0.0), 1.0)
    return line_height(z, m, c, False, u)


def _node_push(stk, sp, xs, ys, node, split, seg):
    """Push the children of ``node`` cut at the crossings ``split = (cm, rm, tx, ty)``
    (:func:`node_split`) far-first, so that the nearest pops first; returns the new size."""
    sL, sR, sC, sT = stk
    L, R, C, a0, a1 = node
    cm, rm, tx, ty = split
    ax, ay, dx, dy = seg
    splitx = cm < xs.shape[0] - 1
    splity = rm < ys.shape[0] - 1
    s1 = tx
    s2 = _INF
    if ty < _INF:
        if ty < s1:
            s2 = s1
            s1 = ty
        else:
            s2 = ty
    # boundaries a0 < s1 < s2 < a1 (missing ones are inf)
    nb_ = 1
    if s1 < _INF:
        nb_ = 2
        if s2 < _INF:
            nb_ = 3
    for q in range(nb_ - 1, -1, -1):
        if q == 0:
            b0 = a0
        elif q == 1:
            b0 = s1
        else:
            b0 = s2
        if q == nb_ - 1:
            b1 = a1
        elif q == 0:
            b1 = s1
        else:
            b1 = s2
        tm = 0.5 * (b0 + b1)
        cc = 2 * C
        rr = 2 * R
        if splitx and ax + tm * dx >= xs[cm]:
            cc += 1
        if splity and ay + tm * dy >= ys[rm]:
            rr += 1
        sL[sp] = L - 1
        sR[sp] = rr
        sC[sp] = cc
        sT[2 * sp] = b0
        sT[2 * sp + 1] = b1
        sp += 1
    return sp


# Each descent helper twice, from the one source above: plain and without the runtime for
# the serial walks (the thresholds), inlined at numba IR level for the pair engine's
# parallel loop (there the plain calls are not inlined by LLVM, and every node paid them;
# the IR-inlined twins count no references there, the arrays being bound once per walk).
# The inlined twins are never cached (numba inlines their source).
_INLINE = {"cache": False, "nogil": True, "inline": "always"}
node_pop, node_pop_inline = nb.njit(**_STEP)(_node_pop), nb.njit(**_INLINE)(_node_pop)
node_root, node_root_inline = nb.njit(**_STEP)(_node_root), nb.njit(**_INLINE)(_node_root)
node_split, node_split_inline = nb.njit(**_STEP)(_node_split), nb.njit(**_INLINE)(_node_split)
mid_height, mid_height_inline = nb.njit(**_STEP)(_mid_height), nb.njit(**_INLINE)(_mid_height)
node_push, node_push_inline = nb.njit(**_STEP)(_node_push), nb.njit(**_INLINE)(_node_push)
