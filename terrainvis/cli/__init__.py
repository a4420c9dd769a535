"""The ``terrainvis`` command line.

* ``terrainvis compare`` runs the paper's experiment (by default on the five bundled
  120x120 terrains and the real Jacksboro DEM), prints Tables 1-4, the cost table and
  the paper's findings, and writes ``results.csv``, ``tables.md``, figures and the
  simplified terrains (``simplified/``) into ``--out``.
* ``terrainvis simplify DEM -m METHOD -l LEVEL -o OUT`` simplifies a DEM and writes the
  result as a grid (``.tif``, ``.asc``, ``.npz``) or a mesh (``.ply``, ``.obj``, ``.stl``,
  ``.glb``; TINs also ``.npz``).
* ``terrainvis los DEM --from X Y --to X Y`` checks lines of sight.
* ``terrainvis viewshed DEM --observer X Y -o viewshed.tif`` writes an observer's viewshed.
* ``terrainvis cumulative DEM --observers OBS.csv -o counts.tif`` counts the observers that
  see each sample (a cumulative viewshed).
* ``terrainvis relocate DEM --points CSV ...`` places points on a simplification.
* ``terrainvis info DEM`` describes a terrain.

Positions (``--from``, ``--to``, ``--observer``, the ``--pairs``, ``--points`` and ``--observers`` CSVs) are
in the DEM's native CRS by default (lon/lat degrees on a lon/lat DEM), or in the terrain's
own frame with ``--frame local``; outputs that report positions use the frame of the input
(:mod:`terrainvis.core._positions`). ``--metric`` resamples a lon/lat DEM onto a metric grid
first (:func:`terrainvis.io.to_metric`).

User mistakes end with one line on stderr and exit status 2; a run that produced no
result, or a failed write (a full disk), exits with 1; an interrupt exits with 130
(SIGINT) or 143 (SIGTERM), after the finished units have been written; a closed pipe
(``terrainvis ... | head``) ends the command quietly with 141, as Unix tools do.

Nothing is written over an input (under any spelling of its path, or through a symlink)
or into the installed package. Heights above the surface (``--height``,
``--target-height``, ``--offset``) must be finite and >= 0 everywhere.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

__all__ = ["main"]

#: ``--quick``: a run of seconds for smoke tests (terrains, and options by name, each unless given);
#: the calibrated relocation against its core partners alone (512, calibrated jointly), whose
#: cost does not grow with the points, as the sets are small.
QUICK = {"terrains": ["hills", "ridges"], "levels": [1, 3], "n_points": 20, "n_sets": 2, "n_partners": 512}


class UsageError(ValueError):
    """A mistake on the command line: reported in one line, exit status 2."""


# ------------------------------------------------------------------ parser
class _ParseError(ValueError):
    """argparse's complaint, reported in one line by :func:`main` (exit status 2)."""


class _Parser(argparse.ArgumentParser):
    """argparse with its errors on one line (no usage block), like every other error of the command line."""

    def error(self, message):
        raise _ParseError(f"{self.prog}: error: {message} (see {self.prog} --help)")


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def _height(text: str) -> float:
    """A height above the surface: finite and >= 0 (a negative eye height would stand underground)."""
    value = _number(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a height >= 0 above the surface, got {text!r}")
    return value


def _distance_arg(text: str) -> float:
    value = _number(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a distance >= 0, got {text!r}")
    return value


def _add_target_height(p) -> None:
    p.add_argument("--target-height", type=_height, default=0.0, help="target height above the surface, >= 0 (default 0)")


def _add_max_distance(p, help_text: str) -> None:
    p.add_argument("--max-distance", type=_distance_arg, default=None, help=help_text)


def _add_nodata(p) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--fill", choices=["nearest", "linear"], default=None,
                   help="fill nodata cells first (nearest sample, or linear inside the valid hull)")
    g.add_argument("--crop-valid", action="store_true", help="cut the DEM to its largest window without nodata")


def _add_positions(p, *, frame: bool = True) -> None:
    """``--frame`` (how positions are given and printed) and ``--metric`` (resample a lon/lat DEM first)."""
    from ..core._positions import FRAMES

    if frame:
        p.add_argument("--frame", choices=FRAMES, default="native",
                       help="positions given and printed in the DEM's CRS (native, the default: lon/lat degrees on a "
                            "lon/lat DEM, x, y of its projection otherwise) or in the terrain's own frame (local: "
                            "metres from the south-west sample on a lon/lat DEM; see terrainvis info)")
    p.add_argument("--metric", action="store_true",
                   help="a lon/lat DEM: resample it first onto a metric grid (a transverse Mercator centred on it), "
                        "so distances are right across the whole DEM, not only at its centre latitude; changes the "
                        "samples (heights read from the DEM's surface, over the largest rectangle inside it); positions "
                        "stay lon/lat (docs/user-guide.md, Georeferencing)")


def _coefficient(text: str) -> float:
    """An earth curvature coefficient: finite and >= 0 (GDAL's -cc)."""
    value = _number(text)
    if value < 0:
        raise argparse.ArgumentTypeError(
            f"expected a coefficient >= 0 (0 flat, 1 geometric, 0.85714 GDAL's), got {text!r}")
    return value


def _radius(text: str) -> float:
    value = _number(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a radius > 0, got {text!r}")
    return value


def _add_earth(p) -> None:
    """``--curvature`` and ``--earth-radius`` of the visibility commands (flat by default, as the API)."""
    p.add_argument("--curvature", type=_coefficient, default=0.0,
                   help="earth curvature and refraction coefficient, GDAL's -cc: 0 a flat earth (the default, as the "
                        "Python API and the paper), 1 geometric curvature, 0.85714 standard refraction (gdal_viewshed's "
                        "default); the command prints the model it used")
    p.add_argument("--earth-radius", type=_radius, default=6378137.0,
                   help="with --curvature: the earth's radius in the DEM's x/y units (default 6378137, WGS84's "
                        "semi-major axis in metres, as GDAL takes it)")


def _earth(args) -> str:
    """The earth model a command used, for its output (one phrase)."""
    if args.curvature == 0:
        return "earth: flat (curvature 0; --curvature 0.85714 for gdal_viewshed's default, standard refraction)"
    name = {1.0: " (geometric)", 0.85714: " (standard refraction)"}.get(args.curvature, "")
    return f"earth: curved, coefficient {args.curvature:g}{name}, radius {args.earth_radius:,.0f}"


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="terrainvis", description="How much line of sight does terrain simplification cost?")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _compare_parser(sub)
    _simplify_parser(sub)
    _los_parser(sub)
    _viewshed_parser(sub)
    _cumulative_parser(sub)
    _relocate_parser(sub)
    i = sub.add_parser("info", help="describe a terrain (bundled name or DEM file)")
    i.add_argument("terrain", help="bundled name or DEM file")
    _add_nodata(i)
    _add_positions(i, frame=False)
    return p


def _compare_parser(sub) -> None:
    """``terrainvis compare``: the options' flags come from :data:`terrainvis.experiment.options.OPTIONS`."""
    from ..experiment.options import add_flags
    from ..experiment.plan import DEFAULT_TERRAINS

    c = sub.add_parser(
        "compare", help="run the paper's experiment and print its tables",
        description=(
            "Simplify each terrain with each method and level, relocate random point sets onto the "
            "simplification, and count the line-of-sight verdicts that survive. Defaults reproduce the "
            "paper's protocol: the five bundled 120x120 terrains plus the central 120x120 window of the "
            "Jacksboro DEM, 6 sets of 50 points, levels 1-3, all seven methods, all three relocations."
        ),
    )
    c.add_argument("--terrain", nargs="+", default=None, metavar="T",
                   help=f"bundled names ({', '.join(DEFAULT_TERRAINS)}) or DEM files (.npz .npy .asc .tif)")
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
    _add_nodata(c)


def _quick_flags() -> str:
    from ..experiment.options import OPTIONS

    words = lambda v: " ".join(map(str, v)) if isinstance(v, list) else str(v)  # noqa: E731
    return " ".join(f"{'--terrain' if k == 'terrains' else OPTIONS[k].flag} {words(v)}" for k, v in QUICK.items())


def _simplify_parser(sub) -> None:
    from simplifiers import METHODS

    s = sub.add_parser(
        "simplify", help="simplify a DEM and write the result",
        description=(
            "Simplify a DEM with one method, to a level or to a target error, and write it. OUT by extension: "
            ".npz for grids and TINs; .tif .asc for grids, and for TINs sampled back at the DEM's samples (same "
            "CRS and transform); .ply .obj .stl .glb for any result as a mesh."
        ),
    )
    s.add_argument("dem", help="DEM file or bundled name")
    s.add_argument("-m", "--method", required=True, choices=list(METHODS), metavar="METHOD",
                   help=f"one of {', '.join(METHODS)}")
    s.add_argument("-l", "--level", type=int, default=None,
                   help="level: each one halves both axes (default 1; with --max-error, the finest allowed)")
    s.add_argument("--max-error", type=_distance_arg, default=None, metavar="E",
                   help="the smallest result whose max vertical error is <= E (z units)")
    s.add_argument("-o", "--output", required=True, metavar="OUT", help="output file")
    s.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="an option of the method, e.g. weights=derived for lls (repeatable)")
    _add_nodata(s)


def _los_parser(sub) -> None:
    los = sub.add_parser(
        "los", help="check lines of sight on a DEM",
        description=(
            "Print whether the points see each other, and the lowest clearance of the segment (segment height "
            "minus surface height) with where it occurs. Positions are in the DEM's CRS (lon, lat in degrees on a "
            "lon/lat DEM), or in the terrain's own frame with --frame local (see terrainvis info)."
        ),
    )
    los.add_argument("dem", help="DEM file or bundled name")
    los.add_argument("--from", dest="start", nargs=2, type=_number, metavar=("X", "Y"),
                     help="observer position (lon lat on a lon/lat DEM)")
    los.add_argument("--to", dest="end", nargs=2, type=_number, metavar=("X", "Y"),
                     help="target position (lon lat on a lon/lat DEM)")
    los.add_argument("--pairs", metavar="CSV", help="many pairs: a CSV with columns x1, y1, x2, y2 (lon, lat on a "
                                                   "lon/lat DEM)")
    los.add_argument("--height", type=_height, default=1.7, help="observer height above the surface, >= 0 (default 1.7)")
    _add_target_height(los)
    los.add_argument("--end-radius", type=_distance_arg, default=0.0,
                     help="ignore the surface within this distance of each end (default 0)")
    _add_earth(los)
    _add_nodata(los)
    _add_positions(los)


def _viewshed_parser(sub) -> None:
    v = sub.add_parser(
        "viewshed", help="which samples of a DEM an observer sees",
        description=(
            "Compute the exact viewshed of one observer on a DEM (every sample as a target, on the piecewise-linear "
            "surface) and write it as a GeoTIFF aligned with the DEM (CRS and transform kept; 1 visible, 0 not, "
            "255 nodata), an .npz, or a .png drawn over the hillshade."
        ),
    )
    v.add_argument("dem", help="DEM file or bundled name")
    v.add_argument("--observer", nargs=2, type=_number, required=True, metavar=("X", "Y"),
                   help="observer position (lon lat on a lon/lat DEM; see --frame)")
    v.add_argument("--height", type=_height, default=1.7, help="eye height above the surface, >= 0 (default 1.7)")
    _add_target_height(v)
    _add_max_distance(v, "only samples within this distance")
    v.add_argument("-o", "--output", required=True, metavar="OUT", help="output file: .tif, .npz or .png")
    _add_earth(v)
    _add_nodata(v)
    _add_positions(v)


def _cumulative_parser(sub) -> None:
    c = sub.add_parser(
        "cumulative", help="how many observers see each sample of a DEM",
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
    c.add_argument("--observer-height", "--height", dest="height", type=_height, default=1.7,
                   help="eye height above the surface, >= 0, for observers without a height column (default 1.7)")
    _add_target_height(c)
    _add_max_distance(c, "each observer sees only the samples within this distance")
    c.add_argument("--workers", type=_workers_arg, default=None,
                   help="local worker processes (default 1: in this process, each viewshed on every core)")
    c.add_argument("--scheduler", default=None, metavar="ADDRESS", help="run on this dask.distributed scheduler "
                                                                        "(needs the dask extra)")
    _add_earth(c)
    _add_nodata(c)
    _add_positions(c)


def _workers_arg(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of processes >= 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number of processes >= 1, got {text!r}")
    return value


def _relocate_parser(sub) -> None:
    from simplifiers import METHODS

    from ..relocation.calibrated import N_PARTNERS
    from ..relocation.registry import RELOCATIONS

    r = sub.add_parser(
        "relocate", help="place points of a DEM on its simplification",
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
    r.add_argument("--simplified", metavar="FILE", help="the simplification (.npz from simplify or compare, .tif, .asc)")
    r.add_argument("-m", "--method", choices=list(METHODS), metavar="METHOD",
                   help=f"simplify the DEM here instead, with one of {', '.join(METHODS)}")
    r.add_argument("-l", "--level", type=int, default=None, help="with -m: the level (default 1)")
    r.add_argument("--how", choices=list(RELOCATIONS), default="calibrated",
                   help="the relocation (default calibrated)")
    r.add_argument("--offset", type=_height, default=0.0,
                   help="the points' height above the DEM's surface, >= 0 (default 0: on the surface)")
    r.add_argument("--target-height", type=_height, default=None,
                   help="calibrated: the points will look at targets this high above the surface (a viewshed's "
                        "cells); without it they will look at each other")
    r.add_argument("--no-neighbours", dest="neighbours", action="store_false",
                   help="calibrated: the partners alone, without each point's neighbours 1.5-8 cells around it")
    r.add_argument("--partners", type=int, default=N_PARTNERS,
                   help=f"calibrated: partners spread over the DEM (default {N_PARTNERS})")
    r.add_argument("--seed", type=int, default=0, help="calibrated: seed of the partners' positions (default 0)")
    _add_earth(r)  # the calibrated relocation's lines of sight
    _add_nodata(r)
    _add_positions(r)


# ------------------------------------------------------------------ helpers
def _terrain(name: str, args=None):
    """One terrain from a bundled name or a DEM file, with --fill / --crop-valid applied."""
    import numpy as np

    from ..experiment.plan import resolve_one

    if Path(name).suffix and not Path(name).exists():
        raise UsageError(f"DEM file {name!r} does not exist")
    label, grid = resolve_one(None, name, 0)
    if not np.isfinite(grid.z).any():
        raise UsageError(f"DEM {name!r} has no valid sample: all {_plural(grid.size, 'cell')} are nodata")
    if args is not None and getattr(args, "metric", False):
        grid = _metric_grid(name, grid)
    if args is not None and getattr(args, "fill", None):
        grid = grid.fill_nodata(args.fill)
    elif args is not None and getattr(args, "crop_valid", False):
        rs, cs = grid.valid_window()
        grid = grid.crop(rs, cs)
    return label, grid


def _metric_grid(name: str, grid):
    """``--metric``: a lon/lat DEM resampled onto a transverse Mercator grid (:func:`terrainvis.io.to_metric`)."""
    from ..io import to_metric

    if not grid.attrs.get("geographic"):
        crs = grid.attrs.get("crs")
        raise UsageError(f"--metric resamples lon/lat DEMs; {name!r} is "
                         + (f"in {crs}, whose x, y are metres already" if crs else "not georeferenced (no CRS)"))
    return to_metric(grid)


def _frame(grid, args):
    """The :class:`~terrainvis.core._positions.PositionFrame` of a command's positions (``--frame``)."""
    from ..core._positions import PositionFrame

    return PositionFrame(grid, getattr(args, "frame", "native"))


def _outside(frame, xy_user, what: str = "") -> str:
    """``lies outside the DEM's footprint ... (or on nodata)`` in the user's frame, with a hint when the
    position is on the DEM in the other frame (lon/lat given to --frame local, or local metres to native)."""
    import numpy as np

    from ..core._positions import PositionFrame

    text = f"lies outside the DEM's footprint {frame.footprint()}{what} (or on nodata)"
    other = PositionFrame(frame.terrain, "local" if frame.frame == "native" else "native")
    if other.identity and frame.identity:
        return text  # both frames are the same
    try:
        fits = np.isfinite(frame.terrain.height_at(other.to_grid(np.asarray([xy_user[:2]], float)))[0])
    except ValueError:
        fits = False
    if fits:
        text += f"; it is on the DEM as {other.describe()}: add --frame {other.frame} if you meant those"
    return text


def _plural(n: int, word: str, plural: str | None = None) -> str:
    """``1 terrain``, ``2 terrains``, ``12,000 vertices`` (with ``plural`` for irregular words)."""
    return f"{n:,} {word if n == 1 else plural or word + 's'}"


def _option_value(text: str):
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)


def _options(items) -> dict:
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise UsageError(f"--option must be KEY=VALUE, got {item!r}")
        out[key.strip()] = _option_value(value.strip())
    return out


# ------------------------------------------------------------------ compare
def _client(address: str):
    try:
        from dask.distributed import Client
    except ImportError:
        raise UsageError('--scheduler needs the dask extra: pip install "terrainvis[dask]"') from None
    try:
        return Client(address, timeout="10s")
    except (OSError, TimeoutError) as exc:
        raise UsageError(f"--scheduler {address!r} could not be reached within 10 s ({type(exc).__name__})") from None


def _compare(args) -> int:
    from ..core.fileio import RunLock, check_writable_dir, refuse_protected
    from ..experiment._outdir import LOCK, foreign_files

    refuse_protected(args.out, "--out")
    out = check_writable_dir(args.out, "--out")
    foreign = foreign_files(out)  # a results.lock terrainvis did not write: the lock would replace it
    if foreign:
        raise UsageError(_foreign_message(out, foreign))
    with RunLock(out / LOCK, f"--out {str(out)!r}", "terrainvis compare"):
        return _compare_in(out, args)


def _compare_in(out: Path, args) -> int:
    """``terrainvis compare`` with the output folder locked: check everything, clear an earlier run, run, report."""
    from ..experiment.comparison import compare, resolve_terrains
    from ..experiment.options import given
    from ..experiment.plan import DEFAULT_TERRAINS, settings_for

    terrains = args.terrain or (QUICK["terrains"] if args.quick else list(DEFAULT_TERRAINS))
    options = given(args)
    if args.quick:
        options = {**{k: v for k, v in QUICK.items() if k != "terrains"}, **options}
    grids = {}
    for t in terrains:
        label, grid = _terrain(t, args)
        if label in grids:
            raise UsageError(f"--terrain names must be unique, got {label!r} twice")
        grids[label] = grid
    grids = resolve_terrains(grids)
    settings = settings_for(grids, options)  # compare checks them again; here before anything is removed
    _earlier_run(out, args, list(grids), settings, inputs=[t for t in terrains if Path(t).is_file()])
    client = _client(args.scheduler) if args.scheduler else None
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
    from ..core.fileio import atomic_write_text

    extra = {}
    beyond = report.beyond_paper(df) if settings.measure == "pairs" else None
    if beyond is not None and not beyond.empty:
        extra["beyond"] = beyond
    elif (df["relocation"] == "oracle").any():
        extra["oracle"] = report.oracle_gap(df)
    if df["max_distance"].nunique(dropna=False) > 1:
        extra["localized"] = report.localized(df)
    if settings.measure == "viewshed":
        if df["accuracy"].notna().any():
            extra["viewsheds"] = report.viewshed_table(df)
        text = report.to_markdown({**report.paper_tables(df), **extra})
        lines = []  # the paper's findings are about pairs
    else:
        text = (report.to_markdown({**report.paper_tables(df), **extra}) + "\n"
                + report.comparison_markdown(report.paper_comparison(df)))
        lines = report.findings_markdown(report.findings(df)) + report.beyond_paper_findings(df)
    fast = sorted(set(df[(df["method"] == "qec") & (df["backend"] == "fast-simplification")]["terrain"]))
    if fast:
        from simplifiers.quadric import AUTO_MAX_SAMPLES

        lines += ["", f"Note: QEC ran on fast-simplification for {', '.join(fast)} (more than {AUTO_MAX_SAMPLES:,} "
                      "samples, where pymeshlab takes minutes per level); pymeshlab, the paper's QEC, ran elsewhere."]
    units = df[["terrain", "method", "level"]].drop_duplicates().shape[0]
    failed = df[df["error"] != ""].drop_duplicates(["terrain", "method", "level"])
    if len(failed):
        lines += ["", "### Failed units", ""]
        lines += [f"- {r.terrain} / {r.method} / level {r.level}: {r.error}" for r in failed.itertuples()]
    summary = (f"{_plural(units, 'unit')}, {_plural(len(df), 'row')}, {_plural(len(grids), 'terrain')}, "
               f"predicate {settings.predicate}, {seconds:.1f} s")
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


def _write_plots(df, grids, out: Path) -> None:
    """The figures, drawn from the rows and the saved simplified terrains (nothing is simplified again)."""
    from simplifiers import METHODS

    from ..experiment import plot
    from ..core.fileio import atomic_path
    from ..experiment._outdir import figure_metadata
    from ..io import load_terrain
    from ..experiment.units import simplified_path

    def save(fig, name, dpi):
        with atomic_path(out / name) as tmp:
            fig.savefig(tmp, dpi=dpi, format="png", metadata=figure_metadata())

    ok = df[df["error"] == ""]
    if ok.empty:
        return
    save(plot.accuracy_vs_size(ok), "accuracy_vs_size.png", 110)
    for rel in sorted(set(ok["relocation"])):
        save(plot.tradeoff(ok, relocation=rel), f"tradeoff_{rel}.png", 110)
    if ok["max_distance"].nunique(dropna=True) >= 1:
        save(plot.accuracy_vs_distance(ok), "accuracy_vs_distance.png", 110)
    level = int(ok["level"].min())
    for name, grid in grids.items():
        views = {}
        for m in METHODS:
            path = simplified_path(out / "simplified", name, m, level)
            if path.exists():  # a failed unit saved nothing and is reported in the tables already
                views[m] = load_terrain(path)
        fig = plot.terrain_views(grid, views)
        fig.suptitle(f"{name}: level {level}")
        save(fig, f"views_{name}.png", 90)


# ------------------------------------------------------------------ simplify
_GRID_SUFFIXES = (".tif", ".tiff", ".asc", ".npz", ".npy")
_MESH_SUFFIXES = (".ply", ".obj", ".stl", ".glb")


def _simplify(args) -> int:
    from simplifiers import METHODS, simplify

    from ..core.fileio import check_output_file
    from ..io import save_terrain

    out = Path(args.output)
    suffix = out.suffix.lower()
    regular = METHODS[args.method].regular
    valid = _GRID_SUFFIXES + _MESH_SUFFIXES
    if suffix not in valid:
        raise UsageError(f"-o must end in one of {list(valid)}, got {out.name!r}")
    check_output_file(out, "-o", inputs=[args.dem])
    label, grid = _terrain(args.dem, args)
    level = 1 if args.level is None and args.max_error is None else args.level
    result = simplify(grid, args.method, level, max_error=args.max_error, **_options(args.option))
    # a TIN to a raster is sampled at the DEM's own samples (nodata outside the TIN)
    save_terrain(result, out, like=None if regular or suffix == ".npz" else grid)
    a = result.attrs
    kind = f"{result.shape[0]} x {result.shape[1]} grid" if regular else f"TIN with {_plural(result.n_faces, 'face')}"
    at = f"level {a['level']}" if a.get("level") is not None else f"max error <= {args.max_error:g}"
    print(f"{label}: {args.method} {at}: {_plural(a['n_vertices'], 'vertex', 'vertices')} ({kind}), "
          f"{100 * a['n_vertices'] / grid.size:.2f} % of {grid.size:,}")
    print(f"  max error {a['max_error']:.4g}, RMS error {a['rms_error']:.4g} (z units), {a['seconds']:.3f} s")
    for note in a.get("notes", []):
        print(f"  note: {note}")
    if regular and suffix in (".tif", ".tiff", ".asc") and not result.is_uniform:
        # the file holds the grid resampled onto uniform coordinates: its errors are not the ones above
        from ..core.deviation import vertical_errors
        from ..io import load_terrain

        worst, rms = vertical_errors(grid, load_terrain(out))
        print(f"  as written (resampled onto a uniform grid): max error {worst:.4g}, RMS error {rms:.4g}")
    print(f"  wrote {out}")
    return 0


# ------------------------------------------------------------------ los
def _los(args) -> int:
    import numpy as np

    from ..visibility import line_of_sight, min_clearance
    from ..visibility.profile import lowest_point

    label, grid = _terrain(args.dem, args)
    if args.pairs:
        if args.start or args.end:
            raise UsageError("give either --pairs or --from and --to, not both")
        user1, user2 = _read_pairs(args.pairs)
    else:
        if not (args.start and args.end):
            raise UsageError("give --from X Y and --to X Y (or --pairs CSV)")
        user1 = np.array([args.start], float)
        user2 = np.array([args.end], float)
    frame = _frame(grid, args)
    xy1, xy2 = frame.to_grid(user1), frame.to_grid(user2)
    z1 = grid.height_at(xy1) + args.height
    z2 = grid.height_at(xy2) + args.target_height
    outside = np.isnan(z1) | np.isnan(z2)
    if outside.any():
        k = int(np.flatnonzero(outside)[0])
        bad = user1[k] if np.isnan(z1[k]) else user2[k]
        raise UsageError(
            f"point pair {k} from {frame.point(user1[k])} to {frame.point(user2[k])}: {frame.point(bad)} "
            f"{_outside(frame, bad)}"
        )
    a = np.column_stack([xy1, z1])
    b = np.column_stack([xy2, z2])
    earth = {"curvature": args.curvature, "earth_radius": args.earth_radius}
    visible = line_of_sight(grid, a, b, end_radius=args.end_radius, **earth)
    clear = min_clearance(grid, a, b, end_radius=args.end_radius, **earth)
    print(f"{label}: observer {args.height:g} above the surface, target {args.target_height:g} above it; "
          f"{_earth(args)}")
    for k in range(a.shape[0]):
        low = lowest_point(grid, a[k], b[k], end_radius=args.end_radius, **earth)
        verdict = "visible" if visible[k] else "blocked"
        where = ("" if not np.isfinite(clear[k]) else
                 f" at {frame.point(frame.from_grid([low['x'], low['y']]))}, {low['distance']:.6g} from the observer")
        print(f"  {frame.point(user1[k])} -> {frame.point(user2[k])}: {verdict}; lowest clearance "
              f"{clear[k]:.4g}{where}")
    return 0


def _read_pairs(path: str):
    """The x1, y1 and x2, y2 columns of a --pairs CSV; a bad cell is named by row and column."""
    values = _read_columns(path, "--pairs", ("x1", "y1", "x2", "y2"))
    return values[:, :2], values[:, 2:]


def _read_columns(path: str, flag: str, columns, optional=()):
    """The named columns of a CSV as an (n, k) float array (the ``optional`` ones NaN when absent);
    a missing column or a bad cell is named by file, row and column."""
    import numpy as np
    import pandas as pd

    try:
        table = pd.read_csv(path, dtype=str, keep_default_na=False)
    except (OSError, ValueError) as exc:
        raise UsageError(f"{flag} {path!r} could not be read as CSV: {exc}") from None
    missing = [c for c in columns if c not in table.columns]
    if missing:
        raise UsageError(f"{flag} needs the columns {', '.join(columns)}; {path!r} lacks {missing}")
    wanted = list(columns) + list(optional)
    values = np.full((len(table), len(wanted)), np.nan)
    for j, c in enumerate(wanted):
        if c not in table.columns:
            continue
        for i, text in enumerate(table[c]):
            try:
                values[i, j] = float(text)
            except ValueError:
                values[i, j] = np.nan
            if not np.isfinite(values[i, j]):
                what = "is empty" if not text.strip() else f"holds {text!r}, not a finite number"
                raise UsageError(f"{flag} {path!r}: row {i + 1} (line {i + 2}), column {c} {what}")
    return values


# ------------------------------------------------------------------ viewshed
def _viewshed(args) -> int:
    import numpy as np

    from ..core.fileio import check_output_file
    from ..visibility import viewshed

    out = Path(args.output)
    suffix = out.suffix.lower()
    if suffix not in (".tif", ".tiff", ".npz", ".png"):
        raise UsageError(f"-o must end in .tif, .npz or .png, got {out.name!r}")
    check_output_file(out, "-o", inputs=[args.dem])
    label, grid = _terrain(args.dem, args)
    frame = _frame(grid, args)
    observer = tuple(float(v) for v in frame.to_grid(args.observer))
    if np.isnan(grid.height_at([observer])[0]):
        raise UsageError(f"--observer {frame.point(args.observer)} {_outside(frame, args.observer)}")
    t0 = time.perf_counter()
    vis = viewshed(grid, observer, observer_height=args.height, target_height=args.target_height,
                   max_distance=args.max_distance, curvature=args.curvature, earth_radius=args.earth_radius)
    seconds = time.perf_counter() - t0
    valid = np.isfinite(grid.z)
    n_vis = int(vis[valid].sum())
    _write_viewshed(grid, vis, out, suffix, args, label, observer)
    print(f"{label}: observer {frame.point(args.observer)}, eye {args.height:g} above the surface")
    print(f"  {_earth(args)}")
    print(f"  visible {n_vis:,} of {_plural(int(valid.sum()), 'sample')} "
          f"({100 * n_vis / max(int(valid.sum()), 1):.2f} %), {seconds:.2f} s")
    print(f"  wrote {out}")
    return 0


def _write_viewshed(grid, vis, out: Path, suffix: str, args, label: str, observer) -> None:
    """The viewshed by OUT's suffix; ``observer`` in the grid's own frame."""
    import numpy as np

    from ..core.fileio import atomic_path

    if suffix == ".png":
        from ..experiment import plot

        from ..experiment._outdir import figure_metadata

        fig = plot.viewshed(grid, vis, observer=observer, title=f"{label}: viewshed")
        with atomic_path(out) as tmp:
            fig.savefig(tmp, dpi=110, format="png", metadata=figure_metadata())
        return
    if suffix == ".npz":
        from ..io import save_terrain

        from ..core.terrain import HeightGrid

        # a grid of the same samples: 1 visible, 0 not, NaN nodata (with the DEM's georeferencing)
        z = np.where(np.isfinite(grid.z), vis.astype(np.float64), np.nan)
        # the observer in the grid's frame (that of its xs, ys) and in the DEM's native CRS
        attrs = {**grid.attrs, "viewshed_observer": [float(v) for v in observer],
                 "viewshed_observer_native": [float(v) for v in _frame(grid, None).from_grid(observer)],
                 "viewshed_observer_height": float(args.height), "viewshed_target_height": float(args.target_height),
                 "viewshed_curvature": float(args.curvature), "viewshed_earth_radius": float(args.earth_radius)}
        save_terrain(HeightGrid.from_coords(z, grid.xs, grid.ys, attrs=attrs), out)
        return
    from ..io import write_mask_geotiff

    write_mask_geotiff(grid, vis, out, nodata_mask=~np.isfinite(grid.z))


# ------------------------------------------------------------------ cumulative
def _cumulative(args) -> int:
    import numpy as np

    from ..core.fileio import check_output_file
    from ..visibility import cumulative_viewshed

    out = Path(args.output)
    suffix = out.suffix.lower()
    if suffix not in (".tif", ".tiff", ".npz"):
        raise UsageError(f"-o must end in .tif or .npz, got {out.name!r}")
    png = Path(args.png) if args.png else None
    if png is not None and png.suffix.lower() != ".png":
        raise UsageError(f"--png must end in .png, got {png.name!r}")
    inputs = [args.dem, args.observers]
    check_output_file(out, "-o", inputs=inputs)
    if png is not None:
        check_output_file(png, "--png", inputs=inputs + [str(out)])
    label, grid = _terrain(args.dem, args)
    if suffix in (".tif", ".tiff") and not grid.is_uniform:
        raise UsageError("a GeoTIFF needs a uniform grid, and this DEM is rectilinear: write the counts as .npz")
    table = _read_columns(args.observers, "--observers", ("x", "y"), optional=("height",))
    if not len(table):
        raise UsageError(f"--observers {args.observers!r} holds no observer (a header and no rows)")
    frame = _frame(grid, args)
    user = table[:, :2]
    xy = frame.to_grid(user)
    outside = np.isnan(grid.height_at(xy))
    if outside.any():
        k = int(np.flatnonzero(outside)[0])
        raise UsageError(f"--observers {args.observers!r}: row {k + 1} {frame.point(user[k])} {_outside(frame, user[k])}; "
                         f"{_plural(int(outside.sum()), 'observer')} of {len(xy):,} do")
    heights = np.where(np.isnan(table[:, 2]), args.height, table[:, 2])
    if (heights < 0).any():
        k = int(np.flatnonzero(heights < 0)[0])
        raise UsageError(f"--observers {args.observers!r}: row {k + 1}, column height is {heights[k]:g}; "
                         "heights above the surface must be >= 0")
    client = _client(args.scheduler) if args.scheduler else None
    try:
        t0 = time.perf_counter()
        counts = cumulative_viewshed(grid, xy, observer_height=heights, target_height=args.target_height,
                                     max_distance=args.max_distance, curvature=args.curvature,
                                     earth_radius=args.earth_radius, workers=args.workers, client=client,
                                     progress=True)
        seconds = time.perf_counter() - t0
    finally:
        if client is not None:
            client.close()
    _write_counts(grid, counts, out, suffix, args, len(xy))
    if png is not None:
        _write_counts_png(grid, counts, xy, png, label)
    valid = np.isfinite(grid.z)
    n_valid = max(int(valid.sum()), 1)
    seen = counts[valid]
    if client is not None:
        where = "on the dask cluster"
    else:
        where = "in this process" if (args.workers or 1) == 1 else "on " + _plural(args.workers, "worker")
    print(f"{label}: {_plural(len(xy), 'observer')}, eyes {_heights_text(heights)} above the surface, target "
          f"{args.target_height:g}" + (f", within {args.max_distance:g}" if args.max_distance is not None else ""))
    print(f"  {_earth(args)}")
    print(f"  seen by any {int((seen > 0).sum()):,} of {_plural(n_valid, 'sample')} ({100 * (seen > 0).mean():.2f} %), "
          f"by all {100 * (seen == len(xy)).mean():.2f} %, most observers on one sample {int(seen.max()):,}; "
          f"{seconds:.1f} s {where} ({len(xy) / seconds:.1f} observers/s)")
    print(f"  wrote {out}" + (f" and {png}" if png is not None else ""))
    return 0


def _heights_text(heights) -> str:
    lo, hi = float(heights.min()), float(heights.max())
    return f"{lo:g}" if lo == hi else f"{lo:g} to {hi:g}"


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
    from ..core.fileio import atomic_path
    from ..core._georef import parse_crs
    from ..io._geotiff import _north_up_transform, _write_gtiff
    from ..io._raster import _uniform_layout

    dtype = np.uint16 if k < np.iinfo(np.uint16).max else np.uint32  # the largest value stays free for nodata
    fill = np.iinfo(dtype).max
    _, nx, ny, crs_text, _ = _uniform_layout(grid, suffix)
    crs = parse_crs(crs_text, "grid.attrs['crs']") if crs_text else None
    data = counts.astype(dtype)
    data[nodata] = fill
    profile = dict(height=data.shape[0], width=data.shape[1], count=1, dtype=np.dtype(dtype).name,
                   transform=_north_up_transform(nx, ny), crs=crs, nodata=fill)
    with atomic_path(out) as tmp:
        _write_gtiff(tmp, np.ascontiguousarray(data[::-1]), profile,
                     {"TERRAINVIS_CUMULATIVE": f"observers={k} target_height={args.target_height:g} "
                                               f"curvature={args.curvature:g} earth_radius={args.earth_radius:g}"})


def _write_counts_png(grid, counts, xy, png: Path, label: str) -> None:
    from ..experiment import plot
    from ..core.fileio import atomic_path
    from ..experiment._outdir import figure_metadata

    fig = plot.cumulative_viewshed(grid, counts, observers=xy, title=f"{label}: cumulative viewshed")
    with atomic_path(png) as tmp:
        fig.savefig(tmp, dpi=110, format="png", metadata=figure_metadata())


# ------------------------------------------------------------------ relocate
def _relocate(args) -> int:
    import numpy as np
    import pandas as pd

    from ..core.fileio import atomic_path, check_output_file
    from ..relocation.registry import relocate

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
    check_output_file(out, "-o", inputs=[args.dem, args.points] + ([args.simplified] if args.simplified else []))
    label, grid = _terrain(args.dem, args)
    simplified, what = _simplification(grid, args)
    table = _read_columns(args.points, "--points", ("x", "y"), optional=("z",))
    frame = _frame(grid, args)
    user = table[:, :2]
    xy = frame.to_grid(user)
    ground = grid.height_at(xy)
    outside = np.isnan(ground) | np.isnan(simplified.height_at(xy))
    if outside.any():
        k = int(np.flatnonzero(outside)[0])
        raise UsageError(f"--points {args.points!r}: row {k + 1} {frame.point(user[k])} "
                         f"{_outside(frame, user[k], ' or its simplification')}; {int(outside.sum())} point(s) do")
    z = np.where(np.isnan(table[:, 2]), ground + args.offset, table[:, 2])
    points = np.column_stack([xy, z])
    t0 = time.perf_counter()
    moved = relocate(points, simplified, args.how, offset=args.offset, original=grid, target_height=args.target_height,
                     n_partners=args.partners, seed=args.seed, curvature=args.curvature,
                     earth_radius=args.earth_radius, neighbours=args.neighbours)
    seconds = time.perf_counter() - t0
    surface = simplified.height_at(xy)
    written = pd.DataFrame({**_csv_positions(frame, user), "z": moved[:, 2], "z_original": z,
                            "ground_simplified": surface})
    with atomic_path(out) as tmp:
        written.to_csv(tmp, index=False, float_format="%.6f")
    lift = moved[:, 2] - (surface + args.offset)
    print(f"{label}: {_plural(len(points), 'point')} relocated ({args.how}) onto {what}, {seconds:.2f} s")
    if args.how == "calibrated" and len(points):
        from ..tolerances import MOVED_ABS

        off = np.abs(lift) > MOVED_ABS
        print(f"  {int(off.sum())} off the full projection (S(T) + offset); height change from it "
              f"{lift.min():+.4g} to {lift.max():+.4g}, median {np.median(lift):+.4g} (z units)")
        print(f"  {_earth(args)}")
    print(f"  wrote {out}")
    return 0


def _csv_positions(frame, user) -> dict:
    """The x, y columns of a CSV the command writes, in the frame of its input (degrees to 1e-9, 0.1 mm)."""
    if frame.degrees:
        return {"x": [f"{v:.9f}" for v in user[:, 0]], "y": [f"{v:.9f}" for v in user[:, 1]]}
    return {"x": user[:, 0], "y": user[:, 1]}


def _simplification(grid, args):
    """The simplified terrain of ``relocate``: read from --simplified, or made with -m/-l; and how to name it."""
    if args.method is not None:
        from simplifiers import simplify

        level = 1 if args.level is None else args.level
        return simplify(grid, args.method, level), f"{args.method} level {level}"
    from ..io import load_terrain

    path = Path(args.simplified)
    if not path.exists():
        raise UsageError(f"--simplified {args.simplified!r} does not exist")
    if path.suffix.lower() == ".npz":
        terrain = load_terrain(path)
    else:
        from ..io import load_dem

        terrain = load_dem(path)
    return terrain, path.name


# ------------------------------------------------------------------ info
def _info(args) -> int:
    import numpy as np

    from simplifiers import METHODS, max_level, vertex_budget

    label, grid = _terrain(args.terrain, args)
    rows, cols = grid.shape
    local = _frame(grid, argparse.Namespace(frame="local"))
    xmin, xmax, ymin, ymax = (local.value(v) for v in grid.extent)
    z = grid.z
    kind = "uniform" if grid.is_uniform else "rectilinear"
    nodata = f", {_plural(grid.n_nodata, 'nodata cell')}" if grid.n_nodata else ""
    print(f"{label}: {rows}x{cols} {kind} grid, x [{xmin}, {xmax}], y [{ymin}, {ymax}], "
          f"z [{np.nanmin(z):.6g}, {np.nanmax(z):.6g}]{nodata}")
    print(f"  samples   {rows} x {cols} = {grid.size:,}  ({grid.nbytes / 1e6:.2f} MB as a grid)")
    print(f"  spacing   dx {grid.dx:g}, dy {grid.dy:g}" + ("" if grid.is_uniform else " (mean; rectilinear)"))
    print(f"  extent    x [{xmin}, {xmax}], y [{ymin}, {ymax}]")
    crs = grid.attrs.get("crs") or "not recorded"
    print(f"  CRS       {crs}" + (" (x, y converted to local metres)" if grid.attrs.get("geographic") else ""))
    _info_positions(grid)
    print(f"  heights   {np.nanmin(z):.6g} to {np.nanmax(z):.6g}")
    print(f"  nodata    {_plural(grid.n_nodata, 'cell')} ({100 * grid.n_nodata / grid.size:.2f} %)"
          + (" (use --fill or --crop-valid)" if grid.n_nodata else ""))
    top = max_level(grid.shape)
    print("  levels    vertices per level (regular methods keep a grid; irregular ones get the same budget)")
    for level in range(1, top + 1):
        n = vertex_budget(grid.shape, level)
        print(f"    {level}: {n:>12,} {'vertex' if n == 1 else 'vertices'} ({100 * n / grid.size:.3g} %)")
    print(f"  methods   {', '.join(METHODS)}")
    return 0


def _info_positions(grid) -> None:
    """``info``'s lines on positions: the frame the commands take, and the local frame's distances."""
    from ..core._georef import local_frame_error

    native = _frame(grid, None)
    if native.identity:
        print(f"  positions {native.describe()}, in the commands (--from, --to, --observer, CSVs; --frame local is "
              "the same here)")
    else:
        print(f"  positions {native.describe()}, the commands' default: {native.footprint(units=False)}; "
              "--frame local takes the x, y above (local metres)")
    if grid.attrs.get("metric_resampling"):
        print(f"  metric    {grid.attrs['metric_resampling']}")
    errors = local_frame_error(grid.attrs, grid.ys)
    if errors is not None:
        south, north = errors
        print(f"  distances local metres with one east-west scale for every row: east-west lengths "
              f"{100 * south:+.2f} % off at the southern edge, {100 * north:+.2f} % at the northern edge "
              "(--metric resamples onto a metric grid)")


# ------------------------------------------------------------------ main
_COMMANDS = {"compare": _compare, "simplify": _simplify, "los": _los, "viewshed": _viewshed,
             "cumulative": _cumulative, "relocate": _relocate, "info": _info}


def main(argv=None) -> int:
    """Entry point of the ``terrainvis`` console script."""
    import signal

    from ..core.runner import Interrupted

    def terminated(signum, frame):
        raise Interrupted(signum)

    # SIGTERM ends the command like Ctrl-C does (cleanly, with a message), from the start
    previous = signal.signal(signal.SIGTERM, terminated) if _main_thread() else None
    name = "terrainvis"
    try:
        try:
            args = _parser().parse_args(argv)
        except _ParseError as exc:
            print(exc, file=sys.stderr)
            return 2
        name = f"terrainvis {args.command}"
        with _one_line_warnings(name):
            return _run(args, name)
    except BrokenPipeError:  # the reader went away (| head): stop quietly, as Unix tools do
        _stdout_to_devnull()
        return 128 + signal.SIGPIPE
    except Interrupted as exc:
        note = "; finished units are in results.csv (use --resume)" if name == "terrainvis compare" else ""
        print(f"{name}: interrupted ({exc}){note}", file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        return 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _stdout_to_devnull() -> None:
    """Point stdout at /dev/null, so the interpreter's last flush does not fail on the closed pipe again."""
    import os

    with contextlib.suppress(Exception):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())


@contextlib.contextmanager
def _one_line_warnings(name: str):
    """Warnings as one line each, prefixed with the command (no source file and line)."""
    import warnings

    def show(message, category, filename, lineno, file=None, line=None):
        print(f"{name}: warning: {message}", file=sys.stderr if file is None else file)

    with warnings.catch_warnings():
        warnings.showwarning = show
        yield


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


def _run(args, name: str) -> int:
    from ..core.fileio import OutputError
    from ..errors import NodataError, SimplificationError

    try:
        return _COMMANDS[args.command](args)
    except BrokenPipeError:
        raise
    except SimplificationError as exc:
        print(f"{name}: failed: {exc}", file=sys.stderr)
        return 1
    except NodataError as exc:
        rows, cols = exc.shape
        print(f"{name}: error: {exc.operation} needs a DEM without nodata, but it has {exc.n_nan:,} NaN cell(s) "
              f"out of {rows}x{cols}; add --fill nearest (or linear) to fill them, or --crop-valid to cut them "
              "away (from Python: HeightGrid.fill_nodata(), HeightGrid.valid_window())", file=sys.stderr)
        return 2
    except (ValueError, TypeError, FileNotFoundError, ImportError) as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 2
    except OutputError as exc:  # a full disk, a folder turned read-only, ...: not a usage mistake
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 1
    except MemoryError as exc:
        print(f"{name}: error: out of memory" + (f": {exc}" if str(exc) else ""), file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"{name}: error: {exc.strerror or exc}" + (f": {exc.filename}" if exc.filename else ""), file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
