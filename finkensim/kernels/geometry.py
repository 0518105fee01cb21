"""Planar geometry kernels (numba). All lengths in metres, points as (x, y).

Scalar helpers are ``inline='always'`` so sensor and world kernels can call them inside
their own loops; the batched kernels loop over the leading environment axis with
``prange``. Each has a plain NumPy twin in ``tests/naive/geometry.py``.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

INF = np.inf


@njit(cache=True, inline="always")
def point_segment_distance(px, py, ax, ay, bx, by):
    """Distance from point P to segment AB (m). A degenerate segment (A = B) is a point."""
    abx = bx - ax
    aby = by - ay
    denom = abx * abx + aby * aby
    if denom > 0.0:
        s = ((px - ax) * abx + (py - ay) * aby) / denom
        s = min(1.0, max(0.0, s))
    else:
        s = 0.0
    dx = px - (ax + s * abx)
    dy = py - (ay + s * aby)
    return np.sqrt(dx * dx + dy * dy)


@njit(cache=True, inline="always")
def ray_segment(ox, oy, dx, dy, ax, ay, bx, by):
    """Distance along the unit ray O + t·D (t ≥ 0) to segment AB; ``inf`` if it misses or is parallel."""
    ex = bx - ax
    ey = by - ay
    den = dx * ey - dy * ex
    if den == 0.0:
        return INF
    wx = ax - ox
    wy = ay - oy
    t = (wx * ey - wy * ex) / den
    s = (wx * dy - wy * dx) / den
    if t >= 0.0 and 0.0 <= s <= 1.0:
        return t
    return INF


@njit(cache=True, inline="always")
def ray_circle(ox, oy, dx, dy, cx, cy, r):
    """Distance along the unit ray O + t·D (t ≥ 0) to the first crossing of circle (C, r); ``inf`` if none.

    An origin inside the circle returns the exit distance (the ray still meets the rim).
    """
    fx = ox - cx
    fy = oy - cy
    b = fx * dx + fy * dy
    c = fx * fx + fy * fy - r * r
    disc = b * b - c
    if disc < 0.0:
        return INF
    sq = np.sqrt(disc)
    t = -b - sq
    if t >= 0.0:
        return t
    t = -b + sq
    if t >= 0.0:
        return t
    return INF


@njit(cache=True, parallel=True)
def pairwise_distances(pos):
    """Centre distances between copters. pos (B, N, 2) m → (B, N, N) m, symmetric, zero diagonal."""
    B, N, _ = pos.shape
    out = np.empty((B, N, N))
    for b in prange(B):
        for i in range(N):
            out[b, i, i] = 0.0
            for j in range(i + 1, N):
                dx = pos[b, i, 0] - pos[b, j, 0]
                dy = pos[b, i, 1] - pos[b, j, 1]
                d = np.sqrt(dx * dx + dy * dy)
                out[b, i, j] = d
                out[b, j, i] = d
    return out


@njit(cache=True, inline="always")
def nearest_body_distance_env(seg_a, seg_b, pos_b, radius, out_row):
    """For one environment: per segment, the distance to the nearest copter body (m, ≥ 0).

    seg_a, seg_b (S, 2); pos_b (N, 2); writes out_row (S,). No copters → ``inf``.
    """
    S = seg_a.shape[0]
    N = pos_b.shape[0]
    for s in range(S):
        best = INF
        for n in range(N):
            d = point_segment_distance(pos_b[n, 0], pos_b[n, 1], seg_a[s, 0], seg_a[s, 1], seg_b[s, 0], seg_b[s, 1])
            if d < best:
                best = d
        out_row[s] = max(0.0, best - radius)


@njit(cache=True, parallel=True)
def segment_copter_distances(seg_a, seg_b, pos, radius):
    """Distance from each segment to the nearest copter body (point-to-segment minus radius, ≥ 0).

    seg_a, seg_b (S, 2) m; pos (B, N, 2) m; radius m → (B, S) m.
    """
    B = pos.shape[0]
    S = seg_a.shape[0]
    out = np.empty((B, S))
    for b in prange(B):
        nearest_body_distance_env(seg_a, seg_b, pos[b], radius, out[b])
    return out
