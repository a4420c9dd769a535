"""``delatin``: Delatin's greedy Delaunay insertion (pydelatin, a binding of Fogleman's hmm).

Delatin (Agafonkin; hmm by Fogleman) is Garland & Heckbert's greedy insertion (1995,
Algorithm III): from the two triangles of the rectangle, insert the sample with the
largest vertical error, restore the Delaunay property, repeat. Its vertices are grid
samples, and the rectangle's corners are the first four, so its result is a height
field over the grid's extent as it comes.

**The parameter.** pydelatin stops at ``max_points`` vertices (or at ``max_error``, set
here to 0 so that only the count stops it): the search asks for the budget and checks
the count it gets, correcting ``max_points`` when the library's count differs (it has
not, on the grids measured; ``attrs["search"]`` records each run).

**What the adapter does to its output.** pydelatin's y axis points the other way
(its y = rows - 1 - row) and its heights are float32: the adapter turns its (x, y)
back into the sample's (row, column), places the vertex at the grid's coordinates with
the grid's float64 height, and orders each face counter-clockwise. ``attrs`` records
Delatin's own ``library_error`` (its max error, over the samples, in float32): an
independent check of the max error terrainvis measures.

Delatin works on sample indices: on a grid whose cells are not square its Delaunay
flips see squares (a tile, as a tiler gives it).

References
----------
M. Garland and P. S. Heckbert, "Fast polygonal approximation of terrains and height
fields", Technical Report CMU-CS-95-181, Carnegie Mellon University, 1995.

M. Fogleman, hmm (heightmap meshing utility), https://github.com/fogleman/hmm;
V. Agafonkin, delatin, https://github.com/mapbox/delatin.
"""

from __future__ import annotations

import time

import numpy as np

from terrainvis.core.terrain import TIN, HeightGrid

from ..registry import check_height_field
from ._common import BudgetSearch, check_input, index_tin, require

__all__ = ["build", "LIBRARY"]

#: The library this adapter needs (the ``peers`` extra).
LIBRARY = "pydelatin"


def build(grid: HeightGrid, n_vertices: int, *, max_error: float | None = None, max_probes: int = 12) -> TIN:
    """Delatin's TIN of ``grid`` with ``n_vertices`` vertices (within the budget's tolerance).

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
    max_probes : int
        Delatin runs allowed to meet the budget.

    Returns
    -------
    TIN
        Vertices at grid samples with the grid's heights. ``attrs``: ``library``,
        ``library_error`` (Delatin's max error of the mesh kept), ``search``
        (``parameter`` "max_points", ``value``, ``probes`` [max_points, vertices],
        ``failures``) and ``seconds_search``.

    Raises
    ------
    ImportError
        pydelatin is not installed (the message says ``pip install "terrainvis[peers]"``).
    SimplificationError
        No ``max_points`` gives a count within the tolerance.
    """
    budget = check_input(grid, n_vertices, "delatin")
    pydelatin = require(LIBRARY, "delatin")
    rows, cols = grid.shape
    z = np.ascontiguousarray(grid.z, dtype=np.float64)
    errors = {}

    def run(max_points: int) -> TIN:
        d = pydelatin.Delatin(z, max_error=0.0, max_points=int(max_points))
        v = np.asarray(d.vertices)
        c = np.rint(v[:, 0]).astype(np.int64)
        r = (rows - 1) - np.rint(v[:, 1]).astype(np.int64)  # Delatin's y runs from the last row
        tin = index_tin(grid, c, r, np.asarray(d.triangles))
        errors[max_points] = float(d.error)
        check_height_field(tin, grid, method="delatin")
        return tin

    t0 = time.perf_counter()
    search = BudgetSearch("delatin", "max_points", run, budget, lo=4, hi=grid.size, max_probes=max_probes)
    tin = search.result(budget, grid, max_error)
    tin.attrs.update(
        library=f"pydelatin {getattr(pydelatin, '__version__', '?')}",
        library_error=errors[tin.attrs["search"]["value"]], seconds_search=time.perf_counter() - t0,
    )
    return tin
