"""The targeted test of a gap (:func:`finkensim.gap.attribute.targeted.targeted_test`): when the omnibus calibration test finds
nothing, a structured effect whose fit improves the held-out score significantly still reveals a gap; catch-alls
never do, and the threshold is Bonferroni over the structured candidates.

The unit tests use a stand-in for the diagnosis' block bootstrap (independent rows, normal approximation); the
end-to-end test diagnoses a ranging lag that the omnibus test misses.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from finkensim.gap import Diagnosis, run_diagnosis
from finkensim.gap.attribute import targeted as S
from finkensim.gap.diagnosis import FitResult
from finkensim.gap.report.markdown import markdown
from finkensim.gap.validation.cases import Case, _post_latency, generate
from finkensim.config import load_config

N = 4000
LAG, LAG_SEED = 0.16, 0  # a ranging lag of 0.16 s in two 30 s flights: the omnibus test misses it


class _IidDiag:
    """``overall`` as the mean over sensors of the per-row means, with a one-sided normal-approximation p-value."""

    def overall(self, values, rows):
        means = [np.mean(v) for v in values.values()]
        var = sum(np.var(v, ddof=1) / len(v) for v in values.values()) / len(values) ** 2
        m = float(np.mean(means))
        se = math.sqrt(var)
        p = 0.5 * math.erfc(m / se / math.sqrt(2)) if se > 0 else math.nan  # no variation: unknown power
        return m, (m - 1.96 * se, m + 1.96 * se), p


def _fit(name, base, shift, rng):
    """A FitResult whose held-out rows score ``shift`` lower than ``base`` on the effect's own sensors."""
    rows = {s: base[s] - (shift + 0.01 * rng.standard_normal(N) if s in S.fx.REGISTRY[name].sensors else 0.0)
            for s in base}
    return FitResult(name, {}, None, math.nan, rows_score=rows)


@pytest.fixture
def setting():
    rng = np.random.default_rng(7)
    base = {s: 1.0 + 0.1 * rng.standard_normal(N) for s in ("ultrasonic", "ranging", "imu")}
    return rng, base, {s: np.arange(N) for s in base}, load_config().gap


def test_a_clear_structured_improvement_reveals_a_gap_on_its_sensors(setting):
    rng, base, rows, cfg = setting
    first = [_fit("ranging_nlos", base, 0.005, rng), _fit("sound_speed", base, 0.0, rng),
             _fit("imu_bias", base, -0.002, rng)]
    t = S.targeted_test(_IidDiag(), first, base, rows, cfg)
    assert t is not None and t["effect"] == "ranging_nlos" and t["sensors"] == ["ranging"], t
    assert t["passed"] == ["ranging_nlos"]
    assert t["threshold"] == pytest.approx(cfg.alpha / 3)
    assert t["improvement"] == pytest.approx(0.005, abs=5e-4) and t["p"] < 1e-6


def test_the_gap_lies_on_the_sensors_the_effect_improves_by_themselves(setting):
    rng, base, rows, cfg = setting
    lag = FitResult("latency", {}, None, math.nan, rows_score={
        **base, "ranging": base["ranging"] - (0.02 + 0.01 * rng.standard_normal(N))})  # a lag on the radio only
    t = S.targeted_test(_IidDiag(), [lag], base, rows, cfg)
    assert t is not None and t["sensors"] == ["ranging"], t
    both = _fit("latency", base, 0.02, rng)  # improves every sensor it acts on
    assert S.targeted_test(_IidDiag(), [both], base, rows, cfg)["sensors"] == ["ultrasonic", "ranging", "imu"]


def test_catch_alls_never_reveal_a_gap(setting):
    rng, base, rows, cfg = setting
    # a noise scale, a constant bias and pose noise absorb recording conventions: even a large improvement is not a gap
    first = [_fit(n, base, 0.05, rng) for n in ("sonar_rayleigh_scale", "sonar_bias", "pose_noise", "crosstalk_constant")]
    first.append(_fit("latency", base, 0.0, rng))
    assert S.targeted_test(_IidDiag(), first, base, rows, cfg) is None
    assert S.targeted_test(_IidDiag(), first[:4], base, rows, cfg) is None  # no structured candidate at all


def test_an_improvement_below_the_practical_bar_or_the_bonferroni_threshold_is_no_gap(setting):
    rng, base, rows, cfg = setting
    small = _fit("ranging_dropout", base, 0.5 * cfg.accept_improvement, rng)  # significant, but too small to matter
    assert S.targeted_test(_IidDiag(), [small], base, rows, cfg) is None
    # p = 0.023 (mean 2 standard errors above 0): significant alone, not among eight structured candidates
    zero = {s: np.zeros(N) for s in base}
    z = rng.standard_normal(N)
    z = (z - z.mean()) / z.std(ddof=1)
    m = 2 * cfg.accept_improvement
    middling = FitResult("ranging_nlos", {}, None, math.nan,
                         rows_score={**zero, "ranging": -(m + 0.5 * m * math.sqrt(N) * z)})
    alone = S.targeted_test(_IidDiag(), [middling], zero, rows, cfg)
    assert alone is not None and alone["p"] == pytest.approx(0.0228, abs=1e-4)
    others = [FitResult(n, {}, None, math.nan, rows_score=dict(zero))
              for n in ("wall_bulge", "crosstalk_geometric", "beam_width", "sound_speed", "latency", "ranging_dropout",
                        "imu_bias")]
    assert S.targeted_test(_IidDiag(), [middling] + others, zero, rows, cfg) is None


SMALL = {"gap.draws": 12, "gap.max_samples_per_flight": 300, "gap.fit_max_readings": 5000, "gap.n_boot": 200}


def test_a_ranging_lag_the_omnibus_test_misses_is_found_and_named_latency():
    lag = Case("ranging_lag", "latency", lambda r: ({}, _post_latency("ranging", LAG, t := {}), t), "ranging")
    logs, cfg, _ = generate(lag, LAG_SEED, n_flights=2, duration=30.0)
    rep = run_diagnosis(Diagnosis(logs, ["a.npz", "b.npz"], cfg.replace(SMALL)))
    d = rep.details
    assert not any(v["significant"] for v in d.per_sensor.values()), f"the omnibus test found it: {d.per_sensor}"
    assert d.targeted is not None and d.targeted["effect"] == "latency", d.targeted
    v = rep["verdict"]
    assert v["significant_gap"] and not v["unexplained"] and v["effect"] == "latency", v
    assert d.gap_sensors == d.targeted["sensors"]
    assert "targeted test" in markdown(rep, {})


def test_the_halves_of_a_single_flight_get_no_targeted_test():
    """They share the flight's slow random state (the IMU bias walk): fitting on one half and improving the other is
    no evidence of a mismatch, so only the omnibus test decides."""
    lag = Case("ranging_lag", "latency", lambda r: ({}, _post_latency("ranging", LAG, t := {}), t), "ranging")
    logs, cfg, _ = generate(lag, LAG_SEED, n_flights=1, duration=30.0)
    rep = run_diagnosis(Diagnosis(logs, ["a.npz"], cfg.replace(SMALL)))
    assert rep.details.targeted is None
    assert rep["verdict"]["significant_gap"] == any(v["significant"] for v in rep.details.per_sensor.values())
