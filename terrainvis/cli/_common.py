"""What the commands share: the one-line errors, the argument types and flags declared once, reading a terrain.

Flags that several commands take (``--fill``/``--crop-valid``, ``--frame``/``--metric``,
``--target-height``, ``--max-distance``, ``--curvature``/``--earth-radius``) are declared
here once, by ``add_*`` functions, so that they read and fail the same everywhere.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path


class UsageError(ValueError):
    """A mistake on the command line: reported in one line, exit status 2."""


#: What the running command's "interrupted" line adds: where its finished work is (:func:`on_interrupt`).
_INTERRUPT_NOTE = [""]


def on_interrupt(note: str = "") -> str:
    """Set what an interrupt of the running command adds to its one line ("; the ... are in X (--resume
    continues)"), once it writes work that survives one; the note before."""
    before, _INTERRUPT_NOTE[0] = _INTERRUPT_NOTE[0], note
    return before


class ParseError(ValueError):
    """argparse's complaint, reported in one line by :func:`main` (exit status 2)."""


class Parser(argparse.ArgumentParser):
    """argparse with its errors on one line (no usage block), like every other error of the command line."""

    def error(self, message):
        raise ParseError(f"{self.prog}: error: {message} (see {self.prog} --help)")


def number_arg(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def height_arg(text: str) -> float:
    """A height above the surface: finite and >= 0 (a negative eye height would stand underground)."""
    value = number_arg(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a height >= 0 above the surface, got {text!r}")
    return value


def distance_arg(text: str) -> float:
    value = number_arg(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a distance >= 0, got {text!r}")
    return value


def method_arg(text: str) -> str:
    """A registered method's name; an unknown one says how a method of one's own reaches the command line."""
    from simplifiers import METHODS

    if text not in METHODS:
        raise argparse.ArgumentTypeError(
            f"unknown method {text!r}: the methods are {', '.join(METHODS)}; simplifiers.register() adds a method of "
            "your own to its Python process only: the command line sees one through a plugin, an entry point of the "
            "group 'terrainvis.simplifiers' (examples/plugin/README.md)")
    return text


def add_target_height(p) -> None:
    p.add_argument("--target-height", type=height_arg, default=0.0, help="target height above the surface, >= 0 (default 0)")


def add_max_distance(p, help_text: str) -> None:
    p.add_argument("--max-distance", type=distance_arg, default=None, help=help_text)


def add_field_of_view(p) -> None:
    """``--azimuth``, ``--vertical`` and ``--min-distance``: a field of view, beside ``--max-distance``."""
    p.add_argument("--azimuth", nargs=2, type=number_arg, default=None, metavar=("START", "END"),
                   help="field of view: only samples whose direction from the observer lies from START to END, "
                        "degrees clockwise from north (the grid's +y axis), each in [0, 360], both inclusive; "
                        "START > END wraps through north (300 60); 0 360 is the full circle")
    p.add_argument("--vertical", nargs=2, type=number_arg, default=None, metavar=("LOW", "HIGH"),
                   help="field of view: only samples whose elevation angle from the eye (the target height "
                        "included, lowered by the earth's curvature) lies from LOW to HIGH degrees, each in "
                        "[-90, 90], LOW <= HIGH")
    p.add_argument("--min-distance", type=distance_arg, default=None,
                   help="field of view: only samples at least this horizontal distance from the observer")


def sight_args(args):
    """The one :class:`~terrainvis.visibility.Sight` of a command's flags (``--height``, ``--target-height``,
    ``--curvature``, ``--earth-radius`` and the field of view), checked before anything is computed (a
    mistake in the field of view names its flag)."""
    from ..visibility.viewsheds.field_of_view import CLI_NAMES
    from ..visibility.sight import Sight

    try:
        return Sight.make(observer_height=args.height, target_height=args.target_height, curvature=args.curvature,
                          earth_radius=args.earth_radius, azimuth=args.azimuth, vertical=args.vertical,
                          min_distance=args.min_distance, max_distance=args.max_distance, names=CLI_NAMES)
    except (TypeError, ValueError) as exc:
        raise UsageError(str(exc)) from None


def add_nodata(p) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--fill", choices=["nearest", "linear"], default=None,
                   help="fill nodata cells first (nearest sample, or linear inside the valid hull)")
    g.add_argument("--crop-valid", action="store_true", help="cut the DEM to its largest window without nodata")


def add_positions(p, *, frame: bool = True) -> None:
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


def coefficient_arg(text: str) -> float:
    """An earth curvature coefficient: finite and >= 0 (GDAL's -cc)."""
    value = number_arg(text)
    if value < 0:
        raise argparse.ArgumentTypeError(
            f"expected a coefficient >= 0 (0 flat, 1 geometric, 0.85714 GDAL's), got {text!r}")
    return value


def radius_arg(text: str) -> float:
    value = number_arg(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a radius > 0, got {text!r}")
    return value


def add_earth(p) -> None:
    """``--curvature`` and ``--earth-radius`` of the visibility commands (flat by default, as the API)."""
    p.add_argument("--curvature", type=coefficient_arg, default=0.0,
                   help="earth curvature and refraction coefficient, GDAL's -cc: 0 a flat earth (the default, as the "
                        "Python API and the paper), 1 geometric curvature, 0.85714 standard refraction (gdal_viewshed's "
                        "default); the command prints the model it used")
    p.add_argument("--earth-radius", type=radius_arg, default=6378137.0,
                   help="with --curvature: the earth's radius in the DEM's x/y units (default 6378137, WGS84's "
                        "semi-major axis in metres, as GDAL takes it)")


def earth_text(args) -> str:
    """The earth model a command used, for its output (one phrase)."""
    if args.curvature == 0:
        return "earth: flat (curvature 0; --curvature 0.85714 for gdal_viewshed's default, standard refraction)"
    name = {1.0: " (geometric)", 0.85714: " (standard refraction)"}.get(args.curvature, "")
    return f"earth: curved, coefficient {args.curvature:g}{name}, radius {args.earth_radius:,.0f}"


def read_terrain(name: str, args=None):
    """One terrain from a bundled name or a DEM file, with --fill / --crop-valid applied."""
    from ..io._names import resolve_one

    from ..core.synthetic import BUNDLED
    from ..io._sample import BUNDLED_DEMS

    # a folder named like a bundled terrain shadows nothing (only a file does): the bundled one is read
    if Path(name).is_dir() and name not in (*BUNDLED, *BUNDLED_DEMS, "jacksboro"):
        raise UsageError(f"DEM {name!r} is a folder, not a DEM file")
    if Path(name).suffix and not Path(name).exists():
        raise UsageError(f"DEM file {name!r} does not exist")
    label, grid = resolve_one(None, name, 0)
    if grid.n_nodata == grid.size:
        raise UsageError(f"DEM {name!r} has no valid sample: all {plural(grid.size, 'cell')} are nodata")
    if args is not None and getattr(args, "metric", False):
        grid = metric_grid(name, grid)
    if args is not None and getattr(args, "fill", None):
        grid = grid.fill_nodata(args.fill)
    elif args is not None and getattr(args, "crop_valid", False):
        rs, cs = grid.valid_window()
        grid = grid.crop(rs, cs)
    return label, grid


#: Mesh files the commands read as a TIN (what ``simplify -o`` writes, and ``.off``).
MESH_SUFFIXES = (".ply", ".obj", ".off", ".stl", ".glb")


def read_surface(name: str, args=None, *, command: str):
    """A terrain a command reads as it is: a TIN from a mesh file (or a TIN ``.npz``), else :func:`read_terrain`.

    ``--fill``, ``--crop-valid`` and ``--metric`` concern grids; with a TIN they are refused,
    naming ``command``.
    """
    path = Path(name)
    suffix = path.suffix.lower()
    if path.is_file() and (suffix in MESH_SUFFIXES or (suffix == ".npz" and _holds_tin(path))):
        for flag, on in (("--fill", getattr(args, "fill", None)), ("--crop-valid", getattr(args, "crop_valid", False)),
                         ("--metric", getattr(args, "metric", False))):
            if on:
                raise UsageError(f"{flag} works on a grid DEM, and {name!r} is a mesh (a TIN)")
        from ..core.validate import file_label

        return file_label(path.stem), _read_tin(path)
    if suffix in MESH_SUFFIXES and not path.exists():
        raise UsageError(f"mesh file {name!r} does not exist")
    return read_terrain(name, args)


def _holds_tin(path: Path) -> bool:
    import numpy as np

    try:
        with np.load(path, allow_pickle=False) as a:
            return "faces" in a.files
    except (OSError, ValueError):
        return False


def _read_tin(path: Path):
    from ..experiment.evaluate import _read

    from ..core.validate import file_label

    return _read(path, file_label(path.stem))


def loading_kernels(load, command: str):
    """A block during which ``load()`` runs in a helper thread: the imports and first calls
    that load a command's cached numba kernels (about half a second) beside the block's
    reading of its input (:func:`terrainvis.core.interrupt.alongside`). Its error, if any, is
    raised when the block ends.

    GDAL's decompression releases the GIL and numba's loading mostly holds it, so on two
    cores the two overlap. The block's own error or an interrupt still waits for the load to
    end (an interrupt while it loads says so on stderr): a process must not exit while
    LLVM works in another thread.
    """

    from ..core.interrupt import alongside

    def note():
        print(f"terrainvis {command}: stopping once the kernels have loaded", file=sys.stderr, flush=True)

    return _gc_paused(alongside(load, on_interrupt=note))


@contextlib.contextmanager
def _gc_paused(block):
    """``block`` (a context manager) with Python's cyclic garbage collector paused; then, in
    a process of the command's own (:func:`own_process`), every object alive is frozen out
    of the collector's later passes (:func:`gc.freeze`).

    Importing numba and loading a viewshed's kernels makes about 110,000 objects tracked by
    the collector, which live as long as the process (a full pass over them: 0.03 s); the
    collector's passes over them while they are made, during the command and when the
    process ends took about 0.2 s of a warm 3601² ``viewshed`` command of 1.0 s
    (``benchmarks/bench_startup.py``). A cold cache's compilation makes garbage too (about
    230 MB while a 1024² viewshed's kernels compile): after one in the block, the garbage
    is collected first. Called in another program's process (``main()`` from Python),
    nothing is frozen: that process's garbage stays collectable.
    """
    import gc

    def compiled() -> float:  # seconds numba has compiled in this process so far
        compiling = sys.modules.get("terrainvis.core.compiling")
        return compiling.seconds() if compiling is not None else 0.0

    was = gc.isenabled()
    before = compiled()
    gc.disable()
    try:
        with block:
            yield
    finally:
        if compiled() > before:  # a cold cache's compilation in the block: its garbage first
            gc.collect()
        if _OWN_PROCESS[0]:
            gc.freeze()
        if was:
            gc.enable()


#: Whether the command line runs in a process of its own (the ``terrainvis`` script), not inside a program's.
_OWN_PROCESS = [False]


def own_process() -> None:
    """Say that the command line runs in a process of its own (:func:`terrainvis.cli.console`)."""
    _OWN_PROCESS[0] = True


def working(command: str, what: str) -> None:
    """On a terminal, say what a long step is doing before it starts (a log gets only the results)."""

    from ..core._progress import on_a_terminal

    if on_a_terminal():
        print(f"terrainvis {command}: {what} ...", file=sys.stderr, flush=True)


#: The height flags and their names in the API: each is checked against the terrain once it is read.
_HEIGHT_FLAGS = (("height", "--height"), ("target_height", "--target-height"), ("offset", "--offset"))


def check_heights(terrain, args) -> None:
    """Refuse a height flag that float64 cannot resolve against ``terrain`` (one line naming the flag)."""
    from ..visibility.predicate import _height_above

    for dest, flag in _HEIGHT_FLAGS:
        value = getattr(args, dest, None)
        if value is not None:
            try:
                _height_above(value, flag, terrain)
            except ValueError as exc:
                raise UsageError(str(exc)) from None


def metric_grid(name: str, grid):
    """``--metric``: a lon/lat DEM resampled onto a transverse Mercator grid (:func:`terrainvis.io.to_metric`)."""
    from ..io import to_metric

    if not grid.attrs.get("geographic"):
        crs = grid.attrs.get("crs")
        raise UsageError(f"--metric resamples lon/lat DEMs; {name!r} is "
                         + (f"in {crs}, whose x, y are metres already" if crs else "not georeferenced (no CRS)"))
    return to_metric(grid)


def position_frame(grid, args):
    """The :class:`~terrainvis.core._positions.PositionFrame` of a command's positions (``--frame``)."""
    from ..core._positions import PositionFrame

    return PositionFrame(grid, getattr(args, "frame", "native"))


def outside_message(frame, xy_user, what: str = "") -> str:
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


def plural(n: int, word: str, plural: str | None = None) -> str:
    """``1 terrain``, ``2 terrains``, ``12,000 vertices`` (with ``plural`` for irregular words)."""
    return f"{n:,} {word if n == 1 else plural or word + 's'}"


def read_columns(path: str, flag: str, columns, optional=()):
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
    if table.empty:
        raise UsageError(f"{flag} {path!r} holds no row after its header: nothing to compute")
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


def dask_client(address: str):
    try:
        from dask.distributed import Client
    except ImportError:
        raise UsageError('--scheduler needs the dask extra: pip install "terrainvis[dask]"') from None
    try:
        return Client(address, timeout="10s")
    except (OSError, TimeoutError) as exc:
        raise UsageError(f"--scheduler {address!r} could not be reached within 10 s ({type(exc).__name__})") from None
