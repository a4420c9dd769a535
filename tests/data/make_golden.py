"""Regenerate the golden regression data: ``python tests/data/make_golden.py``.

The golden files pin what the project computes on fixed inputs, so that a change that
moves the paper's results fails CI instead of passing silently:

* ``golden_simplify.csv``: vertex count, maximum and RMS vertical error of every method
  at levels 1-3 on two bundled terrains (hills, ridges) and on a 120x120 crop of a real
  DEM (green_mountains_vt from ../shared/data/dem);
* ``golden_compare.csv``: the agreement counts of a small seeded ``compare`` (two
  terrains, all seven methods, levels 1 and 3, 2 sets of 20 points).

Run it only when a change of these numbers is deliberate, and say in the commit message
what moved and why. ``tests/experiment/test_golden.py`` checks the files.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from conftest import shared_dem_120  # noqa: E402  (tests/conftest.py)

SIMPLIFY_TERRAINS = ("hills", "ridges", "green_mountains_vt")
COMPARE_TERRAINS = ("mesas", "rough")
COMPARE_KW = dict(levels=[1, 3], n_points=20, n_sets=2, seed=7, repeats=1, volume=True)
COUNTS = ["agree_visible", "agree_blocked", "false_visible", "false_blocked"]


def golden_terrain(name: str):
    from terrainvis import bundled_terrain

    return shared_dem_120(name) if name == "green_mountains_vt" else bundled_terrain(name)


def simplify_table() -> pd.DataFrame:
    from simplifiers import default_methods, simplify

    rows = []
    for name in SIMPLIFY_TERRAINS:
        grid = golden_terrain(name)
        for method in default_methods():  # the paper's methods (not visopt)
            for level in (1, 2, 3):
                a = simplify(grid, method, level).attrs
                rows.append({"terrain": name, "method": method, "level": level, "n_vertices": a["n_vertices"],
                             "max_error": a["max_error"], "rms_error": a["rms_error"]})
    return pd.DataFrame(rows)


def compare_table() -> pd.DataFrame:
    from terrainvis import bundled_terrain, compare

    df = compare({t: bundled_terrain(t) for t in COMPARE_TERRAINS}, workers=1, **COMPARE_KW)
    return df[["terrain", "set", "method", "level", "relocation", "n_vertices", *COUNTS, "volume_error"]]


if __name__ == "__main__":
    simplify_table().to_csv(HERE / "golden_simplify.csv", index=False, float_format="%.17g")
    compare_table().to_csv(HERE / "golden_compare.csv", index=False, float_format="%.17g")
    print(f"wrote {HERE / 'golden_simplify.csv'} and {HERE / 'golden_compare.csv'}")
