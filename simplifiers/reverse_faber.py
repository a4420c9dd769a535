"""Regularity-preserving simplification: reverse Faber subdivision of curves and grids.

Faber subdivision turns a coarse curve ``c`` (n samples) into a fine curve ``f = S c``
by inserting midpoints. Reverse subdivision goes the other way: it picks ``c`` for a
given fine curve ``f`` (m samples) so that ``S c`` is close to ``f``. A height grid is
reduced by applying a curve operator along its rows (axis 1), then along its columns
(axis 0): :func:`simplifiers.simplify` does this ``level`` times.

Conventions (docs/ALGORITHMS.md section 2)
------------------------------------------
A curve of ``m`` fine samples at positions ``0..m-1`` keeps ``n = (m + 1) // 2`` coarse
samples:

* odd ``m = 2n - 1``: coarse positions ``0, 2, ..., 2n - 2``; S is the paper's Faber
  matrix, ``f_2j = c_j`` and ``f_2j+1 = (c_j + c_j+1) / 2``;
* even ``m = 2n``: coarse positions ``0, 2, ..., 2n - 4`` and ``2n - 1``, so both ends
  are kept and the last gap is 3 fine steps wide, where S interpolates linearly:
  ``f_2n-3 = 2/3 c_n-2 + 1/3 c_n-1`` and ``f_2n-2 = 1/3 c_n-2 + 2/3 c_n-1``.

The operators (every one keeps the dimension of its input and reduces one axis):

* :func:`simple` keeps the samples at the coarse positions;
* :func:`lls` is the paper's local least-squares filter (see its notes for the
  discrepancy between the printed and the derived coefficients);
* :func:`gls` is the exact least-squares solution of ``S c = f``;
* :func:`feature` adds one constraint per pair of consecutive critical points.

All reproduce constants; simple, GLS and LLS reproduce linear functions (and so does
the feature-aware operator, whose only constraint on a monotone line is consistent).
:func:`subdivide` and :func:`faber_subdivide` go forwards (coarse to fine).

References
----------
.. [1] Alderson, T. and Samavati, F. "Reverse subdivision for optimizing visibility
   tests", GRAPP 2012, pp. 143-150. :doi:`10.5220/0003851501430150`
.. [2] Samavati, F. and Bartels, R. "Multiresolution curve and surface representation:
   reversing subdivision rules by least-squares data fitting", Computer Graphics Forum
   18(2), 1999. :doi:`10.1111/1467-8659.00360`
"""

from __future__ import annotations

import functools
import math

import numpy as np

from terrainvis.core.interrupt import call
from terrainvis.core.validate import as_int, as_nonnegative_finite, describe
from terrainvis.core.terrain import HeightGrid

from . import _faber_kernels as _k

__all__ = [
    "simple", "lls", "gls", "feature", "reduce_level", "subdivide", "faber_subdivide", "coarse_positions",
    "critical_points", "LLS_WEIGHTS",
]

# Below this many samples of work a kernel runs serially (see _run).
_PARALLEL_MIN = 1 << 18

#: The LLS filters (five taps centred on a coarse position) by name.
#: ``"paper"``: the coefficients printed in [1]; ``"derived"``: the central row of
#: ``(L^T L)^-1 L^T`` for the 5x3 local Faber matrix L.
LLS_WEIGHTS = {
    "paper": (-1.0 / 6.0, 1.0 / 3.0, 2.0 / 3.0),
    "derived": (-1.0 / 7.0, 2.0 / 7.0, 5.0 / 7.0),
}


# ------------------------------------------------------------------ validation
def _real_array_axis(value, name: str, axis):
    """``value`` as a real numeric array with at least one axis, and ``axis`` normalised."""
    try:
        arr = np.asarray(value)
    except Exception as exc:  # an object numpy cannot turn into an array
        raise TypeError(f"{name} must be a numeric array, got {describe(value)}") from exc
    if arr.dtype.kind not in "biuf":
        raise TypeError(f"{name} must be a real numeric array, got {describe(arr)}")
    if arr.ndim == 0:
        raise ValueError(f"{name} must have at least one axis, got a 0-D array ({describe(arr)})")
    axis = as_int(axis, "axis")
    if not -arr.ndim <= axis < arr.ndim:
        raise ValueError(f"axis must be in [{-arr.ndim}, {arr.ndim - 1}] for a {arr.ndim}-D array, got {axis}")
    return arr, axis % arr.ndim


def _as_curves(f, axis, op: str):
    """Validate ``f`` and ``axis``; return the (A, m, B) C-contiguous float64 view (read-only) and shapes."""
    if isinstance(f, HeightGrid):
        raise TypeError(
            f"f must be an array of heights; to reduce a HeightGrid use simplifiers.simplify(grid, {op!r}, level)"
        )
    arr, axis = _real_array_axis(f, "f", axis)
    m = arr.shape[axis]
    if m < 3:
        raise ValueError(
            f"{op}: the curve along axis {axis} has {m} sample(s), too short to reduce "
            f"(reverse subdivision needs at least 3); f has shape {arr.shape}"
        )
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    a = math.prod(arr.shape[:axis])
    b = math.prod(arr.shape[axis + 1:])
    n = (m + 1) // 2
    out_shape = arr.shape[:axis] + (n,) + arr.shape[axis + 1:]
    # always a read-only view: the kernels only read their input, and numba compiles a
    # kernel once per signature, so a writable input (the rows' pass output, a user's
    # array) and a read-only one (a HeightGrid's z) would each cost a compilation
    view = arr.reshape(a, m, b)
    view.flags.writeable = False
    return view, out_shape, axis, m, n


def _raise_nonfinite(f3, op: str):
    """Raise for a non-finite result: name the NaN and inf in the input, or the overflow.

    Every fine sample enters some coarse value of lls, gls and feature with a non-zero
    weight, so a non-finite input always gives a non-finite output. The kernels report
    non-finite outputs as they write them, so finite input costs no extra pass; only
    then is the input scanned, to name the problem precisely.
    """
    bad = ~np.isfinite(f3)
    if bad.any():
        n_nan = int(np.isnan(f3).sum())
        n_inf = int(bad.sum()) - n_nan
        raise ValueError(
            f"{op}: f must be finite (NaN marks nodata), got {n_nan} NaN and {n_inf} infinite value(s); "
            "fill nodata first (HeightGrid.fill_nodata)"
        )
    raise FloatingPointError(f"{op}: the result overflowed float64 (max |f| = {float(np.abs(f3).max()):g})")


def _run(kernel, args, ntasks: int, work: int) -> int:
    """Run a kernel's ``ntasks`` tasks: in the calling thread when the input is small, else
    spread over the threads (:func:`terrainvis.core.interrupt.call`); the number of tasks
    that wrote a non-finite value.

    Starting threads costs far more than filtering a few thousand samples (and much more
    on a loaded machine), so inputs below ``_PARALLEL_MIN`` samples of work run in the
    calling thread.
    """
    if ntasks < 1:
        return 0
    return call(kernel, *args, work=work, items=ntasks, min_parallel=_PARALLEL_MIN)


# ------------------------------------------------------------ the matrix S
def coarse_positions(m: int) -> np.ndarray:
    """Fine positions of the coarse samples of a curve of ``m >= 2`` samples.

    Returns
    -------
    (n,) int64, read-only
        ``0, 2, ..., 2n-2`` for odd ``m = 2n-1``; ``0, 2, ..., 2n-4, 2n-1`` for even
        ``m = 2n``.

    Examples
    --------
    >>> coarse_positions(7).tolist(), coarse_positions(8).tolist()
    ([0, 2, 4, 6], [0, 2, 4, 7])
    """
    return _coarse_positions(as_int(m, "m", minimum=2))


@functools.lru_cache(maxsize=64)
def _coarse_positions(m: int) -> np.ndarray:
    n = (m + 1) // 2
    pos = 2 * np.arange(n, dtype=np.int64)
    pos[-1] = m - 1
    pos.flags.writeable = False
    return pos


@functools.lru_cache(maxsize=64)
def _faber_structure(m: int):
    """S for m fine samples: per fine row, its left coarse index and the two weights.

    Also its CSC form (for ``S^T f``), the tridiagonal ``S^T S`` and that matrix's LDL^T
    factors. Everything is read-only and cached per length.
    """
    pos = _coarse_positions(m)
    n = pos.size
    k = np.arange(m, dtype=np.int64)
    lo = np.minimum(np.searchsorted(pos, k, side="right") - 1, n - 2)
    gap = (pos[lo + 1] - pos[lo]).astype(np.float64)
    wl = (pos[lo + 1] - k) / gap  # one division of exact integers: 2/3 and 1/3 correctly rounded
    wr = (k - pos[lo]) / gap
    # CSC of S: the entries (k, lo, wl) and (k, lo + 1, wr), zeros dropped, by column
    ent_r = np.concatenate([k, k])
    ent_c = np.concatenate([lo, lo + 1])
    ent_v = np.concatenate([wl, wr])
    keep = ent_v != 0.0
    ent_r, ent_c, ent_v = ent_r[keep], ent_c[keep], ent_v[keep]
    order = np.lexsort((ent_r, ent_c))
    rows, cols, vals = ent_r[order], ent_c[order], ent_v[order]
    colptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(cols, minlength=n), out=colptr[1:])
    tdiag = np.bincount(cols, weights=vals * vals, minlength=n).astype(np.float64)
    toff = np.bincount(lo, weights=wl * wr, minlength=n)[: n - 1].astype(np.float64)
    lsub = np.empty(n)
    dinv = np.empty(n)
    _k.ldl_tridiagonal(tdiag, toff, lsub, dinv)
    out = dict(
        pos=pos, lo=lo, wl=wl, wr=wr, colptr=colptr, rows=rows, vals=vals,
        tdiag=tdiag, toff=np.ascontiguousarray(toff), lsub=lsub, dinv=dinv,
    )
    for v in out.values():
        v.flags.writeable = False
    return out


# ------------------------------------------------------------ operators
def simple(f, axis: int = -1):
    """Reverse Faber, simple variant: keep the samples at the coarse positions.

    Parameters
    ----------
    f : (..., m, ...) array_like
        Fine curves along ``axis`` (m >= 3), batched over every other axis; finite.
    axis : int
        The axis to reduce.

    Returns
    -------
    (..., (m+1)//2, ...) float64
        New array; ``f`` is not modified.

    Examples
    --------
    >>> simple([0.0, 1.0, 2.0, 3.0, 4.0, 5.0]).tolist()
    [0.0, 2.0, 5.0]
    """
    f3, out_shape, axis, m, n = _as_curves(f, axis, "simple")
    if not np.isfinite(f3).all():
        _raise_nonfinite(f3, "simple")
    out = np.empty((f3.shape[0], n, f3.shape[2]))
    # coarse positions 0, 2, ..., 2n-4 by a strided copy, and the last one (2n-2 or 2n-1)
    out[:, : n - 1] = f3[:, 0 : 2 * n - 3 : 2]
    out[:, n - 1] = f3[:, m - 1]
    return out.reshape(out_shape)


def lls(f, axis: int = -1, *, weights: str = "paper"):
    """Reverse Faber, local least squares: a five-tap filter at each coarse position.

    ``c_i = w0 f_2i-2 + w1 f_2i-1 + w2 f_2i + w1 f_2i+1 + w0 f_2i+2`` for every interior
    coarse sample ``1 <= i <= n-2``; the two end samples are kept (``c_0 = f_0``,
    ``c_n-1 = f_m-1``).

    Parameters
    ----------
    f : (..., m, ...) array_like
        Fine curves along ``axis`` (m >= 3), batched over every other axis; finite.
    axis : int
        The axis to reduce.
    weights : {"paper", "derived"}
        ``"paper"`` (default): the coefficients printed in [1]_,
        ``(1/6)[-1, 2, 4, 2, -1]``, which the paper's results used. ``"derived"``:
        ``(1/7)[-1, 2, 5, 2, -1]``, the central row of ``(L^T L)^-1 L^T`` where L is the
        5x3 Faber matrix mapping ``c_i-1, c_i, c_i+1`` to ``f_2i-2 .. f_2i+2``, i.e. what
        an actual local least-squares fit gives. Both sum to 1 and are symmetric, so both
        reproduce constants and linear functions; the paper's are not the least-squares
        solution of their own local problem.

    Returns
    -------
    (..., (m+1)//2, ...) float64

    Notes
    -----
    Even ``m = 2n``: the coarse positions are ``0, 2, ..., 2n-4, 2n-1``. The filter is
    applied at every interior coarse position ``2i`` (``1 <= i <= n-2``); its taps
    ``2i-2 .. 2i+2`` then always exist (the last interior one, at ``2n-4``, reads up to
    ``2n-2``), and the last coarse sample is the kept end ``f_2n-1``. Because the filter
    is symmetric and sums to 1, a linear curve gives exactly its values at ``2i``, so
    linear functions are reproduced for both parities.

    References
    ----------
    .. [1] Alderson and Samavati, GRAPP 2012, :doi:`10.5220/0003851501430150`

    Examples
    --------
    >>> lls([0.0, 0.0, 6.0, 0.0, 0.0]).tolist()
    [0.0, 4.0, 0.0]
    >>> lls([0.0, 0.0, 7.0, 0.0, 0.0], weights="derived").tolist()
    [0.0, 5.0, 0.0]
    """
    if not isinstance(weights, str) or weights not in LLS_WEIGHTS:
        raise ValueError(f"weights must be one of {list(LLS_WEIGHTS)}, got {weights!r}")
    f3, out_shape, axis, m, n = _as_curves(f, axis, "lls")
    w0, w1, w2 = LLS_WEIGHTS[weights]
    out = np.empty((f3.shape[0], n, f3.shape[2]))
    A, _, B = f3.shape
    if B == 1:
        args = (f3.reshape(A, m), w0, w1, w2, out.reshape(A, n))
        bad = _run(_k.lls_curves, args, A, f3.size)
    else:
        bad = _run(_k.lls_rows, (f3, w0, w1, w2, out), A * n, f3.size)
    # with n == 2 only the two ends are kept and the middle samples enter no output
    if bad or (n == 2 and not np.isfinite(f3).all()):
        _raise_nonfinite(f3, "lls")
    return out.reshape(out_shape)


def gls(f, axis: int = -1):
    """Reverse Faber, global least squares: ``c = argmin ||S c - f||``.

    Solves the tridiagonal normal equations ``S^T S c = S^T f``; the LDL^T factors of
    ``S^T S`` depend only on m, so they are computed once and every curve costs one
    forward and one backward sweep (O(m), no dense matrix).

    Parameters
    ----------
    f : (..., m, ...) array_like
        Fine curves along ``axis`` (m >= 3), batched over every other axis; finite.
    axis : int
        The axis to reduce.

    Returns
    -------
    (..., (m+1)//2, ...) float64

    Examples
    --------
    >>> np.round(gls([0.0, 0.5, 1.0, 1.5, 2.0]), 12).tolist()
    [0.0, 1.0, 2.0]
    """
    f3, out_shape, axis, m, n = _as_curves(f, axis, "gls")
    s = _faber_structure(m)
    out = np.empty((f3.shape[0], n, f3.shape[2]))
    # columns 1 .. jend-1 of S are the standard hat (0.5, 1, 0.5); for even m the last
    # two columns touch the 3-wide last gap
    jend = n - 1 if m % 2 else n - 2
    factors = (jend, s["colptr"], s["rows"], s["vals"], s["lsub"], s["dinv"])
    A, _, B = f3.shape
    if B == 1:
        args = (f3.reshape(A, m), *factors, out.reshape(A, n))
        bad = _run(_k.gls_curves, args, (A + 3) // 4, f3.size)
    else:
        ntasks = A * -(-B // _k._BLOCK)
        bad = _run(_k.gls_rows, (f3, *factors, out), ntasks, f3.size)
    if bad:
        _raise_nonfinite(f3, "gls")
    return out.reshape(out_shape)


def feature(f, axis: int = -1, *, weight: float = 1.0):
    """Reverse Faber, feature-aware least squares.

    The critical points of a curve are its two ends and its strict local extrema (see
    :func:`critical_points` for plateaus). For each pair of consecutive critical points
    ``j < k`` one row is appended to S: ``+1`` at coarse index ``p = floor(j/2)``, ``-1``
    at ``q = floor(k/2)`` (both clamped to ``n-1``; the clamp never binds, since
    ``floor((m-1)/2) = n-1`` for both parities), right-hand side ``f_j - f_k``, the row
    and its right-hand side scaled by ``weight``; a row with ``p == q`` is skipped.
    The result is the least-squares solution of the stacked system.

    Parameters
    ----------
    f : (..., m, ...) array_like
        Fine curves along ``axis`` (m >= 3), batched over every other axis; finite.
    axis : int
        The axis to reduce.
    weight : float
        Scale of the constraint rows, finite and >= 0 (1, as in the paper; 0 gives
        :func:`gls`).

    Returns
    -------
    (..., (m+1)//2, ...) float64

    Notes
    -----
    The normal matrix is ``S^T S`` (tridiagonal) plus, per constraint, ``weight^2`` on
    two diagonal entries and ``-weight^2`` at ``(p, q)``. The constraints chain through
    increasing coarse indices, so every row of the matrix couples with at most one
    non-adjacent earlier index; an envelope Cholesky factorises it in O(m) per curve,
    even when a monotone stretch couples index 0 with index n-1. Each curve is solved
    in a numba kernel, curves in parallel.

    Examples
    --------
    >>> feature([1.0, 2.0, 3.0, 4.0, 5.0]).round(12).tolist()
    [1.0, 3.0, 5.0]

    A peak at fine sample 3 (odd, between coarse samples 1 and 2): GLS spreads it
    evenly, the constraints pull coarse sample 1 (floor(3/2)) up towards the peak's height.

    >>> gls([0.0, 0.0, 0.0, 4.0, 0.0, 0.0, 0.0]).round(3).tolist()
    [-0.235, 1.176, 1.176, -0.235]
    >>> feature([0.0, 0.0, 0.0, 4.0, 0.0, 0.0, 0.0]).round(3).tolist()
    [-1.006, 2.315, 1.093, -0.87]
    """
    w = as_nonnegative_finite(weight, "weight")
    f3, out_shape, axis, m, n = _as_curves(f, axis, "feature")
    s = _faber_structure(m)
    out = np.empty((f3.shape[0], n, f3.shape[2]))
    A, _, B = f3.shape
    ntasks = A * -(-B // (_k._FEATURE_BLOCK if B > 1 else 1))
    args = (f3, s["colptr"], s["rows"], s["vals"], s["tdiag"], s["toff"], w * w, out)
    # the solve costs ~20x a filter per sample, so smaller inputs already pay for threads
    bad = _run(_k.feature_apply, args, ntasks, 20 * f3.size)
    if bad:
        _raise_nonfinite(f3, "feature")
    return out.reshape(out_shape)


def reduce_level(z, op, **options) -> np.ndarray:
    """One 2-D reverse-subdivision level: a curve operator along rows (axis 1), then columns.

    ``op(op(z, axis=1, **options), axis=0, **options)``; for :func:`lls` it runs as one
    fused pass (each coarse row made from five row-filtered fine rows, no intermediate
    array) and for :func:`simple` as one gather, about twice as fast and equal bit for bit.

    Parameters
    ----------
    z : (rows, cols) array_like
        Finite heights, rows >= 3 and cols >= 3.
    op : callable
        A curve operator ``op(f, axis=..., **options)``: :func:`simple`, :func:`lls`,
        :func:`gls`, :func:`feature` or any function with that signature.
    **options
        The operator's options (``weights=`` for LLS, ``weight=`` for feature).

    Returns
    -------
    ((rows+1)//2, (cols+1)//2) float64

    Examples
    --------
    >>> reduce_level(np.arange(25.0).reshape(5, 5), lls).round(12).tolist()
    [[0.0, 2.0, 4.0], [10.0, 12.0, 14.0], [20.0, 22.0, 24.0]]
    """
    if not callable(op):
        raise TypeError(f"op must be a curve operator such as simplifiers.reverse_faber.lls, got {describe(op)}")
    arr = np.asarray(z)
    if arr.ndim != 2:
        raise ValueError(f"z must be a 2-D array (rows, cols), got {arr.ndim}-D with shape {arr.shape}")
    if op is not lls and op is not simple:
        return op(op(arr, axis=1, **options), axis=0, **options)
    if op is simple:
        if options:
            raise TypeError(f"simple takes no options, got {sorted(options)}")
        f3, _, _, m, _ = _as_curves(arr, 1, "simple")
        rows = _as_curves(arr, 0, "simple")[3]
        f = f3.reshape(rows, m)
        if not np.isfinite(f).all():
            _raise_nonfinite(f, "simple")
        nr = (rows + 1) // 2
        n = (m + 1) // 2
        out = np.empty((nr, n))
        for o_rows, f_rows in ((slice(0, nr - 1), slice(0, 2 * nr - 3, 2)), (nr - 1, rows - 1)):
            out[o_rows, : n - 1] = f[f_rows, 0 : 2 * n - 3 : 2]
            out[o_rows, n - 1] = f[f_rows, m - 1]
        return out
    weights = options.pop("weights", "paper")
    if options:
        raise TypeError(f"lls got unexpected options {sorted(options)}; it takes weights=")
    if not isinstance(weights, str) or weights not in LLS_WEIGHTS:
        raise ValueError(f"weights must be one of {list(LLS_WEIGHTS)}, got {weights!r}")
    f3, _, _, m, n = _as_curves(arr, 1, "lls")
    rows = _as_curves(arr, 0, "lls")[3]
    f = f3.reshape(rows, m)
    nr = (rows + 1) // 2
    out = np.empty((nr, n))
    w0, w1, w2 = LLS_WEIGHTS[weights]
    bad = _run(_k.lls_level, (f, w0, w1, w2, out), nr, f.size)
    if bad or ((n == 2 or nr == 2) and not np.isfinite(f).all()):
        _raise_nonfinite(f, "lls")
    return out


def critical_points(f) -> np.ndarray:
    """Critical points of one curve, as used by :func:`feature`.

    The two ends always count. The curve is split into runs of equal consecutive
    values; an interior run (one touching neither end) whose value is strictly greater
    than the values of both neighbouring runs, or strictly smaller than both, is one
    extremum, placed at its lower-middle sample ``(first + last) // 2``. A run touching
    an end is represented by that end only; a run between a lower and a higher run (a
    step) is not critical.

    Parameters
    ----------
    f : (m,) array_like
        One finite curve, m >= 1.

    Returns
    -------
    (k,) int64
        Strictly increasing indices, starting with 0 and ending with m-1.

    Examples
    --------
    >>> critical_points([0, 3, 3, 3, 3, 1, 2, 2]).tolist()
    [0, 2, 5, 7]
    """
    arr = np.asarray(f)
    if arr.dtype.kind not in "biuf":
        raise TypeError(f"f must be a real numeric array, got {describe(arr)}")
    if arr.ndim != 1 or arr.size == 0:
        raise ValueError(f"f must be a non-empty 1-D curve, got shape {arr.shape}")
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    if not np.isfinite(arr).all():
        raise ValueError(f"f must be finite, got {int((~np.isfinite(arr)).sum())} NaN or infinite value(s)")
    if arr.size == 1:
        return np.zeros(1, dtype=np.int64)
    return _k.critical_points_1d(arr)


# ------------------------------------------------------------ forward subdivision
def subdivide(c, axis: int = -1, m: int | None = None):
    """Forward Faber subdivision of curves: exactly ``S @ c`` along ``axis``.

    Parameters
    ----------
    c : (..., n, ...) array_like
        Coarse curves along ``axis`` (n >= 2), batched over every other axis; finite.
    axis : int
        The axis to refine.
    m : int, optional
        Fine length, ``2n - 1`` (default: midpoints inserted) or ``2n`` (the last gap is
        split in thirds, the even rule of the conventions above).

    Returns
    -------
    (..., m, ...) float64
        ``f_pos[j] = c_j`` at the coarse positions, linear interpolation between them.

    Examples
    --------
    >>> subdivide([0.0, 2.0, 8.0]).tolist()
    [0.0, 1.0, 2.0, 5.0, 8.0]
    >>> subdivide([0.0, 3.0], m=4).tolist()
    [0.0, 1.0, 2.0, 3.0]
    """
    arr, axis = _real_array_axis(c, "c", axis)
    n = arr.shape[axis]
    if n < 2:
        raise ValueError(f"subdivide: the curve along axis {axis} has {n} sample(s); it needs at least 2")
    if m is None:
        m = 2 * n - 1
    m = as_int(m, "m")
    if m not in (2 * n - 1, 2 * n):
        raise ValueError(f"m must be {2 * n - 1} or {2 * n} for {n} coarse samples, got {m}")
    arr = np.moveaxis(np.asarray(arr, dtype=np.float64), axis, -1)
    if not np.isfinite(arr).all():
        raise ValueError(f"subdivide: c must be finite, got {int((~np.isfinite(arr)).sum())} NaN or infinite value(s)")
    s = _faber_structure(m)
    lo, wl, wr = s["lo"], s["wl"], s["wr"]
    # f_k = wl[k] c[lo[k]] + wr[k] c[lo[k] + 1]: S @ c row by row, with the zero term dropped
    left = arr[..., lo]
    right = arr[..., lo + 1]
    out = np.where(wr == 0.0, left, np.where(wl == 0.0, right, wl * left + wr * right))
    return np.ascontiguousarray(np.moveaxis(out, -1, axis))


def faber_subdivide(grid: HeightGrid, *, shape=None) -> HeightGrid:
    """Forward Faber subdivision of a height grid: rows, then columns, coordinates too.

    Parameters
    ----------
    grid : HeightGrid
        Coarse grid (R, C), without nodata.
    shape : (int, int), optional
        Fine shape; each axis ``2R - 1`` or ``2R`` (``2C - 1`` or ``2C``). Default
        ``(2R - 1, 2C - 1)``. An even length uses the even rule (the last gap is split in
        thirds), so ``faber_subdivide(simplify(g, "simple", 1), shape=g.shape)`` has the
        coordinates of ``g`` when g is uniform.

    Returns
    -------
    HeightGrid
        The tensor-product Faber surface sampled on the fine grid: a new sample inside a
        coarse cell is the average of the cell's four corners (bilinear at the centre),
        not the value of the grid's triangulated surface there. ``attrs`` are copied.

    Examples
    --------
    >>> g = HeightGrid([[0.0, 2.0], [4.0, 6.0]], dx=2.0, dy=2.0)
    >>> faber_subdivide(g).z.tolist()
    [[0.0, 1.0, 2.0], [2.0, 3.0, 4.0], [4.0, 5.0, 6.0]]
    """
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
    grid.require_finite("faber_subdivide")
    rows, cols = grid.shape
    if shape is None:
        shape = (2 * rows - 1, 2 * cols - 1)
    try:
        fr, fc = shape
    except (TypeError, ValueError) as exc:
        raise TypeError(f"shape must be a pair (rows, cols), got {describe(shape)}") from exc
    fr = as_int(fr, "shape[0]")
    fc = as_int(fc, "shape[1]")
    if fr not in (2 * rows - 1, 2 * rows) or fc not in (2 * cols - 1, 2 * cols):
        raise ValueError(
            f"shape must be ({2 * rows - 1} or {2 * rows}, {2 * cols - 1} or {2 * cols}) for a "
            f"{rows}x{cols} grid, got {tuple(shape)!r}"
        )
    z = subdivide(subdivide(grid.z, axis=1, m=fc), axis=0, m=fr)
    xs = subdivide(grid.xs, m=fc)
    ys = subdivide(grid.ys, m=fr)
    return HeightGrid.from_coords(z, xs, ys, attrs=grid.attrs)
