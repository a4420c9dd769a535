"""The calibrated relocation: a point's height on S(T) chosen so that it sees what it saw on T.

Moving a point of the original terrain T vertically onto its simplification S(T) (the
paper's full projection) keeps its position but not its view: S(T) smooths ridges and
fills valleys, so the point sees over crests it was hidden by, or loses sight of what it
saw. The calibrated relocation instead picks, for each point, the height on S(T) whose
verdicts agree best with the point's verdicts on T, against *partners* that stand for
the points it will be tested with.

Partners
--------
About ``n_partners`` positions spread uniformly over the terrain (stratified: one at a
random place in each cell of a square lattice over T's extent, from ``seed``), standing
``height`` above the surface: on T at ``T(x, y) + height``, on S(T) where the point's
real partners will stand. Two settings:

* **points** (``target_height=None``, the pair experiment): the partners are points like
  the one relocated, carrying the same ``offset`` and relocated the same way. A *core* of
  :data:`CORE_PARTNERS` of them is calibrated first, jointly: Gauss-Seidel sweeps in which
  each core partner in turn takes its best height against the others at their current
  heights (each step keeps or raises their total agreement), starting from the full
  projection, ``sweeps`` times. The other partners (a second stratified sample) are then
  placed against the core one by one, exactly as the points are (with their neighbours).
  More partners make each point's agreement a finer estimate of what it will meet; the
  core keeps the joint calibration, whose cost grows with its square, at the size where
  it pays.
* **targets** (``target_height=h``, the viewshed experiment): the partners are targets
  standing ``h`` above each surface, as a viewshed's cells do; they do not move.

The partners depend on T, S(T), the setting and the seed, never on the points being
relocated: a point's new height does not change when the other points change. They are
computed once per (T, S(T), setting) and cached on S(T).

The best height
---------------
Seeing a partner is monotone in the point's height: for each partner there is an exact
*threshold* above which the point sees it on S(T) (:mod:`terrainvis.visibility.thresholds`
computes it at the breakpoints the LOS engines test, with their trim, tolerance and end
radius). The agreement with T's verdicts is then a step function of the height, and its
maximum is found exactly by sorting the thresholds. Among the optimal heights the one
nearest the full projection is taken, a small margin away from any threshold.

Short sight lines
-----------------
Partners spread over the whole terrain stand, on average, tens of cells from a point, so
they say little about its short sight lines: chasing one more far partner, a point could
sink a little into S(T) and lose sight of what is around it (docs/relocation.md measures
what that cost on the shared DEMs).
So each point also has *neighbours* (``neighbours=True``, the default): L = 48 probes on
rings 1.5, 3, 5 and 8 cells of T around it (:data:`NEIGHBOUR_RINGS`), standing like the
point (``offset`` or ``target_height`` above T), with the point's verdicts to them on T.
On S(T) a neighbour *moves with the point*: it stands at its full projection raised by
as much as the point moved off its own, as the point's real neighbours, relocated the
same way over nearly the same error of S(T), would. The whole segment then rises with
the point, so the point sees the neighbour exactly when its height is at least its
reference height minus the segment's least clearance there (and the tolerance): a
threshold again (:func:`_neighbour_thresholds`, from the exact
:func:`terrainvis.min_clearance`). The best height maximises the partners' agreement plus
a weight times the neighbours' (:func:`terrainvis.visibility.thresholds.best_height_kept`):
:data:`NEIGHBOUR_WEIGHT` (0.5) against 512 partners, scaled with the number of partners
(2 against the default 2,048) so that the neighbours keep their share of the agreement
(:func:`neighbour_weight`). The neighbours depend on the point alone.

Cost
----
Per point, K + L LOS queries on T and K + L threshold walks on S(T) (K = ``n_partners``,
L = 48 neighbours or none); per (T, S(T), setting), once, C² / 2 LOS queries on T and
``sweeps`` x C² walks on S(T) for the core (C = :data:`CORE_PARTNERS`), and (K - C) x
(C + L) of each for the other partners.

Most walks need not run to their end. A point's best height almost always lies close to
its reference height, so its thresholds are first walked in a *window* around it
(:data:`WINDOW_ERRORS` times S(T)'s largest vertical error at the partners): a walk stops
as soon as it shows the threshold above the window (for a point on the ground, most
sight lines are blocked near it), and skips what cannot rise above the window's floor.
The best height is then chosen from the most favourable thresholds those bounds allow;
when that choice lies inside the window, no exact threshold can change it, and otherwise
the point's thresholds are walked whole (:mod:`terrainvis.visibility._threshold_kernels`,
"Windows"). The heights are the same bit for bit.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from ..core.option import Flag, Option, Switch, boolean, integer
from ..core.validate import as_int, describe
from ..errors import OutsideFootprintError
from ..core.terrain import HeightGrid, fingerprint
from ..tolerances import THRESHOLD_MARGIN_REL
from ..visibility import EARTH_RADIUS, Sight, curvature_coefficient
from ..visibility.thresholds import ThresholdSurface, best_height, best_heights, gauss_seidel, threshold_row

__all__ = ["calibrated_heights", "best_responses", "neighbour_weight", "Partners", "partners", "N_PARTNERS",
           "CORE_PARTNERS", "SWEEPS", "MIN_GAIN", "WINDOW_ERRORS", "RUN_OPTIONS"]

#: Default number of partners (K), the core and the others (see "Partners" in the module
#: docstring); chosen on the tuning terrains (docs/relocation.md gives the figures).
N_PARTNERS = 2048
#: Partners calibrated jointly by Gauss-Seidel sweeps (the core, C of them: C² / 2 LOS
#: queries and ``sweeps`` x C² threshold walks); the other partners are placed against it.
CORE_PARTNERS = 512
#: Default Gauss-Seidel sweeps over the partners of the points setting (the first does most).
SWEEPS = 2
#: Default least gain (partners' verdicts) that moves a point off the full projection.
MIN_GAIN = 1
#: Each best height is found from thresholds walked exactly within this many times S(T)'s
#: largest vertical error (at the partners) of the reference height first, and from every
#: threshold exactly only when that choice might not be the exact one: the same heights
#: bit for bit, for less walking (inf: every threshold exactly; see "Cost" above).
WINDOW_ERRORS = 0.5
#: The least window, in height margins (:data:`MARGIN_REL` of the terrain's scale): when
#: S(T) is T, 1,000 margins (about 5 m on a 5 km grid).
WINDOW_MIN_MARGINS = 1000.0
#: Points per chunk of the T-side verdicts (bounds the temporary (chunk x K) segment arrays).
_CHUNK_PAIRS = 1 << 20
#: Height margin kept from thresholds, as a fraction of the terrain's scale (about 5 mm on a 5 km grid).
MARGIN_REL = THRESHOLD_MARGIN_REL
#: The neighbours of a point (see "Short sight lines" in the module docstring): rings at
#: these distances, in cells of T, ...
NEIGHBOUR_RINGS = (1.5, 3.0, 5.0, 8.0)
#: ... with this many neighbours on each ring (alternate rings turned by half a step).
NEIGHBOUR_DIRECTIONS = 12
#: A neighbour's weight against a partner's when there are 512 partners (inf: never lose a
#: neighbour); chosen on the tuning terrains (docs/relocation.md). With K partners each
#: neighbour weighs K / 512 times this (:func:`neighbour_weight`), so that the neighbours
#: together keep their share of the agreement (24 of 536 votes) whatever K is.
NEIGHBOUR_WEIGHT = 0.5
#: The number of partners at which :data:`NEIGHBOUR_WEIGHT` holds as given.
NEIGHBOUR_WEIGHT_PARTNERS = 512

#: The calibrated relocation's own options of a run, declared in its registry entry
#: (:attr:`terrainvis.relocation.Relocation.run_options`; the eye relocation, whose surface
#: a calibrated relocation fits, declares them too): keywords of :func:`terrainvis.compare`,
#: validated before a run and stored with it, and flags of ``terrainvis compare`` and
#: ``terrainvis relocate``. ``terrainvis compare --quick`` runs against the core alone.
RUN_OPTIONS = (
    Option(
        "n_partners", N_PARTNERS, integer(minimum=1), "partners of the calibrated relocation", "int",
        doc=("The calibrated relocation places each point against about this many partners spread over the "
             "terrain (:func:`terrainvis.relocation.calibrated.partners`: a core of up to ``CORE_PARTNERS`` = 512 "
             "calibrated jointly, the others placed against the core); their positions come from ``seed``."),
        cli=Flag("--partners", int), quick=CORE_PARTNERS,
    ),
    Option(
        "neighbours", True, boolean, "calibrated relocation: count each point's neighbours (short sight lines)",
        "bool",
        doc=("The calibrated relocation weighs each point's agreement with 48 neighbours 1.5 to 8 cells of T "
             "around it beside its partners (:func:`terrainvis.relocate`); False: the partners alone, a little "
             "better over all pairs, worse among pairs a few cells apart."),
        cli=Switch(off="--no-neighbours", off_help="calibrated relocation: the partners alone, no neighbours"),
    ),
)


def neighbour_weight(k: int) -> float:
    """The weight of one neighbour against a partner when a point has ``k`` partners."""
    if NEIGHBOUR_WEIGHT == np.inf:
        return np.inf
    return NEIGHBOUR_WEIGHT * k / NEIGHBOUR_WEIGHT_PARTNERS


@dataclass(frozen=True)
class Partners:
    """The partners of a calibrated relocation (see the module docstring).

    Attributes
    ----------
    xy : (K, 2) float64
        Positions.
    z_original : (K,) float64
        Heights on the original terrain T (its surface plus ``height``).
    z_simplified : (K,) float64
        Heights on S(T): calibrated (points setting) or its surface plus ``height`` (targets).
    ground_simplified : (K,) float64
        The surface of S(T) under each partner.
    visible : (C, C) bool or None
        The verdicts on T of the core (the first C partners) among themselves (points
        setting only).
    """

    xy: np.ndarray
    z_original: np.ndarray
    z_simplified: np.ndarray
    ground_simplified: np.ndarray
    visible: np.ndarray | None


# ----------------------------------------------------------------------- partners
def _positions(original: HeightGrid, simplified, k: int, seed: int, stream: int = 0) -> np.ndarray:
    """About ``k`` stratified random positions over T's extent where both surfaces exist
    (``stream`` 0: the core partners, 1: the others, drawn apart)."""
    words = [int(seed), 0x7E11] + ([int(stream)] if stream else [])
    rng = np.random.default_rng(np.random.SeedSequence(words))
    xmin, xmax, ymin, ymax = original.extent
    n = max(1, int(round(np.sqrt(k))))
    u = (np.arange(n)[None, :] + rng.random((n, n))) / n
    v = (np.arange(n)[:, None] + rng.random((n, n))) / n
    xy = np.column_stack([xmin + u.ravel() * (xmax - xmin), ymin + v.ravel() * (ymax - ymin)])
    ok = np.isfinite(original.height_at(xy)) & np.isfinite(simplified.height_at(xy))
    return xy[ok]


#: Verdicts on T, kept across calls by content (T's fingerprint and the points' bytes): the
#: units of a comparison simplify one terrain many ways and relocate the same point sets
#: onto each, in processes that receive T anew each time, so a cache on T would not last.
#: The least recently used go first once they hold more than :data:`_ON_ORIGINAL_BYTES`
#: (the default comparison's six terrains hold about 10 MB; units of different terrains
#: come interleaved, so a cache of 64 entries, as before, kept none of them until reused:
#: a quarter of the comparison's time went into recomputing them).
_ON_ORIGINAL: OrderedDict = OrderedDict()
_ON_ORIGINAL_BYTES = 256 << 20


def _cached(key, compute):
    out = _ON_ORIGINAL.get(key)
    if out is None:
        out = compute()
        _ON_ORIGINAL[key] = out
        held = sum(v.nbytes for v in _ON_ORIGINAL.values())
        while held > _ON_ORIGINAL_BYTES and len(_ON_ORIGINAL) > 1:
            _, gone = _ON_ORIGINAL.popitem(last=False)
            held -= gone.nbytes
    else:
        _ON_ORIGINAL.move_to_end(key)
    return out


def predicate_of(sight, **keywords) -> dict:
    """The predicate's ``keywords`` of a relocation that computes visibility (``end_radius``,
    ``curvature``, ``earth_radius``, and ``engine`` where it takes one), as ``sight`` gives
    them when a :class:`~terrainvis.visibility.Sight` is passed in their place (as
    :func:`terrainvis.compare` does: :meth:`terrainvis.relocation.Relocation.keywords`); a
    keyword set beside it, or a field of view, is refused as the pair functions refuse them
    (:func:`~terrainvis.visibility.sight.pair_sight`)."""
    if sight is None:
        return keywords
    from ..visibility.sight import pair_sight

    s = pair_sight(sight, keywords, "relocate")
    return {name: getattr(s, name) for name in keywords}


def _sight(end_radius: float, curvature: float, earth_radius: float) -> Sight:
    """The relocation's predicate as one value: the verdicts on S(T) take its end radius, those on T
    (:func:`_on_original`) the exact predicate; both the grid engine (on a grid) and its curvature."""
    return Sight.make(engine="grid", end_radius=end_radius, curvature=curvature, earth_radius=earth_radius)


def _on_original(sight: Sight) -> Sight:
    """The predicate of the verdicts on T: exact (no end radius), the grid engine, the Sight's curvature."""
    return dataclasses.replace(sight, end_radius=0.0) if sight.end_radius else sight


def _key(original, sight: Sight, *arrays):
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return (fingerprint(original), sight.kc, h.hexdigest())


def _verdicts_on_original(original: HeightGrid, a: np.ndarray, b: np.ndarray, sight: Sight) -> np.ndarray:
    """(n, K) verdicts on T between the points ``a`` (n, 3) and the partners ``b`` (K, 3), in chunks (cached)."""
    return _cached(("pairs",) + _key(original, sight, a, b), lambda: _line_of_sight_rows(original, a, b, sight))


def _line_of_sight_rows(original: HeightGrid, a: np.ndarray, b: np.ndarray, sight: Sight) -> np.ndarray:
    from ..visibility import line_of_sight

    n, k = a.shape[0], b.shape[0]
    out = np.empty((n, k), dtype=bool)
    step = max(1, _CHUNK_PAIRS // max(k, 1))
    for i in range(0, n, step):
        j = min(n, i + step)
        aa = np.repeat(a[i:j], k, axis=0)
        bb = np.tile(b, (j - i, 1))
        out[i:j] = line_of_sight(original, aa, bb, sight=_on_original(sight)).reshape(j - i, k)
    return out


def partners(original: HeightGrid, simplified, *, height: float, move: bool, n_partners: int = N_PARTNERS,
             sweeps: int = SWEEPS, seed: int = 0, end_radius: float = 0.0, curvature: float = 0.0,
             earth_radius: float = EARTH_RADIUS, min_gain: int = MIN_GAIN, neighbours: bool = True,
             core: int | None = None) -> Partners:
    """The partners of a calibrated relocation onto ``simplified`` (cached on it).

    ``move`` True: the points setting (the core of ``min(n_partners, core)`` partners
    calibrated by Gauss-Seidel sweeps, the others placed against the core as the points
    are, with their ``neighbours`` or without; ``core`` :data:`CORE_PARTNERS` by default);
    False: the targets setting (partners fixed ``height`` above each surface). See the
    module docstring. Inputs are validated by :func:`calibrated_heights`; ``curvature``
    and ``earth_radius`` as in :func:`terrainvis.line_of_sight`, on both surfaces.
    """
    sight = _sight(end_radius, curvature, earth_radius)
    core = CORE_PARTNERS if core is None else core
    key = ("calibration", fingerprint(original), float(height), bool(move), int(n_partners), int(sweeps),
           int(seed), sight.end_radius, sight.kc, int(min_gain), bool(neighbours), int(core))
    cached = simplified._cache.get(key)
    if cached is not None:
        return cached
    n_core = min(int(n_partners), int(core))
    core_key = key[:4] + key[5:10] + ("core", n_core)  # the core does not depend on the neighbours
    inner = simplified._cache.get(core_key)
    if inner is None:
        inner = _core(original, simplified, height, move, n_core, sweeps, seed, sight, min_gain)
        simplified._cache[core_key] = inner
    out = inner
    if n_partners > n_core:
        xy = _positions(original, simplified, int(n_partners) - n_core, seed, stream=1)
        z_t = original.height_at(xy) + height
        ground = simplified.height_at(xy)
        z_s = ground + height
        if move and xy.shape[0] and inner.xy.shape[0]:
            z_s = _place(np.column_stack([xy, z_t]), simplified, original, inner, height, neighbours, sight,
                         min_gain)
        out = Partners(np.concatenate([inner.xy, xy]), np.concatenate([inner.z_original, z_t]),
                       np.concatenate([inner.z_simplified, z_s]), np.concatenate([inner.ground_simplified, ground]),
                       inner.visible)
    simplified._cache[key] = out
    return out


def _core(original: HeightGrid, simplified, height: float, move: bool, k: int, sweeps: int, seed: int,
          sight: Sight, min_gain: int) -> Partners:
    """The core partners: ``k`` stratified positions, calibrated jointly by Gauss-Seidel sweeps (``move``)."""
    xy = _positions(original, simplified, k, seed)
    z_t = original.height_at(xy) + height
    ground = simplified.height_at(xy)
    z_s = ground + height
    visible = None
    if move and xy.shape[0] > 1:
        from ..visibility import visibility_matrix

        at = np.column_stack([xy, z_t])
        visible = _cached(("matrix",) + _key(original, sight, at),
                          lambda: visibility_matrix(original, at, sight=_on_original(sight)))
        surf = ThresholdSurface(simplified)
        q = surf.local(np.column_stack([xy, z_s]))
        order_rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5EED]))
        n = xy.shape[0]
        for _ in range(sweeps):
            order = order_rng.permutation(n).astype(np.int64)
            gauss_seidel(surf, q, order, visible, end_radius=sight.end_radius, kc=sight.kc, min_gain=min_gain,
                         window=_window(surf, z_t, z_s))
        z_s = q[:, 2].copy()
    return Partners(xy, z_t, z_s, ground, visible)


# ----------------------------------------------------------------------- relocation
def calibrated_heights(points, simplified, original, *, offset: float = 0.0, target_height=None,
                       n_partners: int = N_PARTNERS, sweeps: int = SWEEPS, seed: int = 0,
                       end_radius: float = 0.0, curvature: float = 0.0,
                       earth_radius: float = EARTH_RADIUS, min_gain: int = MIN_GAIN,
                       neighbours: bool = True) -> np.ndarray:
    """The calibrated height on ``simplified`` of each point of ``original`` (see the module docstring).

    Parameters
    ----------
    points : (n, 3) float64
        Validated points on (``offset`` above) the original terrain, inside both footprints.
    simplified : HeightGrid or TIN
        S(T); a HeightGrid must be free of nodata.
    original : HeightGrid
        T, free of nodata.
    offset : float
        The points' height above T (their verdicts on T are taken from there); the
        reference height on S(T) is its surface plus ``offset``.
    target_height : float or None
        None: the points setting; a number: the targets setting (partners that high
        above each surface).
    n_partners, sweeps, seed : int
        The partners (about ``n_partners`` of them), the Gauss-Seidel sweeps of the
        points setting and the seed of their positions and sweep order.
    min_gain : int
        A point (and a partner in a sweep) leaves its reference height only for a
        height that agrees with at least this many more partners (1: any gain).
    end_radius : float
        End radius of the verdicts on S(T) (:func:`terrainvis.line_of_sight`); the
        verdicts on T are exact.
    curvature, earth_radius : float
        Earth curvature and refraction of the verdicts on both surfaces
        (:func:`terrainvis.line_of_sight`).
    neighbours : bool
        Count each point's neighbours too (short sight lines; see the module docstring).

    Returns
    -------
    (n,) float64
    """
    pts = np.asarray(points, dtype=np.float64)
    move = target_height is None
    height = float(offset if move else target_height)
    part = partners(original, simplified, height=height, move=move, n_partners=n_partners, sweeps=sweeps,
                    seed=seed, end_radius=end_radius, min_gain=min_gain, neighbours=neighbours, curvature=curvature,
                    earth_radius=earth_radius)
    if pts.shape[0] == 0 or part.xy.shape[0] == 0:
        return simplified.height_at(pts[:, :2]) + offset
    return _place(pts, simplified, original, part, offset, neighbours, _sight(end_radius, curvature, earth_radius),
                  min_gain, height=height)


def _place(pts: np.ndarray, simplified, original: HeightGrid, part: Partners, offset: float, neighbours: bool,
           sight: Sight, min_gain: int, height: float | None = None) -> np.ndarray:
    """The best height on S(T) of each point ``pts`` (n, 3; ``offset`` above T) against the
    partners ``part``, counting its neighbours (standing ``height`` above the surfaces,
    ``offset`` by default) when ``neighbours``."""
    height = float(offset if height is None else height)
    n = pts.shape[0]
    vis = _verdicts_on_original(original, pts, np.column_stack([part.xy, part.z_original]), sight)
    surf = ThresholdSurface(simplified)
    ground = simplified.height_at(pts[:, :2])
    p = surf.local(np.column_stack([pts[:, :2], ground + offset]))
    q = surf.local(np.column_stack([part.xy, part.z_simplified]))
    if neighbours:
        near, near_vis = _neighbours(original, simplified, pts, height, sight)
        lthr = _neighbour_thresholds(simplified, np.column_stack([pts[:, :2], ground + offset]), near, near_vis,
                                     surf.tol, sight)
    else:
        lthr, near_vis = np.zeros((n, 0)), np.zeros((n, 0), dtype=np.int8)
    weight = float(neighbour_weight(q.shape[0]))
    out, _ = best_heights(surf, p, q, vis, neighbour_thresholds=lthr, neighbour_verdicts=near_vis, weight=weight,
                          end_radius=sight.end_radius, kc=sight.kc, min_gain=min_gain,
                          window=_window(surf, part.z_original, part.ground_simplified + height))
    return out


def _window(surf, z_original, z_simplified) -> float:
    """The window of the best heights (:data:`WINDOW_ERRORS`) on ``surf`` (S(T)), from
    partners standing at ``z_original`` on T and ``z_simplified`` on S(T)."""
    if WINDOW_ERRORS == np.inf:
        return np.inf
    err = float(np.max(np.abs(z_simplified - z_original))) if z_original.size else 0.0
    return max(WINDOW_ERRORS * err, WINDOW_MIN_MARGINS * surf.margin)


def best_responses(points: np.ndarray, simplified, verdicts: np.ndarray, counted: np.ndarray, *,
                   end_radius: float = 0.0, curvature: float = 0.0,
                   earth_radius: float = EARTH_RADIUS) -> tuple[np.ndarray, bool]:
    """One Gauss-Seidel sweep of exact best responses among ``points`` (the oracle bound's step).

    Each point in turn (in order) takes the height on ``simplified`` that maximises the
    number of its ``counted`` pairs whose verdict there agrees with ``verdicts`` (n, n),
    the others standing at their current heights: the thresholds of the calibrated
    relocation, sorted (:func:`terrainvis.visibility.thresholds.best_height`; the height
    nearest its current one, moved only for a gain). So no step lowers the agreement of
    the counted pairs. Returns the new (n,) heights and whether any moved.
    """
    kc = curvature_coefficient(curvature, earth_radius)
    surf = ThresholdSurface(simplified)
    q = surf.local(np.asarray(points, dtype=np.float64))
    n = q.shape[0]
    thr = np.empty(n)
    moved = False
    for i in range(n):
        threshold_row(surf, q[i], q, skip=i, end_radius=end_radius, kc=kc, out=thr)
        ignore = ~counted[i]
        row = np.where(ignore, -np.inf, thr)  # a pair that does not count is seen, and agrees, at any height
        z, _ = best_height(row, verdicts[i] | ignore, q[i, 2], surf.margin, 1)
        if z != q[i, 2]:
            q[i, 2] = z
            moved = True
    return q[:, 2].copy(), moved


def _neighbour_thresholds(simplified, ref, near, near_vis, tol, sight: Sight) -> np.ndarray:
    """(n, L) thresholds of the points at ``ref`` (n, 3: their reference heights on S(T)) for
    neighbours that move with them: a neighbour stands at ``near`` (its reference height)
    raised by the same amount as the point, so the segment rises as a whole and its least
    clearance by that amount; the point at z sees it exactly when
    ``z >= z_ref - tol - clearance at the reference heights``. ``-inf`` where the segment is
    not tested (too short) or there is no neighbour (``near_vis`` -1)."""
    n, L = near_vis.shape
    lthr = np.full((n, L), -np.inf)
    ok = near_vis >= 0
    if ok.any():
        rows = np.nonzero(ok)[0]
        mc = _min_clearance(simplified, ref[rows], near[ok], sight)
        tested = np.isfinite(mc)
        vals = np.full(rows.size, -np.inf)
        vals[tested] = ref[rows[tested], 2] - tol - mc[tested]
        lthr[ok] = vals
    return lthr


def _min_clearance(simplified, a: np.ndarray, b: np.ndarray, sight: Sight) -> np.ndarray:
    """:func:`terrainvis.min_clearance` of the points and their neighbours, known to lie
    inside S(T)'s footprint (both surfaces have a height at each), without its checks."""
    from ..visibility.los import segment_clearances

    return segment_clearances(simplified, np.ascontiguousarray(a, dtype=np.float64),
                              np.ascontiguousarray(b, dtype=np.float64), end_radius=sight.end_radius, kc=sight.kc)


def _neighbours(original: HeightGrid, simplified, pts: np.ndarray, height: float, sight: Sight):
    """Each point's neighbours: positions on :data:`NEIGHBOUR_RINGS` around it, standing
    ``height`` above S(T), (n, L, 3), and the point's verdicts to them on T (standing
    ``height`` above T), (n, L) int8: 1 seen, 0 not, -1 no neighbour (off either surface).

    They depend on the point alone, so a point's height still does not depend on the
    other points.
    """
    n = pts.shape[0]
    step = max(abs(original.dx), abs(original.dy))
    d = NEIGHBOUR_DIRECTIONS
    offsets = []
    for j, r in enumerate(NEIGHBOUR_RINGS):
        a = 2.0 * np.pi * (np.arange(d) + 0.5 * (j % 2)) / d
        offsets.append(r * step * np.column_stack([np.cos(a), np.sin(a)]))
    offsets = np.concatenate(offsets)
    xy = pts[:, None, :2] + offsets[None, :, :]
    flat = xy.reshape(-1, 2)
    z_t = original.height_at(flat)
    z_s = simplified.height_at(flat)
    ok = np.isfinite(z_t) & np.isfinite(z_s)
    vis = np.full(flat.shape[0], -1, dtype=np.int8)
    if ok.any():
        src = np.repeat(pts, offsets.shape[0], axis=0)[ok]
        dst = np.column_stack([flat[ok], z_t[ok] + height])
        key = ("neighbours",) + _key(original, sight, src, dst)
        seen = _cached(key, lambda: _pairs_on_original(original, src, dst, sight))
        vis[ok] = seen
    # a missing neighbour stands on the point itself: its threshold is never tested
    near = np.column_stack([np.where(ok[:, None], flat, np.repeat(pts[:, :2], offsets.shape[0], axis=0)),
                            np.where(ok, z_s + height, np.repeat(pts[:, 2], offsets.shape[0]))])
    return near.reshape(n, offsets.shape[0], 3), vis.reshape(n, offsets.shape[0])


def _pairs_on_original(original: HeightGrid, a: np.ndarray, b: np.ndarray, sight: Sight) -> np.ndarray:
    from ..visibility import line_of_sight

    out = np.empty(a.shape[0], dtype=bool)
    for i in range(0, a.shape[0], _CHUNK_PAIRS):
        out[i:i + _CHUNK_PAIRS] = line_of_sight(original, a[i:i + _CHUNK_PAIRS], b[i:i + _CHUNK_PAIRS],
                                                sight=_on_original(sight))
    return out


# ---------------------------------------------------------------------- the relocation
def relocate_calibrated(points, simplified, *, offset: float = 0.0, original=None, target_height=None,
                        end_radius: float = 0.0, curvature: float = 0.0, earth_radius: float = EARTH_RADIUS,
                        n_partners: int = N_PARTNERS, sweeps: int = SWEEPS, seed: int = 0,
                        min_gain: int = MIN_GAIN, neighbours: bool = True, sight=None) -> np.ndarray:
    """The calibrated relocation, registered as ``"calibrated"``: :func:`calibrated_heights` with its input checked.

    Parameters
    ----------
    points : (n, 3) array_like
        Points on (or ``offset`` above) T, inside both footprints. Never modified.
    simplified : HeightGrid or TIN
        S(T); a HeightGrid must be free of nodata.
    original : HeightGrid
        Required: T, free of nodata (the points' verdicts on T).
    offset, target_height, end_radius, curvature, earth_radius, n_partners, sweeps, seed, min_gain, neighbours
        See :func:`calibrated_heights`. A point's height depends on these, T, S(T) and
        the point, never on the other points.
    sight : Sight, optional
        The predicate of the verdicts on S(T) as one value (its ``end_radius``, ``curvature``
        and ``earth_radius``; :func:`predicate_of`), instead of those keywords, as
        :func:`terrainvis.compare` hands it.

    Returns
    -------
    (n, 3) float64
        A new array; x and y are unchanged.
    """
    from ..core.memory import check_memory
    from ..core.validate import as_bool, as_height, as_nonnegative_finite, as_points
    from ..visibility import terrain_scale
    from .paper import ground_heights

    pts = as_points(points, "points", 3)
    end_radius, curvature, earth_radius = predicate_of(sight, end_radius=end_radius, curvature=curvature,
                                                       earth_radius=earth_radius).values()
    if original is None:
        raise TypeError("relocate(..., 'calibrated') needs original=, the original terrain T (a HeightGrid)")
    if not isinstance(original, HeightGrid):
        raise TypeError(f"original must be a terrainvis.HeightGrid, got {describe(original)}")
    original.require_finite("relocate(..., 'calibrated') (original)")
    if isinstance(simplified, HeightGrid):
        simplified.require_finite("relocate(..., 'calibrated') (simplified)")
    scale = float(terrain_scale(original))
    ground = float(np.nanmax(np.abs(original.z)))
    off = as_height(offset, "offset", scale=scale, ground=ground)
    if target_height is not None:
        target_height = as_height(target_height, "target_height", scale=scale, ground=ground, minimum=0.0)
    curvature_coefficient(curvature, earth_radius)  # validates both
    options = dict(end_radius=as_nonnegative_finite(end_radius, "end_radius"), curvature=curvature,
                   earth_radius=earth_radius, n_partners=as_int(n_partners, "n_partners", minimum=1),
                   sweeps=as_int(sweeps, "sweeps", minimum=0), seed=as_int(seed, "seed", minimum=0),
                   min_gain=as_int(min_gain, "min_gain", minimum=1), neighbours=as_bool(neighbours, "neighbours"))
    check_memory(memory_need(options["n_partners"], pts.shape[0]),
                 f"the calibrated relocation of {pts.shape[0]:,} points against {options['n_partners']:,} partners")
    out = pts.copy()
    if pts.shape[0] == 0:
        return out
    ground_heights(simplified, pts)  # inside S(T)'s footprint
    on_t = original.height_at(pts[:, :2])
    if np.isnan(on_t).any():
        first = int(np.flatnonzero(np.isnan(on_t))[0])
        raise OutsideFootprintError(
            f"points must lie inside the original terrain's footprint, but {int(np.isnan(on_t).sum())} of "
            f"{pts.shape[0]} do not (first at index {first})"
        )
    out[:, 2] = calibrated_heights(pts, simplified, original, offset=off, target_height=target_height, **options)
    return out


def memory_need(n_partners: int, n_points: int = 0) -> int:
    """A lower bound of the bytes the calibrated relocation allocates: per partner its positions and
    heights and its verdicts against the core and the neighbours (a byte each), per point a row of
    thresholds and verdicts against the partners (chunked to at most :data:`_CHUNK_PAIRS` pairs)."""
    per_partner = 64 + CORE_PARTNERS + NEIGHBOUR_DIRECTIONS * len(NEIGHBOUR_RINGS)
    rows = min(n_points * n_partners, max(_CHUNK_PAIRS, n_partners))
    return int(n_partners) * per_partner + 9 * rows
