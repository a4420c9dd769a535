"""Hashes of greedy cuts' and greedy insertion's TINs: run it in two checkouts and diff, for "the same bits".

Prints one line per result (terrain, method, size, vertex and face counts, the first 16
hex digits of the SHA-256 of its vertices' and faces' bytes) and a total:
``simplifiers.simplify(T, method, level)`` for ``greedy-cuts`` and ``greedy-insertion`` at
levels 1, 2, 3 and at ``max_error=5`` on the five bundled terrains and on the first
256 x 256 samples of ``jacksboro_fault_tn`` (non-square cells: greedy insertion's scaled
in-circle test), read from ``$TERRAINVIS_SHARED_DEMS``, default ``../shared/data/dem``
beside the repository (skipped when absent). Run each checkout with an empty
``NUMBA_CACHE_DIR``: numba checks a cached kernel against its own file only, not the
helpers it inlined from other files::

    NUMBA_CACHE_DIR=$(mktemp -d) PYTHONPATH=/tmp/before python benchmarks/greedy_bits.py > before.txt
    NUMBA_CACHE_DIR=$(mktemp -d) PYTHONPATH=. python benchmarks/greedy_bits.py > after.txt
    diff before.txt after.txt
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np

import simplifiers
import terrainvis as tv

SHARED = Path(os.environ.get("TERRAINVIS_SHARED_DEMS", Path(__file__).resolve().parents[2] / "shared" / "data" / "dem"))
SIZES = ({"level": 1}, {"level": 2}, {"level": 3}, {"max_error": 5.0})


def main() -> None:
    terrains = {name: tv.bundled_terrain(name) for name in ("hills", "mountains", "mesas", "ridges", "rough")}
    dem = SHARED / "jacksboro_fault_tn.npz"
    if dem.exists():
        terrains["jacksboro_fault_tn[:256, :256]"] = tv.load_dem(dem).crop(rows=(0, 256), cols=(0, 256))
    total = hashlib.sha256()
    for name, grid in terrains.items():
        for method in ("greedy-cuts", "greedy-insertion"):
            for size in SIZES:
                tin = simplifiers.simplify(grid, method, **size)
                h = hashlib.sha256(np.ascontiguousarray(tin.vertices).tobytes())
                h.update(np.ascontiguousarray(tin.faces).tobytes())
                total.update(h.digest())
                print(name, method, size, tin.vertices.shape[0], tin.faces.shape[0], h.hexdigest()[:16], flush=True)
    print("total", total.hexdigest())


if __name__ == "__main__":
    main()
