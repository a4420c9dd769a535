"""``vtk-greedy``: VTK's ``vtkGreedyTerrainDecimation`` at the level's vertex budget.

VTK's filter (after Garland & Heckbert 1995) triangulates an image's samples by greedy
Delaunay insertion: from the image's corners, insert the sample farthest from the mesh
until an error measure is met. Its vertices are samples; with
``BoundaryVertexDeletion`` on (VTK's default) border samples are inserted only when
they are worst, like any other. The output covers the image's rectangle, so it is a
height field over the grid's extent as it comes.

**The parameter.** The filter stops at an absolute or relative error, a reduction or a
number of triangles. The adapter uses ``NumberOfTriangles`` and searches it until the
vertex count is within the budget's tolerance (a disk with V vertices, B on its border,
has 2V - B - 2 triangles: the first guess is 2 x budget). VTK's ``AbsoluteError`` is not
the error its result reaches (measured in docs/peers.md), which is one more reason to
search the triangle count.

**What the adapter does to its output.** The filter sees the grid as a vtkImageData of
unit spacing (sample indices; a rectilinear grid has no image): each output point is
turned back into its sample (row, column) and placed at the grid's coordinates with the
grid's height; faces are ordered counter-clockwise.

References
----------
M. Garland and P. S. Heckbert, "Fast polygonal approximation of terrains and height
fields", Technical Report CMU-CS-95-181, Carnegie Mellon University, 1995.

W. Schroeder, K. Martin and B. Lorensen, "The Visualization Toolkit", 4th ed., Kitware,
2006 (vtkGreedyTerrainDecimation).
"""

from __future__ import annotations

import time

import numpy as np

from terrainvis.core.terrain import TIN, HeightGrid
from terrainvis.errors import SimplificationError

from ..registry import check_height_field
from ._common import BudgetSearch, check_input, index_tin, require

__all__ = ["build", "LIBRARY"]

#: The library this adapter needs (the ``peers`` extra: the ``vtk`` wheel).
LIBRARY = "vtkmodules.vtkFiltersHybrid"


def build(grid: HeightGrid, n_vertices: int, *, max_error: float | None = None, max_probes: int = 30) -> TIN:
    """VTK's greedy terrain decimation of ``grid`` with ``n_vertices`` vertices (within the tolerance).

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
        Filter runs allowed to meet the budget.

    Returns
    -------
    TIN
        Vertices at grid samples with the grid's heights. ``attrs``: ``library``,
        ``search`` (``parameter`` "NumberOfTriangles", ``value``, ``probes``
        [triangles, vertices], ``failures``) and ``seconds_search``.

    Raises
    ------
    ImportError
        vtk is not installed (the message says ``pip install "terrainvis[peers]"``).
    SimplificationError
        No triangle count gives a vertex count within the tolerance.
    """
    budget = check_input(grid, n_vertices, "vtk-greedy")
    hybrid = require(LIBRARY, "vtk-greedy")
    data_model = require("vtkmodules.vtkCommonDataModel", "vtk-greedy")
    support = require("vtkmodules.util.numpy_support", "vtk-greedy")
    rows, cols = grid.shape
    image = data_model.vtkImageData()
    image.SetDimensions(cols, rows, 1)  # x = column (fastest), y = row
    image.SetOrigin(0.0, 0.0, 0.0)
    image.SetSpacing(1.0, 1.0, 1.0)
    scalars = support.numpy_to_vtk(np.ascontiguousarray(grid.z, dtype=np.float64).ravel(), deep=True)
    scalars.SetName("z")
    image.GetPointData().SetScalars(scalars)

    def run(n_triangles: int) -> TIN:
        f = hybrid.vtkGreedyTerrainDecimation()
        f.SetInputData(image)
        f.SetErrorMeasureToNumberOfTriangles()
        f.SetNumberOfTriangles(int(n_triangles))
        f.Update()
        out = f.GetOutput()
        polys = out.GetPolys()
        offsets = support.vtk_to_numpy(polys.GetOffsetsArray())
        conn = support.vtk_to_numpy(polys.GetConnectivityArray())
        if offsets.size < 2 or not (np.diff(offsets) == 3).all():
            raise SimplificationError(f"vtk-greedy: the filter returned {offsets.size - 1} polygons, not all triangles")
        points = support.vtk_to_numpy(out.GetPoints().GetData())
        used, faces = np.unique(conn.reshape(-1, 3), return_inverse=True)
        faces = faces.reshape(-1, 3)
        c = np.rint(points[used, 0]).astype(np.int64)
        r = np.rint(points[used, 1]).astype(np.int64)
        tin = index_tin(grid, c, r, faces)
        check_height_field(tin, grid, method="vtk-greedy")
        return tin

    t0 = time.perf_counter()
    search = BudgetSearch("vtk-greedy", "NumberOfTriangles", run, budget, lo=2, hi=2 * grid.size,
                          max_probes=max_probes)
    tin = search.result(2 * budget, grid, max_error)
    version = require("vtkmodules", "vtk-greedy").__version__
    tin.attrs.update(library=f"vtk {version}", seconds_search=time.perf_counter() - t0)
    return tin
