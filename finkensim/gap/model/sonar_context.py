"""Context features of every logged sonar reading (:func:`sonar_features`): what the ray hit, at which incidence,
how near another copter is, how far the plate at the hit is displaced and how ambiguous the reading is under the
tracking noise. The diagnosis locates a gap by these features (:mod:`~finkensim.gap.detect.locations`)."""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ...kernels.geometry import point_segment_distance
from ...kernels.raycast import HIT_NONE, HIT_WALL, plate_bands
from ...kernels.trig import sin_fast
from ...sensors.sonar_kernels import displaced_plates_env, sonar_hit, sonar_pose, sonar_poses_env

__all__ = ["sonar_features"]


@njit(cache=True)
def _sonar_context(P2, yaw_k, theta_k, geometry, plates, sonar, n, s, echo, out):
    """Features 2, 3, 5 of a wall hit (see :func:`sonar_features`) into out (8,); plates = (pa, pb) (S_p, 2) m the
    displaced plate surfaces; echo = (t_, hk, hx, hy) of :func:`~finkensim.sensors.sonar_kernels.sonar_hit`."""
    pa, pb = plates
    t_, hk, hx, hy = echo
    out[2] = np.nan
    out[3] = np.nan
    out[5] = np.nan
    if hk != HIT_WALL or t_ > sonar.max_range:
        return
    psi = yaw_k[n] + sonar.mount_yaw[s]
    dx = np.cos(psi)
    dy = np.sin(psi)
    # the wall line the ray meets (nearest of the four) gives the normal
    dl = min(min(hx, geometry.width - hx), min(hy, geometry.length - hy))
    if dl == hx or dl == geometry.width - hx:
        out[2] = np.degrees(np.arccos(min(1.0, abs(dx))))
    else:
        out[2] = np.degrees(np.arccos(min(1.0, abs(dy))))
    best = np.inf
    for q in range(P2.shape[0]):
        ddx = P2[q, 0] - hx
        ddy = P2[q, 1] - hy
        best = min(best, np.sqrt(ddx * ddx + ddy * ddy))
    out[3] = best
    # the plate at the hit (nearest displaced plate surface) and its displacement
    bs = 0.0
    bd = np.inf
    for p in range(pa.shape[0]):
        d = point_segment_distance(hx, hy, pa[p, 0], pa[p, 1], pb[p, 0], pb[p, 1])
        if d < bd:
            bd = d
            bs = geometry.lever * sin_fast(theta_k[p])
    out[5] = bs


@njit(cache=True, parallel=True)
def sonar_features(poses, geometry, sonar, times, sigma_xy, sigma_yaw, out):
    """Context features of every sonar reading at the logged poses → out (K, N, S, 8):

    0 true_range (m), 1 hit_type (0 none, 1 wall, 2 copter), 2 incidence (deg, ray vs wall
    normal; NaN unless a wall hit), 3 hit_to_copter (m, wall hit point to nearest copter centre;
    NaN unless a wall hit), 4 neighbor_in_beam (0/1: another copter centre inside the cone
    within max_range), 5 plate_shift (m, displacement lever·sin θ of the plate at the hit, unit
    bending walls), 6 wall_distance (m, copter centre to nearest wall line), 7 ambiguity (in units
    of the pose noise: how far the ray is from grazing another copter's rim, or the hit from the
    range limit, divided by σ_xy + σ_ψ·distance; inf without noise). Readings with a small
    ambiguity have an ideal value that flips under tracking noise.

    poses: :class:`ReplayPoses`; geometry: the WallGeometry; sonar: the SonarModel with one ray along each sonar's heading
    (``sonar.with_beam(0.0, 1)``); ``sonar.cos_half_angle`` is the cone of feature 4.
    """
    K = times.shape[0]
    N = poses.pos.shape[1]
    S = sonar.mount_yaw.shape[0]
    P = geometry.plate_a.shape[0]
    for ti in prange(K):
        k = times[ti]
        pa = np.empty((P, 2))
        pbb = np.empty((P, 2))
        buf = np.empty((N, S, 4))
        displaced_plates_env(poses.theta[k], geometry.plate_a, geometry.plate_b, geometry.normal, geometry.lever, pa, pbb)
        P2 = poses.pos[k]
        sonar_poses_env(P2, poses.yaw[k], sonar, buf)
        bands = plate_bands(pa, pbb, geometry.width, geometry.length)
        for n in range(N):
            wd = min(min(P2[n, 0], geometry.width - P2[n, 0]), min(P2[n, 1], geometry.length - P2[n, 1]))
            for s in range(S):
                echo = sonar_hit(n, sonar_pose(buf, n, s), poses.yaw[k, n] + sonar.mount_yaw[s], P2,
                                 (pa, pbb, geometry.width, geometry.length), sonar, sonar.ray_angles, bands, np.empty(0, dtype=np.int64), -1)
                t_, hk, hx, hy = echo
                o = out[ti, n, s]
                o[6] = wd
                if t_ > sonar.max_range:
                    o[0] = sonar.max_range
                    o[1] = HIT_NONE
                else:
                    o[0] = t_
                    o[1] = hk
                _sonar_context(P2, poses.yaw[k], poses.theta[k], geometry, (pa, pbb), sonar, n, s, echo, o)
                o[4], o[7] = _beam_neighbours(P2, buf, n, s, t_, sonar, sigma_xy, sigma_yaw)


@njit(cache=True)
def _beam_neighbours(P2, buf, n, s, t_, sonar, sigma_xy, sigma_yaw):
    """(neighbor_in_beam 0/1, ambiguity) of sonar s of copter n with ray length t_ (see :func:`sonar_features`)."""
    ox = buf[n, s, 0]
    oy = buf[n, s, 1]
    dx = buf[n, s, 2]
    dy = buf[n, s, 3]
    inb = 0.0
    amb = np.inf
    for q in range(P2.shape[0]):
        if q == n:
            continue
        wx = P2[q, 0] - ox
        wy = P2[q, 1] - oy
        L = np.sqrt(wx * wx + wy * wy)
        if 0.0 < L <= sonar.max_range and dx * wx + dy * wy >= sonar.cos_half_angle * L:
            inb = 1.0
        along = dx * wx + dy * wy
        if along > 0.0 and along < min(t_, sonar.max_range) + sonar.radius:
            perp = abs(dx * wy - dy * wx)
            sc = sigma_xy * 1.4142 + sigma_yaw * along
            if sc > 0.0:
                amb = min(amb, abs(perp - sonar.radius) / sc)
    sc = sigma_xy * 1.4142 + sigma_yaw * t_
    if sc > 0.0 and np.isfinite(t_):
        amb = min(amb, abs(t_ - sonar.max_range) / sc)
    return inb, amb
