"""A results table on disk that survives interrupts: ``results.csv`` and its settings file.

:class:`ResultStore` is the one writer of an experiment's CSV:

* Each finished unit's rows are added with :meth:`ResultStore.add`, which rewrites the
  whole file atomically (a temporary file in the same folder, renamed into place), so
  the file on disk always holds every unit that finished and never a damaged row.
* The run's settings are stored beside it (``<name>.settings.json``). Resuming checks
  them strictly: a resume with different settings is refused with a message naming the
  settings that differ and the two ways forward.
* On resume, the units already complete are kept and reported by :attr:`done`; units
  with missing rows or an error are run again. A cut-off last line (a file damaged
  outside terrainvis, e.g. a full disk) is dropped with a warning.
"""

from __future__ import annotations

import csv
import io
import json
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from ..core.fileio import atomic_write_text

__all__ = ["ResultStore", "settings_path", "lock_path", "read_results", "as_table"]


def settings_path(csv_path) -> Path:
    """The settings file stored beside a results CSV: ``results.csv`` -> ``results.settings.json``."""
    p = Path(csv_path)
    return p.with_name(p.stem + ".settings.json")


def lock_path(csv_path) -> Path:
    """The lock held beside a results CSV while a run writes it: ``results.csv`` -> ``results.lock``."""
    p = Path(csv_path)
    return p.with_name(p.stem + ".lock")


#: Columns read as text whatever they hold (a terrain named "2024" stays a name).
TEXT_COLUMNS = ("terrain", "method", "kind", "relocation", "predicate", "measure", "stopped_by", "repair", "error")


def _read_csv(text: str, columns) -> pd.DataFrame:
    dtype = {c: str for c in TEXT_COLUMNS if c in columns}
    df = pd.read_csv(io.StringIO(text), keep_default_na=True, dtype=dtype)
    df["error"] = _error_column(df["error"])
    return df


def _frame(rows, columns) -> pd.DataFrame:
    df = pd.DataFrame(list(rows), columns=list(columns))
    df["error"] = _error_column(df["error"])
    return df


def _error_column(values: pd.Series) -> pd.Series:
    """The ``error`` column: the message of a unit that failed, NA (missing) for one that did not.

    One convention whether the rows come from :func:`terrainvis.compare` or from the CSV
    (which writes NA as an empty field): ``df[df.error.isna()]`` keeps the good rows.
    """
    text = values.astype(object)
    return text.where(text.notna() & (text != ""), np.nan)


def as_table(rows, columns) -> pd.DataFrame:
    """Rows (dicts) as the frame a results CSV reads back as: the same values and dtypes
    whether or not the run was written to disk."""
    return _read_csv(_csv_text(_frame(rows, columns), header=True), columns)


def _csv_text(df: pd.DataFrame, header: bool) -> str:
    buf = io.StringIO()
    df.to_csv(buf, index=False, header=header, lineterminator="\n")
    return buf.getvalue()


def read_results(path, columns, optional=()) -> pd.DataFrame:
    """Read a results CSV written by :class:`ResultStore`, dropping a cut-off last line.

    A file written before some of ``optional`` existed (its header is ``columns`` without
    them, in the same order) reads with them empty (NaN).

    Raises
    ------
    ValueError
        When the file is not a results file of these columns, or is damaged before its
        last line.
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"results file {str(path)!r} is a folder, not a file")
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines(keepends=True)
    if not lines:
        return _frame([], columns)
    header = next(csv.reader([lines[0]]))
    missing = [c for c in columns if c not in header]
    if header != [c for c in columns if c not in missing] or not set(missing) <= set(optional):
        missing = [c for c in missing if c not in optional] or missing
        raise ValueError(
            f"{str(path)!r} is not a terrainvis results file of this version (missing columns {missing}; a file "
            "written by an older terrainvis lacks the columns added since): write to a new output instead"
            if missing else f"{str(path)!r} has its columns in another order than this version writes"
        )
    body = lines[1:]
    # A line without its newline, or with the wrong number of fields, can only be the
    # last one (the file is rewritten atomically): a write cut off from outside.
    if body:
        last = body[-1]
        fields = next(csv.reader([last]), [])
        if not last.endswith("\n") or len(fields) != len(header):
            warnings.warn(
                f"{path.name}: dropped a cut-off last row (a damaged write); its unit will run again",
                RuntimeWarning, stacklevel=2,
            )
            body = body[:-1]
    for i, line in enumerate(body):
        if len(next(csv.reader([line]), [])) != len(header):
            raise ValueError(f"{str(path)!r} is damaged at line {i + 2}: it does not have {len(header)} fields")
    df = _read_csv(lines[0] + "".join(body), header)
    return df.assign(**{c: np.nan for c in missing})[list(columns)]


class ResultStore:
    """The CSV of one experiment and the settings it was run with.

    Parameters
    ----------
    path : str or Path
        The CSV. Its folder is created when missing.
    settings : dict
        JSON-serialisable description of everything that determines the rows (methods,
        levels, point sets, the terrains' fingerprints, ...).
    columns : sequence of str
        The CSV's columns, in order.
    unit_key : sequence of str
        Columns identifying a unit (the rows one task produces).
    rows_per_unit : callable
        ``rows_per_unit(key) -> int``: how many error-free rows a complete unit has.
    resume : bool
        Keep the complete units of an existing file (with the same settings).
    absent : dict, optional
        What a setting missing from a stored settings file means (a file written before
        that setting existed): resuming such a file compares these values instead.
    optional : sequence of str, optional
        Columns a file written before they existed may lack and still resume (its rows
        read them as NaN, and the file is written back with them); a file lacking any
        other column is refused.
    """

    def __init__(self, path, settings: dict, columns, unit_key, rows_per_unit, *, resume: bool,
                 absent: dict | None = None, optional=()):
        self.path = Path(path)
        self.columns = list(columns)
        self.unit_key = list(unit_key)
        self.settings = json.loads(json.dumps(settings))  # normalised (tuples -> lists)
        self.absent = json.loads(json.dumps(absent or {}))
        self.optional = tuple(optional)
        self.done: set = set()
        self._parts: list[str] = []
        if self.path.is_dir():
            raise ValueError(f"out_csv {str(self.path)!r} is a folder; give the path of a .csv file inside it")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if not resume and self.path.exists() and not self._ours():
            raise ValueError(
                f"out_csv {str(self.path)!r} exists and was not written by terrainvis (no settings file "
                f"{settings_path(self.path).name!r} beside it, or not a results file's columns); terrainvis never "
                "replaces a file it did not write: choose another out_csv"
            )
        if resume and self.path.exists():
            self._resume(rows_per_unit)
        else:
            atomic_write_text(settings_path(self.path), json.dumps(self.settings, indent=1, sort_keys=True) + "\n")
        self._write()

    def _ours(self) -> bool:
        """Whether the existing file is a results file terrainvis wrote: a settings file it wrote
        beside it, and a header that holds the unit's columns."""
        try:
            stored = json.loads(settings_path(self.path).read_text(encoding="utf-8"))
            with open(self.path, encoding="utf-8", errors="replace") as fh:
                header = next(csv.reader([fh.readline(1 << 16)]), [])
        except (OSError, ValueError):
            return False
        return isinstance(stored, dict) and (not header or set(self.unit_key) <= set(header))

    # ---------------------------------------------------------------- resume
    def _resume(self, rows_per_unit) -> None:
        spath = settings_path(self.path)
        if not spath.exists():
            raise ValueError(
                f"cannot resume {str(self.path)!r}: its settings file {spath.name!r} is missing (the file was "
                "written by an older terrainvis, or not by terrainvis); write to a new output instead"
            )
        try:
            stored = json.loads(spath.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise ValueError(f"cannot resume {str(self.path)!r}: its settings file is unreadable ({exc})") from None
        diff = _differences({**self.absent, **stored}, self.settings)
        if diff:
            raise ValueError(
                f"cannot resume {str(self.path)!r}: it was written with other settings ("
                + "; ".join(diff)
                + "). Either write to a new output (another --out, or another out_csv), or resume with the "
                "same settings as before"
            )
        old = read_results(self.path, self.columns, self.optional)
        keep = np.zeros(len(old), dtype=bool)
        for key, idx in old.groupby(self.unit_key, sort=False).groups.items():
            key = tuple(key) if isinstance(key, tuple) else (key,)
            rows = old.loc[idx]
            if len(rows) == rows_per_unit(key) and rows["error"].isna().all():
                self.done.add(key)
                keep[old.index.get_indexer(idx)] = True
        kept = old[keep]
        if len(kept):
            self._parts.append(_csv_text(kept, header=False))

    # ---------------------------------------------------------------- writing
    def add(self, rows: list[dict]) -> None:
        """Add one finished unit's rows and rewrite the file atomically."""
        if rows:
            self._parts.append(_csv_text(_frame(rows, self.columns), header=False))
        self._write()

    def rows(self) -> pd.DataFrame:
        """Every row held (the kept ones of a resumed file and those added since)."""
        return _read_csv(self._header() + "".join(self._parts), self.columns)

    def finish(self, df: pd.DataFrame) -> None:
        """Write the final table (the same rows, sorted) in place of the unit-by-unit file."""
        self._parts = [_csv_text(df[self.columns], header=False)] if len(df) else []
        self._write()

    def _header(self) -> str:
        return _csv_text(pd.DataFrame(columns=self.columns), header=True)

    def _write(self) -> None:
        atomic_write_text(self.path, self._header() + "".join(self._parts))


def _differences(stored: dict, now: dict) -> list[str]:
    out = []
    for key in sorted(set(stored) | set(now)):
        a, b = stored.get(key, "(not set)"), now.get(key, "(not set)")
        if a != b:
            out.append(f"{key}: {_short(a)} before, {_short(b)} now")
    return out


def _short(value) -> str:
    text = json.dumps(value, sort_keys=True)
    return text if len(text) <= 80 else text[:77] + "..."
