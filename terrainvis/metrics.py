"""How far a simplified terrain is from the original, and how many LOS verdicts survive."""

from __future__ import annotations

import numpy as np

from ._validate import describe
from .terrain import TIN, HeightGrid

__all__ = ["vertical_errors", "volume_error", "agreement"]


def vertical_errors(fine: HeightGrid, coarse) -> tuple[float, float]:
    """Maximum and RMS vertical error of ``coarse`` against the samples of ``fine``.

    Parameters
    ----------
    fine : HeightGrid
        The original terrain (nodata samples are ignored).
    coarse : HeightGrid or TIN
        A simplification covering the same extent.

    Returns
    -------
    (max_error, rms_error) : (float, float)
        Over every finite sample of ``fine``: max |coarse(x, y) - z| and its RMS.
    """
    if not isinstance(fine, HeightGrid):
        raise TypeError(f"fine must be a terrainvis.HeightGrid, got {describe(fine)}")
    if isinstance(coarse, TIN):
        approx = coarse.height_on_grid(fine.xs, fine.ys)
    elif isinstance(coarse, HeightGrid):
        approx = coarse.height_on_grid(fine.xs, fine.ys)
    else:
        raise TypeError(f"coarse must be a terrainvis.HeightGrid or terrainvis.TIN, got {describe(coarse)}")
    return errors_from_heights(fine, approx)


def errors_from_heights(fine: HeightGrid, approx: np.ndarray) -> tuple[float, float]:
    """Max and RMS of ``approx - fine.z`` over the finite samples of ``fine``.

    ``approx`` holds a simplified surface's heights at ``fine``'s samples (NaN where it
    does not cover them, which is an error).
    """
    valid = np.isfinite(fine.z)
    if np.isnan(approx[valid]).any():
        n = int(np.isnan(approx[valid]).sum())
        raise ValueError(f"coarse does not cover the fine grid: {n} fine samples fall outside it")
    diff = approx[valid] - fine.z[valid]
    return float(np.abs(diff).max()), float(np.sqrt(np.mean(diff**2)))


def _solid(vertices: np.ndarray, faces: np.ndarray, floor: float):
    """A closed manifold: the surface, a floor copy of it at ``floor``, and vertical walls."""
    import manifold3d

    n = vertices.shape[0]
    bottom = vertices.copy()
    bottom[:, 2] = floor
    # Boundary edges are the directed edges whose reverse is absent; faces are CCW seen
    # from above, so the footprint lies to the left of each boundary edge.
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    key = directed[:, 0].astype(np.int64) * n + directed[:, 1]
    rkey = directed[:, 1].astype(np.int64) * n + directed[:, 0]
    boundary = directed[~np.isin(key, rkey)]
    a, b = boundary[:, 0], boundary[:, 1]
    walls = np.concatenate([np.column_stack([b, a, a + n]), np.column_stack([b, a + n, b + n])])
    tris = np.concatenate([faces, faces[:, ::-1] + n, walls]).astype(np.uint64)
    mesh = manifold3d.Mesh64(np.ascontiguousarray(np.vstack([vertices, bottom])), np.ascontiguousarray(tris))
    solid = manifold3d.Manifold(mesh)
    if solid.status() != manifold3d.Error.NoError:
        raise ValueError(f"could not build a closed solid from the terrain: {solid.status()}")
    return solid


def volume_error(fine: HeightGrid, coarse) -> float:
    """Volume between the fine surface and a simplified one (a shape error, in units³).

    Each terrain is turned into a closed solid with manifold3d (its surface, vertical
    walls along the footprint boundary and a flat floor below both), and the volume of
    the symmetric difference, ``vol(A) + vol(B) - 2 vol(A and B)``, is returned. For two height
    fields over the same footprint this equals the integral of ``|coarse - fine|`` over
    the footprint; divided by the footprint area it is the mean absolute vertical error.

    Parameters
    ----------
    fine : HeightGrid
        The original terrain (no nodata).
    coarse : HeightGrid or TIN
        A simplification over the same extent.

    Returns
    -------
    float
    """
    if not isinstance(fine, HeightGrid):
        raise TypeError(f"fine must be a terrainvis.HeightGrid, got {describe(fine)}")
    if not isinstance(coarse, (HeightGrid, TIN)):
        raise TypeError(f"coarse must be a terrainvis.HeightGrid or terrainvis.TIN, got {describe(coarse)}")
    fine.require_finite("volume_error")
    if isinstance(coarse, HeightGrid):
        coarse.require_finite("volume_error")
        coarse = coarse.to_tin()
    if not np.allclose(coarse.extent, fine.extent, rtol=0, atol=1e-9 * (1 + np.abs(fine.extent).max())):
        raise ValueError(f"coarse must cover the extent of fine {fine.extent}, got {coarse.extent}")
    xmin, xmax, ymin, ymax = fine.extent
    area = (xmax - xmin) * (ymax - ymin)
    if abs(coarse.footprint_area() - area) > 1e-9 * area:
        raise ValueError(
            f"coarse must cover the footprint of fine (area {area:g}), but its faces cover {coarse.footprint_area():g}"
        )
    ft = fine.to_tin()
    # A local origin keeps the coordinates small (UTM northings lose digits otherwise).
    origin = np.array([fine.xs[0], fine.ys[0], 0.0])
    zmin = min(ft.vertices[:, 2].min(), coarse.vertices[:, 2].min())
    zmax = max(ft.vertices[:, 2].max(), coarse.vertices[:, 2].max())
    floor = zmin - max(1.0, 0.1 * (zmax - zmin))
    a = _solid(ft.vertices - origin, ft.faces, floor)
    b = _solid(coarse.vertices - origin, coarse.faces, floor)
    # |A xor B| = |A| + |B| - 2 |A and B|: one boolean instead of two differences, and in
    # float64 the cancellation costs a few digits of 16 (checked against the two
    # differences to 3e-14 relative on the bundled terrains).
    return float(a.volume() + b.volume() - 2.0 * (a ^ b).volume())


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
    tv = t[iu][sel]
    sv = s[iu][sel]
    agree_visible = int(np.count_nonzero(tv & sv))
    agree_blocked = int(np.count_nonzero(~tv & ~sv))
    false_visible = int(np.count_nonzero(~tv & sv))
    false_blocked = int(np.count_nonzero(tv & ~sv))
    n_pairs = int(tv.size)
    n_vis = agree_visible + false_blocked
    n_blk = agree_blocked + false_visible
    accuracy = (agree_visible + agree_blocked) / n_pairs if n_pairs else float("nan")
    if mask is None:
        accuracy_paper = (2 * (agree_visible + agree_blocked) + n) / (n * n) if n else float("nan")
    else:
        accuracy_paper = accuracy  # the paper's P x P convention has no meaning for a subset of pairs
    return {
        "n_pairs": n_pairs,
        "agree_visible": agree_visible,
        "agree_blocked": agree_blocked,
        "false_visible": false_visible,
        "false_blocked": false_blocked,
        "accuracy": accuracy,
        "visible_kept": agree_visible / n_vis if n_vis else float("nan"),
        "blocked_kept": agree_blocked / n_blk if n_blk else float("nan"),
        "accuracy_paper": accuracy_paper,
    }


def _square_bool(value, name: str) -> np.ndarray:
    arr = np.asarray(value)
    if arr.ndim != 2 or arr.shape[0] != arr.shape[1]:
        raise ValueError(f"{name} must be a square (n, n) matrix, got shape {arr.shape}")
    if arr.dtype != bool:
        if not np.isin(arr, (0, 1)).all():
            raise ValueError(f"{name} must be boolean (or 0/1), got values other than 0 and 1 (dtype {arr.dtype})")
        arr = arr.astype(bool)
    return arr
