"""Plain-NumPy reference of the virtual-ranging sensor, for tests only: the batched API
(``finkensim.sensors.ranging``), its kernels (``ranging_kernels``) and the alias tables (``ranging_table``).

Readable loops, no numba of its own. It consumes the same counter-based random numbers as the
kernel, taken from ``finkensim.kernels.rng.uniforms_array`` / ``normals_array`` (one row of
numbers per measuring copter), and the same responsibility table (``model.table``: node grid and
alias tables), so it must agree with the kernel to rounding.

What it shares and why: the alias table is the sampler's discretisation of the mixture, so replaying it here checks
the kernel's indexing, interpolation between nodes and clipping — not whether the table samples the right law. That
is checked without the table or ``Mixture``: the sampler against the conditional law computed straight from the
JSON file with scipy (``tests/test_ranging.py::test_sampler_matches_the_mixture_computed_from_the_json``), and the
table's total-variation bound against the exact responsibilities.
"""
from __future__ import annotations

import numpy as np

from finkensim.kernels.rng import STREAM_RANGING, normals_array, uniforms_array


def naive_pick_component(x, u_node, u_col, table):
    """Component drawn from the table at true distance x: node g or g+1, then the alias table of that node."""
    n_nodes, k = table.prob.shape
    t = x * table.inv_h
    g = min(int(np.floor(t)), n_nodes - 2)
    f = t - g  # fractional position between node g and node g + 1
    node = g + 1 if u_node < f else g
    s = u_col * k
    column = min(int(np.floor(s)), k - 1)
    coin = s - column
    return column if coin < table.prob[node, column] else int(table.alias[node, column])


def naive_reading(x, j, model, u, z):
    """Reading of column j for true distance x; ``u``/``z`` are the measuring copter's uniforms/normals."""
    if x > model.max_range:
        return model.max_range
    mix = model.mixture
    if model.error == "none":
        y = x
    elif model.error == "gaussian":
        y = x + model.sigma * z[j]
    elif model.error == "mixture":
        c = naive_pick_component(x, u[4 * j], u[4 * j + 1], model.table)
        centre = mix.cond_mean[c] + mix.slope[c] * (x - mix.mean[c])
        y = centre + np.sqrt(mix.cond_covar[c]) * z[2 * j + 1]
    elif model.error == "seed":
        k = mix.n_components
        # the script's rule: exact responsibilities, one draw per component, weighted sum
        log_p = (np.log(mix.weights) - 0.5 * np.log(2 * np.pi * mix.covar)
                 - 0.5 * (x - mix.mean) ** 2 / mix.covar)
        r = np.exp(log_p - log_p.max())
        r = r / r.sum()
        draws = mix.cond_mean + np.sqrt(model.seed_variance_factor * mix.covar) * z[j * k:(j + 1) * k]
        y = float(np.sum(r * draws))
    else:
        raise ValueError(model.error)
    return max(y, 0.0)  # a range cannot be negative


def naive_row_numbers(model, seed, env, step, copter, n_columns):
    """The uniforms and normals one measuring copter's row consumes."""
    if model.error == "mixture":
        u = uniforms_array(seed, env, step, copter, STREAM_RANGING, 4 * n_columns)
        z = normals_array(seed, env, step, copter, STREAM_RANGING, 2 * n_columns)
    elif model.error == "seed":
        u = None
        z = normals_array(seed, env, step, copter, STREAM_RANGING, n_columns * model.mixture.n_components)
    elif model.error == "gaussian":
        u = None
        z = normals_array(seed, env, step, copter, STREAM_RANGING, n_columns)
    else:
        u = z = None
    return u, z


def naive_ranging_readings(positions, beacons, seed, env_ids, step, model, ideal=False):
    """Reference of ``ranging_readings``: (B, N, N + M) readings."""
    positions = np.asarray(positions, dtype=np.float64)
    beacons = np.asarray(beacons, dtype=np.float64).reshape(-1, 2)
    n_env, n, _ = positions.shape
    targets_all = [np.concatenate([positions[b], beacons], axis=0) for b in range(n_env)]
    out = np.zeros((n_env, n, n + beacons.shape[0]))
    for b in range(n_env):
        targets = targets_all[b]
        for i in range(n):
            u, z = (None, None) if ideal else naive_row_numbers(model, seed, env_ids[b], step, i, targets.shape[0])
            for j in range(targets.shape[0]):
                if j == i:
                    out[b, i, j] = 0.0
                    continue
                dx = targets[j, 0] - positions[b, i, 0]
                dy = targets[j, 1] - positions[b, i, 1]
                x = np.sqrt(dx * dx + dy * dy)
                if ideal:
                    out[b, i, j] = min(x, model.max_range)
                else:
                    out[b, i, j] = naive_reading(x, j, model, u, z)
    return out


def naive_sample(model, x, seed=0, env=0, step=0, copter=0):
    """Reference of ``RangingModel.sample``: element j of x uses reading column j."""
    xs = np.asarray(x, dtype=np.float64).ravel()
    u, z = naive_row_numbers(model, seed, env, step, copter, xs.size)
    return np.array([naive_reading(xs[j], j, model, u, z) for j in range(xs.size)]).reshape(np.shape(x))


def naive_build_alias(p):
    """Reference of ``ranging_table.build_alias``: Vose's alias tables (prob, alias) of every row of ``p`` (G, K).

    The same stack discipline as the kernel (last in, first out; leftovers get probability 1), so the
    tables agree exactly, not only in the distributions they encode.
    """
    p = np.asarray(p, dtype=np.float64)
    n_rows, k = p.shape
    prob = np.empty((n_rows, k))
    alias = np.empty((n_rows, k), dtype=np.int32)
    for g in range(n_rows):
        q = [float(v) * k for v in p[g]]
        small = [i for i in range(k) if q[i] < 1.0]
        large = [i for i in range(k) if q[i] >= 1.0]
        while small and large:
            s = small.pop()
            big = large.pop()
            prob[g, s] = q[s]
            alias[g, s] = big
            q[big] = (q[big] + q[s]) - 1.0
            (small if q[big] < 1.0 else large).append(big)
        for i in large + small:  # leftovers are 1 up to rounding
            prob[g, i] = 1.0
            alias[g, i] = i
    return prob, alias


def naive_pick_components(table, xs, seed=0, env=0, step=0, copter=0):
    """Reference of ``ResponsibilityTable.sample_components``: the component of column j for true distance xs[j]."""
    xs = np.asarray(xs, dtype=np.float64).ravel()
    u = uniforms_array(seed, env, step, copter, STREAM_RANGING, 4 * xs.size)
    return np.array([naive_pick_component(x, u[4 * j], u[4 * j + 1], table) for j, x in enumerate(xs)], dtype=np.int64)
