"""Regenerate examples/explore.ipynb (without outputs): python examples/make_notebook.py"""

from pathlib import Path

import nbformat as nbf

CELLS = [
    ("md", """# Exploring terrainvis on a real DEM

How many line-of-sight (LOS) answers does terrain simplification lose, and what does it buy?
This notebook walks through the API on the USGS 3-arc-second DEM of the Jacksboro fault,
Tennessee, which ships with matplotlib (`terrainvis.sample_dem("jacksboro")`)."""),
    ("code", """%matplotlib inline
import numpy as np
import terrainvis as tv
import simplifiers
from terrainvis import plot"""),
    ("md", """## 1. Load the DEM and look at it

`sample_dem` converts the lon/lat cells to metres (74.6 m east-west, 92.5 m north-south) and
flips the rows so that y grows northwards. We work on a 160 x 160 window around the fault
valley to keep the notebook quick."""),
    ("code", """dem = tv.sample_dem("jacksboro")
print(dem)
T = dem.crop(rows=(90, 250), cols=(120, 280))
print(T, f"{T.nbytes / 1e3:.0f} kB")
plot.hillshade(T, title="Jacksboro fault, 160 x 160 window")"""),
    ("md", """## 2. Simplify with every method at one level

Level 2 keeps 1/16 of the samples. The regular methods (reverse Faber: simple, GLS, LLS,
feature-aware) return a coarser `HeightGrid`; the irregular ones (quadric edge collapse,
greedy insertion, greedy cuts) return a `TIN` with the same number of vertices. These are
the paper's seven, `simplifiers.default_methods()`; `simplifiers.available()` also lists
`visopt` (a regular grid optimised for the calibrated relocation, which takes about half a
minute here) and any method you or a plugin registered (section 7)."""),
    ("code", """level = 2
results = {m: simplifiers.simplify(T, m, level) for m in simplifiers.default_methods()}
for m, S in results.items():
    meta = S.attrs
    print(f"{m:17s} {meta['n_vertices']:6d} vertices  {meta['nbytes'] / 1e3:7.1f} kB  "
          f"max err {meta['max_error']:6.1f} m  RMS {meta['rms_error']:5.2f} m  {meta['seconds']:6.3f} s")
plot.terrain_views(T, results)"""),
    ("md", """## 3. Which verdicts change?

Sample 40 observers on the original terrain, compute the visibility matrix there and on the
LLS simplification (after moving the points onto it with the *half* relocation), and draw
the pairs whose verdict changed: red pairs were visible and became blocked, blue pairs the
other way round."""),
    ("code", """P = tv.sample_points(T, 40, seed=1)
V_T = tv.visibility_matrix(T, P)
S = results["lls"]
P_S = tv.relocate(P, S, "half")
V_S = tv.visibility_matrix(S, P_S)
print(tv.agreement(V_T, V_S))
plot.los_pairs(T, P, V_T, V_S, title="LLS, level 2, half relocation")"""),
    ("md", """## 4. A small comparison

`compare` runs the paper's experiment: every method, level and relocation, over several point
sets. Here: the Jacksboro window, two levels, three sets of 25 points (`terrainvis compare` on
the command line runs the full protocol). `progress=True` shows a progress bar (a widget
when ipywidgets is installed: `pip install "terrainvis[notebook]"`)."""),
    ("code", """df = tv.compare({"jacksboro": T}, levels=[1, 2], n_points=25, n_sets=3, workers=1, progress=True)
tables = tv.report.paper_tables(df)
tables["Table 1"]"""),
    ("code", """plot.accuracy_vs_size(df)"""),
    ("code", """plot.tradeoff(df, relocation="half")"""),
    ("md", """## 5. Viewsheds: what an observer sees, before and after simplification

`tv.viewshed` decides every sample of a grid as a target, exactly on the piecewise-linear
surface (the verdict `line_of_sight` would give, cell by cell), in well under a second even
on an SRTM tile. On a simplification, `at=T` puts the targets on T's samples, standing on
the simplified surface, so the two rasters compare cell by cell."""),
    ("code", """observer = (15000.0, 15500.0)
V_T = tv.viewshed(T, observer, observer_height=2.0)
V_S = tv.viewshed(results["lls"], observer, observer_height=2.0, at=T)
print(f"visible on T: {V_T.mean():.1%}, on LLS level 2: {V_S.mean():.1%}, cells agreeing: {(V_T == V_S).mean():.1%}")
plot.viewshed(T, V_T, observer=observer, title="viewshed on T")"""),
    ("md", """## 6. Use a simplification outside terrainvis

`save_terrain` writes a simplified grid as a GeoTIFF in the DEM's own CRS (here lon/lat, so
it lines up with the original in QGIS), and any result as a mesh that trimesh, Blender or a
game engine opens. The same from the shell:
`terrainvis simplify dem.tif -m lls -l 2 -o lls.tif`. An even-sized grid's coarse samples are
not evenly spaced at the last row and column (reverse Faber keeps both ends), so a GeoTIFF of
it is resampled onto even spacing, with a warning saying by how much; odd-sized grids (like
this 161 x 161 window) are written exactly."""),
    ("code", """import tempfile, pathlib, warnings
out = pathlib.Path(tempfile.mkdtemp())
W = dem.crop(rows=(90, 251), cols=(120, 281))          # 161 x 161: the coarse grids are exact
S_lls = simplifiers.simplify(W, "lls", 2)
tv.save_terrain(S_lls, out / "lls.tif")
tv.save_terrain(simplifiers.simplify(W, "greedy-insertion", 2), out / "greedy.ply")
back = tv.load_terrain(out / "lls.tif")
print(back, back.attrs["crs"])
print("same heights:", np.array_equal(back.z, S_lls.z))
import trimesh
mesh = trimesh.load(out / "greedy.ply", process=False)
print(mesh)"""),
    ("md", """## 7. Bring your own simplifier

A function of your own becomes a method with one call, and `compare` then runs it beside
the built-in ones (a function defined in a notebook cannot reach worker processes, so
this comparison runs in the notebook's process: `workers=1`; put the function in a module
to run it on workers). A mesh made by another tool is measured with `evaluate`, on the
same points and relocations as `compare` uses; and `assert_visibility_kept` turns the
measure into a test for your own pipeline (it raises an `AssertionError` that lists the
wrong pairs when the share kept is below the threshold)."""),
    ("code", """from scipy.ndimage import uniform_filter
from terrainvis.testing import assert_visibility_kept

def smoothed(grid, level, *, size=3):
    \"\"\"The coarse samples of "simple", each the mean of a size x size window around it.\"\"\"
    xs, ys = simplifiers.coarse_coords(grid.xs, level), simplifiers.coarse_coords(grid.ys, level)
    z = uniform_filter(grid.z, size=size, mode="nearest")
    return tv.HeightGrid.from_coords(z[np.ix_(np.searchsorted(grid.ys, ys), np.searchsorted(grid.xs, xs))], xs, ys)

if "smoothed" not in simplifiers.METHODS:
    simplifiers.register("smoothed", smoothed, kind="regular", options=("size",))
mine = tv.compare({"jacksboro": T}, methods=["smoothed", "lls"], levels=[2], n_points=25, n_sets=3,
                  relocations=["full"], workers=1)
print(mine.groupby("method")["accuracy"].mean().round(4))

# the greedy-insertion mesh of section 6, as another tool would hand it over
measured = tv.evaluate({"window": W}, out / "greedy.ply", n_points=25, n_sets=3, relocations=["full"])
print(f"greedy.ply keeps {measured['accuracy'].mean():.1%} of the verdicts")
kept = assert_visibility_kept(W, out / "greedy.ply", min_accuracy=0.9, n=60)
print(f"assert_visibility_kept passed: {kept['accuracy']:.1%} kept, {kept['false_visible']} falsely visible")"""),
]


def main():
    nb = nbf.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.cells = [nbf.v4.new_markdown_cell(src) if kind == "md" else nbf.v4.new_code_cell(src) for kind, src in CELLS]
    path = Path(__file__).with_name("explore.ipynb")
    nbf.write(nb, path)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
