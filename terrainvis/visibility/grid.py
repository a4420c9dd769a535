"""Grid engine: an exact walk over a HeightGrid, accelerated by a min/max pyramid.

The segment's ground track is walked across grid lines and cell diagonals; between two
crossings both the segment and the surface are linear, so evaluating the clearance at
every crossing gives the exact minimum. A pyramid of per-block (min, max) corner heights
(Duvenhage 2009 style implicit min/max tree) lets the walk skip blocks the segment
clears and stop at blocks that bury it; descent is near-first with an exact evaluation in
each cell at the leaves.

Functions here take validated float64 arrays; :mod:`terrainvis.visibility` validates.

References
----------
B. Duvenhage, "Using an implicit min/max KD-tree for doing efficient terrain line of
sight calculations", AFRIGRAPH 2009, doi:10.1145/1503454.1503465.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.interrupt import call
from ..core.surface import SurfaceGrid, no_strips
from ..tolerances import DIVISOR_FLOOR
from . import _kernels

__all__ = ["GridAccel", "grid_accel", "grid_clearance", "grid_matrix"]


@dataclass(frozen=True)
class GridAccel:
    """What the grid engine caches on a HeightGrid (``grid._cache["visibility"]``).

    Attributes
    ----------
    x0, y0 : float
        Local origin (``xs[0]``, ``ys[0]``); the kernels work in local coordinates.
    xs, ys : (cols,), (rows,) float64
        Local coordinate vectors.
    ixw, iyw : (cols - 1,), (rows - 1,) float64
        Inverse cell widths ``1 / diff(xs)`` and ``1 / diff(ys)``.
    uniform : bool
        True when both spacings are uniform (cells are then located by division, then checked).
    pyr : (k,) float32
        Min/max pyramid, levels 1..ltop (see ``_kernels``).
    off, nxl, nyl : (ltop + 1,) int64
        Start of each level in ``pyr`` and its size in nodes.
    ltop : int
        Root level (its single node covers the whole grid; 0 when the grid is one cell).
    build_seconds : float
        Time taken to build the pyramid.
    """

    x0: float
    y0: float
    xs: np.ndarray
    ys: np.ndarray
    ixw: np.ndarray
    iyw: np.ndarray
    uniform: bool
    pyr: np.ndarray
    off: np.ndarray
    nxl: np.ndarray
    nyl: np.ndarray
    ltop: int
    build_seconds: float

    @property
    def nbytes(self) -> int:
        """Bytes of the acceleration structures (pyramid, level tables, local coordinates)."""
        return int(
            self.pyr.nbytes + self.off.nbytes + self.nxl.nbytes + self.nyl.nbytes
            + self.xs.nbytes + self.ys.nbytes + self.ixw.nbytes + self.iyw.nbytes
        )


def _f32_bounds(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float64 lows and highs as float32, rounded down and up (a bound stays a bound)."""
    flo = lo.astype(np.float32)
    np.nextafter(flo, np.float32(-np.inf), out=flo, where=np.greater(flo, lo))
    fhi = hi.astype(np.float32)
    np.nextafter(fhi, np.float32(np.inf), out=fhi, where=np.less(fhi, hi))
    return flo, fhi


def _strided3(a: np.ndarray, axis: int, n: int, reduce) -> np.ndarray:
    """``reduce`` over the windows [2i, 2i + 2] (clamped to the last index) along ``axis``, i < n:
    the samples of cell blocks 2 cells wide, which share their edge samples (strided views, one
    output array)."""
    last = a.shape[axis] - 1
    full = min(n, last // 2)  # blocks whose three samples all exist

    def part(start, stop, step=2):
        return a[:, start:stop:step] if axis == 1 else a[start:stop:step]

    shape = (a.shape[0], n) if axis == 1 else (n, a.shape[1])
    out = np.empty(shape, dtype=a.dtype)
    head = out[:, :full] if axis == 1 else out[:full]
    reduce(part(0, 2 * full, 2), part(1, 2 * full, 2), out=head)
    reduce(head, part(2, 2 * full + 1, 2), out=head)
    if n > full:  # the last block, one or two samples wide
        reduce.reduce(part(2 * full, None, 1), axis=axis, out=out[:, full] if axis == 1 else out[full])
    return out


def build_pyramid(z, pyr, off, nxl, nyl, ltop) -> None:
    """Fill the min/max pyramid of the grid engine (levels 1..``ltop``, the layout
    :mod:`terrainvis.visibility._kernels` reads) from the heights ``z``, with numpy.

    Level 1 holds, for each block of 2 x 2 cells, the lowest and highest of its up to 3 x 3
    samples, rounded outwards to float32; level L, of the up to 2 x 2 blocks of level L - 1
    under it. (A numba kernel did this before, the same values; it took 0.3-0.45 s to compile
    on a first run of every line-of-sight entry point.) NaN are ignored, as the kernel's
    comparisons ignored them.
    """
    if ltop < 1:
        return
    nx, ny = int(nxl[1]), int(nyl[1])
    # rows first: their reduction reads whole rows, and halves what the strided columns' reads
    lo = _strided3(_strided3(z, 0, ny, np.fmin), 1, nx, np.fmin)
    hi = _strided3(_strided3(z, 0, ny, np.fmax), 1, nx, np.fmax)
    lo[np.isnan(lo)] = np.inf
    hi[np.isnan(hi)] = -np.inf
    flo, fhi = _f32_bounds(lo, hi)
    for L in range(1, ltop + 1):
        if L > 1:
            nx, ny = int(nxl[L]), int(nyl[L])
            flo = _pairs(_pairs(flo, 1, nx, np.minimum, np.inf), 0, ny, np.minimum, np.inf)
            fhi = _pairs(_pairs(fhi, 1, nx, np.maximum, -np.inf), 0, ny, np.maximum, -np.inf)
        level = pyr[off[L]: off[L] + 2 * nx * ny].reshape(ny, nx, 2)
        level[..., 0] = flo
        level[..., 1] = fhi


def _pairs(a: np.ndarray, axis: int, n: int, reduce, fill: float) -> np.ndarray:
    """``reduce`` of the pairs (2i, 2i + 1) along ``axis``, i < n, a missing second padded with ``fill``."""
    if a.shape[axis] < 2 * n:
        pad = [(0, 0), (0, 0)]
        pad[axis] = (0, 2 * n - a.shape[axis])
        a = np.pad(a, pad, constant_values=np.float32(fill))
    even = np.take(a, np.arange(0, 2 * n, 2), axis=axis)
    return reduce(even, np.take(a, np.arange(1, 2 * n, 2), axis=axis), out=even)


def grid_accel(grid) -> GridAccel:
    """The cached :class:`GridAccel` of a (NaN-free) HeightGrid, built on first use."""
    acc = grid._cache.get("visibility")
    if acc is not None:
        return acc
    import time

    t = time.perf_counter()
    rows, cols = grid.shape
    ncx, ncy = cols - 1, rows - 1
    ltop = int(math.ceil(math.log2(max(ncx, ncy)))) if max(ncx, ncy) > 1 else 0
    nxl = np.array([(ncx + (1 << L) - 1) >> L for L in range(ltop + 1)], dtype=np.int64)
    nyl = np.array([(ncy + (1 << L) - 1) >> L for L in range(ltop + 1)], dtype=np.int64)
    off = np.zeros(ltop + 1, dtype=np.int64)
    total = 0
    for L in range(1, ltop + 1):
        off[L] = total
        total += 2 * int(nxl[L] * nyl[L])
    pyr = np.empty(max(total, 1), dtype=np.float32)
    build_pyramid(grid.z, pyr, off, nxl, nyl, ltop)
    x0 = float(grid.xs[0])
    y0 = float(grid.ys[0])
    xs = grid.xs - x0
    ys = grid.ys - y0
    uniform = bool(grid.is_uniform)
    ixw = 1.0 / np.diff(xs)
    iyw = 1.0 / np.diff(ys)
    acc = GridAccel(x0, y0, xs, ys, ixw, iyw, uniform, pyr, off, nxl, nyl, ltop, time.perf_counter() - t)
    grid._cache["visibility"] = acc
    return acc


def _morton_order(xy: np.ndarray, extent, bits: int = 8) -> np.ndarray:
    """Permutation sorting points by the Morton (Z-order) code of their position.

    ``bits`` per axis (8: a 256 x 256 lattice over the extent, 16-bit keys, which numpy
    sorts with a radix sort in a few milliseconds per million points).
    """
    xmin, xmax, ymin, ymax = extent
    scale = float((1 << bits) - 1)
    qx = np.clip((xy[:, 0] - xmin) * (scale / max(xmax - xmin, DIVISOR_FLOOR)), 0, scale).astype(np.uint32)
    qy = np.clip((xy[:, 1] - ymin) * (scale / max(ymax - ymin, DIVISOR_FLOOR)), 0, scale).astype(np.uint32)
    key = _spread(qx) | (_spread(qy) << np.uint32(1))
    key = key.astype(np.uint16 if bits <= 8 else np.uint32)
    return np.argsort(key, kind="stable")


def _spread(v: np.ndarray) -> np.ndarray:
    """Insert a zero bit between the low 16 bits of each value (uint32)."""
    v = v & np.uint32(0xFFFF)
    v = (v | (v << np.uint32(8))) & np.uint32(0x00FF00FF)
    v = (v | (v << np.uint32(4))) & np.uint32(0x0F0F0F0F)
    v = (v | (v << np.uint32(2))) & np.uint32(0x33333333)
    v = (v | (v << np.uint32(1))) & np.uint32(0x55555555)
    return v


#: Sort segment queries by the Morton code of their start when the height array is at
#: least this large (smaller arrays stay in cache and the gather costs more than it saves).
SORT_MIN_BYTES = 32 << 20


def _local(points: np.ndarray, acc: GridAccel) -> np.ndarray:
    out = points.copy()
    out[:, 0] -= acc.x0
    out[:, 1] -= acc.y0
    return out


def _walk_grid(grid, acc: GridAccel) -> SurfaceGrid:
    """The arrays the kernels read, grouped (no copies; no strip maxima)."""
    cmax, rmax = no_strips()
    return SurfaceGrid(grid.z, acc.xs, acc.ys, acc.ixw, acc.iyw, acc.uniform, bool(grid.n_nodata > 0), acc.pyr, acc.off,
                       acc.nxl, acc.ltop, cmax, rmax)


def grid_clearance(
    grid, a, b, *, delta: float, tol: float, los: bool, end_radius: float = 0.0, kc: float = 0.0
) -> np.ndarray:
    """Clearance of each segment a[i] -> b[i] on a HeightGrid (validated input).

    The segment is tested over ``[t0, 1 - t0]`` with ``t0 = max(delta / length,
    end_radius / horizontal length)``. With ``los`` False: the exact minimum clearance
    over that interval. With ``los`` True: a value that is ``>= -tol`` exactly when the
    segment is visible (the walk stops early). Segments no longer than ``2 * delta``, or
    (for ``end_radius > 0``) with a horizontal length of at most ``2 * end_radius``,
    give ``inf``. ``kc`` is the earth-curvature coefficient ``curvature / (2 R)`` (0: flat).
    """
    m = a.shape[0]
    out = np.empty(m, dtype=np.float64)
    if m == 0:
        return out
    acc = grid_accel(grid)
    la = _local(a, acc)
    lb = _local(b, acc)
    if grid.z.nbytes >= SORT_MIN_BYTES:
        order = _morton_order(a[:, :2], grid.extent).astype(np.int64)
    else:
        order = np.arange(m, dtype=np.int64)
    # through the interrupt helper: on threads, and Ctrl-C stops the kernel within an iteration
    pred = (float(delta), float(end_radius), bool(los), float(tol), float(kc))
    call(_kernels.grid_walks, _walk_grid(grid, acc), la, lb, order, pred, out, np.zeros((0, 0), dtype=np.bool_),
         work=m, items=_kernels.grid_walk_iterations(0, m, False))
    return out


def grid_matrix(grid, points, *, delta: float, tol: float, end_radius: float = 0.0, kc: float = 0.0) -> np.ndarray:
    """(n, n) visibility matrix of validated points on a HeightGrid (pairs i < j, parallel)."""
    n = points.shape[0]
    out = np.zeros((n, n), dtype=np.bool_)
    if n == 0:
        return out
    acc = grid_accel(grid)
    order = _morton_order(points[:, :2], grid.extent).astype(np.int64)
    p = np.ascontiguousarray(_local(points, acc)[order])
    # through the interrupt helper: on threads, and Ctrl-C stops the kernel within an iteration
    pred = (float(delta), float(end_radius), True, float(tol), float(kc))
    call(_kernels.grid_walks, _walk_grid(grid, acc), p, p, order, pred, np.zeros(0), out, work=n * n // 2,
         items=_kernels.grid_walk_iterations(n, 0, True))
    return out
