"""Flying a config's ranging along recorded poses (``scenario.fly_recorded_poses``,
``sensors.ranging.readings_along_poses``) and cutting a flight log in time (``FlightLog.between``): the kernel
against the plain-NumPy reference with heights, the engine's own readings reproduced bit for bit on a simulated
flight's poses, heights read as 3-D distances, named errors."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.config import ConfigError, load_config
from finkensim.flightlog import FlightLog, FlightLogError, validate
from finkensim.scenario import fly_recorded_poses, simulate_flight
from finkensim.sensors.ranging import RangingModel, readings_along_poses
from tests.naive.ranging_radio import naive_radio_readings
from tests.test_ranging_radio import radio_effects


@pytest.mark.parametrize("error", ["none", "gaussian", "mixture"])
@settings(max_examples=15, deadline=None)
@given(radio=st.one_of(st.just({}), radio_effects), seed=st.integers(0, 2**31), data_seed=st.integers(0, 2**31))
def test_readings_along_poses_equal_the_reference_with_heights(error, radio, seed, data_seed):
    rng = np.random.default_rng(data_seed)
    model = RangingModel(error, max_range=3.0, sigma=0.1, **radio)
    T, N = 3, 4
    pose = np.concatenate([rng.uniform(0.0, 2.5, (T, N, 2)), rng.uniform(-np.pi, np.pi, (T, N, 1))], axis=-1)
    z = rng.uniform(0.0, 1.5, (T, N))
    got = readings_along_poses(pose, model, z=z, seed=seed, env=2, step0=7)
    for k in range(T):
        want = naive_radio_readings(pose[None, k, :, :2], pose[None, k, :, 2], np.zeros((0, 2)), seed, [2], 7 + k,
                                    model, z=z[None, k])[0]
        np.testing.assert_allclose(got[k], want, rtol=0, atol=1e-9)


def test_a_simulated_flights_own_poses_give_back_its_readings_bit_for_bit():
    """Every radio effect, dropout and a latency of two steps on: the engine's readings, reproduced from its poses."""
    cfg = load_config({"copters": {"n": 4}, "simulation": {"duration": 2.0, "dt": 0.05},
                       "ranging": {"enabled": True, "error": "mixture", "max_range": 3.0, "latency": 0.1,
                                   "node_delay": [0.1, -0.05, 0.0, 0.2], "antenna_offset": [0.05, 0.02, 0.0],
                                   "nlos_bias": 0.3, "nlos_tail_probability": 0.2, "dropout_a": -2.0,
                                   "dropout_b": 0.5}})
    log, _, _ = simulate_flight(cfg, seed=11)
    flown = fly_recorded_poses(log, cfg, seed=11)
    assert np.isnan(log.ranging).any()
    np.testing.assert_array_equal(flown.ranging, log.ranging)
    assert not np.array_equal(fly_recorded_poses(log, cfg, seed=12).ranging, log.ranging, equal_nan=True)


def _log(z=None, t=None):
    t = np.arange(5.0) if t is None else np.asarray(t, float)
    pose = np.zeros((t.size, 2, 3))
    pose[:, 0, :2] = [1.0, 1.0]
    pose[:, 1, :2] = [3.0, 1.0]
    extras = {} if z is None else {"z": np.asarray(z, float)}
    return FlightLog(t=t, arena=np.array([5.0, 3.0]), pose=pose, copter_ids=np.array(["a", "b"]),
                     ranging=np.zeros((t.size, 2, 2)), extras=extras, meta={"copter_radius": 0.15})


def test_heights_are_read_as_3d_distances():
    cfg = {"ranging": {"enabled": True, "error": "none", "max_range": 5.0, "node_delay": [0.1, 0.05]}}
    z = np.tile([1.75, 0.5], (5, 1))
    flown = fly_recorded_poses(_log(z), cfg)
    np.testing.assert_allclose(flown.ranging[:, 0, 1], np.hypot(2.0, 1.25) + 0.15, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(flown.extras["z"], z)
    planar = fly_recorded_poses(_log(), cfg)
    np.testing.assert_allclose(planar.ranging[:, 1, 0], 2.15, rtol=0, atol=1e-12)
    validate(flown)


@pytest.mark.parametrize("cfg, log, match", [
    ({"ranging": {"enabled": False}}, _log(), "ranging.enabled"),
    ({"ranging": {"enabled": True, "beacons": [[1.0, 1.0]]}}, _log(), "ranging.beacons"),
    ({"ranging": {"enabled": True, "latency": 0.5}}, _log(t=[0.0, 1.0, 1.5, 3.0, 4.0]), "ranging.latency"),
])
def test_what_cannot_be_flown_is_a_named_error(cfg, log, match):
    with pytest.raises(ConfigError, match=match):
        fly_recorded_poses(log, cfg)


@pytest.mark.parametrize("kwargs, match", [({"pose": np.zeros((3, 2, 2))}, "pose"),
                                           ({"pose": np.zeros((3, 2, 3)), "z": np.zeros((3, 3))}, "z")])
def test_wrong_arrays_are_named(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        readings_along_poses(params=RangingModel("none"), **kwargs)


@settings(max_examples=30, deadline=None)
@given(cut=st.floats(1.01, 8.0), T=st.integers(10, 12))
def test_a_log_cut_in_time_keeps_every_sample_once(cut, T):
    t = np.arange(float(T))
    z = np.arange(2.0 * T).reshape(T, 2)
    log = _log(z=z, t=t)
    log.extras["beacon_positions"] = np.ones((3, 2))  # no time axis: kept whole
    first, rest = log.between(-1.0, cut), log.between(cut, T + 1.0)
    np.testing.assert_array_equal(np.concatenate([first.t, rest.t]), t)
    np.testing.assert_array_equal(np.concatenate([first.extras["z"], rest.extras["z"]]), z)
    np.testing.assert_array_equal(np.concatenate([first.pose, rest.pose]), log.pose)
    assert first.ranging.shape == (first.t.size, 2, 2)
    np.testing.assert_array_equal(rest.extras["beacon_positions"], np.ones((3, 2)))
    assert rest.meta == log.meta and list(rest.copter_ids) == ["a", "b"]
    validate(first)


@pytest.mark.parametrize("window, match", [((3.0, 3.0), "start < stop"), (("x", 2.0), "two numbers"),
                                           ((4.0, 4.5), "holds 1")])
def test_a_bad_time_window_is_a_named_error(window, match):
    with pytest.raises(FlightLogError, match=match):
        _log().between(*window)
