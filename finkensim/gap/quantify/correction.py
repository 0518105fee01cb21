"""A data-driven correction for what the effect catalogue cannot explain.

When a significant gap remains, the diagnosis fits, on the training flights, the distribution of the
real reading around the model's prediction as a function of the reading's context features: quantile
regressions (scikit-learn's histogram gradient boosting, one model per quantile level) of the residual

    r = v(y) − median_m v(X_m)

on the table's features and the model median itself (v: the censoring of :mod:`.censoring`). On the
held-out flights its predictive distribution is the model median plus the Q predicted residual
quantiles (levels (k − ½)/Q, sorted so they never cross), scored with the same threshold-weighted CRPS as
every model, so "how much of the held-out gap the correction removes" is measured exactly as for a
catalogued effect. Its partial dependence on the located features says *where* and *how much* reality
departs from the simulator, even when no catalogued mechanism does.
"""
from __future__ import annotations

import importlib.util
from dataclasses import dataclass, field

import numpy as np

from ...sensors.correction_table import ChannelTables, CorrectionTable
from ...sensors.imu_correction import IMU_CHANNELS, IMU_UNITS
from ..model.scoring import brier, ensemble_terms

__all__ = ["Correction", "fit_correction", "residual_table", "channel_tables", "QUANTILES"]

QUANTILES = 19  # quantile levels of the correction's predictive distribution
MAX_TRAIN_ROWS = 20000
MIN_TRAIN_ROWS = 200  # fewer training readings with a value: no correction (the report says so)
METHOD = "sklearn HistGradientBoostingRegressor, quantile loss, {q} levels, residual on features + model median"


@dataclass
class Correction:
    """A fitted correction. sensor: the sensor it corrects first (largest gap); sensors: all corrected;
    features: feature names used (the last is ``model_median``); rows_score, rows_expected: sensor →
    (n,) held-out normalised score and the correction's own expected score; rows_gap: their difference, the
    calibration gap; partial_dependence: sensor →
    {feature: (grid (G,), median residual (G,) m)}; tables: sensor → the residual's quantiles on a grid of the model
    median (:func:`residual_table`; the IMU: one per channel, :func:`channel_tables`), the form the simulator flies
    (:mod:`finkensim.sensors.correction_table`)."""

    sensor: str
    sensors: list
    features: list
    method: str
    rows_score: dict = field(default_factory=dict, repr=False)
    rows_expected: dict = field(default_factory=dict, repr=False)
    rows_gap: dict = field(default_factory=dict, repr=False)
    partial_dependence: dict = field(default_factory=dict, repr=False)
    tables: dict = field(default_factory=dict, repr=False)


def _design(tab, rows, median):
    names = sorted(tab.features)
    X = np.column_stack([tab.features[k][rows] for k in names] + [median])
    return X, names + ["model_median"]


#: the exported table's bins: at most this many, each with at least TABLE_MIN_ROWS training readings
TABLE_BINS = 12
TABLE_MIN_ROWS = 200


def residual_table(median: np.ndarray, residual: np.ndarray, levels: np.ndarray, unit: str = "m") -> CorrectionTable:
    """The correction as a table the simulator applies: the empirical quantiles at ``levels`` (Q,) of the training
    residuals (n,) in bins of the model median (n,), both in ``unit`` (equal-count bins, at most :data:`TABLE_BINS`,
    each with at least ``TABLE_MIN_ROWS`` readings; the outer edges widened by 1e-3 ``unit``)."""
    G = max(1, min(TABLE_BINS, median.size // TABLE_MIN_ROWS))
    edges = np.unique(np.quantile(median, np.linspace(0.0, 1.0, G + 1)))
    if edges.size < 2:
        edges = np.array([edges[0] - 1e-3, edges[0] + 1e-3])
    edges[0] -= 1e-3
    edges[-1] += 1e-3
    g = np.clip(np.searchsorted(edges, median, side="right") - 1, 0, edges.size - 2)
    q = np.array([np.quantile(residual[g == k], levels) if (g == k).any() else np.quantile(residual, levels)
                  for k in range(edges.size - 1)])
    return CorrectionTable(edges, np.asarray(levels, dtype=float), np.maximum.accumulate(q, axis=1), unit)


def channel_tables(median: np.ndarray, residual: np.ndarray, channel: np.ndarray, window: float,
                   levels: np.ndarray) -> ChannelTables | None:
    """The IMU's correction as a table per channel (:data:`~finkensim.sensors.imu_correction.IMU_CHANNELS`, the
    rows' ``channel`` (n,) 0, 1, 2) of its window integrals over ``window`` s (:func:`residual_table` of each
    channel's rows); None when a channel has no training reading."""
    if any(not (channel == c).any() for c in range(len(IMU_CHANNELS))):
        return None
    return ChannelTables({name: residual_table(median[channel == c], residual[channel == c], levels, unit)
                          for c, (name, unit) in enumerate(zip(IMU_CHANNELS, IMU_UNITS))}, float(window))


def _export(tab, sensor, rows, median, residual, levels):
    """The table the simulator flies of ``sensor``'s training ``rows`` (model medians, residuals), or None."""
    if sensor == "imu":
        return channel_tables(median, residual, tab.channel[rows], float(np.median(tab.window_s[rows])), levels)
    return residual_table(median, residual, levels)


def _fit_sensor(diag, sensor, p, located):
    from sklearn.ensemble import HistGradientBoostingRegressor
    from sklearn.inspection import partial_dependence

    tab = diag.tables[sensor]
    rng = np.random.default_rng(diag.seed)
    rows_fit = diag.rows_fit[sensor]
    if rows_fit.size > MAX_TRAIN_ROWS:
        rows_fit = np.sort(rng.choice(rows_fit, MAX_TRAIN_ROWS, replace=False))
    D, y, _ = diag.censored_draws(sensor, p, rows_fit)
    med = np.median(D, axis=1)
    ok = np.isfinite(y) & np.isfinite(med)
    if ok.sum() < MIN_TRAIN_ROWS:
        return None
    X, names = _design(tab, rows_fit[ok], med[ok])
    r = (y - med)[ok]
    levels = (np.arange(QUANTILES) + 0.5) / QUANTILES
    models = [HistGradientBoostingRegressor(loss="quantile", quantile=float(q), max_iter=100, max_leaf_nodes=15,
                                            min_samples_leaf=40, early_stopping=False, random_state=0).fit(X, r)
              for q in levels]
    rows_ho = diag.rows_ho[sensor]
    Dh, yh, _ = diag.censored_draws(sensor, p, rows_ho)
    cens = diag.censoring.get(sensor)
    medh = np.median(Dh, axis=1)
    Xh, _ = _design(tab, rows_ho, medh)
    Q = np.sort(np.column_stack([m.predict(Xh) for m in models]), axis=1) + medh[:, None]
    if cens is not None:
        Q = cens.draws(Q)
    a, b_fair = ensemble_terms(np.ascontiguousarray(Q), np.ascontiguousarray(yh))
    pair = b_fair * (QUANTILES - 1) / QUANTILES  # the Q points are the distribution itself: plain mean over pairs
    sc = diag.scale.get(sensor, 1.0)
    score = (a - 0.5 * pair) / sc
    expected = 0.5 * pair / sc
    if sensor == "ranging":  # missing readings keep the model's dropout probability
        prob = tab.dropout_prob(p, rows_ho)
        z = tab.missing[rows_ho].astype(float)
        score = np.nan_to_num(score, nan=0.0) + brier(prob, z)
        expected = np.nan_to_num(expected, nan=0.0) + prob * (1.0 - prob)
    pd = {}
    mid = models[QUANTILES // 2]
    sample = X[rng.choice(X.shape[0], min(2000, X.shape[0]), replace=False)]
    for feat in [f for f in located if f in names][:2] or names[:1]:
        j = names.index(feat)
        if np.unique(sample[:, j][np.isfinite(sample[:, j])]).size < 2:
            continue
        res = partial_dependence(mid, sample, [j], grid_resolution=20, kind="average")
        pd[feat] = (np.asarray(res["grid_values"][0], float), np.asarray(res["average"][0], float))
    return names, score, expected, pd, _export(tab, sensor, rows_fit[ok], med[ok], r, levels)


def fit_correction(diag, p, sensors, located: dict | None = None, why: dict | None = None) -> Correction | None:
    """Fit the correction of each sensor in ``sensors`` (those with a significant gap) under the model
    ``p``; located: sensor → features of its significant locations, most significant first (for the
    partial-dependence plot). Returns None when scikit-learn is missing or no sensor has enough readings;
    ``why`` (a dict, filled in) says, per sensor (or "all"), why no correction was fitted."""
    why = {} if why is None else why
    if importlib.util.find_spec("sklearn") is None:  # optional dependency ([fit] extra): said in the report
        diag.say("  scikit-learn is not installed: no data-driven correction")
        why["all"] = "scikit-learn is not installed (pip install 'finkensim[fit]')"
        return None
    located = located or {}
    out = None
    for s in sensors:
        if s not in diag.tables:
            continue
        diag.say(f"  fitting a data-driven correction of {s}")
        fitted = _fit_sensor(diag, s, p, located.get(s, []))
        if fitted is None:
            why[s] = (f"too few training readings with a value ({int(np.isfinite(diag.tables[s].y[diag.rows_fit[s]]).sum())}"
                      f" < {MIN_TRAIN_ROWS}) to fit a correction")
            continue
        names, score, expected, pd, table = fitted
        if out is None:
            out = Correction(sensor=s, sensors=[], features=names, method=METHOD.format(q=QUANTILES))
        out.sensors.append(s)
        out.rows_score[s] = score
        out.rows_expected[s] = expected
        out.rows_gap[s] = score - expected
        out.partial_dependence[s] = pd
        if table is not None:
            out.tables[s] = table
    return out
