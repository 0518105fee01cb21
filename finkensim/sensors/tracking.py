"""The tracking system (the arena's cameras) as a sensor: a tracked pose is the true pose plus Gaussian noise
σ_xy (x, y) and σ_ψ (yaw), the one model of tracking noise.

The flight-log writer uses it to record what a tracker would (:func:`tracked_poses`, config keys
``log.tracking_sigma_xy`` / ``log.tracking_sigma_yaw``); the gap diagnosis uses the same kernel the other way round:
its pose draws are the logged pose plus tracking noise, keyed by (seed, flight, time index, copter, draw) so that
every sensor sees the same realisation in draw m and refits reuse the same numbers (common random numbers).
:func:`pose_normal_table` keeps a draw set's standard normals, which do not depend on σ, for the evaluations of a
fit to share."""
from __future__ import annotations

from typing import NamedTuple

from numba import njit, prange

from ..kernels.rng import STREAM_POSE_NOISE, STREAM_TRACKING, counter_key, normal


class PoseNoise(NamedTuple):
    """Tracking noise of a flight's logged poses and the keys of its pose draws.

    sigma_xy m, sigma_yaw rad: standard deviations; seed and flight_id key the draws
    (``counter_key(seed, flight_id, sample, copter, STREAM_POSE_NOISE)``, normals 3m, 3m+1, 3m+2 of draw m).
    """

    sigma_xy: float
    sigma_yaw: float
    seed: int
    flight_id: int


@njit(cache=True, inline="always")
def pose_normals(key, m):
    """The standard normals (x, y, yaw) of pose draw m in one copter's STREAM_POSE_NOISE cell ``key``."""
    return normal(key, 3 * m), normal(key, 3 * m + 1), normal(key, 3 * m + 2)


@njit(cache=True, inline="always")
def noisy_pose(pos, yaw, k, n, sigma_xy, sigma_yaw, zx, zy, zw):
    """Copter n's logged pose at sample k moved by the tracking noise σ·z of standard normals (zx, zy, zw)."""
    return pos[k, n, 0] + sigma_xy * zx, pos[k, n, 1] + sigma_xy * zy, yaw[k, n] + sigma_yaw * zw


@njit(cache=True, inline="always")
def pose_draw(pos, yaw, k, n, m, sigma_xy, sigma_yaw, seed, flight_id):
    """Draw m of copter n's true pose at sample k: logged pose + tracking noise (x, y, yaw)."""
    if sigma_xy == 0.0 and sigma_yaw == 0.0:
        return pos[k, n, 0], pos[k, n, 1], yaw[k, n]
    zx, zy, zw = pose_normals(counter_key(seed, flight_id, k, n, STREAM_POSE_NOISE), m)
    return noisy_pose(pos, yaw, k, n, sigma_xy, sigma_yaw, zx, zy, zw)


@njit(cache=True, inline="always")
def draw_poses(pos, yaw, k, m, noise, pos_out, yaw_out):
    """Draw m of every copter's true pose at sample k → pos_out (N, 2) m, yaw_out (N,) rad."""
    for n in range(pos.shape[1]):
        x, y, w = pose_draw(pos, yaw, k, n, m, noise.sigma_xy, noise.sigma_yaw, noise.seed, noise.flight_id)
        pos_out[n, 0] = x
        pos_out[n, 1] = y
        yaw_out[n] = w


@njit(cache=True, parallel=True)
def pose_normal_table(times, N, G, seed, flight_id, out):
    """The standard normals of pose draws m < G of every copter at each sample in ``times`` → out (K, G, N, 3)
    (x, y, yaw; those :func:`draw_poses` scales by the pose noise). They do not depend on σ: the evaluations of
    a fit that moves σ, the walls or the beam share one table."""
    for ti in prange(times.shape[0]):
        for n in range(N):
            key = counter_key(seed, flight_id, times[ti], n, STREAM_POSE_NOISE)
            for m in range(G):
                zx, zy, zw = pose_normals(key, m)
                out[ti, m, n, 0] = zx
                out[ti, m, n, 1] = zy
                out[ti, m, n, 2] = zw


@njit(cache=True, inline="always")
def draw_poses_from(pos, yaw, k, z, sigma_xy, sigma_yaw, pos_out, yaw_out):
    """:func:`draw_poses` with the draw's normals z (N, 3) from :func:`pose_normal_table` (the same numbers)."""
    exact = sigma_xy == 0.0 and sigma_yaw == 0.0
    for n in range(pos.shape[1]):
        if exact:
            x, y, w = pos[k, n, 0], pos[k, n, 1], yaw[k, n]
        else:
            x, y, w = noisy_pose(pos, yaw, k, n, sigma_xy, sigma_yaw, z[n, 0], z[n, 1], z[n, 2])
        pos_out[n, 0] = x
        pos_out[n, 1] = y
        yaw_out[n] = w


@njit(cache=True, parallel=True)
def tracked_poses(pos, yaw, sigma_xy, sigma_yaw, seed, env_id, pos_out, yaw_out):
    """What a tracker with noise σ_xy m, σ_ψ rad records of true poses pos (T, N, 2) m, yaw (T, N) rad →
    pos_out, yaw_out (same shapes): :func:`noisy_pose` with the normals of draw 0 of the cell
    ``counter_key(seed, env_id, sample, copter, STREAM_TRACKING)`` (independent of every sensor's numbers)."""
    for k in prange(pos.shape[0]):
        for n in range(pos.shape[1]):
            zx, zy, zw = pose_normals(counter_key(seed, env_id, k, n, STREAM_TRACKING), 0)
            x, y, w = noisy_pose(pos, yaw, k, n, sigma_xy, sigma_yaw, zx, zy, zw)
            pos_out[k, n, 0] = x
            pos_out[k, n, 1] = y
            yaw_out[k, n] = w
