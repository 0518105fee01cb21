"""The learned correction of the IMU (``imu.correction_file``): one table per channel of the window integrals.

The diagnosis compares the IMU over windows of W s (``gap.imu_window``): channels ``dv_x``, ``dv_y`` (m/s, the
world-frame velocity change integrated from the body-frame accelerometer) and ``dyaw`` (rad, the integrated gyro).
Its learned correction (:mod:`finkensim.gap.quantify.correction`) is therefore a table per channel of the residual
of a window integral around its model median (:class:`~finkensim.sensors.correction_table.ChannelTables`, file format
version 2, with the window W).

**The simulator** (:func:`corrected_imu`, called by :func:`~finkensim.sensors.imu.imu_env`) splits time into blocks of
h = max(1, round(W/dt)) steps. In block b = ⌊step/h⌋ each copter draws one uniform per channel,
u_c = ``uniform(counter_key(seed, env, b, copter, STREAM_CORRECTION_IMU), c)``, and every sample of the block reads

    world acceleration  a_w + R(ψ)·(acc_bias) + (Q_x(ref_x, u_x), Q_y(ref_y, u_y)) / W,   rotated into the body,
    yaw rate            ω + gyro_bias + Q_ψ(ref_ψ, u_ψ) / W,

ref_c the sample's model median scaled to a window (``(a_w + R(ψ)·acc_bias)·W``, ``(ω + gyro_bias)·W``), Q_c the
channel's quantile function in ref_c's bin. The correction replaces the error model's white noise and bias random
walk (the table was fitted on readings the model explained badly, noise included): a window that is one block
integrates to its model median plus a draw of Q_c. A window that straddles two blocks integrates to a blend of two
draws, narrower than Q_c: the table describes window integrals, and no per-sample law reproduces an arbitrary window
distribution at every window position. This is the approximation the IMU's correction makes.

**The diagnosis** (:func:`corrected_window_draws`) draws a window integral as its model median (ideal integral plus
the constant bias) plus Q_c at a uniform keyed per (seed, flight, time, channel) and draw.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..kernels.rng import STREAM_CORRECTION_IMU, counter_key, uniform
from .correction_table import ChannelTables, CorrectionFileError, correction_quantile, read_correction

__all__ = ["IMU_CHANNELS", "IMU_UNITS", "NO_IMU_TABLE", "corrected_imu", "corrected_window_draws", "imu_correction",
           "pack_channels"]

#: the IMU's channels in the diagnosis and in its correction table, and their units
IMU_CHANNELS = ("dv_x", "dv_y", "dyaw")
IMU_UNITS = ("m/s", "m/s", "rad")
#: "no correction": the ImuModel's ``correction`` without a file
NO_IMU_TABLE = np.zeros((0, 0, 0))


def pack_channels(tables: ChannelTables, where: str = "imu") -> np.ndarray:
    """The channel tables of :data:`IMU_CHANNELS` as one (3, G + 1, Q + 1) array: channel c's packed table
    (:meth:`~finkensim.sensors.correction_table.CorrectionTable.packed`), a channel with fewer bins padded with
    copies of its last bin behind edges at +inf (the lookup never leaves the last real bin's values). The channels
    must share their levels (a :class:`CorrectionFileError` naming ``where`` otherwise)."""
    chans = [tables.channels[c] for c in IMU_CHANNELS]
    levels = chans[0].levels
    for name, t in zip(IMU_CHANNELS, chans):
        if t.levels.shape != levels.shape or not np.array_equal(t.levels, levels):
            raise CorrectionFileError(f"{where}.channels.{name}.levels = {t.levels.tolist()[:6]}: expected the "
                                      f"levels of channel {IMU_CHANNELS[0]} ({levels.tolist()[:6]})")
    G = max(t.quantiles.shape[0] for t in chans)
    out = np.empty((3, G + 1, levels.size + 1))
    for c, t in enumerate(chans):
        p = t.packed()
        g = t.quantiles.shape[0]
        out[c, :g + 1] = p
        out[c, g + 1:, 0] = np.inf
        out[c, g + 1:, 1:] = p[g, 1:]
    return out


def imu_correction(path: str) -> tuple[np.ndarray, float]:
    """(packed tables (3, G + 1, Q + 1), window W s) of the ``imu`` entry of the correction file ``path``
    (``imu.correction_file``); :data:`NO_IMU_TABLE` and 0 for an empty path. Named errors for a bad file."""
    if not path:
        return NO_IMU_TABLE, 0.0
    tables = read_correction(path, "imu", key="imu.correction_file", channels=IMU_CHANNELS)
    if not tables.window > 0.0:
        raise CorrectionFileError(f"imu.correction_file = {str(path)!r}: sensors.imu.window = {tables.window!r}: "
                                  "expected the window (s > 0) its readings integrate")
    return pack_channels(tables, f"{path}: sensors.imu"), float(tables.window)


@njit(cache=True, inline="always")
def corrected_imu(a_wx, a_wy, yaw_rate, c, s, params, seed, env, step, n):
    """One copter's corrected sample: (body acc x, body acc y m/s², gyro rad/s) from the world acceleration (a_wx,
    a_wy) m/s², the yaw rate rad/s and cos/sin (c, s) of the heading, with the tables and window of ``params`` (an
    :class:`~finkensim.sensors.imu.ImuModel` with a correction); the block's uniforms as in the module docstring."""
    window = params.correction_window
    h = max(1, int(round(window / params.dt)))
    key = counter_key(seed, env, step // h, n, STREAM_CORRECTION_IMU)
    bx = c * params.acc_bias_x - s * params.acc_bias_y  # the constant body-frame bias in the world frame
    by = s * params.acc_bias_x + c * params.acc_bias_y
    mx = a_wx + bx
    my = a_wy + by
    mg = yaw_rate + params.gyro_bias
    tab = params.correction
    wx = mx + correction_quantile(tab[0], mx * window, uniform(key, 0)) / window
    wy = my + correction_quantile(tab[1], my * window, uniform(key, 1)) / window
    g = mg + correction_quantile(tab[2], mg * window, uniform(key, 2)) / window
    return c * wx + s * wy, -s * wx + c * wy, g


@njit(cache=True, parallel=True)
def corrected_window_draws(ideal, bias, channel, flight, tidx, chan, seed, table, out):
    """The diagnosis's draws of IMU window integrals with the learned correction: out (n, M) = ideal (n, M) + bias
    (n,) + Q_c(ideal + bias, u), c = channel (n,) (0, 1, 2: :data:`IMU_CHANNELS`), table (3, G + 1, Q + 1)
    (:func:`pack_channels`); u = uniform m of ``counter_key(seed, flight[i], tidx[i], chan[i],
    STREAM_CORRECTION_IMU)``."""
    n, M = ideal.shape
    for i in prange(n):
        key = counter_key(seed, flight[i], tidx[i], chan[i], STREAM_CORRECTION_IMU)
        tab = table[channel[i]]
        for m in range(M):
            ref = ideal[i, m] + bias[i]
            out[i, m] = ref + correction_quantile(tab, ref, uniform(key, m))
