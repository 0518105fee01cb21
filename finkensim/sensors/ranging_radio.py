"""Radio effects of a ranging reading: the one kernel the simulator flies and the gap diagnosis fits.

A two-way-ranging radio does not measure the distance between the copters' centres. What it reports, for nodes a
and b (copters 0…N−1, then fixed beacons), is built here in this order:

1. **Tag distance** (``ranging.antenna_offset``, ``antenna_offset_per_copter``): each copter's tag sits at a
   body-frame offset (x, y, z) m from its centre, so the true distance x is tag to tag and depends on both headings
   (:func:`tag_position`). Beacons are their own tags. x decides "out of range" (> ``max_range`` reads exactly
   ``max_range``, no effect below applies).
2. The error model's draw y of x (:func:`~finkensim.sensors.ranging_kernels.reading_rule`, clipped at 0).
3. :func:`radio_shift`: ``scale·y + bias + delay[a] + delay[b] + nlos_bias·exp(−(c/nlos_width)²) + tail``:
   ``scale`` a clock-rate factor (``ranging.scale``), ``bias`` m a constant offset, ``delay[k]`` m each node's
   constant antenna delay (``ranging.node_delay``, nodes beyond the list have none; a pair reads the sum), c m the
   clearance of the line of sight from a third copter's centre (``ranging.nlos_bias``, ``nlos_width``: NLOS near a
   third copter), and ``tail`` m a positive exponential with mean ``nlos_tail_mean`` drawn with probability
   ``nlos_tail_probability`` independent of other copters (obstacles, people). The result is clipped at 0.
4. **Dropout** (``ranging.dropout_a``, ``dropout_b`` 1/m): the reading is lost (NaN) with probability
   sigmoid(a + b·x) (:func:`dropout_probability`; a = −inf: never).

**The learned correction** (``ranging.correction_file``, :mod:`finkensim.sensors.correction_table`) replaces steps 2
and 3's random parts: :func:`corrected_reading` reads ``max(0, ref + Q_g(u))``, ref = ``max(0, line(m(x)))`` the
model's median reading (m(x) the error model's median at true distance x, :func:`error_median`; line the
deterministic part of step 3: scale, bias, delays, NLOS near a third copter; the tail is part of what the table
replaces), Q_g the residual's quantile function in the bin g of ref and u uniform ``j`` of the measuring copter's
key on ``STREAM_CORRECTION_RANGING``. Steps 1 and 4 stay. The diagnosis's draws (:func:`radio_batch`) call the same
function.

:class:`RadioParams` lists these fields; they are the last fields of :class:`~finkensim.sensors.ranging_kernels.RangingParams`;
``radio_on`` = 0 (every default) skips all of it, so readings are bit for bit those without the effects.

**Random numbers**: the measuring copter's row key (``STREAM_RANGING``), uniforms ``RADIO_BASE + 4j`` (tail coin),
``+ 4j + 1`` (tail length) and ``+ 4j + 2`` (dropout) of column j: far above every index the error models use, so
they never change an error draw.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange

from ..kernels.rng import STREAM_CORRECTION_RANGING, STREAM_RANGING, counter_key, uniform
from .correction_table import correction_quantile
from .tracking import draw_poses

__all__ = ["RADIO_BASE", "RadioParams", "antenna_key", "corrected_reading", "error_median", "radio_line", "radio_draws", "dropout_probabilities", "dropout_probability", "neutral_radio", "node_delay", "radio_batch",
           "radio_dropped", "radio_shift", "tag_distance", "tag_distance_draws", "tag_position", "los_clearance"]

#: first uniform index of the radio effects in a row (error models use indices < 4·(columns) or (columns)·K)
RADIO_BASE = 1 << 40


class RadioParams(NamedTuple):
    """The radio effects as one numba record (built by :class:`~finkensim.sensors.ranging.RangingModel`).

    Its fields are appended to :class:`~finkensim.sensors.ranging_kernels.RangingParams` (one flat record: numba's
    parallel loops take no record nested in another), and every kernel here reads them by name from either.
    ``radio_on`` int64: 0 skips every effect; ``antenna_on``, ``nlos_on``, ``tail_on``, ``dropout_on`` int64: which parts
    run. ``scale`` (factor), ``bias`` m. ``node_delay`` (K,) float64 m, read-only: node k's delay (nodes ≥ K: 0).
    ``antenna`` (1 + A, 3) float64 m, read-only: row 0 the tag offset (x, y, z) in the body frame shared by every
    copter, row 1 + k copter k's own extra offset (nodes ≥ A: none). ``nlos_bias`` m, ``nlos_width`` m,
    ``tail_probability``, ``tail_mean`` m, ``dropout_a``, ``dropout_b`` 1/m as in the module docstring.
    """

    radio_on: np.int64
    antenna_on: np.int64
    nlos_on: np.int64
    tail_on: np.int64
    dropout_on: np.int64
    scale: float
    bias: float
    node_delay: np.ndarray
    antenna: np.ndarray
    nlos_bias: float
    nlos_width: float
    tail_probability: float
    tail_mean: float
    dropout_a: float
    dropout_b: float


def neutral_radio() -> RadioParams:
    """A record with every effect off (the defaults)."""
    delay = np.zeros(0)
    antenna = np.zeros((1, 3))
    for a in (delay, antenna):
        a.setflags(write=False)
    return RadioParams(np.int64(0), np.int64(0), np.int64(0), np.int64(0), np.int64(0), 1.0, 0.0, delay, antenna,
                       0.0, 0.2, 0.0, 0.3, -np.inf, 0.0)


@njit(cache=True, inline="always")
def node_delay(ranging, k):
    """Node k's constant delay, m (0 beyond the configured list)."""
    return ranging.node_delay[k] if k < ranging.node_delay.shape[0] else 0.0


@njit(cache=True, inline="always")
def tag_position(ranging, k, x, y, z, yaw):
    """World position (x, y, z) m of copter k's tag: its centre (x, y, z) m plus its body-frame offset turned by
    its heading yaw rad. A node with no offset (a beacon: k beyond every row) is its own tag."""
    ox = ranging.antenna[0, 0]
    oy = ranging.antenna[0, 1]
    oz = ranging.antenna[0, 2]
    if k + 1 < ranging.antenna.shape[0]:
        ox += ranging.antenna[k + 1, 0]
        oy += ranging.antenna[k + 1, 1]
        oz += ranging.antenna[k + 1, 2]
    c = np.cos(yaw)
    s = np.sin(yaw)
    return x + c * ox - s * oy, y + s * ox + c * oy, z + oz


@njit(cache=True, inline="always")
def tag_distance(ranging, a, pose_a, b, pose_b, b_is_tag):
    """Tag-to-tag distance m of copter a (pose_a = (x m, y m, z m, heading rad) of its centre) and node b (pose_b
    likewise); ``b_is_tag``: b is a beacon whose position is its tag (no offset applied)."""
    xa, ya, za, wa = pose_a
    xb, yb, zb, wb = pose_b
    ta = tag_position(ranging, a, xa, ya, za, wa)
    if b_is_tag:
        tb = (xb, yb, zb)
    else:
        tb = tag_position(ranging, b, xb, yb, zb, wb)
    dx = tb[0] - ta[0]
    dy = tb[1] - ta[1]
    dz = tb[2] - ta[2]
    return np.sqrt(dx * dx + dy * dy + dz * dz)


@njit(cache=True, inline="always")
def los_clearance(pos, a, b, bx, by):
    """Smallest distance m from a third copter's centre (rows of ``pos`` (N, 2) m other than a and b; b = −1 for a
    beacon) to the segment from copter a's centre to (bx, by) m; inf when there is none."""
    best = np.inf
    ax = pos[a, 0]
    ay = pos[a, 1]
    for c in range(pos.shape[0]):
        if c == a or c == b:
            continue
        px = pos[c, 0]
        py = pos[c, 1]
        ex = bx - ax
        ey = by - ay
        den = ex * ex + ey * ey
        s = ((px - ax) * ex + (py - ay) * ey) / den if den > 0.0 else 0.0
        s = min(1.0, max(0.0, s))
        dx = px - (ax + s * ex)
        dy = py - (ay + s * ey)
        best = min(best, np.sqrt(dx * dx + dy * dy))
    return best


@njit(cache=True, inline="always")
def radio_line(y, a, b, clear, ranging):
    """The deterministic radio effects on the error model's draw y m of nodes a, b, m (not clipped): scale, bias,
    both node delays, NLOS near a third copter at clearance ``clear`` m."""
    v = ranging.scale * y + ranging.bias + node_delay(ranging, a) + node_delay(ranging, b)
    if ranging.nlos_on:
        w = clear / ranging.nlos_width
        v += ranging.nlos_bias * np.exp(-(w * w))
    return v


@njit(cache=True, inline="always")
def error_median(ranging, x):
    """The error model's median reading m at true distance x in [0, max_range] m: linear between the nodes of
    ``ranging.median`` (R,), spaced max_range/(R − 1) from 0."""
    last = ranging.median.shape[0] - 1
    t = x / ranging.max_range * last
    k = min(int(t), last - 1)
    w = t - k
    return ranging.median[k] + w * (ranging.median[k + 1] - ranging.median[k])


@njit(cache=True, inline="always")
def corrected_reading(x, a, b, clear, ckey, j, ranging):
    """The reading m of nodes a, b at true distance x ≤ max_range m with the learned correction: ``max(0, ref +
    Q_g(u))``, ref = max(0, :func:`radio_line` of :func:`error_median`) the model's median reading, Q_g the
    correction's quantile function in ref's bin (:func:`~finkensim.sensors.correction_table.correction_quantile`)
    and u uniform j of ``ckey`` (the ``STREAM_CORRECTION_RANGING`` key)."""
    ref = radio_line(error_median(ranging, x), a, b, clear, ranging)
    ref = ref if ref > 0.0 else 0.0
    v = ref + correction_quantile(ranging.correction, ref, uniform(ckey, j))
    return v if v > 0.0 else 0.0


@njit(cache=True, inline="always")
def radio_shift(y, a, b, clear, key, j, ranging):
    """The reading m of nodes a, b after the radio effects, from the error model's draw y m (≥ 0): scale, bias,
    both node delays, NLOS near a third copter at clearance ``clear`` m (:func:`radio_line`), the exponential
    tail (uniforms of column j of row ``key``); clipped at 0."""
    v = radio_line(y, a, b, clear, ranging)
    if ranging.tail_on:
        if uniform(key, RADIO_BASE + 4 * j) < ranging.tail_probability:
            v -= ranging.tail_mean * np.log(uniform(key, RADIO_BASE + 4 * j + 1))
    return v if v > 0.0 else 0.0


@njit(cache=True, inline="always")
def dropout_probability(x, dropout_a, dropout_b):
    """Probability that a reading of true distance x m is lost: sigmoid(a + b·x) (a = −inf: 0)."""
    if dropout_a == -np.inf:
        return 0.0
    return 1.0 / (1.0 + np.exp(-(dropout_a + dropout_b * x)))


@njit(cache=True)
def dropout_probabilities(x, dropout_a, dropout_b):
    """:func:`dropout_probability` of each true distance of x (n,) m → (n,)."""
    out = np.empty(x.shape[0])
    for i in range(x.shape[0]):
        out[i] = dropout_probability(x[i], dropout_a, dropout_b)
    return out


@njit(cache=True, inline="always")
def radio_dropped(x, key, j, ranging):
    """Whether column j's reading of true distance x m is lost (uniform ``RADIO_BASE + 4j + 2`` of row ``key``)."""
    if not ranging.dropout_on:
        return False
    return uniform(key, RADIO_BASE + 4 * j + 2) < dropout_probability(x, ranging.dropout_a, ranging.dropout_b)


@njit(cache=True, parallel=True)
def radio_batch(y0, x, a, b, clear, key, ckey, max_range, ranging, out):
    """The diagnosis's draws with the radio effects: out (n, M) m from the error model's draws y0 (n, M) m of true
    (tag) distances x (n, M) m between nodes a (n,) and b (n,) int64, line-of-sight clearances clear (n,) m. Draw
    (i, m) uses column i·M + m of the row ``key`` (with a learned correction: :func:`corrected_reading`, uniform
    i·M + m of ``ckey``, and y0 is not read); x > max_range reads max_range (no effect)."""
    n, M = y0.shape
    corrected = ranging.correction.shape[0] > 0
    for i in prange(n):
        for m in range(M):
            if x[i, m] > max_range:
                out[i, m] = max_range
            elif corrected:
                out[i, m] = corrected_reading(x[i, m], a[i], b[i], clear[i], ckey, i * M + m, ranging)
            else:
                out[i, m] = radio_shift(y0[i, m], a[i], b[i], clear[i], key, i * M + m, ranging)


def radio_draws(y0, x, a, b, clear, seed, p) -> np.ndarray:
    """:func:`radio_batch` of the diagnosis's draws y0 (n, M) m of true distances x (n, M) m between nodes a, b (n,)
    at clearances clear (n,) m, keyed by the run ``seed`` (row key of copter 0 at env 0, step 0), with the
    :class:`~finkensim.sensors.ranging_kernels.RangingParams` p (its learned correction keyed on
    ``STREAM_CORRECTION_RANGING`` likewise) → (n, M) m."""
    out = np.empty(np.shape(y0))
    key, ckey = (np.uint64(counter_key(np.int64(seed), np.int64(0), np.int64(0), np.int64(0), np.int64(stream)))
                 for stream in (STREAM_RANGING, STREAM_CORRECTION_RANGING))
    radio_batch(np.ascontiguousarray(y0, dtype=np.float64), np.ascontiguousarray(x, dtype=np.float64),
                np.ascontiguousarray(a, dtype=np.int64), np.ascontiguousarray(b, dtype=np.int64),
                np.ascontiguousarray(clear, dtype=np.float64), key, ckey, float(p.max_range), p, out)
    return out


def antenna_key(p):
    """A hashable key of the tag offsets of record p (None without them): what the ideal distances depend on."""
    return p.antenna.tobytes() if p.antenna_on else None


@njit(cache=True, parallel=True)
def tag_distance_draws(pos, z, yaw, times, noise, M, ranging, out):
    """Tag-to-tag distances for M pose draws: out (K, N, N, M) m (diagonal 0) of the logged poses pos (T, N, 2) m,
    heights z (T, N) m, headings yaw (T, N) rad at the samples ``times`` (K,), each pose drawn with the tracking
    noise ``noise`` (:class:`~finkensim.sensors.tracking.PoseNoise`). ``ranging``: the record whose tag offsets
    (``antenna``) apply (:func:`tag_distance`), or None for the distances between the copters' centres (the
    diagnosis's ``gap.replay.ranging_draws``: 3-D with the heights, horizontal for zero heights, bit for bit)."""
    K = times.shape[0]
    N = pos.shape[1]
    for i in prange(K * M):
        ti = i // M
        m = i % M
        k = times[ti]
        P = np.empty((N, 2))
        W = np.empty(N)
        draw_poses(pos, yaw, k, m, noise, P, W)
        for a in range(N):
            out[ti, a, a, m] = 0.0
            for b in range(a + 1, N):
                if ranging is None:  # resolved when compiling: one machine code per case
                    dx = P[a, 0] - P[b, 0]
                    dy = P[a, 1] - P[b, 1]
                    dz = z[k, a] - z[k, b]
                    d = np.sqrt(dx * dx + dy * dy + dz * dz)
                else:
                    d = tag_distance(ranging, a, (P[a, 0], P[a, 1], z[k, a], W[a]), b, (P[b, 0], P[b, 1], z[k, b], W[b]),
                                     False)
                out[ti, a, b, m] = d
                out[ti, b, a, m] = d
