"""A catch-all named beside a structured effect must earn its place against a more flexible fit of that effect.

A catch-all (a noise scale, a constant bias, pose noise, constant cross-talk) absorbs part of any misfit: beside a wall
bulge whose amplitude law differs from the catalogue's ``amplitude·exp(−(d/reach)^shape)`` it soaks up the shape
mismatch, and the report names a tracking system and a sonar that are fine. So once the selection has named a
catch-all beside a structured effect on a shared sensor, :func:`earn_place` takes each such catch-all out (the last
added first), refits the structured effect with a more flexible version of itself on top of the rest
(:func:`flexible_version`: the bulge's law blended with the walls' own polynomial hinge law,
:func:`~finkensim.gap.model.bulge.bulge_target`), and keeps the catch-all only when the selection with it still beats that
model by the bar of a further effect, the structured effect refitted flexibly with the catch-all in place too (the selection's rule: an improvement of the held-out score of at least
``gap.accept_improvement`` in units of the typical error of the model without it, with a p-value under ``gap.alpha``
/ the number of candidates), or when the selection without it would leave the gap unexplained (the step prunes
an explanation, it never undoes one: an insignificant constant cross-talk beside a bulge once went, and the verdict
turned unexplained). The catch-all keeps its fitted value and the bulge is refitted around it (a catch-all
refitted alone on top of a bulge can stop partway along the valley the two share, which a joint fit reached). Every refit is a "tried" line of the waterfall and of
``verdict.tried``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import effects as fx
from .fit_result import FitResult
from .fits import nelder_mead

__all__ = ["flexible_version", "earn_place", "Earned", "pair_suffices"]

#: hinge-law weight, reach factor: the starting points of the flexible bulge's search (the polynomial law ends at its
#: threshold, so a bulge that law describes needs a longer reach than the Gaussian fitted to it)
_BULGE_STARTS = ((0.0, 1.0), (0.5, 1.0), (1.0, 1.0), (0.5, 1.6), (1.0, 2.2))


def _fit_flexible_bulge(diag, effect, current, vals):
    """The flexible bulge from the catalogue fit ``vals``: a few hinge weights and reaches, then Nelder–Mead over
    every parameter from the best."""
    sensors = [s for s in effect.sensors if s in diag.tables]
    reach = next(q for q in effect.params if q.name == "reach")
    f = lambda v: diag.objective(effect, current, sensors, v)  # noqa: E731
    cands = [{**vals, "hinge": h, "reach": min(reach.hi, vals["reach"] * k)} for h, k in _BULGE_STARTS]
    scores = [f(c) for c in cands]
    i = int(np.argmin(scores))
    return nelder_mead(f, cands[i], effect.params, [cands[i][q.name] for q in effect.params], scores[i], maxfev=60)


def flexible_version(name: str) -> fx.Effect | None:
    """The more flexible version of the catalogued effect ``name`` (same name, one more parameter), or None.

    ``wall_bulge``: its four parameters plus ``hinge`` in [0, 1], the weight of the walls' own polynomial amplitude
    law (:func:`~finkensim.gap.model.bulge.bulge_target`; 0 is the catalogue's law, 1 the hinge law with ``reach`` as its
    threshold).

    Parameters
    ----------
    name : str
        A catalogued effect's name.

    Returns
    -------
    Effect or None
        The flexible effect (fitted by its own ``fit``), None when the effect has none.
    """
    if name != "wall_bulge" or name not in fx.REGISTRY:
        return None
    wb = fx.REGISTRY[name]
    return fx.Effect(
        name, wb.sensors, wb.params + (fx.Param("hinge", 0.0, 1.0),),
        lambda b, v: wb.apply(b, v).with_(bulge_hinge=float(v["hinge"])),
        doc=wb.doc + "; its law blended with the walls' own polynomial hinge law (weight hinge)",
        initial=lambda b: {**wb.start(b), "hinge": b.bulge_hinge}, expected_features=wb.expected_features,
        fit=_fit_flexible_bulge)


@dataclass
class Earned:
    """What :func:`earn_place` found.

    Parameters
    ----------
    added : list of FitResult or None
        The new selection (in the original order) when a catch-all was dropped, else None (the selection stands).
    final : FitResult or None
        The new selection's model, scored on the held-out flights (None when the selection stands).
    steps : list of tuple
        Waterfall steps ``(label, effect, rows_score, rows_gap, params)``, one per refit.
    tried : list of dict
        ``verdict.tried``: per catch-all {effect, beside, refit, improvement, p, threshold, kept}.
    """

    added: list | None = None
    final: FitResult | None = None
    steps: list = field(default_factory=list)
    tried: list = field(default_factory=list)


def _shares_sensor(a: str, b: str) -> bool:
    return bool(set(fx.REGISTRY[a].sensors) & set(fx.REGISTRY[b].sensors))


def earn_place(diag, added, improvement, further_bar, n_candidates: int, evaluated: list,
               gain=None, explains=None) -> Earned | None:
    """Does each catch-all of the selection ``added`` earn its place beside a structured effect refitted flexibly?

    Parameters
    ----------
    diag : Diagnosis
        The diagnosis (fits and held-out scores).
    added : list of FitResult
        The selection, in the order added (each ``values`` its fitted parameters).
    improvement : callable
        ``improvement(cur_rows, new_rows) -> (mean, ci, p)``: the held-out improvement test of the selection.
    further_bar : callable
        ``further_bar(score) -> float``: the improvement a further effect needs on a model scoring ``score``.
    n_candidates : int
        The Bonferroni count of the test (the candidates a further effect is picked from).
    evaluated : list
        Every model's held-out rows so far; the refits' are appended.
    gain : callable, optional
        ``gain(old, new) -> float``: the share of a gap sensor's configured-model gap that going from FitResult
        ``old`` to ``new`` removes; a catch-all removing at least ``gap.accept_gain`` is material and stays on a
        significant improvement (the selection's first rule).
    explains : callable, optional
        ``explains(result) -> bool``: whether the model of a FitResult (its held-out rows) explains the gap as the
        verdict measures it; given when the selection explains it. A catch-all whose removal would leave the gap
        unexplained stays whatever its test says (dropping a catch-all never turns an explained verdict unexplained).

    Returns
    -------
    Earned or None
        None when no catch-all sits beside a structured effect with a flexible version on a shared sensor.
    """
    flexible = [r.name for r in added if flexible_version(r.name) is not None]
    catch = [r for r in added if fx.REGISTRY[r.name].catch_all and any(_shares_sensor(r.name, s) for s in flexible)]
    if not catch:
        return None
    cfg = diag.cfg.gap
    threshold = cfg.alpha / max(1, n_candidates)
    out = Earned()
    sel = list(added)
    for c in reversed(catch):  # the last added first: it had the least to explain
        others = [r for r in sel if r is not c]
        # both sides with the structured effects refitted flexibly: the test isolates the catch-all
        _, cur = _flexible_without(diag, sel)
        chain, reduced = _flexible_without(diag, others)
        evaluated += [cur.rows_score, reduced.rows_score]
        imp, _, pv = improvement(reduced.rows_score, cur.rows_score)
        bar = further_bar(reduced.score_heldout)
        share = gain(reduced, cur) if gain is not None else 0.0
        # the selection's rule: significant, and material (a share of the gap) or beyond a further effect's bar
        earned = bool(np.isfinite(pv) and pv < cfg.alpha and imp > 0 and (
            share >= cfg.accept_gain or (imp >= bar and pv < threshold)))
        # without it the gap would be left unexplained: the parsimony step prunes an explanation, never undoes one
        needed = bool(not earned and explains is not None and not explains(reduced))
        stays = earned or needed
        beside = ", ".join(f"{r.name} (flexible)" if r.name in flexible else r.name for r in others)
        out.tried.append({"effect": c.name, "beside": beside, "improvement": float(imp), "bar": float(bar),
                          "gap_share": float(share),
                          "p": float(pv), "threshold": threshold, "kept": stays, "needed_to_explain": needed})
        out.steps.append((f"tried: {beside} without {c.name} ({c.name} {'kept' if stays else 'dropped'})", None,
                          reduced.rows_score, reduced.rows_gap, {r.name: dict(r.values) for r in chain}))
        diag.say(f"  {c.name} against {beside}: improvement {imp:.4f} (bar {bar:.4f}), p = {pv:.3g}: "
                 f"{'kept' if stays else 'dropped'}{' (without it the gap is unexplained)' if needed else ''}")
        if not stays:
            sel, final = chain, reduced
    if len(sel) == len(added):
        return out
    out.added, out.final = sel, final
    return out


def _model(diag, selection):
    """The configured model with every FitResult of ``selection`` applied at its values, in order."""
    p = diag.base
    for r in selection:
        e = flexible_version(r.name) if "hinge" in r.values else fx.REGISTRY[r.name]
        p = e.apply(p, r.values)
    return p


def _flexible_without(diag, selection):
    """``selection`` with each effect that has a flexible version refitted with it on top of all the others (at
    their values); returns (the new selection in the same order, its model scored on the held-out flights)."""
    chain = list(selection)
    for k, r in enumerate(chain):
        flex = flexible_version(r.name)
        if flex is None:
            continue
        rest = _model(diag, chain[:k] + chain[k + 1:])
        vals = flex.fit(diag, flex, rest, {"hinge": 0.0, **r.values})
        chain[k] = FitResult(r.name, vals, flex.apply(rest, vals), math.nan)
    last = chain[-1]
    return chain, diag.score_heldout(FitResult(last.name, last.values, _model(diag, chain), math.nan))


def pair_suffices(pair, cur_rows: dict, improvement, further_bar, n_candidates: int, alpha: float, explains) -> bool:
    """Does a joint pair describe the held-out data as well as a selection of more effects?

    The effects beyond a pair must earn their place against the best pair (the first selected effect fitted jointly
    with each candidate on its sensors) as a further effect does: the selection must improve the pair's held-out
    score by at least ``further_bar`` with p < ``alpha`` / ``n_candidates``. A greedy path can take a detour: a bulge
    and a 0.13 m sonar bias (wall_bulge+sonar_bias, seed 3 of the random conventions) came out as the bulge plus
    sound speed, beam width and noise scale, each step significant on top of the last, none of them there.

    Parameters
    ----------
    pair : list of FitResult or None
        The pair's chain (its last entry held-out scored), or None (no pair: False).
    cur_rows : dict
        The selection's held-out score rows (sensor → (n,)).
    improvement : callable
        ``improvement(cur_rows, new_rows) -> (mean, ci, p)``: the held-out improvement test of the selection.
    further_bar : callable
        ``further_bar(score) -> float``: the improvement a further effect needs on a model scoring ``score``.
    n_candidates : int
        The Bonferroni count of the test.
    alpha : float
        ``gap.alpha``.
    explains : callable
        ``explains(result) -> bool``: the pair may replace the selection only when this holds for its last FitResult
        (it explains the gap, or the selection did not either).

    Returns
    -------
    bool
        True when the selection does not beat the pair and the pair passes ``explains``.
    """
    if pair is None:
        return False
    imp, _, p = improvement(pair[-1].rows_score, cur_rows)
    beats = bool(imp >= further_bar(pair[-1].score_heldout) and np.isfinite(p) and p < alpha / max(1, n_candidates))
    return not beats and bool(explains(pair[-1]))
