"""The geometric cross-talk cone as a parameter of the effect ``crosstalk_geometric`` (issue 37 item 4, issue 41
item 2): the fit recovers a drawn cone, the calibrated config flies it, and the effect keeps its contract."""
import math

import pytest

from finkensim.config import load_config
from finkensim.gap.attribute import effects as fx
from finkensim.gap.attribute import fits
from finkensim.gap.diagnosis import Diagnosis
from finkensim.gap.model.params import ModelParams
from finkensim.gap.validation.cases import Case, generate
from finkensim.testing import check_effect

EFFECT = fx.REGISTRY["crosstalk_geometric"]
SMALL = {"gap.draws": 8, "gap.max_samples_per_flight": 150, "gap.fit_max_readings": 3000, "gap.n_boot": 60,
         "gap.param_intervals": False}


def test_the_effect_keeps_its_contract_and_its_custom_fit():
    check_effect(EFFECT)
    check_effect(EFFECT, load_config().replace({"sonar.beam": "cone", "sonar.cone_half_angle_deg": 30.0}))
    assert EFFECT.fit is fits.fit_crosstalk_cone
    assert {p.name: (p.lo, p.hi) for p in EFFECT.params} == {"probability": (0.0, 1.0),
                                                            "cone_half_angle_deg": (5.0, 80.0)}


@pytest.mark.parametrize("cone", [48.0])
def test_the_fit_recovers_a_drawn_cone(cone):
    """A 'real' swarm whose sonars hear each other within a 48° cone (the configured model: 45°, no cross-talk):
    the fit finds the cone within 3° and full hearing (a p ≤ 1 at 45° cannot reach a wider cone)."""
    case = Case("cone", "crosstalk_geometric", lambda r: (
        {"sonar.crosstalk": "geometric", "sonar.schedule": "simultaneous", "sonar.cone_half_angle_deg": cone}, None,
        {"probability": 1.0, "cone_half_angle_deg": cone}), "ultrasonic")
    logs, cfg, _ = generate(case, 100, n_flights=2, duration=15.0)
    diag = Diagnosis(logs, ["a.npz", "b.npz"], cfg.replace(SMALL))
    got = diag.fit(EFFECT, diag.base).values
    assert abs(got["cone_half_angle_deg"] - cone) < 3.0, got
    assert got["probability"] > 0.9, got


@pytest.mark.parametrize("beam", ["ray", "cone"])
def test_calibrate_writes_the_cone_the_simulator_flies(beam):
    """The calibrated key is ``sonar.cone_half_angle_deg`` (the cone of the simulator's geometric cross-talk); a cone
    beam that followed it keeps the width it flew (``beam_width`` fits that one)."""
    cfg = load_config().replace({"sonar.crosstalk": "off", "sonar.beam": beam, "sonar.beam_rays": 5})
    values = {"probability": 0.8, "cone_half_angle_deg": 52.0}
    updates = EFFECT.calibrate(values, cfg)
    assert updates["sonar.cone_half_angle_deg"] == 52.0
    assert updates["sonar.crosstalk"] == "geometric"
    flown = cfg.replace(updates)
    assert flown.sonar.cone_half_angle_deg == 52.0
    model = ModelParams.from_config(flown)
    assert model.sonar.cos_half_angle == math.cos(math.radians(52.0))
    assert model.sonar.ray_angles.tolist() == ModelParams.from_config(cfg).sonar.ray_angles.tolist()
    want = EFFECT.apply(ModelParams.from_config(cfg), values)
    assert model.sensor_key("ultrasonic") == want.sensor_key("ultrasonic")
    # the configured cone kept: the key is written with the config's own value, nothing else moves
    kept = EFFECT.calibrate({"probability": 1.0, "cone_half_angle_deg": 45.0}, cfg)
    assert kept["sonar.cone_half_angle_deg"] == cfg.sonar.cone_half_angle_deg and "sonar.beam_half_angle_deg" not in kept
