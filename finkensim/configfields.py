"""Config field declarations and value checks: the machinery behind :mod:`finkensim.config`'s sections.

A field is declared with :func:`field_spec` (unit, range or choices, doc); a :class:`Section` dataclass checks every
field on construction with :func:`coerce`, so a wrong value is a :class:`ConfigError` naming the key, the value and
what is allowed, whether the section comes from TOML or from Python.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import field
from typing import Any, Mapping

from .usertext import suggest

__all__ = ["ConfigError", "NameRegistry", "BEHAVIOUR_KINDS", "field_spec", "describe_range", "check_number", "coerce", "Section"]

class ConfigError(ValueError):
    """A configuration value is wrong. The message names the key, the value and what is allowed."""


ConfigError.__module__ = "finkensim.config"  # its public home (``from finkensim.config import ConfigError``)


class NameRegistry:
    """The allowed names of a string key that a higher layer extends at run time, used as that field's ``choices``:
    the built-in names first, then the keys of every table registered with :meth:`follow` (``behaviour.kind``: the
    behaviour registry's table, so whatever :func:`~finkensim.behaviours.register_behaviour` adds — or a test
    removes — is what the config accepts). The config sits below the modules that define the plug-ins, so they
    register their table here instead of the config importing them.

    Parameters
    ----------
    key : str
        The dotted config key (``"behaviour.kind"``).
    builtin : tuple of str
        The names valid before anything registers more.
    how : str
        How a name gets added, for error messages (``"register_behaviour"``).
    """

    def __init__(self, key: str, builtin: tuple, how: str = ""):
        self.key = key
        self.builtin = tuple(builtin)
        self.how = how
        self._tables: list = []

    def follow(self, table) -> None:
        """Accept the keys of ``table`` (a mapping a higher layer keeps up to date) as valid values too.

        Parameters
        ----------
        table : Mapping
            Name → plug-in; read live, at every check.
        """
        if not any(t is table for t in self._tables):
            self._tables.append(table)

    def names(self) -> tuple:
        """Every valid name: the built-ins, then the followed tables' other keys, in registration order."""
        extra = [n for t in self._tables for n in t if n not in self.builtin]
        return self.builtin + tuple(dict.fromkeys(extra))

    def __iter__(self):
        return iter(self.names())

    def __contains__(self, name) -> bool:
        return name in self.names()

    def __len__(self) -> int:
        return len(self.names())

    def __repr__(self) -> str:
        return f"NameRegistry({self.key!r}, {self.names()!r})"


#: the names ``behaviour.kind`` accepts: the built-in behaviours, then every name in the behaviour registry's table
#: (:mod:`finkensim.behaviours.registry` has it follow ``BEHAVIOURS``)
BEHAVIOUR_KINDS = NameRegistry("behaviour.kind", ("random_walk", "hover", "attraction_repulsion"),
                               how="finkensim.behaviours.register_behaviour")


def field_spec(default, unit="", lo=None, hi=None, lo_open=False, hi_open=False, choices=None, doc="", length=None):
    """A dataclass field with validation metadata: ``lo``/``hi`` bound numbers (inclusive unless ``*_open``);
    ``choices`` lists allowed strings (a :class:`NameRegistry` when other layers add names); ``length`` fixes the length of a tuple field (None = any length)."""
    meta = dict(unit=unit, lo=lo, hi=hi, lo_open=lo_open, hi_open=hi_open, choices=choices, doc=doc, length=length)
    if isinstance(default, (list, tuple)):
        return field(default_factory=lambda d=tuple(default): d, metadata=meta)
    return field(default=default, metadata=meta)


def describe_range(meta) -> str:
    """The allowed values of a field as text ("one of 'a', 'b'", ">= 0 and <= 1 m"), from its metadata."""
    parts = []
    if meta["choices"] is not None:
        how = getattr(meta["choices"], "how", "")
        return "one of " + ", ".join(repr(c) for c in meta["choices"]) + (f" (more with {how})" if how else "")
    if meta["lo"] is not None:
        parts.append((">" if meta["lo_open"] else ">=") + f" {meta['lo']}")
    if meta["hi"] is not None:
        parts.append(("<" if meta["hi_open"] else "<=") + f" {meta['hi']}")
    unit = f" {meta['unit']}" if meta["unit"] else ""
    return " and ".join(parts) + unit if parts else "any value"


def check_number(key, value, meta, kind):
    """``value`` checked as a finite ``kind`` ("number" or "integer") within the field's range; a
    :class:`ConfigError` naming ``key`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        article = "an" if kind[0] in "aeiou" else "a"
        raise ConfigError(f"{key} = {value!r}: expected {article} {kind}, got {type(value).__name__}")
    if kind == "integer" and not isinstance(value, int):
        raise ConfigError(f"{key} = {value!r}: expected an integer, got {type(value).__name__}")
    if not math.isfinite(value):
        raise ConfigError(f"{key} = {value!r}: expected a finite {kind}")
    lo, hi = meta["lo"], meta["hi"]
    bad_lo = lo is not None and (value <= lo if meta["lo_open"] else value < lo)
    bad_hi = hi is not None and (value >= hi if meta["hi_open"] else value > hi)
    if bad_lo or bad_hi:
        raise ConfigError(f"{key} = {value!r}: expected {describe_range(meta)}")
    return float(value) if kind == "number" else int(value)


def coerce(key: str, value: Any, ftype: Any, meta: Mapping) -> Any:
    """Check one value against its declared type and metadata; return it in canonical form."""
    t = ftype if isinstance(ftype, str) else getattr(ftype, "__name__", str(ftype))
    if t == "float":
        return check_number(key, value, meta, "number")
    if t == "int":
        return check_number(key, value, meta, "integer")
    if t == "bool":
        if not isinstance(value, bool):
            raise ConfigError(f"{key} = {value!r}: expected true or false, got {type(value).__name__}")
        return value
    if t == "str":
        if not isinstance(value, str):
            raise ConfigError(f"{key} = {value!r}: expected a string, got {type(value).__name__}")
        if meta["choices"] is not None and value not in meta["choices"]:
            raise ConfigError(f"{key} = {value!r}: expected {describe_range(meta)}{suggest(value, meta['choices'])}")
        return value
    if t == "tuple[str, ...]":
        if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
            raise ConfigError(f"{key} = {value!r}: expected a list of strings")
        return tuple(value)
    if t.startswith("tuple"):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{key} = {value!r}: expected a list of numbers")
        inner = "tuple[float, float]" in t or "tuple[tuple" in t
        if not inner:  # a bad element is named before a wrong length
            checked = tuple(check_number(f"{key}[{i}]", v, meta, "number") for i, v in enumerate(value))
        if meta["length"] is not None and len(value) != meta["length"]:
            raise ConfigError(f"{key} = {value!r}: expected a list of {meta['length']} numbers, got {len(value)}")
        if inner:  # a list of 2-D points
            pts = []
            for i, p in enumerate(value):
                if not isinstance(p, (list, tuple)) or len(p) != 2:
                    raise ConfigError(f"{key}[{i}] = {p!r}: expected a point [x, y] in m")
                pts.append(tuple(check_number(f"{key}[{i}]", c, meta, "number") for c in p))
            return tuple(pts)
        return checked
    raise TypeError(f"unsupported config field type {t} for {key}")  # a bug in this module, not user input


class Section:
    """Mixin: validate every field on construction (also when built from Python)."""

    _section = ""

    def __post_init__(self):
        for f in dataclasses.fields(self):
            key = f"{self._section}.{f.name}" if self._section else f.name
            object.__setattr__(self, f.name, coerce(key, getattr(self, f.name), f.type, f.metadata))
        self._check()

    def _check(self):
        """Cross-field checks; override in sections that need them."""
