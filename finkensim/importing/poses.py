"""Tracked poses between their samples: each copter's x, y interpolated linearly, yaw unwrapped first.

Tracking systems record each copter at its own times (100-250 Hz, with jitter and dropouts); the flight log
needs every copter at the common sample times. :class:`TrackedPoses` interpolates each copter's x and y linearly
in time and its yaw linearly after ``np.unwrap`` (so a turn through ±π is not a spin the other way), then wraps
yaw back to [-π, π).
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["TrackedPoses", "wrap_angle"]


def wrap_angle(a):
    """Angles (rad, any shape) wrapped to [-π, π)."""
    return (np.asarray(a) + math.pi) % (2 * math.pi) - math.pi


class TrackedPoses:
    """Interpolated poses of a checked recording's tracking (:class:`~.recording.CheckedRecording`).

    Attributes: n_copters; span (t_lo, t_hi) s, the times at which every copter is tracked; rate (Hz), the median
    tracking rate over copters; longest_gap (s), the longest interval between two poses of one copter; has_z: the
    tracking has heights (:meth:`heights`).
    """

    def __init__(self, ch):
        self.n_copters = len(ch.copters)
        bounds = np.searchsorted(ch.tr_copter, np.arange(self.n_copters + 1))
        self._t, self._x, self._y, self._yaw, self._z = [], [], [], [], []
        self.has_z = getattr(ch, "tr_z", None) is not None
        gaps, rates = [], []
        for n in range(self.n_copters):
            a, b = bounds[n], bounds[n + 1]
            t = ch.tr_t[a:b]
            self._t.append(t)
            self._x.append(ch.tr_x[a:b])
            self._y.append(ch.tr_y[a:b])
            self._yaw.append(np.unwrap(ch.tr_yaw[a:b]))
            if self.has_z:
                self._z.append(ch.tr_z[a:b])
            d = np.diff(t)
            gaps.append(float(d.max()) if d.size else math.inf)
            rates.append(1.0 / float(np.median(d)) if d.size else math.nan)
        self.span = (max(t[0] for t in self._t), min(t[-1] for t in self._t))
        self.rate = float(np.nanmedian(rates)) if self.n_copters else math.nan
        self.longest_gap = max(gaps) if gaps else math.inf
        self.counts = [int(t.size) for t in self._t]

    def copter(self, n: int, times) -> np.ndarray:
        """Pose of copter n at ``times`` (K,) s (inside its tracking): (K, 3) x, y (m), yaw (rad, in [-π, π))."""
        times = np.asarray(times, dtype=np.float64)
        out = np.empty(times.shape + (3,))
        out[..., 0] = np.interp(times, self._t[n], self._x[n])
        out[..., 1] = np.interp(times, self._t[n], self._y[n])
        out[..., 2] = wrap_angle(np.interp(times, self._t[n], self._yaw[n]))
        return out

    def heights(self, times) -> np.ndarray | None:
        """Heights (K, N) m of every copter at ``times`` (K,) s, interpolated linearly; None without a z column."""
        if not self.has_z:
            return None
        times = np.asarray(times, dtype=np.float64)
        return np.stack([np.interp(times, self._t[n], self._z[n]) for n in range(self.n_copters)], axis=1)

    def all(self, times) -> np.ndarray:
        """Poses of every copter at ``times`` (K,) s: (K, N, 3)."""
        times = np.asarray(times, dtype=np.float64)
        return np.stack([self.copter(n, times) for n in range(self.n_copters)], axis=1)
