"""The practitioners' simplifiers, as terrainvis methods: ``rtin``, ``delatin``, ``fqmr``, ``fqmr-free``, ``meshopt``, ``vtk-greedy``.

Each is a library that terrain and graphics practitioners use, wrapped so that it takes
a level's vertex budget like the built-in irregular methods (docs/peers.md has what
each reaches):

* ``rtin`` (semi-regular): pymartini, ``max_error`` searched; a height field as it
  comes (grids that are not (2^k+1)² are padded and clipped, see :mod:`.rtin`).
* ``delatin``: pydelatin, ``max_points``; a height field as it comes.
* ``fqmr``: pyfqmr with its border locked, ``target_count``; a height field, but the
  border's samples alone exceed the coarse levels' budgets.
* ``fqmr-free``: pyfqmr with a free border, ``target_count``; made a height field by
  :func:`terrainvis.repair_tin`.
* ``meshopt``: meshoptimizer, ``target_index_count``; then :func:`terrainvis.repair_tin`.
* ``vtk-greedy``: VTK's vtkGreedyTerrainDecimation, ``NumberOfTriangles``; a height
  field as it comes.

They reach terrainvis through its own plugin mechanism: terrainvis's ``pyproject.toml``
names each :class:`~simplifiers.Method` below in the entry-point group
``terrainvis.simplifiers``, and :func:`simplifiers.load_plugins` registers them when
:mod:`simplifiers` is imported. None is in a comparison's default list. The libraries
are the ``peers`` extra (``pip install "terrainvis[peers]"``); each adapter imports its
library only when it runs, so importing :mod:`simplifiers` stays fast and a missing
library is an ImportError with that hint (:func:`require`).
"""

from __future__ import annotations

from ..registry import Method
from ._common import INSTALL_HINT, require

__all__ = ["RTIN", "DELATIN", "FQMR", "FQMR_FREE", "MESHOPT", "VTK_GREEDY", "PEERS", "require", "INSTALL_HINT"]

_P = "simplifiers.peers."

RTIN = Method(
    "rtin", "semi-regular", _P + "rtin", "build",
    "Martini RTIN (pymartini; Evans et al. 2001), max_error searched; grids padded to 2^k+1 and clipped",
    options=("max_probes",), cost_rank=7, style=("tab:brown", "<"), default=False,
    # padded float64 and float32 tiles, Martini's errors, indices and triangle coordinates (up to ~4x the
    # samples when padding), and the errors' evaluation
    memory=(160, 64, None),
)
DELATIN = Method(
    "delatin", "irregular", _P + "delatin", "build",
    "Delatin greedy Delaunay insertion (pydelatin; Garland & Heckbert 1995), max_points searched",
    options=("max_probes",), cost_rank=7, style=("black", ">"), default=False, memory=(64, 200, None),
)
FQMR = Method(
    "fqmr", "irregular", _P + "fqmr", "build",
    "fast quadric mesh simplification (pyfqmr; Forstmann), border locked, target_count searched",
    options=("aggressiveness", "max_probes"), cost_rank=4, style=("navy", "p"), default=False,
    # the grid's mesh in numpy and in the library's vectors, and the repair
    memory=(600, 200, None),
)
FQMR_FREE = Method(
    "fqmr-free", "irregular", _P + "fqmr", "build_free",
    "fast quadric mesh simplification (pyfqmr; Forstmann), border free, then repair_tin; target_count searched",
    options=("aggressiveness", "max_probes"), cost_rank=4, style=("slateblue", "H"), default=False,
    memory=(600, 200, None),
)
MESHOPT = Method(
    "meshopt", "irregular", _P + "meshopt", "build",
    "meshoptimizer simplify (Kapoulkine), then repair_tin; target_index_count searched",
    options=("max_probes",), cost_rank=4, style=("teal", "8"), default=False, memory=(250, 200, None),
)
VTK_GREEDY = Method(
    "vtk-greedy", "irregular", _P + "vtk_greedy", "build",
    "VTK greedy terrain decimation (vtkGreedyTerrainDecimation), NumberOfTriangles searched",
    options=("max_probes",), cost_rank=6, style=("firebrick", "d"), default=False, memory=(200, 200, None),
)

#: Every peer's Method, by name (what the entry points name).
PEERS = {m.name: m for m in (RTIN, DELATIN, FQMR, FQMR_FREE, MESHOPT, VTK_GREEDY)}
