"""The ``terrainvis`` command line.

``terrainvis compare`` runs the paper's experiment (by default on the five bundled 120x120
terrains and the real Jacksboro DEM), prints Tables 1-4 and the cost table, and writes
``results.csv``, ``tables.md``, figures and the simplified terrains (``simplified/``) into
``--out``. ``terrainvis info`` describes a terrain.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

__all__ = ["main"]

QUICK = {"terrains": ["hills", "ridges"], "levels": [1, 3], "points": 20, "sets": 2}


def _parser() -> argparse.ArgumentParser:
    from simplifiers import METHODS

    from .experiment import DEFAULT_TERRAINS
    from .relocation import RELOCATIONS

    p = argparse.ArgumentParser(prog="terrainvis", description="How much line of sight does terrain simplification cost?")
    sub = p.add_subparsers(dest="command", required=True)
    c = sub.add_parser(
        "compare",
        help="run the paper's experiment and print its tables",
        description=(
            "Simplify each terrain with each method and level, relocate random point sets onto the "
            "simplification, and count the line-of-sight verdicts that survive. Defaults reproduce the "
            "paper's protocol: the five bundled 120x120 terrains plus the central 120x120 window of the "
            "Jacksboro DEM, 6 sets of 50 points, levels 1-3, all seven methods, all three relocations."
        ),
    )
    c.add_argument("--terrain", nargs="+", default=None, metavar="T",
                   help=f"bundled names ({', '.join(DEFAULT_TERRAINS)}) or DEM files (.npz .npy .asc .tif)")
    c.add_argument("--levels", nargs="+", type=int, default=None, help="simplification levels (default: 1 2 3)")
    c.add_argument("--methods", nargs="+", default=None, metavar="M", help=f"methods (default: all of {', '.join(METHODS)})")
    c.add_argument("--relocations", nargs="+", default=None, metavar="R", help=f"relocations (default: {' '.join(RELOCATIONS)})")
    c.add_argument("--points", type=int, default=None, help="points per set (default 50)")
    c.add_argument("--sets", type=int, default=None, help="point sets per terrain (default 6)")
    c.add_argument("--seed", type=int, default=0, help="seed of the point sets (default 0)")
    c.add_argument("--offset", type=float, default=0.0, help="observer height above the surface (default 0)")
    c.add_argument("--max-distance", type=float, default=None, help="count only pairs within this horizontal distance")
    c.add_argument("--workers", type=int, default=None, help="local worker processes (default: number of CPUs)")
    c.add_argument("--scheduler", default=None, metavar="ADDRESS", help="run on this dask.distributed scheduler (needs the dask extra)")
    c.add_argument("--no-volume", action="store_true", help="skip the manifold3d volume shape error (skipped anyway above 10^6 samples)")
    c.add_argument("--no-plots", action="store_true", help="do not write the figures")
    c.add_argument("--quick", action="store_true",
                   help="a run of seconds for smoke tests: terrains hills and ridges, levels 1 and 3, 2 sets of 20 points")
    c.add_argument("--resume", action="store_true", help="keep the units already in OUT/results.csv and run only the rest")
    c.add_argument("--out", default="terrainvis-results", help="output folder (default: ./terrainvis-results)")
    i = sub.add_parser("info", help="describe a terrain (bundled name or DEM file)")
    i.add_argument("terrain", help="bundled name or DEM file")
    return p


def _compare(args) -> int:
    import pandas as pd

    from . import report
    from .experiment import DEFAULT_TERRAINS, compare, resolve_terrains

    terrains = args.terrain or (QUICK["terrains"] if args.quick else list(DEFAULT_TERRAINS))
    levels = args.levels or (QUICK["levels"] if args.quick else [1, 2, 3])
    points = args.points or (QUICK["points"] if args.quick else 50)
    sets = args.sets or (QUICK["sets"] if args.quick else 6)
    relocations = args.relocations or ["identity", "full", "half"]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    client = None
    if args.scheduler:
        try:
            from dask.distributed import Client
        except ImportError:
            print('terrainvis: --scheduler needs the dask extra: pip install "terrainvis[dask]"', file=sys.stderr)
            return 2
        client = Client(args.scheduler)
    grids = resolve_terrains(terrains)
    t0 = time.perf_counter()
    df = compare(
        grids, methods=args.methods, levels=levels, relocations=relocations, n_points=points, n_sets=sets,
        seed=args.seed, max_distance=args.max_distance, workers=args.workers, client=client, offset=args.offset,
        volume=False if args.no_volume else "auto", out_csv=out / "results.csv", resume=args.resume,
        save_dir=out / "simplified", progress=True,
    )
    seconds = time.perf_counter() - t0
    df.to_csv(out / "results.csv", index=False)  # the same rows, now in sorted order
    tables = report.paper_tables(df)
    text = report.to_markdown(tables)
    found = report.findings(df)
    verdict = {True: "held", False: "did not hold", None: "cannot tell"}
    lines = ["### The paper's findings on these terrains", ""]
    lines += [f"- **{f['claim']}**: {verdict[f['held']]}. {f['evidence']}." for f in found]
    failed = df[df["error"] != ""].drop_duplicates(["terrain", "method", "level"])
    if len(failed):
        lines += ["", "### Failed units", ""]
        lines += [f"- {r.terrain} / {r.method} / level {r.level}: {r.error}" for r in failed.itertuples()]
    summary = (
        f"{df[['terrain', 'method', 'level']].drop_duplicates().shape[0]} units, {len(df)} rows, "
        f"{len(grids)} terrains, {seconds:.1f} s"
    )
    (out / "tables.md").write_text(f"# terrainvis compare\n\n{summary}\n\n{text}\n" + "\n".join(lines) + "\n")
    print(text)
    print("\n".join(lines))
    if not args.no_plots:
        _write_plots(df, grids, levels, args.methods, out)
    print(f"\n{summary}; wrote {out / 'results.csv'}, {out / 'tables.md'}" + ("" if args.no_plots else " and figures"))
    return 0 if pd.isna(df["accuracy"]).sum() < len(df) else 1


def _write_plots(df, grids, levels, methods, out: Path) -> None:
    from simplifiers import simplify
    from simplifiers import METHODS

    from . import plot
    from .experiment import load_simplified, simplified_path

    fig = plot.accuracy_vs_size(df)
    fig.savefig(out / "accuracy_vs_size.png", dpi=110)
    for rel in sorted(set(df["relocation"])):
        try:
            plot.tradeoff(df, relocation=rel).savefig(out / f"tradeoff_{rel}.png", dpi=110)
        except ValueError:
            pass
    level = min(levels) if levels else 1
    for name, grid in grids.items():
        views = {}
        for m in methods or METHODS:
            path = simplified_path(out / "simplified", name, m, level)
            if path.exists():  # saved by the run
                views[m] = load_simplified(path)
                continue
            try:
                views[m] = simplify(grid, m, level)
            except Exception as exc:  # a failed method is reported in the tables already
                print(f"terrainvis: no view of {m} on {name}: {exc}", file=sys.stderr)
        fig = plot.terrain_views(grid, views)
        fig.suptitle(f"{name}: level {level}")
        fig.savefig(out / f"views_{name}.png", dpi=90)


def _info(args) -> int:
    from .experiment import resolve_terrains

    (name, grid), = resolve_terrains([args.terrain]).items()
    rows, cols = grid.shape
    xmin, xmax, ymin, ymax = grid.extent
    print(f"{name}: {grid!r}")
    print(f"  samples   {rows} x {cols} = {grid.size:,}  ({grid.nbytes / 1e6:.2f} MB as a grid)")
    print(f"  spacing   dx {grid.dx:g}, dy {grid.dy:g}" + ("" if grid.is_uniform else " (mean; rectilinear)"))
    print(f"  extent    x [{xmin:.6g}, {xmax:.6g}], y [{ymin:.6g}, {ymax:.6g}]")
    print(f"  nodata    {grid.n_nodata} cells")
    print(f"  TIN       {grid.size:,} vertices, {2 * (rows - 1) * (cols - 1):,} faces")
    from simplifiers import max_level

    print(f"  levels    0 to {max_level(grid.shape)}")
    return 0


def main(argv=None) -> int:
    """Entry point of the ``terrainvis`` console script."""
    args = _parser().parse_args(argv)
    try:
        if args.command == "compare":
            return _compare(args)
        return _info(args)
    except (ValueError, TypeError, FileNotFoundError) as exc:
        print(f"terrainvis {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("terrainvis: interrupted; finished units are in results.csv (use --resume)", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
