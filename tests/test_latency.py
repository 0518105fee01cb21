"""Sensor latency (finkensim.sensors.latency): one law for the simulator and the diagnosis. The ring-buffer kernel
against its NumPy reference, the simulator's compiled and reference paths against the undelayed flight, the
controlled steps, the config keys and the calibration mapping."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.config import ConfigError, load_config
from finkensim.gap.attribute import effects as fx
from finkensim.gap.model.params import ModelParams
from finkensim.sensors.latency import (delay_buffer, delay_env, delay_reference, delayed_steps, lag_steps,
                                       sensor_lags)


@settings(max_examples=60, deadline=None)
@given(lag=st.integers(1, 6), extra=st.integers(0, 3), T=st.integers(1, 25), C=st.integers(1, 4),
       seed=st.integers(0, 2**31))
def test_delay_kernel_matches_reference(lag, extra, T, C, seed):
    """A stream through the ring buffer shows readings[max(t − lag, 0)] (a buffer larger than needed too)."""
    readings = np.random.default_rng(seed).normal(size=(T, 3, C))
    buf = np.full((lag + 1 + extra, 3, C + 1), -1.0)
    shown = np.empty_like(readings)
    for t in range(T):
        v = readings[t].copy()
        delay_env(v, buf, 0, t, lag)
        shown[t] = v
    np.testing.assert_array_equal(shown, delay_reference(readings, lag))


def test_delay_starts_at_the_first_step_sensed():
    """A stream that starts at step 5 shows its first reading until step 5 + lag."""
    buf = np.full((3, 1, 2), -1.0)
    out = []
    for k in range(5, 10):
        v = np.array([[float(k)]])
        delay_env(v, buf, 0, k, 2)
        out.append(v[0, 0])
    assert out == [5.0, 5.0, 5.0, 6.0, 7.0]


def test_lag_law_is_the_diagnosis_law():
    assert lag_steps(0.05, 0.02) == 3 and lag_steps(-0.05, 0.02) == -3 and lag_steps(0.0, 0.02) == 0
    np.testing.assert_array_equal(delayed_steps(np.arange(5), 2, 5), [0, 0, 0, 1, 2])
    assert delay_buffer(np.zeros(3, dtype=np.int64), 2, 3, 4).shape == (2, 0, 3, 0)
    assert delay_buffer(np.array([2, 0, 1]), 2, 3, 5).shape == (2, 3, 3, 4 + 3 + 1)
    with pytest.raises(ValueError, match="expected >= 0"):
        sensor_lags(-0.1, 0.0, 0.0, 0.02)


@pytest.mark.parametrize("key", ["sonar.latency", "ranging.latency", "imu.latency"])
@pytest.mark.parametrize("bad", [-0.1, 2.5, "x"])
def test_bad_latency_is_a_named_error(key, bad):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        load_config().replace({key: bad})


def test_latency_calibrates_to_the_config_keys():
    cfg = load_config()
    upd = fx.REGISTRY["latency"].calibrate({"ultrasonic": 0.06, "ranging": -0.04, "imu": 0.1}, cfg)
    assert upd == {"sonar.latency": 0.06, "ranging.latency": 0.0, "imu.latency": 0.1}
    p = ModelParams.from_config(cfg.replace(upd))
    assert (p.latency_sonar, p.latency_ranging, p.latency_imu) == (0.06, 0.0, 0.1)


SMALL = {"copters.n": 3, "behaviour.kind": "random_walk", "simulation.dt": 0.02}
RECORD = ("sonar", "ranging", "imu_acc", "imu_gyro")
LAGS = {"sonar.latency": 0.06, "ranging.latency": 0.1, "imu.latency": 0.04}


@pytest.fixture(scope="module")
def flights():
    from finkensim.swarm import SwarmSim

    out = {}
    for name, upd in (("base", {}), ("late", LAGS)):
        sim = SwarmSim(load_config().replace({**SMALL, **upd}))
        out[name] = sim.rollout(sim.init(n_envs=2, seed=4), 40, record=RECORD)[1]
        out[name + "_python"] = sim.rollout(sim.init(n_envs=2, seed=4), 40, record=RECORD, python=True)[1]
    return out


@pytest.mark.parametrize("name,key", [("sonar", "sonar.latency"), ("ranging", "ranging.latency"),
                                      ("imu_acc", "imu.latency"), ("imu_gyro", "imu.latency")])
def test_the_simulator_flies_the_latency(flights, name, key):
    """An open-loop flight with latency records exactly the undelayed flight's readings, lag steps later (the
    compiled loop and the reference path alike)."""
    lag = lag_steps(LAGS[key], SMALL["simulation.dt"])
    want = delay_reference(getattr(flights["base"], name), lag)
    np.testing.assert_array_equal(getattr(flights["late"], name), want)
    np.testing.assert_array_equal(getattr(flights["late_python"], name), want)


def test_controlled_steps_fly_the_latency(flights):
    from finkensim.swarm import SwarmSim
    from finkensim.swarm.control import Controlled

    sim = SwarmSim(load_config().replace({**SMALL, **LAGS, "behaviour.kind": "hover"}))
    base = SwarmSim(load_config().replace({**SMALL, "behaviour.kind": "hover"}))
    seen = {}
    for name, s in (("late", sim), ("base", base)):
        ctl = Controlled(s)
        state = s.init(n_envs=2, seed=1)
        obs = [ctl.sense(state).sonar.copy()]
        for _ in range(6):
            state, o = ctl.step(state, np.zeros((2, 3, 2)))
            obs.append(o.sonar.copy())
        seen[name] = np.array(obs)
    np.testing.assert_array_equal(seen["late"], delay_reference(seen["base"], 3))


def test_a_foreign_state_is_a_named_error():
    from finkensim.swarm import SwarmSim

    sim = SwarmSim(load_config().replace({**SMALL, **LAGS}))
    state = SwarmSim(load_config().replace(SMALL)).init(n_envs=1, seed=0)
    with pytest.raises(ConfigError, match="sensor_delay"):
        sim.rollout(state, 2)


def test_a_latency_buffer_beyond_the_memory_is_a_named_error(monkeypatch):
    """A latency of many steps for many copters is refused before it is allocated, naming the latency keys."""
    from finkensim.budget import MemoryBudgetError
    from finkensim.sensors.latency import delay_buffer

    monkeypatch.setenv("FINKENSIM_MEMORY_AVAILABLE", "1e6")
    with pytest.raises(MemoryBudgetError, match="ranging.latency"):
        delay_buffer(np.array([0, 100_000, 0]), 1, 242, 242)
