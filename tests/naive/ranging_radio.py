"""Plain-NumPy reference of the ranging radio effects (``finkensim.sensors.ranging_radio`` and
``ranging_kernels.ranging_radio_env``), for tests only: readable loops over the same counter-based uniforms
(``finkensim.kernels.rng.uniform`` of the measuring copter's row key) and the error model's reference
(``tests.naive.ranging.naive_reading``)."""
from __future__ import annotations

import math

import numpy as np

from finkensim.kernels.rng import STREAM_CORRECTION_RANGING, counter_key, uniform
from finkensim.sensors.ranging_kernels import row_key
from finkensim.sensors.ranging_radio import RADIO_BASE
from tests.naive.ranging import naive_reading, naive_row_numbers


def naive_offset(radio: dict, k: int) -> np.ndarray:
    """Copter k's body-frame tag offset (x, y, z) m: the shared one plus its own (missing: none)."""
    off = np.array(radio["antenna_offset"], float)
    per = list(radio["antenna_offset_per_copter"])
    if k < len(per):
        off[:2] += np.array(per[k], float)
    return off


def naive_tag(radio, k, x, y, z, yaw):
    o = naive_offset(radio, k)
    return np.array([x + math.cos(yaw) * o[0] - math.sin(yaw) * o[1], y + math.sin(yaw) * o[0] + math.cos(yaw) * o[1],
                     z + o[2]])


def naive_delay(radio, k):
    d = list(radio["node_delay"])
    return float(d[k]) if k < len(d) else 0.0


def naive_clearance(pos, a, b, end):
    """Smallest distance from a copter other than a, b to the segment pos[a] → end (inf if none)."""
    best = math.inf
    A, B = np.asarray(pos[a], float), np.asarray(end, float)
    for c in range(len(pos)):
        if c in (a, b):
            continue
        P = np.asarray(pos[c], float)
        AB = B - A
        L2 = float(AB @ AB)
        s = 0.0 if L2 == 0 else min(1.0, max(0.0, float((P - A) @ AB) / L2))
        best = min(best, float(np.linalg.norm(A + s * AB - P)))
    return best


def naive_shift(y, a, b, clear, key, j, radio):
    """The radio effects on the error model's draw y (the module docstring's formula)."""
    v = radio["scale"] * y + radio["bias"] + naive_delay(radio, a) + naive_delay(radio, b)
    if radio["nlos_bias"] != 0.0:
        v += radio["nlos_bias"] * math.exp(-(clear / radio["nlos_width"]) ** 2)
    if radio["nlos_tail_probability"] > 0.0 and uniform(key, RADIO_BASE + 4 * j) < radio["nlos_tail_probability"]:
        v += -radio["nlos_tail_mean"] * math.log(uniform(key, RADIO_BASE + 4 * j + 1))
    return max(v, 0.0)


def naive_dropout_probability(x, a, b):
    return 0.0 if a <= -100.0 else 1.0 / (1.0 + math.exp(-(a + b * x)))


def naive_radio_readings(positions, yaw, beacons, seed, env_ids, step, model, z=None):
    """Reference of ``ranging_readings`` with the radio effects of ``model.radio``: (B, N, N + M); ``z`` (B, N) m
    the copters' heights (None: 0, planar; beacons sit at height 0)."""
    radio = model.radio
    positions = np.asarray(positions, float)
    h = np.zeros(positions.shape[:2]) if z is None else np.asarray(z, float)
    beacons = np.asarray(beacons, float).reshape(-1, 2)
    n_env, n, _ = positions.shape
    out = np.zeros((n_env, n, n + len(beacons)))
    for e in range(n_env):
        for i in range(n):
            key = row_key(seed, env_ids[e], step, i)
            u, z = naive_row_numbers(model, seed, env_ids[e], step, i, n + len(beacons))
            ti = naive_tag(radio, i, *positions[e, i], h[e, i], yaw[e, i])
            for j in range(n + len(beacons)):
                if j == i:
                    continue
                end = positions[e, j] if j < n else beacons[j - n]
                tj = naive_tag(radio, j, *end, h[e, j], yaw[e, j]) if j < n else np.array([*end, 0.0])
                x = float(np.linalg.norm(tj - ti))
                if x > model.max_range:
                    out[e, i, j] = model.max_range
                elif uniform(key, RADIO_BASE + 4 * j + 2) < naive_dropout_probability(x, radio["dropout_a"],
                                                                                       radio["dropout_b"]):
                    out[e, i, j] = np.nan
                elif model.correction is not None:  # the learned correction replaces the error model's draw
                    clear = naive_clearance(positions[e], i, j if j < n else -1, end)
                    ckey = np.uint64(counter_key(*map(np.int64, (seed, env_ids[e], step, i, STREAM_CORRECTION_RANGING))))
                    out[e, i, j] = naive_corrected(x, i, j, clear, ckey, j, model)
                else:
                    y = naive_reading(x, j, model, u, z)
                    clear = naive_clearance(positions[e], i, j if j < n else -1, end)
                    out[e, i, j] = naive_shift(y, i, j, clear, key, j, radio)
    return out


def naive_corrected(x, a, b, clear, ckey, j, model):
    """Reference of ``ranging_radio.corrected_reading``: the model's median reading (the error model's median on the
    grid ``model.params.median``, linear, then the deterministic radio effects, clipped at 0) plus the correction's
    quantile (``np.interp`` of its levels in ref's bin) at uniform j of ``ckey``, clipped at 0."""
    radio, t = model.radio, model.correction
    grid = np.linspace(0.0, model.max_range, model.params.median.size)
    m = float(np.interp(x, grid, model.params.median))
    ref = radio["scale"] * m + radio["bias"] + naive_delay(radio, a) + naive_delay(radio, b)
    if radio["nlos_bias"] != 0.0:
        ref += radio["nlos_bias"] * math.exp(-(clear / radio["nlos_width"]) ** 2)
    ref = max(ref, 0.0)
    g = int(np.clip(np.searchsorted(t.edges, ref, side="right") - 1, 0, t.quantiles.shape[0] - 1))
    return max(ref + float(np.interp(uniform(ckey, j), t.levels, t.quantiles[g])), 0.0)
