"""Parsing shared by the sweep file (``sweepfile``), the sweep design (``design``) and the study file
(``finkensim.tune.studyfile``): the error type, the :class:`Parser` (checks whose errors name the source),
config-key checks with suggestions, and the keys a sweep may not set."""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Mapping

from ..config import SECTIONS, Config, ConfigError, check_key

RESERVED_KEYS = {
    "simulation.seed": "the seed of each run derives from the top-level 'seed' of the sweep",
    "simulation.n_envs": "each run is one environment",
}


class SweepError(ConfigError):
    """A sweep file, design, executor or output directory is wrong; raised before any run starts."""


def is_number(v) -> bool:
    """Whether ``v`` is an int or float (a bool is not a number here)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _field(key: str):
    """The dataclass field of a dotted config key (the key has been checked)."""
    section, _, name = key.partition(".")
    return {f.name: f for f in dataclasses.fields(SECTIONS[section])}[name]


def is_duration(v) -> bool:
    """Whether ``v`` is a valid episode duration: a finite number of seconds > 0."""
    return is_number(v) and math.isfinite(v) and v > 0


def field_kind(key: str) -> str:
    """The type name of a checked dotted config key's values: "int", "float", "bool", "str" or "tuple"."""
    if key == "profile":
        return "str"
    t = _field(key).type
    t = t if isinstance(t, str) else getattr(t, "__name__", str(t))
    return "tuple" if t.startswith("tuple") else t


def config_value(cfg: Config, key: str):
    """The value of a dotted config key (or "profile") in ``cfg``, as the config holds it."""
    if key == "profile":
        return cfg.profile
    section, _, name = key.partition(".")
    return getattr(getattr(cfg, section), name)

class Parser:
    """Checks a sweep table with error messages prefixed by the sweep's source name."""

    def __init__(self, source: str):
        self.source = source

    def error(self, message: str) -> SweepError:
        """A SweepError (to raise) of ``message`` prefixed by the sweep's source name."""
        return SweepError(f"{self.source}: {message}")

    def check_key(self, table: str, key: str) -> str:
        """``key`` if it is a dotted config key (or "profile") that may be swept; else a SweepError."""
        if key == "profile":
            return key
        section, _, name = key.partition(".")
        if not name or "." in name:
            raise self.error(f"[{table}] {key!r}: expected a dotted config key 'section.key' (e.g. 'copters.n') or 'profile'")
        try:
            check_key(section, name)
        except ConfigError as exc:
            raise self.error(f"[{table}] {exc}") from None
        if key in RESERVED_KEYS:
            raise self.error(f"[{table}] {key} cannot be swept: {RESERVED_KEYS[key]}")
        return key

    def flatten(self, table: str, data: Mapping[str, Any], is_leaf: Callable[[Any], bool],
                prefix: str = "") -> dict[str, Any]:
        """Nested tables as dotted keys; a mapping for which ``is_leaf`` is true is kept as a value."""
        out: dict[str, Any] = {}
        for k, v in data.items():
            key = f"{prefix}.{k}" if prefix else str(k)
            if isinstance(v, Mapping) and not is_leaf(v):
                out.update(self.flatten(table, v, is_leaf, key))
            else:
                out[key] = v
        return out

    def integer(self, key, value, lo, hi=None) -> int:
        """``value`` if it is an integer in [lo, hi] (hi None: no upper bound); else a SweepError."""
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(f"{key} = {value!r}: expected an integer, got {type(value).__name__}")
        if value < lo or (hi is not None and value > hi):
            allowed = f">= {lo}" + (f" and <= {hi}" if hi is not None else "")
            raise self.error(f"{key} = {value!r}: expected an integer {allowed}")
        return int(value)
