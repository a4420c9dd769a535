"""What the tilers' halving rule keeps of line of sight, against budgets chosen by ``--keep-los``.

For each DEM, a tileset is written with the common rule (zoom z's max vertical error
77067 / 2^z m) and with ``keep_los=P`` for each P asked for; for every simplified zoom the
script prints the budget, the tiles' vertices and the share of the zoom's sight lines (780
pairs per tile, ends 2 m above the ground: :mod:`terrainvis.tiles.keep_los`) whose verdict
the written tiles keep. The halving rule's shares are measured here on its written tiles by
the same functions ``--keep-los`` uses.

    python studies/tiles_keep_los.py                                   # cumberland, zooms 9-12, P 0.95 0.99
    python studies/tiles_keep_los.py --dem ../shared/data/dem/green_mountains_vt.tif --zooms 10 13
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import terrainvis as tv
from terrainvis.tiles import decode_tile, tile_bounds, tile_lattice, write_tileset
from terrainvis.tiles.keep_los import kept_pairs, tile_sights
from terrainvis.tiles.tileset import _Frame, _rectangle


def _shares(dem, out: Path, zooms) -> dict:
    """Each zoom's (kept, pairs) on the tiles written in ``out``."""
    import gzip

    frame = _Frame(dem, "dem")
    rect = _rectangle(dem, frame, "dem")
    got = {}
    for z in range(zooms[0], zooms[1] + 1):
        kept = pairs = 0
        for f in sorted((out / str(z)).glob("*/*.terrain")):
            x, y = int(f.parent.name), int(f.stem)
            lat_ = tile_lattice(dem, z, x, y, rect, frame=frame)
            s = tile_sights(lat_, z, x, y)
            kept += kept_pairs(lat_, s, decode_tile(gzip.decompress(f.read_bytes()), tile_bounds(z, x, y)))
            pairs += s.verdicts.size
        got[z] = (kept, pairs)
    return got


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dem", default="cumberland", help="a bundled name or a DEM file with a CRS")
    ap.add_argument("--zooms", type=int, nargs=2, default=[9, 12])
    ap.add_argument("--method", default="greedy-insertion")
    ap.add_argument("--keep", type=float, nargs="+", default=[0.95, 0.99])
    args = ap.parse_args()
    dem = tv.bundled_terrain(args.dem) if "/" not in args.dem and "." not in args.dem else tv.load_dem(args.dem)
    zooms = tuple(args.zooms)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        halving = write_tileset(dem, Path(tmp) / "halving", method=args.method, zooms=zooms)
        t_halving = time.perf_counter() - t0
        shares = _shares(dem, Path(tmp) / "halving", zooms)
        runs, times = {}, {}
        for p in args.keep:
            t0 = time.perf_counter()
            runs[p] = write_tileset(dem, Path(tmp) / f"keep{p}", method=args.method, zooms=zooms, keep_los=p)
            times[p] = time.perf_counter() - t0
    print(f"{args.dem}: {args.method}, zooms {zooms[0]}-{zooms[1]}; sight lines 780 per tile, ends 2 m above the ground")
    head = f"{'zoom':>4} {'tiles':>5} | {'halving: budget':>15} {'vertices':>8} {'kept':>7}"
    for p in args.keep:
        head += f" | {f'keep {p:g}: budget':>16} {'vertices':>8} {'kept':>7}"
    print(head)
    for r in halving.zooms:
        if not r.simplified:
            continue
        k, n = shares[r.zoom]
        line = f"{r.zoom:>4} {r.n_tiles:>5} | {r.max_error:>13.2f} m {r.n_vertices:>8,} {100 * k / n:>6.2f}%"
        for p in args.keep:
            q = next(z for z in runs[p].zooms if z.zoom == r.zoom)
            line += f" | {q.max_error:>14.2f} m {q.n_vertices:>8,} {100 * q.los_kept:>6.2f}%"
        print(line)
    print(f"time: halving {t_halving:.1f} s; " + ", ".join(f"keep {p:g} {times[p]:.1f} s" for p in args.keep))


if __name__ == "__main__":
    main()
