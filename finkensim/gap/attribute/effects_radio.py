"""The catalogue's radio effects: each one part of the simulator's ranging kernel (:mod:`finkensim.sensors.ranging_radio`).

Every entry changes the ``ranging`` record of a :class:`~finkensim.gap.model.params.ModelParams` through
:meth:`~finkensim.gap.model.params.ModelParams.with_ranging` and is flown by the simulator through the ``[ranging]`` config
keys of the same names (``calibrate``). Registered when :mod:`finkensim.gap.attribute.effects` is imported:

- (``ranging_nlos``, near a third copter, and ``ranging_dropout``, vs distance, are registered in
  :mod:`finkensim.gap.attribute.effects` in their old place of the catalogue, flown the same way);
- ``ranging_bias`` (a constant offset, m), ``ranging_scale`` (a clock-rate factor);
- ``ranging_antenna_offset``: the tag's (x, y) position in the body frame, shared by every copter;
- ``ranging_node_delay``: a constant per node (``delay_k`` for node k = copter k of the log; a pair reads the sum),
  fitted by least absolute deviations of the readings from the model's median on the node-incidence design (the
  minimum-norm solution where a sum is all the log pins down, e.g. one copter ranging to fixed anchors). It is a
  catch-all: equal delays are a constant offset, so it absorbs any constant offset, per node or not; it is named
  only when no structured effect (``ranging_bias`` among them) comes within the tie tolerance of it;
- ``ranging_nlos_tail``: a positive exponential extra length with a probability, independent of other copters.
"""
from __future__ import annotations

import numpy as np

from ...config import Config
from .effects import Effect, Param, register
from .objective import FitObjective
from ..model.params import ModelParams

__all__ = ["MAX_DELAY_NODES", "delay_nodes", "fit_node_delay", "node_delays", "pair_sums_l1"]

#: nodes whose delay ``ranging_node_delay`` fits (node k = copter k of the log; later nodes keep the configured one)
MAX_DELAY_NODES = 10


def _radio(b: ModelParams) -> dict:
    return b.ranging.radio


def node_delays(values: dict) -> list[float]:
    """The per-node delays m of ``ranging_node_delay``'s ``values`` (``delay_0`` …; a missing one is 0)."""
    return [float(values.get(f"delay_{k}", 0.0)) for k in range(MAX_DELAY_NODES)]


def _plus_delays(configured, values: dict) -> list[float]:
    """The configured per-node delays (any length) plus the fitted ones, as one list (at least MAX_DELAY_NODES)."""
    n = max(len(configured), MAX_DELAY_NODES)
    now = [float(d) for d in configured] + [0.0] * (n - len(configured))
    fitted = node_delays(values) + [0.0] * (n - MAX_DELAY_NODES)
    return [d + e for d, e in zip(now, fitted)]


def delay_nodes(diag: FitObjective) -> tuple[str, ...]:
    """The ``delay_k`` parameters the logs inform: node k is an end of some ranging reading (k < MAX_DELAY_NODES)."""
    if "ranging" not in diag.tables:
        return ()
    tab = diag.tables["ranging"]
    nodes = np.union1d(np.unique(tab.copter), np.unique(tab.channel))
    return tuple(f"delay_{int(k)}" for k in nodes if 0 <= k < MAX_DELAY_NODES)


def fit_node_delay(diag: FitObjective, effect: Effect, current: ModelParams, vals: dict) -> dict:
    """Per-node delays from the training readings: the residual r = reading − model median of each reading between
    nodes a and b is d_a + d_b; least absolute deviations (iteratively reweighted least squares, minimum norm where
    the log pins down only sums), clipped to the parameters' bounds."""
    if "ranging" not in diag.tables:
        return vals
    tab = diag.tables["ranging"]
    rows = diag.rows_fit["ranging"]
    D, _ = tab.draws(diag.flights, current, rows, diag.seed, diag.M)
    med = np.median(D, axis=1)
    res = tab.y[rows] - med
    a, b = tab.copter[rows], tab.channel[rows]
    ok = np.isfinite(res) & (med < current.ranging.max_range) & (a < MAX_DELAY_NODES) & (b < MAX_DELAY_NODES)
    if ok.sum() < 2:
        return vals
    sol = pair_sums_l1(res[ok], a[ok], b[ok], MAX_DELAY_NODES)
    lim = {q.name: (q.lo, q.hi) for q in effect.params}
    return {f"delay_{k}": float(np.clip(sol[k], *lim[f"delay_{k}"])) for k in range(MAX_DELAY_NODES)}


def pair_sums_l1(r: np.ndarray, a: np.ndarray, b: np.ndarray, n_nodes: int, iterations: int = 20) -> np.ndarray:
    """Per-node values d (n_nodes,) whose pair sums d[a] + d[b] fit ``r`` (n,) in least absolute deviations:
    iteratively reweighted least squares on the node-incidence design, each step solved through its
    (n_nodes × n_nodes) normal equations (the minimum-norm solution where only sums are pinned down: one copter
    ranging to fixed anchors). The normal equations are summed with ``np.bincount``, so a step costs O(n), not a
    least-squares solve of the (n, n_nodes) design (that made the node delays a joint search's whole cost)."""
    k = n_nodes
    cells = (a * k + a, b * k + b, a * k + b, b * k + a)
    weight = np.ones(r.size)
    sol = np.zeros(k)
    for _ in range(iterations):  # toward the L1 fit: robust to a long NLOS tail
        normal = sum(np.bincount(c, weight, minlength=k * k) for c in cells).reshape(k, k)
        rhs = np.bincount(a, weight * r, minlength=k) + np.bincount(b, weight * r, minlength=k)
        sol = np.linalg.lstsq(normal, rhs, rcond=None)[0]
        weight = 1.0 / np.maximum(np.abs(r - sol[a] - sol[b]), 0.01)
    return sol


def _antenna(b: ModelParams, v: dict) -> ModelParams:
    x, y, z = _radio(b)["antenna_offset"]
    return b.with_ranging(antenna_offset=(x + v["x"], y + v["y"], z))


def _cal_antenna(v: dict, cfg: Config) -> dict:
    x, y, z = cfg.ranging.antenna_offset
    return {"ranging.antenna_offset": [x + v["x"], y + v["y"], z]}


register(Effect(
    "ranging_bias", ("ranging",), (Param("bias", -1.0, 1.0, unit="m"),),
    lambda b, v: b.with_ranging(bias=_radio(b)["bias"] + v["bias"]),
    doc="a constant offset on every ranging reading", initial=lambda b: {"bias": 0.0},
    calibrate=lambda v, cfg: {"ranging.bias": cfg.ranging.bias + v["bias"]}))
register(Effect(
    "ranging_scale", ("ranging",), (Param("factor", 0.8, 1.25),),
    lambda b, v: b.with_ranging(scale=_radio(b)["scale"] * v["factor"]),
    doc="the radios' clock rate differs from the assumed one: readings scale by a factor",
    initial=lambda b: {"factor": 1.0}, expected_features=("true_range",),
    calibrate=lambda v, cfg: {"ranging.scale": cfg.ranging.scale * v["factor"]}))
register(Effect(
    "ranging_antenna_offset", ("ranging",), (Param("x", -0.4, 0.4, unit="m"), Param("y", -0.4, 0.4, unit="m")),
    _antenna,
    doc="the radio tag sits off the copter's centre at (x, y) in the body frame: readings are tag to tag and "
        "depend on both headings",
    initial=lambda b: {"x": 0.0, "y": 0.0}, calibrate=_cal_antenna))
register(Effect(
    "ranging_node_delay", ("ranging",),
    tuple(Param(f"delay_{k}", -0.5, 0.5, unit="m") for k in range(MAX_DELAY_NODES)),
    lambda b, v: b.with_ranging(node_delay=tuple(_plus_delays(_radio(b)["node_delay"], v))),
    doc="each radio node (copter k of the log) has its own constant delay delay_k; a pair reads the sum of its "
        "two nodes' delays",
    initial=lambda b: {f"delay_{k}": 0.0 for k in range(MAX_DELAY_NODES)},
    calibrate=lambda v, cfg: {"ranging.node_delay": _plus_delays(cfg.ranging.node_delay, v)},
    catch_all=True, fit=fit_node_delay, informed=delay_nodes, profiled=True))
register(Effect(
    "ranging_nlos_tail", ("ranging",),
    (Param("probability", 0.0, 0.5), Param("mean", 0.02, 1.5, unit="m", log=True)),
    lambda b, v: b.with_ranging(nlos_tail_probability=v["probability"], nlos_tail_mean=v["mean"]),
    doc="obstacles or people in the line of sight: with a probability, a reading is longer by an exponential "
        "length of the given mean, independent of other copters",
    initial=lambda b: {"probability": _radio(b)["nlos_tail_probability"], "mean": _radio(b)["nlos_tail_mean"]},
    calibrate=lambda v, cfg: {"ranging.nlos_tail_probability": v["probability"],
                              "ranging.nlos_tail_mean": v["mean"]}))
