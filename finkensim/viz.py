"""Matplotlib figures and animations of the arena, its Bernoulli walls and the copters.

Everything here only draws: no state is changed and nothing is shown (no ``plt.show``), so it
works under the Agg backend, in scripts, notebooks and the CLI alike. Functions that create a
figure return it (and its axes) for the caller to save or display.

    fig, ax = plot_arena(world, state.pos[0], state.yaw[0], state.theta[0], trails=traj.pose[:, 0])
    fig, ax = plot_wall_response(world, traj)           # amplitude law + simulated plate angles
    animate(world, traj, path="flight.gif")              # small animated GIF (PillowWriter)

``arena`` arguments accept an :class:`~finkensim.arena.Arena` or a :class:`~finkensim.world.World`;
with a World the copter radius comes from its config, with an Arena pass ``radius`` (default
0.15 m). ``traj`` arguments accept a :class:`~finkensim.world.Trajectory` (shapes (T, B, ...)) or a
:class:`~finkensim.flightlog.FlightLog` carrying the ``wall_theta`` extra written by
:func:`finkensim.scenario.simulate_flight`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .arena import Arena, target_angles

__all__ = [
    "WALL_NAMES",
    "plot_arena",
    "plot_wall_response",
    "plot_plate_timeseries",
    "animate",
    "peak_deflection_index",
    "plate_label",
]

WALL_NAMES = ("south", "east", "north", "west")
"""Wall names in plate order (wall_index 0..3): y = 0, x = width, y = length, x = 0."""

DEFAULT_RADIUS = 0.15  # m, copter radius when only an Arena is given
_WALL_CMAP = "viridis"
_COPTER_CMAP = "tab10"


# ------------------------------------------------------------------------------------------
# input helpers
# ------------------------------------------------------------------------------------------

def _resolve(arena: Any, radius: float | None) -> tuple[Arena, float]:
    """(Arena, copter radius) from an Arena or a World."""
    if isinstance(arena, Arena):
        return arena, DEFAULT_RADIUS if radius is None else float(radius)
    inner = getattr(arena, "arena", None)
    cfg = getattr(arena, "cfg", None)
    if isinstance(inner, Arena):
        r = radius if radius is not None else (cfg.copters.radius if cfg is not None else DEFAULT_RADIUS)
        return inner, float(r)
    raise TypeError(f"arena: expected a finkensim Arena or World, got {type(arena).__name__}")


def _one_env(a: np.ndarray, ndim: int, name: str) -> np.ndarray:
    """Drop a leading environment axis of length 1: (1, ...) → (...)."""
    a = np.asarray(a, dtype=float)
    if a.ndim == ndim + 1 and a.shape[0] == 1:
        a = a[0]
    if a.ndim != ndim:
        raise ValueError(f"{name} has shape {a.shape}: expected {ndim} dimensions (one environment)")
    return a


def _traj_arrays(traj: Any, env: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t (T,), pose (T, B', N, 3), theta (T, B', S)) from a Trajectory or a FlightLog.

    ``env``: an environment index, a list/slice of them, or None for all.
    """
    if hasattr(traj, "theta") and hasattr(traj, "pose"):  # Trajectory
        t, pose, theta = np.asarray(traj.t), np.asarray(traj.pose), np.asarray(traj.theta)
    elif hasattr(traj, "extras") and hasattr(traj, "pose"):  # FlightLog
        if "wall_theta" not in traj.extras:
            raise ValueError("flight log has no 'wall_theta' extra array (plate angles); "
                             "expected a log written by finkensim.scenario.simulate_flight")
        t = np.asarray(traj.t)
        pose = np.asarray(traj.pose)[:, None]
        theta = np.asarray(traj.extras["wall_theta"])[:, None]
    else:
        raise TypeError(f"traj: expected a Trajectory or a FlightLog, got {type(traj).__name__}")
    if env is not None:
        sel = [env] if isinstance(env, (int, np.integer)) else env
        pose, theta = pose[:, sel], theta[:, sel]
    return t, pose, theta


def peak_deflection_index(traj: Any, env: int = 0) -> int:
    """Sample index of the largest total wall deflection of environment ``env``: the moment when
    the plates together are pulled furthest into the arena (sum of sin θ over plates; 0 if the
    walls never move)."""
    _, _, theta = _traj_arrays(traj, env)
    total = np.sum(np.sin(theta[:, 0]), axis=1)
    return int(np.argmax(total)) if total.size else 0


def plate_label(arena: Arena, s: int) -> str:
    """Human-readable name of plate ``s``, e.g. ``"east 3"`` (plates counted from 0 along each wall)."""
    w = int(arena.wall_index[s])
    k = int(s - np.flatnonzero(arena.wall_index == w)[0])
    return f"{WALL_NAMES[w]} {k}"


def _new_axes(ax, figsize):
    import matplotlib.pyplot as plt

    if ax is None:
        fig, ax = plt.subplots(figsize=figsize, layout="constrained")
        return fig, ax
    return ax.figure, ax


def _angle_norm(arena: Arena, theta_deg: np.ndarray, vmax_deg: float | None):
    from matplotlib.colors import Normalize

    top = float(np.rad2deg(arena.hinge.max_amplitude)) * 1.1  # f(x) peaks at 1.1
    if vmax_deg is None:
        vmax_deg = max(top, float(np.nanmax(theta_deg)) if theta_deg.size else 0.0, 1.0)
    vmin = min(0.0, float(np.nanmin(theta_deg)) if theta_deg.size else 0.0)
    return Normalize(vmin=vmin, vmax=vmax_deg)


# ------------------------------------------------------------------------------------------
# the arena picture (shared by plot_arena and animate)
# ------------------------------------------------------------------------------------------

@dataclass
class _ArenaArtists:
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


def _draw_arena(ax, arena: Arena, pos, yaw, theta, trails, radius, exaggeration, norm, labels) -> _ArenaArtists:
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
    trail_lines = []
    if trails is not None:
        for i in range(n):
            (line,) = ax.plot(trails[:, i, 0], trails[:, i, 1], color=colours[i], lw=1.0, alpha=0.55, zorder=2)
            trail_lines.append(line)
    bodies = []
    for i in range(n):
        c = Circle(pos[i], radius, facecolor=(*colours[i][:3], 0.35), edgecolor=colours[i], lw=1.5, zorder=4)
        ax.add_patch(c)
        bodies.append(c)
    headings = LineCollection(_heading_segments(pos, yaw, radius), colors="k", linewidths=1.6, zorder=5)
    ax.add_collection(headings)
    texts = []
    if labels:
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
    return _ArenaArtists(walls, bodies, headings, trail_lines, texts)


def _update_arena(art: _ArenaArtists, arena: Arena, pos, yaw, theta, trails, radius, exaggeration) -> None:
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


def _title(base: str, t: float | None, exaggeration: float) -> str:
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
        labels: print each copter's index on its body.

    Each plate is drawn at flight height where the sensors see it: its own width, moved into the
    arena by ``exaggeration · lever · sin θ`` and coloured by θ. The dashed rectangle is the rest line.

    Returns:
        (fig, ax)
    """
    arena, radius = _resolve(arena, radius)
    pos = _one_env(pos, 2, "pos")
    yaw = _one_env(yaw, 1, "yaw")
    theta = _one_env(theta, 1, "theta")
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
    fig, ax = _new_axes(ax, (5.4, 6.4))
    norm = _angle_norm(arena, np.rad2deg(theta), vmax_deg)
    art = _draw_arena(ax, arena, pos, yaw, theta, trails, radius, exaggeration, norm, labels)
    if colorbar:
        fig.colorbar(art.walls, ax=ax, label="plate angle θ (deg)", shrink=0.85, pad=0.02)
    ax.set_title(_title(title or "Arena, top view", t, exaggeration))
    return fig, ax


# ------------------------------------------------------------------------------------------
# wall response
# ------------------------------------------------------------------------------------------

def plate_distances(arena: Arena, pose: np.ndarray, radius: float) -> np.ndarray:
    """Distance (m) from each plate's rest line to the nearest copter body, as the wall model uses it.

    pose (..., N, 2 or 3) → (..., S).
    """
    from .kernels.geometry import segment_copter_distances

    pose = np.asarray(pose, dtype=float)
    lead = pose.shape[:-2]
    flat = np.ascontiguousarray(pose.reshape((-1,) + pose.shape[-2:])[..., :2])
    d = segment_copter_distances(arena.seg_a, arena.seg_b, flat, float(radius))
    return d.reshape(lead + (arena.n_plates,))


def plot_wall_response(arena, traj=None, *, env=None, radius: float | None = None, ax=None,
                       max_points: int = 20000, d_max: float | None = None, title: str | None = None):
    """Plate angle (deg) against the distance (m) from the plate to the nearest copter body.

    Draws the amplitude law's target angle ``max_amplitude · f((threshold − d) / threshold)``
    with the threshold marked, the largest angle the hinge motor can hold against gravity when
    that is below the targets (e.g. ``profile = "seed"``), and, given a trajectory, the simulated
    (distance, angle) pairs of every plate and sample (a random subset of ``max_points``) with
    their binned median. The simulated angles lag the target: plates need time to swing.

    Args:
        arena: an Arena or a World.
        traj: optional Trajectory (or FlightLog with ``wall_theta``) to scatter.
        env: environment index or indices to use from the trajectory (default: all).
        radius: copter radius in m (default: from the World, else 0.15).
        ax: axes to draw into; None makes a new figure.
        max_points: largest number of scattered points.
        d_max: right end of the distance axis in m (default 1.6 × threshold).

    Returns:
        (fig, ax)
    """
    arena, radius = _resolve(arena, radius)
    hp = arena.hinge
    thr = hp.threshold
    d_max = 1.6 * thr if d_max is None else float(d_max)
    fig, ax = _new_axes(ax, (6.4, 4.2))

    if traj is not None:
        _, pose, theta = _traj_arrays(traj, env)
        d = plate_distances(arena, pose, radius).ravel()
        th = np.rad2deg(theta).ravel()
        keep = d <= d_max
        d, th = d[keep], th[keep]
        if d.size:
            rng = np.random.default_rng(0)
            idx = rng.choice(d.size, size=max_points, replace=False) if d.size > max_points else slice(None)
            ax.scatter(d[idx], th[idx], s=5, alpha=0.18, color="tab:blue", lw=0, zorder=2,
                       label="simulated plates (samples)")
            edges = np.linspace(0.0, d_max, 33)
            which = np.digitize(d, edges) - 1
            centres, medians = [], []
            for k in range(len(edges) - 1):
                sel = which == k
                if np.count_nonzero(sel) >= max(20, d.size // 2000):  # skip sparsely sampled bins
                    centres.append(0.5 * (edges[k] + edges[k + 1]))
                    medians.append(np.median(th[sel]))
            if centres:
                ax.plot(centres, medians, "o-", ms=3.5, lw=1.4, color="tab:blue", zorder=4,
                        label="simulated (binned median)")

    grid = np.linspace(0.0, d_max, 400)
    target = np.rad2deg(target_angles(grid, thr, hp.max_amplitude))
    ax.plot(grid, target, color="tab:red", lw=2.2, zorder=5, label="amplitude law target")
    ax.axvline(thr, color="0.3", ls="--", lw=1.0, zorder=3)
    ax.annotate(f"threshold {thr:g} m", xy=(thr, 0.5), xycoords=("data", "axes fraction"), rotation=90,
                xytext=(-3, 0), textcoords="offset points", ha="right", va="center", fontsize=8, color="0.3")
    hold = np.rad2deg(arena.max_equilibrium_angle())
    if hp.bending and hold < target.max() - 1e-9:
        ax.axhline(hold, color="tab:orange", ls=":", lw=1.5, zorder=3,
                   label=f"motor limit against gravity ({hold:.1f}°)")
    ax.set_xlim(0.0, d_max)
    ax.set_xlabel("distance from plate to nearest copter body d (m)")
    ax.set_ylabel("plate angle θ (deg)")
    ax.set_title(title or "Bernoulli wall response")
    ax.grid(True, lw=0.4, alpha=0.4)
    leg = ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
    for h in leg.legend_handles:  # the scatter's legend marker: visible, not faint
        if hasattr(h, "set_sizes"):
            h.set_sizes([16.0])
            h.set_alpha(0.8)
    return fig, ax


def plot_plate_timeseries(arena, traj, *, env: int = 0, n_plates: int = 6, ax=None, title: str | None = None):
    """Plate angle (deg) over time (s) for the ``n_plates`` plates that swing furthest in ``env``.

    Returns:
        (fig, ax)
    """
    arena, _ = _resolve(arena, None)
    t, _, theta = _traj_arrays(traj, env)
    th = np.rad2deg(theta[:, 0])
    order = np.argsort(-np.max(np.abs(th), axis=0), kind="stable")[: max(1, int(n_plates))]
    fig, ax = _new_axes(ax, (8.0, 3.6))
    for s in order:
        ax.plot(t, th[:, s], lw=1.2, label=f"plate {plate_label(arena, int(s))}")
    top = np.rad2deg(arena.hinge.max_amplitude) * 1.1
    ax.axhline(top, color="0.4", ls=":", lw=1.0, label=f"largest target ({top:.0f}°)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("plate angle θ (deg)")
    if len(t) > 1:
        ax.set_xlim(t[0], t[-1])
    ax.set_title(title or "Most active wall plates")
    ax.grid(True, lw=0.4, alpha=0.4)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, frameon=False)
    return fig, ax


# ------------------------------------------------------------------------------------------
# animation
# ------------------------------------------------------------------------------------------

def _gif_writer_class():
    from matplotlib.animation import PillowWriter

    class GifWriter(PillowWriter):
        """PillowWriter that maps every frame onto the first frame's palette (no dithering).

        One shared palette is ~3x faster than Pillow's per-frame adaptive quantisation, keeps
        colours steady between frames and makes the GIF smaller.
        """

        def grab_frame(self, **savefig_kwargs):
            from PIL import Image

            super().grab_frame(**savefig_kwargs)
            im = self._frames[-1].convert("RGB")
            if len(self._frames) == 1:
                self._palette = im.quantize(colors=255, method=Image.Quantize.MEDIANCUT)
                self._frames[-1] = self._palette
            else:
                self._frames[-1] = im.quantize(palette=self._palette, dither=Image.Dither.NONE)

    return GifWriter


def animate(arena, traj, env: int = 0, path: str | Path | None = None, *, fps: int = 10,
            stride: int | None = None, max_frames: int = 150, radius: float | None = None,
            exaggeration: float = 1.0, trail_seconds: float = 4.0, dpi: int = 72,
            figsize: tuple[float, float] = (4.6, 5.4)):
    """Animate one environment of a trajectory: walls, copters and short trails.

    Args:
        arena: an Arena or a World.
        traj: a Trajectory (or a FlightLog with ``wall_theta``).
        env: environment index.
        path: where to write an animated GIF (matplotlib's PillowWriter). None: return a
            ``FuncAnimation`` instead (e.g. for ``IPython.display.HTML(anim.to_jshtml())``).
        fps: frames per second of the GIF.
        stride: samples between frames (default: the smallest that gives ≤ ``max_frames`` frames).
        max_frames: frame budget for the default stride; keeps the GIF small.
        radius: copter radius in m (default: from the World, else 0.15).
        exaggeration: factor on the drawn wall displacement.
        trail_seconds: length of the trail behind each copter (0 = none).
        dpi, figsize: frame size (default 331 × 389 px).

    Returns:
        the GIF's Path, or the FuncAnimation when ``path`` is None.
    """
    from matplotlib.animation import FuncAnimation
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    arena, radius = _resolve(arena, radius)
    t, pose, theta = _traj_arrays(traj, env)
    pose, theta = pose[:, 0], theta[:, 0]
    T = len(t)
    if T == 0:
        raise ValueError("traj has no samples to animate")
    if stride is None:
        stride = max(1, math.ceil(T / max(1, int(max_frames))))
    stride = int(stride)
    if stride < 1:
        raise ValueError(f"stride = {stride}: expected >= 1")
    frames = list(range(0, T, stride))
    dt = float(t[1] - t[0]) if T > 1 else 1.0
    trail_n = int(round(trail_seconds / dt)) if trail_seconds > 0 else 0

    def trail(k):
        return pose[max(0, k - trail_n): k + 1, :, :2] if trail_n else None

    # A bare Figure (not registered with pyplot): never shown by an interactive backend or inline.
    # Fixed axes positions instead of a layout engine, and the static parts (axes, ticks, grid,
    # colour bar, rest line) rendered once into a background image: re-laying out and
    # re-drawing them for every frame would cost most of the rendering time.
    fig = Figure(figsize=figsize, dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.15, 0.09, 0.64, 0.80))
    cax = fig.add_axes((0.83, 0.14, 0.035, 0.70))
    norm = _angle_norm(arena, np.rad2deg(theta), None)
    art = _draw_arena(ax, arena, pose[0, :, :2], pose[0, :, 2], theta[0], trail(0), radius, exaggeration,
                      norm, labels=False)
    fig.colorbar(art.walls, cax=cax, label="plate angle θ (deg)")
    dynamic = [art.walls, art.headings, *art.bodies, *art.trails]
    static = [p for p in ax.patches if p not in art.bodies]
    for a in dynamic:
        a.set_visible(False)
    fig.canvas.draw()
    background = np.asarray(fig.canvas.buffer_rgba()).copy()
    for a in dynamic:
        a.set_visible(True)
    for a in static:
        a.set_visible(False)
    ax.set_axis_off()
    cax.set_visible(False)
    fig.figimage(background, xo=0, yo=0, origin="upper", zorder=-10)

    # the title changes every frame; a figure text at a fixed place is far cheaper than an axes title
    bbox = ax.get_position()
    title = fig.text(0.5 * (bbox.x0 + bbox.x1), bbox.y1 + 0.012, "", ha="center", va="bottom", fontsize=10)

    def update(k):
        _update_arena(art, arena, pose[k, :, :2], pose[k, :, 2], theta[k], trail(k), radius, exaggeration)
        title.set_text(_title("Arena, top view", float(t[k]), exaggeration))
        return []

    if path is None:
        return FuncAnimation(fig, update, frames=frames, interval=1000.0 / fps, blit=False)
    path = Path(path)
    writer = _gif_writer_class()(fps=fps)
    with writer.saving(fig, str(path), dpi):
        for k in frames:
            update(k)
            writer.grab_frame()
    return path
