"""Moving test points onto a simplified terrain before testing visibility on it.

Points sampled on the original terrain T do not, in general, lie on its simplification
S(T). Alderson and Samavati compare three ways of placing them on S(T):

``"identity"``
    The points do not move. They may end up below S(T) (then every segment from them is
    blocked) or above it.
``"full"``
    Every point is moved vertically onto S(T).
``"half"``
    Only points below S(T) are moved up onto it; points above it stay where they are.

Observer offsets
----------------
Points often carry an observer (eye) height above the ground. :func:`relocate` takes it
as ``offset``: the *ground point* of an observer is ``z - offset``, relocation decides and
moves using the ground point, and the offset is added back. So ``"full"`` gives
``S(x, y) + offset``, and ``"half"`` lifts an observer only when its ground point is below
S(T), to ``S(x, y) + offset``. With ``offset = 0`` (points on the original surface, the
paper's setting) these are exactly the definitions above. Passing the offset matters:
an observer 2 m above a ground point that is 1 m below S(T) would otherwise count as
"above" S(T) and keep its height under ``"half"``, i.e. stand 1 m above S(T) instead of
2 m.
"""

from __future__ import annotations

import numpy as np

from ._validate import as_float_array, as_points, choice, describe
from .errors import OutsideFootprintError
from .terrain import as_terrain

__all__ = ["relocate", "RELOCATIONS"]

#: The relocation strategies, in the paper's order.
RELOCATIONS = ("identity", "full", "half")


def relocate(points, simplified, how: str, *, offset: float = 0.0) -> np.ndarray:
    """Place points on a simplified terrain.

    Parameters
    ----------
    points : (n, 3) array_like
        Points on (or ``offset`` above) the original terrain. Never modified.
    simplified : HeightGrid or TIN
        The simplified terrain.
    how : {"identity", "full", "half"}
        See the module docstring.
    offset : float
        The observer height that ``points`` carry above their ground point.

    Returns
    -------
    (n, 3) float64
        A new array; x and y are unchanged.

    Examples
    --------
    >>> from terrainvis import HeightGrid
    >>> S = HeightGrid(np.full((2, 2), 10.0))
    >>> P = np.array([[0.5, 0.5, 8.0], [0.5, 0.5, 12.0]])
    >>> relocate(P, S, "half")[:, 2].tolist()
    [10.0, 12.0]
    >>> relocate(P, S, "full")[:, 2].tolist()
    [10.0, 10.0]
    """
    pts = as_points(points, "points", 3)
    as_terrain(simplified, "simplified")
    how = choice(how, "how", RELOCATIONS)
    off = as_float_array(offset, "offset")
    if off.ndim != 0 or not np.isfinite(off):
        raise ValueError(f"offset must be a finite scalar, got {describe(offset)}")
    off = float(off)
    out = pts.copy()
    if how == "identity" or pts.shape[0] == 0:
        return out
    ground = simplified.height_at(pts[:, :2])
    outside = np.isnan(ground)
    if outside.any():
        first = int(np.flatnonzero(outside)[0])
        raise OutsideFootprintError(
            f"points must lie inside the simplified terrain's footprint, but {int(outside.sum())} of "
            f"{pts.shape[0]} do not (first at index {first})"
        )
    if how == "full":
        out[:, 2] = ground + off
    else:
        below = pts[:, 2] - off < ground
        out[below, 2] = ground[below] + off
    return out
