"""Viewshed output modes (issue 30 part 1): ``output="min_height"`` and ``output="angle"``,
checked against the pair engine and the boolean viewshed, a brute force over the
breakpoints, and the command line."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numba
import numpy as np
import pytest

import terrainvis as tv
import terrainvis.visibility
from terrainvis import HeightGrid
from terrainvis.cli import main

#: Heights are checked to this fraction of the relief (the issue's 1e-6).
REL = 1e-6


def _random_grid(seed: int, rows: int = 23, cols: int = 29, spacing: float = 1.0, relief: float = 10.0):
    rng = np.random.default_rng(seed)
    z = relief * rng.random((rows, cols))
    return HeightGrid.from_coords(z, spacing * np.arange(cols), spacing * np.arange(rows))


def _with_nodata(g: HeightGrid) -> HeightGrid:
    z = g.z.copy()
    z[2:6, 6:22] = np.nan  # a hole that sight lines cross
    z[4, 14] = 5.0 * np.nanmax(z)  # a spike in it, with no triangle: it must not block
    z[0, :3] = np.nan
    z[-1, -2:] = np.nan
    return HeightGrid.from_coords(z, g.xs, g.ys)


def _judged(g: HeightGrid, obs) -> np.ndarray:
    """Samples whose boolean verdict is the pair engine's: all but, on a grid with nodata, the
    sample nearest the observer (which the boolean viewshed marks True as GIS tools do, while
    the output modes give its exact value)."""
    keep = np.ones(g.shape, dtype=bool)
    if g.n_nodata:
        keep[np.argmin(np.abs(g.ys - obs[1])), np.argmin(np.abs(g.xs - obs[0]))] = False
    return keep


def _relief(g: HeightGrid) -> float:
    return float(np.nanmax(g.z) - np.nanmin(g.z))


CASES = {
    # name: (seed, spacing, keyword arguments of viewshed)
    "flat": (1, 1.0, dict(observer_height=1.7)),
    "high eye": (2, 1.0, dict(observer_height=6.0)),
    "curved": (3, 400.0, dict(observer_height=3.0, curvature=0.85714)),
    "curved, geometric": (4, 400.0, dict(observer_height=0.0, curvature=1.0, earth_radius=2.0e5)),
    "field of view": (5, 1.0, dict(observer_height=2.0, max_distance=13.0, azimuth=(300.0, 100.0),
                                   min_distance=2.0)),
}


def _observer(g: HeightGrid, seed: int):
    rng = np.random.default_rng(100 + seed)
    xmin, xmax, ymin, ymax = g.extent
    return (xmin + (xmax - xmin) * rng.uniform(0.3, 0.7), ymin + (ymax - ymin) * rng.uniform(0.3, 0.7))


def _eye(g: HeightGrid, obs, kw) -> np.ndarray:
    return np.array([obs[0], obs[1], float(g.height_at([obs])[0]) + kw.get("observer_height", 1.7)])


@pytest.mark.parametrize("name", list(CASES))
def test_min_height_is_the_pair_engines_threshold(name):
    """A target at min_height (plus a hair) sees the eye under line_of_sight; a hair below, it does not."""
    seed, spacing, kw = CASES[name]
    g = _random_grid(seed, spacing=spacing)
    obs = _observer(g, seed)
    mh = tv.viewshed(g, obs, output="min_height", **kw)
    eps = REL * _relief(g)
    r, c = np.nonzero(np.isfinite(mh))
    assert r.size > 50
    ground = g.z[r, c]
    eye = _eye(g, obs, kw)
    a = np.repeat(eye[None, :], r.size, axis=0)
    earth = {k: kw[k] for k in ("curvature", "earth_radius") if k in kw}
    up = np.column_stack([g.xs[c], g.ys[r], ground + mh[r, c] * (1 + REL) + eps])
    assert tv.line_of_sight(g, a, up, **earth).all()
    positive = mh[r, c] > eps
    assert positive.sum() > 20  # some targets are hidden: the check below is not empty
    down = np.column_stack([g.xs[c], g.ys[r], ground + mh[r, c] * (1 - REL) - eps])[positive]
    assert not tv.line_of_sight(g, a[positive], down, **earth).any()


@pytest.mark.parametrize("nodata", [False, True])
@pytest.mark.parametrize("name", list(CASES))
def test_min_height_agrees_with_the_viewshed_at_every_height(name, nodata):
    """min_height == 0 exactly where viewshed(target_height=0) is True, and a target of height H
    is visible iff min_height <= H (but within REL of the relief); NaN exactly outside the field
    of view and on nodata."""
    seed, spacing, kw = CASES[name]
    g = _random_grid(seed, spacing=spacing)
    if nodata:
        g = _with_nodata(g)
    obs = _observer(g, seed)
    mh = tv.viewshed(g, obs, output="min_height", **kw)
    vis0 = tv.viewshed(g, obs, target_height=0.0, **kw)
    fov = {k: kw[k] for k in ("azimuth", "min_distance", "max_distance") if k in kw}
    inside = tv.visibility.field_of_view_mask(g, obs, tv.visibility.field_of_view(**fov)) if fov else np.ones(g.shape, bool)
    expected_nan = ~(inside & np.isfinite(g.z))
    if nodata:
        from terrainvis.visibility.viewsheds.sweep import _on_surface

        expected_nan |= ~_on_surface(g.z)
    np.testing.assert_array_equal(np.isnan(mh), expected_nan)
    judged = _judged(g, obs)
    np.testing.assert_array_equal((mh == 0.0)[judged], vis0[judged])
    eps = REL * _relief(g)
    for h in (0.3, 1.0, 2.5, 6.0):
        vis = tv.viewshed(g, obs, target_height=h, **kw)
        clear = (np.abs(np.nan_to_num(mh, nan=-1.0) - h) > eps) & judged
        np.testing.assert_array_equal(vis[clear], (np.nan_to_num(mh, nan=np.inf) <= h)[clear])
        assert clear.mean() > 0.95


@pytest.mark.parametrize("nodata", [False, True])
@pytest.mark.parametrize("name", list(CASES))
def test_angle_sign_is_the_verdict(name, nodata):
    seed, spacing, kw = CASES[name]
    g = _random_grid(seed, spacing=spacing)
    if nodata:
        g = _with_nodata(g)
    obs = _observer(g, seed)
    for h in (0.0, 2.0):
        ang = tv.viewshed(g, obs, output="angle", target_height=h, **kw)
        vis = tv.viewshed(g, obs, target_height=h, **kw)
        finite = np.isfinite(ang)
        np.testing.assert_array_equal(np.isnan(ang), np.isnan(tv.viewshed(g, obs, output="min_height", **kw)))
        clear = finite & (np.abs(ang) > 1e-7) & _judged(g, obs)
        np.testing.assert_array_equal(ang[clear] >= 0, vis[clear])
        assert clear.sum() > 0.9 * finite.sum()
        assert (ang[finite] < 0).any() and (ang[finite] > 0).any()


def _brute_angle(g: HeightGrid, eye, target, kc: float) -> float:
    """The angle above the horizon by brute force: the threshold as the largest
    ``(s(u) - ez) / u + kc L**2 (1 - u)`` over every crossing of the ray with a grid line or
    a cell diagonal (unit grid: x = i, y = j, x - y = k) and a dense sampling of the pieces
    between them (where curvature can peak), within the trim of a target standing at the
    threshold itself."""
    (ex, ey, ez), (tx, ty, tz) = eye, target
    dx, dy = tx - ex, ty - ey
    L2 = dx * dx + dy * dy
    breaks = []
    for k in range(-60, 61):
        if dx:
            breaks.append((k - ex) / dx)  # x = k
        if dy:
            breaks.append((k - ey) / dy)  # y = k
        if dx != dy:
            breaks.append((k - (ex - ey)) / (dx - dy))  # x - y = k
    thr = tz
    for _ in range(2):  # the trim of a target at tz, then that of a target at the threshold itself
        tau = tv.visibility.trim_length(g) / np.sqrt(L2 + (thr - ez) ** 2)
        us = [tau, 1 - tau, *np.linspace(tau, 1 - tau, 4001), *breaks]
        u = np.array([v for v in us if tau <= v <= 1 - tau])
        s = g.height_at(np.column_stack([ex + u * dx, ey + u * dy]))
        thr = ez + np.max((s - ez) / u + kc * L2 * (1 - u))
    L = np.sqrt(L2)
    drop = kc * L2
    return float(np.degrees(np.arctan2(tz - drop - ez, L) - np.arctan2(thr - drop - ez, L)))


def test_angle_by_hand_over_a_wall():
    """A 5 m wall 2 m from an eye 1 m up: a target 4 m away on the ground is atan(-1/4) - atan(8/4)
    below the horizon, and one on the wall's near side sees over nothing higher than its ground."""
    z = np.zeros((3, 5))
    z[:, 2] = 5.0
    g = HeightGrid(z)
    ang = tv.viewshed(g, (0.0, 1.0), observer_height=1.0, output="angle")
    assert ang[1, 4] == pytest.approx(np.degrees(np.arctan(-0.25) - np.arctan(2.0)), abs=1e-6)
    assert ang[1, 3] == pytest.approx(np.degrees(np.arctan(-1 / 3) - np.arctan(6 / 3)), abs=1e-6)
    mh = tv.viewshed(g, (0.0, 1.0), observer_height=1.0, output="min_height")
    np.testing.assert_allclose(mh[:, 3:], [[7.0, 9.0]] * 3, atol=1e-6)
    np.testing.assert_array_equal(mh[:, :3], 0.0)


@pytest.mark.parametrize("kc_curvature", [0.0, 1.0])
def test_angle_matches_a_brute_force_over_the_breakpoints(kc_curvature):
    g = _random_grid(7, rows=9, cols=11)
    radius = 50.0  # a strong curvature on a small grid
    obs = (2.3, 3.6)
    kw = dict(observer_height=2.0, target_height=0.5, curvature=kc_curvature, earth_radius=radius)
    ang = tv.viewshed(g, obs, output="angle", **kw)
    kc = tv.visibility.curvature_coefficient(kc_curvature, radius)
    eye = _eye(g, obs, kw)
    checked = 0
    for r, c in [(0, 10), (8, 0), (8, 10), (1, 7), (6, 9), (2, 0), (8, 5), (0, 0)]:
        target = (g.xs[c], g.ys[r], g.z[r, c] + 0.5)
        assert ang[r, c] == pytest.approx(_brute_angle(g, eye, target, kc), abs=1e-6)
        checked += 1
    assert checked == 8 and (ang < 0).any()


def test_tin_gives_the_grids_values():
    g = _random_grid(8)
    obs = _observer(g, 8)
    for output in ("min_height", "angle"):
        on_grid = tv.viewshed(g, obs, output=output, curvature=0.85714, earth_radius=1e3)
        on_tin = tv.viewshed(g.to_tin(), obs, at=g, output=output, curvature=0.85714, earth_radius=1e3)
        np.testing.assert_allclose(on_tin, on_grid, rtol=0, atol=1e-9 * _relief(g))


def test_visible_is_the_default_and_unchanged():
    g = _random_grid(9)
    obs = _observer(g, 9)
    out = tv.viewshed(g, obs, output="visible")
    assert out.dtype == bool
    np.testing.assert_array_equal(out, tv.viewshed(g, obs))


@pytest.mark.parametrize("bad", ["height", "MIN_HEIGHT", None, 1, ""])
def test_a_bad_output_names_the_argument_and_the_choices(bad):
    g = _random_grid(10, rows=5, cols=5)
    with pytest.raises(ValueError) as err:
        tv.viewshed(g, (2.0, 2.0), output=bad)
    assert str(err.value) == f"output must be one of 'visible', 'min_height', 'angle', got {bad!r}"


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two numba threads")
def test_one_thread_and_two_give_the_same_bits():
    g = _random_grid(11, rows=40, cols=40)
    tin = g.to_tin()

    def run():
        return [tv.viewshed(g, (17.2, 21.9), output="min_height"),
                tv.viewshed(tin, (17.2, 21.9), at=g, output="angle")]

    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = run()
        numba.set_num_threads(2)
        two = run()
    finally:
        numba.set_num_threads(before)
    for a, b in zip(one, two):
        np.testing.assert_array_equal(a, b)


def test_cli_writes_float32_geotiff_with_nan_nodata(tmp_path, capsys):
    rasterio = pytest.importorskip("rasterio", reason="the geo extra is not installed")
    g = _with_nodata(_random_grid(12, spacing=30.0))
    g = HeightGrid.from_coords(g.z, 500000.0 + g.xs, 4500000.0 + g.ys, attrs={"crs": "EPSG:32618"})
    dem = tmp_path / "dem.tif"
    tv.save_dem(g, dem)
    grid = tv.load_dem(dem)
    obs = (500000.0 + 14 * 30.0, 4500000.0 + 11 * 30.0)
    args = ["viewshed", str(dem), "--observer", str(obs[0]), str(obs[1]), "--height", "3"]
    for mode in ("min_height", "angle"):
        out = tmp_path / f"{mode}.tif"
        assert main([*args, "--output-mode", mode, "-o", str(out)]) == 0
        assert mode.replace("_", " ").split()[0] in capsys.readouterr().out
        expected = tv.viewshed(grid, obs, observer_height=3.0, output=mode)
        with rasterio.open(out) as f, rasterio.open(dem) as src:
            assert f.dtypes[0] == "float32" and np.isnan(f.nodata)
            assert f.crs == src.crs and f.transform == src.transform
            np.testing.assert_array_equal(f.read(1)[::-1], expected.astype(np.float32))
        assert np.isnan(expected[~np.isfinite(grid.z)]).all()
    assert main([*args, "--output-mode", "min_height", "-o", str(tmp_path / "m.npz")]) == 0
    saved = tv.load_terrain(tmp_path / "m.npz")
    np.testing.assert_array_equal(saved.z, tv.viewshed(grid, obs, observer_height=3.0, output="min_height"))
    assert saved.attrs["viewshed_output_mode"] == "min_height"
    assert main([*args, "--output-mode", "angle", "-o", str(tmp_path / "a.png")]) == 0
    assert (tmp_path / "a.png").stat().st_size > 1000
    capsys.readouterr()
    assert main([*args, "--output-mode", "depth", "-o", str(tmp_path / "x.tif")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    assert "--output-mode" in err and "'depth'" in err and "min_height" in err


@pytest.mark.parametrize("curvature", [0.0, 1.0])
def test_thresholds_take_the_trim_of_the_answer(curvature):
    """Each threshold is the threshold engine's (threshold_row) for a target standing at that
    threshold itself (the trim depends on the target's height): the kernel's walk of the
    slivers between the two trims gives what a second whole walk gives."""
    from terrainvis.visibility.thresholds import ThresholdSurface, threshold_row

    g = _random_grid(13, rows=15, cols=17, spacing=300.0)
    obs = _observer(g, 13)
    radius = 5e4
    kw = dict(observer_height=0.0, curvature=curvature, earth_radius=radius)
    mh = tv.viewshed(g, obs, output="min_height", **kw)
    surf = ThresholdSurface(g)
    kc = tv.visibility.curvature_coefficient(curvature, radius)
    eye = surf.local(_eye(g, obs, kw)[None, :])
    checked = 0
    for r, c in zip(*np.nonzero(mh > 0)):
        p = surf.local(np.array([[g.xs[c], g.ys[r], g.z[r, c]]]))[0]
        t1 = threshold_row(surf, p, eye, kc=kc)[0]
        p[2] = t1
        t2 = threshold_row(surf, p, eye, kc=kc)[0]
        assert g.z[r, c] + mh[r, c] == pytest.approx(t2, rel=0, abs=1e-9 * _relief(g))
        checked += 1
    assert checked > 50


@pytest.mark.parametrize("output", ["min_height", "angle"])
def test_a_tin_with_a_hole_gives_the_grids_values(output):
    """A TIN with a hole (a grid with nodata as its TIN): sight lines across the hole are
    checked by the exact TIN engine, and the values are the grid's."""
    g = _with_nodata(_random_grid(14))
    obs = _observer(g, 14)
    on_grid = tv.viewshed(g, obs, output=output, observer_height=4.0)
    on_tin = tv.viewshed(g.to_tin(), obs, at=g, output=output, observer_height=4.0)
    judged = _judged(g, obs) & np.isfinite(on_grid)
    np.testing.assert_array_equal(np.isnan(on_tin), np.isnan(on_grid))
    # heights to REL of the relief; an angle by that height over the distance
    tol = np.full(g.shape, REL * _relief(g))
    if output == "angle":
        d = np.hypot(g.xs[None, :] - obs[0], g.ys[:, None] - obs[1])
        tol = np.degrees(tol / d)
    assert (np.abs(on_tin - on_grid)[judged] <= tol[judged]).all()
