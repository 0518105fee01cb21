"""Numbers behind the figures of :mod:`finkensim.viz`: no plotting, no matplotlib.

* trajectories: :func:`trajectory_arrays` (a Trajectory or a FlightLog as plain arrays),
  :func:`peak_deflection_index`, :func:`plate_distances`;
* sensors: the simulator's config recorded in a log (:func:`log_config`), sonar cross-talk
  (:func:`crosstalk_threshold`, :func:`sonar_crosstalk_events`), virtual ranging against the
  true distances (:func:`ranging_vs_truth`);
* binned statistics of scattered (x, y) samples (:func:`binned_median`, :func:`binned_mean_std`).

``traj`` arguments accept a :class:`~finkensim.world.Trajectory` (shapes (T, B, ...)) or a
:class:`~finkensim.flightlog.FlightLog` carrying the ``wall_theta`` extra written by
:func:`finkensim.scenario.simulate_flight`; ``log`` arguments any FlightLog.
"""
from __future__ import annotations

from typing import Any, Iterator

import numpy as np

from .arena import Arena

__all__ = [
    "trajectory_arrays",
    "peak_deflection_index",
    "plate_distances",
    "log_config",
    "crosstalk_threshold",
    "sonar_crosstalk_events",
    "ranging_vs_truth",
    "bins_with_samples",
    "binned_median",
    "binned_mean_std",
]


# ------------------------------------------------------------------------------------------
# trajectories and walls
# ------------------------------------------------------------------------------------------

def trajectory_arrays(traj: Any, env: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t (T,) s, pose (T, B', N, 3) m, m, rad, theta (T, B', S) rad) from a Trajectory or a FlightLog.

    ``env``: an environment index, a list/slice of them, or None for all (a FlightLog has one
    environment, B' = 1).
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
    _, _, theta = trajectory_arrays(traj, env)
    total = np.sum(np.sin(theta[:, 0]), axis=1)
    return int(np.argmax(total)) if total.size else 0


def plate_distances(arena: Arena, pose: np.ndarray, radius: float) -> np.ndarray:
    """Distance (m) from each plate's rest line to the nearest copter body, as the wall model uses it.

    pose (..., N, 2 or 3) m → (..., S) m; ``radius`` is the copter radius in m.
    """
    from .kernels.geometry import segment_copter_distances

    pose = np.asarray(pose, dtype=float)
    lead = pose.shape[:-2]
    flat = np.ascontiguousarray(pose.reshape((-1,) + pose.shape[-2:])[..., :2])
    d = segment_copter_distances(arena.seg_a, arena.seg_b, flat, float(radius))
    return d.reshape(lead + (arena.n_plates,))


# ------------------------------------------------------------------------------------------
# sensors
# ------------------------------------------------------------------------------------------

def log_config(log: Any, section: str, key: str, default: Any) -> Any:
    """A config value recorded in ``log.meta["config"]`` (written by simulate_flight), else ``default``."""
    cfg = (getattr(log, "meta", None) or {}).get("config") or {}
    try:
        return cfg[section][key]
    except (KeyError, TypeError):
        return default


def crosstalk_threshold(log: Any) -> float:
    """How much shorter than the ideal echo a sonar reading must be to count as cross-talk (m):
    5 σ of the configured error (at least 0.1 m). The Rayleigh term alone exceeds this with
    probability < 1e-6 (R − s > 5σ needs R > 5.66σ)."""
    return max(0.1, 5.0 * float(log_config(log, "sonar", "sigma", 0.05)))


def sonar_crosstalk_events(log: Any) -> np.ndarray | None:
    """Boolean (T, N, S): sonar readings far shorter than the ideal echo (cross-talk, see
    :func:`crosstalk_threshold`), or None when the log has no sonar or no ``ultrasonic_ideal`` extra.

    The ideal echo (m) is clamped to the sonar's [min_range, max_range] first (from the config
    in ``log.meta``, default [0.2, 3.0] m)."""
    u = getattr(log, "ultrasonic", None)
    ideal = (getattr(log, "extras", None) or {}).get("ultrasonic_ideal")
    if u is None or ideal is None:
        return None
    lo = float(log_config(log, "sonar", "min_range", 0.2))
    hi = float(log_config(log, "sonar", "max_range", 3.0))
    return np.asarray(u) < np.clip(np.asarray(ideal), lo, hi) - crosstalk_threshold(log)


def ranging_vs_truth(log: Any) -> tuple[np.ndarray, np.ndarray]:
    """(true, reading): (M,) true centre distances (m, from the poses, unclipped) and the (M,)
    virtual-ranging readings (m) of every ordered pair of distinct copters at every sample
    (T · N · (N − 1) pairs, sample-major), both finite (pairs with a NaN are left out)."""
    pose = np.asarray(log.pose)
    r = np.asarray(log.ranging)
    n = r.shape[1]
    true = np.linalg.norm(pose[:, :, None, :2] - pose[:, None, :, :2], axis=-1)  # (T, N, N), unclipped
    off = ~np.eye(n, dtype=bool)
    x = true[:, off].ravel()
    y = r[:, off].ravel()
    ok = np.isfinite(x) & np.isfinite(y)
    return x[ok], y[ok]


# ------------------------------------------------------------------------------------------
# binned statistics
# ------------------------------------------------------------------------------------------

def bins_with_samples(x: np.ndarray, edges: np.ndarray, min_count: int) -> Iterator[tuple[float, np.ndarray]]:
    """(bin centre, (M,) bool selection of ``x``) for every bin [edges[k], edges[k+1]) holding at
    least ``min_count`` of the (M,) values ``x``; values outside [edges[0], edges[-1]) are in no bin."""
    which = np.digitize(x, edges) - 1
    for k in range(len(edges) - 1):
        sel = which == k
        if np.count_nonzero(sel) >= min_count:
            yield 0.5 * (edges[k] + edges[k + 1]), sel


def binned_median(x: np.ndarray, y: np.ndarray, edges: np.ndarray, min_count: int) -> tuple[list, list]:
    """(centres, medians): the median of the (M,) ``y`` in each bin of the (M,) ``x`` (see
    :func:`bins_with_samples`); units those of ``x`` and ``y``."""
    centres, medians = [], []
    for centre, sel in bins_with_samples(x, edges, min_count):
        centres.append(centre)
        medians.append(np.median(y[sel]))
    return centres, medians


def binned_mean_std(x: np.ndarray, y: np.ndarray, edges: np.ndarray, min_count: int) -> tuple[list, list, list]:
    """(centres, means, stds): mean and standard deviation of the (M,) ``y`` in each bin of the
    (M,) ``x`` (see :func:`bins_with_samples`); units those of ``x`` and ``y``."""
    centres, means, stds = [], [], []
    for centre, sel in bins_with_samples(x, edges, min_count):
        centres.append(centre)
        means.append(float(np.mean(y[sel])))
        stds.append(float(np.std(y[sel])))
    return centres, means, stds
