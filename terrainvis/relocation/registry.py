"""The relocations: every fact about each in one declaration, and :func:`relocate`.

Points sampled on the original terrain T do not, in general, lie on its simplification
S(T); a *relocation* places them there before their visibility is tested. Each one is a
:class:`Relocation` in :data:`RELOCATIONS`, the one place the rest of terrainvis reads:
:func:`relocate` dispatches on it and checks its options, :func:`terrainvis.compare` runs
the default ones and hands each the options it declares, the tables and figures take
its order and style from it, and the command line's ``--relocations`` and ``--how`` list
it. Adding a relocation is one :func:`register` call (or one entry here) and its own
function. An entry declares, besides its function and style, its own options of a run
(:attr:`Relocation.run_options`: :class:`~terrainvis.core.option.Option` records, which
:func:`terrainvis.compare` takes as keywords, validates, stores with the run and hands to
it, and ``terrainvis compare`` and ``terrainvis relocate`` offer as flags) and what it
cannot run without (:attr:`Relocation.needs`: T, or T's verdicts of the pairs), so that
no other module knows a relocation by name.

The built-in ones:

``"identity"``, ``"full"``, ``"half"``
    The paper's three (:mod:`terrainvis.relocation.paper`).
``"calibrated"``
    Each point takes the height on S(T) whose verdicts agree best with its verdicts on T,
    against partners spread over the terrain that stand for the points it will be tested
    with (never the other points themselves): :mod:`terrainvis.relocation.calibrated`.
    It needs T (``original=``). Its own options of a run, the partners and the neighbours,
    are declared in its module (:data:`terrainvis.relocation.calibrated.RUN_OPTIONS`).
``"eye"``
    The calibrated relocation without T: each point at S(T) plus the offset an *eye
    surface* (fitted once from T and S(T), shipped with S(T)) gives there
    (:mod:`terrainvis.relocation.eye`). It needs ``eye=`` (or ``original=``, T, to fit one
    once per S(T), as :func:`terrainvis.compare` does). Not in the default set.
``"oracle"`` (a bound, not a practical relocation)
    Coordinate descent of the points' heights on the agreement of their own pairs with
    T's verdicts (:mod:`terrainvis.relocation.oracle`): it needs those verdicts
    (``reference=``), which a practical relocation does not have, so it estimates how much
    any relocation of the points alone could recover.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..core.option import Option
from ..core.registry import Registry
from ..core.terrain import as_terrain
from ..core.validate import as_finite_scalar, as_points, describe

__all__ = [
    "Relocation", "RELOCATIONS", "register", "unregister", "available", "default_relocations",
    "practical_relocations", "relocate", "run_options", "PAPER_RELOCATIONS", "CALIBRATED", "EYE", "ORACLE",
]

#: What a relocation may need besides the points, S(T) and the offset (:attr:`Relocation.needs`):
#: T itself, or T's verdicts of the evaluated pairs (a bound's).
NEEDS = ("original", "reference")

#: The paper's relocations, in the paper's order.
PAPER_RELOCATIONS = ("identity", "full", "half")
#: The calibrated relocation's name.
CALIBRATED = "calibrated"
#: The eye surface's relocation's name (not a default: the golden tables stay the paper's and the calibrated).
EYE = "eye"
#: The oracle bound's name.
ORACLE = "oracle"


@dataclass(frozen=True)
class Relocation:
    """Every fact about one relocation.

    Parameters
    ----------
    name : str
        How users name it (``relocate(P, S, name)``, ``--relocations name``).
    function : callable
        ``function(points, simplified, *, offset, **options) -> (n, 3) float64``: a new
        array with x and y unchanged. ``points`` arrive checked as an (n, 3) float64 array
        and ``simplified`` as a HeightGrid or TIN; ``offset`` is the observer height the
        points carry above their ground point.
    summary : str
        One line for ``--help`` and the docs.
    options : tuple of str
        The keyword options ``function`` takes besides ``offset``. :func:`terrainvis.compare`
        hands it those it knows from the run (``original``, ``end_radius``, ``seed``,
        ``target_height``, the run options of the relocations, ``sight`` for one declared
        :attr:`predicate` and, for a bound, ``reference``, ``mask``, ``start``);
        :func:`relocate` passes on those the caller gives. The names of its
        :attr:`run_options` are added when they are not listed, and ``sight`` for a
        :attr:`predicate` one.
    run_options : tuple of Option, or callable
        Its own options of a run, each a :class:`terrainvis.core.option.Option` (name,
        default, check, help, command-line flag): :func:`terrainvis.compare` takes each as a
        keyword, validates it before any unit runs, stores it in the run's settings (a
        resume with another value is refused, naming it) and hands it to this relocation;
        ``terrainvis compare`` and ``terrainvis relocate`` get its flag; :func:`relocate`
        runs its check on a value given. Several relocations may declare the same option
        (the very same declaration). A callable returning the tuple is read when first
        needed (a built-in relocation whose module is slow to import declares its options
        in that module); its names must then be in ``options``.
    needs : tuple of str
        What it cannot run without besides the points and S(T): ``"original"`` (T itself)
        or ``"reference"`` (T's verdicts of the evaluated pairs, as a bound needs them).
        :mod:`terrainvis.testing` and ``terrainvis relocate`` give T to a relocation that
        needs it and do not offer one that needs the reference.
    default : bool
        In :func:`terrainvis.compare`'s default relocations.
    bound : bool
        Not a practical relocation but a bound fitted to T's verdicts of the evaluated
        pairs (``reference``): a comparison runs it for each distance mask, after the
        practical relocations, and the reports never count it as one of them.
    measures : tuple of str, optional
        The measures of :func:`terrainvis.compare` it serves (``"pairs"``, ``"viewshed"``,
        ...); None (the default) is every measure.
    starts_from : tuple of str
        A bound's starts: the heights of the first of these relocations the run computed
        are passed as ``start=``.
    predicate : bool
        It evaluates visibility itself: :func:`terrainvis.compare` hands it ``sight=``, the
        :class:`~terrainvis.visibility.Sight` of the verdicts on S(T) (the run's engine,
        curvature and earth radius, and the unit's end radius), in place of those four
        keywords (``sight`` is added to its :attr:`options`, so its function takes it);
        :func:`relocate` passes it on when the caller gives it.
    memory : callable, optional
        ``memory(settings) -> (bytes, what)``: a lower bound of what it allocates in one
        unit of :func:`terrainvis.compare` beyond the measure's own, from the run's
        :class:`~terrainvis.experiment.options.Settings`, and the option that sets it, as a
        message names it (``"n_partners=2,048 (the calibrated relocation's partners)"``).
        The run is refused before it starts when the units could not fit
        (:func:`terrainvis.experiment.plan.check_memory`). None: nothing beyond the measure's.
    tables : callable, optional
        ``tables(accuracy) -> dict``: report tables of its own (key -> DataFrame with a
        ``"title"`` in its ``attrs``), which ``terrainvis compare`` prints and writes to
        ``tables.md`` after the measure's when the run has its rows
        (:func:`terrainvis.experiment.report.relocation_tables`). ``accuracy`` is the mean
        accuracy (%) of every relocation of the run, a column each, per method and level
        (its index: method and level, or method and ``max_error_budget``); each table is on
        that index (the report orders its rows). A measure's table that reports this
        relocation already names it in its ``attrs["covers"]``, and these are then left
        out. None: no table of its own.
    color, marker, linestyle : str
        Its style in the figures (matplotlib names).
    """

    name: str
    function: Callable
    summary: str
    options: tuple = ()
    run_options: tuple | Callable = ()
    needs: tuple = ()
    default: bool = False
    bound: bool = False
    measures: tuple | None = None
    starts_from: tuple = ()
    predicate: bool = False
    memory: Callable | None = None
    tables: Callable | None = None
    color: str = "black"
    marker: str = "o"
    linestyle: str = "-"

    def __post_init__(self):
        if self.predicate and "sight" not in self.options:  # compare hands it the Sight of its verdicts
            object.__setattr__(self, "options", tuple(self.options) + ("sight",))
        if isinstance(self.run_options, list):
            object.__setattr__(self, "run_options", tuple(self.run_options))
        if isinstance(self.run_options, tuple):
            own = tuple(o.name for o in self.run_options if isinstance(o, Option) and o.name not in self.options)
            if own:
                object.__setattr__(self, "options", tuple(self.options) + own)

    def declared_options(self) -> tuple:
        """Its :attr:`run_options` (read from their module when declared by a callable)."""
        return tuple(self.run_options() if callable(self.run_options) else self.run_options)

    def keywords(self, available: dict, sight=None) -> dict:
        """What this relocation takes of ``available`` (name -> value): ``offset`` and its
        options; with :attr:`predicate`, ``sight`` (a :class:`~terrainvis.visibility.Sight`,
        the predicate of its verdicts) in place of the keywords it holds."""
        out = {k: v for k, v in available.items() if k == "offset" or k in self.options}
        if self.predicate and sight is not None:
            from ..visibility.sight import PAIR_KEYWORDS  # the predicate's keywords, which the Sight holds

            for name in PAIR_KEYWORDS:
                out.pop(name, None)
            out["sight"] = sight
        return out


def _paper(name):
    from . import paper

    return getattr(paper, name)


def _calibrated(points, simplified, **options):
    from .calibrated import relocate_calibrated

    return relocate_calibrated(points, simplified, **options)


def _calibrated_memory(settings) -> tuple[int, str]:
    from .calibrated import memory_need

    return (memory_need(settings.n_partners, settings.n_points),
            f"n_partners={settings.n_partners:,} (the calibrated relocation's partners)")


def _eye(points, simplified, **options):
    from .eye import relocate_eye

    return relocate_eye(points, simplified, **options)


def _eye_memory(settings) -> tuple[int, str]:
    from .calibrated import memory_need
    from .eye import MAX_NODES

    return (memory_need(settings.n_partners, MAX_NODES),
            f"n_partners={settings.n_partners:,} (the eye surface's fit, a calibrated relocation of its lattice)")


def _calibrated_run_options() -> tuple:
    from .calibrated import RUN_OPTIONS

    return RUN_OPTIONS


def _oracle(points, simplified, **options):
    from .oracle import oracle

    return oracle(points, simplified, **options)


def _oracle_tables(accuracy) -> dict:
    from .oracle import gap_table

    return {"oracle": gap_table(accuracy, [r for r in practical_relocations() if r in accuracy.columns])}


_CALIBRATED_OPTIONS = ("original", "target_height", "end_radius", "curvature", "earth_radius", "n_partners", "sweeps",
                       "seed", "min_gain", "neighbours", "sight")
_EYE_OPTIONS = ("eye",) + _CALIBRATED_OPTIONS
_ORACLE_OPTIONS = ("reference", "mask", "original", "end_radius", "engine", "n_candidates", "start", "curvature",
                   "earth_radius", "sight")

#: Every relocation by name, in the order of the tables and figures.
RELOCATIONS: Registry = Registry("relocation", {
    r.name: r for r in (
        Relocation("identity", _paper("identity"), "the points do not move", default=True, color="tab:red",
                   marker="o"),
        Relocation("full", _paper("full"), "every point moved vertically onto S(T)", default=True, color="tab:blue",
                   marker="s"),
        Relocation("half", _paper("half"), "points below S(T) moved up onto it, the others kept", default=True,
                   color="tab:green", marker="^"),
        Relocation(CALIBRATED, _calibrated, "the height on S(T) that keeps the most verdicts against partners "
                   "spread over T", options=_CALIBRATED_OPTIONS, run_options=_calibrated_run_options,
                   needs=("original",), default=True, predicate=True, memory=_calibrated_memory, color="tab:purple",
                   marker="D"),
        # the eye surface is fitted by a calibrated relocation of its lattice: the same run options
        Relocation(EYE, _eye, "the calibrated height from an eye surface shipped with S(T), without T",
                   options=_EYE_OPTIONS, run_options=_calibrated_run_options, needs=("original",), predicate=True,
                   memory=_eye_memory, color="tab:orange", marker="v"),
        Relocation(ORACLE, _oracle, "an upper bound fitted to T's verdicts of the evaluated pairs",
                   options=_ORACLE_OPTIONS, needs=("reference",), bound=True, measures=("pairs",),
                   starts_from=(CALIBRATED,), predicate=True, tables=_oracle_tables, color="black", marker="*",
                   linestyle="--"),
    )
})
#: The relocations terrainvis ships, which :func:`register` never replaces.
BUILTIN = RELOCATIONS.builtin


def register(relocation: Relocation, *, replace: bool = False) -> Relocation:
    """Add a relocation to :data:`RELOCATIONS` (after the others) and return it.

    Parameters
    ----------
    relocation : Relocation
    replace : bool
        Replace a relocation registered earlier under the same name (never a built-in one).

    Raises
    ------
    TypeError
        ``relocation`` is not a :class:`Relocation`, or its function is not callable.
    ValueError
        Its name is empty or already taken (a built-in name always is), its measures are
        not names, or a start is unknown.

    Examples
    --------
    >>> import numpy as np
    >>> from terrainvis import HeightGrid, relocate
    >>> def raised(points, simplified, *, offset=0.0, by=1.0):
    ...     out = relocate(points, simplified, "full", offset=offset)
    ...     out[:, 2] += by
    ...     return out
    >>> r = register(Relocation("raised", raised, "full projection, 1 m higher", options=("by",)))
    >>> S = HeightGrid(np.full((2, 2), 10.0))
    >>> relocate(np.array([[0.5, 0.5, 3.0]]), S, "raised", by=2.0)[:, 2].tolist()
    [12.0]
    >>> _ = unregister("raised")
    """
    if not isinstance(relocation, Relocation):
        raise TypeError(f"relocation must be a terrainvis.relocation.Relocation, got {describe(relocation)}")
    name = RELOCATIONS.check_new(relocation.name, replace=replace)
    if not callable(relocation.function):
        raise TypeError(f"relocation {name!r}: function must be callable, got {describe(relocation.function)}")
    measures = relocation.measures
    if measures is not None and (not isinstance(measures, tuple) or not measures
                                 or not all(isinstance(m, str) and m for m in measures)):
        raise ValueError(f"relocation {name!r}: measures must be None (every measure) or a non-empty tuple of "
                         f"measure names, got {measures!r}")
    for start in relocation.starts_from:
        if start not in RELOCATIONS and start != name:
            raise ValueError(f"relocation {name!r}: starts_from names {start!r}, which is not registered")
    for field in ("memory", "tables"):
        if getattr(relocation, field) is not None and not callable(getattr(relocation, field)):
            raise TypeError(f"relocation {name!r}: {field} must be callable or None, got "
                            f"{describe(getattr(relocation, field))}")
    if not isinstance(relocation.needs, tuple) or any(n not in NEEDS for n in relocation.needs):
        raise ValueError(f"relocation {name!r}: needs must be a tuple of {list(NEEDS)}, got {relocation.needs!r}")
    _check_run_options(relocation)
    _check_signature(relocation)
    RELOCATIONS[name] = relocation
    return relocation


def _check_run_options(relocation: Relocation) -> None:
    """Its run options are Options of names it takes, each the same declaration as another relocation's of that name."""
    name = relocation.name
    if not isinstance(relocation.run_options, tuple) and not callable(relocation.run_options):
        raise TypeError(f"relocation {name!r}: run_options must be a tuple of terrainvis.core.option.Option, got "
                        f"{describe(relocation.run_options)}")
    others = {o.name: (r.name, o) for r in RELOCATIONS.values() if r.name != name for o in r.declared_options()}
    for own in relocation.declared_options():
        if not isinstance(own, Option):
            raise TypeError(f"relocation {name!r}: each of run_options must be a terrainvis.core.option.Option, got "
                            f"{describe(own)}")
        if not isinstance(own.name, str) or not own.name.isidentifier() or own.name == "offset":
            raise ValueError(f"relocation {name!r}: a run option's name must be a Python keyword other than offset, "
                             f"got {own.name!r}")
        if own.name not in relocation.options:
            raise ValueError(f"relocation {name!r}: its run option {own.name!r} is not among its options "
                             f"{list(relocation.options)}")
        if own.name in others and others[own.name][1] != own:
            raise ValueError(f"relocation {name!r}: its run option {own.name!r} is declared otherwise by the "
                             f"{others[own.name][0]!r} relocation; declare it with the same Option, or name it "
                             "otherwise")


def _check_signature(relocation: Relocation) -> None:
    """The function takes (points, simplified, *, offset, <its options>), or says which is missing."""
    try:
        sig = inspect.signature(relocation.function)
    except (TypeError, ValueError):  # a builtin or a C function: nothing to check
        return
    params = sig.parameters
    if any(p.kind == p.VAR_KEYWORD for p in params.values()):
        return
    missing = [k for k in ("offset",) + tuple(relocation.options) if k not in params]
    if missing:
        raise TypeError(f"relocation {relocation.name!r}: its function takes no keyword "
                        f"{', '.join(repr(k) for k in missing)}; it must accept offset= and every name in options")


def unregister(name: str) -> Relocation:
    """Remove a relocation added with :func:`register` and return it (built-in ones stay)."""
    return RELOCATIONS.remove(name)


def available() -> list[str]:
    """Every relocation's name, practical ones and bounds, in registry order."""
    return RELOCATIONS.names()


def default_relocations() -> tuple:
    """The relocations a comparison runs by default (those declared ``default=True``)."""
    return tuple(name for name, r in RELOCATIONS.items() if r.default)


def practical_relocations() -> tuple:
    """The relocations that are not bounds, in registry order."""
    return tuple(name for name, r in RELOCATIONS.items() if not r.bound)


def run_options(names=None) -> tuple:
    """The run options the relocations declare (:attr:`Relocation.run_options`): of those
    ``names`` (default every registered relocation), each name once, in registry order."""
    chosen = RELOCATIONS.values() if names is None else [RELOCATIONS[n] for n in names]
    out = {}
    for relocation in chosen:
        for own in relocation.declared_options():
            out.setdefault(own.name, own)
    return tuple(out.values())


def relocate(points, simplified, how: str, *, offset: float = 0.0, **options) -> np.ndarray:
    """Place points on a simplified terrain.

    Parameters
    ----------
    points : (n, 3) array_like
        Points on (or ``offset`` above) the original terrain. Never modified.
    simplified : HeightGrid or TIN
        The simplified terrain.
    how : str
        A relocation of :data:`RELOCATIONS`: ``"identity"``, ``"full"``, ``"half"``
        (the paper's: :mod:`terrainvis.relocation.paper`), ``"calibrated"``
        (:func:`terrainvis.relocation.calibrated.relocate_calibrated`), ``"oracle"`` (the
        bound: :func:`terrainvis.relocation.oracle.oracle`) or one registered with
        :func:`register`.
    offset : float
        The observer height that ``points`` carry above their ground point.
    **options
        The relocation's own options (its :attr:`Relocation.options`), e.g. for
        ``"calibrated"``: ``original`` (T, required), ``target_height``, ``end_radius``,
        ``curvature``, ``earth_radius``, ``n_partners``, ``sweeps``, ``seed``,
        ``min_gain``, ``neighbours``; for ``"eye"``: ``eye`` (an
        :class:`~terrainvis.relocation.eye.EyeSurface`), or ``original`` and the
        calibrated relocation's options to fit one; for ``"oracle"``: ``reference`` (required),
        ``mask``, ``original``, ``end_radius``, ``engine``, ``n_candidates``, ``start``.
        An option that another relocation takes but this one does not is ignored, so one
        set of options can serve a loop over relocations; a name no relocation takes is
        refused.

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
    if not isinstance(how, str) or how not in RELOCATIONS:
        raise ValueError(f"how must be one of {available()}, got {how!r}")
    relocation = RELOCATIONS[how]
    off = as_finite_scalar(offset, "offset")
    known = {k for r in RELOCATIONS.values() for k in r.options}
    unknown = sorted(k for k in options if k not in known)
    if unknown:
        raise TypeError(f"relocate got unknown option(s) {unknown}; {how!r} takes "
                        f"{sorted(relocation.options) or 'no options'} besides offset")
    for own in relocation.declared_options():  # its run options, checked as compare checks them
        if own.name in options:
            options[own.name] = own.check(options[own.name], own.name)
    out = relocation.function(pts, simplified, **relocation.keywords({**options, "offset": off}))
    out = np.asarray(out, dtype=np.float64)
    if out.shape != pts.shape:
        raise ValueError(f"relocation {how!r} returned {describe(out)}; it must return the points' shape "
                         f"{pts.shape}")
    if not np.array_equal(out[:, :2], pts[:, :2]):
        raise ValueError(f"relocation {how!r} moved points horizontally; a relocation changes heights only")
    return out
