"""The terrainvis ``.npz`` format (version 1) and the older ``.npz`` dialects (see :mod:`terrainvis.io`)."""

from __future__ import annotations

import math
import zipfile
import zlib
from pathlib import Path

import numpy as np

from ..core.fileio import atomic_path
from ..core._georef import IDENTITY
from ..core.terrain import TIN, HeightGrid
from ..tolerances import SPACING_MATCH_REL
from ._attrs import _attrs_from_json, _attrs_to_json
from ..core.memory import check_memory, format_bytes
from ._common import (
    _READ_BYTES_PER_SAMPLE,
    FORMAT,
    FORMAT_VERSION,
    _TIN_ORIENTATION,
    _Corrupt,
    _npy_header,
    _UserError,
)
from ._raster import _georeference

_GRID_ORIENTATIONS = ("y_increasing", "y_decreasing")
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")


def _check_npz_memory(p: Path) -> None:
    """Refuse an archive whose arrays (by their headers) cannot be read into memory.

    A float array costs its own bytes plus the float64 copies a reader makes
    (``_READ_BYTES_PER_SAMPLE``); other arrays their own bytes.
    """
    raw = need = 0
    with zipfile.ZipFile(p) as zf:
        for info in zf.infolist():
            if not info.filename.endswith(".npy"):
                continue
            with zf.open(info) as fh:
                try:
                    shape, dtype = _npy_header(fh)
                except ValueError:
                    continue  # numpy's own reader names the problem
            n = math.prod(int(v) for v in shape)
            raw += n * dtype.itemsize
            need += n * (dtype.itemsize + (_READ_BYTES_PER_SAMPLE if dtype.kind == "f" else 0))
    if need:
        check_memory(need, f"reading {p.name!r} (arrays of {format_bytes(raw)})")


def _read_npz(p: Path, *, crs=None, band=None):
    with open(p, "rb") as fh:
        head = fh.read(8)
    if head.startswith(b"\x93NUMPY"):
        raise _Corrupt("it is a .npy file (one bare array), not a .npz archive; give it the suffix .npy")
    if not head.startswith(_ZIP_MAGIC):
        raise _Corrupt(f"it is not a .npz file (a zip archive of .npy arrays): it starts with {head!r}")
    try:
        _check_npz_memory(p)
    except zipfile.BadZipFile:
        pass  # numpy's reader below names the damage
    try:
        with np.load(p, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except ValueError as exc:
        if "pickle" in str(exc):
            raise _Corrupt(
                "it holds an object array, which only pickle can read; terrainvis never writes one and does not "
                "unpickle files"
            ) from None
        raise _Corrupt(f"it is truncated or corrupt (ValueError: {exc})") from None
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError) as exc:
        raise _Corrupt(f"it is truncated or corrupt ({type(exc).__name__}: {exc})") from None
    terrain = _terrain_from_arrays(arrays)
    if crs is not None and isinstance(terrain, HeightGrid):
        if terrain.attrs.get("crs"):
            raise _UserError(
                f"crs: {p.name!r} records the CRS {terrain.attrs['crs']!r}; crs= is only for files that record none, "
                f"got {crs!r}"
            )
        if terrain.attrs.get("geographic"):
            raise _UserError(f"crs: {p.name!r} is a lon/lat grid already converted to metres; crs= cannot apply")
        terrain = _georeference(terrain.z, terrain.xs, terrain.ys, dict(terrain.attrs), None, crs, p.name)
    return terrain


def _text(a: dict, key: str) -> str:
    v = a[key]
    if v.ndim != 0 or v.dtype.kind not in "US":
        raise _Corrupt(f"key {key!r} must be a text scalar, got an array of shape {v.shape} and dtype {v.dtype}")
    return str(v)


def _scalar(a: dict, key: str) -> float:
    v = a[key]
    if v.size != 1 or v.dtype.kind not in "biuf":
        raise _Corrupt(f"key {key!r} must be a numeric scalar, got an array of shape {v.shape} and dtype {v.dtype}")
    return float(v.reshape(()))


def _need(a: dict, keys, what: str):
    missing = [k for k in keys if k not in a]
    if missing:
        raise _Corrupt(f"{what} needs the keys {list(keys)}, but {missing} are missing (found {sorted(a)})")


def _terrain_from_arrays(a: dict):
    keys = set(a)
    if "format" in keys:
        return _from_v1(a)
    if "vertices" in keys or "faces" in keys:
        if "z" in keys:
            raise _Corrupt(f"it holds both a grid ('z') and a TIN ('vertices', 'faces') and no 'format' key; keys {sorted(a)}")
        if "kind" in keys and _text(a, "kind") != "tin":
            raise _Corrupt(f"its key 'kind' is {_text(a, 'kind')!r}, but it holds 'vertices'/'faces' (a TIN)")
        _need(a, ("vertices", "faces"), "a TIN")
        return TIN(a["vertices"], a["faces"])
    if "z" not in keys:
        raise _Corrupt(f"it holds neither a grid (key 'z') nor a TIN (keys 'vertices', 'faces'); keys {sorted(a)}")
    if "kind" in keys and _text(a, "kind") != "grid":
        raise _Corrupt(f"its key 'kind' is {_text(a, 'kind')!r}, but it holds 'z' (a grid)")
    z = np.asarray(a["z"], dtype=np.float64)
    if z.ndim != 2:
        raise _Corrupt(f"z must be 2-D, got shape {z.shape}")
    has_spacing = "dx" in keys or "dy" in keys
    has_coords = "xs" in keys or "ys" in keys
    if has_spacing:
        _need(a, ("dx", "dy"), "a north-up raster .npz (the shared-DEM dialect)")
        return _from_north_up(a, z)
    if has_coords:
        _need(a, ("xs", "ys"), "a grid .npz with coordinates")
        xs = np.asarray(a["xs"], dtype=np.float64)
        ys = np.asarray(a["ys"], dtype=np.float64)
        # z[r, c] at (xs[c], ys[r]): unambiguous whichever way the coordinates run.
        if ys.ndim == 1 and ys.size >= 2 and ys[-1] < ys[0]:
            z, ys = z[::-1], ys[::-1]
        if xs.ndim == 1 and xs.size >= 2 and xs[-1] < xs[0]:
            z, xs = z[:, ::-1], xs[::-1]
        return HeightGrid.from_coords(z, xs, ys)
    raise _Corrupt(
        "it has 'z' but no coordinates: neither 'dx'/'dy' (a north-up raster, as in shared/data/dem) nor "
        "'xs'/'ys' (grid rows with their coordinates), so its spacing and row order are unknown"
    )


def _from_north_up(a: dict, z_north_up: np.ndarray) -> HeightGrid:
    """The shared-DEM dialect and the former save_dem dialect: raster rows, dx/dy in metres."""
    z = z_north_up[::-1]
    rows, cols = z.shape
    attrs = {}
    for key in ("crs", "source", "license", "description", "z_units"):
        if key in a:
            attrs[key] = _text(a, key)
    geographic = bool(_scalar(a, "geographic")) if "geographic" in a else False
    attrs["geographic"] = geographic
    dx, dy = _scalar(a, "dx"), _scalar(a, "dy")
    if "xs" in a or "ys" in a:
        # The former save_dem dialect: exact coordinates beside the mean spacing.
        _need(a, ("xs", "ys"), "a north-up .npz with coordinates (the former save_dem dialect)")
        xs = np.asarray(a["xs"], dtype=np.float64)
        ys = np.asarray(a["ys"], dtype=np.float64)
        for axis, v, d in (("x", xs, dx), ("y", ys, dy)):
            if v.ndim == 1 and v.size >= 2:
                mean = float((v[-1] - v[0]) / (v.size - 1))
                if not abs(mean - d) <= SPACING_MATCH_REL * max(abs(d), abs(mean)):
                    raise _Corrupt(
                        f"its d{axis} = {d!r} disagrees with the mean spacing {mean!r} of {axis}s, so it is not a "
                        "file of a known dialect (z, dx, dy, xs, ys as the former save_dem wrote)"
                    )
        if not geographic:
            attrs["xy_to_native"] = IDENTITY
        return HeightGrid.from_coords(z, xs, ys, attrs=attrs)
    origin = (0.0, 0.0)
    if "geotransform" in a:
        gt = np.asarray(a["geotransform"], dtype=np.float64).ravel()
        if gt.size != 6 or gt[2] != 0 or gt[4] != 0:
            raise _Corrupt(f"geotransform must be 6 numbers of a north-up raster (no rotation), got {gt.tolist()}")
        x0 = gt[0] + 0.5 * gt[1]  # the south-west sample centre in native coordinates
        y0 = gt[3] + gt[5] * (rows - 0.5)
        if gt[1] > 0 and gt[5] < 0:  # north-up: the cells as stored (see _raster.native_lattice)
            attrs["native_lattice"] = (float(gt[0]), float(gt[1]), float(gt[3]), float(-gt[5]))
        if geographic:
            dx_native = _scalar(a, "dx_native") if "dx_native" in a else abs(gt[1])
            dy_native = _scalar(a, "dy_native") if "dy_native" in a else abs(gt[5])
            attrs["xy_to_native"] = (dx_native / dx, float(x0), dy_native / dy, float(y0))
        else:
            origin = (float(x0), float(y0))
            attrs["xy_to_native"] = IDENTITY
    elif not geographic:
        attrs["xy_to_native"] = IDENTITY
    return HeightGrid(z, dx=dx, dy=dy, origin=origin, attrs=attrs)


def _from_v1(a: dict):
    fmt = _text(a, "format")
    if fmt != FORMAT:
        raise _Corrupt(f"its key 'format' is {fmt!r}, not {FORMAT!r}")
    _need(a, ("format_version", "kind", "orientation", "attrs"), f"a {FORMAT} .npz")
    version = _scalar(a, "format_version")
    if version != int(version) or version < 1:
        raise _Corrupt(f"its format_version must be a positive integer, got {version!r}")
    if version > FORMAT_VERSION:
        raise _Corrupt(
            f"it was written by a newer terrainvis (format version {int(version)}; this one reads up to "
            f"{FORMAT_VERSION}); upgrade terrainvis to read it"
        )
    kind = _text(a, "kind")
    orientation = _text(a, "orientation")
    attrs = _attrs_from_json(_text(a, "attrs"))
    if kind == "grid":
        _need(a, ("z", "xs", "ys"), "a grid")
        z, xs, ys = a["z"], a["xs"], a["ys"]
        if orientation == "y_decreasing":
            if z.ndim != 2 or ys.ndim != 1:
                raise _Corrupt(f"z must be 2-D and ys 1-D, got shapes {z.shape} and {ys.shape}")
            z, ys = z[::-1], ys[::-1]
        elif orientation != "y_increasing":
            raise _Corrupt(f"a grid's orientation must be one of {list(_GRID_ORIENTATIONS)}, got {orientation!r}")
        return HeightGrid.from_coords(z, xs, ys, attrs=attrs)
    if kind == "tin":
        if orientation != _TIN_ORIENTATION:
            raise _Corrupt(f"a TIN's orientation must be {_TIN_ORIENTATION!r}, got {orientation!r}")
        _need(a, ("vertices", "faces"), "a TIN")
        return TIN(a["vertices"], a["faces"], attrs=attrs)
    raise _Corrupt(f"its kind must be 'grid' or 'tin', got {kind!r}")


def _npz_arrays(terrain) -> dict:
    common = {
        "format": np.asarray(FORMAT), "format_version": np.int64(FORMAT_VERSION),
        "attrs": np.asarray(_attrs_to_json(terrain.attrs)),
    }
    if isinstance(terrain, HeightGrid):
        return dict(common, kind=np.asarray("grid"), orientation=np.asarray("y_increasing"), z=terrain.z,
                    xs=terrain.xs, ys=terrain.ys)
    return dict(common, kind=np.asarray("tin"), orientation=np.asarray(_TIN_ORIENTATION), vertices=terrain.vertices,
                faces=terrain.faces)


def _write_npz(terrain, p: Path) -> None:
    arrays = _npz_arrays(terrain)
    with atomic_path(p) as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)  # a file object: numpy appends no suffix
