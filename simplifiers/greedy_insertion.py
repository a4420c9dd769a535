"""Greedy insertion (Garland & Heckbert 1995, Algorithm III): a Delaunay TIN refined point by point.

Start from the four corners (two triangles split along the grid's own diagonal). Each
triangle keeps one candidate, its grid sample with the largest vertical error (scan
conversion), and the candidates sit in an indexed max-heap. Each step pops the worst
candidate, inserts it (splitting its triangle in 3, or in 4 / 2 when the sample lies on
an interior / boundary edge), restores the Delaunay property by in-circle edge flips and
rescans only the triangles that changed. Expected cost O((m + n) log m) for m samples and
n vertices.

The geometry is done on the integer sample indices (exact orientation tests, exact scan
conversion), with the in-circle test of the Delaunay flips taken in the scaled space
``(col * dx, row * dy)``. On a uniform grid (any ``dx != dy``) this is exactly the world
space, so the vertical errors are the world-space errors. On a rectilinear grid with
non-uniform spacing the triangulation is built in the scaled index space (``dx``, ``dy`` =
the mean spacings) and the errors are measured on the surface interpolated in that space;
the output vertices are still the world samples ``(xs[c], ys[r], z[r, c])``, and a
triangle that would fold over in world space raises :class:`SimplificationError`.

References
----------
M. Garland and P. S. Heckbert, "Fast polygonal approximation of terrains and height
fields", Technical Report CMU-CS-95-181, Carnegie Mellon University, 1995.
"""

from __future__ import annotations


import numpy as np

from terrainvis.core.interrupt import call
from terrainvis.core.validate import as_int, as_nonnegative_finite, describe
from terrainvis.core.mesh import signed_area2
from terrainvis.errors import SimplificationError
from terrainvis.core.terrain import TIN, HeightGrid
from terrainvis.tolerances import SQUARE_CELL_REL

from . import _gi_kernels as K
from .levels import check_budget

__all__ = ["build", "GreedyInserter"]

_NAME = "greedy-insertion"
#: Largest grid side: the in-circle determinants (6 L^4) stay exact in int64 up to L ~ 35,000.
_MAX_SIDE = 32768


def _check_max_error(max_error):
    if max_error is None:
        return None
    return as_nonnegative_finite(max_error, "max_error", "in z units")


class GreedyInserter:
    """Resumable greedy-insertion state over one height grid.

    Parameters
    ----------
    grid : HeightGrid
        The terrain, without nodata. Its arrays are not modified.

    Notes
    -----
    :meth:`run` can be called again with a larger vertex count or a smaller error
    threshold and continues from the current TIN; the vertices already inserted are kept,
    so a run to ``n`` vertices followed by a run to ``m > n`` gives exactly the TIN of a
    single run to ``m``.

    Examples
    --------
    >>> import numpy as np
    >>> from terrainvis import HeightGrid
    >>> z = np.add.outer(np.arange(5.0), np.arange(5.0)) ** 2
    >>> gi = GreedyInserter(HeightGrid(z))
    >>> gi.run(n_vertices=6).n_vertices
    6
    >>> gi.run(max_error=0.0).max_error
    0.0
    """

    def __init__(self, grid: HeightGrid):
        if not isinstance(grid, HeightGrid):
            raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
        grid.require_finite("GreedyInserter")
        rows, cols = grid.shape
        if max(rows, cols) > _MAX_SIDE:
            raise ValueError(
                f"grid must have at most {_MAX_SIDE} samples per side for greedy insertion "
                f"(exact int64 in-circle tests), got {rows}x{cols}; subsample or crop it"
            )
        self.grid = grid
        self._W = cols
        self._z = np.ascontiguousarray(grid.z, dtype=np.float64).ravel()
        # in-circle test in the space (col * dx, row * dy): only (dy / dx)^2 matters
        ratio = (grid.dy / grid.dx) ** 2
        self._ratio = 1.0 if abs(ratio - 1.0) <= SQUARE_CELL_REL else float(ratio)
        self._counts = np.zeros(5, dtype=np.int64)
        self._vcap = 0
        self._alloc(min(grid.size, 64))
        K.init_state(self._z, cols, rows, self._state())
        self._max_error = float(self._hval[0]) if self._counts[K.NH] > 0 else 0.0

    # ---------------------------------------------------------------- storage
    def _alloc(self, vcap: int) -> None:
        """Grow every array to hold ``vcap`` vertices (2 * vcap triangles), keeping the state."""
        if vcap <= self._vcap:
            return
        tcap = 2 * vcap
        old = self._vcap

        def grow(name, size, dtype, fill):
            new = np.full(size, fill, dtype=dtype)
            if old:
                cur = getattr(self, name)
                new[: cur.size] = cur
            setattr(self, name, new)

        grow("_vx", vcap, np.int64, 0)
        grow("_vy", vcap, np.int64, 0)
        grow("_tri", 3 * tcap, np.int32, -1)
        grow("_half", 3 * tcap, np.int32, -1)
        grow("_cand", tcap, np.int64, -1)
        grow("_terr", tcap, np.float64, -1.0)
        grow("_heap", tcap, np.int32, -1)
        grow("_hval", tcap, np.float64, 0.0)
        grow("_pos", tcap, np.int32, -1)
        grow("_pend", tcap, np.int32, -1)
        grow("_pmark", tcap, np.bool_, False)
        self._stack = np.empty(3 * tcap + 16, dtype=np.int32)
        self._vcap = vcap

    def _state(self) -> K.State:
        """The kernel's named record over the current arrays (they are replaced when they grow)."""
        return K.State(
            self._vx, self._vy, self._tri, self._half, self._cand, self._terr, self._heap, self._hval, self._pos,
            self._pend, self._pmark, self._stack, self._counts,
        )

    # ---------------------------------------------------------------- running
    def run(self, n_vertices: int | None = None, max_error=None) -> "GreedyInserter":
        """Insert points until ``n_vertices`` vertices or until the max error is <= ``max_error``.

        Parameters
        ----------
        n_vertices : int, optional
            Stop at this many vertices, in [4, grid.size]; the default is every sample
            (stop on ``max_error`` only). Counts below the current one are rejected.
        max_error : float, optional
            Stop as soon as the largest vertical error (z units) is <= this.

        Returns
        -------
        GreedyInserter
            ``self``, so that ``gi.run(...).to_tin()`` works.
        """
        size = self.grid.size
        if n_vertices is None:
            target = size
        else:
            target = as_int(n_vertices, "n_vertices", minimum=4, maximum=size)
            if target < self.n_vertices:
                raise ValueError(
                    f"n_vertices must be >= the {self.n_vertices} vertices already inserted "
                    f"(greedy insertion only adds points), got {target}"
                )
        eps = _check_max_error(max_error)
        if n_vertices is None and eps is None:
            raise TypeError("run needs n_vertices, max_error or both")
        if eps is None:
            self._alloc(target)
        else:
            # the count is unknown up front: grow geometrically
            self._alloc(min(target, max(self._vcap, 64)))
        while True:
            goal = min(target, self._vcap)
            self._max_error = float(
                call(K.run, self._z, self._W, self._ratio, self._state(), goal, -1.0 if eps is None else eps,
                     work=self._z.size)
            )
            done_error = eps is not None and self._max_error <= eps
            if self.n_vertices >= target or done_error or self._counts[K.NH] == 0:
                break
            self._alloc(min(target, 2 * self._vcap))
        return self

    # ---------------------------------------------------------------- results
    @property
    def n_vertices(self) -> int:
        """Vertices inserted so far (the four corners included)."""
        return int(self._counts[K.NV])

    @property
    def n_triangles(self) -> int:
        return int(self._counts[K.NT])

    @property
    def max_error(self) -> float:
        """Largest vertical error of the current TIN over every grid sample (z units)."""
        return self._max_error

    def indices(self) -> np.ndarray:
        """(n, 2) int64 ``(row, col)`` of every vertex, in insertion order."""
        n = self.n_vertices
        return np.column_stack([self._vy[:n], self._vx[:n]])

    def to_tin(self) -> TIN:
        """The current TIN, vertices at the grid's world samples ``(xs[c], ys[r], z[r, c])``.

        Raises
        ------
        SimplificationError
            When a face folds over in world space (only possible on a strongly
            non-uniform rectilinear grid).
        """
        g = self.grid
        n = self.n_vertices
        cols = self._vx[:n]
        rows = self._vy[:n]
        vertices = np.column_stack([g.xs[cols], g.ys[rows], g.z[rows, cols]])
        faces = self._tri[: 3 * self.n_triangles].reshape(-1, 3).astype(np.int32)
        nz = signed_area2(vertices, faces)
        if not (nz > 0).all():
            raise SimplificationError(
                f"{_NAME}: {int((nz <= 0).sum())} of {nz.size} faces fold over when the index-space "
                f"triangulation is mapped to the world coordinates of this non-uniform grid"
            )
        meta = {
            "backend": "terrainvis numba (simplifiers._gi_kernels)",
            "greedy_max_error": self._max_error,
            "n_flips": int(self._counts[K.NFLIP]),
            "n_edge_splits": int(self._counts[K.NEDGE]),
        }
        return TIN(vertices, faces, attrs=meta)


def build(grid: HeightGrid, n_vertices: int, *, max_error=None) -> TIN:
    """Greedy-insertion TIN of ``grid`` with ``n_vertices`` vertices (Garland & Heckbert 1995).

    Parameters
    ----------
    grid : HeightGrid
        The terrain, without nodata (uniform or rectilinear; see the module notes).
    n_vertices : int
        Vertex budget in [4, grid.size]; the result has exactly this many vertices unless
        ``max_error`` stops it earlier.
    max_error : float, optional
        Also stop as soon as the largest vertical error is <= ``max_error`` (z units);
        the TIN then has fewer vertices and ``attrs["stopped_by"] == "max_error"``.

    Returns
    -------
    TIN
        Vertices are grid samples (the four corners first, then in insertion order), faces
        counter-clockwise. ``attrs`` holds ``stopped_by`` (``"budget"`` or ``"max_error"``),
        ``greedy_max_error`` (the largest vertical error over every sample), the numbers of
        edge flips and of edge splits, and the backend.

    Examples
    --------
    >>> import numpy as np
    >>> from terrainvis import HeightGrid
    >>> z = np.hypot(*np.meshgrid(np.arange(9.0), np.arange(9.0)))
    >>> build(HeightGrid(z, dx=30.0, dy=30.0), 20).n_vertices
    20

    References
    ----------
    M. Garland and P. S. Heckbert, "Fast polygonal approximation of terrains and height
    fields", CMU-CS-95-181, 1995.
    """
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
    grid.require_finite(f"{_NAME}.build")
    n = check_budget(grid.shape, n_vertices)
    eps = _check_max_error(max_error)
    gi = GreedyInserter(grid).run(n_vertices=n, max_error=eps)
    if gi.n_vertices < n and not (eps is not None and gi.max_error <= eps):
        raise SimplificationError(f"{_NAME}: ran out of candidates at {gi.n_vertices} of {n} vertices")
    tin = gi.to_tin()
    tin.attrs["stopped_by"] = "budget" if gi.n_vertices == n else "max_error"
    if eps is not None:
        tin.attrs["max_error_threshold"] = eps
    return tin
