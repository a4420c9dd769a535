"""The kernel primitives both greedy simplifiers use (simplifiers._shared_kernels)."""

from __future__ import annotations

import numpy as np

from simplifiers import _shared_kernels as sk


def test_orient_signs_and_exact_integers():
    assert sk.orient(0, 0, 1, 0, 0, 1) == 1  # counter-clockwise
    assert sk.orient(0.0, 0.0, 0.0, 1.0, 1.0, 0.0) == -1.0  # clockwise
    assert sk.orient(0, 0, 2, 2, 5, 5) == 0  # collinear
    big = 30_000  # the largest grid side greedy insertion takes
    assert sk.orient(0, 0, big, 1, big - 1, 1) == 1
    assert sk.orient(np.int64(0), np.int64(0), np.int64(big), np.int64(1), np.int64(big - 1), np.int64(1)) == 1
