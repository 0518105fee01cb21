"""The arena seen from above: bent walls coloured by plate angle, copters with headings and trails.

:func:`plot_arena` draws one moment; :func:`draw_arena` and :func:`update_arena` are shared with
:func:`~finkensim.viz.animation.animate`, which moves the same artists frame by frame.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..arena import Arena
from .inputs import new_axes, one_env, resolve_arena

__all__ = ["ArenaArtists", "angle_norm", "draw_arena", "update_arena", "arena_title", "plot_arena"]

_WALL_CMAP = "viridis"
_COPTER_CMAP = "tab10"


def angle_norm(arena: Arena, theta_deg: np.ndarray, vmax_deg: float | None):
    """Colour normalisation of plate angles (deg): from min(0, smallest angle) to ``vmax_deg``
    (default the larger of 1.1 × max amplitude, the largest angle and 1°)."""
    from matplotlib.colors import Normalize

    top = float(np.rad2deg(arena.hinge.max_amplitude)) * 1.1  # f(x) peaks at 1.1
    if vmax_deg is None:
        vmax_deg = max(top, float(np.nanmax(theta_deg)) if theta_deg.size else 0.0, 1.0)
    vmin = min(0.0, float(np.nanmin(theta_deg)) if theta_deg.size else 0.0)
    return Normalize(vmin=vmin, vmax=vmax_deg)


@dataclass
class ArenaArtists:
    """The matplotlib artists of one arena picture, kept to move them in an animation.

    walls: LineCollection of the S plates; bodies: N Circles; headings: LineCollection of N
    heading ticks; trails: N Line2D (empty without trails); labels: N Texts (empty without labels).
    """

    walls: Any
    bodies: list
    headings: Any
    trails: list
    labels: list


def _copter_colours(n: int):
    import matplotlib

    cmap = matplotlib.colormaps[_COPTER_CMAP]
    return [cmap(i % cmap.N) for i in range(n)]


def _wall_segments(arena: Arena, theta: np.ndarray, exaggeration: float) -> np.ndarray:
    shift = (exaggeration * arena.lever * np.sin(theta))[:, None] * arena.normal
    return np.stack([arena.plate_a + shift, arena.plate_b + shift], axis=1)  # (S, 2, 2)


def _heading_segments(pos: np.ndarray, yaw: np.ndarray, radius: float) -> np.ndarray:
    """Heading ticks from inside the body to beyond its rim (leaves the centre free for a label)."""
    u = radius * np.stack([np.cos(yaw), np.sin(yaw)], axis=-1)
    return np.stack([pos + 0.45 * u, pos + 1.7 * u], axis=1)


#: above this many copters the arena is drawn without labels and with thin lines
CROWD = 50


def draw_arena(ax, arena: Arena, pos, yaw, theta, trails, radius, exaggeration, norm, labels) -> ArenaArtists:
    """Draw the arena into ``ax``: rest line, plates (coloured by θ with ``norm``), copters.

    pos (N, 2) m, yaw (N,) rad, theta (S,) rad, trails None or (T', N, 2+) m, radius m,
    exaggeration: factor on the drawn wall displacement, labels: print copter indices (not above
    :data:`CROWD` copters, where lines are drawn thin too).
    """
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Circle, Rectangle

    W, L = arena.width, arena.length
    ax.add_patch(Rectangle((0, 0), W, L, fill=False, ls=(0, (4, 3)), lw=0.8, ec="0.55", zorder=1))
    walls = LineCollection(_wall_segments(arena, theta, exaggeration), cmap=_WALL_CMAP, norm=norm,
                           linewidths=4.5, capstyle="butt", zorder=3)
    walls.set_array(np.rad2deg(theta))
    ax.add_collection(walls)

    n = pos.shape[0]
    colours = _copter_colours(n)
    crowd = n > CROWD  # many copters: thin lines, or the picture is all ink
    lw_body, lw_heading, lw_trail = (0.2, 0.3, 0.3) if crowd else (1.5, 1.6, 1.0)
    trail_lines = []
    if trails is not None:
        for i in range(n):
            (line,) = ax.plot(trails[:, i, 0], trails[:, i, 1], color=colours[i], lw=lw_trail, alpha=0.55, zorder=2)
            trail_lines.append(line)
    bodies = []
    for i in range(n):
        c = Circle(pos[i], radius, facecolor=(*colours[i][:3], 0.35), edgecolor=colours[i], lw=lw_body, zorder=4)
        ax.add_patch(c)
        bodies.append(c)
    headings = LineCollection(_heading_segments(pos, yaw, radius), colors="k", linewidths=lw_heading, zorder=5)
    ax.add_collection(headings)
    texts = []
    if labels and not crowd:
        for i in range(n):
            texts.append(ax.text(pos[i, 0], pos[i, 1], str(i), ha="center", va="center", fontsize=7,
                                 color="0.1", zorder=6))

    pad = 0.12
    ax.set_xlim(-pad, W + pad)
    ax.set_ylim(-pad, L + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, lw=0.4, alpha=0.35, zorder=0)
    return ArenaArtists(walls, bodies, headings, trail_lines, texts)


def update_arena(art: ArenaArtists, arena: Arena, pos, yaw, theta, trails, radius, exaggeration) -> None:
    """Move the artists of :func:`draw_arena` to a new moment (same arguments and units)."""
    art.walls.set_segments(_wall_segments(arena, theta, exaggeration))
    art.walls.set_array(np.rad2deg(theta))
    for i, c in enumerate(art.bodies):
        c.center = pos[i]
    art.headings.set_segments(_heading_segments(pos, yaw, radius))
    for i, txt in enumerate(art.labels):
        txt.set_position(pos[i])
    if trails is not None:
        for i, line in enumerate(art.trails):
            line.set_data(trails[:, i, 0], trails[:, i, 1])


def arena_title(base: str, t: float | None, exaggeration: float) -> str:
    """``base``, and below it the time ``t`` (s) and the wall exaggeration when not 1."""
    parts = [base]
    if t is not None:
        parts.append(f"t = {t:.1f} s")
    if exaggeration != 1.0:
        parts.append(f"wall displacement ×{exaggeration:g}")
    return parts[0] + ("\n" + ", ".join(parts[1:]) if len(parts) > 1 else "")


def plot_arena(arena, pos, yaw, theta, ax=None, trails=None, *, radius: float | None = None,
               exaggeration: float = 1.0, t: float | None = None, title: str | None = None,
               vmax_deg: float | None = None, colorbar: bool = True, labels: bool = True):
    """Top view of the arena: bent walls, copters with headings, optional trails.

    Args:
        arena: an Arena or a World (the World also gives the copter radius).
        pos: (N, 2) copter positions in m (a leading environment axis of 1 is accepted).
        yaw: (N,) headings in rad.
        theta: (S,) plate hinge angles in rad.
        ax: axes to draw into; None makes a new figure.
        trails: optional (T, N, 2) or (T, N, 3) past positions (poses) drawn as lines.
        radius: copter radius in m (default: from the World, else 0.15).
        exaggeration: factor on the drawn wall displacement lever · sin θ (1 = true scale).
        t: time in s for the title.
        vmax_deg: top of the plate-angle colour scale (default 1.1 × max amplitude).
        colorbar: add a colour bar of plate angles in degrees.
        labels: print each copter's index on its body (up to :data:`CROWD` copters).

    Each plate is drawn at flight height where the sensors see it: its own width, moved into the
    arena by ``exaggeration · lever · sin θ`` and coloured by θ. The dashed rectangle is the rest line.

    Returns:
        (fig, ax)
    """
    arena, radius = resolve_arena(arena, radius)
    pos = one_env(pos, 2, "pos")
    yaw = one_env(yaw, 1, "yaw")
    theta = one_env(theta, 1, "theta")
    if theta.shape[0] != arena.n_plates:
        raise ValueError(f"theta has {theta.shape[0]} plates: expected {arena.n_plates}")
    if yaw.shape[0] != pos.shape[0]:
        raise ValueError(f"yaw has {yaw.shape[0]} entries: expected one per copter ({pos.shape[0]})")
    if trails is not None:
        trails = np.asarray(trails, dtype=float)
        if trails.ndim == 4 and trails.shape[1] == 1:
            trails = trails[:, 0]
        if trails.ndim != 3 or trails.shape[1] != pos.shape[0] or trails.shape[2] not in (2, 3):
            raise ValueError(f"trails has shape {trails.shape}: expected (T, {pos.shape[0]}, 2) positions or poses")
    fig, ax = new_axes(ax, (5.4, 6.4))
    norm = angle_norm(arena, np.rad2deg(theta), vmax_deg)
    art = draw_arena(ax, arena, pos, yaw, theta, trails, radius, exaggeration, norm, labels)
    if colorbar:
        fig.colorbar(art.walls, ax=ax, label="plate angle θ (deg)", shrink=0.85, pad=0.02)
    ax.set_title(arena_title(title or "Arena, top view", t, exaggeration))
    return fig, ax
