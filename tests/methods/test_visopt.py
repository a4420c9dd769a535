"""The visibility-optimized regular simplifier (simplifiers.visopt, issue 18 item 3).

References: the coordinate-descent step against a brute-force scan of one coarse
height with the exact grid LOS engine; the breakpoint verdicts against the engine;
GLS's grid where the method must not move (rounds 0, trust 0, constant terrain).
"""

from __future__ import annotations

import numpy as np
import pytest

import simplifiers
import terrainvis as tv
from simplifiers import _visopt_kernels as vk
from simplifiers import visopt as vo
from terrainvis import HeightGrid, synthetic_terrain
from terrainvis.core.compiling import from_python
from terrainvis.relocation.calibrated import MARGIN_REL
from terrainvis.errors import NodataError
from terrainvis.visibility import clearance_tolerance, terrain_scale

# kernel-only kernels (no Python entry of their own: terrainvis.core.compiling.KERNEL_ONLY), called
# here through one made for them
vertex_intervals = from_python(vk.vertex_intervals)
best_value = from_python(vk.best_value)


@pytest.fixture(scope="module")
def descent_case():
    """A 17x17 terrain at level 2 (5x5), 24 points standing at arbitrary heights above S0."""
    T = synthetic_terrain("rough", size=17, seed=3)
    S0 = vo.start_grid(T, 2)
    n = 24
    W = tv.sample_points(T, n, seed=7)
    vt_full = tv.visibility_matrix(T, W)
    p = np.column_stack([W[:, 0] - S0.xs[0], W[:, 1] - S0.ys[0], S0.height_at(W[:, :2])])
    pairs = vo._Pairs(S0, p, n, 1 << 30, np.random.default_rng(0))
    ev = np.empty((n, 3), dtype=np.int64)
    ew = np.empty((n, 3))
    vk.barycentric(pairs.xs, pairs.ys, p[:, 0].copy(), p[:, 1].copy(), ev, ew)
    d = np.random.default_rng(5).normal(0.0, 2.0, n)
    return T, S0, W, pairs, vt_full[pairs.ii, pairs.jj], ev, ew, d


def _engine_agreement(S0, W, pairs, vt, ev, ew, d, c):
    """Agreement of the pairs on the grid of heights c (flat), points riding d above it: the LOS engine."""
    G = HeightGrid.from_coords(c.reshape(S0.shape), S0.xs, S0.ys)
    P = np.column_stack([W[:, :2], d + (c[ev] * ew).sum(axis=1)])
    return int((tv.line_of_sight(G, P[pairs.ii], P[pairs.jj], engine="grid") == vt).sum())


def test_all_pairs_kept_and_breakpoint_verdicts_match_the_engine(descent_case):
    T, S0, W, pairs, vt, ev, ew, d = descent_case
    assert pairs.ii.size == pairs.n_pairs_all == 24 * 23 // 2
    c = S0.z.ravel().copy()
    z = d + (c[ev] * ew).sum(axis=1)
    P = np.column_stack([W[:, :2], z])
    engine = tv.line_of_sight(S0, P[pairs.ii], P[pairs.jj], engine="grid")
    np.testing.assert_array_equal(pairs.visible(c, z, clearance_tolerance(S0)), engine)
    assert 0 < engine.sum() < engine.size  # both verdicts occur: the comparison means something


@pytest.mark.parametrize("v", [2, 7, 11, 12, 17])
def test_descent_step_is_the_best_value_of_a_brute_force_scan(descent_case, v):
    """The value best_value picks for one coarse height agrees with as many pairs as the
    best of 801 heights scanned with the exact LOS engine, and the count it reports is
    the engine's count on the pairs that touch the vertex."""
    T, S0, W, pairs, vt, ev, ew, d = descent_case
    c = S0.z.ravel().copy()
    tol = clearance_tolerance(S0)
    margin = MARGIN_REL * terrain_scale(S0)
    mx = int(np.diff(pairs.vptr).max())
    lo, hi, vis = np.empty(mx), np.empty(mx), np.empty(mx, dtype=bool)
    m = vertex_intervals(v, c, vk.Riders(d, ev, ew), pairs.tracks, tol, lo, hi)
    touching = pairs.items[pairs.vptr[v]:pairs.vptr[v + 1]]
    vis[:m] = vt[touching]
    R = 30.0
    x, score = best_value(lo, hi, vis, m, c[v], c[v] - R, c[v] + R, margin, np.empty(2 * mx), np.empty(2 * mx))
    assert c[v] - R <= x <= c[v] + R

    def agree(value):
        cc = c.copy()
        cc[v] = value
        return _engine_agreement(S0, W, pairs, vt, ev, ew, d, cc)

    others = np.setdiff1d(np.arange(pairs.ii.size), touching)
    zc = d + (c[ev] * ew).sum(axis=1)
    P = np.column_stack([W[:, :2], zc])
    fixed = int((tv.line_of_sight(S0, P[pairs.ii[others]], P[pairs.jj[others]], engine="grid") == vt[others]).sum())
    chosen = agree(x)
    assert chosen == fixed + score
    scan = max(agree(value) for value in np.linspace(c[v] - R, c[v] + R, 801))
    assert chosen >= scan
    assert chosen >= agree(c[v])


def test_best_value_hand_worked():
    # three pairs: seen on T in [0, 1] and [0.5, 2]; unseen on T, seen on S in [1.5, 3]
    lo = np.array([0.0, 0.5, 1.5])
    hi = np.array([1.0, 2.0, 3.0])
    vis = np.array([True, True, False])
    pos, dl = np.empty(6), np.empty(6)
    x, score = best_value(lo, hi, vis, 3, -5.0, -10.0, 10.0, 1e-6, pos, dl)
    assert score == 3 and 0.5 < x < 1.0 and x == pytest.approx(0.5, abs=1e-5)  # nearest to -5 in (0.5, 1)
    x, score = best_value(lo, hi, vis, 3, 0.7, -10.0, 10.0, 1e-6, pos, dl)
    assert (x, score) == (0.7, 3)  # already optimal: it stays
    # the trust region excludes (0.5, 1): at -5 only the unseen pair agrees, in (0, 0.2] also the first
    x, score = best_value(lo, hi, vis, 3, -5.0, -10.0, 0.2, 1e-6, pos, dl)
    assert score == 2 and x == pytest.approx(1e-6, abs=1e-12)
    x, score = best_value(lo, hi, vis, 3, 0.1, -10.0, 0.2, 1e-6, pos, dl)
    assert (x, score) == (0.1, 2)  # a tie never moves the height
    x, score = best_value(lo, hi, vis, 3, 2.5, -10.0, 10.0, 1e-6, pos, dl)
    assert score == 3 and x == pytest.approx(1.0 - 1e-6)


def test_training_agreement_never_decreases():
    T = synthetic_terrain("ridges", size=33, seed=2)
    S, info = vo.optimize(T, 2, n_train=80, rounds=4, seed=1)
    hist = info["history"]
    assert len(hist) == 4
    assert hist[0][1] > hist[0][0]  # the first descent gains
    for (a0, a1, _), (b0, _, _) in zip(hist, hist[1:] + [(1.0, 1.0, 0)]):
        assert a1 >= a0
        assert b0 >= a1
    # the exact engine on the result, the points at their final heights: the descent's gain is real
    # there too. The model differs from the engine only where a sight line's trim decides it (the
    # breakpoints keep the trim of the start heights; the engine trims by the current 3-D length):
    # measured, 1 pair of 3160 here (a short pair with one end 1.2 cm below the surface).
    W, z = info["train"], info["heights"]
    VT = tv.visibility_matrix(T, W)
    iu = np.triu_indices(W.shape[0], 1)
    V = tv.visibility_matrix(S, np.column_stack([W[:, :2], z]))
    S0 = info["start"]
    z0 = tv.relocate(np.column_stack([W[:, :2], S0.height_at(W[:, :2])]), S0, "full")[:, 2]
    V0 = tv.visibility_matrix(S0, np.column_stack([W[:, :2], z0]))
    engine_end, engine_start = float((V[iu] == VT[iu]).mean()), float((V0[iu] == VT[iu]).mean())
    assert engine_end > engine_start + 0.01
    assert abs(engine_end - hist[-1][1]) <= 2 / iu[0].size


def test_result_sits_at_the_coarse_positions_and_moves_within_the_trust_region():
    T = synthetic_terrain("mesas", size=33, seed=4)
    S, info = vo.optimize(T, 2, n_train=60, seed=0)
    G = simplifiers.simplify(T, "gls", 2)
    np.testing.assert_array_equal(S.xs, G.xs)
    np.testing.assert_array_equal(S.ys, G.ys)
    np.testing.assert_array_equal(info["start"].z, G.z)
    moved = np.abs(S.z - G.z).ravel()
    assert (moved <= info["radius"] + 1e-9).all()
    assert (moved > 0).any()
    # the radius: the largest |T - S0| over the fine samples each vertex's triangles cover
    X, Y = np.meshgrid(T.xs, T.ys)
    err = np.abs(T.z - G.height_at(np.column_stack([X.ravel(), Y.ravel()])).reshape(T.shape))
    r, c = 2, 3  # an interior coarse vertex: its support is the fine samples within one coarse cell
    ys, xs = G.ys, G.xs
    inside = (X > xs[c - 1]) & (X < xs[c + 1]) & (Y > ys[r - 1]) & (Y < ys[r + 1])
    du = (X - xs[c]) / np.where(X >= xs[c], xs[c + 1] - xs[c], xs[c] - xs[c - 1])
    dv = (Y - ys[r]) / np.where(Y >= ys[r], ys[r + 1] - ys[r], ys[r] - ys[r - 1])
    # the hexagon of the six triangles around (r, c) with the diagonal convention of the grid
    hexagon = inside & (np.abs(du - dv) < 1.0)
    assert info["radius"][r * G.shape[1] + c] == pytest.approx(err[hexagon].max(), rel=1e-12)


def test_nothing_moves_where_it_must_not():
    T = synthetic_terrain("hills", size=33, seed=1)
    G = simplifiers.simplify(T, "gls", 2)
    np.testing.assert_array_equal(vo.visopt(T, 2, n_train=40, rounds=0).z, G.z)
    np.testing.assert_array_equal(vo.visopt(T, 2, n_train=40, trust=0.0).z, G.z)
    flat = HeightGrid(np.full((17, 17), 12.5), dx=10.0)
    out, info = vo.optimize(flat, 2, n_train=30)
    # GLS reproduces a constant up to rounding (4e-15 here); nothing moves beyond that
    np.testing.assert_allclose(out.z, 12.5, rtol=0, atol=1e-12)
    assert (np.abs(out.z - info["start"].z).ravel() <= info["radius"]).all() and info["radius"].max() < 1e-12
    same = vo.visopt(T, 0, n_train=40)
    np.testing.assert_array_equal(same.z, T.z)
    assert same is not T
    tiny = HeightGrid([[0.0, 3.0, 1.0], [2.0, 9.0, 1.0], [0.0, 1.0, 4.0]])
    out = vo.visopt(tiny, 1, n_train=10)
    assert out.shape == (2, 2) and np.isfinite(out.z).all()


def test_deterministic_for_a_seed():
    T = synthetic_terrain("rough", size=33, seed=6)
    a = vo.visopt(T, 2, n_train=60, seed=3)
    b = vo.visopt(T, 2, n_train=60, seed=3)
    np.testing.assert_array_equal(a.z, b.z)
    c = vo.visopt(T, 2, n_train=60, seed=4)
    assert not np.array_equal(a.z, c.z)


def test_pair_budget_keeps_a_subset():
    T = synthetic_terrain("hills", size=33, seed=1)
    _, full = vo.optimize(T, 1, n_train=50, rounds=1)
    _, part = vo.optimize(T, 1, n_train=50, rounds=1, max_breakpoints=full["breakpoints"] // 3)
    assert full["pairs_kept"] == full["pairs"] == 50 * 49 // 2
    assert part["pairs"] == full["pairs"] and 0 < part["pairs_kept"] < full["pairs"] // 2
    assert part["breakpoints"] <= full["breakpoints"] // 3


def test_held_out_points_gain_over_the_start():
    """Points never seen in training, relocated with the production calibrated relocation,
    keep more verdicts on visopt's grid than on GLS's (its start). Measured on this case
    (mountains, seed 21, 60x60, level 2, 300 training points, 300 held-out points): 95.64
    against 95.84 %; on four other kinds at the same settings the gain was -0.05 to +0.16
    points (docs/visopt.md), so this is one fixed case, asserted with half its margin."""
    T = synthetic_terrain("mountains", size=60, seed=21)
    S, info = vo.optimize(T, 2, n_train=300, seed=0)
    P = tv.sample_points(T, 300, seed=1000)
    VT = tv.visibility_matrix(T, P)

    def accuracy(surface):
        Q = tv.relocate(P, surface, "calibrated", original=T, n_partners=256)
        return tv.agreement(VT, tv.visibility_matrix(surface, Q))["accuracy"]

    gain = accuracy(S) - accuracy(info["start"])
    assert gain > 0.001


def test_registered_regular_method_not_in_the_default_list():
    T = synthetic_terrain("ridges", size=33, seed=2)
    S = simplifiers.simplify(T, "visopt", 2, n_train=40, seed=2)
    np.testing.assert_array_equal(S.z, vo.visopt(T, 2, n_train=40, seed=2).z)
    assert S.attrs["method"] == "visopt" and S.attrs["kind"] == "regular" and S.attrs["n_vertices"] == 81
    assert simplifiers.METHODS["visopt"].kind == "regular" and simplifiers.METHODS["visopt"].halo is None
    from terrainvis.experiment.options import _DECLARED

    methods = next(o for o in _DECLARED if o.name == "methods")
    default = methods.check(None, "methods")
    assert "visopt" not in default and default == tuple(m for m, i in simplifiers.METHODS.items() if i.default)
    assert default == tuple(m for m in simplifiers.METHODS if m in simplifiers.registry.BUILTIN and m != "visopt")  # the paper's seven


def test_max_error_search():
    T = synthetic_terrain("hills", size=33, seed=1)
    out = simplifiers.simplify(T, "visopt", max_error=15.0, n_train=30)
    errors = {lv: simplifiers.simplify(T, "visopt", lv, n_train=30).attrs["max_error"] for lv in range(6)}
    within = [lv for lv, e in errors.items() if e <= 15.0]
    assert out.attrs["level"] == max(within) and out.attrs["max_error"] <= 15.0
    assert out.attrs["stopped_by"] == "max_error" and [lv for lv, _ in out.attrs["level_errors"]] == list(range(6))


@pytest.mark.parametrize("kwargs, err, match", [
    ({"level": 9}, ValueError, r"level must be in \[0, 5\] for a 33x33 grid.*got 9"),
    ({"level": -1}, ValueError, "level"),
    ({"n_train": 1}, ValueError, "n_train"),
    ({"n_train": 2.5}, TypeError, "n_train"),
    ({"rounds": -1}, ValueError, "rounds"),
    ({"seed": -2}, ValueError, "seed"),
    ({"trust": -1.0}, ValueError, "trust"),
    ({"trust": float("nan")}, ValueError, "trust"),
    ({"max_breakpoints": 0}, ValueError, "max_breakpoints"),
])
def test_bad_input(kwargs, err, match):
    T = synthetic_terrain("hills", size=33, seed=1)
    args = {"level": 2, **kwargs}
    level = args.pop("level")
    with pytest.raises(err, match=match):
        vo.visopt(T, level, **args)


def test_bad_grids_and_options():
    with pytest.raises(TypeError, match="grid must be a terrainvis.HeightGrid"):
        vo.visopt(np.zeros((9, 9)), 1)
    z = synthetic_terrain("hills", size=9).z.copy()
    z[2, 2] = np.nan
    with pytest.raises(NodataError):
        vo.visopt(HeightGrid(z), 1)
    with pytest.raises(TypeError, match=r"visopt got unexpected option\(s\) \['weights'\]"):
        simplifiers.simplify(synthetic_terrain("hills", size=9), "visopt", 1, weights="paper")
