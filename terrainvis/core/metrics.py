"""How many line-of-sight verdicts a simplification keeps.

How far a simplified surface is from the original (vertical and volume errors) is measured
in :mod:`terrainvis.core.deviation`, below the simplifiers.
"""

from __future__ import annotations

import numpy as np


__all__ = ["agreement", "viewshed_agreement", "verdict_edges"]


def agreement(V_true, V_test, mask=None) -> dict:
    """How many line-of-sight verdicts a simplification keeps.

    Counted over unordered distinct pairs {i, j}, i < j (the upper triangle).

    Parameters
    ----------
    V_true : (n, n) bool
        Visibility on the original terrain.
    V_test : (n, n) bool
        Visibility on the simplified terrain (after relocating the points).
    mask : (n, n) bool, optional
        Pairs to count (e.g. those within a horizontal distance); only its upper
        triangle is read.

    Returns
    -------
    dict
        ``n_pairs``; ``agree_visible`` (agree+: visible on both), ``agree_blocked``
        (agree-), ``false_visible`` (blocked on the original, visible on the
        simplification), ``false_blocked`` (visible, then blocked); ``accuracy`` =
        (agree+ + agree-) / n_pairs; ``visible_kept`` = agree+ / (visible pairs), the
        paper's "Visible Rays" of Table 4; ``blocked_kept`` = agree- / (blocked pairs);
        ``accuracy_paper``, the same agreement over the n² ordered pairs of P x P.

    Notes
    -----
    The paper divides by |P x P| = n². That counts every pair twice and adds the n
    diagonal pairs, which always agree: ``accuracy_paper = (n(n-1) accuracy + n) / n²``.
    With n = 50 it is ``0.98 accuracy + 0.02``: an accuracy of 90 % over distinct pairs
    reads as 90.2 % the paper's way. The difference is at most 1/n and shrinks as the
    accuracy rises. Rates whose denominator is zero are NaN.

    Examples
    --------
    >>> T = np.array([[1, 1, 0], [1, 1, 1], [0, 1, 1]], bool)
    >>> S = np.array([[1, 0, 0], [0, 1, 1], [0, 1, 1]], bool)
    >>> a = agreement(T, S)
    >>> a["accuracy"], a["false_blocked"]
    (0.6666666666666666, 1)
    """
    t = _square_bool(V_true, "V_true")
    s = _square_bool(V_test, "V_test")
    if s.shape != t.shape:
        raise ValueError(f"V_test must have the shape of V_true {t.shape}, got {s.shape}")
    n = t.shape[0]
    iu = np.triu_indices(n, k=1)
    sel = np.ones(iu[0].size, dtype=bool)
    if mask is not None:
        m = _square_bool(mask, "mask")
        if m.shape != t.shape:
            raise ValueError(f"mask must have the shape of V_true {t.shape}, got {m.shape}")
        sel = m[iu]
    counts = _tally(t[iu][sel], s[iu][sel])
    agreed = counts["agree_visible"] + counts["agree_blocked"]
    if mask is None:
        counts["accuracy_paper"] = (2 * agreed + n) / (n * n) if n else float("nan")
    else:
        counts["accuracy_paper"] = counts["accuracy"]  # the paper's P x P convention has no meaning for a subset
    return counts


def viewshed_agreement(V_true, V_test, mask=None) -> dict:
    """How many cells of a viewshed keep their verdict: the counts of :func:`agreement` for one observer.

    A cell counts as the pair (observer, cell), so the counts read as in :func:`agreement`.

    Parameters
    ----------
    V_true, V_test : (rows, cols) bool
        The viewshed on the original terrain and on the simplified one (targets at the
        same samples, e.g. :func:`terrainvis.viewshed` with ``at=``).
    mask : (rows, cols) bool, optional
        Cells to count (e.g. those within a distance of the observer).

    Returns
    -------
    dict
        The keys of :func:`agreement` (``n_pairs`` is the number of cells counted;
        ``accuracy_paper`` is NaN: the paper's convention is about point pairs), and
        ``visible_area_ratio``, the visible area on S(T) over that on T.

    Examples
    --------
    >>> T = np.array([[1, 1], [0, 0]], bool)
    >>> S = np.array([[1, 0], [1, 0]], bool)
    >>> a = viewshed_agreement(T, S)
    >>> a["accuracy"], a["false_visible"], a["visible_area_ratio"]
    (0.5, 1, 1.0)
    """
    t = _bool_array(V_true, "V_true")
    s = _bool_array(V_test, "V_test")
    if s.shape != t.shape:
        raise ValueError(f"V_test must have the shape of V_true {t.shape}, got {s.shape}")
    if mask is not None:
        m = _bool_array(mask, "mask")
        if m.shape != t.shape:
            raise ValueError(f"mask must have the shape of V_true {t.shape}, got {m.shape}")
        t, s = t[m], s[m]
    counts = _tally(t.ravel(), s.ravel())
    visible = counts["agree_visible"] + counts["false_blocked"]
    counts["accuracy_paper"] = np.nan
    counts["visible_area_ratio"] = (
        (counts["agree_visible"] + counts["false_visible"]) / visible if visible else np.nan)
    return counts


def verdict_edges(viewshed) -> np.ndarray:
    """The cells of a viewshed that have a cell of the other verdict among their 8 neighbours.

    Two exact viewsheds of different surface models (ours against GDAL's or GRASS's)
    differ mostly where a ray grazes its horizon, on these cells: the share of their
    differences that lies here says whether they differ as models do or otherwise.

    Parameters
    ----------
    viewshed : (rows, cols) bool

    Returns
    -------
    (rows, cols) bool

    Examples
    --------
    >>> v = np.zeros((3, 4), bool)
    >>> v[:, 2:] = True
    >>> verdict_edges(v).astype(int)
    array([[0, 1, 1, 0],
           [0, 1, 1, 0],
           [0, 1, 1, 0]])
    """
    vis = _bool_array(viewshed, "viewshed")
    p = np.pad(vis, 1, mode="edge")
    rows, cols = vis.shape
    edge = np.zeros(vis.shape, dtype=bool)
    for dr in range(3):
        for dc in range(3):
            edge |= p[dr : dr + rows, dc : dc + cols] != vis
    return edge


def _tally(t: np.ndarray, s: np.ndarray) -> dict:
    """The agreement counts and rates of verdicts ``t`` (true) and ``s`` (test), 1-D bool arrays."""
    agree_visible = int(np.count_nonzero(t & s))
    agree_blocked = int(np.count_nonzero(~t & ~s))
    false_visible = int(np.count_nonzero(~t & s))
    false_blocked = int(np.count_nonzero(t & ~s))
    n = int(t.size)
    n_vis = agree_visible + false_blocked
    n_blk = agree_blocked + false_visible
    return {
        "n_pairs": n,
        "agree_visible": agree_visible,
        "agree_blocked": agree_blocked,
        "false_visible": false_visible,
        "false_blocked": false_blocked,
        "accuracy": (agree_visible + agree_blocked) / n if n else float("nan"),
        "visible_kept": agree_visible / n_vis if n_vis else float("nan"),
        "blocked_kept": agree_blocked / n_blk if n_blk else float("nan"),
    }


def _square_bool(value, name: str) -> np.ndarray:
    arr = np.asarray(value)
    if arr.ndim != 2 or arr.shape[0] != arr.shape[1]:
        raise ValueError(f"{name} must be a square (n, n) matrix, got shape {arr.shape}")
    return _bool_array(arr, name)


def _bool_array(value, name: str) -> np.ndarray:
    arr = np.asarray(value)
    if arr.ndim != 2:
        raise ValueError(f"{name} must be a 2-D array, got shape {arr.shape}")
    if arr.dtype != bool:
        if not np.isin(arr, (0, 1)).all():
            raise ValueError(f"{name} must be boolean (or 0/1), got values other than 0 and 1 (dtype {arr.dtype})")
        arr = arr.astype(bool)
    return arr
