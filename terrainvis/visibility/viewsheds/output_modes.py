"""Viewshed output modes: the least visible height and the angle above the horizon of every target.

:func:`terrainvis.viewshed` answers, by default (``output="visible"``), whether each
target is visible. Two other outputs come from the threshold engine
(:mod:`terrainvis.visibility.thresholds`): for the fixed eye E and a target point p over a
sample, the *threshold* ``z*(p)`` is the least height at which p sees E under the LOS
predicate (the same trim and tolerance, and earth curvature), the largest
``(s(u) - tol - E_z) / u`` (plus the curvature bulge) over the breakpoints of the ground
track from E to p, plus ``E_z``. A target standing at height z is visible exactly when
``z >= z*(p)``. The walk is the project's one threshold walk; this module only turns its
thresholds into output values:

``"min_height"``
    ``max(z*(p) - s(p), 0)``: the least height above the surface under test at which a
    target at that sample is visible, 0 where the ground itself is visible (the meaning
    of GDAL's ``gdal_viewshed -om GROUND``). It does not depend on ``target_height``.
``"angle"``
    The elevation angle of the target (standing ``target_height`` above the surface)
    above the horizon along its ray, in degrees, both seen from the eye and lowered by the
    earth's drop ``kc d**2`` (``kc = curvature / (2 R)``, d the horizontal distance):
    ``atan2(z_T - kc d**2 - E_z, d) - atan2(z* - kc d**2 - E_z, d)``. The horizon of a
    ray is the sight line grazing the highest terrain between the eye and the target, so
    the angle is >= 0 exactly where the target is visible (to within the clearance
    tolerance), as QGIS's depth below the horizon. GRASS r.viewshed's angle output is
    another quantity: the first term alone (as 90 + degrees, 0 straight down), for
    visible cells only (``benchmarks/bench_grass_angle.py`` compares the two). A target
    whose segment is not tested at all (within the trim of the eye) has a horizon of
    -90 degrees.

Both are NaN where the viewshed would say False without deciding: nodata samples,
samples off the surface under test, and samples outside the field of view.
"""

from __future__ import annotations

import numpy as np

from ...core.interrupt import call
from ...core.terrain import HeightGrid
from .. import _threshold_kernels as _tk
from .field_of_view import elevation_degrees
from ..predicate import clearance_tolerance, trim_length
from ..thresholds import ThresholdSurface

__all__ = ["OUTPUTS", "check_output", "eye_thresholds", "output_values"]

#: The values of ``viewshed(..., output=...)``.
OUTPUTS = ("visible", "min_height", "angle")


def check_output(output, name: str = "output") -> str:
    """``output`` if it is one of :data:`OUTPUTS`; otherwise a ValueError naming ``name``.

    Examples
    --------
    >>> check_output("angle")
    'angle'
    >>> check_output("height")
    Traceback (most recent call last):
    ...
    ValueError: output must be one of 'visible', 'min_height', 'angle', got 'height'
    """
    if not isinstance(output, str) or output not in OUTPUTS:
        allowed = ", ".join(repr(o) for o in OUTPUTS)
        raise ValueError(f"{name} must be one of {allowed}, got {output!r}")
    return output


def eye_thresholds(terrain, eye: np.ndarray, targets: np.ndarray, kc: float) -> np.ndarray:
    """The threshold height of each target point for the eye (the threshold engine, exact).

    Parameters
    ----------
    terrain : HeightGrid (without nodata) or TIN
        The surface under test.
    eye : (3,) float64
        The eye (x, y, z), world coordinates.
    targets : (n, 3) float64
        Target points (x, y, z); z (near the answer) only sets the trim.
    kc : float
        Curvature coefficient (:func:`terrainvis.visibility.curvature_coefficient`).

    Returns
    -------
    (n,) float64
        The least height at which each target sees the eye under the LOS predicate of
        ``terrain`` (its trim and tolerance); -inf where the segment is not tested.
        On numba's number of threads; interruptible.
    """
    surf = ThresholdSurface(terrain)
    rules = surf.rules(kc=kc)
    kernel = _tk.grid_eye_thresholds if isinstance(terrain, HeightGrid) else _tk.tin_eye_thresholds
    return _run(kernel, surf, rules, eye, targets)


def tin_of_grid_thresholds(grid: HeightGrid, eye: np.ndarray, targets: np.ndarray, kc: float) -> np.ndarray:
    """:func:`eye_thresholds` on a grid with nodata, walked as its TIN (``grid.to_tin()``, the
    same surface without the triangles touching nodata) under the grid's own trim and
    tolerance. The TIN walk stops at a hole: callers check its answers (see
    :func:`terrainvis.visibility.viewshed`)."""
    surf = ThresholdSurface(grid.to_tin())
    rules = surf.rules(kc=kc)._replace(delta=float(trim_length(grid)), tol=float(clearance_tolerance(grid)))
    return _run(_tk.tin_eye_thresholds, surf, rules, eye, targets)


def _run(kernel, surf: ThresholdSurface, rules, eye: np.ndarray, targets: np.ndarray) -> np.ndarray:
    out = np.empty(targets.shape[0])
    if targets.shape[0] == 0:
        return out
    q = (float(eye[0] - surf.x0), float(eye[1] - surf.y0), float(eye[2]))
    call(kernel, surf.data, q, np.ascontiguousarray(surf.local(targets)), rules, out, work=64 * targets.shape[0],
         items=_tk.eye_chunks(targets.shape[0]))
    return out


def output_values(output: str, thr: np.ndarray, eye: np.ndarray, targets: np.ndarray, ground: np.ndarray,
                  kc: float) -> np.ndarray:
    """The values of ``output`` ("min_height" or "angle") from the thresholds ``thr`` (n,).

    ``targets`` (n, 3) are the targets (x, y, z standing ``target_height`` above the
    surface), ``ground`` (n,) the surface under them, ``eye`` the eye (x, y, z); see the
    module docstring.
    """
    if output == "min_height":
        return np.maximum(thr - ground, 0.0)
    d = np.hypot(targets[:, 0] - eye[0], targets[:, 1] - eye[1])
    return elevation_degrees(d, targets[:, 2] - eye[2], kc) - elevation_degrees(d, thr - eye[2], kc)
