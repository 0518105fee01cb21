"""The sonar replay with the walls apart from the copters: when only the walls move, only the walls are cast again.

A fit of the walls' own parameters (the ``wall_bulge`` effect's amplitude, reach, shape and response; the plates'
gain) moves no copter and no pose draw. Each ray of :func:`~finkensim.gap.model.replay.sonar_draws` meets the nearest
of the plates, the arena's net and the other copters
(:func:`~finkensim.kernels.raycast.cast_ray_culled`: the walls first, then the nearest copter if it is nearer), and
each reading's cross-talk path involves no wall. So the nearest copter of every ray and pose draw, and the cross-talk
paths, are kept from one replay (``record``) and read back in the next ones (``reuse``), which cast only the walls:
the same comparisons on the same numbers, so the same readings bit for bit (a test compares them with
:func:`~finkensim.gap.model.replay.sonar_draws`).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ...kernels.raycast import HIT_COPTER, HIT_NONE, cast_ray_culled, copter_hits, plate_bands
from ...sensors.sonar_kernels import (crosstalk_path, fire_slots_env, shifted_plates_env, sonar_pose,
                                      sonar_poses_env, sonar_spread, store_ideal)
from ...sensors.sonar_model import CROSSTALK_GEOMETRIC, sonar_scalars
from ...sensors.tracking import draw_poses_from


@njit(cache=True, inline="always")
def _split_hit(n, pose, psi, pos_m, walls, scalars, rays, bands, cands, kept):
    """:func:`~finkensim.sensors.sonar_kernels.sonar_hit` of sonar (n, ·) over all copters, its copters' part taken
    from kept = (copters (R,) m, record): the nearest copter of each ray, written when ``record``, else read. Returns
    (t m, kind, hx m, hy m) as sonar_hit does. cands = (an empty candidate list: the walls alone, "every copter")."""
    none, all_ = cands
    copters, record = kept
    ox, oy, cx, cy = pose
    R = rays.shape[0]
    best = np.inf
    bkind = HIT_NONE
    hx = np.nan
    hy = np.nan
    for r in range(R):
        if R == 1 and rays[0] == 0.0:
            dx = cx
            dy = cy
        else:
            a = psi + rays[r]
            dx = np.cos(a)
            dy = np.sin(a)
        ray = (ox, oy, dx, dy)
        t, hk = cast_ray_culled(ray, n, pos_m, scalars.radius, walls, bands, none, 0)  # plates and net only
        if record:
            copters[r] = copter_hits(ray, n, pos_m, scalars.radius, np.inf, HIT_NONE, all_, -1)[0]
        if copters[r] < t:  # as copter_hits compares the nearest copter with the walls' best
            t = copters[r]
            hk = HIT_COPTER
        if t < best:
            best = t
            bkind = hk
            hx = ox + t * dx
            hy = oy + t * dy
    return best, bkind, hx, hy


@njit(cache=True)
def _split_draws_at(poses, geometry, sonar, gain, at, noise, z, need, out, kept):
    """:func:`~finkensim.gap.model.replay._sonar_draws_at` at at = (log index k, row ti) with the copters' part and
    the cross-talk paths written to (``record``) or read from kept = (copters (K, N, S, M, R), record) and out's
    cross-talk array."""
    k, ti = at
    copters, record = kept
    out_dist, out_kind, out_xtalk = out
    M = z.shape[1]
    N = poses.pos.shape[1]
    mount_yaw = sonar.mount_yaw
    rays = sonar.ray_angles
    scalars = sonar_scalars(sonar)
    geometric = scalars.crosstalk & CROSSTALK_GEOMETRIC
    spread = sonar_spread(scalars)
    S = mount_yaw.shape[0]
    P = geometry.plate_a.shape[0]
    pos_m = np.empty((N, 2))
    yaw_m = np.empty(N)
    pa = np.empty((P, 2))
    pb = np.empty((P, 2))
    slots = np.zeros(N, dtype=np.int64)
    buf = np.empty((N, S, 4))
    dist = np.empty((N, S))
    kind = np.empty((N, S), dtype=np.int64)
    hit = np.empty((N, S, 2))
    all_ = np.empty(0, dtype=np.int64)
    none = np.empty(0, dtype=np.int64)
    scratch = np.empty(N, dtype=np.int64)
    shifted_plates_env(poses.theta[k], geometry.plate_a, geometry.plate_b, geometry.normal, geometry.lever, gain, pa, pb)
    for p in range(P):
        b = poses.bulge[k, p]
        pa[p, 0] += b * geometry.normal[p, 0]
        pa[p, 1] += b * geometry.normal[p, 1]
        pb[p, 0] += b * geometry.normal[p, 0]
        pb[p, 1] += b * geometry.normal[p, 1]
    bands = plate_bands(pa, pb, geometry.width, geometry.length)
    walls = (pa, pb, geometry.width, geometry.length)
    for m in range(M):
        draw_poses_from(poses.pos, poses.yaw, k, z[ti, m], noise.sigma_xy, noise.sigma_yaw, pos_m, yaw_m)
        sonar_poses_env(pos_m, yaw_m, sonar, buf)
        if geometric and record:
            fire_slots_env(noise.seed, noise.flight_id, k, scalars, slots, m)
        for n in range(N):
            for s in range(S):
                if not need[ti, n, s]:
                    out_dist[ti, n, s, m] = np.nan
                    out_kind[ti, n, s, m] = HIT_NONE
                    if record:
                        out_xtalk[ti, n, s, m] = np.inf
                    continue
                pose = sonar_pose(buf, n, s)
                echo = _split_hit(n, pose, yaw_m[n] + mount_yaw[s], pos_m, walls, scalars, rays, bands, (none, all_),
                                  (copters[ti, n, s, m], record))
                store_ideal(n, s, echo, scalars.max_range, pose, dist, kind, hit)
                out_dist[ti, n, s, m] = dist[n, s]
                out_kind[ti, n, s, m] = kind[n, s]
                if record:
                    out_xtalk[ti, n, s, m] = (crosstalk_path(n, s, buf, slots, scalars, all_, -1, spread, scratch)
                                              if geometric else np.inf)


@njit(cache=True, parallel=True)
def _split_draws(poses, geometry, sonar, gain, times, noise, z, need, out, kept):
    """The loop of :func:`sonar_draws_split` over its times (kept = (copters, record))."""
    for ti in prange(times.shape[0]):
        _split_draws_at(poses, geometry, sonar, gain, (times[ti], ti), noise, z, need, out, kept)


def sonar_draws_split(poses, geometry, sonar, gain, times, noise, z, need, out_dist, out_kind, out_xtalk, copters,
                      record: bool):
    """:func:`~finkensim.gap.model.replay.sonar_draws` (its arguments, with the pose normals ``z`` (K, M, N, 3)
    given), the copters apart from the walls.

    copters (K, N, S, M, R) float64 m: the nearest copter of each ray r of each needed reading and pose draw (inf:
    none). ``record`` True: everything is cast, and copters and out_xtalk (the cross-talk paths) are written;
    False: they hold what a recording replay wrote for the same poses, draws, sonar model and needed rays (only
    the walls — plates, bulge, gain — may differ), and only the walls are cast; out_xtalk is left as it is. Either
    way out_dist and out_kind (and out_xtalk) are those of sonar_draws bit for bit.
    """
    K, M, N = z.shape[0], z.shape[1], poses.pos.shape[1]
    S, R = sonar.mount_yaw.shape[0], sonar.ray_angles.shape[0]
    if copters.shape != (K, N, S, M, R):
        raise ValueError(f"copters {copters.shape}: expected (K, N, S, M, R) = {(K, N, S, M, R)}")
    _split_draws(poses, geometry, sonar, gain, times, noise, z, need, (out_dist, out_kind, out_xtalk),
                 (copters, bool(record)))
