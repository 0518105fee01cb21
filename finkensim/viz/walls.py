"""The Bernoulli walls: plate angle against the distance to the nearest copter, and over time."""
from __future__ import annotations

import numpy as np

from ..analysis import binned_median, plate_distances, trajectory_arrays
from ..arena import target_angles
from .inputs import new_axes, plate_label, resolve_arena

__all__ = ["plot_wall_response", "plot_plate_timeseries"]


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
    arena, radius = resolve_arena(arena, radius)
    hp = arena.hinge
    thr = hp.threshold
    d_max = 1.6 * thr if d_max is None else float(d_max)
    fig, ax = new_axes(ax, (6.4, 4.2))

    if traj is not None:
        _, pose, theta = trajectory_arrays(traj, env)
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
            centres, medians = binned_median(d, th, edges, max(20, d.size // 2000))  # skip sparsely sampled bins
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
    arena, _ = resolve_arena(arena, None)
    t, _, theta = trajectory_arrays(traj, env)
    th = np.rad2deg(theta[:, 0])
    order = np.argsort(-np.max(np.abs(th), axis=0), kind="stable")[: max(1, int(n_plates))]
    fig, ax = new_axes(ax, (8.0, 3.6))
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
