"""Which effect explains the gap: the first round of fits, greedy forward selection over the fitted catalogue, and
its state (:class:`Selection`).

Every candidate effect is fitted on the training flights and scored on the held-out ones; the best is
added while it removes a significant share (``gap.accept_gain``) of the configured model's held-out gap — or, after
the first, improves the held-out score by ``gap.accept_improvement`` (in units of the current model's typical error)
with a p-value that survives Bonferroni over the candidates — up to ``max_added`` effects. Joint refits of what was
selected are :mod:`.joint`, the parsimony rule for catch-alls :mod:`.parsimony`; the verdict is
:mod:`finkensim.gap.quantify.verdict`. A gap is significant when some sensor's calibration gap is (the omnibus
test, :mod:`finkensim.gap.detect.significance`) or, failing that, when a structured effect's training fit improves
its sensors' held-out score significantly (the targeted test, :mod:`.targeted`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import effects as fx
from ..detect.significance import sensor_gaps
from ..model.replay import GapInputError
from .shrink import ShrinkMeter
from .parsimony import earn_place
from .targeted import passed

__all__ = ["check_effects", "candidates", "first_round", "Selection", "select_greedy", "hopeless", "keep_earned",
           "clean_values"]


def check_effects(names) -> None:
    """Raise :class:`GapInputError` if ``names`` holds an effect that is not catalogued (``--effects``, ``gap.effects``)."""
    unknown = [n for n in names if n not in fx.REGISTRY]
    if unknown:
        raise GapInputError(f"--effects / gap.effects names unknown effects {unknown}; catalogued: {sorted(fx.REGISTRY)}")


def candidates(diag, effect_names=None) -> list:
    """The candidate effects: ``effect_names`` (default ``gap.effects``, else the whole catalogue), checked, those
    with a sensor the logs have."""
    cfg = diag.cfg.gap
    names = list(effect_names if effect_names is not None else (cfg.effects or fx.REGISTRY))
    check_effects(names)
    return [fx.REGISTRY[n] for n in names if any(s in diag.tables for s in fx.REGISTRY[n].sensors)]


def first_round(diag, cands) -> list:
    """Every candidate fitted on top of the configured model and scored on the held-out flights, best first."""
    diag.say(f"fitting {len(cands)} effects")
    first = []
    for e in cands:
        diag.say(f"  effect {e.name}")
        r = diag.score_heldout(diag.fit(e, diag.base))
        first.append(r)
    first.sort(key=lambda r: r.score_heldout)
    return first


@dataclass
class Selection:
    """The state of the selection: the effects added, the model they make and its held-out rows, the waterfall's
    steps and every model's held-out scores evaluated so far (the shrink's best score,
    :mod:`~finkensim.gap.attribute.shrink`).

    ``current``, ``cur_scores``, ``cur_gaps`` and ``cur_score`` are the current model, its per-row held-out scores
    and gaps (sensor → (n,)) and its mean held-out score; ``steps`` are (label, effect, rows_score, rows_gap,
    values) tuples; ``pool`` the candidates left, ``ambiguous`` the first pick's near ties, ``runners_up`` the
    second pick's alternatives, ``lead`` the first round's best, ``earned`` the parsimony step's finding,
    ``hopeless`` the first round's candidates that the later rounds do not refit (:func:`hopeless`), ``refits`` the
    ``verdict.tried`` entries of the structured refits (:func:`~finkensim.gap.attribute.hinge.refit_as_hinge`).
    """

    diag: object
    found: object
    first: list
    current: object
    cur_scores: dict
    cur_gaps: dict
    cur_score: float
    evaluated: list
    steps: list
    added: list = field(default_factory=list)
    pool: list = field(default_factory=list)
    ambiguous: list = field(default_factory=list)
    runners_up: list = field(default_factory=list)
    lead: object = None
    earned: object = None
    hopeless: frozenset = frozenset()
    refits: list = field(default_factory=list)
    _left: tuple = field(default=(None, None), repr=False)

    @classmethod
    def start(cls, diag, found, first) -> "Selection":
        """Nothing added yet: the configured model, the first round as the pool."""
        evaluated = [found.base_scores] + [r.rows_score for r in first]
        steps = [("configured model", None, found.base_scores, found.gap_vals, None)]
        return cls(diag, found, first, diag.base, found.base_scores, found.gap_vals, found.score_before, evaluated,
                   steps, pool=list(first), hopeless=hopeless(first, found.score_before))

    def improvement(self, cur_scores, new_scores):
        """(mean, ci, p) of the held-out score's improvement from ``cur_scores`` to ``new_scores``."""
        diff = {s: cur_scores[s] - new_scores[s] for s in cur_scores if s in new_scores}
        return self.diag.overall(diff, self.found.rows_ho)

    def further_bar(self, score):
        """The improvement a further effect needs, in units of the typical error of a model scoring ``score``."""
        cfg, score_before = self.diag.cfg.gap, self.found.score_before
        return cfg.accept_improvement * min(1.0, score / score_before) if score_before > 0 else cfg.accept_improvement

    def share(self, cur: dict, new: dict) -> float:
        """The largest share of a gap sensor's configured-model gap that going from ``cur`` to ``new`` removes."""
        return _share(cur, new, self.found.gap_sensors, self.found.per_sensor)

    def adopt(self, chain, label) -> None:
        """Make a joint fit's chain the selection, with its waterfall step."""
        last = chain[-1]
        values = {r.name: clean_values(r.values) for r in chain}
        self.steps.append((label, None, last.rows_score, last.rows_gap, values))
        self.diag.say(f"  joint fit of {chain[0].name} and {chain[1].name}: held-out score {last.score_heldout:.4f}")
        self.added, self.current, self.cur_scores, self.cur_gaps, self.cur_score = (
            chain, last.params, last.rows_score, last.rows_gap, last.score_heldout)

    def significantly_better(self, chain) -> bool:
        """A joint fit's chain beats the current selection: lower held-out score, significant improvement."""
        if chain is None or not chain[-1].score_heldout < self.cur_score:
            return False
        imp, _, imp_p = self.improvement(self.cur_scores, chain[-1].rows_score)
        return bool(np.isfinite(imp_p) and imp_p < self.diag.cfg.gap.alpha and imp > 0)

    def explains(self, rows_score, rows_gap) -> bool:
        """The verdict's test on a model's held-out rows: enough shrink (``gap.unexplained_shrink``), or a
        remainder that cannot be told from zero (:mod:`finkensim.gap.quantify.verdict`)."""
        found, cfg = self.found, self.diag.cfg.gap
        sensors = found.gap_sensors or list(found.base_scores)
        if ShrinkMeter(found.base_scores, found.gap_vals, sensors, self.evaluated).shrink(
                rows_score, rows_gap) >= cfg.unexplained_shrink:
            return True
        remaining = sensor_gaps(self.diag, rows_gap, found.rows_ho, found.gap_sensors, len(found.gap_vals), cfg,
                                remainder=True)
        return not any(r["significant"] for r in remaining.values())

    def remaining(self) -> dict:
        """Per gap sensor, the test of what the current selection leaves (two-sided; computed once per step)."""
        if self._left[0] != len(self.added):
            found, cfg = self.found, self.diag.cfg.gap
            self._left = (len(self.added), sensor_gaps(self.diag, self.cur_gaps, found.rows_ho, found.gap_sensors,
                                                       len(found.gap_vals), cfg, remainder=True))
        return self._left[1]

    def second_matters(self, chain, n_candidates) -> bool:
        """The second effect of a joint fit clears a further effect's bar against the first effect of the same fit
        alone (so a better optimum of the first, which the joint search also finds, does not let a second in: a
        wall bulge refitted beside a 3 mm bias improved the held-out score by 0.0036, the bias itself by nothing).
        The bar, as for any pick (:func:`select_greedy`): a significant improvement (Bonferroni over the candidates)
        that is material, i.e. at least a further effect's score improvement, or a cut of the calibration gap's size
        by at least ``gap.accept_gain`` of a gap sensor's configured-model gap (:func:`_abs_share`: a gap turned
        negative, a predictive made too wide, is no cut) (a weak obstacle tail beside a −0.11 m ranging
        offset: score improvement 0.0010 against a bar of 0.0028, yet the held-out shrink rose from 0.70 to 0.95)."""
        alone = self.diag.score_heldout(chain[0])
        self.evaluated.append(alone.rows_score)
        imp, _, imp_p = self.improvement(alone.rows_score, chain[-1].rows_score)
        gain = _abs_share(alone.rows_gap, chain[-1].rows_gap, self.found.gap_sensors, self.found.per_sensor)
        material = imp >= self.further_bar(alone.score_heldout) or gain >= self.diag.cfg.gap.accept_gain
        return bool(material and imp > 0 and np.isfinite(imp_p) and imp_p < self.diag.cfg.gap.alpha / max(1, n_candidates))


def select_greedy(sel: Selection, max_added: int, refit_top: int) -> None:
    """Greedy forward selection on the held-out score: add the best candidate while it is material (or, after the
    first, a clear further improvement), refitting the leading remaining candidates on top of what was added."""
    diag, found, cfg = sel.diag, sel.found, sel.diag.cfg.gap
    targeted = found.targeted
    while found.significant and sel.pool and len(sel.added) < max_added:
        if sel.added:  # refit the leading remaining candidates on top of what was added
            # every remaining effect on a sensor with a gap, plus the leading others (the first round's order
            # says little once an effect is in) — but not the hopeless ones: fitted alone, they left the held-out
            # score no better than the configured model's (:func:`hopeless`)
            live = [r for r in sel.pool if r.name not in sel.hopeless or _unmasked(sel, r.name)]
            on_gap = [r for r in live if set(fx.REGISTRY[r.name].sensors) & set(found.gap_sensors)]
            again = on_gap + [r for r in live if r not in on_gap][:max(0, refit_top - len(on_gap))]
            sel.pool = sorted((diag.score_heldout(diag.fit(fx.REGISTRY[r.name], sel.current)) for r in again),
                              key=lambda r: r.score_heldout)
            sel.evaluated += [r.rows_score for r in sel.pool]
            if not sel.pool:
                break
        # a gap found by the targeted test is what the passing effects describe: the first is one of them
        best = _pick(sel.pool if sel.added or targeted is None else passed(sel.pool, targeted), sel.cur_score,
                     cfg.tie_tolerance)
        sel.lead = sel.lead or best
        imp, imp_ci, imp_p = sel.improvement(sel.cur_scores, best.rows_score)
        # the largest share of a gap sensor's configured-model gap this step removes (not of what is left: a
        # small misfit of the first effect must not let a catch-all in as a second one; per sensor: an effect on
        # a sensor with a small gap is not diluted by a large gap elsewhere)
        gain = sel.share(sel.cur_gaps, best.rows_gap)
        score_gain = sel.share(sel.cur_scores, best.rows_score)
        diag.say(f"  candidate {best.name}: improvement {imp:.4f} (p = {imp_p:.3g}), gap gain {gain:.3f}, score gain "
                 f"{score_gain:.3f}")
        # (after a targeted test, the configured model's calibration gap on the sensor can be about zero: its
        # significant structured effects are material by that test)
        material = max(gain, score_gain) >= cfg.accept_gain or (
            not sel.added and targeted is not None and best.name in targeted["passed"])
        # a weaker effect beside a dominant one removes little of the configured model's gap, yet is real when its
        # own improvement is clear: after the first effect, an improvement of at least gap.accept_improvement that
        # survives Bonferroni over the candidates it was picked from also counts. The bar is in units of the current
        # model's typical error (its held-out score against the configured model's): the dominant effect's misfit
        # no longer inflates it (a σ × 2.9 sonar noise beside geometric cross-talk improved the score by 0.0021 of
        # the configured model's units, 0.0048 of the current one's, and was left out)
        further = (bool(sel.added) and imp >= sel.further_bar(sel.cur_score) and np.isfinite(imp_p)
                   and imp_p < cfg.alpha / len(sel.pool))
        if not (np.isfinite(imp_p) and imp_p < cfg.alpha and imp > 0 and (material or further)):
            break
        if not sel.added:
            sel.ambiguous = _near_ties(sel.pool if targeted is None else passed(sel.pool, targeted), best,
                                       sel.cur_score, cfg.tie_tolerance)
        elif len(sel.added) == 1:  # the runners-up of the second pick, fitted on top of the first: its alternatives
            sel.runners_up = [r for r in sel.pool if r.name != best.name]
        sel.added.append(best)
        sel.current, sel.cur_scores, sel.cur_gaps = best.params, best.rows_score, best.rows_gap
        sel.cur_score = best.score_heldout
        sel.steps.append((f"+ {best.name}", best.name, best.rows_score, best.rows_gap, clean_values(best.values)))
        sel.pool = [r for r in sel.pool if r.name != best.name]
        diag.say(f"  added {best.name}: held-out score {best.score_heldout:.4f}")


def hopeless(first, score_before: float) -> frozenset:
    """Names of the first round's candidates that, fitted alone on the configured model, left the held-out score
    no better than the configured model's ``score_before``: the later rounds do not refit them (an effect that
    explains none of the held-out gap alone is not the next one to add; refitting every sonar candidate on top of
    each added effect was a third of a trial's CPU)."""
    return frozenset(r.name for r in first if not r.score_heldout < score_before)


def _unmasked(sel: Selection, name: str) -> bool:
    """A hopeless candidate (:func:`hopeless`) is refitted once an added effect shares one of its sensors and a
    significant gap is left there: an effect can hide another one on its sensor, and what the hidden one does fitted
    alone says nothing of it — a negative ranging offset hid a positive tail, which fitted alone went to probability
    0; a tag's antenna offset hid a −0.10 … −0.12 m ranging offset, which fitted alone went to −0.17, −0.03 or
    +0.02 m and lost held-out score (``ranging_bias+ranging_antenna_offset`` seeds 10, 14, 17, named a scale or
    an NLOS bias beside the offset instead). Refitted beside the effect that hid it, it competes as every other
    candidate does; the catch-all rule (:func:`keep_earned`) still judges what it adds."""
    effect = fx.REGISTRY[name]
    if not any(r.name == name for r in sel.first):
        return False
    shared = set(effect.sensors) & {s for r in sel.added for s in fx.REGISTRY[r.name].sensors}
    shared &= set(sel.found.gap_sensors)
    if not shared:
        return False
    left = sel.remaining()
    return any(left[s]["significant"] for s in shared if s in left)


def keep_earned(sel: Selection) -> None:
    """A catch-all beside a structured effect stays only against a more flexible fit of that effect
    (:mod:`.parsimony`), or when the selection, which explains the gap, would not without it; the selection and its
    waterfall follow what earned its place."""
    if not (sel.found.significant and len(sel.added) > 1):
        return
    explains = ((lambda r: sel.explains(r.rows_score, r.rows_gap)) if sel.explains(sel.cur_scores, sel.cur_gaps)
                else None)
    sel.earned = earned = earn_place(sel.diag, sel.added, sel.improvement, sel.further_bar,
                                     max(1, len(sel.first) - 1), sel.evaluated,
                                     lambda a, b: max(sel.share(a.rows_gap, b.rows_gap),
                                                      sel.share(a.rows_score, b.rows_score)), explains=explains)
    if earned is None:
        return
    sel.steps += [(label, n, rs, rg, _clean_nested(v)) for label, n, rs, rg, v in earned.steps]
    if earned.added is not None:
        sel.added, final = earned.added, earned.final
        sel.current, sel.cur_scores, sel.cur_gaps, sel.cur_score = (final.params, final.rows_score, final.rows_gap,
                                                                    final.score_heldout)


def _share(cur: dict, new: dict, sensors, per_sensor) -> float:
    """The largest share of a gap sensor's configured-model gap that going from ``cur`` to ``new`` (sensor →
    per-row values) removes."""
    return max((float(np.nanmean(cur[s]) - np.nanmean(new[s])) / per_sensor[s]["gap"]
                for s in sensors if per_sensor[s]["gap"] > 0), default=0.0)


def _abs_share(cur: dict, new: dict, sensors, per_sensor) -> float:
    """The largest cut of a gap sensor's calibration gap in size, |mean cur| − |mean new| (sensor → per-row gaps),
    as a share of its configured-model gap."""
    return max(((abs(float(np.nanmean(cur[s]))) - abs(float(np.nanmean(new[s])))) / per_sensor[s]["gap"]
                for s in sensors if per_sensor[s]["gap"] > 0), default=0.0)


def _near_ties(pool, chosen, cur_score, tol):
    """Other candidates whose held-out improvement is within the tie tolerance of the chosen one's."""
    imp = cur_score - chosen.score_heldout
    return [r.name for r in pool if r.name != chosen.name and imp > 0 and (cur_score - r.score_heldout) >= (1 - tol) * imp]


def _pick(pool, cur_score, tol):
    """The candidate to add: the best held-out score, unless it is a catch-all and a structured effect's
    improvement comes within the tie tolerance of it (catch-alls absorb part of any gap)."""
    best = pool[0]
    if fx.REGISTRY[best.name].catch_all:
        ties = set(_near_ties(pool, best, cur_score, tol))
        return next((r for r in pool if r.name in ties and not fx.REGISTRY[r.name].catch_all), best)
    return best


def _clean_nested(values: dict) -> dict:
    """:func:`clean_values` of a values dict, or of each of a dict of them (effect name → values)."""
    return ({k: clean_values(v) for k, v in values.items()} if all(isinstance(v, dict) for v in values.values())
            else clean_values(values))


def clean_values(values: dict) -> dict:
    """Parameter values as plain ``int`` / ``float`` (for the report's JSON)."""
    return {k: (int(v) if isinstance(v, (int, np.integer)) else float(v)) for k, v in values.items()}
