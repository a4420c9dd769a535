"""Quadric edge collapse (Garland and Heckbert 1997) with an exact rectangular footprint.

The collapses themselves are done by a library: pymeshlab's
``meshing_decimation_quadric_edge_collapse`` (VCG; planar quadric, normal preservation
and optimal placement), the paper's method, or ``fast_simplification.simplify``
(Forstmann's threshold variant), faster and smaller in memory (measured figures:
``docs/performance.md#simplifiers-figures-behind-their-defaults``). ``backend="auto"`` (the default) takes pymeshlab up to
:data:`AUTO_MAX_SAMPLES` grid samples and fast-simplification above; ``attrs["backend"]``
records the library used.

This module holds the library adapters and the search for the exact vertex budget; every
decimated mesh is then turned into a valid height field over the grid's exact extent by
:class:`terrainvis.core.repair.PostProcessor` (boundary snapping, fold-over repair).

**Units for pymeshlab.** VCG ranks a collapse by its quadric error after normalising it by
the bounding-box diagonal (``1e8 / diag**6``); an error below its ``QuadricEpsilon``
(1e-15) is clamped and multiplied by the edge's length in mesh units. The share of clamped
collapses grows with the number of faces, and with metres as units (edges of 30-60 m) a
clamped collapse ranks behind collapses with a much larger error, and the result depends
on the grid's unit and on the bounding box (the figures are in the docs). The adapter
therefore hands pymeshlab coordinates in units of the input's longest edge, so that a
clamped collapse ranks before the others and the results no longer depend on the unit of
the grid (``tests/methods/test_quadric.py``). With these units the boundary weight that keeps the
border in place is 10.
fast-simplification compares its errors with an absolute threshold schedule in squared
mesh units and gets metres (or larger units, when its schedule runs out).

**Tiles.** Above :data:`TILE_SAMPLES` samples (option ``tile_samples``) the grid is first
decimated tile by tile, each tile with its border kept, to 1.2 times its share of the
budget; the tiles are stitched along their identical borders and the global passes below
take the stitched mesh to the budget (the block-based scheme of Hoppe 1998). The library
then never holds more than a tile or about 1.2 times the budget (the library keeps its
buffers, sized for the largest mesh it was given, until the process ends).

**Budget.** The vertex count of the *post-processed* mesh must be within
:func:`~simplifiers.levels.budget_tolerance` of the budget. The libraries take a face
target, and a disk has F = 2V - B - 2 faces (B boundary vertices), so the decimation runs
in stages: a first pass to about the budget, then, when needed, further passes on the
decimated mesh with face targets corrected from the measured count (a later pass starts
from fresh quadrics of the decimated mesh; at 1 % tolerance on large grids the first pass
is usually enough). An overshoot restarts from the last mesh above the budget with a
smaller step. When a pass cannot be post-processed (a library output that is not a disk,
or whose border misses the corners' order; seen on tiny budgets) or the library stalls,
the last valid result a little above the budget (at most ``max(16, min(budget // 10,
200))`` vertices) is finished by our own valid half-edge collapses, flattest vertex
first (``attrs["collapses"]``).

**Cascading levels.** ``build(grid, n, start=tin)`` decimates ``tin``, a finer result on
the same grid, instead of the full grid: each later level costs a decimation of the
finer TIN, not of the grid. The later levels start from quadrics of the finer TIN, not
of the grid, so their errors differ a little from independent runs (figures and
``benchmarks/bench_quadric.py --cascade`` in the docs). ``simplify`` runs every level
independently unless given ``start``; ``terrainvis.compare`` cascades on grids above
:data:`terrainvis.experiment.CASCADE_AUTO_MIN_SAMPLES` samples (``cascade="auto"``).

References
----------
M. Garland and P. S. Heckbert, "Surface simplification using quadric error metrics",
SIGGRAPH 1997, DOI 10.1145/258734.258849.

H. Hoppe, "Smooth view-dependent level-of-detail control and its application to terrain
rendering", IEEE Visualization 1998, 35-42, DOI 10.1109/VISUAL.1998.745282.

P. Cignoni, M. Callieri, M. Corsini, M. Dellepiane, F. Ganovelli and G. Ranzuglia,
"MeshLab: an open-source mesh processing tool", Eurographics Italian Chapter Conference
2008, DOI 10.2312/LocalChapterEvents/ItalChap/ItalianChapConf2008/129-136.
"""

from __future__ import annotations

import functools
import math
import time

import numpy as np

from terrainvis.core.interrupt import abandonable, call_in_child, call_library, import_library
from terrainvis.core.memory import release_freed_memory
from terrainvis.core.mesh import boundary_edges
from terrainvis.core.validate import as_int, describe
from terrainvis.errors import SimplificationError
from terrainvis.core.terrain import TIN, HeightGrid
from terrainvis.tolerances import TILE_BORDER_REL

from terrainvis.core.repair import PostError, PostProcessor
from .levels import budget_tolerance, check_budget

__all__ = [
    "build", "resolve_backend", "report_notes", "BACKENDS", "AUTO_MAX_SAMPLES", "TILE_SAMPLES", "PYMESHLAB_DEFAULTS",
    "FAST_DEFAULTS",
]

#: The decimation libraries :func:`build` can use (and ``"auto"`` to choose by size).
BACKENDS = ("pymeshlab", "fast-simplification")

#: ``backend="auto"`` uses pymeshlab (the paper's method) for grids of at most this many
#: samples (1024² and 1025² included, 1095² at most) and fast-simplification above, where
#: pymeshlab's time per level grows past a minute (figures in docs/performance.md#simplifiers-figures-behind-their-defaults).
AUTO_MAX_SAMPLES = 1_200_000

#: pymeshlab filter settings used unless overridden through ``**tuning``. ``boundaryweight``
#: 10 keeps the border within a fraction of a cell of its lines (larger weights keep too
#: many boundary vertices at small budgets, 1 loses corners). ``preservenormal`` costs
#: time and changes nothing on smooth terrain, but cliffs suffer without it.
#: ``qualitythr`` must be > 0: VCG divides each collapse's error by
#: ``min(quality, qualitythr)``.
PYMESHLAB_DEFAULTS = {
    "qualitythr": 0.3,
    "boundaryweight": 10.0,
    "preservenormal": True,
    "preservetopology": True,
    "optimalplacement": True,
    "planarquadric": True,
    "planarweight": 0.001,
    "qualityweight": False,
}

#: fast-simplification settings used unless overridden through ``**tuning``.
FAST_DEFAULTS = {"agg": 7.0}

_BOOL_KEYS = {"preservenormal", "preservetopology", "optimalplacement", "planarquadric", "qualityweight"}

#: Options accepted by both backends (post-processing and budget search).
_COMMON_DEFAULTS = {"corner_tol": 0.25, "max_stages": 30, "tile_samples": None}


# --------------------------------------------------------------------------- public
def build(grid: HeightGrid, n_vertices: int, *, backend: str = "auto", start: TIN | None = None, **tuning) -> TIN:
    """Quadric edge collapse of a height grid to a TIN with ``n_vertices`` vertices.

    Parameters
    ----------
    grid : HeightGrid
        The terrain, without nodata. Uniform or rectilinear; cells need not be square
        (everything runs in world coordinates, shifted to a local origin for the
        libraries).
    n_vertices : int
        The vertex budget, in [4, grid.size]. The result has this many vertices to
        within :func:`simplifiers.levels.budget_tolerance` (1 %, at least one).
    backend : {"auto", "pymeshlab", "fast-simplification"}
        The library that performs the collapses; ``"auto"`` chooses by the grid's sample
        count (:func:`resolve_backend`).
    start : TIN, optional
        A finer result on the same grid (a previous :func:`build` with more vertices):
        decimate it instead of the full grid (cascading levels). Its extent must be the
        grid's and it must have more than ``n_vertices`` vertices. Default: decimate the
        full grid (independent levels).
    **tuning
        For pymeshlab: any of :data:`PYMESHLAB_DEFAULTS` (``qualitythr``,
        ``boundaryweight``, ``preservenormal``, ``preservetopology``,
        ``optimalplacement``, ``planarquadric``, ``planarweight``, ``qualityweight``).
        For fast-simplification: ``agg`` (aggressiveness, default 7).
        For both: ``corner_tol`` (a boundary vertex closer than this many grid
        spacings to a corner becomes the corner, default 0.25), ``max_stages``
        (decimation passes allowed to meet the budget, default 30) and
        ``tile_samples`` (grids with more samples are first decimated in tiles of at
        most this many samples, default :data:`TILE_SAMPLES`; at least 16; not used
        with ``start``). With
        ``backend="auto"``, the options must suit the backend chosen.

    Returns
    -------
    TIN
        Counter-clockwise faces covering exactly ``grid.extent``. ``attrs`` records the
        ``backend`` used, the ``settings``, ``start_vertices`` (vertices of ``start``,
        or of the grid), ``tiles`` (tile rows and columns of the first phase, or None),
        ``tiled_vertices`` (vertices after it, or None), ``tile_fallbacks`` (tiles kept
        undecimated because the library lost part of their border), ``stages`` (global decimation
        passes), ``failures`` (passes whose
        output could not be post-processed), ``history`` (target faces, faces and
        vertices, or the error, per pass), ``target_faces`` (of the last pass),
        ``snapped`` (boundary vertices moved onto a boundary line), ``max_snap``
        (largest such move, in world units), ``reordered`` (boundary chains whose order
        had to be restored), ``corners_inserted``, ``boundary`` (boundary vertices),
        ``repairs`` (fold-over relocations), ``collapses`` (vertex removals by our own
        half-edge collapses) and ``timing`` (seconds spent on ``setup``, on the
        ``tiles``, in the library's global passes (``library``), in ``post``-processing
        and in our ``finish``-ing collapses).

    Raises
    ------
    SimplificationError
        When the library fails or no valid height field within the budget is found;
        the message names the backend and the cause.

    Examples
    --------
    >>> import numpy as np
    >>> from terrainvis import HeightGrid
    >>> yy, xx = np.mgrid[0:20, 0:20]
    >>> g = HeightGrid(np.sin(xx / 3.0) * 10 + yy, dx=30.0, dy=30.0)
    >>> tin = build(g, 100)
    >>> abs(tin.n_vertices - 100) <= 1, tin.is_height_field(), tin.extent == g.extent
    (True, True, True)
    >>> tin.attrs["backend"]
    'pymeshlab'
    >>> coarse = build(g, 40, start=tin)  # the next level, from the finer one
    >>> abs(coarse.n_vertices - 40) <= 1, coarse.attrs["start_vertices"] == tin.n_vertices
    (True, True)
    """
    t_setup = time.perf_counter()
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
    grid.require_finite("quadric edge collapse")
    n_vertices = check_budget(grid.shape, n_vertices, "n_vertices")
    backend = resolve_backend(backend, grid.size)
    settings, common = _check_tuning(backend, tuning)
    if start is not None:
        _check_start(start, grid, n_vertices)
    tol = budget_tolerance(n_vertices)
    if start is None and n_vertices == grid.size:
        fine = grid.to_tin()
        return TIN(fine.vertices, fine.faces, attrs={"backend": backend, "stages": 0})
    origin = np.array([grid.xs[0], grid.ys[0], float(np.mean(grid.z))])
    decimate = functools.partial(_pymeshlab_decimate if backend == "pymeshlab" else _fast_decimate, settings=settings)
    tile_samples = TILE_SAMPLES if common["tile_samples"] is None else common["tile_samples"]
    tiled, t_tiles = {"tiles": None, "tile_fallbacks": 0}, 0.0
    if start is not None:
        local = start.vertices - origin  # a new array: start is not modified
        faces = np.array(start.faces, dtype=np.int32)
    elif grid.size > tile_samples:
        t0 = time.perf_counter()
        local, faces, tiled = _tiled_mesh(grid, origin, n_vertices, decimate, tile_samples)
        t_tiles = time.perf_counter() - t0
    else:
        local, faces = _grid_mesh(grid, origin)
    search = _BudgetSearch(decimate, PostProcessor(grid, common["corner_tol"]), origin, n_vertices, tol, backend)
    timing = {"setup": time.perf_counter() - t_setup - t_tiles, "tiles": t_tiles}
    vertices, out_faces, stats = search.run(local, faces, common["max_stages"])
    timing.update(search.timing)
    meta = {
        "backend": backend, "settings": dict(settings),
        "start_vertices": grid.size if start is None else start.n_vertices,
        **tiled, "tiled_vertices": int(local.shape[0]) if tiled["tiles"] else None,
        **stats, **search.info(), "timing": timing,
    }
    return TIN(vertices, out_faces, attrs=meta)


def resolve_backend(backend, n_samples: int) -> str:
    """The library :func:`build` uses for ``backend`` on a grid of ``n_samples`` samples.

    Examples
    --------
    >>> resolve_backend("auto", 120 * 120), resolve_backend("auto", 3601 * 3601)
    ('pymeshlab', 'fast-simplification')
    >>> resolve_backend("fast-simplification", 100)
    'fast-simplification'
    """
    if backend == "auto":
        return "pymeshlab" if n_samples <= AUTO_MAX_SAMPLES else "fast-simplification"
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {['auto', *BACKENDS]}, got {backend!r}")
    return backend


# --------------------------------------------------------------------------- options
def _check_tuning(backend: str, tuning: dict):
    defaults = PYMESHLAB_DEFAULTS if backend == "pymeshlab" else FAST_DEFAULTS
    settings = dict(defaults)
    common = dict(_COMMON_DEFAULTS)
    for key, value in tuning.items():
        if key in common:
            if key == "max_stages":
                common[key] = as_int(value, key, minimum=1)
            elif key == "tile_samples":
                common[key] = as_int(value, key, minimum=16)
            else:
                common[key] = _positive(value, key)
        elif key in settings:
            if key in _BOOL_KEYS:
                if not isinstance(value, (bool, np.bool_)):
                    raise TypeError(f"{key} must be a bool, got {describe(value)}")
                settings[key] = bool(value)
            else:
                settings[key] = _positive(value, key)
        else:
            valid = sorted(list(defaults) + list(common))
            raise TypeError(f"unknown option {key!r} for backend {backend!r}; valid options are {valid}")
    if common["corner_tol"] >= 0.5:
        raise ValueError(f"corner_tol must be < 0.5 grid spacings, got {common['corner_tol']!r}")
    return settings, common


def _positive(value, name: str) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number, got {describe(value)}")
    out = float(value)
    if not math.isfinite(out) or out <= 0:
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return out


def _check_start(start, grid: HeightGrid, n_vertices: int) -> None:
    if not isinstance(start, TIN):
        raise TypeError(f"start must be a terrainvis.TIN (a finer qec result on the same grid), got {describe(start)}")
    if start.extent != grid.extent:
        raise ValueError(f"start must cover the grid's extent {grid.extent}, got a TIN over {start.extent}")
    if start.n_vertices <= n_vertices:
        raise ValueError(
            f"start must have more vertices than n_vertices={n_vertices} (it is decimated further), "
            f"got a TIN with {start.n_vertices}"
        )


# --------------------------------------------------------------------------- backends
def _grid_mesh(grid: HeightGrid, origin: np.ndarray, rows: slice = slice(None), cols: slice = slice(None)):
    """The grid's TIN (the faces of :meth:`HeightGrid.to_tin`) relative to ``origin``.

    ``rows`` and ``cols`` (steps of 1) select a window; its vertices are numbered row-major
    within the window. Returns ``(vertices (n, 3) float64, faces (m, 3) int32)``, built
    without the grid's cached TIN and its int64 temporaries (about a fifth of the memory).
    """
    xs, ys, z = grid.xs[cols], grid.ys[rows], grid.z[rows, cols]
    nr, nc = z.shape
    v = np.empty((nr * nc, 3))
    v[:, 0] = np.tile(xs - origin[0], nr)
    v[:, 1] = np.repeat(ys - origin[1], nc)
    v[:, 2] = z.ravel() - origin[2]
    idx = np.arange(nr * nc, dtype=np.int32).reshape(nr, nc)
    f = np.empty((nr - 1, nc - 1, 2, 3), dtype=np.int32)
    f[:, :, :, 0] = idx[:-1, :-1, None]  # both triangles of a cell start at (r, c)
    f[:, :, 0, 1] = idx[:-1, 1:]
    f[:, :, 0, 2] = idx[1:, 1:]
    f[:, :, 1, 1] = idx[1:, 1:]
    f[:, :, 1, 2] = idx[1:, :-1]
    return v, f.reshape(-1, 3)


def _longest_edge(v: np.ndarray, f: np.ndarray, chunk: int = 1 << 20) -> float:
    """Length of the longest edge of a mesh (faces in chunks, to bound the temporaries)."""
    longest = 0.0
    for s in range(0, f.shape[0], chunk):
        ff = f[s : s + chunk]
        for i in range(3):
            d = v[ff[:, i]] - v[ff[:, (i + 1) % 3]]
            longest = max(longest, float(np.sqrt(np.einsum("ij,ij->i", d, d).max())))
    return longest


def _pymeshlab_decimate(vertices: np.ndarray, faces: np.ndarray, target_faces: int, settings: dict,
                        keep_border: bool = False):
    """One pymeshlab pass: (vertices, faces) of the decimated mesh, in the input's coordinates.

    pymeshlab sees the mesh in units of its longest edge (see the module notes). With
    ``keep_border`` no border vertex is removed or moved. A command runs a long pass in a
    child process, which Ctrl-C abandons at once (:func:`terrainvis.core.interrupt.abandonable`).
    """
    if abandonable(vertices.shape[0]):
        return call_in_child(_pymeshlab_pass, vertices, faces, target_faces, settings, keep_border,
                             what="pymeshlab's quadric edge collapse")
    return _pymeshlab_pass(vertices, faces, target_faces, settings, keep_border)


def _pymeshlab_pass(vertices, faces, target_faces, settings, keep_border):
    """:func:`_pymeshlab_decimate`'s pass, in this process."""
    pymeshlab = import_library("pymeshlab")  # an interrupt during its import would become an ImportError
    unit = _longest_edge(vertices, faces) or 1.0
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices / unit, face_matrix=np.asarray(faces, dtype=np.int32)))
    call_library(
        ms.meshing_decimation_quadric_edge_collapse, what="pymeshlab's quadric edge collapse",
        targetfacenum=int(target_faces), targetperc=0.0, preserveboundary=bool(keep_border), autoclean=True,
        selected=False,
        **settings,
    )
    m = ms.current_mesh()
    v = np.array(m.vertex_matrix(), dtype=np.float64) * unit
    f = np.array(m.face_matrix(), dtype=np.int64)
    del m, ms
    release_freed_memory()
    return _compact(v, f)


def _fast_decimate(vertices: np.ndarray, faces: np.ndarray, target_faces: int, settings: dict,
                   keep_border: bool = False):
    """One fast-simplification pass: (vertices, faces) of the decimated mesh, in the input's units.

    With ``keep_border`` no edge touching a border vertex collapses (border vertices stay).
    A command runs a long pass in a child process, as :func:`_pymeshlab_decimate` does.

    Its collapse threshold grows as 1e-9 (iteration + 3) ** agg, in squared mesh units
    (metres for a grid in metres), for at most 100 iterations, so a rough terrain may stop
    short of the target; the caller then runs another pass, which starts from fresh
    quadrics. A pass that removes less than half of the faces asked for has run out of
    threshold (errors far above 1e5 squared units, e.g. a grid in millimetres): it is
    repeated in units ten times larger, up to :data:`_FAST_RESCALES` times.
    """
    if abandonable(vertices.shape[0]):
        return call_in_child(_fast_pass, vertices, faces, target_faces, settings, keep_border,
                             what="fast-simplification's edge collapse")
    return _fast_pass(vertices, faces, target_faces, settings, keep_border)


def _fast_pass(vertices, faces, target_faces, settings, keep_border):
    """:func:`_fast_decimate`'s passes, in this process."""
    fast_simplification = import_library("fast_simplification")
    faces = np.ascontiguousarray(faces, dtype=np.int32)  # the library copies its input
    asked = faces.shape[0] - int(target_faces)
    unit = 1.0
    for attempt in range(_FAST_RESCALES + 1):
        v, f = call_library(
            fast_simplification.simplify,
            np.ascontiguousarray(vertices / unit if attempt else vertices, dtype=np.float64), faces,
            what="fast-simplification's edge collapse",
            target_count=int(target_faces), agg=float(settings["agg"]), preserve_border=bool(keep_border),
        )
        if faces.shape[0] - f.shape[0] >= asked / 2 or attempt == _FAST_RESCALES:
            break
        unit *= 10.0
    release_freed_memory()
    return _compact(np.asarray(v, dtype=np.float64) * unit, np.asarray(f, dtype=np.int64).reshape(-1, 3))


#: Rescalings (by 10 each) fast-simplification may take when its threshold schedule runs out.
_FAST_RESCALES = 8


def _compact(v: np.ndarray, f: np.ndarray):
    """Drop unreferenced vertices (keeping their order) and renumber the faces."""
    used = np.zeros(v.shape[0], dtype=bool)
    used[f.ravel()] = True
    if used.all():
        return v, f
    new = np.cumsum(used) - 1
    return v[used], new[f]


# --------------------------------------------------------------------------- tiles
def _tile_edges(n: int, parts: int) -> np.ndarray:
    """Indices where ``parts`` tiles along an axis of ``n`` samples meet (tiles share them)."""
    return np.linspace(0, n - 1, parts + 1).round().astype(np.int64)


def _tiled_mesh(grid: HeightGrid, origin: np.ndarray, budget: int, decimate, tile_samples: int):
    """Phase one of a tiled decimation: the grid decimated tile by tile, borders kept.

    The grid is cut into tiles of at most ``tile_samples`` samples that share their border
    rows and columns. Each tile is decimated on its own, with every border vertex kept, to
    its share of ``budget`` (times :data:`_TILE_MARGIN`) plus its border; the tiles are then
    stitched along their identical borders. Returns ``(vertices (n, 3) local, faces (m, 3)
    int32, info)``: a disk of about ``1.2 * budget`` vertices plus the tile borders, which
    the global passes decimate to the budget, and ``info`` with ``tiles`` (tile rows and
    columns) and ``tile_fallbacks`` (tiles whose decimation lost part of their border, kept
    undecimated). Only one tile's mesh is in the library at a time.
    """
    rows, cols = grid.shape
    side = max(math.sqrt(tile_samples) - 1.0, 2.0)  # cells along a tile's side
    parts = (max(1, math.ceil((rows - 1) / side)), max(1, math.ceil((cols - 1) / side)))
    re, ce = _tile_edges(rows, parts[0]), _tile_edges(cols, parts[1])
    lx, ly = grid.xs - origin[0], grid.ys - origin[1]
    tiny = TILE_BORDER_REL * max(lx[-1] - lx[0], ly[-1] - ly[0])
    keys, verts, faces = [], [], []
    n_stacked = fallbacks = 0
    n_interior = grid.size  # interior vertices take keys from here on (border ones: r * cols + c)
    for i in range(parts[0]):
        for j in range(parts[1]):
            r0, r1, c0, c1 = int(re[i]), int(re[i + 1]), int(ce[j]), int(ce[j + 1])
            v, f = _grid_mesh(grid, origin, slice(r0, r1 + 1), slice(c0, c1 + 1))
            h, w = r1 - r0 + 1, c1 - c0 + 1
            n_border = 2 * (h + w) - 4
            share = _TILE_MARGIN * budget * (h * w) / grid.size
            target = int(2 * share + n_border - 2)  # F = 2V - B - 2 with V = share + B
            placed = None
            if target < f.shape[0] - 1:
                dv, df = decimate(v, f, max(target, 2), keep_border=True)
                placed = _tile_border(dv, df, lx, ly, n_border, tiny)
                if placed is None:  # the library lost or moved part of the border: keep the tile as it is
                    fallbacks += 1
                else:
                    v, f = dv, df
            if placed is None:
                placed = _tile_border(v, f, lx, ly, n_border, tiny)  # the undecimated tile: always whole
            on, r, c = placed
            v[on, 0], v[on, 1], v[on, 2] = lx[c], ly[r], grid.z[r, c] - origin[2]  # exact samples again
            key = np.empty(v.shape[0], dtype=np.int64)
            key[on] = r * cols + c
            key[~on] = n_interior + np.arange(int((~on).sum()))
            n_interior += int((~on).sum())
            keys.append(key)
            verts.append(v)
            faces.append(np.asarray(f, dtype=np.int64) + n_stacked)
            n_stacked += v.shape[0]
    _, first, inverse = np.unique(np.concatenate(keys), return_index=True, return_inverse=True)
    vertices = np.concatenate(verts)[first]
    out_faces = inverse[np.concatenate(faces)].astype(np.int32)
    return vertices, out_faces, {"tiles": parts, "tile_fallbacks": fallbacks}


def _tile_border(v, f, lx, ly, n_border: int, tiny: float):
    """``(on, rows, cols)``: the tile's boundary vertices and the grid samples they sit on
    (within ``tiny``), or None when the boundary is not the tile's whole border."""
    on = np.zeros(v.shape[0], dtype=bool)
    on[boundary_edges(f, v.shape[0]).ravel()] = True
    if on.sum() != n_border:
        return None
    c = _nearest(lx, v[on, 0])
    r = _nearest(ly, v[on, 1])
    if not ((np.abs(lx[c] - v[on, 0]) <= tiny) & (np.abs(ly[r] - v[on, 1]) <= tiny)).all():
        return None
    if np.unique(r * lx.size + c).size != n_border:
        return None
    return on, r, c


def _nearest(axis: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Index of the nearest entry of the increasing ``axis`` to each value."""
    i = np.clip(np.searchsorted(axis, values), 1, axis.size - 1)
    return np.where(np.abs(axis[i - 1] - values) <= np.abs(axis[i] - values), i - 1, i)


#: Grids with more samples than this are first decimated tile by tile (option ``tile_samples``).
TILE_SAMPLES = 2**22

#: A tile keeps this many times its share of the budget (plus its border) for the global passes.
_TILE_MARGIN = 1.2


# --------------------------------------------------------------------------- budget
def _finish_limit(budget: int) -> int:
    """Most vertices our own collapses may remove to finish a decimation (they are slow)."""
    return max(16, min(budget // 10, 200))


class _BudgetSearch:
    """Decimate in stages until the post-processed mesh is within ``tol`` of ``budget``.

    Each pass decimates ``base``, the last mesh known to post-process to more than
    ``budget`` vertices (at first the input). When a pass cannot be post-processed or
    the library cannot get closer, the last valid result above the budget (``best``)
    is finished by our own valid half-edge collapses.
    """

    def __init__(self, decimate, post: PostProcessor, origin, budget: int, tol: int, backend: str):
        self.decimate = decimate
        self.post = post
        self.origin = origin
        self.budget = budget
        self.tol = tol
        self.backend = backend
        self.stages = self.failures = 0
        self.history = []
        self.target = 0
        self.best = None  # the last valid post-processed result above the budget
        self.timing = {"library": 0.0, "post": 0.0, "finish": 0.0}

    def info(self) -> dict:
        return {
            "stages": self.stages, "failures": self.failures, "target_faces": int(self.target), "history": self.history,
        }

    def _error(self, reason: str) -> SimplificationError:
        return SimplificationError(f"qec ({self.backend} backend) cannot reach {self.budget} vertices: {reason}")

    def finish(self, reason: str):
        """Finish ``best`` by our own collapses, or raise naming ``reason``."""
        v, f, side, stats = self.best
        excess = v.shape[0] - self.budget
        if excess > _finish_limit(self.budget):
            raise self._error(
                f"{reason}; the closest valid mesh has {v.shape[0]} vertices "
                f"(passes: target faces, faces, vertices or error: {self.history})"
            )
        t0 = time.perf_counter()
        v, f, side, removed = self.post.remove_vertices(v, f, side, excess)
        self.timing["finish"] += time.perf_counter() - t0
        if abs(v.shape[0] - self.budget) > self.tol:
            raise self._error(
                f"{reason}, and only {removed} of {excess} further vertices could be removed by valid collapses"
            )
        return v, f, dict(stats, collapses=stats["collapses"] + removed)

    def run(self, local: np.ndarray, faces: np.ndarray, max_stages: int):
        """``(vertices, faces, stats)`` of the result, in world coordinates."""
        budget, tol = self.budget, self.tol
        # A disk has F = 2V - B - 2. Guess B low (a quarter of a uniform grid's boundary) so that
        # the first pass lands at or above the budget; later passes correct from measurements.
        target = 2 * budget - 2 - int(math.sqrt(budget))
        base_v, base_f = local, faces
        overshoots = 0
        while self.stages < max_stages:
            self.stages += 1
            target = int(min(max(target, 2), base_f.shape[0] - 1))
            self.target = target
            t0 = time.perf_counter()
            try:
                v, f = self.decimate(base_v, base_f, target)
            except (MemoryError, KeyboardInterrupt):
                raise
            except Exception as exc:  # the library failed: name it and the cause
                raise SimplificationError(
                    f"qec ({self.backend} backend) failed in decimation pass {self.stages} (target {target} faces): "
                    f"{type(exc).__name__}: {exc}"
                ) from exc
            t1 = time.perf_counter()
            self.timing["library"] += t1 - t0
            try:
                if f.shape[0] == 0:
                    raise PostError(f"qec ({self.backend} backend) returned an empty mesh")
                result = self.post.run(v + self.origin, f, f"qec ({self.backend} backend)")
            except PostError as exc:
                self.timing["post"] += time.perf_counter() - t1
                self.failures += 1
                self.history.append((target, int(f.shape[0]), str(exc)))
                if self.best is not None and self.best[0].shape[0] - budget <= _finish_limit(budget):
                    return self.finish(f"pass {self.stages} failed ({exc})")
                # decimate less: a result a little above the budget can be finished by our own collapses
                # (tiny meshes need a few tries; on large ones each try is expensive)
                if target >= base_f.shape[0] - 1 or self.failures >= (8 if base_f.shape[0] < 10_000 else 3):
                    if self.best is not None:
                        return self.finish(f"pass {self.stages} failed ({exc})")
                    raise SimplificationError(
                        f"{exc} ({self.failures} failed passes; target faces, faces and error per pass: {self.history})"
                    ) from exc
                target = target + max(2, target // 20)
                continue
            self.timing["post"] += time.perf_counter() - t1
            n_out = result[0].shape[0]
            self.history.append((target, int(f.shape[0]), int(n_out)))
            excess = n_out - budget
            if abs(excess) <= tol:
                return result[0], result[1], result[3]
            if excess > 0:
                self.best = result
                if f.shape[0] > target + max(4, target // 50):
                    # the library stopped short of the target (fast-simplification's threshold
                    # schedule): a new pass starts from fresh quadrics and goes further
                    if f.shape[0] < base_f.shape[0]:
                        base_v, base_f = v, f
                        continue
                    return self.finish(f"the library stalls at {f.shape[0]} faces for a target of {target}")
                if target <= 2:
                    return self.finish("the library reached its smallest target")
                base_v, base_f = v, f
                # each removed vertex costs about two faces (one on the border)
                b_frac = result[3]["boundary"] / max(n_out, 1)
                target = f.shape[0] - max(1, int(round(excess * (2.0 - b_frac))))
            else:
                overshoots += 1
                if self.best is not None and overshoots > 2:
                    return self.finish("the library keeps overshooting")
                # go back to the base mesh with a smaller step
                target = target + max(1, int(round(-excess * 2.0)))
                if target >= base_f.shape[0]:
                    if self.best is not None:
                        return self.finish("one collapse pass removes too many vertices")
                    raise self._error(f"the decimation jumps from {base_v.shape[0]} to {n_out} vertices")
        if self.best is not None:
            return self.finish(f"the budget was not met in {max_stages} passes")
        raise SimplificationError(
            f"qec ({self.backend} backend) did not meet the budget of {budget} +- {tol} vertices in {max_stages} "
            f"passes (targets, faces and vertices per pass: {self.history})"
        )


def report_notes(rows) -> list[str]:
    """The comparison report's note where QEC ran on fast-simplification (grids of more than
    :data:`AUTO_MAX_SAMPLES` samples): ``rows`` are QEC's rows of a comparison (the
    :attr:`simplifiers.registry.Method.report_notes` of ``"qec"``)."""
    if "backend" not in rows.columns:
        return []
    fast = sorted(set(rows.loc[rows["backend"] == "fast-simplification", "terrain"]))
    if not fast:
        return []
    return ["", f"Note: QEC ran on fast-simplification for {', '.join(fast)} (more than {AUTO_MAX_SAMPLES:,} "
                "samples, where pymeshlab takes minutes per level); pymeshlab, the paper's QEC, ran elsewhere."]
