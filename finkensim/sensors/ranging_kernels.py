"""Numba kernels of the virtual-ranging sensor: the one implementation of a ranging reading.

Every caller — the batched API (:func:`finkensim.sensors.ranging.ranging_readings`,
:meth:`~finkensim.sensors.ranging.RangingModel.sample`) and compiled closed loops — computes readings
with these functions, fed by the :class:`RangingParams` record (``RangingModel.params``):

- :func:`reading_rule`: the whole rule for one reading of true distance x (out of range → exactly
  ``max_range``; mode dispatch; clip at 0) on the unpacked fields of the record, built from
  :func:`fast_reading` (modes ``mixture``, ``gaussian``, ``none``) and :func:`seed_reading` (mode ``seed``); :func:`pick_component` draws the
  mixture component from the responsibility table (:mod:`finkensim.sensors.ranging_table`);
- :func:`ranging_env`: one environment's readings (N, N + M); :func:`ranging_grid_env` the same readings with
  the pairs in range found on the engine's cell grid (large swarms); :func:`ranging_batch` runs it over a
  batch in parallel; :func:`sample_readings` reads a list of true distances as one copter's row;
- :func:`row_key`: the counter key of one measuring copter's row (from Python).

The model itself (modes, rules, mixture) is described in :mod:`finkensim.sensors.ranging`.

**Random numbers.** Every draw is a counter-based uniform (:mod:`finkensim.kernels.rng`) of the key
``counter_key(seed, env_id, step, i, STREAM_RANGING)`` of the *measuring* copter ``i``; reading
column ``j`` (0…N−1 copters, N…N+M−1 beacons) uses its own indices, so i→j and j→i are independent
and a reading depends only on (seed, env_id, step, i, j), never on the batch size or thread count:

- ``mixture``: uniform ``4j`` picks the node, uniform ``4j+1`` the alias column (integer part of
  u·K) and the alias coin (fractional part), ``normal(key, 2j+1)`` (uniforms 4j+2, 4j+3) the noise;
- ``seed``: ``normal(key, j·K + i)`` for component i;
- ``gaussian``: ``normal(key, j)``.

**Cost** (one core): mixture ≈ 27 ns per reading, of which ≈ 14 ns are its random numbers (2 uniforms
+ 1 Box–Muller normal); the exact 100-exponential draw would be ≈ 500 ns. ``seed`` ≈ 2.6 µs (100 normals);
``gaussian`` ≈ 14 ns. The loops unpack the record once: calling the inlined rule with the record itself cost
≈ 60 ns per reading (see :class:`RangingParams`).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange

from ..kernels.cellgrid import build_env, grid_layout, query_env
from ..kernels.rng import STREAM_CORRECTION_RANGING, STREAM_RANGING, counter_key, normal, uniform
from .ranging_radio import RadioParams, corrected_reading, los_clearance, radio_dropped, radio_shift, tag_distance

__all__ = [
    "MODES", "MODE_GAUSSIAN", "MODE_MIXTURE", "MODE_NONE", "MODE_SEED", "RangingParams",
    "fast_reading", "pick_component", "pick_components", "ranging_batch", "ranging_env", "ranging_grid_env",
    "ranging_reach", "ranging_radio_env", "radio_reading", "ranging_along_poses",
    "reading_rule", "row_key", "sample_readings", "seed_reading", "COMP_MEAN", "COMP_SLOPE", "COMP_COND_MEAN",
    "COMP_COND_STD", "COMP_LOG_WN", "COMP_HALF_INV_COVAR", "COMP_SEED_STD",
]

MODE_NONE = 0
MODE_GAUSSIAN = 1
MODE_MIXTURE = 2
MODE_SEED = 3
#: ``ranging.error`` names → the mode codes of :attr:`RangingParams.mode`.
MODES = {"none": MODE_NONE, "gaussian": MODE_GAUSSIAN, "mixture": MODE_MIXTURE, "seed": MODE_SEED}


#: Columns of :attr:`RangingParams.comp`, one row per mixture component.
COMP_MEAN, COMP_SLOPE, COMP_COND_MEAN, COMP_COND_STD, COMP_LOG_WN, COMP_HALF_INV_COVAR, COMP_SEED_STD = range(7)


class RangingParams(NamedTuple):
    """Everything the kernels read, as one flat numba argument (built by ``RangingModel``).

    Scalars: ``mode`` (int64, a ``MODE_*`` code), ``max_range`` m, ``sigma`` m (``gaussian``),
    ``inv_h`` 1/m (inverse node spacing of the table). The responsibility table (``mixture`` only):
    ``prob`` (G, K) float64 and ``alias`` (G, K) int32. ``comp`` (K, 7) float64, one row per component,
    columns ``COMP_*``: mean m, slope (dimensionless), cond_mean m, cond_std = sqrt(cond_covar) m,
    log_wn = log weight − ½ log(2π covar), half_inv_covar = 1/(2 covar) 1/m², seed_std =
    sqrt(seed_variance_factor · covar) m. Unused parts are small placeholders; all arrays are read-only and
    C-contiguous, so every mode has the same numba type (one compilation).

    Then the fields of :class:`~finkensim.sensors.ranging_radio.RadioParams`, the radio effects (antenna offsets,
    delays, scale, bias, NLOS, tail, dropout; ``radio_on`` = 0 leaves every reading as without them), and the
    learned correction (``ranging.correction_file``; :func:`~finkensim.sensors.ranging_radio.corrected_reading`, which
    runs on the radio path: ``radio_on`` is 1 with a correction): ``correction`` the packed table (G + 1, Q + 1)
    (:meth:`~finkensim.sensors.correction_table.CorrectionTable.packed`; (0, 0) = none) and ``median`` (R,) m the
    error model's median reading at true distances k·max_range/(R − 1) (a placeholder without a correction).

    Loops unpack the record once (``mode, max_range, sigma, inv_h, prob, alias, comp = ranging[:7]``) and call
    :func:`reading_rule`: numba does not always elide the reference counting of arrays handed to an inlined
    function, and each count is an atomic increment and decrement. With the record passed per reading (and a
    compiled, not inlined, ``seed`` branch) that cost ≈ 33 ns of a 60 ns mixture reading. The outlined copies that
    run these loops (``error_model="numpy"``, see :mod:`finkensim.swarm.kernel`) and an inlined
    :func:`seed_reading` leave no count per reading (seen by sampling the callers of ``NRT_incref`` under gdb);
    inlining ``seed_reading`` costs ≈ 1.5 s of cold compile of ``ranging_grid_env``.
    """

    mode: np.int64
    max_range: float
    sigma: float
    inv_h: float
    prob: np.ndarray
    alias: np.ndarray
    comp: np.ndarray
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
    correction: np.ndarray
    median: np.ndarray


# the radio effects' fields, in the same order, then the learned correction's
assert RangingParams._fields[7:-2] == RadioParams._fields


def row_key(seed, env, step, copter) -> np.uint64:
    """The counter key of one measuring copter's row (integers), as a numba-ready uint64."""
    return np.uint64(counter_key(np.int64(seed), np.int64(env), np.int64(step), np.int64(copter),
                                 np.int64(STREAM_RANGING)))


@njit(cache=True, inline="always")
def pick_component(x, u_node, u_col, inv_h, prob, alias):
    """Component index for true distance x ≥ 0 m from two uniforms in [0, 1) (node choice; alias column + coin).

    ``inv_h`` 1/m is the inverse node spacing, ``prob`` (G, K) float64 / ``alias`` (G, K) int32 the alias
    tables of the nodes x_g = g/inv_h. Node g + 1 is taken with probability f = x·inv_h − g, else node g;
    then column c = ⌊u_col·K⌋ with coin u_col·K − c: c if the coin < prob[node, c], else alias[node, c].
    """
    n_nodes, k = prob.shape
    t = x * inv_h
    g = int(t)
    if g > n_nodes - 2:
        g = n_nodes - 2
    # the two coins are random by design: selects, not branches, which the predictor would miss half the time
    g += u_node < t - g  # take the upper node with probability f = t - g
    s = u_col * k
    c = int(s)
    if c > k - 1:  # u_col * k can round up to k
        c = k - 1
    other = np.int64(alias[g, c])
    return c if s - c < prob[g, c] else other


@njit(cache=True)
def pick_components(xs, key, inv_h, prob, alias, out):
    """out[j] (int64): the component :func:`fast_reading` draws for true distance xs[j] m (1-D) as column j
    of the row with counter key ``key`` (its uniforms 4j and 4j + 1)."""
    for j in range(xs.shape[0]):
        out[j] = pick_component(xs[j], uniform(key, 4 * j), uniform(key, 4 * j + 1), inv_h, prob, alias)


@njit(cache=True, inline="always")
def seed_reading(x, key, j, comp):
    """``seed`` mode, before clipping, m: exact responsibilities at true distance x m, one normal per
    component (``normal(key, j·K + i)``), the responsibility-weighted sum. ``comp`` (K, 7) as in
    :class:`RangingParams`."""
    k = comp.shape[0]
    top = -np.inf
    for i in range(k):
        d = x - comp[i, COMP_MEAN]
        lp = comp[i, COMP_LOG_WN] - comp[i, COMP_HALF_INV_COVAR] * d * d
        if lp > top:
            top = lp
    total = 0.0
    acc = 0.0
    for i in range(k):
        d = x - comp[i, COMP_MEAN]
        r = np.exp(comp[i, COMP_LOG_WN] - comp[i, COMP_HALF_INV_COVAR] * d * d - top)
        total += r
        acc += r * (comp[i, COMP_COND_MEAN] + comp[i, COMP_SEED_STD] * normal(key, j * k + i))
    return acc / total


@njit(cache=True, inline="always")
def fast_reading(x, key, j, mode, sigma, inv_h, prob, alias, comp):
    """``mixture`` / ``gaussian`` / ``none`` reading before clipping, m, of column j for true distance x in
    [0, max_range] m (row key ``key``). Arguments as the fields of :class:`RangingParams`."""
    if mode == MODE_MIXTURE:
        c = pick_component(x, uniform(key, 4 * j), uniform(key, 4 * j + 1), inv_h, prob, alias)
        return (comp[c, COMP_COND_MEAN] + comp[c, COMP_SLOPE] * (x - comp[c, COMP_MEAN])
                + comp[c, COMP_COND_STD] * normal(key, 2 * j + 1))
    if mode == MODE_GAUSSIAN:
        return x + sigma * normal(key, j)
    return x


@njit(cache=True, inline="always")
def reading_rule(x, key, j, mode, max_range, sigma, inv_h, prob, alias, comp):
    """The reading, m, of column j for true distance x ≥ 0 m in the row with counter key ``key``; the other
    arguments are the fields of a :class:`RangingParams`, unpacked (see there why).

    x > ``max_range`` reads exactly ``max_range``; otherwise the mode's draw (:func:`seed_reading` or
    :func:`fast_reading`), clipped at 0.
    """
    if x > max_range:
        return max_range
    if mode == MODE_SEED:
        y = seed_reading(x, key, j, comp)
    else:
        y = fast_reading(x, key, j, mode, sigma, inv_h, prob, alias, comp)
    return y if y > 0.0 else 0.0


@njit(cache=True, inline="always")
def radio_reading(x, pos_b, i, j, b, bx, by, key, ckey, ranging):
    """Copter i's reading m of column j with the radio effects of ``ranging``, at true (tag) distance x m: beyond
    ``max_range`` exactly ``max_range``; a lost reading (dropout) NaN; else the error model's draw
    (:func:`reading_rule`) through :func:`radio_shift`, or with a learned correction :func:`corrected_reading`
    (uniform j of ``ckey``). The line-of-sight clearance (NLOS near a third copter) is measured among the copters
    ``pos_b`` (N, 2) m from copter i to node b at (bx, by) m (b = −1 for a beacon). ``key``: copter i's row key."""
    mode, max_range, sigma, inv_h, prob, alias, comp = ranging[:7]
    if x > max_range:
        return max_range
    if radio_dropped(x, key, j, ranging):
        return np.nan
    clear = los_clearance(pos_b, i, b, bx, by) if ranging.nlos_on else np.inf
    if ranging.correction.shape[0] > 0:
        return corrected_reading(x, i, j, clear, ckey, j, ranging)
    y = reading_rule(x, key, j, mode, max_range, sigma, inv_h, prob, alias, comp)
    return radio_shift(y, i, j, clear, key, j, ranging)


@njit(cache=True, inline="always")
def ranging_radio_env(pos_b, yaw_b, beacons, seed, env, step, ranging, out):
    """:func:`ranging_env` with the radio effects of ``ranging`` (:mod:`finkensim.sensors.ranging_radio`): the
    tag-to-tag distance decides the range and feeds the error model, whose draw :func:`radio_shift` turns into
    the reading; a lost reading (dropout) is NaN. Every pair is visited (no cell grid). With a learned correction
    (``ranging.correction``) a reading that is not lost is :func:`corrected_reading` instead (uniform j of the key
    ``counter_key(seed, env, step, i, STREAM_CORRECTION_RANGING)``)."""
    n = pos_b.shape[0]
    m = beacons.shape[0]
    corrected = ranging.correction.shape[0] > 0
    for i in range(n):
        key = counter_key(seed, env, step, i, STREAM_RANGING)
        ckey = counter_key(seed, env, step, i, STREAM_CORRECTION_RANGING) if corrected else key
        xi = pos_b[i, 0]
        yi = pos_b[i, 1]
        for j in range(n + m):
            if j == i:
                out[i, j] = 0.0
                continue
            if j < n:
                bx = pos_b[j, 0]
                by = pos_b[j, 1]
                wb = yaw_b[j]
            else:
                bx = beacons[j - n, 0]
                by = beacons[j - n, 1]
                wb = 0.0
            if ranging.antenna_on:
                x = tag_distance(ranging, i, (xi, yi, 0.0, yaw_b[i]), j, (bx, by, 0.0, wb), j >= n)
            else:
                dx = bx - xi
                dy = by - yi
                x = np.sqrt(dx * dx + dy * dy)
            out[i, j] = radio_reading(x, pos_b, i, j, j if j < n else -1, bx, by, key, ckey, ranging)


@njit(cache=True, inline="always")
def ranging_env(pos_b, yaw_b, beacons, seed, env, step, ranging, out):
    """Virtual-ranging readings of one environment → out (N, N + M) float64, m.

    ``pos_b`` (N, 2) copter positions m; ``yaw_b`` (N,) headings rad (read only by the antenna offsets);
    ``beacons`` (M, 2) tags m; ``seed``, ``env`` (global environment index), ``step``: integers of the counter
    keys; ``ranging`` a :class:`RangingParams` (with radio effects on: :func:`ranging_radio_env`). out[i, j] is copter
    i's reading of copter j (j < N; out[i, i] = 0) or of beacon j − N.
    """
    if ranging.radio_on:
        ranging_radio_env(pos_b, yaw_b, beacons, seed, env, step, ranging, out)
        return
    n = pos_b.shape[0]
    m = beacons.shape[0]
    mode, max_range, sigma, inv_h, prob, alias, comp = ranging[:7]
    drawn = np.empty(n + m, dtype=np.int64)
    for i in range(n):
        key = counter_key(seed, env, step, i, STREAM_RANGING)
        xi = pos_b[i, 0]
        yi = pos_b[i, 1]
        # 1. true distances into the row, and the columns that draw a random reading listed without branches (which
        # copters are beyond max_range is unpredictable); 2. those columns' readings. Beyond max_range the reading is
        # max_range itself (reading_rule) and the diagonal 0.
        count = 0
        for j in range(n + m):
            if j < n:
                dx = pos_b[j, 0] - xi
                dy = pos_b[j, 1] - yi
            else:
                dx = beacons[j - n, 0] - xi
                dy = beacons[j - n, 1] - yi
            x = np.sqrt(dx * dx + dy * dy)
            beyond = x > max_range
            out[i, j] = 0.0 if j == i else (max_range if beyond else x)
            drawn[count] = j
            count += (j != i) & (not beyond)
        for c in range(count):
            j = drawn[c]
            out[i, j] = reading_rule(out[i, j], key, j, mode, max_range, sigma, inv_h, prob, alias, comp)


@njit(cache=True, inline="always")
def ranging_reach(max_range):
    """The radius (m) of the grid query that finds every copter the ranging draws for: max_range·(1 + 1e-9) (the
    exact rule then applies to sqrt(dx² + dy²)), inf for a huge range."""
    return max_range * (1.0 + 1e-9) if max_range < 1e300 else np.inf


@njit(cache=True, inline="always", error_model="numpy")  # why: finkensim.kernels.outline
def ranging_grid_env(pos_b, yaw_b, beacons, counter, ranging, out, grid, cells, fill=True):
    """:func:`ranging_env` with the copter pairs found on a cell grid when ``grid.on``: the same readings, bit for bit;
    counter = (seed, env, step) of its random numbers.

    grid: a :class:`~finkensim.kernels.cellgrid.EngineGrid`, cells: this environment's buffers of it
    (:func:`~finkensim.kernels.cellgrid.env_grid`; the grid is rebuilt here). Copters farther than ``max_range``
    read exactly ``max_range`` without a random number, so the row is filled with it and only the copters the grid
    finds within max_range·(1 + 1e-9) (a superset of those the exact rule keeps: the test itself stays the one
    in :func:`reading_rule`, on the same sqrt(dx² + dy²)) are drawn; beacons as in :func:`ranging_env`.
    ``fill`` False (grid on only) leaves the other copter columns as they were: for a caller that reads only the
    columns the same grid query finds (the wall check on the engine's grid) — at N = 10 000 the fill is 10⁸ writes
    per step, the drawn readings 10⁵.
    """
    seed, env, step = counter
    if not grid.on or ranging.radio_on:  # the radio effects visit every pair (tag distances, third copters)
        ranging_env(pos_b, yaw_b, beacons, seed, env, step, ranging, out)
        return
    n = pos_b.shape[0]
    m = beacons.shape[0]
    cell_start, order, spos, cell_of, found, found_d2 = cells
    layout = grid_layout(grid)
    build_env(pos_b, layout, cell_start, order, spos, cell_of)
    mode, max_range, sigma, inv_h, prob, alias, comp = ranging[:7]
    reach = ranging_reach(max_range)
    for i in range(n):
        key = counter_key(seed, env, step, i, STREAM_RANGING)
        xi = pos_b[i, 0]
        yi = pos_b[i, 1]
        if fill:
            for j in range(n):
                out[i, j] = max_range
        out[i, i] = 0.0
        if reach < np.inf:
            count = query_env(xi, yi, reach, i, layout, cell_start, order, spos, found, found_d2)
        else:  # every copter is in range: no grid query can narrow it down
            count = 0
            for j in range(n):
                if j != i:
                    found[count] = j
                    count += 1
        for c in range(count):
            j = found[c]
            dx = pos_b[j, 0] - xi
            dy = pos_b[j, 1] - yi
            out[i, j] = reading_rule(np.sqrt(dx * dx + dy * dy), key, j, mode, max_range, sigma, inv_h, prob, alias,
                                     comp)
        for j in range(n, n + m):
            dx = beacons[j - n, 0] - xi
            dy = beacons[j - n, 1] - yi
            out[i, j] = reading_rule(np.sqrt(dx * dx + dy * dy), key, j, mode, max_range, sigma, inv_h, prob, alias,
                                     comp)


@njit(cache=True, parallel=True)
def ranging_batch(positions, yaws, beacons, seed, env_ids, step, ranging, out):
    """:func:`ranging_env` for every environment b (in parallel): ``positions`` (B, N, 2) m, ``yaws`` (B, N) rad,
    ``beacons`` (M, 2) m, ``env_ids`` (B,) int64 → out (B, N, N + M) float64 m."""
    for b in prange(positions.shape[0]):
        ranging_env(positions[b], yaws[b], beacons, seed, env_ids[b], step, ranging, out[b])


@njit(cache=True, parallel=True)
def ranging_along_poses(pos, z, yaw, seed, env, step0, ranging, out):
    """The copters' readings of each other along given poses: out (T, N, N) float64 m (diagonal 0) of positions
    ``pos`` (T, N, 2) m, heights ``z`` (T, N) m and headings ``yaw`` (T, N) rad, sample k keyed as step
    ``step0 + k`` of environment ``env`` of the run ``seed`` (in parallel over the samples).

    Each reading is the engine's (:func:`ranging_env` without beacons, bit for bit where every height is 0) at the
    3-D tag-to-tag distance (:func:`~finkensim.sensors.ranging_radio.tag_distance` with the heights): the error model
    (:func:`reading_rule`) and, with radio effects or a learned correction, :func:`radio_reading`."""
    T, n = pos.shape[0], pos.shape[1]
    mode, max_range, sigma, inv_h, prob, alias, comp = ranging[:7]
    for k in prange(T):
        step = step0 + k
        for i in range(n):
            key = counter_key(seed, env, step, i, STREAM_RANGING)
            ckey = counter_key(seed, env, step, i, STREAM_CORRECTION_RANGING)
            pose_i = (pos[k, i, 0], pos[k, i, 1], z[k, i], yaw[k, i])
            for j in range(n):
                if j == i:
                    out[k, i, j] = 0.0
                    continue
                x = tag_distance(ranging, i, pose_i, j, (pos[k, j, 0], pos[k, j, 1], z[k, j], yaw[k, j]), False)
                if ranging.radio_on:
                    out[k, i, j] = radio_reading(x, pos[k], i, j, j, pos[k, j, 0], pos[k, j, 1], key, ckey, ranging)
                else:
                    out[k, i, j] = reading_rule(x, key, j, mode, max_range, sigma, inv_h, prob, alias, comp)


@njit(cache=True, parallel=True)
def sample_readings(xs, key, ranging, out):
    """out[j]: :func:`reading_rule` of true distance xs[j] m (1-D, ≥ 0) as column j of the row ``key``
    (in parallel: each column's random numbers depend on j alone)."""
    mode, max_range, sigma, inv_h, prob, alias, comp = ranging[:7]
    for j in prange(xs.shape[0]):
        out[j] = reading_rule(xs[j], key, j, mode, max_range, sigma, inv_h, prob, alias, comp)
