"""Plain NumPy reference of finkensim.gap.model.imu_latency, used only by tests.

Written from the IMU table's definition with a different structure from the kernel: the window's weights are the
table's integration of a reading applied to unit impulses (the cumulative sums of ``ImuTable.build``: a box of h
samples averaged over the b window ends), not the kernel's closed-form count; the velocity changes are whole-flight
arrays of NumPy differences, looked up by index; the turn of the windows is a matrix product."""
from __future__ import annotations

import numpy as np


def window_weights(t, s, h, b):
    """(T,) the weight of every sample of t (T,) s in the window integral ending at sample s: the table's trapezoid
    Σ_{j'=s−b+1..s} (W_{j'} − W_{j'−h}) / b of the cumulative integral W = cumsum(a·dt), read off for a = 1 at one
    sample at a time (so the weight includes the sample's dt)."""
    T = t.size
    dts = np.diff(t, prepend=t[0])
    out = np.zeros(T)
    for j in range(T):
        a = np.zeros(T)
        a[j] = 1.0
        W = np.cumsum(a * dts)
        out[j] = sum(W[e] - W[e - h] for e in range(s - b + 1, s + 1)) / b
    return out


def naive_imu_latency_turn(pos, yaw_unwrapped, t, samples, times, h, b):
    """(turn (K, N) rad, shift (K, N, 2) m/s): the weighted mean over the window ending at samples[k] of the turn
    θ_j = ψ[j] − ψ[j − d], d = samples[k] − times[k], with the weights of :func:`window_weights`; and the sum over
    the window of (weight / dt_j)·β·(t_j − t̄)·Δu[j − d], β the weighted least-squares slope of θ in time (t̄ the
    weighted mean time: :func:`numpy.polyfit` with weights √w), Δu the change of the one-step velocities
    u_i = (p_i − p_{i−1}) / (t_i − t_{i−1}) from sample i − 1 to i."""
    K, N = samples.size, yaw_unwrapped.shape[1]
    u = np.diff(pos, axis=0) / np.diff(t)[:, None, None]  # u[i - 1] = u_i
    du = np.full(pos.shape, np.nan)
    du[2:] = np.diff(u, axis=0)  # du[i] = u_i - u_{i-1}
    dts = np.diff(t, prepend=t[0])
    turn, shift = np.empty((K, N)), np.empty((K, N, 2))
    for k in range(K):
        w = window_weights(t, samples[k], h, b)
        d = samples[k] - times[k]
        j = np.flatnonzero(w)
        theta = yaw_unwrapped[j] - yaw_unwrapped[j - d]  # (J, N)
        turn[k] = (w[j, None] * theta).sum(axis=0) / w[j].sum()
        tbar = (w[j] * t[j]).sum() / w[j].sum()
        slope = np.polyfit(t[j], theta, 1, w=np.sqrt(w[j]))[0] if j.size > 1 and np.ptp(t[j]) > 0 else np.zeros(N)
        dev = slope[None, :] * (t[j] - tbar)[:, None]  # (J, N)
        shift[k] = ((w[j] / dts[j])[:, None, None] * dev[..., None] * du[j - d]).sum(axis=0)
    return turn, shift


def naive_turn_windows(windows, turn, shift):
    """windows (K, N, 3, G) with channels 0, 1 replaced by R(turn)·(v + R(π/2)·shift); channel 2 as is."""
    def rotation(a):
        c, s = np.cos(a), np.sin(a)
        return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)  # (..., 2, 2)

    out = windows.copy()
    v = windows[:, :, :2, :] + np.einsum("ij,knj->kni", rotation(np.pi / 2), shift)[..., None]
    out[:, :, :2, :] = np.einsum("knij,knjg->knig", rotation(turn), v)
    return out
