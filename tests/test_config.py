"""Configuration: defaults, TOML round trip, every kind of error, the seed profile, Config.replace."""
from __future__ import annotations

import copy
import dataclasses
import json
import math
import pickle

import pytest

from finkensim.config import (
    PROFILES,
    SECTIONS,
    ArenaConfig,
    Config,
    ConfigError,
    WallConfig,
    config_from_dict,
    describe,
    load_config,
)


def to_toml(data: dict) -> str:
    """A minimal TOML writer for Config.to_dict() output (top-level keys, then one table per section)."""

    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, int):
            return str(v)
        if isinstance(v, float):
            assert math.isfinite(v)
            return repr(v)  # '0.3', '9e-05', '1e+20': all valid TOML floats
        if isinstance(v, str):
            return json.dumps(v)  # a TOML basic string
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        raise TypeError(type(v))

    lines = [f"{k} = {value(v)}" for k, v in data.items() if not isinstance(v, dict)]
    for name, table in data.items():
        if isinstance(table, dict):
            lines.append(f"\n[{name}]")
            lines += [f"{k} = {value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- defaults and round trip

def test_defaults_load():
    for cfg in (Config(), load_config(), load_config({}), config_from_dict({})):
        assert cfg == Config()
        assert cfg.profile == "default"
    c = Config()
    assert (c.arena.width, c.arena.length, c.arena.altitude) == (3.0, 4.0, 0.6)
    assert c.walls.threshold == 1.0 and c.walls.max_amplitude_deg == 30.0 and c.walls.joint_force == 15.0
    assert (c.walls.pid_p, c.walls.pid_i, c.walls.pid_d) == (1.0, 2.0, 1.0)
    assert c.walls.plate_mass == 0.3
    assert set(c.to_dict()) == {"profile", *SECTIONS}


CONFIGS = [
    Config(),
    Config("seed"),
    Config().replace({"walls.n_segments": 20, "copters.n": 3, "sonar.yaw_deg": [10.0, 100.0, 190.0, -80.0],
                      "ranging.beacons": [[0.5, 0.5], [2.5, 3.5]], "imu.acc_noise_density": 1e-5,
                      "behaviour.kind": "hover", "walls.bending": False, "simulation.seed": 2**62}),
]


@pytest.mark.parametrize("cfg", CONFIGS, ids=["default", "seed", "custom"])
def test_toml_round_trip(cfg, tmp_path):
    text = to_toml(cfg.to_dict())
    path = tmp_path / "scenario.toml"
    path.write_text(text)
    assert load_config(path) == cfg
    assert load_config(str(path)) == cfg
    assert load_config(text) == cfg  # a multi-line TOML string
    assert config_from_dict(cfg.to_dict()) == cfg
    assert load_config(path).to_dict() == cfg.to_dict()


def test_partial_toml_takes_defaults(tmp_path):
    path = tmp_path / "partial.toml"
    path.write_text("[walls]\nn_segments = 18\n\n[copters]\nn = 10\n")
    cfg = load_config(path)
    assert cfg.walls.n_segments == 18 and cfg.copters.n == 10
    assert cfg.walls.threshold == Config().walls.threshold
    assert cfg == Config().replace({"walls.n_segments": 18, "copters.n": 10})


def test_ints_are_accepted_for_floats_and_stored_as_float():
    cfg = load_config({"arena": {"width": 5}})
    assert cfg.arena.width == 5.0 and isinstance(cfg.arena.width, float)


# --------------------------------------------------------------------------- errors

@pytest.mark.parametrize("data, pattern", [
    # unknown key, with a suggestion and the allowed keys
    ({"walls": {"n_segmnts": 3}}, r"unknown key walls\.n_segmnts \(did you mean walls\.n_segments\?\).*allowed:"),
    # unknown section
    ({"wall": {"n_segments": 3}}, r"unknown section \[wall\].*did you mean 'walls'"),
    # wrong types
    ({"walls": {"threshold": "1.0"}}, r"walls\.threshold = '1\.0': expected a number, got str"),
    ({"walls": {"n_segments": 3.0}}, r"walls\.n_segments = 3\.0: expected an integer, got float"),
    ({"walls": {"bending": 1}}, r"walls\.bending = 1: expected true or false, got int"),
    ({"walls": {"threshold": True}}, r"walls\.threshold = True: expected a number"),
    ({"sonar": {"error": 3}}, r"sonar\.error = 3: expected a string"),
    ({"sonar": {"yaw_deg": 5.0}}, r"sonar\.yaw_deg = 5\.0: expected a list"),
    ({"walls": "x"}, r"\[walls\] = 'x': expected a table"),
    # out of range (value and the allowed range named)
    ({"walls": {"threshold": -1.0}}, r"walls\.threshold = -1\.0: expected > 0\.0 and <= 10\.0 m"),
    ({"walls": {"threshold": 0.0}}, r"walls\.threshold = 0\.0: expected > 0\.0"),
    ({"copters": {"n": 0}}, r"copters\.n = 0: expected >= 1"),
    ({"simulation": {"dt": float("nan")}}, r"simulation\.dt = nan: expected a finite number"),
    ({"sonar": {"yaw_deg": [0.0, 90.0, 180.0]}}, r"sonar\.yaw_deg = .*: expected a list of 4 numbers, got 3"),
    ({"sonar": {"yaw_deg": [0.0, 90.0, 180.0, 720.0]}}, r"sonar\.yaw_deg\[3\] = 720\.0: expected >= -360\.0"),
    ({"ranging": {"beacons": [[1.0, 2.0, 3.0]]}}, r"ranging\.beacons\[0\] = \[1\.0, 2\.0, 3\.0\]: expected a point"),
    # cross-field check
    ({"walls": {"plate_length": 2.0}}, r"walls\.plate_length = 2\.0: expected <= walls\.hinge_height"),
    # bad choice, with a suggestion
    ({"sonar": {"error": "rayleig"}}, r"sonar\.error = 'rayleig': expected one of .*\(did you mean 'rayleigh'\?\)"),
    ({"behaviour": {"kind": "randomwalk"}}, r"behaviour\.kind = 'randomwalk'.*did you mean 'random_walk'"),
    # bad profile
    ({"profile": "sed"}, r"profile = 'sed': expected one of 'default', 'seed'.*did you mean 'seed'"),
    ({"profile": 1}, r"profile = 1: expected a string"),
])
def test_config_errors(data, pattern):
    with pytest.raises(ConfigError, match=pattern):
        load_config(data)


def test_errors_from_python_constructors():
    with pytest.raises(ConfigError, match=r"arena\.width = 0\.1: expected >= 0\.5"):
        ArenaConfig(width=0.1)
    with pytest.raises(ConfigError, match=r"walls\.n_segments = 2\.5: expected an integer"):
        WallConfig(n_segments=2.5)
    with pytest.raises(ConfigError, match=r"profile = 'sedd'.*did you mean 'seed'"):
        Config("sedd")
    with pytest.raises(ConfigError, match=r"unknown config sections: walz"):
        Config(walz=WallConfig())


def test_invalid_toml_text():
    with pytest.raises(ConfigError, match=r"invalid TOML"):
        load_config("[walls\nn_segments = 3\n")
    with pytest.raises(ConfigError, match=r"invalid TOML"):
        load_config("[walls]\nn_segments = \n")


def test_invalid_toml_file_names_the_file(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[walls]\nn_segments = = 3\n")
    with pytest.raises(ConfigError, match=r"invalid TOML in .*broken\.toml"):
        load_config(path)


def test_missing_file(tmp_path):
    with pytest.raises(ConfigError, match=r"config file '.*nope\.toml' does not exist"):
        load_config(tmp_path / "nope.toml")


def test_config_error_is_a_value_error():
    assert issubclass(ConfigError, ValueError)


def test_one_line_toml_string():
    assert load_config('profile = "seed"') == Config("seed")


# --------------------------------------------------------------------------- profiles

def test_seed_profile_overrides():
    for cfg in (Config("seed"), load_config({"profile": "seed"}), load_config('profile = "seed"\n')):
        assert cfg.profile == "seed"
        assert cfg.walls.plate_mass == 40.0
        assert cfg.sonar.error == "seed"
        assert cfg.sonar.crosstalk == "constant"
        assert cfg.ranging.error == "seed"
        # everything the profile does not mention keeps its default
        assert cfg.walls.threshold == Config().walls.threshold
        assert cfg.arena == Config().arena
    for section, overrides in PROFILES["seed"].items():
        for key, v in overrides.items():
            assert getattr(getattr(Config("seed"), section), key) == v


def test_explicit_keys_override_the_profile():
    cfg = load_config({"profile": "seed", "walls": {"plate_mass": 2.0}, "sonar": {"error": "none"}})
    assert cfg.walls.plate_mass == 2.0 and cfg.sonar.error == "none"
    assert cfg.ranging.error == "seed"  # untouched profile values stay
    assert cfg.sonar.crosstalk == "constant"  # same section, other profile key stays
    assert load_config('profile = "seed"\n[walls]\nplate_mass = 1.5\n').walls.plate_mass == 1.5


# --------------------------------------------------------------------------- replace, immutability

def test_replace():
    base = Config()
    new = base.replace({"walls.bending": False, "copters.n": 10})
    assert new.walls.bending is False and new.copters.n == 10
    assert base.walls.bending is True and base.copters.n == 6  # the original is untouched
    assert new.walls.n_segments == base.walls.n_segments
    assert base.replace({}) == base
    seed = Config("seed").replace({"copters.n": 3})
    assert seed.profile == "seed" and seed.walls.plate_mass == 40.0 and seed.copters.n == 3
    with pytest.raises(ConfigError, match=r"unknown key walls\.benidng \(did you mean walls\.bending\?\)"):
        base.replace({"walls.benidng": False})
    with pytest.raises(ConfigError, match=r"unknown section \[wals\]"):
        base.replace({"wals.bending": False})
    with pytest.raises(ConfigError, match=r"'walls': expected a dotted key"):
        base.replace({"walls": False})
    with pytest.raises(ConfigError, match=r"copters\.n = -1: expected >= 1"):
        base.replace({"copters.n": -1})


def test_replace_profile_applies_the_profile():
    cfg = Config().replace({"profile": "seed"})
    assert cfg.walls.plate_mass == 40.0
    assert cfg == Config("seed")


def test_frozen():
    cfg = Config()
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.walls = WallConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.walls.n_segments = 3
    assert hash(cfg) == hash(Config())


@pytest.mark.parametrize("cfg", CONFIGS, ids=["default", "seed", "custom"])
def test_pickle_and_copy_round_trip(cfg):
    # process pools and Dask ship configs by pickle; a frozen config must survive it unchanged
    for clone in (pickle.loads(pickle.dumps(cfg)), copy.deepcopy(cfg), copy.copy(cfg)):
        assert clone == cfg and clone.profile == cfg.profile and clone.to_dict() == cfg.to_dict()


def test_describe_rows():
    rows = describe(WallConfig)
    names = [r[0] for r in rows]
    assert names == [f.name for f in dataclasses.fields(WallConfig)]
    threshold = rows[names.index("threshold")]
    assert threshold[1] == 1.0 and threshold[2] == "m" and threshold[3] == "> 0.0 and <= 10.0 m"
