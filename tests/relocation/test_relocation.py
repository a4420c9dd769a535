"""relocate: the three strategies, offsets, and bad input."""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from simplifiers import simplify
from terrainvis import HeightGrid, relocate, sample_points, synthetic_terrain, visibility_matrix
from terrainvis.errors import OutsideFootprintError
from terrainvis.relocation import RELOCATIONS
from terrainvis.visibility import Sight


def _plane(z0=10.0):
    return HeightGrid(np.full((3, 3), z0), dx=5.0, dy=5.0)


def test_hand_cases():
    S = _plane(10.0)
    P = np.array([[1.0, 1.0, 8.0], [2.0, 3.0, 12.0], [4.0, 4.0, 10.0]])
    before = P.copy()
    np.testing.assert_array_equal(relocate(P, S, "identity"), P)
    np.testing.assert_array_equal(relocate(P, S, "full")[:, 2], [10.0, 10.0, 10.0])
    np.testing.assert_array_equal(relocate(P, S, "half")[:, 2], [10.0, 12.0, 10.0])
    np.testing.assert_array_equal(P, before)  # never modified
    assert relocate(P, S, "identity") is not P


def test_offset_acts_on_the_ground_point():
    S = _plane(10.0)
    # An observer 2 m above a ground point 1 m below S: its ground point is lifted to S.
    P = np.array([[1.0, 1.0, 11.0], [1.0, 1.0, 15.0]])
    np.testing.assert_array_equal(relocate(P, S, "half", offset=2.0)[:, 2], [12.0, 15.0])
    np.testing.assert_array_equal(relocate(P, S, "full", offset=2.0)[:, 2], [12.0, 12.0])


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000), st.sampled_from(["simple", "lls", "greedy-insertion"]))
def test_properties_on_real_simplifications(seed, method):
    from simplifiers import simplify

    T = synthetic_terrain("mountains", size=33, seed=seed % 7)
    S = simplify(T, method, 2)
    P = sample_points(T, 40, seed=seed)
    full = relocate(P, S, "full")
    half = relocate(P, S, "half")
    ground = S.height_at(P[:, :2])
    np.testing.assert_allclose(full[:, 2], ground)
    # half = max(original, simplified surface), and x, y never move
    np.testing.assert_allclose(half[:, 2], np.maximum(P[:, 2], ground))
    np.testing.assert_array_equal(half[:, :2], P[:, :2])
    assert (half[:, 2] >= full[:, 2] - 1e-12).all()


def test_bad_input():
    S = _plane()
    P = np.array([[1.0, 1.0, 8.0]])
    from terrainvis.relocation import available

    # the registry's names (every built-in one, in its order), not a list kept here
    assert available()[:3] == ["identity", "full", "half"] and {"calibrated", "eye", "oracle"} <= set(available())
    with pytest.raises(ValueError, match=re.escape(f"how must be one of {available()}, got 'up'")):
        relocate(P, S, "up")
    with pytest.raises(OutsideFootprintError, match=r"1 of 2 do not \(first at index 1\)"):
        relocate(np.array([[1.0, 1.0, 0.0], [50.0, 1.0, 0.0]]), S, "full")
    with pytest.raises(ValueError, match=r"points must have shape \(m, 3\)"):
        relocate(np.zeros((2, 2)), S, "full")
    with pytest.raises(TypeError, match="simplified must be"):
        relocate(P, np.zeros((3, 3)), "full")
    assert relocate(np.empty((0, 3)), S, "half").shape == (0, 3)


# ----------------------------------------------------------------- the oracle bound
def _oracle_case(method="lls", level=3, seed=0):
    from simplifiers import simplify

    from terrainvis import visibility_matrix

    T = synthetic_terrain("hills", size=33, seed=seed)
    S = simplify(T, method, level)
    P = sample_points(T, 25, seed=seed)
    return T, S, P, visibility_matrix(T, P)


def _agree(V, S, Q, mask=None):
    from terrainvis import agreement, visibility_matrix

    return agreement(V, visibility_matrix(S, Q), mask)["accuracy"]


@pytest.mark.parametrize("method", ["lls", "greedy-insertion"])
def test_oracle_is_an_upper_bound_of_the_practical_relocations(method):
    T, S, P, V = _oracle_case(method)
    best = max(_agree(V, S, relocate(P, S, how)) for how in ("identity", "full", "half"))
    O = relocate(P, S, "oracle", reference=V, original=T)
    np.testing.assert_array_equal(O[:, :2], P[:, :2])
    assert _agree(V, S, O) >= best
    # deterministic, and it never modifies its input
    before = P.copy()
    np.testing.assert_array_equal(relocate(P, S, "oracle", reference=V, original=T), O)
    np.testing.assert_array_equal(P, before)


def test_oracle_is_a_local_optimum_of_its_candidates():
    """No single point can improve the agreement by moving to another of its candidates."""
    from terrainvis.relocation.oracle import _candidates

    T, S, P, V = _oracle_case("simple", 2, seed=3)
    O = relocate(P, S, "oracle", reference=V, original=T)
    score = _agree(V, S, O)
    cand = _candidates(P, S, S.height_at(P[:, :2]), 0.0, T, 9)
    for i in range(0, P.shape[0], 5):
        for h in cand[i]:
            Q = O.copy()
            Q[i, 2] = h
            assert _agree(V, S, Q) <= score + 1e-12


@pytest.mark.parametrize("method", ["lls", "greedy-insertion"])
def test_oracle_is_an_exact_best_response_and_never_below_its_start(method):
    """From the calibrated heights, the oracle ends where no point gains by its exact best
    height against the others (the true verdicts, every pair counted), above its start."""
    from terrainvis.relocation.calibrated import best_responses

    T, S, P, V = _oracle_case(method, seed=2)
    C = relocate(P, S, "calibrated", original=T, n_partners=64)
    O = relocate(P, S, "oracle", reference=V, original=T, start=C[:, 2])
    assert _agree(V, S, O) >= max(_agree(V, S, C), *(_agree(V, S, relocate(P, S, h)) for h in ("full", "half")))
    counted = ~np.eye(P.shape[0], dtype=bool)
    z, moved = best_responses(O, S, V, counted)
    assert not moved and np.array_equal(z, O[:, 2])
    # one sweep of best responses from the full projection never lowers the agreement
    F = relocate(P, S, "full")
    z, moved = best_responses(F, S, V, counted)
    assert moved and _agree(V, S, np.column_stack([P[:, :2], z])) >= _agree(V, S, F)
    with pytest.raises(ValueError, match=r"start must hold 25 finite heights \(one per point\)"):
        relocate(P, S, "oracle", reference=V, start=C[:3, 2])


def test_oracle_respects_the_mask_and_needs_its_reference():
    T, S, P, V = _oracle_case()
    d = np.hypot(*(P[:, None, :2] - P[None, :, :2]).transpose(2, 0, 1))
    mask = d <= 400.0
    O = relocate(P, S, "oracle", reference=V, original=T, mask=mask)
    best = max(_agree(V, S, relocate(P, S, how), mask) for how in ("identity", "full", "half"))
    assert _agree(V, S, O, mask) >= best
    with pytest.raises(TypeError, match="needs reference="):
        relocate(P, S, "oracle")
    with pytest.raises(ValueError, match=r"reference must be an \(25, 25\) boolean matrix"):
        relocate(P, S, "oracle", reference=V[:3, :3])
    with pytest.raises(TypeError, match="original must be a terrainvis.HeightGrid"):
        relocate(P, S, "oracle", reference=V, original=S.to_tin())


def test_the_relocations_that_compute_visibility_take_the_sight_of_their_verdicts():
    """calibrated, eye and oracle take ``sight=`` (end radius, curvature, earth radius; the oracle's
    engine too), as compare hands it, in place of those keywords: the same heights; a Sight beside
    one of those keywords, or with a field of view, is refused, naming it."""
    T = synthetic_terrain("hills", size=33, seed=2)
    S = simplify(T, "lls", 2)
    P = sample_points(T, 12, seed=1)
    P[:, 2] += 1.7
    kw = dict(curvature=0.85714, earth_radius=6378137.0 / 400, end_radius=3.0)
    reference = visibility_matrix(T, P, curvature=kw["curvature"], earth_radius=kw["earth_radius"])
    for how, extra in (("calibrated", dict(original=T, n_partners=64)), ("eye", dict(original=T, n_partners=64)),
                       ("oracle", dict(reference=reference))):
        by_keywords = relocate(P, S, how, offset=1.7, **extra, **kw)
        by_sight = relocate(P, S, how, offset=1.7, **extra, sight=Sight.make(**kw))
        assert np.array_equal(by_keywords, by_sight), how
        assert not np.array_equal(by_sight, relocate(P, S, how, offset=1.7, **extra)), how  # the Sight was read
        with pytest.raises(TypeError, match="pass either sight= or the keyword curvature=, not both"):
            relocate(P, S, how, offset=1.7, **extra, sight=Sight.make(**kw), curvature=0.5)
        with pytest.raises(ValueError, match="relocate takes the predicate of a Sight .* its field of view"):
            relocate(P, S, how, offset=1.7, **extra, sight=Sight.make(max_distance=100.0, **kw))
    assert "sight" in RELOCATIONS["calibrated"].options and "sight" not in RELOCATIONS["full"].options
