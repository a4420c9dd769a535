"""``terrainvis evaluate``: simplifications made elsewhere (meshes, rasters, tilesets) measured as ``compare`` measures a method's."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from ._common import UsageError, add_nodata, method_arg, plural, read_terrain


#: The command's line in ``terrainvis --help`` (also its light sub-parser: :func:`terrainvis.cli._parser`).
HELP = "measure simplifications made elsewhere (meshes, rasters, tilesets) as compare measures a method's"

#: How messages name the tileset options.
_TILE_FLAGS = {"zoom": "--zoom", "tile_mesh": "--tile-mesh", "tile_max_error": "--tile-max-error",
               "tile_offset": "--tile-offset"}


def add_parser(sub) -> None:
    from simplifiers import METHODS

    from ..experiment.evaluate import COMPARE_ONLY, MESH_SUFFIXES, RASTER_SUFFIXES
    from ..experiment.options import add_flags

    e = sub.add_parser(
        "evaluate", help=HELP,
        description=(
            "Measure each SIMPLIFIED terrain of DEM on the comparison's measure: the same point sets (by the DEM's "
            "name and --seed), relocations, predicate and columns as terrainvis compare, optionally beside "
            "built-in methods at the same vertex count (--against). A SIMPLIFIED folder is a tileset (Cesium "
            "quantized-mesh with its layer.json, or terrain-RGB PNG tiles): each --zoom's tiles over the DEM are "
            "stitched into one TIN, clipped to the DEM, and measured, with a zoom column. Exits 1 when "
            "--min-accuracy is not met."
        ),
    )
    e.add_argument("dem", help="the original DEM (file or bundled name)")
    e.add_argument("simplified", nargs="+", metavar="SIMPLIFIED",
                   help=f"simplified terrains: meshes ({' '.join(MESH_SUFFIXES)}), rasters "
                        f"({' '.join(RASTER_SUFFIXES)}) or tileset folders")
    e.add_argument("--against", nargs="+", default=[], metavar="M", type=method_arg,
                   help=f"methods measured beside them at the same size: {', '.join(METHODS)}")
    e.add_argument("--frame", choices=["native", "local"], default=None,
                   help="the simplified terrains' coordinates: native (the DEM's CRS) or local (the terrain's own "
                        "frame); default: local for files terrainvis wrote, native for others")
    e.add_argument("--repair", action="store_true",
                   help="repair a mesh that is not a height field over the DEM (folds, corners, a border off the "
                        "rectangle) instead of refusing it")
    tiles = e.add_argument_group("tilesets (a SIMPLIFIED folder)")
    tiles.add_argument("--zoom", nargs="+", type=int, default=None, metavar="Z",
                       help="the zooms of each tileset to measure, each stitched into one TIN (required with a "
                            "tileset; an absent zoom is refused with the zooms it holds)")
    tiles.add_argument("--tile-mesh", choices=["grid", "martini", "delatin"], default="grid",
                       help="how terrain-RGB tiles are meshed: every pixel a vertex (grid, the default), or as deck.gl "
                            "meshes them, Martini or Delatin at --tile-max-error")
    tiles.add_argument("--tile-max-error", nargs="+", type=float, default=None, metavar="E",
                       help="Martini's or Delatin's maximum error (m): one for every zoom, or one per --zoom")
    tiles.add_argument("--tile-offset", type=float, default=0.0, metavar="M",
                       help="height (m) added to the tiles' heights, when they are not in the DEM's vertical datum "
                            "(minus the geoid undulation for ellipsoidal tiles over an orthometric DEM); default 0")
    e.add_argument("--min-accuracy", type=float, default=None, metavar="A",
                   help="exit 1 unless every simplified terrain keeps at least this share of verdicts (0.95 for 95 "
                        "%%) under every relocation of the run")
    e.add_argument("--out", default=None,
                   help="also write results.csv, tables.md and the figures into this folder (each measured terrain's "
                        "rows are kept in results.partial.csv until the run is complete)")
    again = e.add_mutually_exclusive_group()
    again.add_argument("--resume", action="store_true",
                       help="keep the terrains already measured in --out (an interrupted run: same settings, same "
                            "simplified terrains) and measure only the rest")
    again.add_argument("--overwrite", action="store_true",
                       help="replace an earlier run's files in --out (once the new run is complete)")
    e.add_argument("--no-plots", action="store_true", help="with --out: do not write the figures")
    add_flags(e, exclude=tuple(COMPARE_ONLY))  # what is simplified, and how, is given
    add_nodata(e)


def run(args) -> int:
    import numpy as np

    if args.min_accuracy is not None and not (np.isfinite(args.min_accuracy) and 0.0 <= args.min_accuracy <= 1.0):
        raise UsageError(f"--min-accuracy must be a share in [0, 1] (0.95 for 95 %), got {args.min_accuracy:g}")
    label, grid = read_terrain(args.dem, args)
    for s in args.simplified:
        if not Path(s).exists():
            raise UsageError(f"SIMPLIFIED {s!r} does not exist")
    from ..experiment.evaluate import COMPARE_ONLY
    from ..experiment.options import given
    from ..experiment.plan import settings_for

    # the options checked here, where a message names the flags (evaluate() checks them again)
    settings_for({label: grid}, {**{k: v for k, v in given(args).items() if k not in COMPARE_ONLY},
                                 "methods": args.against or ["simple"]}, flags=True)
    if not args.out:
        if args.resume:
            raise UsageError("--resume continues the run stored in --out; give --out")
        return _evaluate(args, label, grid, None, [])
    from .compare import locked_out

    with locked_out(args.out, "terrainvis evaluate") as out:
        return _evaluate(args, label, grid, out, _check_out(args, label, out))


def _evaluate(args, label: str, grid, out: Path | None, earlier: list) -> int:
    """Measure, print, and with ``out`` write the new run, then remove what is left of the
    ``earlier`` one: until the new files are in place, the earlier run stays whole.

    With ``out`` each measured terrain's rows go to ``results.partial.csv`` as they are
    measured (``--resume`` continues it); the complete table is then renamed over
    ``results.csv``. ``--resume`` of a finished run continues its ``results.csv`` in place.
    """
    from ..experiment._outdir import PARTIAL, RESULTS
    from ..experiment.evaluate import COMPARE_ONLY, prepared
    from ..experiment.options import given
    from ._common import on_interrupt

    options = {k: v for k, v in given(args).items() if k not in COMPARE_ONLY}
    t0 = time.perf_counter()
    run = prepared({label: grid}, list(args.simplified), against=args.against, frame=args.frame, repair=args.repair,
                   **_tile_options(args), names=_TILE_FLAGS, **options)
    rows = None
    if out is not None:
        rows = out / PARTIAL
        if args.resume and not rows.exists() and (out / RESULTS).exists():
            rows = out / RESULTS
        on_interrupt(f"; the terrains measured so far are in {rows} (--resume continues)")
    df = run.measure(rows, resume=args.resume, on_unit=_measured_line())
    seconds = time.perf_counter() - t0
    _print(df, label, seconds)
    if out is not None:
        written = _write(df, run, rows, out, args, seconds)
        stale = [p for p in earlier if p.resolve() not in {w.resolve() for w in written} and p.exists()]
        if stale:
            from ..experiment._outdir import describe, remove

            remove(out, stale)
            print(f"terrainvis evaluate: --overwrite: removed the earlier run's {describe(stale)} that this run did "
                  "not write again", file=sys.stderr)
    return _verdict(df, args)


def _tile_options(args) -> dict:
    return {"zoom": args.zoom, "tile_mesh": args.tile_mesh, "tile_max_error": args.tile_max_error,
            "tile_offset": args.tile_offset}


def _measured_line():
    """On a terminal, a line as each terrain (or ``--against`` method at one size) is measured,
    as :func:`~terrainvis.cli._common.working` says what a long step does; a log gets the
    results only. None elsewhere."""
    from ..core._progress import on_a_terminal

    if not on_a_terminal():
        return None
    last = [time.perf_counter()]

    def line(key, rows):
        now = time.perf_counter()
        what = "failed" if rows["error"].notna().any() else f"{int(rows['n_vertices'].iloc[0]):,} vertices"
        print(f"terrainvis evaluate: measured {key[1]} ({what}, {now - last[0]:.1f} s)", file=sys.stderr,
              flush=True)
        last[0] = now

    return line


def _check_out(args, label: str, out: Path) -> list[Path]:
    """``--out`` checked before anything is measured; the earlier run's files, which the new run replaces.

    Refused: files at the names this run writes that terrainvis did not write, or that no
    earlier run in ``out`` recorded (a simplified terrain of the user's own at the name of
    one this run saves: not even ``--overwrite`` replaces it); an earlier run without
    ``--overwrite`` or ``--resume``; an input (the DEM, a SIMPLIFIED) among the files the
    run replaces. Nothing is removed here; with ``--resume`` nothing is (the run goes on).
    """
    from ..experiment._outdir import _candidates, describe, earlier_run, foreign_files
    from ..experiment.evaluate import _named, is_tileset
    from .compare import _foreign_message

    names = []
    for m, s in _named(list(args.simplified), None, taken=args.against):
        names += [f"{m}-z{z}" for z in (args.zoom or [])] if is_tileset(s) else [m]
    names += list(args.against)
    foreign = foreign_files(out, [label], names, [])
    if foreign:
        raise UsageError(_foreign_message(out, foreign))
    files = earlier_run(out)
    if files and not (args.overwrite or args.resume):
        raise UsageError(f"--out {str(out)!r} holds the results of an earlier run ({describe(files)}); add "
                         "--resume to continue it (same settings), --overwrite to replace it, or choose another --out")
    ours = {p.resolve() for p in files}
    for p in _candidates(out, [label], names, []):
        if p.resolve() not in ours:
            raise UsageError(f"--out {str(out)!r} holds {p.relative_to(out).as_posix()}, which this run would "
                             "write and which no earlier run there recorded; terrainvis never replaces it: move "
                             "it away or choose another --out")
    inputs = [Path(args.dem)] + [Path(s) for s in args.simplified]
    for inp in inputs:
        if inp.is_file() and inp.resolve() in ours:
            raise UsageError(f"{'--resume' if args.resume else '--overwrite'} would replace {str(inp)!r}, an input "
                             "of this run, with the new run's files; move it out of --out first, or choose another "
                             "--out")
    return [] if args.resume else files


def _print(df, label: str, seconds: float) -> None:
    import pandas as pd

    ok = df[df["error"].isna()]
    if len(ok):
        g = ok.groupby(["method", "relocation"], sort=False)
        t = pd.DataFrame({**({"zoom": g["zoom"].first().astype("Int64")} if ok["zoom"].notna().any() else {}),
                          "vertices": g["n_vertices"].first(), "level": g["level"].first(),
                          "accuracy": 100 * g["accuracy"].mean(), "visible_kept": 100 * g["visible_kept"].mean(),
                          "blocked_kept": 100 * g["blocked_kept"].mean(), "max_error": g["max_error"].first()})
        print(f"{label}: accuracy (%) of each simplified terrain, mean over {ok['set'].nunique()} point set(s)")
        print(t.to_string(float_format=lambda v: f"{v:.2f}"))
    for r in df[df["error"].notna()].drop_duplicates("method").itertuples():
        print(f"{label}: {r.method}: failed: {r.error}", file=sys.stderr)
    for r in df[df["repair"].notna()].drop_duplicates("method").itertuples():
        print(f"{label}: {r.method}: changed to be measured: {r.repair}", file=sys.stderr)
    print(f"{plural(len(df), 'row')}, {seconds:.1f} s")


def _write(df, run, rows: Path, out: Path, args, seconds: float) -> list[Path]:
    """``results.csv`` (``rows``, the complete table, renamed into place), its settings, ``tables.md``,
    the simplified terrains and the figures; the paths written."""
    import os

    from ..experiment._outdir import RESULTS, figure_names
    from ..experiment.results import settings_path
    from ..experiment.units import simplified_path
    from ..io import save_terrain
    from .compare import _compare_report

    results = out / RESULTS
    if rows != results:
        # two renames, each atomic; cut off between them, the folder holds the new results.csv beside the
        # earlier settings and the new ones' partial file, all recognised as terrainvis's (--overwrite clears them)
        os.replace(rows, results)
        os.replace(settings_path(rows), settings_path(results))
    written = [results, settings_path(results)]
    if not args.no_plots:
        for method, terrain in run.terrains.items():
            level = int(df[df["method"] == method]["level"].iloc[0])
            path = simplified_path(out / "simplified", run.name, method, level)
            path.parent.mkdir(exist_ok=True)
            save_terrain(terrain, path)
            written.append(path)
    # its exit status is compare's; evaluate's is _verdict
    _compare_report(df, {run.name: run.grid}, run.settings, out, args, seconds)
    written.append(out / "tables.md")
    written += [out / f for f in figure_names([run.name], set(df["relocation"])) if (out / f).is_file()]
    return written


def _verdict(df, args) -> int:
    failed = df[df["error"].notna()]
    if len(failed):
        return 1
    if args.min_accuracy is None:
        return 0
    evaluated = df[~df["method"].isin(args.against)]
    mean = evaluated.groupby(["method", "relocation"], sort=False)["accuracy"].mean()
    below = mean[~(mean >= args.min_accuracy)]
    if len(below):
        (method, how), value = next(iter(below.items()))
        print(f"terrainvis evaluate: {method} keeps {100 * value:.2f} % of the verdicts under {how!r}, below "
              f"--min-accuracy {100 * args.min_accuracy:.2f} %" + (f" (and {len(below) - 1} more)" if len(below) > 1
                                                                     else ""), file=sys.stderr)
        return 1
    return 0
