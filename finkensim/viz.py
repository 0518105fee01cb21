"""Matplotlib figures and animations of the arena, its Bernoulli walls and the copters.

Everything here only draws: no state is changed and nothing is shown (no ``plt.show``), so it
works under the Agg backend, in scripts, notebooks and the CLI alike. Functions that create a
figure return it (and its axes) for the caller to save or display.

    fig, ax = plot_arena(world, state.pos[0], state.yaw[0], state.theta[0], trails=traj.pose[:, 0])
    fig, ax = plot_wall_response(world, traj)           # amplitude law + simulated plate angles
    animate(world, traj, path="flight.gif")              # small animated GIF (PillowWriter)
    fig, axes = plot_sensors(log, copter=0)              # sonar, ranging, IMU vs ideal values

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
    "plot_sensors",
    "save_png",
    "sonar_crosstalk_events",
    "SONAR_NAMES",
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


# ------------------------------------------------------------------------------------------
# sensors
# ------------------------------------------------------------------------------------------

SONAR_NAMES = ("front", "left", "back", "right")
_SENSOR_PANELS = ("sonar", "ranging", "acc", "gyro", "acc_error", "gyro_error")


def _log_config(log: Any, section: str, key: str, default: Any) -> Any:
    """A config value recorded in ``log.meta["config"]`` (written by simulate_flight), else ``default``."""
    cfg = (getattr(log, "meta", None) or {}).get("config") or {}
    try:
        return cfg[section][key]
    except (KeyError, TypeError):
        return default


def _crosstalk_threshold(log: Any) -> float:
    """How much shorter than the ideal echo a sonar reading must be to count as cross-talk (m):
    5 σ of the configured error (at least 0.1 m). The Rayleigh term alone exceeds this with
    probability < 1e-6 (R − s > 5σ needs R > 5.66σ)."""
    return max(0.1, 5.0 * float(_log_config(log, "sonar", "sigma", 0.05)))


def sonar_crosstalk_events(log: Any) -> np.ndarray | None:
    """Boolean (T, N, 4): sonar readings far shorter than the ideal echo (cross-talk, see
    :func:`_crosstalk_threshold`), or None when the log has no sonar or no ``ultrasonic_ideal`` extra."""
    u = getattr(log, "ultrasonic", None)
    ideal = (getattr(log, "extras", None) or {}).get("ultrasonic_ideal")
    if u is None or ideal is None:
        return None
    lo = float(_log_config(log, "sonar", "min_range", 0.2))
    hi = float(_log_config(log, "sonar", "max_range", 3.0))
    return np.asarray(u) < np.clip(np.asarray(ideal), lo, hi) - _crosstalk_threshold(log)


def _sensor_axes(ax, panels: list[str], imu_errors: bool = True):
    """(fig, {panel: axes or list of axes}) for the panels present; ``ax`` as in :func:`plot_sensors`.

    Layout: the four sonar strips across the top; below, the ranging scatter on the left and the
    accelerometer and gyro time series stacked on the right, each with an error strip when
    ``imu_errors`` (the log has ideal IMU values).
    """
    import matplotlib.pyplot as plt

    if isinstance(ax, dict):
        axes = {k: v for k, v in ax.items() if k in panels or (k.endswith("_error") and k[:-6] in panels)}
        first = next(iter(axes.values()), None)
        if first is None:
            raise ValueError(f"ax: expected a dict with some of the keys {', '.join(_SENSOR_PANELS)}")
        first = first[0] if isinstance(first, (list, tuple, np.ndarray)) else first
        return first.figure, axes
    imu = [p for p in ("acc", "gyro") if p in panels]
    bottom = bool(imu) or "ranging" in panels
    if ax is None:
        height = (4.2 if "sonar" in panels else 0.0) + (4.6 if bottom else 0.0)
        fig = plt.figure(figsize=(11.5, max(height, 3.6)), layout="constrained")
    else:
        fig = ax  # a Figure or SubFigure
    axes: dict[str, Any] = {}
    rows = ([4.2] if "sonar" in panels else []) + ([4.6] if bottom else [])
    outer = fig.add_gridspec(len(rows), 1, height_ratios=rows)
    r = 0
    if "sonar" in panels:
        gs = outer[r].subgridspec(4, 1, hspace=0.0)
        strips = []
        for k in range(4):
            strips.append(fig.add_subplot(gs[k], sharex=strips[0] if strips else None))
        axes["sonar"] = strips
        r += 1
    if bottom:
        ncols = (1 if imu else 0) + (1 if "ranging" in panels else 0)
        widths = [1.0, 1.6] if ncols == 2 else [1.0]
        gs = outer[r].subgridspec(max(len(imu), 1), ncols, width_ratios=widths)
        if "ranging" in panels:
            axes["ranging"] = fig.add_subplot(gs[:, 0])
        if imu:
            # each IMU channel: the signal, and below it a thin strip with its error (measured − ideal)
            per = 2 if imu_errors else 1
            ratios = ([3.0, 1.3] if imu_errors else [1.0]) * len(imu)
            sub = gs[:, ncols - 1].subgridspec(per * len(imu), 1, height_ratios=ratios,
                                               hspace=0.0 if imu_errors else None)
            first = None
            for i, p in enumerate(imu):
                a = fig.add_subplot(sub[per * i], sharex=first)
                first = first or a
                axes[p] = a
                if imu_errors:
                    axes[p + "_error"] = fig.add_subplot(sub[per * i + 1], sharex=first)
    return fig, axes


_SONAR_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:purple")
_CROSSTALK_COLOUR = "tab:red"


def _plot_sonar_panel(axs, log, copter: int, t: np.ndarray) -> None:
    from matplotlib.lines import Line2D

    u = np.asarray(log.ultrasonic)[:, copter]
    extras = getattr(log, "extras", None) or {}
    ideal = extras.get("ultrasonic_ideal")
    ideal = None if ideal is None else np.asarray(ideal)[:, copter]
    events = sonar_crosstalk_events(log)
    events = None if events is None else events[:, copter]
    lo = float(_log_config(log, "sonar", "min_range", 0.2))
    hi = float(_log_config(log, "sonar", "max_range", 3.0))
    n_s = u.shape[1]
    axs = list(axs) if isinstance(axs, (list, tuple, np.ndarray)) else [axs]
    single = len(axs) == 1
    thr = _crosstalk_threshold(log)
    handles = []
    for k in range(n_s):
        a = axs[0] if single else axs[min(k, len(axs) - 1)]
        name = SONAR_NAMES[k] if k < len(SONAR_NAMES) else f"sonar {k}"
        c = _SONAR_COLOURS[k % len(_SONAR_COLOURS)]
        a.plot(t, u[:, k], ".", ms=2.2, color=c)
        if single:
            handles.append(Line2D([], [], ls="none", marker=".", ms=7, color=c, label=f"{name} reading"))
        if ideal is not None:
            a.plot(t, ideal[:, k], "-", lw=0.8, color=c if single else "k", alpha=0.85)
        if events is not None and np.any(events[:, k]):
            sel = events[:, k]
            a.plot(t[sel], u[sel, k], "x", ms=3.5, mew=0.9, color=_CROSSTALK_COLOUR)
        if not single:
            a.set_ylabel(f"{name}\n(m)", fontsize=8)
            a.set_ylim(0.0, hi * 1.1)
            a.axhline(lo, color="0.6", lw=0.6, ls=":")
            a.grid(True, lw=0.4, alpha=0.4)
            a.tick_params(labelsize=8)
            if k < n_s - 1:
                a.tick_params(labelbottom=False)
            if events is not None:
                n_ev = int(np.count_nonzero(events[:, k]))
                a.text(0.995, 0.93, f"cross-talk: {n_ev} of {len(t)} readings ({100.0 * n_ev / max(1, len(t)):.1f} %)",
                       transform=a.transAxes, ha="right", va="top", fontsize=7, color=_CROSSTALK_COLOUR,
                       bbox=dict(fc="white", ec="none", alpha=0.75, pad=1.0))
    if not single:
        handles.append(Line2D([], [], ls="none", marker=".", ms=7, color="0.35", label="reading (colour per sonar)"))
    if ideal is not None:
        handles.append(Line2D([], [], lw=0.9, color="0.35" if single else "k", label="ideal: distance to first hit"))
    if events is not None:
        handles.append(Line2D([], [], ls="none", marker="x", ms=5, color=_CROSSTALK_COLOUR,
                              label=f"cross-talk: reading > {thr:.2g} m shorter than ideal"))
    handles.append(Line2D([], [], lw=0.6, ls=":", color="0.6", label=f"min range {lo:g} m"))
    if single:
        axs[0].set_ylabel("sonar reading (m)")
        axs[0].set_ylim(0.0, hi * 1.1)
        axs[0].grid(True, lw=0.4, alpha=0.4)
    axs[-1].set_xlabel("time (s)")
    axs[0].set_xlim(t[0], t[-1])
    axs[0].set_title(f"(a) ultrasonic sonars of copter {copter}: readings (clamped to [{lo:g}, {hi:g}] m) "
                     "vs ideal distance", fontsize=10)
    axs[0].legend(handles=handles, loc="upper left", fontsize=7, ncol=len(handles), framealpha=0.85)


def _plot_ranging_panel(a, log, max_points: int) -> None:
    pose = np.asarray(log.pose)
    r = np.asarray(log.ranging)
    n = r.shape[1]
    true = np.linalg.norm(pose[:, :, None, :2] - pose[:, None, :, :2], axis=-1)  # (T, N, N), unclipped
    off = ~np.eye(n, dtype=bool)
    x = true[:, off].ravel()
    y = r[:, off].ravel()
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    max_range = float(_log_config(log, "ranging", "max_range", 2.5))
    if x.size > max_points:
        idx = np.random.default_rng(0).choice(x.size, size=max_points, replace=False)
        xs, ys = x[idx], y[idx]
    else:
        xs, ys = x, y
    inr = xs <= max_range
    a.scatter(xs[inr], ys[inr], s=3, alpha=0.15, lw=0, color="tab:blue", label="reading (in range)")
    a.scatter(xs[~inr], ys[~inr], s=3, alpha=0.25, lw=0, color="tab:gray",
              label=f"out of range: reads {max_range:g} m")
    top = max(float(np.max(x)) if x.size else max_range, max_range) * 1.03
    a.plot([0, top], [0, top], "k-", lw=1.0, label="identity (reading = true)")
    # binned mean ± std of the in-range readings
    edges = np.linspace(0.0, max_range, 26)
    which = np.digitize(x, edges) - 1
    cx, mu, sd = [], [], []
    for k in range(len(edges) - 1):
        sel = (which == k) & (x <= max_range)
        if np.count_nonzero(sel) >= 30:
            cx.append(0.5 * (edges[k] + edges[k + 1]))
            mu.append(float(np.mean(y[sel])))
            sd.append(float(np.std(y[sel])))
    if cx:
        cx, mu, sd = map(np.asarray, (cx, mu, sd))
        a.plot(cx, mu, "-", color="tab:orange", lw=1.6, label="binned mean")
        a.fill_between(cx, mu - sd, mu + sd, color="tab:orange", alpha=0.25, lw=0, label="± 1 std")
    a.axvline(max_range, color="tab:red", ls="--", lw=1.0, label=f"cut-off {max_range:g} m")
    a.set_xlim(0.0, top)
    a.set_ylim(0.0, max(top, float(np.max(y)) * 1.03 if y.size else top))
    a.set_aspect("equal", adjustable="box")
    a.set_xlabel("true distance (m)")
    a.set_ylabel("virtual ranging reading (m)")
    a.set_title(f"(b) virtual ranging, all {n * (n - 1)} ordered pairs", fontsize=10)
    a.grid(True, lw=0.4, alpha=0.4)
    leg = a.legend(loc="upper left", fontsize=7, framealpha=0.9)
    for h in leg.legend_handles:
        if hasattr(h, "set_sizes"):
            h.set_sizes([14.0])
            h.set_alpha(0.9)


def _plot_imu_panel(a, err_ax, t, meas, ideal, ylabel: str, unit: str, title: str, colour: str) -> None:
    """Measured and ideal on ``a``; on ``err_ax`` (if given and ideal values exist) the error
    measured − ideal and its 1 s running mean, which follows the bias random walk."""
    a.plot(t, meas, "-", lw=1.6, color=colour, alpha=0.9, label="measured")
    if ideal is not None:
        a.plot(t, ideal, "-", lw=0.8, color="k", label="ideal (kinematic)")
    fin = meas[np.isfinite(meas)]
    lo, hi = (float(fin.min()), float(fin.max())) if fin.size else (-1.0, 1.0)
    span = max(hi - lo, 1e-12)
    a.set_ylim(lo - 0.05 * span, hi + 0.3 * span)  # headroom for the legend
    a.set_ylabel(ylabel)
    a.set_title(title, fontsize=10)
    a.set_xlim(t[0], t[-1])
    a.grid(True, lw=0.4, alpha=0.4)
    a.legend(loc="upper left", fontsize=7, ncol=2, framealpha=0.85)
    if err_ax is None:
        return
    a.tick_params(labelbottom=False)
    if ideal is None:
        err_ax.text(0.5, 0.5, "no ideal values in the log", transform=err_ax.transAxes, ha="center",
                    va="center", fontsize=8, color="0.4")
        err_ax.set_yticks([])
        return
    err = meas - ideal
    err_ax.plot(t, err, "-", lw=0.5, color="0.5", label=f"error (measured − ideal), std {np.nanstd(err):.2g} {unit}")
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    w = max(1, int(round(1.0 / dt)))
    if err.size >= w:
        run = np.convolve(err, np.ones(w) / w, mode="valid")
        off = (w - 1) // 2
        err_ax.plot(t[off:off + run.size], run, "-", lw=1.3, color="tab:red", label="1 s running mean (≈ bias)")
    err_ax.axhline(0.0, color="k", lw=0.5)
    m = max(float(np.nanmax(np.abs(err))) if np.any(np.isfinite(err)) else 0.0, 1e-12)
    err_ax.set_ylim(-1.15 * m, 1.9 * m)
    err_ax.set_ylabel(f"error\n({unit})", fontsize=8)
    err_ax.tick_params(labelsize=7)
    err_ax.grid(True, lw=0.4, alpha=0.4)
    err_ax.legend(loc="upper left", fontsize=6.5, ncol=2, framealpha=0.85)


def plot_sensors(log, copter: int = 0, ax=None, *, max_points: int = 40000, title: str | None = None):
    """The sensors of one flight log, measured against ideal, in up to four panels.

    (a) ``sonar``: the four sonar readings of ``copter`` over time (dots) with the ideal first-hit
        distance (thin line, extra ``ultrasonic_ideal``) and the cross-talk events marked (readings
        more than max(0.1 m, 5·sonar.sigma) shorter than the ideal echo; counts per sonar);
    (b) ``ranging``: virtual-ranging reading against the true distance (from the poses) for all
        ordered pairs and samples (a random subset of ``max_points``), with the identity line,
        the binned mean ± std and the ``ranging.max_range`` cut-off;
    (c) ``acc``: accelerometer body x (forward) of ``copter``, measured vs ideal (m/s²);
    (d) ``gyro``: yaw-rate gyro of ``copter``, measured vs ideal (rad/s);
    each IMU channel with a strip below showing the error measured − ideal and its 1 s running
    mean (which follows the bias random walk).

    Works with any :class:`~finkensim.flightlog.FlightLog`: a panel whose block is missing
    (no ``ultrasonic``, ``ranging`` or ``imu_acc``) is skipped, and without the ideal extras
    (``finkensim run --no-ideal``, real logs) only the measurements are drawn.

    Args:
        log: a FlightLog (ideally from :func:`finkensim.scenario.simulate_flight` with ``ideal=True``).
        copter: index of the copter for the time series.
        ax: None (new figure), a Figure/SubFigure to fill, or a dict {panel name: Axes} with any of
            "sonar" (one Axes, or a list of 4 strips), "ranging", "acc", "gyro", "acc_error",
            "gyro_error" (strips for measured − ideal); panels not in the dict are not drawn.
        max_points: largest number of scattered ranging points.
        title: figure title (default names the flight length and the number of copters).

    Returns:
        (fig, axes): axes is a dict {panel name: Axes (or list of Axes for "sonar")}.
    """
    n = int(np.asarray(log.pose).shape[1])
    if not 0 <= copter < n:
        raise ValueError(f"copter = {copter}: expected an index in [0, {n - 1}]")
    panels = []
    if getattr(log, "ultrasonic", None) is not None:
        panels.append("sonar")
    if getattr(log, "ranging", None) is not None and n > 1:
        panels.append("ranging")
    if getattr(log, "imu_acc", None) is not None:
        panels += ["acc", "gyro"]
    if not panels:
        raise ValueError("flight log has no sensor blocks (ultrasonic, ranging, imu_acc/imu_gyro) to plot")
    extras = getattr(log, "extras", None) or {}
    fig, axes = _sensor_axes(ax, panels, imu_errors="imu_acc_ideal" in extras or "imu_gyro_ideal" in extras)
    t = np.asarray(log.t, dtype=float)
    if "sonar" in axes:
        _plot_sonar_panel(axes["sonar"], log, copter, t)
    if "ranging" in axes:
        _plot_ranging_panel(axes["ranging"], log, max_points)
    imu_last = "gyro" if "gyro" in axes else "acc"
    for p, key, ideal_key, ylabel, unit, panel_title, colour in (
            ("acc", "imu_acc", "imu_acc_ideal", "acceleration (m/s²)", "m/s²",
             f"(c) IMU accelerometer, body x (forward), copter {copter}", "tab:green"),
            ("gyro", "imu_gyro", "imu_gyro_ideal", "yaw rate (rad/s)", "rad/s",
             f"(d) IMU yaw-rate gyro, copter {copter}", "tab:purple")):
        if p not in axes:
            continue
        meas = np.asarray(getattr(log, key))[:, copter]
        ideal = extras.get(ideal_key)
        ideal = None if ideal is None else np.asarray(ideal)[:, copter]
        if p == "acc":
            meas = meas[:, 0]
            ideal = None if ideal is None else ideal[:, 0]
        err_ax = axes.get(p + "_error")
        _plot_imu_panel(axes[p], err_ax, t, meas, ideal, ylabel, unit, panel_title, colour)
        last = err_ax if err_ax is not None else axes[p]
        if p == imu_last:
            last.set_xlabel("time (s)")
        else:
            last.tick_params(labelbottom=False)
    if not isinstance(ax, dict):
        dur = t[-1] - t[0] if t.size > 1 else 0.0
        fig.suptitle(title or f"Sensors of a {dur:g} s flight ({n} copters)"
                     + ("" if extras.get("ultrasonic_ideal") is not None or extras.get("imu_acc_ideal") is not None
                        else ", no ideal values in the log"), fontsize=11)
    return fig, axes


def save_png(fig, path: str | Path, dpi: int = 100, colors: int | None = 256) -> Path:
    """Save ``fig`` as a PNG; with ``colors`` (default 256) as a palette image without dithering.

    Plots are mostly flat colours, so a 256-colour palette looks the same and is about a third
    of the size of the RGBA file (dense scatter plots with transparency otherwise make large
    files). ``colors=None`` writes the plain RGBA PNG of ``fig.savefig``.
    """
    import io

    from PIL import Image

    path = Path(path)
    if colors is None:
        fig.savefig(path, dpi=dpi)
        return path
    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format="png")
    buf.seek(0)
    with Image.open(buf) as im:
        pal = im.convert("RGB").quantize(colors=int(colors), method=Image.Quantize.MEDIANCUT,
                                         dither=Image.Dither.NONE)
    pal.save(path, format="PNG", optimize=True)
    return path
