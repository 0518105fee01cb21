"""Sample-and-hold of the sonars: a new measurement ``update_hz`` times a second, held in between.

A real sonar may measure less often than the simulation steps (a sonar ring fires its sonars in turn; the FINken's
2015 log bounds its rate from below only: ``notebooks/09_real_finken_sonar.ipynb``). The sonars take a
measurement at the instants ``t = phase + m / update_hz`` (s, m = 0, 1, ...), each at the first step at or after
it, and show it until the next one; ``update_hz <= 0`` measures at every step (the neutral default,
``sonar.update_hz = 0``).

One kernel, :func:`held_step` — the step whose measurement is shown at step k — is what both users call: the
simulator's sense step (:func:`hold_env`: keep the held readings unless k is a measuring step) and the gap
diagnosis (:func:`held_steps`: predict each reading from the poses at the step it was measured,
``sonar_update_rate`` in :mod:`finkensim.gap.attribute.effects`). Times are measured from step 0 (``t = k · dt``).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["held_step", "held_steps", "hold_env", "EPS_STEPS"]

#: rounding allowance (in steps / periods) so that an update instant that falls on a step counts as that step
EPS_STEPS = 1e-9


@njit(cache=True, inline="always")
def _measuring_step(m, dt, update_hz, phase):
    """The step at which measurement m (at t = phase + m / update_hz s) is taken: the first at or after it, as a
    float (a slow rate puts measurement m ± 1 beyond any int64 step: ±inf compares correctly, an overflowed integer
    made the search below loop for ever)."""
    return np.ceil((phase + m / update_hz) / dt - EPS_STEPS)


@njit(cache=True, inline="always")
def held_step(k, dt, update_hz, phase):
    """The step (int, 0 ≤ result ≤ k) whose measurement a sample-and-hold sonar shows at step ``k``: the latest
    measuring step at or before k (measurements before t = 0 count as taken at step 0).

    Args: k step index; dt s per step; update_hz measurements per second (≤ 0: every step, returns k); phase s,
    the first measurement instant (any real number: only its value modulo the period matters).
    """
    if update_hz <= 0.0:
        return k
    period = 1.0 / update_hz
    if phase < 0.0 or phase >= period:
        # only the phase modulo the period matters; far from [0, period) the count m below would be too large for
        # a float to step by one (a phase of 1e300 s looped for ever)
        phase = phase % period
    m = math.floor((k * dt - phase) * update_hz)            # about the last measurement at or before step k
    while _measuring_step(m, dt, update_hz, phase) > k:     # rounding: step back or on, by the step rule itself
        m -= 1
    while _measuring_step(m + 1, dt, update_hz, phase) <= k:
        m += 1
    u = _measuring_step(m, dt, update_hz, phase)
    return np.int64(u) if u > 0 else 0


@njit(cache=True)
def held_steps(steps, dt, update_hz, phase):
    """:func:`held_step` of every entry of ``steps`` (m,) int64 → (m,) int64 (the diagnosis's sample indices)."""
    out = np.empty(steps.shape[0], dtype=np.int64)
    for i in range(steps.shape[0]):
        out[i] = held_step(steps[i], dt, update_hz, phase)
    return out


@njit(cache=True, inline="always")
def hold_env(son, held, k, dt, update_hz, phase):
    """Sample-and-hold of one environment's sonar readings ``son`` (N, S) m at step k, in place: at a measuring
    step (:func:`held_step` is k) ``held`` (N, S) takes the new readings; otherwise ``son`` shows ``held``."""
    if held_step(k, dt, update_hz, phase) == k:
        for n in range(son.shape[0]):
            for j in range(son.shape[1]):
                held[n, j] = son[n, j]
    else:
        for n in range(son.shape[0]):
            for j in range(son.shape[1]):
                son[n, j] = held[n, j]
