"""``terrainvis site``: choose k observers among candidates that together see the most of a DEM."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from ._common import (
    UsageError,
    add_earth,
    add_field_of_view,
    add_max_distance,
    add_nodata,
    add_positions,
    add_target_height,
    check_heights,
    dask_client,
    earth_text,
    height_arg,
    outside_message,
    plural,
    position_frame,
    read_columns,
    read_terrain,
    sight_args,
)


#: The command's line in ``terrainvis --help`` (also its light sub-parser: :func:`terrainvis.cli._parser`).
HELP = "choose k observers that together see the most of a DEM"


def whole_arg(text: str) -> int:
    """A whole number >= 1 (-k, --grid)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}")
    return value


def add_parser(sub) -> None:
    from .cumulative import workers_arg

    s = sub.add_parser(
        "site", help=HELP,
        description=(
            "Choose k observers among candidate positions so that together they see the largest area of a DEM "
            "(samples seen by at least one, each weighted by its cell's area), each candidate's viewshed exact. "
            "The choice is greedy, lazily evaluated: it covers at least 1 - 1/e (63.2 %) of the best k "
            "candidates' area (Nemhauser, Wolsey & Fisher 1978), and the run prints a tighter bound of its own. "
            "Candidates come from a CSV with columns x, y (lon, lat on a lon/lat DEM; see --frame) and optionally "
            "height, or from every STEP-th sample of the DEM (--grid). Prints the chosen observers in order with "
            "the area covered after each choice."
        ),
    )
    s.add_argument("dem", help="DEM file or bundled name")
    where = s.add_mutually_exclusive_group(required=True)
    where.add_argument("--candidates", metavar="CSV",
                       help="the candidates: a CSV with columns x, y (lon, lat on a lon/lat DEM) and optionally height")
    where.add_argument("--grid", type=whole_arg, metavar="STEP",
                       help="the candidates: every STEP-th sample along rows and columns (a lattice centred on the DEM)")
    s.add_argument("-k", type=whole_arg, required=True, metavar="K", help="how many observers to choose (>= 1)")
    s.add_argument("--height", "--observer-height", dest="height", type=height_arg, default=1.7,
                   help="eye height above the surface, >= 0, for candidates without a height column (default 1.7)")
    add_target_height(s)
    add_max_distance(s, "each observer sees only the samples within this distance")
    add_field_of_view(s)
    s.add_argument("-o", "--output", metavar="CSV", help="write the chosen observers and the coverage after each "
                                                         "choice to this .csv")
    s.add_argument("--coverage", metavar="OUT", help="write the samples seen by the chosen observers: .tif (1 seen, 0 "
                                                     "not, 255 nodata, aligned with the DEM) or .npz")
    s.add_argument("--plot", metavar="PNG", help="draw the covered-area curve and the chosen observers into this .png")
    s.add_argument("--workers", type=workers_arg, default=None,
                   help="local worker processes for the candidates' viewsheds (default 1: in this process, one "
                        "viewshed per core at a time)")
    s.add_argument("--scheduler", default=None, metavar="ADDRESS", help="run the viewsheds on this dask.distributed "
                                                                        "scheduler (needs the dask extra)")
    add_earth(s)
    add_nodata(s)
    add_positions(s)


def run(args) -> int:
    from ..visibility import site_observers

    outputs = _check_outputs(args)
    sight = sight_args(args)
    fov = sight.fov
    label, grid = read_terrain(args.dem, args)
    check_heights(grid, args)
    if outputs.get("coverage") is not None and outputs["coverage"].suffix.lower() != ".npz" and not grid.is_uniform:
        raise UsageError("--coverage: a GeoTIFF needs a uniform grid, and this DEM is rectilinear: write an .npz")
    if outputs.get("coverage") is not None and outputs["coverage"].suffix.lower() != ".npz":
        from ..io import check_geotiff_target

        check_geotiff_target(grid, outputs["coverage"])  # a CRS it cannot write fails now, not after the siting
    frame = position_frame(grid, args)
    xy, heights, source = _candidates(grid, frame, args)
    if args.k > len(xy):
        raise UsageError(f"-k must be at most the number of candidates, {len(xy):,} ({source}), got {args.k}")
    client = dask_client(args.scheduler) if args.scheduler else None
    try:
        t0 = time.perf_counter()
        result = site_observers(grid, xy, args.k, observer_height=heights, sight=sight, workers=args.workers,
                                client=client, progress=True)
        seconds = time.perf_counter() - t0
    finally:
        if client is not None:
            client.close()
    table = _native_table(result.table, frame)
    _report(label, frame, args, result, table, (heights, source, fov), seconds)
    _write(grid, result, table, outputs, frame, label, xy)
    return 0


def _check_outputs(args) -> dict:
    """The output paths, their suffixes checked, each checked writable before anything runs."""
    from ..core.fileio import check_output_file

    wanted = {"output": (args.output, (".csv",), "-o"), "coverage": (args.coverage, (".tif", ".tiff", ".npz"),
                                                                      "--coverage"),
              "plot": (args.plot, (".png",), "--plot")}
    inputs = [args.dem] + ([args.candidates] if args.candidates else [])
    out, flags = {}, {}
    for key, (path, suffixes, flag) in wanted.items():
        if path is None:
            continue
        p = Path(path)
        if p.suffix.lower() not in suffixes:
            raise UsageError(f"{flag} must end in {' or '.join(suffixes)}, got {p.name!r}")
        check_output_file(p, flag, inputs=inputs, outputs=flags)
        out[key] = flags[flag] = p
    return out


def _candidates(grid, frame, args):
    """The candidates in the grid's frame, their eye heights and a phrase saying where they came from."""
    import numpy as np

    from ..visibility import candidate_grid

    if args.grid is not None:
        xy = candidate_grid(grid, args.grid)
        if not len(xy):
            raise UsageError(f"--grid {args.grid} puts no candidate on the DEM: every lattice sample is nodata")
        return xy, np.full(len(xy), args.height), f"--grid {args.grid}"
    table = read_columns(args.candidates, "--candidates", ("x", "y"), optional=("height",))
    user = table[:, :2]
    xy = frame.to_grid(user)
    outside = np.isnan(grid.height_at(xy))
    if outside.any():
        k = int(np.flatnonzero(outside)[0])
        raise UsageError(f"--candidates {args.candidates!r}: row {k + 1} {frame.point(user[k])} "
                         f"{outside_message(frame, user[k])}; {plural(int(outside.sum()), 'candidate')} of "
                         f"{len(xy):,} do")
    heights = np.where(np.isnan(table[:, 2]), args.height, table[:, 2])
    if (heights < 0).any():
        k = int(np.flatnonzero(heights < 0)[0])
        raise UsageError(f"--candidates {args.candidates!r}: row {k + 1}, column height is {heights[k]:g}; "
                         "heights above the surface must be >= 0")
    return xy, heights, f"--candidates {Path(args.candidates).name}"


def _native_table(table, frame):
    """The result's table with x, y in the frame the positions were given in."""
    out = table.copy()
    native = frame.from_grid(out[["x", "y"]].to_numpy())
    out["x"], out["y"] = native[:, 0], native[:, 1]
    return out


def _report(label, frame, args, result, table, setup, seconds) -> None:
    from .cumulative import heights_text

    heights, source, fov = setup
    n = len(heights)
    print(f"{label}: choosing {args.k} of {plural(n, 'candidate')} ({source}), eyes {heights_text(heights)} "
          f"above the surface, target {args.target_height:g}"
          + (f", {fov.describe()}" if fov.limited else ""))
    print(f"  {earth_text(args)}")
    plain = args.k * n - args.k * (args.k - 1) // 2
    print(f"  viewsheds {result.seconds['viewsheds']:.1f} s, greedy {result.seconds['greedy']:.2f} s "
          f"({result.evaluations:,} gains evaluated; the plain greedy evaluates {plain:,}); {seconds:.1f} s in all")
    names = frame.names
    print(f"  {'order':>5}  {'candidate':>9}  {names[0] + ', ' + names[1]:<28}  {'gain (samples)':>14}  "
          f"{'covered (samples)':>17}  {'covered area':>14}  share")
    for row in table.itertuples(index=False):
        where = frame.point((row.x, row.y))
        print(f"  {row.order:>5}  {row.candidate:>9}  {where:<28}  {row.gain_cells:>14,}  {row.covered_cells:>17,}  "
              f"{_area(row.covered_area):>14}  {100 * row.covered_share:.2f} %")
    last = float(table["covered_area"].iloc[-1])
    reach = last / result.bound if result.bound > 0 else 1.0
    print(f"  the best {args.k} candidates cover at most {_area(result.bound)} (x/y units squared): this choice "
          f"reaches at least {100 * reach:.1f} % of the optimum (greedy's guarantee: "
          f"{100 * (1 - (1 - 1 / args.k) ** args.k):.1f} %)")


def _area(v: float) -> str:
    """An area for the table: whole units with thousands separators, small ones with 4 digits."""
    return f"{v:,.0f}" if abs(v) >= 100 else f"{v:.4g}"


def _write(grid, result, table, outputs: dict, frame, label: str, xy) -> None:
    import numpy as np

    written = []
    if "output" in outputs:
        from ..io import write_csv

        write_csv(table, outputs["output"])
        written.append(outputs["output"])
    if "coverage" in outputs:
        path = outputs["coverage"]
        nodata = ~np.isfinite(grid.z)
        if path.suffix.lower() == ".npz":
            from ..core.terrain import HeightGrid
            from ..io import save_terrain

            z = np.where(nodata, np.nan, result.covered.astype(np.float64))
            attrs = {**grid.attrs, "siting_chosen": result.chosen.tolist()}
            save_terrain(HeightGrid.from_coords(z, grid.xs, grid.ys, attrs=attrs), path)
        else:
            from ..io import write_mask_geotiff

            write_mask_geotiff(grid, result.covered, path, nodata_mask=nodata)
        written.append(path)
    if "plot" in outputs:
        from ..experiment import plot
        from ..io import save_figure

        save_figure(plot.siting(grid, result, candidates=xy, title=f"{label}: {len(result.chosen)} observers"),
                    outputs["plot"])
        written.append(outputs["plot"])
    if written:
        print("  wrote " + ", ".join(str(p) for p in written))
