"""Input checks for the arrays handed to finkensim's public functions.

Each helper converts its input to the C-contiguous array the numba kernels expect (no copy when it
already is one) or raises a :class:`~finkensim.config.ConfigError` (a ``ValueError``) that names the
array, shows its shape or value, and says what was expected — instead of a numba typing error or a
bare NumPy traceback from deep inside a kernel call.

Shapes are described by tuples of dimensions: an ``int`` is an exact size, a ``str`` a named size
(``"B"``, ``"N"``: any size, but the same name must have the same size everywhere it appears, and the
size given for it in ``sizes``, if any), ``None`` any size. Example::

    pos = as_points("positions", positions, ("B", "N"))            # (B, N, 2) float64, finite
    env = as_env_ids("env_ids", env_ids, pos.shape[0])              # (B,) int64
    out = check_inplace("out", out, (B, N, N + M))                  # preallocated result
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence, Union

import numpy as np

from .config import ConfigError

__all__ = ["as_array", "as_env_ids", "as_points", "as_vectors", "check_inplace", "describe_shape"]

Dim = Union[int, str, None]


def describe_shape(shape: Sequence[Dim], sizes: Mapping[str, int] | None = None) -> str:
    """A shape description: ``(B, N, 2)``; with the sizes of the named dimensions known, ``(B, N, 2) = (4, 3, 2)``.

    ``None`` dimensions print as ``*``.
    """
    names = ["*" if d is None else str(d) for d in shape]
    text = "(" + ", ".join(names) + ("," if len(names) == 1 else "") + ")"
    if sizes and any(isinstance(d, str) and d in sizes for d in shape):
        known = [str(sizes[d]) if isinstance(d, str) and d in sizes else n for d, n in zip(shape, names)]
        text += " = (" + ", ".join(known) + ("," if len(known) == 1 else "") + ")"
    return text


def _unit(unit: str) -> str:
    return f" {unit}" if unit else ""


def _short(value: Any, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def as_array(name: str, value: Any, dtype=np.float64, shape: Sequence[Dim] | None = None, *,
             sizes: Mapping[str, int] | None = None, unit: str = "", finite: bool = False) -> np.ndarray:
    """``value`` as a C-contiguous array of ``dtype`` whose shape matches ``shape`` (``None``: any shape).

    ``sizes`` fixes named dimensions; ``unit`` is quoted in errors; ``finite=True`` rejects NaN and ±inf.
    For an integer ``dtype``, non-integral numbers are rejected rather than truncated.
    Raises :class:`~finkensim.config.ConfigError` naming ``name``.
    """
    dtype = np.dtype(dtype)
    expected = f"{describe_shape(shape, sizes)}{_unit(unit)}" if shape is not None else f"numbers{_unit(unit)}"
    try:
        raw = np.asarray(value)
        if raw.dtype.kind not in "biuf":
            raise TypeError(raw.dtype)
        if dtype.kind in "iu" and raw.dtype.kind == "f":
            if not np.all(np.isfinite(raw)) or np.any(raw != np.round(raw)):
                raise ConfigError(f"{name} = {_short(value)}: expected integers {expected}")
        a = np.ascontiguousarray(raw, dtype=dtype) if raw.ndim else raw.astype(dtype)  # keeps 0-d as 0-d
    except (TypeError, ValueError) as exc:
        if isinstance(exc, ConfigError):
            raise
        raise ConfigError(f"{name} = {_short(value)}: expected an array of numbers {expected}") from None
    if shape is not None:
        _check_shape(name, a, tuple(shape), dict(sizes or {}), unit)
    if finite and a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(a))[0])
        where = f"[{', '.join(map(str, bad))}]" if bad else ""
        raise ConfigError(f"{name}{where} = {a[bad].item()!r}: expected finite values{_unit(unit)}")
    return a


def _check_shape(name: str, a: np.ndarray, shape: tuple, sizes: dict, unit: str) -> None:
    ok = a.ndim == len(shape)
    bound = dict(sizes)
    if ok:
        for d, n in zip(shape, a.shape):
            if isinstance(d, str):
                if bound.setdefault(d, n) != n:
                    ok = False
            elif d is not None and d != n:
                ok = False
    if not ok:
        raise ConfigError(f"{name} has shape {a.shape}: expected {describe_shape(shape, sizes)}{_unit(unit)}")


def as_vectors(name: str, value: Any, dim: int, leading: Sequence[Dim] = ("N",), *,
               sizes: Mapping[str, int] | None = None, unit: str = "", allow_empty: bool = False) -> np.ndarray:
    """Finite float64 vectors of length ``dim``: shape (*leading, dim), C-contiguous.

    ``allow_empty=True`` with one leading dimension turns any empty input (``()``, ``[]``, ``None``)
    into an array of shape (0, dim).
    """
    if allow_empty and len(leading) == 1 and (value is None or np.size(value) == 0):
        return np.zeros((0, dim))
    return as_array(name, value, np.float64, tuple(leading) + (dim,), sizes=sizes, unit=unit, finite=True)


def as_points(name: str, value: Any, leading: Sequence[Dim] = ("N",), *, sizes: Mapping[str, int] | None = None,
              unit: str = "m", allow_empty: bool = False) -> np.ndarray:
    """Finite float64 (x, y) points in ``unit`` (default m): shape (*leading, 2); see :func:`as_vectors`."""
    return as_vectors(name, value, 2, leading, sizes=sizes, unit=unit, allow_empty=allow_empty)


def as_env_ids(name: str, value: Any, n_env: int | None = None) -> np.ndarray:
    """Global environment indices as a C-contiguous (B,) int64 array (a single integer gives (1,)).

    ``n_env`` (if given) is the required count B, one per environment of the batch.
    """
    if np.ndim(value) == 0:
        value = np.reshape(value, 1)
    env = as_array(name, value, np.int64, ("B",))
    if n_env is not None and env.shape[0] != n_env:
        raise ConfigError(f"{name} has {env.shape[0]} entries: expected {n_env} (one per environment)")
    return env


def check_inplace(name: str, out: Any, shape: Sequence[int], dtype=np.float64) -> np.ndarray:
    """``out`` itself, if it is a writable C-contiguous ndarray of exactly ``dtype`` and ``shape`` (to be
    filled in place); otherwise :class:`~finkensim.config.ConfigError` saying what it is instead."""
    dtype = np.dtype(dtype)
    shape = tuple(int(n) for n in shape)
    if isinstance(out, np.ndarray):
        if out.dtype == dtype and out.shape == shape and out.flags.c_contiguous and out.flags.writeable:
            return out
        got = f"a {out.dtype} array of shape {out.shape}"
        got += "" if out.flags.c_contiguous else ", not C-contiguous"
        got += "" if out.flags.writeable else ", read-only"
    else:
        got = f"a {type(out).__name__}"
    raise ConfigError(f"{name} is {got}: expected a writable C-contiguous {dtype} array of shape {shape} "
                      f"to fill in place")
