"""The output folder of ``terrainvis compare``: which files a run writes there.

A run writes ``results.csv`` and ``results.settings.json`` (:class:`~terrainvis.results.ResultStore`),
``tables.md``, the figures and ``simplified/<terrain>__<method>__level<k>.npz``, and holds
``results.lock`` while it runs (:class:`~terrainvis._fileio.RunLock`). :func:`earlier_run`
finds the files an earlier run left, by these names and the terrains, methods and
relocations that run recorded, so ``--overwrite`` removes exactly those and never a file
terrainvis did not write.
"""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

__all__ = ["RESULTS", "TABLES", "SIMPLIFIED", "LOCK", "figure_names", "earlier_run", "describe", "remove"]

RESULTS = "results.csv"
TABLES = "tables.md"
SIMPLIFIED = "simplified"
LOCK = "results.lock"
#: Figures every run may write, whatever its terrains and relocations.
FIXED_FIGURES = ("accuracy_vs_size.png", "accuracy_vs_distance.png")


def figure_names(terrains, relocations) -> list[str]:
    """The figures a run on ``terrains`` with ``relocations`` may write."""
    return list(FIXED_FIGURES) + [f"tradeoff_{r}.png" for r in relocations] + [f"views_{t}.png" for t in terrains]


def _recorded(out: Path) -> tuple[list, list, list]:
    """The terrains, methods and relocations the earlier run recorded (its settings, else its rows)."""
    from .results import settings_path

    with contextlib.suppress(OSError, ValueError, AttributeError):
        stored = json.loads(settings_path(out / RESULTS).read_text(encoding="utf-8"))
        return list(stored.get("terrains") or []), list(stored.get("methods") or []), list(
            stored.get("relocations") or [])
    with contextlib.suppress(Exception):
        import pandas as pd

        rows = pd.read_csv(out / RESULTS, usecols=["terrain", "method", "relocation"], dtype=str)
        return [sorted(set(rows[c].dropna())) for c in ("terrain", "method", "relocation")]
    return [], [], []


def earlier_run(out) -> list[Path]:
    """The files of an earlier run in the folder ``out`` (existing ones only; none: no earlier run).

    ``results.csv``, its settings file, ``tables.md``, their leftover temporary files (a
    write cut off by SIGKILL), the figures of the terrains and relocations the run
    recorded, and its simplified terrains (``simplified/<terrain>__<method>__level<k>.npz``).
    """
    from . import relocation
    from .results import settings_path

    out = Path(out)
    fixed = [out / RESULTS, settings_path(out / RESULTS), out / TABLES]
    if not any(p.is_file() for p in fixed):
        return []
    terrains, methods, relocations = _recorded(out)
    found = [p for p in fixed if p.is_file()]
    leftovers = tuple(f".{p.name}." for p in fixed)  # atomic writes cut off by SIGKILL
    found += [q for q in out.iterdir() if q.is_file() and q.name.startswith(leftovers)]
    relocations = list(dict.fromkeys(relocations + list(relocation.RELOCATIONS) + [relocation.ORACLE]))
    found += [out / f for f in figure_names(terrains, relocations) if (out / f).is_file()]
    folder = out / SIMPLIFIED
    prefixes = [f"{t}__{m}__level" for t in terrains for m in methods]
    if folder.is_dir():
        for q in folder.iterdir():
            if q.is_file() and q.suffix == ".npz" and any(
                    q.name.startswith(p) and q.name[len(p):-len(".npz")].isdigit() for p in prefixes):
                found.append(q)
    return sorted(set(found))


def describe(files) -> str:
    """A short account of an earlier run's files: ``results.csv, tables.md, 6 figures and 28 simplified terrains``."""
    names = [p.name for p in files]
    parts = [n for n in (RESULTS, TABLES) if n in names]
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
