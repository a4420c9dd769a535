"""Earth curvature and refraction in every visibility entry point.

The model (docs/visibility.md, "Earth curvature"): with ``k = curvature / (2 R)`` the sight
line between p and q must clear the surface raised by ``k d1 d2`` (d1, d2 the horizontal
distances to p and q), i.e. the clearance at parameter t is the flat one less
``k L**2 t (1 - t)``. References, independent of the engines:

* a numpy brute force: the flat clearance is linear between the crossings of the ground
  track with grid lines and diagonal lines (or TIN edges), so on each piece the curved
  clearance is convex; its minimum is found by a golden-section search on
  ``HeightGrid.height_at`` / ``TIN.height_at`` (no vertex formula);
* hand-worked cases: two towers over flat ground, the radio horizon of an observer;
* the pair engine against the viewshed sweep, the grid walk against the TIN clipper.

A small earth radius (a few km on grids a few km wide) makes the bulge large, so a wrong
bound or a missed interior minimum changes verdicts.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from conftest import shared_dem_120
from terrainvis import HeightGrid, TIN
from terrainvis.core.compiling import from_python
from terrainvis.core.sampling import sample_points
from terrainvis.core.synthetic import synthetic_terrain
from terrainvis.visibility import (
    clearance_tolerance,
    curvature_coefficient,
    line_of_sight,
    min_clearance,
    trim_length,
    viewshed,
    visibility_matrix,
)
from terrainvis.visibility.profile import clearance_profile, lowest_point
from terrainvis.visibility.viewsheds.sweep import _surface_at, _viewshed
from terrainvis.visibility.viewsheds import _bound_kernels, _geometry_kernels

# kernel-only kernels (no Python entry of their own: terrainvis.core.compiling.KERNEL_ONLY), called
# here through one made for them
unwrap = from_python(_geometry_kernels.unwrap)
diamond = from_python(_geometry_kernels.diamond)
curvature_pads = from_python(_bound_kernels.curvature_pads)
edge_update = from_python(_bound_kernels._edge_update)


# ----------------------------------------------------------------- brute force
def _golden_section_min(f, lo, hi, iters=100):
    """Minimum of convex functions f (vectorised over pieces [lo, hi]) by golden-section search."""
    invphi = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = lo.copy(), hi.copy()
    for _ in range(iters):
        c = b - invphi * (b - a)
        d = a + invphi * (b - a)
        left = f(c) < f(d)
        b = np.where(left, d, b)
        a = np.where(left, a, c)
    return np.minimum(f(a), f(b))


def _breakpoints(terrain, a, d, t0, t1):
    """Parameters in [t0, t1] where the ground track crosses a grid line or a diagonal line
    (a HeightGrid) or a TIN edge, plus t0 and t1."""
    ts = [np.array([t0, t1])]
    with np.errstate(divide="ignore", invalid="ignore"):
        if isinstance(terrain, HeightGrid):
            xs, ys = terrain.xs, terrain.ys
            if d[0] != 0:
                ts.append((xs - a[0]) / d[0])
            if d[1] != 0:
                ts.append((ys - a[1]) / d[1])
            X0, Y0 = np.meshgrid(xs[:-1], ys[:-1])
            WX, WY = np.meshgrid(np.diff(xs), np.diff(ys))
            den = d[0] / WX - d[1] / WY
            td = ((a[1] - Y0) / WY - (a[0] - X0) / WX) / den
            ts.append(td[np.isfinite(td)].ravel())
        else:
            e = np.concatenate([terrain.faces[:, [0, 1]], terrain.faces[:, [1, 2]], terrain.faces[:, [2, 0]]])
            P = terrain.vertices[e[:, 0], :2]
            E = terrain.vertices[e[:, 1], :2] - P
            den = d[0] * E[:, 1] - d[1] * E[:, 0]
            t = ((P[:, 0] - a[0]) * E[:, 1] - (P[:, 1] - a[1]) * E[:, 0]) / den
            s = ((P[:, 0] - a[0]) * d[1] - (P[:, 1] - a[1]) * d[0]) / den
            ts.append(t[np.isfinite(t) & (s >= -1e-12) & (s <= 1 + 1e-12)])
    t = np.unique(np.concatenate(ts))
    return t[(t >= t0) & (t <= t1)]


def brute_curved_min(terrain, a, b, curvature, earth_radius, end_radius=0.0):
    """Exact minimum clearance under curvature by brute force (see the module docstring)."""
    k = curvature / (2.0 * earth_radius)
    delta = trim_length(terrain)
    out = np.empty(a.shape[0])
    for i in range(a.shape[0]):
        d = b[i] - a[i]
        length = np.linalg.norm(d)
        lh = np.hypot(d[0], d[1])
        if length <= 2 * delta or (end_radius > 0 and lh <= 2 * end_radius):
            out[i] = np.inf
            continue
        t0 = delta / length if end_radius == 0 else max(delta / length, end_radius / lh)
        t = _breakpoints(terrain, a[i], d, t0, 1.0 - t0)

        def f(tt, i=i, d=d):
            p = a[i] + tt[:, None] * d
            return p[:, 2] - terrain.height_at(p[:, :2]) - k * lh * lh * tt * (1.0 - tt)

        pieces = _golden_section_min(f, t[:-1], t[1:]) if t.size > 1 else np.array([np.inf])
        out[i] = min(f(t).min(), pieces.min())
    return out


def _pairs(g, n=120, seed=1, offset=2.0):
    P = sample_points(g, 2 * n, seed=seed, offset=offset)
    return P[:n], P[n:]


def _mountains():
    # 2.4 km x 2.4 km, relief 700 m
    return synthetic_terrain("mountains", 80, seed=3)


# ----------------------------------------------------------------- hand-worked cases
@pytest.mark.parametrize("h, expect", [(1000.0, -250.0), (1300.0, 50.0)])
def test_hand_case_two_towers_over_flat_ground(h, expect):
    # flat ground 10 km long, towers h high at both ends, R = 10 km, curvature 1:
    # k = 1 / 20 km, the ground rises k * 5 km * 5 km = 1250 m midway under the sight line
    g = HeightGrid(np.zeros((3, 21)), dx=500.0, dy=500.0)
    a, b = np.array([[0.0, 500.0, h]]), np.array([[10_000.0, 500.0, h]])
    kw = {"curvature": 1.0, "earth_radius": 10_000.0}
    for surface in (g, g.to_tin()):
        assert min_clearance(surface, a, b, **kw)[0] == pytest.approx(expect, abs=1e-6)
        assert line_of_sight(surface, a, b, **kw)[0] == (expect > 0)
        assert line_of_sight(surface, b, a, **kw)[0] == (expect > 0)
        low = lowest_point(surface, a[0], b[0], **kw)
        assert low["clearance"] == pytest.approx(expect, abs=1e-6)
        assert (low["x"], low["y"], low["t"]) == pytest.approx((5000.0, 500.0, 0.5))
        assert low["bulge"] == pytest.approx(1250.0)
    # the same with half the coefficient is the same as twice the radius
    assert min_clearance(g, a, b, curvature=0.5, earth_radius=5_000.0)[0] == pytest.approx(expect, abs=1e-6)
    # a flat earth: the towers see each other over flat ground with clearance h
    assert min_clearance(g, a, b)[0] == pytest.approx(h)


def test_hand_case_standard_refraction_magnitudes():
    # ALGORITHMS.md section 4: with c = 0.85714 the earth drops 6.7 m at 10 km and 168 m at 50 km
    k = curvature_coefficient(0.85714)
    assert k * 10_000.0**2 == pytest.approx(6.72, abs=0.01)
    assert k * 50_000.0**2 == pytest.approx(168.0, abs=0.1)
    assert curvature_coefficient() == 0.0


def test_radio_horizon_of_an_observer():
    # flat ground, eye h above it, targets on the ground: the clearance along the sight
    # line to a target at distance D is (1 - t) (h - k D**2 t), so the target is visible
    # up to the horizon D = sqrt(h / k) (the trim moves that by a relative 1e-5 or so)
    n = 101
    g = HeightGrid(np.full((n, n), 250.0), dx=40.0, dy=40.0)
    R, h = 20_000.0, 20.0
    k = 1.0 / (2.0 * R)
    horizon = np.sqrt(h / k)  # 894 m
    obs = (2000.0, 2000.0)
    X, Y = np.meshgrid(g.xs, g.ys)
    D = np.hypot(X - obs[0], Y - obs[1])
    out, info = _viewshed(g, obs, observer_height=h, curvature=1.0, earth_radius=R)
    assert out[D < 0.99 * horizon].all() and not out[D > 1.01 * horizon].any()
    assert info["lb"] + info["ub"] + info["walk"] > 0.9 * info["targets"]
    # and on its TIN (the exact clipper) and through the pair engine, sample by sample
    np.testing.assert_array_equal(viewshed(g.to_tin(), obs, observer_height=h, at=g, curvature=1.0,
                                           earth_radius=R), out)
    np.testing.assert_array_equal(_pairwise(g, obs, h, 0.0, 1.0, R), out)
    # flat earth: everything visible
    assert viewshed(g, obs, observer_height=h).all()


# ----------------------------------------------------------------- against brute force
@pytest.mark.parametrize("R", [3_000.0, 30_000.0])
@pytest.mark.parametrize("name", ["mountains", "ridges", "rectilinear", "dem:green_mountains_vt"])
def test_min_clearance_matches_brute_force(name, R):
    if name == "mountains":
        g = _mountains()
    elif name == "ridges":
        g = synthetic_terrain("ridges", 60, seed=2)
    elif name == "rectilinear":
        rng = np.random.default_rng(7)
        base = synthetic_terrain("rough", 50, seed=1)
        g = HeightGrid.from_coords(base.z, np.cumsum(rng.uniform(5.0, 90.0, 50)) + 1000.0,
                                   np.cumsum(rng.uniform(10.0, 70.0, 50)))
    else:
        g = shared_dem_120(name[4:]).subsample(2)
    a, b = _pairs(g, 60)
    tol = clearance_tolerance(g)
    for c, r in ((1.0, 0.0), (0.85714, 0.0), (1.0, 2.5 * float(np.diff(g.xs).mean()))):
        ref = brute_curved_min(g, a, b, c, R, end_radius=r)
        got = min_clearance(g, a, b, curvature=c, earth_radius=R, end_radius=r)
        np.testing.assert_allclose(got, ref, rtol=0, atol=tol)
        # the walk's verdicts are those of its minima
        np.testing.assert_array_equal(line_of_sight(g, a, b, curvature=c, earth_radius=R, end_radius=r),
                                      got >= -tol)
    # the bulge matters here: the minima drop by metres against a flat earth
    assert (min_clearance(g, a, b) - min_clearance(g, a, b, curvature=1.0, earth_radius=R)).max() > 1.0


@pytest.mark.parametrize("R", [3_000.0, 30_000.0])
def test_tin_clipper_matches_brute_force(R):
    from simplifiers import simplify

    g = _mountains()
    tin = simplify(g, "greedy-insertion", 2)
    a, b = _pairs(g, 60, seed=5)
    tol = clearance_tolerance(tin)
    ref = brute_curved_min(tin, a, b, 1.0, R)
    got = min_clearance(tin, a, b, curvature=1.0, earth_radius=R)
    np.testing.assert_allclose(got, ref, rtol=0, atol=tol)
    np.testing.assert_array_equal(line_of_sight(tin, a, b, curvature=1.0, earth_radius=R), got >= -tol)
    # the grid walk and the clipper on the grid's own TIN: the same surface
    np.testing.assert_allclose(min_clearance(g.to_tin(), a, b, curvature=1.0, earth_radius=R),
                               min_clearance(g, a, b, curvature=1.0, earth_radius=R), rtol=0, atol=tol)


def test_profile_matches_min_clearance():
    g = _mountains()
    tin = g.to_tin()
    a, b = _pairs(g, 40, seed=9)
    for surface in (g, tin):
        tol = clearance_tolerance(surface)
        for R in (3_000.0, 6_378_137.0):
            exact = min_clearance(surface, a, b, curvature=1.0, earth_radius=R)
            low = [lowest_point(surface, a[i], b[i], curvature=1.0, earth_radius=R)["clearance"] for i in range(40)]
            np.testing.assert_allclose(low, exact, rtol=0, atol=tol)
    t, c = clearance_profile(g, a[0], b[0], curvature=1.0, earth_radius=3_000.0)
    assert (np.diff(t) > 0).all() and c.min() == pytest.approx(min_clearance(g, a[:1], b[:1], curvature=1.0,
                                                                             earth_radius=3_000.0)[0], abs=1e-6)


# ----------------------------------------------------------------- properties
def _int_grid(seed, rows=7, cols=9, dx=200.0, dy=300.0):
    rng = np.random.default_rng(seed)
    return HeightGrid(rng.integers(0, 120, size=(rows, cols)).astype(float), dx=dx, dy=dy)


_point = st.tuples(st.floats(0.0, 1600.0), st.floats(0.0, 1800.0), st.floats(-20.0, 200.0))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 30), _point, _point, st.sampled_from([0.5, 1.0]), st.sampled_from([1_000.0, 8_000.0]))
@example(0, (0.0, 0.0, 50.0), (1600.0, 1800.0, 60.0), 1.0, 1_000.0)
def test_symmetric_in_p_and_q(seed, p, q, c, R):
    g = _int_grid(seed)
    a = np.array([[p[0], p[1], g.height_at([p[:2]])[0] + p[2]]])
    b = np.array([[q[0], q[1], g.height_at([q[:2]])[0] + q[2]]])
    kw = {"curvature": c, "earth_radius": R}
    for surface in (g, g.to_tin()):
        assert min_clearance(surface, a, b, **kw).tobytes() == min_clearance(surface, b, a, **kw).tobytes()
        assert line_of_sight(surface, a, b, **kw)[0] == line_of_sight(surface, b, a, **kw)[0]


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 30), st.integers(-5000, 5000))
def test_more_curvature_never_shows_more(seed, shift):
    g = _int_grid(seed)
    a, b = _pairs(g, 30, seed=seed)
    m = [min_clearance(g, a, b, curvature=c, earth_radius=2_000.0) for c in (0.0, 0.5, 1.0)]
    tol = clearance_tolerance(g)
    assert (m[1] <= m[0] + tol).all() and (m[2] <= m[1] + tol).all()
    # a vertical shift of everything changes nothing
    g2 = HeightGrid(g.z + shift, dx=200.0, dy=300.0)
    a2, b2 = a + [0, 0, shift], b + [0, 0, shift]
    np.testing.assert_array_equal(line_of_sight(g, a, b, curvature=1.0, earth_radius=2_000.0),
                                  line_of_sight(g2, a2, b2, curvature=1.0, earth_radius=2_000.0))


# ----------------------------------------------------------------- curvature 0 is today's answer
def test_zero_curvature_is_bit_identical_to_before():
    import test_visibility as tv

    g, a, b = tv._golden_case()
    for R in (6_378_137.0, 1.0, 1e12):
        m = min_clearance(g, a, b, curvature=0.0, earth_radius=R)
        assert [float(v).hex() for v in m] == tv._GOLDEN_MIN_CLEARANCE
        assert line_of_sight(g, a, b, curvature=0, earth_radius=R).astype(int).tolist() == tv._GOLDEN_LOS
    # viewsheds computed before curvature existed (commit 97a8b91), as sha256 of np.packbits
    mount = synthetic_terrain("mountains", 150, seed=1)
    xmin, xmax, ymin, ymax = mount.extent
    golden = {(0.37, 0.61, 1.7): "9291d9e2ad970889d0415c7e", (0.5, 0.5, 10.0): "62701d790d452a970e5049df",
              (0.0, 0.0, 2.0): "c524014b5d89401818946ea8", (0.9, 0.2, 30.0): "f7e419d9de98e005bb136c31"}
    for (fx, fy, h), digest in golden.items():
        obs = (xmin + fx * (xmax - xmin), ymin + fy * (ymax - ymin))
        out = viewshed(mount, obs, observer_height=h, curvature=0.0, earth_radius=1000.0)
        assert hashlib.sha256(np.packbits(out).tobytes()).hexdigest()[:24] == digest, (fx, fy, h)
        # the invariant beside the golden bits: they are the pair engine's verdicts
        np.testing.assert_array_equal(out, _pairwise(mount, obs, h, 0.0, 0.0, 1.0))


# ----------------------------------------------------------------- viewsheds
def _pairwise(grid, obs, h_o, h_t, c, R, engine="grid"):
    """Per-target line_of_sight from the eye under curvature, the nearest sample visible."""
    X, Y = np.meshgrid(grid.xs, grid.ys)
    b = np.column_stack([X.ravel(), Y.ravel(), grid.z.ravel() + h_t])
    eye = np.array([obs[0], obs[1], _surface_at(grid, float(obs[0]), float(obs[1])) + h_o])
    a = np.repeat(eye[None, :], b.shape[0], axis=0)
    ref = line_of_sight(grid, a, b, engine=engine, curvature=c, earth_radius=R).reshape(grid.shape)
    ref[int(np.argmin(np.abs(grid.ys - obs[1]))), int(np.argmin(np.abs(grid.xs - obs[0])))] = True
    return ref


def _observers(g):
    xmin, xmax, ymin, ymax = g.extent
    rows, cols = g.shape
    return [(xmin + 0.37 * (xmax - xmin), ymin + 0.61 * (ymax - ymin)), (float(g.xs[cols // 2]), float(g.ys[rows // 3])),
            (xmin, ymin), (xmax, 0.5 * (ymin + ymax))]


@pytest.mark.parametrize("R", [2_500.0, 20_000.0, 6_378_137.0])
@pytest.mark.parametrize("kind", ["mountains", "ridges", "hills", "mesas"])
def test_viewshed_matches_the_pair_engine(kind, R):
    g = synthetic_terrain(kind, 70, seed=4)
    n_sweep = n_targets = 0
    changed = 0
    for obs in _observers(g):
        for h_o, h_t, c in ((1.7, 0.0, 0.85714), (25.0, 3.0, 1.0)):
            out, info = _viewshed(g, obs, observer_height=h_o, target_height=h_t, curvature=c, earth_radius=R)
            np.testing.assert_array_equal(out, _pairwise(g, obs, h_o, h_t, c, R), err_msg=f"{obs} {h_o} {c}")
            n_sweep += info["lb"] + info["ub"] + info["walk"]
            n_targets += info["targets"]
            changed += int((out != viewshed(g, obs, observer_height=h_o, target_height=h_t)).sum())
    assert n_sweep > 0.9 * n_targets  # the sweep decides, not the exact fallback
    if R < 1e5:
        assert changed > 0  # the bulge matters at this radius


def test_viewshed_on_real_dems_and_rectilinear_grids():
    rng = np.random.default_rng(11)
    base = synthetic_terrain("mountains", 50, seed=1)
    grids = [shared_dem_120("green_mountains_vt"), shared_dem_120("mount_st_helens_wa"),
             HeightGrid.from_coords(base.z, np.cumsum(rng.uniform(5.0, 60.0, 50)), np.cumsum(rng.uniform(10.0, 40.0, 50))),
             HeightGrid(base.z, dx=30.0, dy=30.0, origin=(560000.0, 5.1e6))]
    for g in grids:
        for obs in _observers(g)[:3]:
            for R in (5_000.0, 6_378_137.0):
                out = viewshed(g, obs, observer_height=10.0, curvature=1.0, earth_radius=R)
                np.testing.assert_array_equal(out, _pairwise(g, obs, 10.0, 0.0, 1.0, R))


def test_viewshed_at_other_targets_and_with_nodata():
    from simplifiers import simplify

    g = synthetic_terrain("ridges", 61, seed=9)
    coarse = simplify(g, "gls", 1)
    R = 4_000.0
    tol = clearance_tolerance(coarse)
    for obs in _observers(g)[:3]:
        out, info = _viewshed(coarse, obs, observer_height=5.0, at=g, curvature=1.0, earth_radius=R)
        assert info["lb"] + info["ub"] + info["walk"] > 0.5 * info["targets"]
        zt = coarse.height_on_grid(g.xs, g.ys)
        X, Y = np.meshgrid(g.xs, g.ys)
        b = np.column_stack([X.ravel(), Y.ravel(), zt.ravel()])
        eye = np.array([obs[0], obs[1], _surface_at(coarse, *obs) + 5.0])
        ref = (min_clearance(coarse, np.repeat(eye[None], b.shape[0], 0), b, curvature=1.0, earth_radius=R)
               >= -tol).reshape(g.shape)
        ref[int(np.argmin(np.abs(g.ys - obs[1]))), int(np.argmin(np.abs(g.xs - obs[0])))] = True
        np.testing.assert_array_equal(out, ref)
    # nodata: absent triangles do not block; the reference is the TIN clipper on grid.to_tin()
    z = synthetic_terrain("rough", 45, seed=8).z.copy()
    z[10:14, 20:27] = np.nan
    z[25, 25] = np.nan
    holey = HeightGrid(z, dx=30.0, dy=30.0)
    tin = holey.to_tin()
    tol = clearance_tolerance(holey)
    for obs in [(400.0, 700.0), (1000.0, 350.0)]:
        out = viewshed(holey, obs, observer_height=3.0, curvature=1.0, earth_radius=2_000.0)
        zt = tin.height_on_grid(holey.xs, holey.ys)
        ok = np.isfinite(zt).ravel()
        X, Y = np.meshgrid(holey.xs, holey.ys)
        b = np.column_stack([X.ravel(), Y.ravel(), zt.ravel()])[ok]
        eye = np.array([obs[0], obs[1], _surface_at(holey, *obs) + 3.0])
        ref = np.zeros(holey.z.size, bool)
        ref[ok] = min_clearance(tin, np.repeat(eye[None], b.shape[0], 0), b, curvature=1.0,
                                earth_radius=2_000.0) >= -tol
        ref = ref.reshape(holey.shape)
        ref[int(np.argmin(np.abs(holey.ys - obs[1]))), int(np.argmin(np.abs(holey.xs - obs[0])))] = True
        np.testing.assert_array_equal(out, ref)


def test_tin_viewshed_uses_the_exact_clipper():
    g = synthetic_terrain("mountains", 50, seed=2)
    tin = g.to_tin()
    tol = clearance_tolerance(g)
    for obs in _observers(g)[:3]:
        exact = viewshed(g, obs, observer_height=4.0, curvature=1.0, earth_radius=3_000.0)
        on_tin = viewshed(tin, obs, observer_height=4.0, at=g, curvature=1.0, earth_radius=3_000.0)
        # the same surface: they may differ only where the clearance is within rounding of -tol
        X, Y = np.meshgrid(g.xs, g.ys)
        b = np.column_stack([X.ravel(), Y.ravel(), g.z.ravel()])
        eye = np.array([obs[0], obs[1], _surface_at(g, *obs) + 4.0])
        mc = min_clearance(g, np.repeat(eye[None], b.shape[0], 0), b, curvature=1.0,
                           earth_radius=3_000.0).reshape(g.shape)
        differ = exact != on_tin
        assert np.all(np.abs(mc[differ] + tol) <= 0.01 * tol), differ.sum()


def test_visibility_matrix_equals_pairwise_line_of_sight():
    g = _mountains()
    P = sample_points(g, 40, seed=3, offset=3.0)
    ii, jj = np.triu_indices(40, 1)
    for surface in (g, g.to_tin()):
        m = visibility_matrix(surface, P, curvature=1.0, earth_radius=3_000.0)
        assert (m == m.T).all() and m.diagonal().all()
        np.testing.assert_array_equal(m[ii, jj], line_of_sight(surface, P[ii], P[jj], curvature=1.0,
                                                               earth_radius=3_000.0))
        assert m.sum() < visibility_matrix(surface, P).sum()


# ----------------------------------------------------------------- engines and bad input
def test_embree_refuses_curvature():
    g = _mountains()
    a, b = _pairs(g, 5)
    msg = "engine 'embree' cannot model earth curvature"
    with pytest.raises(ValueError, match=msg):
        line_of_sight(g, a, b, engine="embree", curvature=0.85714)
    with pytest.raises(ValueError, match=msg):
        visibility_matrix(g.to_tin(), a, engine="embree", curvature=1.0)
    with pytest.raises(ValueError, match=msg):
        viewshed(g, (100.0, 100.0), engine="embree", curvature=0.5)
    # a flat earth through Embree works as before, and "auto" on a TIN is exact under curvature
    assert line_of_sight(g, a, b, engine="embree", curvature=0.0).shape == (5,)
    tin = g.to_tin()
    tol = clearance_tolerance(tin)
    np.testing.assert_array_equal(line_of_sight(tin, a, b, curvature=1.0, earth_radius=3_000.0),
                                  min_clearance(tin, a, b, curvature=1.0, earth_radius=3_000.0) >= -tol)


def test_bad_curvature_input():
    g = _mountains()
    a, b = _pairs(g, 3)
    for fn in (lambda **kw: min_clearance(g, a, b, **kw), lambda **kw: line_of_sight(g, a, b, **kw),
               lambda **kw: visibility_matrix(g, a, **kw), lambda **kw: viewshed(g, (10.0, 10.0), **kw),
               lambda **kw: lowest_point(g, a[0], b[0], **kw)):
        with pytest.raises(ValueError, match="curvature must be finite and >= 0"):
            fn(curvature=-0.1)
        with pytest.raises(ValueError, match="curvature must be finite and >= 0"):
            fn(curvature=float("nan"))
        with pytest.raises(TypeError, match="curvature must be a real number"):
            fn(curvature="standard")
        with pytest.raises(ValueError, match="earth_radius must be finite and > 0"):
            fn(curvature=1.0, earth_radius=0.0)
        with pytest.raises(ValueError, match="earth_radius must be finite and > 0"):
            fn(earth_radius=-6e6)
        with pytest.raises(TypeError, match="earth_radius must be a real number"):
            fn(earth_radius=None)


# ----------------------------------------------------------------- the sweep's bounds
def _wedges(x, y, bsz):
    """Global wedge index of the directions (x, y) from the eye (pseudo-angles unwrapped
    around quadrant 0, as the sweep does)."""
    from terrainvis.visibility.viewsheds import _bound_kernels as bk
    from terrainvis.visibility.viewsheds import _geometry_kernels as geo

    p = np.array([unwrap(diamond(a, b), 0) for a, b in zip(x, y)])
    return np.floor(p * bsz / 4).astype(int)


def _cell_case(z, X0, Y0, w, h, ez, kc):
    """The far-cell bound of one cell (corner heights z (2, 2), lower-left corner (X0, Y0)
    relative to the eye) as the sweep computes it (no rounding terms): (ub, lb, glo, bsz)."""
    from terrainvis.core.surface import SurfaceGrid, no_pyramid
    from terrainvis.visibility.viewsheds import _bound_kernels as bk
    from terrainvis.visibility.viewsheds import _geometry_kernels as geo

    xs, ys = np.array([X0, X0 + w]), np.array([Y0, Y0 + h])
    zz = np.asarray(z, float)
    cmax, rmax = np.empty((1, 2), dtype=np.float32), np.empty((2, 1), dtype=np.float32)
    bk.strip_max(zz, cmax, rmax)
    pyr, off, nxl, ltop = no_pyramid()
    g = SurfaceGrid(zz, xs, ys, 1.0 / np.diff(xs), 1.0 / np.diff(ys), False, False, pyr, off, nxl, ltop, cmax, rmax)
    eye = geo.Eye(0, 0, 0.0, 0.0, ez)
    vals = [bk._sample_val(g, eye, r, c, 0, kc) for r, c in ((0, 0), (0, 1), (1, 0), (1, 1))]
    dring = np.hypot(max(X0, 0.0), 0.0 if Y0 <= 0.0 <= Y0 + h else min(abs(Y0), abs(Y0 + h)))
    diag2 = w * w + h * h
    rel = 0.25 * diag2 / dring**2 * (1.0 + 1e-12)
    pads = curvature_pads(kc, diag2, dring, rel, np.hypot(X0 + w, max(abs(Y0), abs(Y0 + h))))
    bsz = 1 << 14
    glo = -bsz // 2
    ub = np.full(2 * bsz, -np.inf)
    lb = np.full(2 * bsz, -np.inf)
    bk.cell_bounds(ub, lb, (glo, 2 * bsz, bsz * 0.25), (rel, pads[0], pads[1], True),
                    tuple(v[0] for v in vals), tuple(v[1] for v in vals))
    return ub, lb, glo, bsz


def _surface_points(z, X0, Y0, w, h, n, rng, boundary=False):
    if boundary:
        s = rng.random(n)
        side = rng.integers(0, 4, n)
        u = np.select([side == 0, side == 1, side == 2], [s, np.ones(n), s], np.zeros(n))
        v = np.select([side == 0, side == 1, side == 2], [np.zeros(n), s, np.ones(n)], s)
    else:
        u, v = rng.random(n), rng.random(n)
    zz = np.where(u >= v, z[0][0] + u * (z[0][1] - z[0][0]) + v * (z[1][1] - z[0][1]),
                  z[0][0] + v * (z[1][0] - z[0][0]) + u * (z[1][1] - z[1][0]))
    return X0 + u * w, Y0 + v * h, zz


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 10**6), st.sampled_from([1.0 / 5_000, 1.0 / 50_000, 0.85714 / (2 * 6_378_137.0)]))
@example(0, 1.0 / 5_000)
def test_far_cell_bounds_hold_under_curvature(seed, kc):
    """Every surface point of a cell lies under the cell's upper bound in its wedge, and
    every boundary point above its lower bound (the corrected slope s - k d)."""
    rng = np.random.default_rng(seed)
    w, h = rng.uniform(20.0, 60.0, 2)
    X0, Y0 = rng.uniform(90.0, 600.0), rng.uniform(-300.0, 300.0)
    z = rng.uniform(0.0, 300.0, (2, 2))
    ez = rng.uniform(0.0, 300.0)
    ub, lb, glo, bsz = _cell_case(z, X0, Y0, w, h, ez, kc)
    for boundary, bound in ((False, ub), (True, lb)):
        x, y, zz = _surface_points(z, X0, Y0, w, h, 4000, rng, boundary)
        d = np.hypot(x, y)
        sig = (zz - ez) / d - kc * d
        i = _wedges(x, y, bsz) - glo
        if boundary:
            assert (sig >= lb[i]).all()
        else:
            assert (sig <= ub[i]).all()


def test_far_cell_bound_covers_a_minimum_distance_inside_an_edge():
    # flat cell below the eye, the eye facing the middle of its near edge: the corrected
    # slope peaks there (the nearest point), above all four corners; the bound's curvature
    # pad covers it (without the pad the peak exceeds the bound by about 7e-4)
    z = np.zeros((2, 2))
    ub, lb, glo, bsz = _cell_case(z, 100.0, -30.0, 40.0, 60.0, 0.5, 1.0 / 5_000)
    y = np.linspace(-30.0, 30.0, 2001)
    x = np.full_like(y, 100.0)
    d = np.hypot(x, y)
    sig = -0.5 / d - d / 5_000
    assert (sig <= ub[_wedges(x, y, bsz) - glo]).all()
    corners = [-0.5 / np.hypot(100.0, 30.0) - np.hypot(100.0, 30.0) / 5_000]
    assert sig.max() > max(corners) + 5e-4  # the peak is well above the corners


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 10**6), st.sampled_from([1.0 / 2_000, 1.0 / 20_000]))
def test_edge_bounds_cover_the_triangles_beside_them(seed, kc):
    """Near the eye the sweep clips edges to wedges: each edge's upper bound, lowered by
    k (d_min - diagonal), still covers every point of the triangles beside it."""
    from terrainvis.visibility.viewsheds import _bound_kernels as bk
    from terrainvis.visibility.viewsheds import _geometry_kernels as geo

    rng = np.random.default_rng(seed)
    pts = rng.uniform(-40.0, 40.0, (3, 2))
    pts[:, 0] += rng.uniform(45.0, 150.0)  # a triangle beside the eye, not around it (x > 0)
    zs = rng.uniform(0.0, 50.0, 3)
    ez = rng.uniform(0.0, 50.0)
    diam = max(np.hypot(*(pts[i] - pts[j])) for i in range(3) for j in range(3))
    bsz = 1 << 12
    glo = -bsz // 2
    ub = np.full(2 * bsz, -np.inf)
    lb = np.full(2 * bsz, -np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        edge_update((pts[i, 0], pts[i, 1], zs[i]), (pts[j, 0], pts[j, 1], zs[j]), ez, (glo, 2 * bsz, bsz),
                    ub, lb, (0.0, 0.0, 0.0, 0.0, kc, diam))
    # points inside the triangle (barycentric)
    r = rng.random((4000, 3))
    r /= r.sum(axis=1, keepdims=True)
    xy = r @ pts
    zz = r @ zs
    d = np.hypot(xy[:, 0], xy[:, 1])
    sig = (zz - ez) / d - kc * d
    assert (sig <= ub[_wedges(xy[:, 0], xy[:, 1], bsz) - glo]).all()


def test_edge_bound_covers_a_peak_inside_the_triangle():
    # flat ground 10 m under the eye: along a ray the corrected slope -10/d - k d peaks at
    # d* = sqrt(10 / k) = 141 m, inside this triangle (its edges cross the rays near it at
    # 100 m and 200 m, where it is 0.0086 lower); the pad of one diameter covers the peak
    from terrainvis.visibility.viewsheds import _bound_kernels as bk
    from terrainvis.visibility.viewsheds import _geometry_kernels as geo

    kc = 1.0 / 2_000
    pts = np.array([[100.0, -50.0], [100.0, 50.0], [200.0, 0.0]])
    diam = 112.0  # >= the triangle's diameter (111.8 m)
    bsz = 1 << 12
    glo = -bsz // 2
    ub = np.full(2 * bsz, -np.inf)
    lb = np.full(2 * bsz, -np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        edge_update((pts[i, 0], pts[i, 1], 0.0), (pts[j, 0], pts[j, 1], 0.0), 10.0, (glo, 2 * bsz, bsz),
                    ub, lb, (0.0, 0.0, 0.0, 0.0, kc, diam))
    x = np.linspace(100.0, 199.0, 991)
    y = np.zeros_like(x)
    sig = -10.0 / x - kc * x
    assert sig.max() > max(sig[0], sig[-1]) + 0.008
    assert (sig <= ub[_wedges(x, y, bsz) - glo]).all()
