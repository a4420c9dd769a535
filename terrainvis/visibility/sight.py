"""The sight: what a line of sight of a viewshed is, as one value.

A :class:`Sight` holds everything about the sight lines of a viewshed that does not depend
on the terrain: the eye's height above the surface, the targets' height, the engine, the
earth model (curvature coefficient and radius), the end radius of the predicate and the
field of view (:class:`~terrainvis.visibility.FieldOfView`: azimuth, vertical angles, the
least and the largest distance). It is checked once, when it is made, with the messages the functions
give for their keywords; it is frozen and pickles, so it crosses to worker processes
whole. :func:`terrainvis.viewshed`, :func:`terrainvis.cumulative_viewshed`,
:func:`terrainvis.observer_sets` and :func:`terrainvis.site_observers` take one as
``sight=`` instead of their keywords (which stay as a front: each call makes one Sight
from them). A viewshed tests its sight lines whole: its Sight's ``end_radius`` must be 0.

The functions of point pairs, :func:`terrainvis.line_of_sight`,
:func:`terrainvis.visibility_matrix` and :func:`terrainvis.min_clearance`, read the
predicate from a Sight (:func:`pair_sight`): engine, end radius, curvature and earth
radius. Their points carry their own heights (a Sight's eye and target heights are not
used), and a field of view is a viewshed's: they refuse a Sight that has one.

The checks that need the terrain (a height within what float64 resolves on it, an engine
that runs on it) are :func:`engine_on`'s, made where the terrain is known.

Many observers (``cumulative_viewshed`` and the others) may stand at different heights:
the Sight holds one eye height, and those functions keep a (K,) ``observer_height`` array
beside it, which replaces the Sight's height observer by observer.

Examples
--------
>>> import numpy as np
>>> from terrainvis import HeightGrid, viewshed
>>> s = Sight.make(observer_height=1.0, max_distance=3.0)
>>> s.fov.max_distance, s.kc
(3.0, 0.0)
>>> z = np.zeros((3, 5))
>>> z[:, 2] = 5.0
>>> viewshed(HeightGrid(z), (0.0, 1.0), sight=s).astype(int)
array([[1, 1, 1, 0, 0],
       [1, 1, 1, 0, 0],
       [1, 1, 1, 0, 0]])
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..core.validate import as_nonnegative_finite, describe
from .engines import AUTO, Engine, check_name, choose
from .viewsheds.field_of_view import FieldOfView, field_of_view
from .predicate import EARTH_RADIUS, _check_end_radius, _height_above, curvature_coefficient

__all__ = ["Sight", "KEYWORDS", "PAIR_KEYWORDS", "sight_of", "pair_sight", "engine_on"]

#: The keywords of the viewshed family that a Sight gathers, with the defaults of the functions that take them.
KEYWORDS = {
    "observer_height": 1.7, "target_height": 0.0, "max_distance": None, "engine": AUTO, "curvature": 0.0,
    "earth_radius": EARTH_RADIUS, "azimuth": None, "vertical": None, "min_distance": None,
}
#: The keywords of the functions of point pairs that a Sight gathers (the predicate), with their defaults.
PAIR_KEYWORDS = {"engine": AUTO, "end_radius": 0.0, "curvature": 0.0, "earth_radius": EARTH_RADIUS}


@dataclass(frozen=True)
class Sight:
    """The sight lines of a viewshed: eye and target heights, engine, earth model, field of view.

    Made checked: ``Sight(...)`` and :meth:`make` refuse a bad value with the message
    :func:`terrainvis.viewshed` gives for the same keyword.

    Attributes
    ----------
    observer_height : float
        Height (>= 0, z units) of the eye above the surface (not used for an observer given
        as its eye (x, y, z)).
    target_height : float
        Height (>= 0) of every target above the surface.
    engine : str
        ``"auto"`` or a registered engine's name (:data:`terrainvis.visibility.ENGINES`).
    curvature : float
        GDAL's ``-cc`` coefficient: 0 a flat earth, 1 geometric, 0.85714 standard refraction.
    earth_radius : float
        The earth's radius in the terrain's x/y units.
    fov : FieldOfView
        The field of view (``max_distance`` among its limits); no limits by default.
    end_radius : float
        Horizontal distance (>= 0, x/y units) around each end of a sight line inside which
        the surface is not tested (:mod:`terrainvis.visibility`); 0, the exact predicate,
        is the only value a viewshed takes.
    """

    observer_height: float = 1.7
    target_height: float = 0.0
    engine: str = AUTO
    curvature: float = 0.0
    earth_radius: float = EARTH_RADIUS
    fov: FieldOfView = FieldOfView()
    end_radius: float = 0.0

    def __post_init__(self):
        if not isinstance(self.fov, FieldOfView):
            raise TypeError(f"fov must be a FieldOfView (from field_of_view(...)), got {describe(self.fov)}")
        put = object.__setattr__  # frozen: the checked values replace the given ones once, here
        put(self, "observer_height", as_nonnegative_finite(self.observer_height, "observer_height", "z units"))
        put(self, "target_height", as_nonnegative_finite(self.target_height, "target_height", "z units"))
        put(self, "engine", check_name(self.engine))
        curvature_coefficient(self.curvature, self.earth_radius)  # both checked, in its words
        put(self, "curvature", float(self.curvature))
        put(self, "earth_radius", float(self.earth_radius))
        put(self, "end_radius", _check_end_radius(self.end_radius))

    @classmethod
    def make(cls, *, observer_height=1.7, target_height=0.0, max_distance=None, engine: str = AUTO,
             curvature=0.0, earth_radius=EARTH_RADIUS, azimuth=None, vertical=None, min_distance=None,
             end_radius=0.0, names=None) -> "Sight":
        """A Sight from the keywords of :func:`terrainvis.viewshed` (and the same messages).

        ``names`` is passed to :func:`~terrainvis.visibility.viewsheds.field_of_view.field_of_view` (the command line
        names the limits by its flags).
        """
        fov = field_of_view(azimuth=azimuth, vertical=vertical, min_distance=min_distance,
                            max_distance=max_distance, names=names)
        return cls(observer_height, target_height, engine, curvature, earth_radius, fov, end_radius)

    @property
    def kc(self) -> float:
        """The curvature coefficient ``curvature / (2 earth_radius)`` (:func:`~terrainvis.visibility.curvature_coefficient`)."""
        return curvature_coefficient(self.curvature, self.earth_radius)

    @property
    def max_distance(self) -> float | None:
        """The field of view's largest distance (None: no limit)."""
        return self.fov.max_distance

    def keywords(self) -> dict:
        """The Sight as the viewshed's keywords: ``viewshed(t, obs, **s.keywords())`` is ``viewshed(t, obs, sight=s)``
        (a viewshed has no ``end_radius``: it is 0 there)."""
        return {"observer_height": self.observer_height, "target_height": self.target_height,
                "max_distance": self.fov.max_distance, "engine": self.engine, "curvature": self.curvature,
                "earth_radius": self.earth_radius, "azimuth": self.fov.azimuth, "vertical": self.fov.vertical,
                "min_distance": self.fov.min_distance}

    def with_observer_height(self, height) -> "Sight":
        """The same Sight with the eye at ``height`` above the surface (checked)."""
        return dataclasses.replace(self, observer_height=height)


def sight_of(sight, keywords: dict, defaults: dict = KEYWORDS) -> Sight:
    """The one Sight of a public function's call: ``sight`` itself, or one made from its ``keywords``.

    Raises
    ------
    TypeError
        When ``sight`` is not a Sight, or comes with a keyword set to other than its default
        in ``defaults`` (:data:`KEYWORDS`, the viewshed's; :data:`PAIR_KEYWORDS`, the pair
        functions'; the message names the keyword).
    """
    if sight is None:
        return Sight.make(**keywords)
    if not isinstance(sight, Sight):
        raise TypeError(f"sight must be a terrainvis.visibility.Sight (from Sight.make(...)) or None, "
                        f"got {describe(sight)}")
    for name, value in keywords.items():
        if _differs(value, defaults[name]):
            raise TypeError(f"pass either sight= or the keyword {name}=, not both (the Sight holds {name}; "
                            f"got {name}={describe(value)} beside it)")
    return sight


def pair_sight(sight, keywords: dict, name: str) -> Sight:
    """The Sight of a call of a function of point pairs (``name``): ``sight``, or one made from its
    :data:`PAIR_KEYWORDS` (``keywords``); a Sight given with a keyword set beside it, or with a field of
    view, is refused."""
    s = sight_of(sight, keywords, PAIR_KEYWORDS)
    if sight is not None and s.fov.limited:
        raise ValueError(f"{name} takes the predicate of a Sight (engine, end_radius, curvature, earth_radius); its "
                         f"field of view ({s.fov.describe()}) is a viewshed's: pass a Sight without one")
    return s


def _differs(value, default) -> bool:
    """Whether a keyword was given a value other than its default."""
    if default is None:
        return value is not None
    if isinstance(default, str):
        return not (isinstance(value, str) and value == default)
    return not (np.ndim(value) == 0 and not isinstance(value, (str, bytes)) and value == default)


def engine_on(terrain, sight: Sight) -> Engine:
    """The engine that answers ``sight`` on ``terrain``, after the checks that need the terrain.

    The engine must run on the terrain and model the Sight's curvature
    (:func:`~terrainvis.visibility.engines.choose`), and each height must lie within what
    float64 resolves against the terrain.
    """
    if sight.end_radius != 0.0:
        raise ValueError(f"a viewshed tests its sight lines whole (the exact predicate): the Sight's end_radius must "
                         f"be 0, got {sight.end_radius!r}")
    engine = choose(sight.engine, terrain, sight.kc)
    _height_above(sight.observer_height, "observer_height", terrain)
    _height_above(sight.target_height, "target_height", terrain)
    return engine
