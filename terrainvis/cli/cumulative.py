"""``terrainvis cumulative``: how many of a CSV's observers see each sample (a cumulative viewshed)."""

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
HELP = "how many observers see each sample of a DEM"


def add_parser(sub) -> None:
    c = sub.add_parser(
        "cumulative", help=HELP,
        description=(
            "Compute the cumulative viewshed of many observers on a DEM: for every sample, how many observers see it "
            "(each observer's exact viewshed, summed; count > 0 is the area seen by any). Observers come from a CSV "
            "with columns x, y (lon, lat on a lon/lat DEM; see --frame) and optionally height (each eye's height "
            "above the surface, instead of --observer-height). Writes the counts as a GeoTIFF aligned with the DEM "
            "(CRS and transform kept; unsigned integers, nodata the type's largest value) or an .npz, and with --png "
            "a picture of them over the hillshade."
        ),
    )
    c.add_argument("dem", help="DEM file or bundled name")
    c.add_argument("--observers", required=True, metavar="CSV",
                   help="the observers: a CSV with columns x, y (lon, lat on a lon/lat DEM) and optionally height")
    c.add_argument("-o", "--output", required=True, metavar="OUT", help="output file: .tif (counts aligned with the "
                                                                         "DEM) or .npz")
    c.add_argument("--png", metavar="PNG", help="also draw the counts over the hillshade into this .png")
    c.add_argument("--observer-height", "--height", dest="height", type=height_arg, default=1.7,
                   help="eye height above the surface, >= 0, for observers without a height column (default 1.7)")
    add_target_height(c)
    add_max_distance(c, "each observer sees only the samples within this distance")
    add_field_of_view(c)
    c.add_argument("--workers", type=workers_arg, default=None,
                   help="local worker processes (default 1: in this process, one viewshed per core at a time)")
    c.add_argument("--scheduler", default=None, metavar="ADDRESS", help="run on this dask.distributed scheduler "
                                                                        "(needs the dask extra)")
    c.add_argument("--network", metavar="FILE",
                   help="also write the intervisibility network among the observers (every pair, whether eye sees "
                        "eye and the sight line's exact clearance): .csv, or .gpkg (GeoPackage lines in the DEM's CRS)")
    c.add_argument("--observers-out", metavar="NPZ",
                   help="also write which observers see each sample (the observer sets, packed bits) to this .npz "
                        "(terrainvis.ObserverSets.load reads it)")
    add_earth(c)
    add_nodata(c)
    add_positions(c)


def run(args) -> int:
    import numpy as np

    from ..core.fileio import check_output_file
    from ..visibility import cumulative_viewshed, observer_sets

    out = Path(args.output)
    suffix = out.suffix.lower()
    if suffix not in (".tif", ".tiff", ".npz"):
        raise UsageError(f"-o must end in .tif or .npz, got {out.name!r}")
    png = Path(args.png) if args.png else None
    if png is not None and png.suffix.lower() != ".png":
        raise UsageError(f"--png must end in .png, got {png.name!r}")
    inputs = [args.dem, args.observers]
    check_output_file(out, "-o", inputs=inputs)
    outputs = {"-o": out}
    if png is not None:
        check_output_file(png, "--png", inputs=inputs, outputs=outputs)
        outputs["--png"] = png
    sight = sight_args(args)
    fov = sight.fov
    extra = _check_extra_outputs(args, inputs, outputs)
    label, grid = read_terrain(args.dem, args)
    _check_grid(grid, args, out, extra)
    table = read_columns(args.observers, "--observers", ("x", "y"), optional=("height",))  # refuses a header alone
    frame = position_frame(grid, args)
    user = table[:, :2]
    xy = frame.to_grid(user)
    outside = np.isnan(grid.height_at(xy))
    if outside.any():
        k = int(np.flatnonzero(outside)[0])
        raise UsageError(f"--observers {args.observers!r}: row {k + 1} {frame.point(user[k])} {outside_message(frame, user[k])}; "
                         f"{plural(int(outside.sum()), 'observer')} of {len(xy):,} do")
    heights = np.where(np.isnan(table[:, 2]), args.height, table[:, 2])
    if (heights < 0).any():
        k = int(np.flatnonzero(heights < 0)[0])
        raise UsageError(f"--observers {args.observers!r}: row {k + 1}, column height is {heights[k]:g}; "
                         "heights above the surface must be >= 0")
    if "network" in extra:
        _check_network_memory(extra["network"], len(xy))  # before the viewsheds, not after them
    client = dask_client(args.scheduler) if args.scheduler else None
    try:
        t0 = time.perf_counter()
        many = observer_sets if "sets" in extra else cumulative_viewshed
        result = many(grid, xy, observer_height=heights, sight=sight, workers=args.workers, client=client,
                      progress=True)
        counts = result.count() if "sets" in extra else result
        seconds = time.perf_counter() - t0
    finally:
        if client is not None:
            client.close()
    _write_counts(grid, counts, out, suffix, args, len(xy))
    if png is not None:
        _write_counts_png(grid, counts, xy, png, label)
    written = [out] + ([png] if png is not None else [])
    network = _write_extra(grid, xy, heights, args, result, extra, written)
    valid = np.isfinite(grid.z)
    n_valid = max(int(valid.sum()), 1)
    seen = counts[valid]
    if client is not None:
        where = "on the dask cluster"
    else:
        where = "in this process" if (args.workers or 1) == 1 else "on " + plural(args.workers, "worker")
    print(f"{label}: {plural(len(xy), 'observer')}, eyes {heights_text(heights)} above the surface, target "
          f"{args.target_height:g}" + (f", {fov.describe()}" if fov.limited else ""))
    print(f"  {earth_text(args)}")
    print(f"  seen by any {int((seen > 0).sum()):,} of {plural(n_valid, 'sample')} ({100 * (seen > 0).mean():.2f} %), "
          f"by all {100 * (seen == len(xy)).mean():.2f} %, most observers on one sample {int(seen.max()):,}; "
          f"{seconds:.1f} s {where} ({len(xy) / seconds:.1f} observers/s)")
    if network is not None:
        n_seen = int(network["visible"].sum())
        print(f"  network: {n_seen:,} of {plural(len(network), 'pair')} of observers see each other"
              + (f", median clearance of those {network['clearance'][network['visible']].median():.4g}"
                 if n_seen else ""))
    print("  wrote " + ", ".join(str(p) for p in written[:-1]) + (" and " if len(written) > 1 else "")
          + str(written[-1]))
    return 0


def _write_extra(grid, xy, heights, args, result, extra: dict, written: list):
    """``--observers-out`` (``result`` holds the sets then) and ``--network``; the network, or None."""
    if "sets" in extra:
        result.save(extra["sets"])
        written.append(extra["sets"])
    if "network" not in extra:
        return None
    network = _write_network(grid, xy, heights, args, position_frame(grid, args), extra["network"])
    written.append(extra["network"])
    return network


#: Peak bytes per pair of observers of ``--network``, by format: the table, its copy in the
#: observers' frame, the lines, and the file's own (CSV text; GeoPackage blobs and the
#: read-back's geometries). Measured with /usr/bin/time on 1,000 observers (499,500 pairs)
#: over 10 (29 November 2026): GeoPackage 1,280, CSV 390; rounded up.
NETWORK_BYTES_PER_PAIR = {".gpkg": 1400, ".csv": 450}


def _check_network_memory(path: Path, k: int) -> None:
    from ..core.memory import check_memory

    n_pairs = k * (k - 1) // 2
    check_memory(n_pairs * NETWORK_BYTES_PER_PAIR[path.suffix.lower()],
                 f"--network {path.name!r}: the intervisibility network of {k:,} observers ({n_pairs:,} pairs)")


def _check_grid(grid, args, out: Path, extra: dict) -> None:
    """What the DEM must be for the outputs asked, before any viewshed runs."""
    check_heights(grid, args)
    if "network" in extra:
        grid.require_finite("--network (the pair engine's exact clearance)")
    if out.suffix.lower() in (".tif", ".tiff"):
        if not grid.is_uniform:
            raise UsageError("a GeoTIFF needs a uniform grid, and this DEM is rectilinear: write the counts as .npz")
        from ..io import check_geotiff_target

        check_geotiff_target(grid, out)  # a CRS it cannot write fails now, not after the viewsheds


def _check_extra_outputs(args, inputs, outputs: dict) -> dict:
    """``--network`` and ``--observers-out``: their suffixes, and writable and apart from the
    inputs and the other ``outputs`` ({flag: path}), before anything runs."""
    from ..core.fileio import check_output_file

    extra, outputs = {}, dict(outputs)
    if args.network:
        path = Path(args.network)
        if path.suffix.lower() not in (".csv", ".gpkg"):
            raise UsageError(f"--network must end in .csv or .gpkg, got {path.name!r}")
        check_output_file(path, "--network", inputs=inputs, outputs=outputs)
        extra["network"] = outputs["--network"] = path
    if args.observers_out:
        path = Path(args.observers_out)
        if path.suffix.lower() != ".npz":
            raise UsageError(f"--observers-out must end in .npz, got {path.name!r}")
        check_output_file(path, "--observers-out", inputs=inputs, outputs=outputs)
        extra["sets"] = path
    return extra


def _write_network(grid, xy, heights, args, frame, path: Path):
    """The intervisibility network as CSV (with WKT lines) or GeoPackage, positions in the observers' frame."""
    import numpy as np

    from ..visibility import intervisibility_network

    net = intervisibility_network(grid, xy, observer_height=heights, curvature=args.curvature,
                                  earth_radius=args.earth_radius)
    out = net.copy()
    for end in ("i", "j"):
        native = frame.from_grid(net[[f"x_{end}", f"y_{end}"]].to_numpy())
        out[f"x_{end}"], out[f"y_{end}"] = native[:, 0], native[:, 1]
    lines = np.stack([out[["x_i", "y_i"]].to_numpy(), out[["x_j", "y_j"]].to_numpy()], axis=1)
    if path.suffix.lower() == ".gpkg":
        from ..core._georef import position_crs
        from ..io import write_geopackage_lines

        # the frame's CRS: the native one, or in --frame local the grid's own when it is the native one
        local_metres = bool(grid.attrs.get("geographic") or grid.attrs.get("source_crs"))
        crs = position_crs(grid.attrs) if frame.frame == "native" or not local_metres else None
        write_geopackage_lines(path, lines, out, table="intervisibility", crs=crs,
                               description="terrainvis cumulative --network: every pair of observers")
    else:
        from ..io import write_csv

        out["wkt"] = [f"LINESTRING ({float(a[0])!r} {float(a[1])!r}, {float(b[0])!r} {float(b[1])!r})" for a, b in lines]
        write_csv(out, path)
    return net


def _write_counts(grid, counts, out: Path, suffix: str, args, k: int) -> None:
    """The counts as a GeoTIFF aligned with the DEM (unsigned integers, nodata the type's maximum) or an .npz."""
    import numpy as np

    nodata = ~np.isfinite(grid.z)
    if suffix == ".npz":
        from ..io import save_terrain
        from ..core.terrain import HeightGrid

        z = np.where(nodata, np.nan, counts.astype(np.float64))
        attrs = {**grid.attrs, "cumulative_observers": int(k), "cumulative_target_height": float(args.target_height),
                 "cumulative_curvature": float(args.curvature), "cumulative_earth_radius": float(args.earth_radius)}
        save_terrain(HeightGrid.from_coords(z, grid.xs, grid.ys, attrs=attrs), out)
        return
    from ..io import write_geotiff

    dtype = np.uint16 if k < np.iinfo(np.uint16).max else np.uint32  # the largest value stays free for nodata
    fill = np.iinfo(dtype).max
    data = counts.astype(dtype)
    data[nodata] = fill
    write_geotiff(grid, data, out, nodata=fill,
                  tags={"TERRAINVIS_CUMULATIVE": f"observers={k} target_height={args.target_height:g} "
                                                 f"curvature={args.curvature:g} earth_radius={args.earth_radius:g}"})


def _write_counts_png(grid, counts, xy, png: Path, label: str) -> None:
    from ..experiment import plot
    from ..io import save_figure

    save_figure(plot.cumulative_viewshed(grid, counts, observers=xy, title=f"{label}: cumulative viewshed"), png)


def heights_text(heights) -> str:
    lo, hi = float(heights.min()), float(heights.max())
    return f"{lo:g}" if lo == hi else f"{lo:g} to {hi:g}"


def workers_arg(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of processes >= 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number of processes >= 1, got {text!r}")
    return value
