"""Plain-NumPy references of the planar geometry kernels (``finkensim.kernels.geometry``), for tests only.

Written from the definitions, not from the kernels: projection onto a segment, a 2x2 linear
solve for ray/segment, the quadratic for ray/circle, broadcasting for pairwise distances.
"""
from __future__ import annotations

import numpy as np


def point_segment_distance(p, a, b):
    """Distance from points p to segments ab; all (..., 2), broadcast. A = B is a point."""
    p, a, b = (np.asarray(v, dtype=float) for v in (p, a, b))
    ab = b - a
    denom = np.sum(ab * ab, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.sum((p - a) * ab, axis=-1) / denom
    s = np.where(denom > 0.0, np.clip(s, 0.0, 1.0), 0.0)  # parameter of the closest point on AB
    closest = a + s[..., None] * ab
    return np.linalg.norm(p - closest, axis=-1)


def ray_segment(o, d, a, b):
    """Distance t >= 0 along the unit ray o + t d to segment ab, or inf (miss or parallel). Scalars in, float out.

    Solves o + t d = a + s (b - a) for (t, s) with Cramer's rule; a hit needs t >= 0 and 0 <= s <= 1.
    """
    o, d, a, b = (np.asarray(v, dtype=float) for v in (o, d, a, b))
    e = b - a
    w = a - o

    def cross(u, v):
        return u[0] * v[1] - u[1] * v[0]

    den = cross(d, e)  # zero: ray and segment are parallel (collinear counts as a miss)
    if abs(den) < 1e-300:  # also a segment shorter than 1e-300 m: its numerators would underflow to a false t = 0
        return np.inf
    with np.errstate(over="ignore"):  # nearly parallel: t, s overflow to inf, as in the kernel
        t = cross(w, e) / den  # distance along the ray
        s = cross(w, d) / den  # position along the segment, 0 at a and 1 at b
    return float(t) if (t >= 0.0 and 0.0 <= s <= 1.0) else np.inf


def ray_circle(o, d, c, r):
    """Distance t >= 0 along the unit ray o + t d to the first crossing of the circle (c, r), or inf.

    |o + t d - c|² = r² is t² + 2 b t + (|o - c|² - r²) = 0 with b = (o - c)·d. From inside the
    circle the first crossing ahead is the exit.
    """
    o, d, c = (np.asarray(v, dtype=float) for v in (o, d, c))
    f = o - c
    b = f[0] * d[0] + f[1] * d[1]
    q = f[0] * f[0] + f[1] * f[1] - r * r
    disc = b * b - q
    if disc < 0.0:
        return np.inf
    roots = (-b - np.sqrt(disc), -b + np.sqrt(disc))
    ahead = [t for t in roots if t >= 0.0]
    return float(ahead[0]) if ahead else np.inf


def pairwise_distances(pos):
    """(B, N, 2) -> (B, N, N) centre distances by broadcasting."""
    pos = np.asarray(pos, dtype=float)
    diff = pos[:, :, None, :] - pos[:, None, :, :]
    return np.sqrt(np.sum(diff * diff, axis=-1))


def segment_copter_distances(seg_a, seg_b, pos, radius):
    """(S, 2), (S, 2), (B, N, 2), r -> (B, S): distance from each segment to the nearest copter body, >= 0.

    No copters gives inf.
    """
    pos = np.asarray(pos, dtype=float)
    B, N = pos.shape[:2]
    S = np.asarray(seg_a).shape[0]
    if N == 0:
        return np.full((B, S), np.inf)
    # (B, N, S): every copter against every segment
    d = point_segment_distance(pos[:, :, None, :], np.asarray(seg_a)[None, None], np.asarray(seg_b)[None, None])
    return np.maximum(0.0, d.min(axis=1) - radius)
