"""Input validation shared by the public functions (kernels never validate)."""

from __future__ import annotations

import re

import numpy as np

from ..tolerances import CLEARANCE_REL

#: What an entry's name may be (a method, relocation, engine or measure): it becomes a
#: file name component (``simplified/<terrain>__<method>__level<k>.npz``), a CSV cell, a
#: Markdown table cell and a command-line word, so it starts with a letter or digit and
#: holds only letters, digits and ``_ . + -`` (no path separator, space, ``|`` or newline).
ENTRY_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]{0,63}")


def file_label(text: str) -> str:
    """A name made from a file name, as text every output can hold.

    A file name that is not valid UTF-8 arrives with surrogate escapes (``\\udcff`` for the
    byte 0xff), which no UTF-8 file, CSV or figure can store. Its bytes become ``\\xff``
    escapes instead: ``dem_\\xff``, readable and the same every run.

    >>> file_label("hills")
    'hills'
    >>> import os
    >>> file_label(os.fsdecode(b"dem_\\xff"))
    'dem_\\\\xff'
    """
    return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")


def entry_name(value, what: str) -> str:
    """``value`` if it is a valid name for a registry entry (:data:`ENTRY_NAME`), else a ValueError.

    ``what`` names the entry in the message ("method", "relocation", ...).

    >>> entry_name("greedy-cuts", "method")
    'greedy-cuts'
    >>> entry_name("v2/../../escaped", "method")
    Traceback (most recent call last):
    ...
    ValueError: a method name must be 1-64 characters, a letter or digit first, then letters, digits, '_', '.', '+' or '-' (no path separator, space, '|' or newline), got 'v2/../../escaped'
    """
    if not isinstance(value, str) or ENTRY_NAME.fullmatch(value) is None:
        raise ValueError(f"a {what} name must be 1-64 characters, a letter or digit first, then letters, digits, "
                         f"'_', '.', '+' or '-' (no path separator, space, '|' or newline), got {value!r}")
    return value


def describe(value) -> str:
    """A short description of ``value`` for error messages."""
    if isinstance(value, np.ndarray):
        return f"array of shape {value.shape} and dtype {value.dtype}"
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{type(value).__name__} {text}"


def as_float_array(value, name: str) -> np.ndarray:
    """``value`` as a float64 ndarray (a new array when a conversion is needed)."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be numeric array-like, got {describe(value)}") from exc
    return arr


def as_finite_scalar(value, name: str) -> float:
    """``value`` as a float: a 0-d numeric array-like (a number, a numpy scalar) that is finite.

    Examples
    --------
    >>> as_finite_scalar(np.float32(1.5), "offset")
    1.5
    >>> as_finite_scalar([1.0, 2.0], "offset")
    Traceback (most recent call last):
    ...
    ValueError: offset must be a finite scalar, got list [1.0, 2.0]
    """
    arr = as_float_array(value, name)
    if arr.ndim != 0 or not np.isfinite(arr):
        raise ValueError(f"{name} must be a finite scalar, got {describe(value)}")
    return float(arr)


def as_points(value, name: str, dim: int, *, finite: bool = True) -> np.ndarray:
    """Validate an (m, dim) float array of points and return it as float64.

    A single point of shape (dim,) is not accepted: callers pass (m, dim) arrays, and
    being strict here avoids silently broadcasting a wrong shape.
    """
    arr = as_float_array(value, name)
    if arr.ndim != 2:
        raise ValueError(
            f"{name} must be a 2-D array of shape (m, {dim}), got {arr.ndim}-D with shape {arr.shape}"
        )
    if arr.shape[1] != dim:
        raise ValueError(f"{name} must have shape (m, {dim}), got shape {arr.shape}")
    if finite and arr.size and not np.isfinite(arr).all():
        bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
        raise ValueError(
            f"{name} must be finite, but {bad.size} row(s) hold NaN or inf "
            f"(first at index {int(bad[0])})"
        )
    return arr


def _real_number(value, name: str) -> float:
    """``float(value)`` for a real number (not a string, bytes or a bool), else a TypeError naming ``name``.

    The one parse behind :func:`as_positive_finite`, :func:`as_nonnegative_finite` and
    :func:`as_height`, which then check its range.
    """
    if isinstance(value, (str, bytes, bool, np.bool_)):
        raise TypeError(f"{name} must be a real number, got {describe(value)}")
    try:
        return float(value)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a real number, got {describe(value)}") from exc


def as_positive_finite(value, name: str) -> float:
    out = _real_number(value, name)
    if not np.isfinite(out) or out <= 0:
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return out


def as_nonnegative_finite(value, name: str, unit: str = "") -> float:
    """A finite real number >= 0 (``unit`` is named in the message, e.g. "z units")."""
    out = _real_number(value, name)
    if not np.isfinite(out) or out < 0:
        suffix = f" ({unit})" if unit else ""
        raise ValueError(f"{name} must be finite and >= 0{suffix}, got {value!r}")
    return out


def as_bool(value, name: str) -> bool:
    """True or False (numpy's bool too), or a TypeError naming ``name``."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {describe(value)}")
    return bool(value)


def as_int(value, name: str, *, minimum: int | None = None, maximum: int | None = None) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, got {describe(value)}")
    out = int(value)
    if minimum is not None and out < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {out}")
    if maximum is not None and out > maximum:
        raise ValueError(f"{name} must be <= {maximum}, got {out}")
    return out


def choice(value, name: str, valid) -> str:
    valid = list(valid)
    if value not in valid:
        raise ValueError(f"{name} must be one of {valid}, got {value!r}")
    return value


#: Relative rounding of float64: the spacing of float64 numbers near x is about ``2**-52 * |x|``.
FLOAT64_EPS = 2.0**-52


def height_limit(scale: float, ground: float = 0.0, tol_rel: float = CLEARANCE_REL) -> float:
    """The largest |height| (or offset) that float64 resolves against a terrain.

    The line-of-sight predicate accepts clearances down to ``-tol`` with ``tol = tol_rel *
    scale`` (``terrainvis.visibility.clearance_tolerance``:
    :data:`~terrainvis.tolerances.CLEARANCE_REL` times the larger of the extent's diagonal
    and the relief). An end of a segment at height ``H`` above the
    datum is known to ``2**-52 * |H|`` only, so once that exceeds ``tol`` the predicate
    decides on rounding noise. With ``|H| <= |h| + ground`` (``ground`` the largest |z|
    of the terrain), a height ``h`` is resolved while ``|h| <= tol / 2**-52 - ground``.

    Examples
    --------
    >>> round(height_limit(1000.0, 500.0) / 1e9, 3)  # a 1 km terrain: about 4.5e9
    4.504
    """
    return tol_rel * scale / FLOAT64_EPS - ground


def as_height(value, name: str, *, scale: float, ground: float = 0.0, tol_rel: float = CLEARANCE_REL,
              minimum: float | None = None) -> float:
    """``value`` as a finite float within what float64 resolves against a terrain (:func:`height_limit`).

    ``scale`` is the terrain's scale (``terrainvis.visibility.terrain_scale``), ``ground``
    its largest |z|; ``minimum`` an optional lower bound of the caller's own (e.g. 0).

    Examples
    --------
    >>> as_height(1.7, "observer_height", scale=1000.0)
    1.7
    >>> as_height(1e20, "observer_height", scale=1000.0)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: observer_height must be within [-4.5e+09, 4.5e+09] for this terrain (float64 resolves ...
    """
    out = _real_number(value, name)
    if not np.isfinite(out):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    limit = height_limit(scale, ground, tol_rel)
    if limit <= 0.0:  # the terrain itself, not the value: no height is resolved on it
        raise ValueError(
            f"{name}: the terrain's heights (up to |z| = {ground:.6g}) are known to 2^-52 of their size, "
            f"{ground * FLOAT64_EPS:.3g}, more than the line of sight's tolerance ({tol_rel:g} x its scale "
            f"{scale:.6g}): float64 cannot decide line of sight on it; check the DEM's vertical scale, units and "
            "nodata value"
        )
    low = -limit if minimum is None else max(-limit, minimum)
    if not low <= out <= limit:
        raise ValueError(
            f"{name} must be within [{low:.3g}, {limit:.3g}] for this terrain (float64 resolves heights to "
            f"2^-52 of their size, and line of sight compares them to {tol_rel:g} x the terrain's scale "
            f"{scale:.6g}), got {value!r}"
        )
    return out
