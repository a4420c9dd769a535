"""Tests of observer siting (terrainvis.visibility.viewsheds.siting).

References, independent of the lazy greedy and its packed bits:
* the plain greedy, written here over boolean viewsheds from :func:`terrainvis.viewshed`
  (every candidate's gain recomputed in every round, ties to the lowest index): the lazy
  one must choose the same sequence, with the same gains;
* the optimum by brute force over every k-subset of a few candidates: greedy <= optimum
  <= the run's bound, and greedy >= (1 - 1/e) optimum;
* hand-worked cases: a wall splitting a flat grid, the cell areas of a rectilinear grid,
  the candidate lattice;
* hypothesis over random small terrains and candidates.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from terrainvis import HeightGrid, bundled_terrain, candidate_grid, site_observers, synthetic_terrain, viewshed
from terrainvis.errors import NotEnoughMemoryError, OutsideFootprintError
from terrainvis.visibility import sample_areas


@pytest.fixture(scope="module")
def hills():
    return synthetic_terrain("hills", size=33, seed=4)


def _random_candidates(grid, n, seed):
    rng = np.random.default_rng(seed)
    xmin, xmax, ymin, ymax = grid.extent
    return np.column_stack([rng.uniform(xmin, xmax, n), rng.uniform(ymin, ymax, n)])


def _viewsheds(grid, cands, **kw):
    return [viewshed(grid, c, **kw) for c in cands]


def _plain_greedy(views, k, areas):
    """The textbook greedy: every gain recomputed each round, the first (lowest index) of the largest."""
    covered = np.zeros(views[0].shape, dtype=bool)
    chosen, gains = [], []
    for _ in range(k):
        g = [float(areas[v & ~covered].sum()) if i not in chosen else -1.0 for i, v in enumerate(views)]
        best = int(np.argmax(g))  # argmax returns the first of equal maxima
        chosen.append(best)
        gains.append(g[best])
        covered |= views[best]
    return chosen, gains, covered


def _optimum(views, k, areas):
    return max(float(areas[np.logical_or.reduce([views[i] for i in s])].sum())
               for s in itertools.combinations(range(len(views)), k))


# ----------------------------------------------------------------- against the plain greedy and brute force
@pytest.mark.parametrize("kw", [
    {},
    {"observer_height": 10.0, "target_height": 2.0},
    {"max_distance": 300.0},
    {"curvature": 1.0, "earth_radius": 3000.0},  # a tiny earth, so that the bulge changes the viewsheds
    {"azimuth": (300.0, 60.0), "vertical": (-20.0, 10.0), "min_distance": 50.0},  # a field of view
])
def test_lazy_greedy_chooses_the_plain_greedys_sequence(hills, kw):
    cands = _random_candidates(hills, 12, seed=1)
    views = _viewsheds(hills, cands, **kw)
    cell = hills.dx * hills.dy
    areas = np.full(hills.shape, cell)
    if kw.get("curvature"):
        flat = _viewsheds(hills, cands, **{**kw, "curvature": 0.0})
        assert any((a != b).any() for a, b in zip(views, flat)), "the earth model changes no viewshed here"
    if kw.get("azimuth"):
        whole = _viewsheds(hills, cands)
        assert all((a <= b).all() for a, b in zip(views, whole)) and sum(a.sum() for a in views) < 0.5 * sum(
            b.sum() for b in whole), "the field of view leaves most of each viewshed"
    k = 6
    chosen, gains, covered = _plain_greedy(views, k, areas)
    result = site_observers(hills, cands, k, workers=1, **kw)
    assert result.chosen.tolist() == chosen
    np.testing.assert_array_equal(result.table["gain_area"], gains)
    np.testing.assert_array_equal(result.table["gain_cells"], np.asarray(gains) / cell)
    np.testing.assert_array_equal(result.covered, covered)
    assert result.table["covered_cells"].iloc[-1] == covered.sum()
    assert result.total_area == hills.size * cell
    np.testing.assert_allclose(result.table["covered_share"], np.cumsum(gains) / (hills.size * cell), rtol=1e-15)
    assert result.evaluations >= len(cands)
    np.testing.assert_array_equal(result.table[["x", "y"]].to_numpy(), cands[chosen])


@pytest.mark.parametrize("k", [2, 3])
def test_greedy_against_the_brute_force_optimum(hills, k):
    cands = _random_candidates(hills, 8, seed=7)
    views = _viewsheds(hills, cands, observer_height=3.0)
    areas = np.full(hills.shape, hills.dx * hills.dy)
    best = _optimum(views, k, areas)
    result = site_observers(hills, cands, k, observer_height=3.0, workers=1)
    got = float(result.table["covered_area"].iloc[-1])
    assert (1 - 1 / math.e) * best <= got <= best
    assert best <= result.bound
    assert result.bound <= float(sum(sorted(areas[v].sum() for v in views)[-k:]))  # at most the first round's bound


def test_a_wall_splitting_the_terrain_gets_one_observer_on_each_side():
    z = np.zeros((9, 11))
    z[:, 5] = 20.0  # a wall along x = 5, the whole height of the grid
    g = HeightGrid(z)
    west = [[1.0, 2.0], [3.0, 6.0]]
    east = [[7.0, 4.0], [9.0, 8.0]]
    cands = west + east
    # each side sees itself and the crest (hand-worked: flat ground, eyes 1.5 m up, a 20 m wall)
    for c in west:
        np.testing.assert_array_equal(viewshed(g, c, observer_height=1.5), np.tile(np.arange(11) <= 5, (9, 1)))
    result = site_observers(g, cands, 2, observer_height=1.5, workers=1)
    assert result.chosen.tolist() == [0, 2]  # ties to the lowest index: the first west, then the first east
    assert result.table["gain_cells"].tolist() == [9 * 6, 9 * 5]
    assert result.table["covered_share"].tolist() == [54 / 99, 1.0]
    assert result.covered.all()
    one = site_observers(g, east + west, 1, observer_height=1.5, workers=1)
    assert one.chosen.tolist() == [0]  # the east candidates come first now: 54 samples against 54, the lowest index
    assert one.table["gain_cells"].tolist() == [54]


def test_rectilinear_grid_counts_each_samples_cell_area():
    base = synthetic_terrain("ridges", size=21, seed=2)
    xs = np.cumsum(np.r_[0.0, np.linspace(20.0, 60.0, 20)])  # spacing growing west to east
    ys = np.cumsum(np.r_[0.0, np.linspace(50.0, 25.0, 20)])
    g = HeightGrid.from_coords(base.z, xs, ys)
    assert not g.is_uniform
    # the cells around the samples, by hand: half-way to each neighbour, a full spacing at the ends
    wx = np.r_[xs[1] - xs[0], (xs[2:] - xs[:-2]) / 2, xs[-1] - xs[-2]]
    wy = np.r_[ys[1] - ys[0], (ys[2:] - ys[:-2]) / 2, ys[-1] - ys[-2]]
    areas = wy[:, None] * wx[None, :]
    np.testing.assert_allclose(sample_areas(g), areas, rtol=1e-15)
    cands = _random_candidates(g, 10, seed=3)
    views = _viewsheds(g, cands, observer_height=2.0)
    chosen, gains, covered = _plain_greedy(views, 4, areas)
    result = site_observers(g, cands, 4, observer_height=2.0, workers=1)
    assert result.chosen.tolist() == chosen
    np.testing.assert_allclose(result.table["gain_area"], gains, rtol=1e-12)
    assert result.table["gain_cells"].tolist() == [int((views[i] & ~np.logical_or.reduce(
        [views[j] for j in chosen[:n]] + [np.zeros(g.shape, bool)])).sum()) for n, i in enumerate(chosen)]
    np.testing.assert_allclose(result.total_area, areas.sum(), rtol=1e-12)
    np.testing.assert_array_equal(result.covered, covered)


def test_nodata_samples_cover_nothing_and_count_nowhere():
    g = bundled_terrain("hills").crop(rows=(0, 30), cols=(0, 30))
    z = g.z.copy()
    z[20:, 20:] = np.nan
    g = g.copy_with(z)
    cands = candidate_grid(g, 6)
    # rows and cols start at (30 - 1) % 6 // 2 = 2: 2, 8, 14, 20, 26; the four with r, c >= 20 are nodata
    assert len(cands) == 25 - 4
    result = site_observers(g, cands, 3, workers=1)
    assert not result.covered[~np.isfinite(z)].any()
    assert result.total_area == np.isfinite(z).sum() * g.dx * g.dy


def test_candidates_as_eyes_and_heights_per_candidate(hills):
    cands = _random_candidates(hills, 6, seed=5)
    heights = np.array([0.0, 5.0, 1.0, 20.0, 2.0, 8.0])
    views = [viewshed(hills, c, observer_height=h) for c, h in zip(cands, heights)]
    chosen, _, _ = _plain_greedy(views, 3, np.ones(hills.shape))
    assert site_observers(hills, cands, 3, observer_height=heights, workers=1).chosen.tolist() == chosen
    eyes = np.column_stack([cands, hills.height_at(cands) + heights])
    by_eyes = site_observers(hills, eyes, 3, workers=1)
    assert by_eyes.chosen.tolist() == chosen
    np.testing.assert_allclose(by_eyes.table["eye"], eyes[chosen, 2], rtol=1e-15)


def test_workers_give_the_same_choice(hills):
    cands = candidate_grid(hills, 5)
    here = site_observers(hills, cands, 4, workers=1)
    there = site_observers(hills, cands, 4, workers=2)
    assert here.chosen.tolist() == there.chosen.tolist()
    np.testing.assert_array_equal(here.covered, there.covered)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(1, 9), k=st.integers(1, 9), h=st.sampled_from([0.0, 1.7, 15.0]))
def test_lazy_is_plain_greedy_on_random_terrains(seed, n, k, h):
    k = min(k, n)
    g = synthetic_terrain(["hills", "ridges", "mesas"][seed % 3], size=17, seed=seed)
    cands = _random_candidates(g, n, seed)
    views = _viewsheds(g, cands, observer_height=h)
    chosen, gains, covered = _plain_greedy(views, k, np.ones(g.shape))
    result = site_observers(g, cands, k, observer_height=h, workers=1)
    assert result.chosen.tolist() == chosen
    assert result.table["gain_cells"].tolist() == gains
    np.testing.assert_array_equal(result.covered, covered)
    assert result.bound >= result.table["covered_area"].iloc[-1]


# ----------------------------------------------------------------- the candidate lattice
def test_candidate_grid_by_hand():
    g = HeightGrid(np.zeros((7, 10)), dx=2.0, dy=3.0, origin=(100.0, 200.0))
    # rows: (7 - 1) % 3 = 0 -> start 0: 0, 3, 6; cols: (10 - 1) % 3 = 0 -> 0, 3, 6, 9
    got = candidate_grid(g, 3)
    expected = [(100.0 + 2 * c, 200.0 + 3 * r) for r in (0, 3, 6) for c in (0, 3, 6, 9)]
    assert got.tolist() == [list(p) for p in expected]
    # (7 - 1) % 4 = 2 -> start 1: rows 1, 5; (10 - 1) % 4 = 1 -> start 0: cols 0, 4, 8
    assert candidate_grid(g, 4).tolist() == [[100.0 + 2 * c, 200.0 + 3 * r] for r in (1, 5) for c in (0, 4, 8)]
    assert len(candidate_grid(g, 1)) == 70


def test_candidate_grid_leaves_out_samples_off_the_surface():
    z = np.zeros((5, 5))
    z[2, 2] = np.nan  # every triangle around (2, 2) is absent
    z[0, 4] = np.nan
    got = candidate_grid(HeightGrid(z), 2)
    assert got.tolist() == [[0.0, 0.0], [2.0, 0.0], [0.0, 2.0], [4.0, 2.0], [0.0, 4.0], [2.0, 4.0], [4.0, 4.0]]


# ----------------------------------------------------------------- bad input
@pytest.mark.parametrize(("k", "error", "match"), [
    (5, ValueError, r"k must be between 1 and the number of candidates \(4\), got 5"),
    (0, ValueError, r"k must be between 1 and the number of candidates \(4\), got 0"),
    (-1, ValueError, r"k must be between 1 .* got -1"),
    (2.0, TypeError, r"k must be an integer .* got "),
    (True, TypeError, r"k must be an integer"),
])
def test_bad_k(hills, k, error, match):
    with pytest.raises(error, match=match):
        site_observers(hills, _random_candidates(hills, 4, 0), k, workers=1)


def test_bad_candidates(hills):
    cands = _random_candidates(hills, 4, 0)
    cands[2] = (2000.0, 10.0)
    with pytest.raises(OutsideFootprintError, match=r"candidates\[2\] = \(2000.0, 10.0\) is outside .*1 of 4 candidates"):
        site_observers(hills, cands, 2, workers=1)
    with pytest.raises(ValueError, match=r"candidates must be a 2-D array"):
        site_observers(hills, [1.0, 2.0], 1)
    with pytest.raises(ValueError, match=r"candidates must hold at least one"):
        site_observers(hills, np.zeros((0, 2)), 1)
    with pytest.raises(ValueError, match=r"step must be >= 1, got 0"):
        candidate_grid(hills, 0)
    with pytest.raises(TypeError, match=r"step must be an integer"):
        candidate_grid(hills, 2.5)
    with pytest.raises(TypeError, match=r"terrain must be a terrainvis.HeightGrid"):
        candidate_grid(hills.to_tin(), 2)


def test_memory_is_checked_before_the_viewsheds(hills, monkeypatch):
    import terrainvis.core.memory as memory

    monkeypatch.setattr(memory, "available_memory", lambda: 10_000)
    with pytest.raises(NotEnoughMemoryError, match=r"siting among 100 candidates on 33x33 samples \(13,700 bytes"):
        site_observers(hills, _random_candidates(hills, 100, 0), 3, workers=1)


def test_siting_figure_draws_the_curve_of_the_result(hills):
    from terrainvis.experiment import plot

    cands = candidate_grid(hills, 8)
    result = site_observers(hills, cands, 3, workers=1)
    fig = plot.siting(hills, result, candidates=cands)
    curve = fig.axes[1]
    covered = next(ln for ln in curve.get_lines() if ln.get_label() == "covered")
    np.testing.assert_allclose(covered.get_ydata(), 100 * np.r_[0.0, result.table["covered_share"]], rtol=1e-12)
    assert [round(p.get_height(), 9) for p in curve.patches] == [
        round(100 * g / result.total_area, 9) for g in result.table["gain_area"]]
    labels = [t.get_text() for t in fig.axes[0].texts]
    assert labels == ["1", "2", "3"]
    with pytest.raises(TypeError, match="result must be a SitingResult"):
        plot.siting(hills, object())
