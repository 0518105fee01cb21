"""Fitted values at a bound of their range (:func:`~finkensim.gap.attribute.effects.at_bound`): :func:`flag_bounds`,
so that the report flags them."""
from __future__ import annotations

from ..attribute import effects as fx

__all__ = ["flag_bounds"]


def flag_bounds(effects: list, base) -> dict:
    """effect name -> the names of its parameters at a bound of their range, for each effect entry ({name, params,
    ...}) that has any. (Kept beside the spec's effect entries, which have exactly the spec's keys.)"""
    out = {}
    for e in effects:
        eff = fx.REGISTRY.get(e["name"])
        names = fx.at_bound(eff, e["params"], base) if eff is not None else []
        if names:
            out[e["name"]] = names
    return out
