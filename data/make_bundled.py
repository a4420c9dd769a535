"""Regenerate the five bundled 120x120 terrains: python data/make_bundled.py

They are frozen here so that results do not drift with numpy or scipy versions; running
this script with other versions may give slightly different files.
"""

from pathlib import Path

import numpy as np

from terrainvis.synthetic import KINDS, synthetic_terrain

if __name__ == "__main__":
    here = Path(__file__).resolve().parent
    for kind in KINDS:
        grid = synthetic_terrain(kind, size=120, seed=0)
        np.savez_compressed(here / f"{kind}.npz", z=grid.z, xs=grid.xs, ys=grid.ys)
        print(f"{kind:10s} {grid.shape} z [{grid.z.min():.1f}, {grid.z.max():.1f}] m")
