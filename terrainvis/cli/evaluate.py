"""``terrainvis evaluate``: simplifications made elsewhere (meshes, rasters) measured as ``compare`` measures a method's."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from ._common import UsageError, add_nodata, method_arg, plural, read_terrain


#: Options of compare that do not apply: what is simplified, and how, is given.
_NOT_HERE = ("methods", "levels", "cascade")


#: The command's line in ``terrainvis --help`` (also its light sub-parser: :func:`terrainvis.cli._parser`).
HELP = "measure simplifications made elsewhere (meshes, rasters) as compare measures a method's"


def add_parser(sub) -> None:
    from simplifiers import METHODS

    from ..experiment.evaluate import MESH_SUFFIXES, RASTER_SUFFIXES
    from ..experiment.options import add_flags

    e = sub.add_parser(
        "evaluate", help=HELP,
        description=(
            "Measure each SIMPLIFIED terrain of DEM on the comparison's measure: the same point sets (by the DEM's "
            "name and --seed), relocations, predicate and columns as terrainvis compare, optionally beside "
            "built-in methods at the same vertex count (--against). Exits 1 when --min-accuracy is not met."
        ),
    )
    e.add_argument("dem", help="the original DEM (file or bundled name)")
    e.add_argument("simplified", nargs="+", metavar="SIMPLIFIED",
                   help=f"simplified terrains: meshes ({' '.join(MESH_SUFFIXES)}) or rasters "
                        f"({' '.join(RASTER_SUFFIXES)})")
    e.add_argument("--against", nargs="+", default=[], metavar="M", type=method_arg,
                   help=f"methods measured beside them at the same size: {', '.join(METHODS)}")
    e.add_argument("--frame", choices=["native", "local"], default=None,
                   help="the simplified terrains' coordinates: native (the DEM's CRS) or local (the terrain's own "
                        "frame); default: local for files terrainvis wrote, native for others")
    e.add_argument("--repair", action="store_true",
                   help="repair a mesh that is not a height field over the DEM (folds, corners, a border off the "
                        "rectangle) instead of refusing it")
    e.add_argument("--min-accuracy", type=float, default=None, metavar="A",
                   help="exit 1 unless every simplified terrain keeps at least this share of verdicts (0.95 for 95 "
                        "%%) under every relocation of the run")
    e.add_argument("--out", default=None, help="also write results.csv, tables.md and the figures into this folder")
    e.add_argument("--overwrite", action="store_true", help="replace an earlier run's files in --out")
    e.add_argument("--no-plots", action="store_true", help="with --out: do not write the figures")
    add_flags(e, exclude=_NOT_HERE)
    add_nodata(e)


def run(args) -> int:
    import numpy as np

    if args.min_accuracy is not None and not (np.isfinite(args.min_accuracy) and 0.0 <= args.min_accuracy <= 1.0):
        raise UsageError(f"--min-accuracy must be a share in [0, 1] (0.95 for 95 %), got {args.min_accuracy:g}")
    label, grid = read_terrain(args.dem, args)
    for s in args.simplified:
        if not Path(s).exists():
            raise UsageError(f"SIMPLIFIED {s!r} does not exist")
    from ..experiment.options import given
    from ..experiment.plan import settings_for

    # the options checked here, where a message names the flags (evaluate() checks them again)
    settings_for({label: grid}, {**{k: v for k, v in given(args).items() if k not in _NOT_HERE},
                                 "methods": args.against or ["simple"]}, flags=True)
    if not args.out:
        return _evaluate(args, label, grid, None, [])
    from .compare import locked_out

    with locked_out(args.out, "terrainvis evaluate") as out:
        return _evaluate(args, label, grid, out, _check_out(args, label, out))


def _evaluate(args, label: str, grid, out: Path | None, earlier: list) -> int:
    """Measure, print, and with ``out`` write the new run, then remove what is left of the
    ``earlier`` one: until the new files are in place, the earlier run stays whole."""
    from ..experiment.evaluate import evaluate
    from ..experiment.options import given

    options = {k: v for k, v in given(args).items() if k not in _NOT_HERE}
    t0 = time.perf_counter()
    df = evaluate({label: grid}, list(args.simplified), against=args.against, frame=args.frame, repair=args.repair,
                  **options)
    seconds = time.perf_counter() - t0
    _print(df, label, seconds)
    if out is not None:
        written = _write(df, grid, label, out, args, options, seconds)
        stale = [p for p in earlier if p.resolve() not in {w.resolve() for w in written} and p.exists()]
        if stale:
            from ..experiment._outdir import describe, remove

            remove(out, stale)
            print(f"terrainvis evaluate: --overwrite: removed the earlier run's {describe(stale)} that this run did "
                  "not write again", file=sys.stderr)
    return _verdict(df, args)


def _check_out(args, label: str, out: Path) -> list[Path]:
    """``--out`` checked before anything is measured; the earlier run's files, which the new run replaces.

    Refused: files at the names this run writes that terrainvis did not write, or that no
    earlier run in ``out`` recorded (a simplified terrain of the user's own at the name of
    one this run saves: not even ``--overwrite`` replaces it); an earlier run without
    ``--overwrite``; an input (the DEM, a SIMPLIFIED) among the files the run replaces.
    Nothing is removed here.
    """
    from ..experiment._outdir import _candidates, describe, earlier_run, foreign_files
    from ..experiment.evaluate import _named
    from .compare import _foreign_message

    names = [m for m, _ in _named(list(args.simplified), None, taken=args.against)] + list(args.against)
    foreign = foreign_files(out, [label], names, [])
    if foreign:
        raise UsageError(_foreign_message(out, foreign))
    files = earlier_run(out)
    if files and not args.overwrite:
        raise UsageError(f"--out {str(out)!r} holds the results of an earlier run ({describe(files)}); add "
                         "--overwrite to replace it, or choose another --out")
    ours = {p.resolve() for p in files}
    for p in _candidates(out, [label], names, []):
        if p.resolve() not in ours:
            raise UsageError(f"--out {str(out)!r} holds {p.relative_to(out).as_posix()}, which this run would "
                             "write and which no earlier run there recorded; terrainvis never replaces it: move "
                             "it away or choose another --out")
    inputs = [Path(args.dem)] + [Path(s) for s in args.simplified]
    for inp in inputs:
        if inp.is_file() and inp.resolve() in ours:
            raise UsageError(f"--overwrite would replace {str(inp)!r}, an input of this run, with the new run's "
                             "files; move it out of --out first, or choose another --out")
    return files


def _print(df, label: str, seconds: float) -> None:
    import pandas as pd

    ok = df[df["error"].isna()]
    if len(ok):
        g = ok.groupby(["method", "relocation"], sort=False)
        t = pd.DataFrame({"vertices": g["n_vertices"].first(), "level": g["level"].first(),
                          "accuracy": 100 * g["accuracy"].mean(), "visible_kept": 100 * g["visible_kept"].mean(),
                          "blocked_kept": 100 * g["blocked_kept"].mean(), "max_error": g["max_error"].first()})
        print(f"{label}: accuracy (%) of each simplified terrain, mean over {ok['set'].nunique()} point set(s)")
        print(t.to_string(float_format=lambda v: f"{v:.2f}"))
    for r in df[df["error"].notna()].drop_duplicates("method").itertuples():
        print(f"{label}: {r.method}: failed: {r.error}", file=sys.stderr)
    for r in df[df["repair"].notna()].drop_duplicates("method").itertuples():
        print(f"{label}: {r.method}: changed to be measured: {r.repair}", file=sys.stderr)
    print(f"{plural(len(df), 'row')}, {seconds:.1f} s")


def _write(df, grid, label: str, out: Path, args, options: dict, seconds: float) -> list[Path]:
    """``results.csv``, its settings, ``tables.md``, the simplified terrains and the figures; the paths written."""
    from ..experiment.collect import COLUMNS, UNIT_KEY
    from ..experiment.plan import run_record, settings_for
    from ..experiment._outdir import figure_names
    from ..experiment.results import ResultStore, settings_path
    from ..experiment.units import simplified_path
    from ..io import save_terrain
    from .compare import _compare_report

    grids = {label: grid}
    settings = settings_for(grids, {**options, "methods": args.against or ["simple"]})
    record = {**run_record(settings, grids), "evaluated": [str(s) for s in args.simplified],
              "methods": sorted(set(df["method"]))}
    store = ResultStore(out / "results.csv", record, COLUMNS, UNIT_KEY, lambda key: 0, resume=False)
    store.finish(df)
    written = [store.path, settings_path(store.path)]
    if not args.no_plots:
        from ..experiment.evaluate import _named, as_simplified

        for method, s in _named(list(args.simplified), None, taken=args.against):
            level = int(df[df["method"] == method]["level"].iloc[0])
            terrain = as_simplified(s, grid, frame=args.frame, repair=args.repair, label=method)
            path = simplified_path(out / "simplified", label, method, level)
            path.parent.mkdir(exist_ok=True)
            save_terrain(terrain, path)
            written.append(path)
    _compare_report(df, grids, settings, out, args, seconds)  # its exit status is compare's; evaluate's is _verdict
    written.append(out / "tables.md")
    written += [out / f for f in figure_names([label], set(df["relocation"])) if (out / f).is_file()]
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
