"""``terrainvis compare``: the paper's experiment, its tables, figures and simplified terrains in ``--out``."""

from __future__ import annotations

import contextlib
import sys
import time
from pathlib import Path

from ._common import UsageError, add_nodata, dask_client, plural, read_terrain


#: ``--quick``: a run of seconds for smoke tests, on these terrains; each option declared with a
#: ``quick`` value takes it unless given (:func:`quick_options`).
QUICK_TERRAINS = ["hills", "ridges"]


def quick_options() -> dict:
    """The options of ``--quick`` (name -> value), each as its declaration's ``quick`` says
    (the levels, points and sets; the calibrated relocation against its core partners alone)."""
    from ..experiment.options import OPTIONS

    return {name: option.quick for name, option in OPTIONS.items() if option.quick is not None}


#: The command's line in ``terrainvis --help`` (also its light sub-parser: :func:`terrainvis.cli._parser`).
HELP = "run the paper's experiment and print its tables"


def add_parser(sub) -> None:
    """``terrainvis compare``: the options' flags come from :data:`terrainvis.experiment.options.OPTIONS`."""
    from ..experiment.options import add_flags
    from ..experiment.plan import DEFAULT_TERRAINS

    c = sub.add_parser(
        "compare", help=HELP,
        description=(
            "Simplify each terrain with each method and level, relocate random point sets onto the "
            "simplification, and count the line-of-sight verdicts that survive. Defaults reproduce the "
            "paper's protocol: the five bundled 120x120 terrains plus the central 120x120 window of the "
            "Jacksboro DEM, 6 sets of 50 points, levels 1-3, every default method (the paper's seven), the "
            "default relocations (the paper's identity, full and half, and the calibrated one). --max-error E [E ...] "
            "budgets the run in maximum vertical error instead of levels: each method at its smallest result within "
            "each E."
        ),
    )
    c.add_argument("--terrain", nargs="+", default=None, metavar="T",
                   help=f"bundled names ({', '.join(DEFAULT_TERRAINS)}; cumberland, a GeoTIFF, is not a default) or DEM "
                        "files (.npz .npy .asc .tif)")
    add_flags(c)
    c.add_argument("--workers", type=int, default=None, help="local worker processes (default: number of CPUs)")
    c.add_argument("--scheduler", default=None, metavar="ADDRESS", help="run on this dask.distributed scheduler (needs the dask extra)")
    c.add_argument("--no-plots", action="store_true", help="do not write the figures")
    c.add_argument("--quick", action="store_true",
                   help=f"a run of seconds for smoke tests: {_quick_flags()} (each unless given)")
    again = c.add_mutually_exclusive_group()
    again.add_argument("--resume", action="store_true",
                       help="keep the units already in OUT/results.csv and run only the rest (same settings)")
    again.add_argument("--overwrite", action="store_true",
                       help="replace an earlier run in OUT: remove the files it wrote (and only those) first")
    c.add_argument("--out", default="terrainvis-results",
                   help="output folder (default: ./terrainvis-results); one run at a time")
    add_nodata(c)


def _quick_flags() -> str:
    from ..experiment.options import OPTIONS

    words = lambda v: " ".join(map(str, v)) if isinstance(v, list) else str(v)  # noqa: E731
    return " ".join([f"--terrain {words(QUICK_TERRAINS)}"]
                    + [f"{OPTIONS[k].flag} {words(v)}" for k, v in quick_options().items()])


def run(args) -> int:
    from ._common import on_interrupt

    on_interrupt("; finished units are in results.csv (use --resume)")
    with locked_out(args.out, "terrainvis compare") as out:
        return _compare_in(out, args)


@contextlib.contextmanager
def locked_out(path: str, command: str):
    """``--out`` checked (not a protected folder, writable, no lock file of another tool)
    and held by this run's lock for the block, which gets the folder's Path."""
    from ..core.fileio import RunLock, check_writable_dir, refuse_protected
    from ..experiment._outdir import LOCK, foreign_files

    refuse_protected(path, "--out")
    out = check_writable_dir(path, "--out")
    foreign = foreign_files(out)  # a results.lock terrainvis did not write: the lock would replace it
    if foreign:
        raise UsageError(_foreign_message(out, foreign))
    with RunLock(out / LOCK, f"--out {str(out)!r}", command):
        yield out


def _compare_in(out: Path, args) -> int:
    """``terrainvis compare`` with the output folder locked: check everything, clear an earlier run, run, report."""
    from ..experiment.comparison import compare, resolve_terrains
    from ..experiment.options import given
    from ..experiment.plan import DEFAULT_TERRAINS, settings_for

    terrains = args.terrain or (list(QUICK_TERRAINS) if args.quick else list(DEFAULT_TERRAINS))
    options = given(args)
    if args.quick:  # a run budgeted in vertical error keeps its budgets in place of the quick levels
        skip = {"levels"} if options.get("max_errors") is not None else set()
        options = {**{k: v for k, v in quick_options().items() if k not in skip}, **options}
    grids = {}
    for t in terrains:
        label, grid = read_terrain(t, args)
        if label in grids:
            raise UsageError(f"--terrain names must be unique, got {label!r} twice")
        grids[label] = grid
    grids = resolve_terrains(grids)
    settings = settings_for(grids, options, flags=True)  # compare checks them again; here before anything is removed
    _earlier_run(out, args, list(grids), settings, inputs=[t for t in terrains if Path(t).is_file()])
    client = dask_client(args.scheduler) if args.scheduler else None
    t0 = time.perf_counter()
    df = compare(grids, **options, workers=args.workers, client=client, out_csv=out / "results.csv",
                 resume=args.resume, save_dir=out / "simplified", progress=True)
    return _compare_report(df, grids, settings, out, args, time.perf_counter() - t0)


def _earlier_run(out: Path, args, names, settings, inputs) -> None:
    """An earlier run's results in ``out``: refused without --resume or --overwrite; --overwrite removes them.

    Files at the names this run writes that terrainvis did not write are refused in any
    case: neither the run nor --overwrite replaces them.
    """
    from ..experiment._outdir import describe, earlier_run, foreign_files, remove

    foreign = foreign_files(out, names, settings.methods, settings.relocations)
    if foreign:
        raise UsageError(_foreign_message(out, foreign))
    files = earlier_run(out)
    if not files or args.resume:
        return
    if not args.overwrite:
        raise UsageError(
            f"--out {str(out)!r} holds the results of an earlier run ({describe(files)}); add --resume to "
            "continue it (same settings), --overwrite to replace it, or choose another --out"
        )
    for f in files:
        for inp in inputs:
            if Path(inp).resolve() == f.resolve():
                raise UsageError(f"--overwrite would remove {str(f)!r}, which is an input (--terrain); "
                                 "move it out of --out first")
    remove(out, files)
    print(f"terrainvis compare: --overwrite: removed the earlier run's {describe(files)}", file=sys.stderr)


def _foreign_message(out: Path, files) -> str:
    names = [p.relative_to(out).as_posix() for p in files]
    if len(names) == 1:
        shown = names[0]
    elif len(names) <= 4:
        shown = ", ".join(names[:-1]) + " and " + names[-1]
    else:
        shown = ", ".join(names[:4]) + f" and {len(names) - 4} more"
    which = "it" if len(names) == 1 else "them"
    return (f"--out {str(out)!r} holds {shown}, which terrainvis did not write but a run writes under "
            f"{'that name' if len(names) == 1 else 'those names'}; terrainvis never replaces a file it did not "
            f"write: move {which} away or choose another --out")


def _compare_report(df, grids, settings, out: Path, args, seconds: float) -> int:
    """Print and write the tables, draw the figures; the exit status."""
    from ..experiment import report
    from ..experiment.report import step_column
    from ..experiment.measures import MEASURES
    from ..core.fileio import atomic_write_text

    measure = MEASURES[settings.measure]
    step = step_column(df)  # level, or max_error_budget in a run budgeted in vertical error
    extra = {k: t for k, t in (measure.tables(df) if measure.tables is not None else {}).items() if not t.empty}
    extra.update(report.relocation_tables(df, extra))  # the relocations' own (the oracle's gap)
    if df["max_distance"].nunique(dropna=False) > 1:
        extra["localized"] = report.localized(df)
    text = report.to_markdown({**report.paper_tables(df), **extra})
    lines = []  # the paper's side by side and its findings are about its matrices of pairs, at its levels
    if measure.paper and step == "level":
        text += "\n" + report.comparison_markdown(report.paper_comparison(df))
        lines = report.findings_markdown(report.findings(df)) + report.beyond_paper_findings(df)
    elif measure.paper:
        lines = ["", "The paper side by side and its findings are at its levels (shares of the samples): a run "
                     "budgeted in maximum vertical error (--max-error) leaves them out."]
        lines += report.beyond_paper_findings(df)
    if step != "level":
        lines += _budgets_not_met(df)
    lines += report.method_notes(df)  # the methods' own (QEC's backend beyond pymeshlab's size)
    units = df[["terrain", "method", step]].drop_duplicates().shape[0]
    failed = df[df["error"].notna()].drop_duplicates(["terrain", "method", step])
    if len(failed):
        lines += ["", "### Failed units", ""]
        lines += [f"- {r.terrain} / {r.method} / {_step_text(step, getattr(r, step))}: {r.error}"
                  for r in failed.itertuples()]
    changed = df[df["repair"].notna()].drop_duplicates(["terrain", "method"]) if "repair" in df else df.iloc[:0]
    if len(changed):  # evaluate's meshes that were changed to be measured (reversed faces, --repair)
        lines += ["", "### Meshes changed to be measured", ""]
        lines += [f"- {r.terrain} / {r.method}: {r.repair}" for r in changed.itertuples()]
    from ..visibility.engines import verdicts_text

    tins = bool((df["kind"] == "irregular").any()) if "kind" in df else False
    summary = (f"{plural(units, 'unit')}, {plural(len(df), 'row')}, {plural(len(grids), 'terrain')}, "
               f"predicate {settings.predicate}, {verdicts_text(settings.engine, tins, settings.curvature)}, "
               f"{seconds:.1f} s")
    atomic_write_text(out / "tables.md", f"# terrainvis compare\n\n{summary}\n\n{text}\n" + "\n".join(lines) + "\n")
    print(text)
    print("\n".join(lines))
    if not args.no_plots:
        _write_plots(df, grids, out)
    print(f"\n{summary}; wrote {out / 'results.csv'}, {out / 'tables.md'}" + ("" if args.no_plots else " and figures"))
    if df["accuracy"].notna().any():
        return 0
    if len(failed) == units:
        print("terrainvis compare: every unit failed (see 'Failed units' above)", file=sys.stderr)
    else:
        print("terrainvis compare: no pair was counted: every accuracy is undefined (with --max-distance, "
              "no two points of a set lie that close; try a larger distance or more --points)", file=sys.stderr)
    return 1


def _step_text(step: str, value) -> str:
    """``level 2``, or ``max error 2.5`` for a unit of a run budgeted in vertical error."""
    return f"level {value}" if step == "level" else f"max error {value:g}"


def _budgets_not_met(df) -> list[str]:
    """The units of a run budgeted in vertical error whose result is not within its budget, as markdown lines
    (their rows are kept, with what stopped the method in ``stopped_by``)."""
    ok = df[df["error"].isna()]
    missed = ok[ok["stopped_by"].fillna("") != "max_error"].drop_duplicates(["terrain", "method", "max_error_budget"])
    if not len(missed):
        return []
    lines = ["", "### Budgets not met", ""]
    lines += [f"- {r.terrain} / {r.method} / max error {r.max_error_budget:g}: its result's max error is "
              f"{r.max_error:.4g} with {r.n_vertices:,} vertices (stopped by {r.stopped_by})" for r in missed.itertuples()]
    return lines


def _write_plots(df, grids, out: Path) -> None:
    """The figures, drawn from the rows and the saved simplified terrains (nothing is simplified again)."""
    from ..experiment import plot
    from ..experiment.units import simplified_path
    from ..io import load_terrain, save_figure

    def save(fig, name, dpi):
        save_figure(fig, out / name, dpi=dpi)

    from ..experiment.report import step_column

    ok = df[df["error"].isna()]
    if ok.empty:
        return
    budgets = step_column(ok) == "max_error_budget"
    save(plot.accuracy_vs_size(ok), "accuracy_vs_size.png", 110)
    if budgets:
        save(plot.accuracy_vs_budget(ok), "accuracy_vs_budget.png", 110)
    for rel in sorted(set(ok["relocation"])):
        save(plot.tradeoff(ok, relocation=rel), f"tradeoff_{rel}.png", 110)
    if ok["max_distance"].nunique(dropna=True) >= 1:
        save(plot.accuracy_vs_distance(ok), "accuracy_vs_distance.png", 110)
    if "zoom" in ok and ok["zoom"].notna().any():  # tilesets measured by evaluate
        save(plot.accuracy_vs_zoom(ok), "accuracy_vs_zoom.png", 110)
    # the finest results: the shallowest level, or the smallest budget
    level = float(ok["max_error_budget"].min()) if budgets else int(ok["level"].min())
    for name, grid in grids.items():
        views = {}
        for m in dict.fromkeys(ok[ok["terrain"] == name]["method"]):
            path = (simplified_path(out / "simplified", name, m, None, max_error=level) if budgets else
                    simplified_path(out / "simplified", name, m, level))
            if path.exists():  # a failed unit saved nothing and is reported in the tables already
                views[m] = load_terrain(path)
        fig = plot.terrain_views(grid, views)
        fig.suptitle(f"{name}: max error ≤ {level:g}" if budgets else f"{name}: level {level}")
        save(fig, f"views_{name}.png", 90)
