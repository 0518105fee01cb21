"""Animated GIFs (or a ``FuncAnimation``) of one environment: walls, copters and short trails."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..analysis import trajectory_arrays
from ..atomic import atomic_path
from .arena import angle_norm, arena_title, draw_arena, update_arena
from .inputs import resolve_arena

__all__ = ["animate"]


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

    arena, radius = resolve_arena(arena, radius)
    t, pose, theta = trajectory_arrays(traj, env)
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
    norm = angle_norm(arena, np.rad2deg(theta), None)
    art = draw_arena(ax, arena, pose[0, :, :2], pose[0, :, 2], theta[0], trail(0), radius, exaggeration,
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
        update_arena(art, arena, pose[k, :, :2], pose[k, :, 2], theta[k], trail(k), radius, exaggeration)
        title.set_text(arena_title("Arena, top view", float(t[k]), exaggeration))
        return []

    if path is None:
        return FuncAnimation(fig, update, frames=frames, interval=1000.0 / fps, blit=False)
    path = Path(path)
    writer = _gif_writer_class()(fps=fps)
    with atomic_path(path) as tmp, writer.saving(fig, str(tmp), dpi):  # the GIF appears whole or not at all
        for k in frames:
            update(k)
            writer.grab_frame()
    return path
