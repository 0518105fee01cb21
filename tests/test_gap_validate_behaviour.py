"""The behaviour-level check of the calibration (finkensim.gap.validation.behaviour): the three configs are built
right, and the judgement is correct on constructed statistics. No diagnosis runs here (the full check does)."""
import numpy as np
import pytest

from finkensim.gap.attribute.effects import REGISTRY
from finkensim.gap.validation import behaviour as bh
from finkensim.gap.validation.cases import CASES, base_config


def _flat(cfg):
    return {f"{s}.{k}": v for s, d in cfg.to_dict().items() if isinstance(d, dict) for k, v in d.items()}


def _diff(a, b):
    fa, fb = _flat(a), _flat(b)
    return {k for k in fa if fa[k] != fb.get(k)}


def _configs(name, seed=100):
    """The three configs of ``name`` with a calibration that fits the truth exactly (the effect's mapping of the
    true parameters on the diagnosed config)."""
    _, _, truth = CASES[name].make(np.random.default_rng(seed))
    if name == "latency":
        truth[truth["_sensor"]] = 0.2
    diagnosed = base_config({"copters.n": 6, "sonar.error": "rayleigh"})
    effect = REGISTRY[CASES[name].effect]
    calibrated = diagnosed.replace(effect.calibrate(bh.true_params(name, truth), diagnosed))
    return bh.behaviour_configs(name, seed, truth, diagnosed, calibrated), effect, truth


@pytest.mark.parametrize("name", ["wall_bulge", "sonar_bias", "crosstalk_constant", "imu_bias", "ranging_nlos"])
def test_truth_differs_from_base_by_the_case_keys(name):
    cfgs, effect, truth = _configs(name)
    updates, post, _ = CASES[name].make(np.random.default_rng(100))
    keys = set(updates) - set(bh.FLIGHT_KEYS)
    if post is not None:  # a post-processing case: the effect's own mapping of its true parameters
        keys |= set(effect.calibrate(bh.true_params(name, truth), base_config()))
    assert _diff(cfgs["truth"], cfgs["base"]) == keys
    for cfg in cfgs.values():
        assert cfg.behaviour.kind == "attraction_repulsion"
        assert cfg.copters.n == cfgs["truth"].copters.n  # the flight's keys: the truth's (ranging_nlos flies 8)
    # the calibrated config holds the effect's keys
    assert _diff(cfgs["calibrated"], cfgs["base"]) <= set(effect.calibrate(bh.true_params(name, truth),
                                                                             base_config()))
    assert _diff(cfgs["calibrated"], cfgs["base"])


def test_latency_truth_is_the_applied_delay():
    cfgs, _, truth = _configs("latency")
    key = {"ultrasonic": "sonar.latency", "ranging": "ranging.latency", "imu": "imu.latency"}[truth["_sensor"]]
    assert _flat(cfgs["truth"])[key] == 0.2
    assert _diff(cfgs["truth"], cfgs["base"]) == {key}


def test_null_truth_is_base_and_foreign_is_not_flown():
    cfgs = bh.behaviour_configs("null", 100, {}, base_config({"sonar.error": "rayleigh"}),
                                base_config({"sonar.error": "rayleigh"}))
    assert not _diff(cfgs["truth"], cfgs["base"])
    with pytest.raises(ValueError):
        bh.truth_config("foreign", 100, {})


def _stats(truth, base, cal, values=None):
    """Statistics of one metric (wall_sticking) as (mean, lo, hi) per model; the other metrics all equal."""
    out = {}
    for name, (m, lo, hi) in zip(bh.MODELS, (truth, base, cal)):
        s = {}
        for metric in bh.METRICS:
            mm, ll, hh = (m, lo, hi) if metric == "wall_sticking" else (1.0, 0.9, 1.1)
            s.update({f"{metric}_mean": mm, f"{metric}_ci_low": ll, f"{metric}_ci_high": hh})
        if values is not None:
            s["values"] = {metric: values[name] for metric in bh.METRICS}
        out[name] = s
    return out


def test_judgement():
    met = bh.judge(_stats((0.15, 0.13, 0.17), (0.05, 0.03, 0.06), (0.14, 0.12, 0.16)))
    assert met["verdict"] == "met" and met["metrics"]["wall_sticking"]["verdict"] == "met"
    assert met["metrics"]["cohesion"]["verdict"] == "unchanged"
    miss = bh.judge(_stats((0.15, 0.13, 0.17), (0.05, 0.03, 0.06), (0.08, 0.06, 0.10)))
    assert miss["verdict"] == "not met" and miss["metrics"]["wall_sticking"]["verdict"] == "not met"
    same = bh.judge(_stats((0.15, 0.13, 0.17), (0.15, 0.13, 0.17), (0.15, 0.13, 0.17),
                           values={"truth": [0.1, 0.2], "base": [0.1, 0.2], "calibrated": [0.1, 0.2]}))
    assert same["verdict"] == "does not change this behaviour"
    assert same["metrics"]["wall_sticking"]["identical"]
    off = bh.judge(_stats((0.15, 0.13, 0.17), (0.15, 0.13, 0.17), (0.30, 0.28, 0.32)))
    assert off["verdict"] == "not met" and off["metrics"]["wall_sticking"]["verdict"] == "calibration off"
    table = bh.behaviour_table([{"case": "x", "effects": ["sonar_bias"], "unexplained": False,
                                 "stats": _stats((0.15, 0.13, 0.17), (0.05, 0.03, 0.06), (0.14, 0.12, 0.16)),
                                 "judgement": met}])
    assert "| x | sonar_bias | truth | 0.150 [0.130, 0.170]" in table and "met (✓ = =)" in table


def test_sweeps_small():
    cfgs, _, _ = _configs("sonar_bias")
    stats = bh.behaviour_sweeps(cfgs, replicates=3, duration=2.0)
    assert set(stats) == set(bh.MODELS)
    for s in stats.values():
        assert s["n_ok"] == 3 and len(s["values"]["cohesion"]) == 3
        assert s["cohesion_ci_low"] <= s["cohesion_mean"] <= s["cohesion_ci_high"]
    assert bh.judge(stats)["verdict"] in ("met", "not met", "does not change this behaviour")
