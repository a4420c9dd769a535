"""Regression tests against mesh ground truth: does a simplification keep its lines of sight?

:func:`assert_visibility_kept` is for a project's own test suite: "our terrain pipeline
keeps at least 95 % of line-of-sight verdicts". It samples points on the original
terrain T (or takes yours), relocates them onto the simplification S(T), and compares
every pair's verdict on the two surfaces with the exact predicate. Below the threshold it
raises :class:`AssertionError` with a report a person can act on: the accuracy, how many
pairs became falsely visible or falsely blocked, and the worst pairs (those T decides
most clearly) with their coordinates and clearances on both surfaces. Above it, it
returns the same figures.

Examples
--------
In a pytest test file::

    import simplifiers
    import terrainvis as tv
    from terrainvis.testing import assert_visibility_kept

    def test_our_lls_level_2_keeps_line_of_sight():
        T = tv.load_dem("our_dem.tif")
        assert_visibility_kept(T, simplifiers.simplify(T, "lls", 2), min_accuracy=0.95)
"""

from __future__ import annotations

import numpy as np

__all__ = ["assert_visibility_kept"]


def assert_visibility_kept(original, simplified, *, min_accuracy: float, points=None, n: int = 200, seed: int = 0,
                           offset: float = 0.0, relocation: str = "full", frame: str | None = None,
                           repair: bool = False, worst: int = 5, **predicate) -> dict:
    """Raise :class:`AssertionError` unless ``simplified`` keeps at least ``min_accuracy`` of the pairs' verdicts.

    Parameters
    ----------
    original : HeightGrid, str or Path
        T: a HeightGrid, a bundled name or a DEM file.
    simplified : TIN, HeightGrid, trimesh mesh, str or Path
        S(T), as :func:`terrainvis.evaluate` takes it (a mesh or raster file in the DEM's
        CRS or the terrain's frame, checked as a height field over T's footprint).
    min_accuracy : float
        The least share of pairs, in [0, 1], whose visible/blocked verdict must be the
        same on S(T) as on T (0.95 for 95 %).
    points : (k, 3) array_like, optional
        The points to test (on or ``offset`` above T); default ``n`` random points of T
        (:func:`terrainvis.sample_points` with ``seed``).
    n, seed, offset
        How many random points, their seed and their height above T.
    relocation : str
        How the points are placed on S(T) (:data:`terrainvis.relocation.RELOCATIONS`): a
        relocation that needs T (its entry declares ``needs=("original",)``, as the
        calibrated one does) is given it; one that needs T's verdicts of the pairs (a bound,
        ``needs=("reference",)``) is refused.
    frame, repair
        As in :func:`terrainvis.evaluate`, for ``simplified``.
    worst : int
        How many of the wrong pairs the report lists.
    **predicate
        The line-of-sight options of both surfaces' verdicts (``curvature``,
        ``earth_radius``, ``end_radius`` (S(T) only), ``engine``).

    Returns
    -------
    dict
        ``accuracy``, ``n_pairs``, ``agree_visible``, ``agree_blocked``,
        ``false_visible`` (blocked on T, visible on S(T)), ``false_blocked``,
        ``visible_kept``, ``blocked_kept`` (as :func:`terrainvis.agreement` counts them)
        and ``worst``: the wrong pairs that T decides most clearly, each a dict with the
        two points ``a`` and ``b`` (on T), the verdict on T and the minimum clearance of
        the segment on T and on S(T).

    Raises
    ------
    AssertionError
        Below ``min_accuracy``, with the report.
    ValueError
        Bad arguments (a threshold outside [0, 1], a simplified terrain that is not a
        height field over T, ...).

    Examples
    --------
    >>> import simplifiers, terrainvis as tv
    >>> T = tv.bundled_terrain("hills")
    >>> kept = assert_visibility_kept(T, simplifiers.simplify(T, "lls", 1), min_accuracy=0.9, n=60)
    >>> kept["accuracy"] >= 0.9, kept["n_pairs"]
    (True, 1770)
    """
    __tracebackhide__ = True  # pytest shows the failing assertion of the test, not this helper's source
    from .core.sampling import sample_points
    from .core.validate import as_finite_scalar, as_int, as_nonnegative_finite, as_points
    from .core.metrics import agreement
    from .experiment.evaluate import as_simplified
    from .experiment.plan import resolve_terrains
    from .relocation import RELOCATIONS, relocate
    from .visibility import min_clearance, visibility_matrix

    threshold = as_finite_scalar(min_accuracy, "min_accuracy")
    if not 0.0 <= threshold <= 1.0:
        raise ValueError(f"min_accuracy must be a share in [0, 1] (0.95 for 95 %), got {min_accuracy!r}")
    worst = as_int(worst, "worst", minimum=0)
    beyond = [n for n in (RELOCATIONS[relocation].needs if isinstance(relocation, str) and relocation in RELOCATIONS
                                                      else ()) if n != "original"]
    if beyond:
        raise ValueError(f"relocation {relocation!r} needs {', '.join(beyond)} (T's verdicts of the very pairs it is "
                         "tested on), which a test of the simplification cannot give; use a practical relocation")
    offset = as_nonnegative_finite(offset, "offset", "z units")  # a point below T sees nothing, on T or S(T)
    (_, T), = resolve_terrains([original]).items()
    S = as_simplified(simplified, T, frame=frame, repair=repair, label="simplified")
    if points is None:
        P = sample_points(T, as_int(n, "n", minimum=2), seed=as_int(seed, "seed", minimum=0), offset=offset)
    else:
        P = as_points(points, "points", 3)
        if P.shape[0] < 2:
            raise ValueError(f"points must hold at least 2 points, got {P.shape[0]}")
    on_s = {k: v for k, v in predicate.items()}
    on_t = {k: v for k, v in predicate.items() if k != "end_radius"}
    # T to every relocation (one that needs it declares so; one that takes no original ignores it, terrainvis.relocate)
    Q = relocate(P, S, relocation, offset=offset, original=T, **on_s)
    v_t = visibility_matrix(T, P, **on_t)
    v_s = visibility_matrix(S, Q, **on_s)
    counts = agreement(v_t, v_s)
    result = {k: counts[k] for k in ("accuracy", "n_pairs", "agree_visible", "agree_blocked", "false_visible",
                                     "false_blocked", "visible_kept", "blocked_kept")}
    i, j = np.nonzero(np.triu(v_t != v_s, 1))
    result["worst"] = _worst(T, S, P, Q, i, j, v_t, worst, on_t, on_s, min_clearance) if len(i) and worst else []
    if not counts["accuracy"] >= threshold:
        raise AssertionError(_report(result, threshold, relocation, len(P), T))
    return result


def _worst(T, S, P, Q, i, j, v_t, k, on_t, on_s, min_clearance) -> list[dict]:
    """The ``k`` wrong pairs with the largest clearance on T in absolute value (T decides them most clearly)."""
    curve_t = {key: v for key, v in on_t.items() if key in ("curvature", "earth_radius")}
    curve_s = {key: v for key, v in on_s.items() if key in ("curvature", "earth_radius", "end_radius")}
    c_t = min_clearance(T, P[i], P[j], **curve_t)
    pick = np.argsort(-np.abs(c_t), kind="stable")[:k]
    c_s = min_clearance(S, Q[i[pick]], Q[j[pick]], **curve_s)
    return [{"a": P[i[m]].tolist(), "b": P[j[m]].tolist(), "visible_on_original": bool(v_t[i[m], j[m]]),
             "clearance_original": float(c_t[m]), "clearance_simplified": float(cs)}
            for m, cs in zip(pick, c_s)]


def _report(result: dict, threshold: float, relocation: str, n: int, T) -> str:
    """The failure's text; positions with the digits that show a tenth of T's cell (``.6g``
    rounded a UTM northing to 10 m), heights to the centimetre."""
    from .core._positions import PositionFrame

    frame = PositionFrame(T, "local")

    def point(p) -> str:
        return f"{frame.value(p[0])}, {frame.value(p[1])}, {p[2]:.2f}"

    lines = [
        f"the simplification keeps {100 * result['accuracy']:.2f} % of the line-of-sight verdicts, below the "
        f"required {100 * threshold:.2f} %",
        f"  {result['n_pairs']:,} pairs of {n} points, relocated onto it by {relocation!r}: "
        f"{result['false_visible']:,} blocked pairs became visible, {result['false_blocked']:,} visible pairs became "
        f"blocked (visible kept {100 * result['visible_kept']:.1f} %, blocked kept {100 * result['blocked_kept']:.1f} %)",
    ]
    if result["worst"]:
        lines.append("  the wrong pairs the original decides most clearly:")
        for w in result["worst"]:
            a, b = point(w["a"]), point(w["b"])
            seen = "visible" if w["visible_on_original"] else "blocked"
            lines.append(f"    ({a}) -> ({b}): {seen} on the original (clearance {w['clearance_original']:+.4g}), "
                         f"not on the simplification (clearance {w['clearance_simplified']:+.4g})")
    return "\n".join(lines)
