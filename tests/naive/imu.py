"""Plain NumPy reference of finkensim.sensors.imu, used only by tests.

Consumes the same counter-based normals (``normals_array``) as the kernel: per (seed, env, step,
copter, STREAM_IMU) cell, normals 0-2 are the white noise (acc x, acc y, gyro), 3-5 the bias
increments, 6-8 the turn-on bias.

What it shares and why: the random-number layout above (which normal feeds which channel) is the model's definition,
so the reference restates it; the noise law itself is checked against the analytic discretisation (white-noise std
σ/√dt, bias std √(k·dt)·σ_b; ``tests/test_imu.py``, ``examples/sensor_stats.py`` with ``tests/test_readme_numbers.py``,
and the CLI flight's gyro error in ``tests/test_cli.py``).
"""
from __future__ import annotations

import numpy as np

from finkensim.kernels.rng import STREAM_IMU, normals_array


def ideal_ref(acc_world, yaw, yaw_rate):
    """Rotate the world acceleration by −yaw with an explicit rotation matrix R(yaw)ᵀ."""
    acc_world = np.asarray(acc_world, float)
    yaw = np.asarray(yaw, float)
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)  # body → world, (..., 2, 2)
    acc_body = np.einsum("...ji,...j->...i", R, acc_world)  # Rᵀ a
    return acc_body, np.asarray(yaw_rate, float).copy()


def _cell_normals(seed, env_ids, step, N, n):
    """(B, N, n) standard normals of the cells (seed, env_ids[b], step, copter, STREAM_IMU)."""
    return np.array([[normals_array(seed, int(e), int(step), c, STREAM_IMU, n) for c in range(N)]
                     for e in env_ids]).reshape(len(env_ids), N, n)


def imu_step_ref(acc_world, yaw, yaw_rate, bias, acc_density, acc_walk_density, gyro_density, gyro_walk_density,
                 dt, seed, env_ids, step, constant=(0.0, 0.0, 0.0)):
    """One step from the continuous densities; returns (acc_meas, gyro_meas, new_bias) — bias not mutated.
    constant: the constant biases (acc x, acc y m/s², gyro rad/s) added to every reading."""
    acc_world = np.asarray(acc_world, float)
    B, N, _ = acc_world.shape
    z = _cell_normals(seed, env_ids, step, N, 6)
    sigma = np.array([acc_density, acc_density, gyro_density]) / np.sqrt(dt)
    walk = np.array([acc_walk_density, acc_walk_density, gyro_walk_density]) * np.sqrt(dt)
    acc_body, gyro = ideal_ref(acc_world, yaw, yaw_rate)
    ideal = np.concatenate([acc_body, gyro[..., None]], axis=-1)  # (B, N, 3)
    meas = ideal + (bias + np.asarray(constant, float)) + sigma * z[..., 0:3]
    new_bias = bias + walk * z[..., 3:6]
    return meas[..., 0:2], meas[..., 2], new_bias


def imu_trajectory_ref(acc_world, yaw, yaw_rate, bias0, acc_density, acc_walk_density, gyro_density,
                       gyro_walk_density, dt, seed, env_ids, step0):
    """Loop ``imu_step_ref`` over T samples (T, B, N, ...); returns (imu_acc, imu_gyro, final_bias)."""
    T = np.shape(acc_world)[0]
    bias = np.array(bias0, float)
    accs, gyros = [], []
    for t in range(T):
        a, g, bias = imu_step_ref(acc_world[t], yaw[t], yaw_rate[t], bias, acc_density, acc_walk_density,
                                  gyro_density, gyro_walk_density, dt, seed, env_ids, step0 + t)
        accs.append(a)
        gyros.append(g)
    return np.array(accs), np.array(gyros), bias


def turn_on_ref(N, seed, env_ids, step, acc_spread, gyro_spread):
    z = _cell_normals(seed, env_ids, step, N, 9)[..., 6:9]
    return z * np.array([acc_spread, acc_spread, gyro_spread])


def corrected_imu_ref(acc_world, yaw, yaw_rate, tables, window, dt, acc_bias, gyro_bias, seed, env, step):
    """Reference of ``imu_correction.corrected_imu`` for every copter of one environment: (acc_body (N, 2), gyro
    (N,)). ``tables``: the three :class:`~finkensim.sensors.correction_table.CorrectionTable` (dv_x, dv_y, dyaw),
    ``window`` s; the block's uniforms 0, 1, 2 of the cell (seed, env, step // h, copter, STREAM_CORRECTION_IMU)."""
    from finkensim.kernels.rng import STREAM_CORRECTION_IMU, counter_key, uniform

    h = max(1, int(round(window / dt)))
    N = len(yaw)
    acc, gyro = np.empty((N, 2)), np.empty(N)
    for n in range(N):
        key = np.uint64(counter_key(*map(np.int64, (seed, env, step // h, n, STREAM_CORRECTION_IMU))))
        c, s = np.cos(yaw[n]), np.sin(yaw[n])
        median = [acc_world[n, 0] + c * acc_bias[0] - s * acc_bias[1], acc_world[n, 1] + s * acc_bias[0] + c * acc_bias[1],
                  yaw_rate[n] + gyro_bias]
        v = []
        for ch, (t, m) in enumerate(zip(tables, median)):
            g = int(np.clip(np.searchsorted(t.edges, m * window, side="right") - 1, 0, t.quantiles.shape[0] - 1))
            v.append(m + float(np.interp(uniform(key, ch), t.levels, t.quantiles[g])) / window)
        acc[n] = c * v[0] + s * v[1], -s * v[0] + c * v[1]
        gyro[n] = v[2]
    return acc, gyro
