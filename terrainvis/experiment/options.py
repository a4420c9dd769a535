"""The options of :func:`terrainvis.compare`, each declared once.

An option is everything that determines the rows of a run (methods, levels, point sets,
predicate, ...). Each one is one :class:`Option` in :data:`OPTIONS`: its name, default,
validation, help text, command-line flag, the measures it applies to, and whether it is
passed on to every visibility computation of the run. From that one entry:

* :func:`terrainvis.compare` accepts it as a keyword-only argument, shows it in its
  signature and docstring (``help(compare)``), and validates it before any unit runs
  (:func:`validate`);
* ``terrainvis compare`` gets its flag, with the help text and the default
  (:func:`add_flags`, :func:`given`);
* the run's stored settings (``results.settings.json``) record it, and a resume with
  another value is refused naming it (:meth:`Settings.as_dict`);
* with ``los=True``, it is the field of the same name of the run's
  :class:`~terrainvis.visibility.Sight` (:func:`sight`), the one record the units hand to
  every visibility computation.

Checks that involve several options (or the terrains) are the :data:`RULES`.
``docs/architecture.md`` ("How to add an option") shows how to add one.

An option that only one relocation reads (the number of the calibrated relocation's partners,
for instance) is not declared here but in the relocation's own entry
(:attr:`terrainvis.relocation.Relocation.run_options`): :data:`OPTIONS` reads those from
the relocation registry whenever it is asked, so such an option is everything above, and
the units hand its value to the relocations that declare it.
:class:`~terrainvis.core.option.Option` itself lives in :mod:`terrainvis.core.option`, so
that the relocation layer can make one without importing the experiment.
"""

from __future__ import annotations

import argparse
import inspect
import numbers
from collections.abc import Callable, MutableMapping, Sequence

import numpy as np

from ..core.option import Flag, Option, Switch, add_flag, boolean, finite, height, integer, nonnegative
from ..core.validate import as_float_array, as_int, choice, describe
from ..relocation.registry import run_options
from ..visibility import EARTH_RADIUS

__all__ = [
    "Option", "Flag", "Switch", "OPTIONS", "RULES", "Settings", "DEFAULTS", "validate", "sight",
    "add_flags", "given", "PREDICATES", "DISTANCE_UNITS", "CASCADE_AUTO_MIN_SAMPLES", "budgeted", "steps",
    "integer", "finite", "height", "boolean", "one_of", "names",
]


#: Line-of-sight predicates for the verdicts on S(T) (verdicts on T are always exact):
#: ``"exact"`` tests the whole segment; ``"paper"`` ignores the surface within one cell
#: of S(T) around each end (see :func:`terrainvis.experiment.units.end_radius_for`).
PREDICATES = ("exact", "paper")

#: Units of ``max_distance``: world units (metres), or cells of the original terrain
#: (its larger cell side), so one sweep means the same on terrains of different resolution.
DISTANCE_UNITS = ("world", "cells")

#: ``cascade="auto"`` cascades on grids of more than this many samples (above about
#: 724²; at 1024² three independent QEC decimations take minutes and, two at once on two
#: workers, 2.9 GB; the paper's 120² terrains stay independent). :func:`terrainvis.compare`
#: reads it as ``terrainvis.experiment.comparison.CASCADE_AUTO_MIN_SAMPLES`` when it plans a run.
CASCADE_AUTO_MIN_SAMPLES = 1 << 19


# ---------------------------------------------------------------------- checks
def _positive(value, name: str) -> float:
    """A check: a finite real number > 0."""
    out = finite(value, name)
    if out <= 0:
        raise ValueError(f"{name} must be > 0, got {out!r}")
    return out


def one_of(valid: Callable[[], Sequence[str]]):
    """A check: one of the names ``valid()`` lists (read when the check runs)."""
    return lambda value, name: choice(value, name, valid())


def names(valid: Callable[[], Sequence[str]], default: Callable[[], Sequence[str]], hint: str = ""):
    """A check: distinct names drawn from ``valid()`` (a str is one name; None is ``default()``);
    ``hint`` ends the message of an unknown name."""

    def check(value, name: str) -> tuple:
        if value is None:
            return tuple(default())
        if isinstance(value, str):
            value = [value]
        if not isinstance(value, (list, tuple)):
            raise TypeError(f"{name} must be a list of names, got {describe(value)}")
        allowed = list(valid())
        out = []
        for v in value:
            if not isinstance(v, str) or v not in allowed:
                raise ValueError(f"{name} must be drawn from {allowed}, got {v!r}{hint}")
            if v in out:
                raise ValueError(f"{name} must not repeat a name, got {v!r} twice")
            out.append(v)
        if not out:
            raise ValueError(f"{name} must name at least one of {allowed}, got an empty list")
        return tuple(out)

    return check


def _levels(value, name: str) -> tuple:
    """Distinct levels >= 1 (whether each terrain has them is the rule :func:`_levels_fit`)."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
        value = [value]
    if not isinstance(value, (list, tuple)):
        raise TypeError(f"{name} must be an integer or a list of integers, got {describe(value)}")
    levels = []
    for v in value:
        lv = as_int(v, name, minimum=1)
        if lv in levels:
            raise ValueError(f"{name} must not repeat a level, got {lv} twice")
        levels.append(lv)
    if not levels:
        raise ValueError(f"{name} must hold at least one level, got an empty list")
    return tuple(levels)


def _budgets(value, name: str) -> tuple | None:
    """Distinct maximum vertical errors > 0 (z units) as a tuple of floats, or None (a run by levels)."""
    if value is None:
        return None
    if isinstance(value, np.ndarray) and value.ndim == 1:
        value = value.tolist()
    values = list(value) if isinstance(value, (list, tuple)) else [value]
    if not values:
        raise ValueError(f"{name} must hold at least one maximum vertical error (a number > 0, z units), got an "
                         "empty list")
    out = []
    for v in values:
        expected = f"{name} must hold finite numbers > 0 (maximum vertical errors, z units)"
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real):
            raise ValueError(f"{expected}, got {describe(v)}")
        e = float(v)
        if not np.isfinite(e) or e <= 0:
            raise ValueError(f"{expected}, got {e!r}")
        if e in out:
            raise ValueError(f"{name} must not repeat an error, got {e!r} twice")
        out.append(e)
    return tuple(out)


def _error_word(text: str) -> float:
    """``--max-error`` words: numbers (whether each is finite and > 0 is the option's own check)."""
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a maximum vertical error (a number > 0, z units), "
                                         f"got {text!r}") from None


def _distances(value, name: str) -> tuple:
    """Distinct distances > 0 (None: unlimited) as a tuple."""
    values = list(value) if isinstance(value, (list, tuple)) else [value]
    out = []
    for v in values:
        if v is not None:
            d = as_float_array(v, name)
            if d.ndim != 0:
                raise TypeError(f"{name} must hold numbers or None, got {describe(v)}")
            v = float(d)
            if v == np.inf:
                v = None
            elif not np.isfinite(v) or v <= 0:
                raise ValueError(f"{name} must be > 0 (or None / inf for every pair), got {v!r}")
        if v in out:
            raise ValueError(f"{name} must not repeat a distance, got {v!r} twice")
        out.append(v)
    if not out:
        raise ValueError(f"{name} must hold at least one distance (None: every pair), got an empty list")
    return tuple(out)


def _cascade(value, name: str):
    if isinstance(value, str) and value == "auto":
        return value
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True, False or 'auto', got {describe(value)}")
    return bool(value)


def _distance_word(text: str):
    """``--max-distance`` words: a number, or ``all`` (also ``inf``, ``none``) for every pair."""
    if text.lower() in ("all", "inf", "none"):
        return None
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a distance or 'all', got {text!r}") from None


def _method_names():
    from simplifiers import METHODS

    return list(METHODS)


def _methods(value, name: str) -> tuple:
    """A check: method names, a :class:`simplifiers.Method` counting as its name (registered first if new)."""
    from simplifiers import METHODS, Method

    if isinstance(value, (list, tuple)):
        named = []
        for v in value:
            if isinstance(v, Method):
                if v.name not in METHODS:
                    _register_entry(v)
                elif METHODS[v.name] != v:
                    raise ValueError(f"{name}: a different method named {v.name!r} is registered already; "
                                     "unregister it or give yours another name")
                v = v.name
            named.append(v)
        value = named
    elif isinstance(value, Method):
        return _methods([value], name)
    return names(_method_names, _default_method_names, _OWN_METHODS)(value, name)


#: How a method of one's own reaches a run: the end of the message of an unknown method.
_OWN_METHODS = ("; simplifiers.register() adds a method of your own to its Python process only: the command line "
                "sees one through a plugin, an entry point of the group 'terrainvis.simplifiers' (examples/plugin/"
                "README.md)")


def _register_entry(method) -> None:
    from simplifiers.registry import METHODS, register

    if method.function is not None:
        register(method.name, method.function, kind=method.kind, description=method.description,
                 options=method.options, cost_rank=method.cost_rank, style=method.style, memory=method.memory,
                 default=method.default)
    else:  # a Method that names its module and attribute, as a plugin's does
        METHODS[method.name] = method


def _default_method_names():
    from simplifiers import default_methods

    return default_methods()


def _relocation_names():
    from ..relocation.registry import available

    return available()


def _default_relocations():
    from ..relocation.registry import default_relocations

    return default_relocations()


def _measure_names():
    from .measures import available

    return available()


def _engines():
    from ..visibility import engine_names

    return engine_names()


# ---------------------------------------------------------------------- the options
_DECLARED = [
    Option(
        "methods", None, _methods,
        "simplification methods", "sequence of str or simplifiers.Method", default_text="the paper's seven (every method declared default)",
        doc=("Names of the registry :data:`simplifiers.METHODS` (in the paper's order, then the methods registered "
             "from outside: :func:`simplifiers.register`, plugins) or :class:`simplifiers.Method` entries, which "
             "are registered under their names if they are not yet; the default is every method whose entry has "
             "``default=True`` (the paper's seven: every built-in one but ``visopt``; the practitioners' simplifiers of the ``peers`` extra are not default)."),
        cli=Flag(many=True, metavar="M", listed=_method_names),
    ),
    Option(
        "levels", (1, 2, 3), _levels, "simplification levels", "int or sequence of int",
        doc="For 120x120 grids 1, 2, 3 are the paper's 25 %, 6 % and 1.5 %.",
        cli=Flag(type=int, many=True), quick=[1, 3],
    ),
    Option(
        "max_errors", None, _budgets,
        "budgets in maximum vertical error (z units), in place of levels: each method simplified to its "
        "smallest result within each", "float or sequence of float", default_text="none: budgets by levels",
        doc=("With budgets, a unit is a terrain x method x budget E: :func:`simplifiers.simplify` ``(grid, "
             "method, max_error=E)`` gives the smallest result whose maximum vertical error is <= E (a regular "
             "method its coarsest level within E, greedy insertion and greedy cuts stopping at E, QEC a search on "
             "the vertex count). The rows carry E in ``max_error_budget``, the error reached in ``max_error``, "
             "the level a regular method reached in ``level`` (empty for the irregular ones) and in ``stopped_by`` "
             "``\"max_error\"`` when E was met, ``\"budget\"`` when the method could not reach E at any size "
             "it allows, or ``\"exceeded\"`` when it said E was met and the measured error exceeds it (such rows "
             "are kept). Not with ``levels`` given too, nor with ``cascade=True`` (each budget "
             "is simplified from T: ``\"auto\"`` never cascades budgets)."),
        cli=Flag("--max-error", _error_word, many=True, metavar="E"),
    ),
    Option(
        "relocations", None, names(_relocation_names, _default_relocations),
        "relocations of the points onto S(T) (add 'oracle' for the upper bound)", "sequence of str",
        default_text="every relocation declared default: identity, full, half, calibrated",
        doc=("Names of the registry :data:`terrainvis.relocation.RELOCATIONS`: the paper's ``\"identity\"``, "
             "``\"full\"``, ``\"half\"``, the ``\"calibrated\"`` relocation (:func:`terrainvis.relocate`; "
             ":mod:`terrainvis.relocation.calibrated`), ``\"oracle\"``, the upper bound that needs T's verdicts "
             "(not a practical relocation; it costs many visibility queries per point set), and any registered "
             "with :func:`terrainvis.relocation.register`. The default is every relocation declared "
             "``default=True``."),
        cli=Flag(many=True, metavar="R"),
    ),
    Option(
        "n_points", 50, integer(minimum=2), "points per set", "int", measures=("pairs",),
        doc="Each terrain gets ``n_sets`` sets of ``n_points`` uniform random points; every method sees the same sets.",
        cli=Flag("--points", int), quick=20,
    ),
    Option("n_sets", 6, integer(minimum=1), "point sets per terrain", "int", measures=("pairs",),
           cli=Flag("--sets", int), quick=2),
    Option(
        "seed", 0, integer(minimum=0), "seed of the point sets (and of the viewshed measure's observers)", "int",
        doc="The point sets depend only on ``seed`` and the terrain's name.",
        cli=Flag(type=int),
    ),
    Option(
        "max_distance", None, _distances,
        "count only pairs within this horizontal distance; several give a sweep from the same verdicts "
        "('all' for every pair)", "float or None or sequence of them", default_text="every pair",
        doc=("Localized visibility tests; None or inf: every pair. A sweep costs little more than one "
             "distance: each distance gets its rows from the same verdicts."),
        cli=Flag(type=_distance_word, many=True, metavar="D"),
    ),
    Option(
        "distance_unit", "world", one_of(lambda: DISTANCE_UNITS),
        "unit of max_distance: world units or cells of the terrain (its larger cell side)", "{'world', 'cells'}",
        cli=Flag(choices=lambda: DISTANCE_UNITS),
    ),
    Option(
        "offset", 0.0, height, "observer height above the original surface, >= 0", "float",
        doc="See :mod:`terrainvis.relocation`.", cli=Flag(type=float),
    ),
    Option(
        "engine", "auto", one_of(_engines), "visibility engine", "str: 'auto' or a name of terrainvis.visibility.ENGINES",
        doc=("``\"auto\"`` (the exact grid walk on grids; on TINs Embree, or the exact TIN clipper under curvature) or "
             "an engine of :data:`terrainvis.visibility.ENGINES`: see :func:`terrainvis.visibility_matrix`."),
        cli=Flag(choices=_engines), los=True,
    ),
    Option(
        "curvature", 0.0, nonnegative, "earth curvature coefficient: 0 a flat earth (the paper's), 1 geometric, "
        "0.85714 with standard refraction (GDAL's -cc)", "float",
        doc=("Every line of sight, on T and on S(T), clears the surface raised by ``curvature * d1 * d2 / "
             "(2 * earth_radius)`` (:func:`terrainvis.line_of_sight`)."),
        cli=Flag(type=float), los=True,
    ),
    Option(
        "earth_radius", EARTH_RADIUS, _positive, "earth radius in the terrain's x/y units (metres)", "float",
        default_text=f"{EARTH_RADIUS:,.0f} (WGS84's semi-major axis)", cli=Flag(type=float), los=True,
    ),
    Option(
        "predicate", "exact", one_of(lambda: PREDICATES),
        "line-of-sight predicate on S(T): exact, or paper (ignore one cell of S(T) around each end)",
        "{'exact', 'paper'}", doc="The verdicts on T are always exact (:data:`PREDICATES`).",
        cli=Flag(choices=lambda: PREDICATES),
    ),
    Option(
        "volume", True, boolean, "compute the volume between T and S(T)", "bool",
        doc="See :func:`terrainvis.volume_error`.",
        cli=Switch(off="--no-volume", off_help="skip the volume between T and S(T)"),
    ),
    Option(
        "repeats", 3, integer(minimum=1), "timings per visibility matrix (the fastest is kept)", "int",
        cli=Flag(type=int),
    ),
    Option(
        "cascade", "auto", _cascade,
        "simplify each QEC level from the previous level's result (one decimation instead of three; changes "
        "QEC's results slightly, see the README)", "bool or 'auto'",
        default_text=f"only on grids of more than {CASCADE_AUTO_MIN_SAMPLES:,} samples",
        doc=("Applies to the methods that can continue from a finer result (QEC). On 1024², RMS errors are "
             "6-8 % lower and accuracies within 0.1 points. False simplifies every level from T as the paper "
             "does; ``\"auto\"`` cascades on grids of more than :data:`CASCADE_AUTO_MIN_SAMPLES` samples only. "
             "The ``cascaded`` column records which levels started from a finer result."),
        cli=Switch(on="--cascade", off="--no-cascade",
                   off_help="simplify every level from the terrain itself, as the paper does, whatever its size"),
    ),
    Option(
        "measure", "pairs", one_of(_measure_names),
        "pairs: the paper's visibility matrices; viewshed: each observer's viewshed of every sample",
        "str: a measure of terrainvis.experiment.measures.MEASURES",
        doc=("With ``\"viewshed\"``, for ``n_observers`` random observers per terrain (``offset`` above T, "
             "relocated onto S(T) like the points), the viewshed of every sample of T on T and on S(T) "
             "(targets ``target_height`` above the surface under test); each row is one observer and "
             "counts cells as pairs (observer, cell), with the share of cells whose verdict survives in "
             "``accuracy``, the visible-area ratio S(T) / T in ``visible_area_ratio`` and the error of the "
             "minimum-visible-height raster on S(T) (RMS and 95th percentile of its absolute value, z units) in "
             "``min_height_rms`` and ``min_height_p95``; once per unit, the share of T's area that ``siting`` "
             "observers sited on S(T), and as many sited on T, see on T, in ``siting_share``, "
             "``siting_share_original`` and ``siting_ratio``."),
        cli=Flag(choices=_measure_names),
    ),
    Option("n_observers", 20, integer(minimum=1), "observers per terrain", "int", measures=("viewshed",),
           cli=Flag("--observers", int)),
    Option(
        "target_height", 0.0, height, "the viewshed targets' height above the surface under test, >= 0", "float",
        measures=("viewshed",), cli=Flag(type=float),
    ),
    Option(
        "min_height", True, boolean, "measure the error of the minimum-visible-height raster on S(T)", "bool",
        measures=("viewshed",),
        doc=("The ``output=\"min_height\"`` viewsheds on T and on S(T) behind ``min_height_rms`` and "
             "``min_height_p95``; False leaves those columns empty and saves about 40 % of a viewshed run."),
        cli=Switch(off="--no-min-height", off_help="skip the minimum-visible-height rasters (viewshed measure)"),
    ),
    Option(
        "siting", 4, integer(minimum=0),
        "observers sited greedily on S(T) and on T to compare the area each choice sees on T (0: no siting)", "int",
        measures=("viewshed",),
        doc=("Per unit, k observers chosen by :func:`terrainvis.site_observers` among a lattice of T's samples "
             "(at most 8 x 8) on S(T) and on T, and the share of T's area each choice sees on T: "
             "``siting_share``, ``siting_share_original`` and their ratio ``siting_ratio`` "
             "(:func:`terrainvis.experiment.measures.siting_coverage`); 0 leaves those columns empty and saves "
             "about 12 % of a viewshed run."),
        cli=Flag(type=int, metavar="K"),
    ),
]


class _Options(MutableMapping):
    """The options of :func:`terrainvis.compare` by name, in the order of its signature: those
    declared here, and after ``relocations`` those the relocations declare (their
    :attr:`~terrainvis.relocation.Relocation.run_options`, in registry order), read from
    the registry whenever asked, so that a relocation registered at any time brings its own.
    Setting or deleting a name changes the options declared here."""

    def __init__(self, declared):
        self._declared = {o.name: o for o in declared}

    def _all(self) -> dict:
        out = {}
        for name, option in self._declared.items():
            out[name] = option
            if name == "relocations":
                for own in run_options():
                    out.setdefault(own.name, own)  # a name taken here is refused (check_relocation_options)
        return out

    def __getitem__(self, name: str) -> Option:
        return self._all()[name]

    def __iter__(self):
        return iter(self._all())

    def __len__(self) -> int:
        return len(self._all())

    def __setitem__(self, name: str, option: Option) -> None:
        self._declared[name] = option

    def __delitem__(self, name: str) -> None:
        del self._declared[name]

    def __repr__(self) -> str:
        return f"OPTIONS({list(self)})"


#: Every option of :func:`terrainvis.compare`, by name, in the order of its signature.
#: Adding an option is one entry in ``_DECLARED`` (plus the code that uses it); an option
#: of one relocation is declared by its entry instead (``Relocation(run_options=...)``).
OPTIONS: MutableMapping[str, Option] = _Options(_DECLARED)


def check_relocation_options() -> None:
    """Refuse a relocation's own option whose name is one of the options declared here.

    Raises
    ------
    TypeError
        Naming the relocation, the option and what to do.
    """
    from ..relocation.registry import RELOCATIONS

    for relocation in RELOCATIONS.values():
        for own in relocation.declared_options():
            if own.name in OPTIONS._declared:  # noqa: SLF001
                raise TypeError(f"relocation {relocation.name!r} declares a run option {own.name!r}, which is an option "
                                f"of compare already; list it in its options to be handed the run's value, or give "
                                "its own option another name")


# ---------------------------------------------------------------------- rules
def _levels_fit(settings: Settings, grids: dict) -> None:
    from simplifiers import max_level

    for name, grid in grids.items():
        top = max_level(grid.shape)
        if top == 0:
            raise ValueError(f"terrain {name!r} ({grid.shape[0]}x{grid.shape[1]}) is too small to simplify: each level "
                             "needs at least 3 samples per axis")
        if settings.levels and max(settings.levels) > top:
            raise ValueError(
                f"levels must be at most {top} for terrain {name!r} ({grid.shape[0]}x{grid.shape[1]}: each "
                f"level needs at least 3 samples per axis), got {max(settings.levels)}"
            )


def _engine_runs_on_every_surface(settings: Settings, grids: dict) -> None:
    """A named engine answers on T (a grid), on every method's result, and under the run's curvature."""
    from simplifiers import METHODS

    from ..visibility.engines import AUTO, ENGINES

    if settings.engine == AUTO:
        return
    engine = ENGINES[settings.engine]
    if "grid" not in engine.terrains:
        raise ValueError(f"engine {settings.engine!r} does not run on grids, and the verdicts on each terrain T are "
                         "computed on its grid; use engine='auto'")
    if "tin" not in engine.terrains:
        tins = [m for m in settings.methods if not METHODS[m].regular]
        if tins:
            raise ValueError(
                f"engine {settings.engine!r} works on grids only, but methods {tins} produce TINs; use engine='auto' "
                "(the grid engine on grids, Embree on TINs) or leave those methods out"
            )
    if settings.curvature != 0.0 and not engine.curvature:
        raise ValueError(f"engine {settings.engine!r} cannot model earth curvature, and curvature is "
                         f"{settings.curvature:g}; use engine='auto' (exact on grids and TINs) or curvature=0")


def _measure_supports_the_predicate(settings: Settings, grids: dict) -> None:
    from .measures import MEASURES

    supported = MEASURES[settings.measure].predicates
    if settings.predicate not in supported:
        raise ValueError(f"measure {settings.measure!r} supports predicate {' and '.join(map(repr, supported))} only, "
                         f"got {settings.predicate!r}")


def _heights_resolve_on_every_terrain(settings: Settings, grids: dict) -> None:
    """``offset`` and ``target_height`` within what float64 resolves against each terrain (else every unit fails)."""
    from ..core.validate import as_height
    from ..visibility import terrain_scale

    for name, grid in grids.items():
        z = grid.z[np.isfinite(grid.z)]
        ground = float(np.abs(z).max()) if z.size else 0.0
        for option in ("offset", "target_height"):
            try:
                as_height(getattr(settings, option), option, scale=terrain_scale(grid), ground=ground, minimum=0.0)
            except ValueError as exc:
                raise ValueError(f"{exc} (terrain {name!r})") from None


def _relocations_serve_the_measure(settings: Settings, grids: dict) -> None:
    from ..relocation.registry import RELOCATIONS

    for name in settings.relocations:
        if RELOCATIONS[name].measures is not None and settings.measure not in RELOCATIONS[name].measures:
            raise ValueError(f"measure {settings.measure!r} does not support the {name!r} relocation (it serves "
                             f"the measure(s) {list(RELOCATIONS[name].measures)})")


def _siting_fits_the_candidates(settings: Settings, grids: dict) -> None:
    """``siting`` k at most the siting's candidates on every terrain (``terrainvis site -k`` refuses more;
    the measure chose all of them without a word)."""
    if settings.measure != "viewshed" or not settings.siting:
        return
    from .measures import siting_candidates

    for name, grid in grids.items():
        n = siting_candidates(grid).shape[0]
        if settings.siting > n:
            raise ValueError(f"siting must be at most the siting candidates of terrain {name!r}, {n} (a lattice of "
                             f"its samples), got {settings.siting}")


def _budgets_do_not_cascade(settings: Settings, grids: dict) -> None:
    """``cascade=True`` chains levels, finest first; a budget run has none: each budget is simplified from T."""
    if settings.max_errors is not None and settings.cascade is True:
        raise ValueError("cascade=True (--cascade) chains the levels of a run, and max_errors (--max-error) runs "
                         "budgets in place of levels, each simplified from the terrain itself; leave cascade at 'auto' "
                         "(or False) with max_errors")


#: Checks across options (and the terrains), run after every option's own check:
#: ``rule(settings, grids)`` raises a ValueError naming the options involved.
RULES: list[Callable] = [_engine_runs_on_every_surface, _measure_supports_the_predicate, _relocations_serve_the_measure,
                         _heights_resolve_on_every_terrain, _levels_fit, _siting_fits_the_candidates,
                         _budgets_do_not_cascade]


# ---------------------------------------------------------------------- settings
class Settings:
    """Everything that determines the rows of a :func:`~terrainvis.compare` run: a value per option.

    ``Settings(n_points=20)`` holds the given values; an option not given reads as its
    default (:data:`OPTIONS`), so :data:`DEFAULTS` (``Settings()``) is the defaults of
    :func:`~terrainvis.compare` and of ``terrainvis compare``. Immutable: :meth:`replace`
    returns a changed copy. Values are kept as given; :func:`validate` makes validated ones.

    Examples
    --------
    >>> s = Settings(n_points=20)
    >>> s.n_points, s.n_sets, s.replace(n_sets=2).n_sets
    (20, 6, 2)
    """

    __slots__ = ("_values",)

    def __init__(self, **values):
        unknown = [k for k in values if k not in OPTIONS]
        if unknown:
            raise TypeError(f"Settings got unknown option(s) {unknown}; the options are {list(OPTIONS)}")
        object.__setattr__(self, "_values", dict(values))

    def __getattr__(self, name: str):
        if name.startswith("__"):
            raise AttributeError(name)
        values = object.__getattribute__(self, "_values")
        if name in values:
            return values[name]
        if name in OPTIONS:
            return OPTIONS[name].default
        raise AttributeError(f"Settings has no option {name!r}; the options are {list(OPTIONS)}")

    def __setattr__(self, name, value):
        raise AttributeError(f"Settings are immutable; use .replace({name}=...)")

    def __reduce__(self):  # pickled to workers as its values, whatever options they declare
        return (_restore, (dict(self._values),))

    def replace(self, **changes) -> Settings:
        """A copy with ``changes``."""
        return Settings(**{**self._values, **changes})

    def as_dict(self) -> dict:
        """Every option's value (given or default), in :data:`OPTIONS` order."""
        return {name: getattr(self, name) for name in OPTIONS}

    def __eq__(self, other):
        return isinstance(other, Settings) and self.as_dict() == other.as_dict()

    def __hash__(self):
        return hash(tuple(sorted((k, repr(v)) for k, v in self.as_dict().items())))

    def __repr__(self):
        return "Settings(" + ", ".join(f"{k}={v!r}" for k, v in self.as_dict().items()) + ")"


def _restore(values: dict) -> Settings:
    s = Settings.__new__(Settings)
    object.__setattr__(s, "_values", values)
    return s


#: The defaults of :func:`terrainvis.compare` and ``terrainvis compare``.
DEFAULTS = Settings()


def validate(grids: dict, values: dict, *, caller: str = "compare()", flags: bool = False) -> Settings:
    """``values`` (option name -> value; missing ones take their defaults) checked into :class:`Settings`.

    Every option's own check runs first, in :data:`OPTIONS` order, then the :data:`RULES`.
    With ``flags`` (the command line), a message names the option's flag (``--points``),
    not its Python keyword (``n_points``).

    Raises
    ------
    TypeError
        An unknown option (the message lists the known ones), or a value of the wrong type.
    ValueError
        A value out of range, or options that do not go together.
    """
    check_relocation_options()
    unknown = [k for k in values if k not in OPTIONS]
    if unknown:
        raise TypeError(f"{caller} got unexpected option(s) {unknown}; the options are {list(OPTIONS)}")
    label = {name: option.flag if flags and option.flag else name for name, option in OPTIONS.items()}
    budgets = values.get("max_errors") is not None
    if budgets and "levels" in values:
        raise ValueError(f"{label['levels']} and {label['max_errors']} cannot be given together: "
                         f"{label['max_errors']} runs budgets in maximum vertical error in place of levels; "
                         "give one of them")
    checked = {}
    for name, option in OPTIONS.items():
        checked[name] = option.check(values.get(name, option.default), label[name])
    if budgets:
        checked["levels"] = ()  # a run by budgets has no levels (the stored settings say so)
    settings = Settings(**checked)
    for rule in RULES:
        rule(settings, grids)
    sight(settings)  # the run's Sight, made once here: every unit makes the same
    return settings


def budgeted(settings: Settings) -> bool:
    """Whether the run is budgeted in maximum vertical error (``max_errors``) rather than by levels."""
    return settings.max_errors is not None


def steps(settings: Settings) -> tuple:
    """What each unit of a terrain and method is run at: the budgets (``max_errors``) or the levels."""
    return tuple(settings.max_errors) if budgeted(settings) else tuple(settings.levels)


def sight(settings: Settings):
    """The sight lines of every visibility computation of the run: a
    :class:`~terrainvis.visibility.Sight` of its options declared ``los=True`` (the engine,
    the earth's curvature and radius) and its ``target_height``, with no field of view; the
    pair measure sets the end radius of its verdicts on S(T), the viewshed measure the eye's
    height (``offset``)."""
    import dataclasses

    from ..visibility import Sight

    fields = {name: getattr(settings, name) for name, option in OPTIONS.items() if option.los}
    other = sorted(set(fields) - {f.name for f in dataclasses.fields(Sight)} | ({"target_height"} & set(fields)))
    if other:
        raise TypeError(f"the options declared los=True must be fields of a terrainvis.visibility.Sight, got "
                        f"{sorted(fields)}: {other} {'is not one' if len(other) == 1 else 'are not'} (the Sight "
                        "holds engine, curvature, earth_radius, and the run's target_height)")
    return Sight(target_height=settings.target_height, **fields)


# ---------------------------------------------------------------------- the signature and docstring
def signature_parameters() -> list[inspect.Parameter]:
    """The options as keyword-only parameters, with their defaults (for ``compare.__signature__``)."""
    return [inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=o.default)
            for name, o in OPTIONS.items()]


def docstring_section(indent: str = "    ") -> str:
    """The options as a numpydoc "Parameters" block (for ``compare.__doc__``)."""
    import textwrap

    lines = []
    for name, o in OPTIONS.items():
        lines.append(f"{indent}{name} : {o.type}, default {o.documented_default()}")
        text = o.help[0].upper() + o.help[1:] + o.scope() + "."
        if o.doc:
            text += " " + o.doc
        lines += textwrap.wrap(text, width=88, initial_indent=indent * 2, subsequent_indent=indent * 2)
    return "\n".join(lines)


# ---------------------------------------------------------------------- the command line
def add_flags(parser: argparse.ArgumentParser, *, exclude=()) -> None:
    """Add every option's flag (but those named in ``exclude``) to a command's parser.

    ``terrainvis compare`` takes them all; ``terrainvis evaluate`` all but the methods,
    levels and cascading. A flag not given leaves no attribute on the parsed namespace
    (``argparse.SUPPRESS``), so :func:`given` returns only what the user typed, and
    everything else takes the option's default in :func:`validate`.
    """
    for option in OPTIONS.values():
        if option.name not in exclude:
            add_flag(parser, option)


def given(args: argparse.Namespace) -> dict:
    """The options the user gave on the command line (name -> value)."""
    return {name: getattr(args, name) for name in OPTIONS if hasattr(args, name)}
