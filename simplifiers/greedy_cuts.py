"""Greedy cuts (Silva, Mitchell & Kaufman 1995): an advancing-front subset TIN with an ε guarantee.

The front is a set of closed counter-clockwise polygons around the region not yet
triangulated. It starts at the grid boundary, simplified to the longest ε-valid boundary
segments, and each step removes one triangle on a front edge a -> b:

1. *ear cutting*: the triangle with the edge's previous or next front vertex;
2. *greedy biting*: the largest valid triangle whose apex is a grid sample on the inward
   normal through the edge's midpoint (galloping outwards, then bisecting); when a bite is
   blocked by the front, the blocking front vertex is tried as the apex (this connects the
   front to itself and splits a front loop in two, adding no vertex);
3. *edge splitting* (fallback): the free grid sample or front vertex left of the edge with
   the smallest circumcircle through a and b, i.e. the sample nearest the middle of the
   edge in the constrained-Delaunay sense. Its triangle holds no other sample except on
   the edge ab, whose samples are already within ε, so this step always succeeds and the
   front always closes. A sample is only ever inserted off the edge, never on it, so no
   finished triangle is split and no T-junction is made.

A triangle is *valid* when every grid sample in it (scan conversion) lies within ε
vertically of it, and it lies in the untriangulated region: no front edge meets its
interior, no other front vertex lies in it or on its sides, and its apex is a free sample
or a front vertex whose free angle holds it. So every sample of the grid lies within ε of
the TIN: ``max |TIN - z| <= epsilon``.

:func:`build` reaches a vertex budget by searching ε (see its docstring).

References
----------
.. [1] C. T. Silva, J. S. B. Mitchell and A. E. Kaufman, "Automatic generation of
   triangular irregular networks using greedy cuts", Proc. IEEE Visualization '95,
   pp. 201-208, 1995. DOI 10.1109/VISUAL.1995.480813
.. [2] C. T. Silva and J. S. B. Mitchell, "Greedy cuts: an advancing front terrain
   triangulation algorithm", Proc. ACM GIS '98, pp. 137-144, 1998.
   DOI 10.1145/288692.288717
"""

from __future__ import annotations

import math

import numpy as np

from terrainvis._validate import as_int, as_nonnegative_finite, describe
from terrainvis.errors import SimplificationError
from terrainvis.terrain import TIN, HeightGrid

from . import _gc_kernels

__all__ = ["build", "greedy_cuts"]

_METHOD = "greedy-cuts"


def _plane_coords(grid: HeightGrid) -> tuple[np.ndarray, np.ndarray, str]:
    """Coordinates the kernel computes in: indices on a uniform grid, local world coordinates otherwise."""
    rows, cols = grid.shape
    if grid.is_uniform:
        return np.arange(cols, dtype=np.float64), np.arange(rows, dtype=np.float64), "index"
    return np.ascontiguousarray(grid.xs - grid.xs[0]), np.ascontiguousarray(grid.ys - grid.ys[0]), "world"


def _boundary(gx, gy, z, eps: np.ndarray) -> np.ndarray:
    """The initial front: the four sides simplified to ε-valid segments, counter-clockwise from (0, 0)."""
    rows, cols = z.shape
    zf = z.ravel()
    idx = np.arange(rows * cols, dtype=np.int64).reshape(rows, cols)
    sides = (idx[0, :], idx[:, cols - 1], idx[rows - 1, ::-1], idx[::-1, 0])
    parts = [
        _gc_kernels.boundary_chain(np.ascontiguousarray(s), gx, gy, zf, cols, eps)[:-1]
        for s in sides
    ]
    return np.concatenate(parts)


def _run(grid: HeightGrid, gx, gy, eps: float, eps_first: float | None = None, k: int = 0, order=None):
    """One triangulation: the first k samples of ``order`` (default: row-major) get
    ``eps_first``, the others ``eps``."""
    z = np.ascontiguousarray(grid.z, dtype=np.float64)
    epsmap = np.full(grid.size, float(eps))
    if k:
        epsmap[slice(0, k) if order is None else order[:k]] = eps_first
    boundary = _boundary(gx, gy, z, epsmap)
    window = 2 * max(grid.shape)
    tris, counts = _gc_kernels.greedy_cuts_front(gx, gy, z, epsmap, boundary, window)
    if counts[3] != 0:
        raise SimplificationError(
            f"{_METHOD}: the advancing front got stuck at epsilon={eps!r} on a {grid.shape} grid "
            f"(status {int(counts[3])}, {tris.shape[0]} triangles made)"
        )
    return tris, counts


def _to_tin(grid: HeightGrid, tris: np.ndarray, meta: dict) -> TIN:
    cols = grid.shape[1]
    used, inverse = np.unique(tris.ravel(), return_inverse=True)
    r, c = np.divmod(used, cols)
    vertices = np.column_stack([grid.xs[c], grid.ys[r], grid.z[r, c]])
    faces = inverse.reshape(-1, 3)
    return TIN(vertices, faces, attrs=meta)


def _check_grid(grid) -> None:
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
    grid.require_finite(_METHOD)


def _check_epsilon(epsilon) -> float:
    return as_nonnegative_finite(epsilon, "epsilon", "z units")


def greedy_cuts(grid: HeightGrid, epsilon: float) -> TIN:
    """Greedy-cuts TIN of ``grid`` with every sample within ``epsilon`` of the surface.

    Parameters
    ----------
    grid : HeightGrid
        The terrain (no nodata); uniform or rectilinear, any cell aspect.
    epsilon : float
        Largest allowed vertical error, in z units (>= 0).

    Returns
    -------
    TIN
        A subset TIN (every vertex is a grid sample, at its world coordinates) covering
        the grid's extent, with ``max |TIN(x, y) - z| <= epsilon`` over all samples.
        ``attrs`` holds ``epsilon``, ``n_ears`` (triangles adding no vertex: ears and
        connections to the front), ``n_bites`` (triangles adding a vertex, including
        ``n_splits`` fallback insertions), ``n_evaluated`` (candidate triangles tested)
        and ``plane_space`` (``"index"`` or ``"world"``, see ``_gc_kernels``).

    Examples
    --------
    >>> import numpy as np
    >>> from terrainvis import HeightGrid
    >>> g = HeightGrid(np.add.outer(np.arange(5.0), np.arange(5.0)))  # a plane
    >>> greedy_cuts(g, 0.0).n_vertices
    4
    """
    _check_grid(grid)
    eps = _check_epsilon(epsilon)
    gx, gy, space = _plane_coords(grid)
    tris, counts = _run(grid, gx, gy, eps)
    return _to_tin(grid, tris, _meta(eps, counts, space, 1))


def _meta(eps, counts, space, runs) -> dict:
    return {
        "method": _METHOD, "epsilon": float(eps), "n_ears": int(counts[0]), "n_bites": int(counts[1]),
        "n_splits": int(counts[2]), "n_evaluated": int(counts[4] + counts[5] + counts[6]),
        "plane_space": space, "runs": int(runs),
    }


def build(grid: HeightGrid, n_vertices: int, *, epsilon: float | None = None) -> TIN:
    """Greedy-cuts TIN with ``n_vertices`` vertices (within 1 %), found by searching ε.

    Parameters
    ----------
    grid : HeightGrid
        The terrain (no nodata).
    n_vertices : int
        The vertex budget, in [4, grid.size].
    epsilon : float, optional
        A first guess for ε (z units); the default starts from 2 % of the height range.

    Returns
    -------
    TIN
        Every sample lies within ``attrs["epsilon"]`` of it; ``attrs["runs"]`` counts the
        triangulations made. When the budget needed the mixed tolerance (step 2 below),
        ``attrs["epsilon_rest"]`` is the smaller tolerance and
        ``attrs["n_samples_at_epsilon"]`` the number of samples (the first of the order
        ``attrs["mixed_order"]``) allowed ``attrs["epsilon"]``.

    Raises
    ------
    SimplificationError
        When no tried ε lands within the tolerance, or when even ε = 0 gives fewer
        vertices than the budget (a grid with large exactly planar parts).

    Notes
    -----
    The vertex count falls as ε grows, but in steps and not monotonically: one large
    triangle accepted early changes the whole front after it. The search has three
    stages and stops at the first count within ``max(1, 1 %)`` of the budget:

    1. A bracket ``eps_lo`` (too many vertices, starting at 0) and ``eps_hi`` (too few,
       starting at the height range, where the two corner triangles are valid: 4
       vertices); the next ε interpolates log(count) against log(ε) (a power law), kept
       inside the middle 80 % of the log bracket (a safeguarded secant method). Until
       both ends have been measured it assumes count ~ 1/ε (the rate of a smooth
       surface), with steps of at most a factor 8. Stops when the bracket is narrower than
       1e-4 relative: the count jumps over the window there.
    2. A mixed tolerance across the jump: the first k samples of an order (row-major,
       then column-major, then fixed pseudo-random permutations: 60 on grids of up to
       250,000 samples, where runs are cheap and the window narrowest, else 4)
       may be ``eps_hi`` off, the others ``eps_lo``; k = 0 gives too many vertices and
       k = all too few, and a bisection on k lands in between (the guarantee is then
       ``eps_hi``; ``attrs["mixed_order"]`` names the order).
       This is needed on quantised DEMs (integer metres), where thousands of samples
       have errors of exactly 1 and the count jumps by a quarter at ε = 1.
    3. Last resort: ε within ±2 % of the jump in steps of 0.1 %.
    """
    from .levels import budget_tolerance

    _check_grid(grid)
    budget = as_int(n_vertices, "n_vertices")
    if budget < 4 or budget > grid.size:
        raise ValueError(
            f"n_vertices must be in [4, {grid.size}] for a {grid.shape[0]}x{grid.shape[1]} grid, got {budget}"
        )
    tol = budget_tolerance(budget)
    gx, gy, space = _plane_coords(grid)
    zmin = float(grid.z.min())
    ptp = float(grid.z.max()) - zmin
    runs = 0
    tried = []

    def attempt(eps, eps_first=None, k=0, order=None):
        nonlocal runs
        runs += 1
        tris, counts = _run(grid, gx, gy, eps, eps_first, k, order)
        n = int(np.unique(tris).size)
        tried.append((eps if not k else eps_first, n))
        return n, tris, counts

    def finish(eps, tris, counts, eps_rest=None, k=0, order_name=None):
        meta = _meta(eps, counts, space, runs)
        if k:
            meta.update(epsilon_rest=float(eps_rest), n_samples_at_epsilon=int(k), mixed_order=order_name)
        return _to_tin(grid, tris, meta)

    if ptp == 0.0:
        n, tris, counts = attempt(0.0)
        if abs(n - budget) <= tol:
            return finish(0.0, tris, counts)
        raise SimplificationError(
            f"{_METHOD}: the grid is flat, so every epsilon gives {n} vertices; the budget {budget} cannot be reached"
        )
    # 1. a safeguarded secant search on eps, in log(count) against log(eps)
    lo_e, lo_n = 0.0, grid.size
    hi_e, hi_n = ptp, 4
    eps = _check_epsilon(epsilon) if epsilon is not None else 0.02 * ptp
    if not (0.0 < eps < ptp):
        eps = 0.02 * ptp
    for _ in range(40):
        n, tris, counts = attempt(eps)
        if abs(n - budget) <= tol:
            return finish(eps, tris, counts)
        if n > budget:
            lo_e, lo_n = eps, n
        else:
            hi_e, hi_n = eps, n
        if hi_e - lo_e <= 1e-4 * hi_e:
            break
        if lo_e > 0.0 and hi_e < ptp:
            a, b = math.log(lo_e), math.log(hi_e)
            slope = (math.log(hi_n) - math.log(lo_n)) / (b - a)
            x = a + (math.log(budget) - math.log(lo_n)) / slope if slope < 0 else 0.5 * (a + b)
            x = min(max(x, a + 0.1 * (b - a)), b - 0.1 * (b - a))
            eps = math.exp(x)
        elif lo_e > 0.0:  # only too many vertices so far: assume count ~ 1 / eps, at most x8
            eps = min(lo_e * min(lo_n / budget, 8.0), 0.5 * (lo_e + ptp))
        else:  # only too few vertices so far
            eps = hi_e * max(hi_n / budget, 1.0 / 8.0)
    # 2. the count jumps over the window between lo_e and hi_e: mix the two. The first k
    #    samples (row-major) may be hi_e off, the others lo_e; k = 0 gives lo_n vertices,
    #    k = grid.size gives hi_n, and a bisection on k lands in between. The guarantee
    #    is then max error <= hi_e.
    if lo_e == 0.0:
        n, tris, counts = attempt(0.0)
        if abs(n - budget) <= tol:
            return finish(0.0, tris, counts)
        if n < budget:
            raise SimplificationError(
                f"{_METHOD}: even epsilon = 0 gives only {n} vertices (the grid has large planar parts), "
                f"fewer than the budget {budget} - {tol}"
            )
    #    The count is not monotone in k either, so when one order's bisection misses the
    #    window, the next order is tried: row-major, column-major, then fixed
    #    pseudo-random permutations (deterministic).
    #    Runs are cheap on small grids (where the window is also narrowest, +-1 vertex),
    #    so they get more orders and a larger run cap.
    small = grid.size <= 250_000
    max_runs = 2000 if small else 200
    n_perm = 60 if small else 4
    orders = [("row-major", None), ("column-major", np.arange(grid.size).reshape(grid.shape).T.ravel())]
    orders += [(f"permutation {seed}", np.random.default_rng(seed).permutation(grid.size)) for seed in range(n_perm)]
    for order_name, order in orders:
        if runs >= max_runs:
            break
        k_lo, k_hi = 0, grid.size
        while k_hi - k_lo > 1 and runs < max_runs:
            k = (k_lo + k_hi) // 2
            n, tris, counts = attempt(lo_e, hi_e, k, order)
            if abs(n - budget) <= tol:
                return finish(hi_e, tris, counts, lo_e, k, order_name)
            if n > budget:
                k_lo = k
            else:
                k_hi = k
    # 3. last resort: walk outwards from the jump in steps of 0.1 % of eps, alternating sides
    centre = 0.5 * (lo_e + hi_e)
    for j in range(1, 41):
        e = centre * (1.0 + (1 if j % 2 else -1) * 0.001 * ((j + 1) // 2))
        n, tris, counts = attempt(e)
        if abs(n - budget) <= tol:
            return finish(e, tris, counts)
    closest = min(tried, key=lambda t: abs(t[1] - budget))
    raise SimplificationError(
        f"{_METHOD}: no epsilon gave {budget} +- {tol} vertices on a {grid.shape} grid after {runs} runs; "
        f"the closest was {closest[1]} vertices at epsilon={closest[0]:.6g}"
    )
