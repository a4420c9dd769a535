"""Embree engine: line of sight by occlusion rays (embreex), with the underground fix.

A segment a -> b is tested over ``t`` in [t0, 1 - t0], with ``t0 = tau = delta / |b - a|``
(the trim) or, with an end radius r > 0, ``t0 = max(tau, r / |b - a|_h)`` (the horizontal
length; nothing is tested when it is at most 2 r). It is blocked when

* the tested part ``a + t (b - a)`` crosses the surface (one occlusion ray from
  ``a + t0 (b - a)`` along ``b - a`` with ``tfar = 1 - 2 t0``), or
* either end of the tested part lies below the surface (an upward vertical occlusion
  ray from that end hits the surface exactly when the end is below it).

The second rule catches segments that run underground and meet the surface only at
their ends, which a surface-crossing query alone reports as visible.

All rays start from the segment raised by a quarter of :func:`embree_tolerance`. Without the
lift, segments lying exactly on the surface (clearance 0, e.g. between two points on flat
or planar ground) would be decided by float32 noise; the definition counts them as
visible, and with the lift Embree does too. Only pairs whose minimum clearance lies
inside the band can change their answer.

Embree works in float32. Every coordinate is shifted to a local origin (the minimum
corner of the terrain) in float64 before the cast, so UTM-sized coordinates keep
millimetre precision. Answers can differ from the exact float64 grid walk only on pairs
whose minimum clearance is within :func:`embree_tolerance` of zero.

One scene per terrain is built on first use and cached on the TIN (``tin._cache``); a
HeightGrid goes through its (cached) ``grid.to_tin()``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .predicate import terrain_scale

__all__ = ["EmbreeScene", "embree_scene", "embree_visible", "embree_tolerance", "embree_matrix"]

#: Relative float32 degeneracy band, see :func:`embree_tolerance`.
EMBREE_REL_TOL = 2.0**-20

_CHUNK = 1 << 20  # segments per batched call (bounds the temporary ray buffers)


def _import_embreex():
    try:
        from embreex import mesh_construction, rtcore_scene
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "the Embree engine needs the 'embreex' package (pip install embreex); "
            "use engine='grid' on a HeightGrid instead"
        ) from exc
    return rtcore_scene, mesh_construction


@dataclass
class EmbreeScene:
    """A cached Embree scene of one TIN.

    Attributes
    ----------
    scene : embreex.rtcore_scene.EmbreeScene
    origin : (3,) float64
        Local origin subtracted (in float64) before the float32 cast.
    build_seconds : float
        Time to fill Embree's buffers (embreex copies them in a Python loop) and
        commit; the BVH itself is built lazily by the first query.
    n_faces : int
    """

    scene: object
    origin: np.ndarray
    build_seconds: float
    n_faces: int

    def run(self, origins, dirs, dists):
        """Occlusion query: True where a ray hits the surface within its ``dists``."""
        o = (origins - self.origin).astype(np.float32)
        d = np.asarray(dirs, dtype=np.float32)
        res = self.scene.run(o, d, query="OCCLUDED", dists=np.asarray(dists, dtype=np.float32))
        return np.asarray(res) != -1


def embree_scene(tin) -> EmbreeScene:
    """The cached :class:`EmbreeScene` of a TIN (built on first use)."""
    sc = tin._cache.get("embree")
    if sc is not None:
        return sc
    rtcore_scene, mesh_construction = _import_embreex()
    t = time.perf_counter()
    v = tin.vertices
    origin = v.min(axis=0)
    verts = (v - origin).astype(np.float32)
    faces = np.ascontiguousarray(tin.faces, dtype=np.int32)
    scene = rtcore_scene.EmbreeScene()
    mesh_construction.TriangleMesh(scene=scene, vertices=verts, indices=faces)
    del verts
    sc = EmbreeScene(scene, origin, time.perf_counter() - t, int(faces.shape[0]))
    tin._cache["embree"] = sc
    return sc


def embree_tolerance(terrain) -> float:
    """Half-width of the band of minimum clearances where Embree may disagree with float64.

    ``EMBREE_REL_TOL * M`` with ``M = max(horizontal diagonal, z range)`` of the terrain
    (:func:`terrainvis.visibility.terrain_scale`): 2**-20 (about 9.5e-7) of the terrain's
    size, i.e. 16 float32 ulps of the largest local coordinate (3.4 mm on a 120 x 120
    grid of 30 m cells). It covers the rounding of the vertices and ray origins to
    float32 (amplified by slopes) and Embree's own float32 intersection test. Over
    100,000 random pairs on the bundled terrains and shared DEMs, the largest
    disagreement had ``|min clearance|`` of 1.3e-8 M, 70 times inside this band.
    """
    return EMBREE_REL_TOL * terrain_scale(terrain)


def _tin_of(terrain):
    from ..core.terrain import HeightGrid

    return terrain.to_tin() if isinstance(terrain, HeightGrid) else terrain


def embree_visible(terrain, a, b, *, delta: float, end_radius: float = 0.0) -> np.ndarray:
    """(m,) bool: Embree's line of sight for validated segments a[i] -> b[i].

    ``end_radius`` (a validated horizontal distance >= 0) shrinks the tested part as in
    :func:`terrainvis.visibility.line_of_sight`.
    """
    m = a.shape[0]
    out = np.ones(m, dtype=np.bool_)
    if m == 0:
        return out
    sc = embree_scene(_tin_of(terrain))
    lift = 0.25 * embree_tolerance(terrain)
    for s in range(0, m, _CHUNK):
        e = min(m, s + _CHUNK)
        out[s:e] = _visible_chunk(sc, a[s:e], b[s:e], delta, end_radius, lift)
    return out


def _visible_chunk(sc: EmbreeScene, a, b, delta, end_radius, lift):
    # canonical direction (the lexicographically smaller end first), as in the grid engine
    swap = (b[:, 0] < a[:, 0]) | (
        (b[:, 0] == a[:, 0]) & ((b[:, 1] < a[:, 1]) | ((b[:, 1] == a[:, 1]) & (b[:, 2] < a[:, 2])))
    )
    p = np.where(swap[:, None], b, a)
    q = np.where(swap[:, None], a, b)
    d = q - p
    length = np.sqrt((d * d).sum(axis=1))
    live = length > 2.0 * delta
    if end_radius > 0.0:
        lh = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])
        live &= lh > 2.0 * end_radius
    vis = np.ones(a.shape[0], dtype=np.bool_)
    if not live.any():
        return vis
    p = p[live]
    d = d[live]
    # start t0 of the tested interval [t0, 1 - t0] (as _kernels.interval_start)
    tau = delta / length[live]
    if end_radius > 0.0:
        tau = np.maximum(tau, end_radius / lh[live])
    start = p + tau[:, None] * d
    end = p + (1.0 - tau)[:, None] * d
    start[:, 2] += lift
    end[:, 2] += lift
    k = start.shape[0]
    up = np.zeros((k, 3))
    up[:, 2] = 1.0
    inf = np.full(k, np.inf)
    origins = np.concatenate([start, start, end])
    dirs = np.concatenate([d, up, up])
    dists = np.concatenate([1.0 - 2.0 * tau, inf, inf])
    hit = sc.run(origins, dirs, dists).reshape(3, k).any(axis=0)
    vis[live] = ~hit
    return vis


def embree_matrix(terrain, points, *, delta: float, end_radius: float = 0.0, chunk_pairs: int = _CHUNK) -> np.ndarray:
    """(n, n) visibility matrix by Embree, pairs i < j in chunks of about ``chunk_pairs``."""
    n = points.shape[0]
    out = np.zeros((n, n), dtype=np.bool_)
    if n == 0:
        return out
    sc = embree_scene(_tin_of(terrain))
    lift = 0.25 * embree_tolerance(terrain)
    np.fill_diagonal(out, True)
    i = 0
    while i < n - 1:
        # rows i..i2-1 hold about chunk_pairs pairs (row r holds n - 1 - r pairs)
        i2 = i
        count = 0
        while i2 < n - 1 and (count == 0 or count + (n - 1 - i2) <= chunk_pairs):
            count += n - 1 - i2
            i2 += 1
        rows = np.arange(i, i2)
        ii = np.repeat(rows, n - 1 - rows)
        starts = np.cumsum(n - 1 - rows) - (n - 1 - rows)
        jj = np.arange(ii.size) - np.repeat(starts, n - 1 - rows) + ii + 1
        vis = _visible_chunk(sc, points[ii], points[jj], delta, end_radius, lift)
        out[ii, jj] = vis
        out[jj, ii] = vis
        i = i2
    return out
