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
* ``terrainvis tiles DEM OUT_DIR --method M --zoom MIN MAX`` writes a Cesium quantized-mesh
  tileset, each tile simplified by the method.
* ``terrainvis info DEM`` describes a terrain.
* ``terrainvis compile`` compiles every numba kernel ahead, into numba's cache (CI images,
  containers).

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

from . import compare, compile_ahead, cumulative, evaluate, info, los, relocate, simplify, site, tiles, viewshed
from . import _common
from ._common import ParseError, Parser

__all__ = ["main"]


#: The commands, in the order ``terrainvis --help`` lists them: each module declares its
#: sub-parser (``add_parser(sub)``) and runs it (``run(args) -> exit status``).
COMMANDS = {"compare": compare, "evaluate": evaluate, "simplify": simplify, "los": los, "viewshed": viewshed,
            "cumulative": cumulative, "site": site, "relocate": relocate, "tiles": tiles, "info": info,
            "compile": compile_ahead}


def _parser(argv=None) -> argparse.ArgumentParser:
    """The parser of ``terrainvis``: the command named in ``argv`` with all its flags, the others light.

    A command's flags can need heavy imports (``compare``'s come from the experiment's
    options, which import pandas and the simplifiers), and a command must not pay for the
    others': the other commands get a sub-parser with only their ``HELP`` line, which is all
    ``terrainvis --help`` and an unknown command's message show. ``argv`` None: every
    command with all its flags (for documentation and tests).
    """
    p = Parser(prog="terrainvis", description="How much line of sight does terrain simplification cost?")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    wanted = None if argv is None else _command_in(argv)
    for name, command in COMMANDS.items():
        if argv is None or name == wanted:
            command.add_parser(sub)
        else:
            sub.add_parser(name, help=command.HELP)
    return p


def _command_in(argv) -> str | None:
    """The command ``argv`` names (its first word: ``terrainvis`` has no option of its own but -h)."""
    return argv[0] if argv and argv[0] in COMMANDS else None


def console() -> None:
    """The ``terrainvis`` script and ``python -m terrainvis``: :func:`main` in a process of its own.

    OpenBLAS runs on one thread unless ``OPENBLAS_NUM_THREADS`` says otherwise: no command
    does BLAS work, and the threads OpenBLAS starts when numpy loads it (and numba, looking
    for BLAS, loads scipy's) busy-wait for a while, which on 2 cores took about 0.1 s of a
    warm 3601² ``viewshed`` command (``benchmarks/bench_startup.py``). The objects made
    while a command loads its kernels are frozen out of the garbage collector's passes
    (:func:`terrainvis.cli._common.loading_kernels`), which only a process of its own may do.
    """
    import os

    if "numpy" not in sys.modules:  # read when OpenBLAS loads
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    _common.own_process()
    sys.exit(main())


def main(argv=None) -> int:
    """The command line: run the command ``argv`` names (default ``sys.argv[1:]``), return its exit status.

    The ``terrainvis`` script calls it through :func:`console`."""
    import signal

    from ..core.interrupt import child_calls, kept_interrupts, raise_pending
    from ..errors import Interrupted

    name = "terrainvis"
    _common.on_interrupt()  # no note of an earlier command of this process
    # SIGTERM ends the command like Ctrl-C does (cleanly, with a message), from the start;
    # an interrupt that C code swallowed still ends it (kept_interrupts)
    try:
        with kept_interrupts():
            try:
                argv = sys.argv[1:] if argv is None else list(argv)
                wanted = _command_in(argv)
                # building a command's parser can import the simplifiers, whose plugins warn when
                # they fail to load: one line too, as every warning of the command
                with _one_line_warnings(f"terrainvis {wanted}" if wanted else name):
                    args = _parser(argv).parse_args(argv)
            except ParseError as exc:
                print(exc, file=sys.stderr)
                return 2
            name = f"terrainvis {args.command}"
            with _one_line_warnings(name), _file_names_print(), child_calls():
                status = _run(args, name)
                raise_pending()  # swallowed where no kernel came after it: the run is still not a success
                return status
    except BrokenPipeError:  # the reader went away (| head): stop quietly, as Unix tools do
        _stdout_to_devnull()
        return 128 + signal.SIGPIPE
    except Interrupted as exc:
        print(f"{name}: interrupted ({exc}){_common.on_interrupt()}", file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:
        print(f"{name}: interrupted{_common.on_interrupt()}", file=sys.stderr)
        return 130


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


@contextlib.contextmanager
def _file_names_print():
    """stdout and stderr write a file name that is not UTF-8 as its own bytes, as ``ls`` and GDAL do.

    Python decodes such a name with surrogate escapes, which a strict UTF-8 stream refuses
    (stdout is strict by default). The command would then fail after its work was done,
    on the line that says where it wrote. The streams' previous error handlers are put
    back afterwards (``main`` may be called from Python)."""
    previous = []
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        errors = getattr(stream, "errors", None)
        if reconfigure is not None and errors == "strict":
            with contextlib.suppress(Exception):
                reconfigure(errors="surrogateescape")
                previous.append((stream, errors))
    try:
        yield
    finally:
        for stream, errors in previous:
            with contextlib.suppress(Exception):
                stream.flush()
                stream.reconfigure(errors=errors)


def _run(args, name: str) -> int:
    from ..core.fileio import OutputError
    from ..errors import WorkersDied
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

