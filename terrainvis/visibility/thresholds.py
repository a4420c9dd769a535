"""The threshold engine: the height at which a point starts to see a target, exactly.

A point p standing at height z sees a target q exactly when z is at least its
*threshold* for q: the largest ``(s(u) - tol - qz) / u`` (plus the bulge of earth
curvature) over the breakpoints of the ground track from q to p that the exact LOS
engines visit (see :mod:`terrainvis.visibility._threshold_kernels`). From the thresholds
of a point against many partners and the partners' verdicts on another surface, the
height that agrees with the most verdicts is found by sorting them
(:func:`best_height`). The calibrated relocation
(:mod:`terrainvis.relocation.calibrated`) and the visibility-optimized simplifier
(:mod:`simplifiers.visopt`) are built on it.

A :class:`ThresholdSurface` holds a surface as the kernels read it (in local
coordinates: :meth:`ThresholdSurface.local` moves points there); the functions below take
it with points already local.

Examples
--------
>>> import numpy as np
>>> from terrainvis import HeightGrid
>>> S = HeightGrid.from_coords(np.array([[0.0, 0.0, 0.0], [0.0, 4.0, 0.0], [0.0, 0.0, 0.0]]),
...                            np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 2.0]))
>>> surf = ThresholdSurface(S)
>>> q = surf.local(np.array([[0.0, 1.0, 0.0], [2.0, 1.0, 0.0]]))
>>> thr = threshold_row(surf, q[0], q, skip=0)
>>> bool(thr[0] == -np.inf), round(float(thr[1]), 3)  # q[0] must stand ~8 above 0 to see q[1] over the peak
(True, 8.0)
"""

from __future__ import annotations

import numpy as np

from ..core.interrupt import call
from ..core.surface import SurfaceTin
from ..core.terrain import TIN, HeightGrid
from ..tolerances import THRESHOLD_MARGIN_REL
from . import _threshold_kernels as _tk
from .predicate import clearance_tolerance, terrain_scale, trim_length

__all__ = ["ThresholdSurface", "threshold_row", "gauss_seidel", "best_heights", "best_height", "best_height_kept",
           "interval", "MARGIN_REL"]

#: Height margin kept from thresholds, as a fraction of the terrain's scale (about 5 mm on a 5 km grid).
MARGIN_REL = THRESHOLD_MARGIN_REL

#: :func:`terrainvis.visibility._threshold_kernels.interval`: the tested interval ``(u0, u1)`` of
#: the segment p-q (the LOS engines' trim and end radius), ``(-1, -1)`` when none; a numba
#: function, callable from other kernels.
interval = _tk.interval
#: :func:`terrainvis.visibility._threshold_kernels.best_height`: ``(z, agreement)``, the height
#: that agrees with the most verdicts given a point's thresholds (a numba function).
best_height = _tk.best_height
#: :func:`terrainvis.visibility._threshold_kernels.best_height_kept`: :data:`best_height`
#: counting the point's neighbours too (a numba function).
best_height_kept = _tk.best_height_kept


class ThresholdSurface:
    """A surface as the threshold kernels read it, in local coordinates.

    Parameters
    ----------
    terrain : HeightGrid or TIN
        The surface (S(T) for a relocation); a grid is walked with the pair engine's
        min/max pyramid, a TIN from face to face.

    Attributes
    ----------
    terrain : HeightGrid or TIN
    grid : bool
        Whether ``terrain`` is a grid.
    delta, tol, margin : float
        The LOS engines' trim and clearance tolerance on it, and the height margin kept
        from thresholds (:data:`MARGIN_REL` times its scale).
    x0, y0 : float
        The local origin.
    data : SurfaceGrid or SurfaceTin
        The kernels' record of it (:mod:`terrainvis.core.surface`).
    ltop : int
        The grid's pyramid's root level (0 for a TIN).
    """

    def __init__(self, terrain):
        self.terrain = terrain
        self.grid = isinstance(terrain, HeightGrid)
        self.delta = float(trim_length(terrain))
        self.tol = float(clearance_tolerance(terrain))
        self.margin = MARGIN_REL * float(terrain_scale(terrain))
        if self.grid:
            from .grid import _walk_grid, grid_accel

            acc = grid_accel(terrain)
            self.x0, self.y0 = acc.x0, acc.y0
            self.data = _walk_grid(terrain, acc)
            self.ltop = acc.ltop
        else:
            self.x0, self.y0, self.data = _tin_surface(terrain)
            self.ltop = 0

    def local(self, xy: np.ndarray) -> np.ndarray:
        """A copy of the points ``xy`` (n, 2 or 3) in local coordinates (heights unchanged)."""
        out = np.array(xy, dtype=np.float64, copy=True)
        out[:, 0] -= self.x0
        out[:, 1] -= self.y0
        return out

    def rules(self, *, end_radius: float = 0.0, kc: float = 0.0, min_gain: int = 1,
              window: float = np.inf) -> _tk.Rules:
        """The kernels' :data:`~terrainvis.visibility._threshold_kernels.Rules` on this surface."""
        return _tk.Rules(self.delta, float(end_radius), self.tol, float(kc), self.margin, int(min_gain),
                         float(window))


def _tin_surface(tin: TIN):
    """The TIN as the threshold walk reads it (a :data:`~terrainvis.core.surface.SurfaceTin`
    with the faces' neighbours, local coordinates) and its origin (cached on the TIN)."""
    cached = tin._cache.get("calibration_walk")
    if cached is not None:
        return cached
    from ..core.mesh import edge_keys, half_edges

    bk = tin._buckets()
    faces = np.ascontiguousarray(tin.faces, dtype=np.int64)
    he = half_edges(faces)  # (3m, 2): edge e of face f is row 3 f + e
    key = edge_keys(he, tin.n_vertices, directed=True)
    twin = edge_keys(he[:, ::-1], tin.n_vertices, directed=True)
    order = np.argsort(key)
    pos = np.searchsorted(key[order], twin)
    pos = np.minimum(pos, key.size - 1)
    found = key[order][pos] == twin
    nbr = np.where(found, order[pos] // 3, -1).reshape(-1, 3).astype(np.int64)
    v = tin.vertices
    walk = SurfaceTin(
        np.ascontiguousarray(v[:, 0] - bk.x0), np.ascontiguousarray(v[:, 1] - bk.y0), np.ascontiguousarray(v[:, 2]),
        faces, nbr, bk.starts, bk.items, 0.0, 0.0, float(bk.bw), float(bk.bh), int(bk.nbx), int(bk.nby),
    )
    out = (float(bk.x0), float(bk.y0), walk)
    tin._cache["calibration_walk"] = out
    return out


def threshold_row(surface: ThresholdSurface, p, q: np.ndarray, *, skip: int = -1, end_radius: float = 0.0,
                  kc: float = 0.0, out: np.ndarray | None = None) -> np.ndarray:
    """The thresholds of the point ``p`` (local (x, y, z)) for every target ``q[k]`` (local, (n, 3)).

    ``p``'s height only sets the trim; ``kc`` is the curvature coefficient
    (:func:`terrainvis.visibility.curvature_coefficient`, 0: flat). A threshold of -inf:
    the segment is not tested (seen at any height), and so is target ``skip`` (the
    point itself when ``p`` is one of ``q``).
    """
    if out is None:
        out = np.empty(q.shape[0])
    point = (float(p[0]), float(p[1]), float(p[2]))
    kernel = _tk.grid_row if surface.grid else _tk.tin_row
    kernel(surface.data, point, q, surface.rules(end_radius=end_radius, kc=kc), int(skip), out)
    return out


def gauss_seidel(surface: ThresholdSurface, q: np.ndarray, order: np.ndarray, visible: np.ndarray, *,
                 end_radius: float = 0.0, kc: float = 0.0, min_gain: int = 1, window: float = np.inf) -> None:
    """One Gauss-Seidel sweep over the points ``q`` (local, (n, 3); heights updated in place):
    each point ``q[order[j]]`` in turn takes its best height against the others at their
    current heights, given the verdicts ``visible`` (n, n) to agree with. Interruptible.

    ``window`` (z units; inf: none) walks each point's thresholds exactly only within
    that distance of its current height first, and all of them exactly only when the
    choice made from those might not be the exact one: the same heights, bit for bit
    (the module docstring of :mod:`terrainvis.visibility._threshold_kernels`, "Windows")."""
    kernel = _tk.grid_sweep if surface.grid else _tk.tin_sweep
    n = q.shape[0]
    rules = surface.rules(end_radius=end_radius, kc=kc, min_gain=min_gain, window=_window(window))
    call(kernel, surface.data, q, order, visible, rules, work=n * n)


def best_heights(surface: ThresholdSurface, p: np.ndarray, q: np.ndarray, visible: np.ndarray, *,
                 neighbour_thresholds: np.ndarray, neighbour_verdicts: np.ndarray, weight: float,
                 end_radius: float = 0.0, kc: float = 0.0, min_gain: int = 1,
                 window: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
    """The best height of each point ``p[i]`` (local (x, y, reference height)) against the
    partners ``q`` (local, (K, 3)) whose verdicts it should agree with are ``visible[i]``,
    counting its neighbours (thresholds (n, L), verdicts (n, L) int8: 1 seen, 0 not, -1
    none; each weighing ``weight`` partners). Returns the heights (n,) and the partners'
    agreement (n,) int64. On numba's number of threads; interruptible. ``window`` as
    in :func:`gauss_seidel` (the same heights; not used when ``weight`` is inf)."""
    n = p.shape[0]
    out = np.empty(n)
    score = np.empty(n, dtype=np.int64)
    kernel = _tk.grid_heights if surface.grid else _tk.tin_heights
    near = _tk.Neighbours(neighbour_thresholds, neighbour_verdicts, float(weight))
    rules = surface.rules(end_radius=end_radius, kc=kc, min_gain=min_gain,
                          window=np.inf if weight == np.inf else _window(window))
    call(kernel, surface.data, p, q, visible, near, rules, out, score, work=n * q.shape[0], items=n)
    return out, score


def _window(window) -> float:
    """``window`` as the kernels take it: a positive float, inf for none."""
    w = float(window)
    if not w > 0.0:
        raise ValueError(f"window must be a positive number of z units (inf: none), got {window!r}")
    return w
