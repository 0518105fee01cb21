"""Counter-based RNG: numba kernels == NumPy reference, distribution and independence checks.

Statistical tests use fixed seeds, so they are deterministic: a failure is a change in the
generator, not bad luck. Thresholds: p > 1e-3 for KS and chi-square tests; moments and correlations within 5
standard errors (tests/stats.py), closed-form SEs for 50 000 draws: mean of U(0,1) 0.0013, mean of N(0,1) 0.0045,
variance 0.0063, skewness 0.011, excess kurtosis 0.022; correlation of 5 000 pairs 0.014 (5 SE each).
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from finkensim.kernels import rng
from tests.naive import rng as naive
from tests.stats import assert_mean_within_se, assert_within_se

I64 = st.integers(-(2**63), 2**63 - 1)
SEED = st.integers(0, 2**63 - 1)  # simulation.seed's allowed range
SMALL = st.integers(-(2**31), 2**31)  # env/step/copter/stream as they occur, negative included
NORMAL_ATOL = 3e-14  # kernel normal vs its libm reference, see test_normal_matches_naive
U64 = st.integers(0, 2**64 - 1)


def _inverse_mix64(z: int) -> int:
    """Inverse of SplitMix64's finaliser (used to construct a key whose first draw is the largest)."""
    mask = 2**64 - 1

    def unxorshift(y, s):
        x = y
        for _ in range(64 // s + 1):
            x = y ^ (x >> s)
        return x & mask

    z = unxorshift(z, 31)
    z = (z * pow(0x94D049BB133111EB, -1, 2**64)) & mask
    z = unxorshift(z, 27)
    z = (z * pow(0xBF58476D1CE4E5B9, -1, 2**64)) & mask
    return unxorshift(z, 30)


# --------------------------------------------------------------------------- numba == naive

@pytest.mark.jit_only
@settings(max_examples=200, deadline=None)
@given(SEED, I64, I64, I64, I64)
def test_counter_key_matches_naive(seed, env, step, copter, stream):
    assert np.uint64(rng.counter_key(seed, env, step, copter, stream)) == naive.counter_key(seed, env, step, copter, stream)


@pytest.mark.jit_only
@settings(max_examples=200, deadline=None)
@given(U64, I64)
def test_uniform_matches_naive(key, index):
    assert rng.uniform(np.uint64(key), index) == naive.uniform(np.uint64(key), index)


@pytest.mark.jit_only
@settings(max_examples=200, deadline=None)
@given(U64, st.integers(-(2**62), 2**62 - 1))
def test_normal_matches_naive(key, index):
    # the uniforms are bit-identical (above); the reference takes libm's cosine, the kernel the polynomial sine of
    # kernels/trig.py: |Δcos| ≤ 2e-15 (its bound) + 1e-15 (rounding of the argument) times R ≤ 8.6 (u ≥ 2^-53)
    np.testing.assert_allclose(rng.normal(np.uint64(key), index), naive.normal(np.uint64(key), index),
                               rtol=1e-13, atol=NORMAL_ATOL)


@pytest.mark.jit_only
@settings(max_examples=50, deadline=None)
@given(SEED, SMALL, SMALL, SMALL, SMALL, st.integers(0, 64))
def test_arrays_match_naive(seed, env, step, copter, stream, n):
    u = rng.uniforms_array(seed, env, step, copter, stream, n)
    np.testing.assert_array_equal(u, naive.uniforms_array(seed, env, step, copter, stream, n))
    z = rng.normals_array(seed, env, step, copter, stream, n)
    np.testing.assert_allclose(z, naive.normals_array(seed, env, step, copter, stream, n), rtol=1e-13, atol=NORMAL_ATOL)


# SplitMix64 (Steele, Lea & Flood 2014; Vigna's splitmix64.c) seeded with 1234567: its first five outputs, as
# published on Rosetta Code, "Pseudo-random numbers/Splitmix64" (hex 599ED017FB08FC85, 2C73F08458540FA5, ...).
SPLITMIX64_1234567 = [6457827717110365317, 3203168211198807973, 9817491932198370423, 4593380528125082431,
                      16408922859458223821]
GOLDEN_GAMMA = 0x9E3779B97F4A7C15


def test_mix64_is_splitmix64_by_published_vectors():
    """Output i of SplitMix64 is mix64(seed + i·γ) (mod 2⁶⁴): the finaliser against an outside reference."""
    for i, want in enumerate(SPLITMIX64_1234567, start=1):
        state = (1234567 + i * GOLDEN_GAMMA) % 2**64
        assert int(rng.mix64(np.uint64(state))) == want


def test_uniform_is_the_splitmix64_stream_of_its_key():
    """uniform(key, i) takes the top 52 bits of SplitMix64 output i + 1 seeded with key, plus ½ ulp, times 2⁻⁵²."""
    for i, want in enumerate(SPLITMIX64_1234567):
        assert rng.uniform(np.uint64(1234567), i) == ((want >> 12) + 0.5) * 2.0**-52


@pytest.mark.jit_only
def test_known_values_are_stable():
    """Pin a few outputs: changing the generator changes every seeded result downstream."""
    assert rng.counter_key(0, 1, 2, 3, 4) == 472297383753096155
    np.testing.assert_array_equal(rng.uniforms_array(0, -1, -5, 2, 3, 2), [0.6467384135140753, 0.5084253396278114])


# --------------------------------------------------------------------------- range

@pytest.mark.jit_only
@settings(max_examples=300, deadline=None)
@given(U64, I64)
def test_uniform_in_open_unit_interval(key, index):
    u = rng.uniform(np.uint64(key), index)
    assert 0.0 < u < 1.0


def test_uniform_extremes_bulk():
    u = rng.uniforms_array(123, 0, 0, 0, rng.STREAM_COMMAND, 200_000)
    assert u.min() > 0.0 and u.max() < 1.0
    assert np.all(np.isfinite(np.log(u)))
    # the smallest possible value keeps log finite
    assert np.isfinite(np.log(0.5 * 2.0**-52))


def test_uniform_never_returns_one_at_the_top_of_the_range():
    z_max = 2**64 - 1  # mix64 output whose top 53 bits are all ones
    key = (_inverse_mix64(z_max) - 0x9E3779B97F4A7C15) % 2**64  # so that uniform(key, 0) sees z_max
    assert naive.mix64(np.uint64(key) + naive.GOLDEN) == np.uint64(z_max)
    assert rng.uniform(np.uint64(key), 0) < 1.0


def test_uniform_accepts_the_key_counter_key_returns():
    key = rng.counter_key(0, 1, 2, 3, 4)
    assert rng.uniform(key, 0) == rng.uniforms_array(0, 1, 2, 3, 4, 1)[0]


# --------------------------------------------------------------------------- distributions (fixed seeds)

@pytest.mark.parametrize("seed", [0, 1, 2**40 + 7])
def test_uniform_ks(seed):
    u = rng.uniforms_array(seed, 3, 11, 2, rng.STREAM_SONAR, 50_000)
    assert stats.kstest(u, "uniform").pvalue > 1e-3
    assert_mean_within_se(u, 0.5, se=np.sqrt(1 / 12 / u.size), what=f"mean of uniforms, seed {seed}")


@pytest.mark.parametrize("seed", [0, 5, 2**40 + 7])
def test_normal_ks_and_moments(seed):
    z = rng.normals_array(seed, 1, 2, 3, rng.STREAM_IMU, 50_000)
    assert stats.kstest(z, "norm").pvalue > 1e-3
    n = z.size
    assert_mean_within_se(z, 0.0, se=1 / np.sqrt(n), what=f"mean of normals, seed {seed}")
    assert_within_se(z.var(), 1.0, np.sqrt(2 / n), what=f"variance of normals, seed {seed}")  # 5 SE: 3 % of 1
    assert_within_se(stats.skew(z), 0.0, np.sqrt(6 / n), what=f"skewness of normals, seed {seed}")
    assert_within_se(stats.kurtosis(z), 0.0, np.sqrt(24 / n), what=f"excess kurtosis of normals, seed {seed}")


def test_uniform_ks_across_cells():
    """First draws of many keys (the usual access pattern: one key per copter and step) are uniform too."""
    keys = naive.counter_key(9, np.arange(20_000), 0, 0, rng.STREAM_BEHAVIOUR)
    u = np.array([rng.uniform(k, 0) for k in keys[:2000]])  # numba on a sample, reference on the rest
    np.testing.assert_array_equal(u, naive.uniform(keys[:2000], 0))
    assert stats.kstest(naive.uniform(keys, 0), "uniform").pvalue > 1e-3


# --------------------------------------------------------------------------- independence

def _first_uniforms(seed, env, step, copter, stream, n=2):
    """Numba draws of one cell per row of the broadcast index arrays: shape (cells, n)."""
    env, step, copter, stream = np.broadcast_arrays(env, step, copter, stream)
    return np.array([rng.uniforms_array(seed, int(e), int(s), int(c), int(k), n)
                     for e, s, c, k in zip(env, step, copter, stream)])


@pytest.mark.parametrize("axis", [pytest.param(a, marks=pytest.mark.jit_only) for a in ("env", "step", "copter", "stream")]
                         + ["seed", "index"])
def test_neighbouring_cells_are_uncorrelated(axis):
    """Cells that differ by one in a single index give uncorrelated draws (|r| < 5/sqrt(n))."""
    n = 5000
    i = np.arange(n) - n // 2  # negative indices included
    base = dict(env=np.int64(4), step=np.int64(17), copter=np.int64(2), stream=np.int64(rng.STREAM_SONAR))
    if axis == "index":
        u = rng.uniforms_array(3, 4, 17, 2, rng.STREAM_SONAR, 2 * n)
        a, b = u[0::2], u[1::2]
    elif axis == "seed":
        a = np.array([rng.uniforms_array(s, 4, 17, 2, 3, 1)[0] for s in range(n)])
        b = np.array([rng.uniforms_array(s + 1, 4, 17, 2, 3, 1)[0] for s in range(n)])
    else:
        args = {**base, axis: i}
        a = _first_uniforms(3, **args)[:, 0]
        args[axis] = i + 1
        b = _first_uniforms(3, **args)[:, 0]
    assert_within_se(np.corrcoef(a, b)[0, 1], 0.0, 1 / np.sqrt(n), what=f"correlation of neighbours along {axis}")
    # and the pairs fill the unit square evenly (chi-square over a 10 x 10 grid)
    counts, _, _ = np.histogram2d(a, b, bins=10, range=[[0, 1], [0, 1]])
    assert stats.chisquare(counts.ravel()).pvalue > 1e-3


def test_streams_differ_everywhere():
    """No two registered streams share a key for the same (seed, env, step, copter)."""
    streams = [getattr(rng, k) for k in dir(rng) if k.startswith("STREAM_")]
    assert len(set(streams)) == len(streams)
    keys = {rng.counter_key(1, 2, 3, 4, s) for s in streams}
    assert len(keys) == len(streams)


def test_normal_within_its_stated_tolerance_of_the_libm_box_muller_on_a_million_draws():
    z = rng.normals_array(3, 1, 2, 3, rng.STREAM_IMU, 1_000_000)
    y = naive.normals_array(3, 1, 2, 3, rng.STREAM_IMU, 1_000_000)
    assert np.abs(z - y).max() <= NORMAL_ATOL
