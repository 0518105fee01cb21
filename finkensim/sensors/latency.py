"""Sensor latency: a reading describes the world some time earlier.

One law serves the simulator and the gap diagnosis. A latency of ``seconds`` is :func:`lag_steps` whole samples of
the stream's period (nearest; ties away from 0), and the reading shown at step k is the one measured at step
``max(k − lag, first)``, ``first`` being the first step measured (before it there is no older reading: the first
one is shown). The diagnosis predicts a log's readings from the poses at those steps (:func:`delayed_steps`); the
simulator keeps the readings of the last ``lag`` steps in a ring buffer and shows the delayed one
(:func:`delay_env`, one call per sensor after it sensed).

The ring buffer of one environment, ``buf`` (slots, N, W) float64: ``slots`` = the largest lag + 1, one column
block per delayed sensor (:func:`delay_columns`: sonar 4, ranging R, IMU 3 — accelerometer x, y and gyro — in
this order, only for sensors with a lag > 0) and a last column with the step each slot holds (−1: empty).
The config keys are ``sonar.latency``, ``ranging.latency`` and ``imu.latency`` (s, neutral default 0: nothing is
buffered and every reading is the step's own).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["lag_steps", "delayed_steps", "sensor_lags", "delay_columns", "delay_buffer", "delay_env",
           "delay_batch", "delay_reference", "LAG_SONAR", "LAG_RANGING", "LAG_IMU"]

#: positions of the sensors in the lags array (:func:`sensor_lags`)
LAG_SONAR, LAG_RANGING, LAG_IMU = 0, 1, 2


def lag_steps(seconds: float, dt: float) -> int:
    """A latency of ``seconds`` as whole samples of a stream with sample period ``dt`` s (nearest; ties away from
    0; negative for a negative latency)."""
    x = seconds / dt
    return int(math.copysign(math.floor(abs(x) + 0.5), x))


def delayed_steps(steps: np.ndarray, lag: int, n: int) -> np.ndarray:
    """The steps (same shape as ``steps``, int) whose world the readings at ``steps`` describe with a lag of ``lag``
    samples, in a stream of ``n`` samples that starts at 0: ``clip(steps − lag, 0, n − 1)`` (the diagnosis's side
    of the law; a negative lag looks ahead, which only a recorded log can)."""
    return np.clip(np.asarray(steps) - int(lag), 0, int(n) - 1)


def sensor_lags(sonar_latency: float, ranging_latency: float, imu_latency: float, dt: float) -> np.ndarray:
    """The lags (3,) int64 in simulation steps of sonar, ranging and IMU (:data:`LAG_SONAR` …) from their latencies
    (s, ≥ 0) and the step dt (s)."""
    lags = np.array([lag_steps(s, dt) for s in (sonar_latency, ranging_latency, imu_latency)], dtype=np.int64)
    if (lags < 0).any():
        raise ValueError(f"latencies ({sonar_latency}, {ranging_latency}, {imu_latency}) s: expected >= 0 s "
                         "(a simulated reading cannot describe a later world)")
    return lags


@njit(cache=True)
def delay_columns(lags, R):
    """(first column of the sonar, ranging and IMU blocks, total width W) of the ring buffer for ``lags`` (3,)
    and R ranging columns; a sensor without lag has no block (its first column is −1)."""
    cols = np.full(3, -1, dtype=np.int64)
    widths = (4, R, 3)
    w = 0
    for s in range(3):
        if lags[s] > 0:
            cols[s] = w
            w += widths[s]
    return cols, w + 1


def delay_buffer(lags: np.ndarray, B: int, N: int, R: int) -> np.ndarray:
    """An empty ring buffer (B, slots, N, W) for B environments of N copters with R ranging columns; (B, 0, N, 0)
    when no sensor has a lag. A buffer beyond the memory available is a
    :class:`~finkensim.budget.MemoryBudgetError` naming the latency keys."""
    if int(np.max(lags, initial=0)) <= 0:
        return np.zeros((B, 0, N, 0))
    from ..budget import check_memory

    _, W = delay_columns(np.asarray(lags, dtype=np.int64), int(R))
    shape = (B, int(np.max(lags)) + 1, N, W)
    check_memory({f"latency ring buffer {shape}": 8.0 * math.prod(shape)},
                 f"sensor latencies of {tuple(int(x) for x in lags)} steps (sonar, ranging, imu) for {B} x {N} copters",
                 "lower sonar.latency / ranging.latency / imu.latency, or raise simulation.dt")
    return np.full(shape, -1.0)


@njit(cache=True, error_model="numpy")
def delay_env(values, buf, col, k, lag):
    """Store ``values`` (N, C) — a sensor's readings measured at step k — in the ring buffer ``buf`` (slots, N, W)
    at columns col … col + C − 1, and replace them in place with the readings of step ``max(k − lag, first)``
    (``first``: the earliest step the buffer still holds when k − lag was never stored). ``lag`` ≥ 1 and
    slots > lag."""
    slots = buf.shape[0]
    N, C = values.shape
    stamp = buf.shape[2] - 1
    s = k % slots
    for n in range(N):
        for c in range(C):
            buf[s, n, col + c] = values[n, c]
        buf[s, n, stamp] = k
    src = k - lag
    slot = src % slots if src >= 0 else -1
    if slot < 0 or buf[slot, 0, stamp] != src:
        slot = s  # the earliest step held: the smallest stamp >= 0
        for j in range(slots):
            if 0.0 <= buf[j, 0, stamp] < buf[slot, 0, stamp]:
                slot = j
    for n in range(N):
        for c in range(C):
            values[n, c] = buf[slot, n, col + c]


def delay_batch(values: np.ndarray, buf: np.ndarray, lags: np.ndarray, sensor: int, k: int, R: int,
                offset: int = 0) -> None:
    """:func:`delay_env` for each of B environments from Python (the reference sense step and the controlled
    steps): values (B, N, C) or (B, N) (one column) readings of ``sensor`` (:data:`LAG_SONAR` …) measured at step
    k, delayed in place; buf (B, slots, N, W) the environments' ring buffers; R ranging columns; ``offset``: the
    first column within the sensor's block (the IMU's gyro follows its two accelerometer columns: offset 2).
    Nothing happens when the sensor has no lag."""
    lag = int(lags[sensor])
    if lag <= 0:
        return
    col = int(delay_columns(np.asarray(lags, dtype=np.int64), int(R))[0][sensor]) + int(offset)
    for b in range(values.shape[0]):
        v = values[b] if values.ndim == 3 else values[b].reshape(-1, 1)
        delay_env(v, buf[b], col, int(k), lag)


def delay_reference(readings: np.ndarray, lag: int) -> np.ndarray:
    """NumPy reference of a stream through :func:`delay_env`: readings (T, ...) measured at steps 0 … T − 1 →
    what is shown at each step, ``readings[max(t − lag, 0)]`` (the law of :func:`delayed_steps`)."""
    T = readings.shape[0]
    return readings[delayed_steps(np.arange(T), lag, T)]
