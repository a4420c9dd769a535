"""Adding a line-of-sight engine touches the registry and the engine's own module only.

A toy engine answers each segment from :func:`terrainvis.min_clearance` (exact on grids
and TINs), one segment at a time, and counts its calls. It is written as a module of its
own (in a temporary folder) and given one :func:`terrainvis.visibility.register_engine`
call; ``line_of_sight``, ``visibility_matrix``, ``viewshed``, ``compare`` (in this process
and on worker processes) and ``--engine`` then take it, and the checks that an engine
runs on the terrains and the curvature of a run read its declaration.
"""

from __future__ import annotations

import re
import textwrap

import numpy as np
import pandas as pd
import pytest

from terrainvis import compare, line_of_sight, sample_points, synthetic_terrain, viewshed, visibility_matrix
from terrainvis.cli import main
from terrainvis.visibility import ENGINES, Engine, engine_names, register_engine, unregister_engine

_MODULE = '''
"""A toy engine: the exact minimum clearance, segment by segment."""
import numpy as np

from terrainvis import min_clearance

CALLS = []


def pairs(terrain, a, b, predicate):
    CALLS.append(len(a))
    return min_clearance(terrain, a, b, end_radius=predicate.end_radius) >= -predicate.tol


def matrix(terrain, points, predicate):
    n = len(points)
    i, j = np.triu_indices(n, 1)
    out = np.eye(n, dtype=bool)
    out[i, j] = out[j, i] = pairs(terrain, points[i], points[j], predicate)
    return out
'''


@pytest.fixture
def toy(tmp_path, monkeypatch):
    (tmp_path / "toy_engine.py").write_text(textwrap.dedent(_MODULE))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    import toy_engine

    toy_engine.CALLS.clear()
    entry = register_engine(Engine("toy", toy_engine.pairs, toy_engine.matrix, "min_clearance, one by one",
                                   curvature=False))
    yield toy_engine
    unregister_engine("toy")


def test_the_visibility_functions_take_it(toy):
    g = synthetic_terrain("mountains", size=33, seed=5)
    P = sample_points(g, 25, seed=1, offset=2.0)
    np.testing.assert_array_equal(visibility_matrix(g, P, engine="toy"), visibility_matrix(g, P, engine="grid"))
    a, b = P[:12], P[12:24]
    np.testing.assert_array_equal(line_of_sight(g, a, b, engine="toy", end_radius=40.0),
                                  line_of_sight(g, a, b, engine="grid", end_radius=40.0))
    tin = g.to_tin()
    np.testing.assert_array_equal(viewshed(tin, P[0, :2], at=g, engine="toy"), viewshed(tin, P[0, :2], at=g,
                                                                                          engine="tin"))
    assert len(toy.CALLS) >= 3 and "toy" in engine_names()
    with pytest.raises(ValueError, match="engine 'toy' cannot model earth curvature"):
        line_of_sight(g, a, b, engine="toy", curvature=0.85714)


def test_the_registry_is_checked(toy):
    with pytest.raises(ValueError, match="engine 'grid' is built in and cannot be replaced"):
        register_engine(Engine("grid", toy.pairs, toy.matrix, "x"))
    with pytest.raises(ValueError, match="engine.name must not be 'auto'"):
        register_engine(Engine("auto", toy.pairs, toy.matrix, "x"))
    with pytest.raises(TypeError, match=re.escape("engine 'short': pairs must take (terrain, a, b, predicate)")):
        register_engine(Engine("short", lambda terrain, a: a, toy.matrix, "x"))
    with pytest.raises(ValueError, match=r"terrains must be some of \['grid', 'tin'\], got \['mesh'\]"):
        register_engine(Engine("mesh", toy.pairs, toy.matrix, "x", terrains=("mesh",)))
    with pytest.raises(ValueError, match="engine 'embree' is built in and cannot be removed"):
        unregister_engine("embree")
    assert ENGINES["toy"].runs_on(synthetic_terrain("hills", size=9)) and "tin" in ENGINES["toy"].terrains


def test_compare_takes_it_and_checks_what_it_declares(toy):
    g = {"g": synthetic_terrain("hills", size=33, seed=2)}
    kw = dict(methods=["lls", "qec"], levels=[1], n_points=10, n_sets=1, repeats=1, relocations=["full", "half"],
              workers=1)
    ours = compare(g, engine="toy", **kw)
    exact = compare(g, engine="auto", curvature=0.0, **kw)
    tin_rows = exact["method"] == "qec"  # "auto" answers on the TIN with Embree: the toy is exact
    cols = ["method", "relocation", "accuracy", "agree_visible", "agree_blocked"]
    pd.testing.assert_frame_equal(ours.loc[~tin_rows, cols], exact.loc[~tin_rows, cols])
    assert ours["error"].isna().all() and len(toy.CALLS) > 0
    with pytest.raises(ValueError, match=r"engine 'toy' cannot model earth curvature, and curvature is 0.85714"):
        compare(g, engine="toy", curvature=0.85714, **kw)
    with pytest.raises(ValueError, match="engine 'embree' cannot model earth curvature, and curvature is 0.5"):
        compare(g, engine="embree", curvature=0.5, **kw)  # refused before any unit runs, not in every unit
    with pytest.raises(ValueError, match="engine 'tin' does not run on grids"):
        compare(g, engine="tin", **kw)


@pytest.mark.slow
def test_worker_processes_get_it(toy):
    g = {"g": synthetic_terrain("hills", size=33, seed=2)}
    kw = dict(methods=["lls"], levels=[1, 2], n_points=10, n_sets=1, repeats=1, relocations=["full"], engine="toy")
    cols = ["level", "accuracy", "agree_visible"]
    pd.testing.assert_frame_equal(compare(g, workers=1, **kw)[cols], compare(g, workers=2, **kw)[cols])


def test_the_command_line_takes_it(toy, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["compare", "--terrain", "hills", "--levels", "1", "--methods", "lls", "--points", "8", "--sets", "1",
                 "--repeats", "1", "--workers", "1", "--relocations", "full", "--engine", "toy", "--no-plots",
                 "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["compare", "--terrain", "hills", "--levels", "1", "--methods", "lls", "--points", "8", "--sets", "1",
                 "--engine", "embree", "--curvature", "0.85714", "--no-plots", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("terrainvis compare: error: engine 'embree' cannot model earth curvature")
    assert "\n" not in err and not (tmp_path / "x" / "results.csv").exists()
