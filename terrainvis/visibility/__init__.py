"""Exact line of sight (LOS) on height grids and TINs.

Definition
----------
Points p and q see each other when the open segment pq nowhere passes below the
terrain surface: the *clearance*

    c(t) = z_seg(t) - surface(x(t), y(t)),   x(t), y(t), z_seg(t) = p + t (q - p),

is at least ``-tol`` for every t in [tau, 1 - tau].

* ``tau = delta / |q - p|`` trims the length ``delta`` (3-D) off both ends, so that end
  points lying on the surface do not block themselves. ``delta`` is
  :func:`trim_length`: ``1e-5`` times the horizontal diagonal of the terrain's extent
  (3.6 cm on a 120 x 120 grid of 30 m cells). A segment not longer than ``2 delta`` is
  trimmed away entirely and is visible (a point sees itself); its clearance is ``inf``.
* ``tol`` is :func:`clearance_tolerance`: ``1e-9`` times :func:`terrain_scale`, the
  larger of the horizontal diagonal and the elevation range. It absorbs float64
  rounding, so that a segment grazing the surface (clearance exactly 0) is visible. It
  does not depend on the absolute elevation, so adding a constant to the terrain and to
  the points does not change the answer.
* A segment whose ends sit on the surface can run underground and meet the surface only
  at its ends. It is **blocked** (its clearance is negative inside the interval). This is
  common after simplification, where points often sit below the simplified surface.

The surface of a HeightGrid is the piecewise-linear surface with every cell split along
the (r, c)-(r+1, c+1) diagonal, identical to ``grid.to_tin()``.

End radius
----------
``end_radius`` r >= 0 (default 0) is a horizontal distance. Around each end of a segment
the surface is not tested within horizontal distance r of that end; the rest of the
segment is tested exactly as above, including the underground rule at the ends of the
tested part (a tested part that starts below the surface is blocked). With ``L_h`` the
segment's horizontal length, the tested interval is

    [max(tau, r / L_h), min(1 - tau, 1 - r / L_h)].

A segment with ``L_h <= 2 r`` (for r > 0), or no longer than ``2 delta``, is visible and
its clearance is ``inf``. ``end_radius = 0`` is the exact predicate above, bit for bit.
This is the predicate of DEM ray casters that test only the cells strictly between
observer and target (r = one cell). It matters for points lying below the surface under
test (common after simplification): such a point can see over the surface once r covers
the part of the segment that runs underground.

Engines
-------
``"grid"`` (HeightGrid only)
    An exact walk of the ground track across grid lines and cell diagonals (the
    clearance is linear between crossings, so checking every crossing is exact),
    accelerated by a min/max pyramid, compiled with numba and parallel over pairs.
``"embree"`` (any terrain; a HeightGrid goes through ``grid.to_tin()``)
    Embree occlusion rays in float32 plus upward vertical rays from both ends of the
    tested part (the underground fix). It agrees with the exact answer on every pair whose minimum
    clearance is farther than :func:`~terrainvis.visibility.embree.embree_tolerance`
    from zero.
``"tin"`` (TIN only)
    The exact clip of each segment's ground track against every face it crosses; any
    earth curvature.
``"auto"``
    ``"grid"`` for a HeightGrid; for a TIN ``"embree"`` on a flat earth, ``"tin"`` under
    curvature.

The engines are the registry :data:`ENGINES` (:mod:`terrainvis.visibility.engines`):
each answers ``pairs`` and ``matrix`` through one interface, and
:func:`register_engine` adds one.

:func:`min_clearance` is always exact: the grid walk on a HeightGrid, and on a TIN a
clip of the ground track (over the tested interval) against every face it crosses.

References
----------
B. Duvenhage, "Using an implicit min/max KD-tree for doing efficient terrain line of
sight calculations", AFRIGRAPH 2009, doi:10.1145/1503454.1503465.
"""

import importlib

# Every name below is imported on first use (PEP 562), so that a command that reads only
# what it uses (``terrainvis viewshed`` checks its flags before it loads the sweep) does not
# pay for the whole package.

#: Each public name and the submodule that defines it (``(module, name there)`` when renamed).
_API = {
    "cumulative_viewshed": "viewsheds.cumulative",
    "ENGINES": "engines", "Engine": "engines", "Predicate": "engines", "engine_names": "engines",
    "register_engine": ("engines", "register"), "unregister_engine": ("engines", "unregister"),
    "embree_tolerance": "los", "line_of_sight": "los", "min_clearance": "los", "visibility_matrix": "los",
    "ObserverSets": "viewsheds.observers", "intervisibility_network": "viewsheds.observers",
    "observer_sets": "viewsheds.observers",
    "EARTH_RADIUS": "predicate", "STANDARD_REFRACTION": "predicate", "TOL_REL": "predicate", "TRIM_REL": "predicate",
    "clearance_tolerance": "predicate", "curvature_coefficient": "predicate", "terrain_scale": "predicate",
    "trim_length": "predicate",
    "FresnelClearance": "fresnel", "fresnel_clearance": "fresnel", "fresnel_radius": "fresnel",
    "clearance_profile": "profile", "lowest_point": "profile",
    "SitingResult": "viewsheds.siting", "candidate_grid": "viewsheds.siting", "sample_areas": "viewsheds.siting",
    "site_observers": "viewsheds.siting",
    "FieldOfView": "viewsheds.field_of_view", "field_of_view": "viewsheds.field_of_view",
    "field_of_view_mask": "viewsheds.field_of_view",
    "Sight": "sight",
    "viewshed": "viewsheds.sweep",
}


def __getattr__(name):
    spec = _API.get(name)
    if spec is None:
        raise AttributeError(f"module 'terrainvis.visibility' has no attribute {name!r}")
    module, attr = spec if isinstance(spec, tuple) else (spec, name)
    value = getattr(importlib.import_module(f"{__name__}.{module}"), attr)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))


__all__ = [
    "ENGINES",
    "Engine",
    "Predicate",
    "engine_names",
    "register_engine",
    "unregister_engine",
    "TRIM_REL",
    "TOL_REL",
    "EARTH_RADIUS",
    "STANDARD_REFRACTION",
    "curvature_coefficient",
    "min_clearance",
    "line_of_sight",
    "visibility_matrix",
    "trim_length",
    "clearance_tolerance",
    "terrain_scale",
    "embree_tolerance",
    "viewshed",
    "Sight",
    "cumulative_viewshed",
    "FieldOfView",
    "field_of_view",
    "field_of_view_mask",
    "FresnelClearance",
    "fresnel_clearance",
    "fresnel_radius",
    "observer_sets",
    "ObserverSets",
    "intervisibility_network",
    "site_observers",
    "SitingResult",
    "candidate_grid",
    "sample_areas",
    "lowest_point",
    "clearance_profile",
]
