"""Proper scoring rules for predictive distributions given as ensembles of draws.

For a predictive distribution F with draws X, X' ~ F and an observation y::

    CRPS(F, y) = E|X − y| − ½ E|X − X'|                     (Gneiting & Raftery 2007, eq. 21)

If y itself came from F, E_y[CRPS(F, y)] = ½ E|X − X'|. The per-reading *gap*::

    gap(F, y) = CRPS(F, y) − ½ E|X − X'| = E|X − y| − E|X − X'|

is therefore exactly zero on average when the real readings could have come from the model,
positive when they are further from the model's draws than its draws are from each other.
Both terms are computed from an M-member ensemble with the unbiased ("fair") estimator of
E|X − X'| (divide by M(M − 1)), in O(M log M) per reading by sorting.

Binary events (a reading is missing or not) use the Brier score, the CRPS of a Bernoulli:
(p − z)², with expectation p(1 − p) under the model.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange
from scipy.special import ndtr  # not scipy.stats: it takes a quarter second of every process's start


@njit(cache=True, inline="always")
def _sorted_terms(xs, y):
    """For sorted draws xs (M,): (mean |X − y|, fair mean |X − X'|)."""
    M = xs.shape[0]
    s_abs = 0.0
    for k in range(M):
        s_abs += abs(xs[k] - y)
    # Σ_{i<j} (x_j − x_i) = Σ_k x_k (2k − M + 1) for sorted x
    s_pair = 0.0
    for k in range(M):
        s_pair += xs[k] * (2.0 * k - M + 1.0)
    mean_abs = s_abs / M
    mean_pair = 2.0 * s_pair / (M * (M - 1.0)) if M > 1 else 0.0
    return mean_abs, mean_pair


@njit(cache=True, inline="always")
def _grouped_terms(x, y, period):
    """(mean |X − y|, mean |X_i − X_j| over pairs with i ≢ j mod period) for one reading."""
    M = x.shape[0]
    s_abs = 0.0
    for k in range(M):
        s_abs += abs(x[k] - y)
    s_pair = 0.0
    n_pair = 0
    for i in range(M):
        skip = i + period  # the members j ≡ i (mod period) after i, stepped instead of a modulo per pair
        for j in range(i + 1, M):
            if j == skip:
                skip += period
                continue
            s_pair += abs(x[i] - x[j])
            n_pair += 1
    return s_abs / M, (s_pair / n_pair if n_pair > 0 else 0.0)


@njit(cache=True, inline="always")
def _grouped_terms4(draws, y, i0, period, t_abs, t_pair):
    """:func:`_grouped_terms` of rows i0 … i0 + 3 (finite observations, one period) at once → t_abs, t_pair.

    Each row's sums run in the same order as :func:`_grouped_terms` (bit for bit); four rows side by side give
    the CPU four independent chains of additions instead of one, whose latency bounds the single-row loop."""
    M = draws.shape[1]
    a0 = a1 = a2 = a3 = 0.0
    for k in range(M):
        a0 += abs(draws[i0, k] - y[i0])
        a1 += abs(draws[i0 + 1, k] - y[i0 + 1])
        a2 += abs(draws[i0 + 2, k] - y[i0 + 2])
        a3 += abs(draws[i0 + 3, k] - y[i0 + 3])
    p0 = p1 = p2 = p3 = 0.0
    n_pair = 0
    for i in range(M):
        skip = i + period
        x0 = draws[i0, i]
        x1 = draws[i0 + 1, i]
        x2 = draws[i0 + 2, i]
        x3 = draws[i0 + 3, i]
        for j in range(i + 1, M):
            if j == skip:
                skip += period
                continue
            p0 += abs(x0 - draws[i0, j])
            p1 += abs(x1 - draws[i0 + 1, j])
            p2 += abs(x2 - draws[i0 + 2, j])
            p3 += abs(x3 - draws[i0 + 3, j])
            n_pair += 1
    t_abs[i0] = a0 / M
    t_abs[i0 + 1] = a1 / M
    t_abs[i0 + 2] = a2 / M
    t_abs[i0 + 3] = a3 / M
    if n_pair > 0:
        t_pair[i0] = p0 / n_pair
        t_pair[i0 + 1] = p1 / n_pair
        t_pair[i0 + 2] = p2 / n_pair
        t_pair[i0 + 3] = p3 / n_pair
    else:
        t_pair[i0:i0 + 4] = 0.0


@njit(cache=True, inline="always")
def _terms_row(draws, y, period, i, t_abs, t_pair):
    """The two terms of row i → t_abs[i], t_pair[i] (NaN for a non-finite observation)."""
    M = draws.shape[1]
    if not np.isfinite(y[i]):
        t_abs[i] = np.nan
        t_pair[i] = np.nan
    elif period[i] <= 1 or period[i] >= M:
        xs = np.sort(draws[i])
        t_abs[i], t_pair[i] = _sorted_terms(xs, y[i])
    else:
        t_abs[i], t_pair[i] = _grouped_terms(draws[i], y[i], period[i])


@njit(cache=True, parallel=True)
def ensemble_terms_grouped(draws, y, period):
    """Like :func:`ensemble_terms`, for ensembles whose members m and m + period share a random input
    (e.g. a pose draw reused cyclically): the pair term uses only independent pairs, which keeps it
    unbiased. period (n,) int64; period ≤ 1 or ≥ M means all members are independent. Rows are taken four
    at a time where four neighbours share a grouping period (the same numbers as row by row)."""
    n, M = draws.shape
    t_abs = np.empty(n)
    t_pair = np.empty(n)
    for b in prange((n + 3) // 4):
        i0 = 4 * b
        if i0 + 4 <= n:
            p = period[i0]
            same = (period[i0 + 1] == p) & (period[i0 + 2] == p) & (period[i0 + 3] == p) & (p > 1) & (p < M)
            finite = (np.isfinite(y[i0]) & np.isfinite(y[i0 + 1]) & np.isfinite(y[i0 + 2])
                      & np.isfinite(y[i0 + 3]))
            if same and finite:
                _grouped_terms4(draws, y, i0, p, t_abs, t_pair)
                continue
        for i in range(i0, min(i0 + 4, n)):
            _terms_row(draws, y, period, i, t_abs, t_pair)
    return t_abs, t_pair


def ensemble_terms(draws, y):
    """Per reading: (E|X − y|, E|X − X'|) from an ensemble of independent members.

    draws (n, M) float64 predictive draws; y (n,) observations → two (n,) arrays. Readings with
    a non-finite observation give NaN. (:func:`ensemble_terms_grouped` with every period 1.)
    """
    return ensemble_terms_grouped(draws, y, np.ones(draws.shape[0], dtype=np.int64))


def crps_ensemble(draws, y):
    """CRPS of ensemble forecasts (fair estimator). draws (n, M), y (n,) → (n,), same units as y."""
    draws, y = _as_inputs(draws, y)
    a, p = ensemble_terms(draws, y)
    return a - 0.5 * p


def gap_ensemble(draws, y):
    """Per-reading gap E|X − y| − E|X − X'| (zero-mean when y ~ the ensemble's distribution). (n, M), (n,) → (n,)."""
    draws, y = _as_inputs(draws, y)
    a, p = ensemble_terms(draws, y)
    return a - p


def crps_normal(mu, sigma, y):
    """Closed-form CRPS of N(mu, sigma²) at y (Gneiting et al. 2005). Broadcasts; sigma > 0."""
    mu, sigma, y = np.broadcast_arrays(np.asarray(mu, float), np.asarray(sigma, float), np.asarray(y, float))
    z = (y - mu) / sigma
    return sigma * (z * (2.0 * ndtr(z) - 1.0) + 2.0 * normal_pdf(z) - 1.0 / np.sqrt(np.pi))


def normal_pdf(z):
    """Standard normal density at z (array), as ``scipy.stats.norm.pdf`` computes it (the same numbers)."""
    return np.exp(-z ** 2 / 2.0) / np.sqrt(2 * np.pi)


def normal_sf(z: float) -> float:
    """Standard normal upper tail P(Z > z), as ``scipy.stats.norm.sf`` computes it (``ndtr(−z)``, the same
    number)."""
    return float(ndtr(-z))


def brier(p, z):
    """Brier score (p − z)² of probability p for a binary outcome z ∈ {0, 1}."""
    return (np.asarray(p, float) - np.asarray(z, float)) ** 2


def brier_gap(p, z):
    """Brier score minus its expectation p(1 − p) under the model: zero-mean when z ~ Bernoulli(p)."""
    p = np.asarray(p, float)
    return brier(p, z) - p * (1.0 - p)


def _as_inputs(draws, y):
    draws = np.ascontiguousarray(draws, dtype=np.float64)
    y = np.ascontiguousarray(y, dtype=np.float64)
    if draws.ndim != 2 or y.ndim != 1 or draws.shape[0] != y.shape[0]:
        raise ValueError(f"draws has shape {draws.shape} and y {y.shape}: expected (n, M) and (n,)")
    if draws.shape[1] < 2:
        raise ValueError(f"draws has {draws.shape[1]} members per reading: expected at least 2")
    return draws, y
