"""Figure: where gdal_viewshed and r.viewshed disagree with the exact viewshed.

On a DEM (default: the shared green_mountains_vt.tif, 237 x 188 samples of 90 m), from its
highest sample with an eye ``--eye`` m up and targets on the ground, flat earth, it runs
our exact viewshed, ``gdal_viewshed -cc 0`` (Debian package gdal-bin) and r.viewshed in a
temporary GRASS location (Debian package grass-core), and draws two panels over the
hillshade: cells both see (pale), cells only ours sees (blue) and cells only the peer sees
(red). It prints the counts. Command that made docs/figures/viewshed_peers.png::

    python studies/peer_viewshed_figure.py -o docs/figures/viewshed_peers.png
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import tempfile

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import rasterio  # noqa: E402
from matplotlib.colors import LightSource, ListedColormap  # noqa: E402

from terrainvis import viewshed  # noqa: E402
from terrainvis.io import load_dem  # noqa: E402

DEM = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "data", "dem",
                   "green_mountains_vt.tif")


def _read(path) -> np.ndarray:
    with rasterio.open(path) as ds:
        return ds.read(1)[::-1] == 1  # north-up file; our rows go south to north


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dem", default=DEM)
    ap.add_argument("--eye", type=float, default=10.0)
    ap.add_argument("-o", "--output", default="viewshed_peers.png")
    args = ap.parse_args(argv)
    g = load_dem(args.dem)
    r, c = np.unravel_index(int(np.nanargmax(g.z)), g.shape)
    x, y = float(g.xs[c]), float(g.ys[r])
    ours = viewshed(g, (x, y), observer_height=args.eye)
    tmp = tempfile.mkdtemp(prefix="peer_fig_")
    peers = {}
    out = os.path.join(tmp, "gdal.tif")
    subprocess.run(["gdal_viewshed", "-q", "-ox", repr(x), "-oy", repr(y), "-oz", repr(args.eye), "-tz", "0",
                    "-cc", "0", "-vv", "1", "-iv", "0", args.dem, out], check=True)
    peers["gdal_viewshed (-cc 0)"] = _read(out)
    env = dict(os.environ, GRASS_MESSAGE_FORMAT="silent")
    loc = os.path.join(tmp, "loc")
    subprocess.run(["grass", "-c", args.dem, loc, "-e"], check=True, capture_output=True, env=env)
    gx = ["grass", os.path.join(loc, "PERMANENT"), "--exec"]
    for cmd in (["r.in.gdal", f"input={args.dem}", "output=dem"], ["g.region", "raster=dem"],
                ["r.viewshed", "input=dem", "output=vs", f"coordinates={x!r},{y!r}", f"observer_elevation={args.eye!r}",
                 "target_elevation=0", "-b"],
                ["r.out.gdal", "input=vs", f"output={os.path.join(tmp, 'grass.tif')}", "type=Byte", "-f"]):
        subprocess.run(gx + cmd + ["--quiet"], check=True, capture_output=True, env=env)
    peers["r.viewshed"] = _read(os.path.join(tmp, "grass.tif"))
    shutil.rmtree(tmp, ignore_errors=True)

    ls = LightSource(azdeg=315, altdeg=45)
    shade = ls.hillshade(np.nan_to_num(g.z[::-1], nan=float(np.nanmin(g.z))), vert_exag=2.0)
    extent = (g.xs[0], g.xs[-1], g.ys[0], g.ys[-1])
    cmap = ListedColormap([(0, 0, 0, 0), (1.0, 1.0, 0.6, 0.45), (0.1, 0.3, 1.0, 1.0), (0.9, 0.05, 0.05, 1.0)])
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.2))
    for ax, (name, peer) in zip(axes, peers.items()):
        code = np.zeros(g.shape, dtype=int)
        code[ours & peer] = 1
        code[ours & ~peer] = 2
        code[peer & ~ours] = 3
        n_o, n_p = int((ours & ~peer).sum()), int((peer & ~ours).sum())
        print(f"{name}: both {int((ours & peer).sum())}, only ours {n_o}, only the peer {n_p} "
              f"({100 * (n_o + n_p) / g.z.size:.2f} % of {g.z.size} cells)")
        ax.imshow(shade, cmap="gray", extent=extent, origin="upper")
        ax.imshow(code[::-1], cmap=cmap, vmin=0, vmax=3, extent=extent, origin="upper", interpolation="nearest")
        ax.plot([x], [y], marker="^", color="k", markersize=8)
        ax.set_title(f"ours vs {name}: only ours {n_o}, only {name.split()[0]} {n_p} cells", fontsize=10)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"{os.path.basename(args.dem)}, eye {args.eye:g} m on the highest sample, flat earth: pale = both "
                 "see, blue = only ours, red = only the peer", fontsize=10)
    fig.subplots_adjust(left=0.01, right=0.99, bottom=0.02, top=0.88, wspace=0.03)
    fig.savefig(args.output, dpi=110)
    print("wrote", args.output)


if __name__ == "__main__":
    main()
