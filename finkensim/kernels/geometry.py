"""Planar geometry kernels (numba). All lengths in metres, points as (x, y).

Scalar helpers are ``inline='always'`` so sensor and world kernels can call them inside
their own loops; the batched kernels loop over the leading environment axis with
``prange``. Each has a plain NumPy reference in ``tests/naive/geometry.py``.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange
from .outline import python_function

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


#: |D × AB| below this counts as parallel (D a unit vector: AB shorter than 1e-300 m or parallel to the ray)
TINY_DENOMINATOR = 1e-300


@njit(cache=True, inline="always")
def ray_segment(ox, oy, dx, dy, ax, ay, bx, by, selects=True):
    """Distance along the unit ray O + t·D (t ≥ 0) to segment AB; ``inf`` if it misses or is parallel.

    ``selects`` as in :func:`ray_circle` (the same result either way): True computes both quotients and selects
    (whether a ray meets a plate is a coin toss for the branch predictor; the parallel case divides by 1 instead of
    0 and is then discarded), False returns early on a parallel segment and branches on the hit test.
    """
    ex = bx - ax
    ey = by - ay
    den = dx * ey - dy * ex
    # parallel, or a segment so short (|AB| < 1e-300 m) that the numerators below underflow to a false hit at t = 0
    parallel = abs(den) < TINY_DENOMINATOR
    if not selects and parallel:
        return INF
    q = 1.0 if parallel else den
    wx = ax - ox
    wy = ay - oy
    t = (wx * ey - wy * ex) / q
    s = (wx * dy - wy * dx) / q
    if not selects:
        if t >= 0.0 and 0.0 <= s <= 1.0:
            return t
        return INF
    hit = (t >= 0.0) & (s >= 0.0) & (s <= 1.0) & (not parallel)
    return t if hit else INF


@njit(cache=True, inline="always")
def ray_circle(ox, oy, dx, dy, cx, cy, r, selects=True):
    """Distance along the unit ray O + t·D (t ≥ 0) to the first crossing of circle (C, r); ``inf`` if none.

    An origin inside the circle returns the exit distance (the ray still meets the rim).

    ``selects`` (a constant at each call site; the result is the same bit for bit) chooses the machine code:
    True computes both crossings (the square root of a negative discriminant is NaN and then discarded) and selects
    the answer; False returns early when the ray's line misses the circle. Whether a sonar ray's line passes
    within r of another copter is a coin toss in a swarm that gathers or presses against a wall, and there the
    early return spent more time in mispredicted branches than in arithmetic (``benchmarks.breakdown``: ideal sonar
    raycast of 10 copters 5.3 → 4.3 µs per environment step with :func:`~finkensim.kernels.raycast.copter_hits`);
    among copters spread over the arena nearly every line misses, the branch is predictable and the skipped square
    root is the saving (the comparison workload of ``benchmarks.workloads``: 18 % faster with branches).
    """
    fx = ox - cx
    fy = oy - cy
    b = fx * dx + fy * dy
    c = fx * fx + fy * fy - r * r
    disc = b * b - c
    if not selects:
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
    sq = np.sqrt(disc)
    near = -b - sq
    far = -b + sq
    t = far if far >= 0.0 else INF
    t = near if near >= 0.0 else t
    return INF if disc < 0.0 else t


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


# the brute force as a called function: the rare fallback of nearest_body_distance_within_env
_nearest_body_distance_fn = njit(cache=True)(python_function(nearest_body_distance_env))

@njit(cache=True, inline="always")
def _wall_line(seg_a, seg_b, s0, n, ci, sign):
    """(ok, c, u_first, u_last, scale) of the n segments s0 … s0 + n − 1 of one wall.

    ok: every segment lies on the line {coordinate ci = c} (both ends exactly) and the along-wall
    intervals [lo_k, hi_k] (u = sign · other coordinate) are finite and ordered (lo and hi nondecreasing
    in k). u_first = lo_0, u_last = hi_{n−1}; scale = |c| + |u_first| + |u_last|.
    """
    ui = 1 - ci
    c = seg_a[s0, ci]
    lo_prev = -np.inf
    hi_prev = -np.inf
    u_first = 0.0
    u_last = 0.0
    for k in range(n):
        s = s0 + k
        ua = sign * seg_a[s, ui]
        ub = sign * seg_b[s, ui]
        if not (seg_a[s, ci] == c and seg_b[s, ci] == c and abs(c) < 1e300 and abs(ua) < 1e300
                and abs(ub) < 1e300):
            return False, c, u_first, u_last, 0.0
        lo = ua if ua < ub else ub
        hi = ub if ua < ub else ua
        if not (lo >= lo_prev and hi >= hi_prev):
            return False, c, u_first, u_last, 0.0
        if k == 0:
            u_first = lo
        lo_prev = lo
        hi_prev = hi
    u_last = hi_prev
    return True, c, u_first, u_last, abs(c) + abs(u_first) + abs(u_last)


@njit(cache=True)
def nearest_body_distance_within_env(seg_a, seg_b, pos_b, radius, cutoff, out_row):
    """:func:`nearest_body_distance_env` where it is below ``cutoff``, ``inf`` elsewhere (m).

    out_row[s] is bit for bit the value of :func:`nearest_body_distance_env` when that value is < cutoff,
    and ``inf`` when it is ≥ cutoff — all the hinge model needs with cutoff = max(threshold, lever): a
    plate that far is inactive and uncapped either way. For the Arena layout (see :func:`_wall_line`;
    anything else, or a copter position that is not finite, runs the brute force) each copter tests
    only the segments of a wall near its projection on it:

    *Lemma.* For a point P and a straight wall made of consecutive segments on one line, ordered
    along it, the distance to segment k is sqrt(h² + g_k²), with h the distance from P to the line and
    g_k the distance along the line from P's projection Q to the interval of segment k (0 if Q lies in
    it). g_k is 0 on the segment containing Q (or, if Q lies beyond a wall end, smallest on the end
    segment) and nondecreasing moving away from it in either direction, because the intervals are
    ordered: for k' < k ≤ k0, hi_k' ≤ hi_k, so g_k' ≥ Q − hi_k' ≥ Q − hi_k (and symmetrically above).
    Hence the nearest point of the wall to P is on the segment containing the projection or at a wall
    end, and once Q − hi_k (or lo_k − Q) reaches the cut-off radius every further segment in that
    direction is at least that far. So per copter and wall: skip the wall if h ≥ cut, else start at the
    segment k0 near Q and walk outwards until the along-wall gap reaches cut, testing segments with
    h² + g² < cut² by the exact point_segment_distance. (Any start k0 is correct; the one holding Q
    tests the fewest.)

    cut = cutoff + radius + eps, eps = 1e-9 · (1 + |P| + wall coordinates): every copter whose exact
    distance minus radius is < cutoff passes the bounds (their rounding is ~10⁻¹⁵ · scale), so every
    segment whose exact value is < cutoff gets the same minimum over the same nearest copter (copters
    left out are farther), in the same copter order; the result is then max(0, best − radius) as in
    the brute force, and inf where that is ≥ cutoff.

    Not ``inline="always"``: compiled once and called (inlining it at numba's IR level into every kernel
    that inlines ``world.step_env`` costs seconds of cold compile time each).
    """
    S = seg_a.shape[0]
    N = pos_b.shape[0]
    n = S // 4
    ok = n > 0 and 4 * n == S and 0.0 <= cutoff < 1e300 and 0.0 <= radius < 1e300
    c_s = c_e = c_n = c_w = f_s = f_e = f_n = f_w = l_s = l_e = l_n = l_w = 0.0
    wall_scale = 0.0
    for w in range(4 if ok else 0):  # south, east, north, west (one call site: short compile)
        ci = 1 if w % 2 == 0 else 0
        sign = 1.0 if w < 2 else -1.0
        ok_w, c, u_first, u_last, sc = _wall_line(seg_a, seg_b, w * n, n, ci, sign)
        ok = ok and ok_w
        wall_scale = max(wall_scale, sc)
        if w == 0:
            c_s, f_s, l_s = c, u_first, u_last
        elif w == 1:
            c_e, f_e, l_e = c, u_first, u_last
        elif w == 2:
            c_n, f_n, l_n = c, u_first, u_last
        else:
            c_w, f_w, l_w = c, u_first, u_last
    for m in range(N):
        ok = ok and abs(pos_b[m, 0]) < 1e300 and abs(pos_b[m, 1]) < 1e300
    if not ok:  # another layout, or a copter that is not a finite point: brute force
        _nearest_body_distance_fn(seg_a, seg_b, pos_b, radius, out_row)
        for s in range(S):
            if not (out_row[s] < cutoff):
                out_row[s] = INF
        return
    for s in range(S):
        out_row[s] = INF  # the nearest centre distance found so far
    for m in range(N):
        px = pos_b[m, 0]
        py = pos_b[m, 1]
        cut = cutoff + radius + 1e-9 * (1.0 + abs(px) + abs(py) + wall_scale)
        cut2 = cut * cut
        for w in range(4):
            if w == 0:  # south, east, north, west: (wall-normal coordinate, along-wall direction) as _wall_line
                ci, sign, c, u_first, u_last = 1, 1.0, c_s, f_s, l_s
            elif w == 1:
                ci, sign, c, u_first, u_last = 0, 1.0, c_e, f_e, l_e
            elif w == 2:
                ci, sign, c, u_first, u_last = 1, -1.0, c_n, f_n, l_n
            else:
                ci, sign, c, u_first, u_last = 0, -1.0, c_w, f_w, l_w
            pc = py if ci == 1 else px
            q = sign * (px if ci == 1 else py)  # along-wall coordinate of the projection
            h = abs(pc - c)
            if h >= cut:
                continue
            h2 = h * h
            span = u_last - u_first
            f = (q - u_first) / span * n if span > 0.0 else 0.0
            k0 = 0 if not (f > 0.0) else (n - 1 if f >= n - 1.0 else int(f))
            s0 = w * n
            ui = 1 - ci
            # walk k0, k0 − 1, …, 0 (towards the start of the wall), then k0 + 1, …, n − 1
            k = k0
            step = -1
            while True:
                if k < 0:
                    k = k0 + 1
                    step = 1
                if k >= n:
                    break
                s = s0 + k
                ua = sign * seg_a[s, ui]
                ub = sign * seg_b[s, ui]
                lo = ua if ua < ub else ub
                hi = ub if ua < ub else ua
                if (q - hi if step < 0 else lo - q) >= cut:  # this one and all further this way are too far
                    if step > 0:
                        break
                    k = -1
                    continue
                g = max(lo - q, q - hi, 0.0)
                # computed for every segment walked and kept by a select: which copter is nearest to a plate is
                # unpredictable, and the walk stops near the cut-off anyway
                d = point_segment_distance(px, py, seg_a[s, 0], seg_a[s, 1], seg_b[s, 0], seg_b[s, 1])
                nearer = (h2 + g * g < cut2) & (d < out_row[s])
                out_row[s] = d if nearer else out_row[s]
                k += step
    for s in range(S):
        v = max(0.0, out_row[s] - radius)
        out_row[s] = v if v < cutoff else INF


@njit(cache=True, parallel=True)
def segment_copter_distances_within(seg_a, seg_b, pos, radius, cutoff):
    """Batched :func:`nearest_body_distance_within_env`: (B, S) m, exact below ``cutoff``, inf elsewhere."""
    B = pos.shape[0]
    S = seg_a.shape[0]
    out = np.empty((B, S))
    for b in prange(B):
        nearest_body_distance_within_env(seg_a, seg_b, pos[b], radius, cutoff, out[b])
    return out


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
