"""Field-of-view limits of viewsheds (terrainvis.visibility.viewsheds.field_of_view; issue 30, part 2).

References, independent of the module's code:
* a per-cell loop with ``math.atan2`` of every target against the observer, whose
  azimuth test is written as intervals (``start <= az <= end``, or the union of two
  intervals through north) rather than the module's modular offsets;
* the plain viewshed: inside the field every verdict must be the plain one (a field of
  view only masks), so ``viewshed(..., limits) == viewshed(...) & independent_mask``;
* hand-worked cases on flat 5x5 grids, where every sample is visible and the field alone
  decides.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from terrainvis import HeightGrid, bundled_terrain, cumulative_viewshed, synthetic_terrain, viewshed
from terrainvis.cli import main
from terrainvis.visibility import curvature_coefficient, field_of_view, field_of_view_mask
from terrainvis.visibility.viewsheds.sweep import _surface_at


# ----------------------------------------------------------------- reference
def _nearest(grid, obs):
    return int(np.argmin(np.abs(grid.ys - obs[1]))), int(np.argmin(np.abs(grid.xs - obs[0])))


def _reference_mask(grid, obs, *, azimuth=None, vertical=None, min_distance=None, max_distance=None,
                    h_o=1.7, h_t=0.0, curvature=0.0, earth_radius=6378137.0):
    """The field of view cell by cell, with math.atan2 (see the module docstring)."""
    ez = _surface_at(grid, float(obs[0]), float(obs[1])) + h_o
    kc = curvature / (2.0 * earth_radius)
    out = np.zeros(grid.shape, dtype=bool)
    for r, y in enumerate(grid.ys):
        for c, x in enumerate(grid.xs):
            dx, dy = float(x - obs[0]), float(y - obs[1])
            d = math.hypot(dx, dy)
            ok = True
            if min_distance is not None:
                ok &= d >= min_distance
            if max_distance is not None:
                ok &= d <= max_distance
            if azimuth is not None:
                az = math.degrees(math.atan2(dx, dy))
                az = az + 360.0 if az < 0 else az
                start, end = azimuth
                if (start, end) == (0, 360):
                    pass
                elif start <= end:
                    ok &= start <= az <= end
                else:  # through north: [start, 360) or [0, end]
                    ok &= az >= start or az <= end
            if vertical is not None:
                angle = math.degrees(math.atan2(grid.z[r, c] + h_t - kc * d * d - ez, d))
                ok &= vertical[0] <= angle <= vertical[1]
            out[r, c] = ok
    # the observer's own sample is exempt from every limit but min_distance (its distance is defined)
    r, c = _nearest(grid, obs)
    out[r, c] = min_distance is None or math.hypot(grid.xs[c] - obs[0], grid.ys[r] - obs[1]) >= min_distance
    return out


HILLS = synthetic_terrain("hills", size=33)  # 960 m across, 30 m cells, relief 150 m


def _observers(g):
    """Inside a cell, on a sample, on the west edge, in the south-east corner."""
    return [
        (g.xs[11] + 7.3, g.ys[19] + 12.1),
        (g.xs[16], g.ys[16]),
        (g.xs[0], g.ys[13] + 4.0),
        (g.xs[-1], g.ys[0]),
    ]


LIMITS = [
    {"azimuth": (300.0, 60.0)},  # through north
    {"azimuth": (0.0, 360.0)},  # the full circle
    {"azimuth": (90.0, 180.0)},
    {"azimuth": (170.0, 10.0)},  # more than half the circle, through north
    {"vertical": (-3.0, 2.0)},
    {"min_distance": 200.0},
    {"min_distance": 150.0, "max_distance": 600.0, "azimuth": (45.0, 225.0), "vertical": (-10.0, 10.0)},
]


@pytest.mark.parametrize("limits", LIMITS, ids=lambda d: "-".join(f"{k}={v}" for k, v in d.items()))
@pytest.mark.parametrize("curvature", [0.0, 1.0])
def test_only_masks_and_the_mask_is_the_reference(limits, curvature):
    # curvature 1 with a 20 km earth: a drop of 9 m at 600 m, so the vertical limits move
    earth = {"curvature": curvature, "earth_radius": 20_000.0}
    for obs in _observers(HILLS):
        plain = viewshed(HILLS, obs, observer_height=4.0, target_height=1.0, **earth)
        limited = viewshed(HILLS, obs, observer_height=4.0, target_height=1.0, **earth, **limits)
        ref = _reference_mask(HILLS, obs, h_o=4.0, h_t=1.0, **earth, **limits)
        np.testing.assert_array_equal(limited, plain & ref)
        if limits != {"azimuth": (0.0, 360.0)} and obs != (HILLS.xs[-1], HILLS.ys[0]):
            # the limits matter here: the test could fail (some visible samples are cut, some kept)
            assert (plain & ~ref).any() and (plain & ref).sum() > 1
        assert not (limited & ~plain).any()


def test_curvature_moves_the_vertical_limit():
    """The elevation angle is that of the target lowered by c d^2 / (2 R): on flat ground with
    the eye 10 above it, a target at distance d is atan(10 / d + c d / (2 R)) below the
    horizontal. With c / (2 R) = 1 / 200 km that is at least atan(2 sqrt(10 / 200 km)) = 0.81
    degrees at every distance (least at d = 1414 m), so no target is within -0.6; on a flat
    earth atan(10 / d) <= 0.6 degrees from d = 955 m on."""
    g = HeightGrid(np.zeros((2, 41)), dx=100.0)  # row 0 is a flat line 4 km long
    obs = (0.0, 0.0)
    earth = {"curvature": 1.0, "earth_radius": 100_000.0}
    curved = field_of_view_mask(g, obs, field_of_view(vertical=(-0.6, 0.0)), observer_height=10.0, **earth)
    assert curved[0, 0] and curved[0].sum() == 1  # the observer's own sample alone
    flat = field_of_view_mask(g, obs, field_of_view(vertical=(-0.6, 0.0)), observer_height=10.0)
    np.testing.assert_array_equal(flat[0, 1:], g.xs[1:] >= 1000.0)
    # a looser limit, -0.85 degrees: the curved angle is 0.859 at 1 and 2 km, 0.81 at 1.4 km
    loose = field_of_view_mask(g, obs, field_of_view(vertical=(-0.85, 0.0)), observer_height=10.0, **earth)
    d = g.xs
    np.testing.assert_array_equal(loose[0, 1:], np.degrees(np.arctan(10.0 / d[1:] + d[1:] / 200_000.0)) <= 0.85)
    assert loose[0, 11:20].all() and not loose[0, 10] and not loose[0, 20]


# ----------------------------------------------------------------- hand-worked cases
FLAT = HeightGrid(np.zeros((5, 5)))  # x, y = 0..4; everything is visible from an eye above it
CENTRE = (2.0, 2.0)  # on a sample


def _flat(**limits):
    return viewshed(FLAT, CENTRE, observer_height=1.0, **limits).astype(int)


def test_flat_grid_sees_everything():
    assert _flat().all()


def test_a_quadrant_holds_both_of_its_boundary_rays():
    # rows are y (row 0 south), columns x; (0, 90) is north to east, both axes included
    expected = np.zeros((5, 5), int)
    expected[2:, 2:] = 1
    np.testing.assert_array_equal(_flat(azimuth=(0, 90)), expected)
    # the diagonal at exactly 45 degrees is a boundary too: (45, 90) keeps it, (46, 90) does not
    half = _flat(azimuth=(45, 90))
    assert half[3, 3] == 1 and half[4, 4] == 1 and half[4, 3] == 0 and half[3, 4] == 1 and half[2, 4] == 1
    assert _flat(azimuth=(46, 90))[3, 3] == 0
    south_west = np.zeros((5, 5), int)
    south_west[:3, :3] = 1
    np.testing.assert_array_equal(_flat(azimuth=(180, 270)), south_west)


def test_a_range_through_north_and_the_full_circle():
    north = np.zeros((5, 5), int)
    north[2:, :] = 1  # 270 through 0 to 90: the northern half with the east-west axis
    np.testing.assert_array_equal(_flat(azimuth=(270, 90)), north)
    south = np.zeros((5, 5), int)
    south[:3, :] = 1
    np.testing.assert_array_equal(_flat(azimuth=(90, 270)), south)
    np.testing.assert_array_equal(_flat(azimuth=(0, 360)), np.ones((5, 5), int))
    # 360 as an end is north: (300, 360) holds due north (0) and the azimuths 315 and 333.4 of
    # (-1, 1), (-2, 2), (-1, 2), not 296.6 of (-2, 1) nor due east
    narrow = np.zeros((5, 5), int)
    narrow[2, 2] = narrow[3, 2] = narrow[3, 1] = narrow[4, 2] = narrow[4, 1] = narrow[4, 0] = 1
    np.testing.assert_array_equal(_flat(azimuth=(300, 360)), narrow)


def test_vertical_limits_on_a_flat_grid():
    """Eye 1 above flat ground: a target at distance d is atan(1 / d) below the horizontal."""
    d = np.hypot(*np.meshgrid(FLAT.xs - 2.0, FLAT.ys - 2.0))
    steep = _flat(vertical=(-45, 0))  # d = 1 is exactly -45 degrees: inclusive
    np.testing.assert_array_equal(steep, (d >= 1) | (d == 0))
    shallow = _flat(vertical=(-44.9, 0))  # d = 1 out, d = sqrt(2) (35.3 degrees below) in
    np.testing.assert_array_equal(shallow, (d > 1.1) | (d == 0))
    assert _flat(vertical=(0, 90)).sum() == 1  # every target is below the eye: the observer's own sample alone
    # the target height counts: targets 1 high are level with the eye (0 degrees)
    level = viewshed(FLAT, CENTRE, observer_height=1.0, target_height=1.0, vertical=(0, 0))
    assert level.all()


def test_distance_limits_are_inclusive_and_min_distance_leaves_out_the_observers_sample():
    """Issue 42, item 9: samples nearer than min_distance are False, the observer's own one too
    (it was kept, against the docstring); it stays exempt from max_distance and the angles."""
    d = np.hypot(*np.meshgrid(FLAT.xs - 2.0, FLAT.ys - 2.0))
    np.testing.assert_array_equal(_flat(min_distance=2.0), d >= 2)
    np.testing.assert_array_equal(_flat(min_distance=1.0, max_distance=2.0), (d >= 1) & (d <= 2))
    np.testing.assert_array_equal(_flat(max_distance=0.5), d == 0)
    # an observer inside a cell: its nearest sample (0, 0), 0.5 away, is left out by min_distance 3 (and not by
    # the azimuth limit); sample (4, 0) is 3.61 away at azimuth 94.8; (3, 0) is 2.62 away, (2, 0) at azimuth 100.6
    v = viewshed(FLAT, (0.4, 0.3), observer_height=1.0, min_distance=3.0, azimuth=(90, 100))
    expected = np.zeros((5, 5), bool)
    expected[0, 4] = True
    np.testing.assert_array_equal(v, expected)
    kept = viewshed(FLAT, (0.4, 0.3), observer_height=1.0, min_distance=0.5, azimuth=(90, 100))
    assert kept[0, 0] and kept[0, 3] and kept[0, 4] and kept.sum() == 3  # (0, 0) 0.5 away: not nearer than 0.5
    mask = field_of_view_mask(FLAT, (0.4, 0.3), field_of_view(min_distance=0.6))
    assert not mask[0, 0] and mask[0, 1]  # (0, 1) is 0.67 away


def test_observer_on_the_edge_of_the_grid():
    """On the west edge, looking west (180..360) sees only the edge column itself."""
    obs = (0.0, 2.0)
    v = viewshed(FLAT, obs, observer_height=1.0, azimuth=(180, 360))
    expected = np.zeros((5, 5), bool)
    expected[:, 0] = True  # due south (180) and due north (360) along the edge, both inclusive
    np.testing.assert_array_equal(v, expected)
    # just off the rays: nothing but the observer's own sample
    v = viewshed(FLAT, obs, observer_height=1.0, azimuth=(181, 359))
    assert v.sum() == 1 and v[2, 0]


# ----------------------------------------------------------------- bad input
@pytest.mark.parametrize("azimuth, expected", [
    ((-1, 10), "got (-1, 10)"), ((10, 361), "got (10, 361)"), ((0, float("nan")), "got (0, nan)"),
    ((10, 20, 30), "got (10, 20, 30)"),
])
def test_azimuth_out_of_range_names_argument_expected_and_received(azimuth, expected):
    with pytest.raises(ValueError) as e:
        viewshed(HILLS, (480.0, 480.0), azimuth=azimuth)
    msg = str(e.value)
    assert msg.startswith("azimuth must be two angles (start, end) in [0, 360] degrees clockwise from north")
    assert msg.endswith(expected)


@pytest.mark.parametrize("azimuth", [(30, 30), (0, 0), (360, 360), (360, 0), (0.5, 0.5)])
def test_an_empty_azimuth_range_is_refused(azimuth):
    with pytest.raises(ValueError, match=r"azimuth must span more than 0 degrees \(start != end; \(0, 360\) is"):
        viewshed(HILLS, (480.0, 480.0), azimuth=azimuth)


def test_bad_vertical_and_distance_limits():
    with pytest.raises(ValueError, match=r"vertical must be \(low, high\) with low <= high, got \(10, -10\)"):
        viewshed(HILLS, (480.0, 480.0), vertical=(10, -10))
    with pytest.raises(ValueError, match=r"vertical must be two angles \(low, high\) in \[-90, 90\] .*got \(-91, 0\)"):
        viewshed(HILLS, (480.0, 480.0), vertical=(-91, 0))
    with pytest.raises(ValueError, match="min_distance must not exceed max_distance, got 300 > 200"):
        viewshed(HILLS, (480.0, 480.0), min_distance=300, max_distance=200)
    with pytest.raises(ValueError, match="min_distance must be finite and >= 0"):
        cumulative_viewshed(HILLS, [(480.0, 480.0)], min_distance=-1)
    with pytest.raises(TypeError, match="azimuth must be two angles"):
        viewshed(HILLS, (480.0, 480.0), azimuth="north")


# ----------------------------------------------------------------- many observers, other targets, xarray
def test_cumulative_is_the_sum_of_the_observers_limited_viewsheds():
    g = bundled_terrain("ridges").crop(slice(20, 60), slice(30, 75))
    obs = np.array([[g.xs[5] + 3.0, g.ys[30] + 8.0], [g.xs[40], g.ys[4]], [g.xs[22] + 11.0, g.ys[19]]])
    limits = {"azimuth": (200.0, 20.0), "vertical": (-8.0, 3.0), "min_distance": 90.0, "max_distance": 900.0}
    earth = {"curvature": 0.85714, "earth_radius": 50_000.0}
    counts = cumulative_viewshed(g, obs, observer_height=[2.0, 6.0, 0.0], target_height=0.5, workers=1,
                                 **earth, **limits)
    expected = sum(viewshed(g, o, observer_height=h, target_height=0.5, **earth, **limits).astype(int)
                   for o, h in zip(obs, [2.0, 6.0, 0.0]))
    np.testing.assert_array_equal(counts, expected)
    plain = cumulative_viewshed(g, obs, observer_height=[2.0, 6.0, 0.0], target_height=0.5, workers=1, **earth)
    assert (plain > counts).any()  # the limits took something away


def test_other_targets_at_a_coarser_grid():
    at = HILLS.subsample(2)
    obs = (HILLS.xs[9] + 5.0, HILLS.ys[20] + 2.0)
    limits = {"azimuth": (100.0, 250.0), "vertical": (-6.0, 1.0)}
    v = viewshed(HILLS, obs, at=at, observer_height=3.0, **limits)
    plain = viewshed(HILLS, obs, at=at, observer_height=3.0)
    # the targets stand on HILLS's surface at at's samples (at's own heights are the same samples here)
    ref = _reference_mask(at, obs, h_o=3.0, azimuth=limits["azimuth"])
    np.testing.assert_array_equal(field_of_view_mask(HILLS, obs, field_of_view(azimuth=limits["azimuth"]), at=at), ref)
    assert not (v & ~plain).any() and (plain & ~v).any()


def test_north_of_a_dataarray_with_y_descending():
    """A raster's first row is its northern edge: after from_xarray, azimuth 0..90 is north-east."""
    xr = pytest.importorskip("xarray", reason="the xarray extra is not installed")
    z = np.zeros((7, 9))
    da = xr.DataArray(z, dims=("y", "x"), coords={"y": 1000.0 - 10.0 * np.arange(7), "x": 10.0 * np.arange(9)})
    g = HeightGrid.from_xarray(da)
    v = viewshed(g, (40.0, 970.0), observer_height=1.0, azimuth=(0, 90))
    X, Y = np.meshgrid(g.xs, g.ys)
    np.testing.assert_array_equal(v, (X >= 40.0) & (Y >= 970.0))
    back = g.copy_with(v.astype(float)).to_xarray()  # north-east in the DataArray's own coordinates
    assert float(back.sel(x=80.0, y=1000.0)) == 1.0 and float(back.sel(x=0.0, y=940.0)) == 0.0


# ----------------------------------------------------------------- command line
def _run(capsys, argv):
    capsys.readouterr()
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_viewshed_command_takes_the_field_of_view(tmp_path, capsys):
    from terrainvis import load_terrain

    code, out, err = _run(capsys, ["viewshed", "hills", "--observer", "1800", "1700", "-o", tmp_path / "v.npz",
                                   "--azimuth", "300", "60", "--vertical", "-10", "5", "--min-distance", "100",
                                   "--max-distance", "1500", "--curvature", "1"])
    assert code == 0, err
    grid = bundled_terrain("hills")
    expected = viewshed(grid, (1800.0, 1700.0), azimuth=(300, 60), vertical=(-10, 5), min_distance=100,
                        max_distance=1500, curvature=1.0)
    saved = load_terrain(tmp_path / "v.npz")
    np.testing.assert_array_equal(saved.z, expected.astype(float))
    assert saved.attrs["viewshed_azimuth"] == [300.0, 60.0] and saved.attrs["viewshed_min_distance"] == 100.0
    assert ("  field of view: azimuth 300 to 60 degrees clockwise (through north), vertical angle -10 to 5 degrees, "
            "at least 100 away, within 1500") in out.splitlines()
    assert f"visible {int(expected.sum()):,} of 14,400 samples" in out


def test_cumulative_command_takes_the_field_of_view(tmp_path, capsys):
    from terrainvis import load_terrain

    obs = tmp_path / "obs.csv"
    obs.write_text("x,y\n300,400\n2000,2500\n3300,900\n")
    code, out, err = _run(capsys, ["cumulative", "ridges", "--observers", obs, "-o", tmp_path / "c.npz",
                                   "--workers", "1", "--azimuth", "90", "270", "--min-distance", "300"])
    assert code == 0, err
    expected = cumulative_viewshed(bundled_terrain("ridges"), [(300.0, 400.0), (2000.0, 2500.0), (3300.0, 900.0)],
                                   azimuth=(90, 270), min_distance=300.0, workers=1)
    np.testing.assert_array_equal(load_terrain(tmp_path / "c.npz").z, expected)
    assert "target 0, azimuth 90 to 270 degrees clockwise, at least 300 away" in out


@pytest.mark.parametrize("flags, message", [
    (["--azimuth", "10", "400"], "--azimuth must be two angles (start, end) in [0, 360] degrees clockwise from "
                                 "north, got (10, 400)"),
    (["--azimuth", "-5", "10"], "--azimuth must be two angles (start, end) in [0, 360] degrees clockwise from "
                                "north, got (-5, 10)"),
    (["--azimuth", "45", "45"], "--azimuth must span more than 0 degrees"),
    (["--vertical", "5", "-5"], "--vertical must be (low, high) with low <= high, got (5, -5) (reversed)"),
    (["--vertical", "-100", "5"], "--vertical must be two angles (low, high) in [-90, 90]"),
    (["--min-distance", "500", "--max-distance", "100"], "--min-distance must not exceed --max-distance, got 500 > 100"),
    (["--min-distance", "-1"], "argument --min-distance: expected a distance >= 0, got '-1'"),
])
@pytest.mark.parametrize("command", ["viewshed", "cumulative"])
def test_command_line_mistakes_are_one_line_naming_the_flag(tmp_path, capsys, command, flags, message):
    obs = tmp_path / "obs.csv"
    obs.write_text("x,y\n300,400\n")
    where = ["--observer", "300", "400"] if command == "viewshed" else ["--observers", obs]
    code, out, err = _run(capsys, [command, "hills", *where, "-o", tmp_path / "v.npz", *flags])
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and message in err
    assert not (tmp_path / "v.npz").exists()


def test_the_png_draws_the_field_apart(tmp_path):
    pytest.importorskip("matplotlib")
    from terrainvis.experiment import plot

    obs = (480.0, 480.0)
    fov = field_of_view(azimuth=(300, 60), max_distance=400.0)
    field = field_of_view_mask(HILLS, obs, fov)
    vis = viewshed(HILLS, obs, azimuth=(300, 60), max_distance=400.0)
    fig = plot.viewshed(HILLS, vis, observer=obs, field=field)
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    share = 100 * vis[field].mean()
    assert labels == [f"visible ({share:.1f} % of the field)", "hidden", "outside the field of view"]
    with pytest.raises(ValueError, match=r"field must have the terrain's shape \(33, 33\), got \(3, 3\)"):
        plot.viewshed(HILLS, vis, field=np.ones((3, 3), bool))


_angle = st.floats(0.0, 360.0, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(start=_angle, end=_angle, ox=st.floats(0.0, 4.0), oy=st.floats(0.0, 4.0))
def test_a_range_and_its_complement_cover_the_circle_and_meet_on_their_rays(start, end, ox, oy):
    """(start, end) and (end, start) together hold every sample, and share only the samples on the
    two boundary rays, to rounding (1e-9 degrees), and the observer's own sample."""
    if (end - start) % 360.0 == 0.0:
        return  # refused ranges are tested above
    obs = (ox, oy)
    one = field_of_view_mask(FLAT, obs, field_of_view(azimuth=(start, end)))
    other = field_of_view_mask(FLAT, obs, field_of_view(azimuth=(end, start)))
    assert (one | other).all()
    X, Y = np.meshgrid(FLAT.xs, FLAT.ys)
    az = np.degrees(np.arctan2(X - ox, Y - oy)) % 360.0
    def off(limit):
        gap = np.abs(az - limit % 360.0) % 360.0
        return np.minimum(gap, 360.0 - gap)

    on_a_ray = (off(start) < 1e-9) | (off(end) < 1e-9) | ((X == ox) & (Y == oy))
    on_a_ray[_nearest(FLAT, obs)] = True
    assert not (one & other & ~on_a_ray).any()


def test_field_of_view_mask_checks_its_input():
    with pytest.raises(TypeError, match="fov must be a FieldOfView"):
        field_of_view_mask(FLAT, CENTRE, {"azimuth": (0, 90)})
    with pytest.raises(ValueError, match="observer must be a finite pair"):
        field_of_view_mask(FLAT, (1.0, float("nan")), field_of_view(azimuth=(0, 90)))
