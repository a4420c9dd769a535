"""Golden regression tests: what the project computes on fixed inputs, pinned.

The invariants elsewhere check that every result is valid; these check that it is the
same result as before. A failure here means a change moved the vertex counts, errors or
agreement counts of the paper's experiment. If that is deliberate, regenerate the files
with ``python tests/data/make_golden.py`` and say in the commit what moved and why.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from conftest import SHARED_DEM

DATA = Path(__file__).resolve().parents[1] / "data"
REGENERATE = "if the change is deliberate, run `python tests/data/make_golden.py` and explain it in the commit"


def _load(name):
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_golden", DATA / "make_golden.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return pd.read_csv(DATA / name, dtype={"terrain": str, "method": str, "relocation": str}), module


def _diff(expected: pd.DataFrame, got: pd.DataFrame, keys, exact, close) -> list[str]:
    merged = expected.merge(got, on=keys, how="outer", suffixes=("_golden", "_now"), indicator=True)
    problems = [f"{dict(zip(keys, r))}: only in {'the golden file' if side == 'left_only' else 'this run'}"
                for *r, side in merged[keys + ["_merge"]].itertuples(index=False) if side != "both"]
    both = merged[merged["_merge"] == "both"]
    for col in exact:
        bad = both[both[f"{col}_golden"] != both[f"{col}_now"]]
        problems += [f"{dict(zip(keys, r[:len(keys)]))}: {col} {r[-2]} golden, {r[-1]} now"
                     for r in bad[keys + [f"{col}_golden", f"{col}_now"]].itertuples(index=False)]
    for col in close:
        a, b = both[f"{col}_golden"].to_numpy(float), both[f"{col}_now"].to_numpy(float)
        bad = ~np.isclose(a, b, rtol=1e-9, atol=1e-9, equal_nan=True)
        problems += [f"{dict(zip(keys, r[:len(keys)]))}: {col} {r[-2]!r} golden, {r[-1]!r} now"
                     for r in both[bad][keys + [f"{col}_golden", f"{col}_now"]].itertuples(index=False)]
    return problems


def test_simplifiers_golden():
    if not (SHARED_DEM / "green_mountains_vt.npz").exists():
        pytest.skip(f"the shared DEMs are absent ({SHARED_DEM}); the golden table uses one of them")
    expected, mg = _load("golden_simplify.csv")
    problems = _diff(expected, mg.simplify_table(), ["terrain", "method", "level"], ["n_vertices"],
                     ["max_error", "rms_error"])
    assert not problems, "golden simplification results moved:\n" + "\n".join(problems[:40]) + f"\n({REGENERATE})"


@pytest.mark.slow
def test_compare_golden_and_cross_checked_by_embree():
    expected, mg = _load("golden_compare.csv")
    got = mg.compare_table()
    problems = _diff(expected, got, ["terrain", "set", "method", "level", "relocation"], ["n_vertices", *mg.COUNTS],
                     ["volume_error"])
    assert not problems, "golden agreement counts moved:\n" + "\n".join(problems[:40]) + f"\n({REGENERATE})"


def test_golden_verdicts_agree_with_embree_on_the_same_meshes():
    """The verdicts behind the golden counts, on S(T), are Embree's too (outside its float32 band)."""
    from simplifiers import simplify

    from terrainvis import bundled_terrain, min_clearance, relocate, visibility_matrix
    from terrainvis.experiment import point_sets
    from terrainvis.visibility import clearance_tolerance, embree_tolerance

    _, mg = _load("golden_compare.csv")
    for name in mg.COMPARE_TERRAINS:
        T = bundled_terrain(name)
        P = point_sets(T, name, mg.COMPARE_KW["n_points"], 1, mg.COMPARE_KW["seed"], 0.0)[0]
        for method in ("lls", "qec", "greedy-cuts"):
            S = simplify(T, method, 3)
            Q = relocate(P, S, "half")
            i, j = np.triu_indices(len(Q), 1)
            c = min_clearance(S, Q[i], Q[j])  # exact on grids and TINs
            exact = c >= -clearance_tolerance(S)
            embree = visibility_matrix(S, Q, engine="embree")[i, j]
            outside = np.abs(c) > embree_tolerance(S)
            assert (exact == embree)[outside].all(), (name, method, int((exact != embree)[outside].sum()))
            if method == "lls":  # and the grid engine that compare uses gives the exact answer
                assert (visibility_matrix(S, Q, engine="grid")[i, j] == exact).all()
