"""Numba loops for the terrain models (point location in TINs, rasterisation).

Kernels loop and never validate: the public wrappers in ``terrain.py`` check their input.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..tolerances import BUCKET_SLACK, RASTER_BOX_REL  # frozen into the kernels when they compile
from .compiling import KERNEL_ONLY
from .stopflag import stopped
from .surface import barycentric, plane_uv, weighted


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _tri_z_at(vx, vy, vz, i0, i1, i2, x, y, rel_eps):
    """Height of triangle (i0, i1, i2) at (x, y), or NaN when (x, y) is outside it.

    ``rel_eps`` widens the triangle by a relative barycentric tolerance so that points
    on a shared edge are found by either neighbour.
    """
    det, l1, l2 = barycentric(vx, vy, i0, i1, i2, x, y)
    if det == 0.0:
        return np.nan
    l0 = 1.0 - l1 - l2
    if l0 < -rel_eps or l1 < -rel_eps or l2 < -rel_eps:
        return np.nan
    return weighted(vz, i0, i1, i2, l1, l2)


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _face_buckets(vx, vy, faces, f, x0, y0, bw, bh, nbx, nby):
    """The range of bucket columns and rows covered by face f's bounding box."""
    xmin = min(vx[faces[f, 0]], vx[faces[f, 1]], vx[faces[f, 2]])
    xmax = max(vx[faces[f, 0]], vx[faces[f, 1]], vx[faces[f, 2]])
    ymin = min(vy[faces[f, 0]], vy[faces[f, 1]], vy[faces[f, 2]])
    ymax = max(vy[faces[f, 0]], vy[faces[f, 1]], vy[faces[f, 2]])
    bx0 = min(max(int((xmin - x0) / bw), 0), nbx - 1)
    bx1 = min(max(int((xmax - x0) / bw), 0), nbx - 1)
    by0 = min(max(int((ymin - y0) / bh), 0), nby - 1)
    by1 = min(max(int((ymax - y0) / bh), 0), nby - 1)
    return bx0, bx1, by0, by1


@nb.njit(cache=True, nogil=True)
def build_buckets(vx, vy, faces, x0, y0, bw, bh, nbx, nby):
    """Bin faces into a uniform bucket grid by their bounding boxes (CSR layout)."""
    nf = faces.shape[0]
    counts = np.zeros(nbx * nby + 1, dtype=np.int64)
    for f in range(nf):
        bx0, bx1, by0, by1 = _face_buckets(vx, vy, faces, f, x0, y0, bw, bh, nbx, nby)
        for by in range(by0, by1 + 1):
            for bx in range(bx0, bx1 + 1):
                counts[by * nbx + bx + 1] += 1
    for i in range(nbx * nby):
        counts[i + 1] += counts[i]
    items = np.empty(counts[nbx * nby], dtype=np.int64)
    fill = counts[:-1].copy()
    for f in range(nf):
        bx0, bx1, by0, by1 = _face_buckets(vx, vy, faces, f, x0, y0, bw, bh, nbx, nby)
        for by in range(by0, by1 + 1):
            for bx in range(bx0, bx1 + 1):
                b = by * nbx + bx
                items[fill[b]] = f
                fill[b] += 1
    return counts, items


@nb.njit(cache=True, nogil=True)
def locate_heights(tin, qx, qy, out, rel_eps, stop):
    """Height of the TIN (a :data:`~terrainvis.core.surface.SurfaceTin` in world coordinates,
    ``nbr`` not read) at each query point (NaN outside the footprint): the first face of the
    point's bucket that holds it within the barycentric slack ``rel_eps``.

    ``stop`` is the stop flag (:mod:`terrainvis.core.interrupt`), read every 4096 points.
    """
    vx, vy, vz, faces, starts, items = tin.vx, tin.vy, tin.vz, tin.faces, tin.starts, tin.items
    x0, y0, bw, bh, nbx, nby = tin.x0, tin.y0, tin.bw, tin.bh, tin.nbx, tin.nby
    for i in range(qx.shape[0]):
        if i % 4096 == 0 and stopped(stop):
            return
        x = qx[i]
        y = qy[i]
        out[i] = np.nan
        fx = (x - x0) / bw
        fy = (y - y0) / bh
        if not (fx >= -BUCKET_SLACK and fy >= -BUCKET_SLACK and fx <= nbx + BUCKET_SLACK and fy <= nby + BUCKET_SLACK):
            continue
        bx = min(max(int(fx), 0), nbx - 1)
        by = min(max(int(fy), 0), nby - 1)
        b = by * nbx + bx
        for k in range(starts[b], starts[b + 1]):
            f = items[k]
            z = _tri_z_at(vx, vy, vz, faces[f, 0], faces[f, 1], faces[f, 2], x, y, rel_eps)
            if not np.isnan(z):
                out[i] = z
                break


@nb.njit(cache=True, nogil=True)
def rasterize_tin(vx, vy, vz, faces, xs, ys, out, rel_eps, stop):
    """Evaluate a TIN at every node (xs[c], ys[r]) of a rectilinear grid.

    Each face visits only the grid nodes inside its bounding box, so the cost is
    O(faces + nodes). Nodes outside every face stay NaN (``out`` is pre-filled by the caller).
    ``stop`` is the stop flag (:mod:`terrainvis.core.interrupt`), read before every face.
    """
    nc = xs.shape[0]
    nr = ys.shape[0]
    for f in range(faces.shape[0]):
        if stopped(stop):
            return
        i0 = faces[f, 0]
        i1 = faces[f, 1]
        i2 = faces[f, 2]
        xmin = min(vx[i0], vx[i1], vx[i2])
        xmax = max(vx[i0], vx[i1], vx[i2])
        ymin = min(vy[i0], vy[i1], vy[i2])
        ymax = max(vy[i0], vy[i1], vy[i2])
        c0 = np.searchsorted(xs, xmin - RASTER_BOX_REL * (abs(xmin) + 1.0))
        c1 = np.searchsorted(xs, xmax + RASTER_BOX_REL * (abs(xmax) + 1.0), side="right")
        r0 = np.searchsorted(ys, ymin - RASTER_BOX_REL * (abs(ymin) + 1.0))
        r1 = np.searchsorted(ys, ymax + RASTER_BOX_REL * (abs(ymax) + 1.0), side="right")
        for r in range(r0, min(r1, nr)):
            for c in range(c0, min(c1, nc)):
                if not np.isnan(out[r, c]):
                    continue
                z = _tri_z_at(vx, vy, vz, i0, i1, i2, xs[c], ys[r], rel_eps)
                if not np.isnan(z):
                    out[r, c] = z


@nb.njit(cache=True, nogil=True)
def largest_valid_rectangle(valid, stop):
    """Largest all-True axis-aligned rectangle of a boolean mask (histogram-stack method).

    Returns (r0, r1, c0, c1) with half-open bounds, or (0, 0, 0, 0) when nothing is valid
    (or when the stop flag ``stop`` of :mod:`terrainvis.core.interrupt`, read every row, is set).
    """
    nr, nc = valid.shape
    heights = np.zeros(nc + 1, dtype=np.int64)
    stack = np.empty(nc + 1, dtype=np.int64)
    best = 0
    br0 = 0
    br1 = 0
    bc0 = 0
    bc1 = 0
    for r in range(nr):
        if stopped(stop):
            return 0, 0, 0, 0
        for c in range(nc):
            if valid[r, c]:
                heights[c] += 1
            else:
                heights[c] = 0
        top = 0
        for c in range(nc + 1):
            h = heights[c] if c < nc else 0
            while top > 0 and heights[stack[top - 1]] >= h:
                hh = heights[stack[top - 1]]
                top -= 1
                left = stack[top - 1] + 1 if top > 0 else 0
                area = hh * (c - left)
                if area > best:
                    best = area
                    br0 = r - hh + 1
                    br1 = r + 1
                    bc0 = left
                    bc1 = c
            stack[top] = c
            top += 1
    return br0, br1, bc0, bc1


@nb.njit(cache=True, nogil=True)
def grid_on_grid(xs, ys, z, qx, qy, out, stop):
    """Evaluate the grid surface (xs, ys, z) at every node (qx[j], qy[i]) of another grid.

    The query nodes are separable, so each column's cell and u, and each row's cell and
    v, are found once. Nodes outside the extent stay as pre-filled by the caller (NaN).
    ``stop`` is the stop flag (:mod:`terrainvis.core.interrupt`), read before every row.
    """
    nc = xs.shape[0]
    nr = ys.shape[0]
    cidx = np.empty(qx.shape[0], dtype=np.int64)
    uu = np.empty(qx.shape[0])
    for j in range(qx.shape[0]):
        c = min(max(np.searchsorted(xs, qx[j], side="right") - 1, 0), nc - 2)
        cidx[j] = c
        uu[j] = (qx[j] - xs[c]) / (xs[c + 1] - xs[c])
    for i in range(qy.shape[0]):
        if stopped(stop):
            return
        y = qy[i]
        if not (y >= ys[0] and y <= ys[nr - 1]):
            continue
        r = min(max(np.searchsorted(ys, y, side="right") - 1, 0), nr - 2)
        v = (y - ys[r]) / (ys[r + 1] - ys[r])
        for j in range(qx.shape[0]):
            x = qx[j]
            if not (x >= xs[0] and x <= xs[nc - 1]):
                continue
            out[i, j] = plane_uv(z, r, cidx[j], uu[j], v)
