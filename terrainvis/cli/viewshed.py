"""``terrainvis viewshed``: an observer's exact viewshed, as a GeoTIFF, an ``.npz`` or a ``.png``."""

from __future__ import annotations

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
    earth_text,
    height_arg,
    loading_kernels,
    number_arg,
    outside_message,
    plural,
    position_frame,
    read_terrain,
    sight_args,
)


#: The command's line in ``terrainvis --help`` (also its light sub-parser: :func:`terrainvis.cli._parser`).
HELP = "which samples of a DEM an observer sees"


def add_parser(sub) -> None:
    v = sub.add_parser(
        "viewshed", help=HELP,
        description=(
            "Compute the exact viewshed of one observer on a DEM (every sample as a target, on the piecewise-linear "
            "surface) and write it as a GeoTIFF aligned with the DEM (CRS and transform kept; 1 visible, 0 not, "
            "255 nodata), an .npz, or a .png drawn over the hillshade. With --output-mode min_height or angle, "
            "each sample gets a value instead (a float32 GeoTIFF with NaN as nodata, a float .npz, or a .png): "
            "the least height above the ground at which a target there is visible (0: the ground is visible; "
            "gdal_viewshed's -om GROUND), or the target's elevation angle above (+) or below (-) the horizon "
            "of its ray, in degrees."
        ),
    )
    v.add_argument("dem", help="DEM file or bundled name")
    v.add_argument("--observer", nargs=2, type=number_arg, required=True, metavar=("X", "Y"),
                   help="observer position (lon lat on a lon/lat DEM; see --frame)")
    v.add_argument("--height", type=height_arg, default=1.7, help="eye height above the surface, >= 0 (default 1.7)")
    add_target_height(v)
    add_max_distance(v, "only samples within this distance")
    add_field_of_view(v)
    v.add_argument("-o", "--output", required=True, metavar="OUT", help="output file: .tif, .npz or .png")
    v.add_argument("--output-mode", choices=["visible", "min_height", "angle"], default="visible",
                   help="what each sample gets: visible (1/0, the default), min_height (least visible height "
                        "above the ground, 0 where the ground is visible) or angle (degrees above the horizon); "
                        "NaN outside the field of view and on nodata")
    add_earth(v)
    add_nodata(v)
    add_positions(v)


def run(args) -> int:
    import numpy as np

    from ..core.fileio import check_output_file

    out = Path(args.output)
    suffix = out.suffix.lower()
    if suffix not in (".tif", ".tiff", ".npz", ".png"):
        raise UsageError(f"-o must end in .tif, .npz or .png, got {out.name!r}")
    check_output_file(out, "-o", inputs=[args.dem])
    sight = sight_args(args)
    fov = sight.fov
    with loading_kernels(lambda: _load_kernels(args.dem), "viewshed"):
        label, grid = read_terrain(args.dem, args)
    from ..visibility import viewshed

    check_heights(grid, args)
    if suffix in (".tif", ".tiff"):
        from ..io import check_geotiff_target

        check_geotiff_target(grid, out)  # a grid it cannot write fails now, not after the viewshed
    frame = position_frame(grid, args)
    observer = tuple(float(v) for v in frame.to_grid(args.observer))
    if np.isnan(grid.height_at([observer])[0]):
        raise UsageError(f"--observer {frame.point(args.observer)} {outside_message(frame, args.observer)}")
    t0 = time.perf_counter()
    vis = viewshed(grid, observer, sight=sight, output=args.output_mode)
    seconds = time.perf_counter() - t0
    if args.output_mode != "visible":
        return _report_values(grid, vis, out, suffix, args, (label, observer, frame, fov, seconds))
    valid = np.isfinite(grid.heights) if grid.n_nodata else None  # a full-size mask only where there is nodata
    n_vis = int(np.count_nonzero(vis if valid is None else vis & valid))
    n_valid = grid.size - grid.n_nodata
    field = _field(grid, observer, sight)
    _write_viewshed(grid, vis, out, suffix, args, label, observer, field)
    print(f"{label}: observer {frame.point(args.observer)}, eye {args.height:g} above the surface")
    print(f"  {earth_text(args)}")
    inside = ""
    if field is not None:
        n_in = int(np.count_nonzero(field if valid is None else field & valid))
        print(f"  field of view: {fov.describe()}")
        inside = f"; {plural(n_in, 'sample')} in the field of view, {100 * n_vis / max(n_in, 1):.2f} % of them visible"
    print(f"  visible {n_vis:,} of {plural(n_valid, 'sample')} "
          f"({100 * n_vis / max(n_valid, 1):.2f} %{inside}), {seconds:.2f} s")
    print(f"  wrote {out}")
    return 0


def _load_kernels(dem) -> None:
    """Import the viewshed and load its cached kernels: a viewshed on a 3 x 3 grid (run beside the
    DEM's reading) whose heights have the dtype the DEM's will have (a float32 GeoTIFF's grid keeps
    float32 heights, whose kernels are others: loading the float64 ones compiled both on a first run)."""
    import numpy as np

    from ..core.terrain import HeightGrid
    from ..io._names import heights_dtype
    from ..visibility import viewshed

    z = np.zeros((3, 3), dtype=heights_dtype(dem))
    viewshed(HeightGrid._from_coords(z, [0.0, 1.0, 2.0], [0.0, 1.0, 2.0], None, owned=True), (1.0, 1.0))


def _report_values(grid, values, out: Path, suffix: str, args, about) -> int:
    """``--output-mode min_height`` or ``angle``: write the values and say what they hold."""
    import numpy as np

    label, observer, frame, fov, seconds = about
    _write_values(grid, values, out, suffix, args, label, observer)
    print(f"{label}: observer {frame.point(args.observer)}, eye {args.height:g} above the surface")
    print(f"  {earth_text(args)}")
    if fov.limited:
        print(f"  field of view: {fov.describe()}")
    v = values[np.isfinite(values)]
    if args.output_mode == "min_height":
        n0 = int((v == 0).sum())
        print(f"  least visible height above the ground, {plural(v.size, 'sample')} with a value: ground visible at "
              f"{n0:,} ({100 * n0 / max(v.size, 1):.2f} %), median {np.median(v) if v.size else 0:.2f}, "
              f"largest {v.max() if v.size else 0:.2f}; {seconds:.2f} s")
    else:
        n0 = int((v >= 0).sum())
        print(f"  angle above the horizon (degrees, target {args.target_height:g} above the surface), "
              f"{plural(v.size, 'sample')} with a value: >= 0 (visible) at {n0:,} ({100 * n0 / max(v.size, 1):.2f} %), "
              f"range {v.min() if v.size else 0:.3f} to {v.max() if v.size else 0:.3f}; {seconds:.2f} s")
    print(f"  wrote {out}")
    return 0


def _write_values(grid, values, out: Path, suffix: str, args, label: str, observer) -> None:
    """The values of ``--output-mode`` by OUT's suffix: float32 GeoTIFF (NaN nodata), float .npz, or .png."""
    import numpy as np

    if suffix == ".png":
        from ..experiment import plot
        from ..io import save_figure

        save_figure(plot.viewshed_values(grid, values, args.output_mode, observer=observer,
                                         title=f"{label}: viewshed, {args.output_mode}"), out)
        return
    if suffix == ".npz":
        from ..io import save_terrain

        from ..core.terrain import HeightGrid

        attrs = {**grid.attrs, "viewshed_output_mode": args.output_mode,
                 "viewshed_observer": [float(v) for v in observer],
                 "viewshed_observer_native": [float(v) for v in position_frame(grid, None).from_grid(observer)],
                 "viewshed_observer_height": float(args.height), "viewshed_target_height": float(args.target_height),
                 "viewshed_curvature": float(args.curvature), "viewshed_earth_radius": float(args.earth_radius),
                 **_field_of_view_attrs(args)}
        save_terrain(HeightGrid.from_coords(values, grid.xs, grid.ys, attrs=attrs), out)
        return
    from ..io import write_geotiff

    unit = "z units above the ground" if args.output_mode == "min_height" else "degrees above the horizon"
    write_geotiff(grid, values.astype(np.float32), out, nodata=float("nan"),
                  tags={"TERRAINVIS_OUTPUT_MODE": args.output_mode, "TERRAINVIS_UNITS": unit})


def _field(grid, observer, sight):
    """The samples inside the sight's field of view (None without limits)."""
    from ..visibility import field_of_view_mask

    if not sight.fov.limited:
        return None
    return field_of_view_mask(grid, observer, sight.fov, observer_height=sight.observer_height,
                              target_height=sight.target_height, curvature=sight.curvature,
                              earth_radius=sight.earth_radius)


def _write_viewshed(grid, vis, out: Path, suffix: str, args, label: str, observer, field) -> None:
    """The viewshed by OUT's suffix; ``observer`` in the grid's own frame; a .png shows the field of view."""
    import numpy as np

    if suffix == ".png":
        from ..experiment import plot
        from ..io import save_figure

        save_figure(plot.viewshed(grid, vis, observer=observer, title=f"{label}: viewshed", field=field), out)
        return
    if suffix == ".npz":
        from ..io import save_terrain

        from ..core.terrain import HeightGrid

        # a grid of the same samples: 1 visible, 0 not, NaN nodata (with the DEM's georeferencing)
        z = np.where(np.isfinite(grid.heights), vis.astype(np.float64), np.nan)
        # the observer in the grid's frame (that of its xs, ys) and in the DEM's native CRS
        attrs = {**grid.attrs, "viewshed_observer": [float(v) for v in observer],
                 "viewshed_observer_native": [float(v) for v in position_frame(grid, None).from_grid(observer)],
                 "viewshed_observer_height": float(args.height), "viewshed_target_height": float(args.target_height),
                 "viewshed_curvature": float(args.curvature), "viewshed_earth_radius": float(args.earth_radius),
                 **_field_of_view_attrs(args)}
        save_terrain(HeightGrid.from_coords(z, grid.xs, grid.ys, attrs=attrs), out)
        return
    from ..io import write_mask_geotiff

    write_mask_geotiff(grid, vis, out, nodata_mask=np.isnan(grid.heights) if grid.n_nodata else None)


def _field_of_view_attrs(args) -> dict:
    """The field-of-view flags that were given, for the .npz's attrs."""
    given = {"azimuth": args.azimuth, "vertical": args.vertical, "min_distance": args.min_distance,
             "max_distance": args.max_distance}
    return {f"viewshed_{k}": (list(map(float, v)) if isinstance(v, list) else float(v))
            for k, v in given.items() if v is not None}
