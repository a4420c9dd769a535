"""The visibility-optimized regular simplifier (``"visopt"``).

A HeightGrid at exactly the coarse positions of the reverse Faber levels (the grid of
``gls``/``lls`` at the same level), whose coarse heights are chosen so that points
relocated onto it with the *calibrated* relocation (:mod:`terrainvis.relocation.calibrated`)
keep the line-of-sight verdicts they had on the original terrain T.

The method
----------
1. Start from GLS's coarse grid S0 (:func:`simplifiers.reverse_faber.gls`, ``level`` times).
2. Draw ``n_train`` *training points* uniformly on T (:func:`terrainvis.sample_points`,
   their own seed, never the evaluated points) and take their mutual verdicts on T
   (exact, :func:`terrainvis.visibility_matrix`).
3. ``rounds`` times:

   a. *Calibrate* the training points on S jointly, as the calibrated relocation
      calibrates its partners: Gauss-Seidel sweeps in which each point takes its best
      height against the others' T verdicts at their current heights
      (:func:`terrainvis.visibility.thresholds.gauss_seidel`: exact thresholds, sorted;
      3 sweeps in the first round, 1 afterwards).
   b. One sweep of exact *coordinate descent* over the coarse heights: each coarse
      height in turn (random order) takes the value that maximises the number of
      training pairs whose verdict on S agrees with T, the others fixed. The points
      ride on the surface (each keeps its height above S), so each pair sees exactly
      when the height lies in one interval; the optimum is found by sorting the
      intervals' ends (:func:`simplifiers._visopt_kernels.best_value`). A height
      moves only for a strict gain, and at most ``trust`` x the largest |T - S0| over
      the fine samples its triangles cover (a trust region: without it the descent
      moved heights by up to 340 standard deviations of T and over-fitted).

   Each step keeps or raises the agreement of the training pairs (step a in the
   threshold model of the relocation, step b in the breakpoint model below; the two
   differ only on pairs decided within the LOS engines' trim, 1e-5 of the extent's
   diagonal at each end, which the breakpoints take at the start heights).

docs/visopt.md gives the measurements on the default experiment: a few hundredths of a
point above GLS with the calibrated relocation (not significant at any level), at 1,300
to 1,800 times GLS's time. Kept out of compare's default methods.

The pair verdicts of step b are evaluated at the *breakpoints* of each sight line on
the coarse grid (the ends of its tested interval, its crossings of grid lines and cell
diagonals), stored once: about ``n_train² / 2`` pairs x their crossings. When that
exceeds ``max_breakpoints``, or a descent sweep would evaluate more than
:data:`MAX_WORK` breakpoints (fine levels, large grids), a random subset of the pairs
is kept (their own seed) so that it fits; the calibration step always uses every point.

Parameters (fixed from the research, docs/visopt.md)
----------------------------------------------------
``n_train=1200``, ``rounds=3``, ``trust=1.0``, start GLS: chosen on synthetic terrains
of seeds 11 and 12 (``terrainvis.core.synthetic.synthetic_terrain(kind, 120, seed)``, the
five kinds), point sets of seed 1000, level 3 -- never on the bundled terrains (seed 0)
or Jacksboro on which it is reported. Tried and left: 400 and 800 training points,
5 and 10 rounds, LLS as the start, no trust region, an L1 pull towards S0, a margin
from thresholds, training points calibrated against separate proxies instead of each
other, down-weighting pairs decided near their ends, 2000 points with 30 % of the pairs.

Cost: ``n_train²`` exact LOS queries on T once; per round, ``n_train²`` threshold walks
on S per Gauss-Seidel sweep (serial) and one pass over the stored breakpoints per
coarse vertex they touch. Memory: about 40 bytes per stored breakpoint (at most
``max_breakpoints``) plus ``n_train²`` bytes.
"""

from __future__ import annotations

import numpy as np

from terrainvis.core.validate import as_int, as_nonnegative_finite, describe
from terrainvis.core.terrain import HeightGrid

from .levels import check_level, coarse_coords

__all__ = ["visopt", "N_TRAIN", "ROUNDS", "TRUST", "MAX_BREAKPOINTS"]

#: Training points (chosen on the tuning terrains: 800 gave 96.79, 1200 96.94 at level 3).
N_TRAIN = 1200
#: Rounds of (calibrate, coordinate descent) (5 and 10 rounds did worse: 96.87 and 96.69).
ROUNDS = 3
#: A coarse height moves at most this many times the local max |T - S0| (0: it never moves).
TRUST = 1.0
#: Breakpoints stored at most (about 40 bytes each with the incidence lists: 650 MB at most).
MAX_BREAKPOINTS = 1 << 24
#: Sum over the kept pairs of their breakpoints squared at most: one descent sweep costs about
#: that many breakpoint evaluations (each pair is visited once per coarse vertex it crosses).
#: It keeps every pair at level 3 of a 120x120 grid (about 3e8) and bounds the finer levels.
MAX_WORK = 1 << 29
#: Gauss-Seidel sweeps of the training points' calibration in the first round and the later ones.
FIRST_SWEEPS, LATER_SWEEPS = 3, 1


def visopt(grid: HeightGrid, level: int, *, n_train: int = N_TRAIN, rounds: int = ROUNDS, seed: int = 0,
           trust: float = TRUST, max_breakpoints: int = MAX_BREAKPOINTS) -> HeightGrid:
    """The visibility-optimized coarse grid of ``grid`` at ``level`` (see the module docstring).

    Parameters
    ----------
    grid : HeightGrid
        The fine terrain T, free of nodata.
    level : int
        Reverse-subdivision steps (0: a copy of ``grid``); the result has the shape and
        coordinates of every regular method at this level.
    n_train : int >= 2
        Training points drawn on T.
    rounds : int >= 0
        Rounds of calibration and coordinate descent (0: GLS's grid).
    seed : int >= 0
        Seed of the training points, the sweep orders and the pair subset: the same
        seed gives the same grid.
    trust : float >= 0
        A coarse height moves at most ``trust`` x the largest |T - S0| over the fine
        samples its triangles cover.
    max_breakpoints : int >= 1
        Sight-line breakpoints stored at most (a random subset of the training pairs
        beyond it).

    Returns
    -------
    HeightGrid
        With ``grid``'s attrs.

    Examples
    --------
    >>> from terrainvis import synthetic_terrain
    >>> S = visopt(synthetic_terrain("hills", size=33), 2, n_train=60)
    >>> S.shape
    (9, 9)
    """
    out, _ = optimize(grid, level, n_train=n_train, rounds=rounds, seed=seed, trust=trust,
                      max_breakpoints=max_breakpoints)
    return out


def _check(grid, level, n_train, rounds, seed, trust, max_breakpoints):
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
    grid.require_finite("visopt")
    return (check_level(grid.shape, level), as_int(n_train, "n_train", minimum=2), as_int(rounds, "rounds", minimum=0),
            as_int(seed, "seed", minimum=0), as_nonnegative_finite(trust, "trust"),
            as_int(max_breakpoints, "max_breakpoints", minimum=1))


def start_grid(grid: HeightGrid, level: int) -> HeightGrid:
    """S0: GLS's coarse grid at ``level`` (the start of the descent)."""
    from .reverse_faber import gls, reduce_level

    z = grid.z
    for _ in range(level):
        z = reduce_level(z, gls)
    return HeightGrid.from_coords(z, coarse_coords(grid.xs, level), coarse_coords(grid.ys, level))


class _Pairs:
    """The training pairs kept, their breakpoints on the coarse grid and the vertex -> pairs incidence."""

    def __init__(self, S0: HeightGrid, p: np.ndarray, n: int, budget: int, rng: np.random.Generator):
        from terrainvis.core.interrupt import call
        from terrainvis.visibility import trim_length

        from . import _visopt_kernels as _vk

        self.xs = np.ascontiguousarray(S0.xs - S0.xs[0])
        self.ys = np.ascontiguousarray(S0.ys - S0.ys[0])
        self.ncx = self.xs.size - 1
        self.axes = (self.xs, self.ys, 1.0 / np.diff(self.xs), 1.0 / np.diff(self.ys))
        ii, jj = np.triu_indices(n, 1)
        ii = ii.astype(np.int64)
        jj = jj.astype(np.int64)
        self.n_pairs_all = ii.size
        delta = float(trim_length(S0))
        counts = np.empty(ii.size, dtype=np.int64)
        call(_vk.track_counts, self.axes, p, ii, jj, delta, counts, work=ii.size * 8, items=_vk.pair_chunks(ii.size))
        total = int(counts.sum())
        work = counts.astype(np.float64) ** 2
        if total > budget or work.sum() > MAX_WORK:  # a random subset of the pairs that fits both budgets
            perm = rng.permutation(ii.size)
            fits = (np.cumsum(counts[perm]) <= budget) & (np.cumsum(work[perm]) <= MAX_WORK)
            keep = np.sort(perm[fits])
            ii, jj, counts = ii[keep], jj[keep], counts[keep]
        self.ii, self.jj = ii, jj
        self.ptr = np.zeros(ii.size + 1, dtype=np.int64)
        np.cumsum(counts, out=self.ptr[1:])
        nb_ = int(self.ptr[-1])
        self.bu = np.empty(nb_)
        self.btri = np.empty(nb_, dtype=np.int32)
        self.ba = np.empty(nb_)
        self.bb = np.empty(nb_)
        call(_vk.track_fill, self.axes, p, ii, jj, delta, self.ptr, (self.bu, self.btri, self.ba, self.bb), work=nb_,
             items=_vk.pair_chunks(ii.size))
        self.vptr, self.items = call(_vk.incidence, S0.size, self.ncx, self.ptr, self.btri, self.ba, self.bb,
                                     work=nb_)
        self.tracks = _vk.Tracks(self.ncx, self.ii, self.jj, self.ptr, self.bu, self.btri, self.ba, self.bb, self.vptr,
                                 self.items)

    @property
    def n_breakpoints(self) -> int:
        return int(self.ptr[-1])

    def visible(self, c: np.ndarray, z: np.ndarray, tol: float) -> np.ndarray:
        """Verdicts of the kept pairs on the coarse heights ``c`` (flat), points at heights ``z``."""
        from terrainvis.core.interrupt import call

        from . import _visopt_kernels as _vk

        out = np.empty(self.ii.size, dtype=bool)
        call(_vk.pair_visible, c, z, self.tracks, tol, out, work=self.n_breakpoints, items=_vk.pair_chunks(self.ii.size))
        return out


def optimize(grid: HeightGrid, level: int, *, n_train: int = N_TRAIN, rounds: int = ROUNDS, seed: int = 0,
             trust: float = TRUST, max_breakpoints: int = MAX_BREAKPOINTS):
    """:func:`visopt` and what it did: ``(grid, info)``.

    ``info`` holds ``train`` (the training points, (n, 3) on T), ``heights`` (their
    calibrated heights on the result), ``history`` (per round: the kept pairs' agreement
    after the calibration and after the descent, and the heights changed),
    ``pairs`` / ``pairs_kept`` and ``breakpoints``.
    """
    level, n_train, rounds, seed, trust, max_breakpoints = _check(grid, level, n_train, rounds, seed, trust,
                                                                   max_breakpoints)
    if level == 0:
        return grid.copy_with(), {"history": [], "pairs": 0, "pairs_kept": 0, "breakpoints": 0}
    from terrainvis.core.interrupt import call
    from terrainvis.core.sampling import sample_points
    from terrainvis.visibility import clearance_tolerance, terrain_scale, visibility_matrix
    from terrainvis.visibility.thresholds import MARGIN_REL, ThresholdSurface, gauss_seidel

    from . import _visopt_kernels as _vk

    S0 = start_grid(grid, level)
    W = sample_points(grid, n_train, seed=np.random.default_rng(np.random.SeedSequence([seed, 1])))
    vt_full = np.ascontiguousarray(visibility_matrix(grid, W, engine="grid"))
    order_rng = np.random.default_rng(np.random.SeedSequence([seed, 2]))
    x0, y0 = float(S0.xs[0]), float(S0.ys[0])
    p = np.column_stack([W[:, 0] - x0, W[:, 1] - y0, S0.height_at(W[:, :2])])
    pairs = _Pairs(S0, p, n_train, max_breakpoints, np.random.default_rng(np.random.SeedSequence([seed, 3])))
    vt = np.ascontiguousarray(vt_full[pairs.ii, pairs.jj])
    ev = np.empty((n_train, 3), dtype=np.int64)
    ew = np.empty((n_train, 3))
    _vk.barycentric(pairs.xs, pairs.ys, np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]), ev, ew)
    c = np.ascontiguousarray(S0.z, dtype=np.float64).ravel().copy()
    cref = c.copy()
    rad = np.empty(S0.size)
    call(_vk.local_radius, np.ascontiguousarray(grid.z, dtype=np.float64), np.ascontiguousarray(grid.xs - x0),
         np.ascontiguousarray(grid.ys - y0), c, pairs.xs, pairs.ys, rad, work=grid.size)
    rad *= trust
    tol = float(clearance_tolerance(S0))
    margin = MARGIN_REL * float(terrain_scale(S0))

    def surface_at(cc):
        return (cc[ev] * ew).sum(axis=1)

    z = p[:, 2].copy()
    history = []
    for r in range(rounds):
        S = HeightGrid.from_coords(c.reshape(S0.shape).copy(), S0.xs, S0.ys)
        surf = ThresholdSurface(S)
        q = surf.local(np.column_stack([W[:, :2], z]))
        for _ in range(FIRST_SWEEPS if r == 0 else LATER_SWEEPS):
            order = order_rng.permutation(n_train).astype(np.int64)
            gauss_seidel(surf, q, order, vt_full, end_radius=0.0, kc=0.0, min_gain=1)
        z = q[:, 2].copy()
        d = z - surface_at(c)
        a0 = float((pairs.visible(c, z, tol) == vt).mean()) if vt.size else 1.0
        order = order_rng.permutation(S0.size).astype(np.int64)
        changed = call(_vk.c_sweep, c, cref, rad, _vk.Riders(d, ev, ew), vt, pairs.tracks, tol, margin, order,
                       work=pairs.n_breakpoints)
        z = d + surface_at(c)
        a1 = float((pairs.visible(c, z, tol) == vt).mean()) if vt.size else 1.0
        history.append((a0, a1, int(changed)))
    out = HeightGrid.from_coords(c.reshape(S0.shape), S0.xs, S0.ys, attrs=grid.attrs)
    info = {"train": W, "heights": z, "history": history, "pairs": pairs.n_pairs_all, "pairs_kept": int(pairs.ii.size),
            "breakpoints": pairs.n_breakpoints, "start": S0, "radius": rad}
    return out, info
