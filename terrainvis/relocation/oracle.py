"""The oracle bound: how much any relocation of the points alone could recover.

Registered as the relocation ``"oracle"`` (:mod:`terrainvis.relocation.registry`), a
*bound*: it fits the heights to T's verdicts of the evaluated pairs themselves, so a
comparison runs it once per distance mask, after the practical relocations, and never
counts it as one of them. Its table in a comparison's report, the bound against the best
practical relocation, is :func:`gap_table`.
"""

from __future__ import annotations

import numpy as np

from ..core.terrain import HeightGrid
from ..core.validate import (
    as_finite_scalar,
    as_float_array,
    as_int,
    as_nonnegative_finite,
    as_points,
    describe,
    height_limit,
)
from ..visibility import EARTH_RADIUS, terrain_scale
from .calibrated import best_responses, predicate_of
from .paper import ground_heights

__all__ = ["oracle", "gap_table"]


def oracle(points, simplified, *, offset: float = 0.0, reference=None, mask=None, original=None,
           end_radius: float = 0.0, engine: str = "auto", n_candidates: int = 9, start=None, curvature: float = 0.0,
           earth_radius: float = EARTH_RADIUS, sight=None) -> np.ndarray:
    """The oracle bound: the points' heights that keep the most of their own pairs' verdicts.

    Not a practical relocation: it needs T's verdicts of the very pairs it is evaluated
    on. Coordinate descent from the best of the paper's three (and of ``start``): each
    point in turn takes the best of a set of candidate heights spanning the local
    vertical error of S(T), then its exact best height against the others (the
    calibrated relocation's thresholds with the true verdicts:
    :func:`terrainvis.relocation.calibrated.best_responses`), until nothing improves. A
    local optimum, not a proof: no relocation started from it would gain by moving one
    point, and it is never below its starts.

    Parameters
    ----------
    points : (n, 3) array_like
        Points ``offset`` above the original terrain T. Never modified.
    simplified : HeightGrid or TIN
    offset : float
        The observer height the points carry above their ground point.
    reference : (n, n) bool
        Required: the verdicts on T.
    mask : (n, n) bool, optional
        The pairs that count (e.g. within a distance); default every pair.
    original : HeightGrid, optional
        T itself: the candidate heights of a point span the vertical error of S(T) around
        it (T's samples within one coarse cell); without it they span ``[-max_error,
        max_error]`` of ``simplified.attrs``.
    end_radius, engine, curvature, earth_radius
        The predicate of the verdicts on S(T) (:func:`terrainvis.line_of_sight`); or ``sight``,
        the same as one :class:`~terrainvis.visibility.Sight`
        (:func:`terrainvis.relocation.calibrated.predicate_of`).
    n_candidates : int
        Candidate heights per point spanning the local error (the original, full and
        half heights are always candidates too).
    start : (n,) array_like of float, optional
        Heights to start from besides the paper's three (e.g. the calibrated
        relocation's), so that the bound is never below them.

    Returns
    -------
    (n, 3) float64
    """
    pts = as_points(points, "points", 3)
    off = as_finite_scalar(offset, "offset")
    end_radius, engine, curvature, earth_radius = predicate_of(
        sight, end_radius=end_radius, engine=engine, curvature=curvature, earth_radius=earth_radius).values()
    curve = {"curvature": curvature, "earth_radius": earth_radius}
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
    cand = _candidates(pts, simplified, ground_heights(simplified, pts), off, original, k)
    out = _oracle_start(pts, simplified, cand, start, ref, counted, los_kw)
    # a best response above a partner's threshold near a wall can be 1e10 m: past what float64
    # resolves against the terrain, where verdicts are rounding noise; such a point keeps its height
    limit = height_limit(terrain_scale(simplified))
    for _ in range(50):  # each round raises the agreement or stops; 50 is a safety bound
        changed = _candidate_pass(pts, simplified, cand, out, ref, counted, los_kw)
        best, _ = best_responses(out, simplified, ref, counted, end_radius=radius, **curve)
        best = np.where(np.abs(best) <= limit, best, out[:, 2])
        moved = bool((best != out[:, 2]).any())
        out[:, 2] = best
        if not (changed or moved):
            break
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


def gap_table(accuracy, practical):
    """How much relocation could recover: the oracle bound against the best practical relocation.

    ``accuracy`` is the mean accuracy (%) of each relocation (a column each) per method and
    level (:attr:`~terrainvis.relocation.Relocation.tables`); ``practical`` names its
    columns of practical relocations. Returns a DataFrame on its index with the columns
    ``oracle``, ``best`` (the best practical relocation's name; "–" where none has an
    accuracy), ``best_accuracy`` and ``gap`` (oracle - best, points); empty without an
    oracle column.
    """
    import pandas as pd

    if "oracle" not in accuracy.columns:
        return pd.DataFrame(columns=["oracle", "best", "best_accuracy", "gap"])
    shown = accuracy[list(practical)]
    best = [row.idxmax() if row.notna().any() else "–" for _, row in shown.iterrows()] if shown.shape[1] \
        else ["–"] * len(accuracy)
    out = pd.DataFrame({"oracle": accuracy["oracle"], "best": best,
                        "best_accuracy": shown.max(axis=1) if shown.shape[1] else np.nan}, index=accuracy.index)
    out["gap"] = out["oracle"] - out["best_accuracy"]
    out.attrs["title"] = ("Oracle bound: the best any relocation of the points could do (needs T's verdicts), "
                          "against the best practical one (accuracy %)")
    return out
