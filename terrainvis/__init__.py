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
    "HeightGrid": "terrainvis.terrain",
    "TIN": "terrainvis.terrain",
    "sample_points": "terrainvis.sampling",
    "load_dem": "terrainvis.io",
    "save_dem": "terrainvis.io",
    "load_terrain": "terrainvis.io",
    "save_terrain": "terrainvis.io",
    "native_coords": "terrainvis.io",
    "sample_dem": "terrainvis.io",
    "synthetic_terrain": "terrainvis.synthetic",
    "bundled_terrain": "terrainvis.synthetic",
    "min_clearance": "terrainvis.visibility",
    "line_of_sight": "terrainvis.visibility",
    "visibility_matrix": "terrainvis.visibility",
    "viewshed": "terrainvis.visibility",
    "relocate": "terrainvis.relocation",
    "agreement": "terrainvis.metrics",
    "vertical_errors": "terrainvis.deviation",
    "volume_error": "terrainvis.deviation",
    "compare": "terrainvis.experiment",
}
_MODULES = {
    "errors", "synthetic", "io", "visibility", "relocation", "deviation", "metrics", "experiment", "report", "plot",
    "cli", "terrain", "sampling", "options", "calibration",
}

__all__ = sorted(_API) + sorted(_MODULES)


def __getattr__(name):
    if name in _API:
        value = getattr(importlib.import_module(_API[name]), name)
        globals()[name] = value
        return value
    if name in _MODULES:
        module = importlib.import_module(f"terrainvis.{name}")
        globals()[name] = module
        return module
    raise AttributeError(f"module 'terrainvis' has no attribute {name!r}")


def __dir__():
    return __all__
