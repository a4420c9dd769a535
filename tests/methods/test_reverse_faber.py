"""Reverse Faber subdivision: the curve operators, forward subdivision and simplify().

References used here are independent of the implementation: a dense Faber matrix S
built from the text of ALGORITHMS.md section 2 with loops, a pure-Python critical-point
finder, ``numpy.linalg.lstsq`` of the dense (stacked) system, the paper's LLS formula
written out tap by tap, and the pseudo-inverse of the 5x3 local Faber matrix.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import simplifiers
from simplifiers import reverse_faber as rf
from terrainvis.errors import NodataError
from terrainvis.core.terrain import HeightGrid

from conftest import DEM_NAMES, shared_dem_120

OPS = {"simple": rf.simple, "lls": rf.lls, "gls": rf.gls, "feature": rf.feature}
HYP = settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])


# ------------------------------------------------------------------ references
def dense_S(m: int) -> np.ndarray:
    """The m x n Faber matrix, from the conventions: hat functions on the coarse positions."""
    n = (m + 1) // 2
    if m % 2:
        pos = [2 * j for j in range(n)]
    else:
        pos = [2 * j for j in range(n - 1)] + [m - 1]
    S = np.zeros((m, n))
    for k in range(m):
        for j in range(n - 1):
            a, b = pos[j], pos[j + 1]
            if a <= k <= b:
                S[k, j] = (b - k) / (b - a)
                S[k, j + 1] = (k - a) / (b - a)
                break
    return S


def ref_critical(g) -> list[int]:
    """Ends, plus each interior run of equal values that is a strict extremum (lower middle)."""
    g = list(g)
    m = len(g)
    runs = []
    s = 0
    while s < m:
        e = s
        while e + 1 < m and g[e + 1] == g[s]:
            e += 1
        runs.append((s, e))
        s = e + 1
    out = [0]
    for t in range(1, len(runs) - 1):
        s, e = runs[t]
        v, left, right = g[s], g[runs[t - 1][0]], g[runs[t + 1][0]]
        if (v > left and v > right) or (v < left and v < right):
            out.append((s + e) // 2)
    if m > 1:
        out.append(m - 1)
    return out


def ref_feature(g, weight: float = 1.0) -> np.ndarray:
    """Dense least squares of S stacked with the weighted constraint rows."""
    g = np.asarray(g, dtype=float)
    m = g.size
    S = dense_S(m)
    n = S.shape[1]
    rows, rhs = [], []
    cp = ref_critical(g)
    for j, k in zip(cp[:-1], cp[1:]):
        p, q = min(j // 2, n - 1), min(k // 2, n - 1)
        if p == q:
            continue
        r = np.zeros(n)
        r[p], r[q] = weight, -weight
        rows.append(r)
        rhs.append(weight * (g[j] - g[k]))
    A = np.vstack([S, *rows]) if rows else S
    b = np.concatenate([g, rhs])
    return np.linalg.lstsq(A, b, rcond=None)[0]


def ref_gls(g) -> np.ndarray:
    return np.linalg.lstsq(dense_S(len(g)), np.asarray(g, dtype=float), rcond=None)[0]


def ref_lls_paper(g) -> np.ndarray:
    """The paper's printed formula, tap by tap, ends kept, at every interior coarse sample."""
    g = np.asarray(g, dtype=float)
    n = (g.size + 1) // 2
    c = np.empty(n)
    c[0], c[-1] = g[0], g[-1]
    for i in range(1, n - 1):
        c[i] = (
            -1 / 6 * g[2 * i - 2] + 1 / 3 * g[2 * i - 1] + 2 / 3 * g[2 * i] + 1 / 3 * g[2 * i + 1]
            - 1 / 6 * g[2 * i + 2]
        )
    return c


def make_curve(kind: str, m: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if kind == "normal":
        return rng.normal(0, 50, m)
    if kind == "ties":  # small integers: plateaus, ties between neighbours and steps
        return rng.integers(-2, 3, m).astype(float)
    if kind == "monotone":  # one constraint couples coarse 0 with coarse n-1
        return np.cumsum(rng.uniform(0.0, 3.0, m))
    if kind == "constant":
        return np.full(m, rng.normal())
    if kind == "walk":
        return np.cumsum(rng.normal(size=m))
    raise AssertionError(kind)


KINDS = ("normal", "ties", "monotone", "constant", "walk")
curves = st.tuples(st.integers(3, 200), st.sampled_from(KINDS), st.integers(0, 2**32 - 1))


def _close(a, b, scale=1.0):
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * max(1.0, scale))


# ------------------------------------------------------------------ conventions
def test_dense_S_matches_the_hand_worked_conventions():
    np.testing.assert_array_equal(rf.coarse_positions(7), [0, 2, 4, 6])
    np.testing.assert_array_equal(rf.coarse_positions(8), [0, 2, 4, 7])
    np.testing.assert_allclose(dense_S(4), [[1, 0], [2 / 3, 1 / 3], [1 / 3, 2 / 3], [0, 1]])
    np.testing.assert_allclose(dense_S(5), [[1, 0, 0], [0.5, 0.5, 0], [0, 1, 0], [0, 0.5, 0.5], [0, 0, 1]])


@given(st.integers(2, 60), st.booleans(), st.integers(0, 2**32 - 1))
@HYP
def test_subdivide_is_S_times_c(n, even, seed):
    c = np.random.default_rng(seed).normal(size=(3, n))
    m = 2 * n if even else 2 * n - 1
    f = rf.subdivide(c, axis=1, m=m)
    np.testing.assert_allclose(f, c @ dense_S(m).T, rtol=1e-15, atol=1e-13)
    np.testing.assert_array_equal(rf.simple(f, axis=1), c)  # exact: the coarse samples are copied
    np.testing.assert_allclose(rf.gls(f, axis=1), c, rtol=0, atol=1e-12)  # S has full column rank
    np.testing.assert_allclose(rf.subdivide(c.T, axis=0, m=m), f.T, rtol=0, atol=0)


# ------------------------------------------------------------------ GLS and feature vs dense lstsq
@given(curves)
@example((3, "normal", 1))
@example((4, "normal", 2))
@example((4, "constant", 3))
@example((200, "monotone", 4))
@example((199, "ties", 5))
@HYP
def test_gls_equals_dense_lstsq(case):
    m, kind, seed = case
    g = make_curve(kind, m, seed)
    _close(rf.gls(g), ref_gls(g), np.abs(g).max())


@given(curves, st.sampled_from([1.0, 0.0, 0.3, 4.0]))
@example((3, "normal", 1), 1.0)
@example((4, "ties", 2), 1.0)
@example((200, "monotone", 4), 1.0)  # a single constraint coupling index 0 with index n-1
@example((200, "monotone", 4), 4.0)
@example((5, "constant", 0), 1.0)
@example((150, "ties", 7), 1.0)
@HYP
def test_feature_equals_dense_lstsq(case, weight):
    m, kind, seed = case
    g = make_curve(kind, m, seed)
    _close(rf.feature(g, weight=weight), ref_feature(g, weight), np.abs(g).max())


def test_feature_long_monotone_stretch_between_extrema():
    # a long climb, a peak, a long descent and one dip: couplings far apart in index
    m = 801
    k = np.arange(m, dtype=float)
    g = np.where(k < 500, k * 0.7, 350 - (k - 500) * 1.3)
    g[700] -= 200.0
    _close(rf.feature(g), ref_feature(g), 400)
    _close(rf.feature(g, weight=10.0), ref_feature(g, 10.0), 400)


@given(st.integers(3, 120), st.sampled_from(KINDS), st.integers(0, 2**32 - 1), st.sampled_from(["gls", "feature"]),
       st.integers(0, 2))
@HYP
def test_least_squares_batched_random_shapes_and_axes(m, kind, seed, name, axis):
    rng = np.random.default_rng(seed)
    shape = [int(s) for s in rng.integers(1, 4, size=3)]
    shape[axis] = m
    data = np.stack([make_curve(kind, m, seed + i) for i in range(int(np.prod(shape)) // m)])
    f = np.moveaxis(data.reshape([s for i, s in enumerate(shape) if i != axis] + [m]), -1, axis)
    out = OPS[name](f, axis=axis)
    assert out.shape == tuple((m + 1) // 2 if i == axis else s for i, s in enumerate(shape))
    ref = ref_gls if name == "gls" else ref_feature
    for idx in np.ndindex(*[s for i, s in enumerate(shape) if i != axis]):
        sl = list(idx)
        sl.insert(axis, slice(None))
        curve = f[tuple(sl)]
        _close(out[tuple(sl)], ref(curve), np.abs(curve).max())


# ------------------------------------------------------------------ critical points
@pytest.mark.parametrize(
    "g, expected",
    [
        ([0, 1, 0], [0, 1, 2]),
        ([0, 1, 2, 3], [0, 3]),  # monotone: the ends only
        ([5, 5, 5], [0, 2]),  # constant
        ([0, 3, 3, 3, 3, 1, 2, 2], [0, 2, 5, 7]),  # plateau max [1, 4] -> 2; the end run counts once
        ([0, 2, 2, 1], [0, 1, 3]),  # plateau of 2 -> its first sample (lower middle)
        ([0, 1, 1, 2, 0], [0, 3, 4]),  # a step is not an extremum
        ([3, 3, 1, 1, 4], [0, 2, 4]),  # plateau min [2, 3] -> 2; the leading run is just the end
        ([1, 0, 0, 0, 0, 0, 1], [0, 3, 6]),
    ],
)
def test_critical_points_hand_worked(g, expected):
    assert rf.critical_points(np.array(g, dtype=float)).tolist() == expected
    assert ref_critical(g) == expected


@given(curves)
@HYP
def test_critical_points_match_reference(case):
    m, kind, seed = case
    g = make_curve(kind, m, seed)
    assert rf.critical_points(g).tolist() == ref_critical(g)


# ------------------------------------------------------------------ LLS
@given(st.integers(3, 200), st.integers(0, 2**32 - 1))
@example(3, 0)
@example(4, 0)
@example(6, 1)
@HYP
def test_lls_equals_the_papers_formula(m, seed):
    g = np.random.default_rng(seed).normal(0, 100, m)
    np.testing.assert_allclose(rf.lls(g), ref_lls_paper(g), rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(rf.lls(g, weights="paper"), ref_lls_paper(g), rtol=1e-14, atol=1e-12)


def test_lls_derived_weights_are_the_local_least_squares_filter():
    L = np.array([[1, 0, 0], [0.5, 0.5, 0], [0, 1, 0], [0, 0.5, 0.5], [0, 0, 1]])
    central = (np.linalg.inv(L.T @ L) @ L.T)[1]
    np.testing.assert_allclose(central, np.array([-1, 2, 5, 2, -1]) / 7, rtol=0, atol=1e-15)
    # the operator applies exactly this row: probe it with unit impulses
    for t in range(5):
        e = np.zeros(9)
        e[2 + t] = 1.0  # taps 2..6 around coarse sample 2 (position 4)
        assert rf.lls(e, weights="derived")[2] == pytest.approx(central[t], abs=1e-15)
    # and the paper's printed coefficients are not that solution (the documented discrepancy)
    paper = np.array([-1, 2, 4, 2, -1]) / 6
    assert paper.sum() == pytest.approx(1.0)
    assert np.abs(paper - central).max() > 0.04  # 1/21
    for t in range(5):
        e = np.zeros(9)
        e[2 + t] = 1.0
        assert rf.lls(e)[2] == pytest.approx(paper[t], abs=1e-15)


def test_lls_unknown_weights_lists_the_valid_ones():
    with pytest.raises(ValueError, match=r"weights must be one of \['paper', 'derived'\], got 'exact'"):
        rf.lls(np.zeros(5), weights="exact")


# ------------------------------------------------------------------ reproduction
@given(st.integers(3, 150), st.floats(-1e3, 1e3), st.floats(-50, 50))
@example(4, 0.0, 1.0)
@example(3, 5.0, -2.0)
@HYP
def test_linear_functions_are_reproduced(m, a, b):
    k = np.arange(m, dtype=float)
    f = a + b * k
    expected = a + b * rf.coarse_positions(m)
    tol = 1e-12 * (abs(a) + abs(b) * m + 1)
    for name, out in [
        ("simple", rf.simple(f)), ("gls", rf.gls(f)), ("lls", rf.lls(f)),
        ("lls-derived", rf.lls(f, weights="derived")),
        ("feature", rf.feature(f)),  # a line's only critical points are its ends: a consistent constraint
    ]:
        np.testing.assert_allclose(out, expected, rtol=0, atol=tol, err_msg=name)


@given(st.integers(3, 150), st.floats(-1e4, 1e4), st.sampled_from([0.0, 1.0, 7.0]))
@HYP
def test_constants_are_reproduced_by_all_four(m, value, weight):
    f = np.full((2, m), value)
    tol = 1e-12 * (abs(value) + 1)
    for name, op in OPS.items():
        np.testing.assert_allclose(op(f, axis=1), value, rtol=0, atol=tol, err_msg=name)
    np.testing.assert_allclose(rf.feature(f, axis=1, weight=weight), value, rtol=0, atol=tol)


def test_gls_is_optimal_among_the_variants_on_real_rows():
    """||S c - f|| is smallest for GLS; checked on every row and column of each shared DEM crop."""
    for name in DEM_NAMES:
        z = shared_dem_120(name).z
        for f in (z, z.T):
            S = dense_S(f.shape[1])
            res = {k: np.linalg.norm(op(f, axis=1) @ S.T - f, axis=1) for k, op in OPS.items()}
            for k in ("simple", "lls", "feature"):
                assert (res["gls"] <= res[k] * (1 + 1e-12) + 1e-9).all(), (name, k)
            assert (res["gls"] < res["simple"]).any()


# ------------------------------------------------------------------ batching and input handling
@pytest.mark.parametrize("name", list(OPS))
@pytest.mark.parametrize("m", [3, 4, 17, 40])
def test_batched_equals_per_curve(name, m):
    rng = np.random.default_rng(m)
    op = OPS[name]
    z = rng.normal(0, 10, (m, m + 3)).round(1)  # rounding makes ties and plateaus
    by_cols = op(z, axis=0)
    for c in range(z.shape[1]):
        np.testing.assert_array_equal(by_cols[:, c], op(z[:, c].copy()))
    zr = rng.normal(0, 10, (5, m)).round(1)
    by_rows = op(zr, axis=1)
    for r in range(zr.shape[0]):
        np.testing.assert_array_equal(by_rows[r], op(zr[r].copy()))
    # a 3-D array reduced along its middle axis, and a non-contiguous view
    cube = rng.normal(size=(3, m, 70))
    mid = op(cube, axis=1)
    for a in range(3):
        np.testing.assert_array_equal(mid[a], op(cube[a], axis=0))
    np.testing.assert_array_equal(op(z.T, axis=1), by_cols.T)
    np.testing.assert_array_equal(op(cube, axis=-2), mid)


@pytest.mark.parametrize("name", list(OPS))
def test_input_is_not_modified_and_output_is_float64(name):
    z = np.arange(35, dtype=np.int32).reshape(5, 7)
    before = z.copy()
    out = OPS[name](z, axis=1)
    np.testing.assert_array_equal(z, before)
    assert out.dtype == np.float64 and out.shape == (5, 4)
    f = np.random.default_rng(0).normal(size=(9, 6))
    fb = f.copy()
    OPS[name](f, axis=0)
    np.testing.assert_array_equal(f, fb)


@pytest.mark.parametrize("name", list(OPS))
def test_bad_input(name):
    op = OPS[name]
    with pytest.raises(ValueError, match=r"along axis 1 has 2 sample\(s\), too short to reduce"):
        op(np.zeros((5, 2)), axis=1)
    with pytest.raises(ValueError, match=r"along axis 0 has 1 sample\(s\), too short"):
        op(np.zeros(1))
    with pytest.raises(ValueError, match=r"axis must be in \[-2, 1\] for a 2-D array, got 2"):
        op(np.zeros((5, 5)), axis=2)
    with pytest.raises(TypeError, match="axis must be an integer"):
        op(np.zeros((5, 5)), axis=1.0)
    with pytest.raises(TypeError, match="real numeric array"):
        op(np.zeros(5, dtype=complex))
    for m in (3, 4, 9, 10):  # NaN and inf anywhere, including samples no output reads
        for pos in range(m):
            for bad in (np.nan, np.inf):
                f = np.ones((2, m))
                f[1, pos] = bad
                with pytest.raises(ValueError, match="f must be finite"):
                    op(f, axis=1)
                with pytest.raises(ValueError, match="f must be finite"):
                    op(f.T.copy(), axis=0)


def test_feature_weight_validation():
    with pytest.raises(ValueError, match="weight must be finite and >= 0, got -1"):
        rf.feature(np.zeros(5), weight=-1)
    with pytest.raises(TypeError, match="weight must be a real number"):
        rf.feature(np.zeros(5), weight="big")
    g = np.random.default_rng(3).normal(size=31)
    np.testing.assert_allclose(rf.feature(g, weight=0.0), rf.gls(g), rtol=0, atol=1e-12)


# ------------------------------------------------------------------ simplify() and grids
def _grid(rows, cols, seed=0, dx=30.0, dy=25.0, origin=(500000.0, 4000000.0)):
    rng = np.random.default_rng(seed)
    z = np.cumsum(np.cumsum(rng.normal(size=(rows, cols)), axis=0), axis=1)
    return HeightGrid(z, dx=dx, dy=dy, origin=origin)


@pytest.mark.parametrize("method", ["simple", "lls", "gls", "feature"])
@pytest.mark.parametrize("size, sizes", [(120, [60, 30, 15]), (121, [61, 31, 16])])
def test_simplify_shapes_and_coordinates(method, size, sizes):
    g = _grid(size, size, dx=30.0, dy=30.0)
    for level, n in enumerate(sizes, start=1):
        out = simplifiers.simplify(g, method, level)
        assert out.shape == (n, n)
        assert out.extent == g.extent
        # the coordinates are those at the coarse positions, level by level
        idx = np.arange(size)
        for _ in range(level):
            idx = idx[rf.coarse_positions(idx.size)]
        np.testing.assert_array_equal(out.xs, g.xs[idx])
        np.testing.assert_array_equal(out.ys, g.ys[idx])
        assert out.attrs["method"] == method and out.attrs["level"] == level


def test_simplify_level_zero_and_errors():
    g = _grid(120, 120)
    same = simplifiers.simplify(g, "gls", 0)
    np.testing.assert_array_equal(same.z, g.z)
    np.testing.assert_array_equal(same.xs, g.xs)
    top = simplifiers.max_level(g.shape)
    simplifiers.simplify(g, "feature", top)  # the deepest level works
    with pytest.raises(ValueError, match=rf"level must be in \[0, {top}\] for a 120x120 grid"):
        simplifiers.simplify(g, "lls", top + 1)
    with pytest.raises(ValueError, match=r"method must be one of \[.*'simple'.*'feature'.*available"):
        simplifiers.simplify(g, "faber", 1)
    z = g.z.copy()
    z[3, 4] = np.nan
    with pytest.raises(NodataError):
        simplifiers.simplify(HeightGrid(z), "gls", 1)


def test_simplify_is_rows_then_columns_and_order_matters_for_feature():
    g = _grid(41, 37, seed=5)
    out = simplifiers.simplify(g, "feature", 1)
    manual = rf.feature(rf.feature(g.z, axis=1), axis=0)
    np.testing.assert_array_equal(out.z, manual)
    other = rf.feature(rf.feature(g.z, axis=0), axis=1)
    assert other.shape == manual.shape
    assert np.abs(other - manual).max() > 1e-6  # the feature-aware operator is not separable
    # a separable linear operator (LLS) does not care about the order (to rounding)
    lls_other = rf.lls(rf.lls(g.z, axis=0), axis=1)
    np.testing.assert_allclose(simplifiers.simplify(g, "lls", 1).z, lls_other, rtol=0, atol=1e-9)


def test_faber_subdivide_grid():
    g = HeightGrid([[0.0, 2.0], [4.0, 6.0]], dx=2.0, dy=2.0)
    fine = simplifiers.faber_subdivide(g)
    np.testing.assert_array_equal(fine.z, [[0, 1, 2], [2, 3, 4], [4, 5, 6]])
    np.testing.assert_array_equal(fine.xs, [0, 1, 2])
    big = _grid(120, 121)
    coarse = simplifiers.simplify(big, "simple", 1)
    back = rf.faber_subdivide(coarse, shape=big.shape)
    assert back.shape == big.shape
    np.testing.assert_allclose(back.xs, big.xs, rtol=1e-15)
    np.testing.assert_allclose(back.ys, big.ys, rtol=1e-15)
    # z is the tensor-product Faber surface: S_r coarse S_c^T
    Sr, Sc = dense_S(120), dense_S(121)
    np.testing.assert_allclose(back.z, Sr @ coarse.z @ Sc.T, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(rf.simple(rf.simple(back.z, axis=1), axis=0), coarse.z)
    with pytest.raises(ValueError, match=r"shape must be \(119 or 120, 121 or 122\) for a 60x61 grid"):
        rf.faber_subdivide(coarse, shape=(121, 121))
    with pytest.raises(TypeError, match="grid must be a terrainvis.HeightGrid"):
        rf.faber_subdivide(coarse.z)


def test_subdivide_bad_input():
    with pytest.raises(ValueError, match="m must be 5 or 6 for 3 coarse samples, got 7"):
        rf.subdivide(np.zeros(3), m=7)
    with pytest.raises(ValueError, match="needs at least 2"):
        rf.subdivide(np.zeros(1))
    with pytest.raises(ValueError, match="c must be finite"):
        rf.subdivide(np.array([0.0, np.nan]))


@pytest.mark.parametrize("shape", [(3, 3), (4, 3), (3, 4), (9, 10), (120, 121), (301, 300)])
@pytest.mark.parametrize("method, options", [
    ("simple", {}), ("lls", {}), ("lls", {"weights": "derived"}), ("gls", {}), ("feature", {}),
    ("feature", {"weight": 2.0}),
])
def test_reduce_level_equals_rows_then_columns_bitwise(shape, method, options):
    z = np.random.default_rng(sum(shape)).normal(0, 100, shape).round(0)
    op = OPS[method]
    expected = op(op(z, axis=1, **options), axis=0, **options)
    got = rf.reduce_level(z, op, **options)
    assert got.shape == expected.shape
    np.testing.assert_array_equal(got, expected)


def test_reduce_level_large_grid_runs_in_parallel_chunks():
    # big enough for the threaded path; chunks restart their ring of filtered rows
    z = np.random.default_rng(1).normal(size=(1201, 1000))
    np.testing.assert_array_equal(rf.reduce_level(z, rf.lls), rf.lls(rf.lls(z, axis=1), axis=0))
    np.testing.assert_array_equal(rf.reduce_level(z, rf.gls), rf.gls(rf.gls(z, axis=1), axis=0))
    # and the threaded two-pass kernels agree with the serial per-curve ones
    np.testing.assert_array_equal(rf.gls(z, axis=0)[:, 17], rf.gls(z[:, 17].copy()))
    np.testing.assert_array_equal(rf.lls(z, axis=1)[999], rf.lls(z[999].copy()))
    np.testing.assert_array_equal(rf.feature(z[:, :40], axis=0)[:, 5], rf.feature(z[:, 5].copy()))


def test_reduce_level_bad_input():
    with pytest.raises(TypeError, match="op must be a curve operator"):
        rf.reduce_level(np.zeros((5, 5)), "lls")
    with pytest.raises(ValueError, match="z must be a 2-D array"):
        rf.reduce_level(np.zeros(5), rf.lls)
    with pytest.raises(ValueError, match="too short to reduce"):
        rf.reduce_level(np.zeros((2, 5)), rf.lls)
    with pytest.raises(ValueError, match="weights must be one of"):
        rf.reduce_level(np.zeros((5, 5)), rf.lls, weights="x")
    for shape in [(3, 3), (4, 4), (7, 9)]:
        for pos in np.ndindex(*shape):
            z = np.zeros(shape)
            z[pos] = np.nan
            for op in (rf.simple, rf.lls):
                with pytest.raises(ValueError, match="f must be finite"):
                    rf.reduce_level(z, op)


@pytest.mark.parametrize("name", list(OPS))
def test_empty_batches(name):
    assert OPS[name](np.zeros((0, 5)), axis=1).shape == (0, 3)
    assert OPS[name](np.zeros((6, 0)), axis=0).shape == (3, 0)
    assert OPS[name](np.zeros((3, 0, 2)), axis=0).shape == (2, 0, 2)
