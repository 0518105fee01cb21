"""Plain-NumPy reference of the swarm behaviours (``finkensim.behaviours.attraction`` and ``.wall_check``),
for tests only. Written from the model description (module docstrings / DESIGN.md), vectorised over
environments, copters and sonars, with the parameters derived here from the Config (degrees → radians,
rim = radius + offset), so the kernels' parameter conversion is checked too.
"""
from __future__ import annotations

import math

import numpy as np

from finkensim.kernels.rng import STREAM_BEHAVIOUR
from tests.naive.rng import counter_key, uniform


def attraction(sonar, wall, seed, env_ids, step, cfg):
    """Body-frame velocity commands (B, N, 2) m/s and yaw-rate commands (B, N) of attraction–repulsion.

    p_j = r_j (cos m_j, sin m_j); Δ = w_c Σ_j p_j (a·[not wall] − b exp(−|p_j|²/c)) + w_t a target,
    readings ≥ max_range excluded; target = target_distance (cos φ, sin φ), φ = 2π u with u the uniform 0
    of counter_key(seed, env, step // redraw_steps, n, STREAM_BEHAVIOUR); v = gain Δ limited to max_speed.
    """
    be = cfg.behaviour
    sonar = np.asarray(sonar, float)
    wall = np.asarray(wall, bool)
    B, N, K = sonar.shape
    m = np.radians(np.asarray(cfg.sonar.yaw_deg, float))
    u = np.stack([np.cos(m), np.sin(m)], -1)  # (K, 2)
    p = sonar[..., None] * u  # (B, N, K, 2)
    d2 = (p ** 2).sum(-1)
    f = np.where(wall, 0.0, be.ar_a) - be.ar_b * np.exp(-d2 / be.ar_c)
    f = np.where(sonar >= cfg.sonar.max_range, 0.0, f)
    swarm = (p * f[..., None]).sum(-2)  # (B, N, 2)
    env = np.asarray(env_ids, np.int64)[:, None]
    key = counter_key(seed, env, step // be.redraw_steps, np.arange(N)[None, :], STREAM_BEHAVIOUR)
    phi = 2.0 * np.pi * uniform(key, 0)
    target = be.target_distance * np.stack([np.cos(phi), np.sin(phi)], -1)
    v = be.gain * (be.w_c * swarm + be.w_t * be.ar_a * target)
    speed = np.linalg.norm(v, axis=-1, keepdims=True)
    vmax = cfg.copters.max_speed
    v = np.where(speed > vmax, v * vmax / np.where(speed > 0, speed, 1.0), v)
    return v, np.zeros((B, N))


def per_reading(sonar, ranging, cfg):
    """(B, N, K) bool: echoes whose centre-distance estimate r + radius + offset matches no ranging
    reading of another column within ε (a reading at the ranging max_range matches any estimate ≥ max − ε)."""
    eps = cfg.behaviour.wall_check_epsilon
    sonar = np.asarray(sonar, float)
    ranging = np.asarray(ranging, float)
    B, N, K = sonar.shape
    e = sonar + cfg.copters.radius + cfg.sonar.offset
    rho = ranging[:, :, None, :]  # (B, N, 1, N + M)
    ee = e[..., None]
    far = rho >= cfg.ranging.max_range
    match = np.where(far, ee >= cfg.ranging.max_range - eps, np.abs(ee - rho) <= eps)
    self_col = np.arange(ranging.shape[2])[None, :] == np.arange(N)[:, None]  # (N, N + M): own column
    match = match & ~self_col[None, :, None, :]
    return (sonar < cfg.sonar.max_range) & ~match.any(-1)


def dead_reckon(imu_acc, imu_gyro, dr_pos, dr_vel, dr_yaw, dt):
    """One dead-reckoning update; returns new (dr_pos, dr_vel, dr_yaw) (inputs untouched)."""
    yaw = dr_yaw + imu_gyro * dt
    c, s = np.cos(yaw), np.sin(yaw)
    a = np.stack([c * imu_acc[..., 0] - s * imu_acc[..., 1], s * imu_acc[..., 0] + c * imu_acc[..., 1]], -1)
    vel = dr_vel + a * dt
    pos = dr_pos + vel * dt
    return pos, vel, yaw


def sequence(fail, count, wall, anchor, dr_pos, dr_yaw, cfg):
    """One sequence-check update; returns new (count, wall, anchor, onsets (B, N)) (inputs untouched).

    Flagged sonars are released (flag and counter cleared) once |p̂ − p̂_flag| ≥ release_distance or
    |ψ̂ − ψ̂_flag| ≥ release_angle; unflagged sonars count consecutive failures (a pass resets) and are
    flagged, with the current dead-reckoned pose as anchor, on reaching fail_count.
    """
    be = cfg.behaviour
    count, wall, anchor = count.copy(), wall.copy(), anchor.copy()
    moved = np.linalg.norm(dr_pos[:, :, None, :] - anchor[..., :2], axis=-1)
    turned = np.abs(dr_yaw[:, :, None] - anchor[..., 2])
    release = wall & ((moved >= be.sequence_release_distance) | (turned >= math.radians(be.sequence_release_angle_deg)))
    wall[release] = False
    count[release] = 0
    free = ~wall
    count = np.where(free, np.where(fail, count + 1, 0), count)
    flag = free & (count >= be.sequence_fail_count)
    wall[flag] = True
    count[flag] = 0
    pose = np.concatenate([dr_pos, dr_yaw[..., None]], -1)  # (B, N, 3)
    anchor = np.where(flag[..., None], pose[:, :, None, :], anchor)
    return count, wall, anchor, flag.sum(-1)
