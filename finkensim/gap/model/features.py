"""Context features of logged readings (the location table's columns) and sonar channel names.

All positions in m, times in s; K samples, N copters.
"""
from __future__ import annotations

import numpy as np

SONAR_NAMES = {0.0: "front", 90.0: "left", 180.0: "back", -90.0: "right"}


def sonar_channel_names(yaw_rad) -> list[str]:
    """Names of sonars from their mounting yaw: front/left/back/right within 10°, else 'sonar<k>'."""
    names = []
    for k, y in enumerate(np.degrees(np.asarray(yaw_rad, dtype=float))):
        y = (y + 180.0) % 360.0 - 180.0
        best = min(SONAR_NAMES, key=lambda a: abs((y - a + 180.0) % 360.0 - 180.0))
        names.append(SONAR_NAMES[best] if abs((y - best + 180.0) % 360.0 - 180.0) <= 10.0 else f"sonar{k}")
    return names


def range_rate(values, dt):
    """d/dt along axis 0 (central differences), values (K, ...) sampled every dt."""
    if values.shape[0] < 3:
        return np.zeros_like(values)
    return np.gradient(values, dt, axis=0)


def range_rate_at(values, f):
    """d/dt along axis 0 of values (K, ...) at flight f's used samples: :func:`range_rate` with the common step when
    the samples are evenly strided, else central differences over their times (a log whose slow radio links add
    samples between the strided ones)."""
    K = f.samples.size
    steps = np.diff(f.samples)
    if K < 3 or np.all(steps == steps[0]):
        return range_rate(values, f.dt * max(1, int(np.median(steps))) if K > 1 else f.dt)
    return np.gradient(values, f.t[f.samples], axis=0)



def append_identity(cols, f, y, sel, sample_pos, copter, channel):
    """Append the identity columns of the selected readings y[sel] of flight f to ``cols``.

    sample_pos, copter, channel: index arrays shaped like y (sample_pos indexes ``f.samples``).
    """
    cols["y"].append(y[sel])
    cols["flight"].append(np.full(int(np.count_nonzero(sel)), f.index))
    cols["sample"].append(sample_pos[sel])
    cols["time"].append(f.samples[sample_pos[sel]])
    cols["copter"].append(copter[sel])
    cols["channel"].append(channel[sel])
    cols["sec"].append(f.t[f.samples[sample_pos[sel]]] - f.t[0])


def wall_distance(P, arena):
    """(..., ) distance (m) of copter centres P (..., 2) to the nearest wall line."""
    return np.minimum(np.minimum(P[..., 0], arena.width - P[..., 0]), np.minimum(P[..., 1], arena.length - P[..., 1]))


def nearest_neighbor(P):
    """(K, N) distance from each copter centre to the nearest other one (inf alone)."""
    d = np.sqrt(((P[:, :, None, :] - P[:, None, :, :]) ** 2).sum(-1))
    n = P.shape[1]
    d[:, np.arange(n), np.arange(n)] = np.inf
    return d.min(axis=-1) if n > 1 else np.full(P.shape[:2], np.inf)


def speed(f) -> np.ndarray:
    """(K, N) speed (m/s) at the used samples from central differences of the logged positions."""
    v = np.gradient(f.pos, f.t, axis=0)
    return np.sqrt((v[f.samples] ** 2).sum(-1))
