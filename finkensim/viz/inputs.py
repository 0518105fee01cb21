"""Argument handling shared by the figures: Arena or World, one environment, plate names, axes."""
from __future__ import annotations

from typing import Any

import numpy as np

from ..arena import Arena
from ..flightlog import DEFAULT_COPTER_RADIUS

__all__ = ["WALL_NAMES", "DEFAULT_RADIUS", "resolve_arena", "one_env", "plate_label", "new_axes"]

WALL_NAMES = ("south", "east", "north", "west")
"""Wall names in plate order (wall_index 0..3): y = 0, x = width, y = length, x = 0."""

DEFAULT_RADIUS = DEFAULT_COPTER_RADIUS
"""Copter radius (m) when only an Arena is given."""


def resolve_arena(arena: Any, radius: float | None) -> tuple[Arena, float]:
    """(Arena, copter radius in m) from an Arena or a World.

    ``radius`` (m) wins when given; otherwise a World's ``cfg.copters.radius``, else
    :data:`DEFAULT_RADIUS`.
    """
    if isinstance(arena, Arena):
        return arena, DEFAULT_RADIUS if radius is None else float(radius)
    inner = getattr(arena, "arena", None)
    cfg = getattr(arena, "cfg", None)
    if isinstance(inner, Arena):
        r = radius if radius is not None else (cfg.copters.radius if cfg is not None else DEFAULT_RADIUS)
        return inner, float(r)
    raise TypeError(f"arena: expected a finkensim Arena or World, got {type(arena).__name__}")


def one_env(a: np.ndarray, ndim: int, name: str) -> np.ndarray:
    """``a`` as a float array of ``ndim`` dimensions, dropping a leading environment axis of
    length 1: (1, ...) → (...); raise ValueError naming ``name`` otherwise."""
    a = np.asarray(a, dtype=float)
    if a.ndim == ndim + 1 and a.shape[0] == 1:
        a = a[0]
    if a.ndim != ndim:
        raise ValueError(f"{name} has shape {a.shape}: expected {ndim} dimensions (one environment)")
    return a


def plate_label(arena: Arena, s: int) -> str:
    """Human-readable name of plate ``s``, e.g. ``"east 3"`` (plates counted from 0 along each wall)."""
    w = int(arena.wall_index[s])
    k = int(s - np.flatnonzero(arena.wall_index == w)[0])
    return f"{WALL_NAMES[w]} {k}"


def new_axes(ax, figsize: tuple[float, float]):
    """(fig, ax): ``ax`` and its figure, or a new constrained-layout figure of ``figsize`` inches."""
    import matplotlib.pyplot as plt

    if ax is None:
        fig, ax = plt.subplots(figsize=figsize, layout="constrained")
        return fig, ax
    return ax.figure, ax
