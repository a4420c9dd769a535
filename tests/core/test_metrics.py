"""agreement: how many line-of-sight verdicts survive."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from terrainvis import agreement


def test_agreement_hand_case():
    T = np.array([[1, 1, 0, 1], [1, 1, 1, 0], [0, 1, 1, 1], [1, 0, 1, 1]], bool)
    S = np.array([[1, 0, 0, 1], [0, 1, 1, 1], [0, 1, 1, 0], [1, 1, 0, 1]], bool)
    a = agreement(T, S)
    # pairs (0,1) T S: 1 0 -> false blocked; (0,2) 0 0 agree-; (0,3) 1 1 agree+;
    # (1,2) 1 1 agree+; (1,3) 0 1 false visible; (2,3) 1 0 false blocked
    assert (a["agree_visible"], a["agree_blocked"], a["false_visible"], a["false_blocked"]) == (2, 1, 1, 2)
    assert a["n_pairs"] == 6 and a["accuracy"] == pytest.approx(3 / 6)
    assert a["visible_kept"] == pytest.approx(2 / 4) and a["blocked_kept"] == pytest.approx(1 / 2)
    assert a["accuracy_paper"] == pytest.approx((2 * 3 + 4) / 16)
    m = np.zeros((4, 4), bool)
    m[0, 3] = m[1, 2] = m[1, 3] = True
    b = agreement(T, S, mask=m)
    assert b["n_pairs"] == 3 and b["accuracy"] == pytest.approx(2 / 3) and b["false_visible"] == 1


@settings(max_examples=50, deadline=None)
@given(st.integers(2, 30), st.integers(0, 2**31))
def test_agreement_counts_add_up(n, seed):
    rng = np.random.default_rng(seed)
    T = rng.random((n, n)) < 0.5
    S = rng.random((n, n)) < 0.5
    T = np.triu(T, 1) | np.triu(T, 1).T | np.eye(n, dtype=bool)
    S = np.triu(S, 1) | np.triu(S, 1).T | np.eye(n, dtype=bool)
    a = agreement(T, S)
    total = a["agree_visible"] + a["agree_blocked"] + a["false_visible"] + a["false_blocked"]
    assert total == a["n_pairs"] == n * (n - 1) // 2
    # the paper's |P x P| figure follows from ours
    assert a["accuracy_paper"] == pytest.approx((n * (n - 1) * a["accuracy"] + n) / n**2)
    assert agreement(T, T)["accuracy"] == 1.0


def test_agreement_bad_input():
    with pytest.raises(ValueError, match="V_true must be a square"):
        agreement(np.zeros((2, 3), bool), np.zeros((2, 3), bool))
    with pytest.raises(ValueError, match="V_test must have the shape of V_true"):
        agreement(np.zeros((2, 2), bool), np.zeros((3, 3), bool))
    with pytest.raises(ValueError, match="V_true must be boolean"):
        agreement(np.full((2, 2), 0.5), np.zeros((2, 2), bool))
    assert np.isnan(agreement(np.ones((1, 1), bool), np.ones((1, 1), bool))["accuracy"])


def _cells_by_hand(T, S, counted):
    """The viewshed counts by a loop over the cells (an independent reference)."""
    av = ab = fv = fb = 0
    for t, s, c in zip(T.ravel(), S.ravel(), counted.ravel()):
        if c:
            av += t and s
            ab += (not t) and (not s)
            fv += (not t) and s
            fb += t and (not s)
    return av, ab, fv, fb


@settings(max_examples=50, deadline=None)
@given(st.integers(1, 12), st.integers(1, 12), st.integers(0, 2**31))
def test_viewshed_agreement_counts_every_counted_cell(rows, cols, seed):
    from terrainvis.core.metrics import viewshed_agreement

    rng = np.random.default_rng(seed)
    T, S, counted = (rng.random((3, rows, cols)) < [[[0.5]], [[0.4]], [[0.7]]])
    a = viewshed_agreement(T, S, counted)
    av, ab, fv, fb = _cells_by_hand(T, S, counted)
    assert (a["agree_visible"], a["agree_blocked"], a["false_visible"], a["false_blocked"]) == (av, ab, fv, fb)
    n = int(counted.sum())
    assert a["n_pairs"] == n and np.isnan(a["accuracy_paper"])
    assert a["accuracy"] == ((av + ab) / n if n else pytest.approx(np.nan, nan_ok=True))
    if av + fb:
        assert a["visible_kept"] == av / (av + fb) and a["visible_area_ratio"] == (av + fv) / (av + fb)
    else:
        assert np.isnan(a["visible_kept"]) and np.isnan(a["visible_area_ratio"])
    whole = viewshed_agreement(T, S)
    assert whole["n_pairs"] == rows * cols


def test_viewshed_agreement_bad_input():
    from terrainvis.core.metrics import viewshed_agreement

    with pytest.raises(ValueError, match="V_test must have the shape of V_true"):
        viewshed_agreement(np.zeros((2, 3), bool), np.zeros((3, 2), bool))
    with pytest.raises(ValueError, match="mask must have the shape of V_true"):
        viewshed_agreement(np.zeros((2, 3), bool), np.zeros((2, 3), bool), np.ones((2, 2), bool))
    with pytest.raises(ValueError, match="V_true must be a 2-D array"):
        viewshed_agreement(np.zeros(4, bool), np.zeros(4, bool))


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 7), st.integers(1, 7), st.integers(0, 2**31))
def test_verdict_edges_are_the_cells_with_a_neighbour_of_the_other_verdict(rows, cols, seed):
    from terrainvis.core.metrics import verdict_edges

    v = np.random.default_rng(seed).random((rows, cols)) < 0.5
    expected = np.zeros_like(v)
    for r in range(rows):
        for c in range(cols):
            around = v[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2]
            expected[r, c] = bool((around != v[r, c]).any())
    np.testing.assert_array_equal(verdict_edges(v), expected)
    with pytest.raises(ValueError, match="viewshed must be a 2-D array"):
        verdict_edges(v.ravel())
