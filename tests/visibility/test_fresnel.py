"""The first Fresnel zone's clearance along a radio path (terrainvis.visibility.fresnel; issue 30, part 5).

References, independent of the module's piecewise minimisation:
* closed forms worked by hand on flat ground (equal and unequal antenna heights, with and
  without earth curvature) and over a knife edge;
* dense sampling of ``(line - surface - bulge) / r1`` with ``HeightGrid.height_at``: the
  exact minimum is at most every sampled value, within a tiny margin of the densest
  sampling around it, and the reported point's own ratio recomputed from its position.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import terrainvis as tv
from terrainvis import HeightGrid, bundled_terrain
from terrainvis.cli import main
from terrainvis.visibility.fresnel import SPEED_OF_LIGHT, fresnel_clearance, fresnel_radius

#: A frequency whose wavelength is 0.1 m (to rounding): lambda L = 100 on a 1 km path.
F_01 = SPEED_OF_LIGHT / 0.1


def _ratio(grid, a, b, t, frequency, kc=0.0):
    """(line - surface - kc d1 d2) / r1 at parameters t, from the surface's own heights."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    L = math.hypot(*(b - a)[:2])
    p = a[None, :2] + t[:, None] * (b - a)[None, :2]
    clear = a[2] + t * (b[2] - a[2]) - grid.height_at(p) - kc * L * L * t * (1 - t)
    return clear / np.sqrt(SPEED_OF_LIGHT / frequency * L * t * (1 - t))


# ----------------------------------------------------------------- by hand
def test_flat_ground_equal_heights_worst_mid_way():
    """Clearance 10 everywhere, r1 largest mid-way: sqrt(0.1 * 500 * 500 / 1000) = 5, so 2 radii."""
    g = HeightGrid(np.zeros((3, 35)), dx=30.0, dy=30.0)
    r = fresnel_clearance(g, [0.0, 30.0, 10.0], [1000.0, 30.0, 10.0], F_01)
    assert r.fraction == pytest.approx(2.0, rel=1e-12)
    assert r.distance == pytest.approx(500.0, rel=1e-12) and r.x == pytest.approx(500.0) and r.y == 30.0
    assert r.clearance == pytest.approx(10.0, rel=1e-12) and r.radius == pytest.approx(5.0, rel=1e-12)
    assert r.clear_60 and r.wavelength == pytest.approx(0.1, rel=1e-15)


def test_flat_ground_unequal_heights_worst_off_the_grid_lines():
    """Heights h_a, h_b over flat ground: the clearance h_a + (h_b - h_a) t over r1 = sqrt(lambda L
    t (1 - t)) is least at t = h_a / (h_a + h_b), where it is 2 sqrt(h_a h_b / (lambda L)).
    With 10 and 40 m, lambda L = 100: 4 radii at 200 m, between the grid lines at 180 and 210."""
    g = HeightGrid(np.zeros((3, 35)), dx=30.0, dy=30.0)
    r = fresnel_clearance(g, [0.0, 30.0, 10.0], [1000.0, 30.0, 40.0], F_01)
    assert r.fraction == pytest.approx(4.0, rel=1e-12)
    assert r.distance == pytest.approx(200.0, rel=1e-9) and r.t == pytest.approx(0.2, rel=1e-9)
    assert r.clearance == pytest.approx(16.0, rel=1e-12)  # 10 + 30 * 0.2
    # on a longer path the same heights fall below 0.6: 2 sqrt(400 / (0.1 * 1e6)) = 0.1265
    big = HeightGrid(np.zeros((3, 1001)), dx=1000.0, dy=1000.0)
    far = fresnel_clearance(big, [0.0, 1000.0, 10.0], [1e6, 1000.0, 40.0], F_01)
    assert far.fraction == pytest.approx(2 * math.sqrt(400 / 1e5), rel=1e-12) and not far.clear_60


def test_curvature_lowers_the_clearance_by_the_bulge():
    """Equal heights h over flat ground on a curved earth: (h - B t (1 - t)) / (K sqrt(t (1 - t)))
    decreases with t (1 - t), so it is least mid-way: (10 - 1.25) / 5 = 1.75 with B = c L^2 / (2 R)
    = 1e6 / 2e5 = 5; curvature 0 gives 2."""
    g = HeightGrid(np.zeros((3, 35)), dx=30.0, dy=30.0)
    curved = fresnel_clearance(g, [0.0, 30.0, 10.0], [1000.0, 30.0, 10.0], F_01, curvature=1.0, earth_radius=1e5)
    assert curved.fraction == pytest.approx(1.75, rel=1e-12) and curved.distance == pytest.approx(500.0)
    assert curved.clearance == pytest.approx(8.75, rel=1e-12)
    # unequal heights on the curved earth: no closed form for the place, but the value at the
    # reported place is the formula's, and nowhere along the path is lower (sampled finely)
    r = fresnel_clearance(g, [0.0, 30.0, 10.0], [1000.0, 30.0, 40.0], F_01, curvature=1.0, earth_radius=1e5)
    t = np.linspace(0, 1, 200_001)[1:-1]
    kc = 1.0 / 2e5
    ref = _ratio(g, [0.0, 30.0, 10.0], [1000.0, 30.0, 40.0], t, F_01, kc)
    assert r.fraction <= ref.min() + 1e-12 and ref.min() - r.fraction < 1e-9
    u = r.t * (1 - r.t)
    assert r.fraction == pytest.approx((10 + 30 * r.t - 5.0 * u) / math.sqrt(100 * u), rel=1e-12)


def test_knife_edge_worst_at_the_ridge():
    """A 6 m wall on flat ground at x = 300 between antennas 10 m up: 4 m of clearance there, where
    r1 = sqrt(0.1 * 300 * 700 / 1000) = 4.583, so 0.8729 radii (mid-way: 10 / 5 = 2)."""
    z = np.zeros((3, 11))
    z[:, 3] = 6.0
    g = HeightGrid(z, dx=100.0, dy=100.0)
    r = fresnel_clearance(g, [0.0, 100.0, 10.0], [1000.0, 100.0, 10.0], F_01)
    assert r.distance == pytest.approx(300.0, rel=1e-12)
    assert r.fraction == pytest.approx(4.0 / math.sqrt(0.1 * 300 * 700 / 1000), rel=1e-12)
    assert r.clear_60
    # taller wall: 9.5 m leaves 0.5 m, 0.109 radii, below the 60 % rule
    z[:, 3] = 9.5
    low = fresnel_clearance(HeightGrid(z, dx=100.0, dy=100.0), [0.0, 100.0, 10.0], [1000.0, 100.0, 10.0], F_01)
    assert low.fraction == pytest.approx(0.5 / math.sqrt(21.0), rel=1e-12) and not low.clear_60


def test_fresnel_radius_formula():
    # 2.4 GHz, 10 km, mid-way: lambda = 0.1249 m, r1 = sqrt(lambda * 2500) = 17.67 m
    assert float(fresnel_radius(5000.0, 5000.0, 2.4e9)) == pytest.approx(math.sqrt(SPEED_OF_LIGHT / 2.4e9 * 2500))
    # ITU-R P.526's practical units, r1 = 550 sqrt(d1 d2 / ((d1 + d2) f)), km and MHz (550 rounds
    # sqrt(c / 1000) = 547.5 up by 0.45 %): 16 and 24 km at 4 GHz give 26.94 m
    assert float(fresnel_radius(16_000.0, 24_000.0, 4e9)) == pytest.approx(550 * math.sqrt(16 * 24 / (40 * 4000)),
                                                                            rel=0.0046)


# ----------------------------------------------------------------- against dense sampling
@pytest.mark.parametrize("curvature", [0.0, 0.85714])
@pytest.mark.parametrize("seed", range(4))
def test_exact_minimum_is_below_every_sample_and_matches_the_densest(seed, curvature):
    g = bundled_terrain("hills").crop(slice(10, 70), slice(20, 90))
    rng = np.random.default_rng(seed)
    xmin, xmax, ymin, ymax = g.extent
    xy = np.column_stack([rng.uniform(xmin, xmax, 2), rng.uniform(ymin, ymax, 2)])
    heights = rng.uniform(5.0, 40.0, 2)
    a = np.r_[xy[0], g.height_at(xy[:1])[0] + heights[0]]
    b = np.r_[xy[1], g.height_at(xy[1:])[0] + heights[1]]
    earth = {"curvature": curvature, "earth_radius": 30_000.0}  # a small earth, so the bulge matters
    kc = curvature / 60_000.0
    freq = 1.5e8
    r = fresnel_clearance(g, a, b, freq, **earth, profile=True)
    t = np.linspace(0.0, 1.0, 400_001)[1:-1]
    sampled = _ratio(g, a, b, t, freq, kc)
    scale = 1e-12 * max(1.0, abs(r.fraction))
    assert r.fraction <= sampled.min() + scale  # exact: no sample lies below it
    # the densest sampling around the reported place comes within rounding of it
    near = np.linspace(max(r.t - 1e-5, 1e-9), min(r.t + 1e-5, 1 - 1e-9), 200_001)
    dense = _ratio(g, a, b, near, freq, kc)
    assert r.fraction <= dense.min() + scale and dense.min() - r.fraction < 1e-9 * max(1.0, abs(r.fraction))
    # the reported point's own ratio, recomputed from its position
    assert _ratio(g, a, b, np.array([r.t]), freq, kc)[0] == pytest.approx(r.fraction, rel=1e-9, abs=1e-12)
    assert (r.x, r.y) == pytest.approx(tuple(a[:2] + r.t * (b - a)[:2]))
    prof = r.profile
    assert prof["fraction"].min() == r.fraction and np.all(np.diff(prof["t"]) > 0)
    assert r.clear_60 == (r.fraction >= 0.6)


def test_curvature_changes_the_answer_on_a_real_path():
    g = bundled_terrain("ridges")
    a = np.r_[300.0, 400.0, g.height_at([[300.0, 400.0]])[0] + 30.0]
    b = np.r_[3300.0, 3000.0, g.height_at([[3300.0, 3000.0]])[0] + 30.0]
    flat = fresnel_clearance(g, a, b, 9e8)
    curved = fresnel_clearance(g, a, b, 9e8, curvature=1.0, earth_radius=20_000.0)
    assert curved.fraction < flat.fraction  # the bulge only lowers the clearance


# ----------------------------------------------------------------- input
def test_bad_input():
    g = HeightGrid(np.zeros((3, 11)), dx=100.0, dy=100.0)
    a, b = [0.0, 100.0, 10.0], [1000.0, 100.0, 10.0]
    for bad in (0.0, -2.4e9, float("nan"), float("inf")):
        with pytest.raises(ValueError, match=r"frequency must be finite and > 0"):
            fresnel_clearance(g, a, b, bad)
    with pytest.raises(TypeError, match="frequency must be a real number"):
        fresnel_clearance(g, a, b, "2.4GHz")
    with pytest.raises(tv.errors.OutsideFootprintError, match="b has 1 point"):
        fresnel_clearance(g, a, [5000.0, 100.0, 10.0], 1e9)
    with pytest.raises(ValueError, match="a and b must be farther apart than twice the trim length"):
        fresnel_clearance(g, a, a, 1e9)
    holes = np.zeros((3, 11))
    holes[1, 5] = np.nan
    with pytest.raises(tv.errors.NodataError):
        fresnel_clearance(HeightGrid(holes), [0.0, 1.0, 1.0], [10.0, 1.0, 1.0], 1e9)


# ----------------------------------------------------------------- command line
def _run(capsys, argv):
    capsys.readouterr()
    code = main([str(v) for v in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_los_fresnel_reports_the_worst_point(capsys):
    code, out, err = _run(capsys, ["los", "hills", "--from", "300", "300", "--to", "3000", "3200", "--height", "30",
                                   "--target-height", "30", "--fresnel", "4.5e8", "--curvature", "0.75"])
    assert code == 0, err
    g = bundled_terrain("hills")
    a = np.r_[300.0, 300.0, g.height_at([[300.0, 300.0]])[0] + 30.0]
    b = np.r_[3000.0, 3200.0, g.height_at([[3000.0, 3200.0]])[0] + 30.0]
    r = fresnel_clearance(g, a, b, 4.5e8, curvature=0.75)
    line = out.splitlines()[2]
    assert line == (f"    first Fresnel zone at 450 MHz (wavelength {r.wavelength:.4g}): worst clearance {r.fraction:.4g} "
                    f"of its radius ({r.clearance:.4g} of {r.radius:.4g}) at ({r.x:g}, {r.y:g}), {r.distance:.6g} "
                    f"from the observer; " + ("at least" if r.clear_60 else "less than") + " 60 % of the zone clear")


def test_los_fresnel_with_pairs_and_a_blocked_link(tmp_path, capsys):
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("x1,y1,x2,y2\n300,300,3000,3200\n200,3000,3400,200\n")
    code, out, err = _run(capsys, ["los", "ridges", "--pairs", pairs, "--height", "2", "--fresnel", "2.4e9"])
    assert code == 0, err
    lines = out.splitlines()
    assert len(lines) == 5 and all(s.startswith("    first Fresnel zone at 2.4 GHz") for s in lines[2::2])
    assert "blocked" in out and "less than 60 % of the zone clear" in out


@pytest.mark.parametrize("value", ["0", "-2.4e9", "nan"])
def test_los_fresnel_bad_frequency_is_one_line_naming_the_flag(capsys, value):
    code, out, err = _run(capsys, ["los", "hills", "--from", "300", "300", "--to", "3000", "3200", f"--fresnel={value}"])
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "argument --fresnel: expected a" in err and repr(value) in err


def test_los_png_draws_the_profile(tmp_path, capsys):
    png = tmp_path / "p.png"
    argv = ["los", "hills", "--from", "300", "300", "--to", "3000", "3200", "--height", "30", "--fresnel", "4.5e8",
            "--png", png]
    code, out, err = _run(capsys, argv)
    assert code == 0, err
    assert png.stat().st_size > 0 and out.splitlines()[-1] == f"  wrote {png}"
    for extra, message in ((["--png", tmp_path / "q.png"], "--png draws the profile of one radio path"),
                           (["--fresnel", "1e9", "--png", tmp_path / "q.jpg"], "--png must end in .png")):
        code, out, err = _run(capsys, ["los", "hills", "--from", "300", "300", "--to", "3000", "3200", *extra])
        assert code == 2 and message in err and len(err.strip().splitlines()) == 1


def test_profile_figure_marks_the_worst_place():
    pytest.importorskip("matplotlib")
    from terrainvis.experiment import plot

    g = HeightGrid(np.zeros((3, 35)), dx=30.0, dy=30.0)
    a, b = [0.0, 30.0, 10.0], [1000.0, 30.0, 40.0]
    r = fresnel_clearance(g, a, b, F_01, profile=True)
    fig = plot.fresnel_profile(r, a, b)
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert labels[-1] == "worst: 4.00 r1 at 200 (60 % clear)"  # the hand-worked case above
    with pytest.raises(ValueError, match="profile=True"):
        plot.fresnel_profile(fresnel_clearance(g, a, b, F_01), a, b)


def test_the_grids_tin_gives_the_same_answer():
    g = bundled_terrain("mesas").crop(slice(30, 60), slice(40, 80))
    a = np.r_[g.xs[2] + 7.0, g.ys[3] + 4.0, 0.0]
    b = np.r_[g.xs[37] - 3.0, g.ys[26] + 1.0, 0.0]
    a[2] = g.height_at([a[:2]])[0] + 12.0
    b[2] = g.height_at([b[:2]])[0] + 25.0
    for curvature in (0.0, 1.0):
        on_grid = fresnel_clearance(g, a, b, 4e8, curvature=curvature, earth_radius=10_000.0)
        on_tin = fresnel_clearance(g.to_tin(), a, b, 4e8, curvature=curvature, earth_radius=10_000.0)
        assert on_tin.fraction == pytest.approx(on_grid.fraction, rel=1e-9, abs=1e-12)
        assert on_tin.distance == pytest.approx(on_grid.distance, rel=1e-6)
