"""Field-of-view limits of a viewshed: azimuth, vertical angle and distance from the observer.

A field of view says which targets an observer looks at, as ArcGIS's observer parameters
do (AZIMUTH1/AZIMUTH2, VERT1/VERT2, RADIUS1/RADIUS2 of Viewshed 2). Whether a target lies in the field is pure geometry of the eye and the target;
whether a target inside the field is visible does not depend on the limits (terrain outside
the field still blocks the sight lines that cross it). So the limits are applied exactly as
a mask on the viewshed's targets: :func:`field_of_view_mask` computes it, and
:func:`terrainvis.viewshed` and :func:`terrainvis.cumulative_viewshed` take the limits as
keywords (``azimuth``, ``vertical``, ``min_distance`` beside ``max_distance``) and return
False outside the field.

The limits, for a target T standing ``target_height`` above the surface at a sample (x, y)
and the eye E = (x_E, y_E, z_E) (``dx = x - x_E``, ``dy = y - y_E``, ``d = hypot(dx, dy)``):

* **azimuth** ``(start, end)``, degrees clockwise from north, each in [0, 360]: the grid's
  +y axis is north and +x east, so the azimuth of T is ``atan2(dx, dy)`` in degrees, taken
  in [0, 360). T is inside when, turning clockwise from ``start``, its azimuth comes no
  later than ``end``: ``(az - start) mod 360 <= (end - start) mod 360``. Both limits are
  inclusive; a range with ``start > end`` wraps through north ((300, 60) is the 120
  degrees around north); ``(0, 360)`` is the full circle. A range of zero width
  (``start == end`` modulo 360, other than (0, 360)) is refused: it would hold only the
  targets exactly on one ray, an empty field in practice (the viewshed analysis of Esri's
  ArcGIS Maps SDK likewise requires a horizontal angle > 0).
* **vertical** ``(low, high)``, degrees in [-90, 90] with ``low <= high``: the elevation
  angle of T seen from E, ``atan2(z_T - c d**2 / (2 R) - z_E, d)`` with c the curvature
  coefficient and R the earth radius, i.e. the angle of the target lowered by the earth's
  drop, as in the project's curvature model (docs/user-guide.md, "Earth curvature and
  refraction": GDAL's observer-centred correction applied to the target). Inclusive.
* **min_distance**, **max_distance**: the horizontal distance d, ``min_distance <= d <=
  max_distance`` (inclusive, as ``max_distance`` always was).

The sample nearest the observer (the ground it stands on: the nearest x and the nearest
y of the targets' grid) is exempt from the other limits and keeps the viewshed's verdict,
as it already was from ``max_distance``: its azimuth is undefined when the observer
stands on it, and GIS viewsheds mark the observer's own cell. It is not exempt from
``min_distance``: its distance is defined, and a viewshed asked to leave out what is
nearer than ``min_distance`` leaves it out too (it is nearer than half a cell's diagonal).

On a projected DEM, north is grid north (the +y axis), which differs from true north by
the projection's meridian convergence; a lon/lat DEM read in local metres has +y on the
meridians. A rectilinear grid is treated the same way (its y axis is north).

References
----------
Esri, "How Viewshed 2 works", ArcGIS Pro documentation (the Spatial Analyst tool whose
observer parameters these limits follow).

Esri, ArcGIS Maps SDK for Kotlin, class ``Viewshed`` (``horizontalAngle`` must be
greater than zero and at most 360 degrees).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...core.terrain import HeightGrid
from ...core.validate import as_nonnegative_finite, describe
from ..predicate import EARTH_RADIUS, curvature_coefficient, target_grid

__all__ = ["FieldOfView", "field_of_view", "field_of_view_mask", "azimuth_degrees", "elevation_degrees"]

#: The names the checks give the limits in their messages: the Python arguments, or the
#: command line's flags (``names=CLI_NAMES``).
API_NAMES = {"azimuth": "azimuth", "vertical": "vertical", "min_distance": "min_distance",
             "max_distance": "max_distance"}
CLI_NAMES = {"azimuth": "--azimuth", "vertical": "--vertical", "min_distance": "--min-distance",
             "max_distance": "--max-distance"}


@dataclass(frozen=True)
class FieldOfView:
    """Validated field-of-view limits (``None``: no limit); see the module docstring."""

    azimuth: tuple[float, float] | None = None
    vertical: tuple[float, float] | None = None
    min_distance: float | None = None
    max_distance: float | None = None

    @property
    def limited(self) -> bool:
        """Whether any limit is set (a field of view without limits masks nothing)."""
        return any(v is not None for v in (self.azimuth, self.vertical, self.min_distance, self.max_distance))

    @property
    def full_circle(self) -> bool:
        return self.azimuth is None or self.azimuth == (0.0, 360.0)

    def describe(self) -> str:
        """The limits in one phrase, for the command line's output (empty without limits)."""
        parts = []
        if self.azimuth is not None:
            s, e = self.azimuth
            wrap = " (through north)" if s > e else ""
            parts.append(f"azimuth {s:g} to {e:g} degrees clockwise{wrap}")
        if self.vertical is not None:
            parts.append(f"vertical angle {self.vertical[0]:g} to {self.vertical[1]:g} degrees")
        if self.min_distance is not None:
            parts.append(f"at least {self.min_distance:g} away")
        if self.max_distance is not None:
            parts.append(f"within {self.max_distance:g}")
        return ", ".join(parts)


def field_of_view(*, azimuth=None, vertical=None, min_distance=None, max_distance=None, names=None) -> FieldOfView:
    """Check field-of-view limits once, at the public boundary.

    Parameters
    ----------
    azimuth : (2,) sequence of float, optional
        ``(start, end)`` in degrees clockwise from north, each in [0, 360]; ``start > end``
        wraps through north; ``(0, 360)`` the full circle; zero width is refused.
    vertical : (2,) sequence of float, optional
        ``(low, high)`` elevation angles in degrees, each in [-90, 90], ``low <= high``.
    min_distance, max_distance : float, optional
        Horizontal distances (>= 0, x/y units), ``min_distance <= max_distance``.
    names : dict, optional
        How the messages name the limits (default: the Python arguments; the command line
        passes its flags).

    Returns
    -------
    FieldOfView

    Raises
    ------
    ValueError, TypeError
        Naming the limit, what was expected and what was given.

    Examples
    --------
    >>> field_of_view(azimuth=(300, 60)).azimuth
    (300.0, 60.0)
    >>> field_of_view(azimuth=(10, 400))
    Traceback (most recent call last):
    ...
    ValueError: azimuth must be two angles (start, end) in [0, 360] degrees clockwise from north, got (10, 400)
    """
    names = API_NAMES if names is None else names
    az = None if azimuth is None else _angles(azimuth, names["azimuth"], 0.0, 360.0,
                                               "(start, end)", "degrees clockwise from north")
    if az is not None and (az[1] - az[0]) % 360.0 == 0.0 and az != (0.0, 360.0):
        raise ValueError(
            f"{names['azimuth']} must span more than 0 degrees (start != end; (0, 360) is the full circle), "
            f"got {_pair_text(azimuth)}"
        )
    vert = None if vertical is None else _angles(vertical, names["vertical"], -90.0, 90.0,
                                                 "(low, high)", "degrees above the horizontal")
    if vert is not None and vert[0] > vert[1]:
        raise ValueError(f"{names['vertical']} must be (low, high) with low <= high, got {_pair_text(vertical)} "
                         "(reversed)")
    dmin = None if min_distance is None else as_nonnegative_finite(min_distance, names["min_distance"], "xy units")
    dmax = None if max_distance is None else as_nonnegative_finite(max_distance, names["max_distance"], "xy units")
    if dmin is not None and dmax is not None and dmin > dmax:
        raise ValueError(f"{names['min_distance']} must not exceed {names['max_distance']}, got {dmin:g} > {dmax:g}")
    return FieldOfView(az, vert, dmin or None, dmax)


def _angles(value, name: str, lo: float, hi: float, form: str, unit: str) -> tuple[float, float]:
    expected = f"two angles {form} in [{lo:g}, {hi:g}] {unit}"
    if isinstance(value, (str, bytes)):
        raise TypeError(f"{name} must be {expected}, got {describe(value)}")
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be {expected}, got {describe(value)}") from exc
    if arr.shape != (2,) or not (np.isfinite(arr).all() and (arr >= lo).all() and (arr <= hi).all()):
        raise ValueError(f"{name} must be {expected}, got {_pair_text(value)}")
    return float(arr[0]), float(arr[1])


def _pair_text(value) -> str:
    try:
        return "(" + ", ".join(f"{float(v):g}" for v in value) + ")"
    except (TypeError, ValueError):
        return describe(value)


# ----------------------------------------------------------------- geometry
def azimuth_degrees(dx, dy) -> np.ndarray:
    """Azimuth of the direction (dx, dy), degrees clockwise from +y (north), in [0, 360).

    ``atan2(dx, dy)`` in degrees, negative ones turned by 360; exact on the axes and on
    the diagonals of a uniform grid (0, 45, 90, ...). A direction just west of north whose
    turned azimuth rounds to 360 is given the largest double below 360, so that it stays
    west of north.

    Examples
    --------
    >>> azimuth_degrees([0.0, 1.0, 0.0, -1.0, 1.0], [1.0, 0.0, -1.0, 0.0, -1.0]).tolist()
    [0.0, 90.0, 180.0, 270.0, 135.0]
    """
    a = np.degrees(np.arctan2(np.asarray(dx, np.float64), np.asarray(dy, np.float64)))
    a = np.where(a < 0.0, a + 360.0, a)
    return np.where(a >= 360.0, np.nextafter(360.0, 0.0), a)


def elevation_degrees(d, dz, kc: float = 0.0) -> np.ndarray:
    """Elevation angle (degrees) of a target at horizontal distance ``d`` and height ``dz``
    above the eye, lowered by the earth's drop ``kc d**2`` (``kc = curvature / (2 R)``)."""
    d = np.asarray(d, np.float64)
    return np.degrees(np.arctan2(np.asarray(dz, np.float64) - kc * d * d, d))


def _in_azimuth(az: np.ndarray, start: float, end: float) -> np.ndarray:
    if (start, end) == (0.0, 360.0):
        return np.ones(az.shape, dtype=bool)
    return np.mod(az - start, 360.0) <= np.mod(end - start, 360.0)


def field_of_view_mask(
    terrain,
    observer,
    fov: FieldOfView,
    *,
    at=None,
    observer_height: float = 1.7,
    target_height: float = 0.0,
    curvature: float = 0.0,
    earth_radius: float = EARTH_RADIUS,
) -> np.ndarray:
    """Which targets of a viewshed lie inside a field of view.

    Parameters
    ----------
    terrain : HeightGrid or TIN
        The surface under test (it gives the eye's and the targets' heights).
    observer : (2,) or (3,) array_like of float
        As in :func:`terrainvis.viewshed`: (x, y) on the surface, or the eye (x, y, z).
    fov : FieldOfView
        From :func:`field_of_view`.
    at, observer_height, target_height, curvature, earth_radius
        As in :func:`terrainvis.viewshed` (the heights matter only for ``vertical``).

    Returns
    -------
    (rows, cols) bool
        True where the target above sample (r, c) of ``at`` (or of the terrain) is inside
        every limit; the sample nearest the observer is True unless it is nearer than
        ``min_distance`` (exempt from the other limits, see the module docstring).
    """
    if not isinstance(fov, FieldOfView):
        raise TypeError(f"fov must be a FieldOfView (from field_of_view(...)), got {describe(fov)}")
    grid = target_grid(terrain, at)
    obs = np.asarray(observer, dtype=np.float64).ravel()
    if obs.size not in (2, 3) or not np.isfinite(obs).all():
        raise ValueError(f"observer must be a finite pair (x, y) or an eye (x, y, z), got {describe(observer)}")
    heights = (float(observer_height), float(target_height), curvature_coefficient(curvature, earth_radius))
    inside = _inside(terrain, grid, obs, fov, np.arange(grid.size), heights).reshape(grid.shape)
    near = _nearest(grid, obs)
    inside[near] = _beyond_min_distance(grid, obs, fov, near)
    return inside


def _beyond_min_distance(grid: HeightGrid, obs: np.ndarray, fov: FieldOfView, sample) -> bool:
    """Whether ``sample`` (r, c) of ``grid`` is at least ``fov.min_distance`` from the observer (True without one)."""
    if fov.min_distance is None:
        return True
    r, c = sample
    dx, dy = grid.xs[c] - obs[0], grid.ys[r] - obs[1]
    return bool(dx * dx + dy * dy >= fov.min_distance * fov.min_distance)


def _nearest(grid: HeightGrid, obs: np.ndarray) -> tuple[int, int]:
    """The sample nearest the observer, as the viewshed finds it: the nearest y and the nearest x."""
    return int(np.argmin(np.abs(grid.ys - obs[1]))), int(np.argmin(np.abs(grid.xs - obs[0])))


def _inside(terrain, grid: HeightGrid, obs: np.ndarray, fov: FieldOfView, idx: np.ndarray, heights) -> np.ndarray:
    """Whether each target ``idx`` (flat indices into ``grid``) lies inside every limit of ``fov``.

    ``heights`` is ``(observer_height, target_height, kc)``, kc the curvature coefficient.
    """
    r, c = np.divmod(idx, grid.shape[1])
    dx = grid.xs[c] - obs[0]
    dy = grid.ys[r] - obs[1]
    inside = np.ones(idx.size, dtype=bool)
    d2 = dx * dx + dy * dy
    if fov.min_distance is not None:
        inside &= d2 >= fov.min_distance * fov.min_distance
    if fov.max_distance is not None:
        inside &= d2 <= fov.max_distance * fov.max_distance
    if not fov.full_circle:
        inside &= _in_azimuth(azimuth_degrees(dx, dy), *fov.azimuth)
    if fov.vertical is not None:
        h_o, h_t, kc = heights
        ez = obs[2] if obs.size == 3 else _ground(terrain, float(obs[0]), float(obs[1])) + h_o
        zt = _target_surface(terrain, grid).ravel()[idx].astype(np.float64) + h_t
        angle = elevation_degrees(np.sqrt(d2), zt - ez, kc)
        inside &= (angle >= fov.vertical[0]) & (angle <= fov.vertical[1])
    return inside


def _ground(terrain, x: float, y: float) -> float:
    """The surface under the observer, as the viewshed places the eye: a sample's own height on a sample."""
    if isinstance(terrain, HeightGrid):
        c = np.flatnonzero(terrain.xs == x)
        r = np.flatnonzero(terrain.ys == y)
        if c.size and r.size:
            return float(terrain.heights[r[0], c[0]])
    return float(terrain.height_at([[x, y]])[0])


def _target_surface(terrain, grid: HeightGrid) -> np.ndarray:
    """The surface under test at the targets' samples (the viewshed's own rule: a grid's own heights)."""
    if isinstance(terrain, HeightGrid) and np.array_equal(grid.xs, terrain.xs) and np.array_equal(grid.ys, terrain.ys):
        return terrain.heights  # float32 for a float32 raster: callers make the heights they use float64
    return terrain.height_on_grid(grid.xs, grid.ys)


def apply_field_of_view(visible: np.ndarray, terrain, observer, fov: FieldOfView, at, heights) -> np.ndarray:
    """``visible`` with the targets outside ``fov`` set to False (``visible`` itself when no limit is set).

    ``at`` is the viewshed's (None: the terrain's own samples); ``heights`` is
    ``(observer_height, target_height, kc)``, kc the curvature coefficient (a Sight's).
    """
    if not fov.limited:
        return visible
    grid = terrain if at is None else at
    obs = np.asarray(observer, dtype=np.float64).ravel()
    idx = np.flatnonzero(visible)  # only the visible targets can change: the mask is computed for them alone
    out = np.zeros_like(visible)
    out.ravel()[idx[_inside(terrain, grid, obs, fov, idx, heights)]] = True
    near = _nearest(grid, obs)
    out[near] = visible[near] and _beyond_min_distance(grid, obs, fov, near)
    return out

