"""The ranging radio effects (finkensim.sensors.ranging_radio): kernels against the plain-NumPy reference, the
neutral defaults, config errors, and the diagnosis's use of the same kernel."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.config import ConfigError, RangingConfig, load_config
from finkensim.sensors.ranging import RangingModel, ranging_readings
from finkensim.sensors.ranging_kernels import row_key
from finkensim.sensors.ranging_radio import dropout_probabilities, radio_batch, tag_distance_draws
from finkensim.sensors.tracking import PoseNoise
from tests.naive.ranging_radio import (naive_clearance, naive_dropout_probability, naive_radio_readings,
                                       naive_shift, naive_tag)

small = st.floats(-0.3, 0.3)
radio_effects = st.fixed_dictionaries({
    "bias": st.floats(-0.5, 0.5),
    "scale": st.floats(0.8, 1.2),
    "node_delay": st.lists(small, max_size=6).map(tuple),
    "antenna_offset": st.tuples(small, small, small),
    "antenna_offset_per_copter": st.lists(st.tuples(small, small), max_size=4).map(tuple),
    "nlos_bias": st.floats(-0.5, 1.0),
    "nlos_width": st.floats(0.05, 0.5),
    "nlos_tail_probability": st.floats(0.0, 1.0),
    "nlos_tail_mean": st.floats(0.05, 1.0),
    "dropout_a": st.one_of(st.just(-100.0), st.floats(-6.0, 3.0)),
    "dropout_b": st.floats(-2.0, 2.0),
})


@pytest.mark.parametrize("error", ["none", "gaussian", "mixture"])
@settings(max_examples=25, deadline=None)
@given(radio=radio_effects, seed=st.integers(0, 2**31), data_seed=st.integers(0, 2**31))
def test_readings_with_radio_effects_equal_the_reference(error, radio, seed, data_seed):
    rng = np.random.default_rng(data_seed)
    model = RangingModel(error, max_range=3.0, sigma=0.1, **radio)
    pos = rng.uniform(0.0, 2.5, (2, 4, 2))
    yaw = rng.uniform(-np.pi, np.pi, (2, 4))
    beacons = rng.uniform(0.0, 2.5, (2, 2))
    env_ids = np.array([3, 8])
    got = ranging_readings(pos, beacons, seed, env_ids, 5, model, yaw=yaw)
    want = naive_radio_readings(pos, yaw, beacons, seed, env_ids, 5, model)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)


@settings(max_examples=25, deadline=None)
@given(radio=radio_effects, seed=st.integers(0, 2**31), data_seed=st.integers(0, 2**31))
def test_radio_batch_equals_the_reference(radio, seed, data_seed):
    """The diagnosis's draws: the same shift, draw (i, m) as column i·M + m."""
    rng = np.random.default_rng(data_seed)
    model = RangingModel("none", max_range=2.0, **radio)
    n, M = 5, 3
    x = rng.uniform(0.0, 2.5, (n, M))
    y0 = x + rng.normal(0.0, 0.1, (n, M)).clip(-x)
    a = rng.integers(0, 8, n)
    b = rng.integers(0, 8, n)
    clear = rng.uniform(0.0, 1.0, n)
    key = row_key(seed, 0, 0, 0)
    out = np.empty((n, M))
    radio_batch(y0, x, a, b, clear, key, row_key(seed, 0, 0, 1), 2.0, model.params, out)
    want = np.array([[2.0 if x[i, m] > 2.0 else naive_shift(y0[i, m], a[i], b[i], clear[i], key, i * M + m,
                                                              model.radio) for m in range(M)] for i in range(n)])
    np.testing.assert_allclose(out, want, rtol=0, atol=1e-12)


@settings(max_examples=20, deadline=None)
@given(radio=radio_effects, data_seed=st.integers(0, 2**31))
def test_tag_distance_draws_without_noise_equal_the_reference(radio, data_seed):
    rng = np.random.default_rng(data_seed)
    model = RangingModel("none", **radio)
    T, N = 4, 3
    pos = rng.uniform(0.0, 3.0, (T, N, 2))
    z = rng.uniform(0.0, 1.5, (T, N))
    yaw = rng.uniform(-np.pi, np.pi, (T, N))
    times = np.array([0, 2, 3])
    out = np.empty((3, N, N, 1))
    tag_distance_draws(pos, z, yaw, times, PoseNoise(0.0, 0.0, 0, 0), 1, model.params, out)
    for ti, k in enumerate(times):
        for a in range(N):
            for b in range(N):
                want = 0.0 if a == b else np.linalg.norm(naive_tag(model.radio, b, *pos[k, b], z[k, b], yaw[k, b])
                                                         - naive_tag(model.radio, a, *pos[k, a], z[k, a], yaw[k, a]))
                assert out[ti, a, b, 0] == pytest.approx(want, abs=1e-12)


@given(a=st.floats(-12.0, 8.0), b=st.floats(-6.0, 6.0), x=st.lists(st.floats(0.0, 10.0), min_size=1, max_size=5))
def test_dropout_probability_equals_the_reference(a, b, x):
    got = dropout_probabilities(np.array(x), a, b)
    np.testing.assert_allclose(got, [naive_dropout_probability(v, a, b) for v in x], rtol=1e-12, atol=1e-300)


def test_clearance_reference_and_kernel_agree_on_a_simple_case():
    pos = np.array([[0.0, 0.0], [2.0, 0.0], [1.0, 0.3]])
    assert naive_clearance(pos, 0, 1, pos[1]) == pytest.approx(0.3)


def test_defaults_are_neutral_and_bit_identical():
    """Every radio key at its default leaves the readings exactly as without the effects (golden results)."""
    model = RangingModel.from_config(load_config().ranging)
    assert int(model.params.radio_on) == 0
    rng = np.random.default_rng(0)
    pos = rng.uniform(0.0, 2.0, (3, 5, 2))
    plain = ranging_readings(pos, (), 4, np.arange(3), 2, model)
    turned = ranging_readings(pos, (), 4, np.arange(3), 2, model, yaw=rng.uniform(-3, 3, (3, 5)))
    np.testing.assert_array_equal(plain, turned)


def test_statistics_of_the_tail_and_the_dropout():
    """A fixed seed and 20 000 readings: the tail's share and mean, the dropout's share (5-sigma bounds)."""
    model = RangingModel("none", max_range=10.0, nlos_tail_probability=0.2, nlos_tail_mean=0.4, dropout_a=-1.0)
    pos = np.array([[[0.0, 0.0], [1.0, 0.0]]])
    extra, lost = [], 0
    for step in range(10_000):
        r = ranging_readings(pos, (), 1, [0], step, model)[0]
        for v in (r[0, 1], r[1, 0]):
            if np.isnan(v):
                lost += 1
            elif v > 1.0 + 1e-12:
                extra.append(v - 1.0)
    p_drop = 1.0 / (1.0 + np.exp(1.0 - 0.0))  # sigmoid(-1 + 0·x)
    n = 20_000
    assert abs(lost / n - p_drop) < 5 * np.sqrt(p_drop * (1 - p_drop) / n)
    kept = n - lost
    assert abs(len(extra) / kept - 0.2) < 5 * np.sqrt(0.2 * 0.8 / kept)
    assert abs(np.mean(extra) - 0.4) < 5 * 0.4 / np.sqrt(len(extra))


@pytest.mark.parametrize("key, value", [("nlos_tail_probability", 1.5), ("scale", 0.1), ("node_delay", [0.1, "x"]),
                                        ("antenna_offset", [0.1, 0.0]), ("antenna_offset_per_copter", [[0.1]]),
                                        ("nlos_width", 0.0), ("dropout_a", 1e9)])
def test_bad_radio_keys_are_named_errors(key, value):
    with pytest.raises(ConfigError, match=f"ranging.{key}"):
        RangingConfig(**{key: value})


def test_a_misspelled_radio_key_gets_a_suggestion():
    with pytest.raises(ConfigError, match="node_delay"):
        load_config({"ranging": {"node_delays": [0.1]}})


def test_the_closed_loop_flies_the_radio_effects_as_the_step_by_step_reference():
    """The compiled rollout (swarm kernel: the headings passed to the ranging) = the per-step Python path
    (ranging_readings with yaw), with every radio effect on, and the readings do carry them."""
    from finkensim.swarm import SwarmSim

    radio = {"ranging.bias": 0.05, "ranging.scale": 1.02, "ranging.node_delay": [0.1, -0.05, 0.0, 0.2, 0.03],
             "ranging.antenna_offset": [0.1, 0.05, 0.0], "ranging.antenna_offset_per_copter": [[0.0, 0.02]],
             "ranging.nlos_bias": 0.3, "ranging.nlos_tail_probability": 0.2, "ranging.dropout_a": -3.0,
             "ranging.dropout_b": 0.5, "ranging.beacons": [[1.0, 1.0]]}
    cfg = load_config({"copters": {"n": 4}, "ranging": {"error": "gaussian", "max_range": 5.0},
                       "behaviour": {"kind": "random_walk"}}).replace(radio)
    sim = SwarmSim(cfg)
    state = sim.init(n_envs=2, seed=5)
    _, fast = sim.rollout(state, 20, record=True)
    _, slow = sim.rollout(state, 20, record=True, python=True)
    np.testing.assert_array_equal(fast.ranging, slow.ranging)
    assert np.isnan(fast.ranging).any()  # dropout
    plain = SwarmSim(load_config({"copters": {"n": 4}, "ranging": {"error": "gaussian", "max_range": 5.0},
                                  "behaviour": {"kind": "random_walk"}}).replace({"ranging.beacons": [[1.0, 1.0]]}))
    _, base = plain.rollout(plain.init(n_envs=2, seed=5), 1, record=True)
    assert not np.allclose(np.nan_to_num(fast.ranging[0]), base.ranging[0])
