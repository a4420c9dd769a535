"""Numba loops for reverse Faber subdivision (see :mod:`simplifiers.reverse_faber`).

Kernels loop and never validate: the public functions in ``reverse_faber.py`` check the
input, move the reduced axis to the middle of a C-contiguous ``(A, m, B)`` view and
allocate the output ``(A, n, B)``. Every kernel comes in two layouts:

* ``B == 1``: ``A`` contiguous curves (a reduction along the last axis); the curves are
  spread over the threads.
* ``B > 1``: the curve index runs along whole rows of length ``B`` (a reduction along
  axis 0 of a 2-D array combines whole rows), so the inner loops stream over contiguous
  memory; blocks of columns (or of coarse rows) are spread over the threads.

Each kernel ``k(..., out, t0, t1, stop)`` is serial and runs its tasks ``t0 .. t1-1``
(a task is a curve, a group of curves or a block of row segments, as its docstring
says), returning once the stop flag ``stop`` is set (:mod:`terrainvis.core.interrupt`);
:func:`terrainvis.core.interrupt.call` spreads the tasks over threads in chunks. Small
inputs run in the calling thread: starting threads costs more than they do. Every kernel
returns how many tasks wrote a non-finite value (0 when all is well), so the public
function can reject NaN or inf input without a separate pass over the data.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from terrainvis.core.compiling import KERNEL_ONLY
from terrainvis.core.stopflag import stopped

# Columns per block when a kernel walks several curves that are interleaved along B.
_BLOCK = 64
# Curves per block for the feature-aware solve (they are gathered into a local buffer).
_FEATURE_BLOCK = 16


_MAX_FLOAT = np.finfo(np.float64).max


@nb.njit(cache=True, nogil=True, inline="always")
def _nonfinite(v):
    """1 when v is NaN or infinite, else 0 (branch-free, so loops that OR it still vectorise)."""
    return 1 - int(abs(v) <= _MAX_FLOAT)


# ----------------------------------------------------------------------------- LLS
@nb.njit(cache=True, nogil=True)
def lls_curves(f, w0, w1, w2, out, t0, t1, stop):
    """Five-tap filter ``w0, w1, w2, w1, w0`` at every interior coarse position, ends kept.

    ``f`` (A, m) holds A contiguous curves, ``out`` (A, n); task ``a`` is curve ``a``:
    ``out[a, i] = w0 f[a, 2i-2] + w1 f[a, 2i-1] + w2 f[a, 2i] + w1 f[a, 2i+1] + w0 f[a, 2i+2]``
    for ``1 <= i <= n-2``, ``out[a, 0] = f[a, 0]`` and ``out[a, n-1] = f[a, m-1]``.
    """
    A, m = f.shape
    n = out.shape[1]
    bad = 0
    for a in range(t0, t1):
        if stopped(stop):
            return bad
        r = f[a]
        o = out[a]
        o[0] = r[0]
        o[n - 1] = r[m - 1]
        flag = _nonfinite(o[0]) | _nonfinite(o[n - 1])
        for i in range(1, n - 1):
            k = 2 * i
            v = w0 * (r[k - 2] + r[k + 2]) + w1 * (r[k - 1] + r[k + 1]) + w2 * r[k]
            o[i] = v
            flag |= _nonfinite(v)
        bad += flag
    return bad


@nb.njit(cache=True, nogil=True)
def lls_rows(f, w0, w1, w2, out, t0, t1, stop):
    """:func:`lls_curves` along the middle axis of ``f`` (A, m, B), by whole rows of length B.

    Task ``t`` is coarse row ``i = t % n`` of ``a = t // n`` (A * n tasks).
    """
    A, m, B = f.shape
    n = out.shape[1]
    bad = 0
    for t in range(t0, t1):
        if stopped(stop):
            return bad
        a = t // n
        i = t - a * n
        o = out[a, i]
        flag = 0
        if i == 0 or i == n - 1:
            r = f[a, 0] if i == 0 else f[a, m - 1]
            for b in range(B):
                v = r[b]
                o[b] = v
                flag |= _nonfinite(v)
        else:
            k = 2 * i
            r0 = f[a, k - 2]
            r1 = f[a, k - 1]
            r2 = f[a, k]
            r3 = f[a, k + 1]
            r4 = f[a, k + 2]
            for b in range(B):
                v = w0 * (r0[b] + r4[b]) + w1 * (r1[b] + r3[b]) + w2 * r2[b]
                o[b] = v
                flag |= _nonfinite(v)
        bad += flag
    return bad


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _lls_filter_row(r, w0, w1, w2, o):
    """The row filter of :func:`lls_curves` for one curve ``r`` (m,) into ``o`` (n,)."""
    m = r.shape[0]
    n = o.shape[0]
    o[0] = r[0]
    o[n - 1] = r[m - 1]
    for i in range(1, n - 1):
        k = 2 * i
        o[i] = w0 * (r[k - 2] + r[k + 2]) + w1 * (r[k - 1] + r[k + 1]) + w2 * r[k]


@nb.njit(cache=True, nogil=True)
def lls_level(f, w0, w1, w2, out, t0, t1, stop):
    """One fused 2-D LLS level: ``f`` (M, C) to ``out`` (N, Cn), rows then columns.

    Task ``t`` is coarse row ``t``. Each fine row it needs is filtered along the row once
    (into a ring of 5 filtered rows) and the 5 filtered rows are then combined, with the
    same arithmetic in the same order as :func:`lls_curves` followed by :func:`lls_rows`,
    so the result is bitwise identical to the two passes, without the intermediate
    (M, Cn) array.
    """
    M = f.shape[0]
    N, Cn = out.shape
    ring = np.empty((5, Cn))
    last = -1  # highest fine row filtered into the ring so far
    bad = 0
    for i in range(t0, t1):
        if stopped(stop):
            return bad
        o = out[i]
        if i == 0 or i == N - 1:
            _lls_filter_row(f[0] if i == 0 else f[M - 1], w0, w1, w2, o)
        else:
            k = 2 * i
            for kk in range(max(last + 1, k - 2), k + 3):
                _lls_filter_row(f[kk], w0, w1, w2, ring[kk % 5])
            last = k + 2
            r0 = ring[(k - 2) % 5]
            r1 = ring[(k - 1) % 5]
            r2 = ring[k % 5]
            r3 = ring[(k + 1) % 5]
            r4 = ring[(k + 2) % 5]
            for b in range(Cn):
                o[b] = w0 * (r0[b] + r4[b]) + w1 * (r1[b] + r3[b]) + w2 * r2[b]
        flag = 0
        for b in range(Cn):
            flag |= _nonfinite(o[b])
        bad += flag
    return bad


# ----------------------------------------------------------------------------- GLS
@nb.njit(cache=True, nogil=True)
def ldl_tridiagonal(diag, off, lsub, dinv):
    """LDL^T of a symmetric tridiagonal matrix: unit lower bidiagonal ``lsub`` and ``1/D``.

    ``lsub[j]`` (j >= 1) is L[j, j-1]; ``lsub[0]`` is set to 0.
    """
    n = diag.shape[0]
    d = diag[0]
    dinv[0] = 1.0 / d
    lsub[0] = 0.0
    for j in range(1, n):
        lj = off[j - 1] / d
        d = diag[j] - lj * off[j - 1]
        lsub[j] = lj
        dinv[j] = 1.0 / d


@nb.njit(cache=True, nogil=True, inline="always")
def _rhs(r, j, colptr, rows, vals):
    """``(S^T r)_j`` from the CSC form of S."""
    acc = 0.0
    for t in range(colptr[j], colptr[j + 1]):
        acc += vals[t] * r[rows[t]]
    return acc


@nb.njit(cache=True, nogil=True)
def gls_curves(f, jend, colptr, rows, vals, lsub, dinv, out, t0, t1, stop):
    """Solve ``S^T S c = S^T f`` for A contiguous curves ``f`` (A, m) into ``out`` (A, n).

    The LDL^T factors (``lsub``, ``dinv``) are shared by every curve. For
    ``1 <= j < jend`` column j of S is the standard hat ``0.5, 1, 0.5`` at fine rows
    ``2j-1, 2j, 2j+1``; the other columns (the first, and the last one or two) are read
    from the CSC form of S (``colptr``, ``rows``, ``vals``). Task ``t`` is the group of
    curves ``4t .. 4t+3`` ((A + 3) // 4 tasks), swept side by side so that their forward
    and backward recurrences overlap; a short last group repeats its last curve.
    """
    A, m = f.shape
    n = out.shape[1]
    bad = 0
    for t in range(t0, t1):
        if stopped(stop):
            return bad
        a = 4 * t
        i1 = min(a + 1, A - 1)  # a short last group repeats its last curve
        i2 = min(a + 2, A - 1)
        i3 = min(a + 3, A - 1)
        r0 = f[a]
        r1 = f[i1]
        r2 = f[i2]
        r3 = f[i3]
        o0 = out[a]
        o1 = out[i1]
        o2 = out[i2]
        o3 = out[i3]
        y0 = y1 = y2 = y3 = 0.0
        for j in range(n):
            if 1 <= j < jend:
                k = 2 * j
                a0 = r0[k] + 0.5 * (r0[k - 1] + r0[k + 1])
                a1 = r1[k] + 0.5 * (r1[k - 1] + r1[k + 1])
                a2 = r2[k] + 0.5 * (r2[k - 1] + r2[k + 1])
                a3 = r3[k] + 0.5 * (r3[k - 1] + r3[k + 1])
            else:
                a0 = _rhs(r0, j, colptr, rows, vals)
                a1 = _rhs(r1, j, colptr, rows, vals)
                a2 = _rhs(r2, j, colptr, rows, vals)
                a3 = _rhs(r3, j, colptr, rows, vals)
            lj = lsub[j]
            dj = dinv[j]
            y0 = a0 - lj * y0
            y1 = a1 - lj * y1
            y2 = a2 - lj * y2
            y3 = a3 - lj * y3
            o0[j] = y0 * dj
            o1[j] = y1 * dj
            o2[j] = y2 * dj
            o3[j] = y3 * dj
        x0 = o0[n - 1]
        x1 = o1[n - 1]
        x2 = o2[n - 1]
        x3 = o3[n - 1]
        flag = _nonfinite(x0) | _nonfinite(x1) | _nonfinite(x2) | _nonfinite(x3)
        for j in range(n - 2, -1, -1):
            lj = lsub[j + 1]
            x0 = o0[j] - lj * x0
            x1 = o1[j] - lj * x1
            x2 = o2[j] - lj * x2
            x3 = o3[j] - lj * x3
            o0[j] = x0
            o1[j] = x1
            o2[j] = x2
            o3[j] = x3
            flag |= _nonfinite(x0) | _nonfinite(x1) | _nonfinite(x2) | _nonfinite(x3)
        bad += flag
    return bad


@nb.njit(cache=True, nogil=True)
def gls_rows(f, jend, colptr, rows, vals, lsub, dinv, out, t0, t1, stop):
    """:func:`gls_curves` along the middle axis of ``f`` (A, m, B), by whole row segments.

    Task ``t`` is the block of ``_BLOCK`` columns number ``t % nblk`` of ``a = t // nblk``
    (A * nblk tasks, nblk = ceil(B / _BLOCK)); every step combines row segments, so the
    sweeps of the block's curves run side by side.
    """
    A, m, B = f.shape
    n = out.shape[1]
    nblk = (B + _BLOCK - 1) // _BLOCK
    bad = 0
    for t in range(t0, t1):
        if stopped(stop):
            return bad
        a = t // nblk
        b0 = (t - a * nblk) * _BLOCK
        b1 = min(B, b0 + _BLOCK)
        w = b1 - b0
        yprev = np.zeros(w)
        fa = f[a]
        oa = out[a]
        for j in range(n):
            o = oa[j, b0:b1]
            lj = lsub[j]
            dj = dinv[j]
            if 1 <= j < jend:
                k = 2 * j
                rm = fa[k - 1, b0:b1]
                rc = fa[k, b0:b1]
                rp = fa[k + 1, b0:b1]
                for bb in range(w):
                    y = rc[bb] + 0.5 * (rm[bb] + rp[bb]) - lj * yprev[bb]
                    yprev[bb] = y
                    o[bb] = y * dj
            else:
                o[:] = 0.0
                for s in range(colptr[j], colptr[j + 1]):
                    v = vals[s]
                    r = fa[rows[s], b0:b1]
                    for bb in range(w):
                        o[bb] += v * r[bb]
                for bb in range(w):
                    y = o[bb] - lj * yprev[bb]
                    yprev[bb] = y
                    o[bb] = y * dj
        flag = 0
        o = oa[n - 1, b0:b1]
        for bb in range(w):
            flag |= _nonfinite(o[bb])
        for j in range(n - 2, -1, -1):
            lj = lsub[j + 1]
            o = oa[j, b0:b1]
            o1 = oa[j + 1, b0:b1]
            for bb in range(w):
                v = o[bb] - lj * o1[bb]
                o[bb] = v
                flag |= _nonfinite(v)
        bad += flag
    return bad


# ------------------------------------------------------------------- feature-aware
@nb.njit(cache=True, nogil=True)
def critical_points(g, crit):
    """Write the critical points of curve ``g`` into ``crit``; return how many there are.

    The ends ``0`` and ``m-1`` always count. The curve is cut into runs of equal values;
    an interior run (touching neither end) whose value is strictly greater than both
    neighbouring runs' values, or strictly smaller than both, is one extremum, placed at
    its lower-middle sample ``(first + last) // 2``. A single sample is a run of length 1,
    so a strict local extremum is at its own index. The result is strictly increasing.
    """
    m = g.shape[0]
    crit[0] = 0
    nc = 1
    e = 0
    while e + 1 < m and g[e + 1] == g[0]:
        e += 1
    prev = g[0]
    s = e + 1
    while s < m:
        v = g[s]
        e = s
        while e + 1 < m and g[e + 1] == v:
            e += 1
        if e == m - 1:
            break
        nxt = g[e + 1]
        if (v > prev and v > nxt) or (v < prev and v < nxt):
            crit[nc] = (s + e) // 2
            nc += 1
        prev = v
        s = e + 1
    crit[nc] = m - 1
    return nc + 1


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def _feature_one(g, op, w2, work, x):
    """Feature-aware least squares for one curve ``g`` (m,), result in ``x`` (n,).

    ``op = (colptr, rows, vals, tdiag, toff)`` is the Faber operator as
    :func:`feature_apply` takes it; ``work = (crit, rhs, diag, off, lc, st, ptr, lv)`` the
    scratch arrays (m, n, n, n, n, n, n and 3n + 1 long) of the calling task.

    Normal equations ``(S^T S + w2 sum e e^T) c = S^T g + w2 sum e (g_j - g_k)`` with
    ``e = e_p - e_q`` per constraint, solved by an envelope (skyline) Cholesky: row q of
    the factor spans columns lc[q]..q when a constraint couples q with a non-adjacent
    p = lc[q] < q - 1, else q-1..q. Constraints chain through increasing coarse indices, so
    each row has at most one such coupling and the factorisation costs O(n).
    """
    colptr, rows, vals, tdiag, toff = op
    crit, rhs, diag, off, lc, st, ptr, lv = work
    n = x.shape[0]
    for j in range(n):
        acc = 0.0
        for t in range(colptr[j], colptr[j + 1]):
            acc += vals[t] * g[rows[t]]
        rhs[j] = acc
        diag[j] = tdiag[j]
        lc[j] = -1
    for j in range(n - 1):
        off[j] = toff[j]
    nc = critical_points(g, crit)
    for t in range(nc - 1):
        j = crit[t]
        k = crit[t + 1]
        p = min(j // 2, n - 1)
        q = min(k // 2, n - 1)
        if p == q:
            continue
        r = w2 * (g[j] - g[k])
        rhs[p] += r
        rhs[q] -= r
        diag[p] += w2
        diag[q] += w2
        if q == p + 1:
            off[p] -= w2
        else:
            lc[q] = p
    # envelope Cholesky: L[i, k] stored at lv[ptr[i] + k - st[i]] for st[i] <= k <= i
    pos = 0
    for i in range(n):
        if lc[i] >= 0:
            s = lc[i]
        elif i > 0:
            s = i - 1
        else:
            s = 0
        st[i] = s
        ptr[i] = pos
        for k in range(s, i):
            if k == i - 1:
                acc = off[i - 1]
            elif k == s:  # the long coupling (lc[i] < i - 1)
                acc = -w2
            else:
                acc = 0.0
            sk = st[k]
            lo = s if s > sk else sk
            pk = ptr[k] - sk
            for l in range(lo, k):
                acc -= lv[pos + l - s] * lv[pk + l]
            lv[pos + k - s] = acc / lv[pk + k]
        acc = diag[i]
        for l in range(s, i):
            v = lv[pos + l - s]
            acc -= v * v
        lv[pos + i - s] = math.sqrt(acc)
        pos += i - s + 1
    # forward: L y = rhs (y kept in rhs)
    for i in range(n):
        s = st[i]
        pi = ptr[i] - s
        acc = rhs[i]
        for l in range(s, i):
            acc -= lv[pi + l] * rhs[l]
        rhs[i] = acc / lv[pi + i]
    # backward: L^T x = y, column by column
    for i in range(n - 1, -1, -1):
        s = st[i]
        pi = ptr[i] - s
        xi = rhs[i] / lv[pi + i]
        x[i] = xi
        for l in range(s, i):
            rhs[l] -= lv[pi + l] * xi


@nb.njit(cache=True, nogil=True)
def feature_apply(f, colptr, rows, vals, tdiag, toff, w2, out, t0, t1, stop):
    """Feature-aware least squares for every curve of ``f`` (A, m, B) into ``out`` (A, n, B).

    Task ``t`` is the block of ``bs`` curves number ``t % nblk`` of ``a = t // nblk``
    (bs = ``_FEATURE_BLOCK`` when B > 1, else 1; A * ceil(B / bs) tasks). The block is
    gathered (reading whole row segments) into a contiguous buffer, solved curve by
    curve and scattered back. The stop flag ``stop`` (:mod:`terrainvis.core.interrupt`) is
    read before every task; once it is set the remaining tasks are skipped.
    """
    A, m, B = f.shape
    n = out.shape[1]
    bs = _FEATURE_BLOCK if B > 1 else 1
    nblk = (B + bs - 1) // bs
    bad = 0
    for t in range(t0, t1):
        if stopped(stop):
            break
        a = t // nblk
        b0 = (t - a * nblk) * bs
        b1 = min(B, b0 + bs)
        w = b1 - b0
        gbuf = np.empty((w, m))
        xbuf = np.empty((w, n))
        crit = np.empty(m, dtype=np.int64)
        rhs = np.empty(n)
        diag = np.empty(n)
        off = np.empty(n)
        lc = np.empty(n, dtype=np.int64)
        st = np.empty(n, dtype=np.int64)
        ptr = np.empty(n, dtype=np.int64)
        lv = np.empty(3 * n + 1)
        work = (crit, rhs, diag, off, lc, st, ptr, lv)
        fa = f[a]
        for i in range(m):
            r = fa[i]
            for bb in range(w):
                gbuf[bb, i] = r[b0 + bb]
        for bb in range(w):
            _feature_one(gbuf[bb], (colptr, rows, vals, tdiag, toff), w2, work, xbuf[bb])
        oa = out[a]
        flag = 0
        for j in range(n):
            o = oa[j]
            for bb in range(w):
                v = xbuf[bb, j]
                o[b0 + bb] = v
                flag |= _nonfinite(v)
        bad += flag
    return bad


@nb.njit(cache=True, nogil=True)
def critical_points_1d(g):
    """Critical points of one curve as a new int64 array (see :func:`critical_points`)."""
    crit = np.empty(g.shape[0], dtype=np.int64)
    nc = critical_points(g, crit)
    return crit[:nc].copy()
