"""finkensim.testing: every public strategy's output passes the validator its objects meet in use (load_config and
``finkensim check``, SwarmSim, World, the flight-log loader, the importer, an effect's apply), for hundreds of
examples; the assertions' failure messages; the profiles; the import needs neither pytest nor more than hypothesis."""
from __future__ import annotations

import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from finkensim.checkfiles import check_file
from finkensim.config import SECTIONS, Config, load_config
from finkensim.flightlog import load, save, validate
from finkensim.testing import (assert_flightlog_valid, assert_inside_arena, assert_no_overlap, assert_reproducible)
from finkensim.testing import strategies as fst
from finkensim.testing.profiles import PROFILE_ENV, THOROUGH_FACTOR, current_profile, examples, load_profile

MANY = settings(max_examples=examples(200), deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
SOME = settings(MANY, max_examples=examples(60))


# ------------------------------------------------------------------------------------------ configs


@MANY
@given(fst.configs())
def test_configs_load_back_from_a_dict_and_from_toml(cfg):
    assert load_config(cfg.to_dict()) == cfg
    assert load_config(fst.config_toml(cfg)) == cfg


@settings(SOME, max_examples=examples(25))  # a ranging range of up to 1000 m builds a large sampling table
@given(fst.configs())
def test_configs_are_accepted_by_the_swarm_and_by_finkensim_check(cfg):
    from finkensim.swarm import SwarmSim

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # e.g. the ranging table's accuracy warning for a 900 m range
        SwarmSim(cfg)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "scenario.toml"
        path.write_text(fst.config_toml(cfg))
        assert check_file(path).startswith("scenario")


@MANY
@given(st.data())
def test_configs_respect_bounds_fixed_and_sections(data):
    cfg = data.draw(fst.configs(["copters"], bounds={"copters.n": (2, 5), "arena.width": (1.0, 2.0)},
                                fixed={"behaviour.kind": "hover"}, profiles=["default"]))
    assert 2 <= cfg.copters.n <= 5 and 1.0 <= cfg.arena.width <= 2.0
    assert cfg.behaviour.kind == "hover" and cfg.profile == "default"
    assert cfg.sonar == Config().sonar  # a section not drawn keeps its defaults


def test_configs_shrink_to_the_default_plus_what_matters():
    from hypothesis import find

    found = find(fst.configs(), lambda c: c.copters.n >= 10, settings=settings(database=None))
    assert found.copters.n == 10 and found.replace({"copters.n": 6}) == Config()  # nothing else left changed


def test_flight_logs_shrink_to_one_sample_of_one_copter():
    log = _one(fst.flight_logs(sensors=["ultrasonic", "ranging"]))
    assert (log.n_steps, log.n_copters) == (1, 1) and not np.isnan(log.ultrasonic).any()


def test_config_strategy_arguments_are_checked():
    with pytest.raises(ValueError, match=r"bounds\['copters.n'\] = \(0, 5\): expected a range inside the declared >= 1"):
        _one(fst.configs(bounds={"copters.n": (0, 5)}))
    with pytest.raises(Exception, match="unknown key copters.m"):
        _one(fst.configs(fixed={"copters.m": 1}))
    with pytest.raises(ValueError, match="no valid config has both"):
        _one(fst.configs(fixed={"behaviour.kind": "attraction_repulsion", "sonar.enabled": False}))


def test_every_config_field_has_a_strategy():
    for section, cls in SECTIONS.items():
        for name in cls.__dataclass_fields__:
            fst.field_values(section, name)  # raises TypeError for a field type the strategies do not know


@MANY
@given(fst.scenarios())
def test_scenarios_are_small_and_pass_finkensim_check(cfg):
    assert cfg.copters.n <= 6 and 1 <= round(cfg.simulation.duration / cfg.simulation.dt) <= 40
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "scenario.toml"
        path.write_text(fst.config_toml(cfg))
        assert check_file(path).startswith("scenario")


@settings(SOME, max_examples=examples(10))
@given(fst.scenarios(max_steps=10))
def test_scenarios_fly_into_valid_logs_inside_the_arena(cfg):
    from finkensim.scenario import simulate_flight

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # min_separation that cannot be met is a warning
        log, _, _ = simulate_flight(cfg, seed=1)
    assert_flightlog_valid(log)
    assert_inside_arena(log, cfg)


# ------------------------------------------------------------------------------------------ world states, models


@settings(MANY, max_examples=examples(100))
@given(fst.scenarios(), st.data())
def test_world_states_are_accepted_by_the_world(cfg, data):
    from finkensim.world import World

    state = data.draw(fst.world_states(cfg, separated=data.draw(st.booleans(), label="separated")))
    assert_inside_arena(state, cfg)
    world = World(cfg)
    B, N = state.n_envs, state.n_copters
    new = world.step(state, np.zeros((B, N, 2)), np.zeros((B, N)))
    assert_inside_arena(new, cfg)


@SOME
@given(fst.scenarios(max_copters=8), st.data())
def test_separated_world_states_have_no_overlap(cfg, data):
    assert_no_overlap(data.draw(fst.world_states(cfg, separated=True)), cfg)


@MANY
@given(fst.sensor_models())
def test_sensor_models_are_complete_records(model):
    from finkensim.sensors.imu import ImuModel
    from finkensim.sensors.ranging import RangingModel
    from finkensim.sensors.sonar_model import SonarModel

    assert isinstance(model, (SonarModel, RangingModel, ImuModel))
    if isinstance(model, SonarModel):
        assert 0.0 <= model.min_range <= model.max_range and model.mount_yaw.shape == (4,)


@SOME
@given(st.sampled_from(fst.SENSOR_KINDS), st.data())
def test_sensor_models_run_in_their_kernels(kind, data):
    from finkensim.sensors.imu import imu_step
    from finkensim.sensors.ranging import ranging_readings
    from finkensim.sensors.sonar import sonar_readings
    from finkensim.world import World

    cfg = data.draw(fst.scenarios(sections=("arena", "copters", kind), fixed={f"{kind}.enabled": True}))
    model = data.draw(fst.sensor_models([kind], cfg=cfg))
    state = data.draw(fst.world_states(cfg))
    B, N = state.n_envs, state.n_copters
    if kind == "sonar":
        out = sonar_readings(state.pos, state.yaw, state.theta, World(cfg).arena, model, 0, state.env_ids, 0)
        assert out.shape == (B, N, 4)
    elif kind == "ranging":
        out = ranging_readings(state.pos, np.zeros((0, 2)), 0, state.env_ids, 0, model)
        assert out.shape == (B, N, N)
    else:
        acc, gyro = imu_step(state.acc, state.yaw, state.yaw_rate, np.zeros((B, N, 3)), model, 0, state.env_ids, 0)
        assert acc.shape == (B, N, 2) and gyro.shape == (B, N)


@MANY
@given(fst.effects())
def test_effects_apply_with_values_in_bounds(case):
    from finkensim.gap.model.params import ModelParams

    effect, values = case
    assert set(values) == {p.name for p in effect.params}
    for p in effect.params:
        assert p.lo <= values[p.name] <= p.hi
    assert isinstance(effect.apply(_BASE_MODEL(), values), ModelParams)


_MODEL_CACHE: dict = {}


def _one(strategy):
    """The simplest example of ``strategy`` (deterministic; Hypothesis's ``find``)."""
    from hypothesis import find

    return find(strategy, lambda _: True, settings=settings(database=None))


def _BASE_MODEL():
    from finkensim.gap.model.params import ModelParams

    if "base" not in _MODEL_CACHE:
        _MODEL_CACHE["base"] = ModelParams.from_config(Config())
    return _MODEL_CACHE["base"]


def test_effects_narrow_by_sensor():
    effect, _ = _one(fst.effects(sensors=["ranging"]))
    assert "ranging" in effect.sensors
    with pytest.raises(ValueError, match="unknown effect"):
        _one(fst.effects(names=["no_such_effect"]))


# ------------------------------------------------------------------------------------------ flight logs, recordings


@MANY
@given(fst.flight_logs())
def test_flight_logs_pass_the_validator(log):
    validate(log)


@MANY
@given(fst.flight_logs(conventions=True))
def test_imported_convention_logs_pass_the_validator(log):
    validate(log)


@SOME
@given(st.booleans().flatmap(lambda conv: fst.flight_logs(conventions=conv)))
def test_flight_logs_round_trip_through_the_loader(log):
    with tempfile.TemporaryDirectory() as d:
        save(log, Path(d) / "f.npz")
        assert load(Path(d) / "f.npz") == log
        assert_flightlog_valid(Path(d) / "f.npz")


def test_flight_logs_honour_their_narrowing():
    log = _one(fst.flight_logs(n_steps=5, n_copters=2, sensors=["ranging"], missing=False))
    assert (log.n_steps, log.n_copters) == (5, 2) and log.has_ranging and not log.has_ultrasonic
    assert not np.isnan(log.ranging).any()
    with pytest.raises(NotImplementedError, match="no height block yet"):
        _one(fst.flight_logs(heights=True))


@settings(MANY, max_examples=examples(100))
@given(fst.recordings())
def test_recordings_are_imported_into_valid_logs(case):
    from finkensim.importing import check_recording

    check_recording(case.recording)
    log = case.build()
    validate(log)
    assert log.n_copters == case.flight.n_copters


# ------------------------------------------------------------------------------------------ assertions


def test_assert_inside_arena_names_the_copter_and_distance():
    pos = np.array([[[1.0, 1.0], [2.96, 1.0]]])  # (B, N, 2)
    with pytest.raises(AssertionError, match=r"copter 1 \(index 0\) is at \(2.96, 1\) m, 0.11 m outside "
                                             r"\[0.15, 2.85\] x \[0.15, 3.85\] m"):
        assert_inside_arena(pos, Config())
    assert_inside_arena(pos, (3.0, 4.0))  # centres only without a radius


def test_assert_no_overlap_names_the_pair():
    pos = np.array([[0.5, 0.5], [0.7, 0.5], [2.0, 2.0]])
    with pytest.raises(AssertionError, match=r"copter 0 and copter 1 overlap: centres 0.2 m apart, expected at "
                                             r"least 2 x radius = 0.3 m; 1 overlapping pair"):
        assert_no_overlap(pos, 0.15)
    assert_no_overlap(pos, 0.05)


def test_assert_flightlog_valid_names_the_array():
    log = _one(fst.flight_logs(n_steps=3, sensors=["ranging"]))
    log.ranging[0, 0, 0] = 1.0
    with pytest.raises(AssertionError, match="not a valid flight log: ranging diagonal"):
        assert_flightlog_valid(log)


def test_assert_reproducible_across_batches_and_executors():
    cfg = Config().replace({"copters.n": 3, "walls.n_segments": 4})
    assert_reproducible(cfg, n_envs=2, n_steps=5, executors=("serial", "process"))


def test_assert_reproducible_catches_a_behaviour_with_hidden_state():
    from finkensim.swarm import SwarmSim

    calls = []

    def restless(readings, memory, params):  # depends on how often it was called, not on the seed
        calls.append(1)
        B, N = readings.sonar.shape[:2]
        return np.full((B, N, 2), 0.01 * len(calls)), None

    with pytest.raises(AssertionError, match="not reproducible"):
        assert_reproducible(SwarmSim(Config().replace({"copters.n": 2}), behaviour=restless), n_envs=2, n_steps=3)


# ------------------------------------------------------------------------------------------ profiles and import


def test_profiles(monkeypatch):
    monkeypatch.setenv(PROFILE_ENV, "thorough")
    assert current_profile() == "thorough" and examples(7) == 7 * THOROUGH_FACTOR
    monkeypatch.setenv(PROFILE_ENV, "fast")
    assert examples(7) == 7
    monkeypatch.setenv(PROFILE_ENV, "thorogh")
    with pytest.raises(ValueError, match="FINKENSIM_HYPOTHESIS = 'thorogh': expected one of 'fast', 'thorough'"):
        load_profile()


def test_import_needs_neither_pytest_nor_hypothesis_until_strategies_are_used():
    code = ("import sys, finkensim.testing as t; assert 'pytest' not in sys.modules and 'hypothesis' not in "
            "sys.modules; from finkensim.testing import strategies; assert 'pytest' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)


# ------------------------------------------------------------------------------------------ found by the strategies
# Valid configs the package once mishandled (docs/testing.md, "Found by these strategies"), now named errors or fixed.


def test_found_a_subnormal_ranging_range_gives_a_clear_error():
    """ranging.max_range = 5e-324 passed the config and broke the ranging table build (IndexError)."""
    from finkensim.config import ConfigError
    from finkensim.swarm import SwarmSim

    with pytest.raises(ConfigError, match="ranging.max_range"):
        SwarmSim(Config().replace({"ranging.max_range": 5e-324}))


def test_found_an_overflowing_step_count_gives_a_clear_error():
    """duration / dt beyond the float range overflowed the memory estimate (OverflowError)."""
    from finkensim.budget import flight_arrays
    from finkensim.config import ConfigError

    with pytest.raises(ConfigError, match="simulation"):
        flight_arrays(Config().replace({"simulation.dt": 1e-308, "simulation.duration": 1e6}))


def test_found_imu_noise_that_reads_as_cm_is_refused_and_the_largest_allowed_passes_the_loader():
    """imu.acc_noise_density = 60 at dt = 0.125 s made simulate_flight refuse its own log (it read as cm/s^2): the
    config refuses it, and a flight at the largest per-sample noise it allows passes the loader."""
    from finkensim.config import MAX_ACC_SAMPLE_NOISE, ConfigError
    from finkensim.scenario import simulate_flight

    with pytest.raises(ConfigError, match="imu.acc_noise_density = 60"):
        Config().replace({"copters.n": 1, "imu.acc_noise_density": 60.0, "simulation.dt": 0.125})
    cfg = Config().replace({"copters.n": 1, "simulation.dt": 0.125,
                            "imu.acc_noise_density": MAX_ACC_SAMPLE_NOISE * 0.125 ** 0.5})
    log, _, _ = simulate_flight(cfg, duration=2.0, seed=0)
    assert_flightlog_valid(log)
