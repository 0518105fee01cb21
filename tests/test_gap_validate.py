"""Withheld-effect checks of the gap diagnosis, CI-sized (2 flights × 30 s, 6 copters).

For every catalogued effect: flights simulated with the effect at a random strength are
diagnosed with a model that lacks it; the effect must be named first and remove at least 60 %
of the held-out gap. Effects outside the catalogue must come out ``unexplained``. The full
matrix with more trials is ``finkensim gap-validate`` (README, "Sim-to-real gap").
"""
from __future__ import annotations

import pytest

from finkensim.gap import Diagnosis, run_diagnosis
from finkensim.gap.effects import REGISTRY
from finkensim.gap.validate import CASES, generate

SMALL = {"gap.draws": 12, "gap.max_samples_per_flight": 300, "gap.fit_max_readings": 5000, "gap.n_boot": 200}
SEED = 3


def _diagnose(case):
    logs, cfg, truth = generate(CASES[case], SEED, n_flights=2, duration=30.0)
    rep = run_diagnosis(Diagnosis(logs, ["a.npz", "b.npz"], cfg.replace(SMALL)))
    return rep, truth


def test_every_catalogued_effect_has_a_validation_case():
    assert set(REGISTRY) <= {c.effect for c in CASES.values()}


@pytest.mark.parametrize("case", [c.name for c in CASES.values() if c.effect is not None])
def test_withheld_effect_is_named_first_and_shrinks_the_gap(case):
    rep, truth = _diagnose(case)
    v = rep["verdict"]
    assert v["significant_gap"], f"{case}: no significant gap found (gap {rep['gap_before']:.4f})"
    assert v["effect"] == CASES[case].effect, f"{case}: named {v['effect']}; ranking {[e['name'] for e in rep['effects']]}"
    assert v["shrink_heldout"] >= 0.6, f"{case}: held-out shrink {v['shrink_heldout']:.2f}"


@pytest.mark.parametrize("case", ["foreign", "foreign_multipath"])
def test_foreign_effect_is_unexplained(case):
    rep, _ = _diagnose(case)
    assert rep["verdict"]["significant_gap"] and rep["verdict"]["unexplained"], rep["verdict"]
    assert rep["verdict"]["effect"] is None
    assert rep["locations"][0]["sensor"] == CASES[case].sensor  # the gap is still located
