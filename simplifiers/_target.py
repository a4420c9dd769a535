"""Simplifying to a target error: the smallest result whose max vertical error is <= E.

:func:`simplifiers.simplify` with ``max_error=E`` comes here for the methods that have no
error threshold of their own:

* regular methods (:func:`regular_within`): every level from the size cap (``level``,
  default 0: the grid itself) to the deepest is computed, each from the previous one,
  and the coarsest level whose max vertical error is <= E is returned. Cost: one
  reverse-subdivision pass per level (each a quarter of the previous) plus one error
  evaluation over the fine grid per level, O(levels x grid size).
* quadric edge collapse (:func:`qec_within`): a search on the vertex count (below).

Greedy insertion and greedy cuts stop at E themselves (their ``build(..., max_error=E)``):
greedy insertion inserts until the error is <= E (the smallest count of its insertion
order), greedy cuts triangulates with tolerance ε = E.
"""

from __future__ import annotations

import math
import time

from terrainvis.core.deviation import vertical_errors
from terrainvis.core.terrain import TIN, HeightGrid

from .levels import budget_tolerance, coarse_coords, max_level

__all__ = ["regular_within", "qec_within"]


def regular_within(grid: HeightGrid, op, cap: int, target: float, options: dict):
    """The coarsest level >= ``cap`` of a regular method whose max vertical error is <= ``target``.

    Parameters
    ----------
    grid : HeightGrid
    op : callable
        The method's curve operator.
    cap : int
        The finest level allowed (0: the grid itself, error 0).
    target : float
        The error target E (z units).
    options : dict
        The operator's options.

    Returns
    -------
    (HeightGrid, dict)
        The grid at the chosen level and the attrs that describe the search:
        ``level``, ``max_error_target``, ``stopped_by`` (``"max_error"``, or
        ``"budget"`` when even the cap level exceeds E), ``level_errors`` (``[level,
        max error]`` for every level computed) and ``notes`` (one line for the user).
    """
    from .reverse_faber import reduce_level

    z = grid.z
    for _ in range(cap):
        z = reduce_level(z, op, **options)
    levels = []  # (level, grid, max error)
    for level in range(cap, max_level(grid.shape) + 1):
        if level > cap:
            z = reduce_level(z, op, **options)
        out = grid.copy_with() if level == 0 else HeightGrid.from_coords(
            z, coarse_coords(grid.xs, level), coarse_coords(grid.ys, level), attrs=grid.attrs
        )
        levels.append((level, out, vertical_errors(grid, out)[0]))
    within = [item for item in levels if item[2] <= target]
    level, out, err = within[-1] if within else levels[0]
    errors = [[lv, e] for lv, _, e in levels]
    coarser = [e for lv, _, e in levels if lv == level + 1]
    if within:
        note = f"max_error {target:g}: level {level} is the coarsest within it (max error {err:.4g}"
        note += f"; level {level + 1}: {coarser[0]:.4g})" if coarser else "; it is the deepest level)"
    else:
        note = f"max_error {target:g} is not met even at level {level}, the finest allowed (max error {err:.4g})"
    return out, {
        "level": level, "max_error_target": target, "stopped_by": "max_error" if within else "budget",
        "level_errors": errors, "notes": [note],
    }


def qec_within(grid: HeightGrid, build, cap: int, target: float, options: dict):
    """The smallest quadric-edge-collapse TIN (to the 1 % budget tolerance) within ``target``.

    Quadric edge collapse takes a vertex count, not an error, and its max error is not
    monotone in the count, so the count is searched:

    1. greedy insertion to ``target`` gives a count ``n_gi`` (cheap; QEC, which minimises
       a squared error, needs at least about as many vertices for the same max error);
    2. a *base* TIN of ``min(cap, 4 n_gi)`` vertices is decimated from the grid (four
       times more, then the cap, when it is not within the target);
    3. bisection on log(count) between the largest count found over the target and the
       smallest found within it, each probe decimated from the smallest TIN within the
       target so far (``start=``, as cascading levels do), until the two are within the
       budget tolerance (1 %).

    Every probe's error is measured (:func:`terrainvis.vertical_errors`), so the result
    is within the target whatever the trend; minimality holds to the 1 % tolerance and
    to the non-monotone steps of the count. Cost: one decimation of the grid (a few when
    step 2 must grow) plus about ``log2(ln(base / lo) / 0.01)`` (8 to 11) decimations of
    TINs of at most the base's size, and one error evaluation per probe.

    Returns
    -------
    (TIN, dict)
        The TIN and the attrs of the search: ``max_error_target``, ``stopped_by``
        (``"max_error"``, or ``"budget"`` when the cap itself exceeds the target),
        ``probes`` (``[vertices, max error]`` per decimation) and ``notes``.
    """
    from .greedy_insertion import GreedyInserter

    t0 = time.perf_counter()
    probes = []

    def probe(n, start=None):
        tin = build(grid, n, start=start, **options)
        err = vertical_errors(grid, tin)[0]
        probes.append([int(tin.n_vertices), err])
        return tin, err

    n_gi = GreedyInserter(grid).run(n_vertices=cap, max_error=target).n_vertices
    lo = 3  # every count below 4 fails
    base_n = min(cap, max(4, 4 * n_gi))
    while True:
        if base_n >= grid.size:
            own = grid.to_tin()
            hi_tin, hi_err = TIN(own.vertices, own.faces, attrs={"backend": "the grid itself"}), 0.0
        else:
            hi_tin, hi_err = probe(base_n)
        if hi_err <= target or base_n >= cap:
            break
        lo = max(lo, hi_tin.n_vertices)
        base_n = min(cap, 4 * base_n)
    if hi_err > target:
        return hi_tin, _qec_attrs(target, "budget", probes, hi_tin, hi_err, t0)
    hi = hi_tin.n_vertices  # the bracket is on the counts asked for (a result lands within 1 % of its ask)
    while hi - lo > budget_tolerance(hi) and hi > 4:
        n = int(round(math.sqrt(lo * hi)))
        n = min(max(n, lo + 1), hi - 1)
        tin, err = probe(n, start=hi_tin)
        if err <= target:
            hi = n
            if tin.n_vertices < hi_tin.n_vertices:
                hi_tin, hi_err = tin, err
        else:
            lo = n
    return hi_tin, _qec_attrs(target, "max_error", probes, hi_tin, hi_err, t0)


def _qec_attrs(target, stopped_by, probes, tin, err, t0) -> dict:
    if stopped_by == "max_error":
        note = (f"max_error {target:g}: {tin.n_vertices:,} vertices (max error {err:.4g}), the smallest count "
                f"within it of {len(probes)} decimations ({time.perf_counter() - t0:.3g} s)")
    else:
        note = f"max_error {target:g} is not met even with the budget's {tin.n_vertices:,} vertices (max error {err:.4g})"
    return {"max_error_target": target, "stopped_by": stopped_by, "probes": probes, "notes": [note]}
