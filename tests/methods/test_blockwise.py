"""Block-wise (dask) reverse subdivision equals the in-memory result."""

from __future__ import annotations

import numpy as np
import pytest

from simplifiers import simplify
from terrainvis import HeightGrid

da = pytest.importorskip("dask.array", reason="the dask extra is not installed")

from simplifiers.blockwise import simplify_dask, simplify_grid_blockwise  # noqa: E402


def _terrain(shape, seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(size=shape).cumsum(0).cumsum(1) + rng.normal(0, 5, size=shape)


@pytest.mark.parametrize("shape", [(257, 300), (120, 121), (331, 190)])
@pytest.mark.parametrize("method", ["simple", "lls"])
def test_local_operators_bit_for_bit(shape, method):
    z = _terrain(shape)
    g = HeightGrid(z)
    for level in (1, 2, 3):
        out = simplify_dask(da.from_array(z, chunks=(37, 41)), method, level)
        assert out.numblocks[0] >= 2 and out.numblocks[1] >= 2 or level == 3
        np.testing.assert_array_equal(out.compute(), simplify(g, method, level).z)


def test_lls_derived_weights_blockwise():
    z = _terrain((150, 161), seed=3)
    out = simplify_dask(da.from_array(z, chunks=40), "lls", 2, weights="derived").compute()
    np.testing.assert_array_equal(out, simplify(HeightGrid(z), "lls", 2, weights="derived").z)


def test_gls_matches_to_rounding_across_many_blocks():
    z = _terrain((700, 650), seed=1)
    lazy = simplify_dask(da.from_array(z, chunks=(100, 100)), "gls", 1)
    assert lazy.numblocks[0] >= 3 and lazy.numblocks[1] >= 3  # halo 64 -> blocks of 128 samples
    ref = simplify(HeightGrid(z), "gls", 1).z
    out = lazy.compute()
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-12 * np.abs(ref).max())


def test_grid_wrapper_and_errors():
    z = _terrain((65, 70))
    g = HeightGrid(z, dx=30.0, dy=30.0, origin=(1000.0, 2000.0))
    b = simplify_grid_blockwise(g, "lls", 2, chunks=20)
    s = simplify(g, "lls", 2)
    np.testing.assert_array_equal(b.z, s.z)
    np.testing.assert_array_equal(b.xs, s.xs)
    np.testing.assert_array_equal(b.ys, s.ys)
    with pytest.raises(ValueError, match=r"method must be one of \['simple', 'gls', 'lls'\]"):
        simplify_dask(z, "feature")
    with pytest.raises(ValueError, match="2-D"):
        simplify_dask(np.zeros(10), "lls")
