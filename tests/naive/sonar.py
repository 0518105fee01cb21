"""Plain-NumPy reference of the sonars (``finkensim.sensors.sonar``), for tests only.

Readable loops, no numba of its own. It takes the wall plates from ``Arena.plate_surfaces`` and the
same counter-based random numbers as the kernels, from ``finkensim.kernels.rng.uniforms_array`` /
``normals_array`` (one row of 40 uniforms / 20 normals per copter and step, layout in the module
docstring of the kernel), so it agrees with the kernels to rounding.

What it shares and why: the plate geometry (``Arena.plate_surfaces``: where a bent plate is) and the random-number
layout (which uniform feeds which error) are the model's definitions, so this reference restates them to check the
kernels' loops, culling and draw bookkeeping — it cannot catch a wrong definition. Those are checked elsewhere
against references that share nothing: the ray cast against a closed form of rectangle walls and circles
(``tests/test_edges.py::test_ideal_sonar_equals_an_independent_closed_form``), the error laws against scipy's
Rayleigh and normal distributions (KS tests in ``tests/test_sonar.py`` and notebook 02), the random numbers
against published SplitMix64 outputs (``tests/test_rng.py``).
"""
from __future__ import annotations

import math

import numpy as np

from finkensim.kernels.rng import STREAM_SONAR, STREAM_SONAR_SCHEDULE, normals_array, uniforms_array

N_UNIFORMS = 40  # 8 per sonar, sonars 0-3 horizontal, 4 down


def naive_ray_segment(o, d, a, b):
    """Distance along the unit ray o + t d (t >= 0) to segment ab, inf if it misses."""
    e = b - a
    den = d[0] * e[1] - d[1] * e[0]
    if den == 0.0:
        return math.inf
    w = a - o
    t = (w[0] * e[1] - w[1] * e[0]) / den
    s = (w[0] * d[1] - w[1] * d[0]) / den
    return t if (t >= 0.0 and 0.0 <= s <= 1.0) else math.inf


def naive_ray_circle(o, d, c, r):
    """First crossing (t >= 0) of the unit ray with the circle (c, r), inf if none."""
    f = o - c
    b = f[0] * d[0] + f[1] * d[1]
    cc = f[0] * f[0] + f[1] * f[1] - r * r
    disc = b * b - cc
    if disc < 0.0:
        return math.inf
    sq = math.sqrt(disc)
    for t in (-b - sq, -b + sq):
        if t >= 0.0:
            return t
    return math.inf


def naive_box_exit(o, d, width, length):
    """Where the ray leaves [0, W] x [0, L] (clamped at 0): the rigid net behind the plates."""
    ts = []
    if d[0] > 0.0:
        ts.append((width - o[0]) / d[0])
    elif d[0] < 0.0:
        ts.append(-o[0] / d[0])
    if d[1] > 0.0:
        ts.append((length - o[1]) / d[1])
    elif d[1] < 0.0:
        ts.append(-o[1] / d[1])
    return max(min(ts), 0.0)


def naive_cast(o, d, self_n, pos_b, radius, pa, pb, width, length):
    """(t, kind): nearest of plates (kind 1), the net (1) and other copters (2); ties keep the earlier."""
    best, kind = math.inf, 0
    for s in range(pa.shape[0]):
        t = naive_ray_segment(o, d, pa[s], pb[s])
        if t < best:
            best, kind = t, 1
    t = naive_box_exit(o, d, width, length)
    if t < best:
        best, kind = t, 1
    for m in range(pos_b.shape[0]):
        if m != self_n:
            t = naive_ray_circle(o, d, pos_b[m], radius)
            if t < best:
                best, kind = t, 2
    return best, kind


def naive_sonar_poses(pos_b, yaw_b, sp):
    """(N, 4, 4): sonar x, y, cos(heading), sin(heading); the heading (cos, sin) is the yaw's rotated by the
    mount's (the kernel's formula)."""
    N = pos_b.shape[0]
    out = np.empty((N, 4, 4))
    for n in range(N):
        for k in range(4):
            cy, sy = math.cos(yaw_b[n]), math.sin(yaw_b[n])
            cm, sm = math.cos(sp.mount_yaw[k]), math.sin(sp.mount_yaw[k])
            c, s = cy * cm - sy * sm, sy * cm + cy * sm
            out[n, k] = (pos_b[n, 0] + sp.offset * c, pos_b[n, 1] + sp.offset * s, c, s)
    return out


def naive_ideal(pos, yaw, theta, arena, sp):
    """Reference of ``ideal_sonar``: (dist (B,N,4), hit_type (B,N,4), hit_xy (B,N,4,2))."""
    pos = np.asarray(pos, dtype=float)
    B, N, _ = pos.shape
    PA, PB = arena.plate_surfaces(np.asarray(theta, dtype=float))
    dist = np.empty((B, N, 4))
    kind = np.zeros((B, N, 4), dtype=np.int64)
    hit = np.empty((B, N, 4, 2))
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):  # near-parallel rays give inf, as in numba
        _naive_ideal_loop(pos, yaw, PA, PB, arena, sp, dist, kind, hit)
    return dist, kind, hit


def _naive_ideal_loop(pos, yaw, PA, PB, arena, sp, dist, kind, hit):
    B, N, _ = pos.shape
    for b in range(B):
        poses = naive_sonar_poses(pos[b], yaw[b], sp)
        for n in range(N):
            for k in range(4):
                o = poses[n, k, :2]
                psi = yaw[b][n] + sp.mount_yaw[k]
                best, bk, h = math.inf, 0, (math.nan, math.nan)
                along = len(sp.ray_angles) == 1 and sp.ray_angles[0] == 0.0  # one ray: the sonar's heading
                for ang in sp.ray_angles:
                    d = poses[n, k, 2:].copy() if along else np.array([math.cos(psi + ang), math.sin(psi + ang)])
                    t, hk = naive_cast(o, d, n, pos[b], sp.radius, PA[b], PB[b], arena.width, arena.length)
                    if t < best:
                        best, bk, h = t, hk, (o[0] + t * d[0], o[1] + t * d[1])
                if best > sp.max_range:
                    dist[b, n, k], kind[b, n, k] = sp.max_range, 0
                else:
                    dist[b, n, k], kind[b, n, k] = best, bk
                hit[b, n, k] = h


def naive_slots(sp, seed, env_id, step, N):
    """Firing slot per copter: simultaneous 0, round_robin n mod n_slots, random_offset from the schedule stream."""
    out = np.zeros(N, dtype=np.int64)
    for n in range(N):
        if sp.schedule == 1:
            out[n] = n % sp.n_slots
        elif sp.schedule == 2:
            u = uniforms_array(seed, env_id, step, n, STREAM_SONAR_SCHEDULE, 1)[0]
            out[n] = min(int(math.floor(u * sp.n_slots)), sp.n_slots - 1)
    return out


def naive_echo(d, echo, k, u, z, sp):
    """Echo reading of sonar k (unclamped); u, z: the copter's uniforms and normals (8 and 4 per sonar)."""
    if not echo:
        return sp.max_range
    # the echo's time converted with the assumed speed of sound: the range scale applies to its error too
    y = d * sp.range_scale + sp.bias
    if sp.error == 0:  # none
        return y
    if sp.error == 1:  # gaussian
        return y + sp.sigma * z[4 * k + 1] * sp.range_scale
    R = math.sqrt(-2.0 * sp.sigma ** 2 * math.log(u[8 * k + 1]))  # Rayleigh by inversion
    s = math.sqrt((4.0 - math.pi) / 2.0) * sp.sigma
    if sp.error == 3:  # seed: the report's sign
        return y + (R - s) * sp.range_scale
    return y + sp.rayleigh_sign * (R - s) * sp.range_scale


def naive_measured(d, echo, path, k, u, z, sp):
    """Measured reading of sonar k: echo error, constant cross-talk (the report's d/2), geometric
    cross-talk (first arrival of path/2 + jitter, heard with crosstalk_hear_probability), clamp."""
    y = naive_echo(d, echo, k, u, z, sp)
    # a cross-talk reading is an echo time converted like any other: the range scale and the bias apply to it
    if sp.crosstalk & 1 and u[8 * k] < sp.crosstalk_probability:
        y = 0.5 * d * sp.range_scale + sp.bias
    if sp.crosstalk & 2 and path < math.inf:
        if sp.crosstalk_hear_probability >= 1.0 or u[8 * k + 6] < sp.crosstalk_hear_probability:
            c = 0.5 * path * sp.range_scale + sp.bias + (sp.crosstalk_jitter * z[4 * k + 2] * sp.range_scale
                                                         if sp.crosstalk_jitter > 0 else 0.0)
            y = min(y, c)
    return min(sp.max_range, max(sp.min_range, y))


def naive_crosstalk_path(n, k, poses, slots, sp):
    """Shortest emitter->receiver distance heard by sonar (n, k), inf if none."""
    best = math.inf
    r, u = poses[n, k, :2], poses[n, k, 2:]
    ch = math.cos(sp.half_angle)
    for m in range(poses.shape[0]):
        if m == n or slots[m] != slots[n]:
            continue
        for j in range(4):
            w = poses[m, j, :2] - r
            L = math.sqrt(w[0] * w[0] + w[1] * w[1])  # the kernel's arithmetic: cone-edge cases agree
            if L == 0.0 or L > 2.0 * sp.max_range:
                continue
            in_receiver_cone = u[0] * w[0] + u[1] * w[1] >= ch * L
            in_emitter_cone = -(poses[m, j, 2] * w[0] + poses[m, j, 3] * w[1]) >= ch * L
            if in_receiver_cone and in_emitter_cone:
                best = min(best, L)
    return best


def naive_readings(pos, yaw, theta, arena, sp, seed, env_ids, step):
    """Reference of ``sonar_readings`` (B, N, 4)."""
    pos = np.asarray(pos, dtype=float)
    B, N, _ = pos.shape
    dist, kind, _ = naive_ideal(pos, yaw, theta, arena, sp)
    out = np.empty((B, N, 4))
    for b in range(B):
        env = int(env_ids[b])
        poses = naive_sonar_poses(pos[b], yaw[b], sp)
        slots = naive_slots(sp, seed, env, step, N)
        for n in range(N):
            u = uniforms_array(seed, env, step, n, STREAM_SONAR, N_UNIFORMS)
            z = normals_array(seed, env, step, n, STREAM_SONAR, N_UNIFORMS // 2)
            for k in range(4):
                L = naive_crosstalk_path(n, k, poses, slots, sp) if sp.crosstalk & 2 else math.inf
                out[b, n, k] = naive_measured(dist[b, n, k], kind[b, n, k] != 0, L, k, u, z, sp)
    return out


def naive_down(alt, sp, seed, env_ids, step):
    """Reference of ``down_readings``: alt (B, N) m -> (B, N) m."""
    alt = np.asarray(alt, dtype=float)
    out = np.empty(alt.shape)
    for b in range(alt.shape[0]):
        for n in range(alt.shape[1]):
            u = uniforms_array(seed, int(env_ids[b]), step, n, STREAM_SONAR, N_UNIFORMS)
            z = normals_array(seed, int(env_ids[b]), step, n, STREAM_SONAR, N_UNIFORMS // 2)
            d = alt[b, n]
            y = naive_echo(d, d <= sp.max_range, 4, u, z, sp)
            out[b, n] = min(sp.max_range, max(sp.min_range, y))
    return out
