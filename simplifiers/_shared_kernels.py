"""Kernel primitives the simplifiers share: the orientation predicate.

Greedy cuts (:mod:`simplifiers._gc_kernels`) and greedy insertion
(:mod:`simplifiers._gi_kernels`) both import it; numba compiles it once per argument type
(float64 plane coordinates for greedy cuts, int64 grid indices for greedy insertion).
Like the kernels around it, it allocates nothing and is compiled without the Numba
runtime (``_nrt=False``, see :mod:`simplifiers._gc_kernels`).
"""

from __future__ import annotations

import numba as nb

_HOT = {"cache": True, "nogil": True, "_nrt": False}


@nb.njit(**_HOT)
def orient(ax, ay, bx, by, cx, cy):
    """Twice the signed area of (a, b, c): > 0 counter-clockwise, 0 collinear.

    Exact on integers (int64 grid indices, or float64 holding integers below 2**26).
    """
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
