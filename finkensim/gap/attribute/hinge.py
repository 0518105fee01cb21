"""The ``wall_bulge`` effect as the simulator's own hinge walls: its structured version, tried once it is selected.

The catalogue's bulge (:mod:`finkensim.gap.model.bulge`) is phenomenological: a target displacement
``amplitude·exp(−(d/reach)^shape)`` followed with a first-order response. A curtain on a hinge behaves otherwise —
a PID drives the plate angle toward ``max_amplitude · f(x)`` within a threshold distance, against gravity, with
overshoot and a second-order response, and the surface moves by ``lever · sin θ`` — and no bulge describes that
exactly: calibrated with the bulge, the simulator left 2–7 % of a hinge's gap on fresh flights, significant every
time (docs/calibration.md). The simulator already has that model and replays it from logged positions
(:func:`finkensim.world.walls_from_positions`). So once the selection names ``wall_bulge``, :func:`refit_as_hinge`
refits it as hinge walls (:func:`hinge_version`: ``max_amplitude_deg``, ``threshold``, ``hinge_height``, the
config keys that fly it) on top of the other selected effects, and keeps the refit when it improves the held-out
score significantly (p < ``gap.alpha``, paired block bootstrap, as the selection's own tests) without leaving an
explained gap unexplained. A curtain may follow either law: the held-out data decide. The refit is a waterfall step
"tried: …" and an entry of ``verdict.tried`` either way; a kept refit is what ``calibrate`` flies
(``walls.bending = true``, ``walls.model = "hinge"`` and the three keys).
"""
from __future__ import annotations

import math

import numpy as np

from ..model.bulge import HINGE_KEYS
from . import effects as fx
from .fit_result import FitResult
from .fits import nelder_mead
from .parsimony import flexible_version

__all__ = ["hinge_version", "fit_hinge", "refit_as_hinge", "effect_of"]

#: evaluations of the hinge version's Nelder–Mead after its starting points (each one replays the training readings)
HINGE_MAXFEV = 30


def _hinge_informed(objective) -> tuple[str, ...]:
    """A log with sonar readings informs how far readings shorten (lever · sin(1.1 · max amplitude)) and how close
    a copter must come (threshold); none without sonar readings. One quantity, not two, for the amplitude and the
    lever: :func:`fit_hinge` sets the hinge height by a rule (the configured one unless its lever is too short) and
    fits the maximum amplitude on it, so the maximum amplitude carries that quantity's uncertainty (its bootstrap
    interval, :mod:`~finkensim.gap.quantify.intervals`) and the hinge height gets none (profiled with the amplitude
    held, it would claim the same information twice)."""
    return HINGE_KEYS[:2] if "ultrasonic" in objective.tables else ()


def _altitude(objective) -> float:
    """The flights' mean altitude, m (the lever is hinge height − altitude)."""
    return float(np.mean([fl.arena.altitude for fl in objective.flights]))


def fit_hinge(objective, effect, current, vals):
    """From the fitted bulge ``vals`` (its amplitude and reach): the hinge height the configured one (the walls'
    geometry, like the arena's size) unless its lever (hinge height − the flights' altitude) is too short for the
    bulge's largest displacement (lever · sin(1.1 · 80°) < amplitude; f(1) = 1.1), then the one whose lever gives
    that displacement at the configured maximum amplitude; a log informs lever · sin(1.1 · max amplitude), not each
    (a fit of both drifts along that valley). Then the maximum amplitude that gives the displacement on that lever
    and the threshold the configured one or the bulge's reach, the better of those starts, and Nelder–Mead over
    maximum amplitude and threshold (:data:`HINGE_MAXFEV` evaluations)."""
    sensors = [s for s in effect.sensors if s in objective.tables]
    amp_p, thr_p, height_p = effect.params
    f = lambda v: objective.objective(effect, current, sensors, v)  # noqa: E731
    alt = _altitude(objective)
    cfg_amp, cfg_thr, cfg_height = (current.walls_hinge or (30.0, 1.0, 1.0))
    clip = lambda p, x: float(min(p.hi, max(p.lo, x)))  # noqa: E731
    bulge = max(0.0, float(vals.get("amplitude", 0.0)))
    lever = max(0.0, cfg_height - alt)
    if lever * math.sin(1.1 * math.radians(amp_p.hi)) < bulge:
        lever = bulge / math.sin(1.1 * math.radians(min(max(cfg_amp, 5.0), amp_p.hi)))
    height = clip(height_p, alt + lever)
    lever = max(0.0, height - alt)
    amp = math.degrees(math.asin(min(1.0, bulge / lever))) / 1.1 if lever > 0 and bulge > 0 else cfg_amp
    cands = [{"max_amplitude_deg": clip(amp_p, amp), "threshold": clip(thr_p, thr), "hinge_height": height}
             for thr in dict.fromkeys((cfg_thr, float(vals.get("reach", cfg_thr))))]
    scores = [f(c) for c in cands]
    i = int(np.argmin(scores))
    group = [amp_p, thr_p]
    return nelder_mead(f, cands[i], group, [cands[i][q.name] for q in group], scores[i], maxfev=HINGE_MAXFEV)


def hinge_version(name: str) -> fx.Effect | None:
    """The structured version of the catalogued effect ``name`` as a simulator model, or None.

    ``wall_bulge``: the simulator's hinge walls (:func:`~finkensim.gap.model.bulge.as_hinge_walls`) with
    ``max_amplitude_deg`` ∈ [0, 80] deg, ``threshold`` ∈ [0.1, 3] m and ``hinge_height`` ∈ [0.2, 5] m fitted (the
    other hinge keys the config's); same name and ``apply`` (the catalogue's dispatches on the values' keys), so
    every later step applies and calibrates a kept refit as ``wall_bulge``.

    Parameters
    ----------
    name : str
        A catalogued effect's name.

    Returns
    -------
    Effect or None
        The hinge version (fitted by :func:`fit_hinge`), None when the effect has none.
    """
    if name != "wall_bulge" or name not in fx.REGISTRY:
        return None
    wb = fx.REGISTRY[name]
    return fx.Effect(
        name, wb.sensors, (fx.Param("max_amplitude_deg", 0.0, 80.0, unit="deg"), fx.Param("threshold", 0.1, 3.0, unit="m"),
                           fx.Param("hinge_height", 0.2, 5.0, unit="m")),
        wb.apply, doc="the walls as the simulator's hinge (PID toward max_amplitude·f(x) within threshold, against "
                      "gravity; the surface moves by (hinge_height − altitude)·sin θ)",
        initial=lambda b: dict(zip(HINGE_KEYS, b.walls_hinge or (30.0, 1.0, 1.0))),
        expected_features=wb.expected_features, calibrate=wb.calibrate, fit=fit_hinge, informed=_hinge_informed)


def refit_as_hinge(sel) -> None:
    """The selected ``wall_bulge`` refitted as hinge walls on top of the other selected effects (at their values),
    kept when its held-out score is significantly better than the selection's (p < ``gap.alpha``) and it does not
    leave an explained gap unexplained. Updates the :class:`~finkensim.gap.attribute.selection.Selection` ``sel``
    (its effects, model, held-out rows, waterfall steps and ``refits``, the ``verdict.tried`` entries)."""
    diag = sel.diag
    k = next((i for i, r in enumerate(sel.added) if hinge_version(r.name) is not None), None)
    if not sel.found.significant or k is None or any(q in sel.added[k].values for q in HINGE_KEYS):
        return
    r = sel.added[k]
    hv = hinge_version(r.name)
    if not hv.free(diag):
        return
    rest = diag.base
    for j, o in enumerate(sel.added):
        if j != k:
            rest = _effect_of(o).apply(rest, o.values)
    diag.say(f"  {r.name} refitted as hinge walls")
    vals = hv.fit(diag, hv, rest, {**hv.start(rest), **r.values})
    vals = {q: float(vals[q]) for q in HINGE_KEYS}
    chain = list(sel.added)
    chain[k] = FitResult(r.name, vals, hv.apply(rest, vals), math.nan)
    model = diag.base
    for o in chain:
        model = _effect_of(o).apply(model, o.values)
    new = diag.score_heldout(FitResult(chain[-1].name, chain[-1].values, model, math.nan))
    sel.evaluated.append(new.rows_score)
    imp, _, pv = sel.improvement(sel.cur_scores, new.rows_score)
    cfg = diag.cfg.gap
    better = bool(np.isfinite(pv) and pv < cfg.alpha and imp > 0)
    undoes = bool(better and sel.explains(sel.cur_scores, sel.cur_gaps) and not sel.explains(new.rows_score,
                                                                                                new.rows_gap))
    kept = better and not undoes
    beside = ", ".join(o.name for o in sel.added if o is not r) or "nothing else"
    sel.refits.append({"effect": r.name, "beside": beside, "refit": "hinge walls", "improvement": float(imp),
                       "bar": 0.0, "gap_share": float(sel.share(sel.cur_gaps, new.rows_gap)), "p": float(pv),
                       "threshold": float(cfg.alpha), "kept": kept, "needed_to_explain": False,
                       "params": dict(vals)})
    sel.steps.append((f"tried: {r.name} as hinge walls ({'kept' if kept else 'not kept'})", None, new.rows_score,
                      new.rows_gap, {r.name: dict(vals)}))
    diag.say(f"  {r.name} as hinge walls ({', '.join(f'{q} {v:.3g}' for q, v in vals.items())}): improvement "
             f"{imp:.4f}, p = {pv:.3g}: {'kept' if kept else 'not kept'}")
    if kept:
        if k == len(chain) - 1:
            chain[k] = new
        sel.added = chain
        sel.current, sel.cur_scores, sel.cur_gaps, sel.cur_score = (new.params, new.rows_score, new.rows_gap,
                                                                    new.score_heldout)


def effect_of(name: str, values: dict) -> fx.Effect:
    """The effect whose parameters ``values`` are: the hinge version of ``name`` (:func:`hinge_version`, values with
    the hinge keys), the parsimony step's flexible version (:func:`~.parsimony.flexible_version`, values with a
    ``hinge`` weight), else the catalogue's. All three apply the same way where they overlap (the catalogue's
    ``apply`` dispatches on the hinge keys too); what differs is which parameters are free, and the flexible
    version's ``hinge`` weight, which only it applies."""
    if HINGE_KEYS[0] in values and hinge_version(name) is not None:
        return hinge_version(name)
    if "hinge" in values and flexible_version(name) is not None:
        return flexible_version(name)
    return fx.REGISTRY[name]


def _effect_of(result):
    """:func:`effect_of` of a FitResult."""
    return effect_of(result.name, result.values)
