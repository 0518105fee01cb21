"""The diagnosis and the simulator share one model: logs simulated with a config and diagnosed with that
same config show no significant gap, for every sensor model the config can select; and a config change the
simulator honours (a shifted ranging mixture) is one the diagnosis honours too."""
from __future__ import annotations

import json
from importlib import resources

import pytest

from finkensim.config import load_config
from finkensim.gap import diagnose
from finkensim.scenario import simulate_flight

SMALL = {"gap.draws": 12, "gap.max_samples_per_flight": 250, "gap.fit_max_readings": 4000, "gap.n_boot": 200,
         "copters.n": 5}


def _shifted_mixture(tmp_path, shift=0.3):
    """The default ranging mixture with every component's measured mean moved by ``shift`` m."""
    d = json.loads(resources.files("finkensim.data").joinpath("vranging_gmm_m.json").read_text())
    d["cond_mean"] = [m + shift for m in d["cond_mean"]]
    path = tmp_path / "shifted.json"
    path.write_text(json.dumps(d))
    return str(path)


def _logs(cfg, seed):
    return [simulate_flight(cfg, duration=20.0, seed=seed * 10 + i)[0] for i in range(2)]


CONFIGS = {
    "default": {},
    "gaussian_sonar_constant_crosstalk": {"sonar.error": "gaussian", "sonar.crosstalk": "constant",
                                          "ranging.error": "gaussian"},
    "seed_models_geometric_round_robin": {"sonar.error": "seed", "sonar.crosstalk": "geometric",
                                          "sonar.schedule": "round_robin", "ranging.error": "seed",
                                          "ranging.seed_variance_factor": 3.0},
    "cone_beam_rigid_walls": {"sonar.beam": "cone", "walls.bending": False},
    "geometric_random_offset": {"sonar.crosstalk": "geometric", "sonar.schedule": "random_offset"},
    "seed_profile": {"profile": "seed"},
    "shifted_mixture_file": "mixture",
}


@pytest.mark.parametrize("name", list(CONFIGS))
def test_logs_diagnosed_with_their_own_config_show_no_gap(name, tmp_path):
    updates = CONFIGS[name]
    if updates == "mixture":
        updates = {"ranging.mixture_file": _shifted_mixture(tmp_path)}
    cfg = load_config().replace({**SMALL, **updates})
    rep = diagnose(_logs(cfg, 3), ["a.npz", "b.npz"], cfg, effect_names=[])
    assert rep.effects == []
    assert rep["verdict"]["significant_gap"] is False, rep.details.per_sensor


def test_a_shifted_mixture_diagnosed_with_the_default_one_is_a_ranging_gap(tmp_path):
    cfg = load_config().replace({**SMALL, "ranging.mixture_file": _shifted_mixture(tmp_path)})
    rep = diagnose(_logs(cfg, 3), ["a.npz", "b.npz"], load_config().replace(SMALL), effect_names=[])
    assert rep["verdict"]["significant_gap"] is True
    assert rep.details.gap_sensors == ["ranging"]
    # each interval is of its own estimate: gap_before averages the sensors with a gap (here the ranging only),
    # calibration_gap every sensor
    lo, hi = rep.details.gap_before_ci
    assert lo <= rep.gap_before <= hi and rep.details.gap_before_p < 0.05
    lo, hi = rep.details.calibration_ci
    assert lo <= rep.details.calibration_gap <= hi and rep.details.calibration_gap < rep.gap_before


@pytest.mark.parametrize("content", [None, "{not json"])
def test_a_bad_mixture_file_is_a_one_line_config_error_in_run_and_gap(tmp_path, capsys, content):
    from finkensim import flightlog
    from finkensim.cli import main

    mix = tmp_path / "mix.json"
    if content is not None:
        mix.write_text(content)
    conf = tmp_path / "c.toml"
    conf.write_text(f'[ranging]\nmixture_file = "{mix}"\n')
    assert main(["run", str(conf), "--out", str(tmp_path / "run"), "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert "ranging.mixture_file = " in err and "Traceback" not in err
    log = simulate_flight(load_config().replace({"copters.n": 3}), duration=3.0, seed=1)[0]
    flightlog.save(log, tmp_path / "a.npz")
    assert main(["gap", str(tmp_path / "a.npz"), "--config", str(conf), "--out", str(tmp_path / "gap")]) == 2
    assert f"ranging.mixture_file = '{mix}'" in capsys.readouterr().err
