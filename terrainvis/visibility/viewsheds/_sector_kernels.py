"""The exact viewshed sweep on a HeightGrid, sector by sector (numba).

The sweep's kernels are split by concern: the records, codes and plane geometry
(:mod:`._geometry_kernels`), the exact walk of a ray (:mod:`._walk_kernels`), the
wedges' bounds and the grid's tables (:mod:`._bound_kernels`), and this module, the sweep
that uses them: :func:`sweep` runs sectors of directions out from the eye ring by ring
(:func:`_sector`), and :func:`bucket_targets` sorts targets that are not the grid's own
samples by sector and ring. :mod:`terrainvis.visibility.viewsheds.sweep` checks the input
and calls it.

Geometry used throughout
------------------------
For a point P on the surface at horizontal distance ``d`` from the eye E, its *slope*
seen from the eye is ``s(P) = (surface(P) - z_E) / d``. On the ray from E to a target T
(horizontal distance D, slope ``s_T``), the clearance at P is ``d * (s_T - s(P))``, so T
is visible iff ``s_T`` is at least the *horizon*: the largest ``s(P)`` over the tested
part of the ray. Along one ray ``s`` is monotone inside a triangle, so the horizon is
reached on a triangle edge.

*Rings.* The eye stands in cell ``(re, ce)``. Cell ring ``j`` (the *annulus* j) is the
set of cells at Chebyshev index distance ``j`` from that cell; sample ring ``j`` is the
boundary of the box of cell rings ``<= j``, so the ray from E to a sample of ring ``j``
leaves box ``j - 1`` and crosses only annulus ``j`` before reaching it.

*Bins.* The directions are cut into ``B`` wedges of equal pseudo-angle (``B`` doubles at
rings ``R1, 2 R1, 4 R1, ...`` so that a wedge is at most about 0.7 cells wide where it is
used). For every wedge the sweep keeps

* an upper bound of ``s`` over every surface point in the wedge of the annuli swept so
  far (no ray in the wedge has a higher horizon there), per quad of ``QUAD`` rings for the
  current and the previous block of ``BLOCK`` rings (``quads``), per completed block (``hist``) and for
  all completed blocks (``ubp``), and
* ``lb``: a value such that every ray in the wedge crosses a surface point (at a distance
  of at least ``delta`` from the eye) whose slope exceeds it by enough to block any target
  of slope below ``lb`` (the clearance tolerance is folded in).

All bounds are rigorous: rounding is covered by ``e_h`` (an upper bound of the absolute
error of any computed height in these kernels and in the pair engine), and the decisions
keep a margin ``m`` from the threshold ``-tol``; targets inside that margin are left
undecided and the caller answers them with the pair engine itself.

*Deciding a target* on sample ring j (the bounds then hold the rings < j): blocked if
``lb`` exceeds its slope; otherwise the part of its ray beyond the box of rings < j is
walked exactly; then it is visible if its slope is at least the upper bound, and
otherwise the rings (near the target) or blocks of rings (farther back) whose bound
reaches its slope are walked exactly too (so only the parts of the ray near its horizon
are walked).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ...core.compiling import KERNEL_ONLY
from ...core.stopflag import stopped
from ...core.surface import borrow, borrow_grid, keep_alive
from ...tolerances import RING_BOUND_REL, WEDGE_BOUNDARY_SLACK
from ._bound_kernels import SEG, annulus_edges, cell_bounds, cell_range, curvature_pads, far_corner, ring_distance
from ._geometry_kernels import (
    BLOCKED, INF, NO_END, NO_RING, NOT_TARGET, PEPS, REL, UNDECIDED, VISIBLE, Targets, Wedges, diamond, locate, unwrap,
)
from ._walk_kernels import walk_min


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _cell_path(q, j, re, ce, nr, nc):
    """The cells of annulus j near quadrant q, in increasing angle, as two runs.

    Returns ``((r_a, c_a, dr_a, dc_a, n_a), (r_b, c_b, dr_b, dc_b, n_b))``: run k starts at
    cell (r, c) and steps by (dr, dc) for n cells (clamped to the grid). Each run has one
    extra cell at its outer end so that cells touching the quadrant's boundary rays are
    included.
    """
    ncr = nr - 1  # cell rows
    ncc = nc - 1
    if q == 0:
        # right column c = ce + j, rows re - 1 .. re + j; top row r = re + j, cols ce + j - 1 .. ce - 1
        ca = ce + j
        ra0 = max(re - 1, 0)
        ra1 = min(re + j, ncr - 1)
        na = ra1 - ra0 + 1 if ca <= ncc - 1 else 0
        rb = re + j
        cb0 = min(ce + j - 1, ncc - 1)
        cb1 = max(ce - 1, 0)
        nb_ = cb0 - cb1 + 1 if rb <= ncr - 1 else 0
        return (ra0, ca, 1, 0, max(na, 0)), (rb, cb0, 0, -1, max(nb_, 0))
    if q == 1:
        # top row r = re + j, cols ce + 1 .. ce - j; left column c = ce - j, rows re + j - 1 .. re - 1
        ra = re + j
        ca0 = min(ce + 1, ncc - 1)
        ca1 = max(ce - j, 0)
        na = ca0 - ca1 + 1 if ra <= ncr - 1 else 0
        cb = ce - j
        rb0 = min(re + j - 1, ncr - 1)
        rb1 = max(re - 1, 0)
        nb_ = rb0 - rb1 + 1 if cb >= 0 else 0
        return (ra, ca0, 0, -1, max(na, 0)), (rb0, cb, -1, 0, max(nb_, 0))
    if q == 2:
        # left column c = ce - j, rows re + 1 .. re - j; bottom row r = re - j, cols ce - j + 1 .. ce + 1
        ca = ce - j
        ra0 = min(re + 1, ncr - 1)
        ra1 = max(re - j, 0)
        na = ra0 - ra1 + 1 if ca >= 0 else 0
        rb = re - j
        cb0 = max(ce - j + 1, 0)
        cb1 = min(ce + 1, ncc - 1)
        nb_ = cb1 - cb0 + 1 if rb >= 0 else 0
        return (ra0, ca, -1, 0, max(na, 0)), (rb, cb0, 0, 1, max(nb_, 0))
    # q == 3: bottom row r = re - j, cols ce - 1 .. ce + j; right column c = ce + j, rows re - j + 1 .. re + 1
    ra = re - j
    ca0 = max(ce - 1, 0)
    ca1 = min(ce + j, ncc - 1)
    na = ca1 - ca0 + 1 if ra >= 0 else 0
    cb = ce + j
    rb0 = max(re - j + 1, 0)
    rb1 = min(re + 1, ncr - 1)
    nb_ = rb1 - rb0 + 1 if cb <= ncc - 1 else 0
    return (ra, ca0, 0, 1, max(na, 0)), (rb0, cb, 1, 0, max(nb_, 0))


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _box_exit(g, eye, k, dx, dy):
    """Parameter where the ray E + t (dx, dy) leaves the box of cell rings <= k."""
    xs, ys = g.xs, g.ys
    re, ce, ex, ey = eye.re, eye.ce, eye.ex, eye.ey
    nr = ys.shape[0]
    nc = xs.shape[0]
    t = INF
    if dx > 0.0:
        i = ce + 1 + k
        if i <= nc - 1:
            t = min(t, (xs[i] - ex) / dx)
    elif dx < 0.0:
        i = ce - k
        if i >= 0:
            t = min(t, (xs[i] - ex) / dx)
    if dy > 0.0:
        i = re + 1 + k
        if i <= nr - 1:
            t = min(t, (ys[i] - ey) / dy)
    elif dy < 0.0:
        i = re - k
        if i >= 0:
            t = min(t, (ys[i] - ey) / dy)
    return t


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _level(j, r1):
    if j < r1:
        return 0
    lev = 1
    lim = 2 * r1
    while j >= lim:
        lim *= 2
        lev += 1
    return lev


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _run_range(g, eye, q, run, plo, phi):
    """Cells [i0, i1] of a run (see :func:`_cell_path`) whose angular range meets [plo, phi]."""
    r0, c0, dr, dc, n = run
    lo = 0
    hi = n
    while lo < hi:
        mid = (lo + hi) >> 1
        pmn, pmx = cell_range(g, eye, r0 + mid * dr, c0 + mid * dc, q)
        if pmx < plo - PEPS:
            lo = mid + 1
        else:
            hi = mid
    i0 = lo
    hi = n
    while lo < hi:
        mid = (lo + hi) >> 1
        pmn, pmx = cell_range(g, eye, r0 + mid * dr, c0 + mid * dc, q)
        if pmn <= phi + PEPS:
            lo = mid + 1
        else:
            hi = mid
    return i0, lo - 1


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _run_lo(run, i0, i1):
    """First row (vertical run) or column (horizontal run) of cells i0..i1 of a run."""
    if run[3] == 0:
        return min(run[0] + i0 * run[2], run[0] + i1 * run[2])
    return min(run[1] + i0 * run[3], run[1] + i1 * run[3])


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _fill(g, eye, q, run, lo, k0, k1, buf, kc):
    """Slopes, pseudo-angles and distances of the samples k0..k1 of a run's two lines.

    Vertical run (dc == 0): line 0 is column c0 and line 1 column c0 + 1, indexed by
    row - lo. Horizontal run: line 0 is row r0 and line 1 row r0 + 1, indexed by
    col - lo. ``buf`` (3, 2, length) gets the slopes, pseudo-angles and distances.
    """
    r0, c0, dc = run[0], run[1], run[3]
    for k in range(k0, k1 + 1):
        for line in range(2):
            if dc == 0:
                rr = lo + k
                cc = c0 + line
            else:
                rr = r0 + line
                cc = lo + k
            dx = g.xs[cc] - eye.ex
            dy = g.ys[rr] - eye.ey
            d = np.sqrt(dx * dx + dy * dy)
            buf[0, line, k] = (np.float64(g.z[rr, cc]) - eye.ez) / d - kc * d
            buf[1, line, k] = unwrap(diamond(dx, dy), q)
            buf[2, line, k] = d


#: Rings per block of the wedges' history.
BLOCK = 16


#: Rings per quad: the finest unit of the history (the walks' pieces).
QUAD = 4


#: Blocks per group: the coarsest unit of the old blocks' history (``GROUP * BLOCK``
#: divides the first refining ring, so a group's rings share one wedge resolution).
GROUP = 8


NQUAD = 2 * BLOCK // QUAD


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _wedge_slot(p, bsz, glo):
    """Local index of the wedge holding pseudo-angle p, and whether p lies on its lower or
    upper boundary (within rounding), where the neighbouring wedge counts too."""
    k4 = bsz * 0.25
    gb = p * k4
    g = int(np.floor(gb))
    fr = gb - g
    return g - glo, fr < WEDGE_BOUNDARY_SLACK * k4, fr > 1.0 - WEDGE_BOUNDARY_SLACK * k4


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _slot(p, bsz, glo):
    """The wedges to read for pseudo-angle p at resolution ``bsz`` (window starting at global
    wedge ``glo``): ``(i, i_lo, i_hi)``, the local index of the wedge holding p and the
    first and last of those counted with it (its neighbour when p lies on a boundary
    within rounding). Computed once per target and resolution, read for every bound."""
    i, at_lo, at_hi = _wedge_slot(p, bsz, glo)
    return i, (i - 1 if at_lo else i), (i + 1 if at_hi else i)


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _slot_max(arr, sl):
    """Value of the wedges of slot ``sl`` (:func:`_slot`): the largest of them."""
    i, i_lo, i_hi = sl
    v = arr[i]
    if i_lo < i:
        v = max(v, arr[i_lo])
    if i_hi > i:
        v = max(v, arr[i_hi])
    return v


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _row_max(arr, row, sl):
    """:func:`_slot_max` of row ``row`` of a 2-D history, indexed in place (a row view
    would cost a reference count increment and decrement, a call each)."""
    i, i_lo, i_hi = sl
    v = arr[row, i]
    if i_lo < i:
        v = max(v, arr[row, i_lo])
    if i_hi > i:
        v = max(v, arr[row, i_hi])
    return v


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _lb_blocks(lb, sl, st, dist, e_h, kc):
    """Whether the lower bound of the target's wedges (slot ``sl``) proves it blocked, given
    its slope ``st`` (lowered by ``kc * dist`` under earth curvature): ``(blocked, slack)``
    with the slope's slack."""
    i_b, i_lo, i_hi = sl
    lbv = lb[i_b]
    if i_lo < i_b:
        lbv = min(lbv, lb[i_lo])
    if i_hi > i_b:
        lbv = min(lbv, lb[i_hi])
    slack = 2.0 * e_h / dist + REL * (abs(st) + kc * dist)
    return lbv > st + slack, slack


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _ub_max(w, j, sl):
    """Upper bound of the slope over the rings < j in the wedges of slot ``sl``: the
    largest of ``ubp`` (the completed blocks) and of the current block's quads."""
    ubv = _slot_max(w.ubp, sl)
    for qk in range(BLOCK * (j // BLOCK) // QUAD, (j - 1) // QUAD + 1):
        ubv = max(ubv, _row_max(w.quads, qk % NQUAD, sl))
    return ubv


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _decide(g, eye, rules, w, j, win, tg, sl, ub_clear):
    """Verdict of a target that the lower bound did not block, from the wedge bounds
    ``w`` (holding the rings <= j - 1) and exact walks.

    ``win`` is ``(s, glo, bsz, b0, r1, nsec)``: the sector, its window of wedges and the
    layout. ``tg`` is ``(p, tdx, tdy, nt, dist, st, slack)``: the target's unwrapped
    pseudo-angle, its offset from the eye, its horizontal distance, its slope and that
    slope's rounding slack; ``sl`` its slot at the current resolution (:func:`_slot`).
    ``ub_clear``: whether the slope less its slack clears the wedge's upper bound (the
    largest of ``ubp``, over the completed blocks, and the current block's quads:
    :func:`_ub_max`). Then only the part beyond the box of rings <= j - 1 (annulus j) is
    walked (the caller first tries the bound of its cells, :func:`_last_ring_bound`);
    otherwise the rings whose bounds reach the slope are walked too, with annulus j as
    one walk (:func:`_block_walk`). Returns (code, how): how 1 (decided by the last
    ring's walk and the upper bound), 2 (by walking rings whose bound reaches the
    target's slope) or 3 (undecided).
    """
    p, tdx, tdy, nt, dist, st, slack = tg
    ray = (eye.ex, eye.ey, eye.ez, tdx, tdy, nt)
    if ub_clear:
        tau = rules.delta / np.sqrt(dist * dist + nt * nt)
        tolm = rules.tol + rules.marg
        cl = _walk_rings(g, eye, ray, j, NO_END, tau, 1.0 - tau, tolm, rules.kc * (dist * dist))
        if cl < -tolm:
            return BLOCKED, 1
        if cl < -rules.tol + rules.marg:
            return UNDECIDED, 3
        return VISIBLE, 1
    tau = rules.delta / np.sqrt(dist * dist + nt * nt)
    res = _block_walk(g, eye, rules, w, j, win, ray, sl, p, st - slack, tau, 1.0 - tau)
    return res, (3 if res == UNDECIDED else 2)


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _block_walk(g, eye, rules, w, j, win, ray, sl, p, smin, tau, t_end):
    """Exact walk of the target's ray over the rings < j whose wedge maximum reaches
    ``smin`` (the target's slope less its slack; ``p`` its unwrapped pseudo-angle, ``sl``
    its slot at the current resolution); the other rings are clear.

    The unit is the quad of QUAD rings (``w.quads``): the quads whose maximum reaches
    ``smin`` are walked, consecutive ones as one piece, so near the target, where a
    visible target's horizon usually is, and around a far horizon, only the rings that
    can reach its slope are walked. The history is read coarse to fine: every old block
    (older than the previous one) is skipped at once when their common maximum
    ``w.ubold`` clears, a group of GROUP old blocks when its maximum ``w.grp`` does, a
    completed block when its maximum ``w.hist`` does, each at the wedge resolution of its
    level (the target's slot computed once per level). ``win`` as in :func:`_decide`.
    Annulus j, beyond the bounds, is walked too. The walks cover t in [tau, t_end].
    Returns BLOCKED, VISIBLE or UNDECIDED (some part within the margin of the threshold,
    nothing clearly blocked).
    """
    s, glo, bsz, b0, r1, nsec = win
    tolm = rules.tol + rules.marg
    amb = -rules.tol + rules.marg
    bulge = rules.kc * (ray[3] * ray[3] + ray[4] * ray[4])
    nfull = j // BLOCK  # completed blocks; the old ones are 0 .. nfull - 2
    nq = (j + QUAD - 1) // QUAD  # quads holding rings 0 .. j - 1
    qpb = BLOCK // QUAD
    ambiguous = False
    run_lo = NO_RING  # first ring of the piece to walk (-1: none open)
    run_hi = NO_RING
    qk = 0
    if nfull >= 2 and not _slot_max(w.ubold, sl) > smin:
        qk = (nfull - 1) * qpb  # every old block clears
    lev_end = -1  # first ring beyond the level of the slot in hand
    slq = sl
    while qk < nq:
        r_lo = QUAD * qk
        if r_lo >= lev_end:
            lev = _level(r_lo, r1)
            lev_end = r1 << lev
            bszb = b0 << lev
            slq = sl if bszb == bsz else _slot(p, bszb, s * (bszb // nsec) - 1)
        b = qk // qpb
        skip = 0
        if qk % qpb == 0 and b < nfull:
            if b % GROUP == 0 and b <= nfull - 2 and not _row_max(w.grp, b // GROUP, slq) > smin:
                skip = min(b + GROUP, nfull - 1) - b  # the group's old blocks clear
            elif not _row_max(w.hist, b, slq) > smin:
                skip = 1
        if skip == 0 and b < nfull - 1:
            # an old block that reaches: walked whole
            if run_lo < 0:
                run_lo = r_lo
            run_hi = r_lo + BLOCK - 1
            qk += qpb
            continue
        if skip == 0 and _row_max(w.quads, qk % NQUAD, slq) > smin:
            if run_lo < 0:
                run_lo = r_lo
            run_hi = min(r_lo + QUAD - 1, j - 1)
            qk += 1
            continue
        if run_lo >= 0:
            cl = _walk_rings(g, eye, ray, run_lo, run_hi, tau, t_end, tolm, bulge)
            run_lo = -1
            if cl < -tolm:
                return BLOCKED
            if cl < amb:
                ambiguous = True
        qk += skip * qpb if skip > 0 else 1
    # the rest of the ray beyond the bounds (annulus j, where an own target stands, or
    # annuli j and j + 1 for another target) is always walked, joined to an open piece
    cl = _walk_rings(g, eye, ray, run_lo if run_lo >= 0 else j, NO_END, tau, t_end, tolm, bulge)
    if cl < -tolm:
        return BLOCKED
    if cl < amb:
        ambiguous = True
    return UNDECIDED if ambiguous else VISIBLE


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _walk_rings(g, eye, ray, r_lo, r_hi, tau, t_end, tolm, bulge):
    """Exact minimum clearance of the ray over the annuli r_lo..r_hi (r_hi ``BEYOND``:
    all annuli from r_lo on), within [tau, t_end] (inf when that is empty; the walk stops
    below ``-tolm``)."""
    t0 = tau
    if r_lo > 0:
        t0 = max(t0, _box_exit(g, eye, r_lo - 1, ray[3], ray[4]))
    t1 = min(_box_exit(g, eye, r_hi, ray[3], ray[4]), t_end)
    if t1 <= t0:
        return INF
    return walk_min(g, ray, t0, t1, -tolm, bulge)


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _seg_hidden(eye, rules, lb, win, rect, zmax, q):
    """Whether the rectangle ``rect`` = (x0, x1, y0, y1) (relative to the eye, not holding
    it), whose heights are at most ``zmax``, lies under the lower bound of every wedge of
    the window ``win`` = (glo, nloc, k4) that it meets: ``(hidden, pmin, pmax)``.

    Every surface point P of a hidden rectangle, and every target standing ``ht`` above
    one, has a slope below ``lb`` of its wedge, so a higher point on its own ray comes
    first: the targets are blocked, and P can never be the horizon of a ray through it,
    so its cells need no bounds (a point dominating P either is in the bounds or is
    itself dominated by an earlier one, down to the first rings). The slope of any point
    is at most ``(zmax + ht - ez) / d`` at its distance d, less ``kc d``.
    """
    glo, nloc, k4 = win
    x0, x1, y0, y1 = rect
    ax = x0 if x0 > 0.0 else (-x1 if x1 < 0.0 else 0.0)
    ay = y0 if y0 > 0.0 else (-y1 if y1 < 0.0 else 0.0)
    dmin = np.sqrt(ax * ax + ay * ay)
    fx = max(abs(x0), abs(x1))
    fy = max(abs(y0), abs(y1))
    num = zmax + rules.ht - eye.ez
    if num >= 0.0:
        sup = num / dmin
    else:
        sup = num / np.sqrt(fx * fx + fy * fy)
    sup = sup - rules.kc * dmin
    sup = sup + 2.0 * rules.e_h / dmin + REL * (abs(sup) + rules.kc * dmin)
    p0 = unwrap(diamond(x0, y0), q)
    p1 = unwrap(diamond(x1, y0), q)
    p2 = unwrap(diamond(x0, y1), q)
    p3 = unwrap(diamond(x1, y1), q)
    pmin = min(min(p0, p1), min(p2, p3))
    pmax = max(max(p0, p1), max(p2, p3))
    g0 = int(np.floor((pmin - PEPS) * k4))
    g1 = int(np.floor((pmax + PEPS) * k4))
    if g0 < glo or g1 > glo + nloc - 1 or not (sup == sup):
        return False, pmin, pmax
    return _all_above(lb, np.uint64(g0 - glo), np.uint64(g1 - glo), sup), pmin, pmax


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _all_above(v, i0, i1, x):
    """Whether ``v[i0..i1]`` all exceed x (unsigned indices and no early exit, so that the
    loop is vectorised: most segments tested are hidden and read every wedge)."""
    ok = True
    for i in range(i0, i1 + np.uint64(1)):
        ok &= v[i] > x
    return ok


@nb.njit(cache=True, nogil=True, error_model="numpy")
def bucket_targets(g, eye, tx, ty, nsec, jstop, tstart, torder):
    """Sort targets (local coordinates) by (sector, ring at which they are decided).

    A target in a cell of cell ring k is decided at ring j = k - 1, when the bounds hold
    the rings <= k - 2 (at least one cell away from it), after an exact walk across the
    rings k - 1 and k. Targets with k < 3 are left out (the caller answers them exactly).
    ``tstart`` (nsec * (jstop + 2) + 1) gets each bucket's start in ``torder``; returns the
    number of targets placed.
    """
    m = tx.shape[0]
    nkey = nsec * (jstop + 2)
    key = np.full(m, -1, dtype=np.int64)
    counts = np.zeros(nkey + 1, dtype=np.int64)
    for i in range(m):
        c = locate(g.xs, g.ixw, g.uniform, tx[i])
        r = locate(g.ys, g.iyw, g.uniform, ty[i])
        k = max(abs(r - eye.re), abs(c - eye.ce))
        if k < 3 or k - 1 > jstop:
            continue
        p = diamond(tx[i] - eye.ex, ty[i] - eye.ey)
        s = min(int(p * 0.25 * nsec), nsec - 1)
        # the sector owning p (the same test as the sweep's: plo <= p < phi)
        while s > 0 and p < s * 4.0 / nsec:
            s -= 1
        while s < nsec - 1 and p >= (s + 1) * 4.0 / nsec:
            s += 1
        kk = s * (jstop + 2) + (k - 1)
        key[i] = kk
        counts[kk + 1] += 1
    for kk in range(nkey):
        counts[kk + 1] += counts[kk]
    for kk in range(nkey + 1):
        tstart[kk] = counts[kk]
    placed = counts[nkey]
    for i in range(m):
        kk = key[i]
        if kk >= 0:
            torder[counts[kk]] = i
            counts[kk] += 1
    return placed


@nb.njit(cache=True, nogil=True, error_model="numpy")
def sweep(g, eye, rules, lay, tg, stats, s0, s1, stop):
    """Decide the targets of sectors ``s0 .. s1 - 1`` with rigorous horizon bounds and partial exact walks.

    One task per angular sector (``lay.nsec`` sectors, a multiple of 4;
    :func:`terrainvis.core.interrupt.call` spreads them over threads). Each task sweeps the rings outwards keeping the bounds for its
    own wedges plus one guard wedge on each side: at ring j it first decides the targets
    whose bounds are complete (the samples of sample ring j whose direction falls in the
    sector, when ``tg.own``; otherwise the targets of bucket (sector, j) of ``tg.tstart`` /
    ``tg.torder``, see :func:`bucket_targets`), then adds annulus j (exact edge clipping up
    to ring ``lay.jnear``, a cell bound beyond). ``tg.code`` (own samples) or ``tg.tcode``
    (other targets) get BLOCKED, VISIBLE or UNDECIDED (the caller answers those with the
    pair engine); targets already NOT_TARGET are skipped. ``stats[sector, 0..4]`` counts
    targets decided by ``lb``, by the upper bound and the last rings' walk, by walking
    blocks of rings, left undecided, and by the upper bound and the last ring's bound
    (:func:`_last_ring_bound`, no walk). ``stop`` is the stop flag of
    :mod:`terrainvis.core.interrupt`: every sector reads it once per ring and returns when it
    is set (the codes are then incomplete and never used).
    """
    for sector in range(s0, s1):
        _sector(g, eye, rules, lay, tg, sector, stats, stop)


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _close_block(w, j, n, r1):
    """Close the block of rings j - BLOCK .. j - 1: keep its upper bounds (the largest of
    its quads') in the history, fold them into ``ubp``, and fold the block before it into
    ``ubold`` and into its group's ``grp``."""
    b = j // BLOCK - 1
    q0 = BLOCK * b // QUAD
    for i in range(n + 2):
        v = -INF
        for qk in range(q0, q0 + BLOCK // QUAD):
            v = max(v, w.quads[qk % NQUAD, i])
        w.hist[b, i] = v
        w.ubp[i] = max(w.ubp[i], v)
    if b >= 1:
        # block b - 1 becomes old; it may hold half as many wedges (refined at block b)
        coarse = _level(BLOCK * (b - 1), r1) < _level(BLOCK * b, r1)
        for i in range(n + 2):
            ic = ((i - 1) >> 1) + 1 if coarse else i
            w.ubold[i] = max(w.ubold[i], w.hist[b - 1, ic])
        # its group (at its own resolution: a group never straddles a refinement)
        grow = w.grp[(b - 1) // GROUP]
        first = (b - 1) % GROUP == 0
        for i in range(((n >> 1) if coarse else n) + 2):
            v = w.hist[b - 1, i]
            grow[i] = v if first else max(grow[i], v)


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _refine(w, tmp, n):
    """Split each of the ``n`` wedges (plus guards) in two (at a block boundary: the new
    block's rings start at the new resolution): local index i covers global
    ``s * n - 1 + i``."""
    for i in range(n + 2):
        tmp[0, i] = w.ubp[i]
        tmp[1, i] = w.lb[i]
        tmp[2, i] = w.ubold[i]
    for i in range(2 * n + 2):
        ic = ((i - 1) >> 1) + 1
        w.ubp[i] = tmp[0, ic]
        w.lb[i] = tmp[1, ic]
        w.ubold[i] = tmp[2, ic]


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _add_cells(w, ring, win, ann, runs, ranges, buf, hidden):
    """Add the cells of both runs of annulus ``ring`` (away from the eye) with
    :func:`cell_bounds`, except those of hidden segments.

    ``runs`` the two runs (:func:`_cell_path`), ``ranges`` (3, 2) int64 each run's first
    and last cell index and the first row or column of its sample buffers ``buf`` (run,
    quantity, line, index; see :func:`_fill`); ``hidden`` (run, segment) flags the
    segments (SEG-aligned, counted from the one holding that first row or column) whose
    points lie under the lower bound (:func:`_seg_hidden`). The cells are visited segment
    by segment in increasing row or column (the bounds are maxima: the order is free).
    """
    cur = w.quads[(ring // QUAD) % NQUAD]
    for run in range(2):
        if ranges[1, run] < ranges[0, run]:
            continue
        r0, c0, dr, dc = runs[run][0], runs[run][1], runs[run][2], runs[run][3]
        lo = ranges[2, run]
        if dc == 0:
            last = max(r0 + ranges[0, run] * dr, r0 + ranges[1, run] * dr)
        else:
            last = max(c0 + ranges[0, run] * dc, c0 + ranges[1, run] * dc)
        s_0 = buf[run, 0, 0]
        s_1 = buf[run, 0, 1]
        p_0 = buf[run, 1, 0]
        p_1 = buf[run, 1, 1]
        slo = lo // SEG
        a = lo
        while a <= last:
            b = min((a // SEG + 1) * SEG - 1, last)
            if not hidden[run, a // SEG - slo]:
                if dc == 0:
                    for k in range(a - lo, b - lo + 1):
                        cell_bounds(cur, w.lb, win, ann, (s_0[k], s_1[k], s_0[k + 1], s_1[k + 1]),
                                     (p_0[k], p_1[k], p_0[k + 1], p_1[k + 1]))
                else:
                    for k in range(a - lo, b - lo + 1):
                        cell_bounds(cur, w.lb, win, ann, (s_0[k], s_0[k + 1], s_1[k], s_1[k + 1]),
                                     (p_0[k], p_0[k + 1], p_1[k], p_1[k + 1]))
            a = b + 1


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _last_ring_bound(buf, k, outer, filled, side, last):
    """Upper bound of the slope at every point where the ray to the target at index k of a
    run's outer line crosses a grid line or a cell diagonal in annulus j; inf when this
    cannot tell (the exact walk of annulus j then decides).

    ``buf`` (3, 2, n) the run's samples (:func:`_fill`), ``filled`` = (k0, k1) the indices
    filled, ``side`` = (s0, s1) the indices of the inner line that lie on the side of the
    box of rings <= j - 1, ``last`` = ``(rel, slack)`` the annulus's convexity factor and
    upper slack (as in :func:`cell_bounds`; slack inf: no bound). The ray leaves that box
    through the inner line between inner samples m and m + 1 (their pseudo-angles bracket
    the target's) when both lie on the side; from there it stays between the two lines,
    in the cells between index m and the target's. Every point where it crosses a grid
    line or a diagonal there lies on an edge of those cells that does not end at the
    target (such an edge meets the ray only at the target), so its slope is at most the
    largest slope of those cells' corners other than the target, up to the convexity
    factor and the slack.
    """
    rel, slack = last
    if not slack < INF:
        return INF
    k0, k1 = filled
    il = 1 - outer
    pt = buf[1, outer, k]
    m = -1
    for mm in range(max(k - 3, k0), min(k + 3, k1 - 1) + 1):
        pa = buf[1, il, mm]
        pb = buf[1, il, mm + 1]
        if min(pa, pb) - PEPS <= pt <= max(pa, pb) + PEPS:
            m = mm
            break
    if m < 0 or m < side[0] or m + 1 > side[1]:
        return INF
    a0 = min(m, k)
    a1 = max(m + 1, k)
    # the crossing near an end of the bracket (within rounding) may lie in the next cell
    if abs(pt - buf[1, il, m]) <= PEPS:
        a0 = min(a0, m - 1)
    if abs(pt - buf[1, il, m + 1]) <= PEPS:
        a1 = max(a1, m + 2)
    if a0 < k0 or a1 > k1:
        return INF
    hi = -INF
    for i in range(a0, a1 + 1):
        hi = max(hi, buf[0, il, i])
        if i != k:
            hi = max(hi, buf[0, outer, i])
    if not hi < INF:
        return INF
    hi = hi + max(hi, 0.0) * rel
    return hi + slack + REL * abs(hi)


#: Segments per block of the first hidden test (:func:`_run_segments`).
BLOCK_SEGS = 8


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _run_segments(g, eye, rules, w, tg, rn, span, dwin, buf, hidden, counts, last):
    """Fill a run's samples and decide the targets on its outer line, segment by segment.

    ``span`` is ``(j, q, i0, i1, lo, cells, plo, phi)``: the sample ring, the quadrant,
    the run's cells in the window, its
    first row or column, whether annulus j is bounded cell by cell (then each SEG-aligned
    segment is first tested with :func:`_seg_hidden`, a whole aligned block of
    :data:`BLOCK_SEGS` segments at once before them: each segment of a hidden block is
    hidden too, its rectangle lower and farther; a hidden one gets no samples, its targets
    are blocked and ``hidden`` flags it) and the sector's own pseudo-angles
    [plo, phi). Returns how many targets the lower bound blocked; ``counts`` gets the
    others (see :func:`sweep`). ``last`` as in :func:`_last_ring_bound`.
    """
    j, q, i0, i1, lo, cells, plo, phi = span
    r0, c0, dc = rn[0], rn[1], rn[3]
    vertical = dc == 0
    if vertical:
        outer = 1 if c0 > eye.ce else 0
    else:
        outer = 1 if r0 > eye.re else 0
    glo, bsz = dwin[1], dwin[2]
    # the inner line's samples on the side of the box of rings <= j - 1 (buffer indices)
    if vertical:
        side = (eye.re - j + 1 - lo, eye.re + j - lo)
    else:
        side = (eye.ce - j + 1 - lo, eye.ce + j - lo)
    end = lo + i1 - i0  # last cell (row or column)
    n_lb = 0
    a = lo
    slo = lo // SEG
    while a <= end:
        b = min((a // SEG + 1) * SEG - 1, end)  # cells a..b: one aligned segment
        hid = False
        pmin = pmax = 0.0
        if cells:
            # an aligned block of BLOCK_SEGS segments first: when it lies under the lower bound, so
            # do all of its segments (one test where there were BLOCK_SEGS); else the segment (one
            # call site: numba inlines the test once)
            block = a % (SEG * BLOCK_SEGS) == 0 and a + SEG * BLOCK_SEGS - 1 <= end
            for attempt in range(2 if block else 1):
                last_cell = a + SEG * BLOCK_SEGS - 1 if block and attempt == 0 else b
                zmax = -INF  # the cells' heights are at most their segments' strip maxima
                for k in range(a // SEG, last_cell // SEG + 1):
                    if vertical:
                        zmax = max(zmax, np.float64(max(g.cmax[k, c0], g.cmax[k, c0 + 1])))
                    else:
                        zmax = max(zmax, np.float64(max(g.rmax[r0, k], g.rmax[r0 + 1, k])))
                if vertical:
                    rect = (g.xs[c0] - eye.ex, g.xs[c0 + 1] - eye.ex, g.ys[a] - eye.ey, g.ys[last_cell + 1] - eye.ey)
                else:
                    rect = (g.xs[a] - eye.ex, g.xs[last_cell + 1] - eye.ex, g.ys[r0] - eye.ey, g.ys[r0 + 1] - eye.ey)
                hid, pmin, pmax = _seg_hidden(eye, rules, w.lb, (glo, bsz // dwin[5] + 2, bsz * 0.25), rect, zmax, q)
                if hid:
                    b = last_cell
                    break
        top = b + 1 if b == end else b  # the samples a..top (the next segment starts at b + 1)
        for k in range(a // SEG - slo, b // SEG - slo + 1):
            hidden[k] = hid
        if hid:
            if tg.own and pmin >= plo + PEPS and pmax < phi - PEPS:
                # every sample of the segment is in the sector: no pseudo-angle to test, and
                # no branch (an already decided or non-target sample is written back as is)
                n_lb += _block_line(tg.code, vertical, r0 + outer if not vertical else c0 + outer, a, top)
            elif tg.own:
                for k in range(a, top + 1):
                    if vertical:
                        rr = k
                        cc = c0 + outer
                    else:
                        rr = r0 + outer
                        cc = k
                    if tg.code[rr, cc] != UNDECIDED:
                        continue
                    p = unwrap(diamond(g.xs[cc] - eye.ex, g.ys[rr] - eye.ey), q)
                    if p < plo or p >= phi:
                        continue
                    tg.code[rr, cc] = BLOCKED
                    n_lb += 1
            a = b + 1
            continue
        _fill(g, eye, q, rn, lo, a - lo, b + 1 - lo, buf, rules.kc)
        if tg.own:
            for k in range(a - lo, top - lo + 1):
                p = buf[1, outer, k]
                if p < plo or p >= phi:
                    continue
                if vertical:
                    rr = lo + k
                    cc = c0 + outer
                else:
                    rr = r0 + outer
                    cc = lo + k
                if tg.code[rr, cc] == NOT_TARGET:
                    continue
                dist = buf[2, outer, k]
                if dist > rules.dmax:
                    tg.code[rr, cc] = NOT_TARGET
                    continue
                nt = np.float64(g.z[rr, cc]) + rules.ht - eye.ez
                # on the ground the target's slope is its sample's, bit for bit (z + 0.0 is z)
                st = buf[0, outer, k] if rules.ht == 0.0 else nt / dist - rules.kc * dist
                sl = _slot(p, bsz, glo)
                blocked, slack = _lb_blocks(w.lb, sl, st, dist, rules.e_h, rules.kc)
                if blocked:
                    tg.code[rr, cc] = BLOCKED
                    n_lb += 1
                    continue
                ub_clear = st - slack >= _ub_max(w, j, sl)
                if ub_clear and st - slack >= _last_ring_bound(buf, k, outer, (a - lo, b + 1 - lo), side, last):
                    # the bounds clear every ring before and the last one's cells: visible
                    tg.code[rr, cc] = VISIBLE
                    counts[4] += 1
                else:
                    tdx = g.xs[cc] - eye.ex
                    tdy = g.ys[rr] - eye.ey
                    res, how = _decide(g, eye, rules, w, j, dwin, (p, tdx, tdy, nt, dist, st, slack), sl,
                                       ub_clear)
                    tg.code[rr, cc] = res
                    counts[how] += 1
        a = b + 1
    return n_lb


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _block_line(code, vertical, line, a, top):
    """Mark BLOCKED the undecided samples a..top of column ``line`` (``vertical``) or row
    ``line``; returns how many."""
    n = 0
    if vertical:
        for rr in range(a, top + 1):
            v = code[rr, line]
            blk = v == UNDECIDED
            code[rr, line] = BLOCKED if blk else v
            n += blk
    else:
        row = code[line]
        for cc in range(a, top + 1):
            v = row[cc]
            blk = v == UNDECIDED
            row[cc] = BLOCKED if blk else v
            n += blk
    return n


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _sector(g, eye, rules, lay, tg, s, stats, stop):
    """The sweep of one sector (see :func:`sweep`), on views of its inputs and of its work
    arrays without reference counts (:func:`~terrainvis.core.surface.borrow`)."""
    nsec, b0, r1, jnear, jstop = lay
    nfin = (b0 << _level(jstop, r1)) // nsec
    blen = max(g.ys.shape[0], g.xs.shape[0]) + 2
    # the work arrays: the wedges' bounds and their refinement buffer; the sample buffers
    # of the two runs (slopes, pseudo-angles and distances of lines 0 and 1); the hidden
    # flags of their segments; per run its first cell, last cell and buffer start; the
    # targets decided by the lower bound, by the upper bound and the last rings' walk, by
    # block walks, left undecided, and by the upper bound and the last ring's bound
    w_own = Wedges(np.full(nfin + 2, -INF), np.full(nfin + 2, -INF), np.full(nfin + 2, -INF),
                   np.empty((jstop // BLOCK + 1, nfin + 2)), np.empty((NQUAD, nfin + 2)),
                   np.empty((jstop // (GROUP * BLOCK) + 1, nfin + 2)))
    tmp_own = np.empty((3, nfin + 2))
    buf_own = np.empty((2, 3, 2, blen))
    hidden_own = np.zeros((2, blen // SEG + 3), dtype=np.bool_)
    ranges_own = np.zeros((3, 2), dtype=np.int64)
    counts_own = np.zeros(5, dtype=np.int64)
    g = borrow_grid(g)
    tg = Targets(tg.own, borrow(tg.code), borrow(tg.tx), borrow(tg.ty), borrow(tg.tz), borrow(tg.tstart),
                 borrow(tg.torder), borrow(tg.tcode))
    w = Wedges(borrow(w_own.ubp), borrow(w_own.ubold), borrow(w_own.lb), borrow(w_own.hist),
               borrow(w_own.quads), borrow(w_own.grp))
    tmp = borrow(tmp_own)
    buf = borrow(buf_own)
    hidden = borrow(hidden_own)
    ranges = borrow(ranges_own)
    counts = borrow(counts_own)
    xs, ys = g.xs, g.ys
    ntg = tg.tx.shape[0]
    nr = ys.shape[0]
    nc = xs.shape[0]
    tolm = rules.tol + rules.marg
    kc = rules.kc
    diag = np.sqrt(rules.diag2)
    lim = (rules.r_excl, rules.r_lb, rules.e_h, tolm, kc, diag)
    q = s // (nsec // 4)
    n_lb = 0
    lev = 0
    bsz = b0
    n = b0 // nsec
    plo = s * 4.0 / nsec
    phi = (s + 1) * 4.0 / nsec
    for j in range(0, jstop + 1):
        if stopped(stop):
            break
        if j > 0 and j % BLOCK == 0:
            _close_block(w, j, n, r1)
        target_lev = _level(j, r1)
        while lev < target_lev:
            _refine(w, tmp, n)
            n *= 2
            bsz *= 2
            lev += 1
        glo = s * n - 1
        nloc = n + 2
        cur = w.quads[(j // QUAD) % NQUAD]
        if j % QUAD == 0:
            cur[:nloc] = -INF
        if j < 2:
            # no targets yet (the caller answers rings 0 and 1 exactly); the cells next to
            # the eye are always clipped edge by edge
            annulus_edges(g, eye, j, (glo, nloc, bsz), cur, w.lb, lim)
            continue
        dwin = (s, glo, bsz, b0, r1, nsec)
        plo_g = glo * 4.0 / bsz
        phi_g = (glo + nloc) * 4.0 / bsz
        dring = ring_distance(g, eye, j - 1)
        rel = 0.25 * rules.diag2 / (dring * dring) * (1.0 + RING_BOUND_REL)
        cells = j > jnear and rel <= 1.0  # cells bounded from their corners, segments tested
        pad_hi, pad_lo = curvature_pads(kc, rules.diag2, dring, rel, far_corner(g, eye, j))
        # what an upper bound of annulus j from its corners' slopes adds (see cell_bounds);
        # inf: none (near the eye, the last ring is walked)
        hi_slack = 2.0 * rules.e_h / dring + pad_hi
        last = (rel, hi_slack if cells and not g.has_nan else INF)
        runs = _cell_path(q, j, eye.re, eye.ce, nr, nc)
        for run in range(2):
            ranges[0, run] = 0
            ranges[1, run] = -1
        for run in range(2):
            rn = runs[run]
            if rn[4] <= 0:
                continue
            i0, i1 = _run_range(g, eye, q, rn, plo_g, phi_g)
            if i1 < i0:
                continue
            ranges[0, run] = i0
            ranges[1, run] = i1
            lo = _run_lo(rn, i0, i1)
            ranges[2, run] = lo
            n_lb += _run_segments(g, eye, rules, w, tg, rn, (j, q, i0, i1, lo, cells, plo, phi), dwin,
                                  buf[run], hidden[run], counts, last)
        # ---- decide the other targets whose box of rings <= j - 1 the bounds now cover
        if ntg > 0:
            key = s * (jstop + 2) + j
            for kk in range(tg.tstart[key], tg.tstart[key + 1]):
                t = tg.torder[kk]
                tdx = tg.tx[t] - eye.ex
                tdy = tg.ty[t] - eye.ey
                dist = np.sqrt(tdx * tdx + tdy * tdy)
                if dist > rules.dmax:
                    tg.tcode[t] = NOT_TARGET
                    continue
                p = unwrap(diamond(tdx, tdy), q)
                nt = tg.tz[t] - eye.ez
                sl = _slot(p, bsz, glo)
                st = nt / dist - kc * dist
                blocked, slack = _lb_blocks(w.lb, sl, st, dist, rules.e_h, kc)
                if blocked:
                    tg.tcode[t] = BLOCKED
                    n_lb += 1
                else:
                    # no bound of the last ring here
                    res, how = _decide(g, eye, rules, w, j, dwin, (p, tdx, tdy, nt, dist, st, slack), sl,
                                       st - slack >= _ub_max(w, j, sl))
                    tg.tcode[t] = res
                    counts[how] += 1
        # ---- add annulus j
        if not cells:
            annulus_edges(g, eye, j, (glo, nloc, bsz), cur, w.lb, lim)
            continue
        ann = (rel, hi_slack, (2.0 * rules.e_h + tolm) / dring + pad_lo, dring >= rules.r_lb)
        _add_cells(w, j, (glo, nloc, bsz * 0.25), ann, runs, ranges, buf, hidden)
    counts[0] += n_lb
    for k in range(5):
        stats[s, k] = counts[k]
    # the owners of the views are used last here, so they live until the sector is done
    keep_alive((w_own, tmp_own, buf_own, hidden_own, ranges_own, counts_own))

