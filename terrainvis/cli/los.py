"""``terrainvis los``: visible or blocked, and the lowest clearance, for one segment or a CSV of pairs."""

from __future__ import annotations

import argparse

from ._common import (
    UsageError,
    add_earth,
    add_nodata,
    add_positions,
    add_target_height,
    check_heights,
    distance_arg,
    earth_text,
    height_arg,
    loading_kernels,
    number_arg,
    outside_message,
    position_frame,
    read_columns,
    read_surface,
)


#: The command's line in ``terrainvis --help`` (also its light sub-parser: :func:`terrainvis.cli._parser`).
HELP = "check lines of sight on a DEM"


def add_parser(sub) -> None:
    los = sub.add_parser(
        "los", help=HELP,
        description=(
            "Print whether the points see each other, and the lowest clearance of the segment (segment height "
            "minus surface height) with where it occurs. Positions are in the DEM's CRS (lon, lat in degrees on a "
            "lon/lat DEM), or in the terrain's own frame with --frame local (see terrainvis info)."
        ),
    )
    los.add_argument("dem", help="DEM file or bundled name")
    los.add_argument("--from", dest="start", nargs=2, type=number_arg, metavar=("X", "Y"),
                     help="observer position (lon lat on a lon/lat DEM)")
    los.add_argument("--to", dest="end", nargs=2, type=number_arg, metavar=("X", "Y"),
                     help="target position (lon lat on a lon/lat DEM)")
    los.add_argument("--pairs", metavar="CSV", help="many pairs: a CSV with columns x1, y1, x2, y2 (lon, lat on a "
                                                   "lon/lat DEM)")
    los.add_argument("--height", type=height_arg, default=1.7, help="observer height above the surface, >= 0 (default 1.7)")
    add_target_height(los)
    los.add_argument("--end-radius", type=distance_arg, default=0.0,
                     help="ignore the surface within this distance of each end (default 0)")
    los.add_argument("--fresnel", type=frequency_arg, default=None, metavar="FREQUENCY",
                     help="a radio link at FREQUENCY in Hz (2.4e9 for 2.4 GHz): also report the worst clearance of "
                          "the first Fresnel zone along the path, as a fraction of its radius, where it occurs, and "
                          "whether at least 60 %% of the zone is clear (x, y, z in metres)")
    los.add_argument("--png", metavar="PNG", help="with --fresnel and one pair: draw the path's profile (terrain, sight "
                                                  "line, first Fresnel zone) into this .png")
    add_earth(los)
    add_nodata(los)
    add_positions(los)


def _load_kernels() -> None:
    """Import line of sight and load its cached kernels: the commands' calls on a 3 x 3 grid (beside the DEM's reading)."""
    import numpy as np

    from ..core.terrain import HeightGrid
    from ..visibility import line_of_sight, min_clearance
    from ..visibility.profile import lowest_point

    grid = HeightGrid(np.zeros((3, 3)))
    a, b = np.array([[0.0, 0.0, 1.0]]), np.array([[2.0, 2.0, 1.0]])
    grid.height_at(a[:, :2])
    line_of_sight(grid, a, b)
    min_clearance(grid, a, b)
    lowest_point(grid, a[0], b[0])


def run(args) -> int:
    import numpy as np

    png = _check_png(args)
    with loading_kernels(_load_kernels, "los"):
        label, grid = read_surface(args.dem, args, command="los")
    from ..visibility import Sight, line_of_sight, min_clearance
    from ..visibility.profile import lowest_point

    check_heights(grid, args)
    if args.pairs:
        if args.start or args.end:
            raise UsageError("give either --pairs or --from and --to, not both")
        user1, user2 = _read_pairs(args.pairs)
    else:
        if not (args.start and args.end):
            raise UsageError("give --from X Y and --to X Y (or --pairs CSV)")
        user1 = np.array([args.start], float)
        user2 = np.array([args.end], float)
    frame = position_frame(grid, args)
    xy1, xy2 = frame.to_grid(user1), frame.to_grid(user2)
    z1 = grid.height_at(xy1) + args.height
    z2 = grid.height_at(xy2) + args.target_height
    outside = np.isnan(z1) | np.isnan(z2)
    if outside.any():
        k = int(np.flatnonzero(outside)[0])
        bad = user1[k] if np.isnan(z1[k]) else user2[k]
        raise UsageError(
            f"point pair {k} from {frame.point(user1[k])} to {frame.point(user2[k])}: {frame.point(bad)} "
            f"{outside_message(frame, bad)}"
        )
    a = np.column_stack([xy1, z1])
    b = np.column_stack([xy2, z2])
    # the predicate as one value (the ends' heights are in a and b already)
    sight = Sight.make(end_radius=args.end_radius, curvature=args.curvature, earth_radius=args.earth_radius)
    visible = line_of_sight(grid, a, b, sight=sight)
    clear = min_clearance(grid, a, b, sight=sight)
    print(f"{label}: observer {args.height:g} above the surface, target {args.target_height:g} above it; "
          f"{earth_text(args)}")
    for k in range(a.shape[0]):
        low = lowest_point(grid, a[k], b[k], sight=sight)
        verdict = "visible" if visible[k] else "blocked"
        where = ("" if not np.isfinite(clear[k]) else
                 f" at {frame.point(frame.from_grid([low['x'], low['y']]))}, {low['distance']:.6g} from the observer")
        print(f"  {frame.point(user1[k])} -> {frame.point(user2[k])}: {verdict}; lowest clearance "
              f"{clear[k]:.4g}{where}")
        if args.fresnel is not None:
            print("    " + _fresnel_text(grid, a[k], b[k], frame, args, png))
    if png is not None:
        print(f"  wrote {png}")
    return 0


def _check_png(args):
    """``--png``: with --fresnel and one pair, a .png that may be written."""
    if args.png is None:
        return None
    from pathlib import Path

    from ..core.fileio import check_output_file

    png = Path(args.png)
    if args.fresnel is None or args.pairs:
        raise UsageError("--png draws the profile of one radio path: give it with --fresnel, --from and --to")
    if png.suffix.lower() != ".png":
        raise UsageError(f"--png must end in .png, got {png.name!r}")
    check_output_file(png, "--png", inputs=[args.dem])
    return png


def _fresnel_text(grid, a, b, frame, args, png=None) -> str:
    """The first Fresnel zone's worst clearance along a -> b, in one line (its profile drawn into ``png``)."""
    from ..visibility.fresnel import fresnel_clearance

    r = fresnel_clearance(grid, a, b, args.fresnel, curvature=args.curvature, earth_radius=args.earth_radius,
                          profile=png is not None)
    if png is not None:
        from ..experiment import plot
        from ..io import save_figure

        save_figure(plot.fresnel_profile(r, a, b), png)
    verdict = "at least 60 % of the zone clear" if r.clear_60 else "less than 60 % of the zone clear"
    return (f"first Fresnel zone at {frequency_text(r.frequency)} (wavelength {r.wavelength:.4g}): worst clearance "
            f"{r.fraction:.4g} of its radius ({r.clearance:.4g} of {r.radius:.4g}) at "
            f"{frame.point(frame.from_grid([r.x, r.y]))}, {r.distance:.6g} from the observer; {verdict}")


def frequency_arg(text: str) -> float:
    """A radio frequency in Hz: finite and > 0."""
    value = number_arg(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a frequency > 0 in Hz (2.4e9 for 2.4 GHz), got {text!r}")
    return value


def frequency_text(hz: float) -> str:
    """A frequency with its unit: 2.4 GHz, 868 MHz, 50 Hz."""
    for unit, scale in (("GHz", 1e9), ("MHz", 1e6), ("kHz", 1e3)):
        if hz >= scale:
            return f"{hz / scale:g} {unit}"
    return f"{hz:g} Hz"


def _read_pairs(path: str):
    """The x1, y1 and x2, y2 columns of a --pairs CSV; a bad cell is named by row and column."""
    values = read_columns(path, "--pairs", ("x1", "y1", "x2", "y2"))
    return values[:, :2], values[:, 2:]
