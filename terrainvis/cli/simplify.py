"""``terrainvis simplify``: one method at one level, written as a grid or a mesh by the output's suffix."""

from __future__ import annotations

from pathlib import Path

from ._common import UsageError, add_nodata, distance_arg, loading_kernels, method_arg, plural, read_terrain, working


#: The command's line in ``terrainvis --help`` (also its light sub-parser: :func:`terrainvis.cli._parser`).
HELP = "simplify a DEM and write the result"


def add_parser(sub) -> None:
    from simplifiers import METHODS

    s = sub.add_parser(
        "simplify", help=HELP,
        description=(
            "Simplify a DEM with one method, to a level or to a target error, and write it. OUT by extension: "
            ".npz for grids and TINs; .tif .asc for grids, and for TINs sampled back at the DEM's samples (same "
            "CRS and transform); .ply .obj .stl .glb for any result as a mesh."
        ),
    )
    s.add_argument("dem", help="DEM file or bundled name")
    s.add_argument("-m", "--method", required=True, type=method_arg, metavar="METHOD",
                   help=f"one of {', '.join(METHODS)}")
    s.add_argument("-l", "--level", type=int, default=None,
                   help="level: each one halves both axes (default 1; with --max-error, the finest allowed)")
    s.add_argument("--max-error", type=distance_arg, default=None, metavar="E",
                   help="the smallest result whose max vertical error is <= E (z units)")
    s.add_argument("-o", "--output", required=True, metavar="OUT", help="output file")
    s.add_argument("--dtype", choices=["float32", "float64"], default="float32",
                   help="how a GeoTIFF stores the heights: float32 as GIS tools write elevation (the rounding is "
                        "printed), or float64 (default: float32)")
    s.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="an option of the method, e.g. weights=derived for lls (repeatable)")
    add_nodata(s)


_GRID_SUFFIXES = (".tif", ".tiff", ".asc", ".npz", ".npy")


_MESH_SUFFIXES = (".ply", ".obj", ".stl", ".glb")


def run(args) -> int:
    from simplifiers import METHODS, simplify

    from ..core.fileio import check_output_file
    from ..io import save_terrain

    out = Path(args.output)
    suffix = out.suffix.lower()
    regular = METHODS[args.method].regular
    valid = _GRID_SUFFIXES + _MESH_SUFFIXES
    if suffix not in valid:
        raise UsageError(f"-o must end in one of {list(valid)}, got {out.name!r}")
    if suffix == ".npy":  # said before minutes of simplifying, not after
        raise UsageError(f"-o {out.name!r}: a .npy file keeps only the heights, and a simplification needs its "
                         "coordinates (a coarser grid or a TIN): write .npz, .tif, .asc or a mesh")
    check_output_file(out, "-o", inputs=[args.dem])
    with loading_kernels(_load_kernels, "simplify"):
        label, grid = read_terrain(args.dem, args)
    level = 1 if args.level is None and args.max_error is None else args.level
    at = f"level {level}" if level is not None else f"max error {args.max_error:g}"
    working("simplify", f"simplifying {grid.shape[0]}x{grid.shape[1]} samples with {args.method} to {at}")
    result = simplify(grid, args.method, level, max_error=args.max_error, **parse_options(args.option))
    # a TIN to a raster is sampled at the DEM's own samples (nodata outside the TIN)
    raster = suffix in (".tif", ".tiff")
    save_terrain(result, out, like=None if regular or suffix == ".npz" else grid,
                 dtype=args.dtype if raster else None)
    a = result.attrs
    kind = f"{result.shape[0]} x {result.shape[1]} grid" if regular else f"TIN with {plural(result.n_faces, 'face')}"
    at = f"level {a['level']}" if a.get("level") is not None else f"max error <= {args.max_error:g}"
    print(f"{label}: {args.method} {at}: {plural(a['n_vertices'], 'vertex', 'vertices')} ({kind}), "
          f"{100 * a['n_vertices'] / grid.size:.2f} % of {grid.size:,}")
    print(f"  max error {a['max_error']:.4g}, RMS error {a['rms_error']:.4g} (z units), {a['seconds']:.3f} s")
    for note in a.get("notes", []):
        print(f"  note: {note}")
    if regular and suffix in (".tif", ".tiff", ".asc") and not result.is_uniform:
        # the file holds the grid resampled onto uniform coordinates: its errors are not the ones above.
        # It is read back as evaluate reads a raster: in the DEM's CRS, moved to the DEM's own frame
        # (a lon/lat file's local metres start at its own corner, not at the DEM's)
        from ..core.deviation import vertical_errors
        from ..experiment.evaluate import as_simplified

        worst, rms = vertical_errors(grid, as_simplified(out, grid, frame="native", label=out.name))
        print(f"  as written (resampled onto a uniform grid): max error {worst:.4g}, RMS error {rms:.4g}")
    if raster and args.dtype == "float32":
        import numpy as np

        z = result.z if regular else result.vertices[:, 2]
        loss = float(np.nanmax(np.abs(z.astype(np.float32).astype(np.float64) - z))) if z.size else 0.0
        if loss > 0.0:
            print(f"  heights stored as float32, rounded by up to {loss:.3g} (z units; --dtype float64 keeps them)")
        else:  # "rounded by up to 0" said nothing
            print("  heights stored as float32, exactly (every height is a float32 number)")
    print(f"  wrote {out}")
    return 0


def _load_kernels() -> None:
    """Import numba and load the kernel every simplification measures itself with (its
    vertical errors; a 3 x 3 grid against itself), beside the DEM's reading: numba's import
    and its first cached kernel are most of a second, a method's own kernels a few
    milliseconds each after it."""
    import numpy as np

    from ..core.deviation import vertical_errors
    from ..core.terrain import HeightGrid

    grid = HeightGrid(np.zeros((3, 3)))
    vertical_errors(grid, grid)


def parse_options(items) -> dict:
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise UsageError(f"--option must be KEY=VALUE, got {item!r}")
        out[key.strip()] = option_value(value.strip())
    return out


def option_value(text: str):
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)
