"""Exact minimum clearance over a TIN: clip the ground track against every face it crosses.

The faces near the track are found with the TIN's uniform bucket grid
(``TIN._buckets()``). Inside one face both the segment and the surface are linear, so
the clearance there is smallest at one of the two clip points; the minimum over all
clip points is the exact minimum over the trimmed segment.

Functions here take validated float64 arrays; :mod:`terrainvis.visibility` validates.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.interrupt import call
from ..core.surface import SurfaceTin, no_neighbours
from ..tolerances import TIN_ON_EDGE_REL

from . import _kernels

__all__ = ["tin_clearance", "tin_matrix"]

#: Pairs per call of the clip kernel in :func:`tin_matrix` (bounds the temporary arrays).
_CHUNK = 1 << 18


def tin_clearance(tin, a, b, *, delta: float, end_radius: float = 0.0, kc: float = 0.0) -> np.ndarray:
    """(m,) exact minimum clearance of each validated segment a[i] -> b[i] over ``tin``.

    The segment is tested over ``[t0, 1 - t0]`` with ``t0 = max(delta / length,
    end_radius / horizontal length)``; segments with nothing to test give ``inf``.
    Parts of a segment whose ground track leaves the TIN's faces (possible only on a
    TIN with holes or a non-convex footprint) do not count. ``kc`` is the earth-curvature
    coefficient ``curvature / (2 R)`` (0: flat).
    """
    m = a.shape[0]
    out = np.empty(m, dtype=np.float64)
    if m == 0:
        return out
    bk = tin._buckets()
    v = tin.vertices
    x0, y0 = bk.x0, bk.y0
    xmin, xmax, ymin, ymax = tin.extent
    eps = TIN_ON_EDGE_REL * float(np.hypot(xmax - xmin, ymax - ymin))
    # local coordinates (the bucket grid starts at the extent's minimum corner)
    vx = np.ascontiguousarray(v[:, 0] - x0)
    vy = np.ascontiguousarray(v[:, 1] - y0)
    vz = np.ascontiguousarray(v[:, 2])
    la = a.copy()
    lb = b.copy()
    la[:, 0] -= x0
    lb[:, 0] -= x0
    la[:, 1] -= y0
    lb[:, 1] -= y0
    mesh = SurfaceTin(vx, vy, vz, tin.faces, no_neighbours(), bk.starts, bk.items, 0.0, 0.0, bk.bw, bk.bh, bk.nbx,
                      bk.nby)
    # through the interrupt helper: Ctrl-C stops the kernel within a segment (work: the
    # faces a segment across the TIN crosses, about the square root of their number, each)
    call(_kernels.tin_pairs, mesh, la, lb, float(delta), float(end_radius), eps, float(kc), out,
         work=m * math.isqrt(tin.faces.shape[0]), items=(m + _kernels.TIN_CHUNK - 1) // _kernels.TIN_CHUNK)
    return out


def tin_matrix(tin, points, *, delta: float, tol: float, end_radius: float = 0.0, kc: float = 0.0) -> np.ndarray:
    """(n, n) exact visibility matrix of validated points on a TIN (pairs i < j, in chunks)."""
    n = points.shape[0]
    out = np.zeros((n, n), dtype=np.bool_)
    np.fill_diagonal(out, True)
    if n < 2:
        return out
    ii, jj = np.triu_indices(n, 1)
    for s in range(0, ii.size, _CHUNK):
        i = ii[s : s + _CHUNK]
        j = jj[s : s + _CHUNK]
        vis = tin_clearance(tin, points[i], points[j], delta=delta, end_radius=end_radius, kc=kc) >= -tol
        out[i, j] = vis
        out[j, i] = vis
    return out
