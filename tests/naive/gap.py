"""Plain NumPy references for the gap-diagnosis kernels (slow, readable; tests only).

Each is written from its definition with a different structure from the kernel: the ensemble terms by brute force
over all member pairs (the kernel sorts), cross-talk paths and line-of-sight clearances by loops over every copter
and sonar (the kernels cull), IMU windows from exact poses, and the bulge's first-order lag as the exact solution of
its ODE (the kernel runs a recursion).

What it shares and why: ``sonar_reading_draws`` takes the reading draws from ``tests.naive.sonar.naive_measured``
and the counter-based numbers of ``finkensim.kernels.rng`` in the diagnosis's documented layout (draw m uses block m of
the reading's STREAM_EFFECT numbers): the error model is the simulator's (one model), so this checks the diagnosis's
bookkeeping, not the model. The CRPS itself is checked against ``scoringrules`` (``tests/test_gap_censoring.py``)."""
from __future__ import annotations

import math

import numpy as np

from finkensim.kernels.rng import STREAM_EFFECT, normals_array, uniforms_array

from .sonar import naive_measured


def ensemble_terms(draws, y, period=None):
    """(E|X − y|, E|X − X'|) by brute force over all pairs (excluding pairs i ≡ j mod period)."""
    n, M = draws.shape
    a = np.abs(draws - y[:, None]).mean(axis=1)
    i, j = np.triu_indices(M, 1)
    b = np.empty(n)
    for r in range(n):
        keep = np.ones(i.size, bool)
        if period is not None and 1 < period[r] < M:
            keep = (j - i) % period[r] != 0
        b[r] = np.abs(draws[r, i[keep]] - draws[r, j[keep]]).mean()
    a[~np.isfinite(y)] = np.nan
    b[~np.isfinite(y)] = np.nan
    return a, b


def sonar_reading_draws(dist, kind, xtalk, flight, tidx, chan, seed, sp):
    """Reading draws (n, M) from ideal draws with the simulator's measured-reading reference, draw m using
    block m of the reading's STREAM_EFFECT numbers."""
    n, M = dist.shape
    out = np.empty((n, M))
    for i in range(n):
        u = uniforms_array(seed, flight[i], tidx[i], chan[i], STREAM_EFFECT, 8 * M)
        z = normals_array(seed, flight[i], tidx[i], chan[i], STREAM_EFFECT, 4 * M)
        for m in range(M):
            out[i, m] = naive_measured(dist[i, m], kind[i, m] != 0, xtalk[i, m], m, u, z, sp)
    return out


def crosstalk_paths(pos, yaw, mount_yaw, offset, max_range, cos_half):
    """Shortest mutual-view emitter→receiver path per (copter, sonar) at one time: (N, S), inf if none."""
    N, S = pos.shape[0], mount_yaw.size
    cy, sy = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    cm, sm = np.cos(mount_yaw)[None, :], np.sin(mount_yaw)[None, :]
    u = np.stack([cy * cm - sy * sm, sy * cm + cy * sm], -1)  # (N, S, 2) headings, as the sonar kernel rotates them
    o = pos[:, None, :] + offset * u
    out = np.full((N, S), np.inf)
    for n in range(N):
        for s in range(S):
            for q in range(N):
                if q == n:
                    continue
                for j in range(S):
                    w = o[q, j] - o[n, s]
                    L = np.hypot(*w)
                    if 0 < L <= 2 * max_range and u[n, s] @ w >= cos_half * L and -(u[q, j] @ w) >= cos_half * L:
                        out[n, s] = min(out[n, s], L)
    return out


def clearance(pos):
    """(N, N) smallest distance of a third copter's centre to each line of sight at one time."""
    N = pos.shape[0]
    out = np.full((N, N), np.inf)
    for a in range(N):
        for b in range(N):
            if a == b:
                continue
            A, B = pos[a], pos[b]
            for c in range(N):
                if c in (a, b):
                    continue
                s = np.clip((pos[c] - A) @ (B - A) / max((B - A) @ (B - A), 1e-300), 0, 1)
                out[a, b] = min(out[a, b], np.hypot(*(A + s * (B - A) - pos[c])))
    return out


def imu_windows(pos, yaw_unwrapped, t, k, h, b=1):
    """(N, 3): Δv_x, Δv_y (world) and Δψ over the h steps ending at sample k, from exact poses; velocities
    are mean velocities over b steps."""
    v1 = (pos[k] - pos[k - b]) / (t[k] - t[k - b])
    v0 = (pos[k - h] - pos[k - h - b]) / (t[k - h] - t[k - h - b])
    return np.concatenate([v1 - v0, (yaw_unwrapped[k] - yaw_unwrapped[k - h])[:, None]], axis=1)


def first_order_lag(target, t, tau):
    """(T, S) plates following ``target`` (T, S) with time constant tau s on times t (T,), written as the
    exact solution of dx/dt = (target − x)/tau with the target held over each interval (not the kernel's
    recursion): x(t_k) = target_k + (x(t_{k−1}) − target_k)·exp(−(t_k − t_{k−1})/tau)."""
    out = [np.array(target[0], dtype=float)]
    for k in range(1, len(t)):
        out.append(target[k] + (out[-1] - target[k]) * math.exp(-(t[k] - t[k - 1]) / tau))
    return np.array(out)


def pair_sums_l1(r, a, b, n_nodes, iterations=20):
    """Per-node values whose pair sums fit ``r`` in least absolute deviations: the same reweighting, each step a
    least-squares solve of the dense (n, n_nodes) node-incidence design (minimum norm)."""
    design = np.zeros((r.size, n_nodes))
    rows = np.arange(r.size)
    np.add.at(design, (rows, a), 1.0)
    np.add.at(design, (rows, b), 1.0)
    weight = np.ones(r.size)
    sol = np.zeros(n_nodes)
    for _ in range(iterations):
        w = np.sqrt(weight)
        sol = np.linalg.lstsq(design * w[:, None], r * w, rcond=None)[0]
        weight = 1.0 / np.maximum(np.abs(r - design @ sol), 0.01)
    return sol
