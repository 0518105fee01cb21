"""Text arrays and the JSON ``meta`` of a flight log: decoding, type checks and (de)serialisation.

``format`` and ``meta`` are stored as 0-d str arrays and ``copter_ids`` as a str array (N,), as the
spec says: bytes there are an error naming the array (a writer that stores bytes stores something else
than the spec's str, and decoding it silently would hide that); extras may hold UTF-8 bytes. ``meta`` is a JSON object
without NaN or infinities.
"""
from __future__ import annotations

import json
from typing import Any, Mapping

import numpy as np

from .format import FlightLogError
from .messages import shape_text

__all__ = ["as_text", "meta_to_json", "meta_from_json"]


def as_text(name: str, arr: Any, *, scalar: bool, bytes_ok: bool = False) -> Any:
    """A str (0-d) or str array from a unicode/bytes array; raise if it is not text.

    Args:
        name: the array's name for the error message.
        arr: a unicode or UTF-8 bytes array (any shape; 0-d when ``scalar``).
        scalar: return a Python ``str`` from a 0-d array (and reject any other shape).
        bytes_ok: decode a bytes array as UTF-8 (else bytes are an error: the spec's text arrays are str).

    Returns:
        a ``str`` when ``scalar``, else a unicode array of the same shape.
    """
    a = np.asarray(arr)
    if a.dtype.kind == "S" and not bytes_ok:
        raise FlightLogError(f"{name} has dtype {a.dtype} (bytes); expected str (np.str_, dtype '<U...'): "
                             f"write it as a str array, e.g. np.array(text) rather than np.array(text.encode())")
    if a.dtype.kind == "S":
        try:
            a = np.char.decode(a, "utf-8")
        except UnicodeDecodeError:
            raise FlightLogError(f"{name} holds bytes that are not UTF-8; expected str") from None
    if a.dtype.kind != "U":
        raise FlightLogError(f"{name} has dtype {a.dtype}; expected str")
    if scalar:
        if a.shape != ():
            raise FlightLogError(f"{name} has shape {shape_text(a.shape)}; expected a 0-d str array, shape ()")
        return str(a[()])
    return a


def _json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"{type(obj).__name__} is not JSON-serialisable")


def meta_to_json(meta: Any) -> str:
    """``meta`` (a dict with str keys; NumPy scalars allowed) as JSON text; raise if it is not one."""
    if not isinstance(meta, Mapping):
        raise FlightLogError(f"meta is a {type(meta).__name__}; expected a JSON object (a dict with str keys)")
    for k in meta:
        if not isinstance(k, str):
            raise FlightLogError(f"meta has key {k!r} ({type(k).__name__}); expected a JSON object with str keys")
    try:
        return json.dumps(dict(meta), allow_nan=False, default=_json_default)
    except (TypeError, ValueError) as exc:
        raise FlightLogError(f"meta is not valid JSON ({exc}); expected a JSON object of numbers, strings, lists and objects (no NaN)") from None


def meta_from_json(text: str) -> dict:
    """The dict stored as JSON ``text``; raise unless it is a JSON object (NaN and Infinity rejected)."""
    def bad_constant(c):
        raise ValueError(f"{c} is not valid JSON")

    try:
        meta = json.loads(text, parse_constant=bad_constant)
    except ValueError as exc:
        raise FlightLogError(f"meta is not valid JSON ({exc}); expected a JSON object") from None
    if not isinstance(meta, dict):
        raise FlightLogError(f"meta is JSON {type(meta).__name__} {text[:60]!r}; expected a JSON object {{...}}")
    return meta
