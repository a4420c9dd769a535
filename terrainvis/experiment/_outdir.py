"""The output folder of ``terrainvis compare``: which files a run writes there, and which it wrote.

A run writes ``results.csv`` and ``results.settings.json`` (:class:`~terrainvis.experiment.results.ResultStore`),
``tables.md``, the figures and ``simplified/<terrain>__<method>__level<k>.npz`` (or
``__max_error<E>.npz`` in a run budgeted in vertical error), and holds
``results.lock`` while it runs (:class:`~terrainvis.core.fileio.RunLock`); ``terrainvis evaluate`` keeps
its rows in ``results.partial.csv`` (and ``results.partial.settings.json``) until its run is
complete, then renames them over ``results.csv``, so an earlier run stays whole until the new
one exists. A file is an earlier
run's only when it can be recognised as written by terrainvis: the settings file by its
settings, ``results.csv`` by its columns beside such a settings file, ``tables.md`` by its
first line, the figures by the mark terrainvis puts in their PNG text
(:data:`terrainvis.io.FIGURE_SOFTWARE`), the simplified terrains by the terrainvis ``.npz`` format.
:func:`earlier_run` lists those, so ``--overwrite`` removes exactly them;
:func:`foreign_files` lists the files at the names a run writes that terrainvis did not
write, which a run refuses to replace.
"""

from __future__ import annotations

import contextlib
import json
import re
import struct
from pathlib import Path

from ..io import FIGURE_SOFTWARE

__all__ = ["RESULTS", "PARTIAL", "TABLES", "SIMPLIFIED", "LOCK", "figure_names", "earlier_run", "foreign_files",
           "written_by_terrainvis", "describe", "remove"]

RESULTS = "results.csv"
#: The rows of an ``evaluate`` run that has not finished (renamed to :data:`RESULTS` when it has).
PARTIAL = "results.partial.csv"
TABLES = "tables.md"
SIMPLIFIED = "simplified"
LOCK = "results.lock"
#: Figures every run may write, whatever its terrains and relocations.
FIXED_FIGURES = ("accuracy_vs_size.png", "accuracy_vs_budget.png", "accuracy_vs_distance.png", "accuracy_vs_zoom.png")
#: The first line of every ``tables.md`` a run writes.
TABLES_TITLE = "# terrainvis compare"
#: Settings every stored settings file of ``compare`` holds, whatever its version.
_SETTINGS_KEYS = frozenset({"terrains", "methods", "levels", "relocations", "seed", "n_points", "n_sets"})
#: Columns every results file of ``compare`` starts with, whatever its version.
_RESULT_COLUMNS = ("terrain", "set", "method")


def figure_names(terrains, relocations) -> list[str]:
    """The figures a run on ``terrains`` with ``relocations`` may write."""
    return list(FIXED_FIGURES) + [f"tradeoff_{r}.png" for r in relocations] + [f"views_{t}.png" for t in terrains]


# ---------------------------------------------------------------------- recognising our files
def _png_text(path: Path, limit: int = 1 << 20) -> dict:
    """The ``tEXt`` chunks of a PNG before its image data (empty when it is no PNG)."""
    out = {}
    with contextlib.suppress(OSError, struct.error, ValueError):
        with open(path, "rb") as fh:
            if fh.read(8) != b"\x89PNG\r\n\x1a\n":
                return {}
            while fh.tell() < limit:
                head = fh.read(8)
                if len(head) < 8:
                    break
                length, kind = struct.unpack(">I4s", head)
                if kind in (b"IDAT", b"IEND"):
                    break
                body = fh.read(length)
                fh.read(4)  # the chunk's CRC
                if kind == b"tEXt" and b"\0" in body:
                    key, _, value = body.partition(b"\0")
                    out[key.decode("latin-1")] = value.decode("latin-1")
    return out


def _settings_file(out: Path, results: str = RESULTS) -> Path:
    from .results import settings_path

    return settings_path(out / results)


def _stored_settings(out: Path, results: str = RESULTS) -> dict | None:
    """The earlier run's settings stored beside ``results`` (:data:`RESULTS` or :data:`PARTIAL`),
    or None when there is no settings file terrainvis wrote."""
    with contextlib.suppress(OSError, ValueError):
        stored = json.loads(_settings_file(out, results).read_text(encoding="utf-8"))
        if isinstance(stored, dict) and _SETTINGS_KEYS <= stored.keys():
            return stored
    return None


def _first_line(path: Path) -> str:
    with contextlib.suppress(OSError), open(path, "rb") as fh:
        return fh.readline(4096).decode("utf-8", "replace").rstrip("\r\n")
    return ""


def _terrainvis_npz(path: Path) -> bool:
    from ..io._common import FORMAT

    with contextlib.suppress(Exception):
        import numpy as np

        with np.load(path, allow_pickle=False) as a:
            return "format" in a.files and str(a["format"]) == FORMAT
    return False


def written_by_terrainvis(path) -> bool:
    """Whether ``path``, a file at one of the names a run writes in its folder, was written by terrainvis.

    ``results.csv`` and ``tables.md`` count only beside a settings file terrainvis wrote
    (the settings are stored first, before any row).
    """
    p = Path(path)
    if not p.is_file():
        return False
    out = p.parent.parent if p.parent.name == SIMPLIFIED else p.parent
    if p.parent.name == SIMPLIFIED and p.suffix == ".npz":
        return _terrainvis_npz(p)
    for results in (RESULTS, PARTIAL):
        if p.name == _settings_file(out, results).name:
            return _stored_settings(out, results) is not None
        if p.name == results:
            return (_stored_settings(out, results) is not None
                    and _first_line(p).split(",")[:3] == list(_RESULT_COLUMNS))
    if p.name == TABLES:
        return _first_line(p) == TABLES_TITLE
    if p.name == LOCK:
        with contextlib.suppress(OSError, ValueError):
            text = p.read_text(encoding="utf-8").strip()
            return text == "" or "pid" in json.loads(text)
        return False
    if p.suffix == ".png":
        return _png_text(p).get("Software", "").startswith(FIGURE_SOFTWARE + " ")
    return False


def _leftover(name: str, of: str) -> bool:
    """A temporary file of an atomic write of ``of`` cut off by SIGKILL (``tempfile.mkstemp``'s names)."""
    stem, suffix = of, Path(of).suffix
    return re.fullmatch(re.escape(f".{stem}.") + r"[a-z0-9_]{8}" + re.escape(suffix), name) is not None


def _recorded(out: Path) -> tuple[list, list, list]:
    """The terrains, methods and relocations the earlier run recorded in its settings (a finished
    run's and an unfinished ``evaluate`` run's together)."""
    terrains, methods, relocations = {}, {}, {}
    for results in (RESULTS, PARTIAL):
        stored = _stored_settings(out, results) or {}
        terrains.update(dict.fromkeys(stored.get("terrains") or []))
        methods.update(dict.fromkeys(stored.get("methods") or []))
        relocations.update(dict.fromkeys(stored.get("relocations") or []))
    return list(terrains), list(methods), list(relocations)


def _candidates(out: Path, terrains, methods, relocations) -> list[Path]:
    """Every existing file at a name a run on these terrains, methods and relocations writes."""
    from ..relocation import registry as relocation

    fixed = [out / RESULTS, _settings_file(out), out / PARTIAL, _settings_file(out, PARTIAL), out / TABLES]
    relocations = list(dict.fromkeys(list(relocations) + list(relocation.RELOCATIONS)))
    found = [p for p in fixed if p.is_file()]
    found += [out / f for f in figure_names(terrains, relocations) if (out / f).is_file()]
    folder = out / SIMPLIFIED
    prefixes = [f"{t}__{m}__" for t in terrains for m in methods]
    if folder.is_dir():
        for q in folder.iterdir():
            if q.is_file() and q.suffix == ".npz" and any(
                    q.name.startswith(p) and _step_name(q.name[len(p):-len(".npz")]) for p in prefixes):
                found.append(q)
    return found


def _step_name(text: str) -> bool:
    """Whether ``text`` names a unit's step in a simplified terrain's file: ``level<k>`` or ``max_error<E>``
    (:func:`terrainvis.experiment.units.simplified_path`)."""
    if text.startswith("level"):
        return text[len("level"):].isdigit()
    if text.startswith("max_error"):
        with contextlib.suppress(ValueError):
            return float(text[len("max_error"):]) > 0
    return False


def earlier_run(out) -> list[Path]:
    """The files an earlier run wrote in the folder ``out`` (none: no earlier run).

    Only files recognised as written by terrainvis (:func:`written_by_terrainvis`):
    ``results.csv``, its settings file, an unfinished ``evaluate`` run's
    ``results.partial.csv`` and its settings file, ``tables.md``, their leftover temporary
    files (a write cut off by SIGKILL), the figures of the terrains and relocations the run
    recorded, and its simplified terrains (``simplified/<terrain>__<method>__level<k>.npz``).
    """
    out = Path(out)
    if _stored_settings(out) is None and _stored_settings(out, PARTIAL) is None and not (out / TABLES).is_file():
        return []
    terrains, methods, relocations = _recorded(out)
    found = [p for p in _candidates(out, terrains, methods, relocations) if written_by_terrainvis(p)]
    if not found:
        return []
    names = (RESULTS, _settings_file(out).name, PARTIAL, _settings_file(out, PARTIAL).name, TABLES)
    found += [q for q in out.iterdir() if q.is_file() and any(_leftover(q.name, n) for n in names)]
    return sorted(set(found))


def foreign_files(out, terrains=(), methods=(), relocations=()) -> list[Path]:
    """Files terrainvis did not write at the names a run on these terrains, methods and relocations writes.

    A run refuses to start over them: it would replace them (``--overwrite`` removes
    only what :func:`earlier_run` lists).
    """
    out = Path(out)
    if not out.is_dir():
        return []
    names = _candidates(out, terrains, methods, relocations)
    if (out / LOCK).is_file():
        names.append(out / LOCK)
    return sorted(p for p in set(names) if not written_by_terrainvis(p))


def describe(files) -> str:
    """A short account of an earlier run's files: ``results.csv, tables.md, 6 figures and 28 simplified terrains``
    (an unfinished ``evaluate`` run's rows: ``the unfinished run's results.partial.csv``)."""
    names = [p.name for p in files]
    parts = [n if n != PARTIAL else f"the unfinished run's {n}" for n in (RESULTS, PARTIAL, TABLES) if n in names]
    figures = sum(1 for p in files if p.suffix == ".png")
    simplified = sum(1 for p in files if p.parent.name == SIMPLIFIED)
    if figures:
        parts.append(f"{figures} figure{'s' if figures != 1 else ''}")
    if simplified:
        parts.append(f"{simplified} simplified terrain{'s' if simplified != 1 else ''}")
    if not parts:
        parts.append(f"{len(files)} file{'s' if len(files) != 1 else ''}")
    return ", ".join(parts[:-1]) + (" and " if len(parts) > 1 else "") + parts[-1]


def remove(out, files) -> None:
    """Remove ``files`` (an earlier run's), then ``simplified/`` when that left it empty."""
    for p in files:
        with contextlib.suppress(FileNotFoundError):
            p.unlink()
    folder = Path(out) / SIMPLIFIED
    with contextlib.suppress(OSError):
        if folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()
