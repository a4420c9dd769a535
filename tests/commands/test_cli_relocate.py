"""terrainvis relocate: the same heights as the API, from a file or a simplification made on the spot; one-line errors."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import simplifiers
import terrainvis as tv
from terrainvis.cli import main


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    folder = tmp_path_factory.mktemp("relocate")
    T = tv.bundled_terrain("ridges")
    P = tv.sample_points(T, 12, seed=4)
    pd.DataFrame({"x": P[:, 0], "y": P[:, 1]}).to_csv(folder / "points.csv", index=False)
    S = simplifiers.simplify(T, "lls", 2)
    tv.save_terrain(S, folder / "s.npz")
    return folder, T, P, S


def _run(capsys, argv):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_the_heights_are_the_apis(case, capsys):
    folder, T, P, S = case
    out = folder / "out.csv"
    code, text, _ = _run(capsys, ["relocate", "ridges", "--simplified", str(folder / "s.npz"), "--points",
                                  str(folder / "points.csv"), "-o", str(out), "--partners", "100", "--seed", "2"])
    assert code == 0 and "12 points relocated (calibrated)" in text
    assert "earth: flat" in text  # the model of its lines of sight, as los and viewshed print it
    got = pd.read_csv(out)
    assert list(got.columns) == ["x", "y", "z", "z_original", "ground_simplified"]
    expected = tv.relocate(P, S, "calibrated", original=T, n_partners=100, seed=2)
    assert np.allclose(got["z"], expected[:, 2], atol=1e-6)  # the CSV keeps 6 decimals
    assert np.allclose(got["z_original"], P[:, 2], atol=1e-6)
    assert np.allclose(got["ground_simplified"], S.height_at(P[:, :2]), atol=1e-6)
    # the same simplification made on the spot gives the same heights
    out2 = folder / "out2.csv"
    code, _, _ = _run(capsys, ["relocate", "ridges", "-m", "lls", "-l", "2", "--points", str(folder / "points.csv"),
                               "-o", str(out2), "--partners", "100", "--seed", "2"])
    assert code == 0 and pd.read_csv(out2).equals(got)


def test_given_heights_and_the_papers_relocations(case, capsys):
    folder, T, P, S = case
    table = pd.DataFrame({"x": P[:, 0], "y": P[:, 1], "z": P[:, 2] + 5.0})
    table.to_csv(folder / "high.csv", index=False)
    out = folder / "half.csv"
    code, _, _ = _run(capsys, ["relocate", "ridges", "--simplified", str(folder / "s.npz"), "--points",
                               str(folder / "high.csv"), "-o", str(out), "--how", "half", "--offset", "5"])
    assert code == 0
    expected = tv.relocate(table.to_numpy(), S, "half", offset=5.0)
    assert np.allclose(pd.read_csv(out)["z"], expected[:, 2], atol=1e-6)


@pytest.mark.parametrize("extra, message", [
    ([], "give the simplification as --simplified FILE or as -m METHOD [-l LEVEL], one of them"),
    (["-m", "lls", "--simplified", "s.npz"], "one of them"),
    (["--simplified", "s.npz", "-l", "2"], "-l goes with -m"),
    (["--simplified", "nowhere.npz"], "--simplified 'nowhere.npz' does not exist"),
    # the earth model is checked as by los, viewshed and cumulative (0 was accepted and refused later by the API)
    (["--simplified", "s.npz", "--curvature", "0.85714", "--earth-radius", "0"], "argument --earth-radius: expected a radius > 0, got '0'"),
    (["--simplified", "s.npz", "--curvature", "-1"], "argument --curvature: expected a coefficient >= 0"),
])
def test_errors_are_one_line(case, capsys, monkeypatch, extra, message):
    folder, *_ = case
    monkeypatch.chdir(folder)
    code, _, err = _run(capsys, ["relocate", "ridges", "--points", "points.csv", "-o", "o.csv", *extra])
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1


def test_bad_points_and_outputs(case, capsys, monkeypatch):
    folder, T, *_ = case
    monkeypatch.chdir(folder)
    (folder / "bad.csv").write_text("x,y\n100,200\n1,abc\n")
    code, _, err = _run(capsys, ["relocate", "ridges", "--simplified", "s.npz", "--points", "bad.csv", "-o", "o.csv"])
    assert code == 2 and "--points 'bad.csv': row 2 (line 3), column y holds 'abc', not a finite number" in err
    (folder / "far.csv").write_text(f"x,y\n100,200\n{T.extent[1] + 500},200\n")
    code, _, err = _run(capsys, ["relocate", "ridges", "--simplified", "s.npz", "--points", "far.csv", "-o", "o.csv"])
    assert code == 2 and "row 2" in err and "outside the DEM" in err
    code, _, err = _run(capsys, ["relocate", "ridges", "--simplified", "s.npz", "--points", "points.csv",
                                 "-o", "points.csv"])
    assert code == 2 and "never overwrites its input" in err
    code, _, err = _run(capsys, ["relocate", "ridges", "--simplified", "s.npz", "--points", "points.csv",
                                 "-o", "o.txt"])
    assert code == 2 and "-o must end in .csv" in err


@pytest.mark.parametrize("extra, message", [
    (["--how", "full", "--partners", "100"], "--partners is an option of calibrated, eye: --how full takes none of the "
                                             "relocations' own options"),
    (["--how", "half", "--no-neighbours"], "--no-neighbours is an option of calibrated, eye: --how half takes none"),
    (["--how", "identity", "--target-height", "2"], "--target-height is for calibrated, eye: --how identity takes no "
                                                    "target height"),
])
def test_another_relocations_flag_is_refused_not_ignored(case, capsys, monkeypatch, extra, message):
    """A flag that the chosen relocation does not read would change nothing: one line says whose it is."""
    folder, *_ = case
    monkeypatch.chdir(folder)
    code, _, err = _run(capsys, ["relocate", "ridges", "--points", "points.csv", "-o", "refused.csv",
                                 "--simplified", "s.npz", *extra])
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not (folder / "refused.csv").exists()
