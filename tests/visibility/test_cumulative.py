"""Tests of cumulative viewsheds (terrainvis.visibility.viewsheds.cumulative).

References, independent of the way the counts are gathered (chunks, workers, dask):
* the sum of single viewsheds (:func:`terrainvis.viewshed`, itself tested against the pair
  engine in test_viewshed.py), with every option: max_distance, curvature, nodata,
  per-observer heights, eyes, targets on another grid, a TIN;
* the pair engine itself (``line_of_sight`` from each eye to every sample), summed over
  the observers, on small grids;
* a hand-worked case (a wall between two observers).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from terrainvis import HeightGrid, cumulative_viewshed, viewshed
from terrainvis.errors import OutsideFootprintError
from terrainvis.core.synthetic import synthetic_terrain
from terrainvis.visibility import line_of_sight
from terrainvis.visibility.viewsheds.many import _chunks, count_dtype
from terrainvis.visibility.viewsheds.sweep import _surface_at


# ----------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def hills():
    return synthetic_terrain("hills", 40, seed=3)


def _observers(grid, k: int, seed: int = 0) -> np.ndarray:
    """Observers inside cells, on a sample, on the boundary and in a corner."""
    rng = np.random.default_rng(seed)
    xmin, xmax, ymin, ymax = grid.extent
    obs = np.column_stack([rng.uniform(xmin, xmax, k), rng.uniform(ymin, ymax, k)])
    obs[0] = (grid.xs[5], grid.ys[7])  # on a sample
    obs[1] = (xmin, 0.5 * (ymin + ymax))  # on the west boundary
    obs[2] = (xmax, ymax)  # the north-east corner
    return obs


def _sum_of_viewsheds(terrain, obs, heights, **kw):
    at = kw.get("at")
    total = np.zeros((terrain if at is None else at).shape, dtype=np.int64)
    for o, h in zip(obs, heights):
        total += viewshed(terrain, o, observer_height=h, **kw)
    return total


# ----------------------------------------------------------------- against single viewsheds
@pytest.mark.parametrize("kw", [
    {},
    {"max_distance": 400.0},
    {"target_height": 3.0},
    {"curvature": 0.85714, "earth_radius": 5000.0},  # a small earth: the bulge matters on 1.2 km
    {"curvature": 1.0, "earth_radius": 3000.0, "max_distance": 700.0, "target_height": 1.0},
], ids=["plain", "max_distance", "target_height", "curvature", "curvature+max_distance"])
def test_equals_the_sum_of_single_viewsheds(hills, kw):
    obs = _observers(hills, 9)
    got = cumulative_viewshed(hills, obs, observer_height=2.0, workers=1, **kw)
    assert got.dtype == np.uint16 and got.shape == hills.shape
    ref = _sum_of_viewsheds(hills, obs, np.full(len(obs), 2.0), **kw)
    np.testing.assert_array_equal(got, ref)
    assert 0 < got.max() <= len(obs)


def test_curvature_changes_the_counts(hills):
    """The option reaches the units: a small earth hides cells a flat one shows."""
    obs = _observers(hills, 6)
    flat = cumulative_viewshed(hills, obs, workers=1)
    curved = cumulative_viewshed(hills, obs, curvature=1.0, earth_radius=2000.0, workers=1)
    assert (curved <= flat).all() and (curved < flat).any()


def test_nodata(hills):
    z = hills.z.copy()
    z[10:14, 20:30] = np.nan
    z[30, 5] = np.nan
    grid = HeightGrid.from_coords(z, hills.xs, hills.ys)
    obs = _observers(grid, 8, seed=1)
    obs = obs[np.isfinite([_surface_at(grid, x, y) for x, y in obs])]
    assert len(obs) >= 6
    got = cumulative_viewshed(grid, obs, workers=1, max_distance=900.0)
    np.testing.assert_array_equal(got, _sum_of_viewsheds(grid, obs, np.full(len(obs), 1.7), max_distance=900.0))
    assert (got[np.isnan(z)] == 0).all()


def test_per_observer_heights_and_eyes(hills):
    obs = _observers(hills, 7, seed=2)
    heights = np.array([0.0, 1.0, 5.0, 20.0, 2.0, 0.5, 60.0])
    got = cumulative_viewshed(hills, obs, observer_height=heights, workers=1)
    np.testing.assert_array_equal(got, _sum_of_viewsheds(hills, obs, heights))
    # the same eyes given as (x, y, z)
    eyes = np.column_stack([obs, [_surface_at(hills, x, y) + h for (x, y), h in zip(obs, heights)]])
    np.testing.assert_array_equal(cumulative_viewshed(hills, eyes, workers=1), got)


def test_targets_on_another_grid_and_a_tin(hills):
    """``at`` (the original's samples) on a coarser grid and on a TIN, as viewshed takes them."""
    coarse = hills.crop(rows=(0, 40), cols=(0, 40))
    coarse = HeightGrid.from_coords(coarse.z[::2, ::2], coarse.xs[::2], coarse.ys[::2])
    obs = _observers(coarse, 5, seed=4)
    got = cumulative_viewshed(coarse, obs, at=hills, workers=1)
    assert got.shape == hills.shape
    np.testing.assert_array_equal(got, _sum_of_viewsheds(coarse, obs, np.full(5, 1.7), at=hills))
    tin = coarse.to_tin()
    got_tin = cumulative_viewshed(tin, obs, at=hills, workers=1, curvature=0.5, earth_radius=4000.0)
    ref_tin = _sum_of_viewsheds(tin, obs, np.full(5, 1.7), at=hills, curvature=0.5, earth_radius=4000.0)
    np.testing.assert_array_equal(got_tin, ref_tin)


# ----------------------------------------------------------------- against the pair engine
@pytest.mark.parametrize("kw", [{}, {"curvature": 1.0, "earth_radius": 1500.0}], ids=["flat", "curved"])
def test_against_the_pair_engine(kw):
    """Each count is the number of eyes from which line_of_sight reaches the sample (plus
    the viewshed's one rule of its own: the sample nearest an observer is always seen)."""
    grid = synthetic_terrain("ridges", 17, seed=5)
    obs = _observers(grid, 6, seed=6)
    got = cumulative_viewshed(grid, obs, observer_height=1.5, target_height=0.5, workers=1, **kw)
    X, Y = np.meshgrid(grid.xs, grid.ys)
    b = np.column_stack([X.ravel(), Y.ravel(), grid.z.ravel() + 0.5])
    ref = np.zeros(grid.shape, dtype=np.int64)
    for x, y in obs:
        a = np.tile([x, y, _surface_at(grid, x, y) + 1.5], (b.shape[0], 1))
        seen = line_of_sight(grid, a, b, engine="grid", **kw).reshape(grid.shape)
        seen[int(np.argmin(np.abs(grid.ys - y))), int(np.argmin(np.abs(grid.xs - x)))] = True
        ref += seen
    np.testing.assert_array_equal(got, ref)


def test_hand_worked_wall():
    """A 5 m wall along x = 2 between two eyes 1 m above the ground at x = 0 and x = 4:
    each sees its own side and the crest, so the crest counts 2 and the rest 1."""
    z = np.zeros((3, 5))
    z[:, 2] = 5.0
    got = cumulative_viewshed(HeightGrid(z), [[0.0, 1.0], [4.0, 1.0]], observer_height=1.0, workers=1)
    np.testing.assert_array_equal(got, np.array([[1, 1, 2, 1, 1]] * 3))
    # the same observer twice counts twice
    twice = cumulative_viewshed(HeightGrid(z), [[0.0, 1.0], [0.0, 1.0]], observer_height=1.0, workers=1)
    np.testing.assert_array_equal(twice, np.array([[2, 2, 2, 0, 0]] * 3))


# ----------------------------------------------------------------- where it runs
def test_workers_one_and_two_give_the_same_raster(hills):
    obs = _observers(hills, 12, seed=7)
    one = cumulative_viewshed(hills, obs, workers=1, max_distance=800.0)
    two = cumulative_viewshed(hills, obs, workers=2, max_distance=800.0)
    assert two.dtype == one.dtype == np.uint16
    np.testing.assert_array_equal(one, two)
    np.testing.assert_array_equal(one, _sum_of_viewsheds(hills, obs, np.full(12, 1.7), max_distance=800.0))


def test_threads_and_one_thread_give_the_same_raster(hills, monkeypatch):
    """The default runs two viewsheds at a time on numba's threads; forced onto one thread
    (one unit after the other) it gives the same counts, and with numba on one thread
    that is what it does."""
    import numba

    from terrainvis.visibility.viewsheds import many as module

    obs = _observers(hills, 24, seed=5)
    if numba.get_num_threads() < 2:
        pytest.skip("numba has one thread here: the threaded path is not taken")
    assert module._local_threads(hills, "auto", 1, None) == numba.get_num_threads()
    assert module._local_threads(hills.to_tin(), "auto", 1, None) == 1  # Embree keeps its own threads
    assert module._local_threads(hills, "auto", 2, None) == 1
    threaded = cumulative_viewshed(hills, obs, curvature=0.85714, earth_radius=6000.0)
    monkeypatch.setattr(module, "_local_threads", lambda *a: 1)
    serial = cumulative_viewshed(hills, obs, curvature=0.85714, earth_radius=6000.0)
    np.testing.assert_array_equal(threaded, serial)
    np.testing.assert_array_equal(
        threaded, _sum_of_viewsheds(hills, obs, [1.7] * len(obs), curvature=0.85714, earth_radius=6000.0))


def test_dask_local_cluster(hills):
    distributed = pytest.importorskip("distributed", reason="the dask extra is not installed (pip install terrainvis[dask])")
    obs = _observers(hills, 10, seed=8)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            got = cumulative_viewshed(hills, obs, client=client, curvature=0.85714, earth_radius=6000.0)
    ref = cumulative_viewshed(hills, obs, workers=1, curvature=0.85714, earth_radius=6000.0)
    np.testing.assert_array_equal(got, ref)


def test_inputs_are_not_modified(hills):
    obs = _observers(hills, 4, seed=9)
    heights = np.array([1.0, 2.0, 3.0, 4.0])
    before = (obs.copy(), heights.copy(), hills.z.copy())
    cumulative_viewshed(hills, obs, observer_height=heights, workers=1)
    np.testing.assert_array_equal(obs, before[0])
    np.testing.assert_array_equal(heights, before[1])
    np.testing.assert_array_equal(hills.z, before[2])


def test_progress_bar_counts_observers(hills, capsys, monkeypatch):
    from terrainvis.core import _progress

    monkeypatch.setattr(_progress, "on_a_terminal", lambda: True)  # a bar (into a log: plain lines, test_newcomer)
    cumulative_viewshed(hills, _observers(hills, 5), workers=1, progress=True)
    err = capsys.readouterr().err
    assert "cumulative viewshed" in err and "5/5" in err and "observer" in err
    cumulative_viewshed(hills, _observers(hills, 5), workers=1)
    assert capsys.readouterr().err == ""


def testcount_dtype():
    assert count_dtype(1) == np.uint16
    assert count_dtype(65535) == np.uint16
    assert count_dtype(65536) == np.uint32
    assert np.iinfo(count_dtype(65535)).max >= 65535


@settings(max_examples=200, deadline=None)
@given(k=st.integers(1, 5000), slots=st.integers(1, 64))
def test_chunks_cover_every_observer_once(k, slots):
    chunks = _chunks(k, slots)
    assert chunks[0][0] == 0 and chunks[-1][1] == k
    assert all(a[1] == b[0] for a, b in zip(chunks, chunks[1:]))
    sizes = [e - s for s, e in chunks]
    assert min(sizes) >= 1 and max(sizes) - min(sizes) <= 1
    assert len(chunks) == min(k, 32 * slots)


# ----------------------------------------------------------------- bad input
def test_bad_input_names_the_argument(hills):
    obs = _observers(hills, 3)
    xmin, xmax, ymin, ymax = hills.extent
    with pytest.raises(OutsideFootprintError, match=r"observers\[1\].*outside the terrain's footprint.*1 of 3"):
        cumulative_viewshed(hills, [obs[0], [xmax + 100.0, ymin], obs[2]], workers=1)
    with pytest.raises(ValueError, match=r"observers must be a 2-D array.*\(one observer: \[\[x, y\]\]\)"):
        cumulative_viewshed(hills, obs[0], workers=1)
    with pytest.raises(ValueError, match=r"observers must have shape \(K, 2\).*got shape \(3, 4\)"):
        cumulative_viewshed(hills, np.zeros((3, 4)), workers=1)
    with pytest.raises(ValueError, match=r"at least one observer \(K >= 1\)"):
        cumulative_viewshed(hills, np.zeros((0, 2)), workers=1)
    with pytest.raises(ValueError, match=r"observers must be finite.*observers\[1\]"):
        cumulative_viewshed(hills, [obs[0], [np.nan, 1.0]], workers=1)
    with pytest.raises(TypeError, match="observers must be numeric"):
        cumulative_viewshed(hills, [["a", "b"]], workers=1)
    with pytest.raises(ValueError, match=r"observer_height must be one number or one per observer \(shape \(3,\)\)"):
        cumulative_viewshed(hills, obs, observer_height=[1.0, 2.0], workers=1)
    with pytest.raises(ValueError, match=r"observer_height must be finite and >= 0.*observer_height\[2\]"):
        cumulative_viewshed(hills, obs, observer_height=[1.0, 2.0, -1.0], workers=1)
    with pytest.raises(ValueError, match="observer_height must be finite and >= 0"):
        cumulative_viewshed(hills, obs, observer_height=-1.0, workers=1)
    with pytest.raises(ValueError, match="target_height must be finite and >= 0"):
        cumulative_viewshed(hills, obs, target_height=-2.0, workers=1)
    with pytest.raises(ValueError, match="max_distance must be finite and >= 0"):
        cumulative_viewshed(hills, obs, max_distance=-1.0, workers=1)
    with pytest.raises(ValueError, match="curvature must be finite and >= 0"):
        cumulative_viewshed(hills, obs, curvature=-0.5, workers=1)
    with pytest.raises(ValueError, match="earth_radius must be finite and > 0"):
        cumulative_viewshed(hills, obs, curvature=0.5, earth_radius=0.0, workers=1)
    with pytest.raises(ValueError, match="engine must be one of"):
        cumulative_viewshed(hills, obs, engine="fast", workers=1)
    with pytest.raises(ValueError, match="workers must be >= 1"):
        cumulative_viewshed(hills, obs, workers=0)
    with pytest.raises(TypeError, match="client must be a dask.distributed.Client"):
        cumulative_viewshed(hills, obs, client="localhost:8786")
    with pytest.raises(TypeError, match="progress must be True or False"):
        cumulative_viewshed(hills, obs, workers=1, progress="yes")
    with pytest.raises(TypeError, match="terrain must be a terrainvis.HeightGrid or terrainvis.TIN"):
        cumulative_viewshed(hills.z, obs, workers=1)
    with pytest.raises(ValueError, match="at is required for a TIN"):
        cumulative_viewshed(hills.to_tin(), obs, workers=1)
    with pytest.raises(ValueError, match="engine 'embree' cannot model earth curvature"):
        cumulative_viewshed(hills.to_tin(), obs, at=hills, engine="embree", curvature=0.85714, workers=1)
    with pytest.raises(TypeError, match="at must be a terrainvis.HeightGrid"):
        cumulative_viewshed(hills, obs, at=hills.to_tin(), workers=1)


def test_observer_on_nodata_is_refused(hills):
    z = hills.z.copy()
    z[20, 20] = np.nan
    grid = HeightGrid.from_coords(z, hills.xs, hills.ys)
    with pytest.raises(OutsideFootprintError, match=r"observers\[0\].*or on nodata.*1 of 2 observers"):
        cumulative_viewshed(grid, [[grid.xs[20], grid.ys[20]], [grid.xs[2], grid.ys[2]]], workers=1)


# ----------------------------------------------------------------- interrupts
_SCRIPT = """
import sys
import numpy as np
from terrainvis import cumulative_viewshed
from terrainvis.core.runner import Interrupted
from terrainvis.core.synthetic import synthetic_terrain

if __name__ == "__main__":
    grid = synthetic_terrain("mountains", 512)
    rng = np.random.default_rng(0)
    obs = np.column_stack([rng.uniform(0, 15000, 5000), rng.uniform(0, 15000, 5000)])
    print("running", flush=True)
    try:
        cumulative_viewshed(grid, obs, workers=2)
    except Interrupted as exc:
        print(exc, file=sys.stderr)
        sys.exit(130)
    sys.exit(0)
"""


def test_ctrl_c_stops_the_workers(tmp_path):
    psutil = pytest.importorskip("psutil", reason="psutil (installed with the dask extra) lists the worker processes")
    script = tmp_path / "cum.py"
    script.write_text(_SCRIPT)
    p = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True)
    assert p.stdout.readline().strip() == "running"
    deadline = time.monotonic() + 60
    workers = []
    while len(workers) < 2 and time.monotonic() < deadline:
        workers = [c for c in psutil.Process(p.pid).children(recursive=True) if "spawn_main" in " ".join(c.cmdline())]
        time.sleep(0.05)
    assert len(workers) == 2, "the pool did not start its workers"
    time.sleep(3.0)  # the workers are computing viewsheds (5,000 observers take minutes)
    err = _ctrl_c(p)
    assert "interrupted by SIGINT" in err and "Traceback" not in err, err
    _, alive = psutil.wait_procs(workers, timeout=10)
    assert not alive, f"worker processes survived: {alive}"


_THREADS_SCRIPT = """
import sys, threading, time
import numpy as np
from terrainvis import cumulative_viewshed
from terrainvis.core.synthetic import synthetic_terrain
from terrainvis.errors import Interrupted

if __name__ == "__main__":
    grid = synthetic_terrain("mountains", 512)
    rng = np.random.default_rng(0)
    obs = np.column_stack([rng.uniform(0, 15000, 20000), rng.uniform(0, 15000, 20000)])
    cumulative_viewshed(grid, obs[:2])  # the kernels loaded and the grid's tables built
    print("running", flush=True)
    try:
        cumulative_viewshed(grid, obs)  # in this process, on numba's threads
    except Interrupted as exc:
        left = [t.name for t in threading.enumerate() if t.name.startswith("terrainvis-unit")]
        print(f"{exc}; unit threads left: {left}", file=sys.stderr)
        sys.exit(130)
    sys.exit(0)
"""


def test_ctrl_c_stops_the_threads_of_an_in_process_run(tmp_path):
    script = tmp_path / "cum_threads.py"
    script.write_text(_THREADS_SCRIPT)
    p = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True)
    assert p.stdout.readline().strip() == "running"
    time.sleep(2.0)  # 20,000 observers take minutes
    t0 = time.monotonic()
    err = _ctrl_c(p)
    assert "interrupted by SIGINT; unit threads left: []" in err and "Traceback" not in err, err
    assert time.monotonic() - t0 < 5.0, "the threads took more than 5 s to stop"


def _ctrl_c(p) -> str:
    """Ctrl-C to the script's process group; its stderr once it has exited with status 130 (within 20 s)."""
    os.killpg(p.pid, signal.SIGINT)
    try:
        p.wait(timeout=20)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        pytest.fail("cumulative_viewshed did not stop within 20 s of Ctrl-C")
    err = p.stderr.read()
    assert p.returncode == 130, err
    return err


# ----------------------------------------------------------------- the figure
def test_plot_draws_the_counts_over_the_hillshade(hills):
    from terrainvis.experiment import plot

    obs = _observers(hills, 6)
    counts = cumulative_viewshed(hills, obs, workers=1)
    fig = plot.cumulative_viewshed(hills, counts, observers=obs, title="six")
    ax = fig.axes[0]
    assert ax.get_title() == "six"
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    seen = 100 * (counts > 0).mean()
    assert labels == [f"seen by none ({100 - seen:.1f} %)", f"seen by any ({seen:.1f} %)", "6 observers"]
    counts_image = ax.get_images()[-1]
    assert counts_image.get_clim() == (1, max(int(counts.max()), 2))
    np.testing.assert_array_equal(counts_image.get_array().mask, counts == 0)
    assert fig.axes[1].get_ylabel() == "observers that see the sample"  # the colour bar
    with pytest.raises(ValueError, match="counts must have the terrain's shape"):
        plot.cumulative_viewshed(hills, counts[:3])
    with pytest.raises(ValueError, match="counts must be integers >= 0"):
        plot.cumulative_viewshed(hills, counts.astype(float))
    with pytest.raises(TypeError, match="terrain must be the HeightGrid"):
        plot.cumulative_viewshed(hills.to_tin(), counts)
    with pytest.raises(ValueError, match=r"observers must have shape \(K, 2\)"):
        plot.cumulative_viewshed(hills, counts, observers=[1.0, 2.0])
