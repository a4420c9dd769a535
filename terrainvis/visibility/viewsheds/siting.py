"""Observer siting: where to put k observers so that together they see the most.

:func:`site_observers` chooses k of K candidate positions (towers, fire lookouts, masts)
that maximise the area seen by at least one of them, each candidate's viewshed exact
(:func:`terrainvis.viewshed`). This is maximum coverage, NP-hard in general; the greedy
algorithm (take the candidate that adds the most area, k times) covers at least
``1 - (1 - 1/k)**k > 1 - 1/e`` (63.2 %) of the optimum, because covered area is a monotone
submodular function of the chosen set (Nemhauser, Wolsey & Fisher 1978). Franklin's
observer siting (2002; Franklin & Vogt 2004) chooses observers on DEMs with this greedy
step, over tentative observers picked by an approximate visibility index.

Lazy evaluation (Minoux 1978; "CELF" in later work) gives the same choices with
far fewer evaluations: a candidate's gain can only shrink as others are chosen, so the
gains computed earlier are upper bounds; a max-heap holds them, and the candidate on top
is re-evaluated against the current coverage: if its fresh gain is still on top it is
the greedy choice. Ties go to the lowest candidate index, in the heap and in the plain
greedy alike, so both choose the same sequence (tested).

Memory: each candidate's viewshed is kept as packed bits (``numpy.packbits``), K x rows x
cols / 8 bytes (1,000 candidates on 1024²: 125 MiB); a request that would not fit is
refused before anything runs (:func:`terrainvis.core.memory.check_memory`). The viewsheds
run in chunks of candidates as :func:`terrainvis.cumulative_viewshed`'s observers do
(:mod:`terrainvis.visibility.viewsheds.many`), on this process, local workers or
dask; the greedy choice itself runs here, in numpy (an AND and a popcount per evaluation).

References
----------
G. L. Nemhauser, L. A. Wolsey, M. L. Fisher, "An analysis of approximations for
maximizing submodular set functions - I", Mathematical Programming 14, 265-294, 1978,
doi:10.1007/BF01588971.

M. Minoux, "Accelerated greedy algorithms for maximizing submodular set functions",
Optimization Techniques (Lecture Notes in Control and Information Sciences 7),
Springer, 1978 (DOI not checked).

W. R. Franklin, "Siting observers on terrain", in D. Richardson, P. van Oosterom (eds.),
Advances in Spatial Data Handling: 10th International Symposium on Spatial Data
Handling, Springer, 2002, 109-120 (DOI not checked).

W. R. Franklin, C. Vogt, "Multiple observer siting on terrain with intervisibility or
lo-res data", XXth Congress of the International Society for Photogrammetry and Remote
Sensing, Istanbul, 2004 (no DOI).
"""

from __future__ import annotations

import heapq
import math
import time
from dataclasses import dataclass, field

import numpy as np

from ...core.memory import check_memory
from ...core.terrain import HeightGrid
from ...core.validate import as_int, describe
from .many import eyes, keep_terrain, prepare, run_chunks, sight_of_many
from ..predicate import EARTH_RADIUS
from .sweep import _on_surface, viewshed

__all__ = ["site_observers", "candidate_grid", "sample_areas", "SitingResult"]


@dataclass
class SitingResult:
    """What :func:`site_observers` chose, and how much each choice added.

    Attributes
    ----------
    chosen : (k,) int64
        Indices into the candidates, in the order chosen.
    table : pandas.DataFrame
        One row per choice, in order: ``order`` (1..k), ``candidate`` (its index), ``x``,
        ``y`` (its position), ``eye`` (the eye's height, z units), ``gain_cells`` and
        ``gain_area`` (what it added: samples, and area in x/y units squared),
        ``covered_cells`` and ``covered_area`` (seen by at least one of the observers
        chosen so far) and ``covered_share`` (``covered_area / total_area``).
    covered : (rows, cols) bool
        The samples seen by at least one chosen observer (the union of their viewsheds).
    total_area : float
        The area of the valid (not nodata) samples, the most any choice can cover.
    bound : float
        An upper bound on the area the best k candidates could cover (from the greedy's
        own gains, see :func:`site_observers`): ``covered_area[-1] / bound`` is a
        guarantee of this run, usually far above 1 - 1/e.
    evaluations : int
        How many marginal gains were computed (K for the first round, then the lazy
        re-evaluations; the plain greedy computes about k x K).
    seconds : dict
        ``viewsheds`` and ``greedy``: wall seconds of the two stages.
    """

    chosen: np.ndarray
    table: object
    covered: np.ndarray
    total_area: float
    bound: float
    evaluations: int
    seconds: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        share = float(self.table["covered_share"].iloc[-1]) if len(self.table) else 0.0
        return (f"SitingResult({len(self.chosen)} observers chosen {self.chosen.tolist()}, covering "
                f"{100 * share:.2f} % of the area; bound on the optimum {self.bound:.6g})")


def site_observers(
    terrain,
    candidates,
    k: int,
    *,
    observer_height=1.7,
    target_height: float = 0.0,
    max_distance=None,
    at=None,
    engine: str = "auto",
    curvature: float = 0.0,
    earth_radius: float = EARTH_RADIUS,
    azimuth=None,
    vertical=None,
    min_distance=None,
    sight=None,
    workers: int | None = None,
    client=None,
    progress: bool = False,
) -> SitingResult:
    """Choose k of the candidates that together see the most area (greedy, lazily evaluated).

    Parameters
    ----------
    terrain : HeightGrid or TIN
        The surface, as in :func:`terrainvis.viewshed`.
    candidates : (K, 2) or (K, 3) array_like of float
        Candidate positions (x, y), each inside the footprint and not on nodata; or
        eyes (x, y, z). :func:`candidate_grid` gives every STEP-th sample.
    k : int
        How many observers to choose, 1 <= k <= K.
    observer_height : float or (K,) array_like of float
        Height (>= 0) of each candidate's eye above the surface.
    target_height, max_distance, at, engine, curvature, earth_radius
        As in :func:`terrainvis.viewshed` (the targets are the samples of ``at``, or of
        the terrain).
    azimuth, vertical, min_distance : optional
        Each candidate's field of view, as in :func:`terrainvis.viewshed`: a candidate
        covers nothing outside it (a mast's antenna sector, a camera's view).
    sight : Sight, optional
        The options above but ``at`` as one value, as in :func:`terrainvis.cumulative_viewshed`
        (``observer_height`` may still be one height per candidate).
    workers, client, progress
        Where the K viewsheds run, as in :func:`terrainvis.cumulative_viewshed` (the
        progress bar counts candidates).

    Returns
    -------
    SitingResult
        The chosen candidates in order, the gain and the covered area after each choice,
        the union of their viewsheds, and a bound on the optimum.

    Raises
    ------
    ValueError, TypeError
        When k is not an integer in [1, K] or another argument is invalid (the message
        names it).
    OutsideFootprintError
        When a candidate is outside the footprint or on nodata.
    NotEnoughMemoryError
        When the K packed viewsheds (K x rows x cols / 8 bytes) would not fit.

    Notes
    -----
    **Area.** Each valid sample of the target grid counts with the area of its cell: on
    a uniform grid ``dx * dy`` for every sample (so area is the sample count times the
    cell area), on a rectilinear grid the width times the height of the cell around the
    sample, whose sides lie half-way to the neighbouring samples (the full spacing beyond
    the first and last ones, which on a uniform grid gives ``dx * dy`` again;
    :func:`sample_areas`). Nodata samples count 0.

    **The guarantee.** Coverage is monotone and submodular, so the greedy choice covers
    at least ``1 - (1 - 1/k)**k`` >= 1 - 1/e of the best k candidates' area (Nemhauser,
    Wolsey & Fisher 1978). A run also certifies itself: before each choice, the covered
    area plus the k largest gains of the candidates left bounds the optimum from above
    (the heap's stale gains are upper bounds of the gains, so they serve); ``bound`` is
    the least such bound, and ``covered_area / bound`` the fraction of the optimum this
    run is known to reach. It is at most ``total_area``.

    **Ties** go to the lowest candidate index; the lazy evaluation then chooses exactly
    the sequence of the plain greedy. On a rectilinear grid the gains are sums of
    floating-point areas, whose rounding could break a tie between two gains equal to the
    last bit differently.

    References
    ----------
    G. L. Nemhauser, L. A. Wolsey, M. L. Fisher, "An analysis of approximations for
    maximizing submodular set functions - I", Mathematical Programming 14, 265-294, 1978,
    doi:10.1007/BF01588971.

    M. Minoux, "Accelerated greedy algorithms for maximizing submodular set functions",
    Optimization Techniques (Lecture Notes in Control and Information Sciences 7),
    Springer, 1978.

    W. R. Franklin, "Siting observers on terrain", Advances in Spatial Data Handling:
    10th International Symposium on Spatial Data Handling, Springer, 2002, 109-120.

    Examples
    --------
    A 5 m wall splits a flat grid; two candidates on each side. One observer sees one
    side and the crest, the second one chosen stands on the other side:

    >>> from terrainvis import HeightGrid
    >>> z = np.zeros((3, 5))
    >>> z[:, 2] = 5.0
    >>> cands = [[0.0, 0.0], [1.0, 2.0], [3.0, 0.0], [4.0, 2.0]]
    >>> r = site_observers(HeightGrid(z), cands, 2, observer_height=1.0, workers=1)
    >>> r.chosen.tolist(), r.table["gain_cells"].tolist(), r.table["covered_share"].tolist()
    ([0, 2], [9, 6], [0.6, 1.0])
    """
    s, each = sight_of_many(sight, observer_height, {
        "target_height": target_height, "max_distance": max_distance, "engine": engine, "curvature": curvature,
        "earth_radius": earth_radius, "azimuth": azimuth, "vertical": vertical, "min_distance": min_distance,
    })
    run = prepare(terrain, candidates, each, s, at, workers=workers, client=client, progress=progress,
                  name="candidates")
    n = run.obs.shape[0]
    if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)):
        raise TypeError(f"k must be an integer (how many observers to choose), got {describe(k)}")
    if not 1 <= int(k) <= n:
        raise ValueError(f"k must be between 1 and the number of candidates ({n:,}), got {int(k)}")
    k = int(k)
    grid = terrain if at is None else at
    row_bytes = -(-grid.size // 8)
    check_memory(n * row_bytes + 4 * grid.size * 8, f"siting among {n:,} candidates on {grid.shape[0]}x"
                                                    f"{grid.shape[1]} samples ({n * row_bytes:,} bytes of packed "
                                                    "viewsheds)")
    t0 = time.perf_counter()
    packed = np.zeros((n, row_bytes), dtype=np.uint8)

    def place(key, part):
        packed[key[0]: key[1]] = part

    run_chunks(run, _siting_unit, place, desc="candidate viewsheds")
    t1 = time.perf_counter()
    weights = None if grid.is_uniform else sample_areas(grid).ravel()
    chosen, gains, bound, evaluations = _lazy_greedy(packed, k, weights, grid.size)
    covered = np.zeros(row_bytes, dtype=np.uint8)
    for i in chosen:
        covered |= packed[i]
    covered_mask = np.unpackbits(covered, count=grid.size).view(bool).reshape(grid.shape)
    table = _table(run, chosen, packed, grid, weights)
    cell = None if weights is not None else grid.dx * grid.dy
    total = float(sample_areas(grid)[np.isfinite(grid.z)].sum())
    bound = min(bound * cell if cell is not None else bound, total)  # nothing covers more than every valid sample
    table["covered_share"] = table["covered_area"] / total if total > 0 else 0.0
    seconds = {"viewsheds": t1 - t0, "greedy": time.perf_counter() - t1}
    return SitingResult(np.asarray(chosen, dtype=np.int64), table, covered_mask, total, float(bound), evaluations,
                        seconds)


def _siting_unit(terrain, at, token: str, observers: np.ndarray, heights: np.ndarray, sight) -> np.ndarray:
    """The packed viewsheds of one chunk of candidates: (n, ceil(rows * cols / 8)) uint8, row-major samples."""
    terrain, at = keep_terrain(token, terrain, at)
    size = (terrain if at is None else at).size
    out = np.empty((observers.shape[0], -(-size // 8)), dtype=np.uint8)
    for i in range(observers.shape[0]):
        out[i] = np.packbits(viewshed(terrain, observers[i], sight=sight.with_observer_height(heights[i]), at=at))
    return out


# ----------------------------------------------------------------- the greedy choice
def _gain(row: np.ndarray, uncovered: np.ndarray, weights, size: int):
    """What a packed viewshed adds to the coverage whose complement is ``uncovered``: samples (int), or area."""
    fresh = np.bitwise_and(row, uncovered)
    if weights is None:
        return int(np.bitwise_count(fresh).sum(dtype=np.int64))
    return float(np.dot(np.unpackbits(fresh, count=size), weights))


def _lazy_greedy(packed: np.ndarray, k: int, weights, size: int):
    """The greedy choice of k rows of ``packed`` with lazy evaluation (Minoux's accelerated greedy).

    Returns (chosen indices, their gains, the least upper bound on the optimum, the
    number of gains computed). The heap holds ``(-gain, index, round)``: ``round`` is how
    many choices had been made when the gain was computed; the top entry is chosen when
    it is of the current round. Ties pop the lowest index first.
    """
    uncovered = np.full(packed.shape[1], 0xFF, dtype=np.uint8)  # the padding bits of every row are 0
    heap = [(-_gain(packed[i], uncovered, weights, size), i, 0) for i in range(packed.shape[0])]
    evaluations = len(heap)
    heapq.heapify(heap)
    chosen, gains = [], []
    covered_value = 0
    bound = math.inf
    while len(chosen) < k:
        neg, i, stamp = heap[0]
        if stamp == len(chosen):
            # every entry is an upper bound of its gain: the covered value plus the k largest bound the optimum
            bound = min(bound, covered_value - sum(e[0] for e in heapq.nsmallest(k, heap)))
            heapq.heappop(heap)
            chosen.append(i)
            gains.append(-neg)
            covered_value += -neg
            np.bitwise_and(uncovered, np.bitwise_not(packed[i]), out=uncovered)
        else:
            heapq.heapreplace(heap, (-_gain(packed[i], uncovered, weights, size), i, len(chosen)))
            evaluations += 1
    return chosen, gains, bound, evaluations


def _table(run, chosen, packed: np.ndarray, grid: HeightGrid, weights):
    """The table of :class:`SitingResult` (``run``: the :class:`~terrainvis.visibility.viewsheds.many.Run`):
    each choice, its gain and the coverage after it."""
    import pandas as pd

    e = eyes(run.terrain, run.obs[chosen], run.heights[chosen])
    uncovered = np.full(packed.shape[1], 0xFF, dtype=np.uint8)
    cell = grid.dx * grid.dy if weights is None else None
    gain_cells, gain_area = [], []
    for i in chosen:
        cells = _gain(packed[i], uncovered, None, grid.size)
        gain_cells.append(cells)
        gain_area.append(cells * cell if cell is not None else _gain(packed[i], uncovered, weights, grid.size))
        np.bitwise_and(uncovered, np.bitwise_not(packed[i]), out=uncovered)
    table = pd.DataFrame({
        "order": np.arange(1, len(chosen) + 1), "candidate": np.asarray(chosen, dtype=np.int64),
        "x": e[:, 0], "y": e[:, 1], "eye": e[:, 2],
        "gain_cells": np.asarray(gain_cells, dtype=np.int64), "gain_area": np.asarray(gain_area, dtype=np.float64),
    })
    table["covered_cells"] = table["gain_cells"].cumsum()
    table["covered_area"] = table["gain_area"].cumsum()
    return table


# ----------------------------------------------------------------- helpers
def sample_areas(grid: HeightGrid) -> np.ndarray:
    """The area each sample of a grid stands for: (rows, cols) float64.

    The cell around a sample reaches half-way to its neighbours along each axis, and one
    full spacing beyond the first and last samples, so on a uniform grid every sample
    gets ``dx * dy`` (a raster's cells); nodata samples get their area too (callers mask
    them).

    Examples
    --------
    >>> g = HeightGrid.from_coords(np.zeros((2, 3)), xs=[0.0, 1.0, 3.0], ys=[0.0, 2.0])
    >>> sample_areas(g).tolist()
    [[2.0, 3.0, 4.0], [2.0, 3.0, 4.0]]
    """
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
    return np.outer(_widths(grid.ys), _widths(grid.xs))


def _widths(v: np.ndarray) -> np.ndarray:
    """Width of the cell around each coordinate of an increasing axis (>= 2 values)."""
    w = np.empty(v.size)
    w[1:-1] = (v[2:] - v[:-2]) / 2.0
    w[0] = v[1] - v[0]
    w[-1] = v[-1] - v[-2]
    return w


def candidate_grid(terrain: HeightGrid, step: int) -> np.ndarray:
    """Every ``step``-th sample of a grid along rows and columns, as (K, 2) candidate positions (x, y).

    The lattice is centred on the grid (its first row and column are ``((n - 1) % step) // 2``)
    and leaves out samples off the surface (nodata, or a sample whose every triangle
    touches nodata). Row-major order: south to north, west to east.

    Examples
    --------
    >>> candidate_grid(HeightGrid(np.zeros((5, 6))), 2).tolist()
    [[0.0, 0.0], [2.0, 0.0], [4.0, 0.0], [0.0, 2.0], [2.0, 2.0], [4.0, 2.0], [0.0, 4.0], [2.0, 4.0], [4.0, 4.0]]
    """
    if not isinstance(terrain, HeightGrid):
        raise TypeError(f"terrain must be a terrainvis.HeightGrid (candidate_grid takes its samples), got "
                        f"{describe(terrain)}")
    step = as_int(step, "step", minimum=1)
    rows, cols = terrain.shape
    rr = np.arange(((rows - 1) % step) // 2, rows, step)
    cc = np.arange(((cols - 1) % step) // 2, cols, step)
    r, c = (a.ravel() for a in np.meshgrid(rr, cc, indexing="ij"))
    keep = _on_surface(terrain.z)[r, c]
    return np.column_stack([terrain.xs[c[keep]], terrain.ys[r[keep]]])
