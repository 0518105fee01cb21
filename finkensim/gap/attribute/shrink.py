"""How much of a held-out gap a model explains, in a way that a wider predictive cannot fake.

Two numbers describe a model F on the held-out readings of the sensors with a significant gap (each a
mean over those sensors of the per-reading mean, normalised as in :mod:`~finkensim.gap.diagnosis`):

- its **calibration gap** c(F) = E|X − y| − E|X − X'| (zero on average when the readings could have come
  from F), and
- its **proper score** S(F), the threshold-weighted CRPS.

A model that only widens its predictive distribution can bring c(F) to zero (or below) without being
right; it cannot lower S(F) below that of a predictive closer to reality (propriety). So

    shrink(F) = min( 1 − |c(F)| / c(F₀),  (S(F₀) − S(F)) / (S(F₀) − S_min) )     if S(F) ≤ S(F₀)
    shrink(F) = min( 1 − |c(F)| / c(F₀),  −(S(F) − S(F₀)) / c(F₀) )             if S(F) > S(F₀)

where F₀ is the configured model and S_min the best score of every predictive the diagnosis built from
the catalogue (each effect, refit and combination; for the data-driven correction of :mod:`~finkensim.gap.quantify.correction`,
also the correction itself). The score term of a model that scores *worse* than F₀ is its score penalty in
units of the gap (a predictive that moves by δ scores worse by about as much as its gap grows, so the penalty
reads as gap added): a ratio to S(F₀) − S_min would divide by ≈ 0 whenever nothing beats the configured model
(a correction fitted to noise once reported a shrink of −1.8·10⁵ that way). The two branches meet at 0 when
S(F) = S(F₀). Both terms are
at most 1, so the shrink cannot exceed 1; an over-dispersed fit loses on the first term (|c| grows as c
turns negative) and, whenever anything describes the data better, on the second. The reported
``gap_after`` = c(F₀) · (1 − shrink(F)), so that ``shrink = 1 − gap_after / gap_before`` as the spec says.
"""
from __future__ import annotations

import numpy as np

__all__ = ["ShrinkMeter", "sensor_mean"]


def sensor_mean(rows: dict, sensors) -> float:
    """Mean over ``sensors`` of the per-reading mean of ``rows`` (sensor → (n,))."""
    return float(np.mean([np.nanmean(rows[s]) for s in sensors]))


class ShrinkMeter:
    """shrink/gap_after of models given as (rows_score, rows_gap) dicts on the same held-out rows.

    base_score, base_gap: the configured model's rows; known: rows_score dicts of every predictive built
    (partial dicts are completed with the base rows); sensors: the sensors the gap is measured on.
    """

    def __init__(self, base_score: dict, base_gap: dict, sensors, known: list[dict]):
        self.sensors = list(sensors)
        self.base_score, self.base_gap = base_score, base_gap
        self.c0 = sensor_mean(base_gap, self.sensors)
        self.s0 = sensor_mean(base_score, self.sensors)
        scores = [self.s0] + [sensor_mean({**base_score, **k}, self.sensors) for k in known]
        self.s_min = float(min(scores))

    def shrink(self, rows_score: dict, rows_gap: dict) -> float:
        """min(calibration shrink, score shrink) of a model (partial dicts: other sensors as the base)."""
        if not self.c0 > 0:
            return 0.0
        c = sensor_mean({**self.base_gap, **rows_gap}, self.sensors)
        s = sensor_mean({**self.base_score, **rows_score}, self.sensors)
        calibration = 1.0 - abs(c) / self.c0
        if s > self.s0:
            score = -(s - self.s0) / self.c0
        else:
            score = (self.s0 - s) / (self.s0 - self.s_min) if self.s0 > self.s_min else 0.0
        return float(min(calibration, score))

    def gap_after(self, rows_score: dict, rows_gap: dict) -> float:
        """The gap a model leaves, c(F₀)·(1 − shrink), in the units of the calibration gap."""
        return float(self.c0 * (1.0 - self.shrink(rows_score, rows_gap))) if self.c0 > 0 else float(self.c0)
