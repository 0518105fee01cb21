"""Coarse-to-fine fits: the coarse stage of a parameter search scored on a subsample of the training readings.

A fit's coarse grid (the points a bounded search or a simplex then starts from) only has to find the basin of the
best value; every point of it replays the sensor's readings under other parameters (for the geometry: pose draws
against moved walls, a wider beam, a later time), which costs in proportion to the readings scored. The coarse stage
therefore scores one training reading in :data:`SCREEN_SHARE` (:func:`screen_rows`, evenly through the flights'
time order), and the refinement, every value compared with it, and the result's training score use all training
readings; held-out scores (the selection's decisions) always use every held-out reading.

Scores of the subsample are means over its own readings, so they are compared only among themselves: a fit
compares its coarse winner with a refined point only after scoring the winner on all training readings
(:func:`full_objective`).
"""
from __future__ import annotations

import numpy as np

__all__ = ["SCREEN_SHARE", "SCREEN_MIN_READINGS", "screen_rows", "screens", "coarse_objective", "full_objective"]

#: the coarse stage of a fit scores one training reading in this many
SCREEN_SHARE = 4
#: a sensor with fewer training readings than this is screened on all of them (a subsample would be too noisy)
SCREEN_MIN_READINGS = 8000


def screen_rows(diag, sensor: str) -> np.ndarray:
    """The training rows of ``sensor`` that a fit's coarse stage scores: every :data:`SCREEN_SHARE`-th of
    ``diag.rows_fit[sensor]`` (sorted, so spread evenly through the flights), or that array itself when it holds
    fewer than :data:`SCREEN_MIN_READINGS` rows. The same array object on every call (score caches key on it).

    Parameters
    ----------
    diag : Diagnosis
        The diagnosis (its ``rows_fit``).
    sensor : str
        A sensor with a table in ``diag``.

    Returns
    -------
    numpy.ndarray
        Row indices (n,) int64 into the sensor's table.
    """
    cache = diag.__dict__.setdefault("_screen_rows", {})
    rows = cache.get(sensor)
    if rows is None:
        fit = diag.rows_fit[sensor]
        rows = cache[sensor] = fit if fit.size < SCREEN_MIN_READINGS else np.ascontiguousarray(fit[::SCREEN_SHARE])
    return rows


def screens(diag, sensors) -> bool:
    """Whether the coarse stage of a fit on ``sensors`` scores a subsample (some sensor has enough training
    readings, :func:`screen_rows`); else coarse and full objectives are one and the same.

    Parameters
    ----------
    diag : Diagnosis
        The diagnosis.
    sensors : list of str
        The sensors of the fit.

    Returns
    -------
    bool
    """
    return any(screen_rows(diag, s) is not diag.rows_fit[s] for s in sensors if s in diag.tables)


def coarse_objective(diag, effect, current, sensors):
    """``f(values) -> float``: the mean training CRPS of ``effect`` at ``values`` on top of ``current``, over
    ``sensors``, each sensor scored on its :func:`screen_rows` (cached per sensor and predictive, like the full
    objective's means).

    Parameters
    ----------
    diag : Diagnosis
        The diagnosis.
    effect : Effect
        The effect (anything with ``apply(params, values)``).
    current : ModelParams
        The model the effect is added to.
    sensors : list of str
        The sensors scored (those without a table are skipped).

    Returns
    -------
    callable
        The objective, values dict → float.
    """
    if not screens(diag, sensors):
        return full_objective(diag, effect, current, sensors)  # too few readings to subsample: one stage
    means = diag.__dict__.setdefault("_screen_means", {})

    def f(values: dict) -> float:
        p = effect.apply(current, values)
        tot = 0.0
        for s in sensors:
            if s in diag.tables:
                key = (s, p.sensor_key(s))
                mean = means.get(key)
                if mean is None:
                    crps, _ = diag.score_rows(s, p, screen_rows(diag, s))
                    mean = means[key] = float(np.nanmean(crps))
                tot += mean
        return tot

    return f


def full_objective(diag, effect, current, sensors):
    """``f(values) -> float``: the fit's objective on all training readings (``Diagnosis._objective``).

    Parameters
    ----------
    diag : Diagnosis
        The diagnosis.
    effect : Effect
        The effect.
    current : ModelParams
        The model the effect is added to.
    sensors : list of str
        The sensors scored.

    Returns
    -------
    callable
        The objective, values dict → float.
    """
    return lambda values: diag._objective(effect, current, sensors, values)
