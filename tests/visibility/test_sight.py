"""Tests of the sight as a value (terrainvis.visibility.sight).

* A Sight is frozen, hashable and pickles; made with a bad value it raises what the
  functions raise for the same keyword, word for word.
* ``sight=`` and the keywords give the same verdicts, bit for bit, for viewshed (every
  option, a TIN with ``at``, the output modes), cumulative_viewshed, observer_sets and
  site_observers (per-observer heights beside a Sight too), and on worker processes.
* ``sight=`` beside a keyword set to other than its default is a TypeError naming it.
"""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest

from terrainvis import HeightGrid
from terrainvis.core.synthetic import synthetic_terrain
from terrainvis.visibility import (
    FieldOfView,
    Sight,
    cumulative_viewshed,
    observer_sets,
    site_observers,
    viewshed,
)
from terrainvis.visibility.predicate import EARTH_RADIUS
from terrainvis.visibility.sight import KEYWORDS


@pytest.fixture(scope="module")
def hills():
    return synthetic_terrain("hills", 33, seed=5)


def _observers(grid, k: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    xmin, xmax, ymin, ymax = grid.extent
    obs = np.column_stack([rng.uniform(xmin, xmax, k), rng.uniform(ymin, ymax, k)])
    obs[0] = (grid.xs[4], grid.ys[6])  # on a sample
    return obs


#: Settings of the viewshed family, each as keywords (``at`` aside).
SETTINGS = [
    {},
    {"observer_height": 12.0, "target_height": 3.0},
    {"curvature": 0.85714, "earth_radius": 3000.0},
    {"curvature": 1.0, "earth_radius": 5000.0, "vertical": (-4.0, 3.0), "observer_height": 5.0},
    {"max_distance": 400.0},
    {"azimuth": (300.0, 60.0), "min_distance": 90.0, "max_distance": 700.0},
    {"engine": "grid", "target_height": 1.0},
]


# ----------------------------------------------------------------- the value
def test_a_sight_is_frozen_hashable_and_pickles():
    s = Sight.make(observer_height=3, target_height=1.5, curvature=0.85714, earth_radius=6e6, azimuth=(300, 60),
                   vertical=(-5, 5), min_distance=10, max_distance=500)
    assert isinstance(s.fov, FieldOfView) and s.fov.azimuth == (300.0, 60.0) and s.max_distance == 500.0
    assert type(s.observer_height) is float and s.observer_height == 3.0
    assert s.kc == 0.85714 / (2.0 * 6e6)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.observer_height = 2.0
    back = pickle.loads(pickle.dumps(s))
    assert back == s and hash(back) == hash(s) and back.kc == s.kc
    assert Sight.make(**s.keywords()) == s
    assert Sight() == Sight.make() and Sight().fov == FieldOfView()
    assert s.with_observer_height(7.0).observer_height == 7.0 and s.observer_height == 3.0


BAD = [
    ("observer_height", -1.0), ("observer_height", "high"), ("target_height", -2.0), ("target_height", "high"),
    ("max_distance", -3.0), ("min_distance", -1.0), ("engine", "fast"), ("engine", 3), ("curvature", -0.5),
    ("curvature", float("nan")), ("earth_radius", 0.0), ("azimuth", (10, 400)), ("azimuth", (30, 30)),
    ("vertical", (20, -20)), ("vertical", "up"),
]


@pytest.mark.parametrize("name, value", BAD)
def test_a_bad_value_raises_what_the_functions_raise(hills, name, value):
    with pytest.raises((TypeError, ValueError)) as made:
        Sight.make(**{name: value})
    obs = _observers(hills, 2)
    for call in (lambda: viewshed(hills, obs[0], **{name: value}),
                 lambda: cumulative_viewshed(hills, obs, workers=1, **{name: value}),
                 lambda: observer_sets(hills, obs, workers=1, **{name: value}),
                 lambda: site_observers(hills, obs, 1, workers=1, **{name: value})):
        with pytest.raises(made.type) as given:
            call()
        assert str(given.value) == str(made.value)


def test_sight_made_directly_is_checked_too():
    with pytest.raises(ValueError, match="observer_height must be finite and >= 0"):
        Sight(observer_height=-1.0)
    with pytest.raises(TypeError, match="fov must be a FieldOfView"):
        Sight(fov=(0, 360))
    with pytest.raises(ValueError, match="max_distance must be finite and >= 0"):
        Sight.make(max_distance=-1.0)


# ----------------------------------------------------------------- the same verdicts
@pytest.mark.parametrize("kw", SETTINGS)
def test_viewshed_with_a_sight_is_viewshed_with_its_keywords(hills, kw):
    s = Sight.make(**kw)
    for obs in _observers(hills, 3, seed=1):
        a = viewshed(hills, obs, sight=s)
        b = viewshed(hills, obs, **kw)
        assert a.dtype == b.dtype and np.array_equal(a, b)
        assert np.array_equal(viewshed(hills, obs, **s.keywords()), b)


@pytest.mark.parametrize("output", ["min_height", "angle"])
def test_the_output_modes_with_a_sight(hills, output):
    kw = {"curvature": 0.85714, "earth_radius": 4000.0, "vertical": (-10.0, 10.0), "max_distance": 600.0}
    obs = _observers(hills, 1)[0]
    a = viewshed(hills, obs, sight=Sight.make(**kw), output=output)
    b = viewshed(hills, obs, output=output, **kw)
    np.testing.assert_array_equal(a, b)  # NaN in the same places, the values bit for bit


@pytest.mark.parametrize("kw", [{}, {"curvature": 0.85714, "earth_radius": 3000.0}, {"target_height": 2.0,
                                                                                    "max_distance": 500.0}])
def test_a_tin_with_at(hills, kw):
    tin = HeightGrid.from_coords(hills.z[::2, ::2], hills.xs[::2], hills.ys[::2]).to_tin()
    s = Sight.make(**kw)
    for obs in _observers(hills, 2, seed=2):
        np.testing.assert_array_equal(viewshed(tin, obs, at=hills, sight=s), viewshed(tin, obs, at=hills, **kw))


@pytest.mark.parametrize("kw", SETTINGS[:4] + SETTINGS[5:])
def test_many_observers_with_a_sight(hills, kw):
    obs = _observers(hills, 9, seed=3)
    s = Sight.make(**kw)
    np.testing.assert_array_equal(cumulative_viewshed(hills, obs, sight=s, workers=1),
                                  cumulative_viewshed(hills, obs, workers=1, **kw))
    with_sight = observer_sets(hills, obs, sight=s, workers=1)
    with_keywords = observer_sets(hills, obs, workers=1, **kw)
    np.testing.assert_array_equal(with_sight.bits, with_keywords.bits)
    assert with_sight.settings == with_keywords.settings
    a = site_observers(hills, obs, 3, sight=s, workers=1)
    b = site_observers(hills, obs, 3, workers=1, **kw)
    np.testing.assert_array_equal(a.chosen, b.chosen)
    np.testing.assert_array_equal(a.covered, b.covered)
    assert a.table.equals(b.table)


def test_per_observer_heights_beside_a_sight(hills):
    obs = _observers(hills, 6, seed=4)
    heights = np.array([1.0, 20.0, 0.0, 5.5, 2.0, 40.0])
    kw = {"target_height": 1.0, "curvature": 0.85714, "earth_radius": 3000.0}
    s = Sight.make(**kw)
    expected = cumulative_viewshed(hills, obs, observer_height=heights, workers=1, **kw)
    np.testing.assert_array_equal(cumulative_viewshed(hills, obs, observer_height=heights, sight=s, workers=1),
                                  expected)
    one_by_one = sum(viewshed(hills, o, sight=s.with_observer_height(h)).astype(np.int64)
                     for o, h in zip(obs, heights))
    np.testing.assert_array_equal(expected, one_by_one)
    a = site_observers(hills, obs, 2, observer_height=heights, sight=s, workers=1)
    b = site_observers(hills, obs, 2, observer_height=heights, workers=1, **kw)
    assert a.table.equals(b.table)
    sets = observer_sets(hills, obs, observer_height=heights, sight=s, workers=1)
    assert sets.settings["observer_height"] == heights.tolist()


@pytest.mark.slow
def test_a_sight_crosses_to_worker_processes(hills):
    obs = _observers(hills, 12, seed=6)
    s = Sight.make(observer_height=4.0, curvature=0.85714, earth_radius=3000.0, azimuth=(200.0, 100.0),
                   max_distance=800.0)
    np.testing.assert_array_equal(cumulative_viewshed(hills, obs, sight=s, workers=2),
                                  cumulative_viewshed(hills, obs, workers=1, **s.keywords()))


# ----------------------------------------------------------------- either the Sight or the keywords
OTHER = {"observer_height": 2.0, "target_height": 1.0, "max_distance": 100.0, "engine": "grid", "curvature": 1.0,
         "earth_radius": 1e6, "azimuth": (0, 90), "vertical": (-5, 5), "min_distance": 1.0}


@pytest.mark.parametrize("name", list(KEYWORDS))
def test_sight_beside_a_keyword_is_refused_naming_it(hills, name):
    assert set(OTHER) == set(KEYWORDS)
    s = Sight()
    obs = _observers(hills, 2)
    match = f"pass either sight= or the keyword {name}="
    for call in (lambda: viewshed(hills, obs[0], sight=s, **{name: OTHER[name]}),
                 lambda: cumulative_viewshed(hills, obs, sight=s, workers=1, **{name: OTHER[name]}),
                 lambda: observer_sets(hills, obs, sight=s, workers=1, **{name: OTHER[name]}),
                 lambda: site_observers(hills, obs, 1, sight=s, workers=1, **{name: OTHER[name]})):
        with pytest.raises(TypeError, match=match):
            call()
    # its default beside a Sight is no conflict
    np.testing.assert_array_equal(viewshed(hills, obs[0], sight=s, **{name: KEYWORDS[name]}),
                                  viewshed(hills, obs[0], sight=s))


def test_sight_must_be_a_sight(hills):
    with pytest.raises(TypeError, match="sight must be a terrainvis.visibility.Sight"):
        viewshed(hills, (100.0, 100.0), sight={"observer_height": 2.0})
    with pytest.raises(TypeError, match="sight must be a terrainvis.visibility.Sight"):
        cumulative_viewshed(hills, [[100.0, 100.0]], sight=FieldOfView(), workers=1)


# ----------------------------------------------------------------- the functions of point pairs
def _pairs(grid, m: int, seed: int = 3):
    from terrainvis.core.sampling import sample_points

    p = sample_points(grid, 2 * m, seed=seed, offset=2.0)
    return p[:m], p[m:]


@pytest.mark.parametrize("keywords", [
    {},
    {"engine": "grid", "end_radius": 40.0},
    {"curvature": 0.85714, "earth_radius": 2e4},
    {"engine": "tin", "end_radius": 15.0, "curvature": 1.0, "earth_radius": 5e4},
])
def test_pair_functions_take_the_predicate_as_a_sight(hills, keywords):
    from terrainvis.visibility import line_of_sight, min_clearance, visibility_matrix
    from terrainvis.visibility.profile import lowest_point

    terrain = hills.to_tin() if keywords.get("engine") == "tin" else hills
    a, b = _pairs(hills, 60)
    s = Sight.make(**keywords)
    assert (s.end_radius, s.kc) == (keywords.get("end_radius", 0.0),
                                    keywords.get("curvature", 0.0) / (2 * keywords.get("earth_radius", EARTH_RADIUS)))
    np.testing.assert_array_equal(line_of_sight(terrain, a, b, sight=s), line_of_sight(terrain, a, b, **keywords))
    np.testing.assert_array_equal(visibility_matrix(terrain, a, sight=s), visibility_matrix(terrain, a, **keywords))
    earth = {k: v for k, v in keywords.items() if k != "engine"}
    np.testing.assert_array_equal(min_clearance(terrain, a, b, sight=s), min_clearance(terrain, a, b, **earth))
    assert lowest_point(terrain, a[0], b[0], sight=s) == lowest_point(terrain, a[0], b[0], **earth)
    # the Sight's heights are not the points': a and b carry theirs
    s2 = dataclasses.replace(s, observer_height=50.0, target_height=9.0)
    np.testing.assert_array_equal(line_of_sight(terrain, a, b, sight=s2), line_of_sight(terrain, a, b, **keywords))


@pytest.mark.parametrize("name, value", [("engine", "grid"), ("end_radius", 3.0), ("curvature", 1.0),
                                         ("earth_radius", 1e6)])
def test_pair_functions_refuse_a_sight_beside_a_keyword(hills, name, value):
    from terrainvis.visibility import line_of_sight, min_clearance, visibility_matrix

    a, b = _pairs(hills, 4)
    match = f"pass either sight= or the keyword {name}=, not both"
    with pytest.raises(TypeError, match=match):
        line_of_sight(hills, a, b, sight=Sight(), **{name: value})
    with pytest.raises(TypeError, match=match):
        visibility_matrix(hills, a, sight=Sight(), **{name: value})
    if name != "engine":  # min_clearance has no engine keyword
        with pytest.raises(TypeError, match=match):
            min_clearance(hills, a, b, sight=Sight(), **{name: value})


def test_pair_functions_refuse_a_sight_with_a_field_of_view(hills):
    from terrainvis.visibility import line_of_sight

    a, b = _pairs(hills, 4)
    with pytest.raises(ValueError, match=r"line_of_sight takes the predicate of a Sight .*its field of view "
                                         r"\(azimuth 0 to 90 degrees"):
        line_of_sight(hills, a, b, sight=Sight.make(azimuth=(0, 90)))


def test_a_viewshed_refuses_an_end_radius_and_a_sight_checks_it(hills):
    obs = _observers(hills, 1)[0]
    with pytest.raises(ValueError, match=r"a viewshed tests its sight lines whole .*end_radius must be 0, got 5.0"):
        viewshed(hills, obs, sight=Sight.make(end_radius=5.0))
    with pytest.raises(ValueError, match="end_radius"):
        Sight(end_radius=-1.0)
    assert pickle.loads(pickle.dumps(Sight.make(end_radius=2.5))).end_radius == 2.5
