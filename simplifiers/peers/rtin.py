"""``rtin``: Martini's right-triangulated irregular network (pymartini), at the level's vertex budget.

Martini (Agafonkin 2019, after Evans, Kirkpatrick & Townsend 2001) is what web-terrain
tilers build: a regular hierarchy of right isosceles triangles over a (2^k+1)² grid,
each split at the middle of its long edge, and a mesh for an error threshold *t* that
keeps splitting every triangle whose long edge's middle sample is off by more than *t*
(with errors carried up the hierarchy, so the mesh has no cracks). Its vertices are
grid samples.

**The parameter.** Martini takes an error threshold, not a vertex count. Its vertex
set at threshold t is the four corners and every sample whose (hierarchy) error is
above t, so the count only changes at the distinct error values of the tile: the
search runs over those values (bisection between the closest counts below and above the
budget). Many samples can share one error value (a sample's error is carried to all its
ancestors, and integer DEMs have ties), so the count can jump past the budget's 1 %
window; then :class:`~terrainvis.errors.SimplificationError` says which two counts
bracket the budget.

**Grids that are not (2^k+1)².** The grid (rows x cols) is padded by edge extension
(its last row and column repeated) to N x N, N = 2^k + 1 the smallest with N >= rows
and N >= cols, Martini runs on the padded tile, and its mesh is clipped to the grid's
rectangle [0, cols-1] x [0, rows-1] (in sample indices). Martini's edges are horizontal,
vertical or at 45 degrees between integer sample positions, so every point where an
edge crosses the line x = cols-1 or y = rows-1 is itself a grid sample: the clipped
mesh has only grid samples as vertices (with the grid's heights), each clipped triangle
piece (a convex polygon) is triangulated without new points, and the mesh stays
conforming. What it costs: the hierarchy is built over N² samples instead of rows x cols
(129² = 1.16 x 120²), the padded samples take part in the errors of the triangles that
straddle the clip lines, and the crossing points are extra vertices on the right and top
borders, counted in the budget like every other vertex. ``attrs`` records ``padded_to``
and ``clip_vertices`` (vertices created by the clipping). A (2^k+1)² grid is not padded
or clipped: the result is Martini's mesh itself.

References
----------
V. Agafonkin, "Martini: real-time RTIN terrain mesh", Observable, 2019
(https://observablehq.com/@mourner/martin-real-time-rtin-terrain-mesh).

W. Evans, D. Kirkpatrick and G. Townsend, "Right-triangulated irregular networks",
Algorithmica 30(2), 2001, 264-286, DOI 10.1007/s00453-001-0006-x.
"""

from __future__ import annotations

import time

import numpy as np

from terrainvis.core.terrain import TIN, HeightGrid
from terrainvis.errors import SimplificationError

from ..registry import check_height_field
from ._common import BudgetSearch, check_input, index_tin, require

__all__ = ["build", "padded_size", "clip_mesh", "LIBRARY", "MAX_TILE"]

#: The library this adapter needs (the ``peers`` extra).
LIBRARY = "pymartini"

#: The largest tile side pymartini takes (its coordinates are 16-bit: 2^15 + 1).
MAX_TILE = 2**15 + 1


def padded_size(shape) -> int:
    """The side N = 2^k + 1 of Martini's tile for a grid of ``shape``: the smallest N >= rows, cols (and >= 3).

    Examples
    --------
    >>> padded_size((120, 120)), padded_size((129, 129)), padded_size((130, 40))
    (129, 129, 257)
    """
    side = max(int(shape[0]), int(shape[1]), 3) - 1
    return (1 << (side - 1).bit_length()) + 1


def build(grid: HeightGrid, n_vertices: int, *, max_error: float | None = None, max_probes: int = 40) -> TIN:
    """Martini's RTIN of ``grid`` with ``n_vertices`` vertices (within the budget's tolerance).

    Parameters
    ----------
    grid : HeightGrid
        The terrain, without nodata; its x and y coordinates may be uneven (Martini
        works on sample indices, which are then placed at the grid's coordinates).
    n_vertices : int
        The budget.
    max_error : float, optional
        A target for the max vertical error measured against the grid (z units; what
        :func:`simplifiers.simplify` passes with ``max_error=E``), not Martini's own
        threshold (whose mesh can be off by more than the threshold): the result with
        the fewest vertices found, at most ``n_vertices``, whose max vertical error is
        <= E, by a bisection over Martini's threshold (``attrs["stopped_by"]`` is
        ``"max_error"``, or ``"budget"`` when even ``n_vertices`` vertices exceed E).
    max_probes : int
        Martini meshes tried at most in the search over the error threshold.

    Returns
    -------
    TIN
        Vertices at grid samples, with the grid's heights. ``attrs``: ``library``
        (name and version), ``max_error_threshold`` (Martini's ``max_error`` of the
        mesh kept), ``search`` (``parameter`` "max_error", ``value``, ``probes``
        [threshold, vertices], ``failures``), ``padded_to`` (N), ``clip_vertices``,
        ``seconds_hierarchy`` (Martini's tile) and ``seconds_search``.

    Raises
    ------
    ImportError
        pymartini is not installed (the message says ``pip install "terrainvis[peers]"``).
    SimplificationError
        No threshold gives a vertex count within the tolerance (the message names the
        two counts around the budget); a grid whose tile would exceed :data:`MAX_TILE`.
    """
    budget = check_input(grid, n_vertices, "rtin")
    pymartini = require(LIBRARY, "rtin")
    rows, cols = grid.shape
    size = padded_size(grid.shape)
    if size > MAX_TILE:
        raise SimplificationError(f"rtin: a {rows}x{cols} grid needs a {size}x{size} Martini tile; pymartini's "
                                  f"tiles have at most {MAX_TILE} samples a side (16-bit coordinates)")
    t0 = time.perf_counter()
    terrain = np.pad(np.asarray(grid.z, dtype=np.float64), ((0, size - rows), (0, size - cols)), mode="edge")
    tile = pymartini.Martini(size).create_tile(np.ascontiguousarray(terrain, dtype=np.float32))
    # the distinct thresholds, largest first: threshold k keeps the samples whose error exceeds it
    thresholds = np.unique(np.asarray(tile.errors_view))[::-1]
    t_hierarchy = time.perf_counter() - t0

    def mesh_at(k: int) -> TIN:
        xy, tri = tile.get_mesh(float(thresholds[k]))
        cols_i, rows_i, faces, n_clip = clip_mesh(np.asarray(xy), np.asarray(tri), rows - 1, cols - 1)
        tin = index_tin(grid, cols_i, rows_i, faces, attrs={"clip_vertices": n_clip})
        check_height_field(tin, grid, method="rtin")
        return tin

    search = BudgetSearch("rtin", "max_error", mesh_at, budget, lo=0, hi=thresholds.size - 1,
                          max_probes=max_probes, label=lambda k: float(thresholds[k]))
    # about one distinct error value per vertex beyond the corners: a first guess near the budget
    tin = search.result(max(budget - 4, 0), grid, max_error)
    tin.attrs.update(
        library=f"pymartini {getattr(pymartini, '__version__', '?')}",
        max_error_threshold=tin.attrs["search"]["value"], padded_to=size,
        seconds_hierarchy=t_hierarchy, seconds_search=search.seconds,
    )
    return tin


# ---------------------------------------------------------------------- clipping
def clip_mesh(xy: np.ndarray, triangles: np.ndarray, r_max: int, c_max: int):
    """Clip a mesh on integer sample positions to the rectangle [0, c_max] x [0, r_max].

    Parameters
    ----------
    xy : (n, 2) int
        Vertex positions as (column, row) sample indices (Martini's order).
    triangles : (m, 3) int
        Vertex indices per triangle, either orientation.
    r_max, c_max : int
        The last row and column of the grid.

    Returns
    -------
    cols, rows : (n',) int64
        The sample of each vertex of the clipped mesh.
    faces : (m', 3) int64
        Counter-clockwise (with y = row growing upwards) triangles.
    clip_vertices : int
        Vertices created where an edge crosses a clip line (not vertices of the input).

    Every edge must run along a row, a column or a 45-degree diagonal (an RTIN's edges),
    so that the crossings are samples; SimplificationError otherwise.

    Examples
    --------
    Two triangles over [0, 4]², clipped to [0, 3] x [0, 4]:

    >>> xy = np.array([[0, 0], [4, 0], [4, 4], [0, 4]])
    >>> cols, rows, faces, extra = clip_mesh(xy, np.array([[0, 1, 2], [0, 2, 3]]), 4, 3)
    >>> sorted(zip(cols.tolist(), rows.tolist())), len(faces), extra
    ([(0, 0), (0, 4), (3, 0), (3, 3), (3, 4)], 3, 3)
    """
    from terrainvis.core.mesh import signed_area2  # core.mesh imports numba: not at import time

    xy = np.asarray(xy, dtype=np.int64)
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    tri = np.where((signed_area2(xy, tri) < 0)[:, None], tri[:, ::-1], tri)  # counter-clockwise
    p = xy[tri]
    inside = (p[:, :, 0].max(axis=1) <= c_max) & (p[:, :, 1].max(axis=1) <= r_max)
    gone = (p[:, :, 0].min(axis=1) >= c_max) | (p[:, :, 1].min(axis=1) >= r_max)
    kept = tri[inside]
    straddle = np.flatnonzero(~inside & ~gone)
    side = max(int(xy.max()) + 1, r_max + 1, c_max + 1)
    new_faces = []  # as sample keys row * side + col
    for t in straddle:
        poly = [tuple(q) for q in p[t]]
        poly = _clip_polygon(poly, 0, c_max)
        poly = _clip_polygon(poly, 1, r_max)
        if len(poly) >= 3:
            for a, b, c in _triangulate_convex(poly):
                new_faces.append([a[1] * side + a[0], b[1] * side + b[0], c[1] * side + c[0]])
    keys_kept = xy[:, 1] * side + xy[:, 0]
    all_keys = keys_kept[kept].ravel()
    if new_faces:
        all_keys = np.concatenate([all_keys, np.asarray(new_faces, dtype=np.int64).ravel()])
    uniq, inverse = np.unique(all_keys, return_inverse=True)
    faces = inverse.reshape(-1, 3)
    original = np.zeros(uniq.size, dtype=bool)
    original[np.searchsorted(uniq, np.intersect1d(uniq, keys_kept))] = True
    return uniq % side, uniq // side, faces, int((~original).sum())


def _clip_polygon(poly, axis: int, limit: int):
    """Sutherland-Hodgman: the part of the convex polygon ``poly`` with coordinate ``axis`` <= ``limit``."""
    out = []
    n = len(poly)
    for i in range(n):
        a, b = poly[i], poly[(i + 1) % n]
        a_in, b_in = a[axis] <= limit, b[axis] <= limit
        if a_in:
            out.append(a)
        if a_in != b_in and a[axis] != limit and b[axis] != limit:
            out.append(_crossing(a, b, axis, limit))
    # drop repeats (a vertex on the line followed by itself)
    dedup = [q for i, q in enumerate(out) if q != out[i - 1]] if len(out) > 1 else out
    return dedup


def _crossing(a, b, axis: int, limit: int):
    """The point of segment ab at coordinate ``axis`` = ``limit``, a sample (an RTIN edge's slope is 0 or +-1)."""
    other = 1 - axis
    d_axis, d_other = b[axis] - a[axis], b[other] - a[other]
    num = (limit - a[axis]) * d_other
    if num % d_axis:
        raise SimplificationError(f"rtin: an edge from {a} to {b} crosses the clip line off a sample")
    q = [0, 0]
    q[axis] = limit
    q[other] = a[other] + num // d_axis
    return tuple(q)


def _turn(a, b, c) -> int:
    return (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])


def _triangulate_convex(poly):
    """Triangles of a counter-clockwise convex polygon whose vertices may include straight (180 degree) ones.

    Every vertex is kept (a straight vertex may be a neighbour's corner). An ear is cut at a
    strictly convex vertex next to a straight one, which makes the straight one convex; when
    none is straight left, a fan finishes.
    """
    poly = list(poly)
    out = []
    while len(poly) > 3:
        n = len(poly)
        turns = [_turn(poly[i - 1], poly[i], poly[(i + 1) % n]) for i in range(n)]
        straight = [i for i in range(n) if turns[i] == 0]
        if not straight:
            out.extend((poly[0], poly[i], poly[i + 1]) for i in range(1, n - 1))
            return out
        s = straight[0]
        # walk from the straight vertex to the end of its straight run: that vertex is convex
        e = (s + 1) % n
        while turns[e] == 0:
            e = (e + 1) % n
        out.append((poly[e - 1], poly[e], poly[(e + 1) % n]))
        del poly[e]
    if len(poly) == 3 and _turn(*poly) > 0:
        out.append(tuple(poly))
    return out
