"""Inertial sensor: body-frame 2-axis accelerometer and yaw-rate gyro with white noise and bias random walk.

The copters fly at a fixed altitude, so the IMU is reduced to what the horizontal kinematic model
produces: the two horizontal accelerometer axes and the yaw-rate gyro. Gravity acts along the body
z axis only (the copter is level) and is therefore absent from the two horizontal axes.

Ideal measurement (per copter, at world state k — the state after k steps)::

    a_w   = (a_x, a_y)          world-frame acceleration applied in the step that ended at k (m/s²),
                                i.e. ``WorldState.acc`` / ``Trajectory.acc``
    ψ     = yaw at k (rad, CCW from world +x);   ω = yaw rate at k (rad/s)
    a_b,x =  cos ψ · a_x + sin ψ · a_y           body x: forward (the heading)
    a_b,y = −sin ψ · a_x + cos ψ · a_y           body y: left
    g     = ω

so the body reading is the world vector rotated by −ψ (a copter yawed +90° that accelerates along
world +y reads +x). The acceleration is the one the kinematic model applied; the velocity it loses
when it is put back on a wall is not in it.

Error model — the standard continuous-time IMU noise model (white noise plus bias random walk, as
used by e.g. Kalibr and most VIO literature) discretised at the sample period Δt = world step. For
each of the three channels c ∈ (acc x, acc y, gyro), with noise density σ_c (unit/√Hz) and bias
random-walk density σ_b,c (unit/s/√Hz)::

    y_k      = h_k + b_k + (σ_c / √Δt) · η_k           η_k ~ N(0, 1)  (white noise, sample std σ_c/√Δt)
    b_{k+1}  = b_k + (σ_b,c · √Δt) · ξ_k               ξ_k ~ N(0, 1)  (random walk of the bias)

The white-noise std follows from averaging a continuous white process of PSD σ_c² over one sample
period; the bias increment is the integral of a white process of PSD σ_b,c² over Δt. Hence, starting
from b_0, Var(b_k − b_0) = σ_b,c² · Δt · k, independent of how Δt is chosen for a fixed time k·Δt.

A reading uses the current bias b_k and then advances it, so the first reading after switch-on
carries the initial bias b_0 (zero by default; :meth:`ImuState.turn_on` draws it from a Gaussian
turn-on spread instead).

Randomness: all draws of copter n in environment e at step k come from the counter-based cell
``counter_key(seed, e, k, n, STREAM_IMU)``: normals 0, 1, 2 are η (acc x, acc y, gyro), normals
3, 4, 5 are ξ (acc x, acc y, gyro), and normals 6, 7, 8 of the switch-on step are the turn-on bias.
Results therefore depend only on (seed, environment index, step, copter) — never on batch size,
thread count or call order.

A learned correction (``imu.correction_file``, :mod:`finkensim.sensors.imu_correction`) replaces the white noise and
the bias random walk of the readings (the bias state still advances) by the correction's draws, on its own stream.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from ..config import ConfigError, ImuConfig
from ..kernels.rng import STREAM_IMU, counter_key, normal
from .imu_correction import NO_IMU_TABLE, corrected_imu, imu_correction

#: Indices of the normals inside one (seed, env, step, copter, STREAM_IMU) cell.
NOISE_INDEX = 0  # 0, 1, 2: white noise of acc x, acc y, gyro
WALK_INDEX = 3  # 3, 4, 5: bias random-walk increments of acc x, acc y, gyro
TURN_ON_INDEX = 6  # 6, 7, 8: turn-on bias (only in the switch-on step's cell)


class ImuModel(NamedTuple):
    """Per-sample (discrete-time) IMU error parameters in SI units, as passed to the kernels.

    acc_sigma: white-noise std of each accelerometer sample, m/s² (= acc_noise_density / √dt).
    acc_walk: std of one accelerometer bias increment, m/s² (= acc_bias_walk · √dt).
    gyro_sigma: white-noise std of each gyro sample, rad/s (= gyro_noise_density / √dt).
    gyro_walk: std of one gyro bias increment, rad/s (= gyro_bias_walk · √dt).
    dt: sample period, s (the world step).
    acc_bias_x, acc_bias_y: constant body-frame accelerometer bias, m/s²; gyro_bias: constant gyro bias, rad/s
    (config ``imu.acc_bias``, ``imu.gyro_bias``; the gap effect ``imu_bias`` fits them). 0 changes nothing.
    correction: the learned correction's tables (3, G + 1, Q + 1) of the channels dv_x, dv_y, dyaw
    (:func:`~finkensim.sensors.imu_correction.pack_channels`; (0, 0, 0) = none) and correction_window s their window
    (config ``imu.correction_file``).
    """

    acc_sigma: float
    acc_walk: float
    gyro_sigma: float
    gyro_walk: float
    dt: float
    acc_bias_x: float = 0.0
    acc_bias_y: float = 0.0
    gyro_bias: float = 0.0
    correction: np.ndarray = NO_IMU_TABLE
    correction_window: float = 0.0

    @classmethod
    def from_densities(cls, acc_noise_density: float, acc_bias_walk: float, gyro_noise_density: float,
                       gyro_bias_walk: float, dt: float) -> "ImuModel":
        """Discretise continuous-time densities at sample period ``dt`` (see the module docstring)."""
        if isinstance(dt, bool) or not isinstance(dt, (int, float, np.floating, np.integer)) \
                or not math.isfinite(dt) or dt <= 0.0:
            raise ConfigError(f"dt = {dt!r}: expected a finite number > 0 s")
        dt = float(dt)
        sq = math.sqrt(dt)
        return cls(acc_sigma=float(acc_noise_density) / sq, acc_walk=float(acc_bias_walk) * sq,
                   gyro_sigma=float(gyro_noise_density) / sq, gyro_walk=float(gyro_bias_walk) * sq, dt=dt)

    @classmethod
    def from_config(cls, imu: ImuConfig, dt: float) -> "ImuModel":
        """Parameters from the ``[imu]`` section and the world step ``dt`` (s).

        ``imu.enabled`` is not part of the model: it tells the caller whether to produce IMU readings.
        """
        model = cls.from_densities(imu.acc_noise_density, imu.acc_bias_walk, imu.gyro_noise_density,
                                   imu.gyro_bias_walk, dt)
        table, window = imu_correction(imu.correction_file)
        return model._replace(acc_bias_x=float(imu.acc_bias[0]), acc_bias_y=float(imu.acc_bias[1]),
                              gyro_bias=float(imu.gyro_bias), correction=table, correction_window=window)


class ImuState(NamedTuple):
    """The IMU's only state: the current bias of every channel, ``bias`` (B, N, 3) float64 —
    (acc x m/s², acc y m/s², gyro rad/s). Kernels update it in place."""

    bias: np.ndarray

    @classmethod
    def zeros(cls, n_envs: int, n_copters: int) -> "ImuState":
        """Zero initial bias (the default)."""
        return cls(np.zeros((int(n_envs), int(n_copters), 3)))

    @classmethod
    def turn_on(cls, n_copters: int, seed: int, env_ids, step: int = 0, acc_spread: float = 0.0,
                gyro_spread: float = 0.0) -> "ImuState":
        """Initial bias drawn from a Gaussian turn-on spread: N(0, acc_spread²) m/s² per accelerometer
        axis and N(0, gyro_spread²) rad/s for the gyro. Uses normals 6–8 of the cell of ``step`` (the
        switch-on step), so it is reproducible per (seed, env, copter) and independent of the noise."""
        for name, v in (("acc_spread", acc_spread), ("gyro_spread", gyro_spread)):
            if not (math.isfinite(v) and v >= 0.0):
                raise ConfigError(f"{name} = {v!r}: expected a finite number >= 0")
        env_ids = _check_env_ids(env_ids, None)
        bias = np.empty((env_ids.size, int(n_copters), 3))
        _turn_on_batch(int(seed), env_ids, int(step), float(acc_spread), float(gyro_spread), bias)
        return cls(bias)

    def copy(self) -> "ImuState":
        return ImuState(self.bias.copy())


@njit(cache=True, parallel=True)
def _turn_on_batch(seed, env_ids, step, acc_spread, gyro_spread, bias):
    for b in prange(bias.shape[0]):
        for n in range(bias.shape[1]):
            key = counter_key(seed, env_ids[b], step, n, STREAM_IMU)
            bias[b, n, 0] = acc_spread * normal(key, TURN_ON_INDEX)
            bias[b, n, 1] = acc_spread * normal(key, TURN_ON_INDEX + 1)
            bias[b, n, 2] = gyro_spread * normal(key, TURN_ON_INDEX + 2)


@njit(cache=True, inline="always", error_model="numpy")  # why: finkensim.kernels.outline
def imu_env(acc_world, yaw, yaw_rate, bias, params, seed, env_id, step, out_acc, out_gyro):
    """IMU readings of one environment at one step, in place.

    acc_world (N, 2) m/s² world frame; yaw, yaw_rate (N,); bias (N, 3) updated in place
    (b_k → b_{k+1}); writes out_acc (N, 2) m/s² body frame (x forward, y left) and out_gyro (N,) rad/s.
    The constant biases of ``params`` add to the drifting ones (only when non-zero: adding 0 would turn a −0.0
    reading into +0.0). With a learned correction (``params.correction``) the readings are
    :func:`~finkensim.sensors.imu_correction.corrected_imu` instead, and the bias still advances.
    """
    corrected = params.correction.shape[0] > 0
    for n in range(acc_world.shape[0]):
        key = counter_key(seed, env_id, step, n, STREAM_IMU)
        c = np.cos(yaw[n])
        s = np.sin(yaw[n])
        ax = acc_world[n, 0]
        ay = acc_world[n, 1]
        if corrected:
            out_acc[n, 0], out_acc[n, 1], out_gyro[n] = corrected_imu(ax, ay, yaw_rate[n], c, s, params, seed, env_id,
                                                                      step, n)
            for ch in range(3):
                bias[n, ch] += (params.gyro_walk if ch == 2 else params.acc_walk) * normal(key, WALK_INDEX + ch)
            continue
        bx = bias[n, 0] + params.acc_bias_x if params.acc_bias_x != 0.0 else bias[n, 0]
        by = bias[n, 1] + params.acc_bias_y if params.acc_bias_y != 0.0 else bias[n, 1]
        bg = bias[n, 2] + params.gyro_bias if params.gyro_bias != 0.0 else bias[n, 2]
        out_acc[n, 0] = (c * ax + s * ay) + bx + params.acc_sigma * normal(key, NOISE_INDEX)
        out_acc[n, 1] = (-s * ax + c * ay) + by + params.acc_sigma * normal(key, NOISE_INDEX + 1)
        out_gyro[n] = yaw_rate[n] + bg + params.gyro_sigma * normal(key, NOISE_INDEX + 2)
        bias[n, 0] += params.acc_walk * normal(key, WALK_INDEX)
        bias[n, 1] += params.acc_walk * normal(key, WALK_INDEX + 1)
        bias[n, 2] += params.gyro_walk * normal(key, WALK_INDEX + 2)


@njit(cache=True, parallel=True)
def _imu_step_batch(acc_world, yaw, yaw_rate, bias, params, seed, env_ids, step, out_acc, out_gyro):
    for b in prange(acc_world.shape[0]):
        imu_env(acc_world[b], yaw[b], yaw_rate[b], bias[b], params, seed, env_ids[b], step, out_acc[b],
                out_gyro[b])


@njit(cache=True, parallel=True)
def _imu_trajectory_batch(acc_world, yaw, yaw_rate, bias, params, seed, env_ids, step0, out_acc, out_gyro):
    T = acc_world.shape[0]
    for b in prange(acc_world.shape[1]):
        for t in range(T):
            imu_env(acc_world[t, b], yaw[t, b], yaw_rate[t, b], bias[b], params, seed, env_ids[b], step0 + t,
                    out_acc[t, b], out_gyro[t, b])


def _check_env_ids(env_ids, n_envs):
    env_ids = np.ascontiguousarray(env_ids, dtype=np.int64)
    if env_ids.ndim != 1 or env_ids.size == 0 or (n_envs is not None and env_ids.size != n_envs):
        want = "a non-empty 1-D array" if n_envs is None else f"shape ({n_envs},)"
        raise ConfigError(f"env_ids has shape {env_ids.shape}: expected {want} of environment indices")
    return env_ids


def _check_bias(bias, B, N):
    bias = bias.bias if isinstance(bias, ImuState) else bias
    if not isinstance(bias, np.ndarray) or bias.shape != (B, N, 3) or bias.dtype != np.float64 \
            or not bias.flags.c_contiguous or not bias.flags.writeable:
        desc = f"shape {bias.shape}, dtype {bias.dtype}" if isinstance(bias, np.ndarray) else type(bias).__name__
        raise ConfigError(f"bias ({desc}): expected a writeable C-contiguous float64 array of shape "
                          f"(B, N, 3) = ({B}, {N}, 3), updated in place (use ImuState.zeros)")
    return bias


def _as_f64(name, a, shape):
    a = np.ascontiguousarray(a, dtype=np.float64)
    if a.shape != shape:
        raise ConfigError(f"{name} has shape {a.shape}: expected {shape}")
    return a


def ideal_imu(acc_world, yaw, yaw_rate):
    """Error-free readings: (acc_body (..., 2) m/s², gyro (...,) rad/s).

    acc_world (..., 2) world-frame m/s²; yaw, yaw_rate (...) — any matching leading shape.
    """
    acc_world = np.asarray(acc_world, dtype=np.float64)
    yaw = np.asarray(yaw, dtype=np.float64)
    c, s = np.cos(yaw), np.sin(yaw)
    ax, ay = acc_world[..., 0], acc_world[..., 1]
    acc_body = np.stack([c * ax + s * ay, -s * ax + c * ay], axis=-1)
    return acc_body, np.array(yaw_rate, dtype=np.float64, copy=True)


def imu_step(acc_world, yaw, yaw_rate, bias, params: ImuModel, seed: int, env_ids, step: int):
    """Readings of every copter in B environments at step ``step``; advances ``bias`` in place.

    acc_world (B, N, 2) m/s² world frame (``WorldState.acc``); yaw, yaw_rate (B, N);
    bias: (B, N, 3) float64 array or :class:`ImuState`, updated b_k → b_{k+1};
    env_ids (B,) global environment indices; step: the world step (``WorldState.step``) keying the noise.
    Returns (acc_body_meas (B, N, 2) m/s² body frame, gyro_meas (B, N) rad/s).
    """
    acc_world = np.ascontiguousarray(acc_world, dtype=np.float64)
    if acc_world.ndim != 3 or acc_world.shape[2] != 2:
        raise ConfigError(f"acc_world has shape {acc_world.shape}: expected (B, N, 2) m/s^2")
    B, N, _ = acc_world.shape
    yaw = _as_f64("yaw", yaw, (B, N))
    yaw_rate = _as_f64("yaw_rate", yaw_rate, (B, N))
    bias = _check_bias(bias, B, N)
    env_ids = _check_env_ids(env_ids, B)
    out_acc = np.empty((B, N, 2))
    out_gyro = np.empty((B, N))
    _imu_step_batch(acc_world, yaw, yaw_rate, bias, params, int(seed), env_ids, int(step), out_acc, out_gyro)
    return out_acc, out_gyro


def imu_from_trajectory(traj, params: ImuModel, seed: int, env_ids, step0: int, bias=None):
    """IMU readings along a recorded :class:`~finkensim.world.Trajectory` (samples taken before each step).

    Sample t is the state after ``step0 + t`` steps and uses the noise of that step, so this equals
    calling :func:`imu_step` on each recorded state in turn with ``step = step0 + t``.
    ``bias``: initial bias (B, N, 3) or :class:`ImuState`, advanced in place through all T samples
    (default: zero, not returned). Returns (imu_acc (T, B, N, 2) m/s², imu_gyro (T, B, N) rad/s).
    """
    acc_world = np.ascontiguousarray(traj.acc, dtype=np.float64)
    if acc_world.ndim != 4 or acc_world.shape[3] != 2:
        raise ConfigError(f"traj.acc has shape {acc_world.shape}: expected (T, B, N, 2) m/s^2")
    T, B, N, _ = acc_world.shape
    pose = np.asarray(traj.pose)
    if pose.shape != (T, B, N, 3):
        raise ConfigError(f"traj.pose has shape {pose.shape}: expected (T, B, N, 3) = ({T}, {B}, {N}, 3)")
    yaw = np.ascontiguousarray(pose[..., 2], dtype=np.float64)
    yaw_rate = _as_f64("traj.yaw_rate", traj.yaw_rate, (T, B, N))
    bias = np.zeros((B, N, 3)) if bias is None else _check_bias(bias, B, N)
    env_ids = _check_env_ids(env_ids, B)
    out_acc = np.empty((T, B, N, 2))
    out_gyro = np.empty((T, B, N))
    _imu_trajectory_batch(acc_world, yaw, yaw_rate, bias, params, int(seed), env_ids, int(step0), out_acc,
                          out_gyro)
    return out_acc, out_gyro
