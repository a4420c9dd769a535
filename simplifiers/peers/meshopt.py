"""``meshopt``: meshoptimizer's ``simplify``, then :func:`terrainvis.repair_tin`.

meshoptimizer (Kapoulkine) is the decimator of real-time engines: edge collapses ranked
by a quadric error, each collapse onto one of the edge's two vertices, so it never
creates a position and its vertices are grid samples (the adapter keeps their exact
float64 coordinates; the library sees float32 ones). Border vertices collapse only
along the border, but a corner can collapse into its neighbour, which moves the
rectangle's corner; and a collapse may fold a face over in projection. Every result is
made a height field over the grid by :func:`terrainvis.repair_tin` (missing corners
inserted with the grid's heights, folded faces unfolded by moving a vertex into the
kernel of its star, taking the grid's height there); ``attrs["repair"]`` says what it
changed.

**The parameter.** ``target_index_count`` (3 x the faces asked), searched until the
repaired mesh's vertex count is within the budget's tolerance; ``target_error`` is set
out of reach (1e30, relative to the mesh's extent), so only the count stops it. The
library's own error of the result (relative to the extent) is in
``attrs["library_error"]``.

References
----------
A. Kapoulkine, meshoptimizer, https://github.com/zeux/meshoptimizer (``meshopt_simplify``).

M. Garland and P. S. Heckbert, "Surface simplification using quadric error metrics",
SIGGRAPH 1997, DOI 10.1145/258734.258849.
"""

from __future__ import annotations

import numpy as np

from terrainvis.core.terrain import TIN, HeightGrid

from ._common import check_input, decimate_to_budget, require

__all__ = ["build", "LIBRARY", "TARGET_ERROR"]

#: The library this adapter needs (the ``peers`` extra).
LIBRARY = "meshoptimizer"

#: ``target_error`` handed to meshoptimizer: out of reach, so that the index count stops it.
TARGET_ERROR = 1e30


def build(grid: HeightGrid, n_vertices: int, *, max_error: float | None = None, max_probes: int = 30) -> TIN:
    """meshoptimizer's simplification of ``grid`` to ``n_vertices`` vertices, repaired into a height field.

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
        Library runs allowed to meet the budget.

    Returns
    -------
    TIN
        ``attrs``: ``library``, ``library_error`` (meshoptimizer's error of the mesh
        kept, relative to its extent), ``search`` (``parameter``
        "target_index_count", ``value``, ``probes`` [indices asked, vertices after
        repair], ``failures``), ``repair``, ``library_vertices``, ``library_faces``,
        ``unit`` and ``seconds_search``.

    Raises
    ------
    ImportError
        meshoptimizer is not installed (the message says ``pip install "terrainvis[peers]"``).
    SimplificationError
        No index target gives a count within the tolerance.
    """
    budget = check_input(grid, n_vertices, "meshopt")
    meshopt = require(LIBRARY, "meshopt")
    errors = {}

    def decimate(local, faces, target_faces):
        indices = np.ascontiguousarray(faces, dtype=np.uint32).ravel()
        positions = np.ascontiguousarray(local, dtype=np.float32)
        dest = np.zeros(indices.size, dtype=np.uint32)
        err = np.zeros(1, dtype=np.float32)
        n = meshopt.simplify(dest, indices, positions, target_index_count=3 * int(target_faces),
                             target_error=TARGET_ERROR, options=0, result_error=err)
        errors[int(target_faces)] = float(err[0])
        return None, dest[: int(n)].reshape(-1, 3)

    tin = decimate_to_budget(grid, budget, "meshopt", "target_index_count", decimate, max_probes=max_probes,
                             label=lambda p: 3 * int(p), samples_only=True, max_error=max_error)
    tin.attrs.update(library=f"meshoptimizer {_version()}",
                     library_error=errors[tin.attrs["search"]["value"] // 3])
    return tin


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("meshoptimizer")
    except PackageNotFoundError:
        return "?"
