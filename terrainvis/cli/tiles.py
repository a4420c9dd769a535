"""``terrainvis tiles``: a DEM as a Cesium quantized-mesh tileset, each tile simplified by a method."""

from __future__ import annotations

import argparse
import math
import sys

from ._common import UsageError, add_nodata, distance_arg, method_arg, on_interrupt, plural, read_terrain, working

#: The command's line in ``terrainvis --help`` (also its light sub-parser: :func:`terrainvis.cli._parser`).
HELP = "write a DEM as terrain tiles: Cesium quantized-mesh or terrain-RGB"

#: How the API's messages name the arguments on the command line.
_NAMES = {"out_dir": "OUT_DIR", "overwrite": "--overwrite", "resume": "--resume", "zooms": "--zoom", "method": "--method",
          "max_error0": "--max-error", "lattice": "--lattice", "grid": "DEM", "keep_los": "--keep-los",
          "los_height": "--los-height", "format": "--format", "gzip": "--gzip"}


def zoom_arg(text: str) -> int:
    from ..tiles.scheme import MAX_ZOOM

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a zoom, an integer in [0, {MAX_ZOOM}], got {text!r}") from None
    if not 0 <= value <= MAX_ZOOM:
        raise argparse.ArgumentTypeError(f"expected a zoom in [0, {MAX_ZOOM}], got {text!r}")
    return value


def share_arg(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0.0 < value <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a share of the verdicts in (0, 1], such as 0.99, got {text!r}")
    return value


def lattice_arg(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= 1024:
        raise argparse.ArgumentTypeError(f"expected an integer in [1, 1024], got {text!r}")
    return value


def add_parser(sub) -> None:
    from simplifiers import METHODS

    from ..tiles.scheme import FORMATS

    t = sub.add_parser(
        "tiles", help=HELP,
        description=(
            "Write a georeferenced DEM as a Cesium quantized-mesh-1.0 tileset (OUT_DIR/{z}/{x}/{y}.terrain and "
            "OUT_DIR/layer.json, EPSG:4326, TMS): the largest lon/lat rectangle inside the DEM's footprint, every "
            "zoom from 0 to MAX. Each tile is the DEM sampled on a 65 x 65 lattice (--lattice), simplified from "
            "zoom MIN on with the method to a max vertical error of E0 / 2^z metres (below MIN the whole lattice), "
            "or, with --keep-los P, to the largest error whose tiles keep a share P of their sight lines' verdicts. "
            "Needs pyproj: pip install \"terrainvis[tiles]\"."
        ),
    )
    t.add_argument("dem", help="DEM file or bundled name (with a CRS)")
    t.add_argument("out_dir", metavar="OUT_DIR", help="output folder (empty, or with --overwrite)")
    t.add_argument("-m", "--method", required=True, type=method_arg, metavar="METHOD",
                   help=f"one of {', '.join(METHODS)}")
    t.add_argument("--zoom", nargs=2, type=zoom_arg, required=True, metavar=("MIN", "MAX"),
                   help="the method simplifies zooms MIN to MAX; zooms 0 to MAX are written")
    budgets = t.add_mutually_exclusive_group()
    budgets.add_argument("--max-error", type=distance_arg, default=None, metavar="E0",
                         help="zoom 0's max vertical error in metres; zoom z gets E0 / 2^z (default 77067)")
    budgets.add_argument("--keep-los", type=share_arg, default=None, metavar="P",
                         help="instead, each zoom's max error is the largest whose tiles keep at least a share P "
                              "(e.g. 0.99) of the line-of-sight verdicts of 780 sight lines per tile, their ends "
                              "--los-height above the ground")
    t.add_argument("--los-height", type=distance_arg, default=2.0, metavar="H",
                   help="with --keep-los: the sight lines' ends above the ground in metres (default 2)")
    t.add_argument("--format", choices=FORMATS, default="quantized-mesh",
                   help="quantized-mesh (Cesium, EPSG:4326, TMS; the default) or terrain-rgb (Mapbox's PNG tiles, "
                        "Web Mercator, XYZ)")
    t.add_argument("--gzip", action=argparse.BooleanOptionalAction, default=None,
                   help="gzip-compress quantized-mesh tiles, as cesium-terrain-builder does (default; --no-gzip writes "
                        "them raw)")
    t.add_argument("--lattice", type=lattice_arg, default=None, metavar="N",
                   help="lattice cells per tile side (default 64: 65 x 65 points, as Cesium's heightmap tiles); "
                        "terrain-rgb: pixels per tile side (default 256)")
    again = t.add_mutually_exclusive_group()
    again.add_argument("--resume", action="store_true",
                       help="continue an interrupted run in OUT_DIR (same settings): its tiles are read and measured "
                            "again, kept when within their budget, and the rest are made")
    again.add_argument("--overwrite", action="store_true",
                       help="replace the tileset in a non-empty OUT_DIR (remove the files a tileset writes, only those)")
    add_nodata(t)


def run(args) -> int:
    from ..core.fileio import refuse_protected
    from ..tiles import write_tileset
    from ..tiles.tileset import pyproj_module

    lo, hi = args.zoom
    if lo > hi:
        raise UsageError(f"--zoom MIN MAX must run from the lower zoom to the higher, got {lo} {hi}")
    pyproj_module()  # said before the DEM is read
    refuse_protected(args.out_dir, "OUT_DIR", inputs=[args.dem])
    label, grid = read_terrain(args.dem, args)
    working("tiles", f"writing zooms 0 to {hi} of {label} ({args.method} from zoom {lo})")
    on_interrupt(f"; the finished tiles are in {args.out_dir!r}, without layer.json (--resume continues)")
    ts = write_tileset(grid, args.out_dir, method=args.method, zooms=(lo, hi), max_error0=args.max_error,
                       gzip=args.gzip, lattice=args.lattice, overwrite=args.overwrite, resume=args.resume, name=label,
                       names={**_NAMES, "grid": f"DEM {args.dem!r}"}, keep_los=args.keep_los,
                       los_height=args.los_height, format=args.format)
    on_interrupt()
    if ts.removed:
        print(f"terrainvis tiles: --overwrite: removed the earlier tileset's {plural(ts.removed, 'file')}",
              file=sys.stderr)
    w, s, e, n = ts.bounds
    print(f"{label}: {args.method} tiles, zooms 0 to {hi} (the method from zoom {lo})")
    print(f"  covers lon {w:.5f} to {e:.5f}, lat {s:.5f} to {n:.5f} (the largest lon/lat rectangle inside the DEM)")
    for r in ts.zooms:
        how = (f"max error {r.largest_error:.2f} m, budget {r.max_error:.2f} m" if r.simplified
               else f"whole lattice, max error {r.largest_error:.3f} m")
        more = (f"; {plural(r.fallbacks, 'tile')} written as the whole lattice (first {r.fallback_reasons[0]})"
                if r.fallbacks else "")
        if r.los is not None:
            more += (f"; keeps {100 * r.los.share:.2f} % of {r.los.pairs:,} sight lines' verdicts"
                     + ("" if r.los.reached else f" (whole lattices: no budget down to {r.los.tried[-1][0]:.3g} m kept "
                                                 f"{100 * args.keep_los:g} %)" if r.los.tried else " (flat: whole lattices)"))
        print(f"  zoom {r.zoom:2d}: {plural(r.n_tiles, 'tile')}, {plural(r.n_vertices, 'vertex', 'vertices')}, "
              f"{how}{more}")
    print(f"  wrote {plural(sum(r.n_tiles for r in ts.zooms), 'tile')} and layer.json in {ts.out_dir}")
    return 0
