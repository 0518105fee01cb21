"""Ray casting against the arena: displaced wall plates, the rigid net backstop, and copter circles.

One implementation serves every caller: the sonar sensor (:mod:`finkensim.sensors.sonar`), the
gap replay (:mod:`finkensim.gap.model.replay`) and the benchmarks. Rays are unit directions from an origin
(m); a hit is the distance t (m) along the ray and a kind (``HIT_WALL`` plate or net, ``HIT_COPTER``).

- :func:`cast_ray` — the full search over every plate, the net and every other copter;
- :func:`cast_ray_culled` — the same result bit for bit, testing only the plates the ray can reach
  before the net (see the comment block below for why it is exact); needs :func:`plate_bands` once per
  environment and step.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .geometry import ray_circle, ray_segment

__all__ = ["HIT_NONE", "HIT_WALL", "HIT_COPTER", "box_exit", "cast_ray", "cast_ray_culled", "plate_bands",
           "copter_hits"]

HIT_NONE = 0
HIT_WALL = 1
HIT_COPTER = 2


@njit(cache=True, inline="always")
def box_exit(ox, oy, dx, dy, width, length):
    """Distance along the unit ray O + t·D to the boundary of [0, W] × [0, L] (≥ 0; the net backstop)."""
    t = np.inf
    if dx > 0.0:
        t = min(t, (width - ox) / dx)
    elif dx < 0.0:
        t = min(t, -ox / dx)
    if dy > 0.0:
        t = min(t, (length - oy) / dy)
    elif dy < 0.0:
        t = min(t, -oy / dy)
    return max(t, 0.0)



@njit(cache=True, inline="always")
def copter_hits(ray, self_n, pos_b, radius, best, kind, cand, n_cand):
    """Nearest of (best, kind) and the hits of the unit ray ``ray`` = (ox, oy, dx, dy) (origin m, unit direction) on
    the copter circles except ``self_n``.

    pos_b (N, 2) m centres, radius m; the copters tested: all when ``n_cand`` < 0, else cand[:n_cand] (int64
    indices, e.g. those a cell grid found near the ray's origin). Returns (t m, kind): the minimum over the
    copters, so the order they are tested in does not matter (a tie keeps the earlier hit, of equal t).
    """
    # the nearest circle first, then one comparison with (best, kind): the same value and kind as comparing
    # circle by circle (the first minimum of [best, t_1, t_2, …] either way, −0 before +0 included), and the loop
    # carries no branch on the data (see ray_circle)
    ox, oy, dx, dy = ray
    M = pos_b.shape[0] if n_cand < 0 else n_cand
    nearest = np.inf
    for c in range(M):
        m = c if n_cand < 0 else cand[c]
        t = ray_circle(ox, oy, dx, dy, pos_b[m, 0], pos_b[m, 1], radius)
        t = np.inf if m == self_n else t
        nearest = t if t < nearest else nearest
    if nearest < best:
        best = nearest
        kind = HIT_COPTER
    return best, kind


@njit(cache=True, inline="always")
def cast_ray(ray, self_n, pos_b, radius, walls, cand, n_cand):
    """Nearest hit of one unit ray ``ray`` = (ox, oy, dx, dy) (origin m, unit direction) for one environment:
    (t m, hit kind HIT_WALL / HIT_COPTER).

    walls = (pa, pb, width, length): the plates pa, pb (S, 2) m first, then the boundary of [0, width] × [0, length]
    m, then the copter circles (centres pos_b (N, 2) m, ``radius`` m) except ``self_n`` (all when ``n_cand`` < 0,
    else cand[:n_cand], see :func:`copter_hits`); a tie keeps the earlier object.
    """
    ox, oy, dx, dy = ray
    pa, pb, width, length = walls
    best = np.inf
    kind = HIT_NONE
    for s in range(pa.shape[0]):
        t = ray_segment(ox, oy, dx, dy, pa[s, 0], pa[s, 1], pb[s, 0], pb[s, 1])
        if t < best:
            best = t
            kind = HIT_WALL
    t = box_exit(ox, oy, dx, dy, width, length)
    if t < best:
        best = t
        kind = HIT_WALL
    return copter_hits(ray, self_n, pos_b, radius, best, kind, cand, n_cand)


# ---------------------------------------------------------------------------------------------
# culled raycast: only the plates a ray can reach
#
# Walls are straight, axis-aligned rows of plates (:class:`~finkensim.arena.Arena`: south, east, north,
# west, n = S/4 plates each, plate k of a wall inside pitch cell k along the wall). A displaced plate
# stays on a line parallel to its wall, so every plate of wall w lies in the band between the smallest
# and the largest of the wall's plate lines (computed from the displaced plates themselves, per
# environment: :func:`plate_bands`). A ray from inside the rectangle ends at the net after t_box
# (:func:`box_exit`), and a plate changes the result only if its computed hit distance is < t_box (a
# plate at exactly t_box gives the same distance and the same kind as the net). So for each wall the
# ray's stretch t ∈ [0, t_box] inside that wall's band (widened by eps) gives an interval along the wall
# (widened by eps), and only the plates whose pitch cells overlap it are tested, in increasing index
# order like the full search. Equal to :func:`cast_ray` bit for bit:
#
# - the plates are axis-aligned (checked: both ends share the wall-normal coordinate exactly), so in
#   ray_segment den = −fl(dy·ex) (south/north; dx·ey for east/west) has no cancellation: a computed
#   hit with t ≤ t_box and s ∈ [0, 1] lies within a few ulps · (arena size) of the true intersection,
#   far inside eps = 1e-9 · (1 + W + L) m;
# - each plate's own extent is checked to lie within its pitch cell [k·pitch − eps, (k + 1)·pitch + eps]
#   along its wall, so a hit anywhere in the ray's interval [u0 − eps, u1 + eps] can only be on plates
#   floor((u0 − 2 eps)/pitch) … floor((u1 + 2 eps)/pitch) (the second eps covers the rounding of the
#   cell bounds and of the division, both ≪ eps);
# - the plates left out have computed distance > t_box (or miss), so the minimum, its first occurrence
#   in index order (ties, signed zeros) and the kind (plates and net are both HIT_WALL) are unchanged;
#   the copter circles are then tested exactly as in cast_ray.
# When the layout does not match (any other plate arrangement, NaN) or the sonar is not strictly inside
# the rectangle or the direction is not finite, :func:`cast_ray_culled` runs the full search.


@njit(cache=True, inline="always")
def _cull_eps(width, length):
    """Safety margin (m) of the culled raycast: 1e-9 · (1 + W + L), ~10⁶ times the rounding it covers."""
    return 1e-9 * (1.0 + width + length)


@njit(cache=True, inline="always")
def _wall_band(pa, pb, s0, n, ci, sign, origin, pitch, eps):
    """(ok, lo, hi) for the n plates s0 … s0 + n − 1 of one wall: ci = index of the wall-normal coordinate
    (1: south/north, 0: east/west), along-wall coordinate u = origin + sign · (other coordinate)."""
    ui = 1 - ci
    lo = np.inf
    hi = -np.inf
    for k in range(n):
        s = s0 + k
        c = pa[s, ci]
        ua = origin + sign * pa[s, ui]
        ub = origin + sign * pb[s, ui]
        if not (pb[s, ci] == c and abs(c) < np.inf and abs(ua) < np.inf and abs(ub) < np.inf):
            return False, lo, hi
        u0 = ua if ua < ub else ub
        u1 = ub if ua < ub else ua
        if not (u0 >= k * pitch - eps and u1 <= (k + 1) * pitch + eps):
            return False, lo, hi
        if c < lo:
            lo = c
        if c > hi:
            hi = c
    return True, lo, hi


@njit(cache=True)
def plate_bands(pa, pb, width, length):
    """Per-environment input of :func:`cast_ray_culled` from the displaced plates pa, pb (S, 2) m.

    Returns (ok, lo_s, hi_s, lo_e, hi_e, lo_n, hi_n, lo_w, hi_w): ok says whether the plates follow the
    :class:`~finkensim.arena.Arena` layout (then culling is exact); lo/hi are the smallest and largest
    wall-normal coordinate (y for south/north, x for east/west, m) of each wall's plates.
    """
    S = pa.shape[0]
    n = S // 4
    ok = n > 0 and 4 * n == S and 0.0 < width < np.inf and 0.0 < length < np.inf
    lo_s = hi_s = lo_e = hi_e = lo_n = hi_n = lo_w = hi_w = 0.0
    eps = _cull_eps(width, length)
    for w in range(4 if ok else 0):  # south, east, north, west (one call site: short compile)
        ci = 1 if w % 2 == 0 else 0
        sign = 1.0 if w < 2 else -1.0
        side = width if ci == 1 else length
        ok_w, lo, hi = _wall_band(pa, pb, w * n, n, ci, sign, 0.0 if w < 2 else side, side / n, eps)
        ok = ok and ok_w
        if w == 0:
            lo_s, hi_s = lo, hi
        elif w == 1:
            lo_e, hi_e = lo, hi
        elif w == 2:
            lo_n, hi_n = lo, hi
        else:
            lo_w, hi_w = lo, hi
    return ok, lo_s, hi_s, lo_e, hi_e, lo_n, hi_n, lo_w, hi_w


@njit(cache=True, inline="always")
def _band_cells(ray, wall, t_end, eps):
    """(k0, k1): the pitch cells of one wall the ray can reach for t ∈ [0, t_end] (k1 < k0: none).

    ray = (ox, oy, dx, dy, inv_dx, inv_dy); wall = (n plates, ci wall-normal coordinate index, sign, origin,
    inv_pitch, lo, hi band of the plate lines) — see :func:`cast_ray_culled`.
    """
    ox, oy, dx, dy, inv_dx, inv_dy = ray
    n, ci, sign, origin, inv_pitch, lo, hi = wall
    if ci == 1:
        oc, _, ou, du, inv = oy, dy, ox, dx, inv_dy
    else:
        oc, _, ou, du, inv = ox, dx, oy, dy, inv_dx
    if inv == 0.0:  # parallel to the wall (or |d| < 1e-200: moves < eps along the normal before t_end)
        if oc < lo - eps or oc > hi + eps:
            return 0, -1
        t0 = 0.0
        t1 = t_end
    else:
        ta = (lo - eps - oc) * inv
        tb = (hi + eps - oc) * inv
        t0 = max(0.0, min(ta, tb))
        t1 = min(t_end, max(ta, tb))
        if not (t0 <= t1):
            return 0, -1
    ua = origin + sign * (ou + t0 * du)
    ub = origin + sign * (ou + t1 * du)
    f0 = math.floor((min(ua, ub) - 2.0 * eps) * inv_pitch)
    f1 = math.floor((max(ua, ub) + 2.0 * eps) * inv_pitch)
    if f1 < 0.0 or f0 > n - 1.0:
        return 0, -1
    return 0 if f0 < 0.0 else int(f0), n - 1 if f1 > n - 1.0 else int(f1)


@njit(cache=True, inline="always")
def _wall_run(w, fast, S, ray, bands, width, length, t_end, eps):
    """(first, last) plate index of run w of :func:`cast_ray_culled`: the cells wall w's band allows (``fast``),
    else every plate (one run)."""
    if not fast:
        return 0, S - 1
    ok, lo_s, hi_s, lo_e, hi_e, lo_n, hi_n, lo_w, hi_w = bands
    n = S // 4
    if w == 0:  # south, east, north, west: plates in increasing index order
        wall = (n, 1, 1.0, 0.0, n / width, lo_s, hi_s)
    elif w == 1:
        wall = (n, 0, 1.0, 0.0, n / length, lo_e, hi_e)
    elif w == 2:
        wall = (n, 1, -1.0, width, n / width, lo_n, hi_n)
    else:
        wall = (n, 0, -1.0, length, n / length, lo_w, hi_w)
    k0, k1 = _band_cells(ray, wall, t_end, eps)
    return w * n + k0, w * n + k1


@njit(cache=True, inline="always")
def cast_ray_culled(ray, self_n, pos_b, radius, walls, bands, cand, n_cand):
    """:func:`cast_ray` testing only the plates the ray can reach before the net (same result, bit for bit).

    ``bands`` = :func:`plate_bands` (pa, pb, width, length) of ``walls`` = (pa, pb, width, length), computed once per environment and step. When the
    layout or the ray does not allow culling, every plate is tested, as in :func:`cast_ray`.

    One path through the arrays (the plate runs, then the copters): with a separate fallback path, numba (0.68,
    whose O3 pipeline merges the reference-count decrements of the two paths before pruning them) kept an atomic
    increment and decrement of each array argument per ray.
    """
    ox, oy, dx, dy = ray
    pa, pb, width, length = walls
    ok = bands[0]
    S = pa.shape[0]
    t_box = box_exit(ox, oy, dx, dy, width, length)
    # a unit direction (the culling margins assume |d| = 1) from strictly inside the rectangle
    fast = (ok and 0.0 < ox < width and 0.0 < oy < length and abs(dx) < np.inf and abs(dy) < np.inf
            and abs(dx) + abs(dy) > 0.5 and t_box < np.inf)
    eps = _cull_eps(width, length)
    t_end = t_box + eps
    # the band crossings only select plates (the distances come from ray_segment), so 1/d is fine here;
    # 0 marks a ray (numerically) parallel to the wall
    inv_dx = 1.0 / dx if abs(dx) >= 1e-200 else 0.0
    inv_dy = 1.0 / dy if abs(dy) >= 1e-200 else 0.0
    slopes = (ox, oy, dx, dy, inv_dx, inv_dy)
    best = np.inf
    for w in range(4 if fast else 1):
        first, last = _wall_run(w, fast, S, slopes, bands, width, length, t_end, eps)
        for s in range(first, last + 1):
            t = ray_segment(ox, oy, dx, dy, pa[s, 0], pa[s, 1], pb[s, 0], pb[s, 1])
            if t < best:
                best = t
    if t_box < best:  # the net
        best = t_box
    # a plate or the net when anything was hit (culled: the net always is)
    kind = HIT_WALL if best < np.inf else HIT_NONE
    return copter_hits(ray, self_n, pos_b, radius, best, kind, cand, n_cand)
