"""One walk: every consumer of a sight line's ground track visits the same breakpoints.

The breakpoints of a track over a grid are the ends of its tested interval and its
crossings of grid lines and cell diagonals (``terrainvis.visibility.walk``). Here, on
random tracks over random grids (uniform and rectilinear, flat earth and curved, with and
without an end radius):

* the shared cursor's breakpoints are exactly (bit for bit) the crossings computed
  independently, in Python, from the grid's lines and diagonals;
* visopt records exactly those breakpoints;
* the threshold engine's cell walk is exactly the largest value over them (flat), its
  pyramid descent agrees, and so does the threshold on the grid's TIN;
* the pair engine's exact clearance (grid and TIN) and the viewshed sweep's walks (with
  and without nodata) are the least clearance over them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import terrainvis as tv
from simplifiers import _visopt_kernels
from terrainvis.core.compiling import from_python
from terrainvis.core.surface import cell_height
from terrainvis.visibility import _kernels as pk
from terrainvis.visibility.viewsheds import _walk_kernels as wk
from terrainvis.visibility import _threshold_kernels as tk
from terrainvis.visibility import thresholds
from terrainvis.visibility.walk import cell_diagonal, cells_next, cells_start

# kernel-only kernels (no Python entry of their own: terrainvis.core.compiling.KERNEL_ONLY), called
# here through one made for them
cell_height = from_python(cell_height)
cell_diagonal = from_python(cell_diagonal)
cells_next = from_python(cells_next)
cells_start = from_python(cells_start)
canonical = from_python(pk._canonical)
interval_start = from_python(pk.interval_start)
new_stack = from_python(pk.new_stack)
curved_min = from_python(pk.curved_min)
grid_threshold = from_python(tk.grid_threshold)
grid_max_slope = from_python(tk.grid_max_slope)
tin_threshold = from_python(tk.tin_threshold)
track = from_python(_visopt_kernels._track)

EARTH = 6378137.0 / 400.0  # a small earth: a bulge of metres on these grids


def _grid(seed, rows, cols, rectilinear, scale=1.0):
    rng = np.random.default_rng(seed)
    if rectilinear:
        xs = np.concatenate([[0.0], np.cumsum(rng.uniform(0.3, 3.0, cols - 1))]) * scale
        ys = np.concatenate([[0.0], np.cumsum(rng.uniform(0.3, 3.0, rows - 1))]) * scale
    else:
        xs = np.arange(cols) * 1.5 * scale
        ys = np.arange(rows) * 1.0 * scale
    z = rng.normal(0.0, 2.0, (rows, cols))
    return tv.HeightGrid.from_coords(z, xs, ys)


def _line_crossings(g, seg, t0, t1):
    """The ends and the grid-line crossings in [t0, t1], each computed as the walk defines it, in Python."""
    ax, ay, dx, dy = seg
    out = {t0, t1}
    with np.errstate(over="ignore"):
        return {t for t in out | _crossings(g.xs, ax, dx) | _crossings(g.ys, ay, dy) if t0 <= t <= t1}


def _crossings(lines, a, d):
    return {(v - a) / d for v in lines} if d != 0.0 else set()


def _diagonal_crossings(g, seg, t0, t1):
    """{t: cell} of the diagonal crossings inside the cells the track passes through (not
    along a grid line), in Python, well inside the track's piece of the cell."""
    ax, ay, dx, dy = seg
    xs, ys = g.xs, g.ys
    ixw, iyw = 1.0 / np.diff(xs), 1.0 / np.diff(ys)
    out = {}
    for r in range(ys.size - 1):
        for c in range(xs.size - 1):
            lo, hi = t0, t1
            for a_, d_, v0, v1 in ((ax, dx, xs[c], xs[c + 1]), (ay, dy, ys[r], ys[r + 1])):
                if d_ == 0.0:
                    if not v0 < a_ < v1:
                        lo, hi = 1.0, 0.0
                    continue
                with np.errstate(over="ignore"):
                    e0, e1 = sorted(((v0 - a_) / d_, (v1 - a_) / d_))
                lo, hi = max(lo, e0), min(hi, e1)
            den = dx * ixw[c] - dy * iyw[r]
            if hi <= lo or den == 0.0:
                continue
            t = ((ay - ys[r]) * iyw[r] - (ax - xs[c]) * ixw[c]) / den
            if lo + 1e-9 < t < hi - 1e-9:
                out[t] = (r, c)
    return out


def _walk(g, seg, t0, t1):
    """The cursor's pieces: [(r, c, t, tn, td)], td the diagonal crossing inside or None."""
    xs, ys = np.asarray(g.xs - g.xs[0]), np.asarray(g.ys - g.ys[0])
    ixw, iyw = 1.0 / np.diff(xs), 1.0 / np.diff(ys)
    cur = cells_start(xs, ys, ixw, iyw, bool(g.is_uniform), seg, t0, t1)
    pieces = []
    while True:
        td = cell_diagonal(xs, ys, ixw, iyw, cur.r, cur.c, seg)
        pieces.append((cur.r, cur.c, cur.t, cur.tn, td if cur.t < td < cur.tn else None))
        if cur.tn >= t1:
            break
        cur = cells_next(xs, ys, cur, seg, t1)
        if cur.r < 0:
            break
        assert len(pieces) <= 4 * (xs.size + ys.size) + 8
    return pieces


def _breakpoints(pieces):
    out = [pieces[0][2]]
    for _, _, _, tn, td in pieces:
        if td is not None:
            out.append(td)
        out.append(tn)
    return out


def _height(g, r, c, t, seg):
    ax, ay, dx, dy = seg
    xs, ys = np.asarray(g.xs), np.asarray(g.ys)
    return cell_height(np.asarray(g.z), xs, ys, 1.0 / np.diff(xs), 1.0 / np.diff(ys), r, c, ax + t * dx, ay + t * dy)


def _track_case(data, g):
    """A random segment a -> b (3-D, local coordinates) inside the grid, on or off grid lines."""
    xmax, ymax = float(g.xs[-1]), float(g.ys[-1])

    def coord(hi, lines):
        return data.draw(st.one_of(st.floats(0.0, hi), st.sampled_from([float(v) for v in lines])))

    a = (coord(xmax, g.xs), coord(ymax, g.ys), data.draw(st.floats(-3.0, 8.0)))
    b = (coord(xmax, g.xs), coord(ymax, g.ys), data.draw(st.floats(-3.0, 8.0)))
    return a, b


CASES = st.tuples(st.integers(0, 2**31), st.integers(2, 9), st.integers(2, 9), st.booleans())


@settings(max_examples=150, deadline=None)
@given(CASES, st.sampled_from([0.0, 0.7]), st.data())
def test_the_cursor_visits_exactly_the_crossings(case, end_radius, data):
    g = _grid(*case)
    a, b = _track_case(data, g)
    seg6, length = canonical(a, b)
    t0 = interval_start(seg6, length, 1e-6, end_radius)
    if t0 < 0.0:
        return
    seg = (seg6[0], seg6[1], seg6[3], seg6[4])
    pieces = _walk(g, seg, t0, 1.0 - t0)
    got = _breakpoints(pieces)
    assert got == sorted(got)  # in order along the track
    lines = _line_crossings(g, seg, t0, 1.0 - t0)
    assert lines <= set(got)  # every end and grid-line crossing, bit for bit
    diagonals = _diagonal_crossings(g, seg, t0, 1.0 - t0)
    walked = {td: (r, c) for r, c, _, _, td in pieces if td is not None}
    for t, cell in diagonals.items():  # every diagonal crossing inside a cell, in that cell
        assert walked.get(t) == cell
    assert set(got) <= lines | set(walked)  # and nothing else


@settings(max_examples=100, deadline=None)
@given(CASES, st.data())
def test_visopt_records_the_cursors_breakpoints(case, data):
    from simplifiers import _visopt_kernels as vk

    g = _grid(*case)
    a, b = _track_case(data, g)
    xs, ys = np.asarray(g.xs), np.asarray(g.ys)
    axes = (xs, ys, 1.0 / np.diff(xs), 1.0 / np.diff(ys))
    u0, u1 = thresholds.interval(b[0], b[1], b[2], a[0], a[1], a[2], 1e-6, 0.0)
    if u0 < 0.0:
        return
    n = track(axes, a[0], a[1], b[0], b[1], u0, u1, 0, False, (np.empty(0), np.empty(0, np.int32),
                                                                    np.empty(0), np.empty(0)))
    bu, btri, ba, bb = np.empty(n), np.empty(n, np.int32), np.empty(n), np.empty(n)
    track(axes, a[0], a[1], b[0], b[1], u0, u1, 0, True, (bu, btri, ba, bb))
    seg = (a[0], a[1], b[0] - a[0], b[1] - a[1])
    assert bu.tolist() == _breakpoints(_walk(g, seg, u0, u1))


def _threshold_reference(g, q, p, tol, delta, end_radius):
    """qz + the largest (s(u) - tol - qz) / u over the cursor's breakpoints (flat earth), in Python."""
    u0, u1 = thresholds.interval(p[0], p[1], p[2], q[0], q[1], q[2], delta, end_radius)
    if u0 < 0.0:
        return -np.inf
    seg = (q[0], q[1], p[0] - q[0], p[1] - q[1])
    best = -np.inf
    for i, (r, c, t, tn, td) in enumerate(_walk(g, seg, u0, u1)):
        for u in ([t] if i == 0 else []) + ([td] if td is not None else []) + [tn]:
            best = max(best, (_height(g, r, c, u, seg) - tol - q[2]) / u)
    return q[2] + best


@settings(max_examples=80, deadline=None)
@given(CASES, st.sampled_from([0.0, 0.7]), st.booleans(), st.data())
def test_thresholds_are_the_largest_value_over_the_breakpoints(case, end_radius, curved, data):
    g = _grid(*case)
    a, b = _track_case(data, g)
    surf = thresholds.ThresholdSurface(g)
    assert surf.x0 == 0.0 and surf.y0 == 0.0
    kc = tv.visibility.curvature_coefficient(0.85714, EARTH) if curved else 0.0
    rules = surf.rules(end_radius=end_radius, kc=kc)
    dda = grid_threshold(surf.data, new_stack(surf.ltop), a, b, rules)  # small grids: the cell walk
    if not curved:
        assert dda == _threshold_reference(g, b, a, surf.tol, surf.delta, end_radius)
    u0, u1 = thresholds.interval(a[0], a[1], a[2], b[0], b[1], b[2], surf.delta, end_radius)
    if u0 < 0.0:
        assert dda == -np.inf
        return
    tr = tk.Track(b[0], b[1], b[2], a[0] - b[0], a[1] - b[1], u0, u1, surf.tol,
                  kc * ((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2), -np.inf, np.inf)
    # the pyramid descent over the same grid (forced: these grids are small) and the TIN of the grid
    desc = b[2] + grid_max_slope(surf.data, tr, new_stack(surf.ltop))
    scale = 1.0 + abs(dda)
    assert desc == pytest.approx(dda, abs=1e-9 * scale)
    tin = thresholds.ThresholdSurface(g.to_tin())
    on_tin = tin_threshold(tin.data, None, (a[0] - tin.x0, a[1] - tin.y0, a[2]), (b[0] - tin.x0, b[1] - tin.y0, b[2]),
                              rules)
    assert on_tin == pytest.approx(dda, abs=1e-7 * scale)



@pytest.mark.parametrize("offset", [2.225073858507e-311, 5e-324, 1e-160, 1e-300])
@pytest.mark.parametrize("at", [(0.0, 0.0), (1.5, 0.0), (0.7, 0.3)])
def test_a_track_too_short_to_walk_is_one_ground_point_on_a_tin_too(offset, at):
    """Found by the property above: a track whose horizontal length squares to zero (a
    subnormal offset) got stuck in the TIN walk before its far end, -41520 against 0.25."""
    g = _grid(0, 2, 2, False)
    a, b = (at[0], at[1] + offset, 0.0), (at[0], at[1], 1.0)
    surf = thresholds.ThresholdSurface(g)
    rules = surf.rules(end_radius=0.0, kc=0.0)
    dda = grid_threshold(surf.data, new_stack(surf.ltop), a, b, rules)
    assert dda == _threshold_reference(g, b, a, surf.tol, surf.delta, 0.0)
    tin = thresholds.ThresholdSurface(g.to_tin())
    on_tin = tin_threshold(tin.data, None, (a[0] - tin.x0, a[1] - tin.y0, a[2]), (b[0] - tin.x0, b[1] - tin.y0, b[2]),
                              rules)
    assert on_tin == pytest.approx(dda, abs=1e-9)


def _clearance_reference(g, seg6, t0, t1, bulge):
    """The least clearance over the cursor's breakpoints (and, curved, inside each piece)."""
    ax, ay, az, dx, dy, dz = seg6
    seg = (ax, ay, dx, dy)
    best = math.inf
    for r, c, t, tn, td in _walk(g, seg, t0, t1):
        us = [t] + ([td] if td is not None else []) + [tn]
        f = [az + u * dz - _height(g, r, c, u, seg) for u in us]
        for k in range(len(us) - 1):
            best = min(best, curved_min(f[k], f[k + 1], us[k], us[k + 1], bulge))
    return best


@settings(max_examples=80, deadline=None)
@given(CASES, st.sampled_from([0.0, 0.7]), st.booleans(), st.booleans(), st.data())
def test_the_least_clearance_is_over_the_breakpoints(case, end_radius, curved, nodata, data):
    g = _grid(*case)
    a, b = _track_case(data, g)
    curve = {"curvature": 0.85714, "earth_radius": EARTH} if curved else {}
    kc = tv.visibility.curvature_coefficient(**curve) if curved else 0.0
    delta = tv.visibility.trim_length(g)
    seg6, length = canonical(a, b)
    t0 = interval_start(seg6, length, delta, end_radius)
    got = tv.min_clearance(g, np.array([a]), np.array([b]), end_radius=end_radius, **curve)[0]
    if t0 < 0.0:
        assert got == np.inf
        return
    bulge = kc * (seg6[3] ** 2 + seg6[4] ** 2)
    want = _clearance_reference(g, seg6, t0, 1.0 - t0, bulge)
    scale = 1.0 + float(np.abs(g.z).max()) + abs(a[2]) + abs(b[2])
    assert got == pytest.approx(want, abs=1e-9 * scale)
    on_tin = tv.min_clearance(g.to_tin(), np.array([a]), np.array([b]), end_radius=end_radius, **curve)[0]
    assert on_tin == pytest.approx(want, abs=1e-7 * scale)
    # the viewshed sweep's two exact walks: along the edges (no nodata) and cell by cell (nodata)
    sg = _sweep_grid(g, nodata)
    walked = wk.walk_min(sg, seg6, t0, 1.0 - t0, -np.inf, bulge)
    assert walked == pytest.approx(want, abs=1e-9 * scale)


def _sweep_grid(g, nodata):
    from terrainvis.core.surface import SurfaceGrid, no_pyramid

    xs, ys = np.asarray(g.xs), np.asarray(g.ys)
    pyr, off, nxl, ltop = no_pyramid()
    cmax, rmax = np.empty((0, 0), dtype=np.float32), np.empty((0, 0), dtype=np.float32)
    # has_nan True sends the walk cell by cell (the nodata path) over the same heights
    return SurfaceGrid(np.asarray(g.z), xs, ys, 1.0 / np.diff(xs), 1.0 / np.diff(ys), bool(g.is_uniform), nodata,
                       pyr, off, nxl, ltop, cmax, rmax)
