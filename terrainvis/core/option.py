"""One keyword option declared once: :class:`Option`, its flags, its usual checks.

An option of :func:`terrainvis.compare` is one :class:`Option`: its name, default,
check, help text and command-line flag (a :class:`Flag` or a :class:`Switch`). The
central ones are declared in :mod:`terrainvis.experiment.options`; a relocation declares
its own (:attr:`terrainvis.relocation.Relocation.run_options`) with the same record, which
lives here, below both, so that the relocation layer need not import the experiment.
:func:`add_flag` adds an option's flag to a command's parser (``terrainvis compare`` takes
every option's, ``terrainvis relocate`` those of the relocations).

The checks (:func:`integer`, :func:`finite`, :func:`height`, :func:`boolean`) are
values that pickle and compare equal when made alike, so that an option of a relocation
registered at run time reaches worker processes with its entry.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from .validate import as_bool, as_finite_scalar, as_int

__all__ = ["Option", "Flag", "Switch", "integer", "finite", "nonnegative", "height", "boolean", "add_flag"]


@dataclass(frozen=True)
class Flag:
    """A command-line flag that takes a value (``--points 20``) or several (``--levels 1 3``).

    ``spelling`` defaults to ``--`` and the option's name with dashes; ``type`` converts
    one word; ``choices`` (called when the parser is built) lists the valid words, which
    argparse then checks; ``listed`` (called then too) lists words the help names without
    argparse checking them (the option's own check has the better message).
    """

    spelling: str | None = None
    type: Callable[[str], Any] = str
    many: bool = False
    metavar: str | None = None
    choices: Callable[[], Sequence[str]] | None = None
    listed: Callable[[], Sequence[str]] | None = None


@dataclass(frozen=True)
class Switch:
    """Command-line flags without a value: ``on`` sets True, ``off`` sets False (either may be absent)."""

    on: str | None = None
    off: str | None = None
    on_help: str | None = None
    off_help: str | None = None


@dataclass(frozen=True)
class Option:
    """One option of :func:`terrainvis.compare`.

    Parameters
    ----------
    name : str
        The keyword of :func:`~terrainvis.compare`, the attribute of
        :class:`~terrainvis.experiment.options.Settings` and the key in the stored settings
        (and, for a relocation's own option, the keyword its function takes).
    default
        The value when the option is not given (also the command line's default).
    check : callable
        ``check(value, name) -> value``: the value validated and normalised (tuples for
        sequences), or a TypeError / ValueError naming ``name``, what was expected and
        what was received.
    help : str
        One line for ``--help`` and the first line of the option in ``help(compare)``.
    type : str
        The type as the docstring shows it (``"int"``, ``"sequence of str"``, ...).
    doc : str
        More for the docstring (optional).
    measures : tuple of str, optional
        The measures (:data:`terrainvis.experiment.measures.MEASURES`) the option applies
        to; None (the default) is every measure. The help says so when it is not every
        measure.
    cli : Flag, Switch or None
        How ``terrainvis compare`` spells it (None: the API only).
    los : bool
        The field of the same name of the run's :class:`~terrainvis.visibility.Sight`
        (``engine``, ``curvature``, ``earth_radius``), the one record handed to every
        visibility computation of a run (``visibility_matrix``, ``viewshed``, and
        ``relocate``, whose calibrated and oracle relocations compute visibility): an
        option such as the earth-curvature coefficient is then one entry and nothing else.
    default_text : str, optional
        How help texts show the default (when ``repr`` of it would not say it well).
    quick : optional
        The value ``terrainvis compare --quick`` gives it unless the flag is given (in the
        command line's form: a list for a flag of several values); None: its default.
    """

    name: str
    default: Any
    check: Callable[[Any, str], Any]
    help: str
    type: str
    doc: str = ""
    measures: tuple | None = None
    cli: Flag | Switch | None = Flag()
    los: bool = False
    default_text: str | None = None
    quick: Any = None

    @property
    def flag(self) -> str | None:
        """The option's command-line flag (a value flag's spelling, or a switch's first flag)."""
        if isinstance(self.cli, Switch):
            return self.cli.on or self.cli.off
        if isinstance(self.cli, Flag):
            return self.cli.spelling or "--" + self.name.replace("_", "-")
        return None

    def shown_default(self) -> str:
        """The default as the command line's help shows it."""
        if self.default_text is not None:
            return self.default_text
        value = self.default
        if isinstance(value, (tuple, list)):
            return " ".join(map(str, value))
        return f"{value:g}" if isinstance(value, float) else str(value)

    def documented_default(self) -> str:
        """The default as :func:`~terrainvis.compare`'s docstring shows it."""
        return f"{self.default!r}" + (f" ({self.default_text})" if self.default_text is not None else "")

    def scope(self) -> str:
        """``" (pairs only)"`` for an option of some measures only, else ``""``."""
        if self.measures is None:
            return ""
        return f" ({', '.join(self.measures)} only)"


# ---------------------------------------------------------------------- checks
@dataclass(frozen=True)
class _Integer:
    minimum: int | None = None

    def __call__(self, value, name: str) -> int:
        return as_int(value, name, minimum=self.minimum)


def integer(minimum: int | None = None) -> Callable[[Any, str], int]:
    """A check: an integer, at least ``minimum``."""
    return _Integer(minimum)


def finite(value, name: str) -> float:
    """A check: a finite real number (:func:`terrainvis.core.validate.as_finite_scalar`)."""
    return as_finite_scalar(value, name)


def nonnegative(value, name: str) -> float:
    """A check: a finite real number >= 0."""
    return _at_least_zero(value, name, "")


def height(value, name: str) -> float:
    """A check: a height above the surface, finite and >= 0 (a negative one would stand underground)."""
    return _at_least_zero(value, name, " (a height above the surface)")


def _at_least_zero(value, name: str, what: str) -> float:
    out = finite(value, name)
    if out < 0:
        raise ValueError(f"{name} must be >= 0{what}, got {out!r}")
    return out


def boolean(value, name: str) -> bool:
    """A check: True or False (numpy's bool too)."""
    return as_bool(value, name)


# ---------------------------------------------------------------------- the command line
def add_flag(parser, option: Option, *, before: str = "") -> None:
    """Add ``option``'s flag (nothing for ``cli=None``) to ``parser``, its help starting with ``before``.

    A flag not given leaves no attribute on the parsed namespace (``argparse.SUPPRESS``),
    so a command passes on exactly what the user typed, and everything else takes the
    option's default.
    """
    cli = option.cli
    if isinstance(cli, Switch):
        _add_switch(parser, option, cli, before)
    elif isinstance(cli, Flag):
        listed = f"; one of: {', '.join(cli.listed())}" if cli.listed is not None else ""
        kw = {"dest": option.name, "default": argparse.SUPPRESS, "type": cli.type,
              "help": f"{before}{option.help}{option.scope()} (default: {option.shown_default()}){listed}"}
        if cli.many:
            kw["nargs"] = "+"
        if cli.choices is not None:
            kw["choices"] = list(cli.choices())
        else:  # named after the flag, not the option (--points N, not N_POINTS)
            kw["metavar"] = cli.metavar or option.flag.lstrip("-").upper().replace("-", "_")
        parser.add_argument(option.flag, **kw)


def _add_switch(parser, option: Option, cli: Switch, before: str) -> None:
    target = parser.add_mutually_exclusive_group() if cli.on and cli.off else parser
    default = f" (default: {option.shown_default()})"
    if cli.on:
        target.add_argument(cli.on, dest=option.name, action="store_const", const=True, default=argparse.SUPPRESS,
                            help=before + (cli.on_help or option.help) + option.scope() + default)
    if cli.off:
        target.add_argument(cli.off, dest=option.name, action="store_const", const=False, default=argparse.SUPPRESS,
                            help=before + (cli.off_help or f"not: {option.help}") + option.scope())
