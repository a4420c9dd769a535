"""Mesh helpers shared by the surfaces, the simplifiers and the measurements.

One home for the small pieces of triangle-mesh bookkeeping that several modules need:
edge keys, boundary edges and loops, and signed projected areas. Everything takes plain
arrays (``vertices`` (n, 2 or 3) float64, ``faces`` (m, 3) int) and never validates:
callers pass what they built themselves or what a public function already checked.

Conventions: faces are counter-clockwise seen from above, so a face's signed projected
area is positive and the footprint lies to the left of every boundary edge.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..tolerances import FOOTPRINT_REL

__all__ = [
    "signed_area2", "footprint_matches", "edge_keys", "undirected_edges", "boundary_edges", "boundary_loop", "NotADiskError",
]


class NotADiskError(ValueError):
    """A mesh is not one triangulated disk with a single boundary loop."""


def signed_area2(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m,) twice the signed projected (x, y) area of each face; > 0 for counter-clockwise."""
    a = vertices[faces[:, 0], :2]
    b = vertices[faces[:, 1], :2]
    c = vertices[faces[:, 2], :2]
    return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])


def footprint_matches(footprint: float, area: float, rtol: float = FOOTPRINT_REL) -> bool:
    """The height-field rule on areas: the faces' summed projected area ``footprint`` equals
    the extent's ``area`` to ``rtol`` of it (with every face counter-clockwise, the faces
    then tile the extent once)."""
    return bool(abs(footprint - area) <= rtol * area)


def half_edges(faces: np.ndarray) -> np.ndarray:
    """(3m, 2) int64 directed edges (a, b), (b, c), (c, a) of every face, face by face."""
    return np.asarray(faces, dtype=np.int64)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)


def edge_keys(edges: np.ndarray, n: int, *, directed: bool = False) -> np.ndarray:
    """One int64 key per edge: ``a * n + b`` (directed) or ``min * n + max`` (undirected).

    A 1-D key makes ``numpy.unique`` and ``numpy.isin`` on edges far cheaper than row-wise
    operations on (k, 2) arrays.
    """
    a = edges[:, 0].astype(np.int64)
    b = edges[:, 1].astype(np.int64)
    n = np.int64(n)
    if directed:
        return a * n + b
    return np.minimum(a, b) * n + np.maximum(a, b)


def undirected_edges(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Keys of the distinct undirected edges (``min * n + max``) and how many faces share each."""
    return np.unique(edge_keys(half_edges(faces), n), return_counts=True)


def boundary_edges(faces: np.ndarray, n: int) -> np.ndarray:
    """(k, 2) int64 directed boundary edges: the half-edges whose twin is absent.

    On a counter-clockwise mesh the footprint lies to the left of each of them.
    """
    he = half_edges(faces)
    key = edge_keys(he, n, directed=True)
    twin = edge_keys(he[:, ::-1], n, directed=True)
    return he[~np.isin(key, twin)]


def boundary_loop(faces: np.ndarray, n: int) -> np.ndarray:
    """Vertex ids of the single boundary loop of a triangulated disk, counter-clockwise.

    Parameters
    ----------
    faces : (m, 3) int
        Counter-clockwise faces over ``n`` vertices.
    n : int
        Number of vertices (every vertex is assumed to be used by a face).

    Returns
    -------
    (k,) int64
        The loop, starting at its smallest vertex id.

    Raises
    ------
    NotADiskError
        When a directed edge appears twice (an edge shared by more than two faces, or
        inconsistent orientation), the boundary is not one simple loop (a pinched
        vertex, several loops), or the Euler characteristic is not 1.
    """
    he = half_edges(faces)
    key = np.sort(edge_keys(he, n, directed=True))
    if key.size > 1 and (np.diff(key) == 0).any():
        raise NotADiskError("the mesh is non-manifold or inconsistently oriented (a directed edge appears twice)")
    twin = edge_keys(he[:, ::-1], n, directed=True)
    pos = np.minimum(np.searchsorted(key, twin), key.size - 1)
    bh = he[key[pos] != twin]
    if bh.shape[0] == 0 or np.bincount(bh[:, 0]).max() > 1:
        raise NotADiskError("the boundary of the mesh is not one simple loop")
    nxt = np.full(n, -1, dtype=np.int64)
    nxt[bh[:, 0]] = bh[:, 1]
    loop = np.empty(bh.shape[0], dtype=np.int64)
    length = _walk_loop(nxt, int(bh[:, 0].min()), loop)
    n_edges = (3 * faces.shape[0] + bh.shape[0]) // 2
    euler = n - n_edges + faces.shape[0]
    if length != bh.shape[0] or euler != 1:
        raise NotADiskError(
            f"the mesh is not a disk ({bh.shape[0]} boundary edges, {length} in the first loop, "
            f"Euler characteristic {euler})"
        )
    return loop


@nb.njit(cache=True, nogil=True)
def _walk_loop(nxt, start, out):
    """Follow ``nxt`` from ``start`` until it returns to ``start``; the loop length (or -1)."""
    k = 0
    cur = start
    while True:
        if k >= out.shape[0] or cur < 0:
            return -1
        out[k] = cur
        k += 1
        cur = nxt[cur]
        if cur == start:
            return k
