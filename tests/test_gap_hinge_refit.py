"""The ``wall_bulge`` effect's hinge version (``finkensim/gap/attribute/hinge.py``): the replay drives the
simulator's own hinge walls at fitted keys (``Flight.hinged``, ``ModelParams.walls_hinge``), the refit recovers a
hinge's maximum amplitude from a short flight, and ``calibrate`` flies a kept refit as hinge walls."""
from __future__ import annotations

import numpy as np
import pytest

from finkensim.arena import Arena
from finkensim.config import load_config
from finkensim.gap import Diagnosis
from finkensim.gap.attribute.effects import REGISTRY
from finkensim.gap.attribute.hinge import fit_hinge, hinge_version
from finkensim.gap.model.params import ModelParams
from finkensim.gap.validation.cases import CASES, generate
from finkensim.world import walls_from_positions

SMALL = {"gap.draws": 12, "gap.max_samples_per_flight": 300, "gap.fit_max_readings": 5000, "gap.n_boot": 200}


@pytest.fixture(scope="module")
def bulge_case():
    """Two 15 s "real" flights of the wall_bulge case (hinge walls, a drawn max amplitude) and their diagnosis
    under the rigid configured walls."""
    logs, cfg, truth = generate(CASES["wall_bulge"], 3, n_flights=2, duration=15.0)
    return Diagnosis(logs, ["a.npz", "b.npz"], cfg.replace(SMALL)), truth


def test_hinged_walls_are_the_simulators_hinge_driven_by_the_logged_copters(bulge_case):
    diag, _ = bulge_case
    fl = diag.flights[0]
    assert fl.hinged(())[0] is fl.theta_unit and fl.hinged(fl.hinge)[0] is fl.theta_unit
    key = (33.0, 0.8, 1.3)
    theta, walls = fl.hinged(key)
    # the reference: the walls of a config with those keys, replayed as prepare_flights replays the configured ones
    cfg = diag.cfg.replace({"walls.bending": True, "walls.max_amplitude_deg": 33.0, "walls.threshold": 0.8,
                            "walls.hinge_height": 1.3, "arena.altitude": fl.arena.altitude,
                            "arena.width": fl.arena.width, "arena.length": fl.arena.length})
    arena = Arena.from_config(cfg.arena, cfg.walls)
    want = np.empty_like(theta)
    dist = np.empty_like(theta)
    walls_from_positions(fl.pos, fl.t, arena.seg_a, arena.seg_b, fl.radius, arena.hinge, arena.lever, want, dist)
    np.testing.assert_array_equal(theta, want)
    assert walls.lever == pytest.approx(1.3 - fl.arena.altitude)
    assert theta.max() > 0.1  # the plates do move
    assert fl.hinged(key)[0] is theta  # kept for the next evaluation


@pytest.mark.parametrize("bending", [True, False])
def test_a_kept_hinge_refit_calibrates_to_hinge_walls(bending):
    cfg = load_config().replace({"walls.bending": bending, "walls.model": "hinge+bulge" if bending else "hinge",
                                 "walls.bulge_amplitude": 0.1 if bending else 0.0})
    v = {"max_amplitude_deg": 36.5, "threshold": 0.9, "hinge_height": 1.2}
    wb = REGISTRY["wall_bulge"]
    upd = wb.calibrate(v, cfg)
    assert upd == {"walls.bending": True, "walls.model": "hinge", "walls.max_amplitude_deg": 36.5,
                   "walls.threshold": 0.9, "walls.hinge_height": 1.2}
    got = ModelParams.from_config(cfg.replace(upd))
    want = wb.apply(ModelParams.from_config(cfg), v)
    assert got.sensor_key("ultrasonic") == want.sensor_key("ultrasonic")
    assert (want.wall_gain, want.bulge_amplitude, want.walls_hinge) == (1.0, 0.0, (36.5, 0.9, 1.2))
    assert hinge_version("wall_bulge").calibrate(v, cfg) == upd and hinge_version("sonar_bias") is None


def test_the_hinge_refit_recovers_the_max_amplitude(bulge_case):
    """From a rough bulge (not the truth) the hinge version's fit finds the drawn maximum amplitude."""
    diag, truth = bulge_case
    hv = hinge_version("wall_bulge")
    assert [q.name for q in hv.free(diag)] == ["max_amplitude_deg", "threshold"]  # the hinge height set by a rule
    vals = fit_hinge(diag, hv, diag.base, {"amplitude": 0.2, "reach": 1.0, "response": 0.5, "shape": 4.0})
    assert vals["max_amplitude_deg"] == pytest.approx(truth["_max_amplitude_deg"], abs=3.0)
    # the fitted walls score better on the training readings than the configured rigid ones
    wb, sensors = REGISTRY["wall_bulge"], ["ultrasonic"]
    assert diag.objective(hv, diag.base, sensors, vals) < diag.objective(wb, diag.base, sensors, wb.start(diag.base))


def test_a_hinge_refit_gets_intervals_for_the_keys_it_flies(bulge_case):
    """The calibration's distributions (``quantify/intervals.py``) profile the parameters the selected values
    belong to: the hinge keys of a bulge refitted as hinge walls (the catalogue's bulge parameters are not among its
    values), each interval around its fit and inside its range; the flexible bulge's ``hinge`` weight profiled with
    the flexible version's ``apply`` (the catalogue's ignores it)."""
    from finkensim.gap.attribute.hinge import effect_of
    from finkensim.gap.attribute.parsimony import flexible_version
    from finkensim.gap.quantify.intervals import parameter_intervals

    diag, truth = bulge_case
    hv = hinge_version("wall_bulge")
    vals = fit_hinge(diag, hv, diag.base, {"amplitude": 0.2, "reach": 1.0, "response": 0.5, "shape": 4.0})
    assert effect_of("wall_bulge", vals).params == hv.params
    flex_vals = {"amplitude": 0.05, "reach": 0.5, "response": 0.3, "shape": 2.0, "hinge": 0.5}
    assert effect_of("wall_bulge", flex_vals).params == flexible_version("wall_bulge").params
    assert effect_of("wall_bulge", {"amplitude": 0.05}) is REGISTRY["wall_bulge"]
    assert effect_of("sonar_bias", {"bias": 0.1}) is REGISTRY["sonar_bias"]

    iv = parameter_intervals(diag, {"wall_bulge": vals})["wall_bulge"]
    assert set(iv) == {"max_amplitude_deg", "threshold"}  # the hinge height is set by a rule, not fitted
    for q in hv.params[:2]:
        d = iv[q.name]
        assert q.lo <= d["lo"] <= d["hi"] <= q.hi and d["unit"] == q.unit
        assert d["value"] == vals[q.name] and sum(d["probabilities"]) == pytest.approx(1.0)
    # the maximum amplitude is informed: its interval is a small part of its range and holds the drawn one
    amp = iv["max_amplitude_deg"]
    assert amp["hi"] - amp["lo"] < 0.25 * 80.0
    assert amp["lo"] - 3.0 <= truth["_max_amplitude_deg"] <= amp["hi"] + 3.0
    flex = parameter_intervals(diag, {"wall_bulge": flex_vals})["wall_bulge"]
    assert "hinge" in flex and 0.0 <= flex["hinge"]["lo"] <= flex["hinge"]["hi"] <= 1.0
