"""``attrs`` as JSON text, with tuples and numpy arrays kept exactly (see :mod:`terrainvis.io`)."""

from __future__ import annotations

import json
import warnings

import numpy as np

from ._common import _Corrupt

_TUPLE = "__tuple__"
_ARRAY = "__ndarray__"


class _Unencodable(Exception):
    pass


def _encode(value, where: str):
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, tuple):
        return {_TUPLE: [_encode(v, f"{where}[{i}]") for i, v in enumerate(value)]}
    if isinstance(value, list):
        return [_encode(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, dict):
        for k in value:
            if not isinstance(k, str):
                raise _Unencodable(f"{where} has a non-string key {k!r}")
        if _TUPLE in value or _ARRAY in value:
            raise _Unencodable(f"{where} uses a reserved key ({_TUPLE!r} or {_ARRAY!r})")
        return {k: _encode(v, f"{where}[{k!r}]") for k, v in value.items()}
    if isinstance(value, np.ndarray) and value.dtype.kind in "biufU":
        return {_ARRAY: value.tolist(), "dtype": value.dtype.str, "shape": list(value.shape)}
    raise _Unencodable(f"{where} is a {type(value).__name__}, which JSON cannot hold")


def _decode_object(obj: dict):
    if set(obj) == {_TUPLE}:
        return tuple(obj[_TUPLE])
    if set(obj) == {_ARRAY, "dtype", "shape"}:
        return np.array(obj[_ARRAY], dtype=np.dtype(obj["dtype"])).reshape(obj["shape"])
    return obj


def _attrs_to_json(attrs: dict) -> str:
    """``attrs`` (without ``path``) as JSON text; values JSON cannot hold are dropped with a warning."""
    out = {}
    for key, value in attrs.items():
        if key == "path":
            continue
        try:
            if not isinstance(key, str):
                raise _Unencodable(f"attrs key {key!r} is not a string")
            out[key] = _encode(value, f"attrs[{key!r}]")
        except _Unencodable as exc:
            warnings.warn(f"{exc}; it is not written to the file", UserWarning, stacklevel=4)
    return json.dumps(out, allow_nan=True)


def _attrs_from_json(text: str) -> dict:
    try:
        attrs = json.loads(text, object_hook=_decode_object)
    except (ValueError, TypeError) as exc:
        raise _Corrupt(f"its attrs are not valid JSON ({exc})") from None
    if not isinstance(attrs, dict):
        raise _Corrupt(f"its attrs must be a JSON object, got {type(attrs).__name__}")
    return attrs
