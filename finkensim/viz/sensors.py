"""The sensors of one flight log against their ideal values: sonar strips, ranging scatter, IMU.

:func:`plot_sensors` lays out up to four panels (:func:`sensor_axes`) and fills each with its
own drawing function; the numbers behind them (cross-talk events, true pair distances, binned
statistics) come from :mod:`finkensim.analysis`.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..analysis import binned_mean_std, crosstalk_threshold, log_config, ranging_vs_truth, sonar_crosstalk_events
from ..flightlog import SONAR_NAMES

__all__ = ["SONAR_NAMES", "SENSOR_PANELS", "sensor_axes", "plot_sensors"]

SENSOR_PANELS = ("sonar", "ranging", "acc", "gyro", "acc_error", "gyro_error")
"""Panel names of :func:`plot_sensors` (keys of its ``ax`` dict and of the axes it returns)."""


def sensor_axes(ax, panels: list[str], imu_errors: bool = True):
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
            raise ValueError(f"ax: expected a dict with some of the keys {', '.join(SENSOR_PANELS)}")
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
    """Sonar readings (m) of ``copter`` over t (T,) s, one strip per sonar (or all in one Axes), cross-talk marked."""
    from matplotlib.lines import Line2D

    u = np.asarray(log.ultrasonic)[:, copter]
    extras = getattr(log, "extras", None) or {}
    ideal = extras.get("ultrasonic_ideal")
    ideal = None if ideal is None else np.asarray(ideal)[:, copter]
    events = sonar_crosstalk_events(log)
    events = None if events is None else events[:, copter]
    lo = float(log_config(log, "sonar", "min_range", 0.2))
    hi = float(log_config(log, "sonar", "max_range", 3.0))
    n_s = u.shape[1]
    axs = list(axs) if isinstance(axs, (list, tuple, np.ndarray)) else [axs]
    single = len(axs) == 1
    thr = crosstalk_threshold(log)
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
    axs[0].set_title(f"(a) sonars of copter {copter}: readings (clamped to [{lo:g}, {hi:g}] m) "
                     "vs ideal distance", fontsize=10)
    axs[0].legend(handles=handles, loc="upper left", fontsize=7, ncol=len(handles), framealpha=0.85)


def _plot_ranging_panel(a, log, max_points: int) -> None:
    """Ranging reading (m) against true distance (m) of all ordered pairs, at most ``max_points`` dots."""
    n = np.asarray(log.ranging).shape[1]
    x, y = ranging_vs_truth(log)
    max_range = float(log_config(log, "ranging", "max_range", 2.5))
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
    edges = np.linspace(0.0, max_range, 26)  # the bins end at max_range: readings beyond are in none
    cx, mu, sd = binned_mean_std(x, y, edges, 30)
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
    fig, axes = sensor_axes(ax, panels, imu_errors="imu_acc_ideal" in extras or "imu_gyro_ideal" in extras)
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
