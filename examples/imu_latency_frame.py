"""Why an IMU latency left a gap after calibration: the simulator and the diagnosis delayed it in different frames.

The simulator's ``imu.latency`` (and the ``latency`` validation case) show at step k the *body-frame* reading
measured at step k − L, so a log's reading is R(−ψ[k−L])·a[k−L], a the world-frame acceleration and ψ the yaw.
The diagnosis turns each logged reading into the world frame with the log's yaw *at its own sample*, ψ[k], and its
latency model predicts the world-frame velocity change over each window at the delayed steps
(``gap/model/predictive.py``, the IMU table's ``_ideal``): it expects a[k−L], it sees R(ψ[k] − ψ[k−L])·a[k−L].
This script flies one noiseless flight of the ``latency`` case's scenario (random walk, the default conventions)
and prints how large that rotation is against the IMU's own white noise over the diagnosis's 1 s windows, and what
is left of it after the turn the diagnosis now applies to each delayed window (``gap/model/imu_latency.py``: the
window's mean turn and its first-order change across the window).

    nice -n 10 python examples/imu_latency_frame.py [latency_s]

(docs/calibration.md quotes its output.)
"""
from __future__ import annotations

import sys

import numpy as np

from finkensim.gap.model.imu_latency import imu_latency_turn, turn_windows
from finkensim.gap.validation.cases import base_config
from finkensim.gap.validation.conventions import DEFAULT_CONVENTIONS
from finkensim.scenario import simulate_flight


def rotate(yaw: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v (..., 2) rotated by yaw (...) rad."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def window_sums(a: np.ndarray, h: int, dt: float) -> np.ndarray:
    """Integrals over consecutive windows of h samples of a (T, ...) sampled every dt s."""
    n = a.shape[0] // h
    return a[: n * h].reshape(n, h, *a.shape[1:]).sum(axis=1) * dt


def main(latency: float = 0.3, seconds: float = 30.0) -> None:
    cfg = base_config(DEFAULT_CONVENTIONS.sim_updates())
    log, _, _ = simulate_flight(cfg, duration=seconds, seed=100000, ideal=True)
    dt = cfg.simulation.dt
    lag, h = int(round(latency / dt)), int(round(1.0 / dt))
    body = log.extras["imu_acc_ideal"]                 # (T, N, 2) m/s², body frame, no noise
    yaw = np.unwrap(log.pose[..., 2], axis=0)           # (T, N) rad
    expected = rotate(yaw, body)[:-lag]                 # the model: world frame at the delayed step
    seen = rotate(yaw[lag:], body[:-lag])               # the log: the delayed reading, rotated with today's yaw
    turn = np.abs(yaw[lag:] - yaw[:-lag])
    rms = lambda x: float(np.sqrt(np.mean(x ** 2)))     # noqa: E731
    print(f"latency {latency:g} s = {lag} samples of {dt:g} s; {log.pose.shape[1]} copters, {seconds:g} s")
    print(f"yaw turned during the lag: median {np.median(turn):.3f} rad, 90th percentile {np.percentile(turn, 90):.3f} rad")
    print(f"1 s window velocity change, rms: {rms(window_sums(expected, h, dt)):.4f} m/s")
    print(f"its rotation error (seen - expected), rms: {rms(window_sums(seen - expected, h, dt)):.4f} m/s")
    # the diagnosis's turn: window n of the delayed samples [n h, (n + 1) h) is stamped lag samples later
    n = window_sums(expected, h, dt).shape[0]
    ends = np.arange(2, n) * h + h - 1                 # windows whose first sample has two before it (for u_{i−1})
    times = ends.astype(np.int64)
    turn, shift = np.empty((ends.size, yaw.shape[1])), np.empty((ends.size, yaw.shape[1], 2))
    imu_latency_turn(log.pose[..., :2], yaw, log.t, times + lag, times, h, 1, turn, shift)
    windows = np.moveaxis(window_sums(expected, h, dt)[2:n], -1, 2)[..., None].copy()  # (n − 2, N, 2, 1)
    windows = np.concatenate([windows, np.zeros_like(windows[:, :, :1])], axis=2)       # + a Δψ channel
    turn_windows(windows, turn, shift)
    left = window_sums(seen, h, dt)[2:n] - np.moveaxis(windows[:, :, :2, 0], 2, -1)
    print(f"after the diagnosis's turn (mean and first-order change), rms: {rms(left):.5f} m/s")
    print(f"accelerometer white noise over a 1 s window, sd: {cfg.imu.acc_noise_density:.4f} m/s")


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 0.3)
