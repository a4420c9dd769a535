"""Options of compare declared once: the signature, the docstring, the CLI flags, the stored settings.

The last tests add a toy option the way tests/extensions/test_toy_method.py adds a toy method: one
entry in :data:`terrainvis.experiment.options.OPTIONS` (monkeypatched), no other file edited, and
the option is accepted and validated by ``compare``, offered by ``terrainvis compare``,
stored in the run's settings and checked on resume.
"""

from __future__ import annotations

import ast
import inspect
import json
import pickle
from pathlib import Path

import numpy as np
import pytest

from terrainvis import compare, synthetic_terrain
from terrainvis.experiment import comparison as experiment
from terrainvis.cli import main
from terrainvis.experiment.options import DEFAULTS, OPTIONS, Flag, Option, Settings, Switch, validate
from terrainvis.experiment.results import settings_path

RUN_CONTROLS = ["workers", "client", "out_csv", "resume", "save_dir", "progress", "on_unit"]


@pytest.fixture(scope="module")
def grid():
    return synthetic_terrain("hills", size=17, seed=4)


def _small(**extra):
    kw = dict(methods=["lls"], levels=[1], n_points=6, n_sets=1, repeats=1, workers=1)
    kw.update(extra)
    return kw


# ---------------------------------------------------------------------- the signature and docstring
def test_the_signature_is_the_declarations():
    params = inspect.signature(compare).parameters
    names = list(params)
    assert names[0] == "terrains" and names[1:] == list(OPTIONS) + RUN_CONTROLS
    for name, option in OPTIONS.items():
        p = params[name]
        assert p.kind is inspect.Parameter.KEYWORD_ONLY, name
        assert p.default == option.default == getattr(DEFAULTS, name), name
    doc = compare.__doc__
    assert "<options>" not in doc
    for name, option in OPTIONS.items():
        assert f"\n    {name} : {option.type}, default {option.default!r}" in doc, name
    # the doctest of the docstring still runs (pytest --doctest-modules collects the generated text)
    assert ">>> df = compare([\"hills\"]" in doc


def test_unknown_options_are_refused_naming_the_known_ones(grid):
    with pytest.raises(TypeError, match=r"compare\(\) got unexpected option\(s\) \['n_point'\]; the options are \['methods'"):
        compare({"g": grid}, n_point=5, workers=1)


def test_settings_read_defaults_and_are_immutable():
    s = Settings(n_points=20)
    assert s.n_points == 20 and s.n_sets == OPTIONS["n_sets"].default
    assert s.replace(n_sets=2).n_sets == 2 and s.n_sets == 6
    with pytest.raises(AttributeError, match="immutable"):
        s.n_points = 3
    with pytest.raises(TypeError, match=r"unknown option\(s\) \['points'\]"):
        Settings(points=3)
    with pytest.raises(AttributeError, match="no option 'points'"):
        s.points  # noqa: B018
    assert pickle.loads(pickle.dumps(s)) == s and pickle.loads(pickle.dumps(s)).n_points == 20
    assert list(DEFAULTS.as_dict()) == list(OPTIONS)


def test_every_flag_reaches_compare_with_its_value(monkeypatch, tmp_path):
    """Each option's flag, given on the command line, arrives at compare under the option's name."""
    seen = {}

    class Stop(Exception):
        pass

    def fake(terrains, **kw):
        seen.update(kw)
        raise Stop

    monkeypatch.setattr(experiment, "compare", fake)
    argv = ["compare", "--terrain", "hills", "--out", str(tmp_path), "--methods", "lls", "gls", "--levels", "2",
            "--relocations", "full", "--points", "7", "--sets", "3", "--seed", "5", "--max-distance", "100", "all",
            "--distance-unit", "cells", "--offset", "1.5", "--engine", "grid", "--predicate", "paper",
            "--no-volume", "--repeats", "2", "--no-cascade", "--partners", "99", "--no-neighbours", "--curvature", "0.5",
            "--earth-radius", "6371000"]
    with pytest.raises(Stop):
        main(argv)
    expected = dict(methods=["lls", "gls"], levels=[2], relocations=["full"], n_points=7, n_sets=3, seed=5,
                    max_distance=[100.0, None], distance_unit="cells", offset=1.5, engine="grid",
                    predicate="paper", volume=False, repeats=2, cascade=False, n_partners=99, neighbours=False,
                    curvature=0.5, earth_radius=6371000.0)
    assert {k: seen[k] for k in expected} == expected
    seen.clear()
    with pytest.raises(Stop):  # the viewshed measure's options (it refuses predicate 'paper')
        main(["compare", "--terrain", "hills", "--out", str(tmp_path), "--measure", "viewshed", "--observers", "4",
              "--target-height", "0.5", "--no-min-height", "--siting", "2"])
    viewshed = dict(measure="viewshed", n_observers=4, target_height=0.5, min_height=False, siting=2)
    assert {k: v for k, v in seen.items() if k in OPTIONS} == viewshed
    expected.update(viewshed)
    seen.clear()
    with pytest.raises(Stop):  # budgets in vertical error, in place of --levels
        main(["compare", "--terrain", "hills", "--out", str(tmp_path), "--max-error", "2", "5.5"])
    assert {k: v for k, v in seen.items() if k in OPTIONS} == {"max_errors": [2.0, 5.5]}
    expected["max_errors"] = [2.0, 5.5]
    assert set(expected) == {n for n, o in OPTIONS.items() if o.cli is not None}  # the test covers every flag
    seen.clear()
    with pytest.raises(Stop):
        main(["compare", "--terrain", "hills", "--out", str(tmp_path), "--cascade"])
    assert seen["cascade"] is True and not set(seen) & (set(OPTIONS) - {"cascade"})  # the rest: compare's defaults
    seen.clear()
    with pytest.raises(Stop):
        main(["compare", "--quick", "--points", "9", "--out", str(tmp_path)])
    assert (seen["levels"], seen["n_points"], seen["n_sets"]) == ([1, 3], 9, 2)
    from terrainvis.relocation.calibrated import CORE_PARTNERS

    assert seen["n_partners"] == CORE_PARTNERS  # quick: the core partners alone


def test_the_help_shows_every_flag_with_its_default(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["compare", "--help"])
    assert exit_.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    for option in OPTIONS.values():
        if isinstance(option.cli, Flag):
            assert f"{option.flag} " in text and f"(default: {option.shown_default()})" in text, option.name
        elif isinstance(option.cli, Switch):
            assert all(f in text for f in (option.cli.on, option.cli.off) if f), option.name
    assert "--points POINTS " in text and "points per set (pairs only) (default: 50)" in text


def test_a_settings_file_without_a_newer_option_resumes_at_its_default(grid, tmp_path):
    out = tmp_path / "results.csv"
    compare({"g": grid}, out_csv=out, **_small())
    stored = json.loads(settings_path(out).read_text())
    del stored["target_height"]  # as if written before the option existed
    settings_path(out).write_text(json.dumps(stored))
    compare({"g": grid}, out_csv=out, resume=True, **_small())  # its default: the same run
    settings_path(out).write_text(json.dumps(stored))
    with pytest.raises(ValueError, match=r"target_height: 0.0 before, 1.0 now"):
        compare({"g": grid}, out_csv=out, resume=True, **_small(target_height=1.0))


def test_relocations_are_read_from_their_registry(grid):
    """A relocation registered with terrainvis.relocation.register is a valid name at once, and gone after."""
    import re

    from terrainvis.relocation import Relocation, available, register, unregister

    register(Relocation("toy", lambda points, simplified, *, offset=0.0: points, "the points as given"))
    try:
        s = validate({"g": grid}, {"relocations": ["toy", "full"]})
        assert s.relocations == ("toy", "full")
        assert "toy" not in validate({"g": grid}, {}).relocations  # not declared default
    finally:
        unregister("toy")
    with pytest.raises(ValueError, match=re.escape(f"relocations must be drawn from {available()}, got 'toy'")):
        validate({"g": grid}, {"relocations": ["toy"]})


# ---------------------------------------------------------------------- the toy option
def _positive(value, name):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise ValueError(f"{name} must be a number > 0, got {value!r}")
    return float(value)


@pytest.fixture
def toy(monkeypatch):
    """One entry: a float option with its check, help and flag (undone afterwards)."""
    entry = Option("toy_scale", 1.0, _positive, "a toy's scale", "float", cli=Flag(type=float))
    monkeypatch.setitem(OPTIONS, "toy_scale", entry)
    return entry


def test_a_toy_option_is_accepted_validated_stored_and_checked_on_resume(toy, grid, tmp_path):
    out = tmp_path / "results.csv"
    df = compare({"g": grid}, out_csv=out, toy_scale=2.5, **_small())
    assert df["error"].isna().all()
    assert json.loads(settings_path(out).read_text())["toy_scale"] == 2.5
    with pytest.raises(ValueError, match=r"toy_scale must be a number > 0, got -1"):
        compare({"g": grid}, toy_scale=-1, **_small())
    with pytest.raises(ValueError, match=r"other settings \(toy_scale: 2.5 before, 3.0 now\)"):
        compare({"g": grid}, out_csv=out, resume=True, toy_scale=3.0, **_small())
    compare({"g": grid}, out_csv=out, resume=True, toy_scale=2.5, **_small())  # the same value resumes
    assert Settings(toy_scale=4.0).toy_scale == 4.0 and DEFAULTS.toy_scale == 1.0


def test_a_toy_option_is_on_the_command_line(toy, tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["compare", "--help"])
    assert "--toy-scale TOY_SCALE" in capsys.readouterr().out
    out = tmp_path / "run"
    argv = ["compare", "--terrain", "hills", "--levels", "1", "--methods", "lls", "--points", "6", "--sets", "1",
            "--repeats", "1", "--workers", "1", "--no-plots", "--out", str(out)]
    assert main([*argv, "--toy-scale", "3"]) == 0
    assert json.loads(settings_path(out / "results.csv").read_text())["toy_scale"] == 3.0
    capsys.readouterr()
    assert main([*argv, "--toy-scale", "0", "--resume"]) == 2
    assert "--toy-scale must be a number > 0, got 0.0" in capsys.readouterr().err
    assert main([*argv, "--toy-scale", "4", "--resume"]) == 2
    assert "toy_scale: 3.0 before, 4.0 now" in capsys.readouterr().err


def test_the_run_s_sight_reaches_every_visibility_computation(monkeypatch, grid):
    """The options declared ``los=True`` are the fields of the run's Sight, one record that the units
    hand to visibility_matrix, viewshed, the viewshed measure's siting (site_observers) and every
    relocation that computes visibility itself (declared ``predicate=True``: calibrated, oracle; with the
    end radius of its verdicts on S(T)); a relocation that does not (full) gets none of it."""
    from terrainvis.relocation import registry as relocation
    from terrainvis import visibility

    seen, inside = [], []

    def spy(fn):
        def wrapped(*args, **kw):
            if not inside:  # the units' own calls, not relocate's calls of visibility_matrix
                s = kw.get("sight")
                seen.append((fn.__name__, args[2] if fn.__name__ == "relocate" else None,
                             s.curvature if s is not None else "no Sight"))
            inside.append(fn)
            try:
                return fn(*args, **kw)
            finally:
                inside.pop()
        return wrapped

    for module, name in ((visibility, "visibility_matrix"), (visibility, "viewshed"), (visibility, "site_observers"),
                         (relocation, "relocate")):
        monkeypatch.setattr(module, name, spy(getattr(module, name)))
    df = compare({"g": grid}, curvature=0.13, relocations=["full", "calibrated", "oracle"], **_small())
    assert df["error"].isna().all()
    assert set(seen) == {("visibility_matrix", None, 0.13), ("relocate", "full", "no Sight"),
                         ("relocate", "calibrated", 0.13), ("relocate", "oracle", 0.13)}
    seen.clear()
    df = compare({"g": grid}, curvature=0.25, measure="viewshed", n_observers=1,
                 **_small(relocations=["half", "calibrated"]))
    assert df["error"].isna().all()
    assert set(seen) == {("viewshed", None, 0.25), ("relocate", "half", "no Sight"), ("relocate", "calibrated", 0.25),
                         ("site_observers", None, 0.25)}
    # an option declared los=True is a field of the Sight: one that names none is refused before any unit runs
    monkeypatch.setitem(OPTIONS, "toy_refraction", Option("toy_refraction", 0.0, lambda v, n: float(v),
                                                          "a toy refraction", "float", los=True))
    seen.clear()
    with pytest.raises(TypeError, match=r"the options declared los=True must be fields of a "
                                        r"terrainvis.visibility.Sight, got \['curvature', 'earth_radius', 'engine', "
                                        r"'toy_refraction'\]"):
        compare({"g": grid}, toy_refraction=0.1, **_small())
    assert seen == []
