"""The eye surface: the calibrated relocation shipped with S(T), without T.

References: the calibrated relocation itself (at the lattice's nodes), the exact LOS
engine (``line_of_sight``) for the verdicts a node keeps under full projection, and
interpolations worked by hand.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

import simplifiers
import terrainvis as tv
from terrainvis.core.terrain import HeightGrid
from terrainvis.relocation import RELOCATIONS, available, default_relocations, practical_relocations
from terrainvis.relocation import calibrated as cal
from terrainvis.relocation import eye as eyemod
from terrainvis.relocation.eye import EyeSurface

FIT = dict(n_partners=64)


@pytest.fixture(scope="module")
def hills():
    T = tv.synthetic_terrain("hills", size=25, seed=3)
    S = simplifiers.simplify(T, "lls", 2)
    return T, S, tv.eye_surface(T, S, **FIT)


# ---------------------------------------------------------------------- the representation
def test_interpolation_worked_by_hand():
    """Nodes [[0, 2, 0], [-2, 0, 2]] (codes +-127 with scale 2) over x in [0, 4], y in [0, 1]."""
    e = EyeSurface(np.array([[0, 127, 0], [-127, 0, 127]], dtype=np.int8), (0.0, 4.0, 0.0, 1.0), scale=2.0)
    np.testing.assert_allclose(e.node_offsets, [[0, 2, 0], [-2, 0, 2]], rtol=1e-12)
    xy = [[1.0, 0.5],   # centre of the first cell: (2 * 0.5 + 0) * 0.5 + (-2 * 0.5 + 0) * 0.5 = 0
          [3.0, 0.25],  # second cell, u 0.5, v 0.25: 1 * 0.75 + 1 * 0.25 = 1
          [0.5, 1.0],   # top edge, u 0.25: -2 * 0.75 = -1.5
          [4.0, 0.0],   # the last node (the lattice's corner): 0
          [2.0, 1.0]]   # a node: 0
    np.testing.assert_allclose(e.offset_at(xy), [0.0, 1.0, -1.5, 0.0, 0.0], atol=1e-12)
    assert e.nbytes == 6 + eyemod.HEADER_BYTES
    S = HeightGrid.from_coords(np.full((2, 2), 10.0), np.array([0.0, 4.0]), np.array([0.0, 1.0]))
    np.testing.assert_allclose(e.heights([[3.0, 0.25, 99.0]], S), [11.0])


def test_mu_law_codes_worked_by_hand():
    scale, mu = 9.0, eyemod.MU
    # code k stands for sign(k) * expm1(|k| / 127 * log1p(mu)) * scale / mu
    np.testing.assert_allclose(eyemod.decode(np.array([0, 127, -127], dtype=np.int8), scale), [0.0, 9.0, -9.0],
                               rtol=1e-12)
    one = np.expm1(np.log1p(mu) / 127) * scale / mu  # the smallest step: about 0.07 mm for 9 m
    assert eyemod.decode(np.array([1], dtype=np.int8), scale)[0] == pytest.approx(one, rel=1e-12)
    assert 6e-5 < one < 8e-5
    assert eyemod.encode(np.array([0.0, one, -9.0, 1e-9]), scale).tolist() == [0, 1, -127, 0]


@given(st.integers(-127, 127), st.floats(1e-3, 1e4))
@example(-127, 1e-3)
def test_every_code_decodes_and_encodes_back(k, scale):
    code = np.array([k], dtype=np.int8)
    assert eyemod.encode(eyemod.decode(code, scale), scale).tolist() == [k]


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-50, 50), min_size=1, max_size=40))
def test_the_codes_are_within_half_a_step(values):
    """mu-law quantisation: relative error at most half a code step (3.7 %) beyond scale / mu."""
    v = np.array(values)
    scale = float(np.abs(v).max())
    back = eyemod.decode(eyemod.encode(v, scale), scale)
    half = np.exp(0.5 * np.log1p(eyemod.MU) / 127) - 1
    assert np.all(np.abs(back - v) <= half * (np.abs(v) + scale / eyemod.MU) + 1e-12)
    assert np.all(np.sign(back) * np.sign(v) >= 0)  # never the wrong side of full projection


def test_the_lattice_fits_the_budget():
    T = tv.synthetic_terrain("hills", size=25, seed=3)
    assert eyemod.lattice_shape(T, 10**6) == T.shape  # never finer than T's samples
    for nodes in (4, 10, 100, 400, 624):
        ny, nx = eyemod.lattice_shape(T, nodes)
        assert 2 <= ny and 2 <= nx and ny * nx <= nodes
    assert eyemod.lattice_shape(T, 400) == (20, 20)


# ---------------------------------------------------------------------- the fit
def test_an_eye_surface_of_T_itself_changes_nothing():
    T = tv.synthetic_terrain("mountains", size=21, seed=4)
    S = HeightGrid.from_coords(T.z.copy(), T.xs.copy(), T.ys.copy())
    e = tv.eye_surface(T, S, **FIT)
    assert e.scale == 0.0 and not e.codes.any()
    P = tv.sample_points(T, 40, seed=9)
    np.testing.assert_array_equal(tv.relocate(P, S, "eye", eye=e), tv.relocate(P, S, "full"))


@settings(max_examples=6, deadline=None)
@given(st.integers(0, 2**16), st.sampled_from([0.0, 2.0]))
def test_an_eye_surface_of_T_itself_changes_nothing_anywhere(seed, offset):
    rng = np.random.default_rng(seed)
    T = HeightGrid(rng.normal(0.0, 5.0, (9, 11)), dx=10.0)
    e = tv.eye_surface(T, T, offset=offset, n_partners=16)
    assert not e.codes.any()
    P = tv.sample_points(T, 10, seed=seed, offset=offset)
    np.testing.assert_array_equal(tv.relocate(P, T, "eye", eye=e, offset=offset)[:, 2],
                                  tv.relocate(P, T, "full", offset=offset)[:, 2])


def test_offsets_are_zero_where_full_projection_keeps_every_verdict():
    """Without neighbours a node's verdicts are those against the partners: where full
    projection keeps all of them, the calibrated relocation does not move the node, and its
    offset is exactly 0; elsewhere some nodes move."""
    T = tv.synthetic_terrain("hills", size=21, seed=5)
    S = simplifiers.simplify(T, "lls", 1)
    opts = dict(n_partners=64, neighbours=False, validate=False)
    e = tv.eye_surface(T, S, shape=T.shape, **opts)
    part = cal.partners(T, S, height=0.0, move=True, n_partners=64, neighbours=False)
    nodes = e.node_xy()
    on_t = np.column_stack([nodes, T.height_at(nodes)])
    on_s = np.column_stack([nodes, S.height_at(nodes)])
    k = part.xy.shape[0]
    a_t, a_s = np.repeat(on_t, k, axis=0), np.repeat(on_s, k, axis=0)
    b_t = np.tile(np.column_stack([part.xy, part.z_original]), (nodes.shape[0], 1))
    b_s = np.tile(np.column_stack([part.xy, part.z_simplified]), (nodes.shape[0], 1))
    same = (tv.line_of_sight(T, a_t, b_t, engine="grid") == tv.line_of_sight(S, a_s, b_s, engine="grid"))
    kept_all = same.reshape(nodes.shape[0], k).all(axis=1)
    offsets = e.node_offsets.ravel()
    assert kept_all.sum() > 20 and (~kept_all).sum() > 20  # both kinds of node occur: the test can fail
    assert not offsets[kept_all].any()
    assert offsets[~kept_all].any()


def test_the_nodes_hold_the_calibrated_offsets(hills):
    """At its nodes the surface gives the calibrated height, to the code's step."""
    T, S, _ = hills
    e = tv.eye_surface(T, S, validate=False, **FIT)
    xy = e.node_xy()
    exact = tv.relocate(np.column_stack([xy, T.height_at(xy)]), S, "calibrated", original=T, **FIT)[:, 2]
    exact = exact - S.height_at(xy)
    half = np.exp(0.5 * np.log1p(eyemod.MU) / 127) - 1
    got = e.offset_at(xy)
    assert np.all(np.abs(got - exact) <= half * (np.abs(exact) + e.scale / eyemod.MU) + 1e-9)
    assert np.abs(exact).max() > 0.1  # S(T) is not T: there is something to fit


def test_the_validation_scales_the_offsets_by_one_factor(hills, monkeypatch):
    T, S, e = hills
    whole = tv.eye_surface(T, S, validate=False, **FIT)
    np.testing.assert_array_equal(e.codes, whole.codes)
    assert e.scale in [f * whole.scale for f in eyemod.SHRINKS]
    monkeypatch.setattr(eyemod, "SHRINKS", (0.0,))  # only full projection to choose from
    P = tv.sample_points(T, 20, seed=3)
    S2 = simplifiers.simplify(T, "lls", 2)  # a fresh S(T): nothing cached
    np.testing.assert_array_equal(tv.relocate(P, S2, "eye", eye=tv.eye_surface(T, S2, **FIT)),
                                  tv.relocate(P, S2, "full"))
    monkeypatch.setattr(eyemod, "SHRINKS", (1.0,))
    assert tv.eye_surface(T, S2, **FIT).scale == whole.scale


def test_by_default_it_is_no_larger_than_S(hills):
    T, S, e = hills
    assert e.nbytes <= S.z.nbytes
    Q = simplifiers.simplify(T, "qec", 3)
    eq = tv.eye_surface(T, Q, **FIT)
    assert eq.nbytes <= Q.vertices.nbytes + Q.faces.nbytes
    assert tv.eye_surface(T, S, budget=200, **FIT).nbytes <= 200


def test_fresh_points_get_heights_without_T(hills):
    """The relocation reads only S(T) and the eye surface; fitted from original= it is the same."""
    T, S, e = hills
    P = tv.sample_points(T, 30, seed=77)
    moved = tv.relocate(P, S, "eye", eye=e)
    np.testing.assert_array_equal(moved[:, :2], P[:, :2])
    np.testing.assert_array_equal(moved[:, 2], S.height_at(P[:, :2]) + e.offset_at(P[:, :2]))
    np.testing.assert_array_equal(tv.relocate(P, S, "eye", original=T, **FIT), moved)
    # a point's height does not depend on the other points
    np.testing.assert_array_equal(tv.relocate(P[:7], S, "eye", eye=e), moved[:7])


# ---------------------------------------------------------------------- files
def test_save_and_reload_give_the_same_heights_bit_for_bit(hills, tmp_path):
    T, S, e = hills
    P = tv.sample_points(T, 50, seed=11)
    want = tv.relocate(P, S, "eye", eye=e)
    own = e.save(tmp_path / "eye.npz")
    inside = e.save(tmp_path / "s.npz", terrain=S)
    tif = tmp_path / "s.tif"
    tif.write_bytes(b"stands for a GeoTIFF")
    side = e.save(EyeSurface.sidecar(tif))
    assert side.name == "s.tif.eye.npz"
    for path in (own, inside, tif):
        back = EyeSurface.load(path)
        np.testing.assert_array_equal(back.codes, e.codes)
        assert (back.extent, back.scale, back.offset, back.target_height) == (e.extent, e.scale, e.offset, None)
        np.testing.assert_array_equal(tv.relocate(P, S, "eye", eye=back), want)
    # the terrain .npz still reads as S(T)
    S2 = tv.load_terrain(inside)
    np.testing.assert_array_equal(S2.z, S.z)


def test_a_failed_write_leaves_the_old_file_whole(hills, tmp_path, monkeypatch):
    T, S, e = hills
    path = e.save(tmp_path / "eye.npz")
    before = path.read_bytes()

    def broken(fh, **arrays):
        fh.write(b"PK\x03\x04 half an archive")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez_compressed", broken)
    other = EyeSurface(np.zeros((2, 2), dtype=np.int8), e.extent, 0.0)
    with pytest.raises(OSError):
        other.save(path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["eye.npz"]


def test_unreadable_files_are_refused_with_a_reason(hills, tmp_path):
    T, S, e = hills
    tv.save_terrain(S, tmp_path / "plain.npz")
    with pytest.raises(ValueError, match="holds no eye surface"):
        EyeSurface.load(tmp_path / "plain.npz")
    with pytest.raises(FileNotFoundError, match="no eye surface at"):
        EyeSurface.load(tmp_path / "missing.tif")
    (tmp_path / "bad.npz").write_bytes(b"PK\x03\x04 not really")
    with pytest.raises(ValueError, match="truncated or corrupt|not a readable eye surface"):
        EyeSurface.load(tmp_path / "bad.npz")
    arrays = dict(e.arrays(), eye_codes=np.zeros((1, 3), dtype=np.int8))
    np.savez(tmp_path / "small.npz", **arrays)
    with pytest.raises(ValueError, match=re.escape("codes must have at least 2 rows and 2 columns, got shape (1, 3)")):
        EyeSurface.load(tmp_path / "small.npz")
    with pytest.raises(ValueError, match="path must end in .npz"):
        e.save(tmp_path / "eye.tif")


# ---------------------------------------------------------------------- the relocation
def test_relocate_eye_without_eye_is_a_one_line_error(hills):
    T, S, _ = hills
    with pytest.raises(TypeError) as info:
        tv.relocate(tv.sample_points(T, 3, seed=1), S, "eye")
    msg = str(info.value)
    assert "\n" not in msg and "eye=" in msg and "original=" in msg


def test_bad_input_is_named(hills):
    T, S, e = hills
    P = tv.sample_points(T, 3, seed=1)
    with pytest.raises(TypeError, match="eye must be a terrainvis.relocation.eye.EyeSurface, got"):
        tv.relocate(P, S, "eye", eye="eye.npz")
    with pytest.raises(ValueError, match="eye was fitted for points 0 above the ground, but offset is 2"):
        tv.relocate(P, S, "eye", eye=e, offset=2.0)
    with pytest.raises(ValueError, match=r"xy must lie inside the eye surface's extent"):
        e.offset_at([[-1e6, 0.0]])
    with pytest.raises(ValueError, match=r"budget must be"):
        tv.eye_surface(T, S, budget=10)
    with pytest.raises(TypeError, match="original must be a terrainvis.HeightGrid"):
        tv.eye_surface(S.z, S)
    with pytest.raises(ValueError, match="codes must be int8, got dtype float64"):
        EyeSurface(np.zeros((2, 2)), (0, 1, 0, 1), 1.0)


def test_the_registry_lists_it_outside_the_defaults():
    assert "eye" in available() and "eye" in practical_relocations()
    assert "eye" not in default_relocations()
    entry = RELOCATIONS["eye"]
    assert "eye" in entry.options and "original" in entry.options and not entry.bound


def test_compare_fits_it_once_per_unit_and_reports_it():
    grid = tv.synthetic_terrain("hills", size=33, seed=2)
    df = tv.compare({"g": grid}, relocations=["full", "calibrated", "eye"], methods=["lls"], levels=[2],
                    n_points=12, n_sets=2, repeats=1, n_partners=32, workers=1)
    assert set(df["relocation"]) == {"full", "calibrated", "eye"}
    eye = df[df["relocation"] == "eye"]
    assert len(eye) == 2 and eye["accuracy"].between(0, 1).all()


def test_line_of_sight_and_the_matrix_take_the_eye_surface(hills):
    """eye= on S(T) places the ends as relocate(..., "eye") does, the given heights unread."""
    T, S, e = hills
    P = tv.sample_points(T, 25, seed=21)
    moved = tv.relocate(P, S, "eye", eye=e)
    junk = P.copy()
    junk[:, 2] = -1e3  # under the ground: would see nothing if read
    np.testing.assert_array_equal(tv.visibility_matrix(S, junk, eye=e), tv.visibility_matrix(S, moved))
    a, b = junk[:12], junk[12:24]
    np.testing.assert_array_equal(tv.line_of_sight(S, a, b, eye=e), tv.line_of_sight(S, moved[:12], moved[12:24]))
    assert tv.visibility_matrix(S, moved).sum() > 25  # some pairs are seen: the comparison can fail
    with pytest.raises(TypeError, match="eye must be an EyeSurface"):
        tv.visibility_matrix(S, P, eye=object())


def test_a_viewshed_takes_the_eye_surface_for_its_observer():
    from terrainvis import line_of_sight, viewshed
    from terrainvis.relocation.eye import EyeSurface

    S = tv.synthetic_terrain("hills", size=33, seed=5)
    x0, x1, y0, y1 = S.extent
    codes = np.array([[0, 90, -60], [127, 0, 40], [-127, 30, 0]], dtype=np.int8)
    e = EyeSurface(codes, (x0, x1, y0, y1), scale=6.0, offset=2.0)
    obs = (float(S.xs[10]) + 3.0, float(S.ys[20]) - 2.0)
    got = viewshed(S, obs, eye=e)
    z = float(S.height_at([obs])[0] + 2.0 + e.offset_at([obs])[0])
    assert z != float(S.height_at([obs])[0] + 2.0)  # the offset there is not 0: the test tells them apart
    # each sample checked pair by pair, the eye where the surface puts it, the targets on the ground
    X, Y = np.meshgrid(S.xs, S.ys)
    t = np.column_stack([X.ravel(), Y.ravel(), S.z.ravel()])
    want = line_of_sight(S, np.tile([obs[0], obs[1], z], (t.shape[0], 1)), t).reshape(S.shape)
    mismatch = got != want
    mismatch[np.hypot(X - obs[0], Y - obs[1]) < 1e-9] = False
    assert not mismatch.any()
    np.testing.assert_array_equal(got, viewshed(S, (obs[0], obs[1], z)))
    with pytest.raises(TypeError, match="pass either eye= or observer_height=, not both"):
        viewshed(S, obs, eye=e, observer_height=3.0)
    with pytest.raises(ValueError, match=r"with eye=, observer must be its position \(x, y\)"):
        viewshed(S, (obs[0], obs[1], z), eye=e)
    with pytest.raises(TypeError, match="eye must be an EyeSurface"):
        viewshed(S, obs, eye="surface.npz")


def _pairs(n: int, gained: int, lost: int, base_kept: int) -> np.ndarray:
    """Whether each of ``n`` pairs keeps its verdict: full projection keeps ``base_kept`` of
    them; a factor keeps those, less ``lost``, plus ``gained`` others."""
    base = np.zeros(n, dtype=bool)
    base[:base_kept] = True
    other = base.copy()
    other[:lost] = False
    other[base_kept:base_kept + gained] = True
    return base, other


def test_a_factor_is_kept_only_where_it_beats_full_projection_by_more_than_chance(monkeypatch):
    """McNemar's statistic on the pairs where a factor and full projection differ: 30 gained
    and 10 lost (3.2) is kept; 6 and 2 (1.4), more pairs kept but as a coin could, is not;
    of two factors that beat it, the one keeping more wins; ties go to the first."""
    monkeypatch.setattr(eyemod, "SHRINKS", (1.0, 0.5, 0.0))
    base, clear = _pairs(1000, 30, 10, 900)
    _, noisy = _pairs(1000, 6, 2, 900)
    assert eyemod._choose_shrink(np.array([clear, noisy, base])) == 1.0
    assert eyemod._choose_shrink(np.array([noisy, noisy, base])) == 0.0
    _, better = _pairs(1000, 50, 10, 900)
    assert eyemod._choose_shrink(np.array([clear, better, base])) == 0.5
    assert eyemod._choose_shrink(np.array([better, better, base])) == 1.0
    # the rule's threshold: 2 x sqrt(b + c) against b - c
    _, edge = _pairs(1000, 12, 4, 900)  # 8 > 2 sqrt(16) = 8 is false
    _, past = _pairs(1000, 13, 4, 900)  # 9 > 2 sqrt(17) = 8.25
    assert eyemod._choose_shrink(np.array([edge, edge, base])) == 0.0
    assert eyemod._choose_shrink(np.array([past, past, base])) == 1.0
    # without full projection among the factors, the one that keeps the most
    monkeypatch.setattr(eyemod, "SHRINKS", (1.0, 0.5))
    assert eyemod._choose_shrink(np.array([noisy, clear])) == 0.5
