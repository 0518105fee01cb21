"""Plain-NumPy reference of the counter-based generator (``finkensim.kernels.rng``), for tests only.

Everything is done on ``uint64`` *arrays*: NumPy array arithmetic wraps modulo 2**64 silently
(scalar arithmetic would warn), which is exactly the arithmetic of the numba kernels. Signed
indices are reinterpreted as uint64 (two's complement), as ``np.uint64(i)`` does inside numba.

    key = mix(mix(mix(mix(mix(seed + G) ^ (env + G)) ^ (step + G)) ^ (copter + G)) ^ (stream + G))
    uniform(key, i) = ((mix(key + (i + 1)·G) >> 12) + 0.5) · 2**-52
    normal(key, i)  = sqrt(−2 ln uniform(key, 2i)) · cos(2π · uniform(key, 2i + 1))

with G the golden-ratio constant and ``mix`` SplitMix64's finaliser.

What this reference can and cannot catch: the formulas above are the generator's specification (the documented random
number layout), so this file necessarily restates them — vectorised over uint64 arrays where the kernel works on
scalars — and catches numba-vs-NumPy drift and layout slips (a wrong index, a missing ½ ulp). It cannot tell whether
``mix`` is SplitMix64 at all: that is checked against an outside reference, the published SplitMix64 outputs for
seed 1234567 (``tests/test_rng.py::test_mix64_is_splitmix64_by_published_vectors``), and the uniform/normal
distributions against scipy (KS tests in the same file).
"""
from __future__ import annotations

import numpy as np

GOLDEN = np.uint64(0x9E3779B97F4A7C15)
M1 = np.uint64(0xBF58476D1CE4E5B9)
M2 = np.uint64(0x94D049BB133111EB)


def as_u64(x) -> np.ndarray:
    """Integers (possibly negative, possibly already uint64) as a uint64 array, two's complement."""
    a = np.asarray(x)
    if a.dtype == np.uint64:
        return a.copy()
    return np.asarray(a, dtype=np.int64).astype(np.uint64)


def mix64(z) -> np.ndarray:
    """SplitMix64 finaliser on a uint64 array."""
    z = as_u64(z)
    with np.errstate(over="ignore"):  # 0-d inputs become NumPy scalars, whose wrap-around warns
        z = (z ^ (z >> np.uint64(30))) * M1
        z = (z ^ (z >> np.uint64(27))) * M2
    return z ^ (z >> np.uint64(31))


def counter_key(seed, env, step, copter, stream) -> np.ndarray:
    """Key of each (seed, env, step, copter, stream) cell; arguments broadcast; uint64 array."""
    with np.errstate(over="ignore"):
        h = mix64(as_u64(seed) + GOLDEN)
        for part in (env, step, copter, stream):
            h = mix64(h ^ (as_u64(part) + GOLDEN))
    return h


def uniform(key, index) -> np.ndarray:
    """The ``index``-th uniform of ``key`` (both broadcast), strictly inside (0, 1)."""
    with np.errstate(over="ignore"):
        z = mix64(as_u64(key) + (as_u64(index) + np.uint64(1)) * GOLDEN)
    return ((z >> np.uint64(12)).astype(np.float64) + 0.5) * 2.0**-52


def normal(key, index) -> np.ndarray:
    """Standard normal from uniforms ``2·index`` and ``2·index + 1`` (Box–Muller, cosine branch)."""
    i2 = np.asarray(index, dtype=np.int64) * 2
    u1 = uniform(key, i2)
    u2 = uniform(key, i2 + 1)
    return np.sqrt(-2.0 * np.log(u1)) * np.cos(2.0 * np.pi * u2)


def uniforms_array(seed, env, step, copter, stream, n) -> np.ndarray:
    """``n`` uniforms of one cell, shape (n,)."""
    return uniform(counter_key(seed, env, step, copter, stream), np.arange(n))


def normals_array(seed, env, step, copter, stream, n) -> np.ndarray:
    """``n`` standard normals of one cell, shape (n,)."""
    return normal(counter_key(seed, env, step, copter, stream), np.arange(n))
