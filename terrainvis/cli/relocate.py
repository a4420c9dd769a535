"""``terrainvis relocate``: points of a DEM placed on its simplification (calibrated by default)."""

from __future__ import annotations

import time
from pathlib import Path

from ._common import (
    MESH_SUFFIXES,
    UsageError,
    add_earth,
    add_nodata,
    add_positions,
    check_heights,
    earth_text,
    height_arg,
    method_arg,
    outside_message,
    plural,
    position_frame,
    read_columns,
    read_surface,
    read_terrain,
    working,
)


#: The command's line in ``terrainvis --help`` (also its light sub-parser: :func:`terrainvis.cli._parser`).
HELP = "place points of a DEM on its simplification"


def add_parser(sub) -> None:
    from simplifiers import METHODS

    from ..core.option import add_flag
    from ..relocation.registry import CALIBRATED, RELOCATIONS, run_options

    offered = offered_relocations()
    r = sub.add_parser(
        "relocate", help=HELP,
        description=(
            "Give each point of a CSV (columns x, y, and optionally z: its height on the DEM; else the surface plus "
            "--offset) a height on a simplification of the DEM: a file (--simplified) or the DEM simplified here "
            "(-m METHOD -l LEVEL). The calibrated relocation (the default) picks the height whose lines of sight "
            "agree best with the point's on the DEM (docs/relocation.md). Writes a CSV with x, y, z (the new "
            "height), z_original and the surface of the simplification under each point."
        ),
    )
    r.add_argument("dem", help="the original DEM (file or bundled name)")
    r.add_argument("--points", required=True, metavar="CSV",
                   help="the points: a CSV with columns x, y (lon, lat on a lon/lat DEM; see --frame) and optionally z")
    r.add_argument("-o", "--output", required=True, metavar="OUT.csv", help="output CSV")
    r.add_argument("--simplified", metavar="FILE",
                   help="the simplification: a grid (.npz, .tif, .asc) or a mesh (.ply, .obj, .off, .stl, .glb) as "
                        "simplify writes them")
    r.add_argument("-m", "--method", type=method_arg, metavar="METHOD",
                   help=f"simplify the DEM here instead, with one of {', '.join(METHODS)}")
    r.add_argument("-l", "--level", type=int, default=None, help="with -m: the level (default 1)")
    r.add_argument("--how", choices=list(offered), default=CALIBRATED, metavar="HOW",
                   help="the relocation: " + "; ".join(f"{name}: {RELOCATIONS[name].summary}" for name in offered)
                        + f" (default {CALIBRATED})")
    r.add_argument("--offset", type=height_arg, default=0.0,
                   help="the points' height above the DEM's surface, >= 0 (default 0: on the surface)")
    r.add_argument("--target-height", type=height_arg, default=None,
                   help=f"{_takers('target_height', offered)}: the points will look at targets this high above the "
                        "surface (a viewshed's cells); without it they will look at each other")
    for option in run_options(offered):  # the relocations' own options, as terrainvis compare spells them
        add_flag(r, option)
    r.add_argument("--seed", type=int, default=0,
                   help=f"{_takers('seed', offered)}: seed of the relocation's random draws (default 0)")
    add_earth(r)  # the lines of sight of the relocations that evaluate visibility
    add_nodata(r)
    add_positions(r)


def offered_relocations() -> tuple:
    """The relocations ``--how`` offers: the practical ones that need at most T (a bound needs T's verdicts)."""
    from ..relocation.registry import RELOCATIONS, practical_relocations

    return tuple(name for name in practical_relocations() if set(RELOCATIONS[name].needs) <= {"original"})


def _takers(keyword: str, offered) -> str:
    """The relocations of ``offered`` that take ``keyword`` ("calibrated, eye"), for a flag's help."""
    from ..relocation.registry import RELOCATIONS

    return ", ".join(name for name in offered if keyword in RELOCATIONS[name].options) or "no relocation"


def own_options(args) -> dict:
    """The run options of the relocation ``--how`` names that the command line gives, checked
    (messages name the flags). A flag of another relocation's option, or ``--target-height``
    for a relocation that takes no target height, is refused: it would change nothing."""
    from ..relocation.registry import RELOCATIONS, run_options

    entry = RELOCATIONS[args.how]
    offered = offered_relocations()
    own = {o.name for o in entry.declared_options()}
    given = [o for o in run_options(offered) if hasattr(args, o.name) and o.name not in own]
    if args.target_height is not None and "target_height" not in entry.options:
        raise UsageError(f"--target-height is for {_takers('target_height', offered)}: "
                         f"--how {args.how} takes no target height")
    if given:
        o = given[0]
        takes = ", ".join(name for name in offered if o in RELOCATIONS[name].declared_options())
        flags = [d.flag for d in entry.declared_options() if d.flag]
        raise UsageError(f"{o.flag} is an option of {takes}: --how {args.how} takes "
                         + (", ".join(flags) if flags else "none of the relocations' own options"))
    return {o.name: o.check(getattr(args, o.name), o.flag or o.name)
            for o in entry.declared_options() if hasattr(args, o.name)}


def run(args) -> int:
    import numpy as np
    import pandas as pd

    from ..core.fileio import check_output_file
    from ..io import write_csv
    from ..relocation.registry import RELOCATIONS, relocate

    out = Path(args.output)
    if out.suffix.lower() != ".csv":
        raise UsageError(f"-o must end in .csv, got {out.name!r}")
    if (args.simplified is None) == (args.method is None):
        raise UsageError("give the simplification as --simplified FILE or as -m METHOD [-l LEVEL], one of them")
    if args.level is not None and args.method is None:
        raise UsageError("-l goes with -m (the level to simplify the DEM to)")
    if args.metric and args.simplified is not None:
        raise UsageError("--metric resamples the DEM, and a --simplified file is in the DEM's frame as read: "
                         "simplify here with -m METHOD [-l LEVEL] instead")
    own = own_options(args)
    check_output_file(out, "-o", inputs=[args.dem, args.points] + ([args.simplified] if args.simplified else []))
    label, grid = read_terrain(args.dem, args)
    check_heights(grid, args)
    simplified, what = read_simplification(grid, args)
    table = read_columns(args.points, "--points", ("x", "y"), optional=("z",))
    frame = position_frame(grid, args)
    user = table[:, :2]
    xy = frame.to_grid(user)
    ground = grid.height_at(xy)
    outside = np.isnan(ground) | np.isnan(simplified.height_at(xy))
    if outside.any():
        k = int(np.flatnonzero(outside)[0])
        raise UsageError(f"--points {args.points!r}: row {k + 1} {frame.point(user[k])} "
                         f"{outside_message(frame, user[k], ' or its simplification')}; {int(outside.sum())} point(s) do")
    z = np.where(np.isnan(table[:, 2]), ground + args.offset, table[:, 2])
    points = np.column_stack([xy, z])
    entry = RELOCATIONS[args.how]
    shown = {o.name: own.get(o.name, o.default) for o in entry.declared_options()}
    working("relocate", f"placing {plural(len(points), 'point')} on {what} ({args.how}"
            + "".join(f", {k} {v}" for k, v in shown.items()) + ")")
    t0 = time.perf_counter()
    # T to every relocation (one that takes no original ignores it, terrainvis.relocate), and its own options
    moved = relocate(points, simplified, args.how, offset=args.offset, original=grid, target_height=args.target_height,
                     seed=args.seed, curvature=args.curvature, earth_radius=args.earth_radius, **own)
    seconds = time.perf_counter() - t0
    surface = simplified.height_at(xy)
    written = pd.DataFrame({**csv_positions(frame, user), "z": moved[:, 2], "z_original": z,
                            "ground_simplified": surface})
    write_csv(written, out, float_format="%.6f")
    lift = moved[:, 2] - (surface + args.offset)
    print(f"{label}: {plural(len(points), 'point')} relocated ({args.how}) onto {what}, {seconds:.2f} s")
    if entry.predicate and len(points):  # a relocation that evaluates visibility: how far, under which earth
        from ..tolerances import MOVED_ABS

        off = np.abs(lift) > MOVED_ABS
        print(f"  {int(off.sum())} off the full projection (S(T) + offset); height change from it "
              f"{lift.min():+.4g} to {lift.max():+.4g}, median {np.median(lift):+.4g} (z units)")
        print(f"  {earth_text(args)}")
    print(f"  wrote {out}")
    return 0


def read_simplification(grid, args):
    """The simplified terrain of ``relocate``: read from --simplified, or made with -m/-l; and how to name it."""
    if args.method is not None:
        from simplifiers import simplify

        level = 1 if args.level is None else args.level
        return simplify(grid, args.method, level), f"{args.method} level {level}"
    from ..io import load_terrain

    path = Path(args.simplified)
    if not path.exists():
        raise UsageError(f"--simplified {args.simplified!r} does not exist")
    if path.suffix.lower() == ".npz" or path.suffix.lower() in MESH_SUFFIXES:
        terrain = load_terrain(path) if path.suffix.lower() != ".off" else read_surface(str(path), command="relocate")[1]
    else:
        from ..io import load_dem

        terrain = load_dem(path)
    return terrain, path.name


def csv_positions(frame, user) -> dict:
    """The x, y columns of a CSV the command writes, in the frame of its input (degrees to 1e-9, 0.1 mm)."""
    if frame.degrees:
        return {"x": [f"{v:.9f}" for v in user[:, 0]], "y": [f"{v:.9f}" for v in user[:, 1]]}
    return {"x": user[:, 0], "y": user[:, 1]}
