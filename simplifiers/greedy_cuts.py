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

:func:`greedy_cuts` triangulates at one tolerance; :func:`build` reaches a vertex budget
by searching ε (see its Notes).

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
from dataclasses import dataclass, field

import numpy as np

from terrainvis.core.interrupt import call
from terrainvis.core.validate import as_nonnegative_finite, describe
from terrainvis.errors import SimplificationError
from terrainvis.core.terrain import TIN, HeightGrid
from terrainvis.tolerances import EPS_BRACKET_FLOOR_REL, EPS_GUESS_FLOOR_REL, WHOLE_UNIT_SLACK

from . import _gc_kernels as K
from .levels import budget_tolerance, check_budget

__all__ = ["build", "greedy_cuts"]

_METHOD = "greedy-cuts"

#: A bracket on ε narrower than this (relative) holds a jump of the vertex count.
_JUMP = 1e-3
#: Most runs of each search stage (deterministic caps, so the result never depends on time).
_MAX_BRACKET_RUNS = 40
_MAX_PROBE_RUNS = 60
_MAX_MIXED_ORDERS = 6
#: Most runs of the mixed-tolerance stage, in units of log2(grid size).
_MIXED_RUNS_PER_LOG2 = 3
#: The ε probes of stage 3 lie within this relative distance of the jump.
_PROBE_SPAN = 0.02
#: Stage 4: how far below the bracket's top (relative) the mixed tolerance's smaller ε goes.
_WIDENINGS = (0.1, 0.25, 0.5)
#: Lines (rows and columns each) followed by the 1-D estimate of the first guess.
_MODEL_LINES = 32
#: The fractions 1/k of a rectilinear grid's least step tried as the unit of its whole-number plane
#: coordinates (a coordinate may lie :data:`~terrainvis.tolerances.WHOLE_UNIT_SLACK` units from a
#: whole number and count as one).
_UNIT_DIVISORS = 64


# ---------------------------------------------------------------- one triangulation
def _plane_coords(grid: HeightGrid) -> tuple[np.ndarray, np.ndarray, str]:
    """Coordinates the kernel computes in, and their name (``attrs["plane_space"]``).

    ``"index"``: a uniform grid's column and row indices. ``"lattice"``: a rectilinear grid
    whose coordinates along each axis are whole multiples of one unit (the S(T) of the
    reverse Faber methods, whose last step is shorter or longer than the others; a DEM cut
    to a partial last cell), as those whole numbers. Both are affine images of the world
    coordinates with a positive determinant, in whole numbers, where every orientation test
    of the kernel is exact. ``"world"``: any other rectilinear grid, in world coordinates from
    a local origin, where the tests round. Rounding matters where samples are exactly
    collinear, as on a lattice: computed in world coordinates, the S(T) grids made the front
    find no valid triangle ("got stuck"); samples in general position (an irregular
    rectilinear grid) agree.
    """
    rows, cols = grid.shape
    if grid.is_uniform:
        return np.arange(cols, dtype=np.float64), np.arange(rows, dtype=np.float64), "index"
    gx, gy = _whole_units(grid.xs), _whole_units(grid.ys)
    if gx is not None and gy is not None:
        return gx, gy, "lattice"
    return np.ascontiguousarray(grid.xs - grid.xs[0]), np.ascontiguousarray(grid.ys - grid.ys[0]), "world"


def _whole_units(coords: np.ndarray) -> np.ndarray | None:
    """``coords - coords[0]`` in whole multiples of the largest unit that divides every step
    (a fraction 1/k of the least step, k <= :data:`_UNIT_DIVISORS`), or None when there is
    none (to :data:`~terrainvis.tolerances.WHOLE_UNIT_SLACK` of the unit) or the multiples
    reach 2**25 (past which a product of two differences is no longer exact in float64)."""
    local = coords - coords[0]
    least = float(np.diff(coords).min())
    for k in range(1, _UNIT_DIVISORS + 1):
        units = local / (least / k)
        whole = np.round(units)
        if whole[-1] >= 2.0**25:
            return None
        if np.abs(units - whole).max() <= WHOLE_UNIT_SLACK:
            return np.ascontiguousarray(whole)
    return None


@dataclass
class _Run:
    """One triangulation. ``n`` is the vertex count, or its extrapolation when the run
    stopped early (``complete`` False) on passing the budget."""

    eps: float  # the guarantee: the largest tolerance any sample had
    n: int
    complete: bool
    tris: np.ndarray
    counts: np.ndarray
    eps_rest: float | None = None  # mixed tolerance: the others' tolerance
    k: int = 0  # mixed tolerance: samples allowed ``eps``
    order_name: str | None = None


class _Triangulator:
    """Runs of the front kernel on one grid (the coordinates and heights prepared once)."""

    def __init__(self, grid: HeightGrid):
        self.grid = grid
        self.gx, self.gy, self.space = _plane_coords(grid)
        self.z = np.ascontiguousarray(grid.z, dtype=np.float64)
        self.integer = bool(np.array_equal(self.z, np.round(self.z)))  # heights in whole units
        self.runs = 0

    def _boundary(self, eps_map: np.ndarray) -> np.ndarray:
        """The initial front: the four sides simplified to ε-valid segments, counter-clockwise from (0, 0)."""
        rows, cols = self.z.shape
        idx = np.arange(rows * cols, dtype=np.int64).reshape(rows, cols)
        sides = (idx[0, :], idx[:, cols - 1], idx[rows - 1, ::-1], idx[::-1, 0])
        zf = self.z.ravel()
        parts = [
            K.boundary_chain(np.ascontiguousarray(s), self.gx, self.gy, zf, cols, eps_map)[:-1] for s in sides
        ]
        return np.concatenate(parts)

    def run(self, eps: float, *, max_vertices: int | None = None, eps_rest: float | None = None, k: int = 0,
            order: np.ndarray | None = None, order_name: str | None = None) -> _Run:
        """Triangulate with tolerance ``eps``; with ``eps_rest``, only the first ``k``
        samples of ``order`` (default: row-major) get ``eps``, the others ``eps_rest``.
        With ``max_vertices``, stop as soon as the count passes it."""
        self.runs += 1
        size = self.z.size
        if eps_rest is None:
            eps_map = np.full(size, float(eps))
        else:
            eps_map = np.full(size, float(eps_rest))
            eps_map[slice(0, k) if order is None else order[:k]] = eps
        boundary = self._boundary(eps_map)
        limit = np.iinfo(np.int64).max if max_vertices is None else int(max_vertices)
        tris, counts = call(
            K.greedy_cuts_front, self.gx, self.gy, self.space == "index", self.z, eps_map, boundary,
            2 * max(self.z.shape), limit, work=size,
        )
        status = int(counts[K.STATUS])
        if status == K.OVER_BUDGET:
            n = max(self._extrapolate(boundary.size, counts), limit + 1)
            return _Run(float(eps), n, False, tris, counts, eps_rest, k, order_name)
        if status != K.DONE:
            raise SimplificationError(
                f"{_METHOD}: the advancing front got stuck at epsilon={eps!r} on a {self.grid.shape} grid "
                f"(status {status}, {tris.shape[0]} triangles made)"
            )
        return _Run(float(eps), int(counts[K.N_VERTICES]), True, tris, counts, eps_rest, k, order_name)

    def _extrapolate(self, n_boundary: int, counts: np.ndarray) -> int:
        """The vertex count a stopped run would have reached: its interior vertices per
        interior sample covered so far, over the whole interior."""
        rows, cols = self.z.shape
        interior = (rows - 2) * (cols - 2)
        covered = int(counts[K.N_COVERED]) - (rows * cols - interior)
        return n_boundary + int(round(int(counts[K.N_BITES]) * interior / max(covered, 1)))

    def tin(self, run: _Run, **extra) -> TIN:
        """The run's TIN, vertices at the grid's world samples, with its metadata."""
        grid = self.grid
        counts = run.counts
        meta = {
            "method": _METHOD, "epsilon": run.eps, "n_ears": int(counts[K.N_EARS]),
            "n_bites": int(counts[K.N_BITES]), "n_splits": int(counts[K.N_SPLITS]),
            "n_evaluated": int(counts[K.N_EVAL_EAR] + counts[K.N_EVAL_BITE] + counts[K.N_EVAL_SPLIT]),
            "plane_space": self.space, "runs": self.runs,
        }
        if run.eps_rest is not None:
            meta.update(epsilon_rest=float(run.eps_rest), n_samples_at_epsilon=int(run.k), mixed_order=run.order_name)
        meta.update(extra)
        used, inverse = np.unique(run.tris.ravel(), return_inverse=True)
        r, c = np.divmod(used, grid.shape[1])
        vertices = np.column_stack([grid.xs[c], grid.ys[r], grid.z[r, c]])
        return TIN(vertices, inverse.reshape(-1, 3), attrs=meta)


def _check_grid(grid) -> None:
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
    grid.require_finite(_METHOD)


def greedy_cuts(grid: HeightGrid, max_error: float) -> TIN:
    """Greedy-cuts TIN of ``grid`` with every sample within ``max_error`` of the surface.

    Parameters
    ----------
    grid : HeightGrid
        The terrain (no nodata); uniform or rectilinear, any cell aspect.
    max_error : float
        Largest allowed vertical error ε, in z units (>= 0).

    Returns
    -------
    TIN
        A subset TIN (every vertex is a grid sample, at its world coordinates) covering
        the grid's extent, with ``max |TIN(x, y) - z| <= max_error`` over all samples.
        ``attrs`` holds ``epsilon`` (= ``max_error``), ``n_ears`` (triangles adding no
        vertex: ears and connections to the front), ``n_bites`` (triangles adding a
        vertex, including ``n_splits`` fallback insertions), ``n_evaluated`` (candidate
        triangles tested), ``plane_space`` (``"index"``, ``"lattice"`` or
        ``"world"``: the kernel's coordinates, see ``_plane_coords``) and ``runs`` (1).

    Examples
    --------
    >>> import numpy as np
    >>> from terrainvis import HeightGrid
    >>> g = HeightGrid(np.add.outer(np.arange(5.0), np.arange(5.0)))  # a plane
    >>> greedy_cuts(g, 0.0).n_vertices
    4
    >>> z = np.zeros((5, 5)); z[2, 2] = 1.0  # one bump
    >>> greedy_cuts(HeightGrid(z), 0.5).n_vertices, greedy_cuts(HeightGrid(z), 1.0).n_vertices
    (5, 4)

    References
    ----------
    C. T. Silva, J. S. B. Mitchell and A. E. Kaufman, "Automatic generation of triangular
    irregular networks using greedy cuts", IEEE Visualization '95, 1995.
    DOI 10.1109/VISUAL.1995.480813
    """
    _check_grid(grid)
    eps = as_nonnegative_finite(max_error, "max_error", "z units")
    tri = _Triangulator(grid)
    return tri.tin(tri.run(eps))


# ---------------------------------------------------------------- the search on ε
def _kappa(density: float) -> float:
    """Vertices of the triangulation per product of the row and column 1-D densities.

    An empirical fit (2.85 at a quarter of the samples, 3.7 at a sixteenth and below;
    how it was measured is in docs/performance.md#simplifiers-figures-behind-their-defaults): a first guess only, which
    the search corrects.
    """
    return float(np.clip(2.85 * (0.25 / density) ** 0.19, 2.0, 3.7))


def _slope(density: float) -> float:
    """Typical -d log(count) / d log(ε) at this vertex density (an empirical fit, as :func:`_kappa`)."""
    return float(np.clip(1.3 + 0.165 * math.log2(0.125 / density), 1.0, 2.0))


@dataclass
class _Search:
    """The state of the search on ε for a vertex budget: the bracket and the runs so far.

    ``lo_eps`` gave too many vertices (``lo_n``), ``hi_eps`` too few (``hi_n``); before
    any run they are 0 (every sample, at most) and the height range ``ptp`` (the two
    corner triangles: 4 vertices).
    """

    tri: _Triangulator
    budget: int
    tol: int = field(init=False)
    ptp: float = field(init=False)
    lo_eps: float = field(init=False)
    lo_n: int = field(init=False)
    hi_eps: float = field(init=False)
    hi_n: int = field(init=False)
    lo_weight: float = 1.0  # Illinois weights of the two ends in the secant
    hi_weight: float = 1.0
    last_side: int = 0  # +1: the last narrowing moved lo, -1: hi
    chaotic: bool = False  # a larger ε gave clearly more vertices than a smaller one
    points: list = field(default_factory=list)  # (ε, count) of every single-tolerance run

    def __post_init__(self):
        z = self.tri.z
        self.tol = budget_tolerance(self.budget)
        self.ptp = float(z.max()) - float(z.min())
        self.lo_eps, self.lo_n = 0.0, z.size
        self.hi_eps, self.hi_n = self.ptp, 4

    @property
    def grid(self) -> HeightGrid:
        return self.tri.grid

    def measure(self, eps: float, **mixed) -> _Run:
        """One run, stopped once it is known to be over the window."""
        return self.tri.run(eps, max_vertices=self.budget + self.tol, **mixed)

    def hit(self, run: _Run) -> bool:
        return run.complete and abs(run.n - self.budget) <= self.tol

    def narrow(self, run: _Run) -> None:
        """Move the bracket's end on the run's side to the run's ε.

        When the same end moves twice in a row, the other end's weight in the secant
        halves (the Illinois rule: regula falsi otherwise creeps towards a jump).
        """
        side = 1 if run.n > self.budget else -1
        if side == 1:
            self.lo_eps, self.lo_n = run.eps, run.n
        else:
            self.hi_eps, self.hi_n = run.eps, run.n
        if side == self.last_side:
            if side == 1:
                self.hi_weight *= 0.5
            else:
                self.lo_weight *= 0.5
        else:
            self.lo_weight = self.hi_weight = 1.0
        self.last_side = side
        for eps, n in self.points:
            if (eps < run.eps and n < run.n - self.tol) or (eps > run.eps and n > run.n + self.tol):
                self.chaotic = True
        self.points.append((run.eps, run.n))

    def finish(self, run: _Run, stage: str, *, stopped_by: str = "budget") -> TIN:
        return self.tri.tin(run, stopped_by=stopped_by, search_stage=stage)


def _model_count(tri: _Triangulator, eps: float, kappa: float) -> float:
    """The 1-D estimate of the vertex count at ``eps``: ``kappa`` times the grid's size
    times the vertex densities of greedy ε-chains along evenly spaced rows and columns."""
    rows, cols = tri.z.shape
    r = np.unique(np.linspace(0, rows - 1, min(_MODEL_LINES, rows)).round().astype(np.int64))
    c = np.unique(np.linspace(0, cols - 1, min(_MODEL_LINES, cols)).round().astype(np.int64))
    along_r, along_c = K.line_segments(tri.z, tri.gx, tri.gy, r, c, float(eps))
    density_r = along_r / (r.size * (cols - 1)) if cols > 1 else 1.0
    density_c = along_c / (c.size * (rows - 1)) if rows > 1 else 1.0
    return kappa * density_r * density_c * rows * cols


def _first_guess(search: _Search) -> float:
    """ε where the 1-D estimate of the count meets the budget (bisection on log ε)."""
    kappa = _kappa(search.budget / search.grid.size)
    lo, hi = math.log(search.hi_eps * EPS_GUESS_FLOOR_REL), math.log(search.hi_eps)
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if _model_count(search.tri, math.exp(mid), kappa) > search.budget:
            lo = mid
        else:
            hi = mid
    eps = math.exp(0.5 * (lo + hi))
    if not search.lo_eps < eps < search.hi_eps:  # a run (at max_error) already rules it out
        eps = math.sqrt(search.lo_eps * search.hi_eps)
    return eps


def _next_eps(search: _Search, last: _Run) -> float:
    """The next ε of the bracket stage: a safeguarded secant on log(count) against log(ε).

    On whole-number heights, a run that just gave too few vertices at (or just above) a
    multiple of 1/2 is followed by one just below it: many samples have exactly that
    error, and if the count jumps there the bracket closes in one run.
    """
    s = search
    if s.tri.integer and last.eps == s.hi_eps < s.ptp and s.hi_eps - s.lo_eps > _JUMP * s.hi_eps:
        tie = math.floor(2.0 * s.hi_eps) / 2.0
        below = tie * (1.0 - 0.5 * _JUMP)
        if s.hi_eps - tie <= 0.5 * _JUMP * s.hi_eps and below > s.lo_eps:
            return below
    if s.lo_eps > 0.0 and s.hi_eps < s.ptp:  # both ends measured: interpolate, keep inside
        a, b = math.log(s.lo_eps), math.log(s.hi_eps)
        f_lo = s.lo_weight * (math.log(s.lo_n) - math.log(s.budget))  # > 0
        f_hi = s.hi_weight * (math.log(s.hi_n) - math.log(s.budget))  # <= 0
        x = a + f_lo / (f_lo - f_hi) * (b - a)
        return math.exp(min(max(x, a + 0.1 * (b - a)), b - 0.1 * (b - a)))
    # one side only: step with the typical slope, at most a factor 8
    step = (last.n / s.budget) ** (1.0 / _slope(s.budget / s.grid.size))
    eps = last.eps * min(max(step, 1.0 / 8.0), 8.0)
    if not s.lo_eps < eps < s.hi_eps:
        eps = math.sqrt(max(s.lo_eps, s.hi_eps * EPS_BRACKET_FLOOR_REL) * s.hi_eps) if s.lo_eps > 0.0 else 0.5 * s.hi_eps
    return eps


def _stage_bracket(search: _Search, eps: float) -> _Run | None:
    """Stage 1: runs from ``eps`` on, narrowing the bracket, until one lands in the window
    (returned) or the bracket is narrower than ``_JUMP`` (None: the count jumps there).
    When the counts are chaotic, it stops once the bracket is inside the probes' span."""
    for _ in range(_MAX_BRACKET_RUNS):
        run = search.measure(eps)
        if search.hit(run):
            return run
        search.narrow(run)
        width = search.hi_eps - search.lo_eps
        if width <= _JUMP * search.hi_eps or (search.chaotic and width <= _PROBE_SPAN * search.hi_eps):
            return None
        eps = _next_eps(search, run)
    return None


def _orders(size: int, shape: tuple[int, int]):
    """Sample orders for the mixed tolerance: row-major, column-major, then fixed permutations."""
    yield "row-major", None
    yield "column-major", np.arange(size).reshape(shape).T.ravel()
    for seed in range(_MAX_MIXED_ORDERS - 2):
        yield f"permutation {seed}", np.random.default_rng(seed).permutation(size)


def _stage_mixed(search: _Search) -> _Run | None:
    """Stage 2: a mixed tolerance across the jump.

    The first k samples of an order may be ``hi_eps`` off, the others ``lo_eps``; k = 0
    gives ``lo_n`` vertices (too many) and k = all ``hi_n`` (too few), and a safeguarded
    interpolation on k (regula falsi kept inside the middle 80 % of the k bracket) lands
    in between. The guarantee is then ``hi_eps``. The count is not monotone in k either,
    so when an order misses the window the next is tried.
    """
    s = search
    size = s.grid.size
    runs_left = _MIXED_RUNS_PER_LOG2 * max(1, math.ceil(math.log2(size)))
    for name, order in _orders(size, s.grid.shape):
        k_lo, n_lo, k_hi, n_hi = 0, s.lo_n, size, s.hi_n
        repeats = 0  # runs in a row that repeated an end's count: an atomic jump, not ties
        while k_hi - k_lo > 1 and repeats < 2:
            if runs_left == 0:
                return None
            runs_left -= 1
            t = (n_lo - s.budget) / (n_lo - n_hi) if n_lo != n_hi else 0.5
            k = k_lo + t * (k_hi - k_lo)
            margin = 0.1 * (k_hi - k_lo)
            k = int(round(min(max(k, k_lo + margin), k_hi - margin)))
            k = min(max(k, k_lo + 1), k_hi - 1)
            run = s.measure(s.hi_eps, eps_rest=s.lo_eps, k=k, order=order, order_name=name)
            if s.hit(run):
                return run
            repeats = repeats + 1 if run.n in (n_lo, n_hi) else 0
            if run.n > s.budget:
                k_lo, n_lo = k, run.n
            else:
                k_hi, n_hi = k, run.n
    return None


def _stage_probe(search: _Search) -> _Run | None:
    """Stage 3: single tolerances spread over ±``_PROBE_SPAN`` around the jump.

    On small budgets the count is chaotic near the target (one triangle accepted early
    changes the whole front after it), so nearby ε values give counts scattered around
    the trend and some land in the window. The probes follow the golden-ratio sequence
    (deterministic, evenly spread, never repeating).
    """
    s = search
    centre = math.sqrt(s.lo_eps * s.hi_eps) if s.lo_eps > 0.0 else s.hi_eps
    golden = 0.5 * (math.sqrt(5.0) - 1.0)
    for j in range(1, _MAX_PROBE_RUNS + 1):
        u = 2.0 * ((j * golden) % 1.0) - 1.0
        run = s.measure(centre * (1.0 + _PROBE_SPAN * u))
        if s.hit(run):
            return run
    return None


def _stage_wide(search: _Search) -> _Run | None:
    """Stage 4: the mixed tolerance across a wider bracket.

    Where the count is chaotic near the jump, every run there lands on one of two modes
    (a large triangle accepted early or not), the window lying between them, and neither
    the mixed tolerance across the narrow bracket nor the probes reach it. A smaller ε
    for the samples after the first k (``hi_eps`` times 1 - w, w in :data:`_WIDENINGS`)
    adds vertices where it applies, so the count moves from below the window (k = all)
    to well above it (k = 0) through many more values, and :func:`_stage_mixed` lands on
    one of them. The guarantee stays ``hi_eps``. When none lands, the bracket is left as
    it was (the error names the jump).
    """
    s = search
    top, jump = s.hi_eps, (s.lo_eps, s.lo_n)
    for w in _WIDENINGS:
        run = s.measure(top * (1.0 - w))
        if s.hit(run):
            return run
        if run.n > s.budget:
            s.lo_eps, s.lo_n = run.eps, run.n
            run = _stage_mixed(s)
            if run is not None:
                return run
    s.lo_eps, s.lo_n = jump
    return None


def _quantised(search: _Search) -> bool:
    """True when the heights are whole numbers and a multiple of 1/2 lies in (lo_eps,
    hi_eps]: a jump where many samples have exactly the same error (flat areas whole
    units apart)."""
    return search.tri.integer and math.floor(2.0 * search.lo_eps) + 1 <= 2.0 * search.hi_eps


def build(grid: HeightGrid, n_vertices: int, *, max_error: float | None = None,
          epsilon_guess: float | None = None) -> TIN:
    """Greedy-cuts TIN with ``n_vertices`` vertices (within 1 %), found by searching ε.

    Parameters
    ----------
    grid : HeightGrid
        The terrain (no nodata).
    n_vertices : int
        The vertex budget, in [4, grid.size].
    max_error : float, optional
        Largest allowed vertical error (z units), as in greedy insertion: when the
        triangulation at ε = ``max_error`` already has no more vertices than the budget,
        it is returned (fewer vertices are fine) with ``attrs["stopped_by"] ==
        "max_error"``; otherwise ε is searched for the budget as usual.
    epsilon_guess : float, optional
        The first ε the search tries (z units); the default is the 1-D estimate (Notes).

    Returns
    -------
    TIN
        Every sample lies within ``attrs["epsilon"]`` of it (the guarantee achieved).
        ``attrs`` also holds ``stopped_by`` (``"budget"`` or ``"max_error"``; with
        ``max_error`` given, ``max_error_threshold`` records it),
        ``search_stage`` (the stage that landed: ``"max_error"``, ``"bracket"``,
        ``"mixed"``, ``"probe"`` or ``"wide"``) and ``runs`` (triangulations made, including
        the ones stopped early). When the budget needed the mixed tolerance,
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
    triangle accepted early changes the whole front after it. Every run stops as soon
    as its count passes the window (its final count is then extrapolated from the area
    it covered), and the search stops at the first run within
    :func:`~simplifiers.levels.budget_tolerance` of the budget:

    0. *First guess*: greedy 1-D ε-chains along 32 rows and 32 columns give vertex
       densities d_r and d_c, and ``kappa * d_r * d_c * size`` (``kappa`` about 3,
       measured) estimates the count; bisection on log ε meets the budget.
    1. *Bracket*: ``eps_lo`` (too many vertices, starting at 0) and ``eps_hi`` (too
       few, starting at the height range); the next ε interpolates log(count) against
       log(ε) (a power law), kept inside the middle 80 % of the log bracket (a
       safeguarded secant method). Until both ends have been measured it steps with the
       typical slope of the count (1.3 to 1.6), at most a factor 8; the Illinois rule
       keeps it from creeping towards a jump, and on whole-number heights a run just
       below a multiple of 1/2 tests for a jump of ties there. Stops when the bracket is
       narrower than 1e-3 relative (the count jumps over the window there), or than
       2 % once the counts have been seen to be chaotic (a larger ε gave more vertices).
    2. *Mixed tolerance* across the jump: the first k samples of an order (row-major,
       column-major, then fixed permutations) may be ``eps_hi`` off, the others
       ``eps_lo``, and a safeguarded interpolation on k lands in between (the guarantee
       is then ``eps_hi``). This is what quantised DEMs (whole metres) need, where
       thousands of samples have errors of exactly 1 and the count jumps by a quarter
       at ε = 1; on a chaotic 2 % bracket it blends the two ends.
    3. *Probes*: single tolerances spread over ±2 % of the jump, for small budgets,
       where the count is chaotic near the target.
    4. *Wide mixed tolerance*: when the runs near the jump all land on two modes on
       either side of the window, the mixed tolerance again with the others' ε 10, 25
       or 50 % below ``eps_hi`` (the guarantee is still ``eps_hi``).

    Stages 2 and 3 run in this order when the heights are whole numbers and the jump
    lies at a multiple of 1/2, or when the counts are chaotic; else in the other order;
    stage 4 runs last, where both missed.
    Every stage has a fixed cap on its runs, so the result is deterministic.

    Examples
    --------
    >>> from terrainvis import bundled_terrain
    >>> tin = build(bundled_terrain("hills"), 900)
    >>> abs(tin.n_vertices - 900) <= 9, tin.attrs["stopped_by"]
    (True, 'budget')
    >>> build(bundled_terrain("hills"), 900, max_error=5.0).attrs["stopped_by"]
    'max_error'

    References
    ----------
    C. T. Silva and J. S. B. Mitchell, "Greedy cuts: an advancing front terrain
    triangulation algorithm", ACM GIS '98, 1998. DOI 10.1145/288692.288717
    """
    _check_grid(grid)
    budget = check_budget(grid.shape, n_vertices)
    threshold = None if max_error is None else as_nonnegative_finite(max_error, "max_error", "z units")
    guess = None if epsilon_guess is None else as_nonnegative_finite(epsilon_guess, "epsilon_guess", "z units")
    search = _Search(_Triangulator(grid), budget)
    if threshold is None:
        stage, run = _search_budget(search, guess)
        return search.finish(run, stage)
    run = search.measure(threshold)
    if run.complete and run.n <= budget:
        stage, stopped_by = "max_error", "max_error"
    elif search.hit(run):
        stage, stopped_by = "max_error", "budget"
    else:
        search.narrow(run)  # too many vertices: the budget needs a larger ε
        (stage, run), stopped_by = _search_budget(search, guess), "budget"
    tin = search.finish(run, stage, stopped_by=stopped_by)
    tin.attrs["max_error_threshold"] = threshold
    return tin


def _search_budget(search: _Search, guess: float | None) -> tuple[str, _Run]:
    """The stages of :func:`build`'s search (see its Notes): the run that lands and its stage."""
    s = search
    if s.ptp == 0.0:
        run = s.tri.run(0.0)
        if s.hit(run):
            return "bracket", run
        raise SimplificationError(
            f"{_METHOD}: the grid is flat, so every epsilon gives {run.n} vertices; "
            f"the budget {s.budget} cannot be reached"
        )
    eps = guess if guess is not None and s.lo_eps < guess < s.hi_eps else _first_guess(s)
    run = _stage_bracket(s, eps)
    if run is not None:
        return "bracket", run
    if s.lo_eps == 0.0:  # every ε > 0 tried gave too few vertices
        run = s.measure(0.0)
        if s.hit(run):
            return "bracket", run
        if run.n < s.budget:
            raise SimplificationError(
                f"{_METHOD}: even epsilon = 0 gives only {run.n} vertices (the grid has large planar parts), "
                f"fewer than the budget {s.budget} - {s.tol}"
            )
        s.narrow(run)
    stages = [("mixed", _stage_mixed), ("probe", _stage_probe)]
    if not (_quantised(s) or s.chaotic):
        stages.reverse()
    for name, stage in [*stages, ("wide", _stage_wide)]:
        run = stage(s)
        if run is not None:
            return name, run
    raise SimplificationError(
        f"{_METHOD}: no epsilon gave {s.budget} +- {s.tol} vertices on a {s.grid.shape} grid after "
        f"{s.tri.runs} runs; the count jumps from {s.lo_n} to {s.hi_n} between epsilon={s.lo_eps:.6g} "
        f"and {s.hi_eps:.6g}"
    )
