"""The frame of a late IMU: the turn between a reading's measurement and the sample its log stamps it at.

A late IMU (``imu.latency``, L samples) shows at sample j the body-frame reading measured at j − L,
R(−ψ[j−L])·a[j−L] (a the world-frame acceleration, ψ the yaw). The IMU table
(:class:`~finkensim.gap.model.predictive.ImuTable`) turns every logged reading into the world frame with the log's
yaw at its own stamp, ψ[j], so a window's integral is Σ_j w_j R(θ_j)·a[j−L] dt_j with the turn θ_j = ψ[j] − ψ[j−L]
the copter made during the lag: the world-frame velocity change of the delayed window, each sample turned by its
own θ_j. The predictive side (:func:`~finkensim.gap.model.replay.imu_window_draws`) has that change Δv from poses,
unturned. Writing θ_j = θ̄ + δ_j with θ̄ the window's weighted mean turn,

    Σ_j w_j R(θ_j)·a_j dt_j = R(θ̄)·(Δv + J·C) + O(δ²),   C = Σ_j w_j δ_j a_j dt_j,   J = R(π/2),

where C is the turns' deviation from their mean weighted with the accelerations, taken from the log's poses
(a_j dt_j = u_j − u_{j−1}, u_j = (p_j − p_{j−1}) / (t_j − t_{j−1}) the one-step velocities: on a uniform time base
the simulator's accelerations exactly). δ_j is taken as the turn's linear trend across the window, β·(t_j − t̄)
(β its weighted least-squares slope in time), not each sample's own deviation: on tracked poses the latter, a
difference of noisy yaws times a second difference of noisy positions, is noise of order σ_ψ·σ_xy·√6/dt per
sample (about 1 m/s at 50 Hz with 9 mm of tracking noise), which made every lag but 0 fit worse than none.
:func:`imu_latency_turn` gives θ̄ and C per window, :func:`turn_windows` applies them to the draws. What is left
is the turn's change across a window beyond its linear trend (0.0017 m/s rms on a simulated random walk flown
with a 0.3 s latency, against 0.012 m/s unturned).

A lag of 0 turns nothing; the table does not call these then, so its numbers at lag 0 stay bit for bit.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, inline="always")
def _count(s, j, h, b):
    """c_j of :func:`imu_latency_turn`: how many of the table's b velocity ends j' ∈ [s − b + 1, s] have the stamp j
    in their window (j' − h, j'] (≤ 0 outside the window)."""
    return min(s, j + h - 1) - max(s - b + 1, j) + 1


@njit(cache=True, parallel=True)
def imu_latency_turn(pos, yaw_unwrapped, t, samples, times, h, b, turn, shift):
    """Per IMU window, the mean yaw turned during the lag, turn (K, N) rad, and the first-order term of its change
    across the window, shift (K, N, 2) m/s (world frame).

    pos (T, N, 2) m and yaw_unwrapped (T, N) rad: the log's poses (the yaw unwrapped along time); t (T,) s: the
    sample times; samples (K,) int: the sample each window of the table ends at (the readings' stamps); times (K,)
    int: the sample the predictive window ends at (``samples − L``, clipped to the log), the shift d = samples −
    times being the lag in samples. h, b: the window and the velocity baseline in samples
    (:func:`~finkensim.gap.model.predictive.imu_steps`).

    With s = samples[k] and the window's stamps j ∈ (s − h − b, s], c_j = #{j' ∈ [s − b + 1, s] : j' − h < j ≤ j'}
    (b times the table's trapezoid weight of sample j), dt_j = t[j] − t[j − 1] s and θ_j = ψ[j] − ψ[j − d]:

    turn[k, n] = Σ_j c_j dt_j θ_j / Σ_j c_j dt_j;
    shift[k, n] = Σ_j (c_j / b) β (t_j − t̄) (u_{j−d} − u_{j−d−1}), u_i = (p_i − p_{i−1}) / (t_i − t_{i−1}),
    with t̄ = Σ_j c_j dt_j t_j / Σ_j c_j dt_j and β = Σ_j c_j dt_j (t_j − t̄)(θ_j − turn) / Σ_j c_j dt_j (t_j − t̄)²
    (0 for a window of one sample).

    Needs h + b ≤ times[k] < T and samples[k] − times[k] ≤ samples[k] − h − b (true for ``times`` clipped to
    [h + b, T − 1]): every index then lies in [0, T).
    """
    K = samples.shape[0]
    N = yaw_unwrapped.shape[1]
    for k in prange(K):
        s = samples[k]
        d = s - times[k]
        lo = s - h - b + 1
        wsum = 0.0
        tbar = 0.0
        for n in range(N):
            turn[k, n] = 0.0
            shift[k, n, 0] = 0.0
            shift[k, n, 1] = 0.0
        for j in range(lo, s + 1):
            c = _count(s, j, h, b)
            if c <= 0:
                continue
            w = c * (t[j] - t[j - 1])
            wsum += w
            tbar += w * t[j]
            for n in range(N):
                turn[k, n] += w * (yaw_unwrapped[j, n] - yaw_unwrapped[j - d, n])
        tbar /= wsum
        tvar = 0.0
        for j in range(lo, s + 1):
            c = _count(s, j, h, b)
            if c > 0:
                tvar += c * (t[j] - t[j - 1]) * (t[j] - tbar) ** 2
        for n in range(N):
            turn[k, n] /= wsum
            # the turn's change across the window: its weighted least-squares slope in time (rad/s), not each
            # sample's own deviation (the tracked yaw's noise would make those, times the poses' one-step
            # accelerations, noise of metres per second at high rates)
            slope = 0.0
            if tvar > 0.0:
                for j in range(lo, s + 1):
                    c = _count(s, j, h, b)
                    if c > 0:
                        slope += c * (t[j] - t[j - 1]) * (t[j] - tbar) * (
                            yaw_unwrapped[j, n] - yaw_unwrapped[j - d, n] - turn[k, n])
                slope /= tvar
            for j in range(lo, s + 1):
                c = _count(s, j, h, b)
                if c <= 0:
                    continue
                i = j - d
                d1 = t[i] - t[i - 1]
                d0 = t[i - 1] - t[i - 2]
                dev = c / b * slope * (t[j] - tbar)
                for a in range(2):
                    du = (pos[i, n, a] - pos[i - 1, n, a]) / d1 - (pos[i - 1, n, a] - pos[i - 2, n, a]) / d0
                    shift[k, n, a] += dev * du


def turn_windows(windows: np.ndarray, turn: np.ndarray, shift: np.ndarray) -> None:
    """Turn the world-frame velocity changes of IMU window draws in place, Δv ← R(turn)·(Δv + J·shift):
    windows (K, N, 3, G), channels 0, 1 = Δv_x, Δv_y m/s, channel 2 = Δψ rad (a yaw change, unchanged by a turn of
    the frame); turn (K, N) rad counter-clockwise and shift (K, N, 2) m/s from :func:`imu_latency_turn`
    (J = R(π/2): J·(x, y) = (−y, x))."""
    c, s = np.cos(turn)[..., None], np.sin(turn)[..., None]
    vx = windows[:, :, 0, :] - shift[:, :, 1, None]
    vy = windows[:, :, 1, :] + shift[:, :, 0, None]
    windows[:, :, 0, :] = c * vx - s * vy
    windows[:, :, 1, :] = s * vx + c * vy
