"""The surface of a grid and of a TIN as numba kernels read it, written once.

Every kernel family (the terrain's own lookups, the LOS pair engines, the viewshed sweep,
the calibration thresholds, the simplifiers) evaluates the same piecewise-linear surface;
the primitives here are its only definition, so that the families agree bit for bit.

The grid's surface
------------------
Cell (r, c) of a rectilinear grid is split along its diagonal from sample (r, c) to
sample (r + 1, c + 1). With the local coordinates ``u = (x - xs[c]) / (xs[c + 1] - xs[c])``
and ``v = (y - ys[r]) / (ys[r + 1] - ys[r])`` of a point in the cell, the *lower* triangle
(``u >= v``) has the corners (r, c), (r, c + 1), (r + 1, c + 1) and the *upper* one
(``v > u``) the corners (r, c), (r + 1, c), (r + 1, c + 1) (:func:`plane_uv`). The kernels
compute ``u`` and ``v`` with the inverse widths ``ixw[c] = 1 / (xs[c + 1] - xs[c])`` and
``iyw[r] = 1 / (ys[r + 1] - ys[r])`` (:func:`cell_height`, :func:`tri_height`);
:meth:`terrainvis.HeightGrid.height_at` divides by the widths (:func:`cell_height_div`).

The TIN's surface
-----------------
Face f's plane is interpolated with barycentric weights from its three vertices
(:func:`barycentric`, :func:`face_height`); :func:`face_at` finds the face under a point
through the uniform bucket grid of ``TIN._buckets()``.

Records
-------
:data:`SurfaceGrid` and :data:`SurfaceTin` are the grid and the TIN as every kernel
family reads them (named tuples of arrays and scalars); a family leaves the arrays it
does not use empty. A kernel that calls a walk many times first rebuilds the record from
views without reference counts (:func:`borrow_grid`, :func:`borrow_tin`, :func:`borrow`).
"""

from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np
from numba.core import cgutils
from numba.core import types as nbtypes
from numba.extending import intrinsic
from numba.np.arrayobj import make_array

from ..tolerances import TRACK_FACE_SLACK
from .compiling import KERNEL_ONLY
from .stopflag import stopped

_INF = np.inf

#: A grid as the kernels read it, in local coordinates (origin at ``xs[0], ys[0]``):
#: ``z`` (rows, cols) float64 heights, or float32 (NaN: nodata; the viewshed's kernels take a
#: float32 raster's own samples, :attr:`terrainvis.HeightGrid.heights`: every kernel reads a
#: height as ``np.float64(z[r, c])``, so that its answers are the float64 grid's bit for bit,
#: as a difference of two float32 heights computed in float32 would be rounded); ``xs`` (cols,) and ``ys`` (rows,)
#: float64 coordinates; ``ixw`` (cols - 1,) and ``iyw`` (rows - 1,) float64 inverse cell
#: widths; ``uniform`` (bool) both spacings uniform; ``has_nan`` (bool) the grid holds
#: nodata. The accelerations of the LOS engines, empty where a family does not use them:
#: ``pyr`` (k,) float32 min/max pyramid with its level tables ``off`` and ``nxl`` (ltop + 1,)
#: int64 and ``ltop`` (int) its root level (:mod:`terrainvis.visibility._kernels`);
#: ``cmax`` (segments, cols) and ``rmax`` (rows, segments) float32 the strip maxima of the
#: viewshed sweep, rounded up (:mod:`terrainvis.visibility.viewsheds._sector_kernels`).
SurfaceGrid = namedtuple(
    "SurfaceGrid", ["z", "xs", "ys", "ixw", "iyw", "uniform", "has_nan", "pyr", "off", "nxl", "ltop", "cmax", "rmax"]
)

#: A TIN as the kernels read it: vertices ``vx``, ``vy``, ``vz`` (n,) float64; ``faces``
#: (m, 3) vertex indices, counter-clockwise; ``nbr`` (m, 3) int64 the face across edge
#: (faces[f, e], faces[f, (e + 1) % 3]) or -1 on the boundary (empty, shape (0, 3), where a
#: family does not walk from face to face); the uniform bucket grid of ``TIN._buckets()``:
#: ``starts`` (nbx * nby + 1,) and ``items`` the faces of each bucket (CSR), ``x0``, ``y0``
#: its corner, ``bw``, ``bh`` its bucket sizes, ``nbx``, ``nby`` its buckets per row and column.
SurfaceTin = namedtuple(
    "SurfaceTin", ["vx", "vy", "vz", "faces", "nbr", "starts", "items", "x0", "y0", "bw", "bh", "nbx", "nby"]
)


def no_pyramid():
    """The empty pyramid fields ``(pyr, off, nxl, ltop)`` of a :data:`SurfaceGrid`."""
    return np.empty(0, dtype=np.float32), np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64), 0


def no_strips():
    """The empty strip maxima ``(cmax, rmax)`` of a :data:`SurfaceGrid` (float32, as the sweep's)."""
    return np.empty((0, 0), dtype=np.float32), np.empty((0, 0), dtype=np.float32)


def no_neighbours():
    """The empty ``nbr`` of a :data:`SurfaceTin`."""
    return np.empty((0, 3), dtype=np.int64)


# --------------------------------------------------------------------------- borrowed arrays
@intrinsic
def borrow(typingctx, arr):
    """A view of ``arr`` without its reference count (no meminfo): valid while ``arr`` is.

    Numba counts references to every array a function receives or binds, with atomic
    operations on the array's shared counter; in large kernels its pruning pass leaves
    most of them, so each call of a walk paid about twenty atomic increments and
    decrements (both threads bouncing the same counters). Views from this function have
    no counter: their increments and decrements are a test of a null pointer. A kernel
    makes them once (per sector, per row), from arrays that stay alive until it returns.
    """
    if not isinstance(arr, nbtypes.Array):
        return None

    def codegen(context, builder, sig, args):
        src = make_array(arr)(context, builder, value=args[0])
        dst = make_array(arr)(context, builder)
        dst.data = src.data
        dst.shape = src.shape
        dst.strides = src.strides
        dst.itemsize = src.itemsize
        dst.nitems = src.nitems
        dst.meminfo = cgutils.get_null_value(dst.meminfo.type)
        dst.parent = cgutils.get_null_value(dst.parent.type)
        return dst._getvalue()

    return arr(arr), codegen


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def keep_alive(owners):
    """Nothing: a use of ``owners`` at the end of a kernel that :func:`borrow` ed views of
    arrays it made itself (numba frees an array after its last use)."""
    return None


@nb.njit(cache=True, nogil=True, inline="always")
def borrow_grid(g):
    """The :data:`SurfaceGrid` ``g`` with every array :func:`borrow` ed (valid while ``g``'s arrays are)."""
    return SurfaceGrid(borrow(g.z), borrow(g.xs), borrow(g.ys), borrow(g.ixw), borrow(g.iyw), g.uniform, g.has_nan,
                       borrow(g.pyr), borrow(g.off), borrow(g.nxl), g.ltop, borrow(g.cmax), borrow(g.rmax))


@nb.njit(cache=True, nogil=True, inline="always")
def borrow_tin(t):
    """The :data:`SurfaceTin` ``t`` with every array :func:`borrow` ed (valid while ``t``'s arrays are)."""
    return SurfaceTin(borrow(t.vx), borrow(t.vy), borrow(t.vz), borrow(t.faces), borrow(t.nbr), borrow(t.starts),
                      borrow(t.items), t.x0, t.y0, t.bw, t.bh, t.nbx, t.nby)


# --------------------------------------------------------------------------- grid
@nb.njit(cache=True, nogil=True, inline="always")
def locate(v, iw, lo, hi, uniform, x):
    """Index i in [lo, hi) with v[i] <= x < v[i+1] (clamped), v increasing local coordinates from 0.

    ``uniform`` True: a guess from the first inverse spacing ``iw[0]``, corrected against
    the coordinates; otherwise a binary search (``iw`` unused). Both give the index
    ``clip(searchsorted(v, x, "right") - 1, lo, hi - 1)`` for any non-NaN x.
    """
    if uniform:
        i = int(x * iw[0])
        if i < lo:
            i = lo
        elif i > hi - 1:
            i = hi - 1
        while i > lo and v[i] > x:
            i -= 1
        while i < hi - 1 and v[i + 1] <= x:
            i += 1
    else:
        a = lo
        b = hi
        while b - a > 1:
            mid = (a + b) >> 1
            if v[mid] <= x:
                a = mid
            else:
                b = mid
        i = a
    if i < lo:
        i = lo
    elif i > hi - 1:
        i = hi - 1
    return i


@nb.njit(cache=True, nogil=True, inline="always")
def tri_uv(z, r, c, upper, u, v):
    """Height of one triangle of cell (r, c) (``upper`` False: the lower one, u >= v) at the
    cell's local coordinates (u, v), extended as a plane beyond the triangle. Each height is
    read as float64 (:data:`SurfaceGrid`)."""
    z00 = np.float64(z[r, c])
    z11 = np.float64(z[r + 1, c + 1])
    if not upper:
        z01 = np.float64(z[r, c + 1])
        return z00 + u * (z01 - z00) + v * (z11 - z01)
    z10 = np.float64(z[r + 1, c])
    return z00 + v * (z10 - z00) + u * (z11 - z10)


@nb.njit(cache=True, nogil=True, inline="always")
def plane_uv(z, r, c, u, v):
    """Height of cell (r, c)'s surface at its local coordinates (u, v): the triangle holding them."""
    return tri_uv(z, r, c, v > u, u, v)


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def cell_height(z, xs, ys, ixw, iyw, r, c, x, y):
    """Height of cell (r, c)'s surface at (x, y), local coordinates clamped into the cell."""
    u = (x - xs[c]) * ixw[c]
    v = (y - ys[r]) * iyw[r]
    if u < 0.0:
        u = 0.0
    elif u > 1.0:
        u = 1.0
    if v < 0.0:
        v = 0.0
    elif v > 1.0:
        v = 1.0
    return plane_uv(z, r, c, u, v)


@nb.njit(cache=True, nogil=True, inline="always")
def tri_height(z, xs, ys, ixw, iyw, r, c, upper, x, y):
    """Height of the plane of one triangle of cell (r, c) at (x, y) (not clamped)."""
    u = (x - xs[c]) * ixw[c]
    v = (y - ys[r]) * iyw[r]
    return tri_uv(z, r, c, upper, u, v)


@nb.njit(cache=True, nogil=True, inline="always")
def line_height(z, r, c, vertical, s):
    """Height on a grid line at its local coordinate s in [0, 1]: ``vertical`` the line
    x = xs[c] from row r to r + 1, otherwise the line y = ys[r] from column c to c + 1."""
    z0 = np.float64(z[r, c])
    if vertical:
        return z0 + s * (np.float64(z[r + 1, c]) - z0)
    return z0 + s * (np.float64(z[r, c + 1]) - z0)


@nb.njit(cache=True, nogil=True)
def heights_at(z, xs, ys, qx, qy, out, stop):
    """Height of the grid's surface at each point (qx[i], qy[i]) inside its extent (the
    others keep what the caller put in ``out``); u and v divide by the cell widths.

    ``stop`` is the stop flag (:mod:`terrainvis.core.interrupt`), read every 4096 points.
    """
    nc = xs.shape[0]
    nr = ys.shape[0]
    for i in range(qx.shape[0]):
        if i % 4096 == 0 and stopped(stop):
            return
        x = qx[i]
        y = qy[i]
        if not (x >= xs[0] and x <= xs[nc - 1] and y >= ys[0] and y <= ys[nr - 1]):
            continue
        c = locate(xs, xs, 0, nc - 1, False, x)
        r = locate(ys, ys, 0, nr - 1, False, y)
        u = (x - xs[c]) / (xs[c + 1] - xs[c])
        v = (y - ys[r]) / (ys[r + 1] - ys[r])
        out[i] = plane_uv(z, r, c, u, v)


# --------------------------------------------------------------------------- TIN
@nb.njit(cache=True, nogil=True, inline="always")
def barycentric(vx, vy, i0, i1, i2, x, y):
    """(det, l1, l2): twice the signed area of triangle (i0, i1, i2) and the barycentric
    weights of (x, y) on i1 and i2 (the weight on i0 is ``1 - l1 - l2``). ``det`` 0 (a
    degenerate triangle) gives non-finite weights."""
    x0 = vx[i0]
    y0 = vy[i0]
    x1 = vx[i1]
    y1 = vy[i1]
    x2 = vx[i2]
    y2 = vy[i2]
    det = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
    if det == 0.0:
        return det, np.nan, np.nan
    l1 = ((x - x0) * (y2 - y0) - (x2 - x0) * (y - y0)) / det
    l2 = ((x1 - x0) * (y - y0) - (x - x0) * (y1 - y0)) / det
    return det, l1, l2


@nb.njit(cache=True, nogil=True, inline="always")
def weighted(vz, i0, i1, i2, l1, l2):
    """The height interpolated with the barycentric weights ``(1 - l1 - l2, l1, l2)``."""
    return (1.0 - l1 - l2) * vz[i0] + l1 * vz[i1] + l2 * vz[i2]


@nb.njit(cache=True, nogil=True, inline="always")
def face_height(vx, vy, vz, faces, f, x, y):
    """Height of face f's plane at (x, y) (NaN for a degenerate face)."""
    i0 = faces[f, 0]
    i1 = faces[f, 1]
    i2 = faces[f, 2]
    _, l1, l2 = barycentric(vx, vy, i0, i1, i2, x, y)
    return weighted(vz, i0, i1, i2, l1, l2)


@nb.njit(cache=True, nogil=True, inline="always")
def bucket_of(t, x, y):
    """The bucket of the :data:`SurfaceTin` ``t`` holding (x, y) (clamped to the bucket grid)."""
    c = min(max(int(np.floor((x - t.x0) / t.bw)), 0), t.nbx - 1)
    r = min(max(int(np.floor((y - t.y0) / t.bh)), 0), t.nby - 1)
    return r * t.nbx + c


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def face_at(t, x, y):
    """A face of the :data:`SurfaceTin` ``t`` containing (x, y), or -1: of the faces in its
    bucket, the one the point lies deepest inside (robust on shared edges), unless the
    point is outside it by more than ``TRACK_FACE_SLACK`` in barycentric weight."""
    b = bucket_of(t, x, y)
    best = -1
    best_l = -_INF
    for k in range(t.starts[b], t.starts[b + 1]):
        f = t.items[k]
        det, l1, l2 = barycentric(t.vx, t.vy, t.faces[f, 0], t.faces[f, 1], t.faces[f, 2], x, y)
        if det == 0.0:
            continue
        low = min(1.0 - l1 - l2, l1, l2)
        if low > best_l:
            best_l = low
            best = f
    if best_l < -TRACK_FACE_SLACK:
        return -1
    return best
