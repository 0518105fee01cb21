"""Detect: is there a gap, and where? The configured model scored on the held-out flights, each sensor's calibration
gap tested (Bonferroni over the sensors), the readings counted and the gap located by context feature.

:func:`detect_gap` is the diagnosis's first step (:func:`~finkensim.gap.pipeline.run_diagnosis`); a gap the omnibus
test misses can still be found by the targeted test of :mod:`finkensim.gap.attribute.targeted`, which needs the
effects' fits.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .sufficiency import check_plausible, sample_sizes

__all__ = ["Detection", "detect_gap", "sensor_gaps"]


@dataclass
class Detection:
    """What the detect step found about the configured model.

    Parameters
    ----------
    base_scores : dict
        Sensor → per-row normalised held-out CRPS of the configured model, shape (n,).
    gap_vals : dict
        Sensor → per-row normalised held-out gap of the configured model, shape (n,).
    rows_ho : dict
        Sensor → the held-out rows scored, int array (n,).
    calibration_gap : float
        The held-out calibration gap over all sensors.
    gap_ci : tuple of float
        Its block-bootstrap 95 % interval.
    gap_p : float
        Its one-sided p-value.
    score_before : float
        The configured model's mean held-out score.
    per_sensor : dict
        Sensor → {gap, ci, p, significant} (:func:`sensor_gaps`).
    gap_sensors : list of str
        The sensors with a significant gap.
    significant : bool
        A significant gap somewhere (the omnibus test, or the targeted one once it ran).
    sizes : dict
        Sensor → readings and blocks held out (:func:`~finkensim.gap.detect.sufficiency.sample_sizes`).
    locs : list of dict
        The gap's locations (:meth:`~finkensim.gap.diagnosis.Diagnosis.locations`).
    targeted : dict or None
        The targeted test's finding (:func:`~finkensim.gap.attribute.targeted.targeted_test`), None when it did
        not run or found nothing.
    """

    base_scores: dict
    gap_vals: dict
    rows_ho: dict
    calibration_gap: float
    gap_ci: tuple
    gap_p: float
    score_before: float
    per_sensor: dict
    gap_sensors: list
    significant: bool
    sizes: dict
    locs: list
    targeted: dict | None = None


def detect_gap(diag) -> Detection:
    """Score the configured model on the held-out flights, test each sensor's gap and locate it.

    Parameters
    ----------
    diag : Diagnosis
        The prepared diagnosis (:class:`~finkensim.gap.diagnosis.Diagnosis`).

    Returns
    -------
    Detection
        The configured model's scores and gaps, the per-sensor tests and the locations.
    """
    cfg = diag.cfg.gap
    diag.say("scoring the configured model")
    ev_b, rows_ho = diag.evaluate(diag.base, "heldout")
    gap_vals = {s: g for s, (_, g) in ev_b.items()}
    calibration_gap, gap_ci, gap_p = diag.overall(gap_vals, rows_ho)
    base_scores = {s: c for s, (c, _) in ev_b.items()}
    score_before = float(np.mean([np.nanmean(c) for c in base_scores.values()]))
    # significance per sensor (Bonferroni over sensors): a gap in one sensor is not diluted by the
    # noise of the others
    per_sensor = sensor_gaps(diag, gap_vals, rows_ho, list(gap_vals), len(gap_vals), cfg)
    check_plausible(per_sensor)
    gap_sensors = [s for s, v in per_sensor.items() if v["significant"]]
    sizes = sample_sizes(diag, rows_ho)
    diag.say("locating the gap")
    locs = diag.locations(diag.base)
    return Detection(base_scores, gap_vals, rows_ho, calibration_gap, gap_ci, gap_p, score_before, per_sensor,
                     gap_sensors, bool(gap_sensors), sizes, locs)


def sensor_gaps(diag, gaps: dict, rows_ho: dict, sensors, n_sensors: int, cfg, remainder: bool = False) -> dict:
    """Per sensor, the held-out calibration gap and its test: {gap, ci, p, significant}.

    Significant: p < ``gap.alpha`` / ``n_sensors`` (Bonferroni over the sensors compared) and beyond ``gap.margin``.
    The configured model's gap is tested one-sided (a positive gap) and unknown power (too few blocks) is not
    significant. ``remainder=True`` tests what selected effects leave: two-sided, since a predictive made too wide
    leaves a negative gap, which is not an explanation, and unknown power counts as significant.

    Parameters
    ----------
    diag : Diagnosis
        The prepared diagnosis.
    gaps : dict
        Sensor → per-row gap, shape (n,).
    rows_ho : dict
        Sensor → the rows of ``gaps``.
    sensors : list of str
        The sensors tested.
    n_sensors : int
        The number of sensors compared (the Bonferroni divisor).
    cfg : GapConfig
        The ``[gap]`` settings (``alpha``, ``margin``).
    remainder : bool
        Test what selected effects leave (two-sided) instead of the configured model's gap.

    Returns
    -------
    dict
        Sensor → {gap, ci, p, significant}.
    """
    out = {}
    for s in sensors:
        m, ci, p_pos = diag.overall({s: gaps[s]}, {s: rows_ho[s]})
        if not remainder:
            sig = bool(np.isfinite(p_pos) and p_pos < cfg.alpha / n_sensors and m > cfg.margin)
            out[s] = {"gap": m, "ci": list(ci), "p": p_pos, "significant": sig}
            continue
        p = 2.0 * min(p_pos, 1.0 - p_pos) if np.isfinite(p_pos) else math.nan
        out[s] = {"gap": m, "ci": list(ci), "p": p,
                  "significant": bool(not np.isfinite(p) or (p < cfg.alpha / n_sensors and abs(m) > cfg.margin))}
    return out
