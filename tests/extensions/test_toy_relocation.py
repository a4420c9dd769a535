"""Adding a relocation touches the registry and the relocation's own module only.

A toy relocation, full projection raised by a ``lift`` option, is written as a module of
its own (in a temporary folder) and given one :func:`terrainvis.relocation.register`
call. ``lift`` is an option of a run of its own, declared in that module
(``Relocation(run_options=...)``): its default, check, help and flag. Nothing else is
edited, and every layer picks it up: ``relocate`` with its option checks, ``compare`` in
this process and on two worker processes (which import terrainvis afresh and get the entry
sent with each unit) with ``lift=`` validated, stored and checked on resume, the report's
tables (and its own table, declared beside it), the figures (in its declared style) and the command line (``terrainvis compare
--lift``, ``terrainvis relocate --how toy --lift``).
"""

from __future__ import annotations

import dataclasses
import json
import re
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from terrainvis import HeightGrid, compare, relocate, synthetic_terrain
from terrainvis.cli import main
from terrainvis.experiment import plot, report
from terrainvis.relocation import (
    RELOCATIONS,
    Option,
    Relocation,
    available,
    default_relocations,
    register,
    run_options,
    unregister,
)

_MODULE = '''
"""A toy relocation: full projection, raised by ``lift``, an option of a run of its own."""
from terrainvis import relocate
from terrainvis.relocation import Flag, Option


def lift_height(value, name):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= 1000.0:
        raise ValueError(f"{name} must be a height in [0, 1000] (z units), got {value!r}")
    return float(value)


#: compare(lift=...), terrainvis compare --lift, terrainvis relocate --how toy --lift
LIFT = Option("lift", 1.0, lift_height, "toy relocation: how far above S(T) it lifts the points", "float",
              cli=Flag(type=float))


def lifted(points, simplified, *, offset=0.0, lift=1.0):
    out = relocate(points, simplified, "full", offset=offset)
    out[:, 2] += lift
    return out


def lift_table(accuracy):
    """The report's table of its own: what the lift gains over full projection (points)."""
    gain = (accuracy["toy"] - accuracy["full"]).to_frame("lift_gain")
    gain.attrs["title"] = "Toy: the lift against full projection (accuracy points)"
    return {"toy_lift": gain}
'''


@pytest.fixture
def toy(tmp_path, monkeypatch):
    """The toy's module on sys.path (and on the workers' PYTHONPATH) and its one registration, undone afterwards."""
    (tmp_path / "toy_lift.py").write_text(textwrap.dedent(_MODULE))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    import toy_lift

    entry = register(Relocation("toy", toy_lift.lifted, "full projection, lifted", run_options=(toy_lift.LIFT,),
                                tables=toy_lift.lift_table, color="tab:olive", marker="P"))
    yield entry
    unregister("toy")


def _small(**kw):
    return {**dict(methods=["lls"], levels=[1], n_points=8, n_sets=1, repeats=1), **kw}


def test_relocate_runs_it_with_its_options(toy):
    S = HeightGrid(np.full((3, 3), 10.0))
    P = np.array([[0.5, 0.5, 4.0], [1.5, 1.0, 30.0]])
    assert relocate(P, S, "toy", offset=2.0, lift=0.5)[:, 2].tolist() == [12.5, 12.5]
    assert relocate(P, S, "toy")[:, 2].tolist() == [11.0, 11.0]
    # an option of another relocation is ignored (one set of options serves a loop); an unknown one is refused
    assert relocate(P, S, "toy", n_partners=5)[:, 2].tolist() == [11.0, 11.0]
    with pytest.raises(TypeError, match=re.escape("relocate got unknown option(s) ['lfit']; 'toy' takes ['lift']")):
        relocate(P, S, "toy", lfit=2.0)
    # its run option's check runs in relocate as in compare
    with pytest.raises(ValueError, match=re.escape("lift must be a height in [0, 1000] (z units), got -1.0")):
        relocate(P, S, "toy", lift=-1.0)
    assert available()[-1] == "toy" and "toy" not in default_relocations() and RELOCATIONS["toy"] is toy


def test_registering_is_checked(toy):
    def no_offset(points, simplified):
        return points

    with pytest.raises(ValueError, match="relocation 'full' is built in and cannot be replaced"):
        register(Relocation("full", no_offset, "x"))
    with pytest.raises(ValueError, match="a relocation named 'toy' is registered already; pass replace=True"):
        register(Relocation("toy", toy.function, "again", options=("lift",)))
    with pytest.raises(TypeError, match="relocation 'bad': its function takes no keyword 'offset'"):
        register(Relocation("bad", no_offset, "no offset"))
    with pytest.raises(ValueError, match=r"measures must be None \(every measure\) or a non-empty tuple"):
        register(Relocation("bad", toy.function, "x", measures="pairs"))
    with pytest.raises(ValueError, match="relocation 'oracle' is built in and cannot be removed"):
        unregister("oracle")
    with pytest.raises(TypeError, match="relocation 'bad': tables must be callable or None, got"):
        register(Relocation("bad", toy.function, "x", options=("lift",), tables={"t": pd.DataFrame()}))
    # a run option is an Option, and one name is one declaration: another relocation's option of that name is it
    def anything(points, simplified, *, offset=0.0, **options):
        return points

    with pytest.raises(TypeError, match="relocation 'bad': each of run_options must be a terrainvis.core.option.Option"):
        register(Relocation("bad", anything, "x", run_options=("lift",)))
    register(Relocation("same", anything, "the toy's lift, the very declaration", run_options=(toy.run_options[0],)))
    unregister("same")
    for theirs in run_options():  # the built-in relocations' and the toy's, as the registry has them
        other = dataclasses.replace(theirs, help="another meaning")
        with pytest.raises(ValueError, match=f"relocation 'bad': its run option '{theirs.name}' is declared otherwise "
                                             "by the '"):
            register(Relocation("bad", anything, "x", run_options=(other,)))
    assert "bad" not in RELOCATIONS
    with pytest.raises(ValueError, match="how must be one of"):
        relocate(np.zeros((1, 3)), HeightGrid(np.zeros((2, 2))), "tyo")


def test_a_relocation_that_moves_points_sideways_is_refused():
    def sideways(points, simplified, *, offset=0.0):
        out = points.copy()
        out[:, 0] += 1.0
        return out

    register(Relocation("sideways", sideways, "a broken relocation"))
    try:
        with pytest.raises(ValueError, match="relocation 'sideways' moved points horizontally"):
            relocate(np.array([[0.5, 0.5, 1.0]]), HeightGrid(np.zeros((2, 2))), "sideways")
    finally:
        unregister("sideways")


def test_compare_the_report_and_the_figures_pick_it_up(toy):
    grid = synthetic_terrain("hills", size=33, seed=2)
    df = compare({"g": grid}, relocations=["full", "toy"], workers=1, **_small(max_distance=[None, 300.0]))
    assert df["error"].isna().all() and list(dict.fromkeys(df["relocation"])) == ["full", "toy"]
    beyond = report.beyond_paper(df)
    assert "toy" in beyond.columns and "beyond the paper" in beyond.attrs["title"].lower()
    assert "toy" in beyond.attrs["title"] and "gain" not in beyond.columns  # no calibrated rows: no gain column
    assert list(report.localized(df).index.get_level_values("relocation").unique()) == ["full", "toy"]
    own = report.relocation_tables(df)  # its table of its own, from its registry entry
    assert list(own) == ["toy_lift"] and own["toy_lift"].attrs["title"].startswith("Toy: the lift")
    allpairs = df[df["max_distance"].isna()]
    mu = 100 * allpairs.groupby("relocation")["accuracy"].mean()
    assert own["toy_lift"].loc[("lls", 1), "lift_gain"] == pytest.approx(mu["toy"] - mu["full"])
    fig = plot.accuracy_vs_size(df)
    assert [ax.get_title() for ax in fig.axes[:2]] == ["relocation: full", "relocation: toy"]
    fig = plot.accuracy_vs_distance(df)
    line = [ln for ln in fig.axes[0].get_lines() if ln.get_label() == "toy"][0]
    assert line.get_color() == "tab:olive" and line.get_marker() == "P"
    # a measure it does not serve is refused, naming it
    register(Relocation("pairs-only", toy.function, "x", options=("lift",), measures=("pairs",)))
    try:
        with pytest.raises(ValueError, match="measure 'viewshed' does not support the 'pairs-only' relocation"):
            compare({"g": grid}, relocations=["pairs-only"], measure="viewshed", workers=1, **_small())
    finally:
        unregister("pairs-only")


@pytest.mark.slow
def test_worker_processes_get_it_and_give_the_same_rows(toy):
    grid = synthetic_terrain("hills", size=33, seed=2)
    kw = _small(levels=[1, 2], lift=5.0)  # its run option reaches the workers with the settings
    serial = compare({"g": grid}, relocations=["toy"], workers=1, **kw)
    pooled = compare({"g": grid}, relocations=["toy"], workers=2, **kw)
    cols = ["terrain", "method", "level", "relocation", "accuracy", "n_pairs", "agree_visible", "false_visible"]
    pd.testing.assert_frame_equal(serial[cols], pooled[cols])
    assert pooled["error"].isna().all()
    at_default = compare({"g": grid}, relocations=["toy"], workers=1, **{**kw, "lift": 1.0})
    assert not serial[cols].equals(at_default[cols])  # so equal rows say the workers lifted by 5


def toy_function(points, simplified, *, offset=0.0, scale=1.0):
    """A relocation workers can import (this module's top level): the points as given."""
    return points.copy()


def test_a_function_workers_cannot_import_is_refused_before_the_run(tmp_path):
    grid = synthetic_terrain("hills", size=33, seed=2)
    register(Relocation("inline", lambda points, simplified, *, offset=0.0: points.copy(), "a lambda"))
    try:
        with pytest.raises(TypeError, match=r"relocation 'inline': its function \S*<lambda> cannot be sent to worker "
                                            r"processes .*top level of a module.*workers=1"):
            compare({"g": grid}, relocations=["inline"], workers=2, out_csv=tmp_path / "r.csv", **_small(levels=[1, 2]))
        assert not (tmp_path / "r.csv").exists()  # refused before anything was written
        assert (compare({"g": grid}, relocations=["inline"], workers=1, **_small())["error"].isna()).all()
    finally:
        unregister("inline")
    # the same for a run option's check (the checks terrainvis.core.option builds are sent)
    register(Relocation("checked", toy_function, "x", run_options=(
        Option("scale", 1.0, lambda value, name: float(value), "a toy's scale", "float"),)))
    try:
        with pytest.raises(TypeError, match=r"relocation 'checked': its entry \(a check of its run options\?\) "
                                            r"cannot be sent to worker processes .*top level of a module"):
            compare({"g": grid}, relocations=["checked"], workers=2, **_small(levels=[1, 2]))
    finally:
        unregister("checked")


def test_the_command_line_picks_it_up(toy, tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["compare", "--terrain", "hills", "--levels", "1", "--methods", "lls", "--points", "8", "--sets", "1",
            "--repeats", "1", "--workers", "1", "--relocations", "full", "toy"]
    assert main([*argv, "--lift", "2", "--out", str(out)]) == 0
    assert "| toy |" in (out / "tables.md").read_text() or " toy " in (out / "tables.md").read_text()
    assert "### Toy: the lift against full projection (accuracy points)" in (out / "tables.md").read_text()
    assert (out / "tradeoff_toy.png").exists()
    assert json.loads((out / "results.settings.json").read_text())["lift"] == 2.0
    cols = ["relocation", "accuracy", "agree_visible", "false_visible", "false_blocked"]
    api = compare(["hills"], relocations=["full", "toy"], lift=2.0, workers=1, **_small())
    pd.testing.assert_frame_equal(pd.read_csv(out / "results.csv")[cols], api[cols], check_dtype=False)
    capsys.readouterr()
    assert main([*argv, "--lift", "-1", "--out", str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err
    assert "--lift must be a height in [0, 1000] (z units), got -1.0" in err and len(err.strip().splitlines()) == 1
    with pytest.raises(SystemExit):
        main(["compare", "--help"])
    assert "--lift LIFT toy relocation: how far above S(T) it lifts the points (default: 1)" in " ".join(
        capsys.readouterr().out.split())
    pts = tmp_path / "p.csv"
    pts.write_text("x,y\n600,600\n1800,2400\n")
    for extra, lift in (([], 1.0), (["--lift", "2.5"], 2.5)):
        assert main(["relocate", "hills", "-m", "lls", "-l", "1", "--points", str(pts), "--how", "toy", *extra,
                     "-o", str(tmp_path / "moved.csv")]) == 0
        moved = pd.read_csv(tmp_path / "moved.csv")
        np.testing.assert_allclose(moved["z"], moved["ground_simplified"] + lift, atol=1e-6)
    capsys.readouterr()
    assert main(["relocate", "hills", "-m", "lls", "-l", "1", "--points", str(pts), "--how", "toy", "--lift", "-1",
                 "-o", str(tmp_path / "bad.csv")]) == 2
    assert "--lift must be a height in [0, 1000] (z units), got -1.0" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["relocate", "--help"])
    shown = " ".join(capsys.readouterr().out.split())
    assert "toy: full projection, lifted" in shown
    assert "--lift LIFT toy relocation: how far above S(T) it lifts the points (default: 1)" in shown


def test_its_memory_estimate_is_checked_before_a_run_and_named(tmp_path, monkeypatch):
    # a relocation declares what it allocates per unit; the run is refused before it starts, naming it
    from terrainvis.errors import NotEnoughMemoryError
    from terrainvis.experiment import plan

    def huge(settings):
        return 10 * 2**40, f"the toy's table of {settings.n_points:,} points"

    register(Relocation("toy-memory", lambda points, simplified, *, offset=0.0: points.copy(), "keeps the points",
                        memory=huge))
    try:
        monkeypatch.setattr("terrainvis.core.memory.available_memory", lambda: 2**30)
        grids = {"h": synthetic_terrain("hills", size=17, seed=0)}
        settings = plan.settings_for(grids, _small(relocations=["full", "toy-memory"]))
        assert plan.unit_bytes(settings, grids) - plan.unit_bytes(
            plan.settings_for(grids, _small(relocations=["full"])), grids) == 10 * 2**40
        with pytest.raises(NotEnoughMemoryError,
                           match=r"^the toy.s table of 8 points needs at least 10 TiB of memory, but this machine "
                                 r"has 1 GiB "):
            compare(grids, relocations=["full", "toy-memory"], workers=1, **{k: v for k, v in _small().items()})
    finally:
        unregister("toy-memory")


def test_its_own_run_option_is_a_keyword_of_compare_checked_stored_and_resumed(toy, tmp_path):
    """``run_options=(LIFT,)`` and nothing else: compare takes ``lift``, hands it to the toy (other rows, the
    other relocations' the same), refuses a bad value naming it before any unit runs, stores it with the run's
    settings and refuses a resume with another value, naming it."""
    from terrainvis.experiment.options import DEFAULTS, OPTIONS

    assert OPTIONS["lift"] is toy.run_options[0] and DEFAULTS.lift == 1.0
    kw = dict(relocations=["full", "toy"], workers=1, **_small())
    out = tmp_path / "results.csv"
    low = compare(["hills"], **kw)
    high = compare(["hills"], lift=2.0, out_csv=out, **kw)
    cols = ["relocation", "accuracy", "agree_visible", "false_visible", "false_blocked"]
    full = [df[df["relocation"] == "full"][cols].reset_index(drop=True) for df in (low, high)]
    pd.testing.assert_frame_equal(*full)
    toys = [df[df["relocation"] == "toy"].reset_index(drop=True) for df in (low, high)]
    assert (toys[1]["false_visible"] > toys[0]["false_visible"]).all()  # lifted higher, the points see more
    assert json.loads((tmp_path / "results.settings.json").read_text())["lift"] == 2.0
    for bad, shown in ((-1.0, "-1.0"), ("2", "'2'")):
        with pytest.raises(ValueError, match=re.escape(f"lift must be a height in [0, 1000] (z units), got {shown}")):
            compare(["hills"], lift=bad, out_csv=tmp_path / "bad.csv", **kw)
        assert not (tmp_path / "bad.csv").exists()  # refused before anything ran
    with pytest.raises(ValueError, match=re.escape("lift: 2.0 before, 3.0 now")):
        compare(["hills"], lift=3.0, out_csv=out, resume=True, **kw)
    again = compare(["hills"], lift=2.0, out_csv=out, resume=True, **kw)  # the same value resumes
    pd.testing.assert_frame_equal(again[cols], high[cols])


def test_help_of_compare_shows_its_own_run_option_while_it_is_registered(toy):
    """``help(compare)`` reads compare's signature and docstring: they name ``lift`` (keyword-only,
    its default, its help) from the registration on, and no longer once it is removed."""
    import inspect

    param = inspect.signature(compare).parameters["lift"]
    assert param.kind is inspect.Parameter.KEYWORD_ONLY and param.default == 1.0
    assert "how far above S(T) it lifts the points" in compare.__doc__
    unregister("toy")
    try:
        assert "lift" not in inspect.signature(compare).parameters
        assert "how far above S(T) it lifts the points" not in compare.__doc__
    finally:
        register(toy)
    assert "lift" in inspect.signature(compare).parameters


def test_a_run_option_of_a_relocation_may_not_take_a_name_of_compare(toy):
    from terrainvis.experiment.options import OPTIONS

    central = next(name for name in OPTIONS if name not in {o.name for o in run_options()})
    def anything(points, simplified, *, offset=0.0, **options):
        return points

    register(Relocation("clash", anything, "x", run_options=(dataclasses.replace(toy.run_options[0], name=central),)))
    try:
        with pytest.raises(TypeError, match=f"relocation 'clash' declares a run option '{central}', which is an "
                                            "option of compare already"):
            compare(["hills"], relocations=["full"], workers=1, **_small())
    finally:
        unregister("clash")


def test_what_a_relocation_needs_is_declared_and_read(toy, tmp_path, capsys):
    """``needs=("original",)``: terrainvis.testing and terrainvis relocate hand it T; a relocation that needs T's
    verdicts of the pairs (a bound) is not offered by ``--how`` and refused by terrainvis.testing."""
    import simplifiers
    from terrainvis import bundled_terrain
    from terrainvis.cli.relocate import offered_relocations
    from terrainvis.testing import assert_visibility_kept

    def near_t(points, simplified, *, offset=0.0, original=None):
        if original is None:
            raise TypeError("near_t needs original=")
        return relocate(points, original, "full", offset=offset)  # the points on T: every verdict kept

    register(Relocation("near-t", near_t, "the points on T itself", options=("original",), needs=("original",)))
    try:
        T = bundled_terrain("hills")
        kept = assert_visibility_kept(T, simplifiers.simplify(T, "lls", 2), min_accuracy=0.0, n=12,
                                      relocation="near-t")
        assert kept["n_pairs"] == 66
        assert "near-t" in offered_relocations()
        pts = tmp_path / "p.csv"
        pts.write_text("x,y\n600,600\n1800,2400\n")
        assert main(["relocate", "hills", "-m", "lls", "-l", "1", "--points", str(pts), "--how", "near-t",
                     "-o", str(tmp_path / "moved.csv")]) == 0
        moved = pd.read_csv(tmp_path / "moved.csv")
        np.testing.assert_allclose(moved["z"], moved["z_original"], atol=1e-6)
    finally:
        unregister("near-t")
    bounds = [name for name, r in RELOCATIONS.items() if "reference" in r.needs]
    assert bounds and not set(bounds) & set(offered_relocations())
    with pytest.raises(ValueError, match=f"relocation {bounds[0]!r} needs reference"):
        assert_visibility_kept(T, T, min_accuracy=0.0, n=4, relocation=bounds[0])
    with pytest.raises(ValueError, match=r"relocation 'bad': needs must be a tuple of \['original', 'reference'\]"):
        register(Relocation("bad", near_t, "x", options=("original",), needs=("t",)))


def test_the_experiment_and_the_commands_name_no_relocation_s_own_option():
    """compare, its units and the commands read a relocation's own options from the registry: no module of the
    experiment, of the command line or terrainvis.testing names one (their names and flags, asked of the registry)."""
    import terrainvis
    from terrainvis.core.option import Switch

    words = set()
    for option in run_options():
        words |= {option.name} | ({option.cli.on, option.cli.off} - {None} if isinstance(option.cli, Switch)
                                  else {option.flag} - {None})
    assert words
    root = Path(terrainvis.__file__).parent
    files = [*sorted((root / "experiment").rglob("*.py")), *sorted((root / "cli").rglob("*.py")), root / "testing.py"]
    named = [(f.relative_to(root).as_posix(), w) for f in files for w in sorted(words)
             if re.search(rf"(?<![\w-]){re.escape(w)}(?![\w-])", f.read_text(encoding="utf-8"))]
    assert not named, named
