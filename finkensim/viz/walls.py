"""The Bernoulli walls: plate angle against the distance to the nearest copter, and over time."""
from __future__ import annotations

import numpy as np

from ..analysis import binned_median, plate_distances, trajectory_arrays
from ..arena import target_angles
from .inputs import new_axes, plate_label, resolve_arena

__all__ = ["plot_wall_response", "plot_plate_timeseries", "START_TRANSIENT_S"]

START_TRANSIENT_S = 2.0
"""Seconds after the start drawn apart in :func:`plot_wall_response`: the plates start at rest, and those of
copters placed near a wall need about 1.5 s to swing up (default scenario, seed 0: 0.4-26 deg at d 0.15-0.2 m,
motor on for 0-1.7 s); left in, they pull the binned median far below the target there."""


def plot_wall_response(arena, traj=None, *, env=None, radius: float | None = None, ax=None,
                       max_points: int = 20000, d_max: float | None = None, title: str | None = None):
    """Plate angle (deg) against the distance (m) from the plate to the nearest copter body.

    Draws the amplitude law's target angle ``max_amplitude · f((threshold − d) / threshold)``
    with the threshold marked, the largest angle the hinge motor can hold against gravity when
    that is below the targets (e.g. ``profile = "seed"``), and, given a trajectory, the simulated
    (distance, angle) pairs of every plate and sample (a random subset of ``max_points``) with
    their binned median. The simulated angles lag the target: plates need time to swing. The figure
    says why samples leave the target: the first :data:`START_TRANSIENT_S` s (plates start at rest,
    drawn grey, left out of the median), the contact limit asin(d / lever) (a plate cannot swing
    through a copter), and the hinge controller's overshoot above the target (its PI term carries
    the plate past the target for a few seconds after it swung up; noted with the largest excess).

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

    excess = None
    if traj is not None:
        t, pose, theta = trajectory_arrays(traj, env)
        d = plate_distances(arena, pose, radius)
        start = np.broadcast_to((np.asarray(t) - float(np.asarray(t).reshape(-1)[0]) < START_TRANSIENT_S)
                                .reshape((-1,) + (1,) * (d.ndim - 1)), d.shape).ravel()
        d, th = d.ravel(), np.rad2deg(theta).ravel()
        keep = d <= d_max
        d, th, start = d[keep], th[keep], start[keep]
        if d.size:
            rng = np.random.default_rng(0)
            idx = rng.choice(d.size, size=max_points, replace=False) if d.size > max_points else np.arange(d.size)
            late, early = idx[~start[idx]], idx[start[idx]]
            ax.scatter(d[late], th[late], s=5, alpha=0.18, color="tab:blue", lw=0, zorder=2,
                       label="simulated plates (samples)")
            if early.size:
                ax.scatter(d[early], th[early], s=5, alpha=0.35, color="0.55", lw=0, zorder=2,
                           label=f"first {START_TRANSIENT_S:g} s (plates start at rest)")
            edges = np.linspace(0.0, d_max, 33)
            dl, tl = d[~start], th[~start]
            centres, medians = binned_median(dl, tl, edges, max(20, dl.size // 2000))  # skip sparse bins
            if centres:
                ax.plot(centres, medians, "o-", ms=3.5, lw=1.4, color="tab:blue", zorder=4,
                        label=f"simulated (binned median, after {START_TRANSIENT_S:g} s)")
            peak = float(np.rad2deg(target_angles(np.linspace(0.0, thr, 400), thr, hp.max_amplitude)).max())
            if (tl > peak + 1.0).any():  # above every target the law can ask for: overshoot, not lag
                excess = (float(tl.max()), peak)

    grid = np.linspace(0.0, d_max, 400)
    target = np.rad2deg(target_angles(grid, thr, hp.max_amplitude))
    ax.plot(grid, target, color="tab:red", lw=2.2, zorder=5, label="amplitude law target")
    if arena.lever > 0:
        dc = np.linspace(0.0, min(d_max, arena.lever), 200)
        contact = np.rad2deg(np.arcsin(dc / arena.lever))
        show = contact <= 1.15 * max(target.max(), 1e-9)
        ax.plot(dc[show], contact[show], color="tab:green", ls="-.", lw=1.3, zorder=3,
                label=f"contact limit asin(d / {arena.lever:g} m): plate touches the copter")
    if excess is not None:
        ax.annotate(f"above the law's {excess[1]:.1f}° peak (up to {excess[0]:.1f}°): the hinge controller\n"
                    "overshoots (its integral term carries the plate past the target after it swung up);\n"
                    "above the curve near the threshold: plates lag as a copter leaves",
                    xy=(0.02, 0.02), xycoords="axes fraction", ha="left", va="bottom", fontsize=7, color="0.2",
                    bbox=dict(boxstyle="round,pad=0.3", fc="white", ec="0.8", alpha=0.9), zorder=6)
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
