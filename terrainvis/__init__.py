"""terrainvis: what terrain simplification costs line of sight, and what it buys.

The public API is imported lazily, so ``import terrainvis`` stays fast and optional
dependencies are only touched by the functions that need them.
"""

from __future__ import annotations

import importlib
import os

# pymeshlab and embreex ship an older TBB than numba's TBB threading layer accepts; numba
# then warns once and falls back to OpenMP. Ask for OpenMP first (unless the user chose),
# so the kernels get the same threads without the warning.
os.environ.setdefault("NUMBA_THREADING_LAYER_PRIORITY", "omp tbb workqueue")

__version__ = "0.1.0"

_API = {
    "HeightGrid": "terrainvis.core.terrain",
    "TIN": "terrainvis.core.terrain",
    "sample_points": "terrainvis.core.sampling",
    "load_dem": "terrainvis.io",
    "save_dem": "terrainvis.io",
    "load_terrain": "terrainvis.io",
    "save_terrain": "terrainvis.io",
    "native_coords": "terrainvis.io",
    "sample_dem": "terrainvis.io",
    "synthetic_terrain": "terrainvis.core.synthetic",
    "bundled_terrain": "terrainvis.io",
    "min_clearance": "terrainvis.visibility",
    "line_of_sight": "terrainvis.visibility",
    "visibility_matrix": "terrainvis.visibility",
    "viewshed": "terrainvis.visibility",
    "cumulative_viewshed": "terrainvis.visibility",
    "fresnel_clearance": "terrainvis.visibility",
    "observer_sets": "terrainvis.visibility",
    "ObserverSets": "terrainvis.visibility",
    "intervisibility_network": "terrainvis.visibility",
    "site_observers": "terrainvis.visibility",
    "candidate_grid": "terrainvis.visibility",
    "relocate": "terrainvis.relocation",
    "eye_surface": "terrainvis.relocation",
    "EyeSurface": "terrainvis.relocation",
    "agreement": "terrainvis.core.metrics",
    "vertical_errors": "terrainvis.core.deviation",
    "volume_error": "terrainvis.core.deviation",
    "compare": "terrainvis.experiment",
    "evaluate": "terrainvis.experiment.evaluate",
    "repair_tin": "terrainvis.core.repair",
}
#: Modules reachable as attributes (``terrainvis.io``), imported on first use.
_MODULES = {
    "errors": "terrainvis.errors", "tolerances": "terrainvis.tolerances", "core": "terrainvis.core",
    "io": "terrainvis.io", "visibility": "terrainvis.visibility", "relocation": "terrainvis.relocation",
    "experiment": "terrainvis.experiment", "cli": "terrainvis.cli",
    "terrain": "terrainvis.core.terrain", "synthetic": "terrainvis.core.synthetic",
    "sampling": "terrainvis.core.sampling", "deviation": "terrainvis.core.deviation",
    "metrics": "terrainvis.core.metrics", "report": "terrainvis.experiment.report",
    "plot": "terrainvis.experiment.plot", "options": "terrainvis.experiment.options",
    "testing": "terrainvis.testing",
}

__all__ = sorted(_API) + sorted(_MODULES)


def __getattr__(name):
    if name in _API:
        value = getattr(importlib.import_module(_API[name]), name)
        globals()[name] = value
        return value
    if name in _MODULES:
        module = importlib.import_module(_MODULES[name])
        globals()[name] = module
        return module
    raise AttributeError(f"module 'terrainvis' has no attribute {name!r}")


def __dir__():
    return __all__
