"""The targeted test of a gap the omnibus test did not find: does a structured effect, fitted on the training
flights, improve the held-out score of its sensors? (A detection that needs the effects' fits, so it runs after the
first round of :func:`~finkensim.gap.attribute.selection.first_round`.)"""
from __future__ import annotations

import numpy as np

from . import effects as fx

__all__ = ["targeted_test", "apply_targeted", "passed"]


def apply_targeted(diag, found, first) -> None:
    """Run the targeted test when the omnibus test found no gap (and the flights are not halves of one); a passing
    effect makes the gap significant on its sensors. Updates ``found`` in place.

    The omnibus test compares the readings with the configured model in every respect at once and can miss a gap
    that one structured effect describes (a ranging lag of a few samples hides in the radio's wide error, yet
    shifting the predictive in time improves its held-out score with p ~ 1e-25). It does not run between the halves
    of a single flight: they share its slow random state, such as the IMU bias's random walk, so a constant fitted
    on the first half predicts the second better without any mismatch (an imported null flight "found" imu_bias at
    p = 2e-4 that way).

    Parameters
    ----------
    diag : Diagnosis
        The prepared diagnosis.
    found : Detection
        The detect step's result (:class:`~finkensim.gap.detect.significance.Detection`).
    first : list of FitResult
        The first round's fits, scored on the held-out flights.
    """
    if found.significant or diag.single:
        return
    targeted = targeted_test(diag, first, found.base_scores, found.rows_ho, diag.cfg.gap)
    found.targeted = targeted
    if targeted is not None:
        found.significant, found.gap_sensors = True, list(targeted["sensors"])
        diag.say(f"  no omnibus gap, but {targeted['effect']} improves the held-out score by "
                 f"{targeted['improvement']:.4f} (p = {targeted['p']:.3g} < {targeted['threshold']:.3g}): a gap on "
                 f"{', '.join(found.gap_sensors)}")


def targeted_test(diag, first, base_scores: dict, rows_ho: dict, cfg) -> dict | None:
    """The targeted test of a gap the omnibus test did not find: does a *structured* effect, fitted on the training
    flights, improve the held-out score of its sensors?

    Each structured (not catch-all) candidate of ``first`` is tested one-sided on its own sensors' held-out score
    difference (configured − fitted; block bootstrap); a candidate passes at p < ``gap.alpha`` / (number of
    structured candidates) (Bonferroni) with an improvement of at least ``gap.accept_improvement`` (normalised
    score units: a 0.2 s ranging lag improved it by 0.005-0.007 where its calibration gap stayed below the
    omnibus test's reach). A fit to noise does not improve held-out data on average, so this keeps the
    false-positive rate under α. Catch-alls (noise scale, constant bias, pose noise) are left out: they also absorb
    a recording convention (the shape of the base noise) that the configured model need not match.

    Parameters
    ----------
    diag : Diagnosis
        The prepared diagnosis.
    first : list of FitResult
        The first round's fits, scored on the held-out flights.
    base_scores : dict
        Sensor → the configured model's per-row held-out score.
    rows_ho : dict
        Sensor → the held-out rows.
    cfg : GapConfig
        The ``[gap]`` settings.

    Returns
    -------
    dict or None
        None, or {effect, sensors, improvement, ci, p, threshold, passed} for the passing candidate with the
        smallest p (``passed``: every passing candidate).
    """
    structured = [r for r in first if not fx.REGISTRY[r.name].catch_all]
    if not structured:
        return None
    threshold = cfg.alpha / len(structured)
    tested = []
    for r in structured:
        sensors = [s for s in fx.REGISTRY[r.name].sensors if s in base_scores and s in r.rows_score]
        diff = {s: base_scores[s] - r.rows_score[s] for s in sensors}
        imp, ci, p = diag.overall(diff, {s: rows_ho[s] for s in sensors})
        if np.isfinite(p) and p < threshold and imp >= cfg.accept_improvement:
            # the gap lies on the sensors the effect improves significantly by themselves (a lag fitted per
            # sensor improves only the late one), or on all of its sensors when none does alone
            alone = [s for s in sensors if len(sensors) > 1 and _p_positive(diag, diff, rows_ho, s) < threshold]
            tested.append({"effect": r.name, "sensors": alone or sensors, "improvement": float(imp),
                           "ci": [float(c) for c in ci], "p": float(p), "threshold": threshold})
    if not tested:
        return None
    best = min(tested, key=lambda t: t["p"])
    return {**best, "passed": [t["effect"] for t in tested]}


def _p_positive(diag, diff: dict, rows_ho: dict, sensor: str) -> float:
    """One-sided p-value of a positive mean of ``diff[sensor]`` (NaN-safe: unknown power is never significant)."""
    _, _, p = diag.overall({sensor: diff[sensor]}, {sensor: rows_ho[sensor]})
    return p if np.isfinite(p) else 1.0


def passed(pool, targeted):
    """The candidates of ``pool`` (FitResults) that passed the targeted test ``targeted``."""
    return [r for r in pool if r.name in targeted["passed"]]
