"""``terrainvis info``: a terrain's shape, spacing, CRS, extent, heights, nodata and level sizes."""

from __future__ import annotations

import argparse

from ._common import add_nodata, add_positions, plural, position_frame, read_surface


#: The command's line in ``terrainvis --help`` (also its light sub-parser: :func:`terrainvis.cli._parser`).
HELP = "describe a terrain (bundled name, DEM file or mesh)"


def add_parser(sub) -> None:
    i = sub.add_parser("info", help=HELP)
    i.add_argument("terrain", help="bundled name, DEM file, or a mesh or TIN file (.ply .obj .off .stl .glb .npz)")
    add_nodata(i)
    add_positions(i, frame=False)


def run(args) -> int:
    import numpy as np

    from simplifiers import METHODS, max_level, vertex_budget

    from ..core.terrain import TIN

    label, grid = read_surface(args.terrain, args, command="info")
    if isinstance(grid, TIN):
        return _info_tin(label, grid)
    rows, cols = grid.shape
    local = position_frame(grid, argparse.Namespace(frame="local"))
    xmin, xmax, ymin, ymax = (local.value(v) for v in grid.extent)
    z = grid.z
    kind = "uniform" if grid.is_uniform else "rectilinear"
    nodata = f", {plural(grid.n_nodata, 'nodata cell')}" if grid.n_nodata else ""
    print(f"{label}: {rows}x{cols} {kind} grid, x [{xmin}, {xmax}], y [{ymin}, {ymax}], "
          f"z [{np.nanmin(z):.6g}, {np.nanmax(z):.6g}]{nodata}")
    print(f"  samples   {rows} x {cols} = {grid.size:,}  ({grid.nbytes / 1e6:.2f} MB as a grid)")
    print(f"  spacing   dx {grid.dx:g}, dy {grid.dy:g}" + ("" if grid.is_uniform else " (mean; rectilinear)"))
    print(f"  extent    x [{xmin}, {xmax}], y [{ymin}, {ymax}]")
    crs = grid.attrs.get("crs") or "not recorded"
    print(f"  CRS       {crs}" + (" (x, y converted to local metres)" if grid.attrs.get("geographic") else ""))
    _info_positions(grid)
    print(f"  heights   {np.nanmin(z):.6g} to {np.nanmax(z):.6g}")
    print(f"  nodata    {plural(grid.n_nodata, 'cell')} ({100 * grid.n_nodata / grid.size:.2f} %)"
          + (" (use --fill or --crop-valid)" if grid.n_nodata else ""))
    top = max_level(grid.shape)
    print("  levels    vertices per level (regular methods keep a grid; irregular ones get the same budget)")
    for level in range(1, top + 1):
        n = vertex_budget(grid.shape, level)
        print(f"    {level}: {n:>12,} {'vertex' if n == 1 else 'vertices'} ({100 * n / grid.size:.3g} %)")
    print(f"  methods   {', '.join(METHODS)}")
    return 0


def _info_tin(label: str, tin) -> int:
    """``info`` of a mesh (a TIN): its size, extent, heights and what terrainvis recorded about it."""
    import argparse

    import numpy as np

    local = position_frame(tin, argparse.Namespace(frame="local"))
    xmin, xmax, ymin, ymax = (local.value(v) for v in tin.extent)
    z = tin.vertices[:, 2]
    print(f"{label}: TIN of {plural(tin.n_vertices, 'vertex', 'vertices')} and {plural(tin.n_faces, 'face')}, "
          f"x [{xmin}, {xmax}], y [{ymin}, {ymax}], z [{np.min(z):.6g}, {np.max(z):.6g}]")
    print(f"  size      {tin.nbytes / 1e6:.2f} MB as a TIN")
    print(f"  extent    x [{xmin}, {xmax}], y [{ymin}, {ymax}]")
    crs = tin.attrs.get("crs") or "not recorded"
    print(f"  CRS       {crs}" + (" (x, y converted to local metres)" if tin.attrs.get("geographic") else ""))
    _info_positions(tin)
    print(f"  heights   {np.min(z):.6g} to {np.max(z):.6g}")
    made = [f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
            for k in ("method", "level", "n_vertices", "max_error", "rms_error")
            if (v := tin.attrs.get(k)) is not None]
    if made:
        print(f"  made by   {', '.join(made)}")
    return 0


def _info_positions(grid) -> None:
    """``info``'s lines on positions: the frame the commands take, and the local frame's distances."""
    import numpy as np

    from ..core._georef import local_frame_error

    native = position_frame(grid, None)
    if native.identity:
        print(f"  positions {native.describe()}, in the commands (--from, --to, --observer, CSVs; --frame local is "
              "the same here)")
    else:
        print(f"  positions {native.describe()}, the commands' default: {native.footprint(units=False)}; "
              "--frame local takes the x, y above (local metres)")
    if grid.attrs.get("metric_resampling"):
        print(f"  metric    {grid.attrs['metric_resampling']}")
    ys = grid.ys if hasattr(grid, "ys") else np.array(grid.extent[2:])  # a TIN: its southern and northern edge
    errors = local_frame_error(grid.attrs, ys)
    if errors is not None:
        south, north = errors
        print(f"  distances local metres with one east-west scale for every row: east-west lengths "
              f"{100 * south:+.2f} % off at the southern edge, {100 * north:+.2f} % at the northern edge "
              "(--metric resamples onto a metric grid)")
