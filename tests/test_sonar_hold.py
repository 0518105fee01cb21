"""Sample-and-hold of the sonars (sonar.update_hz): the kernel against a plain NumPy reference, its properties, and
the simulator's three sense paths (compiled rollout, Python step, controlled step) holding alike."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.sensors.sonar_hold import EPS_STEPS, held_step, held_steps, hold_env


def held_reference(k, dt, hz, phase):
    """NumPy reference: list every measurement instant phase + m/hz near steps 0..k, the step each is taken at (the
    first at or after it, with the same rounding allowance; instants before t = 0 at step 0), and take the latest
    of those steps at or before k."""
    if hz <= 0:
        return k
    m = np.arange(math.floor(-phase * hz) - 2, math.ceil((k * dt - phase) * hz) + 3)
    steps = np.maximum(np.ceil((phase + m / hz) / dt - EPS_STEPS), 0).astype(np.int64)
    return int(steps[steps <= k].max())


@settings(max_examples=300, deadline=None)
@given(k=st.integers(0, 5000), dt=st.sampled_from([0.01, 0.02, 1 / 36, 0.04, 0.005]),
       hz=st.one_of(st.just(0.0), st.floats(0.5, 60.0)), phase=st.floats(-1.0, 1.0))
def test_held_step_matches_the_numpy_reference(k, dt, hz, phase):
    assert held_step(k, dt, hz, phase) == held_reference(k, dt, hz, phase)


@settings(max_examples=200, deadline=None)
@given(k=st.integers(0, 10**6), dt=st.floats(1e-4, 1.0), hz=st.floats(1e-300, 1000.0), phase=st.floats(0.0, 1e300))
def test_held_step_ends_over_the_configs_whole_range(k, dt, hz, phase):
    """Any sonar.update_hz in (0, 1000] and update_phase >= 0 s the config accepts: a step in [0, k] (a slow
    rate's next measurement lies beyond any integer step; it once overflowed and the search never ended)."""
    u = held_step(k, dt, hz, phase)
    assert 0 <= u <= k
    if phase + 1.0 / hz > (k + 1) * dt and phase - 1.0 / hz <= 0.0:
        # one measurement in the flight (at the phase) after one before t = 0 (held from step 0)
        first = math.ceil(phase / dt - EPS_STEPS)
        assert u == (first if first <= k else 0)


@settings(max_examples=50, deadline=None)
@given(dt=st.sampled_from([0.01, 1 / 36, 0.04]), hz=st.floats(1.0, 20.0), phase=st.floats(0.0, 1.0))
def test_held_steps_are_past_nondecreasing_and_measure_at_the_rate(dt, hz, phase):
    T = 2000
    u = held_steps(np.arange(T), dt, hz, phase)
    assert np.all(u <= np.arange(T)) and np.all(np.diff(u) >= 0)
    measuring = np.flatnonzero(u == np.arange(T))
    expected = T * dt * min(hz, 1 / dt)
    assert abs(measuring.size - expected) <= 2       # one measurement per period (the first step may add one)


def test_neutral_rate_measures_every_step():
    assert list(held_steps(np.arange(10), 0.01, 0.0, 0.3)) == list(range(10))


def test_hold_env_keeps_or_takes():
    son, held = np.array([[1.0, 2.0]]), np.array([[5.0, 6.0]])
    hold_env(son, held, 1, 0.01, 10.0, 0.0)             # step 1 of a 10 Hz sonar at 100 Hz: not a measuring step
    assert son.tolist() == [[5.0, 6.0]]
    son = np.array([[1.0, 2.0]])
    hold_env(son, held, 10, 0.01, 10.0, 0.0)            # step 10: measures
    assert held.tolist() == [[1.0, 2.0]] and son.tolist() == [[1.0, 2.0]]


@pytest.fixture(scope="module")
def held_flight():
    import finkensim as fs

    cfg = fs.load_config({"simulation": {"dt": 0.01}, "sonar": {"update_hz": 8.0}, "copters": {"n": 3}})
    log, _, _ = fs.simulate_flight(cfg, duration=3.0, seed=2)
    return cfg, log


def test_simulated_readings_change_only_at_the_update_instants(held_flight):
    cfg, log = held_flight
    u = held_steps(np.arange(log.n_steps - 1), cfg.simulation.dt, 8.0, 0.0)
    son = log.ultrasonic[:-1]
    np.testing.assert_array_equal(son, son[u])         # every reading is its measuring step's
    changed = np.any(son[1:] != son[:-1], axis=(1, 2))
    assert set(np.flatnonzero(changed) + 1) <= set(np.flatnonzero(u == np.arange(u.size)))


def test_python_step_and_controlled_step_hold_like_the_compiled_rollout(held_flight):
    from finkensim.swarm import SwarmSim
    from finkensim.swarm.control import Controlled

    cfg, _ = held_flight
    sim = SwarmSim(cfg)
    state = sim.init(n_envs=1, seed=4)
    _, rec = sim.rollout(state, 30, record=("sonar",))
    s, py = state, []
    for _ in range(30):
        s, r, _ = sim.step(s)
        py.append(r.sonar[0])
    np.testing.assert_array_equal(np.array(py), rec.sonar[:, 0])
    ctl = Controlled(sim)
    c = state.copy()
    seen = [ctl.sense(c).sonar[0].copy()]
    for _ in range(12):
        c, obs = ctl.step(c, np.zeros((1, cfg.copters.n, 2)))
        seen.append(obs.sonar[0].copy())
    u = held_steps(np.arange(13), cfg.simulation.dt, 8.0, 0.0)
    seen = np.array(seen)
    np.testing.assert_array_equal(seen, seen[u])


def test_hold_rhythms_find_the_rate_and_phase_of_a_simulated_hold(held_flight):
    from types import SimpleNamespace

    from finkensim.gap.attribute.fits import hold_rhythms

    cfg, log = held_flight                                  # 8 Hz, measuring from t = 0, at 100 Hz
    found = hold_rhythms([SimpleNamespace(log=log, dt=cfg.simulation.dt)], 0.0, 50.0)
    rate, phase, strength = found[0]
    # refined to 0.01 cycles over the flight (fits.REFINE_RESOLUTION): a tenth of the coarse grid's 0.25 cycles / 3 s
    assert abs(rate - 8.0) < 0.025 / 3.0 and strength > 0.8
    assert min(phase, 1 - phase) < 0.1                      # 0 periods, late by the rounding to samples
    none, _, _ = simulated_without_hold()
    assert hold_rhythms([SimpleNamespace(log=none, dt=0.01)], 0.0, 50.0)[0][2] < 0.4   # chance peaks only


def simulated_without_hold():
    import finkensim as fs

    return fs.simulate_flight(fs.load_config({"simulation": {"dt": 0.01}, "copters": {"n": 3}}), duration=3.0, seed=2)
