"""Exact viewsheds: which samples of a grid an observer sees, under the project's LOS predicate.

The viewshed of an observer standing at ``(x, y)`` (the eye ``observer_height`` above the
surface there) is :func:`terrainvis.visibility.line_of_sight` from the eye to every sample
of a grid, each target standing ``target_height`` above the surface under test, with the
same trim and tolerance. On a HeightGrid the grid engine gives exactly the pair engine's
verdict (``grid_clearance``) for every sample, but decides most samples without walking
their rays.

How the grid engine decides a sample
------------------------------------
For a surface point P at horizontal distance d from the eye E, let its slope be
``s(P) = (surface(P) - z_E) / d``; a target T (distance D, slope ``s_T``) is visible iff
``d (s_T - s(P)) >= -tol`` for every P on its ray (after the trims), i.e. iff ``s_T``
reaches the horizon of its ray. On the piecewise-linear surface the horizon is attained
where the ray crosses a grid line or a cell diagonal, so cell-centre horizons (what GIS
sweeps compute) are only approximations; here they are replaced by *rigorous bounds*:

1. The directions around the eye are cut into narrow wedges (2048 of them near the eye,
   doubling at rings 128, 256, ... so that a wedge is at most about 0.7 cells wide), in 16
   angular sectors swept in parallel, ring by ring outwards (rings are the square annuli of
   cells around the eye's cell). For each wedge the sweep keeps an upper bound ``ub`` of
   the slope of every surface point in the wedge swept so far, and a lower bound ``lb`` of
   the horizon of every ray in the wedge (from cells or edges that every such ray
   crosses). Near the eye (rings <= 4) edges are clipped to each wedge exactly (the slope
   along an edge has a single critical point); farther out a cell is bounded from its four
   corners with a convexity correction of the distance.
2. A sample on ring j (the boundary of the box of cell rings <= j) is decided when the
   sweep reaches it, its wedge then holding the rings < j: blocked if ``lb > s_T``;
   otherwise, if ``s_T >= ub``, it is visible when its last ring (the 1-3 cells between
   ring j - 1 and the sample, with the trim at the sample) clears: ``s_T`` at least the
   bound of the corners of the cells its ray crosses there (the sample itself left out:
   no edge through it meets the ray elsewhere), or else an exact walk of that part.
   Otherwise (the sample is near its horizon) the wedge's upper bounds per
   block of 16 rings tell which parts of the ray can reach ``s_T``, and only those are
   walked exactly. Targets that are not the grid's samples (``at`` with other
   coordinates) are first sorted by sector and ring (counting sort) and decided the same
   way, from the rings at least one cell away from them plus an exact walk of the last two.
3. The few samples of rings 0 and 1, and any target whose exact walks come within the
   rounding margin of the threshold, are answered by the pair engine itself
   (:func:`terrainvis.visibility.grid.grid_clearance`, same delta and tol).

Every bound carries the rounding error of the computation (a bound ``e_h`` on the
absolute error of any computed height, derived from the grid's extent, slopes and
elevations) and decisions keep a margin ``64 e_h`` from the threshold ``-tol``, so the
decided samples get the pair engine's verdict (the exact walks evaluate the same
crossings with errors far below the margin), and samples within the margin go to the pair
engine.

On a grid with nodata the triangles touching a NaN sample are absent (as in
``HeightGrid.to_tin()``) and do not block; undecided samples are then answered by an exact
walk that skips the absent triangles (the pair engine needs a NaN-free grid).

References
----------
M. van Kreveld, "Variations on sweep algorithms: efficient computation of extended
viewsheds and class intervals", Proc. 7th Int. Symp. on Spatial Data Handling, 1996
(no DOI).

H. Haverkort, L. Toma, Y. Zhuang, "Computing visibility on terrains in external memory",
ACM J. Exp. Algorithmics 13, 2009, doi:10.1145/1412228.1412233.

B. Duvenhage, "Using an implicit min/max KD-tree for doing efficient terrain line of
sight calculations", AFRIGRAPH 2009, doi:10.1145/1503454.1503465.
"""

from __future__ import annotations

import math
import threading

import numba
import numpy as np

from ...tolerances import EXTENT_INSIDE_REL, HOLE_REACH_SLACK, OUTPUT_SETTLE_REL, TRIM_MARGIN_REL
from ...core.interrupt import THREAD_MIN_WORK, alongside, call
from ...core.memory import fresh_array
from ...core.mesh import footprint_matches
from ...core.surface import SurfaceGrid, no_pyramid, no_strips
from ...core.validate import describe
from ...errors import OutsideFootprintError
from ...core.terrain import TIN, HeightGrid, as_terrain, height_range
from . import _bound_kernels as _bk
from . import _geometry_kernels as _geo
from . import _sector_kernels as _sk
from . import _walk_kernels as _wk
from ..engines import Predicate, choose
from .field_of_view import apply_field_of_view, field_of_view_mask
from .output_modes import check_output, eye_thresholds, output_values, tin_of_grid_thresholds
from ..predicate import EARTH_RADIUS, _check_heights, clearance_tolerance, target_grid, terrain_scale, trim_length
from ..sight import KEYWORDS, Sight, _differs, engine_on, sight_of

__all__ = ["viewshed"]


# Sweep layout (see the module docstring): sectors (a multiple of 4), wedges near the eye
# (a power of 2, a multiple of the sectors), first ring where the wedges double (a multiple
# of the kernels' GROUP * BLOCK = 128 rings), last ring whose cells are clipped edge by
# edge. Each sector pays a fixed cost per ring (its two runs of cells located, the cells
# at its window's edges bounded by both neighbours and never hidden): 16 sectors took
# 0.12 s of one core for the 3601^2 low observer of benchmarks/bench_viewshed.py --peers
# against 0.20 s with 64, and 0.39 s against 0.46 s for the high one.
_N_SECTORS = 16
_B0 = 2048
_R1 = 128
_J_NEAR = 4
#: Targets per Embree call (bounds the temporary segment arrays).
_CHUNK = 1 << 20


def viewshed(
    terrain,
    observer,
    *,
    observer_height: float = 1.7,
    target_height: float = 0.0,
    max_distance=None,
    at=None,
    engine: str = "auto",
    curvature: float = 0.0,
    earth_radius: float = EARTH_RADIUS,
    azimuth=None,
    vertical=None,
    min_distance=None,
    sight=None,
    output: str = "visible",
    eye=None,
) -> np.ndarray:
    """Which samples of a grid are visible from an observer (or how far from visible they are).

    Parameters
    ----------
    terrain : HeightGrid or TIN
        The surface under test. A HeightGrid may hold NaN (nodata): the triangles touching
        a NaN sample are absent and do not block, as in ``HeightGrid.to_tin()``.
    observer : (2,) or (3,) array_like of float
        World coordinates (x, y) of the observer, inside the footprint (on a present
        triangle). The eye is at ``surface(x, y) + observer_height``; or the eye itself,
        (x, y, z), at any height (e.g. an observer of the original terrain relocated
        onto a simplification, possibly below its surface), and then ``observer_height``
        is not used.
    observer_height, target_height : float
        Heights (>= 0, z units) of the eye and of every target above the surface.
    max_distance : float, optional
        Samples farther than this horizontal distance from the observer are False.
    at : HeightGrid, optional
        The grid whose samples are the targets (normally the original terrain when
        ``terrain`` is a simplified surface); only its coordinates and its nodata mask
        are used: each target stands ``target_height`` above **terrain**'s surface at the
        sample. Required for a TIN; default for a HeightGrid: its own samples.
    engine : {"auto", "grid", "embree"}
        ``"grid"`` (HeightGrid only): exact, the pair engine's verdict for every sample.
        ``"embree"`` (any terrain; a HeightGrid goes through ``to_tin()``; flat earth
        only): float32 rays, agreeing with the exact answer outside
        :func:`~terrainvis.visibility.embree_tolerance`. ``"auto"``: grid for a
        HeightGrid; for a TIN embree, or under earth curvature the exact TIN clipper
        (one exact clip walk per target).
    curvature : float, default 0.0
        Earth curvature and refraction, GDAL's ``-cc`` coefficient: 0 a flat earth, 1
        the geometric curvature, 0.85714 (``1 - 1/7``) standard refraction. A target is
        then visible when the sight line clears the surface raised by
        ``curvature * d1 * d2 / (2 * earth_radius)`` (d1, d2 the horizontal distances to
        the eye and the target), which is GDAL's drop ``curvature * d**2 / (2 R)`` of the
        terrain and the target seen from the eye.
    earth_radius : float, default 6378137.0
        Radius of the earth in the terrain's x/y units (WGS84's semi-major axis in
        metres, as GDAL takes it).
    azimuth : (2,) sequence of float, optional
        Field of view: ``(start, end)`` in degrees clockwise from north (the grid's +y
        axis), each in [0, 360], inclusive; ``start > end`` wraps through north, e.g.
        ``(300, 60)``; ``(0, 360)`` is the full circle; ``start == end`` is refused.
    vertical : (2,) sequence of float, optional
        Field of view: ``(low, high)`` elevation angles in degrees (in [-90, 90], low <=
        high, inclusive) of each target seen from the eye, the target standing
        ``target_height`` above the surface and lowered by the earth's drop
        ``curvature * d**2 / (2 R)``.
    min_distance : float, optional
        Field of view: samples nearer than this horizontal distance are False.
    sight : Sight, optional
        All of the above but ``at`` as one value (:class:`~terrainvis.visibility.Sight`,
        checked when it was made), instead of the keywords: a keyword set to other than
        its default beside it is a TypeError.
    output : {"visible", "min_height", "angle"}, default "visible"
        What to return for each target (:mod:`terrainvis.visibility.viewsheds.output_modes`):
        ``"visible"`` the bool mask below; ``"min_height"`` (float64) the least height
        above the surface at which a target at that sample is visible, 0 where the ground
        itself is visible (GDAL's ``-om GROUND``; ``target_height`` is not used, but for
        the ``vertical`` limit); ``"angle"`` (float64, degrees) the elevation angle of the
        target (standing ``target_height`` above the surface) minus that of the horizon
        of its ray, both seen from the eye and lowered by the earth's drop
        ``curvature * d**2 / (2 R)``: ``atan2(z_T - drop - z_E, d) - atan2(z* - drop - z_E, d)``
        with ``z*`` the target's threshold (least visible height), >= 0 exactly where the
        target is visible (to within the clearance tolerance), -90 degrees for the horizon
        of a segment that is not tested. Both are exact (the threshold engine,
        :mod:`terrainvis.visibility.thresholds`), whatever ``engine``, and NaN where the
        mask is False without a verdict: nodata samples, samples off the surface under
        test, and samples outside the field of view (but for the sample nearest the
        observer, as below). On a grid with nodata the sample nearest the observer gets
        its exact value (the mask marks it True).

    eye : EyeSurface, optional
        An eye surface shipped with ``terrain`` as S(T) (:func:`terrainvis.eye_surface`):
        the observer, given as (x, y), stands where it places it, ``terrain(x, y)`` plus the
        surface's observer height plus its offset there, as ``relocate(..., "eye", eye=eye)``
        places a point (then ``observer_height`` is not given, and a Sight's is not used).

    Returns
    -------
    (rows, cols) bool, or (rows, cols) float64 for ``output="min_height"`` or ``"angle"``
        ``out[r, c]`` is True where the target above sample (r, c) of ``at`` (or of the
        terrain) is visible: the line of sight from the eye to it, with the trim
        :func:`~terrainvis.visibility.trim_length` and the tolerance
        :func:`~terrainvis.visibility.clearance_tolerance` of ``terrain``, as in
        :func:`~terrainvis.visibility.line_of_sight`. Nodata samples (of ``at``, or where
        the surface under test is absent) are False, and samples outside the field of
        view (beyond ``max_distance``, nearer than ``min_distance``, outside ``azimuth``
        or ``vertical``: :mod:`terrainvis.visibility.viewsheds.field_of_view`) are False, but for
        the sample nearest the observer (the ground it stands on), which gets the exact
        verdict whatever the limits but ``min_distance`` (with earth curvature an eye on
        the ground may not see it). Inside the field of view every verdict is the one
        without limits: terrain outside the field still blocks.

    Raises
    ------
    OutsideFootprintError
        When the observer is outside the footprint or on nodata.
    ValueError, TypeError
        On invalid arguments (the message names the argument).

    Notes
    -----
    The grid engine sweeps rings of cells outwards from the observer (in parallel over 16
    angular sectors), keeping rigorous bounds of the horizon in narrow angular wedges; most
    samples are decided by the bounds alone, the others by exact walks of only the parts of
    their rays that the bounds cannot clear, and the few left within the rounding margin
    by the exact pair engine (on a grid with nodata: by an exact walk that skips the absent
    triangles). The sweep costs about 0.1 microsecond per sample and core. Terrain where
    the rays graze large smooth visible areas (a tilted plane at worst) needs long walks
    for most samples and approaches the cost of one exact walk per sample. See the module
    docstring.

    An observer exactly on a sample stands at that sample's height. On a grid with nodata
    the sample nearest the observer is True, as GIS viewsheds mark the observer's own
    cell (the pair engine needs a NaN-free grid to say otherwise).

    References
    ----------
    M. van Kreveld, "Variations on sweep algorithms: efficient computation of extended
    viewsheds and class intervals", Proc. 7th Int. Symp. on Spatial Data Handling, 1996
    (no DOI).

    H. Haverkort, L. Toma, Y. Zhuang, "Computing visibility on terrains in external
    memory", ACM J. Exp. Algorithmics 13, 2009, doi:10.1145/1412228.1412233.

    Examples
    --------
    A 5 m wall along x = 2 hides the far side from an observer on the ground at x = 0:

    >>> from terrainvis import HeightGrid
    >>> z = np.zeros((3, 5))
    >>> z[:, 2] = 5.0
    >>> viewshed(HeightGrid(z), (0.0, 1.0), observer_height=1.0).astype(int)
    array([[1, 1, 1, 0, 0],
           [1, 1, 1, 0, 0],
           [1, 1, 1, 0, 0]])
    """
    check_output(output)
    if eye is not None:
        observer = _eye_observer(eye, terrain, observer, observer_height)
    s = sight_of(sight, {
        "observer_height": observer_height, "target_height": target_height, "max_distance": max_distance,
        "engine": engine, "curvature": curvature, "earth_radius": earth_radius, "azimuth": azimuth,
        "vertical": vertical, "min_distance": min_distance,
    })
    if output != "visible":
        return _output_values(terrain, observer, output, s, at)
    out, _ = _viewshed(terrain, observer, s, at=at)
    return apply_field_of_view(out, terrain, observer, s.fov, at, (s.observer_height, s.target_height, s.kc))


def _eye_observer(eye, terrain, observer, observer_height) -> tuple[float, float, float]:
    """The eye (x, y, z) an eye surface gives the observer at (x, y) on ``terrain`` (S(T))."""
    from ..los import _eye_heights

    xy = np.asarray(observer, dtype=np.float64)
    if xy.shape != (2,):
        raise ValueError(f"with eye=, observer must be its position (x, y): the eye surface gives its height; got "
                         f"{describe(observer)}")
    z = _eye_heights(eye, terrain, np.array([[xy[0], xy[1], 0.0]]))[0, 2]  # checks eye and the position
    if _differs(observer_height, KEYWORDS["observer_height"]):
        raise TypeError(f"pass either eye= or observer_height=, not both (the eye surface stands the observer "
                        f"{eye.offset:g} above S(T) plus its offset there; got observer_height="
                        f"{describe(observer_height)})")
    return float(xy[0]), float(xy[1]), float(z)


def _viewshed(terrain, observer, sight: Sight | None = None, *, at=None, **keywords):
    """:func:`viewshed` without its field of view but ``max_distance``, and a dict of counts:
    how the samples were decided. ``keywords`` (tests, benchmarks) are :func:`viewshed`'s,
    made into a Sight when ``sight`` is None.

    Keys: ``targets`` (samples that are targets), ``lb`` / ``ub`` (decided by the sweep's
    lower bound / by its upper bound and the last ring: its exact walk, or for ``ub_bound``
    of them the bound of its cells' corners), ``walk`` (decided by exact walks of the
    blocks of rings whose bound reached the target), ``exact`` (answered by the pair
    engine, or the nodata-aware walk, or Embree, or the TIN clipper).
    """
    if sight is None:
        sight = Sight.make(**keywords)
    engine, kc, eye, zs, at, own, (h_t, dmax) = _setup(terrain, observer, sight, at)
    if engine.name == "grid":
        # The sweep's bounds assume the eye on or above its own cell's surface (so the
        # part of every ray inside the trim cannot block). An eye below it, e.g. an
        # observer relocated by identity onto a simplification, goes to the exact walk.
        out, info = _grid(terrain, at, eye, (h_t, dmax, kc), own, sweep=bool(eye[2] >= zs))
    else:
        out, info = _rays(terrain, at, eye, (h_t, dmax, kc), own, engine)
    _mark_nearest(out, terrain, at, eye, (h_t, dmax, kc), engine)
    return out, info


def _setup(terrain, observer, sight: Sight, at):
    """The checked arguments of a viewshed: ``(engine, kc, eye, zs, at, own, (h_t, dmax))``,
    ``zs`` the surface under the observer and ``own`` whether the targets are the grid's samples."""
    as_terrain(terrain)
    kc = sight.kc
    engine = engine_on(terrain, sight)
    ox, oy, oz = _as_observer(observer)
    h_o, h_t = sight.observer_height, sight.target_height
    dmax = math.inf if sight.max_distance is None else sight.max_distance
    at = target_grid(terrain, at)
    zs = _surface_at(terrain, ox, oy)
    if not np.isfinite(zs):
        raise OutsideFootprintError(
            f"observer ({ox!r}, {oy!r}) is outside the terrain's footprint {terrain.extent} "
            "or on nodata (a triangle touching a NaN sample)"
        )
    eye = np.array([ox, oy, zs + h_o if oz is None else oz])
    _check_heights(terrain, eye[None, :], "observer")
    own = at is terrain or (
        isinstance(terrain, HeightGrid) and np.array_equal(at.xs, terrain.xs) and np.array_equal(at.ys, terrain.ys)
    )
    return engine, kc, eye, zs, at, own, (h_t, dmax)


# ----------------------------------------------------------------- output modes
#: Height step (a fraction of the terrain's scale) at which the thresholds of a grid with nodata
#: are checked by the exact nodata-aware walk, and to which the bisection narrows those that fail.
_SETTLE_REL = OUTPUT_SETTLE_REL


def _output_values(terrain, observer, output: str, sight: Sight, at) -> np.ndarray:
    """:func:`viewshed`'s ``"min_height"`` or ``"angle"``: the threshold of every target in the field."""
    _, kc, eye, _, at, own, (h_t, _) = _setup(terrain, observer, sight, at)
    fov = sight.fov
    if own:
        zt = np.array(terrain.z, dtype=np.float64)
        if terrain.n_nodata:
            zt[~_on_surface(terrain.z)] = np.nan
    else:
        zt = terrain.height_on_grid(at.xs, at.ys)
    ok = np.isfinite(zt) & np.isfinite(at.z)
    if fov.limited:
        ok &= field_of_view_mask(terrain, eye, fov, at=at, target_height=h_t, curvature=sight.curvature,
                                 earth_radius=sight.earth_radius)
    idx = np.flatnonzero(ok.ravel())
    r, c = np.divmod(idx, at.shape[1])
    ground = zt.ravel()[idx]
    pts = np.column_stack([at.xs[c], at.ys[r], ground + (h_t if output == "angle" else 0.0)])
    if isinstance(terrain, HeightGrid) and terrain.n_nodata:
        thr = _nodata_thresholds(terrain, eye, pts, kc)
    elif isinstance(terrain, TIN):
        thr = _tin_thresholds(terrain, eye, pts, kc)
    else:
        thr = eye_thresholds(terrain, eye, pts, kc)
    out = np.full(at.shape, np.nan)
    out.ravel()[idx] = output_values(output, thr, eye, pts, ground, kc)
    return out


#: Azimuth bins of :func:`_near_holes` (each hole cell marks the bins its directions span, and one more each side).
_HOLE_BINS = 8192


def _nodata_thresholds(grid: HeightGrid, eye: np.ndarray, pts: np.ndarray, kc: float) -> np.ndarray:
    """Thresholds on a grid with nodata: targets whose segment cannot meet a cell touching
    nodata are walked on the grid with its nodata filled (their walk never reads a filled
    height: every cell it evaluates has four finite corners, and the fill, the lowest height,
    keeps the pyramid's bounds true); the others as the grid's TIN, checked (:func:`_settle`)."""
    near = _near_holes(grid, eye, pts)
    thr = np.empty(pts.shape[0])
    far = np.flatnonzero(~near)
    thr[far] = eye_thresholds(_filled(grid), eye, pts[far], kc)
    near = np.flatnonzero(near)
    if near.size:
        thr[near] = _settle(grid, eye, pts[near], tin_of_grid_thresholds(grid, eye, pts[near], kc), kc)
    return thr


def _filled(grid: HeightGrid) -> HeightGrid:
    """The grid with its nodata set to its lowest height (cached)."""
    f = grid._cache.get("output_modes_filled")
    if f is None:
        zmin = _nanrange(grid)[0]
        f = HeightGrid.from_coords(np.where(np.isfinite(grid.z), grid.z, zmin), grid.xs, grid.ys)
        grid._cache["output_modes_filled"] = f
    return f


def _near_holes(grid: HeightGrid, eye: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """(n,) bool: targets whose segment from the eye may pass through a cell with a nodata corner
    (conservative): the target lies at least as far as such a cell, in an azimuth bin that the
    cell's directions from the eye span (widened by a bin each side). All of them when the eye
    is on such a cell."""
    f = np.isfinite(grid.z)
    bad = ~(f[:-1, :-1] & f[:-1, 1:] & f[1:, :-1] & f[1:, 1:])
    r, c = np.nonzero(bad)
    if r.size == 0:
        return np.zeros(pts.shape[0], dtype=bool)
    x0, x1 = grid.xs[c] - eye[0], grid.xs[c + 1] - eye[0]
    y0, y1 = grid.ys[r] - eye[1], grid.ys[r + 1] - eye[1]
    dmin = np.hypot(np.maximum(np.maximum(x0, -x1), 0.0), np.maximum(np.maximum(y0, -y1), 0.0))
    if (dmin == 0.0).any():
        return np.ones(pts.shape[0], dtype=bool)
    centre = np.arctan2(0.5 * (y0 + y1), 0.5 * (x0 + x1))
    turn = np.stack([np.arctan2(y, x) for x, y in ((x0, y0), (x1, y0), (x0, y1), (x1, y1))])
    turn = np.mod(turn - centre + np.pi, 2.0 * np.pi) - np.pi  # a cell away from the eye spans < 180 degrees
    scale = _HOLE_BINS / (2.0 * np.pi)
    lo = np.floor((centre + turn.min(axis=0) + np.pi) * scale).astype(np.int64) - 1
    hi = np.floor((centre + turn.max(axis=0) + np.pi) * scale).astype(np.int64) + 1
    count = hi - lo + 1
    start = np.repeat(lo - np.cumsum(count) + count, count)
    bins = np.mod(start + np.arange(int(count.sum())), _HOLE_BINS)
    nearest = np.full(_HOLE_BINS, np.inf)
    np.minimum.at(nearest, bins, np.repeat(dmin, count))
    tx, ty = pts[:, 0] - eye[0], pts[:, 1] - eye[1]
    tb = np.mod(np.floor((np.arctan2(ty, tx) + np.pi) * scale).astype(np.int64), _HOLE_BINS)
    return np.hypot(tx, ty) >= nearest[tb] * (1.0 - HOLE_REACH_SLACK)


def _settle(terrain, eye: np.ndarray, pts: np.ndarray, thr: np.ndarray, kc: float) -> np.ndarray:
    """Thresholds of a walk that stops where the surface does, checked by an exact engine.

    The TIN walk (of a TIN, or of ``grid.to_tin()`` on a grid with nodata) stops at a hole
    or at a concave edge of the footprint, so a sight line that leaves the surface and
    comes back may get too low a threshold: each finite threshold ``t`` must be blocked at
    ``t - eps`` and visible at ``t + eps`` under the exact verdicts (:func:`_verdicts`); the
    others are found again by bisection of those verdicts.
    """
    seen = _verdicts(terrain, eye, kc)
    eps = _SETTLE_REL * float(terrain_scale(terrain))
    x, y = pts[:, 0], pts[:, 1]
    bad = np.isfinite(thr)
    sel = np.flatnonzero(bad)
    bad[sel] = ~(seen(x[sel], y[sel], thr[sel] + eps) & ~seen(x[sel], y[sel], thr[sel] - eps))
    bad |= thr == np.inf
    sel = np.flatnonzero(bad)
    if sel.size == 0:
        return thr
    z = terrain.z if isinstance(terrain, HeightGrid) else terrain.vertices[:, 2]
    zmin, zmax = float(np.nanmin(z)), float(np.nanmax(z))
    d2 = (x[sel] - eye[0]) ** 2 + (y[sel] - eye[1]) ** 2
    span = 2.0 * (zmax - zmin + abs(eye[2] - zmin) + kc * float(d2.max())) + float(terrain_scale(terrain))
    lo = np.full(sel.size, zmin - span)
    hi = np.full(sel.size, zmax + span)
    out = thr.copy()
    seen_lo = seen(x[sel], y[sel], lo)
    seen_hi = seen(x[sel], y[sel], hi)
    for _ in range(200):
        go = np.flatnonzero(~seen_lo & seen_hi & (hi - lo > eps))
        if go.size == 0:
            break
        mid = 0.5 * (lo[go] + hi[go])
        v = seen(x[sel][go], y[sel][go], mid)
        hi[go] = np.where(v, mid, hi[go])
        lo[go] = np.where(v, lo[go], mid)
    out[sel] = np.where(seen_lo, -np.inf, np.where(seen_hi, hi, np.inf))
    return out


def _verdicts(terrain, eye: np.ndarray, kc: float):
    """``seen(x, y, z)``: whether the eye sees each target (x, y, z), exactly: on a grid the
    nodata-aware walk (:func:`_exact`), on a TIN the TIN engine (the exact clipper)."""
    delta, tol = trim_length(terrain), clearance_tolerance(terrain)
    if isinstance(terrain, HeightGrid):
        return lambda x, y, z: _exact(terrain, eye, (x, y, z), delta, tol, kc)
    engine = choose("tin", terrain, kc)
    predicate = Predicate(delta, tol, 0.0, kc)

    def seen(x, y, z):
        b = np.column_stack([x, y, z])
        return engine.pairs(terrain, np.repeat(eye[None, :], b.shape[0], axis=0), b, predicate)

    return seen


def _tin_thresholds(tin: TIN, eye: np.ndarray, pts: np.ndarray, kc: float) -> np.ndarray:
    """Thresholds on a TIN: checked (:func:`_settle`) unless its footprint is its bounding
    rectangle, where no sight line between two of its points can leave it."""
    thr = eye_thresholds(tin, eye, pts, kc)
    if _fills_its_rectangle(tin):
        return thr
    return _settle(tin, eye, pts, thr, kc)


def _fills_its_rectangle(tin: TIN) -> bool:
    """Whether the TIN's faces cover its bounding rectangle exactly (their areas add up to it;
    faces do not overlap in a valid TIN)."""
    v = tin.vertices[:, :2]
    a, b, c = v[tin.faces[:, 0]], v[tin.faces[:, 1]], v[tin.faces[:, 2]]
    area = 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])).sum()
    box = float(np.ptp(v[:, 0]) * np.ptp(v[:, 1]))
    return footprint_matches(area, box)


# ----------------------------------------------------------------- validation
def _as_observer(observer) -> tuple[float, float, float | None]:
    """(x, y, z or None) of an observer given as (x, y) or as its eye (x, y, z)."""
    try:
        arr = np.asarray(observer, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"observer must be a pair of numbers (x, y) or an eye (x, y, z), got {describe(observer)}") from exc
    if arr.ndim != 1:
        raise ValueError(f"observer must be a 1-D pair (x, y) or an eye (x, y, z), got {arr.ndim}-D with shape {arr.shape}")
    if arr.shape[0] not in (2, 3):
        raise ValueError(f"observer must have 2 values (x, y) or 3 (x, y, z), got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"observer must be finite, got {arr.tolist()}")
    return float(arr[0]), float(arr[1]), (float(arr[2]) if arr.shape[0] == 3 else None)


# ----------------------------------------------------------------- surface
def _surface_at(terrain, x: float, y: float) -> float:
    """Height of the surface under test at (x, y); NaN outside or on nodata."""
    if isinstance(terrain, TIN):
        return float(terrain.height_at([[x, y]])[0])
    xs, ys = terrain.xs, terrain.ys
    slack = EXTENT_INSIDE_REL * float(np.hypot(xs[-1] - xs[0], ys[-1] - ys[0]))
    if not (xs[0] - slack <= x <= xs[-1] + slack and ys[0] - slack <= y <= ys[-1] + slack):
        return math.nan
    c = int(np.searchsorted(xs, x))
    r = int(np.searchsorted(ys, y))
    if c < xs.size and r < ys.size and xs[c] == x and ys[r] == y:
        # exactly on a sample: its own height (the triangle formula may round it)
        v = float(terrain.heights[r, c])
        if np.isfinite(v) and _touches_present(terrain.heights, r, c):
            return v
        return math.nan
    lx = min(max(x, xs[0]), xs[-1]) - xs[0]
    ly = min(max(y, ys[0]), ys[-1]) - ys[0]
    return float(_geo.surface_height(_sweep_grid(terrain, strips=False), lx, ly))


def _touches_present(z: np.ndarray, r: int, c: int) -> bool:
    """Whether sample (r, c) is a vertex of at least one present triangle."""
    return bool(_on_surface(z[max(r - 1, 0) : r + 2, max(c - 1, 0) : c + 2])[min(r, 1), min(c, 1)])


def _on_surface(z: np.ndarray) -> np.ndarray:
    """(rows, cols) bool: samples that are a vertex of a present triangle (no NaN vertex).

    Cell (r, c) has a lower triangle (r, c), (r, c+1), (r+1, c+1) and an upper triangle
    (r, c), (r+1, c+1), (r+1, c).
    """
    f = np.isfinite(z)
    diag = f[:-1, :-1] & f[1:, 1:]
    lower = diag & f[:-1, 1:]
    upper = diag & f[1:, :-1]
    both = lower | upper
    out = np.zeros(z.shape, dtype=bool)
    out[:-1, :-1] |= both
    out[1:, 1:] |= both
    out[:-1, 1:] |= lower
    out[1:, :-1] |= upper
    return out


def _local_axes(grid: HeightGrid):
    """Cached local coordinate vectors, inverse widths and uniformity of a grid."""
    acc = grid._cache.get("viewshed_axes")
    if acc is None:
        xs = np.ascontiguousarray(grid.xs - grid.xs[0])
        ys = np.ascontiguousarray(grid.ys - grid.ys[0])
        acc = (xs, ys, 1.0 / np.diff(xs), 1.0 / np.diff(ys), bool(grid.is_uniform))
        grid._cache["viewshed_axes"] = acc
    return acc


def _sweep_grid(grid: HeightGrid, strips: bool = True) -> SurfaceGrid:
    """The grid as the sweep kernels read it (local coordinates; no copies of the heights; no
    pyramid), with its strips' maxima or (``strips`` False: for a height, read before the
    first sweep builds its tables side by side) without."""
    xs, ys, ixw, iyw, uniform = _local_axes(grid)
    cmax, rmax = _strip_max(grid) if strips else no_strips()
    pyr, off, nxl, ltop = no_pyramid()
    return SurfaceGrid(grid.heights, xs, ys, ixw, iyw, uniform, bool(grid.n_nodata > 0), pyr, off, nxl, ltop, cmax, rmax)


def _strip_max(grid: HeightGrid):
    """Cached largest heights of each column's and row's aligned segments (:func:`_bk.strip_max`)."""
    v = grid._cache.get("viewshed_strip_max")
    if v is None:
        rows, cols = grid.shape
        cmax = np.empty(((rows - 2) // _bk.SEG + 1, cols), dtype=np.float32)
        rmax = np.empty((rows, (cols - 2) // _bk.SEG + 1), dtype=np.float32)
        _bk.strip_max(grid.heights, cmax, rmax)
        v = grid._cache["viewshed_strip_max"] = (cmax, rmax)
    return v


def _max_slope(grid: HeightGrid) -> float:
    """Largest |slope| of any edge of the grid's surface (cached)."""
    g = grid._cache.get("viewshed_max_slope")
    if g is None:
        rows = np.empty(grid.shape[0])
        hx = np.diff(grid.xs)
        _bk.max_slope(grid.heights, grid.xs, grid.ys, bool((hx == hx[0]).all()), rows)
        g = float(rows.max())
        grid._cache["viewshed_max_slope"] = g
    return g


def _build_tables(grid: HeightGrid) -> None:
    """Build a grid's tables for its first sweep at once: the steepest slope in a helper
    thread, the strips' maxima here. The pair engine's pyramid is not built: the few
    targets the bounds leave take the sweep's own walk (:func:`_exact`). Small grids, a
    grid already done, numba on one thread and threads other than the main one (units of
    :func:`terrainvis.core.runner.run_units`) build them where they are first needed, one
    after the other."""
    cached = grid._cache
    if ("viewshed_max_slope" in cached and "viewshed_strip_max" in cached) or grid.size < THREAD_MIN_WORK \
            or numba.get_num_threads() < 2 or threading.current_thread() is not threading.main_thread():
        return
    # the helper's kernel takes no stop flag: under a tenth of a second on 3601²
    with alongside(lambda: _max_slope(grid)):
        _strip_max(grid)


def _nanrange(grid: HeightGrid) -> tuple[float, float]:
    """The grid's lowest and highest heights (NaN ignored; (0, 0) when none is finite): the range
    the grid computed when it was made (:func:`terrainvis.core.terrain.height_range`)."""
    zr = height_range(grid)
    return (0.0, 0.0) if zr is None else zr


# ----------------------------------------------------------------- grid engine
def _grid(grid: HeightGrid, at: HeightGrid, eye: np.ndarray, query, own: bool, sweep: bool = True):
    """Grid engine: the sweep decides what its bounds can, the exact pair engine the rest.

    ``query`` is ``(h_t, dmax, kc)``: target height, maximum distance, earth curvature
    coefficient. With ``own`` the targets are the grid's samples (walked along the
    rings); otherwise they are ``at``'s samples standing on the grid's surface, sorted into
    buckets by sector and ring first. Without ``sweep`` every target goes to the exact walk.
    """
    h_t, dmax, kc = query
    if sweep:
        _build_tables(grid)
    code, zt = _target_codes(grid, at, eye, dmax, own)
    delta = trim_length(grid)
    tol = clearance_tolerance(grid)
    counts = (0, 0, 0, 0)
    wmin = float(min(np.diff(grid.xs).min(), np.diff(grid.ys).min()))
    if sweep and wmin > 2.0 * delta * (1.0 + TRIM_MARGIN_REL) and grid.shape[0] >= 3 and grid.shape[1] >= 3:
        counts = _sweep(grid, at, eye, query, code, zt, own)
    todo = _undecided(code)
    if todo.size:
        r, c = np.divmod(todo, at.shape[1])
        vis = _exact(grid, eye, (at.xs[c], at.ys[r], zt[r, c].astype(np.float64) + h_t), delta, tol, kc)
        code.ravel()[todo] = np.where(vis, _geo.VISIBLE, _geo.BLOCKED)
    info = {"targets": int(code.size - np.count_nonzero(code == _geo.NOT_TARGET)), "lb": counts[0],
            "ub": counts[1], "walk": counts[2], "exact": int(todo.size), "ub_bound": counts[3]}
    # the verdicts written over the codes (one byte each, as bools are): an 8192² grid's
    # viewshed then holds one array of 64 MiB, not two
    return np.equal(code, _geo.VISIBLE, out=code.view(np.bool_)), info


def _undecided(code: np.ndarray) -> np.ndarray:
    """Flat indices of the UNDECIDED codes, found a block of rows at a time (a comparison of the
    whole array made a temporary as large as it: 64 MiB on 8192², whose first touch cost up to
    0.17 s; a block's is reused from one block to the next)."""
    step = max(1, (1 << 20) // max(code.shape[1], 1))
    parts = [np.flatnonzero(code[r : r + step].ravel() == _geo.UNDECIDED) + r * code.shape[1]
             for r in range(0, code.shape[0], step)]
    return np.concatenate(parts) if len(parts) > 1 else parts[0]


def _target_codes(grid: HeightGrid, at: HeightGrid, eye: np.ndarray, dmax: float, own: bool):
    """A code per sample of ``at`` (UNDECIDED, or NOT_TARGET: nodata, no surface under
    it, beyond ``dmax``), and the heights of the surface under test there."""
    code = fresh_array(at.shape, np.int8)
    code.fill(_geo.UNDECIDED)
    if own:
        zt = grid.heights  # float32 for a float32 raster: the heights of targets are made float64 where they are used
        if grid.n_nodata:
            code[~_on_surface(zt)] = _geo.NOT_TARGET
    else:
        zt = grid.height_on_grid(at.xs, at.ys)
        code[np.isnan(zt)] = _geo.NOT_TARGET
    if at.n_nodata:
        code[np.isnan(at.heights)] = _geo.NOT_TARGET
    if math.isfinite(dmax):
        code[(at.xs[None, :] - eye[0]) ** 2 + (at.ys[:, None] - eye[1]) ** 2 > dmax * dmax] = _geo.NOT_TARGET
    return code, zt


def _rules(grid: HeightGrid, ez: float, query) -> _geo.Rules:
    """The sweep's numbers: trim, tolerance, rounding bound and margin, exclusion radii."""
    h_t, dmax, kc = query
    xs, ys = _local_axes(grid)[:2]
    delta = trim_length(grid)
    zmin, zmax = _nanrange(grid)
    wmin = float(min(np.diff(xs).min(), np.diff(ys).min()))
    width = float(xs[-1] + ys[-1])
    # e_h bounds the absolute rounding error of any height or clearance computed by the
    # sweep or the pair engine (local coordinates up to ``width``, slopes up to the grid's
    # largest, heights and the curvature drop up to ``zabs``); decisions keep 64 e_h away
    # from the threshold
    zabs = max(abs(zmin), abs(zmax)) + abs(ez) + h_t + kc * width * width
    e_h = float(64.0 * np.finfo(np.float64).eps * (width * (1.0 + _max_slope(grid)) + zabs))
    dz = max(abs(zmax + h_t - ez), abs(zmin + h_t - ez))
    # closer than r_excl to the eye, a point lies in every target's trimmed end
    r_excl = 0.5 * delta * wmin / math.hypot(wmin, dz)
    diag2 = float(np.diff(xs).max() ** 2 + np.diff(ys).max() ** 2)
    return _geo.Rules(float(h_t), delta, clearance_tolerance(grid), 64.0 * e_h, e_h, r_excl, delta * (1.0 + TRIM_MARGIN_REL),
                     diag2, float(dmax), float(kc))


def _sweep(grid: HeightGrid, at: HeightGrid, eye: np.ndarray, query, code: np.ndarray, zt, own: bool):
    """Run the sweep kernel: ``code`` gets its verdicts (UNDECIDED where it cannot decide);
    returns how many targets the lower bound, the upper bound (and the last ring) and the
    block walks decided, and how many of the upper bound's needed no walk of the last ring."""
    sg = _sweep_grid(grid)
    ex = float(eye[0] - grid.xs[0])
    ey = float(eye[1] - grid.ys[0])
    ez = float(eye[2])
    ce = int(_geo.locate(sg.xs, sg.ixw, sg.uniform, ex))
    re = int(_geo.locate(sg.ys, sg.iyw, sg.uniform, ey))
    veye = _geo.Eye(re, ce, ex, ey, ez)
    jstop = _last_ring(sg.xs, sg.ys, re, ce, ex, ey, query[1])
    stats = np.zeros((_N_SECTORS, 5), dtype=np.int64)
    if own:
        targets = _geo.Targets(True, code, np.empty(0), np.empty(0), np.empty(0), np.zeros(1, dtype=np.int64),
                              np.zeros(1, dtype=np.int64), np.empty(0, dtype=np.int8))
    else:
        idx = _undecided(code)
        r, c = np.divmod(idx, at.shape[1])
        tx = np.ascontiguousarray(at.xs[c] - grid.xs[0])
        ty = np.ascontiguousarray(at.ys[r] - grid.ys[0])
        tz = np.ascontiguousarray(zt.ravel()[idx] + query[0])
        tstart = np.zeros(_N_SECTORS * (jstop + 2) + 1, dtype=np.int64)
        torder = np.empty(idx.size, dtype=np.int64)
        _sk.bucket_targets(sg, veye, tx, ty, _N_SECTORS, jstop, tstart, torder)
        targets = _geo.Targets(False, np.zeros((1, 1), dtype=np.int8), tx, ty, tz, tstart, torder,
                              np.full(idx.size, _geo.UNDECIDED, dtype=np.int8))
    # through the interrupt helper: the sectors on threads, and Ctrl-C stops the sweep within a ring of each
    call(_sk.sweep, sg, veye, _rules(grid, ez, query), _geo.Layout(_N_SECTORS, _B0, _R1, _J_NEAR, jstop),
         targets, stats, work=int(code.size), items=_N_SECTORS)
    if not own:
        code.ravel()[idx] = targets.tcode
    n = stats.sum(axis=0)
    return int(n[0]), int(n[1] + n[4]), int(n[2]), int(n[4])


#: Exact verdicts of at most this many targets take the sweep's own walk (serial, cell by
#: cell), more take the pair engine (threads, the pyramid). The sweep leaves 16 targets
#: or so per viewshed (the cells around the eye): the pair engine's kernel, about 6 s to
#: compile on a first run, is then not compiled at all.
_WALK_MAX_TARGETS = 1024


def _exact(grid: HeightGrid, eye, targets, delta: float, tol: float, kc: float) -> np.ndarray:
    """Exact verdicts eye -> targets ``(tx, ty, tz)`` (world coordinates): the pair engine on
    a NaN-free grid for many targets, the nodata-aware walk otherwise."""
    tx, ty, tz = targets
    m = tx.size
    if grid.n_nodata == 0 and m > _WALK_MAX_TARGETS:
        from ..grid import grid_clearance

        a = np.empty((m, 3))
        a[:] = eye
        b = np.column_stack([tx, ty, tz])
        return grid_clearance(grid, a, b, delta=delta, tol=tol, los=True, kc=kc) >= -tol
    out = np.empty(m)
    _wk.walk_targets(
        _sweep_grid(grid), (eye[0] - grid.xs[0], eye[1] - grid.ys[0], float(eye[2])),
        np.ascontiguousarray(tx - grid.xs[0]), np.ascontiguousarray(ty - grid.ys[0]), np.ascontiguousarray(tz),
        float(delta), float(tol), float(kc), out,
    )
    return out >= -tol


def _last_ring(xs, ys, re: int, ce: int, ex: float, ey: float, dmax: float) -> int:
    """Last sample ring that can hold a sample within ``dmax`` of the eye."""
    nc = xs.size
    nr = ys.size
    jmax = max(re, nr - 2 - re, ce, nc - 2 - ce)
    if not math.isfinite(dmax):
        return jmax
    j = np.arange(jmax + 1)
    big = np.inf
    right = np.where(ce + 1 + j <= nc - 1, xs[np.minimum(ce + 1 + j, nc - 1)] - ex, big)
    left = np.where(ce - j >= 0, ex - xs[np.maximum(ce - j, 0)], big)
    top = np.where(re + 1 + j <= nr - 1, ys[np.minimum(re + 1 + j, nr - 1)] - ey, big)
    bottom = np.where(re - j >= 0, ey - ys[np.maximum(re - j, 0)], big)
    near = np.minimum(np.minimum(right, left), np.minimum(top, bottom))
    inside = np.flatnonzero(near <= dmax)
    return int(inside[-1]) if inside.size else 0


# ----------------------------------------------------------------- other targets
def _rays(terrain, at: HeightGrid, eye: np.ndarray, query, own: bool, engine):
    """Viewshed at ``at``'s samples one segment per target, in chunks, answered by ``engine``
    (an :class:`~terrainvis.visibility.engines.Engine`: Embree's rays, the exact TIN
    clipper, or any registered engine)."""
    h_t, dmax, kc = query
    rows, cols = at.shape
    if own:
        zt = np.array(terrain.z, dtype=np.float64)
        if terrain.n_nodata:
            zt[~_on_surface(terrain.z)] = np.nan
    else:
        zt = terrain.height_on_grid(at.xs, at.ys)
    ok = np.isfinite(zt)
    if at.n_nodata:
        ok &= np.isfinite(at.z)
    if math.isfinite(dmax):
        ok &= (at.xs[None, :] - eye[0]) ** 2 + (at.ys[:, None] - eye[1]) ** 2 <= dmax * dmax
    idx = np.flatnonzero(ok.ravel())
    out = np.zeros(rows * cols, dtype=bool)
    info = {"targets": int(idx.size), "lb": 0, "ub": 0, "walk": 0, "exact": int(idx.size), "ub_bound": 0}
    predicate = Predicate(trim_length(terrain), clearance_tolerance(terrain), 0.0, kc)
    zflat = zt.ravel()
    for s in range(0, idx.size, _CHUNK):
        part = idx[s : s + _CHUNK]
        r, c = np.divmod(part, cols)
        b = np.column_stack([at.xs[c], at.ys[r], zflat[part] + h_t])
        a = np.empty_like(b)
        a[:] = eye
        out[part] = engine.pairs(terrain, a, b, predicate)
    return out.reshape(rows, cols), info


def _mark_nearest(out: np.ndarray, terrain, at: HeightGrid, eye, query, engine) -> None:
    """The sample nearest the observer (the ground it stands on) takes the exact verdict (the
    sweep's own walk on a grid, the engine's pairs otherwise).

    The sweep does not decide the observer's own cell on its own: this one segment is
    answered exactly, so that with earth curvature an eye on the ground that cannot see
    the next sample is not said to see it. On a grid with nodata, whose pair engine needs
    a NaN-free grid, the sample is visible, as GIS viewsheds mark the observer's cell.
    """
    h_t, _, kc = query  # the ground the observer stands on counts at any max_distance
    c = int(np.argmin(np.abs(at.xs - eye[0])))
    r = int(np.argmin(np.abs(at.ys - eye[1])))
    if at.n_nodata and not np.isfinite(at.heights[r, c]):
        return
    x, y = float(at.xs[c]), float(at.ys[r])
    zs = _surface_at(terrain, x, y)
    if not np.isfinite(zs):
        return
    if isinstance(terrain, HeightGrid) and terrain.n_nodata:
        out[r, c] = True
        return
    if engine.name == "grid":  # the sweep's own walk: the same verdict as the pair engine's (see _exact)
        target = (np.array([x]), np.array([y]), np.array([zs + h_t]))
        out[r, c] = bool(_exact(terrain, eye, target, trim_length(terrain), clearance_tolerance(terrain), kc)[0])
        return
    predicate = Predicate(trim_length(terrain), clearance_tolerance(terrain), 0.0, kc)
    out[r, c] = bool(engine.pairs(terrain, eye[None, :], np.array([[x, y, zs + h_t]]), predicate)[0])
