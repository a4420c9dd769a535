"""Radio links: how clear of the terrain the first Fresnel zone of a path is, exactly.

A radio path from antenna A to antenna B needs more than a line of sight: the terrain
should stay out of the first Fresnel ellipsoid, whose radius at horizontal distances d1
from A and d2 from B is

    r1 = sqrt(lambda d1 d2 / (d1 + d2)),   lambda = c / f

(ITU-R P.526, section 2; c the speed of light, f the frequency). :func:`fresnel_clearance`
reports the worst *clearance fraction* along the path, ``min (line - surface) / r1``: the
vertical distance from the straight sight line down to the surface, under earth curvature
the surface raised by the bulge ``curvature * d1 * d2 / (2 R)`` as everywhere in
terrainvis, divided by r1 there. The fraction is 1 where the zone just touches the terrain,
0 where the sight line grazes it, negative where the terrain cuts the line. The usual
radio-planning rule asks for at least 0.6 of the first zone clear (``clear_60``): then an
obstacle costs almost no diffraction loss (ITU-R P.526's knife-edge loss J(nu) starts at
nu = -0.78, i.e. a clearance of 0.78 / sqrt(2) = 0.55 r1), and ITU-R P.1546 measures
path lengths at "0.6 Fresnel clearance".

Exactness. The minimum is taken over the whole path, not over samples. Along the ground
track the surface is linear between consecutive crossings of grid lines and cell
diagonals (:func:`~terrainvis.visibility.clearance_profile` lists them), so on each piece
the clearance is ``g(t) = alpha + beta t - B t (1 - t)`` (t the segment parameter, B =
``curvature L**2 / (2 R)``, L the horizontal length) and ``r1 = sqrt(lambda L t (1 - t))``.
Their ratio is smooth on the piece, so its minimum is at an end of the piece or where the
derivative vanishes: ``g' u = g u' / 2`` with ``u = t (1 - t)``, which expands to the cubic

    2 B t**3 - 3 B t**2 - (2 alpha + beta - B) t + alpha = 0

(on a flat earth the single root ``t = alpha / (2 alpha + beta)``). Its own turning points
cut the piece into at most three parts on which the cubic is monotone; a part whose ends
differ in sign holds one root, found by bisection to the last bit (eigenvalues of the
companion matrix lose their precision when the curvature term is tiny). The ratio is
evaluated at those roots and at the piece's ends. The
interval is the line-of-sight predicate's: the trim of :func:`~terrainvis.visibility.trim_length`
at both ends (an antenna standing on the ground makes r1 and the clearance vanish
together there).

Distances are horizontal (the radio path's profile), and the clearance vertical; on paths
steeper than a few percent the zone's true perpendicular radius differs from r1 by the
cosine of the slope. x, y, z must be metres for r1 to be in metres (a lon/lat DEM is
read in local metres).

References
----------
ITU-R Recommendation P.526, "Propagation by diffraction", section 2 (Fresnel ellipsoids
and zones) and 4.1 (single knife-edge obstacle).

ITU-R Recommendation P.1546, "Method for point-to-area predictions for terrestrial
services" (an approximation to the 0.6 Fresnel clearance path length).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.terrain import HeightGrid, as_terrain
from ..core.validate import as_points, as_positive_finite
from .predicate import EARTH_RADIUS, _check_inside, curvature_coefficient
from .profile import clearance_profile

__all__ = ["SPEED_OF_LIGHT", "CLEAR_FRACTION", "FresnelClearance", "fresnel_clearance", "fresnel_radius"]

#: The speed of light in vacuum, m/s (exact by the SI definition of the metre).
SPEED_OF_LIGHT = 299_792_458.0
#: The share of the first Fresnel zone's radius that radio planning usually asks to keep clear.
CLEAR_FRACTION = 0.6


@dataclass(frozen=True)
class FresnelClearance:
    """The worst clearance of the first Fresnel zone along a path (:func:`fresnel_clearance`).

    Attributes
    ----------
    fraction : float
        ``min (line - surface) / r1`` over the path (the clearance in radii of the zone).
    t, x, y, distance : float
        Where: the segment parameter, the ground position (the terrain's frame) and the
        horizontal distance from ``a``.
    clearance, radius : float
        The clearance (sight line minus surface, less the curvature bulge) and r1 there.
    clear_60 : bool
        ``fraction >= 0.6``: at least 60 % of the first zone clear everywhere.
    frequency, wavelength : float
        Hz and metres.
    profile : dict of (k,) float64 arrays, or None
        With ``profile=True``: ``t``, ``distance``, ``clearance``, ``radius`` and
        ``fraction`` at every breakpoint of the surface along the path and at every
        piece's minimum, in order along the path.
    """

    fraction: float
    t: float
    x: float
    y: float
    distance: float
    clearance: float
    radius: float
    clear_60: bool
    frequency: float
    wavelength: float
    profile: dict | None = field(default=None, repr=False)


def fresnel_radius(d1, d2, frequency: float) -> np.ndarray:
    """Radius of the first Fresnel zone, ``sqrt(lambda d1 d2 / (d1 + d2))`` (metres, Hz).

    Examples
    --------
    Mid-way along a 10 km path at 2.4 GHz (lambda = 0.125 m): sqrt(0.125 * 2500) = 17.7 m.

    >>> round(float(fresnel_radius(5000.0, 5000.0, 2.4e9)), 2)
    17.67
    """
    f = as_positive_finite(frequency, "frequency")
    d1 = np.asarray(d1, np.float64)
    d2 = np.asarray(d2, np.float64)
    return np.sqrt(SPEED_OF_LIGHT / f * d1 * d2 / (d1 + d2))


def fresnel_clearance(
    terrain,
    a,
    b,
    frequency: float,
    *,
    curvature: float = 0.0,
    earth_radius: float = EARTH_RADIUS,
    profile: bool = False,
) -> FresnelClearance:
    """The worst clearance of the first Fresnel zone along the path a -> b, exactly.

    Parameters
    ----------
    terrain : HeightGrid or TIN
        The surface (x, y, z in metres); a HeightGrid without nodata.
    a, b : (3,) array_like of float
        The antennas (x, y, z), inside the footprint; z is the antenna's height, e.g.
        the surface there plus the mast.
    frequency : float
        Hz (> 0): 2.4e9 for 2.4 GHz.
    curvature, earth_radius : float
        Earth curvature and refraction as in :func:`terrainvis.line_of_sight` (GDAL's
        coefficient; radio planners' k-factor 4/3 is ``curvature=0.75``).
    profile : bool
        Also return the clearance fraction along the path.

    Returns
    -------
    FresnelClearance

    Raises
    ------
    ValueError, TypeError
        On invalid arguments (naming the argument): a frequency <= 0, ends outside the
        footprint (:class:`~terrainvis.errors.OutsideFootprintError`), a path no longer
        than twice the trim length.

    Examples
    --------
    Flat ground, both antennas 10 m up, 1 km apart at 3 GHz (lambda = 0.0999 m): the
    worst point is mid-way, where r1 = sqrt(0.0999 * 250) = 5.0 m, so 10 m is 2.0 radii:

    >>> from terrainvis import HeightGrid
    >>> g = HeightGrid(np.zeros((3, 11)), dx=100.0, dy=100.0)
    >>> r = fresnel_clearance(g, [0.0, 100.0, 10.0], [1000.0, 100.0, 10.0], 3e9)
    >>> round(r.fraction, 4), r.distance, r.clear_60
    (2.0007, 500.0, True)
    """
    as_terrain(terrain)
    f = as_positive_finite(frequency, "frequency")
    if isinstance(terrain, HeightGrid):
        terrain.require_finite("fresnel_clearance")
    pts = as_points(np.vstack([np.asarray(a, float).reshape(1, -1), np.asarray(b, float).reshape(1, -1)]), "a, b", 3)
    _check_inside(terrain, pts[:1], "a")
    _check_inside(terrain, pts[1:], "b")
    kc = curvature_coefficient(curvature, earth_radius)
    a, b = pts
    t, flat = clearance_profile(terrain, a, b)  # breakpoints of the flat clearance, linear between them
    if t.size < 2:
        raise ValueError(f"a and b must be farther apart than twice the trim length, got a = {a.tolist()}, "
                         f"b = {b.tolist()}")
    length = float(np.hypot(*(b - a)[:2]))
    if length == 0.0:
        raise ValueError(f"a and b must be apart horizontally, got a vertical link a = {a.tolist()}, b = "
                         f"{b.tolist()}: its first Fresnel zone is not over the terrain (the zone's radius is 0 at "
                         "every point of it); line_of_sight answers whether it is clear")
    wavelength = SPEED_OF_LIGHT / f
    pieces = _Pieces(t, flat, kc * length * length)
    ts = np.unique(np.concatenate([t, pieces.critical_points()]))
    g = pieces.clearance(ts)
    radius = np.sqrt(wavelength * length * ts * (1.0 - ts))
    frac = g / radius
    i = int(np.argmin(frac))
    prof = None
    if profile:
        prof = {"t": ts, "distance": ts * length, "clearance": g, "radius": radius, "fraction": frac}
    return FresnelClearance(
        fraction=float(frac[i]), t=float(ts[i]), x=float(a[0] + ts[i] * (b[0] - a[0])),
        y=float(a[1] + ts[i] * (b[1] - a[1])), distance=float(ts[i] * length), clearance=float(g[i]),
        radius=float(radius[i]), clear_60=bool(frac[i] >= CLEAR_FRACTION), frequency=f, wavelength=wavelength,
        profile=prof,
    )


class _Pieces:
    """The clearance along a path, ``c_k + beta_k (t - t_k) - bulge t (1 - t)`` on the piece
    between breakpoints ``t_k`` and ``t_k+1``."""

    def __init__(self, t: np.ndarray, flat: np.ndarray, bulge: float):
        self.t = t
        self.c = flat[:-1]
        self.beta = np.diff(flat) / np.diff(t)
        self.bulge = bulge

    def clearance(self, ts: np.ndarray, k=None) -> np.ndarray:
        """The clearance at parameters ``ts`` (within the breakpoints), from each one's own piece ``k``."""
        if k is None:
            k = np.clip(np.searchsorted(self.t, ts, side="right") - 1, 0, self.beta.size - 1)
        return self.c[k] + self.beta[k] * (ts - self.t[k]) - self.bulge * ts * (1.0 - ts)

    def _slope_sign(self, ts: np.ndarray, k: np.ndarray) -> np.ndarray:
        """A function with the sign of (clearance / r1)' at ``ts`` on piece ``k``: ``g' u - g u' / 2``,
        ``u = t (1 - t)``."""
        g = self.clearance(ts, k)
        dg = self.beta[k] - self.bulge * (1.0 - 2.0 * ts)
        return dg * ts * (1.0 - ts) - 0.5 * g * (1.0 - 2.0 * ts)

    def critical_points(self) -> np.ndarray:
        """Every t inside a piece where (clearance / r1)' = 0.

        The derivative's sign function is a cubic in t (linear on a flat earth); its own
        turning points, ``t = 1/2 +- sqrt((1 + 2 s) / 12)`` with ``s = (2 alpha + beta) /
        bulge`` (alpha, beta the piece's line in t), cut each piece into at most three
        parts on which it is monotone; a part whose ends differ in sign holds one root,
        found by bisection to the last bit.
        """
        n = self.beta.size
        lo, hi = self.t[:-1], self.t[1:]
        edges = np.column_stack([lo, lo, hi, hi])
        if self.bulge > 0.0:
            two_alpha_beta = 2.0 * self.c + self.beta * (1.0 - 2.0 * lo)  # 2 alpha + beta, alpha the value at t = 0
            with np.errstate(invalid="ignore"):
                w = np.sqrt((1.0 + 2.0 * two_alpha_beta / self.bulge) / 12.0)
            w = np.where(np.isfinite(w), w, 0.0)
            edges[:, 1] = np.clip(0.5 - w, lo, hi)
            edges[:, 2] = np.clip(0.5 + w, lo, hi)
        k = np.repeat(np.arange(n), 3)
        a, b = edges[:, :3].ravel(), edges[:, 1:].ravel()
        return _bisect(lambda x: self._slope_sign(x, k), a, b)


def _bisect(fn, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The roots of ``fn`` (elementwise) in the intervals (a, b) whose ends differ in sign, by bisection."""
    fa, fb = fn(a), fn(b)
    ok = (a < b) & (np.sign(fa) * np.sign(fb) < 0)
    a, b, fa = a.copy(), b.copy(), fa
    for _ in range(1100):  # at most ~1075 halvings separate two doubles; stops when none moves
        m = 0.5 * (a + b)
        moved = ok & (m > a) & (m < b)
        if not moved.any():
            break
        fm = fn(m)
        left = np.sign(fm) == np.sign(fa)
        a = np.where(moved & left, m, a)
        fa = np.where(moved & left, fm, fa)
        b = np.where(moved & ~left, m, b)
    return (0.5 * (a + b))[ok]
