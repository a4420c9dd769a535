"""Moving test points onto a simplified terrain before testing visibility on it.

Points sampled on the original terrain T do not, in general, lie on its simplification
S(T). Alderson and Samavati compare three ways of placing them on S(T):

``"identity"``
    The points do not move. They may end up below S(T) (then every segment from them is
    blocked) or above it.
``"full"``
    Every point is moved vertically onto S(T).
``"half"``
    Only points below S(T) are moved up onto it; points above it stay where they are.
``"calibrated"``
    Each point takes the height on S(T) whose verdicts agree best with its verdicts on T,
    against partners spread over the terrain that stand for the points it will be tested
    with (never the other points themselves): :mod:`terrainvis.relocation.calibrated`. It needs T
    (``original=``).
``"oracle"`` (not a practical relocation: an upper bound)
    Coordinate descent of the points' heights on the agreement of their own pairs with
    T's verdicts: from the best of the paper's three (and of ``start``, e.g. the
    calibrated heights), each point in turn takes the best of a set of candidate heights
    spanning the local vertical error of S(T), then its exact best height against the
    others (the calibrated relocation's thresholds, with the true verdicts:
    :func:`terrainvis.relocation.calibrated.best_responses`), until nothing improves. It needs T's
    verdicts (``reference=``), which a practical relocation does not have, so it estimates
    how much any relocation of the points alone could recover. It is a local optimum, not
    a proof: no relocation started from it would gain by moving one point, and it is never
    below its starts.

Observer offsets
----------------
Points often carry an observer (eye) height above the ground. :func:`relocate` takes it
as ``offset``: the *ground point* of an observer is ``z - offset``, relocation decides and
moves using the ground point, and the offset is added back. So ``"full"`` gives
``S(x, y) + offset``, and ``"half"`` lifts an observer only when its ground point is below
S(T), to ``S(x, y) + offset``. With ``offset = 0`` (points on the original surface, the
paper's setting) these are exactly the definitions above. Passing the offset matters:
an observer 2 m above a ground point that is 1 m below S(T) would otherwise count as
"above" S(T) and keep its height under ``"half"``, i.e. stand 1 m above S(T) instead of
2 m.
"""

from __future__ import annotations

import numpy as np

from ..core.validate import (
    as_bool,
    as_finite_scalar,
    as_float_array,
    as_height,
    as_int,
    as_nonnegative_finite,
    as_points,
    choice,
    describe,
)
from .calibrated import MIN_GAIN, N_PARTNERS, SWEEPS, best_responses
from ..visibility import EARTH_RADIUS
from ..errors import OutsideFootprintError
from ..core.terrain import HeightGrid, as_terrain

__all__ = ["relocate", "RELOCATIONS", "PAPER_RELOCATIONS", "CALIBRATED", "ORACLE"]

#: The paper's relocation strategies, in the paper's order.
PAPER_RELOCATIONS = ("identity", "full", "half")
#: The calibrated relocation (see the module docstring and :mod:`terrainvis.relocation.calibrated`).
CALIBRATED = "calibrated"
#: The practical relocations: the paper's three and the calibrated one.
RELOCATIONS = PAPER_RELOCATIONS + (CALIBRATED,)
#: The oracle bound (see the module docstring); accepted by :func:`relocate` and compare.
ORACLE = "oracle"


def relocate(points, simplified, how: str, *, offset: float = 0.0, original=None, target_height=None,
             end_radius: float = 0.0, curvature: float = 0.0, earth_radius: float = EARTH_RADIUS,
             n_partners: int = N_PARTNERS, sweeps: int = SWEEPS, seed: int = 0, min_gain: int = MIN_GAIN,
             neighbours: bool = True, reference=None, mask=None, engine: str = "auto", n_candidates: int = 9,
             start=None) -> np.ndarray:
    """Place points on a simplified terrain.

    Parameters
    ----------
    points : (n, 3) array_like
        Points on (or ``offset`` above) the original terrain. Never modified.
    simplified : HeightGrid or TIN
        The simplified terrain.
    how : {"identity", "full", "half", "calibrated", "oracle"}
        See the module docstring.
    offset : float
        The observer height that ``points`` carry above their ground point.
    original : HeightGrid, optional
        T itself. ``"calibrated"``: required (the points' verdicts on T). ``"oracle"``:
        the candidate heights of a point span the vertical error of S(T) around it (T's
        samples within one coarse cell); without it they span ``[-max_error,
        max_error]`` of ``simplified.attrs``.
    target_height : float, optional
        ``"calibrated"`` only. None (the default): the points are tested against each
        other (pairs), so the partners are points relocated the same way. A height:
        the points are observers of targets standing that high above each surface (a
        viewshed's cells).
    end_radius : float
        ``"calibrated"`` and ``"oracle"``: the end radius of the verdicts on S(T)
        (:func:`terrainvis.line_of_sight`).
    curvature, earth_radius : float
        ``"calibrated"`` and ``"oracle"``: earth curvature and refraction of the verdicts
        they evaluate (:func:`terrainvis.line_of_sight`; 0, the default, is a flat earth).
    n_partners, sweeps, seed, min_gain : int
        ``"calibrated"`` only: about how many partners, how many Gauss-Seidel sweeps
        calibrate them, the seed of their positions, and the least gain that moves a
        point (:func:`terrainvis.relocation.calibrated.calibrated_heights`). A point's height
        depends on these, T, S(T) and the point, never on the other points.
    neighbours : bool
        ``"calibrated"`` only: count each point's neighbours too, 48 probes 1.5 to 8 cells
        of T around it (True, the default), so that short sight lines are not traded for
        far partners; False: the partners alone (a little better over all pairs, worse
        among pairs a few cells apart: docs/relocation.md gives the figures).
    reference : (n, n) bool, optional
        ``"oracle"`` only (required): the verdicts on the original terrain T.
    mask : (n, n) bool, optional
        ``"oracle"`` only: the pairs that count (e.g. within a distance).
    engine : str
        ``"oracle"`` only: the visibility engine on S(T).
    n_candidates : int
        ``"oracle"`` only: candidate heights per point spanning the local error (the
        original, full and half heights are always candidates too).
    start : (n,) array_like of float, optional
        ``"oracle"`` only: heights to start from besides the paper's three (e.g. the
        calibrated relocation's), so that the bound is never below them.

    Returns
    -------
    (n, 3) float64
        A new array; x and y are unchanged.

    Examples
    --------
    >>> from terrainvis import HeightGrid
    >>> S = HeightGrid(np.full((2, 2), 10.0))
    >>> P = np.array([[0.5, 0.5, 8.0], [0.5, 0.5, 12.0]])
    >>> relocate(P, S, "half")[:, 2].tolist()
    [10.0, 12.0]
    >>> relocate(P, S, "full")[:, 2].tolist()
    [10.0, 10.0]
    """
    pts = as_points(points, "points", 3)
    as_terrain(simplified, "simplified")
    how = choice(how, "how", RELOCATIONS + (ORACLE,))
    off = as_finite_scalar(offset, "offset")
    if how == ORACLE:
        curve = {"curvature": curvature, "earth_radius": earth_radius}
        return _oracle(pts, simplified, off, (reference, mask, start), original, end_radius, engine, n_candidates,
                       curve)
    if how == CALIBRATED:
        options = {"end_radius": end_radius, "curvature": curvature, "earth_radius": earth_radius,
                   "n_partners": n_partners, "sweeps": sweeps, "seed": seed, "min_gain": min_gain,
                   "neighbours": neighbours}
        return _calibrated(pts, simplified, off, original, target_height, options)
    out = pts.copy()
    if how == "identity" or pts.shape[0] == 0:
        return out
    ground = _ground(simplified, pts)
    if how == "full":
        out[:, 2] = ground + off
    else:
        below = pts[:, 2] - off < ground
        out[below, 2] = ground[below] + off
    return out


def _ground(simplified, pts):
    ground = simplified.height_at(pts[:, :2])
    outside = np.isnan(ground)
    if outside.any():
        first = int(np.flatnonzero(outside)[0])
        raise OutsideFootprintError(
            f"points must lie inside the simplified terrain's footprint, but {int(outside.sum())} of "
            f"{pts.shape[0]} do not (first at index {first})"
        )
    return ground


def _calibrated(pts, simplified, off, original, target_height, options):
    from .calibrated import calibrated_heights
    from ..visibility import curvature_coefficient, terrain_scale

    if original is None:
        raise TypeError("relocate(..., 'calibrated') needs original=, the original terrain T (a HeightGrid)")
    if not isinstance(original, HeightGrid):
        raise TypeError(f"original must be a terrainvis.HeightGrid, got {describe(original)}")
    original.require_finite("relocate(..., 'calibrated') (original)")
    if isinstance(simplified, HeightGrid):
        simplified.require_finite("relocate(..., 'calibrated') (simplified)")
    scale = float(terrain_scale(original))
    ground = float(np.nanmax(np.abs(original.z)))
    off = as_height(off, "offset", scale=scale, ground=ground)
    if target_height is not None:
        target_height = as_height(target_height, "target_height", scale=scale, ground=ground, minimum=0.0)
    curvature_coefficient(options["curvature"], options["earth_radius"])  # validates both
    options = dict(options, end_radius=as_nonnegative_finite(options["end_radius"], "end_radius"),
                   n_partners=as_int(options["n_partners"], "n_partners", minimum=1),
                   sweeps=as_int(options["sweeps"], "sweeps", minimum=0), seed=as_int(options["seed"], "seed", minimum=0),
                   min_gain=as_int(options["min_gain"], "min_gain", minimum=1),
                   neighbours=as_bool(options["neighbours"], "neighbours"))
    out = pts.copy()
    if pts.shape[0] == 0:
        return out
    _ground(simplified, pts)
    on_t = original.height_at(pts[:, :2])
    if np.isnan(on_t).any():
        first = int(np.flatnonzero(np.isnan(on_t))[0])
        raise OutsideFootprintError(
            f"points must lie inside the original terrain's footprint, but {int(np.isnan(on_t).sum())} of "
            f"{pts.shape[0]} do not (first at index {first})"
        )
    out[:, 2] = calibrated_heights(pts, simplified, original, offset=off, target_height=target_height, **options)
    return out


def _candidates(pts, simplified, ground, off, original, k):
    """(n, m) candidate heights per point: the local error span of S(T), and identity / full / half."""
    n = pts.shape[0]
    probs = np.linspace(0.0, 1.0, k)
    if original is not None:
        # T's samples within one coarse cell of the point: the error of S(T) around it
        n_s = simplified.size if isinstance(simplified, HeightGrid) else simplified.n_vertices
        radius = max(original.dx, original.dy) * max(1.0, np.sqrt(original.size / max(n_s, 1)))
        errors = original.z - simplified.height_on_grid(original.xs, original.ys)
        span = np.empty((n, k))
        for i in range(n):
            x, y = pts[i, 0], pts[i, 1]
            cs = slice(np.searchsorted(original.xs, x - radius), np.searchsorted(original.xs, x + radius, "right"))
            rs = slice(np.searchsorted(original.ys, y - radius), np.searchsorted(original.ys, y + radius, "right"))
            local = errors[rs, cs]
            local = local[np.isfinite(local)]
            span[i] = np.quantile(local, probs) if local.size else 0.0
    else:
        if "max_error" not in simplified.attrs:
            raise ValueError(
                "relocate(..., 'oracle') needs original= (the original terrain) or a simplified terrain whose "
                "attrs hold max_error (as simplifiers.simplify records)"
            )
        e = float(simplified.attrs["max_error"])
        span = np.broadcast_to(np.linspace(-e, e, k), (n, k))
    base = (ground + off)[:, None]
    practical = np.column_stack([pts[:, 2], ground + off, np.maximum(pts[:, 2], ground + off)])
    return np.concatenate([practical, base + span], axis=1)


def _oracle(pts, simplified, off, given, original, end_radius, engine, n_candidates, curve):
    """The oracle bound (see the module docstring); ``given`` is ``(reference, mask, start)``."""
    reference, mask, start = given
    n = pts.shape[0]
    if reference is None:
        raise TypeError("relocate(..., 'oracle') needs reference=, the (n, n) verdicts on the original terrain")
    ref = np.asarray(reference)
    if ref.shape != (n, n) or ref.dtype != bool:
        raise ValueError(f"reference must be an ({n}, {n}) boolean matrix, got {describe(ref)}")
    if original is not None and not isinstance(original, HeightGrid):
        raise TypeError(f"original must be a terrainvis.HeightGrid, got {describe(original)}")
    counted = np.ones((n, n), dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if counted.shape != (n, n):
        raise ValueError(f"mask must have shape ({n}, {n}), got {counted.shape}")
    counted = counted | counted.T
    np.fill_diagonal(counted, False)
    k = as_int(n_candidates, "n_candidates", minimum=2)
    radius = as_nonnegative_finite(end_radius, "end_radius")
    if start is not None:
        start = as_float_array(start, "start")
        if start.shape != (n,) or not np.isfinite(start).all():
            raise ValueError(f"start must hold {n} finite heights (one per point), got {describe(start)}")
    los_kw = {"engine": engine, "end_radius": radius, **curve}
    if n < 2:
        return pts.copy()
    cand = _candidates(pts, simplified, _ground(simplified, pts), off, original, k)
    out = _oracle_start(pts, simplified, cand, start, ref, counted, los_kw)
    for _ in range(50):  # each round raises the agreement or stops; 50 is a safety bound
        changed = _candidate_pass(pts, simplified, cand, out, ref, counted, los_kw)
        out[:, 2], moved = best_responses(out, simplified, ref, counted, end_radius=radius, **curve)
        if not (changed or moved):
            break
    return out


def _oracle_start(pts, simplified, cand, start, ref, counted, los_kw):
    """The best start of the oracle's descent: identity, full, half, or ``start``."""
    from ..visibility import visibility_matrix

    starts = [cand[:, j] for j in range(3)] + ([start] if start is not None else [])
    best_z, best_score = None, -1
    for z in starts:
        trial = pts.copy()
        trial[:, 2] = z
        score = int((visibility_matrix(simplified, trial, **los_kw) == ref)[counted].sum())
        if score > best_score:
            best_z, best_score = np.array(z, dtype=np.float64), score
    out = pts.copy()
    out[:, 2] = best_z
    return out


def _candidate_pass(pts, simplified, cand, out, ref, counted, los_kw) -> bool:
    """One sweep over the points: each takes the best of its candidate heights against the
    others (``out``, updated in place) if it beats its current one; whether any moved."""
    from ..visibility import line_of_sight

    m = cand.shape[1]
    changed = False
    for i in range(pts.shape[0]):
        others = np.flatnonzero(counted[i])
        if others.size == 0:
            continue
        a = np.repeat(np.column_stack([np.repeat(pts[i:i + 1, :2], m, axis=0), cand[i]]), others.size, axis=0)
        b = np.tile(out[others], (m, 1))
        vis = line_of_sight(simplified, a, b, **los_kw).reshape(m, others.size)
        score = (vis == ref[i, others]).sum(axis=1)
        at = np.flatnonzero(cand[i] == out[i, 2])
        current = (vis[at[0]] == ref[i, others]).sum() if at.size else _row_score(simplified, out, i, others, ref, los_kw)
        j = int(np.argmax(score))
        if score[j] > current:
            out[i, 2] = cand[i, j]
            changed = True
    return changed


def _row_score(simplified, out, i, others, ref, los_kw) -> int:
    """How many of point i's pairs with ``others`` agree with ``ref`` at the current heights."""
    from ..visibility import line_of_sight

    a = np.repeat(out[i:i + 1], others.size, axis=0)
    return int((line_of_sight(simplified, a, out[others], **los_kw) == ref[i, others]).sum())
