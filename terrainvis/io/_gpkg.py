"""GeoPackage line layers, written and read with Python's own sqlite3 (no GDAL needed).

A GeoPackage (OGC 12-128r, version 1.2 here) is an SQLite file with a fixed header
(``application_id`` 'GPKG', ``user_version`` 10200), the tables ``gpkg_spatial_ref_sys``
(with its three required rows: EPSG:4326 and the undefined Cartesian and geographic
systems), ``gpkg_contents`` and ``gpkg_geometry_columns``, and a feature table whose
geometry column holds GeoPackage binary geometries: the header ``'GP'``, version 0, a flags
byte (here: little-endian, an [minx, maxx, miny, maxy] envelope), the srs_id, the envelope,
then the geometry as ISO WKB. :func:`write_lines` writes a table of LINESTRING features
(one per row, two or more vertices each) atomically and reads it back before it returns;
:func:`read_lines` reads such a layer, checking what the standard requires of it.

The CRS row: with rasterio installed, the CRS text of a grid (``"EPSG:26918"``, WKT) is
stored as its WKT with its EPSG code when it has one; without rasterio a plain
``EPSG:<code>`` is stored by its code with the definition ``"undefined"``; without a CRS
the layer uses the undefined Cartesian system (srs_id -1).
"""

from __future__ import annotations

import re
import sqlite3
import struct
from pathlib import Path

import numpy as np

from ..core.fileio import atomic_path

__all__ = ["write_lines", "read_lines"]

#: 'GPKG' as the SQLite header's application_id, and the version of the standard written (1.2).
APPLICATION_ID = 0x47504B47
USER_VERSION = 10200

#: EPSG:4326 as the standard's required row defines it (WKT 1, as OGC 12-128r's examples give it).
_WGS84_WKT = (
    'GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563,AUTHORITY["EPSG","7030"]],'
    'AUTHORITY["EPSG","6326"]],PRIMEM["Greenwich",0,AUTHORITY["EPSG","8901"]],'
    'UNIT["degree",0.0174532925199433,AUTHORITY["EPSG","9122"]],AUTHORITY["EPSG","4326"]]'
)
#: The srs_id of a CRS without an EPSG code (the user range starts above the EPSG codes GDAL uses).
_CUSTOM_SRS_ID = 100000
_WKB_LINESTRING = 2
#: SQLite column types by numpy kind.
_TYPES = {"b": "BOOLEAN", "i": "INTEGER", "u": "INTEGER", "f": "DOUBLE", "O": "TEXT", "U": "TEXT"}
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def write_lines(path, lines, attributes, *, table: str = "lines", crs: str | None = None, description: str = ""):
    """Write LINESTRING features to a GeoPackage, atomically.

    Parameters
    ----------
    path : str or Path
        A ``.gpkg`` file (replaced if it exists).
    lines : (n, m, 2) array_like of float
        The vertices (x, y) of each line, m >= 2, finite.
    attributes : pandas.DataFrame
        n rows: one column per attribute (bool, integer, float or text), named like SQL
        identifiers (letters, digits, ``_``).
    table : str
        The layer's name.
    crs : str, optional
        The coordinates' CRS (``"EPSG:26918"``, WKT), as in a grid's ``attrs["crs"]``.
    description : str
        The layer's description in ``gpkg_contents``.

    Returns
    -------
    Path
    """
    p = Path(path)
    if p.suffix.lower() != ".gpkg":
        raise ValueError(f"path must end in .gpkg, got {p.name!r}")
    xy = np.asarray(lines, dtype=np.float64)
    if xy.ndim != 3 or xy.shape[1] < 2 or xy.shape[2] != 2:
        raise ValueError(f"lines must have shape (n, m >= 2, 2), got {xy.shape}")
    if not np.isfinite(xy).all():
        raise ValueError("lines must be finite")
    if len(attributes) != xy.shape[0]:
        raise ValueError(f"attributes must have one row per line ({xy.shape[0]}), got {len(attributes)}")
    for name in [table, *attributes.columns]:
        if not _NAME.match(str(name)) or str(name).lower() in ("fid", "geom"):
            raise ValueError(f"{name!r} cannot name a table or column here (letters, digits and _; not fid or geom)")
    srs = _srs_row(crs)
    with atomic_path(p) as tmp:
        tmp.unlink()  # sqlite creates its own file
        journal = tmp.with_name(tmp.name + "-journal")
        try:
            con = sqlite3.connect(tmp)
            try:
                _write(con, xy, attributes, table, srs, description)
            finally:
                con.close()
        except sqlite3.Error as exc:  # a full disk is "database or disk is full", not an OSError
            raise OSError(f"SQLite: {exc}") from exc
        finally:
            journal.unlink(missing_ok=True)
        # read back before it replaces the destination: a failed read (a damaged file, no
        # memory left) keeps the old file
        back = read_lines(tmp, table=table)
        if len(back) != xy.shape[0] or not np.array_equal(np.stack(back["geometry"].to_list()) if len(back) else xy,
                                                           xy):
            raise OSError("the GeoPackage read back does not hold the lines written")
    return p


def _srs_row(crs: str | None) -> tuple:
    """(srs_id, name, organization, code, definition) of the layer's CRS."""
    if not crs:
        return (-1, "Undefined cartesian SRS", "NONE", -1, "undefined")
    try:
        from ..core._georef import parse_crs

        parsed = parse_crs(crs)
    except ImportError:  # no rasterio: a bare EPSG code is kept by its code
        m = re.fullmatch(r"\s*EPSG:(\d+)\s*", crs)
        if m:
            code = int(m.group(1))
            return (code, f"EPSG:{code}", "EPSG", code, "undefined")
        return (_CUSTOM_SRS_ID, crs[:80], "NONE", _CUSTOM_SRS_ID, crs)
    code = parsed.to_epsg()
    wkt = parsed.to_wkt()
    if code is not None:
        return (int(code), f"EPSG:{code}", "EPSG", int(code), wkt)
    return (_CUSTOM_SRS_ID, crs[:80], "NONE", _CUSTOM_SRS_ID, wkt)


def _write(con, xy: np.ndarray, attributes, table: str, srs: tuple, description: str) -> None:
    con.execute(f"PRAGMA application_id = {APPLICATION_ID}")
    con.execute(f"PRAGMA user_version = {USER_VERSION}")
    con.executescript("""
        CREATE TABLE gpkg_spatial_ref_sys (
            srs_name TEXT NOT NULL, srs_id INTEGER NOT NULL PRIMARY KEY, organization TEXT NOT NULL,
            organization_coordsys_id INTEGER NOT NULL, definition TEXT NOT NULL, description TEXT);
        CREATE TABLE gpkg_contents (
            table_name TEXT NOT NULL PRIMARY KEY, data_type TEXT NOT NULL, identifier TEXT UNIQUE,
            description TEXT DEFAULT '',
            last_change DATETIME NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ','now')),
            min_x DOUBLE, min_y DOUBLE, max_x DOUBLE, max_y DOUBLE, srs_id INTEGER,
            CONSTRAINT fk_gc_r_srs_id FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys(srs_id));
        CREATE TABLE gpkg_geometry_columns (
            table_name TEXT NOT NULL, column_name TEXT NOT NULL, geometry_type_name TEXT NOT NULL,
            srs_id INTEGER NOT NULL, z TINYINT NOT NULL, m TINYINT NOT NULL,
            CONSTRAINT pk_geom_cols PRIMARY KEY (table_name, column_name),
            CONSTRAINT uk_gc_table_name UNIQUE (table_name),
            CONSTRAINT fk_gc_tn FOREIGN KEY (table_name) REFERENCES gpkg_contents(table_name),
            CONSTRAINT fk_gc_srs FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys (srs_id));
    """)
    rows = [("WGS 84 geodetic", 4326, "EPSG", 4326, _WGS84_WKT, "longitude/latitude coordinates in decimal degrees"),
            ("Undefined cartesian SRS", -1, "NONE", -1, "undefined", "undefined cartesian coordinate reference system"),
            ("Undefined geographic SRS", 0, "NONE", 0, "undefined", "undefined geographic coordinate reference system")]
    srs_id = srs[0]
    if srs_id not in (4326, -1, 0):
        rows.append((srs[1], srs_id, srs[2], srs[3], srs[4], None))
    con.executemany("INSERT INTO gpkg_spatial_ref_sys VALUES (?, ?, ?, ?, ?, ?)", rows)
    lo, hi = (xy.reshape(-1, 2).min(axis=0), xy.reshape(-1, 2).max(axis=0)) if xy.size else ((None,) * 2,) * 2
    con.execute("INSERT INTO gpkg_contents (table_name, data_type, identifier, description, min_x, min_y, max_x, "
                "max_y, srs_id) VALUES (?, 'features', ?, ?, ?, ?, ?, ?, ?)",
                (table, table, description, *(None if v is None else float(v) for v in (lo[0], lo[1], hi[0], hi[1])),
                 srs_id))
    con.execute("INSERT INTO gpkg_geometry_columns VALUES (?, 'geom', 'LINESTRING', ?, 0, 0)", (table, srs_id))
    columns = [(str(c), _TYPES.get(np.asarray(attributes[c]).dtype.kind, "TEXT")) for c in attributes.columns]
    con.execute(f'CREATE TABLE "{table}" (fid INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, geom LINESTRING'
                + "".join(f', "{c}" {t}' for c, t in columns) + ")")
    values = [_sql_values(np.asarray(attributes[c])) for c, _ in columns]
    con.executemany(f'INSERT INTO "{table}" (geom' + "".join(f', "{c}"' for c, _ in columns) + ") VALUES (?"
                    + ", ?" * len(columns) + ")",
                    ([_geometry(xy[n], srs_id)] + [v[n] for v in values] for n in range(xy.shape[0])))
    con.commit()


def _sql_values(a: np.ndarray) -> list:
    """A column as Python values sqlite3 stores (bools as 0/1, NaN as NULL)."""
    if a.dtype.kind == "b":
        return [int(v) for v in a]
    if a.dtype.kind in "iu":
        return [int(v) for v in a]
    if a.dtype.kind == "f":
        return [None if np.isnan(v) else float(v) for v in a]
    return [None if v is None else str(v) for v in a]


def _geometry(line: np.ndarray, srs_id: int) -> bytes:
    """A GeoPackage binary LINESTRING: header (little-endian, xy envelope), then ISO WKB."""
    lo, hi = line.min(axis=0), line.max(axis=0)
    header = b"GP" + struct.pack("<BBi4d", 0, 0b0000_0011, srs_id, lo[0], hi[0], lo[1], hi[1])
    return header + struct.pack("<BII", 1, _WKB_LINESTRING, line.shape[0]) + line.astype("<f8").tobytes()


# ----------------------------------------------------------------- reading
def read_lines(path, *, table: str | None = None):
    """A GeoPackage LINESTRING layer as a DataFrame: its attributes and ``geometry``, (m, 2) arrays.

    Checks the header, the required tables and rows, and every geometry's header and
    envelope; ``DataFrame.attrs`` gets ``srs_id``, ``organization``,
    ``organization_coordsys_id`` and ``definition`` of the layer's CRS.
    """
    import pandas as pd

    con = sqlite3.connect(f"file:{Path(path)}?mode=ro", uri=True)
    try:
        app, ver = con.execute("PRAGMA application_id").fetchone()[0], con.execute("PRAGMA user_version").fetchone()[0]
        if app != APPLICATION_ID:
            raise ValueError(f"{str(path)!r} is not a GeoPackage (application_id {app:#x}, expected 'GPKG')")
        if not 10200 <= ver < 10500:
            raise ValueError(f"{str(path)!r}: GeoPackage version {ver} (user_version), expected 1.2 to 1.4")
        srs_ids = {r[0] for r in con.execute("SELECT srs_id FROM gpkg_spatial_ref_sys")}
        if not {4326, -1, 0} <= srs_ids:
            raise ValueError(f"{str(path)!r}: gpkg_spatial_ref_sys lacks a required row (4326, -1, 0): {srs_ids}")
        layers = con.execute("SELECT c.table_name, g.column_name, g.geometry_type_name, g.srs_id FROM gpkg_contents c "
                             "JOIN gpkg_geometry_columns g ON c.table_name = g.table_name "
                             "WHERE c.data_type = 'features'").fetchall()
        if table is not None:
            layers = [r for r in layers if r[0] == table]
        if len(layers) != 1:
            raise ValueError(f"{str(path)!r}: expected one feature layer{'' if table is None else ' ' + repr(table)}, "
                             f"found {len(layers)}")
        name, column, kind, srs_id = layers[0]
        if kind != "LINESTRING":
            raise ValueError(f"{str(path)!r}: layer {name!r} holds {kind}, not LINESTRING")
        srs = con.execute("SELECT organization, organization_coordsys_id, definition FROM gpkg_spatial_ref_sys "
                          "WHERE srs_id = ?", (srs_id,)).fetchone()
        cursor = con.execute(f'SELECT * FROM "{name}" ORDER BY fid')
        names = [d[0] for d in cursor.description]
        rows = cursor.fetchall()
    finally:
        con.close()
    g = names.index(column)
    out = pd.DataFrame([[v for n, v in enumerate(r) if n != g] for r in rows],
                       columns=[c for n, c in enumerate(names) if n != g])
    out["geometry"] = [_parse_geometry(r[g], srs_id) for r in rows]
    out.attrs.update(srs_id=srs_id, organization=srs[0], organization_coordsys_id=srs[1], definition=srs[2])
    return out


def _parse_geometry(blob: bytes, srs_id: int) -> np.ndarray:
    if blob[:2] != b"GP" or blob[2] != 0:
        raise ValueError("a geometry without the GeoPackage header 'GP', version 0")
    flags = blob[3]
    little = flags & 1
    envelope = (flags >> 1) & 0b111
    if envelope not in (0, 1):
        raise ValueError(f"a geometry with envelope kind {envelope}; this reader takes none or xy")
    order = "<" if little else ">"
    (sid,) = struct.unpack(order + "i", blob[4:8])
    if sid != srs_id:
        raise ValueError(f"a geometry of srs_id {sid} in a layer of srs_id {srs_id}")
    start = 8 + 32 * envelope
    wkb = blob[start:]
    worder = "<" if wkb[0] == 1 else ">"
    kind, n = struct.unpack(worder + "II", wkb[1:9])
    if kind != _WKB_LINESTRING:
        raise ValueError(f"a WKB geometry of type {kind}, not LINESTRING (2)")
    xy = np.frombuffer(wkb[9:9 + 16 * n], dtype=worder + "f8").reshape(n, 2).astype(np.float64)
    if envelope == 1:
        box = struct.unpack(order + "4d", blob[8:40])
        if box != (xy[:, 0].min(), xy[:, 0].max(), xy[:, 1].min(), xy[:, 1].max()):
            raise ValueError(f"a geometry whose envelope {box} is not its extent")
    return xy
