"""How sure a calibration is: each fitted parameter's distribution from the diagnosis's block bootstrap.

For every selected effect (in the order the selection added it, on top of the ones before) and each of its
parameters, the training score is evaluated on a grid of values around the fit (the rest of the model at its
fitted values): :data:`GRID` points spread over the parameter's bounds plus :data:`GRID` points within
±:data:`LOCAL` of its range around the fitted value. Each block-bootstrap replicate of the training readings
(:class:`~finkensim.gap.detect.stats.BlockBootstrap`, the blocks the diagnosis tests with) picks the grid value with the
best weighted score; the picks over the replicates are the parameter's distribution (grid values and their
probabilities), their 2.5 and 97.5 % quantiles its interval. This is a profile bootstrap: the other parameters
stay at their fit, so correlated parameters get intervals that are too narrow rather than too wide.

The result, :func:`parameter_intervals`, goes into ``GapDetails.param_intervals`` and from there into
``calibrated.toml`` (a comment per key, a ``[calibration]`` table with the distributions) and into
``finkensim sweep``'s ``calibration = "sample"`` (:mod:`finkensim.sweep.calibration`).
"""
from __future__ import annotations

import numpy as np

from ..attribute import effects as fx
from ..attribute.hinge import effect_of
from ..model.params import SENSORS
from ..detect.stats import BlockBootstrap

__all__ = ["parameter_intervals", "GRID", "LOCAL", "N_BOOT"]

GRID = 9  #: grid points over the bounds, and again around the fit
LOCAL = 0.1  #: the local grid's half width, as a fraction of the parameter's range
N_BOOT = 200  #: bootstrap replicates
LEVEL = 0.95


def _grid(prm, value: float) -> np.ndarray:
    span = prm.hi - prm.lo
    g = np.concatenate([np.linspace(prm.lo, prm.hi, GRID),
                        np.clip(value + np.linspace(-LOCAL, LOCAL, GRID) * span, prm.lo, prm.hi), [value]])
    if prm.integer:
        g = np.round(g)
    return np.unique(g)


def _row_scores(diag, effect, current, values, sensors) -> list[np.ndarray]:
    p = effect.apply(current, values)
    return [np.asarray(diag.score_rows(s, p, diag.rows_fit[s])[0], dtype=float) for s in sensors]


def _profile(diag, effect, current, values: dict, prm, sensors, boot: BlockBootstrap, inverse: list) -> dict:
    grid = _grid(prm, float(values[prm.name]))
    reps = np.zeros((boot.weights.shape[0], grid.size))
    for j, g in enumerate(grid):
        for scores, inv in zip(_row_scores(diag, effect, current, {**values, prm.name: float(g)}, sensors), inverse):
            ok = np.isfinite(scores)
            sums = np.bincount(inv[ok], weights=scores[ok], minlength=boot.n_blocks)
            counts = np.bincount(inv[ok], minlength=boot.n_blocks).astype(float)
            with np.errstate(invalid="ignore", divide="ignore"):
                reps[:, j] += (boot.weights @ sums) / (boot.weights @ counts)
    reps = reps[np.isfinite(reps).all(axis=1)]
    if reps.shape[0] == 0:
        return {}
    picks = _vertices(grid, reps, float(values[prm.name]), prm)
    uniq, counts = np.unique(np.round(picks, 9), return_counts=True)
    a = (1.0 - LEVEL) / 2.0
    lo, hi = np.quantile(picks, [a, 1.0 - a])
    return {"value": float(values[prm.name]), "lo": float(lo), "hi": float(hi), "unit": prm.unit,
            "values": uniq.tolist(), "probabilities": (counts / counts.sum()).tolist()}


def _vertices(grid: np.ndarray, reps: np.ndarray, value: float, prm) -> np.ndarray:
    """Each replicate's best value (n_boot,): the vertex of a parabola through its scores at the local grid points
    (the best grid point when the parabola opens downward or its vertex leaves them; whole numbers for an integer
    parameter), so an interval narrower than the grid's spacing is resolved."""
    best = grid[np.argmin(reps, axis=1)]
    near = np.abs(grid - value) <= LOCAL * (prm.hi - prm.lo) * (1.0 + 1e-9)
    if near.sum() < 3:
        return best
    x = grid[near] - value
    A = np.column_stack([x * x, x, np.ones_like(x)])
    coef, *_ = np.linalg.lstsq(A, reps[:, near].T, rcond=None)
    a, b = coef[0], coef[1]
    with np.errstate(invalid="ignore", divide="ignore"):
        vertex = value - b / (2.0 * a)
    ok = (a > 0) & (vertex >= grid[near].min()) & (vertex <= grid[near].max()) & (np.abs(best - value) <= np.ptp(x))
    out = np.where(ok, vertex, best)
    return np.round(out) if prm.integer else out


def parameter_intervals(diag, added_params: dict, seed: int = 0) -> dict:
    """{effect: {parameter: {value, lo, hi, unit, values, probabilities}}} for the selected effects
    ``added_params`` (effect → fitted values, in the order they were added) of the diagnosis ``diag``
    (:class:`~finkensim.gap.diagnosis.Diagnosis`); an effect or parameter without training readings (or that the logs cannot inform, ``Effect.informed``) is
    left out."""
    out = {}
    current = diag.base
    for name, values in added_params.items():
        if name not in fx.REGISTRY:
            continue
        effect = effect_of(name, values)  # a bulge refitted as hinge walls has the hinge's parameters
        sensors = [s for s in effect.sensors if s in diag.tables]
        if sensors:
            ids = [diag.block_ids(s, diag.rows_fit[s]) for s in sensors]
            boot = BlockBootstrap(np.concatenate(ids), n_boot=N_BOOT, seed=seed)
            inverse = list(np.split(boot.inverse, np.cumsum([i.size for i in ids])[:-1]))
            per = {}
            for prm in effect.free(diag):
                if prm.name in values and np.isfinite(values[prm.name]):
                    own = [s for s in sensors if not effect.separable or prm.name not in SENSORS or s == prm.name]
                    keep = [i for i, s in enumerate(sensors) if s in own]
                    d = _profile(diag, effect, current, values, prm, own, boot, [inverse[i] for i in keep])
                    if d:
                        per[prm.name] = d
            if per:
                out[name] = per
        current = effect.apply(current, values)
    return out
