"""The paper's three relocations: identity, full and half projection.

Alderson and Samavati place points sampled on the original terrain T on its
simplification S(T) in three ways:

``identity``
    The points do not move. They may end up below S(T) (then every segment from them is
    blocked) or above it.
``full``
    Every point is moved vertically onto S(T).
``half``
    Only points below S(T) are moved up onto it; points above it stay where they are.

Points often carry an observer (eye) height above the ground, the ``offset``: the
*ground point* of an observer is ``z - offset``, relocation decides and moves using the
ground point, and the offset is added back. So ``full`` gives ``S(x, y) + offset``, and
``half`` lifts an observer only when its ground point is below S(T), to ``S(x, y) +
offset``. With ``offset = 0`` (points on the original surface, the paper's setting) these
are exactly the definitions above. Passing the offset matters: an observer 2 m above a
ground point that is 1 m below S(T) would otherwise count as "above" S(T) and keep its
height under ``half``, i.e. stand 1 m above S(T) instead of 2 m.
"""

from __future__ import annotations

import numpy as np

from ..errors import OutsideFootprintError

__all__ = ["identity", "full", "half", "ground_heights"]


def ground_heights(simplified, points: np.ndarray) -> np.ndarray:
    """S(T)'s height under each point, refusing points outside its footprint.

    Parameters
    ----------
    simplified : HeightGrid or TIN
    points : (n, 2+) float64

    Raises
    ------
    terrainvis.errors.OutsideFootprintError
        Naming how many points lie outside and the first one's index.
    """
    ground = simplified.height_at(points[:, :2])
    outside = np.isnan(ground)
    if outside.any():
        first = int(np.flatnonzero(outside)[0])
        raise OutsideFootprintError(
            f"points must lie inside the simplified terrain's footprint, but {int(outside.sum())} of "
            f"{points.shape[0]} do not (first at index {first})"
        )
    return ground


def identity(points: np.ndarray, simplified, *, offset: float = 0.0) -> np.ndarray:
    """The points as they are (a copy)."""
    return np.array(points, dtype=np.float64, copy=True)


def full(points: np.ndarray, simplified, *, offset: float = 0.0) -> np.ndarray:
    """Every point ``offset`` above S(T)."""
    out = np.array(points, dtype=np.float64, copy=True)
    if out.shape[0]:
        out[:, 2] = ground_heights(simplified, out) + offset
    return out


def half(points: np.ndarray, simplified, *, offset: float = 0.0) -> np.ndarray:
    """Points whose ground point is below S(T) lifted to ``offset`` above it; the others unchanged."""
    out = np.array(points, dtype=np.float64, copy=True)
    if out.shape[0]:
        ground = ground_heights(simplified, out)
        below = out[:, 2] - offset < ground
        out[below, 2] = ground[below] + offset
    return out
