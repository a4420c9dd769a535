"""The ``terrainvis`` command line.

* ``terrainvis compare`` runs the paper's experiment (by default on the five bundled
  120x120 terrains and the real Jacksboro DEM), prints Tables 1-4, the cost table and
  the paper's findings, and writes ``results.csv``, ``tables.md``, figures and the
  simplified terrains (``simplified/``) into ``--out``.
* ``terrainvis evaluate DEM SIMPLIFIED...`` measures simplifications made elsewhere (meshes,
  rasters) as ``compare`` measures a method's, optionally beside built-in methods.
* ``terrainvis simplify DEM -m METHOD -l LEVEL -o OUT`` simplifies a DEM and writes the
  result as a grid (``.tif``, ``.asc``, ``.npz``) or a mesh (``.ply``, ``.obj``, ``.stl``,
  ``.glb``; TINs also ``.npz``).
* ``terrainvis los DEM --from X Y --to X Y`` checks lines of sight.
* ``terrainvis viewshed DEM --observer X Y -o viewshed.tif`` writes an observer's viewshed.
* ``terrainvis cumulative DEM --observers OBS.csv -o counts.tif`` counts the observers that
  see each sample (a cumulative viewshed).
* ``terrainvis site DEM --grid STEP -k K`` chooses K observers that together see the most.
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

from . import compare, cumulative, evaluate, info, los, relocate, simplify, site, viewshed
from ._common import ParseError, Parser

__all__ = ["main"]


#: The commands, in the order ``terrainvis --help`` lists them: each module declares its
#: sub-parser (``add_parser(sub)``) and runs it (``run(args) -> exit status``).
COMMANDS = {"compare": compare, "evaluate": evaluate, "simplify": simplify, "los": los, "viewshed": viewshed,
            "cumulative": cumulative, "site": site, "relocate": relocate, "info": info}


def _parser() -> argparse.ArgumentParser:
    p = Parser(prog="terrainvis", description="How much line of sight does terrain simplification cost?")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS.values():
        command.add_parser(sub)
    return p


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
        except ParseError as exc:
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
    from ..core.runner import WorkersDied
    from ..errors import NodataError, SimplificationError

    try:
        return COMMANDS[args.command].run(args)
    except BrokenPipeError:
        raise
    except SimplificationError as exc:
        print(f"{name}: failed: {exc}", file=sys.stderr)
        return 1
    except WorkersDied as exc:  # no script to guard here: the advice for one means nothing
        print(f"{name}: failed: the worker processes died ({exc.cause}); the units finished before are kept "
              "(--resume continues); --workers 1 runs them in this process and shows why", file=sys.stderr)
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

