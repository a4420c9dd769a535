"""``fqmr`` and ``fqmr-free``: Forstmann's fast quadric mesh simplification (pyfqmr).

pyfqmr binds Sven Forstmann's Fast-Quadric-Mesh-Simplification, a general mesh
decimator: quadric errors (Garland & Heckbert 1997), collapses below a threshold that
grows each iteration (``alpha * (iteration + K) ** aggressiveness``), each collapsed
pair moved to the position that minimises its quadric. It knows nothing of terrains.

Two entries:

* ``fqmr``: ``preserve_border=True``. No border vertex is removed or moved, so the
  result keeps the grid's rectangle, but also all of its 2(rows + cols) - 4 border
  samples: a budget below about that many vertices cannot be reached (120²: 476 border
  samples; level 3's budget is 225), and the adapter says so.
* ``fqmr-free``: ``preserve_border=False``. The border collapses like the rest: corners
  move off the rectangle, border vertices leave its sides. The result is then made a
  height field over the grid by :func:`terrainvis.repair_tin` (boundary vertices snapped
  onto the sides, missing corners inserted with the grid's heights, folded faces
  unfolded by moving one vertex into the kernel of its star).

Both run :func:`terrainvis.repair_tin` on every result (``attrs["repair"]`` says what it
changed; for ``fqmr`` it has had nothing to do on the grids measured). Interior vertices
are where the library put them (with the library's heights, not the grid's), except
those the repair moved (counted in ``repairs``).

**The parameter.** ``target_count`` (faces), searched until the repaired mesh's vertex
count is within the budget's tolerance. The library sees the grid in cell units (world
coordinates divided by the cell size, on all three axes), so its threshold schedule does
not depend on the grid's unit.

References
----------
M. Garland and P. S. Heckbert, "Surface simplification using quadric error metrics",
SIGGRAPH 1997, DOI 10.1145/258734.258849.

S. Forstmann, Fast-Quadric-Mesh-Simplification,
https://github.com/sp4cerat/Fast-Quadric-Mesh-Simplification; pyfqmr,
https://github.com/Kramer84/pyfqmr-Fast-Quadric-Mesh-Reduction.
"""

from __future__ import annotations

import numpy as np

from terrainvis.core.terrain import TIN, HeightGrid
from terrainvis.errors import SimplificationError

from ..levels import budget_tolerance
from ._common import check_input, decimate_to_budget, require

__all__ = ["build", "build_free", "LIBRARY", "border_samples"]

#: The library this adapter needs (the ``peers`` extra).
LIBRARY = "pyfqmr"


def border_samples(shape) -> int:
    """Samples on the border of a grid of ``shape``.

    Examples
    --------
    >>> border_samples((120, 120)), border_samples((3, 3))
    (476, 8)
    """
    rows, cols = int(shape[0]), int(shape[1])
    return 2 * (rows + cols) - 4


def build(grid: HeightGrid, n_vertices: int, *, max_error: float | None = None, aggressiveness: float = 7.0,
          max_probes: int = 30) -> TIN:
    """pyfqmr with its border locked, to ``n_vertices`` vertices (within the budget's tolerance).

    Parameters
    ----------
    grid : HeightGrid
        The terrain, without nodata.
    n_vertices : int
        The budget.
    max_error : float, optional
        A target for the max vertical error (z units; what :func:`simplifiers.simplify`
        passes with ``max_error=E``): the result with the fewest vertices found, at most
        ``n_vertices``, whose max vertical error is <= E, by a bisection over the same
        parameter (``attrs["stopped_by"]`` is ``"max_error"``, or ``"budget"`` when even
        ``n_vertices`` vertices exceed E).
    aggressiveness : float
        pyfqmr's exponent of the threshold schedule (its default, 7).
    max_probes : int
        Library runs allowed to meet the budget.

    Returns
    -------
    TIN
        ``attrs``: ``library``, ``preserve_border``, ``search`` (``parameter``
        "target_count", ``value``, ``probes`` [faces asked, vertices after repair],
        ``failures``), ``repair`` (:func:`terrainvis.repair_tin`'s record),
        ``library_vertices``, ``library_faces``, ``unit`` and ``seconds_search``.

    Raises
    ------
    ImportError
        pyfqmr is not installed (the message says ``pip install "terrainvis[peers]"``).
    SimplificationError
        The budget is below the border's sample count (the locked border alone is
        more), or no face target gives a count within the tolerance.
    """
    budget = check_input(grid, n_vertices, "fqmr")
    pyfqmr = require(LIBRARY, "fqmr")
    border = border_samples(grid.shape)
    if budget + budget_tolerance(budget) < border + 1:
        raise SimplificationError(
            f"fqmr cannot reach {budget} vertices: with its border locked (preserve_border=True) it keeps all "
            f"{border} border samples of the {grid.shape[0]}x{grid.shape[1]} grid (and at least one more); "
            "fqmr-free collapses the border"
        )
    return _run(pyfqmr, grid, budget, "fqmr", True, aggressiveness, max_probes, max_error)


def build_free(grid: HeightGrid, n_vertices: int, *, max_error: float | None = None, aggressiveness: float = 7.0,
               max_probes: int = 30) -> TIN:
    """pyfqmr with a free border, then :func:`terrainvis.repair_tin`, to ``n_vertices`` vertices.

    As :func:`build` (the same attrs), with ``preserve_border=False``.
    """
    budget = check_input(grid, n_vertices, "fqmr-free")
    pyfqmr = require(LIBRARY, "fqmr-free")
    return _run(pyfqmr, grid, budget, "fqmr-free", False, aggressiveness, max_probes, max_error)


def _run(pyfqmr, grid, budget, method, preserve_border, aggressiveness, max_probes, max_error) -> TIN:
    def decimate(local, faces, target):
        s = pyfqmr.Simplify()
        s.setMesh(np.array(local, dtype=np.float64), np.array(faces, dtype=np.int32))  # it needs writable arrays
        s.simplify_mesh(target_count=int(target), aggressiveness=float(aggressiveness),
                        preserve_border=bool(preserve_border), verbose=False)
        v, f, _ = s.getMesh()
        return v, f

    tin = decimate_to_budget(grid, budget, method, "target_count", decimate, max_probes=max_probes,
                             max_error=max_error)
    tin.attrs.update(library=f"pyfqmr {_version('pyfqmr')}", preserve_border=preserve_border,
                     aggressiveness=float(aggressiveness))
    return tin


def _version(dist: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(dist)
    except PackageNotFoundError:
        return "?"
