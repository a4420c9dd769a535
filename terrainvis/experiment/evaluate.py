"""Evaluating a simplification made elsewhere, on the comparison's measure: :func:`evaluate`.

A mesh written by another tool (a ``.ply``, ``.obj``, ``.off``, ``.stl`` or ``.glb``), a
raster (``.tif``, ``.asc``, ``.npz``) or, in Python, a TIN, a HeightGrid or a trimesh mesh
is measured exactly as :func:`terrainvis.compare` measures a method's result: the same
point sets of the terrain (by its name and the seed), the same relocations, predicate and
measure, the same columns. Its rows can therefore stand beside a comparison's, or beside
the built-in methods at the same vertex count (``against=``).

Before it is measured, the simplified terrain is put in the original's frame and
checked:

* **Frame.** Coordinates in the DEM's CRS (``frame="native"``, lon/lat degrees on a
  geographic DEM) are moved to the terrain's own frame; ``frame="local"`` takes them as
  they are (the frame of the Python API and of the meshes terrainvis writes). A
  simplified terrain that does not overlap the original is refused, saying where each is.
* **Height field.** A TIN must cover the original's footprint exactly once (its corners,
  no vertex outside, no folded face, one disk whose boundary runs along the sides:
  :func:`terrainvis.core.repair.height_field_problems`). Without ``repair`` the first
  defect is reported with where it is; with ``repair=True`` the mesh is repaired as QEC's
  output is (:func:`terrainvis.core.repair.repair_tin`) and ``attrs["repair"]`` says what
  changed.
* **Tilesets.** A folder of terrain tiles (Cesium quantized-mesh-1.0 with its
  ``layer.json``, or terrain-RGB PNG tiles) is measured once per zoom of ``zoom``: that
  zoom's tiles over the DEM are stitched into one TIN in the DEM's frame and clipped to its
  footprint (:func:`terrainvis.tiles.read.stitch_zoom`), named ``{folder}-z{zoom}``, and
  its rows carry the ``zoom``. Heights are taken as in the DEM's vertical datum;
  ``tile_offset`` is added to them when they are not (the module
  :mod:`terrainvis.tiles.read` says when).
* **Coverage of a raster.** A coarser raster resampled from the DEM (``gdalwarp -tr``)
  has its sample centres half a coarse cell inside the DEM's: its edge samples are
  extended to the DEM's footprint (recorded in ``attrs["padded"]``); a raster that covers
  less than that is refused.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from ..core.terrain import TIN, HeightGrid
from ..core.validate import choice, describe, file_label

__all__ = ["evaluate", "as_simplified", "is_tileset", "MESH_SUFFIXES", "RASTER_SUFFIXES", "TILE_NAMES"]

#: Mesh files :func:`evaluate` reads (through trimesh).
MESH_SUFFIXES = (".ply", ".obj", ".off", ".stl", ".glb")
#: Raster and grid files it reads (through :func:`terrainvis.load_dem`).
RASTER_SUFFIXES = (".tif", ".tiff", ".asc", ".npz", ".npy")
#: The frames simplified coordinates may be given in; None chooses by what is given.
FRAMES = ("native", "local")


def evaluate(original, simplified, *, name: str | None = None, against=(), frame: str | None = None,
             repair: bool = False, zoom=None, tile_mesh: str = "grid", tile_max_error=None, tile_offset: float = 0.0,
             out_csv=None, resume: bool = False, on_unit=None, **options) -> pd.DataFrame:
    """Measure simplifications made elsewhere as :func:`terrainvis.compare` measures a method's.

    Parameters
    ----------
    original : HeightGrid, str or Path, or {name: terrain}
        The original terrain T: a HeightGrid, a bundled name, a DEM file, or a one-entry
        dict naming it. Its name keys the point sets, as in :func:`terrainvis.compare`:
        evaluating a method's output under the terrain's name and the run's seed gives
        that comparison's rows.
    simplified : terrain or path, or a list or dict of them
        S(T): a TIN, a HeightGrid, a ``trimesh.Trimesh``, a file (a mesh of
        :data:`MESH_SUFFIXES`, a raster of :data:`RASTER_SUFFIXES`, or a terrainvis
        ``.npz`` of either kind), or a tileset folder (measured at each of ``zoom``, see the
        module docstring). Several are measured one after the other; a dict gives their
        names, else a file's stem, ``attrs["method"]`` or ``"simplified"``.
    name : str, optional
        The method column of a single simplified terrain.
    against : sequence of str
        Built-in or registered methods measured beside them at the same size: an
        irregular method at the simplified TIN's vertex count, a regular one at the level
        whose grid is closest to it.
    frame : {"native", "local"}, optional
        The frame of the simplified terrain's coordinates (see the module docstring).
        Default: ``"local"`` for terrains given as Python objects and for files terrainvis
        wrote (they record the georeferencing of the terrain's frame), ``"native"`` for
        other files.
    repair : bool
        Repair a mesh that is not a valid height field instead of refusing it.
    zoom : int or sequence of int
        The zooms of the tilesets to measure, each one TIN; required with a tileset (a
        missing one is refused with the zooms the tileset holds), refused without.
    tile_mesh : {"grid", "martini", "delatin"}
        How terrain-RGB tiles are meshed: every pixel a vertex, or deck.gl's Martini or
        Delatin at ``tile_max_error``.
    tile_max_error : float, sequence or dict, optional
        Martini's and Delatin's maximum error (m): one for every zoom, one per zoom of
        ``zoom``, or ``{zoom: error}``.
    tile_offset : float
        Height (m) added to the tiles' heights: the DEM's vertical datum minus the tiles'
        (``-N``, N the geoid undulation, for ellipsoidal tiles over an orthometric DEM).
    out_csv : str or Path, optional
        Write each measured terrain's rows (and each ``against`` method's) to this CSV as
        soon as they are measured, atomically, with the run's settings beside it, as
        :func:`terrainvis.compare` does (:class:`~terrainvis.experiment.results.ResultStore`);
        the settings record the content of every simplified terrain as measured.
    resume : bool
        With ``out_csv``: keep the terrains already measured there (same settings, same
        simplified terrains) and measure only the rest.
    on_unit : callable, optional
        ``on_unit(key, rows)``, called as each terrain (or ``against`` method at one size)
        is measured, after its rows are stored: ``key`` is ``(terrain, method, level)`` and
        ``rows`` a DataFrame of its rows. An exception it raises ends the run; the rows
        stored so far stay in ``out_csv``.
    **options
        The options of :func:`terrainvis.compare` that concern the measure (``relocations``,
        ``n_points``, ``n_sets``, ``seed``, ``predicate``, ``measure``, ``curvature``,
        ``max_distance``, ``offset``, ``engine``, ``volume``, ``repeats``, ...).

    Returns
    -------
    pandas.DataFrame
        :func:`terrainvis.compare`'s columns: one row per point set (or observer) x
        simplified terrain (then each ``against`` method) x relocation (x distance). A
        terrain that could not be measured keeps its rows with the message in ``error``.

    Raises
    ------
    ValueError
        A simplified terrain that cannot be read, is in another frame than said, does
        not overlap or cover the original, or is not a height field (without
        ``repair``): one line naming it and the first problem. Also a resume whose
        settings or simplified terrains differ from the stored run's, naming the
        differences. Every terrain is read and checked before anything is measured or
        written.

    Examples
    --------
    >>> import terrainvis as tv, simplifiers
    >>> T = tv.bundled_terrain("hills")
    >>> S = simplifiers.simplify(T, "greedy-insertion", 3)
    >>> df = evaluate({"hills": T}, S, name="mine", relocations=["full"], n_points=20, n_sets=1)
    >>> df["method"].unique().tolist(), int(df["n_vertices"].iloc[0])
    (['mine'], 225)
    """
    if resume and out_csv is None:
        raise ValueError("resume=True continues the run stored in out_csv; give out_csv (the results file to resume)")
    if on_unit is not None and not callable(on_unit):
        raise TypeError(f"on_unit must be a function of (key, rows) or None, got {describe(on_unit)}")
    run = prepared(original, simplified, name=name, against=against, frame=frame, repair=repair, zoom=zoom,
                   tile_mesh=tile_mesh, tile_max_error=tile_max_error, tile_offset=tile_offset, **options)
    from .comparison import _lock

    with _lock(out_csv):
        return run.measure(out_csv, resume=resume, on_unit=on_unit)


@dataclass(frozen=True)
class Prepared:
    """An :func:`evaluate` run with everything read and checked, nothing measured:
    :meth:`measure` runs it (the command line holds its own lock on ``--out`` meanwhile)."""

    grid: HeightGrid
    name: str
    terrains: dict
    against: list
    settings: object

    def record(self) -> dict:
        """What its results file stores about the run: the comparison's record
        (:func:`terrainvis.experiment.plan.run_record`), the content of each simplified
        terrain as measured (after its frame and any repair), and the methods of its rows."""
        from .plan import run_record

        return {**run_record(self.settings, {self.name: self.grid}),
                "evaluated": {label: _content(t) for label, t in self.terrains.items()},
                "methods": sorted(set(self.terrains) | set(self.against))}

    def measure(self, out_csv=None, *, resume: bool = False, on_unit=None) -> pd.DataFrame:
        """The rows, each unit's stored in ``out_csv`` as it finishes (see :func:`evaluate`)."""
        units = _units(self.grid, self.name, self.terrains, self.against, self.settings)
        store, done = _store(out_csv, self.record(), units, self.settings, resume)
        return _rows(self.grid, self.name, units, store, done, on_unit, self.settings)


#: compare's options that choose what is simplified, which evaluate refuses (it would ignore them), and
#: what to use instead; ``terrainvis evaluate`` has no flags for them.
COMPARE_ONLY = {
    "methods": "against= measures built-in methods beside them, at their size",
    "levels": "against= measures built-in methods at the level whose grid is closest to each",
    "max_errors": "against= measures built-in methods at their size; terrainvis.compare(max_errors=...) budgets "
                  "them in vertical error",
    "cascade": "it simplifies nothing",
}


def prepared(original, simplified, *, name=None, against=(), frame=None, repair=False, zoom=None, tile_mesh="grid",
             tile_max_error=None, tile_offset=0.0, names=None, **options) -> Prepared:
    """Read and check everything :func:`evaluate` measures (its arguments, less the output's); ``names``
    says how messages name the tileset arguments (:data:`TILE_NAMES`; the command line passes its flags)."""
    from .plan import resolve_terrains, settings_for

    grids = resolve_terrains(original if isinstance(original, dict) else [original])
    if len(grids) != 1:
        raise ValueError(f"original must be one terrain, got {len(grids)}")
    (tname, grid), = grids.items()
    against = [against] if isinstance(against, str) else list(against)
    chosen = [k for k in COMPARE_ONLY if k in options]
    if chosen:
        raise TypeError(f"evaluate() takes no {chosen[0]}=: it measures the simplified terrains it is given; "
                        f"{COMPARE_ONLY[chosen[0]]}")
    items = _named(simplified, name, taken=against)
    settings = settings_for(grids, {**options, "methods": against or ["simple"]})
    if frame is not None:
        frame = choice(frame, "frame", FRAMES)
    reading = _TileReading.checked(zoom, tile_mesh, tile_max_error, tile_offset, {**TILE_NAMES, **(names or {})})
    terrains = {}
    for label, s in _tilesets_expanded(items, grid, reading, taken=against):
        terrains[label] = as_simplified(s, grid, frame="local" if _from_tileset(s) else frame, repair=repair,
                                        label=label)
    _check_engine(settings, terrains)
    return Prepared(grid, tname, terrains, against, settings)


# ---------------------------------------------------------------------- tilesets
#: How messages name the tileset arguments of :func:`evaluate` (the command line passes its flags).
TILE_NAMES = {"zoom": "zoom", "tile_mesh": "tile_mesh", "tile_max_error": "tile_max_error",
              "tile_offset": "tile_offset"}


def is_tileset(s) -> bool:
    """A simplified terrain given as a folder: a tileset."""
    return isinstance(s, (str, Path)) and Path(s).is_dir()


def _from_tileset(s) -> bool:
    return isinstance(s, TIN) and "tileset" in s.attrs and "zoom" in s.attrs


@dataclass(frozen=True)
class _TileReading:
    """How tilesets are read: the zooms, the mesher and its errors per zoom, the height offset; checked once."""

    zooms: tuple
    mesh: str
    max_error: dict
    offset: float
    names: dict

    @classmethod
    def checked(cls, zoom, mesh, max_error, offset, names) -> _TileReading:
        from ..tiles.read import MESHERS
        from ..tiles.scheme import MAX_ZOOM

        if zoom is None:
            zooms = ()
        else:
            given = [zoom] if isinstance(zoom, (int, np.integer)) and not isinstance(zoom, bool) else zoom
            try:
                zooms = tuple(given)
            except TypeError:
                raise ValueError(f"{names['zoom']} must be a zoom or a list of zooms, got {describe(zoom)}") from None
            if not zooms or any(isinstance(z, bool) or not isinstance(z, (int, np.integer)) or not 0 <= z <= MAX_ZOOM
                                for z in zooms):
                raise ValueError(f"{names['zoom']} must be one or more integers in [0, {MAX_ZOOM}], got {zoom!r}")
            if len(set(zooms)) != len(zooms):
                raise ValueError(f"{names['zoom']} must not repeat a zoom, got {list(zooms)}")
            zooms = tuple(int(z) for z in zooms)
        mesh = choice(mesh, names["tile_mesh"], MESHERS)
        errors = {}
        if max_error is not None:
            if isinstance(max_error, dict):
                errors = dict(max_error)
            elif isinstance(max_error, (int, float, np.integer, np.floating)) and not isinstance(max_error, bool):
                errors = {z: max_error for z in zooms}
            else:
                values = list(max_error)
                if len(values) == 1:
                    values = values * len(zooms)
                if len(values) != len(zooms):
                    raise ValueError(f"{names['tile_max_error']} must be one error or one per zoom of "
                                     f"{names['zoom']} ({len(zooms)}), got {len(values)}")
                errors = dict(zip(zooms, values))
            for z, e in errors.items():
                if isinstance(e, bool) or not isinstance(e, (int, float, np.integer, np.floating)) \
                        or not np.isfinite(e) or e < 0:
                    raise ValueError(f"{names['tile_max_error']} must be finite errors >= 0 (m), got {e!r} for zoom "
                                     f"{z}")
            errors = {int(z): float(e) for z, e in errors.items()}
        if mesh != "grid":
            lacking = [z for z in zooms if z not in errors]
            if lacking:
                raise ValueError(f"{names['tile_mesh']} {mesh!r} meshes at a maximum error per zoom; give "
                                 f"{names['tile_max_error']} (none for zoom {', '.join(map(str, lacking))})")
        if isinstance(offset, bool) or not isinstance(offset, (int, float, np.integer, np.floating)) \
                or not np.isfinite(offset):
            raise ValueError(f"{names['tile_offset']} must be a finite height (m), got {offset!r}")
        return cls(zooms, mesh, errors, float(offset), names)


def _tilesets_expanded(items: list, grid: HeightGrid, reading: _TileReading, taken=()) -> list:
    """``items`` with each tileset folder replaced by one stitched TIN per zoom, labelled ``{label}-z{zoom}``."""
    out, tilesets = [], 0
    for label, s in items:
        if not is_tileset(s):
            out.append((label, s))
            continue
        tilesets += 1
        from ..tiles.read import open_tileset, stitch_zoom
        from ..tiles.tileset import _Frame

        tiles = open_tileset(s, name=f"simplified terrain {label!r}")
        if not reading.zooms:
            raise ValueError(f"{reading.names['zoom']} must name the zooms of tileset {str(s)!r} to measure; it "
                             f"holds zooms {_zoom_list(tiles.zooms)}")
        absent = [z for z in reading.zooms if z not in tiles.zooms]
        if absent:
            raise ValueError(f"{reading.names['zoom']} {', '.join(map(str, absent))} not in tileset {str(s)!r}, "
                             f"which holds zooms {_zoom_list(tiles.zooms)}")
        frame = _Frame(grid, "original")
        for z in reading.zooms:
            tin = stitch_zoom(grid, tiles, z, mesh=reading.mesh, max_error=reading.max_error.get(z),
                              offset=reading.offset, name=f"simplified terrain {label!r}", frame=frame)
            out.append((f"{label}-z{z}", tin))
    if reading.zooms and not tilesets:
        raise ValueError(f"{reading.names['zoom']} chooses the zooms of a tileset, and no simplified terrain is a "
                         "tileset folder")
    labels = [lab for lab, _ in out]
    if len(set(labels)) != len(labels) or set(labels) & set(taken):
        raise ValueError(f"simplified terrains must have distinct names, got {labels}")
    return out


def _zoom_list(zooms) -> str:
    """``0-5, 7``: zooms as runs."""
    if not zooms:
        return "none"
    runs, start = [], zooms[0]
    for a, b in zip(zooms, list(zooms[1:]) + [None]):
        if b != a + 1:
            runs.append(f"{start}" if start == a else f"{start}-{a}")
            start = b
    return ", ".join(runs)


def _content(terrain) -> str:
    """16 hex digits of the SHA-256 of a terrain's arrays: a changed simplified terrain is a changed run."""
    import hashlib

    from ..core.terrain import fingerprint

    if isinstance(terrain, HeightGrid):
        return fingerprint(terrain)
    h = hashlib.sha256()
    for a in (terrain.vertices, terrain.faces):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def _named(simplified, name, taken=()) -> list[tuple[str, object]]:
    """(label, terrain) pairs: a dict's keys, ``name``, a file's stem or the terrain's method; unique, and
    apart from the ``taken`` names (the methods measured beside them)."""
    if isinstance(simplified, dict):
        items = [(str(k), v) for k, v in simplified.items()]
    elif isinstance(simplified, (list, tuple)):
        items = [(None, v) for v in simplified]
    else:
        items = [(name, simplified)]
    if not items:
        raise ValueError("simplified must hold at least one terrain, got an empty collection")
    if name is not None and len(items) > 1:
        raise ValueError("name names a single simplified terrain; give a dict {name: terrain} for several")
    out, seen = [], set()
    for i, (label, s) in enumerate(items):
        if label is None:
            if isinstance(s, (str, Path)):
                label = file_label(Path(s).stem)
            else:
                label = str(getattr(s, "attrs", {}).get("method") or "simplified")
        if label in taken:
            label = f"{label}-evaluated"
        base, k = label, 2
        while label in seen or label in taken:
            label, k = f"{base}-{k}", k + 1
        seen.add(label)
        out.append((label, s))
    return out


# ---------------------------------------------------------------------- reading and checking
def as_simplified(simplified, grid: HeightGrid, *, frame: str | None = None, repair: bool = False,
                  label: str = "simplified"):
    """``simplified`` (a terrain, a trimesh mesh or a file) as a TIN or HeightGrid in ``grid``'s frame, checked.

    See the module docstring for the frame, the height-field rules and the coverage of a
    raster. ``label`` names it in messages.
    """
    from_file = isinstance(simplified, (str, Path))
    terrain = _read(simplified, label) if from_file else _as_terrain(simplified, label)
    if frame is None:
        frame = "native" if from_file and not _written_by_terrainvis(terrain) else "local"
    terrain = _into_frame(terrain, grid, frame, label)
    _check_overlap(terrain, grid, frame, label)
    if isinstance(terrain, TIN):
        return _checked_tin(terrain, grid, repair, label)
    return _covering(terrain, grid, label)


def _read(path, label: str):
    from ..io import load_dem, load_terrain

    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"simplified terrain {label!r}: {str(p)!r} does not exist")
    suffix = p.suffix.lower()
    if suffix == ".off":
        return _as_terrain(_trimesh_load(p, label), label)
    if suffix in MESH_SUFFIXES or suffix == ".npz":
        return load_terrain(p)
    if suffix in RASTER_SUFFIXES:
        return load_dem(p)
    raise ValueError(f"simplified terrain {label!r}: {p.name!r} is neither a mesh ({', '.join(MESH_SUFFIXES)}) nor a "
                     f"raster ({', '.join(RASTER_SUFFIXES)})")


def _trimesh_load(p: Path, label: str):
    import trimesh

    try:
        return trimesh.load(p, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many kinds on a damaged file
        raise ValueError(f"simplified terrain {label!r}: {p.name!r} could not be read as a mesh "
                         f"({type(exc).__name__}: {exc})") from None


def _as_terrain(obj, label: str):
    if isinstance(obj, (TIN, HeightGrid)):
        return obj
    vertices, faces = getattr(obj, "vertices", None), getattr(obj, "faces", None)
    if vertices is not None and faces is not None:  # a trimesh.Trimesh or alike
        v = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces)
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or not len(f):
            raise ValueError(f"simplified terrain {label!r} must be a triangle mesh with 3-D vertices, got vertices "
                             f"{v.shape} and faces {f.shape}")
        return TIN(v, f.astype(np.int64))
    raise TypeError(f"simplified terrain {label!r} must be a TIN, a HeightGrid, a trimesh mesh or a file path, got "
                    f"{describe(obj)}")


def _written_by_terrainvis(terrain) -> bool:
    """A terrain read from a file terrainvis wrote: its coordinates are the terrain's own frame."""
    return "xy_to_native" in terrain.attrs or "method" in terrain.attrs or "crs" in terrain.attrs


def _into_frame(terrain, grid: HeightGrid, frame: str, label: str):
    from ..core._positions import PositionFrame

    to = PositionFrame(grid, frame)
    if isinstance(terrain, TIN):
        v = terrain.vertices.copy()
        given = v[:, :2].copy()
        v[:, :2] = to.to_grid(given)
        # a vertex on the footprint's edge lands just beside it when the conversion rounds, or when the file
        # stored float32 coordinates (as many mesh writers do): within that rounding it is put on the edge
        slack = _float32_slack(grid, to) if np.array_equal(given.astype(np.float32), given) else (0.0, 0.0)
        xmin, xmax, ymin, ymax = grid.extent
        v[:, 0] = _onto_edge(v[:, 0], xmin, xmax, slack[0])
        v[:, 1] = _onto_edge(v[:, 1], ymin, ymax, slack[1])
        return TIN(v, terrain.faces, attrs=dict(terrain.attrs))
    if frame == "local":
        return terrain
    # a raster: its samples in native coordinates (through its own georeferencing), then the grid's frame
    own = PositionFrame(terrain, "native")
    xs = to.to_grid(own.from_grid(np.column_stack([terrain.xs, np.full(terrain.xs.size, terrain.ys[0])])))
    ys = to.to_grid(own.from_grid(np.column_stack([np.full(terrain.ys.size, terrain.xs[0]), terrain.ys])))
    from ..tolerances import FRAME_AXIS_REL

    if (np.ptp(xs[:, 1]) > FRAME_AXIS_REL * max(1.0, np.ptp(xs[:, 0]))
            or np.ptp(ys[:, 0]) > FRAME_AXIS_REL * max(1.0, np.ptp(ys[:, 1]))):
        raise ValueError(f"simplified terrain {label!r}: its rows and columns are not aligned with the DEM's in the "
                         "DEM's frame (another projection?); resample it onto the DEM's CRS first")
    order_x, order_y = np.argsort(xs[:, 0]), np.argsort(ys[:, 1])
    z = terrain.z[np.ix_(order_y, order_x)]
    return HeightGrid.from_coords(z, xs[order_x, 0], ys[order_y, 1], attrs=dict(terrain.attrs))


def _float32_slack(grid: HeightGrid, to) -> tuple[float, float]:
    """How far (x, y in the grid's frame) one float32 step of the given coordinates moves a position at the edge."""
    xmin, xmax, ymin, ymax = grid.extent
    given = to.from_grid(np.array([[xmin, ymin], [xmax, ymax]]))
    ulp = np.spacing(np.abs(given).max(axis=0).astype(np.float32)).astype(np.float64)
    step = np.abs(to.to_grid(given + ulp) - to.to_grid(given))
    return float(step[:, 0].max()), float(step[:, 1].max())


def _onto_edge(v: np.ndarray, lo: float, hi: float, slack: float = 0.0) -> np.ndarray:
    """Coordinates within rounding (and ``slack``) of ``lo`` or ``hi``, either side, put exactly on it."""
    from ..tolerances import EDGE_SNAP_REL, ROUNDING_ULPS

    tol = EDGE_SNAP_REL * (hi - lo) + ROUNDING_ULPS * np.spacing(max(abs(lo), abs(hi))) + slack
    v = v.copy()
    v[np.abs(v - lo) <= tol] = lo
    v[np.abs(v - hi) <= tol] = hi
    return v


def _check_overlap(terrain, grid: HeightGrid, frame: str, label: str) -> None:
    from ..core._positions import PositionFrame

    xmin, xmax, ymin, ymax = terrain.extent
    gx0, gx1, gy0, gy1 = grid.extent
    if xmax < gx0 or xmin > gx1 or ymax < gy0 or ymin > gy1:
        where = PositionFrame(grid, frame)
        v = PositionFrame(grid, "local").value  # the digits that show a tenth of a cell
        hint = ("; is it in the terrain's own frame? pass frame='local' (--frame local)" if frame == "native" else
                "; is it in the DEM's CRS? pass frame='native' (--frame native)")
        raise ValueError(f"simplified terrain {label!r} covers x [{v(xmin)}, {v(xmax)}], y [{v(ymin)}, {v(ymax)}] "
                         f"in the terrain's frame, which does not overlap the DEM's footprint "
                         f"{where.footprint()}{hint}")


def _checked_tin(tin: TIN, grid: HeightGrid, repair: bool, label: str) -> TIN:
    from ..core.repair import height_field_problems, repair_tin, reversed_winding

    done = {}
    tin, merged = _merged_duplicates(tin)
    if merged:  # a mesh written face by face (PLY and OBJ keep such copies; STL's reader merges them)
        done["merged"] = merged
    if reversed_winding(tin):  # the other orientation of one consistent mesh: the same surface
        tin = TIN(tin.vertices, tin.faces[:, [0, 2, 1]], attrs=dict(tin.attrs))
        done["reversed"] = 1
    problems = height_field_problems(tin, grid)
    if not problems:
        return _with_repair(tin, done) if done else tin
    if not repair:
        raise ValueError(f"simplified terrain {label!r} is not a height field over the DEM's footprint: "
                         + "; ".join(problems) + "; repair it with repair=True (--repair), as terrainvis repairs "
                         "QEC's meshes")
    try:
        fixed = repair_tin(tin, grid, source=f"simplified terrain {label!r}")
    except ValueError as exc:
        raise ValueError(str(exc)) from None
    attrs = dict(fixed.attrs)
    record = attrs.pop("repair")  # this run's repair, apart from a method's own record (QEC's post-processing)
    if "repair" in tin.attrs:
        attrs["repair"] = tin.attrs["repair"]
    return _with_repair(TIN(fixed.vertices, fixed.faces, attrs=attrs), {**done, **record})


def _merged_duplicates(tin: TIN) -> tuple[TIN, int]:
    """``tin`` with its exactly repeated vertices (x, y and z) made one, and how many went: the
    same surface, as one connected mesh."""
    v, inverse = np.unique(tin.vertices, axis=0, return_inverse=True)
    merged = tin.n_vertices - v.shape[0]
    if not merged:
        return tin, 0
    faces = inverse.reshape(-1)[tin.faces]
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    return TIN(v, faces[keep], attrs=dict(tin.attrs)), merged


#: The attrs key of what :func:`evaluate` changed in a mesh to measure it (reversed faces, a
#: repair): the ``repair`` and ``repair_max_snap`` columns.
EVALUATE_REPAIR = "evaluate_repair"


def _with_repair(tin: TIN, record: dict) -> TIN:
    tin.attrs[EVALUATE_REPAIR] = record
    return tin


def _covering(s: HeightGrid, grid: HeightGrid, label: str) -> HeightGrid:
    """A raster extended by its edge samples to the grid's footprint, when it falls short by at most one of its cells."""
    from ..core._positions import PositionFrame
    from ..tolerances import EDGE_SNAP_REL

    xs, ys, z = s.xs, s.ys, s.z
    if not np.isfinite(z).all():
        raise ValueError(f"simplified terrain {label!r} has {int((~np.isfinite(z)).sum())} nodata samples; a "
                         "simplification must cover every point of the original")
    gx0, gx1, gy0, gy1 = grid.extent
    # an edge sample within rounding of the DEM's edge is on it: a raster written by terrainvis
    # has 4.5e-13 of noise in its transform, and padding a whole row for it added 30 vertices
    # to a 30 x 30 grid (the size columns and --against's budgets off by 1.7-3.3 %)
    xs, ys = _onto_edges(xs, gx0, gx1), _onto_edges(ys, gy0, gy1)
    pads = []
    for lo, hi, axis_lo, axis_hi, step, what in (
            (gx0, gx1, xs[0], xs[-1], xs[1] - xs[0] if xs.size > 1 else 0.0, "x"),
            (gy0, gy1, ys[0], ys[-1], ys[1] - ys[0] if ys.size > 1 else 0.0, "y")):
        short_lo, short_hi = max(0.0, axis_lo - lo), max(0.0, hi - axis_hi)
        if max(short_lo, short_hi) > step + EDGE_SNAP_REL * (hi - lo):  # one of its cells, and rounding
            v = PositionFrame(grid, "local").value  # the digits that show a tenth of a cell
            raise ValueError(f"simplified terrain {label!r} covers {what} [{v(axis_lo)}, {v(axis_hi)}], short of "
                             f"the DEM's [{v(lo)}, {v(hi)}] by more than one of its cells; a simplification must "
                             "cover the original's footprint")
        pads.append((short_lo > 0, short_hi > 0))
    (pad_x0, pad_x1), (pad_y0, pad_y1) = pads
    if not any((pad_x0, pad_x1, pad_y0, pad_y1)):
        if xs is s.xs and ys is s.ys:
            return s
        return HeightGrid.from_coords(z, xs, ys, attrs=s.attrs)
    if pad_x0:
        xs, z = np.concatenate([[gx0], xs]), np.concatenate([z[:, :1], z], axis=1)
    if pad_x1:
        xs, z = np.concatenate([xs, [gx1]]), np.concatenate([z, z[:, -1:]], axis=1)
    if pad_y0:
        ys, z = np.concatenate([[gy0], ys]), np.concatenate([z[:1], z], axis=0)
    if pad_y1:
        ys, z = np.concatenate([ys, [gy1]]), np.concatenate([z, z[-1:]], axis=0)
    attrs = {**s.attrs, "padded": "edge samples extended to the DEM's footprint (a raster's sample centres lie half "
                                  "a cell inside it)"}
    return HeightGrid.from_coords(z, xs, ys, attrs=attrs)


def _onto_edges(axis: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """``axis`` with its first and last coordinates put on ``lo`` and ``hi`` when within rounding
    of them (:data:`~terrainvis.tolerances.EDGE_SNAP_REL` of the extent, and a few ulps); the
    array itself when nothing moves."""
    from ..tolerances import EDGE_SNAP_REL, ROUNDING_ULPS

    tol = EDGE_SNAP_REL * (hi - lo) + ROUNDING_ULPS * np.spacing(max(abs(lo), abs(hi)))
    first = lo if axis[0] != lo and abs(axis[0] - lo) <= tol else axis[0]
    last = hi if axis[-1] != hi and abs(axis[-1] - hi) <= tol else axis[-1]
    if first == axis[0] and last == axis[-1]:
        return axis
    out = axis.copy()
    out[0], out[-1] = first, last
    return out


def _check_engine(settings, terrains: dict) -> None:
    from ..visibility.engines import AUTO, ENGINES

    if settings.engine == AUTO:
        return
    for label, t in terrains.items():
        if not ENGINES[settings.engine].runs_on(t):
            raise ValueError(f"engine {settings.engine!r} does not run on simplified terrain {label!r} "
                             f"({describe(t)}); use engine='auto'")


# ---------------------------------------------------------------------- the rows
def _nearest_level(shape, n_vertices: int) -> int:
    from .units import nearest_level

    return nearest_level(shape, n_vertices)


class _Unit(NamedTuple):
    """One unit of an :func:`evaluate` run: ``key`` is ``(terrain, method, level)``
    (:data:`~terrainvis.experiment.collect.UNIT_KEY`), ``base`` its rows' shared columns, and
    ``source`` what is measured: a simplified terrain as read, or ``(method, level,
    n_vertices)`` of an ``against`` method (``n_vertices`` None for a regular one)."""

    key: tuple
    base: dict
    source: object


def _units(grid: HeightGrid, tname: str, terrains: dict, against: list, settings) -> list[_Unit]:
    """The run's units in order: each simplified terrain, then each ``against`` method at each
    size. An irregular method measured at two sizes nearest one level has two units under one key."""
    from simplifiers import METHODS

    from ..core.repair import repair_summary
    from .units import _base

    units = []
    for label, s in terrains.items():
        n = s.size if isinstance(s, HeightGrid) else s.n_vertices
        kind = "regular" if isinstance(s, HeightGrid) else str(s.attrs.get("kind") or "irregular")
        if kind not in ("regular", "irregular", "semi-regular") or (kind == "regular") != isinstance(s, HeightGrid):
            kind = "regular" if isinstance(s, HeightGrid) else "irregular"
        base = _base(grid, tname, label, kind, _nearest_level(grid.shape, n), settings)
        record = s.attrs.get(EVALUATE_REPAIR) or {}
        base["repair"] = repair_summary(record) or None
        base["repair_max_snap"] = float(record.get("max_snap", 0.0)) if record else np.nan
        base["zoom"] = int(s.attrs["zoom"]) if _from_tileset(s) else None
        units.append(_Unit((tname, label, base["level"]), base, s))
    sizes = sorted({(s.size if isinstance(s, HeightGrid) else s.n_vertices) for s in terrains.values()})
    for method in against:
        info = METHODS[method]
        done = set()
        for n in sizes:
            level = _nearest_level(grid.shape, n)
            if (level if info.regular else n) in done:  # a regular method has one size per level
                continue
            done.add(level if info.regular else n)
            base = _base(grid, tname, method, info.kind, level, settings)
            units.append(_Unit((tname, method, level), base, (method, level, None if info.regular else n)))
    return units


def _store(out_csv, record: dict, units: list, settings, resume: bool):
    """The results file of a run with ``out_csv`` (None without), and the unit keys it holds complete."""
    if out_csv is None:
        return None, frozenset()
    from collections import Counter

    from .collect import UNIT_KEY, columns, optional_columns, rows_per_unit
    from .results import ResultStore

    per_unit = rows_per_unit(settings)
    count = Counter(unit.key for unit in units)
    store = ResultStore(out_csv, record, columns(), UNIT_KEY, lambda key: count.get(key, 0) * per_unit, resume=resume,
                        optional=optional_columns(settings.measure))
    return store, frozenset(store.done)


def _rows(grid: HeightGrid, tname: str, units: list, store, done, on_unit, settings) -> pd.DataFrame:
    """Measure the units not ``done``, each one's rows stored as it finishes; the table of every row.

    A unit that fails keeps its rows with the message in ``error``, as in
    :func:`terrainvis.compare`. A simplified terrain's errors are those of the surface as
    read, never those its file records."""
    from simplifiers import simplify

    from .collect import columns, order, table
    from .measures import MEASURES
    from .units import failed_rows, measured_rows

    rows, sets = [], None
    for key, base, source in units:
        if key in done:
            continue
        if sets is None:  # the point sets, made once, when the first unit needs them
            sets = MEASURES[settings.measure].sets(grid, tname, settings)
        made = isinstance(source, tuple)
        try:
            if made:
                method, level, n = source
                source = simplify(grid, method, level) if n is None else simplify(grid, method, level, n_vertices=n)
            unit = measured_rows(grid, source, base, settings, sets, stored_errors=made)
        except Exception as exc:
            unit = failed_rows(base, exc, settings, sets)
        rows += unit
        if store is not None:
            store.add(unit)
        if on_unit is not None:
            on_unit(key, pd.DataFrame(unit, columns=list(columns())))
    df = order(store.rows() if store is not None else table(rows), {tname: grid})
    if store is not None:
        store.finish(df)
    return df
