"""Regenerate the five bundled 120x120 terrains: python terrainvis/data/make_bundled.py

They are frozen here so that results do not drift with numpy or scipy versions; running
this script with other versions may give slightly different files. Each file is written
with :func:`terrainvis.io.save_terrain` in the terrainvis ``.npz`` format (version 1):
``z``, ``xs``, ``ys`` in HeightGrid row order (row 0 is the smallest y) and the attrs
``name``, ``seed``, ``synthetic`` and ``bundled``.
"""

from pathlib import Path

from terrainvis.io import save_terrain
from terrainvis.core.synthetic import KINDS, synthetic_terrain

if __name__ == "__main__":
    here = Path(__file__).resolve().parent
    for kind in KINDS:
        grid = synthetic_terrain(kind, size=120, seed=0)
        grid.attrs["bundled"] = True
        save_terrain(grid, here / f"{kind}.npz")
        print(f"{kind:10s} {grid.shape} z [{grid.z.min():.1f}, {grid.z.max():.1f}] m")
